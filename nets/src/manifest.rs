//! The manifest, `petrel.toml`: reading it into [`Manifest`] and writing it back.
//!
//! ```toml
//! [project]
//! name = "uav"
//! files = ["mission.pn", "events.pn"]   # dispatch order of the nets
//! start = ["MISSION", "EVENTS"]         # nets active when the mission starts
//!
//! [globals]                             # places shared by every net
//! engine_ok = 1
//!
//! [events]
//! start_mission = { category = "nominal" }
//! payload_failure = { category = "mission", params = ["payload: text"] }
//!
//! [programs.DEC]
//! functions = { next_waypoint = [], replan = ["without: text"] }
//!
//! [timers]
//! answer_timer = { event = "answer_timeout" }
//! ```
//!
//! TOML structure errors stop reading (the TOML parser reports one at a time); everything
//! written inside strings (names, types, categories) is checked here and reported all at once.

use crate::diag::{Diagnostic, Diagnostics};
use crate::model::*;
use crate::source::{FileId, Span};
use serde::de::{Deserialize, Deserializer, MapAccess, Visitor};
use std::fmt::Write as _;
use toml::Spanned;

/// A TOML table read in document order, each key with its span: serde's maps forget the order
/// (meaningful for nets, events, rules...) and the keys' places (where diagnostics point).
/// `can.toml`'s reader uses it too.
pub struct Ordered<V>(pub Vec<(Spanned<String>, V)>);

impl<V> Default for Ordered<V> {
    fn default() -> Self {
        Ordered(Vec::new())
    }
}

impl<'de, V: Deserialize<'de>> Deserialize<'de> for Ordered<V> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V2<V>(std::marker::PhantomData<V>);
        impl<'de, V: Deserialize<'de>> Visitor<'de> for V2<V> {
            type Value = Ordered<V>;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a table")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
                let mut out = Vec::new();
                while let Some((k, v)) = map.next_entry()? {
                    out.push((k, v));
                }
                Ok(Ordered(out))
            }
        }
        d.deserialize_map(V2(std::marker::PhantomData))
    }
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RawManifest {
    project: RawProject,
    #[serde(default)]
    globals: Ordered<Spanned<i64>>,
    #[serde(default)]
    events: Ordered<RawEvent>,
    #[serde(default)]
    programs: Ordered<RawProgram>,
    #[serde(default)]
    timers: Ordered<RawTimer>,
    #[serde(default)]
    verify: RawVerify,
}

