//! PNML (ISO/IEC 15909-2) interchange: reading plain place/transition nets, and carrying whole
//! Petrel projects through PNML without loss.
//!
//! Three entry points:
//!
//! - [`parse_pnml`] reads any P/T-net PNML document (the Model Checking Contest models, for
//!   instance) into [`PtNet`]s: places, transitions and weighted arcs, nothing else.
//! - [`export_pnml`] writes a Petrel project as one P/T net. Any PNML tool sees the project's
//!   structure and initial state; everything else Petrel knows (manifest, triggers, actions,
//!   comments, written order) travels in `<toolspecific tool="petrel" version="1">` blocks, which
//!   other tools must keep and ignore.
//! - [`import_pnml`] reads such an export back into the identical [`Project`], or turns a plain
//!   P/T net into a project of immediate transitions, refusing (with a diagnostic per element)
//!   what Petrel's safe, unary nets cannot hold.
//!
//! The reader streams with `quick_xml` over the text (no DOM) so a megabyte of PNML reads in
//! milliseconds, and turns byte positions into [`Span`]s so every problem shows `file:line:col`.
//!
//! Diagnostic codes:
//!
//! - `E0501` malformed PNML (XML syntax, unclosed element, missing id, bad number...);
//! - `E0502` an arc whose source or target is unknown, or that joins two places or two
//!   transitions;
//! - `E0503` a net that is not a P/T net (colored, symmetric, high-level...);
//! - `E0504` an arc weight above 1, which Petrel nets cannot express;
//! - `E0505` an initial marking above 1, which Petrel places cannot hold;
//! - `E0506` Petrel data (`<toolspecific tool="petrel">`) that is invalid or disagrees with the
//!   P/T net it annotates.
//!
//! # The Petrel blocks
//!
//! At net level (inside `<net>`), one block holds the manifest and the layout of the net files:
//!
//! ```xml
//! <toolspecific tool="petrel" version="1">
//!   <manifest name="uav">
//!     <description>...</description>
//!     <file path="nav.pn"/>
//!     <start net="nav"/>
//!     <global name="ready" tokens="1" ref="global.ready"/>
//!     <event name="alarm" category="safety"><param name="why" type="text"/></event>
//!     <program name="PLN"><function name="goto"><param name="x" type="float"/></function></program>
//!     <timer name="watchdog" event="timeout"/>
//!   </manifest>
//!   <netfile path="nav.pn">
//!     <net name="nav" blank-before="true">
//!       <comment>...</comment>
//!       <item ref="nav.idle"/>
//!       <item ref="nav.go"/>
//!       <end-comment>...</end-comment>
//!     </net>
//!     <end-comment>...</end-comment>
//!   </netfile>
//! </toolspecific>
//! ```
//!
//! Each `<place>` and `<transition>` of the page carries its own block (`<place name tokens
//! marking-written blank-before>` or `<transition name blank-before>` with comments, trailing
//! comment, trigger, inputs, outputs, actions and end comments). `<item ref>` fixes the written
//! order of places and transitions, which the P/T net alone cannot record.

use crate::diag::{Diagnostic, Diagnostics};
use crate::fmt::format_action;
use crate::model::*;
use crate::source::{FileId, Span};
use crate::syntax::{is_keyword, parse_action};
use quick_xml::events::{BytesStart, Event};
use quick_xml::Reader;
use std::borrow::Cow;
use std::collections::{HashMap, HashSet};
use std::fmt::Write as _;

/// The PNML type of P/T nets, written on export.
pub const PTNET_TYPE: &str = "http://www.pnml.org/version-2009/grammar/ptnet";

/// The PNML namespace, written on export.
pub const PNML_NAMESPACE: &str = "http://www.pnml.org/version-2009/grammar/pnml";

/// Deepest `<page>` nesting accepted: the page reader recurses, and a hostile file must not be
/// able to overflow the stack.
const MAX_PAGE_DEPTH: usize = 64;

/// The help shown for every problem in Petrel blocks: they are machine-written, so a problem
/// means another tool or a person changed them.
const PETREL_DATA_HELP: &str = "the `<toolspecific tool=\"petrel\">` data was changed after Petrel exported it: export the project again, or delete every petrel block to import the plain P/T net";

/// The hint for nets Petrel cannot take as mission nets but can still analyse.
const VERIFY_HINT: &str = "`petrel verify FILE.pnml` analyses weighted, unsafe P/T nets directly";

// ---------------------------------------------------------------------------------------------
// The P/T model
// ---------------------------------------------------------------------------------------------

/// A place/transition net read from PNML: the structure and the initial marking, nothing else.
#[derive(Clone, Debug, PartialEq)]
pub struct PtNet {
    /// The net's `id` attribute.
    pub id: String,
    /// The net's `<name>` label, or its id when it has none.
    pub name: String,
    /// Places, in document order (pages flattened).
    pub places: Vec<PtPlace>,
    /// Transitions, in document order (pages flattened).
    pub transitions: Vec<PtTransition>,
    /// Arcs, in document order, resolved to places and transitions.
    pub arcs: Vec<PtArc>,
    /// Whether the net carries a `<toolspecific tool="nupn">` block (a split into sequential
    /// units, which some analysers use).
    pub has_nupn: bool,
}

/// A place of a [`PtNet`].
#[derive(Clone, Debug, PartialEq)]
pub struct PtPlace {
    /// The `id` attribute.
    pub id: String,
    /// The `<name>` label, or the id when it has none.
    pub name: String,
    /// Tokens in the initial marking (0 when `<initialMarking>` is absent).
    pub initial: u64,
    /// The place's start tag.
    pub span: Span,
}

/// A transition of a [`PtNet`].
#[derive(Clone, Debug, PartialEq)]
pub struct PtTransition {
    /// The `id` attribute.
    pub id: String,
    /// The `<name>` label, or the id when it has none.
    pub name: String,
    /// The transition's start tag.
    pub span: Span,
}

/// One end of an arc: an index into [`PtNet::places`] or [`PtNet::transitions`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PtNode {
    /// Index into [`PtNet::places`].
    Place(usize),
    /// Index into [`PtNet::transitions`].
    Transition(usize),
}

/// An arc of a [`PtNet`]. [`parse_pnml`] only builds arcs that join a place and a transition,
/// in either direction.
#[derive(Clone, Debug, PartialEq)]
pub struct PtArc {
    /// The `id` attribute.
    pub id: String,
    /// Where tokens come from.
    pub source: PtNode,
    /// Where tokens go.
    pub target: PtNode,
    /// The inscription: tokens moved per firing (1 when `<inscription>` is absent).
    pub weight: u64,
    /// The arc's start tag.
    pub span: Span,
}

impl PtArc {
    /// The place this arc touches, whichever its direction.
    pub fn place(&self) -> Option<usize> {
        match (self.source, self.target) {
            (PtNode::Place(p), _) | (_, PtNode::Place(p)) => Some(p),
            _ => None,
        }
    }

    /// The transition this arc touches, whichever its direction.
    pub fn transition(&self) -> Option<usize> {
        match (self.source, self.target) {
            (PtNode::Transition(t), _) | (_, PtNode::Transition(t)) => Some(t),
            _ => None,
        }
    }

    /// True for an input arc (place to transition): firing takes tokens from the place.
    pub fn is_input(&self) -> bool {
        matches!(
            (self.source, self.target),
            (PtNode::Place(_), PtNode::Transition(_))
        )
    }
}

impl PtNet {
    /// Number of arcs.
    pub fn arc_count(&self) -> usize {
        self.arcs.len()
    }

    /// Number of input arcs (place to transition).
    pub fn input_arc_count(&self) -> usize {
        self.arcs.iter().filter(|a| a.is_input()).count()
    }

    /// Number of output arcs (transition to place).
    pub fn output_arc_count(&self) -> usize {
        self.arcs.len() - self.input_arc_count()
    }

    /// The largest arc weight, 0 for a net without arcs. Above 1, the net is not unary.
    pub fn max_arc_weight(&self) -> u64 {
        self.arcs.iter().map(|a| a.weight).max().unwrap_or(0)
    }

    /// The largest initial marking of a place, 0 for a net without places. Above 1, the initial
    /// marking is not safe.
    pub fn max_initial_marking(&self) -> u64 {
        self.places.iter().map(|p| p.initial).max().unwrap_or(0)
    }

    /// The index of the place with id `id`.
    pub fn place_index(&self, id: &str) -> Option<usize> {
        self.places.iter().position(|p| p.id == id)
    }

