//! What the explored graph shows: dead markings, invariants, progress, stuck nets and the
//! resource cycles behind them, starvation, loops of stable states.
//!
//! Every analysis reads the [`Graph`] the exploration built, in its breadth-first order, so the
//! first state a finding is met in has the shortest trace. The graph keeps its edges forward
//! only (grouped by source state): what is reachable backwards (an end, a firing) is computed
//! over its strongly connected components ([`Scc`]), numbered so that every edge goes to a
//! component numbered no higher, with no reversed copy of the edges.

use super::explore::{Edge, Edges, Graph, NO_EVENT};
use super::{
    DeadFinding, InvariantFinding, LoopFinding, ProgressFinding, StarvationFinding, StuckFinding,
};
use crate::compiled::{CompiledProject, EventId, NetId, PlaceRef};
use crate::semantics::Layout;
use std::collections::{HashMap, HashSet, VecDeque};

/// Whether every place of marking `f` is marked in `s` (its nets active).
fn holds_marking(l: &Layout, s: &[u64], f: &[(NetId, PlaceRef)]) -> bool {
    f.iter()
        .all(|&(n, r)| l.is_active(s, n) || matches!(r, PlaceRef::Global(_)))
        && f.iter().all(|&(n, r)| l.is_marked(s, n, r))
}

/// States that are ends of the mission: a final or goal marking holds, or a catastrophic event
/// ended it.
pub(super) fn ends(p: &CompiledProject, l: &Layout, g: &Graph) -> Vec<bool> {
    g.states
        .iter()
        .map(|s| {
            l.is_over(s)
                || (g.alone && !l.is_active(s, 0))
                || p.finals.iter().any(|f| holds_marking(l, s, f))
                || p.goals.iter().any(|f| holds_marking(l, s, f))
        })
        .collect()
}

/// Whether a dead marking `s` is intended: a catastrophic event ended the mission, a final
/// marking holds, or (alone, `--net`) the net is no longer active: it finished.
pub(super) fn intended_end(p: &CompiledProject, l: &Layout, g: &Graph, s: &[u64]) -> bool {
    l.is_over(s)
        || (g.alone && !l.is_active(s, 0))
        || p.finals.iter().any(|f| holds_marking(l, s, f))
}

/// The dead markings: states where the environment can deliver nothing.
pub(super) fn dead_markings(
    p: &CompiledProject,
    l: &Layout,
    g: &Graph,
    describe: &dyn Fn(&[u64]) -> Vec<String>,
) -> Vec<(DeadFinding, u32)> {
    g.dead
        .iter()
        .map(|&i| {
            let s = &g.states[i as usize];
            let after_catastrophic = l.is_over(s);
            let net_done = g.alone && !l.is_active(s, 0);
            let intended = intended_end(p, l, g, s);
            (
                DeadFinding {
                    marking: describe(s),
                    intended,
                    after_catastrophic,
                    net_done,
                    trace: g.trace(i),
                    places: marked_places(p, l, s),
                },
                i,
            )
        })
        .collect()
}

/// The first reachable state breaking each invariant.
pub(super) fn invariants(
    p: &CompiledProject,
    l: &Layout,
    g: &Graph,
    describe: &dyn Fn(&[u64]) -> Vec<String>,
) -> Vec<(InvariantFinding, u32)> {
    let mut out = Vec::new();
    for inv in &p.invariants {
        if let Some(i) = g.states.iter().position(|s| !l.holds(&inv.formula, s)) {
            out.push((
                InvariantFinding {
                    invariant: inv.name.clone(),
                    marking: describe(&g.states[i]),
                    trace: g.trace(i as u32),
                },
                i as u32,
            ));
        }
    }
    out
}

/// The strongly connected components of the graph, or of the edges whose step kind `keep`
/// keeps (Pearce's space-efficient variant of Tarjan's algorithm, iterative): numbered in the
/// order they complete, so every kept edge goes from a component to one numbered no higher
/// (reverse topological order), with each component's states.
pub(super) struct Scc {
    /// Each state's component.
    pub comp: Vec<u32>,
    /// The states, grouped by component in increasing number.
    order: Vec<u32>,
    /// Component `c`'s states are `order[start[c]..start[c + 1]]`.
    start: Vec<u32>,
}

