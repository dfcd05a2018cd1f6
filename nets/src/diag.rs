//! Diagnostics: what is wrong, where, and what to do about it.
//!
//! Every check collects into a [`Diagnostics`] list rather than stopping at the first problem, so
//! one run of `petrel check` reports everything. Codes are stable (`E0101`...), so tools and
//! golden tests can rely on them; `docs/diagnostics.md` lists them all.

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

    /// Renders every finding for people, followed by a summary line.
    pub fn render_human(&self, sources: &SourceMap) -> String {
        let mut out = String::new();
        for d in &self.list {
            out.push_str(&render_one(d, sources));
        }
        let (e, w) = (self.error_count(), self.warning_count());
        let plural = |n: usize, s: &str| format!("{n} {s}{}", if n == 1 { "" } else { "s" });
        if e + w > 0 {
            let _ = writeln!(out, "{}, {}", plural(e, "error"), plural(w, "warning"));
        }
        out
    }

    /// Renders every finding as one JSON document for tools.
    pub fn to_json(&self, sources: &SourceMap) -> serde_json::Value {
        let list: Vec<_> = self
            .list
            .iter()
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
            "diagnostics": list,
        })
    }
}

impl IntoIterator for Diagnostics {
    type Item = Diagnostic;
    type IntoIter = std::vec::IntoIter<Diagnostic>;
    fn into_iter(self) -> Self::IntoIter {
        self.list.into_iter()
    }
}

fn render_one(d: &Diagnostic, sources: &SourceMap) -> String {
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
                match d.severity {
                    Severity::Error => "Error",
                    Severity::Warning => "Warning",
                },
                d.message
            );
            if let Some(h) = &d.help {
                let _ = writeln!(out, "  Help: {h}");
            }
            return out;
        }
    };
    let file = sources.get(span.file);
    let name = file.name.clone();
    let range = byte_range(&file.text, span);
    let label = if d.label.is_empty() {
        d.message.clone()
    } else {
        d.label.clone()
    };
    let mut report = Report::build(kind, (name.clone(), range.clone()))
        .with_config(
            Config::default()
                .with_color(false)
                .with_char_set(CharSet::Ascii)
                .with_index_type(IndexType::Byte),
        )
        .with_code(d.code)
        .with_message(&d.message)
        .with_label(Label::new((name.clone(), range)).with_message(label));
    let mut cache: Vec<(String, &str)> = vec![(name.clone(), file.text.as_str())];
    for (i, (s, text)) in d.related.iter().enumerate() {
        if s.is_synthetic() || (s.file.0 as usize) >= sources.len() {
            continue;
        }
        let f = sources.get(s.file);
        if !cache.iter().any(|(n, _)| n == &f.name) {
            cache.push((f.name.clone(), f.text.as_str()));
        }
        report = report.with_label(
            Label::new((f.name.clone(), byte_range(&f.text, *s)))
                .with_message(text)
                .with_order(i as i32 + 1),
        );
    }
    if let Some(h) = &d.help {
        report = report.with_help(h);
    }
    let mut buf = Vec::new();
    // Writing into a Vec cannot fail; ariadne only errors on I/O.
    let _ = report.finish().write(ariadne::sources(cache), &mut buf);
    String::from_utf8_lossy(&buf).into_owned()
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
