//! Reading a mission project from its directory, and writing one.

use crate::check;
use crate::compiled::CompiledProject;
use crate::fmt::format_file;
use crate::manifest::{format_manifest, parse_manifest};
use crate::model::Project;
use crate::syntax::parse_file;
use petrel_diag::report::{Diagnostic, Diagnostics};
use petrel_diag::source::{FileId, SourceMap};
use std::fmt;
use std::path::{Path, PathBuf};

/// The manifest's file name.
pub const MANIFEST: &str = "petrel.toml";

/// A project that cannot even be read: a usage or I/O problem (`petrel` exits 2).
#[derive(Debug)]
pub enum LoadError {
    /// The directory has no `petrel.toml`.
    NoManifest(PathBuf),
    /// A file could not be read.
    Io(PathBuf, std::io::Error),
}

impl fmt::Display for LoadError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LoadError::NoManifest(dir) => write!(
                f,
                "{} is not a Petrel project: it has no {MANIFEST} (give the project directory, the one holding {MANIFEST})",
                dir.display()
            ),
            LoadError::Io(p, e) => write!(f, "cannot read {}: {e}", p.display()),
        }
    }
}

impl std::error::Error for LoadError {}

/// A project read from disk, with its sources (for diagnostics) and what reading found.
#[derive(Debug)]
pub struct LoadedProject {
    /// The project directory.
    pub dir: PathBuf,
    /// The model.
    pub project: Project,
    /// Text of the manifest and of every net file read.
    pub sources: SourceMap,
    /// The manifest's file id.
    pub manifest_file: FileId,
    /// For each entry of `project.files`, its file id.
    pub file_ids: Vec<FileId>,
    /// Problems found while reading (syntax, missing files).
    pub diagnostics: Diagnostics,
}

fn display(dir: &Path, rel: &str) -> String {
    if dir == Path::new(".") || dir.as_os_str().is_empty() {
        rel.to_string()
    } else {
        dir.join(rel).display().to_string()
    }
}

/// Reads the manifest and every net file it names. Syntax errors and missing net files are
/// diagnostics; only a missing or unreadable manifest is a [`LoadError`].
pub fn load(dir: &Path) -> Result<LoadedProject, LoadError> {
    let manifest_path = dir.join(MANIFEST);
    if !manifest_path.is_file() {
        return Err(LoadError::NoManifest(dir.to_path_buf()));
    }
    let text = std::fs::read_to_string(&manifest_path)
        .map_err(|e| LoadError::Io(manifest_path.clone(), e))?;
    let mut sources = SourceMap::new();
    let mut diagnostics = Diagnostics::new();
    let manifest_file = sources.add(display(dir, MANIFEST), text.clone());
    let mut project = Project::default();
    let mut file_ids = Vec::new();
    if let Some(manifest) = parse_manifest(manifest_file, &text, &mut diagnostics) {
        // A net file lying in the project but not listed is most likely forgotten, or the
        // listed one renamed: E0104 and W0101 then name each other.
        let unlisted: Vec<String> = match std::fs::read_dir(dir) {
            Ok(entries) => {
                let mut extra: Vec<String> = entries
                    .filter_map(|e| e.ok())
                    .map(|e| e.file_name().to_string_lossy().into_owned())
                    .filter(|n| n.ends_with(".pn") && !manifest.files.iter().any(|f| &f.path == n))
                    .collect();
                extra.sort();
                extra
            }
            Err(_) => Vec::new(),
        };
        let mut unread: Vec<&str> = Vec::new();
        for f in &manifest.files {
            // Never read (and so never let `fmt` rewrite) a file outside the project.
            let path = match petrel_diag::paths::confine(dir, &f.path) {
                Ok(p) => p,
                Err(why @ petrel_diag::paths::PathProblem::Escapes(_)) => {
                    diagnostics.push(crate::manifest::outside_project(f, &why));
                    continue;
                }
                // What the text tells, parse_manifest reported.
                Err(_) => continue,
            };
            match std::fs::read_to_string(&path) {
                Ok(text) => {
                    let id = sources.add(display(dir, &f.path), text.clone());
                    project
                        .files
                        .push(parse_file(id, &f.path, &text, &mut diagnostics));
                    file_ids.push(id);
                }
                Err(e) => {
                    let why = if e.kind() == std::io::ErrorKind::NotFound {
                        "does not exist".to_string()
                    } else {
                        format!("cannot be read: {e}")
                    };
                    unread.push(&f.path);
                    let renamed = match close_file(&f.path, &unlisted) {
                        Some(n) => format!(
                            "did you mean \"{n}\"? It is in the project directory and not listed (W0101); "
                        ),
                        None => String::new(),
                    };
                    diagnostics.push(
                        Diagnostic::error(
                            "E0104",
                            f.span,
                            format!("net file `{}` {why}", path.display()),
                        )
                        .label("named here")
                        .help(format!(
                            "{renamed}create it, or correct the path: paths are relative to the project directory {}",
                            dir.display()
                        )),
                    );
                }
            }
        }
        {
            for n in unlisted {
                let listed: Vec<String> = unread.iter().map(|u| u.to_string()).collect();
                let help = match close_file(&n, &listed) {
                    Some(u) => format!(
                        "the manifest lists \"{u}\", which could not be read (E0104): if \"{n}\" is that file renamed, correct the entry"
                    ),
                    None => format!(
                        "add \"{n}\" to `files` in [project], or move it out of the project"
                    ),
                };
                diagnostics.push(
                    Diagnostic::warning(
                        "W0101",
                        petrel_diag::source::Span::new(manifest_file, 0, 0),
                        format!("net file `{n}` is in the project directory but not in `files`"),
                    )
                    .label("the manifest's file list")
                    .help(help),
                );
            }
        }
        project.manifest = manifest;
    }
    Ok(LoadedProject {
        dir: dir.to_path_buf(),
        project,
        sources,
        manifest_file,
        file_ids,
        diagnostics,
    })
}

