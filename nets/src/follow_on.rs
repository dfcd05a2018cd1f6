//! Errors that follow from a net file the manifest names and that could not be read (E0104):
//! the nets and places it declares are unknown to the rest of the project, so `start`,
//! `activate`, final markings and formulas naming them give E0202, E0208 and E0211. Each such
//! error says it may follow from the missing file, so that the root error is fixed first
//! (a renamed file: E0104 and W0101 name each other, see `project.rs`).

use crate::model::Project;
use petrel_diag::report::Diagnostics;

/// The codes of unknown nets and places a missing net file can cause.
const FOLLOW_ON: [&str; 4] = ["E0201", "E0202", "E0208", "E0211"];

/// `d` with the help of each error of [`FOLLOW_ON`] naming the net files of the manifest that
/// could not be read, when there are any.
pub(crate) fn link_to_missing_files(project: &Project, d: Diagnostics) -> Diagnostics {
    let missing: Vec<String> = project
        .manifest
        .files
        .iter()
        .filter(|f| !project.files.iter().any(|n| n.path == f.path))
        .map(|f| format!("`{}`", f.path))
        .collect();
    if missing.is_empty() {
        return d;
    }
    let mut out = Diagnostics::new();
    for x in d.iter() {
        let mut x = x.clone();
        if FOLLOW_ON.contains(&x.code) {
            let why = format!(
                "this may follow from net file {} that could not be read (E0104): fix that first",
                missing.join(", ")
            );
            x.help = Some(match x.help {
                Some(h) => format!("{h}; {why}"),
                None => why,
            });
        }
        out.push(x);
    }
    out
}