    /// The index of the transition with id `id`.
    pub fn transition_index(&self, id: &str) -> Option<usize> {
        self.transitions.iter().position(|t| t.id == id)
    }
}

// ---------------------------------------------------------------------------------------------
// Streaming XML reader
// ---------------------------------------------------------------------------------------------

/// Marks a problem already reported that stops reading the document (the XML itself is broken,
/// so nothing after it can be trusted).
struct Fatal;

/// An element whose start tag has been read.
struct Elem<'a> {
    start: BytesStart<'a>,
    /// The start tag.
    span: Span,
    /// `<x/>`: no content and no end tag follow.
    empty: bool,
}

impl Elem<'_> {
    fn local(&self) -> &[u8] {
        self.start.local_name().into_inner()
    }

    fn tag(&self) -> String {
        String::from_utf8_lossy(self.start.name().as_ref()).into_owned()
    }
}

/// What an element holds next.
enum Child<'a> {
    Open(Elem<'a>),
    /// Character data, already unescaped.
    Text(Cow<'a, str>, Span),
}

/// A small tree of one `<toolspecific tool="petrel">` block: the only part read as a tree,
/// because its content is nested data rather than a net.
#[derive(Clone, Debug, Default)]
struct Node {
    name: String,
    attrs: Vec<(String, String)>,
    children: Vec<Node>,
    /// The character data directly inside, exactly (comments keep their spaces).
    text: String,
    /// The start tag.
    span: Span,
}

impl Node {
    fn attr(&self, key: &str) -> Option<&str> {
        self.attrs
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    fn child(&self, name: &str) -> Option<&Node> {
        self.children.iter().find(|c| c.name == name)
    }

    fn children<'s>(&'s self, name: &'s str) -> impl Iterator<Item = &'s Node> + 's {
        self.children.iter().filter(move |c| c.name == name)
    }
}

struct Xml<'a> {
    reader: Reader<&'a [u8]>,
    file: FileId,
    text: &'a str,
}

