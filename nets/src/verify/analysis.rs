//! What the explored graph shows: dead markings, invariants, progress, stuck nets and the
//! resource cycles behind them, starvation, loops of stable states.
//!
//! Every analysis reads the [`Graph`] the exploration built, in its breadth-first order, so the
//! first state a finding is met in has the shortest trace.

use super::explore::{Graph, NO_EVENT};
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

/// The graph's edges reversed, as one flat list per target state (built once, walked by every
/// backward search).
pub(super) struct Reverse {
    start: Vec<u32>,
    /// (source state, edge index), grouped by target state.
    from: Vec<(u32, u32)>,
}

impl Reverse {
    pub fn new(g: &Graph) -> Reverse {
        let n = g.states.len();
        let mut start = vec![0u32; n + 1];
        for e in &g.edges {
            start[e.to as usize + 1] += 1;
        }
        for k in 0..n {
            start[k + 1] += start[k];
        }
        let mut next = start.clone();
        let mut from = vec![(0u32, 0u32); g.edges.len()];
        for (k, e) in g.edges.iter().enumerate() {
            let slot = &mut next[e.to as usize];
            from[*slot as usize] = (e.from, k as u32);
            *slot += 1;
        }
        Reverse { start, from }
    }
}

/// The states from which a target is reachable along `keep` edges (backward breadth first from
/// the targets).
fn can_reach(rev: &Reverse, targets: &[bool], keep: &dyn Fn(usize) -> bool) -> Vec<bool> {
    let mut reach = targets.to_vec();
    let mut queue: VecDeque<u32> = (0..reach.len() as u32)
        .filter(|&i| reach[i as usize])
        .collect();
    while let Some(j) = queue.pop_front() {
        let (a, b) = (rev.start[j as usize], rev.start[j as usize + 1]);
        for &(i, k) in &rev.from[a as usize..b as usize] {
            if !reach[i as usize] && keep(k as usize) {
                reach[i as usize] = true;
                queue.push_back(i);
            }
        }
    }
    reach
}