impl Scc {
    /// The components of `g`'s edges whose step kind `keep` keeps (every edge with `None`).
    ///
    /// The edges of the state on top of the depth-first path are in one buffer: when the search
    /// comes back to a state after a child, its edges are fetched again (recomputed, when the
    /// graph does not keep them), so the search holds no edges of the states below.
    pub fn new(g: &Graph, edges: &Edges, keep: Option<&[bool]>) -> Scc {
        let n = g.states.len();
        // Unvisited (0), then the depth-first index while the state is live, then its
        // component counted down from n - 1 (above every live index: Pearce's invariant).
        let mut rindex = vec![0u32; n];
        let mut stack: Vec<u32> = Vec::new();
        // The depth-first path: each state and how many of its edges were looked at, with
        // ROOT while no edge led lower.
        const ROOT: u32 = 1 << 31;
        let mut call: Vec<(u32, u32)> = Vec::new();
        let mut order: Vec<u32> = Vec::with_capacity(n);
        let mut start: Vec<u32> = vec![0];
        let mut index = 1u32;
        let mut c = (n as u32).wrapping_sub(1);
        let mut buf: Vec<Edge> = Vec::new();
        let mut buf_of = u32::MAX;
        for r in 0..n as u32 {
            if rindex[r as usize] != 0 {
                continue;
            }
            rindex[r as usize] = index;
            index += 1;
            call.push((r, ROOT));
            while let Some(&mut (v, ref mut off)) = call.last_mut() {
                if buf_of != v {
                    edges.of(v, &mut buf);
                    buf_of = v;
                }
                let k = (*off & !ROOT) as usize;
                if k < buf.len() {
                    *off += 1;
                    let e = buf[k];
                    if keep.is_some_and(|kp| !kp[e.kind as usize]) {
                        continue;
                    }
                    let w = e.to;
                    if rindex[w as usize] == 0 {
                        rindex[w as usize] = index;
                        index += 1;
                        call.push((w, ROOT));
                    } else if rindex[w as usize] < rindex[v as usize] {
                        rindex[v as usize] = rindex[w as usize];
                        *off &= !ROOT;
                    }
                    continue;
                }
                let root = *off & ROOT != 0;
                call.pop();
                if root {
                    index -= 1;
                    while let Some(&w) = stack.last() {
                        if rindex[v as usize] > rindex[w as usize] {
                            break;
                        }
                        stack.pop();
                        rindex[w as usize] = c;
                        index -= 1;
                        order.push(w);
                    }
                    rindex[v as usize] = c;
                    order.push(v);
                    c = c.wrapping_sub(1);
                    start.push(order.len() as u32);
                } else {
                    stack.push(v);
                }
                if let Some(&mut (u, ref mut uoff)) = call.last_mut() {
                    if rindex[v as usize] < rindex[u as usize] {
                        rindex[u as usize] = rindex[v as usize];
                        *uoff &= !ROOT;
                    }
                }
            }
        }
        // Number the components from 0 in the order they completed.
        let top = (n as u32).wrapping_sub(1);
        for x in &mut rindex {
            *x = top - *x;
        }
        Scc {
            comp: rindex,
            order,
            start,
        }
    }

    /// How many components.
    pub fn count(&self) -> usize {
        self.start.len() - 1
    }

    /// The states of component `c`.
    pub fn members(&self, c: u32) -> &[u32] {
        &self.order[self.start[c as usize] as usize..self.start[c as usize + 1] as usize]
    }

