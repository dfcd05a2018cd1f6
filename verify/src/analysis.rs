//! What the explored graph shows: dead markings, invariants, progress, stuck nets and the
//! resource cycles behind them, starvation, loops of stable states.
//!
//! Every analysis reads the [`Graph`] the exploration built, in its breadth-first order, so the
//! first state a finding is met in has the shortest trace. The graph keeps its edges forward
//! only (grouped by source state): what is reachable backwards (an end, a firing) is computed
//! over its strongly connected components ([`Scc`]), numbered so that every edge goes to a
//! component numbered no higher, with no reversed copy of the edges.

use super::explore::{Edge, Edges, Graph, NO_EVENT};
use super::store::{width_of, Packed};
use crate::report::{
    DeadFinding, InvariantFinding, LoopFinding, ProgressFinding, StarvationFinding, StuckFinding,
    Trace,
};
use petrel_nets::compiled::{CompiledProject, EventId, NetId, PlaceRef};
use petrel_nets::semantics::Layout;
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
    /// Each state's edges are fetched (recomputed, when the graph does not keep them) once,
    /// when the search enters it: its targets not visited yet are kept for the search to come
    /// back to, in one stack of packed numbers for the whole depth-first path (a target and a
    /// step kind in 4 bytes at a million states), while they fit in a budget
    /// ([`Scc::budget`]); beyond it, a state's edges are fetched again each time the search
    /// comes back to it after a child.
    pub fn new(g: &Graph, edges: &Edges, keep: Option<&[bool]>) -> Scc {
        Scc::search(g, edges, keep, None, Scc::budget(g))
    }

    /// Unvisited targets the search keeps at most. Edges replayed: half the edges, which a
    /// graph whose every edge has its reverse never exceeds (of `v -> w` and `w -> v`, only
    /// the one out of the state entered first can find its target unvisited), so that each
    /// state is expanded once; a replay costs much more than the 2 to 4 bytes per edge
    /// (docs/benchmarks.md). Edges kept: one per state, as fetching them again is only
    /// reading them.
    fn budget(g: &Graph) -> usize {
        if g.edges_kept() {
            g.states.len().max(1 << 16)
        } else {
            (g.edge_count() / 2).max(1 << 16)
        }
    }

    /// The components of the whole graph, and what [`Walk`] answers, in the same search: each
    /// edge is looked at once its target is visited (when its source is entered, when the
    /// search comes back to its source from that target, or when it takes the edge up again
    /// after another child), when the target is either done (in a component numbered lower)
    /// or live (in the source's component) for good, so the walk needs no pass of its own
    /// over the edges.
    pub fn with_walk(g: &Graph, edges: &Edges, mut want: Folded) -> (Scc, Walk) {
        let scc = Scc::search(g, edges, None, Some(&mut want), Scc::budget(g));
        (scc, want.finish())
    }

    /// [`Scc::with_walk`] keeping at most `budget` unvisited targets (the tests try 0).
    #[cfg(test)]
    fn with_walk_within(g: &Graph, edges: &Edges, mut want: Folded, budget: usize) -> (Scc, Walk) {
        let scc = Scc::search(g, edges, None, Some(&mut want), budget);
        (scc, want.finish())
    }

    fn search(
        g: &Graph,
        edges: &Edges,
        keep: Option<&[bool]>,
        mut walk: Option<&mut Folded>,
        budget: usize,
    ) -> Scc {
        let n = g.states.len();
        let top = (n as u32).wrapping_sub(1);
        // Unvisited (0), then the depth-first index while the state is live, then its
        // component counted down from n - 1 (above every live index: Pearce's invariant).
        let mut rindex = vec![0u32; n];
        let mut stack: Vec<u32> = Vec::new();
        // The depth-first path: each state and how many of its targets were looked at, with
        // ROOT while no edge led lower, and CHILD while the last target looked at is a child
        // the search is in (or comes back from): the walk looks at that edge when it is back.
        const ROOT: u32 = 1 << 31;
        const CHILD: u32 = 1 << 30;
        const COUNT: u32 = CHILD - 1;
        let mut call: Vec<(u32, u32)> = Vec::new();
        // Per state on the path, where its unvisited targets start in `pending` (the top
        // state's run to the end), or NOT_KEPT: its edges are fetched again when the search
        // comes back to it.
        const NOT_KEPT: u32 = u32::MAX;
        let mut starts: Vec<u32> = Vec::new();
        // Each kept edge one number, its target in the low `shift` bits and its step kind
        // above, in as few bytes as they need (4 at a million states and 40 step kinds).
        let shift = 32 - top.max(1).leading_zeros();
        let mask = (1u64 << shift) - 1;
        let kinds = g.steps().len().max(1) as u64 - 1;
        let mut pending = Packed::with_width(width_of(kinds << shift | mask));
        let encode = |e: &Edge| u64::from(e.to) | u64::from(e.kind) << shift;
        let decode = |v: u64| Edge {
            to: (v & mask) as u32,
            kind: (v >> shift) as u32,
        };
        let mut order: Vec<u32> = Vec::with_capacity(n);
        let mut start: Vec<u32> = vec![0];
        let mut index = 1u32;
        let mut c = (n as u32).wrapping_sub(1);
        let mut buf: Vec<Edge> = Vec::new();
        let mut buf_of = u32::MAX;
        let kept = |e: &Edge| keep.is_none_or(|kp| kp[e.kind as usize]);
        for r in 0..n as u32 {
            if rindex[r as usize] != 0 {
                continue;
            }
            let mut entering = Some(r);
            loop {
                if let Some(w) = entering.take() {
                    rindex[w as usize] = index;
                    index += 1;
                    edges.of(w, &mut buf);
                    buf_of = w;
                    let mut flags = ROOT;
                    // The targets already visited are looked at now (an edge's order does not
                    // matter to the algorithm), the others kept within the budget.
                    let from = pending.len();
                    let mut fits = true;
                    for e in buf.iter().filter(|e| kept(e)) {
                        let x = rindex[e.to as usize];
                        if x == 0 {
                            if fits {
                                pending.push(encode(e));
                                fits = pending.len() <= budget;
                            }
                        } else if x < rindex[w as usize] {
                            rindex[w as usize] = x;
                            flags = 0;
                        }
                    }
                    if let Some(f) = walk.as_deref_mut() {
                        // A state that may be a component's root gathers for it; the others
                        // for the nearest one below them on the path, in their component.
                        // A visited target is done (in a component numbered lower) or live
                        // (in this state's component) for good.
                        if flags == ROOT {
                            f.open();
                        }
                        f.state(w);
                        for e in &buf {
                            let x = rindex[e.to as usize];
                            if x != 0 {
                                f.edge(w, e, Some(f.done(e.to).then(|| top - x)));
                            }
                        }
                    }
                    if fits {
                        starts.push(from as u32);
                    } else {
                        pending.truncate(from);
                        starts.push(NOT_KEPT);
                    }
                    call.push((w, flags));
                }
                let Some(&mut (v, ref mut off)) = call.last_mut() else {
                    break;
                };
                let from = starts[starts.len() - 1];
                if *off & CHILD != 0 {
                    // Back from a child: its component is done, or it is live and in this
                    // state's, for good; the walk looks at the edge to it now.
                    *off &= !CHILD;
                    if let Some(f) = walk.as_deref_mut() {
                        let k = (*off & COUNT) as usize - 1;
                        let e = if from != NOT_KEPT {
                            decode(pending.get(from as usize + k))
                        } else {
                            if buf_of != v {
                                edges.of(v, &mut buf);
                                buf_of = v;
                            }
                            buf[k]
                        };
                        let x = rindex[e.to as usize];
                        f.edge(v, &e, Some(f.done(e.to).then(|| top - x)));
                    }
                }
                // The next target not visited yet; the others, visited since `v` was entered
                // (by its descendants), are looked at on the way.
                let next = loop {
                    let e = if from != NOT_KEPT {
                        let k = from as usize + (*off & COUNT) as usize;
                        if k >= pending.len() {
                            break None;
                        }
                        decode(pending.get(k))
                    } else {
                        if buf_of != v {
                            edges.of(v, &mut buf);
                            buf_of = v;
                        }
                        match buf.get((*off & COUNT) as usize) {
                            Some(e) => *e,
                            None => break None,
                        }
                    };
                    *off += 1;
                    if !kept(&e) {
                        continue;
                    }
                    let x = rindex[e.to as usize];
                    if x == 0 {
                        break Some(e.to);
                    }
                    if x < rindex[v as usize] {
                        rindex[v as usize] = x;
                        if *off & ROOT != 0 {
                            *off &= !ROOT;
                            if let Some(f) = walk.as_deref_mut() {
                                f.merge();
                            }
                        }
                    }
                    if let Some(f) = walk.as_deref_mut() {
                        f.edge(v, &e, Some(f.done(e.to).then(|| top - x)));
                    }
                };
                if let Some(w) = next {
                    *off |= CHILD;
                    entering = Some(w);
                    continue;
                }
                let root = *off & ROOT != 0;
                call.pop();
                if from != NOT_KEPT {
                    pending.truncate(from as usize);
                }
                starts.pop();
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
                    if let Some(f) = walk.as_deref_mut() {
                        f.close(top - c, &order[start[start.len() - 1] as usize..]);
                    }
                    c = c.wrapping_sub(1);
                    start.push(order.len() as u32);
                } else {
                    stack.push(v);
                }
                if let Some(&mut (u, ref mut uoff)) = call.last_mut() {
                    if rindex[v as usize] < rindex[u as usize] {
                        rindex[u as usize] = rindex[v as usize];
                        if *uoff & ROOT != 0 {
                            *uoff &= !ROOT;
                            if let Some(f) = walk.as_deref_mut() {
                                f.merge();
                            }
                        }
                    }
                }
            }
        }
        // Number the components from 0 in the order they completed.
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

