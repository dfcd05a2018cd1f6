//! How to build an executable a vehicle file names and that is missing: the exact cargo command
//! for the binary or example `petrel up` looked for, with the profile of the running `petrel`.
//!
//! `{target}` in a vehicle file is the running petrel's directory (`target/release` for a
//! release build): an executable there was built by the same workspace with the same profile,
//! as a binary (`{target}/NAME`) or an example (`{target}/examples/NAME`). The package that
//! holds it is asked of cargo (`cargo metadata --no-deps`, offline, a fraction of a second, and
//! only on this error path), in the workspace whose target directory is the running petrel's.

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

/// A binary or an example of a Cargo package.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Bin,
    Example,
}

impl Kind {
    fn flag(self) -> &'static str {
        match self {
            Kind::Bin => "--bin",
            Kind::Example => "--example",
        }
    }

    fn cargo_kind(self) -> &'static str {
        match self {
            Kind::Bin => "bin",
            Kind::Example => "example",
        }
    }
}

/// The hint for a missing `path` when the running petrel lives in `target` (the `{target}` of
/// vehicle files), or `None` when `path` is not a build output of that directory.
/// `project_dir` is where to look for the workspace first.
pub fn hint(path: &Path, target: &Path, project_dir: &Path) -> Option<String> {
    let name = path.file_name()?.to_str()?;
    let parent = path.parent()?;
    let kind = if parent == target {
        Kind::Bin
    } else if parent == target.join("examples") {
        Kind::Example
    } else {
        return None;
    };
    let profile = match target.file_name()?.to_str()? {
        "debug" => String::new(),
        "release" => " --release".to_string(),
        other => format!(" --profile {other}"),
    };
    let found = package_of(name, kind, target, project_dir);
    let package = found
        .as_ref()
        .map(|(p, _)| format!(" -p {p}"))
        .unwrap_or_default();
    let command = format!("cargo build{profile}{package} {} {name}", kind.flag());
    let place = match &found {
        Some((_, root)) => format!("in {}", root.display()),
        None => format!(
            "in the workspace that builds into {}",
            target.parent().unwrap_or(target).display()
        ),
    };
    Some(format!(
        "build it with the profile of this petrel: `{command}` ({place})"
    ))
}

/// The package (and its workspace's root) that has a `kind` target called `name`, in the
/// workspace whose target directory holds `target`.
fn package_of(
    name: &str,
    kind: Kind,
    target: &Path,
    project_dir: &Path,
) -> Option<(String, PathBuf)> {
    let target_dir = target.parent()?;
    // The project's workspace (missions inside the Petrel repository), then the one around
    // the target directory (`WORKSPACE/target/PROFILE`).
    let candidates = [project_dir, target_dir.parent().unwrap_or(target_dir)];
    candidates
        .iter()
        .filter_map(|dir| metadata(dir))
        .filter(|m| {
            m["target_directory"]
                .as_str()
                .is_some_and(|t| same_dir(Path::new(t), target_dir))
        })
        .find_map(|m| {
            let root = PathBuf::from(m["workspace_root"].as_str()?);
            let package = m["packages"].as_array()?.iter().find(|p| {
                p["targets"].as_array().is_some_and(|ts| {
                    ts.iter().any(|t| {
                        t["name"] == name
                            && t["kind"]
                                .as_array()
                                .is_some_and(|k| k.iter().any(|k| k == kind.cargo_kind()))
                    })
                })
            })?;
            Some((package["name"].as_str()?.to_string(), root))
        })
}

/// `cargo metadata --no-deps` run in `dir`, if cargo is there and `dir` is in a workspace.
fn metadata(dir: &Path) -> Option<Value> {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let out = Command::new(cargo)
        .args([
            "metadata",
            "--no-deps",
            "--format-version",
            "1",
            "--offline",
        ])
        .current_dir(dir)
        .stdin(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .output()
        .ok()?;
    if !out.status.success() {
        return None;
    }
    serde_json::from_slice(&out.stdout).ok()
}

fn same_dir(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => a == b,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_outputs_of_the_target_directory_get_a_cargo_command() {
        let target = Path::new("/nowhere/target/release");
        let project = Path::new("/nowhere/project");
        assert_eq!(hint(Path::new("/usr/bin/x"), target, project), None);
        let bin = hint(&target.join("prog"), target, project).unwrap();
        assert!(bin.contains("`cargo build --release --bin prog`"), "{bin}");
        let example = hint(&target.join("examples/ex"), target, project).unwrap();
        assert!(
            example.contains("`cargo build --release --example ex`"),
            "{example}"
        );
        let debug = Path::new("/nowhere/target/debug");
        let d = hint(&debug.join("prog"), debug, project).unwrap();
        assert!(d.contains("`cargo build --bin prog`"), "{d}");
        let custom = Path::new("/nowhere/target/fast");
        let c = hint(&custom.join("prog"), custom, project).unwrap();
        assert!(c.contains("`cargo build --profile fast --bin prog`"), "{c}");
    }
}