    /// Per component: whether a state where `target` holds is reachable from it along the
    /// edges `keep` keeps (all with `None`; the components must be those of the same edges).
    /// The components are met in increasing number, so every one an edge leads to is done.
    fn reach(
        &self,
        edges: &Edges,
        keep: Option<&[bool]>,
        target: &dyn Fn(u32) -> bool,
    ) -> Vec<bool> {
        let mut out: Vec<bool> = Vec::with_capacity(self.count());
        let mut buf = Vec::new();
        for c in 0..self.count() as u32 {
            let r = self.members(c).iter().any(|&v| {
                target(v) || {
                    edges.of(v, &mut buf);
                    buf.iter().any(|e| {
                        keep.is_none_or(|kp| kp[e.kind as usize]) && {
                            let d = self.comp[e.to as usize];
                            d != c && out[d as usize]
                        }
                    })
                }
            });
            out.push(r);
        }
        out
    }
}

/// What one walk over the edges, component by component, answers (each part when asked):
/// per component of the whole graph, whether an end is reachable from it (progress, when
/// every edge counts) and which nets can still fire from it; and the loops. One walk where
/// there were three: each walk over the edges is a replay of every state when the graph does
/// not keep them.
pub(super) struct Walk {
    /// Per component: an end is reachable.
    pub reach: Option<Vec<bool>>,
    pub can: Option<CanFire>,
    pub loops: Option<Vec<Loop>>,
}

impl Walk {
    /// The walk over `all`, the components of the whole graph: `ends` (by state) for what
    /// reaches one, `can` for the nets that can still fire, `loops` for the loops.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        p: &CompiledProject,
        l: &Layout,
        g: &Graph,
        edges: &Edges,
        all: &Scc,
        ends: Option<&[bool]>,
        can: bool,
        loops: bool,
    ) -> Walk {
        let words = p.nets.len().div_ceil(64).max(1);
        // The nets each step kind fires.
        let fires = can.then(|| {
            let mut fires = vec![0u64; g.steps().len() * words];
            for (k, &(_, f)) in g.steps().iter().enumerate() {
                for &r in &g.fired_sets[f as usize] {
                    let net = l.rules[r as usize].net as usize;
                    fires[k * words + net / 64] |= 1 << (net % 64);
                }
            }
            fires
        });
        let mut bits = vec![0u64; if can { all.count() * words } else { 0 }];
        let mut reach: Vec<bool> = Vec::with_capacity(if ends.is_some() { all.count() } else { 0 });
        let mut found: Vec<Loop> = Vec::new();
        let mut seen = vec![false; g.steps().len()];
        let mut kinds: Vec<u32> = Vec::new();
        let mut buf = Vec::new();
        for c in 0..all.count() as u32 {
            let mut r = false;
            let mut first = u32::MAX;
            kinds.clear();
            let (here, done) = bits.split_at_mut(if can { c as usize * words } else { 0 });
            for &v in all.members(c) {
                r |= ends.is_some_and(|e| e[v as usize]);
                edges.of(v, &mut buf);
                for e in &buf {
                    let d = all.comp[e.to as usize];
                    if d != c {
                        r |= ends.is_some() && reach[d as usize];
                    } else if loops && e.to != v {
                        first = first.min(v);
                        if !seen[e.kind as usize] {
                            seen[e.kind as usize] = true;
                            kinds.push(e.kind);
                        }
                    }
                    if let Some(fires) = &fires {
                        let row = &mut done[..words];
                        for w in 0..words {
                            row[w] |= fires[e.kind as usize * words + w];
                            if d != c {
                                row[w] |= here[d as usize * words + w];
                            }
                        }
                    }
                }
            }
            if ends.is_some() {
                reach.push(r);
            }
            for &k in &kinds {
                seen[k as usize] = false;
            }
            if first != u32::MAX {
                found.push(Loop {
                    comp: c,
                    first,
                    kinds: kinds.clone(),
                });
            }
        }
        found.sort_unstable_by_key(|x| x.first);
        Walk {
            reach: ends.is_some().then_some(reach),
            can: can.then(|| CanFire {
                words,
                bits,
                no_transitions: p.nets.iter().map(|n| n.transitions.is_empty()).collect(),
            }),
            loops: loops.then_some(found),
        }
    }
}

