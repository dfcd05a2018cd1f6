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

use crate::model::*;
use petrel_diag::report::{Diagnostic, Diagnostics};
use petrel_diag::source::{FileId, Span};
use petrel_diag::toml::Ordered;
use std::fmt::Write as _;
use toml::Spanned;

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RawManifest {
    project: RawProject,
    #[serde(default)]
    globals: Ordered<Spanned<toml::Value>>,
    #[serde(default)]
    instances: Ordered<RawInstance>,
    #[serde(default)]
    invariants: Ordered<Spanned<String>>,
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
    #[serde(default, rename = "goal")]
    goals: Vec<Vec<Spanned<String>>>,
    #[serde(default)]
    progress_excludes: Option<Vec<Spanned<String>>>,
    #[serde(default)]
    bounds: Ordered<RawBound>,
}

/// `[verify.bounds]`: `NAME = { from = "leak", to = "EMERGENCY.surfacing", within = "1s" }`.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBound {
    from: Spanned<String>,
    to: Spanned<String>,
    within: Option<Spanned<String>>,
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
    #[serde(default)]
    internal: bool,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RawProgram {
    description: Option<String>,
    #[serde(default)]
    functions: Ordered<Spanned<toml::Value>>,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTimer {
    event: Spanned<String>,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RawInstance {
    net: Spanned<String>,
    #[serde(default)]
    args: Vec<Spanned<toml::Value>>,
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

    /// The parameters that read, and whether one did not (its error reported).
    fn params(&mut self, list: &[Spanned<String>], text: &str) -> (Vec<Param>, bool) {
        let read: Vec<Param> = list.iter().filter_map(|p| self.param(p, text)).collect();
        let unread = read.len() != list.len();
        (read, unread)
    }

    /// A TOML value written as an argument (an instance's): the same literals as in a net.
    fn expr(&mut self, v: &Spanned<toml::Value>) -> Option<Expr> {
        let span = self.span(v.span());
        Some(match v.get_ref() {
            toml::Value::Integer(i) => Expr::Int(*i, span),
            toml::Value::Float(f) if f.is_finite() => Expr::Float(*f, span),
            toml::Value::Boolean(b) => Expr::Bool(*b, span),
            toml::Value::String(t) => Expr::Text(t.clone(), span),
            toml::Value::Array(items) => {
                let mut out = Vec::new();
                for i in items {
                    match i {
                        toml::Value::Integer(n) => out.push(Expr::Int(*n, span)),
                        toml::Value::Float(f) if f.is_finite() => out.push(Expr::Float(*f, span)),
                        _ => return self.bad_argument(span),
                    }
                }
                Expr::List(out, span)
            }
            _ => return self.bad_argument(span),
        })
    }

    fn bad_argument(&mut self, span: Span) -> Option<Expr> {
        self.diags.push(
            Diagnostic::error(
                "E0101",
                span,
                "this argument is not a value of a net parameter",
            )
            .label("not an int, a finite float, a bool, a text or a list of numbers")
            .help("write arguments as in a net: 3, 2.5, true, \"text\", [1.0, 2.0]"),
        );
        None
    }
}

/// Where `needle` is quoted (`"needle"`) inside `range` of `text`, for names read from a TOML
/// value whose own span covers more than the name.
fn quoted_in(
    text: &str,
    range: std::ops::Range<usize>,
    needle: &str,
) -> Option<std::ops::Range<usize>> {
    let hay = text.get(range.clone())?;
    let quoted = format!("\"{needle}\"");
    hay.find(&quoted)
        .map(|i| range.start + i + 1..range.start + i + 1 + needle.len())
}

/// Reads a manifest. Problems go to `diags`; `None` only when the TOML cannot be read at all.
pub fn parse_manifest(file: FileId, text: &str, diags: &mut Diagnostics) -> Option<Manifest> {
    let raw: RawManifest = petrel_diag::toml::parse(
        file,
        text,
        "E0101",
        "the manifest",
        "the manifest has a [project] table (name, files, start) and optional [globals], [events], [programs.NAME] and [timers] tables; see docs/language.md",
        diags,
    )?;
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
        if let Err(why) = petrel_diag::paths::check_relative(&file.path) {
            r.diags.push(outside_project(&file, &why));
        }
        m.files.push(file);
    }
    for s in &raw.project.start {
        m.start.push(r.name(s, "net", text));
    }
    for (k, v) in &raw.globals.0 {
        let name = r.name(k, "place", text);
        // `x = 1`, or `x = { initial = 1, nets = ["A", "B"] }` for a group of nets.
        let (tokens, nets) = match v.get_ref() {
            toml::Value::Integer(t) => (*t, None),
            toml::Value::Table(t) => {
                let mut nets = Vec::new();
                let mut ok = true;
                for key in t.keys() {
                    if key != "initial" && key != "nets" {
                        ok = false;
                        r.diags.push(
                            Diagnostic::error("E0101", r.span(v.span()), format!("unknown key `{key}` in global place `{name}`"))
                                .label("not `initial` or `nets`")
                                .help("write `NAME = 0|1`, or `NAME = { initial = 0|1, nets = [\"NET\", ...] }`"),
                        );
                    }
                }
                let initial = match t.get("initial") {
                    Some(toml::Value::Integer(i)) => *i,
                    None => 0,
                    Some(_) => {
                        ok = false;
                        0
                    }
                };
                match t.get("nets") {
                    Some(toml::Value::Array(list)) => {
                        for item in list {
                            match item {
                                toml::Value::String(n) => {
                                    let range = quoted_in(text, v.span(), n).unwrap_or(v.span());
                                    nets.push(Name {
                                        text: n.clone(),
                                        span: r.span(range),
                                    });
                                }
                                _ => ok = false,
                            }
                        }
                    }
                    None => ok = false,
                    Some(_) => ok = false,
                }
                if !ok {
                    r.diags.push(
                        Diagnostic::error("E0101", r.span(v.span()), format!("global place `{name}` is not written as expected"))
                            .label("expected `{ initial = 0|1, nets = [\"NET\", ...] }`")
                            .help("`initial` is 0 or 1; `nets` lists the nets (or templates) that may use the place"),
                    );
                }
                (initial, Some(nets))
            }
            _ => {
                r.diags.push(
                    Diagnostic::error(
                        "E0101",
                        r.span(v.span()),
                        format!("global place `{name}` is not written as expected"),
                    )
                    .label("expected 0, 1, or a table")
                    .help(
                        "write `NAME = 0|1`, or `NAME = { initial = 0|1, nets = [\"NET\", ...] }`",
                    ),
                );
                (0, None)
            }
        };
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
            nets,
        });
    }
    for (k, v) in &raw.instances.0 {
        let name = r.name(k, "net", text);
        let net = r.name(&v.net, "net", text);
        let args = v.args.iter().filter_map(|a| r.expr(a)).collect();
        m.instances.push(InstanceDecl { name, net, args });
    }
    for (k, v) in &raw.invariants.0 {
        let name = r.name(k, "invariant", text);
        let mut range = v.span();
        let raw_text = &text[range.clone()];
        // Positions inside the string are exact when it is a basic string without escapes.
        let exact = raw_text.starts_with('"')
            && !raw_text.starts_with("\"\"\"")
            && !raw_text.contains('\\');
        if exact {
            range = range.start + 1..range.end.saturating_sub(1);
        }
        let formula = if exact {
            crate::formula::parse_formula(file, range.start, v.get_ref(), "E0108", r.diags)
        } else {
            // Escapes move positions: report at the whole string.
            let mut inner = Diagnostics::new();
            let f = crate::formula::parse_formula(file, 0, v.get_ref(), "E0108", &mut inner);
            for mut d in inner.into_iter() {
                d.span = Some(r.span(v.span()));
                r.diags.push(d);
            }
            f
        };
        m.invariants.push(InvariantDecl {
            name,
            text: v.get_ref().clone(),
            formula,
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
        let (params, params_unread) = r.params(&v.params, text);
        m.events.push(EventDecl {
            name,
            category,
            params,
            params_unread,
            description: v.description.clone(),
            internal: v.internal,
        });
    }
    for (k, v) in &raw.programs.0 {
        let name = r.name(k, "program", text);
        let mut functions = Vec::new();
        for (fk, fv) in &v.functions.0 {
            let fname = r.name(fk, "function", text);
            // `f = ["x: int"]`, or `f = { params = ["x: int"], answers = ["done"] }`.
            let strings = |r: &mut Reader, list: &toml::Value| -> Option<Vec<Spanned<String>>> {
                let items = list.as_array()?;
                let mut out = Vec::new();
                for i in items {
                    let t = i.as_str()?;
                    let range = quoted_in(text, fv.span(), t).unwrap_or(fv.span());
                    // Spans inside the string, as for a plain list (the quotes around it).
                    let range = range.start.saturating_sub(1)..range.end + 1;
                    out.push(Spanned::new(range, t.to_string()));
                }
                let _ = r;
                Some(out)
            };
            let (params, answers) = match fv.get_ref() {
                toml::Value::Array(_) => (strings(&mut r, fv.get_ref()), Some(Vec::new())),
                toml::Value::Table(t) => {
                    let unknown: Vec<&String> = t
                        .keys()
                        .filter(|k| *k != "params" && *k != "answers")
                        .collect();
                    if let Some(k) = unknown.first() {
                        r.diags.push(
                            Diagnostic::error("E0101", r.span(fv.span()), format!("unknown key `{k}` in function `{fname}`"))
                                .label("not `params` or `answers`")
                                .help("write `f = [\"x: int\"]`, or `f = { params = [\"x: int\"], answers = [\"EVENT\"] }`"),
                        );
                    }
                    (
                        t.get("params")
                            .map_or(Some(Vec::new()), |v| strings(&mut r, v)),
                        t.get("answers")
                            .map_or(Some(Vec::new()), |v| strings(&mut r, v)),
                    )
                }
                _ => (None, None),
            };
            let (Some(params), Some(answers)) = (params, answers) else {
                r.diags.push(
                    Diagnostic::error("E0101", r.span(fv.span()), format!("function `{fname}` is not written as expected"))
                        .label("expected a list of parameters, or a table")
                        .help("write `f = [\"x: int\"]`, or `f = { params = [\"x: int\"], answers = [\"EVENT\"] }`"),
                );
                continue;
            };
            let (params, params_unread) = r.params(&params, text);
            let answers = answers.iter().map(|a| r.name(a, "event", text)).collect();
            functions.push(FunctionDecl {
                name: fname,
                params,
                params_unread,
                answers,
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
    // `NET.place` is not an identifier: keep the text, the checker resolves it.
    let places = |r: &Reader, list: &[Spanned<String>]| -> Vec<Name> {
        list.iter()
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
            .collect()
    };
    for list in &raw.verify.finals {
        m.finals.push(places(&r, list));
    }
    for list in &raw.verify.goals {
        m.goals.push(places(&r, list));
    }
    m.progress_excludes = raw
        .verify
        .progress_excludes
        .as_ref()
        .map(|list| places(&r, list));
    for (k, v) in &raw.verify.bounds.0 {
        let name = r.name(k, "bound", text);
        let from = bound_end_at(&mut r, &v.from, text);
        let to = bound_end_at(&mut r, &v.to, text);
        let within = v.within.as_ref().map(|w| {
            let mut range = w.span();
            if text[range.clone()].starts_with('"') {
                range = range.start + 1..range.end.saturating_sub(1);
            }
            Name {
                text: w.get_ref().clone(),
                span: r.span(range),
            }
        });
        m.bounds.push(BoundDecl {
            name,
            from,
            to,
            within,
        });
    }
    Some(m)
}

/// One end of a bound as written in the manifest (positions inside the string when they are
/// exact, as for invariants).
fn bound_end_at(r: &mut Reader, v: &Spanned<String>, text: &str) -> BoundEnd {
    let mut range = v.span();
    let raw_text = &text[range.clone()];
    let exact =
        raw_text.starts_with('"') && !raw_text.starts_with("\"\"\"") && !raw_text.contains('\\');
    if exact {
        range = range.start + 1..range.end.saturating_sub(1);
        return bound_end(r.file, range.start, v.get_ref(), r.diags);
    }
    // Escapes move positions: report at the whole string.
    let mut inner = Diagnostics::new();
    let mut end = bound_end(r.file, 0, v.get_ref(), &mut inner);
    for mut d in inner.into_iter() {
        d.span = Some(r.span(v.span()));
        r.diags.push(d);
    }
    if let BoundEnd::Event(n) = &mut end {
        n.span = r.span(v.span());
    }
    end
}

/// One end of a bound, from its text at byte `offset` of `file`: a bare name is an event, any
/// other text a marking formula (E0108 when it does not read). PNML's reader shares it, so a
/// bound reads the same from both.
pub(crate) fn bound_end(
    file: FileId,
    offset: usize,
    text: &str,
    diags: &mut Diagnostics,
) -> BoundEnd {
    let trimmed = text.trim();
    if is_identifier(trimmed) {
        let lead = text.len() - text.trim_start().len();
        return BoundEnd::Event(Name {
            text: trimmed.to_string(),
            span: Span::new(file, offset + lead, offset + lead + trimmed.len()),
        });
    }
    BoundEnd::Marking {
        text: text.to_string(),
        formula: crate::formula::parse_formula(file, offset, text, "E0108", diags),
    }
}

/// E0109: a net file path of the manifest that would leave the project directory.
pub(crate) fn outside_project(f: &FileRef, why: &petrel_diag::paths::PathProblem) -> Diagnostic {
    Diagnostic::error(
        "E0109",
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

/// An argument as TOML writes it (floats always with a point, so they read back as floats).
fn toml_expr(e: &Expr) -> String {
    match e {
        Expr::Int(i, _) => i.to_string(),
        Expr::Float(f, _) => crate::fmt::format_float(*f),
        Expr::Bool(b, _) => b.to_string(),
        Expr::Text(t, _) => toml_str(t),
        Expr::List(items, _) => format!(
            "[{}]",
            items.iter().map(toml_expr).collect::<Vec<_>>().join(", ")
        ),
        // Names do not appear in the manifest's arguments.
        Expr::Var(n) | Expr::SelfParam(n) => toml_str(&n.text),
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
            match &g.nets {
                None => {
                    let _ = writeln!(out, "{} = {}", toml_key(&g.name.text), g.tokens);
                }
                Some(nets) => {
                    let nets: Vec<String> = nets.iter().map(|n| toml_str(&n.text)).collect();
                    let _ = writeln!(
                        out,
                        "{} = {{ initial = {}, nets = [{}] }}",
                        toml_key(&g.name.text),
                        g.tokens,
                        nets.join(", ")
                    );
                }
            }
        }
    }
    if !m.instances.is_empty() {
        out.push_str("\n[instances]\n");
        for i in &m.instances {
            let args: Vec<String> = i.args.iter().map(toml_expr).collect();
            let _ = writeln!(
                out,
                "{} = {{ net = {}, args = [{}] }}",
                toml_key(&i.name.text),
                toml_str(&i.net.text),
                args.join(", ")
            );
        }
    }
    if !m.invariants.is_empty() {
        out.push_str("\n[invariants]\n");
        for i in &m.invariants {
            let _ = writeln!(out, "{} = {}", toml_key(&i.name.text), toml_str(&i.text));
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
            if e.internal {
                fields.push("internal = true".to_string());
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
            if f.answers.is_empty() {
                let _ = writeln!(
                    out,
                    "{} = {}",
                    toml_key(&f.name.text),
                    param_list(&f.params)
                );
            } else {
                let answers: Vec<String> = f.answers.iter().map(|a| toml_str(&a.text)).collect();
                let _ = writeln!(
                    out,
                    "{} = {{ params = {}, answers = [{}] }}",
                    toml_key(&f.name.text),
                    param_list(&f.params),
                    answers.join(", ")
                );
            }
        }
    }
    if !m.finals.is_empty() || !m.goals.is_empty() || m.progress_excludes.is_some() {
        out.push_str("\n[verify]\n");
        for (key, list) in [("final", &m.finals), ("goal", &m.goals)] {
            if list.is_empty() {
                continue;
            }
            let _ = writeln!(out, "{key} = [");
            for f in list {
                let places: Vec<String> = f.iter().map(|n| toml_str(&n.text)).collect();
                let _ = writeln!(out, "    [{}],", places.join(", "));
            }
            out.push_str("]\n");
        }
        if let Some(ex) = &m.progress_excludes {
            let cats: Vec<String> = ex.iter().map(|n| toml_str(&n.text)).collect();
            let _ = writeln!(out, "progress_excludes = [{}]", cats.join(", "));
        }
    }
    if !m.bounds.is_empty() {
        out.push_str("\n[verify.bounds]\n");
        for b in &m.bounds {
            let mut fields = vec![
                format!("from = {}", toml_str(b.from.text())),
                format!("to = {}", toml_str(b.to.text())),
            ];
            if let Some(w) = &b.within {
                fields.push(format!("within = {}", toml_str(&w.text)));
            }
            let _ = writeln!(
                out,
                "{} = {{ {} }}",
                toml_key(&b.name.text),
                fields.join(", ")
            );
        }
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
    use petrel_diag::source::SourceFile;

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

[instances]
R1 = { net = "ROBOT", args = ["r1", 0.5, 3, true, [1.0, 2]] }

[invariants]
mutex = "not (R1.in and R2.in)"

[verify.bounds]
reaction = { from = "alarm", to = "R1.in or not active R2", within = "1.5s" }
back = { from = "R1.in", to = "go" }
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
        assert!(matches!(&m.bounds[0].from, BoundEnd::Event(n) if n.text == "alarm"));
        assert!(matches!(
            &m.bounds[0].to,
            BoundEnd::Marking {
                formula: Some(_),
                ..
            }
        ));
        assert_eq!(
            m.bounds[0].within.as_ref().map(|w| w.text.as_str()),
            Some("1.5s")
        );
        assert!(matches!(&m.bounds[1].to, BoundEnd::Event(n) if n.text == "go"));
        // A formula's names point inside the string.
        let BoundEnd::Marking {
            formula: Some(Formula::Or(a, _)),
            ..
        } = &m.bounds[0].to
        else {
            panic!("{:?}", m.bounds[0].to)
        };
        let Formula::Marked(n) = &**a else {
            panic!("{a:?}")
        };
        assert_eq!(&TEXT[n.span.start as usize..n.span.end as usize], "R1.in");
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
