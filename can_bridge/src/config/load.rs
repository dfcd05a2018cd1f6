//! Finding `can.toml` and its DBC in a project directory, for `petrel check` and `petrel bridge`.

use std::path::Path;

use petrel_diag::report::{Diagnostic, Diagnostics};
use petrel_diag::source::{SourceMap, Span};
use petrel_nets::compiled::CompiledProject;
use serde::Deserialize;
use toml::Spanned;

use super::{check_rules, CanConfig};
use crate::dbc::{Dbc, DbcErrorKind};

/// The name of the CAN configuration file in a project directory.
pub const CAN_TOML: &str = "can.toml";

/// Reads the project's `can.toml` (if `dir` has one) and the DBC it names, checks them and
/// returns both. The files are added to `sources` so that their diagnostics render like the
/// nets'. `Ok(None)` when the project has no `can.toml`; `Err` only when a file exists but
/// cannot be read. A DBC that does not parse is E0702 (at its error when the parser locates
/// it, else at the `dbc` value).
pub fn load_project_can(
    dir: &Path,
    project: &CompiledProject,
    sources: &mut SourceMap,
    diags: &mut Diagnostics,
) -> std::io::Result<Option<(CanConfig, Dbc)>> {
    let path = dir.join(CAN_TOML);
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(e),
    };
    let file = sources.add(path.display().to_string(), text.clone());
    let dbc_name = match toml::from_str::<DbcOnly>(&text) {
        Ok(d) => d.dbc,
        Err(_) => {
            // Not valid TOML: check_rules reports it.
            let _ = check_rules(file, &text, &Dbc::empty(), project, diags);
            return Ok(None);
        }
    };
    let Some(dbc_name) = dbc_name else {
        diags.push(
            Diagnostic::error(
                "E0701",
                Span::new(file, 0, 0),
                "can.toml does not name its DBC file",
            )
            .label("no `dbc`")
            .help(
                "add `dbc = \"vehicle.dbc\"` at the top, a path relative to the project directory",
            ),
        );
        return Ok(None);
    };
    let dbc_path = match petrel_diag::paths::confine(dir, dbc_name.get_ref()) {
        Ok(p) => p,
        Err(why) => {
            diags.push(
                Diagnostic::error(
                    "E0711",
                    Span::new(file, dbc_name.span().start, dbc_name.span().end),
                    format!(
                        "the DBC file `{}` is outside the project directory: {why}",
                        dbc_name.get_ref().escape_debug()
                    ),
                )
                .label("named here")
                .help("keep the DBC in the project directory and name it relative to it, without `..`"),
            );
            return Ok(None);
        }
    };
    let dbc_text = match std::fs::read(&dbc_path) {
        Ok(b) => match String::from_utf8(b) {
            Ok(s) => s,
            Err(e) => e.into_bytes().iter().map(|&b| char::from(b)).collect(),
        },
        Err(e) => {
            diags.push(
                Diagnostic::error(
                    "E0702",
                    Span::new(file, dbc_name.span().start, dbc_name.span().end),
                    format!("cannot read the DBC file `{}`: {e}", dbc_path.display()),
                )
                .label("named here")
                .help("the path is relative to the project directory"),
            );
            return Ok(None);
        }
    };
    let dbc = match Dbc::parse(&dbc_text) {
        Ok(d) => d,
        Err(e) => {
            let help = match e.kind {
                DbcErrorKind::Syntax(_) => {
                    "fix the DBC file (cantools or a DBC editor can tell more)"
                }
                _ => {
                    "fix the DBC file: every signal must fit in its message, with a non-zero factor"
                }
            };
            let d = match e.offset {
                Some(at) => {
                    let dfile = sources.add(dbc_path.display().to_string(), dbc_text.clone());
                    let end = dbc_text[at..]
                        .find('\n')
                        .map_or(dbc_text.len(), |n| at + n)
                        .max(at);
                    Diagnostic::error(
                        "E0702",
                        Span::new(dfile, at, end),
                        format!("invalid DBC: {e}"),
                    )
                    .label("here")
                    .related(
                        Span::new(file, dbc_name.span().start, dbc_name.span().end),
                        "the DBC named here",
                    )
                }
                None => Diagnostic::error(
                    "E0702",
                    Span::new(file, dbc_name.span().start, dbc_name.span().end),
                    format!("invalid DBC: {e}"),
                )
                .label("this DBC"),
            };
            diags.push(d.help(help));
            return Ok(None);
        }
    };
    Ok(check_rules(file, &text, &dbc, project, diags).map(|c| (c, dbc)))
}

/// Only the `dbc` key of `can.toml`, with its span.
#[derive(Deserialize)]
struct DbcOnly {
    dbc: Option<Spanned<String>>,
}
