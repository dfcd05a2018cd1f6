//! The P/T view of a project, shared by export and import: which P/T id each Petrel place and
//! transition has, so that both sides name them alike.

use std::collections::{HashMap, HashSet};

use crate::model::*;
use crate::syntax::is_keyword;

/// The P/T id of every Petrel place and transition.
#[derive(Default)]
pub(super) struct Layout {
    /// One per `manifest.globals` entry.
    pub(super) globals: Vec<String>,
    /// Per net in project order, one per item.
    pub(super) nets: Vec<Vec<String>>,
}

/// What the P/T net of a project must hold.
pub(super) struct Structure {
    /// Initial marking per place id, in layout order.
    pub(super) marking: Vec<(String, u64)>,
    /// `(place id, transition id, input?)` to weight, in first-use order.
    pub(super) arcs: Vec<((String, String, bool), u64)>,
}

/// The P/T structure of `project` laid out as `layout` says.
///
/// A transition's input or output name resolves to its net's place of that name, else to the
/// global place of that name, else to nothing (the checker reports it; no arc is drawn).
/// Naming a place twice gives one arc of weight 2, which is what it means in P/T terms.
pub(super) fn structure(project: &Project, layout: &Layout) -> Structure {
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
