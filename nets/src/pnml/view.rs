//! The P/T view of a project, shared by export and import: which P/T id each Petrel place,
//! transition and completion place has in each instance, and the P/T skeleton they make.

use std::collections::{HashMap, HashSet};

use crate::instances::Instances;
use crate::model::is_keyword;
use crate::model::*;

/// A P/T node of a net as written: each of its places and transitions, and each child it
/// declares (the child's completion place `CHILD.done`, a place of the parent).
#[derive(Clone, Copy)]
pub(super) enum Node<'a> {
    Place(&'a PlaceDecl),
    Transition(&'a TransitionDecl),
    Done(&'a ChildDecl),
}

impl Node<'_> {
    /// The node's name in its net: `idle`, `go`, `TRANSIT.done`.
    pub(super) fn name(&self) -> String {
        match self {
            Node::Place(p) => p.name.text.clone(),
            Node::Transition(t) => t.name.text.clone(),
            Node::Done(c) => format!("{}.done", c.net),
        }
    }

    /// Whether the node is a P/T place (else a P/T transition).
    pub(super) fn is_place(&self) -> bool {
        !matches!(self, Node::Transition(_))
    }
}

/// The nodes of a net, in item order (a `children` line gives one per child).
pub(super) fn nodes(net: &NetDecl) -> Vec<Node<'_>> {
    let mut out = Vec::new();
    for item in &net.items {
        match &item.kind {
            ItemKind::Place(p) => out.push(Node::Place(p)),
            ItemKind::Transition(t) => out.push(Node::Transition(t)),
            ItemKind::Children(list) => out.extend(list.iter().map(Node::Done)),
        }
    }
    out
}

/// The P/T id of every node of every instance.
#[derive(Default)]
pub(super) struct Layout {
    /// One per `manifest.globals` entry.
    pub(super) globals: Vec<String>,
    /// Per net in project order, per node ([`nodes`] order), per instance of the net (in
    /// instance order): the P/T id.
    pub(super) nets: Vec<Vec<Vec<String>>>,
}

/// What the P/T net of a project must hold.
pub(super) struct Structure {
    /// Initial marking per place id, in layout order.
    pub(super) marking: Vec<(String, u64)>,
    /// `(place id, transition id, input?)` to weight, in first-use order.
    pub(super) arcs: Vec<((String, String, bool), u64)>,
}

/// The P/T skeleton of `project` expanded into `instances` and laid out as `layout` says.
///
/// Each instance has its own copy of its net's places, transitions and completion places;
/// global places are shared. A transition's input or output name resolves to its net's place
/// of that name, else to its completion place `CHILD.done`, else to the global place of that
/// name, else to nothing (the checker reports it; no arc is drawn). Naming a place twice gives
/// one arc of weight 2, which is what it means in P/T terms. A `finish` action is an output arc
/// to the completion place of the instance in its parent. An emptiness test (`not p`) has no
/// arc: a P/T net cannot test for zero, so the skeleton over-approximates it. The initial
/// marking is the mission's: instances named in `start` hold their places' tokens, global
/// places theirs, everything else none.
pub(super) fn structure(project: &Project, instances: &Instances, layout: &Layout) -> Structure {
    let m = &project.manifest;
    let decls: Vec<&NetDecl> = project.nets().collect();
    let net_nodes: Vec<Vec<Node>> = decls.iter().map(|n| nodes(n)).collect();
    let start: HashSet<&str> = m.start.iter().map(|n| n.as_str()).collect();
    let mut globals: HashMap<&str, &str> = HashMap::new();
    let mut marking = Vec::new();
    for (g, id) in m.globals.iter().zip(&layout.globals) {
        globals.entry(g.name.as_str()).or_insert(id);
        marking.push((id.clone(), u64::from(g.tokens)));
    }
    let ordinals = instances.ordinals();
    let id_of = |net: usize, node: usize, ordinal: usize| -> Option<&str> {
        let id = layout.nets.get(net)?.get(node)?.get(ordinal)?;
        Some(id.as_str())
    };
    // Per net: the node a place name or a completion place name resolves to (first wins), and
    // the node of each declared child, by position.
    let mut locals: Vec<HashMap<String, usize>> = Vec::new();
    let mut dones: Vec<Vec<usize>> = Vec::new();
    for list in &net_nodes {
        let mut names = HashMap::new();
        let mut done = Vec::new();
        for (k, node) in list.iter().enumerate() {
            match node {
                Node::Place(_) => {
                    names.entry(node.name()).or_insert(k);
                }
                Node::Done(_) => {
                    names.entry(node.name()).or_insert(k);
                    done.push(k);
                }
                Node::Transition(_) => {}
            }
        }
        locals.push(names);
        dones.push(done);
    }

    let mut arcs: Vec<((String, String, bool), u64)> = Vec::new();
    let mut arc_index: HashMap<(String, String, bool), usize> = HashMap::new();
    let mut add = |place: &str, transition: &str, input: bool, weight: u64| {
        let key = (place.to_string(), transition.to_string(), input);
        match arc_index.get(&key) {
            Some(&i) => arcs[i].1 = arcs[i].1.saturating_add(weight),
            None => {
                arc_index.insert(key.clone(), arcs.len());
                arcs.push((key, weight));
            }
        }
    };
    for (i, inst) in instances.list.iter().enumerate() {
        let (d, j) = (inst.net, ordinals[i]);
        let (Some(list), Some(local)) = (net_nodes.get(d), locals.get(d)) else {
            continue;
        };
        let active = start.contains(inst.name.as_str());
        for (k, node) in list.iter().enumerate() {
            let Some(id) = id_of(d, k, j) else { continue };
            match node {
                Node::Place(p) => {
                    marking.push((id.to_string(), if active { u64::from(p.tokens) } else { 0 }))
                }
                Node::Done(_) => marking.push((id.to_string(), 0)),
                Node::Transition(_) => {}
            }
        }
        // The completion place this instance's `finish` marks, in its parent's instance.
        let finish_to = inst.parent.and_then(|(p, pos)| {
            let parent = instances.list.get(p)?;
            let node = *dones.get(parent.net)?.get(pos)?;
            id_of(parent.net, node, *ordinals.get(p)?)
        });
        for (k, node) in list.iter().enumerate() {
            let Node::Transition(t) = node else { continue };
            let Some(tid) = id_of(d, k, j) else { continue };
            let ends = t.inputs.iter().map(|n| (n, true));
            for (name, input) in ends.chain(t.outputs.iter().map(|n| (n, false))) {
                let place = match local.get(name.as_str()) {
                    Some(&node) => id_of(d, node, j),
                    None => globals.get(name.as_str()).copied(),
                };
                if let Some(place) = place {
                    add(place, tid, input, 1);
                }
            }
            let finishes = t
                .actions
                .iter()
                .filter(|a| matches!(a.action, Action::Finish(_)))
                .count() as u64;
            if let (Some(done), true) = (finish_to, finishes > 0) {
                add(done, tid, false, finishes);
            }
        }
    }
    Structure { marking, arcs }
}

/// Turns any text into a Petrel identifier: other characters become `_`, a leading digit gets
/// a `_` before it, and a keyword gets one after it.
pub(super) fn sanitize(raw: &str) -> String {
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
pub(super) struct Unique {
    pub(super) used: HashSet<String>,
}

impl Unique {
    pub(super) fn take(&mut self, base: &str, sep: &str) -> String {
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

#[cfg(test)]
mod tests {
    use super::*;

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
}