impl<'a> Xml<'a> {
    fn new(file: FileId, text: &'a str) -> Self {
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
    fn line_col(&self, offset: usize) -> String {
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
    fn event(&mut self, diags: &mut Diagnostics) -> Result<(Event<'a>, Span), Fatal> {
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
    fn next_child(
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
    fn attrs(&self, e: &Elem<'_>, diags: &mut Diagnostics) -> Result<Vec<(String, String)>, Fatal> {
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
    fn attr_quiet(&self, e: &Elem<'_>, key: &str) -> Option<String> {
        e.start.attributes().flatten().find_map(|a| {
            (a.key.local_name().into_inner() == key.as_bytes()).then(|| {
                let raw = String::from_utf8_lossy(&a.value).into_owned();
                unescape(&raw).map(Cow::into_owned).unwrap_or(raw)
            })
        })
    }

    /// Skips `e` and everything in it (iteratively: nesting depth cannot overflow the stack).
    fn skip(&mut self, e: Elem<'a>, diags: &mut Diagnostics) -> Result<(), Fatal> {
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
    fn label(
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
    fn node(&mut self, e: Elem<'a>, diags: &mut Diagnostics) -> Result<Node, Fatal> {
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

fn attr<'v>(attrs: &'v [(String, String)], key: &str) -> Option<&'v str> {
    attrs
        .iter()
        .find(|(k, _)| k == key)
        .map(|(_, v)| v.as_str())
}

/// XML unescaping of the five predefined entities and character references. Written here
/// rather than taken from quick-xml so that it accepts every reference [`escape`] writes.
fn unescape(raw: &str) -> Result<Cow<'_, str>, String> {
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
fn escape(s: &str, attribute: bool) -> Cow<'_, str> {
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

// ---------------------------------------------------------------------------------------------
// Reading PNML
// ---------------------------------------------------------------------------------------------

/// A net as read, with the Petrel blocks kept for [`import_pnml`].
struct RawNet {
    net: PtNet,
    /// The `<net>` start tag.
    span: Span,
    petrel: Option<Node>,
    place_petrel: Vec<Option<Node>>,
    transition_petrel: Vec<Option<Node>>,
}

/// An arc before its ends are resolved (arcs may come before the nodes they join).
struct RawArc {
    id: String,
    source: String,
    target: String,
    weight: u64,
    span: Span,
}

#[derive(Default)]
struct NetBuilder {
    name: Option<String>,
    has_nupn: bool,
    places: Vec<PtPlace>,
    place_petrel: Vec<Option<Node>>,
    transitions: Vec<PtTransition>,
    transition_petrel: Vec<Option<Node>>,
    arcs: Vec<RawArc>,
    petrel: Option<Node>,
}

/// True for the PNML types of P/T nets: the 2009 standard grammar (and its variants that end
/// the same way) and the 2004 Humboldt-University `ptNetb`.
fn is_pt_type(ty: &str) -> bool {
    let last = ty
        .trim()
        .rsplit(['/', '#'])
        .next()
        .unwrap_or("")
        .to_ascii_lowercase();
    let last = last.strip_suffix(".pntd").unwrap_or(&last);
    matches!(last, "ptnet" | "ptnetb")
}

/// Parses a natural number written in a label, reporting what is wrong with it.
fn natural(
    text: &str,
    span: Span,
    what: &str,
    owner: &str,
    min: u64,
    diags: &mut Diagnostics,
) -> Option<u64> {
    match text.trim().parse::<u64>() {
        Ok(n) if n >= min => Some(n),
        _ => {
            diags.push(
                Diagnostic::error(
                    "E0501",
                    span,
                    format!(
                        "the {what} of {owner} is `{}`, not a natural number{}",
                        text.trim(),
                        if min > 0 { " of at least 1" } else { "" }
                    ),
                )
                .label("not a valid number")
                .help(format!(
                    "write the {what} as a decimal number, such as `<text>1</text>`{}",
                    if min > 0 {
                        ", or leave the label out for 1"
                    } else {
                        ", or leave the label out for 0"
                    }
                )),
            );
            None
        }
    }
}

/// Parses a whole PNML document: the `<net>`s that could be read, with their Petrel blocks.
fn parse_document(file: FileId, text: &str, diags: &mut Diagnostics) -> Vec<RawNet> {
    let mut x = Xml::new(file, text);
    let mut nets = Vec::new();
    // Errors stop the reading, but the nets completed before them are kept.
    let _ = read_root(&mut x, &mut nets, diags);
    nets
}

fn read_root<'a>(
    x: &mut Xml<'a>,
    nets: &mut Vec<RawNet>,
    diags: &mut Diagnostics,
) -> Result<(), Fatal> {
    let root = loop {
        let (ev, span) = x.event(diags)?;
        match ev {
            Event::Start(start) => {
                break Elem {
                    start,
                    span,
                    empty: false,
                }
            }
            Event::Empty(start) => {
                break Elem {
                    start,
                    span,
                    empty: true,
                }
            }
            Event::Eof => {
                diags.push(
                    Diagnostic::error("E0501", span, "this file holds no XML element")
                        .label("the document ends here")
                        .help("a PNML file is `<pnml xmlns=\"http://www.pnml.org/version-2009/grammar/pnml\">` holding one or more `<net>`"),
                );
                return Err(Fatal);
            }
            Event::End(_) => {
                diags.push(
                    Diagnostic::error("E0501", span, "malformed XML: end tag before any element")
                        .label("nothing to close")
                        .help("a PNML file starts with `<pnml>`"),
                );
                return Err(Fatal);
            }
            _ => continue,
        }
    };
    if root.local() != b"pnml" {
        diags.push(
            Diagnostic::error(
                "E0501",
                root.span,
                format!("this is not a PNML document: its root element is `<{}>`", root.tag()),
            )
            .label("expected `<pnml>`")
            .help("a PNML file is `<pnml xmlns=\"http://www.pnml.org/version-2009/grammar/pnml\">` holding one or more `<net>`"),
        );
        return Err(Fatal);
    }
    while let Some(c) = x.next_child(&root, diags)? {
        if let Child::Open(e) = c {
            if e.local() == b"net" {
                if let Some(net) = read_net(x, e, diags)? {
                    nets.push(net);
                }
            } else {
                x.skip(e, diags)?;
            }
        }
    }
    Ok(())
}

fn read_net<'a>(
    x: &mut Xml<'a>,
    e: Elem<'a>,
    diags: &mut Diagnostics,
) -> Result<Option<RawNet>, Fatal> {
    let attrs = x.attrs(&e, diags)?;
    let id = attr(&attrs, "id").map(str::to_string);
    let shown = id.as_deref().unwrap_or("without id");
    match attr(&attrs, "type") {
        Some(ty) if is_pt_type(ty) => {}
        Some(ty) => {
            diags.push(
                Diagnostic::error(
                    "E0503",
                    e.span,
                    format!("net `{shown}` has type `{ty}`: Petrel reads P/T nets only"),
                )
                .label("not a place/transition net")
                .help(format!(
                    "colored, symmetric and high-level nets must be unfolded first: export a P/T net (type \"{PTNET_TYPE}\"), such as the `-PT-` instance of an MCC model"
                )),
            );
            x.skip(e, diags)?;
            return Ok(None);
        }
        None => {
            diags.push(
                Diagnostic::error("E0501", e.span, format!("net `{shown}` has no `type`"))
                    .label("the net type is missing")
                    .help(format!(
                        "PNML nets state their type: add type=\"{PTNET_TYPE}\""
                    )),
            );
            x.skip(e, diags)?;
            return Ok(None);
        }
    }
    let Some(id) = id else {
        diags.push(
            Diagnostic::error("E0501", e.span, "this net has no `id`")
                .label("the id is missing")
                .help("PNML nets are identified: add id=\"NAME\""),
        );
        x.skip(e, diags)?;
        return Ok(None);
    };
    let span = e.span;
    let mut b = NetBuilder::default();
    read_container(x, &mut b, e, 0, &id, diags)?;
    Ok(Some(finish_net(x, b, id, span, diags)))
}

/// Reads the content of a `<net>` (depth 0) or of a `<page>`, flattening pages.
fn read_container<'a>(
    x: &mut Xml<'a>,
    b: &mut NetBuilder,
    e: Elem<'a>,
    depth: usize,
    net_id: &str,
    diags: &mut Diagnostics,
) -> Result<(), Fatal> {
    while let Some(c) = x.next_child(&e, diags)? {
        let Child::Open(c) = c else { continue };
        match c.local() {
            b"place" => read_place(x, b, c, diags)?,
            b"transition" => read_transition(x, b, c, diags)?,
            b"arc" => read_arc(x, b, c, diags)?,
            b"page" if depth >= MAX_PAGE_DEPTH => {
                diags.push(
                    Diagnostic::error(
                        "E0501",
                        c.span,
                        format!("pages are nested more than {MAX_PAGE_DEPTH} deep"),
                    )
                    .label("too deep")
                    .help("flatten the pages of this net"),
                );
                return Err(Fatal);
            }
            b"page" => read_container(x, b, c, depth + 1, net_id, diags)?,
            b"name" if depth == 0 => {
                if let Some((name, _)) = x.label(c, diags)? {
                    b.name = Some(name.trim().to_string());
                }
            }
            b"toolspecific" => {
                let attrs = x.attrs(&c, diags)?;
                match attr(&attrs, "tool") {
                    Some("nupn") => {
                        b.has_nupn = true;
                        x.skip(c, diags)?;
                    }
                    Some("petrel") => {
                        let span = c.span;
                        let node = x.node(c, diags)?;
                        if b.petrel.is_some() {
                            diags.push(
                                Diagnostic::error(
                                    "E0506",
                                    span,
                                    format!("net `{net_id}` has two net-level petrel blocks"),
                                )
                                .label("second block")
                                .help(PETREL_DATA_HELP),
                            );
                        } else {
                            b.petrel = Some(node);
                        }
                    }
                    _ => x.skip(c, diags)?,
                }
            }
            _ => x.skip(c, diags)?,
        }
    }
    Ok(())
}

/// The id of a place, transition or arc; reports and skips the element when it has none.
fn required_id<'a>(
    x: &mut Xml<'a>,
    e: Elem<'a>,
    attrs: &[(String, String)],
    diags: &mut Diagnostics,
) -> Result<Option<(String, Elem<'a>)>, Fatal> {
    match attr(attrs, "id") {
        Some(id) => Ok(Some((id.to_string(), e))),
        None => {
            let tag = e.tag();
            diags.push(
                Diagnostic::error("E0501", e.span, format!("this `<{tag}>` has no `id`"))
                    .label("the id is missing")
                    .help(format!(
                        "every PNML {tag} has an id unique in the document: add id=\"NAME\""
                    )),
            );
            x.skip(e, diags)?;
            Ok(None)
        }
    }
}

fn read_place<'a>(
    x: &mut Xml<'a>,
    b: &mut NetBuilder,
    e: Elem<'a>,
    diags: &mut Diagnostics,
) -> Result<(), Fatal> {
    let attrs = x.attrs(&e, diags)?;
    let Some((id, e)) = required_id(x, e, &attrs, diags)? else {
        return Ok(());
    };
    let mut name = None;
    let mut initial = 0;
    let mut petrel = None;
    while let Some(c) = x.next_child(&e, diags)? {
        let Child::Open(c) = c else { continue };
        match c.local() {
            b"name" => name = x.label(c, diags)?.map(|(n, _)| n.trim().to_string()),
            b"initialMarking" => {
                if let Some((text, span)) = x.label(c, diags)? {
                    let owner = format!("place `{id}`");
                    initial =
                        natural(&text, span, "initial marking", &owner, 0, diags).unwrap_or(0);
                }
            }
            b"toolspecific" if x.attr_quiet(&c, "tool").as_deref() == Some("petrel") => {
                petrel = Some(x.node(c, diags)?);
            }
            _ => x.skip(c, diags)?,
        }
    }
    b.places.push(PtPlace {
        name: name.unwrap_or_else(|| id.clone()),
        id,
        initial,
        span: e.span,
    });
    b.place_petrel.push(petrel);
    Ok(())
}

fn read_transition<'a>(
    x: &mut Xml<'a>,
    b: &mut NetBuilder,
    e: Elem<'a>,
    diags: &mut Diagnostics,
) -> Result<(), Fatal> {
    let attrs = x.attrs(&e, diags)?;
    let Some((id, e)) = required_id(x, e, &attrs, diags)? else {
        return Ok(());
    };
    let mut name = None;
    let mut petrel = None;
    while let Some(c) = x.next_child(&e, diags)? {
        let Child::Open(c) = c else { continue };
        match c.local() {
            b"name" => name = x.label(c, diags)?.map(|(n, _)| n.trim().to_string()),
            b"toolspecific" if x.attr_quiet(&c, "tool").as_deref() == Some("petrel") => {
                petrel = Some(x.node(c, diags)?);
            }
            _ => x.skip(c, diags)?,
        }
    }
    b.transitions.push(PtTransition {
        name: name.unwrap_or_else(|| id.clone()),
        id,
        span: e.span,
    });
    b.transition_petrel.push(petrel);
    Ok(())
}

fn read_arc<'a>(
    x: &mut Xml<'a>,
    b: &mut NetBuilder,
    e: Elem<'a>,
    diags: &mut Diagnostics,
) -> Result<(), Fatal> {
    let attrs = x.attrs(&e, diags)?;
    let Some((id, e)) = required_id(x, e, &attrs, diags)? else {
        return Ok(());
    };
    let (source, target) = (attr(&attrs, "source"), attr(&attrs, "target"));
    let (Some(source), Some(target)) = (source, target) else {
        let missing = if source.is_none() { "source" } else { "target" };
        diags.push(
            Diagnostic::error("E0501", e.span, format!("arc `{id}` has no `{missing}`"))
                .label(format!("the {missing} is missing"))
                .help("an arc names the ids it joins: source=\"ID\" target=\"ID\""),
        );
        x.skip(e, diags)?;
        return Ok(());
    };
    let (source, target) = (source.to_string(), target.to_string());
    let mut weight = 1;
    while let Some(c) = x.next_child(&e, diags)? {
        let Child::Open(c) = c else { continue };
        if c.local() == b"inscription" {
            if let Some((text, span)) = x.label(c, diags)? {
                let owner = format!("arc `{id}`");
                weight =
                    natural(&text, span, "inscription (weight)", &owner, 1, diags).unwrap_or(1);
            }
        } else {
            x.skip(c, diags)?;
        }
    }
    b.arcs.push(RawArc {
        id,
        source,
        target,
        weight,
        span: e.span,
    });
    Ok(())
}

