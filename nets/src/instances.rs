//! The nets a project runs, worked out from the model alone: each plain net, each instance of a
//! template (manifest `[instances]`), each child instance `PARENT/CHILD`, in project order.
//!
//! The checker ([`crate::check`]) expands templates the same way while it types them; the PNML
//! export needs the instances of a project that may not check (export is defined on any model,
//! and import faces whatever a file holds), and the DOT drawing needs them before checking too.
//! So this module follows the checker's rules without judging anything:
//!
//! - the **roots** are the nets nobody declares as a child, in project order; a root that the
//!   manifest instantiates stands for its instances (in `[instances]` order), else for itself;
//! - each root is expanded **pre-order** down the `children` lines: every child declared by a
//!   net, resolved to a net of the project, is an instance named `PARENT/CHILD`;
//! - names resolve to the **first** net of that name; an instance whose name is already taken
//!   (by a net or an earlier instance), or whose template is unknown or someone's child, makes
//!   nothing; a child that leads back to one of its ancestors is an instance without children
//!   (the checker reports the cycle).
//!
//! Expansion is iterative and bounded ([`MAX_INSTANCES`], [`MAX_NAME_BYTES`]): a hostile file
//! whose children lines multiply at each level cannot make it run out of time or memory. The
//! checker's expansion is bounded by the same limits and reports E0305 when one is crossed. A
//! test in `nets/tests/pnml.rs` checks that the names and order agree with the checker's.

use crate::model::{Expr, NetDecl, Project};
use std::collections::{HashMap, HashSet};

/// Most instances expanded; beyond it the expansion stops and says so. Real missions have tens.
pub const MAX_INSTANCES: usize = 100_000;

/// Most bytes of instance names in all: names grow with depth (`A/B/C/...`), so a deep chain
/// of children would otherwise use memory quadratic in its length.
pub const MAX_NAME_BYTES: usize = 16 << 20;

/// One net the project runs.
#[derive(Clone, Debug, PartialEq)]
pub struct Instance {
    /// Its name: a plain net's (`MISSION`), a manifest instance's (`R1`) or a child
    /// instance's (`MISSION/TRANSIT`).
    pub name: String,
    /// Its net as written: an index into [`Project::nets`] order.
    pub net: usize,
    /// The arguments that fix its parameters, as written: a manifest instance's, or those of
    /// the `children` line that made it; `None` for a net bound at activation or without
    /// parameters written.
    pub args: Option<Vec<Expr>>,
    /// Its parent instance, and the position of the child among every child its parent's net
    /// declares (over all of its `children` lines): the parent's completion place for it.
    pub parent: Option<(usize, usize)>,
    /// Its child instances, in declared order.
    pub children: Vec<usize>,
}

/// Every net of a project, as [`instances`] expands them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Instances {
    /// In project order (the dispatch order).
    pub list: Vec<Instance>,
    /// The expansion stopped at [`MAX_INSTANCES`] or [`MAX_NAME_BYTES`]: the list is a prefix.
    pub truncated: bool,
}

impl Instances {
    /// The names of the instances of each of `nets` nets (indices into [`Project::nets`]
    /// order), in order; one pass, so that callers need not scan the list once per net.
    pub fn names_by_net(&self, nets: usize) -> Vec<Vec<&str>> {
        let mut out = vec![Vec::new(); nets];
        for i in &self.list {
            if let Some(list) = out.get_mut(i.net) {
                list.push(i.name.as_str());
            }
        }
        out
    }

    /// For each instance, its position among the instances of its net.
    pub fn ordinals(&self) -> Vec<usize> {
        let mut seen: HashMap<usize, usize> = HashMap::new();
        self.list
            .iter()
            .map(|i| {
                let n = seen.entry(i.net).or_insert(0);
                *n += 1;
                *n - 1
            })
            .collect()
    }
}

/// A child a net declares, resolved: its position among all the net's children (the parent's
/// completion place for it), its net, and the arguments of the `children` line.
type Resolved<'a> = (usize, usize, Option<&'a [Expr]>);

/// Expands a project's nets into the nets it runs (see the module documentation).
pub fn instances(project: &Project) -> Instances {
    let decls: Vec<&NetDecl> = project.nets().collect();
    let mut ids: HashMap<&str, usize> = HashMap::new();
    for (i, n) in decls.iter().enumerate() {
        ids.entry(n.name.as_str()).or_insert(i);
    }
    // Each net's resolved children.
    let mut children: Vec<Vec<Resolved>> = Vec::new();
    let mut has_parent = vec![false; decls.len()];
    for n in &decls {
        let mut list = Vec::new();
        for (pos, ch) in n.children().enumerate() {
            if let Some(&k) = ids.get(ch.net.as_str()) {
                has_parent[k] = true;
                list.push((pos, k, ch.args.as_deref()));
            }
        }
        children.push(list);
    }

    // Manifest instances, per template, in manifest order.
    let m = &project.manifest;
    let mut taken: HashSet<&str> = decls.iter().map(|n| n.name.as_str()).collect();
    let mut instanced: HashMap<usize, Vec<usize>> = HashMap::new();
    for (k, inst) in m.instances.iter().enumerate() {
        if !taken.insert(inst.name.as_str()) {
            continue;
        }
        if let Some(&decl) = ids.get(inst.net.as_str()) {
            if !has_parent[decl] {
                instanced.entry(decl).or_default().push(k);
            }
        }
    }

    let mut out = Instances::default();
    let mut name_bytes = 0usize;
    let mut on_path = vec![false; decls.len()];
    for (d, _) in decls.iter().enumerate().filter(|(d, _)| !has_parent[*d]) {
        let roots: Vec<(String, Option<Vec<Expr>>)> = match instanced.get(&d) {
            Some(list) => list
                .iter()
                .map(|&k| {
                    let inst = &m.instances[k];
                    (inst.name.text.clone(), Some(inst.args.clone()))
                })
                .collect(),
            None => vec![(decls[d].name.text.clone(), None)],
        };
        for (name, args) in roots {
            if out.list.len() >= MAX_INSTANCES || name_bytes >= MAX_NAME_BYTES {
                out.truncated = true;
                return out;
            }
            name_bytes += name.len();
            let root = out.list.len();
            out.list.push(Instance {
                name,
                net: d,
                args,
                parent: None,
                children: Vec::new(),
            });
            // Pre-order over an explicit stack of (instance, next child to expand): a deep
            // chain of children cannot overflow the call stack.
            let mut path = vec![(root, 0usize)];
            on_path[d] = true;
            while let Some(top) = path.last_mut() {
                let (me, next) = *top;
                let net = out.list[me].net;
                let Some(&(pos, child, args)) = children[net].get(next) else {
                    on_path[net] = false;
                    path.pop();
                    continue;
                };
                top.1 += 1;
                let name = format!("{}/{}", out.list[me].name, decls[child].name);
                if out.list.len() >= MAX_INSTANCES || name_bytes + name.len() > MAX_NAME_BYTES {
                    out.truncated = true;
                    return out;
                }
                name_bytes += name.len();
                let id = out.list.len();
                out.list.push(Instance {
                    name,
                    net: child,
                    args: args.map(<[Expr]>::to_vec),
                    parent: Some((me, pos)),
                    children: Vec::new(),
                });
                out.list[me].children.push(id);
                // A child that is its own ancestor is made, but not expanded further.
                if !on_path[child] {
                    on_path[child] = true;
                    path.push((id, 0));
                }
            }
        }
    }
    out
}
