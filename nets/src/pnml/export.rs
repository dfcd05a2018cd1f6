//! Writing a Petrel project as one P/T net with its Petrel block ([`export_pnml`]).

use std::collections::HashMap;
use std::fmt::Write as _;

use super::view::{nodes, sanitize, structure, Layout, Node, Unique};
use super::xml::escape;
use super::{PETREL_VERSION, PNML_NAMESPACE, PTNET_TYPE};
use crate::fmt::{format_action, format_expr, format_guard};
use crate::instances::instances;
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
        self.open(
            "toolspecific",
            &[("tool", "petrel"), ("version", PETREL_VERSION)],
        );
    }
}

fn blank_attr(t: &Trivia) -> Option<(&'static str, &'static str)> {
    t.blank_before.then_some(("blank-before", "true"))
}

/// Arguments as the net language writes them between parentheses: `"r1", 0.5, self.speed`.
fn args_text(args: &[Expr]) -> String {
    args.iter().map(format_expr).collect::<Vec<_>>().join(", ")
}

/// The P/T id prefix of an instance: its name, with the `/` of a child instance (not allowed
/// in an XML id) written `-`, which no net name holds.
fn id_prefix(instance: &str) -> String {
    instance.replace('/', "-")
}

/// Writes a whole Petrel project as one PNML P/T net with one page.
///
/// The page is the project's **P/T skeleton**, expanded into the nets the project runs (see
/// [`crate::instances`]): each instance has its own places, transitions and completion places,
/// with ids `NET.place`, `NET.transition` and `NET.CHILD.done` (`R1.moving`,
/// `MISSION-TRANSIT.cruising` for the child instance `MISSION/TRANSIT`), global places are
/// `global.NAME`, and ids that would repeat are suffixed `-2`, `-3`... Arcs follow each
/// transition's inputs and outputs, and each `finish` gives an arc to the parent's completion
/// place; emptiness tests, guards, events and activation are not P/T notions and are left out.
/// The initial marking is the project's initial state: instances listed in `start` have their
/// places' tokens, other instances' places none, global places their tokens.
///
/// Everything else travels in one `<toolspecific tool="petrel" version="2">` block at net
/// level (described in [`super`]), so that [`super::import_pnml`] gives back an equal
/// [`Project`]. A project whose nets expand beyond [`crate::instances::MAX_INSTANCES`] has its
/// skeleton cut there, and does not import back.
pub fn export_pnml(project: &Project) -> String {
    let m = &project.manifest;
    let expanded = instances(project);
    let decls: Vec<&NetDecl> = project.nets().collect();
    let net_nodes: Vec<Vec<Node>> = decls.iter().map(|n| nodes(n)).collect();
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
    layout.nets = net_nodes
        .iter()
        .map(|n| vec![Vec::new(); n.len()])
        .collect();
    // Per instance, its nodes' ids, for the page.
    let mut page: Vec<Vec<String>> = Vec::new();
    for inst in &expanded.list {
        let prefix = id_prefix(&inst.name);
        let mut list = Vec::new();
        for (k, node) in net_nodes[inst.net].iter().enumerate() {
            let id = ids.take(&format!("{prefix}.{}", node.name()), "-");
            layout.nets[inst.net][k].push(id.clone());
            list.push(id);
        }
        page.push(list);
    }
    let st = structure(project, &expanded, &layout);
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
    let names = expanded.names_by_net(decls.len());
    let mut net_index = 0;
    for file in &project.files {
        w.open("netfile", &[("path", &file.path)]);
        for net in &file.nets {
            let copies = names.get(net_index).map(Vec::as_slice).unwrap_or(&[]);
            let ids = layout.nets.get(net_index).map(Vec::as_slice).unwrap_or(&[]);
            write_net(&mut w, net, copies, ids);
            net_index += 1;
        }
        w.comments("end-comment", &file.end_comments);
        w.close("netfile");
    }
    w.close("toolspecific");

    w.open("page", &[("id", &page_id)]);
    let place = |w: &mut Writer, id: &str, name: &str| {
        w.open("place", &[("id", id)]);
        w.label("name", name);
        let tokens = marking.get(id).copied().unwrap_or(0);
        if tokens > 0 {
            w.label("initialMarking", &tokens.to_string());
        }
        w.close("place");
    };
    for (g, id) in m.globals.iter().zip(&layout.globals) {
        place(&mut w, id, &format!("global.{}", g.name));
    }
    for (inst, list) in expanded.list.iter().zip(&page) {
        for (node, id) in net_nodes[inst.net].iter().zip(list) {
            // Names are the places' and transitions' names as Petrel writes them in markings
            // and traces, so a reader of the skeleton can tell R1's `moving` from R2's.
            let name = format!("{}.{}", inst.name, node.name());
            if node.is_place() {
                place(&mut w, id, &name);
            } else {
                w.open("transition", &[("id", id)]);
                w.label("name", &name);
                w.close("transition");
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

fn write_allows(w: &mut Writer, allows: &[Allow]) {
    for a in allows {
        match &a.reason {
            Some(r) => w.empty("allow", &[("code", a.code.as_str()), ("reason", r)]),
            None => w.empty("allow", &[("code", a.code.as_str())]),
        }
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
        let tokens = g.tokens.to_string();
        let attrs = [("name", g.name.as_str()), ("tokens", &tokens), ("ref", id)];
        match &g.nets {
            None => w.empty("global", &attrs),
            Some(nets) => {
                w.open("global", &attrs);
                w.open("scope", &[]);
                for n in nets {
                    w.empty("net", &[("name", n.as_str())]);
                }
                w.close("scope");
                w.close("global");
            }
        }
    }
    for i in &m.instances {
        w.empty(
            "instance",
            &[
                ("name", i.name.as_str()),
                ("net", i.net.as_str()),
                ("args", &args_text(&i.args)),
            ],
        );
    }
    for i in &m.invariants {
        w.leaf("invariant", &[("name", i.name.as_str())], &i.text);
    }
    for e in &m.events {
        let mut attrs = vec![
            ("name", e.name.as_str()),
            ("category", e.category.keyword()),
        ];
        if e.internal {
            attrs.push(("internal", "true"));
        }
        w.open("event", &attrs);
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
            for a in &f.answers {
                w.empty("answer", &[("event", a.as_str())]);
            }
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
    for (kind, markings) in [("final", &m.finals), ("goal", &m.goals)] {
        for f in markings {
            w.open(kind, &[]);
            for p in f {
                w.empty("place", &[("name", p.as_str())]);
            }
            w.close(kind);
        }
    }
    for b in &m.bounds {
        let mut attrs = vec![
            ("name", b.name.as_str()),
            ("from", b.from.text()),
            ("to", b.to.text()),
        ];
        if let Some(w) = &b.within {
            attrs.push(("within", w.as_str()));
        }
        w.empty("bound", &attrs);
    }
    if let Some(excluded) = &m.progress_excludes {
        w.open("progress-excludes", &[]);
        for c in excluded {
            w.empty("category", &[("name", c.as_str())]);
        }
        w.close("progress-excludes");
    }
    w.close("manifest");
}

/// The comments, intended warnings and trailing comment every item carries.
fn write_item_head(w: &mut Writer, item: &Item) {
    w.comments("comment", &item.trivia.comments);
    write_allows(w, &item.allows);
    if let Some(c) = &item.trailing {
        w.leaf("trailing", &[], c);
    }
}

/// The P/T ids of one node in each instance: `<copy net="R1" ref="R1.moving"/>`.
fn write_copies(w: &mut Writer, instances: &[&str], ids: Option<&Vec<String>>) {
    for (name, id) in instances.iter().zip(ids.into_iter().flatten()) {
        w.empty("copy", &[("net", name), ("ref", id)]);
    }
}

/// One net of a net file, its items in written order, each with its P/T ids per instance.
fn write_net(w: &mut Writer, net: &NetDecl, instances: &[&str], ids: &[Vec<String>]) {
    let mut attrs = vec![("name", net.name.as_str())];
    attrs.extend(blank_attr(&net.trivia));
    w.open("net", &attrs);
    w.comments("comment", &net.trivia.comments);
    write_allows(w, &net.allows);
    write_params(w, &net.params);
    let mut node = 0;
    for item in &net.items {
        match &item.kind {
            ItemKind::Place(p) => {
                let tokens = p.tokens.to_string();
                let mut attrs = vec![("name", p.name.as_str()), ("tokens", tokens.as_str())];
                if p.tokens_span.is_some() {
                    attrs.push(("marking-written", "true"));
                }
                attrs.extend(blank_attr(&item.trivia));
                w.open("place", &attrs);
                write_item_head(w, item);
                write_copies(w, instances, ids.get(node));
                node += 1;
                w.close("place");
            }
            ItemKind::Transition(t) => {
                let mut attrs = vec![("name", t.name.as_str())];
                attrs.extend(blank_attr(&item.trivia));
                w.open("transition", &attrs);
                write_item_head(w, item);
                write_transition(w, t);
                write_copies(w, instances, ids.get(node));
                node += 1;
                w.close("transition");
            }
            ItemKind::Children(list) => {
                let attrs: Vec<_> = blank_attr(&item.trivia).into_iter().collect();
                w.open("children", &attrs);
                write_item_head(w, item);
                for c in list {
                    let args = c.args.as_deref().map(args_text);
                    let mut attrs = vec![("net", c.net.as_str())];
                    if let Some(a) = &args {
                        attrs.push(("args", a));
                    }
                    w.open("child", &attrs);
                    write_copies(w, instances, ids.get(node));
                    node += 1;
                    w.close("child");
                }
                w.close("children");
            }
        }
    }
    w.comments("end-comment", &net.end_comments);
    w.close("net");
}

/// A transition's trigger, guard, arcs, emptiness tests, actions and end comments.
fn write_transition(w: &mut Writer, t: &TransitionDecl) {
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
    if let Some(g) = &t.guard {
        w.leaf("guard", &[], &format_guard(g));
    }
    for n in &t.inputs {
        w.empty("input", &[("place", n.as_str())]);
    }
    for n in &t.empty {
        w.empty("empty", &[("place", n.as_str())]);
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
}