/// Whether progress counts on every step kind of `g` (no edge's event is of a category it
/// excludes): then the whole graph's components and [`Walk`] answer it.
pub(super) fn progress_allowed(p: &CompiledProject, g: &Graph) -> Vec<bool> {
    g.steps()
        .iter()
        .map(|&(label, _)| {
            let e = g.labels[label as usize].event;
            e == NO_EVENT || !p.progress_excludes.contains(&p.events[e as usize].category)
        })
        .collect()
}

/// Progress: from every reachable state, an end stays reachable without the events of the
/// excluded categories (AG EF end, over the stable states). The first state (in breadth-first
/// order) that fails, how many do, and the first state the mission stays in for good once it
/// failed (a failing state in a bottom loop of the graph without the excluded events), with
/// their indices. `all_reach`: per component of `all`, whether an end is reachable from it
/// ([`Walk`]), when every edge counts ([`progress_allowed`]).
#[allow(clippy::too_many_arguments)]
pub(super) fn progress(
    p: &CompiledProject,
    l: &Layout,
    g: &Graph,
    edges: &Edges,
    all: &Scc,
    ends: &[bool],
    all_reach: Option<&[bool]>,
    describe: &dyn Fn(&[u64]) -> Vec<String>,
) -> Option<(ProgressFinding, u32, u32, Vec<bool>)> {
    let n = g.states.len();
    if p.finals.is_empty() && p.goals.is_empty() {
        // No end declared: nothing to make progress towards.
        return None;
    }
    // The step kinds progress counts on.
    let allowed = progress_allowed(p, g);
    // Over the allowed edges: their own components, unless every edge is allowed.
    let own;
    let owned;
    let (scc, keep, creach) = match all_reach {
        Some(r) if allowed.iter().all(|&a| a) => (all, None, r),
        _ => {
            let keep = (!allowed.iter().all(|&a| a)).then_some(allowed.as_slice());
            own = Scc::new(g, edges, keep);
            owned = own.reach(edges, keep, &|v| ends[v as usize]);
            (&own, keep, owned.as_slice())
        }
    };
    let reach: Vec<bool> = (0..n).map(|i| creach[scc.comp[i] as usize]).collect();
    let first = (0..n).find(|&i| !reach[i])?;
    let failing = reach.iter().filter(|&&r| !r).count();
    // Where the mission stays: a failing state whose loop (allowed edges only) has no way out.
    // Every allowed successor of a failing state fails too (it is in a component numbered no
    // higher, whose states all fail or all reach), so such a loop exists below each.
    let mut buf = Vec::new();
    let mut has_exit = |c: u32| {
        scc.members(c).iter().any(|&v| {
            edges.of(v, &mut buf);
            buf.iter()
                .any(|e| keep.is_none_or(|kp| kp[e.kind as usize]) && scc.comp[e.to as usize] != c)
        })
    };
    let mut exit_known: HashMap<u32, bool> = HashMap::new();
    let stays = (0..n)
        .filter(|&i| !reach[i])
        .find(|&i| {
            let c = scc.comp[i];
            !*exit_known.entry(c).or_insert_with(|| has_exit(c))
        })
        .unwrap_or(first);
    Some((
        ProgressFinding {
            marking: describe(&g.states[first]),
            trace: g.trace(first as u32),
            states: failing as u64,
            excluded: p
                .progress_excludes
                .iter()
                .map(|c| c.keyword().to_string())
                .collect(),
            stays_in: describe(&g.states[stays]),
            stays_in_trace: g.trace(stays as u32),
            places: marked_places(p, l, &g.states[stays]),
        },
        first as u32,
        stays as u32,
        reach,
    ))
}

/// The marked places of `s` (active nets only), as `NET.place` and `global.place`, to locate a
/// finding in the text.
pub(super) fn marked_places(p: &CompiledProject, l: &Layout, s: &[u64]) -> Vec<String> {
    let mut out = Vec::new();
    for (n, net) in p.nets.iter().enumerate() {
        if !l.is_active(s, n as NetId) {
            continue;
        }
        for (k, place) in net.places.iter().enumerate() {
            if l.is_marked(s, n as NetId, PlaceRef::Local(k as u32)) {
                out.push(format!("{}.{}", net.name, place.name));
            }
        }
    }
    for (k, gp) in p.globals.iter().enumerate() {
        if l.is_marked(s, 0, PlaceRef::Global(k as u32)) {
            out.push(format!("global.{}", gp.name));
        }
    }
    out
}