/// Checks ids and resolves arcs once the whole net is read.
fn finish_net(
    x: &Xml<'_>,
    b: NetBuilder,
    id: String,
    span: Span,
    diags: &mut Diagnostics,
) -> RawNet {
    let mut nodes: HashMap<&str, (PtNode, Span)> = HashMap::new();
    let all = b
        .places
        .iter()
        .enumerate()
        .map(|(i, p)| (p.id.as_str(), PtNode::Place(i), p.span))
        .chain(
            b.transitions
                .iter()
                .enumerate()
                .map(|(i, t)| (t.id.as_str(), PtNode::Transition(i), t.span)),
        );
    for (node_id, node, node_span) in all {
        if let Some((_, first)) = nodes.get(node_id) {
            diags.push(
                Diagnostic::error(
                    "E0501",
                    node_span,
                    format!(
                        "id `{node_id}` is used twice in net `{id}` (first at {})",
                        x.line_col(first.start as usize)
                    ),
                )
                .label("second use of the id")
                .help("ids are unique in a PNML document: rename one of them"),
            );
        } else {
            nodes.insert(node_id, (node, node_span));
        }
    }
    let kind = |n: PtNode| match n {
        PtNode::Place(_) => "place",
        PtNode::Transition(_) => "transition",
    };
    let mut arcs = Vec::with_capacity(b.arcs.len());
    for a in &b.arcs {
        let source = nodes.get(a.source.as_str()).map(|n| n.0);
        let target = nodes.get(a.target.as_str()).map(|n| n.0);
        for (end, which, found) in [(&a.source, "source", source), (&a.target, "target", target)] {
            if found.is_none() {
                diags.push(
                    Diagnostic::error(
                        "E0502",
                        a.span,
                        format!(
                            "arc `{}` has {which} `{end}`, which is no place or transition of net `{id}`",
                            a.id
                        ),
                    )
                    .label(format!("unknown {which}"))
                    .help("an arc joins a place and a transition of its net: correct the id, or add the missing place or transition"),
                );
            }
        }
        let (Some(s), Some(t)) = (source, target) else {
            continue;
        };
        if kind(s) == kind(t) {
            diags.push(
                Diagnostic::error(
                    "E0502",
                    a.span,
                    format!(
                        "arc `{}` joins {} `{}` to {} `{}`: an arc joins a place and a transition",
                        a.id,
                        kind(s),
                        a.source,
                        kind(t),
                        a.target
                    ),
                )
                .label("same kind at both ends")
                .help("P/T arcs go from a place to a transition or from a transition to a place: add the transition or place in between"),
            );
            continue;
        }
        arcs.push(PtArc {
            id: a.id.clone(),
            source: s,
            target: t,
            weight: a.weight,
            span: a.span,
        });
    }
    RawNet {
        net: PtNet {
            name: b.name.unwrap_or_else(|| id.clone()),
            id,
            places: b.places,
            transitions: b.transitions,
            arcs,
            has_nupn: b.has_nupn,
        },
        span,
        petrel: b.petrel,
        place_petrel: b.place_petrel,
        transition_petrel: b.transition_petrel,
    }
}

/// Reads every P/T net of a PNML document.
///
/// Pages are flattened (nested ones too), absent inscriptions weigh 1, absent initial markings
/// are 0, and tool-specific blocks are ignored (a `nupn` block only sets [`PtNet::has_nupn`]).
/// Problems go to `diags` with codes `E0501` (malformed PNML), `E0502` (bad arc ends) and
/// `E0503` (not a P/T net); the result holds the nets that could be read.
pub fn parse_pnml(file: FileId, text: &str, diags: &mut Diagnostics) -> Vec<PtNet> {
    parse_document(file, text, diags)
        .into_iter()
        .map(|r| r.net)
        .collect()
}

// ---------------------------------------------------------------------------------------------
// The P/T view of a project, shared by export and import
// ---------------------------------------------------------------------------------------------

/// The P/T id of every Petrel place and transition.
#[derive(Default)]
struct Layout {
    /// One per `manifest.globals` entry.
    globals: Vec<String>,
    /// Per net in project order, one per item.
    nets: Vec<Vec<String>>,
}

/// What the P/T net of a project must hold.
struct Structure {
    /// Initial marking per place id, in layout order.
    marking: Vec<(String, u64)>,
    /// `(place id, transition id, input?)` to weight, in first-use order.
    arcs: Vec<((String, String, bool), u64)>,
}

/// The P/T structure of `project` laid out as `layout` says.
///
/// A transition's input or output name resolves to its net's place of that name, else to the
/// global place of that name, else to nothing (the checker reports it; no arc is drawn).
/// Naming a place twice gives one arc of weight 2, which is what it means in P/T terms.
fn structure(project: &Project, layout: &Layout) -> Structure {
    let m = &project.manifest;
    let start: HashSet<&str> = m.start.iter().map(|n| n.as_str()).collect();
    let mut globals: HashMap<&str, &str> = HashMap::new();
    let mut marking = Vec::new();
    for (g, id) in m.globals.iter().zip(&layout.globals) {
        globals.entry(g.name.as_str()).or_insert(id);
        marking.push((id.clone(), u64::from(g.tokens)));
    }
    let mut arcs: Vec<((String, String, bool), u64)> = Vec::new();
    let mut arc_index: HashMap<(String, String, bool), usize> = HashMap::new();
    for (net, ids) in project.nets().zip(&layout.nets) {
        let active = start.contains(net.name.as_str());
        let mut local: HashMap<&str, &str> = HashMap::new();
        for (item, id) in net.items.iter().zip(ids) {
            if let ItemKind::Place(p) = &item.kind {
                local.entry(p.name.as_str()).or_insert(id);
                marking.push((id.clone(), if active { u64::from(p.tokens) } else { 0 }));
            }
        }
        for (item, tid) in net.items.iter().zip(ids) {
            let ItemKind::Transition(t) = &item.kind else {
                continue;
            };
            let ends = t.inputs.iter().map(|n| (n, true));
            for (name, input) in ends.chain(t.outputs.iter().map(|n| (n, false))) {
                let place = local
                    .get(name.as_str())
                    .or_else(|| globals.get(name.as_str()));
                let Some(place) = place else { continue };
                let key = (place.to_string(), tid.clone(), input);
                match arc_index.get(&key) {
                    Some(&i) => arcs[i].1 = arcs[i].1.saturating_add(1),
                    None => {
                        arc_index.insert(key.clone(), arcs.len());
                        arcs.push((key, 1));
                    }
                }
            }
        }
    }
    Structure { marking, arcs }
}

/// Turns any text into a Petrel identifier: other characters become `_`, a leading digit gets
/// a `_` before it, and a keyword gets one after it.
fn sanitize(raw: &str) -> String {
    let mut s: String = raw
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect();
    if !s.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_') {
        s.insert(0, '_');
    }
    if is_keyword(&s) {
        s.push('_');
    }
    s
}

/// Hands out names (or ids) unique within one scope, suffixing `_2`, `_3`... on collision.
#[derive(Default)]
struct Unique {
    used: HashSet<String>,
}

impl Unique {
    fn take(&mut self, base: &str, sep: &str) -> String {
        let mut candidate = base.to_string();
        let mut n = 1u64;
        // Terminates: each round tries a new suffix, and only finitely many are taken.
        while !self.used.insert(candidate.clone()) {
            n += 1;
            candidate = format!("{base}{sep}{n}");
        }
        candidate
    }
}

// ---------------------------------------------------------------------------------------------
// Export
// ---------------------------------------------------------------------------------------------

/// A minimal indenting XML writer; every value goes through [`escape`].
struct Writer {
    out: String,
    depth: usize,
    /// A start tag is written up to its attributes: `>` if content follows, `/>` if not.
    open_tag: bool,
}

impl Writer {
    /// Finishes a pending start tag, now that it has content.
    fn settle(&mut self) {
        if self.open_tag {
            self.out.push_str(">\n");
            self.open_tag = false;
        }
    }

    fn indent(&mut self) {
        self.settle();
        for _ in 0..self.depth {
            self.out.push_str("  ");
        }
    }

    fn tag(&mut self, name: &str, attrs: &[(&str, &str)]) {
        self.indent();
        self.out.push('<');
        self.out.push_str(name);
        for (k, v) in attrs {
            let _ = write!(self.out, " {k}=\"{}\"", escape(v, true));
        }
    }

    fn open(&mut self, name: &str, attrs: &[(&str, &str)]) {
        self.tag(name, attrs);
        self.open_tag = true;
        self.depth += 1;
    }

    fn empty(&mut self, name: &str, attrs: &[(&str, &str)]) {
        self.tag(name, attrs);
        self.out.push_str("/>\n");
    }