impl LoadedProject {
    /// The project's source files as `(path, text)`: the manifest, then each net file read,
    /// in the manifest's order (what [`crate::reload::source_digest`] hashes, and what a
    /// reload keeps beside the journal).
    pub fn source_files(&self) -> Vec<(String, String)> {
        let mut out = vec![(
            MANIFEST.to_string(),
            self.sources.get(self.manifest_file).text.clone(),
        )];
        for (f, id) in self.project.files.iter().zip(&self.file_ids) {
            out.push((f.path.clone(), self.sources.get(*id).text.clone()));
        }
        out
    }
}

/// Reads and checks a project: every finding, sorted, and the compiled project if it has no
/// error.
pub fn load_and_check(
    dir: &Path,
) -> Result<(LoadedProject, Option<CompiledProject>, Diagnostics), LoadError> {
    let loaded = load(dir)?;
    let mut all = loaded.diagnostics.clone();
    // Checking a project whose manifest could not be read would only add noise.
    let manifest_ok = !all
        .iter()
        .any(|d| d.code == "E0101" && d.span.map(|s| s.file) == Some(loaded.manifest_file));
    if !manifest_ok {
        return Ok((loaded, None, all));
    }
    let (compiled, found) = check::check(&loaded.project);
    all.extend(found);
    all.sort();
    let compiled = if all.has_errors() { None } else { compiled };
    Ok((loaded, compiled, all))
}

/// Writes a project (manifest and net files, in canonical layout) into `dir`, creating it.
///
/// Every net file path must stay inside `dir` ([`petrel_diag::paths::confine`]): otherwise nothing is
/// written and the error (`InvalidInput`) names the path. Readers report such paths as
/// diagnostics first (E0109, E0508); this is the last guard.
pub fn write(dir: &Path, project: &Project) -> std::io::Result<()> {
    let mut paths = Vec::new();
    for f in &project.files {
        paths.push(confined(dir, &f.path)?);
    }
    let manifest = confined(dir, MANIFEST)?;
    std::fs::create_dir_all(dir)?;
    std::fs::write(manifest, format_manifest(&project.manifest))?;
    for (f, path) in project.files.iter().zip(paths) {
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent)?;
        }
        std::fs::write(path, format_file(f))?;
    }
    Ok(())
}

/// Rewrites one net file of the project in `dir` (what `petrel fmt` does), only if its path
/// stays inside `dir`.
pub fn write_net_file(dir: &Path, rel: &str, text: &str) -> std::io::Result<()> {
    std::fs::write(confined(dir, rel)?, text)
}

fn confined(dir: &Path, rel: &str) -> std::io::Result<PathBuf> {
    petrel_diag::paths::confine(dir, rel).map_err(|why| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!(
                "`{}` is outside {}: {why}",
                rel.escape_debug(),
                dir.display()
            ),
        )
    })
}

/// Reads and checks a project held in memory: a manifest and `(path, text)` net files (the
/// manifest's `files` must name them). For tests and tools that build projects on the fly.
pub fn from_sources(
    manifest: &str,
    files: &[(&str, &str)],
) -> (Project, Option<CompiledProject>, Diagnostics, SourceMap) {
    let mut sources = SourceMap::new();
    let mut d = Diagnostics::new();
    let mid = sources.add(MANIFEST, manifest);
    let mut project = Project::default();
    if let Some(m) = parse_manifest(mid, manifest, &mut d) {
        for f in &m.files {
            match files.iter().find(|(p, _)| *p == f.path) {
                Some((path, text)) => {
                    let id = sources.add(*path, *text);
                    project.files.push(parse_file(id, path, text, &mut d));
                }
                None => d.push(
                    Diagnostic::error(
                        "E0104",
                        f.span,
                        format!("net file `{}` is not given", f.path),
                    )
                    .label("named here")
                    .help("pass it along with the manifest"),
                ),
            }
        }
        project.manifest = m;
    }
    if d.has_errors() {
        return (project, None, d, sources);
    }
    let (compiled, found) = check::check(&project);
    d.extend(found);
    (project, compiled, d, sources)
}

/// The one of `files` whose name is close to `name` (a file renamed, or misspelt in the
/// manifest), by the same measure as the "did you mean" of names.
fn close_file<'a>(name: &str, files: &'a [String]) -> Option<&'a str> {
    let best = files
        .iter()
        .map(|f| (petrel_diag::names::distance(name, f), f.as_str()))
        .min()?;
    (best.0 <= 2.max(name.len() / 3)).then_some(best.1)
}
