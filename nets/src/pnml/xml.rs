//! The streaming XML reader under PNML reading and import, and the escaping export needs.
//!
//! `quick_xml` over the text, without a DOM, so that a megabyte of PNML reads in milliseconds;
//! byte positions become [`Span`]s so that every problem shows `file:line:col`. Only the
//! `<toolspecific tool="petrel">` blocks are read as small trees ([`Node`]), because their
//! content is nested data rather than a net.

use std::borrow::Cow;
use std::fmt::Write as _;

use quick_xml::events::{BytesStart, Event};
use quick_xml::Reader;

use petrel_diag::report::{Diagnostic, Diagnostics};
use petrel_diag::source::{FileId, Span};

/// Deepest nesting of elements in a Petrel block ([`Xml::node`]). The data Petrel writes nests
/// five deep; the bound keeps a crafted block from building a tree whose (recursive) drop
/// overflows the stack: 300,000 nested elements aborted `petrel import`.
pub(super) const MAX_NODE_DEPTH: usize = 64;

/// Marks a problem already reported that stops reading the document (the XML itself is broken,
/// so nothing after it can be trusted).
pub(super) struct Fatal;

/// An element whose start tag has been read.
pub(super) struct Elem<'a> {
    pub(super) start: BytesStart<'a>,
    /// The start tag.
    pub(super) span: Span,
    /// `<x/>`: no content and no end tag follow.
    pub(super) empty: bool,
}

impl Elem<'_> {
    pub(super) fn local(&self) -> &[u8] {
        self.start.local_name().into_inner()
    }

    pub(super) fn tag(&self) -> String {
        String::from_utf8_lossy(self.start.name().as_ref()).into_owned()
    }
}

/// What an element holds next.
pub(super) enum Child<'a> {
    Open(Elem<'a>),
    /// Character data, already unescaped.
    Text(Cow<'a, str>, Span),
}

/// A small tree of one `<toolspecific tool="petrel">` block: the only part read as a tree,
/// because its content is nested data rather than a net.
#[derive(Clone, Debug, Default)]
pub(super) struct Node {
    pub(super) name: String,
    pub(super) attrs: Vec<(String, String)>,
    pub(super) children: Vec<Node>,
    /// The character data directly inside, exactly (comments keep their spaces).
    pub(super) text: String,
    /// The start tag.
    pub(super) span: Span,
}

impl Node {
    pub(super) fn attr(&self, key: &str) -> Option<&str> {
        self.attrs
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    pub(super) fn child(&self, name: &str) -> Option<&Node> {
        self.children.iter().find(|c| c.name == name)
    }

    pub(super) fn children<'s>(&'s self, name: &'s str) -> impl Iterator<Item = &'s Node> + 's {
        self.children.iter().filter(move |c| c.name == name)
    }
}

pub(super) struct Xml<'a> {
    pub(super) reader: Reader<&'a [u8]>,
    pub(super) file: FileId,
    pub(super) text: &'a str,
}

impl<'a> Xml<'a> {
    pub(super) fn new(file: FileId, text: &'a str) -> Self {
        let mut reader = Reader::from_str(text);
        // End tags are matched here, not by quick-xml, so that an unclosed element is reported
        // where it opens rather than where a later end tag happens to disagree.
        reader.config_mut().check_end_names = false;
        Xml { reader, file, text }
    }

    fn span(&self, start: usize, end: usize) -> Span {
        Span::new(self.file, start, end)
    }

    /// `line:column` of a byte offset, for messages that mention a second position.
    pub(super) fn line_col(&self, offset: usize) -> String {
        let before = self.text.get(..offset).unwrap_or(self.text);
        let line = before.matches('\n').count() + 1;
        let column = before
            .rsplit('\n')
            .next()
            .map(|l| l.chars().count())
            .unwrap_or(0)
            + 1;
        format!("{line}:{column}")
    }

    fn xml_error(&self, e: quick_xml::Error, diags: &mut Diagnostics) -> Fatal {
        let at = (self.reader.error_position() as usize).min(self.text.len());
        diags.push(
            Diagnostic::error(
                "E0501",
                self.span(at, (at + 1).min(self.text.len())),
                format!("malformed XML: {e}"),
            )
            .label("the XML breaks here")
            .help("a PNML file must be well-formed XML: fix the markup at this point"),
        );
        Fatal
    }