    fn close(&mut self, name: &str) {
        self.depth = self.depth.saturating_sub(1);
        if std::mem::take(&mut self.open_tag) {
            self.out.push_str("/>\n");
            return;
        }
        self.indent();
        let _ = writeln!(self.out, "</{name}>");
    }

    /// `<name attrs>text</name>` on one line: the text is kept exactly, with no indentation.
    fn leaf(&mut self, name: &str, attrs: &[(&str, &str)], text: &str) {
        self.tag(name, attrs);
        let _ = writeln!(self.out, ">{}</{name}>", escape(text, false));
    }

    /// `<name><text>text</text></name>`, the PNML label form.
    fn label(&mut self, name: &str, text: &str) {
        self.indent();
        let _ = writeln!(
            self.out,
            "<{name}><text>{}</text></{name}>",
            escape(text, false)
        );
    }

    fn comments(&mut self, tag: &str, list: &[String]) {
        for c in list {
            self.leaf(tag, &[], c);
        }
    }

    fn open_petrel(&mut self) {
        self.open("toolspecific", &[("tool", "petrel"), ("version", "1")]);
    }
}

fn blank_attr(t: &Trivia) -> Option<(&'static str, &'static str)> {
    t.blank_before.then_some(("blank-before", "true"))
}

/// Writes a whole Petrel project as one PNML P/T net with one page.
///
/// Place ids are `NET.place` (local places) and `global.NAME` (global places), transition ids
/// `NET.transition` (suffixed `-2`, `-3`... if a name repeats); arcs follow each transition's
/// inputs and outputs. The initial marking is the project's initial state: nets listed in
/// `start` have their places' tokens, other nets' places none, global places their tokens.
/// Everything else travels in `<toolspecific tool="petrel" version="1">` blocks, so that
/// [`import_pnml`] gives back an equal [`Project`].
pub fn export_pnml(project: &Project) -> String {
    let m = &project.manifest;
    let mut ids = Unique::default();
    let net_id = ids.take(
        &if m.name.is_empty() {
            "petrel".to_string()
        } else {
            sanitize(&m.name)
        },
        "-",
    );
    let page_id = ids.take(&format!("{net_id}.page"), "-");
    let mut layout = Layout::default();
    for g in &m.globals {
        layout
            .globals
            .push(ids.take(&format!("global.{}", g.name), "-"));
    }
    for net in project.nets() {
        let list = net
            .items
            .iter()
            .map(|item| {
                let name = match &item.kind {
                    ItemKind::Place(p) => &p.name,
                    ItemKind::Transition(t) => &t.name,
                };
                ids.take(&format!("{}.{}", net.name, name), "-")
            })
            .collect();
        layout.nets.push(list);
    }
    let st = structure(project, &layout);
    let marking: HashMap<&str, u64> = st.marking.iter().map(|(k, v)| (k.as_str(), *v)).collect();

    let mut w = Writer {
        out: String::new(),
        depth: 0,
        open_tag: false,
    };
    w.out
        .push_str("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
    w.open("pnml", &[("xmlns", PNML_NAMESPACE)]);
    w.open("net", &[("id", &net_id), ("type", PTNET_TYPE)]);
    w.label("name", &m.name);
    w.open_petrel();
    write_manifest(&mut w, m, &layout);
    let mut net_index = 0;
    for file in &project.files {
        w.open("netfile", &[("path", &file.path)]);
        for net in &file.nets {
            let mut attrs = vec![("name", net.name.as_str())];
            attrs.extend(blank_attr(&net.trivia));
            w.open("net", &attrs);
            w.comments("comment", &net.trivia.comments);
            for id in layout.nets.get(net_index).into_iter().flatten() {
                w.empty("item", &[("ref", id)]);
            }
            w.comments("end-comment", &net.end_comments);
            w.close("net");
            net_index += 1;
        }
        w.comments("end-comment", &file.end_comments);
        w.close("netfile");
    }
    w.close("toolspecific");

    w.open("page", &[("id", &page_id)]);
    for (g, id) in m.globals.iter().zip(&layout.globals) {
        w.open("place", &[("id", id)]);
        w.label("name", g.name.as_str());
        let tokens = marking.get(id.as_str()).copied().unwrap_or(0);
        if tokens > 0 {
            w.label("initialMarking", &tokens.to_string());
        }
        w.close("place");
    }
    for (net, ids) in project.nets().zip(&layout.nets) {
        for (item, id) in net.items.iter().zip(ids) {
            match &item.kind {
                ItemKind::Place(p) => {
                    w.open("place", &[("id", id)]);
                    w.label("name", p.name.as_str());
                    let tokens = marking.get(id.as_str()).copied().unwrap_or(0);
                    if tokens > 0 {
                        w.label("initialMarking", &tokens.to_string());
                    }
                    write_place_block(&mut w, item, p);
                    w.close("place");
                }
                ItemKind::Transition(t) => {
                    w.open("transition", &[("id", id)]);
                    w.label("name", t.name.as_str());
                    write_transition_block(&mut w, item, t);
                    w.close("transition");
                }
            }
        }
    }
    let mut arc_ids = Unique::default();
    for ((place, transition, input), weight) in &st.arcs {
        let (source, target) = if *input {
            (place, transition)
        } else {
            (transition, place)
        };
        let base = format!("{transition}.{}", if *input { "in" } else { "out" });
        // Arc ids share the document's id space with places and transitions.
        let mut id = arc_ids.take(&base, "");
        while ids.used.contains(&id) {
            id = arc_ids.take(&base, "");
        }
        ids.used.insert(id.clone());
        if *weight == 1 {
            w.empty(
                "arc",
                &[("id", &id), ("source", source), ("target", target)],
            );
        } else {
            w.open(
                "arc",
                &[("id", &id), ("source", source), ("target", target)],
            );
            w.label("inscription", &weight.to_string());
            w.close("arc");
        }
    }
    w.close("page");
    w.close("net");
    w.close("pnml");
    w.out
}

fn write_params(w: &mut Writer, params: &[Param]) {
    for p in params {
        w.empty(
            "param",
            &[("name", p.name.as_str()), ("type", p.ty.keyword())],
        );
    }
}

fn write_manifest(w: &mut Writer, m: &Manifest, layout: &Layout) {
    w.open("manifest", &[("name", &m.name)]);
    if let Some(d) = &m.description {
        w.leaf("description", &[], d);
    }
    for f in &m.files {
        w.empty("file", &[("path", &f.path)]);
    }
    for s in &m.start {
        w.empty("start", &[("net", s.as_str())]);
    }
    for (g, id) in m.globals.iter().zip(&layout.globals) {
        w.empty(
            "global",
            &[
                ("name", g.name.as_str()),
                ("tokens", &g.tokens.to_string()),
                ("ref", id),
            ],
        );
    }
    for e in &m.events {
        w.open(
            "event",
            &[
                ("name", e.name.as_str()),
                ("category", e.category.keyword()),
            ],
        );
        if let Some(d) = &e.description {
            w.leaf("description", &[], d);
        }
        write_params(w, &e.params);
        w.close("event");
    }
    for p in &m.programs {
        w.open("program", &[("name", p.name.as_str())]);
        if let Some(d) = &p.description {
            w.leaf("description", &[], d);
        }
        for f in &p.functions {
            w.open("function", &[("name", f.name.as_str())]);
            write_params(w, &f.params);
            w.close("function");
        }
        w.close("program");
    }
    for t in &m.timers {
        w.empty(
            "timer",
            &[("name", t.name.as_str()), ("event", t.event.as_str())],
        );
    }
    for f in &m.finals {
        w.open("final", &[]);
        for p in f {
            w.empty("place", &[("name", p.as_str())]);
        }
        w.close("final");
    }
    w.close("manifest");
}

fn write_place_block(w: &mut Writer, item: &Item, p: &PlaceDecl) {
    w.open_petrel();
    let tokens = p.tokens.to_string();
    let mut attrs = vec![("name", p.name.as_str()), ("tokens", tokens.as_str())];
    if p.tokens_span.is_some() {
        attrs.push(("marking-written", "true"));
    }
    attrs.extend(blank_attr(&item.trivia));
    w.open("place", &attrs);
    w.comments("comment", &item.trivia.comments);
    if let Some(c) = &item.trailing {
        w.leaf("trailing", &[], c);
    }
    w.close("place");
    w.close("toolspecific");
}

fn write_transition_block(w: &mut Writer, item: &Item, t: &TransitionDecl) {
    w.open_petrel();
    let mut attrs = vec![("name", t.name.as_str())];
    attrs.extend(blank_attr(&item.trivia));
    w.open("transition", &attrs);
    w.comments("comment", &item.trivia.comments);
    if let Some(c) = &item.trailing {
        w.leaf("trailing", &[], c);
    }
    if let Some(trigger) = &t.trigger {
        w.open("trigger", &[("event", trigger.event.as_str())]);
        for b in &trigger.bindings {
            match &b.ty {
                Some((ty, _)) => w.empty(
                    "binding",
                    &[("name", b.name.as_str()), ("type", ty.keyword())],
                ),
                None => w.empty("binding", &[("name", b.name.as_str())]),
            }
        }
        w.close("trigger");
    }
    for n in &t.inputs {
        w.empty("input", &[("place", n.as_str())]);
    }
    for n in &t.outputs {
        w.empty("output", &[("place", n.as_str())]);
    }
    for a in &t.actions {
        let mut attrs = Vec::new();
        attrs.extend(blank_attr(&a.trivia));
        w.open("action", &attrs);
        w.comments("comment", &a.trivia.comments);
        w.leaf("code", &[], &format_action(&a.action));
        if let Some(c) = &a.trailing {
            w.leaf("trailing", &[], c);
        }
        w.close("action");
    }
    w.comments("end-comment", &t.end_comments);
    w.close("transition");
    w.close("toolspecific");
}

// ---------------------------------------------------------------------------------------------
// Import
// ---------------------------------------------------------------------------------------------

/// Reads a PNML document as a Petrel project.
///
/// A document written by [`export_pnml`] (it carries a net-level `<toolspecific
/// tool="petrel">` block) gives back the exact project, after checking that the P/T structure
/// still agrees with the Petrel data (`E0506` otherwise). Any other P/T net becomes a project
/// with one net file per net, named from the PNML ids made into identifiers, with immediate
/// transitions and no actions; every arc weight above 1 (`E0504`) and every initial marking
/// above 1 (`E0505`) is reported, since Petrel nets are unary and safe. Returns `None` when any
/// error was found.
pub fn import_pnml(file: FileId, text: &str, diags: &mut Diagnostics) -> Option<Project> {
    let before = diags.error_count();
    let raws = parse_document(file, text, diags);
    let parse_failed = diags.error_count() > before;
    if raws.iter().any(|r| r.petrel.is_some()) {
        if raws.len() > 1 {
            let span = raws.get(1).map(|r| r.span).unwrap_or_default();
            diags.push(
                Diagnostic::error(
                    "E0506",
                    span,
                    format!(
                        "this document holds {} nets and Petrel data: a Petrel export is one net",
                        raws.len()
                    ),
                )
                .label("a second net")
                .help(PETREL_DATA_HELP),
            );
            return None;
        }
        if parse_failed {
            return None;
        }
        let raw = raws.first()?;
        return Rebuild {
            file,
            diags,
            raw,
            before,
        }
        .project();
    }
    if raws.is_empty() {
        if !parse_failed {
            diags.push(
                Diagnostic::error("E0501", Span::new(file, 0, 0), "this document holds no `<net>`")
                    .label("no net to import")
                    .help("a PNML file holds one or more `<net type=\"http://www.pnml.org/version-2009/grammar/ptnet\">`"),
            );
        }
        return None;
    }
    let project = plain_project(&raws, diags);
    if diags.error_count() > before {
        return None;
    }
    Some(project)
}

/// The project of plain P/T nets, reporting whatever Petrel nets cannot express.
fn plain_project(raws: &[RawNet], diags: &mut Diagnostics) -> Project {
    let mut net_names = Unique::default();
    let mut manifest = Manifest::default();
    let mut files = Vec::new();
    for raw in raws {
        let pt = &raw.net;
        for p in &pt.places {
            if p.initial > 1 {
                diags.push(
                    Diagnostic::error(
                        "E0505",
                        p.span,
                        format!(
                            "place `{}` starts with {} tokens, but a Petrel place holds at most one",
                            p.id, p.initial
                        ),
                    )
                    .label(format!("initial marking {}", p.initial))
                    .help(format!("Petrel mission nets are safe, so this net cannot become one; {VERIFY_HINT}")),
                );
            }
        }
        let mut seen: HashMap<(usize, usize, bool), &str> = HashMap::new();
        for a in &pt.arcs {
            let end = |n: PtNode| match n {
                PtNode::Place(i) => pt.places.get(i).map(|p| p.id.as_str()),
                PtNode::Transition(i) => pt.transitions.get(i).map(|t| t.id.as_str()),
            };
            let (from, to) = (end(a.source).unwrap_or("?"), end(a.target).unwrap_or("?"));
            let key = (
                a.place().unwrap_or(0),
                a.transition().unwrap_or(0),
                a.is_input(),
            );
            if a.weight > 1 {
                diags.push(
                    Diagnostic::error(
                        "E0504",
                        a.span,
                        format!(
                            "arc `{}` from `{from}` to `{to}` has weight {}, but Petrel nets have unary arcs",
                            a.id, a.weight
                        ),
                    )
                    .label(format!("weight {}", a.weight))
                    .help(format!("a Petrel transition moves one token per place, so this net cannot become a mission net; {VERIFY_HINT}")),
                );
            } else if let Some(first) = seen.get(&key) {
                diags.push(
                    Diagnostic::error(
                        "E0504",
                        a.span,
                        format!(
                            "arc `{}` from `{from}` to `{to}` repeats arc `{first}`: together they weigh 2, but Petrel nets have unary arcs",
                            a.id
                        ),
                    )
                    .label("parallel arc")
                    .help(format!("merge the two arcs if one is a mistake; {VERIFY_HINT}")),
                );
            }
            seen.entry(key).or_insert(a.id.as_str());
        }
        let net_name = net_names.take(&sanitize(&pt.id), "_");
        let origin = |id: &str, name: &str| {
            if id == name {
                Vec::new()
            } else {
                vec![format!("PNML id {id:?}")]
            }
        };
        let mut names = Unique::default();
        let place_names: Vec<String> = pt
            .places
            .iter()
            .map(|p| names.take(&sanitize(&p.id), "_"))
            .collect();
        let mut items = Vec::new();
        for (p, name) in pt.places.iter().zip(&place_names) {
            items.push(Item {
                trivia: Trivia {
                    blank_before: false,
                    comments: origin(&p.id, name),
                },
                kind: ItemKind::Place(PlaceDecl {
                    name: Name {
                        text: name.clone(),
                        span: p.span,
                    },
                    tokens: u32::try_from(p.initial).unwrap_or(u32::MAX),
                    tokens_span: (p.initial > 0).then_some(p.span),
                }),
                trailing: None,
            });
        }
        let mut inputs: Vec<Vec<Name>> = vec![Vec::new(); pt.transitions.len()];
        let mut outputs: Vec<Vec<Name>> = vec![Vec::new(); pt.transitions.len()];
        for a in &pt.arcs {
            let (Some(p), Some(t)) = (a.place(), a.transition()) else {
                continue;
            };
            let (Some(name), Some(list)) = (
                place_names.get(p),
                if a.is_input() {
                    inputs.get_mut(t)
                } else {
                    outputs.get_mut(t)
                },
            ) else {
                continue;
            };
            list.push(Name {
                text: name.clone(),
                span: a.span,
            });
        }
        for ((t, ins), outs) in pt.transitions.iter().zip(inputs).zip(outputs) {
            let name = names.take(&sanitize(&t.id), "_");
            items.push(Item {
                trivia: Trivia {
                    blank_before: false,
                    comments: origin(&t.id, &name),
                },
                kind: ItemKind::Transition(TransitionDecl {
                    name: Name {
                        text: name,
                        span: t.span,
                    },
                    trigger: None,
                    inputs: ins,
                    outputs: outs,
                    actions: Vec::new(),
                    end_comments: Vec::new(),
                }),
                trailing: None,
            });
        }
        let path = format!("{net_name}.pn");
        manifest.files.push(FileRef {
            path: path.clone(),
            span: raw.span,
        });
        manifest.start.push(Name {
            text: net_name.clone(),
            span: raw.span,
        });
        files.push(NetFile {
            path,
            nets: vec![NetDecl {
                trivia: Trivia {
                    blank_before: false,
                    comments: origin(&pt.id, &net_name),
                },
                name: Name {
                    text: net_name,
                    span: raw.span,
                },
                items,
                end_comments: Vec::new(),
            }],
            end_comments: Vec::new(),
        });
    }
    manifest.name = raws
        .first()
        .map(|r| sanitize(&r.net.id))
        .unwrap_or_default();
    Project { manifest, files }
}

/// Rebuilds a project from an export's Petrel blocks, reporting every problem (`E0506`).
struct Rebuild<'r, 'd> {
    file: FileId,
    diags: &'d mut Diagnostics,
    raw: &'r RawNet,
    /// Error count when the import began: any more means failure.
    before: usize,
}

impl Rebuild<'_, '_> {
    fn bad(&mut self, span: Span, message: impl Into<String>) {
        self.diags.push(
            Diagnostic::error("E0506", span, message)
                .label("Petrel data in question")
                .help(PETREL_DATA_HELP),
        );
    }

    fn req<'n>(&mut self, n: &'n Node, key: &str) -> &'n str {
        match n.attr(key) {
            Some(v) => v,
            None => {
                self.bad(
                    n.span,
                    format!("petrel element `<{}>` lacks its `{key}` attribute", n.name),
                );
                ""
            }
        }
    }

    fn name(&mut self, n: &Node, key: &str) -> Name {
        Name {
            text: self.req(n, key).to_string(),
            span: n.span,
        }
    }

    fn flag(&mut self, n: &Node, key: &str) -> bool {
        match n.attr(key) {
            None | Some("false") => false,
            Some("true") => true,
            Some(other) => {
                self.bad(
                    n.span,
                    format!(
                        "petrel attribute `{key}` of `<{}>` is `{other}`, not `true` or `false`",
                        n.name
                    ),
                );
                false
            }
        }
    }

    fn number<T: std::str::FromStr + Default>(&mut self, n: &Node, key: &str) -> T {
        let v = self.req(n, key).to_string();
        match v.parse() {
            Ok(x) => x,
            Err(_) => {
                if n.attr(key).is_some() {
                    self.bad(
                        n.span,
                        format!(
                            "petrel attribute `{key}` of `<{}>` is `{v}`, not a number",
                            n.name
                        ),
                    );
                }
                T::default()
            }
        }
    }

    fn ty(&mut self, n: &Node) -> Type {
        let v = self.req(n, "type").to_string();
        Type::from_keyword(&v).unwrap_or_else(|| {
            if n.attr("type").is_some() {
                self.bad(n.span, format!("`{v}` is not a Petrel type"));
            }
            Type::Int
        })
    }

    fn trivia(&mut self, n: &Node) -> Trivia {
        Trivia {
            blank_before: self.flag(n, "blank-before"),
            comments: texts(n, "comment"),
        }
    }

    fn params(&mut self, n: &Node) -> Vec<Param> {
        n.children("param")
            .map(|p| Param {
                name: self.name(p, "name"),
                ty: self.ty(p),
            })
            .collect()
    }

    fn manifest(&mut self, n: &Node) -> Manifest {
        let mut m = Manifest {
            name: self.req(n, "name").to_string(),
            description: n.child("description").map(|d| d.text.clone()),
            ..Manifest::default()
        };
        for f in n.children("file") {
            m.files.push(FileRef {
                path: self.req(f, "path").to_string(),
                span: f.span,
            });
        }
        for s in n.children("start") {
            m.start.push(self.name(s, "net"));
        }
        for g in n.children("global") {
            m.globals.push(GlobalPlaceDecl {
                name: self.name(g, "name"),
                tokens: self.number(g, "tokens"),
            });
        }
        for e in n.children("event") {
            let cat = self.req(e, "category").to_string();
            let category = Category::from_keyword(&cat).unwrap_or_else(|| {
                if e.attr("category").is_some() {
                    self.bad(e.span, format!("`{cat}` is not an event category"));
                }
                Category::Nominal
            });
            m.events.push(EventDecl {
                name: self.name(e, "name"),
                category,
                params: self.params(e),
                description: e.child("description").map(|d| d.text.clone()),
            });
        }
        for p in n.children("program") {
            let functions = p
                .children("function")
                .map(|f| FunctionDecl {
                    name: self.name(f, "name"),
                    params: self.params(f),
                })
                .collect();
            m.programs.push(ProgramDecl {
                name: self.name(p, "name"),
                description: p.child("description").map(|d| d.text.clone()),
                functions,
            });
        }
        for t in n.children("timer") {
            m.timers.push(TimerDecl {
                name: self.name(t, "name"),
                event: self.name(t, "event"),
            });
        }
        for f in n.children("final") {
            let places = f
                .children("place")
                .map(|p| Name {
                    text: self.req(p, "name").to_string(),
                    span: p.span,
                })
                .collect();
            m.finals.push(places);
        }
        m
    }

    /// The data node (`<place>` or `<transition>`) of an element's Petrel block.
    fn element_data<'n>(
        &mut self,
        block: Option<&'n Node>,
        kind: &str,
        id: &str,
        span: Span,
    ) -> Option<&'n Node> {
        let found = block.and_then(|b| b.child(kind));
        if found.is_none() {
            self.bad(
                span,
                format!("{kind} `{id}` has no petrel data, though the net's petrel block lists it"),
            );
        }
        found
    }

    fn place(&mut self, n: &Node) -> Item {
        let tokens = self.number(n, "tokens");
        let tokens_span = self.flag(n, "marking-written").then_some(n.span);
        Item {
            trivia: self.trivia(n),
            kind: ItemKind::Place(PlaceDecl {
                name: self.name(n, "name"),
                tokens,
                tokens_span,
            }),
            trailing: n.child("trailing").map(|t| t.text.clone()),
        }
    }

    fn transition(&mut self, n: &Node) -> Item {
        let trigger = n.child("trigger").map(|tr| Trigger {
            event: self.name(tr, "event"),
            bindings: tr
                .children("binding")
                .map(|b| Binding {
                    name: self.name(b, "name"),
                    ty: b.attr("type").is_some().then(|| (self.ty(b), b.span)),
                })
                .collect(),
        });
        let inputs = n.children("input").map(|i| self.name(i, "place")).collect();
        let outputs = n
            .children("output")
            .map(|o| self.name(o, "place"))
            .collect();
        let actions = n
            .children("action")
            .filter_map(|a| self.action(a))
            .collect();
        Item {
            trivia: self.trivia(n),
            kind: ItemKind::Transition(TransitionDecl {
                name: self.name(n, "name"),
                trigger,
                inputs,
                outputs,
                actions,
                end_comments: texts(n, "end-comment"),
            }),
            trailing: n.child("trailing").map(|t| t.text.clone()),
        }
    }

    fn action(&mut self, n: &Node) -> Option<ActionItem> {
        let Some(code) = n.child("code") else {
            self.bad(n.span, "petrel `<action>` lacks its `<code>`");
            return None;
        };
        // The action text has its own offsets, so its diagnostics are summarised at the
        // `<code>` element, and its spans all point there.
        let mut inner = Diagnostics::new();
        let parsed = parse_action(self.file, &code.text, &mut inner);
        let action = match parsed {
            Some(a) if !inner.has_errors() => a,
            _ => {
                let why = inner
                    .iter()
                    .next()
                    .map(|d| d.message.clone())
                    .unwrap_or_else(|| "it is not an action".into());
                self.bad(
                    code.span,
                    format!("petrel action `{}` does not parse: {why}", code.text),
                );
                return None;
            }
        };
        Some(ActionItem {
            trivia: self.trivia(n),
            action: respan_action(action, code.span),
            trailing: n.child("trailing").map(|t| t.text.clone()),
        })
    }

    fn project(mut self) -> Option<Project> {
        let raw = self.raw;
        let pt = &raw.net;
        let block = raw.petrel.as_ref()?;
        if block.attr("version") != Some("1") {
            self.bad(
                block.span,
                format!(
                    "petrel data version `{}` is not version 1, the one this Petrel reads",
                    block.attr("version").unwrap_or("")
                ),
            );
            return None;
        }
        let Some(mnode) = block.child("manifest") else {
            self.bad(block.span, "the petrel block has no `<manifest>`");
            return None;
        };
        let manifest = self.manifest(mnode);

        let place_ids: HashMap<&str, usize> = pt
            .places
            .iter()
            .enumerate()
            .map(|(i, p)| (p.id.as_str(), i))
            .collect();
        let transition_ids: HashMap<&str, usize> = pt
            .transitions
            .iter()
            .enumerate()
            .map(|(i, t)| (t.id.as_str(), i))
            .collect();
        let mut place_used = vec![false; pt.places.len()];
        let mut transition_used = vec![false; pt.transitions.len()];
        let mut layout = Layout::default();

        for g in mnode.children("global") {
            let id = self.req(g, "ref").to_string();
            match place_ids.get(id.as_str()) {
                Some(&i) if !place_used[i] => place_used[i] = true,
                Some(_) => self.bad(g.span, format!("place `{id}` is claimed twice")),
                None => self.bad(
                    g.span,
                    format!("global place `{id}` is not a place of the P/T net"),
                ),
            }
            layout.globals.push(id);
        }

        let mut files = Vec::new();
        for f in block.children("netfile") {
            let mut nets = Vec::new();
            for n in f.children("net") {
                let mut items = Vec::new();
                let mut ids = Vec::new();
                for item in n.children("item") {
                    let id = self.req(item, "ref").to_string();
                    if let Some(&i) = place_ids.get(id.as_str()) {
                        if std::mem::replace(&mut place_used[i], true) {
                            self.bad(item.span, format!("place `{id}` is claimed twice"));
                        }
                        let span = pt.places[i].span;
                        let data = raw.place_petrel.get(i).and_then(Option::as_ref);
                        if let Some(d) = self.element_data(data, "place", &id, span) {
                            items.push(self.place(d));
                        }
                    } else if let Some(&i) = transition_ids.get(id.as_str()) {
                        if std::mem::replace(&mut transition_used[i], true) {
                            self.bad(item.span, format!("transition `{id}` is claimed twice"));
                        }
                        let span = pt.transitions[i].span;
                        let data = raw.transition_petrel.get(i).and_then(Option::as_ref);
                        if let Some(d) = self.element_data(data, "transition", &id, span) {
                            items.push(self.transition(d));
                        }
                    } else {
                        self.bad(
                            item.span,
                            format!("item `{id}` is no place or transition of the P/T net"),
                        );
                    }
                    ids.push(id);
                }
                layout.nets.push(ids);
                nets.push(NetDecl {
                    trivia: self.trivia(n),
                    name: self.name(n, "name"),
                    items,
                    end_comments: texts(n, "end-comment"),
                });
            }
            files.push(NetFile {
                path: self.req(f, "path").to_string(),
                nets,
                end_comments: texts(f, "end-comment"),
            });
        }
        for (p, used) in pt.places.iter().zip(&place_used) {
            if !used {
                self.bad(
                    p.span,
                    format!(
                        "place `{}` is not in the Petrel data: the P/T net was changed",
                        p.id
                    ),
                );
            }
        }
        for (t, used) in pt.transitions.iter().zip(&transition_used) {
            if !used {
                self.bad(
                    t.span,
                    format!(
                        "transition `{}` is not in the Petrel data: the P/T net was changed",
                        t.id
                    ),
                );
            }
        }
        if self.diags.error_count() > self.before {
            return None;
        }
        let project = Project { manifest, files };
        self.check_structure(&project, &layout, &place_ids, &transition_ids);
        (self.diags.error_count() == self.before).then_some(project)
    }

    /// Compares the P/T net with the structure the rebuilt project implies.
    fn check_structure(
        &mut self,
        project: &Project,
        layout: &Layout,
        place_ids: &HashMap<&str, usize>,
        transition_ids: &HashMap<&str, usize>,
    ) {
        let raw = self.raw;
        let pt = &raw.net;
        let expected = structure(project, layout);
        for (id, tokens) in &expected.marking {
            if let Some(p) = place_ids.get(id.as_str()).and_then(|&i| pt.places.get(i)) {
                if p.initial != *tokens {
                    self.bad(
                        p.span,
                        format!(
                            "place `{id}` starts with {} tokens in the P/T net, but the Petrel data gives {tokens}",
                            p.initial
                        ),
                    );
                }
            }
        }
        let mut actual: Vec<((String, String, bool), u64, Span)> = Vec::new();
        let mut index: HashMap<(String, String, bool), usize> = HashMap::new();
        for a in &pt.arcs {
            let (Some(p), Some(t)) = (
                a.place().and_then(|i| pt.places.get(i)),
                a.transition().and_then(|i| pt.transitions.get(i)),
            ) else {
                continue;
            };
            let key = (p.id.clone(), t.id.clone(), a.is_input());
            match index.get(&key) {
                Some(&i) => actual[i].1 = actual[i].1.saturating_add(a.weight),
                None => {
                    index.insert(key.clone(), actual.len());
                    actual.push((key, a.weight, a.span));
                }
            }
        }
        let wanted: HashMap<&(String, String, bool), u64> =
            expected.arcs.iter().map(|(k, w)| (k, *w)).collect();
        let describe = |(p, t, input): &(String, String, bool)| {
            if *input {
                format!("from `{p}` to `{t}`")
            } else {
                format!("from `{t}` to `{p}`")
            }
        };
        for (key, weight, span) in &actual {
            match wanted.get(key) {
                Some(w) if w == weight => {}
                Some(w) => self.bad(
                    *span,
                    format!(
                        "the arc {} weighs {weight} in the P/T net, but the Petrel data gives {w}",
                        describe(key)
                    ),
                ),
                None => self.bad(
                    *span,
                    format!(
                        "the arc {} is not in the Petrel data: the P/T net was changed",
                        describe(key)
                    ),
                ),
            }
        }
        for (key, _) in &expected.arcs {
            if !index.contains_key(key) {
                let span = transition_ids
                    .get(key.1.as_str())
                    .and_then(|&i| pt.transitions.get(i))
                    .map(|t| t.span)
                    .unwrap_or(raw.span);
                self.bad(
                    span,
                    format!(
                        "the P/T net lacks the arc {} that the transition's Petrel inputs and outputs imply",
                        describe(key)
                    ),
                );
            }
        }
    }
}