/// Progress: from every reachable state, an end stays reachable without the events of the
/// excluded categories (AG EF end, over the stable states). The first state (in breadth-first
/// order) that fails, how many do, and the first state the mission stays in for good once it
/// failed (a failing state in a bottom loop of the graph without the excluded events), with
/// their indices.
pub(super) fn progress(
    p: &CompiledProject,
    l: &Layout,
    g: &Graph,
    rev: &Reverse,
    ends: &[bool],
    describe: &dyn Fn(&[u64]) -> Vec<String>,
) -> Option<(ProgressFinding, u32, u32, Vec<bool>)> {
    let n = g.states.len();
    if p.finals.is_empty() && p.goals.is_empty() {
        // No end declared: nothing to make progress towards.
        return None;
    }
    let allowed = |k: usize| {
        let e = g.labels[g.edges[k].label as usize].event;
        e == NO_EVENT || !p.progress_excludes.contains(&p.events[e as usize].category)
    };
    let reach = can_reach(rev, ends, &allowed);
    let failing: Vec<usize> = (0..n).filter(|&i| !reach[i]).collect();
    let &first = failing.first()?;
    // Where the mission stays: a failing state whose loop (allowed edges only) has no way out.
    // Every allowed successor of a failing state fails too, so such a loop exists below each.
    let mut adj: Vec<Vec<(u32, EventId)>> = vec![Vec::new(); n];
    for (k, e) in g.edges.iter().enumerate() {
        if allowed(k) && !reach[e.from as usize] {
            adj[e.from as usize].push((e.to, 0));
        }
    }
    let comp = tarjan(n, &adj);
    let mut has_exit = vec![false; n];
    for (a, succ) in adj.iter().enumerate() {
        if succ.iter().any(|&(b, _)| comp[b as usize] != comp[a]) {
            has_exit[comp[a] as usize] = true;
        }
    }
    let stays = failing
        .iter()
        .copied()
        .find(|&i| !has_exit[comp[i] as usize])
        .unwrap_or(first);
    Some((
        ProgressFinding {
            marking: describe(&g.states[first]),
            trace: g.trace(first as u32),
            states: failing.len() as u64,
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
    rev: &Reverse,
    describe: &dyn Fn(&[u64]) -> Vec<String>,
) -> (Vec<Stuck>, Vec<Vec<bool>>) {
    let n = g.states.len();
    let mut out = Vec::new();
    // Rules of each net, and the edges where each net fires.
    let mut fires: Vec<Vec<bool>> = vec![vec![false; n]; p.nets.len()];
    for e in &g.edges {
        for &r in &g.fired_sets[e.fired as usize] {
            fires[l.rules[r as usize].net as usize][e.from as usize] = true;
        }
    }
    let mut can: Vec<Vec<bool>> = Vec::with_capacity(p.nets.len());
    for (net, fires) in fires.iter().enumerate() {
        can.push(if p.nets[net].transitions.is_empty() {
            // A net with no transition never fires: it is a store of places, not stuck.
            vec![true; n]
        } else {
            can_reach(rev, fires, &|_| true)
        });
    }
    for net in 0..p.nets.len() {
        let found = (0..n).find(|&i| {
            let s = &g.states[i];
            l.is_active(s, net as NetId) && !can[net][i] && !end_for_net(p, l, s, net as NetId)
        });
        let Some(i) = found else { continue };
        let s = &g.states[i];
        let stuck_here: Vec<NetId> = (0..p.nets.len() as NetId)
            .filter(|&m| l.is_active(s, m) && !can[m as usize][i])
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

/// Loops of stable states: strongly connected components, their edges inside.
pub(super) struct Components {
    pub comp: Vec<u32>,
    pub size: HashMap<u32, u64>,
}

pub(super) fn components(g: &Graph) -> Components {
    let n = g.states.len();
    let mut adj: Vec<Vec<(u32, EventId)>> = vec![Vec::new(); n];
    for e in &g.edges {
        adj[e.from as usize].push((e.to, g.labels[e.label as usize].event));
    }
    let comp = tarjan(n, &adj);
    let mut size = HashMap::new();
    for &c in &comp {
        *size.entry(c).or_insert(0u64) += 1;
    }
    Components { comp, size }
}

/// What a loop's inner edges show: the rules fired, the events, one state of it.
type LoopInside = (HashSet<u32>, Vec<EventId>, u32, bool);

/// Starvation: a loop of stable states the environment can keep the mission in forever, in
/// which a net waits at a transition (active throughout, that transition's local inputs marked
/// in every state of the loop, the transition never firing in it) that takes a global place
/// the loop's own firings give back and take again: it could fire, and never does. Read arcs
/// (an arbiter testing a place) wait for nothing.
pub(super) fn starvation(
    p: &CompiledProject,
    l: &Layout,
    g: &Graph,
    c: &Components,
) -> Vec<StarvationFinding> {
    let mut out: Vec<StarvationFinding> = Vec::new();
    // Per component: the rules fired on its inner edges (not self-loops that change nothing),
    // its events, and one of its states.
    let mut inner: HashMap<u32, LoopInside> = HashMap::new();
    for e in &g.edges {
        let (a, b) = (c.comp[e.from as usize], c.comp[e.to as usize]);
        if a != b || e.from == e.to {
            continue;
        }
        let entry = inner
            .entry(a)
            .or_insert((HashSet::new(), Vec::new(), e.from, true));
        entry
            .0
            .extend(g.fired_sets[e.fired as usize].iter().copied());
        let ev = g.labels[e.label as usize].event;
        if !entry.1.contains(&ev) {
            entry.1.push(ev);
        }
    }
    let mut comps: Vec<(&u32, &LoopInside)> = inner.iter().collect();
    comps.sort_by_key(|(_, v)| v.2);
    // The states of each loop, gathered once.
    let mut members: HashMap<u32, Vec<usize>> = HashMap::new();
    for (i, comp) in c.comp.iter().enumerate() {
        if inner.contains_key(comp) {
            members.entry(*comp).or_default().push(i);
        }
    }
    for (comp, (fired, events, _, _)) in comps {
        let states = &members[comp];
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
                let s = &g.states[i];
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
                        && states.iter().any(|&i| !l.is_marked(&g.states[i], net, x)) =>
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
                trace: g.trace(states[0] as u32),
            });
        }
    }
    out
}

/// Loops of stable states that need events, one finding per set of events, with one turn.
/// Self-loops (an event that changes nothing) are no loop.
pub(super) fn event_loops(p: &CompiledProject, g: &Graph, c: &Components) -> Vec<LoopFinding> {
    let n = g.states.len();
    let mut adj: Vec<Vec<(u32, EventId)>> = vec![Vec::new(); n];
    for e in &g.edges {
        if e.from != e.to {
            adj[e.from as usize].push((e.to, g.labels[e.label as usize].event));
        }
    }
    let mut out: Vec<LoopFinding> = Vec::new();
    let mut done = HashSet::new();
    for (a, succ) in adj.iter().enumerate() {
        let comp = c.comp[a];
        if done.contains(&comp) || c.size[&comp] < 2 {
            continue;
        }
        if !succ.iter().any(|&(b, _)| c.comp[b as usize] == comp) {
            continue;
        }
        done.insert(comp);
        let name = |e: EventId| {
            if e == NO_EVENT {
                "(environment)".to_string()
            } else {
                p.events[e as usize].name.clone()
            }
        };
        let turn: Vec<String> = shortest_cycle(a as u32, &adj, &c.comp)
            .into_iter()
            .map(name)
            .collect();
        let mut inside: Vec<EventId> = Vec::new();
        for (x, succ) in adj.iter().enumerate() {
            if c.comp[x] != comp {
                continue;
            }
            for &(y, e) in succ {
                if c.comp[y as usize] == comp && !inside.contains(&e) {
                    inside.push(e);
                }
            }
        }
        inside.sort_unstable();
        let events: Vec<String> = inside.into_iter().map(name).collect();
        // The same loop in many components (a reaction possible in many states) is one finding.
        match out.iter_mut().find(|l| l.events == events) {
            Some(l) => {
                l.states += c.size[&comp];
                l.components += 1;
            }
            None => out.push(LoopFinding {
                events,
                turn,
                states: c.size[&comp],
                components: 1,
            }),
        }
    }
    out
}

fn shortest_cycle(start: u32, adj: &[Vec<(u32, EventId)>], comp: &[u32]) -> Vec<EventId> {
    let c = comp[start as usize];
    let mut prev: HashMap<u32, (u32, EventId)> = HashMap::new();
    let mut queue = VecDeque::from([start]);
    while let Some(a) = queue.pop_front() {
        for &(b, e) in &adj[a as usize] {
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

/// Strongly connected components (iterative Tarjan); returns each node's component id.
fn tarjan(n: usize, adj: &[Vec<(u32, EventId)>]) -> Vec<u32> {
    const UNSEEN: u32 = u32::MAX;
    let mut index = vec![UNSEEN; n];
    let mut low = vec![0u32; n];
    let mut on_stack = vec![false; n];
    let mut comp = vec![UNSEEN; n];
    let mut stack = Vec::new();
    let mut next_index = 0u32;
    let mut next_comp = 0u32;
    for root in 0..n {
        if index[root] != UNSEEN {
            continue;
        }
        let mut call: Vec<(usize, usize)> = vec![(root, 0)];
        index[root] = next_index;
        low[root] = next_index;
        next_index += 1;
        stack.push(root);
        on_stack[root] = true;
        while let Some(&mut (v, ref mut k)) = call.last_mut() {
            if *k < adj[v].len() {
                let w = adj[v][*k].0 as usize;
                *k += 1;
                if index[w] == UNSEEN {
                    index[w] = next_index;
                    low[w] = next_index;
                    next_index += 1;
                    stack.push(w);
                    on_stack[w] = true;
                    call.push((w, 0));
                } else if on_stack[w] {
                    low[v] = low[v].min(index[w]);
                }
            } else {
                call.pop();
                if let Some(&(u, _)) = call.last() {
                    low[u] = low[u].min(low[v]);
                }
                if low[v] == index[v] {
                    while let Some(w) = stack.pop() {
                        on_stack[w] = false;
                        comp[w] = next_comp;
                        if w == v {
                            break;
                        }
                    }
                    next_comp += 1;
                }
            }
        }
    }
    comp
}