    /// The next event worth reading, with its span; comments, declarations and processing
    /// instructions are skipped.
    pub(super) fn event(&mut self, diags: &mut Diagnostics) -> Result<(Event<'a>, Span), Fatal> {
        loop {
            let start = self.reader.buffer_position() as usize;
            let ev = match self.reader.read_event() {
                Ok(ev) => ev,
                Err(e) => return Err(self.xml_error(e, diags)),
            };
            let span = self.span(start, self.reader.buffer_position() as usize);
            match ev {
                Event::Comment(_) | Event::Decl(_) | Event::PI(_) | Event::DocType(_) => continue,
                ev => return Ok((ev, span)),
            }
        }
    }

    /// Turns a text or CDATA event into text, reporting a bad entity.
    fn char_data(
        &self,
        ev: Event<'a>,
        span: Span,
        diags: &mut Diagnostics,
    ) -> Result<Cow<'a, str>, Fatal> {
        let (raw, escaped) = match ev {
            Event::Text(t) => (t.into_inner(), true),
            Event::CData(c) => (c.into_inner(), false),
            _ => return Ok(Cow::Borrowed("")),
        };
        let raw = match raw {
            Cow::Borrowed(b) => Cow::Borrowed(std::str::from_utf8(b).unwrap_or("")),
            Cow::Owned(b) => Cow::Owned(String::from_utf8_lossy(&b).into_owned()),
        };
        if !escaped {
            return Ok(raw);
        }
        match unescape(&raw) {
            Ok(Cow::Borrowed(_)) => Ok(raw),
            Ok(Cow::Owned(s)) => Ok(Cow::Owned(s)),
            Err(msg) => {
                diags.push(
                    Diagnostic::error("E0501", span, format!("malformed XML: {msg}"))
                        .label("in this text")
                        .help("write `&amp;` for `&`, `&lt;` for `<`; PNML files declare no other entities"),
                );
                Err(Fatal)
            }
        }
    }

    /// The next child of `parent`, or `None` once its end tag is read.
    pub(super) fn next_child(
        &mut self,
        parent: &Elem<'a>,
        diags: &mut Diagnostics,
    ) -> Result<Option<Child<'a>>, Fatal> {
        if parent.empty {
            return Ok(None);
        }
        loop {
            let (ev, span) = self.event(diags)?;
            return match ev {
                Event::Start(start) => Ok(Some(Child::Open(Elem {
                    start,
                    span,
                    empty: false,
                }))),
                Event::Empty(start) => Ok(Some(Child::Open(Elem {
                    start,
                    span,
                    empty: true,
                }))),
                Event::End(end) if end.name() == parent.start.name() => Ok(None),
                Event::End(end) => {
                    let found = String::from_utf8_lossy(end.name().as_ref()).into_owned();
                    diags.push(
                        Diagnostic::error(
                            "E0501",
                            parent.span,
                            format!(
                                "malformed XML: {} is not closed before `</{found}>` at {}",
                                self.describe(parent),
                                self.line_col(span.start as usize)
                            ),
                        )
                        .label("opened here, never closed")
                        .help(format!("add `</{}>` where this element ends", parent.tag())),
                    );
                    Err(Fatal)
                }
                Event::Eof => {
                    diags.push(
                        Diagnostic::error(
                            "E0501",
                            parent.span,
                            format!(
                                "malformed XML: {} is not closed before the end of the file",
                                self.describe(parent)
                            ),
                        )
                        .label("opened here, never closed")
                        .help(format!("add `</{}>` where this element ends", parent.tag())),
                    );
                    Err(Fatal)
                }
                ev @ (Event::Text(_) | Event::CData(_)) => {
                    let text = self.char_data(ev, span, diags)?;
                    Ok(Some(Child::Text(text, span)))
                }
                // Comments and the like: `event` skips them already.
                _ => continue,
            };
        }
    }

    /// `<place id="p1">`, for messages.
    fn describe(&self, e: &Elem<'_>) -> String {
        match self.attr_quiet(e, "id") {
            Some(id) => format!("`<{} id=\"{id}\">`", e.tag()),
            None => format!("`<{}>`", e.tag()),
        }
    }

    /// The attributes of `e`, unescaped. A malformed attribute list is malformed XML: the
    /// parser's idea of where the tag ends is then unreliable, so reading stops there.
    pub(super) fn attrs(
        &self,
        e: &Elem<'_>,
        diags: &mut Diagnostics,
    ) -> Result<Vec<(String, String)>, Fatal> {
        let mut out = Vec::new();
        for a in e.start.attributes() {
            let problem = match a {
                Ok(a) => {
                    let key = String::from_utf8_lossy(a.key.local_name().into_inner()).into_owned();
                    let raw = String::from_utf8_lossy(&a.value).into_owned();
                    match unescape(&raw) {
                        Ok(v) => {
                            out.push((key, v.into_owned()));
                            continue;
                        }
                        Err(msg) => format!("attribute `{key}`: {msg}"),
                    }
                }
                Err(err) => format!("bad attributes in `<{}>`: {err}", e.tag()),
            };
            diags.push(
                Diagnostic::error("E0501", e.span, format!("malformed XML: {problem}"))
                    .label("in this tag")
                    .help("attributes read `name=\"value\"`, each name once, and the tag ends with `>`; write `&amp;` for `&`, `&lt;` for `<` and `&quot;` for `\"` in values"),
            );
            return Err(Fatal);
        }
        Ok(out)
    }

    /// One attribute, for messages only (errors are reported by [`Xml::attrs`]).
    pub(super) fn attr_quiet(&self, e: &Elem<'_>, key: &str) -> Option<String> {
        e.start.attributes().flatten().find_map(|a| {
            (a.key.local_name().into_inner() == key.as_bytes()).then(|| {
                let raw = String::from_utf8_lossy(&a.value).into_owned();
                unescape(&raw).map(Cow::into_owned).unwrap_or(raw)
            })
        })
    }

    /// Skips `e` and everything in it (iteratively: nesting depth cannot overflow the stack).
    pub(super) fn skip(&mut self, e: Elem<'a>, diags: &mut Diagnostics) -> Result<(), Fatal> {
        let mut stack = vec![e];
        while let Some(top) = stack.last() {
            match self.next_child(top, diags)? {
                None => {
                    stack.pop();
                }
                Some(Child::Open(c)) => stack.push(c),
                Some(Child::Text(..)) => {}
            }
        }
        Ok(())
    }

    /// The character data inside `e`, with the span it covers (the start tag when empty);
    /// nested elements are skipped.
    fn text_of(&mut self, e: Elem<'a>, diags: &mut Diagnostics) -> Result<(String, Span), Fatal> {
        let mut out = String::new();
        let mut span: Option<Span> = None;
        while let Some(c) = self.next_child(&e, diags)? {
            match c {
                Child::Text(t, s) => {
                    out.push_str(&t);
                    span = Some(span.map_or(s, |o| o.to(s)));
                }
                Child::Open(inner) => self.skip(inner, diags)?,
            }
        }
        Ok((out, span.unwrap_or(e.span)))
    }

    /// The `<text>` of a PNML label such as `<name>` or `<initialMarking>`.
    pub(super) fn label(
        &mut self,
        e: Elem<'a>,
        diags: &mut Diagnostics,
    ) -> Result<Option<(String, Span)>, Fatal> {
        let mut found = None;
        while let Some(c) = self.next_child(&e, diags)? {
            if let Child::Open(inner) = c {
                if inner.local() == b"text" {
                    found = Some(self.text_of(inner, diags)?);
                } else {
                    self.skip(inner, diags)?;
                }
            }
        }
        Ok(found)
    }

    /// Reads a Petrel block into a [`Node`] tree (iteratively, like [`Xml::skip`]).
    pub(super) fn node(&mut self, e: Elem<'a>, diags: &mut Diagnostics) -> Result<Node, Fatal> {
        let head = |x: &Self, e: &Elem<'_>, diags: &mut Diagnostics| {
            Ok(Node {
                name: String::from_utf8_lossy(e.local()).into_owned(),
                attrs: x.attrs(e, diags)?,
                children: Vec::new(),
                text: String::new(),
                span: e.span,
            })
        };
        let root = head(self, &e, diags)?;
        let mut stack = vec![(e, root)];
        loop {
            let Some((top, _)) = stack.last() else {
                return Ok(Node::default());
            };
            match self.next_child(top, diags)? {
                None => {
                    let Some((_, done)) = stack.pop() else {
                        return Ok(Node::default());
                    };
                    match stack.last_mut() {
                        Some((_, parent)) => parent.children.push(done),
                        None => return Ok(done),
                    }
                }
                Some(Child::Open(c)) if stack.len() >= MAX_NODE_DEPTH => {
                    diags.push(
                        Diagnostic::error(
                            "E0501",
                            c.span,
                            format!(
                                "elements are nested more than {MAX_NODE_DEPTH} deep in a petrel block"
                            ),
                        )
                        .label("too deep")
                        .help("Petrel's own blocks nest a few elements deep: this one was not written by Petrel"),
                    );
                    return Err(Fatal);
                }
                Some(Child::Open(c)) => {
                    let n = head(self, &c, diags)?;
                    stack.push((c, n));
                }
                Some(Child::Text(t, _)) => {
                    if let Some((_, n)) = stack.last_mut() {
                        n.text.push_str(&t);
                    }
                }
            }
        }
    }
}

