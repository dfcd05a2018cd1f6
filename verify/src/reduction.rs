//! Partial-order reduction for project verification (docs/verification.md, "Partial-order
//! reduction").
//!
//! The nets of a project fall into **components**: the smallest groups such that no firing in
//! one group reads or writes anything of another. Two nets are in one component when they
//! share a global place, when one activates, deactivates or finishes into the other (or is its
//! parent or child), when both wait for one event (a delivery of it touches both), when one
//! emits an event the other waits for or addresses one to the other, calls a function whose
//! answer the other waits for, or starts or cancels a timer whose event the other waits for
//! (the environment's counters and the timer's bit are then shared), and when an invariant
//! names both. An immediate transition left enabled in a stable state (refused, or its guard
//! undecided) joins every component (any step's fixpoint tries it): the exploration then
//! starts again in full. A delivery touches the
//! component of the nets that wait for its event; a catastrophic event touches everything (it
//! ends the mission). Deliveries of different components therefore commute, and none enables
//! or disables another: in a state, the enabled deliveries of one component form a persistent
//! set. The exploration expands one such set per state where it can, under the cycle proviso
//! of [`super::explore`], and every state in full where it cannot.

use super::env::Delivery;
use super::explore::Graph;
use super::minimize::Minimizer;
use petrel_nets::compiled::{Action, CompiledProject, NetId, PlaceRef, StateFormula};
use petrel_nets::model::Category;
use petrel_nets::semantics::{Layout, State};
use std::collections::HashMap;