/// What the search for the components of the whole graph answers besides them
/// ([`Scc::with_walk`], each part when asked): per component, whether an end is reachable from
/// it (progress, when every edge counts) and which nets can still fire from it; and the loops.
/// No pass over the edges of its own, where there were three: each is a replay of every state
/// when the graph does not keep its edges.
#[cfg_attr(test, derive(Debug, PartialEq))]
pub(super) struct Walk {
    /// Per component: an end is reachable.
    pub reach: Option<Vec<bool>>,
    pub can: Option<CanFire>,
    pub loops: Option<Vec<Loop>>,
}

/// The nets each step kind of `g` fires (`words` words of bits per kind), the words, and the
/// nets with no transition (a store of places: never stuck), for [`CanFire`].
pub(super) fn nets_fired(
    p: &CompiledProject,
    l: &Layout,
    g: &Graph,
) -> (Vec<u64>, usize, Vec<bool>) {
    let words = p.nets.len().div_ceil(64).max(1);
    let mut fires = vec![0u64; g.steps().len() * words];
    for (k, &(_, f)) in g.steps().iter().enumerate() {
        for &r in &g.fired_sets[f as usize] {
            let net = l.rules[r as usize].net as usize;
            fires[k * words + net / 64] |= 1 << (net % 64);
        }
    }
    (
        fires,
        words,
        p.nets.iter().map(|n| n.transitions.is_empty()).collect(),
    )
}

