//! Diagnostics: what is wrong, where, and what to do about it.
//!
//! Every check collects into a [`Diagnostics`] list rather than stopping at the first problem, so
//! one run of `petrel check` reports everything. Codes are stable (`E0101`...), so tools and
//! golden tests can rely on them; `docs/diagnostics.md` lists them all.

use crate::plural::count;
use crate::source::{LineCol, SourceMap, Span};
use std::fmt::Write as _;

/// How serious a diagnostic is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Severity {
    /// The project cannot run: `petrel check` exits 1.
    Error,
    /// Suspicious but runnable.
    Warning,
}

/// One finding.
#[derive(Clone, Debug, PartialEq)]
pub struct Diagnostic {
    /// Error or warning.
    pub severity: Severity,
    /// Stable code, such as `E0201`.
    pub code: &'static str,
    /// One line saying what is wrong.
    pub message: String,
    /// Where: the primary location, if the finding has one.
    pub span: Option<Span>,
    /// Text shown under the caret.
    pub label: String,
    /// What to do about it.
    pub help: Option<String>,
    /// Other places that explain the finding (the first declaration of a duplicate...).
    pub related: Vec<(Span, String)>,
}

impl Diagnostic {
    /// An error with code `code` at `span`.
    pub fn error(code: &'static str, span: Span, message: impl Into<String>) -> Self {
        Diagnostic {
            severity: Severity::Error,
            code,
            message: message.into(),
            span: Some(span),
            label: String::new(),
            help: None,
            related: Vec::new(),
        }
    }

    /// A warning with code `code` at `span`.
    pub fn warning(code: &'static str, span: Span, message: impl Into<String>) -> Self {
        Diagnostic {
            severity: Severity::Warning,
            ..Diagnostic::error(code, span, message)
        }
    }

    /// An error about the project as a whole, with no position.
    pub fn global(code: &'static str, message: impl Into<String>) -> Self {
        Diagnostic {
            span: None,
            ..Diagnostic::error(code, Span::default(), message)
        }
    }

    /// Sets the text shown under the caret.
    pub fn label(mut self, label: impl Into<String>) -> Self {
        self.label = label.into();
        self
    }

    /// Adds another location that explains the finding.
    pub fn related(mut self, span: Span, label: impl Into<String>) -> Self {
        self.related.push((span, label.into()));
        self
    }

    /// Sets what the user should do.
    pub fn help(mut self, help: impl Into<String>) -> Self {
        self.help = Some(help.into());
        self
    }
}

/// The findings of one run, in the order found.
#[derive(Clone, Debug, Default)]
pub struct Diagnostics {
    list: Vec<Diagnostic>,
}

impl Diagnostics {
    /// An empty list.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a finding.
    pub fn push(&mut self, d: Diagnostic) {
        self.list.push(d);
    }

    /// All findings.
    pub fn iter(&self) -> impl Iterator<Item = &Diagnostic> {
        self.list.iter()
    }

    /// Number of errors.
    pub fn error_count(&self) -> usize {
        self.list
            .iter()
            .filter(|d| d.severity == Severity::Error)
            .count()
    }

    /// Number of warnings.
    pub fn warning_count(&self) -> usize {
        self.list.len() - self.error_count()
    }

    /// True if any error was found.
    pub fn has_errors(&self) -> bool {
        self.error_count() > 0
    }

    /// True if nothing was found.
    pub fn is_empty(&self) -> bool {
        self.list.is_empty()
    }

    /// Number of findings.
    pub fn len(&self) -> usize {
        self.list.len()
    }

    /// Appends every finding of `other`.
    pub fn extend(&mut self, other: Diagnostics) {
        self.list.extend(other.list);
    }

    /// Sorts by file, then position, keeping the found order among equals, so reports read top
    /// to bottom.
    pub fn sort(&mut self) {
        self.list
            .sort_by_key(|d| d.span.map(|s| (0, s.file.0, s.start)).unwrap_or((1, 0, 0)));
    }