#[derive(serde::Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawVerify {
    #[serde(default, rename = "final")]
    finals: Vec<Vec<Spanned<String>>>,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RawProject {
    name: String,
    description: Option<String>,
    files: Vec<Spanned<String>>,
    #[serde(default)]
    start: Vec<Spanned<String>>,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RawEvent {
    category: Spanned<String>,
    #[serde(default)]
    params: Vec<Spanned<String>>,
    description: Option<String>,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RawProgram {
    description: Option<String>,
    #[serde(default)]
    functions: Ordered<Vec<Spanned<String>>>,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTimer {
    event: Spanned<String>,
}

struct Reader<'d> {
    file: FileId,
    diags: &'d mut Diagnostics,
}

impl Reader<'_> {
    fn span(&self, r: std::ops::Range<usize>) -> Span {
        Span::new(self.file, r.start, r.end)
    }

    /// A name from a TOML key or string; the span points inside the quotes when there are some.
    fn name(&mut self, s: &Spanned<String>, what: &str, text: &str) -> Name {
        let mut r = s.span();
        let raw = &text[r.clone()];
        if raw.starts_with('"') || raw.starts_with('\'') {
            r = r.start + 1..r.end.saturating_sub(1).max(r.start + 1);
        }
        let name = Name {
            text: s.get_ref().clone(),
            span: self.span(r),
        };
        if !is_identifier(&name.text) {
            self.diags.push(
                Diagnostic::error("E0105", name.span, format!("`{name}` is not a valid {what} name"))
                    .label("not a name")
                    .help("names start with a letter or `_` and hold only ASCII letters, digits and `_` (not `true` or `false`)"),
            );
        }
        name
    }

    /// A parameter written `name: type`.
    fn param(&mut self, s: &Spanned<String>, text: &str) -> Option<Param> {
        let r = s.span();
        let inner = r.start + 1; // past the opening quote
        let v = s.get_ref();
        let Some((n, t)) = v.split_once(':') else {
            self.diags.push(
                Diagnostic::error("E0103", self.span(r), format!("parameter `{v}` has no type"))
                    .label("expected `name: type`")
                    .help("write parameters as \"name: type\", with type int, float, bool, text or [float]"),
            );
            return None;
        };
        let name_text = n.trim();
        let lead = n.len() - n.trim_start().len();
        let name_span = self.span(inner + lead..inner + lead + name_text.len());
        let raw = &text[r.clone()];
        // Positions inside a string are exact only when it holds no escapes.
        let exact = !raw.contains('\\');
        let name_span = if exact {
            name_span
        } else {
            self.span(r.clone())
        };
        if !is_identifier(name_text) {
            self.diags.push(
                Diagnostic::error(
                    "E0105",
                    name_span,
                    format!("`{name_text}` is not a valid parameter name"),
                )
                .label("not a name")
                .help(
                    "names start with a letter or `_` and hold only ASCII letters, digits and `_`",
                ),
            );
        }
        let ty_text = t.trim();
        let ty_start = inner + n.len() + 1 + (t.len() - t.trim_start().len());
        let ty_span = if exact {
            self.span(ty_start..ty_start + ty_text.len())
        } else {
            self.span(r)
        };
        let Some(ty) = Type::from_keyword(ty_text) else {
            self.diags.push(
                Diagnostic::error("E0103", ty_span, format!("unknown type `{ty_text}`"))
                    .label("not a type")
                    .help("the types are int, float, bool, text and [float]"),
            );
            return None;
        };
        Some(Param {
            name: Name {
                text: name_text.to_string(),
                span: name_span,
            },
            ty,
        })
    }

    fn params(&mut self, list: &[Spanned<String>], text: &str) -> Vec<Param> {
        list.iter().filter_map(|p| self.param(p, text)).collect()
    }
}

/// Where a TOML parse error is and what it says, on one line: for the manifest and for every
/// other TOML file of a project (can.toml).
pub fn toml_error(file: FileId, e: &toml::de::Error) -> (Span, String) {
    let span = e
        .span()
        .map(|r| Span::new(file, r.start, r.end))
        .unwrap_or(Span::new(file, 0, 0));
    let msg = e
        .message()
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect::<Vec<_>>()
        .join(": ");
    (span, msg)
}

/// Reads a manifest. Problems go to `diags`; `None` only when the TOML cannot be read at all.
pub fn parse_manifest(file: FileId, text: &str, diags: &mut Diagnostics) -> Option<Manifest> {
    let raw: RawManifest = match toml::from_str(text) {
        Ok(r) => r,
        Err(e) => {
            let (span, msg) = toml_error(file, &e);
            diags.push(
                Diagnostic::error("E0101", span, format!("the manifest is not valid: {msg}"))
                    .label(msg)
                    .help("the manifest has a [project] table (name, files, start) and optional [globals], [events], [programs.NAME] and [timers] tables; see docs/language.md"),
            );
            return None;
        }
    };
    let mut r = Reader { file, diags };
    let mut m = Manifest {
        name: raw.project.name.clone(),
        description: raw.project.description.clone(),
        ..Manifest::default()
    };
    for f in &raw.project.files {
        let file = FileRef {
            path: f.get_ref().clone(),
            span: r.span(f.span()),
        };
        if let Err(why) = crate::paths::check_relative(&file.path) {
            r.diags.push(outside_project(&file, &why));
        }
        m.files.push(file);
    }
    for s in &raw.project.start {
        m.start.push(r.name(s, "net", text));
    }
    for (k, v) in &raw.globals.0 {
        let name = r.name(k, "place", text);
        let tokens = *v.get_ref();
        if !(0..=1).contains(&tokens) {
            r.diags.push(
                Diagnostic::error(
                    "E0405",
                    r.span(v.span()),
                    format!("global place `{name}` starts with {tokens} tokens"),
                )
                .label("a place holds 0 or 1 token")
                .help("Petrel nets are safe: write 1 for a marked place or 0 for an empty one"),
            );
        }
        m.globals.push(GlobalPlaceDecl {
            name,
            tokens: tokens.clamp(0, u32::MAX as i64) as u32,
        });
    }
    for (k, v) in &raw.events.0 {
        let name = r.name(k, "event", text);
        let category = match Category::from_keyword(v.category.get_ref()) {
            Some(c) => c,
            None => {
                r.diags.push(
                    Diagnostic::error(
                        "E0102",
                        r.span(v.category.span()),
                        format!("unknown event category `{}`", v.category.get_ref()),
                    )
                    .label("not a category")
                    .help("the categories are catastrophic, safety, mission, communication and nominal (highest priority first)"),
                );
                Category::Nominal
            }
        };
        let params = r.params(&v.params, text);
        m.events.push(EventDecl {
            name,
            category,
            params,
            description: v.description.clone(),
        });
    }
    for (k, v) in &raw.programs.0 {
        let name = r.name(k, "program", text);
        let mut functions = Vec::new();
        for (fk, fv) in &v.functions.0 {
            let fname = r.name(fk, "function", text);
            let params = r.params(fv, text);
            functions.push(FunctionDecl {
                name: fname,
                params,
            });
        }
        m.programs.push(ProgramDecl {
            name,
            description: v.description.clone(),
            functions,
        });
    }
    for (k, v) in &raw.timers.0 {
        let name = r.name(k, "timer", text);
        let event = r.name(&v.event, "event", text);
        m.timers.push(TimerDecl { name, event });
    }
    for places in &raw.verify.finals {
        // `NET.place` is not an identifier: keep the text, the checker resolves it.
        let names = places
            .iter()
            .map(|s| {
                let mut r2 = s.span();
                if text[r2.clone()].starts_with('"') {
                    r2 = r2.start + 1..r2.end.saturating_sub(1);
                }
                Name {
                    text: s.get_ref().clone(),
                    span: r.span(r2),
                }
            })
            .collect();
        m.finals.push(names);
    }
    Some(m)
}

/// E0107: a net file path of the manifest that would leave the project directory.
pub(crate) fn outside_project(f: &FileRef, why: &crate::paths::PathProblem) -> Diagnostic {
    Diagnostic::error(
        "E0107",
        f.span,
        format!(
            "net file `{}` is outside the project directory: {why}",
            f.path.escape_debug()
        ),
    )
    .label("not a path inside the project")
    .help("net files live in the project directory: name them relative to it, without `..`, and not through a link that leads out")
}

fn toml_str(s: &str) -> String {
    toml::Value::String(s.to_string()).to_string()
}

fn toml_key(s: &str) -> String {
    if !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
    {
        s.to_string()
    } else {
        toml_str(s)
    }
}

fn param_list(params: &[Param]) -> String {
    let items: Vec<String> = params
        .iter()
        .map(|p| toml_str(&format!("{}: {}", p.name, p.ty)))
        .collect();
    format!("[{}]", items.join(", "))
}

/// The canonical text of a manifest (used when importing PNML into a new project).
pub fn format_manifest(m: &Manifest) -> String {
    let mut out = String::from("[project]\n");
    let _ = writeln!(out, "name = {}", toml_str(&m.name));
    if let Some(d) = &m.description {
        let _ = writeln!(out, "description = {}", toml_str(d));
    }
    let files: Vec<String> = m.files.iter().map(|f| toml_str(&f.path)).collect();
    let _ = writeln!(out, "files = [{}]", files.join(", "));
    let start: Vec<String> = m.start.iter().map(|n| toml_str(&n.text)).collect();
    let _ = writeln!(out, "start = [{}]", start.join(", "));
    if !m.globals.is_empty() {
        out.push_str("\n[globals]\n");
        for g in &m.globals {
            let _ = writeln!(out, "{} = {}", toml_key(&g.name.text), g.tokens);
        }
    }
    if !m.events.is_empty() {
        out.push_str("\n[events]\n");
        for e in &m.events {
            let mut fields = vec![format!("category = {}", toml_str(e.category.keyword()))];
            if !e.params.is_empty() {
                fields.push(format!("params = {}", param_list(&e.params)));
            }
            if let Some(d) = &e.description {
                fields.push(format!("description = {}", toml_str(d)));
            }
            let _ = writeln!(
                out,
                "{} = {{ {} }}",
                toml_key(&e.name.text),
                fields.join(", ")
            );
        }
    }
    for p in &m.programs {
        let _ = write!(out, "\n[programs.{}]\n", toml_key(&p.name.text));
        if let Some(d) = &p.description {
            let _ = writeln!(out, "description = {}", toml_str(d));
        }
        let _ = writeln!(out, "[programs.{}.functions]", toml_key(&p.name.text));
        for f in &p.functions {
            let _ = writeln!(
                out,
                "{} = {}",
                toml_key(&f.name.text),
                param_list(&f.params)
            );
        }
    }
    if !m.finals.is_empty() {
        out.push_str("\n[verify]\nfinal = [\n");
        for f in &m.finals {
            let places: Vec<String> = f.iter().map(|n| toml_str(&n.text)).collect();
            let _ = writeln!(out, "    [{}],", places.join(", "));
        }
        out.push_str("]\n");
    }
    if !m.timers.is_empty() {
        out.push_str("\n[timers]\n");
        for t in &m.timers {
            let _ = writeln!(
                out,
                "{} = {{ event = {} }}",
                toml_key(&t.name.text),
                toml_str(&t.event.text)
            );
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::source::SourceFile;

    const TEXT: &str = r#"
[project]
name = "t"
files = ["a.pn"]
start = ["A"]

[globals]
ok = 1
z = 0

[events]
go = { category = "nominal" }
alarm = { category = "catastrophic", params = ["reason: text", "where: [float]"] }

[programs.PLN]
functions = { plan = ["n: int"], stop = [] }

[timers]
t1 = { event = "go" }
"#;

    #[test]
    fn reads_in_document_order_and_writes_back_the_same_manifest() {
        let mut d = Diagnostics::new();
        let m = parse_manifest(FileId(0), TEXT, &mut d).expect("manifest reads");
        assert!(d.is_empty(), "{d:?}");
        let names: Vec<_> = m.globals.iter().map(|g| g.name.text.as_str()).collect();
        assert_eq!(names, ["ok", "z"]);
        assert_eq!(m.events[1].params[1].ty, Type::FloatList);
        assert_eq!(m.events[1].category, Category::Catastrophic);
        let fns: Vec<_> = m.programs[0]
            .functions
            .iter()
            .map(|f| f.name.text.as_str())
            .collect();
        assert_eq!(fns, ["plan", "stop"]);
        let again = parse_manifest(FileId(0), &format_manifest(&m), &mut d).unwrap();
        assert!(d.is_empty(), "{d:?}");
        assert_eq!(m, again);
    }

    #[test]
    fn type_errors_point_inside_the_string() {
        let text = TEXT.replace("n: int", "n: integer");
        let mut d = Diagnostics::new();
        parse_manifest(FileId(0), &text, &mut d).unwrap();
        let e = d.iter().next().expect("an error");
        assert_eq!(e.code, "E0103");
        let f = SourceFile::new("m", text.as_str());
        let s = e.span.unwrap();
        assert_eq!(&text[s.start as usize..s.end as usize], "integer");
        assert_eq!(f.line_col(s.start as usize).line, 16);
    }
}
