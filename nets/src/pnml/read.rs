//! Reading any P/T-net PNML document into [`PtNet`]s ([`parse_pnml`]), keeping the Petrel
//! blocks for [`super::import_pnml`].

use std::collections::HashMap;

use quick_xml::events::Event;

use super::xml::{attr, Child, Elem, Fatal, Node, Xml};
use super::PTNET_TYPE;
use crate::pt::{PtArc, PtNet, PtNode, PtPlace, PtTransition};
use petrel_diag::report::{Diagnostic, Diagnostics};
use petrel_diag::source::{FileId, Span};

/// Deepest `<page>` nesting accepted: the page reader recurses, and a hostile file must not be
/// able to overflow the stack.
const MAX_PAGE_DEPTH: usize = 64;

/// The help shown for every problem in Petrel blocks: they are machine-written, so a problem
/// means another tool or a person changed them.
pub(super) const PETREL_DATA_HELP: &str = "the `<toolspecific tool=\"petrel\">` data was changed after Petrel exported it: export the project again, or delete every petrel block to import the plain P/T net";

/// A net as read, with the Petrel blocks kept for [`super::import_pnml`].
pub(super) struct RawNet {
    pub(super) net: PtNet,
    /// The `<net>` start tag.
    pub(super) span: Span,
    pub(super) petrel: Option<Node>,
    pub(super) place_petrel: Vec<Option<Node>>,
    pub(super) transition_petrel: Vec<Option<Node>>,
}

/// An arc before its ends are resolved (arcs may come before the nodes they join).
pub(super) struct RawArc {
    pub(super) id: String,
    pub(super) source: String,
    pub(super) target: String,
    pub(super) weight: u64,
    pub(super) span: Span,
}

#[derive(Default)]
pub(super) struct NetBuilder {
    pub(super) name: Option<String>,
    pub(super) has_nupn: bool,
    pub(super) places: Vec<PtPlace>,
    pub(super) place_petrel: Vec<Option<Node>>,
    pub(super) transitions: Vec<PtTransition>,
    pub(super) transition_petrel: Vec<Option<Node>>,
    pub(super) arcs: Vec<RawArc>,
    pub(super) petrel: Option<Node>,
}

/// True for the PNML types of P/T nets: the 2009 standard grammar (and its variants that end
/// the same way) and the 2004 Humboldt-University `ptNetb`.
pub(super) fn is_pt_type(ty: &str) -> bool {
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
pub(super) fn natural(
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
pub(super) fn parse_document(file: FileId, text: &str, diags: &mut Diagnostics) -> Vec<RawNet> {
    let mut x = Xml::new(file, text);
    let mut nets = Vec::new();
    // Errors stop the reading, but the nets completed before them are kept.
    let _ = read_root(&mut x, &mut nets, diags);
    nets
}

pub(super) fn read_root<'a>(
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

pub(super) fn read_net<'a>(
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
pub(super) fn read_container<'a>(
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
pub(super) fn required_id<'a>(
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

pub(super) fn read_place<'a>(
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

pub(super) fn read_transition<'a>(
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

pub(super) fn read_arc<'a>(
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
pub(super) fn finish_net(
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
            petrel_export: b.petrel.is_some(),
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
/// are 0, and tool-specific blocks are ignored (a `nupn` block only sets [`PtNet::has_nupn`], a
/// net-level `petrel` block [`PtNet::petrel_export`]).
/// Problems go to `diags` with codes `E0501` (malformed PNML), `E0502` (bad arc ends) and
/// `E0503` (not a P/T net); the result holds the nets that could be read.
pub fn parse_pnml(file: FileId, text: &str, diags: &mut Diagnostics) -> Vec<PtNet> {
    parse_document(file, text, diags)
        .into_iter()
        .map(|r| r.net)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

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