/// Whether `s` is an end for net `n`: the project is over, or the places of `n` in some final
/// (or goal) marking are all marked.
pub(super) fn end_for_net(p: &CompiledProject, l: &Layout, s: &[u64], n: NetId) -> bool {
    if l.is_over(s) {
        return true;
    }
    p.finals.iter().chain(&p.goals).any(|f| {
        let mine: Vec<&(NetId, PlaceRef)> = f
            .iter()
            .filter(|(m, r)| *m == n && matches!(r, PlaceRef::Local(_)))
            .collect();
        (!mine.is_empty() && mine.iter().all(|&&(m, r)| l.is_marked(s, m, r)))
            || holds_marking(l, s, f)
    })
}

/// A stuck net's finding, the state it is stuck in, and the net.
pub(super) type Stuck = (StuckFinding, u32, NetId);

/// Stuck nets: an active net that, in some reachable state, can never fire again whatever the
/// environment does (unless the state is an end for it). One finding per net, at the first
/// state it is stuck in (with that state and the net), with the resource cycle behind it when
/// the nets stuck there wait on one another's global places; and, per net, the states from
/// which it can still fire.
pub(super) fn stuck_nets(
    p: &CompiledProject,
    l: &Layout,
    g: &Graph,
    all: &Scc,
    can: CanFire,
    describe: &dyn Fn(&[u64]) -> Vec<String>,
) -> (Vec<Stuck>, CanFire) {
    let n = g.states.len();
    let mut out = Vec::new();
    for net in 0..p.nets.len() {
        let found = (0..n).find(|&i| {
            let s = &g.states[i];
            l.is_active(s, net as NetId)
                && !can.can(all, net as NetId, i as u32)
                && !end_for_net(p, l, s, net as NetId)
        });
        let Some(i) = found else { continue };
        let s = &g.states[i];
        let stuck_here: Vec<NetId> = (0..p.nets.len() as NetId)
            .filter(|&m| l.is_active(s, m) && !can.can(all, m, i as u32))
            .collect();
        out.push((
            StuckFinding {
                net: p.nets[net].name.clone(),
                marking: describe(s),
                trace: g.trace(i as u32),
                waits_for: waits_for(p, l, s, net as NetId),
                resource_cycle: resource_cycle(p, l, s, net as NetId, &stuck_here),
                places: marked_places(p, l, s)
                    .into_iter()
                    .filter(|q| {
                        q.split_once('.')
                            .is_some_and(|(owner, _)| owner == p.nets[net].name)
                    })
                    .collect(),
            },
            i as u32,
            net as NetId,
        ));
    }
    (out, can)
}

/// Per component of the whole graph: the nets that can still fire from its states (a set of
/// nets, one bit each).
pub(super) struct CanFire {
    words: usize,
    bits: Vec<u64>,
    /// Nets with no transition: they never fire, and are a store of places, not stuck.
    no_transitions: Vec<bool>,
}

impl CanFire {
    /// Whether net `net` can still fire from state `i` (`all`: the components it was built on).
    pub fn can(&self, all: &Scc, net: NetId, i: u32) -> bool {
        let net = net as usize;
        self.no_transitions[net] || {
            let c = all.comp[i as usize] as usize;
            self.bits[c * self.words + net / 64] & (1 << (net % 64)) != 0
        }
    }
}

/// The global places a net's transitions miss in `s` (all their local inputs marked).
fn missing_globals(p: &CompiledProject, l: &Layout, s: &[u64], n: NetId) -> Vec<u32> {
    let mut out = Vec::new();
    let net = &p.nets[n as usize];
    for t in &net.transitions {
        let locals_ok = t.inputs.iter().all(|&r| match r {
            PlaceRef::Local(_) => l.is_marked(s, n, r),
            PlaceRef::Global(_) => true,
        });
        if !locals_ok {
            continue;
        }
        for &r in &t.inputs {
            if let PlaceRef::Global(gl) = r {
                if !l.is_marked(s, n, r) && !out.contains(&gl) {
                    out.push(gl);
                }
            }
        }
    }
    out
}

