//! Writing a Petrel project as one P/T net with its Petrel blocks ([`export_pnml`]).

use std::collections::HashMap;
use std::fmt::Write as _;

use super::view::{sanitize, structure, Layout, Unique};
use super::xml::escape;
use super::{PNML_NAMESPACE, PTNET_TYPE};
use crate::fmt::format_action;
use crate::model::*;

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
/// [`super::import_pnml`] gives back an equal [`Project`].
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
                    // Not a P/T element: it travels in the net's Petrel block.
                    ItemKind::Children(_) => return String::new(),
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
                ItemKind::Children(_) => {}
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