/// The component of each net, and of each delivery.
pub(super) struct Components {
    /// Per net, its component (numbered from 0 in net order).
    pub of_net: Vec<u32>,
    /// How many components.
    pub count: u32,
    /// The component of the nets named in the `final` and `goal` markings (one, by
    /// construction); `None` when there are none, or they name global places no net touches.
    pub ends: Option<u32>,
    /// Per global place, per event, per timer and per function (programs' functions one
    /// after the other), the component it belongs to; `None` when no net touches it. What
    /// [`super::cache`] needs to tell each component's bits of a state.
    pub of_global: Vec<Option<u32>>,
    pub of_event: Vec<Option<u32>>,
    pub of_timer: Vec<Option<u32>>,
    pub of_function: Vec<Vec<Option<u32>>>,
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
                        Action::Emit {
                            event: e, target, ..
                        } => {
                            uf.union(n, event(*e));
                            // `emit e to m`: its delivery is counted as `m`'s group's, and
                            // its counter is the emitter's (even when `m` does not wait for
                            // `e`, and its delivery is then an unused one).
                            if let Some(m) = target {
                                uf.union(n, *m);
                            }
                        }
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
        let ends_root = ends.first().map(|&x| uf.find(x) as usize);
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
        let ends = ends_root.map(|r| number[r]).filter(|&c| c != u32::MAX);
        let mut of = |node: u32| Some(number[uf.find(node) as usize]).filter(|&c| c != u32::MAX);
        let of_global = (0..p.globals.len() as u32).map(|g| of(global(g))).collect();
        let of_event = (0..p.events.len() as u32).map(|e| of(event(e))).collect();
        let of_timer = (0..p.timers.len() as u32).map(|t| of(timer(t))).collect();
        let of_function = p
            .programs
            .iter()
            .zip(&fbase)
            .map(|(prog, &base)| {
                (0..prog.functions.len() as u32)
                    .map(|f| of(base + f))
                    .collect()
            })
            .collect();
        Components {
            of_net,
            count,
            ends,
            of_global,
            of_event,
            of_timer,
            of_function,
        }
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

/// A net met stuck in the reduced graph only beside an end of the ends' component, and a state
/// of the whole graph where it is stuck with no end holding ([`stuck_beside_ends`]).
pub(super) struct StuckBesideEnds {
    /// The net.
    pub net: NetId,
    /// Where it is stuck, no end holding.
    pub state: State,
    /// The steps (labels) from the initial state to `state`.
    pub steps: Vec<u32>,
    /// The nets stuck there with it.
    pub stuck_here: Vec<NetId>,
}

/// The nets of another component than the ends' that the reduced graph `g` meets stuck (active,
/// never to fire again, the mission not over) only in states where a `final` or `goal` marking
/// holds (`ends`). Whether a net can fire again is its component's question, but whether an
/// end holds is the ends' component's: the reduction may have moved the ends' component to its
/// end before the net's component got the net stuck, and never the other way round. In the
/// whole graph every state of one component meets every state of the others (they are
/// independent), so the net is stuck there beside a state where no end holds. The witness is
/// put together from the ends' component's steps to such a state (the first one breadth
/// first), then the other components' steps to where the net is stuck (the environment's
/// drops of events no net waits for left out), replayed with the firing code (`m`), and
/// checked. `can(net, i)`: whether `net` can still fire from state `i` of `g`. `Err(())` when
/// no witness can be put together this way (the two states were first reached from different
/// initial states, or the replay does not give what it should): the caller then explores in
/// full.
#[allow(clippy::too_many_arguments)]
pub(super) fn stuck_beside_ends(
    p: &CompiledProject,
    l: &Layout,
    g: &Graph,
    comps: &Components,
    ends: &[bool],
    reported: &[NetId],
    can: &dyn Fn(NetId, u32) -> bool,
    m: &Minimizer,
) -> Result<Vec<StuckBesideEnds>, ()> {
    let Some(e) = comps.ends else {
        return Ok(Vec::new());
    };
    let n = g.states.len() as u32;
    let candidates: Vec<(NetId, u32)> = (0..p.nets.len() as NetId)
        .filter(|&net| {
            comps.of_net[net as usize] != e
                && !reported.contains(&net)
                && !p.nets[net as usize].transitions.is_empty()
        })
        .filter_map(|net| {
            (0..n)
                .find(|&i| {
                    let s = &g.states[i as usize];
                    l.is_active(s, net) && !can(net, i) && !l.is_over(s)
                })
                .map(|i| (net, i))
        })
        .collect();
    if candidates.is_empty() {
        return Ok(Vec::new());
    }
    // Breadth first, a state's parent was found before it: one pass gives every state's
    // initial state.
    let mut root: Vec<u32> = Vec::with_capacity(n as usize);
    for i in 0..n {
        let r = g.parent(i).map_or(i, |(up, _)| root[up as usize]);
        root.push(r);
    }
    // The first state where no end holds, per initial state.
    let mut open: HashMap<u32, u32> = HashMap::new();
    for i in 0..n {
        if !ends[i as usize] {
            open.entry(root[i as usize]).or_insert(i);
        }
    }
    if open.is_empty() {
        // An end holds everywhere: no net is stuck, reduced or not.
        return Ok(Vec::new());
    }
    let component_of = |label: u32| {
        let d = &g.deliveries[g.labels[label as usize].delivery as usize];
        comps.of_delivery(p, l, d)
    };
    let mut out = Vec::new();
    for (net, i) in candidates {
        let r = root[i as usize];
        let &t = open.get(&r).ok_or(())?;
        let mut steps = Vec::new();
        for step in g.trace_steps(t) {
            let label = step.ok_or(())?;
            if component_of(label) == Some(e) {
                steps.push(label);
            }
        }
        for step in g.trace_steps(i) {
            let label = step.ok_or(())?;
            if component_of(label).is_some_and(|c| c != e) {
                steps.push(label);
            }
        }
        let state = m.replay(&g.states[r as usize].to_vec(), &steps).ok_or(())?;
        if !l.is_active(&state, net) || super::analysis::end_for_net(p, l, &state, net) {
            return Err(());
        }
        if g.states.find(&state).is_some_and(|k| can(net, k)) {
            return Err(());
        }
        // The ends' component is where it is in `t`, the others where they are in `i`.
        let stuck_here = (0..p.nets.len() as NetId)
            .filter(|&k| {
                let from = if comps.of_net[k as usize] == e { t } else { i };
                l.is_active(&state, k) && !can(k, from)
            })
            .collect();
        out.push(StuckBesideEnds {
            net,
            state,
            steps,
            stuck_here,
        });
    }
    Ok(out)
}