fn waits_for(p: &CompiledProject, l: &Layout, s: &[u64], n: NetId) -> Vec<String> {
    missing_globals(p, l, s, n)
        .into_iter()
        .map(|gl| format!("global.{}", p.globals[gl as usize].name))
        .collect()
}

/// Whether net `m` holds global place `gl` in `s`: from its marked local places, following its
/// own transitions (their local places only), one of them gives `gl` back before any takes it.
/// A net waiting to take `gl` does not hold it; a net that took it and goes on to give it back
/// does.
fn holds(p: &CompiledProject, l: &Layout, s: &[u64], m: NetId, gl: u32) -> bool {
    let net = &p.nets[m as usize];
    let mut reached: Vec<bool> = (0..net.places.len() as u32)
        .map(|k| l.is_marked(s, m, PlaceRef::Local(k)))
        .collect();
    let mut used = vec![false; net.transitions.len()];
    loop {
        let mut grew = false;
        for (k, t) in net.transitions.iter().enumerate() {
            if used[k] || t.inputs.contains(&PlaceRef::Global(gl)) {
                continue;
            }
            let from_reached = t.inputs.iter().any(|r| match r {
                PlaceRef::Local(i) => reached[*i as usize],
                PlaceRef::Global(_) => false,
            });
            if !from_reached {
                continue;
            }
            if t.outputs.contains(&PlaceRef::Global(gl)) {
                return true;
            }
            used[k] = true;
            for r in &t.outputs {
                if let PlaceRef::Local(i) = r {
                    grew |= !std::mem::replace(&mut reached[*i as usize], true);
                }
            }
        }
        if !grew {
            return false;
        }
    }
}

/// A cycle of nets stuck in `s`, each waiting for a global place the next one holds (it took
/// the place and would give it back, could it go on): `A waits for global.y, which B holds; B
/// waits for global.x, which A holds`. A place nobody holds (taken and never given back) makes
/// no cycle.
fn resource_cycle(
    p: &CompiledProject,
    l: &Layout,
    s: &[u64],
    start: NetId,
    stuck_here: &[NetId],
) -> Option<Vec<String>> {
    let mut path: Vec<(NetId, u32)> = Vec::new();
    let mut seen: HashSet<NetId> = HashSet::new();
    let mut cur = start;
    while seen.insert(cur) {
        let next = missing_globals(p, l, s, cur).into_iter().find_map(|gl| {
            stuck_here
                .iter()
                .copied()
                .find(|&m| m != cur && holds(p, l, s, m, gl))
                .map(|m| (gl, m))
        })?;
        path.push((cur, next.0));
        if next.1 == start {
            return Some(
                path.iter()
                    .enumerate()
                    .map(|(k, &(n, gl))| {
                        let holder = path.get(k + 1).map_or(start, |x| x.0);
                        format!(
                            "{} waits for global.{}, which {} holds",
                            p.nets[n as usize].name,
                            p.globals[gl as usize].name,
                            p.nets[holder as usize].name
                        )
                    })
                    .collect(),
            );
        }
        cur = next.1;
    }
    None
}

/// The strongly connected components of the whole graph.
pub(super) fn components(g: &Graph, edges: &Edges) -> Scc {
    Scc::new(g, edges, None)
}

/// A loop of stable states: a component with edges inside it between two different states.
pub(super) struct Loop {
    comp: u32,
    /// Its first state (in breadth-first order) with such an edge.
    first: u32,
    /// The step kinds of those edges (indices in [`Graph::steps`]).
    kinds: Vec<u32>,
}

impl Loop {
    /// The events of its edges, sorted, each once.
    fn events(&self, g: &Graph) -> Vec<EventId> {
        let mut events: Vec<EventId> = self
            .kinds
            .iter()
            .map(|&k| g.labels[g.steps()[k as usize].0 as usize].event)
            .collect();
        events.sort_unstable();
        events.dedup();
        events
    }
}