/// What [`Scc::with_walk`] gathers, for each component while it is being found: one set of
/// values per state of the depth-first path that may still be a component's root (a state
/// that turns out not to be one hands its values to the next such state below it, which is
/// in its component), closed into the component's when its root is left.
pub(super) struct Folded<'x> {
    ends: Option<&'x [bool]>,
    /// The nets each step kind fires, `words` words each (when the nets that can fire are
    /// asked; `words` is 0 otherwise), and the nets with no transition.
    fires: Vec<u64>,
    words: usize,
    no_transitions: Vec<bool>,
    /// Words of a set of step kinds (0 when the loops are not asked).
    kw: usize,
    /// Per open set: an end is reachable (0 or 1), the first state with an edge inside the
    /// component to another state (`u64::MAX`: none yet), the nets that can fire (`words`),
    /// the step kinds of those inner edges (`kw`).
    open: Vec<u64>,
    reach: Vec<bool>,
    bits: Vec<u64>,
    found: Vec<Loop>,
    /// A bit per state whose component is complete.
    done: Vec<u64>,
}

impl<'x> Folded<'x> {
    /// What to gather over `g`: what reaches `ends` (when given), the nets that can still fire
    /// (`nets`, from [`nets_fired`], when given), the loops (when `loops`).
    pub fn new(
        g: &Graph,
        ends: Option<&'x [bool]>,
        nets: Option<(Vec<u64>, usize, Vec<bool>)>,
        loops: bool,
    ) -> Folded<'x> {
        let (fires, words, no_transitions) = nets.unwrap_or_default();
        Folded {
            ends,
            fires,
            words,
            no_transitions,
            kw: if loops {
                g.steps().len().div_ceil(64).max(1)
            } else {
                0
            },
            open: Vec::new(),
            reach: Vec::new(),
            bits: Vec::new(),
            found: Vec::new(),
            done: vec![0; g.states.len().div_ceil(64)],
        }
    }

    fn stride(&self) -> usize {
        2 + self.words + self.kw
    }

    /// A state that may be a component's root is entered.
    fn open(&mut self) {
        let st = self.stride();
        self.open.resize(self.open.len() + st, 0);
        let k = self.open.len() - st;
        self.open[k + 1] = u64::MAX;
    }

    /// State `v` is in the component of the top set.
    fn state(&mut self, v: u32) {
        if self.ends.is_some_and(|e| e[v as usize]) {
            let k = self.open.len() - self.stride();
            self.open[k] = 1;
        }
    }

    /// Edge `e` out of `v`, in the component of the top set, to a target not visited yet
    /// (`None`), in component `d` (`Some(Some(d))`, done), or live (`Some(None)`: in the
    /// component of `v`).
    fn edge(&mut self, v: u32, e: &Edge, target: Option<Option<u32>>) {
        debug_assert!(!self.open.is_empty());
        let (words, st) = (self.words, self.stride());
        let k = self.open.len() - st;
        let kind = e.kind as usize;
        for w in 0..words {
            self.open[k + 2 + w] |= self.fires[kind * words + w];
        }
        match target {
            None => {}
            Some(Some(d)) => {
                if self.ends.is_some() && self.reach[d as usize] {
                    self.open[k] = 1;
                }
                for w in 0..words {
                    self.open[k + 2 + w] |= self.bits[d as usize * words + w];
                }
            }
            Some(None) if self.kw > 0 && e.to != v => {
                self.open[k + 1] = self.open[k + 1].min(u64::from(v));
                self.open[k + 2 + words + kind / 64] |= 1 << (kind % 64);
            }
            Some(None) => {}
        }
    }

    /// The top set's state is not a component's root: its values go to the set below.
    fn merge(&mut self) {
        let st = self.stride();
        let k = self.open.len() - st;
        debug_assert!(k >= st);
        let below = k - st;
        self.open[below] |= self.open[k];
        self.open[below + 1] = self.open[below + 1].min(self.open[k + 1]);
        for w in 2..st {
            self.open[below + w] |= self.open[k + w];
        }
        self.open.truncate(k);
    }

    /// Whether state `v`'s component is complete (its number is then final; a live state's
    /// depth-first index may equal a complete component's number).
    fn done(&self, v: u32) -> bool {
        self.done
            .get(v as usize / 64)
            .is_some_and(|w| w & (1 << (v % 64)) != 0)
    }

    /// The top set's state is the root of component `comp`, now complete with `members`.
    fn close(&mut self, comp: u32, members: &[u32]) {
        for &v in members {
            let w = v as usize / 64;
            if self.done.len() <= w {
                self.done.resize(w + 1, 0);
            }
            self.done[w] |= 1 << (v % 64);
        }
        let (words, st) = (self.words, self.stride());
        let k = self.open.len() - st;
        debug_assert_eq!(self.reach.len(), comp as usize);
        self.reach.push(self.open[k] != 0);
        self.bits
            .extend_from_slice(&self.open[k + 2..k + 2 + words]);
        if self.open[k + 1] != u64::MAX {
            let mut kinds = Vec::new();
            for (w, &bits) in self.open[k + 2 + words..k + st].iter().enumerate() {
                let mut b = bits;
                while b != 0 {
                    kinds.push((w * 64) as u32 + b.trailing_zeros());
                    b &= b - 1;
                }
            }
            self.found.push(Loop {
                comp,
                first: self.open[k + 1] as u32,
                kinds,
            });
        }
        self.open.truncate(k);
    }

    fn finish(mut self) -> Walk {
        self.found.sort_unstable_by_key(|x| x.first);
        Walk {
            reach: self.ends.is_some().then_some(self.reach),
            can: (self.words > 0).then_some(CanFire {
                words: self.words,
                bits: self.bits,
                no_transitions: self.no_transitions,
            }),
            loops: (self.kw > 0).then_some(self.found),
        }
    }
}