    /// Renders the findings for people, followed by a summary line: the first
    /// [`MAX_HUMAN`] in full, then one line counting the rest ("... and N more errors").
    ///
    /// Linear in the size of the sources and the number of findings: each file's line table is
    /// built once for the whole report (not once per finding), and a finding on a line longer
    /// than [`LONG_LINE`] shows a window of that line around its caret rather than the whole
    /// line, so ten thousand bad characters on one line do not print that line ten thousand
    /// times.
    pub fn render_human(&self, sources: &SourceMap) -> String {
        let mut out = String::new();
        let mut cache = ariadne_cache(sources);
        for d in self.list.iter().take(MAX_HUMAN) {
            out.push_str(&render_one(d, sources, &mut cache));
        }
        let (e, w) = (self.error_count(), self.warning_count());
        if self.list.len() > MAX_HUMAN {
            let shown = &self.list[..MAX_HUMAN];
            let shown_e = shown
                .iter()
                .filter(|d| d.severity == Severity::Error)
                .count();
            let (more_e, more_w) = (e - shown_e, w - (MAX_HUMAN - shown_e));
            let mut more = Vec::new();
            if more_e > 0 {
                more.push(count(more_e, "more error"));
            }
            if more_w > 0 {
                more.push(count(more_w, "more warning"));
            }
            let _ = writeln!(
                out,
                "... and {} not shown (the first {MAX_HUMAN} findings are shown; `--format json` lists up to {MAX_JSON})",
                more.join(" and ")
            );
        }
        if e + w > 0 {
            let _ = writeln!(out, "{}, {}", count(e, "error"), count(w, "warning"));
        }
        out
    }

    /// Renders the findings as one JSON document for tools: `errors` and `warnings` count them
    /// all, `diagnostics` lists the first [`MAX_JSON`], and `omitted` says how many more there
    /// are.
    pub fn to_json(&self, sources: &SourceMap) -> serde_json::Value {
        let list: Vec<_> = self
            .list
            .iter()
            .take(MAX_JSON)
            .map(|d| {
                let (file, start, end) = match d.span {
                    Some(s) if (s.file.0 as usize) < sources.len() => {
                        let f = sources.get(s.file);
                        (
                            Some(f.name.clone()),
                            Some(f.line_col(s.start as usize)),
                            Some(f.line_col(s.end as usize)),
                        )
                    }
                    _ => (None, None, None),
                };
                serde_json::json!({
                    "severity": d.severity,
                    "code": d.code,
                    "message": d.message,
                    "file": file,
                    "line": start.map(|p: LineCol| p.line),
                    "column": start.map(|p| p.column),
                    "end_line": end.map(|p: LineCol| p.line),
                    "end_column": end.map(|p| p.column),
                    "label": d.label,
                    "help": d.help,
                })
            })
            .collect();
        serde_json::json!({
            "errors": self.error_count(),
            "warnings": self.warning_count(),
            "omitted": self.list.len().saturating_sub(MAX_JSON),
            "diagnostics": list,
        })
    }
}

/// How many findings [`Diagnostics::render_human`] prints in full: past a hundred, a person
/// fixes the first ones and runs the check again, and the rest would only bury them.
pub const MAX_HUMAN: usize = 100;

/// How many findings [`Diagnostics::to_json`] lists; the counts cover them all.
pub const MAX_JSON: usize = 1000;

/// A source line longer than this many bytes is shown as a window around the caret.
pub const LONG_LINE: usize = 240;

impl IntoIterator for Diagnostics {
    type Item = Diagnostic;
    type IntoIter = std::vec::IntoIter<Diagnostic>;
    fn into_iter(self) -> Self::IntoIter {
        self.list.into_iter()
    }
}

/// A file as ariadne knows it: shown by its name, told apart by its index (two files may
/// share a name).
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
struct SourceId(u32, std::sync::Arc<str>);

impl std::fmt::Display for SourceId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.1)
    }
}

/// Every file's line table, built once per report.
fn ariadne_cache(sources: &SourceMap) -> impl ariadne::Cache<SourceId> + '_ {
    ariadne::sources(
        sources
            .files()
            .map(|(id, f)| (SourceId(id.0, f.name.as_str().into()), f.text.as_str()))
            .collect::<Vec<_>>(),
    )
}

fn severity_word(s: Severity) -> &'static str {
    match s {
        Severity::Error => "Error",
        Severity::Warning => "Warning",
    }
}