/// Starvation: a loop of stable states the environment can keep the mission in forever, in
/// which a net waits at a transition (active throughout, that transition's local inputs marked
/// in every state of the loop, the transition never firing in it) that takes a global place
/// the loop's own firings give back and take again: it could fire, and never does. Read arcs
/// (an arbiter testing a place) wait for nothing.
pub(super) fn starvation(
    p: &CompiledProject,
    l: &Layout,
    g: &Graph,
    c: &Scc,
    loops: &[Loop],
) -> Vec<StarvationFinding> {
    let mut out: Vec<StarvationFinding> = Vec::new();
    // Per loop: the rules fired on its inner edges (not self-loops that change nothing), its
    // events, its states.
    for lp in loops {
        let fired: HashSet<u32> = lp
            .kinds
            .iter()
            .flat_map(|&k| {
                g.fired_sets[g.steps()[k as usize].1 as usize]
                    .iter()
                    .copied()
            })
            .collect();
        let events = lp.events(g);
        // The states of the loop, in breadth-first order.
        let mut states: Vec<u32> = c.members(lp.comp).to_vec();
        states.sort_unstable();
        // Which places the loop's firings give back.
        let released: HashSet<u32> = fired
            .iter()
            .flat_map(|&r| {
                let rule = &l.rules[r as usize];
                p.nets[rule.net as usize].transitions[rule.transition as usize]
                    .outputs
                    .iter()
                    .filter_map(|x| match x {
                        PlaceRef::Global(gl) => Some(*gl),
                        PlaceRef::Local(_) => None,
                    })
            })
            .collect();
        for (r, rule) in l.rules.iter().enumerate() {
            let net = rule.net;
            let t = &p.nets[net as usize].transitions[rule.transition as usize];
            if fired.contains(&(r as u32)) || out.iter().any(|f| f.net == p.nets[net as usize].name)
            {
                continue;
            }
            // The net waits at this transition throughout the loop: active, its local inputs
            // marked in every state of it.
            let waiting = states.iter().all(|&i| {
                let s = &g.states[i as usize];
                l.is_active(s, net)
                    && t.inputs.iter().all(|&x| match x {
                        PlaceRef::Local(_) => l.is_marked(s, net, x),
                        PlaceRef::Global(_) => true,
                    })
            });
            if !waiting {
                continue;
            }
            // A place it takes (not merely reads), missing somewhere in the loop, and given back
            // by the loop's firings: others keep taking it first.
            let starved = t.inputs.iter().find_map(|&x| match x {
                PlaceRef::Global(gl)
                    if !t.outputs.contains(&x)
                        && released.contains(&gl)
                        && states
                            .iter()
                            .any(|&i| !l.is_marked(&g.states[i as usize], net, x)) =>
                {
                    Some(gl)
                }
                _ => None,
            });
            let Some(gl) = starved else { continue };
            let mut names: Vec<String> = events
                .iter()
                .filter(|&&e| e != NO_EVENT)
                .map(|&e| p.events[e as usize].name.clone())
                .collect();
            names.sort();
            out.push(StarvationFinding {
                net: p.nets[net as usize].name.clone(),
                transition: format!("{}.{}", p.nets[net as usize].name, t.name),
                resource: format!("global.{}", p.globals[gl as usize].name),
                loop_events: names,
                trace: g.trace(states[0]),
            });
        }
    }
    out
}