#[cfg(test)]
impl Walk {
    /// The same answers as [`Scc::with_walk`], by a pass of their own over the edges,
    /// component by component (what the search does at once; the tests compare them).
    fn separate(
        edges: &Edges,
        all: &Scc,
        ends: Option<&[bool]>,
        nets: Option<(Vec<u64>, usize, Vec<bool>)>,
        loops: bool,
    ) -> Walk {
        let can = nets.is_some();
        let (fires, words, no_transitions) = nets.unwrap_or_default();
        let mut bits = vec![0u64; all.count() * words];
        let mut reach: Vec<bool> = Vec::new();
        let mut found: Vec<Loop> = Vec::new();
        let mut buf = Vec::new();
        for c in 0..all.count() as u32 {
            let mut r = false;
            let mut first = u32::MAX;
            let mut kinds: Vec<u32> = Vec::new();
            let (here, done) = bits.split_at_mut(c as usize * words);
            for &v in all.members(c) {
                r |= ends.is_some_and(|e| e[v as usize]);
                edges.of(v, &mut buf);
                for e in &buf {
                    let d = all.comp[e.to as usize];
                    if d != c {
                        r |= ends.is_some() && reach[d as usize];
                    } else if loops && e.to != v {
                        first = first.min(v);
                        if !kinds.contains(&e.kind) {
                            kinds.push(e.kind);
                        }
                    }
                    for w in 0..words {
                        done[w] |= fires[e.kind as usize * words + w];
                        if d != c {
                            done[w] |= here[d as usize * words + w];
                        }
                    }
                }
            }
            reach.push(r);
            kinds.sort_unstable();
            if first != u32::MAX {
                found.push(Loop {
                    comp: c,
                    first,
                    kinds,
                });
            }
        }
        found.sort_unstable_by_key(|x| x.first);
        Walk {
            reach: ends.is_some().then_some(reach),
            can: can.then_some(CanFire {
                words,
                bits,
                no_transitions,
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
            stuck_finding(
                p,
                l,
                s,
                net as NetId,
                &stuck_here,
                describe,
                g.trace(i as u32),
            ),
            i as u32,
            net as NetId,
        ));
    }
    (out, can)
}

/// The finding of net `net` stuck in `s`, reached by `trace`, with `stuck_here` the nets stuck
/// there with it.
pub(super) fn stuck_finding(
    p: &CompiledProject,
    l: &Layout,
    s: &[u64],
    net: NetId,
    stuck_here: &[NetId],
    describe: &dyn Fn(&[u64]) -> Vec<String>,
    trace: Trace,
) -> StuckFinding {
    let name = &p.nets[net as usize].name;
    StuckFinding {
        net: name.clone(),
        marking: describe(s),
        trace,
        waits_for: waits_for(p, l, s, net),
        resource_cycle: resource_cycle(p, l, s, net, stuck_here),
        places: marked_places(p, l, s)
            .into_iter()
            .filter(|q| q.split_once('.').is_some_and(|(owner, _)| owner == name))
            .collect(),
    }
}

/// Per component of the whole graph: the nets that can still fire from its states (a set of
/// nets, one bit each).
#[cfg_attr(test, derive(Debug, PartialEq))]
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

/// A loop of stable states: a component with edges inside it between two different states.
#[cfg_attr(test, derive(Debug, PartialEq))]
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
            // The walk folded into the search, against a pass of its own: the same
            // components, reach, nets that can fire (each step kind firing one of 70 nets:
            // two words) and loops.
            let ends: Vec<bool> = (0..n as u32).map(target).collect();
            let kinds = g.steps().len();
            let words = 2;
            let mut fires = vec![0u64; kinds * words];
            for k in 0..kinds {
                let net = (k * 37) % 70;
                fires[k * words + net / 64] |= 1 << (net % 64);
            }
            let nets = || Some((fires.clone(), words, vec![false; 70]));
            let separate = super::Walk::separate(&edges, &scc, Some(&ends), nets(), true);
            // Every unvisited target kept, none, or some (the search comes back to a state
            // whose targets it did not keep by fetching its edges again).
            for budget in [usize::MAX, 0, 3] {
                let want = super::Folded::new(&g, Some(&ends), nets(), true);
                let (folded_scc, folded) = super::Scc::with_walk_within(&g, &edges, want, budget);
                assert_eq!(folded_scc.comp, scc.comp, "{adj:?} {budget}");
                assert_eq!(folded, separate, "{adj:?} {budget}");
            }
        }
    }
}
