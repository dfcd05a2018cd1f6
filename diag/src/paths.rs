//! Paths read from files stay inside their directory.
//!
//! A project's manifest names its net files, a PNML file names the net files of the project it
//! becomes, can.toml names its DBC: each is a path that someone else may have written, and a
//! command that reads or writes it must not reach outside the project (or output) directory.
//! [`check_relative`] refuses what can be told from the text (an absolute path, a `..`);
//! [`confine`] also follows the symbolic links that exist on disk.

use std::fmt;
use std::path::{Component, Path, PathBuf};

/// Why a path read from a file may not be used.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum PathProblem {
    /// The path is empty.
    Empty,
    /// The path is absolute (`/etc/passwd`), or has a Windows prefix.
    Absolute,
    /// The path has a `..` component.
    Parent,
    /// The path holds a NUL character, which no file name can hold.
    Nul,
    /// Following the symbolic links on disk, the path leads to this place outside the
    /// directory (or to a link whose target does not exist, which cannot be told inside).
    Escapes(PathBuf),
}

impl fmt::Display for PathProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PathProblem::Empty => write!(f, "it is empty"),
            PathProblem::Absolute => write!(f, "it is absolute"),
            PathProblem::Parent => write!(f, "it goes up with `..`"),
            PathProblem::Nul => write!(f, "it holds a NUL character"),
            PathProblem::Escapes(to) => {
                write!(f, "a symbolic link leads it out, to {}", to.display())
            }
        }
    }
}

impl std::error::Error for PathProblem {}

/// Checks what the text of `path` alone tells: it is relative, not empty, and has no `..`.
/// (`.` components are harmless and allowed.)
pub fn check_relative(path: &str) -> Result<(), PathProblem> {
    if path.is_empty() {
        return Err(PathProblem::Empty);
    }
    if path.contains('\0') {
        return Err(PathProblem::Nul);
    }
    for c in Path::new(path).components() {
        match c {
            Component::Prefix(_) | Component::RootDir => return Err(PathProblem::Absolute),
            Component::ParentDir => return Err(PathProblem::Parent),
            Component::CurDir | Component::Normal(_) => {}
        }
    }
    Ok(())
}

/// The path of `rel` inside `dir`, once it is known to stay there: [`check_relative`], then,
/// for the part of it that exists on disk, the place its symbolic links lead to must be inside
/// `dir` as well (what does not exist yet has no link to follow, and cannot go up). A link
/// whose target does not exist is refused: writing through it would create that target.
pub fn confine(dir: &Path, rel: &str) -> Result<PathBuf, PathProblem> {
    check_relative(rel)?;
    let path = dir.join(rel);
    // A directory that does not exist holds no link.
    let Ok(root) = dir.canonicalize() else {
        return Ok(path);
    };
    // The longest part of the path that exists (as a link or not).
    let mut existing = path.as_path();
    while existing.symlink_metadata().is_err() {
        match existing.parent() {
            Some(p) => existing = p,
            None => return Ok(path),
        }
    }
    match existing.canonicalize() {
        Ok(real) if real.starts_with(&root) => Ok(path),
        Ok(real) => Err(PathProblem::Escapes(real)),
        Err(_) => Err(PathProblem::Escapes(
            std::fs::read_link(existing).unwrap_or_else(|_| existing.to_path_buf()),
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_paths_without_parent_components_pass() {
        for ok in ["a.pn", "nets/a.pn", "./a.pn", "a..b.pn", "..a.pn"] {
            assert_eq!(check_relative(ok), Ok(()), "{ok}");
        }
        assert_eq!(check_relative(""), Err(PathProblem::Empty));
        assert_eq!(check_relative("/etc/passwd"), Err(PathProblem::Absolute));
        assert_eq!(check_relative("../a.pn"), Err(PathProblem::Parent));
        assert_eq!(check_relative("nets/../../a.pn"), Err(PathProblem::Parent));
        assert_eq!(check_relative("a\0.pn"), Err(PathProblem::Nul));
    }

    #[cfg(unix)]
    #[test]
    fn symbolic_links_leading_out_are_refused() {
        let outside = tempfile::tempdir().unwrap();
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(outside.path().join("victim"), "x").unwrap();
        std::fs::write(dir.path().join("real.pn"), "x").unwrap();
        std::os::unix::fs::symlink(outside.path().join("victim"), dir.path().join("a.pn")).unwrap();
        std::os::unix::fs::symlink(outside.path(), dir.path().join("sub")).unwrap();
        std::os::unix::fs::symlink(dir.path().join("real.pn"), dir.path().join("in.pn")).unwrap();
        std::os::unix::fs::symlink(outside.path().join("nothing"), dir.path().join("dangling"))
            .unwrap();
        assert!(matches!(
            confine(dir.path(), "a.pn"),
            Err(PathProblem::Escapes(_))
        ));
        // Through a linked directory, even to a file that does not exist yet.
        assert!(matches!(
            confine(dir.path(), "sub/new.pn"),
            Err(PathProblem::Escapes(_))
        ));
        assert!(matches!(
            confine(dir.path(), "dangling"),
            Err(PathProblem::Escapes(_))
        ));
        // A link inside the directory, and files yet to be written, are fine.
        assert!(confine(dir.path(), "in.pn").is_ok());
        assert!(confine(dir.path(), "new/dir/b.pn").is_ok());
        assert!(confine(&dir.path().join("not-yet"), "b.pn").is_ok());
    }
}
