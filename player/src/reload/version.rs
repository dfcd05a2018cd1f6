//! The player's side of a reload (docs/reload.md): reading and checking the new version from
//! its directory, keeping its files beside the journal, reading them back for replay and
//! `--resume`. The mapping and the verification are [`petrel_nets::reload`]'s.
//!
//! A version kept is `project-<hash>/` beside the journal, written whole or not at all. The
//! compiled project of a version that runs is leaked on purpose ([`leak`]): the engine and the
//! step record borrow it, and reloads are few.

use petrel_nets::compiled::CompiledProject;
use petrel_nets::reload::{source_digest, Mapping};
use std::path::{Path, PathBuf};

/// A new version of the project, read and checked, not yet running.
pub struct Candidate {
    /// The compiled project.
    pub project: CompiledProject,
    /// Its files, `(path, text)`, the manifest first.
    pub files: Vec<(String, String)>,
    /// Their content hash.
    pub source_hash: String,
    /// The mapping file's text, and what it says.
    pub mapping_text: String,
    /// The mapping.
    pub mapping: Mapping,
}

/// Reads the project in `dir`, checks it and its content hash against `expected` (empty: not
/// checked), and reads the mapping: the candidate, or every reason it is not one.
pub fn load_candidate(dir: &Path, expected: &str, mapping: &str) -> Result<Candidate, Vec<String>> {
    let mapping_parsed = Mapping::parse(mapping).map_err(|e| vec![format!("mapping file:{e}")])?;
    let (loaded, compiled, diagnostics) = petrel_nets::project::load_and_check(dir)
        .map_err(|e| vec![format!("cannot read the new version: {e}")])?;
    let files = loaded.source_files();
    let source_hash = source_digest(files.iter().map(|(p, t)| (p.as_str(), t.as_str())));
    if !expected.is_empty() && source_hash != expected {
        return Err(vec![format!(
            "the files in {} changed between `petrel reload` reading them (content hash {expected}) and the player reading them ({source_hash}): run it again",
            dir.display()
        )]);
    }
    let Some(project) = compiled else {
        let mut reasons: Vec<String> = diagnostics
            .iter()
            .filter(|d| d.severity == petrel_nets::diag::Severity::Error)
            .take(20)
            .map(|d| {
                let at = d.span.map(|s| {
                    let f = loaded.sources.get(s.file);
                    format!("{}:{}: ", f.name, f.line_col(s.start as usize))
                });
                format!("{}error[{}]: {}", at.unwrap_or_default(), d.code, d.message)
            })
            .collect();
        reasons.insert(0, "the new version does not check".to_string());
        return Err(reasons);
    };
    Ok(Candidate {
        project,
        files,
        source_hash,
        mapping_text: mapping.to_string(),
        mapping: mapping_parsed,
    })
}

/// The directory beside the journal in `journal` that keeps the version of content hash
/// `hash`.
pub fn kept_dir(journal: &Path, hash: &str) -> PathBuf {
    journal.join(format!("project-{hash}"))
}

/// Keeps `files` beside the journal in `journal`, in `project-<hash>/` (written in a temporary
/// directory then renamed, so that a crash never leaves half a version; kept as it is when it
/// is there already). Every path stays inside (the checker confined them).
pub fn keep(journal: &Path, hash: &str, files: &[(String, String)]) -> std::io::Result<PathBuf> {
    let target = kept_dir(journal, hash);
    if target.join(petrel_nets::project::MANIFEST).is_file() {
        return Ok(target);
    }
    let tmp = journal.join(format!(".project-{hash}.{}", std::process::id()));
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp)?;
    }
    std::fs::create_dir_all(&tmp)?;
    for (path, text) in files {
        let to = petrel_nets::paths::confine(&tmp, path).map_err(|why| {
            std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!("`{path}` would leave the kept copy: {why}"),
            )
        })?;
        if let Some(parent) = to.parent() {
            std::fs::create_dir_all(parent)?;
        }
        std::fs::write(&to, text)?;
    }
    std::fs::rename(&tmp, &target)?;
    Ok(target)
}

/// Reads the version of content hash `hash` kept beside the journal in `journal`, and checks
/// that its files still hash to it.
pub fn load_kept(journal: &Path, hash: &str) -> Result<CompiledProject, String> {
    let dir = kept_dir(journal, hash);
    let c = load_candidate(&dir, "", "")
        .map_err(|r| format!("the version kept in {}: {}", dir.display(), r.join("; ")))?;
    if c.source_hash != hash {
        return Err(format!(
            "the version kept in {} hashes to {}, not {hash}: its files changed since the reload",
            dir.display(),
            c.source_hash
        ));
    }
    Ok(c.project)
}

/// A project for the rest of the process's life: the engine and the step record borrow the
/// project they run, and a reloaded version must outlive them. Reloads are rare (a few per
/// mission), so the few compiled projects are simply never freed.
pub fn leak(project: CompiledProject) -> &'static CompiledProject {
    Box::leak(Box::new(project))
}