pub(super) fn attr<'v>(attrs: &'v [(String, String)], key: &str) -> Option<&'v str> {
    attrs
        .iter()
        .find(|(k, _)| k == key)
        .map(|(_, v)| v.as_str())
}

/// XML unescaping of the five predefined entities and character references. Written here
/// rather than taken from quick-xml so that it accepts every reference [`escape`] writes.
pub(super) fn unescape(raw: &str) -> Result<Cow<'_, str>, String> {
    if !raw.contains('&') {
        return Ok(Cow::Borrowed(raw));
    }
    let mut out = String::with_capacity(raw.len());
    let mut rest = raw;
    while let Some(amp) = rest.find('&') {
        out.push_str(&rest[..amp]);
        let after = &rest[amp + 1..];
        let Some(semi) = after.find(';') else {
            return Err("`&` starts an entity that has no `;`".into());
        };
        let name = &after[..semi];
        let c = match name {
            "lt" => '<',
            "gt" => '>',
            "amp" => '&',
            "quot" => '"',
            "apos" => '\'',
            _ => {
                let code = if let Some(hex) = name.strip_prefix("#x") {
                    u32::from_str_radix(hex, 16).ok()
                } else if let Some(dec) = name.strip_prefix('#') {
                    dec.parse::<u32>().ok()
                } else {
                    return Err(format!("unknown entity `&{name};`"));
                };
                code.and_then(char::from_u32)
                    .ok_or_else(|| format!("bad character reference `&{name};`"))?
            }
        };
        out.push(c);
        rest = &after[semi + 1..];
    }
    out.push_str(rest);
    Ok(Cow::Owned(out))
}