/// The exact texts of the children named `name`.
fn texts(n: &Node, name: &str) -> Vec<String> {
    n.children(name).map(|c| c.text.clone()).collect()
}

/// Points every span of an action parsed from a Petrel block at the block's `<code>` element:
/// the parser's offsets are into the action text, which is not the file.
fn respan_action(a: Action, span: Span) -> Action {
    let name = |n: Name| Name { text: n.text, span };
    match a {
        Action::Activate(n) => Action::Activate(name(n)),
        Action::Deactivate(n) => Action::Deactivate(name(n)),
        Action::CancelTimer(n) => Action::CancelTimer(name(n)),
        Action::StartTimer { timer, after } => Action::StartTimer {
            timer: name(timer),
            after: match after {
                DurationExpr::Literal { value, unit, .. } => {
                    DurationExpr::Literal { value, unit, span }
                }
                DurationExpr::Seconds(n) => DurationExpr::Seconds(name(n)),
            },
        },
        Action::Call {
            program,
            function,
            args,
            ..
        } => Action::Call {
            program: name(program),
            function: name(function),
            args: args.into_iter().map(|e| respan_expr(e, span)).collect(),
            span,
        },
        Action::Emit { event, args, .. } => Action::Emit {
            event: name(event),
            args: args.into_iter().map(|e| respan_expr(e, span)).collect(),
            span,
        },
    }
}