/// Loops of stable states that need events, one finding per set of events, with one turn.
/// Self-loops (an event that changes nothing) are no loop.
pub(super) fn event_loops(
    p: &CompiledProject,
    g: &Graph,
    edges: &Edges,
    c: &Scc,
    loops: &[Loop],
) -> Vec<LoopFinding> {
    // The edges that move, with their events.
    let moves = |a: u32| {
        let mut buf = Vec::new();
        edges.of(a, &mut buf);
        buf.into_iter()
            .filter(move |e| e.to != a)
            .map(|e| (e.to, g.labels[g.label_of(e.kind) as usize].event))
    };
    let name = |e: EventId| {
        if e == NO_EVENT {
            "(environment)".to_string()
        } else {
            p.events[e as usize].name.clone()
        }
    };
    let mut out: Vec<LoopFinding> = Vec::new();
    for lp in loops {
        let size = c.members(lp.comp).len() as u64;
        let turn: Vec<String> = shortest_cycle(lp.first, &moves, &c.comp)
            .into_iter()
            .map(name)
            .collect();
        let events: Vec<String> = lp.events(g).into_iter().map(name).collect();
        // The same loop in many components (a reaction possible in many states) is one finding.
        match out.iter_mut().find(|l| l.events == events) {
            Some(l) => {
                l.states += size;
                l.components += 1;
            }
            None => out.push(LoopFinding {
                events,
                turn,
                states: size,
                components: 1,
            }),
        }
    }
    out
}

fn shortest_cycle<I: Iterator<Item = (u32, EventId)>>(
    start: u32,
    moves: &dyn Fn(u32) -> I,
    comp: &[u32],
) -> Vec<EventId> {
    let c = comp[start as usize];
    let mut prev: HashMap<u32, (u32, EventId)> = HashMap::new();
    let mut queue = VecDeque::from([start]);
    while let Some(a) = queue.pop_front() {
        for (b, e) in moves(a) {
            if comp[b as usize] != c {
                continue;
            }
            if b == start {
                let mut events = vec![e];
                let mut cur = a;
                while cur != start {
                    let (p, ev) = prev[&cur];
                    events.push(ev);
                    cur = p;
                }
                events.reverse();
                return events;
            }
            if let std::collections::hash_map::Entry::Vacant(v) = prev.entry(b) {
                v.insert((a, e));
                queue.push_back(b);
            }
        }
    }
    Vec::new()
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)]
mod tests {
    /// Strongly connected components by brute force: `a` and `b` are in one when each reaches
    /// the other.
    fn naive(n: usize, adj: &[Vec<u32>]) -> Vec<Vec<bool>> {
        let mut reach = vec![vec![false; n]; n];
        for a in 0..n {
            let mut stack = vec![a];
            reach[a][a] = true;
            while let Some(x) = stack.pop() {
                for &y in &adj[x] {
                    if !reach[a][y as usize] {
                        reach[a][y as usize] = true;
                        stack.push(y as usize);
                    }
                }
            }
        }
        reach
    }

    #[test]
    fn components_match_mutual_reachability_and_are_numbered_downstream() {
        use super::super::explore::tests_graph;
        // Pseudo-random graphs, small enough for the brute force.
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut rnd = move |m: u64| {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed % m
        };
        for _ in 0..200 {
            let n = 1 + rnd(30) as usize;
            let adj: Vec<Vec<u32>> = (0..n)
                .map(|_| (0..rnd(4)).map(|_| rnd(n as u64) as u32).collect())
                .collect();
            let g = tests_graph(&adj);
            let edges = super::Edges::new(&g, None);
            let scc = super::Scc::new(&g, &edges, None);
            let reach = naive(n, &adj);
            for a in 0..n {
                for b in 0..n {
                    let same = reach[a][b] && reach[b][a];
                    assert_eq!(scc.comp[a] == scc.comp[b], same, "{adj:?} {a} {b}");
                }
                for &b in &adj[a] {
                    assert!(scc.comp[b as usize] <= scc.comp[a], "{adj:?}");
                }
            }
            let mut seen = 0;
            for c in 0..scc.count() as u32 {
                for &v in scc.members(c) {
                    assert_eq!(scc.comp[v as usize], c);
                    seen += 1;
                }
            }
            assert_eq!(seen, n);
            // Reachability through the components, against the brute force.
            let target = |v: u32| v.is_multiple_of(5);
            let creach = scc.reach(&edges, None, &target);
            for a in 0..n {
                let expect = (0..n).any(|b| reach[a][b] && target(b as u32));
                assert_eq!(creach[scc.comp[a] as usize], expect, "{adj:?} {a}");
            }
        }
    }
}
