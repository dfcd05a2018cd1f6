//! Partial-order reduction for project verification (docs/verification.md, "Partial-order
//! reduction").
//!
//! The nets of a project fall into **components**: the smallest groups such that no firing in
//! one group reads or writes anything of another. Two nets are in one component when they
//! share a global place, when one activates, deactivates or finishes into the other (or is its
//! parent or child), when both wait for one event (a delivery of it touches both), when one
//! emits an event the other waits for, calls a function whose answer the other waits for, or
//! starts or cancels a timer whose event the other waits for (the environment's counters and
//! the timer's bit are then shared), and when an invariant names both. A delivery touches the
//! component of the nets that wait for its event; a catastrophic event touches everything (it
//! ends the mission). Deliveries of different components therefore commute, and none enables
//! or disables another: in a state, the enabled deliveries of one component form a persistent
//! set. The exploration expands one such set per state where it can, under the cycle proviso
//! of [`super::explore`], and every state in full where it cannot.

use super::env::Delivery;
use crate::compiled::{Action, CompiledProject, PlaceRef, StateFormula};
use crate::model::Category;
use crate::semantics::Layout;

/// The component of each net, and of each delivery.
pub(super) struct Components {
    /// Per net, its component (numbered from 0 in net order).
    pub of_net: Vec<u32>,
    /// How many components.
    pub count: u32,
}

struct UnionFind(Vec<u32>);

impl UnionFind {
    fn find(&mut self, mut x: u32) -> u32 {
        while self.0[x as usize] != x {
            let up = self.0[self.0[x as usize] as usize];
            self.0[x as usize] = up;
            x = up;
        }
        x
    }
    fn union(&mut self, a: u32, b: u32) {
        let (a, b) = (self.find(a), self.find(b));
        if a != b {
            // The smaller root wins, so that numbering follows net order.
            let (lo, hi) = if a < b { (a, b) } else { (b, a) };
            self.0[hi as usize] = lo;
        }
    }
}

fn formula_nets(f: &StateFormula, out: &mut Vec<(u32, Option<u32>)>) {
    match f {
        StateFormula::Const(_) => {}
        StateFormula::Marked(n, PlaceRef::Local(_)) | StateFormula::Active(n) => {
            out.push((*n, None))
        }
        StateFormula::Marked(_, PlaceRef::Global(g)) => out.push((u32::MAX, Some(*g))),
        StateFormula::Not(a) => formula_nets(a, out),
        StateFormula::And(a, b) | StateFormula::Or(a, b) | StateFormula::Implies(a, b) => {
            formula_nets(a, out);
            formula_nets(b, out);
        }
    }
}

impl Components {
    /// The components of `p`'s nets.
    pub fn new(p: &CompiledProject, l: &Layout) -> Components {
        let nets = p.nets.len() as u32;
        // One node per net, then one per global place, per event, per timer, per function:
        // the shared things that join nets.
        let global = |g: u32| nets + g;
        let event = |e: u32| nets + p.globals.len() as u32 + e;
        let timer = |t: u32| nets + (p.globals.len() + p.events.len()) as u32 + t;
        let mut fbase = Vec::with_capacity(p.programs.len());
        let mut total = nets + (p.globals.len() + p.events.len() + p.timers.len()) as u32;
        for prog in &p.programs {
            fbase.push(total);
            total += prog.functions.len() as u32;
        }
        let mut uf = UnionFind((0..total).collect());
        let place = |uf: &mut UnionFind, n: u32, r: &PlaceRef| {
            if let PlaceRef::Global(g) = r {
                uf.union(n, global(*g));
            }
        };
        for (n, net) in p.nets.iter().enumerate() {
            let n = n as u32;
            if let Some((parent, _)) = net.parent {
                uf.union(n, parent);
            }
            for &c in &net.children {
                uf.union(n, c);
            }
            for t in &net.transitions {
                if let Some(e) = t.event {
                    uf.union(n, event(e));
                }
                for r in t.inputs.iter().chain(&t.outputs).chain(&t.empty) {
                    place(&mut uf, n, r);
                }
                for a in &t.actions {
                    match a {
                        Action::Activate { net: m, .. } | Action::Deactivate(m) => {
                            uf.union(n, *m);
                            for &d in &l.subtree[*m as usize] {
                                uf.union(n, d);
                            }
                        }
                        Action::Finish => {}
                        Action::StartTimer { timer: t, .. } | Action::CancelTimer(t) => {
                            uf.union(n, timer(*t));
                        }
                        Action::Call {
                            program, function, ..
                        } => {
                            let f = fbase[*program as usize] + *function;
                            uf.union(n, f);
                            let decl = &p.programs[*program as usize].functions[*function as usize];
                            for &e in &decl.answers {
                                uf.union(f, event(e));
                            }
                        }
                        Action::Emit { event: e, .. } => uf.union(n, event(*e)),
                    }
                }
            }
        }
        for (t, decl) in p.timers.iter().enumerate() {
            uf.union(timer(t as u32), event(decl.event));
        }
        for inv in &p.invariants {
            let mut atoms = Vec::new();
            formula_nets(&inv.formula, &mut atoms);
            let nodes: Vec<u32> = atoms.iter().map(|&(n, g)| g.map_or(n, global)).collect();
            for w in nodes.windows(2) {
                uf.union(w[0], w[1]);
            }
        }
        // The ends (`final` and `goal` markings) in one component: whether an end stays
        // reachable is then a question about that component's state alone.
        let mut ends: Vec<u32> = Vec::new();
        for marking in p.finals.iter().chain(&p.goals) {
            for &(n, r) in marking {
                ends.push(match r {
                    PlaceRef::Local(_) => n,
                    PlaceRef::Global(g) => global(g),
                });
            }
        }
        for w in ends.windows(2) {
            uf.union(w[0], w[1]);
        }
        // Number the components of the nets in net order.
        let mut number: Vec<u32> = vec![u32::MAX; total as usize];
        let mut of_net = Vec::with_capacity(nets as usize);
        let mut count = 0;
        for n in 0..nets {
            let root = uf.find(n) as usize;
            if number[root] == u32::MAX {
                number[root] = count;
                count += 1;
            }
            of_net.push(number[root]);
        }
        Components { of_net, count }
    }

    /// The component a delivery touches; `None` for a catastrophic event (every component:
    /// it ends the mission) and for an event no net waits for.
    pub fn of_delivery(&self, p: &CompiledProject, l: &Layout, d: &Delivery) -> Option<u32> {
        if p.events[d.event as usize].category == Category::Catastrophic {
            return None;
        }
        let net = match d.target {
            Some(n) => n,
            None => l.rules[*l.by_event[d.event as usize].first()? as usize].net,
        };
        Some(self.of_net[net as usize])
    }
}