/// XML escaping for text and attribute values: the markup characters, and as character
/// references every character a parser would not give back as written (carriage returns,
/// control characters, and in attributes the whitespace that attribute normalisation turns
/// into spaces).
pub(super) fn escape(s: &str, attribute: bool) -> Cow<'_, str> {
    let special = |c: char| {
        matches!(c, '<' | '>' | '&' | '"' | '\r')
            || (attribute && matches!(c, '\n' | '\t'))
            || (c.is_control() && c != '\n' && c != '\t')
            || matches!(c, '\u{FFFE}' | '\u{FFFF}')
    };
    if !s.contains(special) {
        return Cow::Borrowed(s);
    }
    let mut out = String::with_capacity(s.len() + 16);
    for c in s.chars() {
        match c {
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '&' => out.push_str("&amp;"),
            '"' => out.push_str("&quot;"),
            c if special(c) => {
                let _ = write!(out, "&#{};", c as u32);
            }
            c => out.push(c),
        }
    }
    Cow::Owned(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escape_and_unescape_are_inverse() {
        let s = "a<b>&\"c'\r\n\t\u{1}\u{0}é\u{FFFF}";
        for attribute in [true, false] {
            let e = escape(s, attribute);
            assert!(!e.contains('<') && !e.contains('\r') && !e.contains('\u{1}'));
            assert_eq!(unescape(&e).unwrap(), s);
        }
        assert!(unescape("&bogus;").is_err());
        assert!(unescape("a & b").is_err());
    }
}