fn respan_expr(e: Expr, span: Span) -> Expr {
    match e {
        Expr::Int(v, _) => Expr::Int(v, span),
        Expr::Float(v, _) => Expr::Float(v, span),
        Expr::Bool(v, _) => Expr::Bool(v, span),
        Expr::Text(v, _) => Expr::Text(v, span),
        // Lists nest only as deep as the action text, which the parser already read.
        Expr::List(items, _) => Expr::List(
            items.into_iter().map(|i| respan_expr(i, span)).collect(),
            span,
        ),
        Expr::Var(n) => Expr::Var(Name { text: n.text, span }),
    }
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

    #[test]
    fn sanitize_makes_identifiers() {
        for (raw, want) in [
            ("cId-44", "cId_44"),
            ("1st", "_1st"),
            ("", "_"),
            ("true", "true_"),
            ("é", "_"),
            ("ok_1", "ok_1"),
        ] {
            assert_eq!(sanitize(raw), want);
            assert!(is_identifier(&sanitize(raw)), "{raw}");
        }
    }

    #[test]
    fn pt_types() {
        assert!(is_pt_type(PTNET_TYPE));
        assert!(is_pt_type(
            "http://www.informatik.hu-berlin.de/top/pntd/ptNetb"
        ));
        assert!(!is_pt_type(
            "http://www.pnml.org/version-2009/grammar/symmetricnet"
        ));
        assert!(!is_pt_type(
            "http://www.pnml.org/version-2009/grammar/pt-hlpng"
        ));
    }
}