fn render_one(
    d: &Diagnostic,
    sources: &SourceMap,
    cache: &mut impl ariadne::Cache<SourceId>,
) -> String {
    use ariadne::{CharSet, Config, IndexType, Label, Report, ReportKind};
    let kind = match d.severity {
        Severity::Error => ReportKind::Error,
        Severity::Warning => ReportKind::Warning,
    };
    let span = match d.span {
        Some(s) if (s.file.0 as usize) < sources.len() => s,
        _ => {
            let mut out = format!(
                "[{}] {}: {}\n",
                d.code,
                severity_word(d.severity),
                d.message
            );
            if let Some(h) = &d.help {
                let _ = writeln!(out, "  Help: {h}");
            }
            return out;
        }
    };
    let related: Vec<(Span, &str)> = d
        .related
        .iter()
        .filter(|(s, _)| !s.is_synthetic() && (s.file.0 as usize) < sources.len())
        .map(|(s, t)| (*s, t.as_str()))
        .collect();
    let label = if d.label.is_empty() {
        d.message.as_str()
    } else {
        d.label.as_str()
    };
    if std::iter::once(span)
        .chain(related.iter().map(|(s, _)| *s))
        .any(|s| on_long_line(sources, s))
    {
        return render_long(d, span, label, &related, sources);
    }
    let id = |s: Span| SourceId(s.file.0, sources.get(s.file).name.as_str().into());
    let range = byte_range(&sources.get(span.file).text, span);
    let mut report = Report::build(kind, (id(span), range.clone()))
        .with_config(
            Config::default()
                .with_color(false)
                .with_char_set(CharSet::Ascii)
                .with_index_type(IndexType::Byte),
        )
        .with_code(d.code)
        .with_message(&d.message)
        .with_label(Label::new((id(span), range)).with_message(label));
    for (i, (s, text)) in related.iter().enumerate() {
        report = report.with_label(
            Label::new((id(*s), byte_range(&sources.get(s.file).text, *s)))
                .with_message(text)
                .with_order(i as i32 + 1),
        );
    }
    if let Some(h) = &d.help {
        report = report.with_help(h);
    }
    let mut buf = Vec::new();
    // Writing into a Vec cannot fail; ariadne only errors on I/O.
    let _ = report.finish().write(cache, &mut buf);
    String::from_utf8_lossy(&buf).into_owned()
}

/// True when `span` starts on a line longer than [`LONG_LINE`] bytes.
fn on_long_line(sources: &SourceMap, span: Span) -> bool {
    sources
        .get(span.file)
        .line_bounds(span.start as usize)
        .len()
        > LONG_LINE
}

/// The same report as ariadne's, for a finding on a long line: the line is cut to a window
/// around each caret (what a person reads anyway), so the report's size does not grow with
/// the line's.
fn render_long(
    d: &Diagnostic,
    span: Span,
    label: &str,
    related: &[(Span, &str)],
    sources: &SourceMap,
) -> String {
    let mut out = format!(
        "[{}] {}: {}\n",
        d.code,
        severity_word(d.severity),
        d.message
    );
    let mut excerpt = |s: Span, text: &str, first: bool| {
        let f = sources.get(s.file);
        let at = f.line_col(s.start as usize);
        let line = f.line_text(at.line);
        // Columns count characters: cut on characters, never inside one.
        let before = 40usize;
        let from = at.column.saturating_sub(1).saturating_sub(before);
        let chars: String = line.chars().skip(from).take(before + 80).collect();
        let total = line.chars().count();
        let lead = if from > 0 { "..." } else { "" };
        let tail = if from + chars.chars().count() < total {
            "..."
        } else {
            ""
        };
        let width = at.line.to_string().len();
        let pad = " ".repeat(width + 2);
        let corner = if first { "," } else { ":" };
        let _ = writeln!(out, "{pad}{corner}-[ {}:{at} ]", f.name);
        let _ = writeln!(out, "{pad}|");
        let _ = writeln!(out, " {} | {lead}{chars}{tail}", at.line);
        let caret_col = lead.len() + (at.column - 1 - from);
        let _ = writeln!(
            out,
            "{pad}| {}^ {text} (line {} is {total} characters long: a part is shown)",
            " ".repeat(caret_col),
            at.line
        );
    };
    excerpt(span, label, true);
    for (s, text) in related {
        excerpt(*s, text, false);
    }
    let width = sources
        .get(span.file)
        .line_col(span.start as usize)
        .line
        .to_string()
        .len();
    if let Some(h) = &d.help {
        let pad = " ".repeat(width + 2);
        let _ = writeln!(out, "{pad}| \n{pad}| Help: {h}");
    }
    let _ = writeln!(out, "{}'", "-".repeat(width + 2));
    out
}

/// A non-empty range inside `text` on character boundaries, whatever the span says: a span at
/// the very end of a file (an unexpected end) still gets a caret.
fn byte_range(text: &str, span: Span) -> std::ops::Range<usize> {
    let len = text.len();
    if len == 0 {
        return 0..0;
    }
    let mut start = (span.start as usize).min(len - 1);
    while !text.is_char_boundary(start) {
        start -= 1;
    }
    let mut end = (span.end as usize).clamp(start + 1, len);
    while !text.is_char_boundary(end) {
        end += 1;
    }
    start..end
}
