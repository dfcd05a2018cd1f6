//! Verification of a mission project (section 2.4 of the ProCoSA paper): explore every stable
//! state the project can reach, with the firing code the player runs ([`petrel_nets::semantics`]),
//! and report what would go wrong in flight, each finding with the shortest sequence of events
//! that shows it (the events that do not matter to it elided).
//!
//! - [`env`]: the environment: which events may come, with which parameters (the classes guards
//!   tell apart), addressed to which net; programs' declared answers and internal events come
//!   only when asked for.
//! - `explore`: breadth first over the stable states; what one step shows (refused firings,
//!   loops of immediate transitions, conflicts).
//! - `analysis`: what the whole graph shows: dead markings, invariants, progress (an end stays
//!   reachable), stuck nets and resource cycles, starvation, loops.
//! - `minimize`: the events of a trace that matter.
//! - `report`: what a verification found; `selfcheck`: the cross-checks tests run.
//! - `render`: the report for people, for tools, and as diagnostics on the project's text.
//!
//! docs/verification.md says exactly what is checked; docs/semantics.md what is explored.

mod analysis;
mod bound;
mod cache;
mod cascade;
mod env;
mod explore;
mod minimize;
pub mod reach;
mod reduction;
pub mod reload;
mod render;
mod report;
mod selfcheck;
mod store;
mod timed;

pub use render::{
    diagnostics, diagnostics_all, render_human, render_human_all, render_summary, to_json,
};
pub use report::{
    BoundFinding, BoundStatus, CascadeFinding, ConflictFinding, DeadFinding, InvariantFinding,
    LivelockFinding, LoopFinding, ProgressFinding, Report, StarvationFinding, StuckFinding, Trace,
    UnsafeFinding,
};
pub use selfcheck::{check_cache, check_replay};

use petrel_nets::compiled::{Action, CompiledProject, NetId, PlaceRef};
use petrel_nets::semantics::Semantics;
use std::time::Instant;

/// What to explore and how far.
#[derive(Default)]
pub struct VerifyOptions {
    /// Stop with [`VerifyError::TooManyStates`] beyond this many states.
    pub max_states: Option<u64>,
    /// Verify one net alone: the global places the other nets change, and the events, are free
    /// choices of the environment; the other nets are not modelled.
    pub only_net: Option<String>,
    /// Called about once a second with (states so far, states per second).
    pub progress: Option<Box<dyn FnMut(u64, f64)>>,
    /// Keep every reachable stable state in [`Report::reachable`] (for cross-checks).
    pub keep_states: bool,
    /// Skip what issue 13 added over the graph: progress, stuck nets, starvation and the
    /// minimization of traces (to measure what they cost; `petrel verify` always runs them).
    pub skip_liveness: bool,
    /// Explore every interleaving (`--no-reduction`): no partial-order reduction. The
    /// reduction keeps dead markings, unsafe places, loops of immediate transitions,
    /// invariants, conflicts, progress and stuck nets exact (docs/verification.md);
    /// starvation and loops need every state, and are checked only when it left none out.
    pub no_reduction: bool,
    /// Timed exploration (`--timed`): timers with literal durations expire in the order their
    /// durations impose (a zone over their clocks beside each state), outside events stay
    /// free. No partial-order reduction then, and traces are kept whole.
    pub timed: bool,
    /// Whether the explored graph keeps its edges in memory or the analyses recompute them.
    pub edges: EdgeMemory,
    /// Compute every step of the full exploration, without the transition cache that reuses
    /// a component's moves wherever its bits of the state are the same (docs/verification.md,
    /// "The transition cache"): the graph is the same, state for state and edge for edge; for
    /// cross-checks and measurements.
    pub no_cache: bool,
    /// The bound of a zero-time cascade the check looks for, instead of
    /// [`petrel_nets::semantics::CASCADE_BOUND`]: for cross-checks with an engine given the same
    /// bound.
    pub cascade_bound: Option<u32>,
}

/// Where the analyses find the explored graph's edges (docs/verification.md, "The state
/// store"): the findings are the same either way.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum EdgeMemory {
    /// Kept while there are few of them (about a million), recomputed beyond.
    #[default]
    Auto,
    /// Always kept: the analyses are fastest, at a few bytes per edge.
    Keep,
    /// Never kept: each state's edges are recomputed with the firing code when an analysis
    /// walks them, so the graph costs its states and parent pointers alone. Not with the
    /// partial-order reduction or `--net`, whose graphs keep their edges.
    Replay,
}

/// Why a verification could not finish.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum VerifyError {
    /// The state space is larger than `--max-states`.
    TooManyStates {
        /// The limit.
        limit: u64,
    },
    /// `--net` named no net.
    UnknownNet(String),
    /// Too many guards that the verifier cannot decide in one step (each doubles the runs).
    TooManyUndecidedGuards {
        /// The event delivered.
        event: String,
    },
}

impl std::fmt::Display for VerifyError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            VerifyError::TooManyStates { limit } => write!(
                f,
                "stopped after {limit} states (--max-states): the project has more reachable states; raise the limit, or verify one net with --net"
            ),
            VerifyError::UnknownNet(n) => write!(f, "no net named `{n}` in the project"),
            VerifyError::TooManyUndecidedGuards { event } => write!(
                f,
                "event `{event}` meets more than {} combinations of guards the verifier cannot decide (comparisons of two parameters, or of parameters bound at activation): compare parameters with constants or with fixed instance parameters",
                env::MAX_GUARD_RUNS
            ),
        }
    }
}

impl std::error::Error for VerifyError {}

/// Verifies a compiled project.
pub fn verify(project: &CompiledProject, opts: VerifyOptions) -> Result<Report, VerifyError> {
    verify_inner(project, opts, None)
}

/// Verifies `project` from `state` (a stable state of its [`petrel_nets::semantics::Layout`])
/// instead of its initial state: what a reload checks before it swaps (docs/semantics.md).
/// Programs' declared answers and internal events are free from there (the calls and
/// emissions outstanding in `state` are not known). Traces start at `state`. Not with
/// [`VerifyOptions::only_net`], which is refused as an unknown net.
pub fn verify_from(
    project: &CompiledProject,
    state: &[u64],
    mut opts: VerifyOptions,
) -> Result<Report, VerifyError> {
    if let Some(n) = opts.only_net.take() {
        return Err(VerifyError::UnknownNet(format!(
            "{n} (a verification from a state covers the whole project)"
        )));
    }
    verify_inner(project, opts, Some(state))
}

fn verify_inner(
    project: &CompiledProject,
    mut opts: VerifyOptions,
    start: Option<&[u64]>,
) -> Result<Report, VerifyError> {
    let restricted;
    let (p, alone) = match &opts.only_net {
        None => (project, None),
        Some(name) => {
            let id = project
                .net_id(name)
                .ok_or_else(|| VerifyError::UnknownNet(name.clone()))?;
            restricted = only_net(project, id);
            (&restricted, Some(id))
        }
    };
    let started = Instant::now();
    let mut sem = Semantics::new(p);
    if let Some(b) = opts.cascade_bound {
        sem.cascade_bound = b;
    }
    let sem = sem;
    let l = &sem.layout;
    let free = match alone {
        Some(id) => free_places(project, id, p, l),
        None => Vec::new(),
    };
    let env = env::Env::new(p, l.words);
    let (mut g, replay) = explore::explore(p, &sem, &env, &free, &mut opts, started, start)?;
    let explore_seconds = started.elapsed().as_secs_f64();
    g.alone = alone.is_some();
    let g = g;
    // The edges, kept or recomputed when an analysis walks them.
    let edges = explore::Edges::new(&g, Some(replay));
    let timing = opts.timed.then(|| timed::Timing::new(p, env.words));
    let describe = |s: &[u64]| {
        let mut out = l.describe_state(p, s);
        out.extend(env.describe(s));
        if let Some(tm) = &timing {
            out.extend(tm.describe(p, s));
        }
        out
    };
    let mut report = Report {
        states: g.states.len() as u64,
        edges: g.edge_count() as u64,
        graph_bytes: g.heap_bytes() as u64,
        explore_seconds,
        max_tokens_per_marking: g.max_tokens_per_marking,
        max_tokens_in_place: u64::from(g.max_tokens_per_marking > 0),
        safe: g.unsafe_places.is_empty(),
        invariants: p.invariants.iter().map(|i| i.name.clone()).collect(),
        protocols: env.names.clone(),
        declares_ends: !p.finals.is_empty() || !p.goals.is_empty(),
        progress_excludes: p
            .progress_excludes
            .iter()
            .map(|c| c.keyword().to_string())
            .collect(),
        ..Report::default()
    };
    // Each finding at a state: its trace keeps the events that matter to it.
    let m = minimize::Minimizer::new(p, &sem, &env, &g);
    let skip = opts.skip_liveness;
    // Timed, a trace with an event elided may not be possible in time: traces stay whole.
    let whole = skip || opts.timed;
    let at = |i: u32, keep: &dyn Fn(&[u64]) -> bool| {
        if whole {
            g.trace(i)
        } else {
            m.trace(i, keep)
        }
    };
    // Which graph state a replayed state is.
    let index_of = |s: &[u64]| -> Option<u32> { g.states.find(s) };
    // The nets a finding at `target` is about: the active ones not at an end of theirs. An
    // event matters when, without it, those nets would not be where they are.
    let concerned = |target: &[u64]| -> Vec<NetId> {
        (0..p.nets.len() as NetId)
            .filter(|&n| l.is_active(target, n) && !analysis::end_for_net(p, l, target, n))
            .collect()
    };
    let same_places = |s: &[u64], target: &[u64], nets: &[NetId]| {
        nets.iter().all(|&n| {
            l.is_active(s, n)
                && (0..p.nets[n as usize].places.len() as u32).all(|k| {
                    l.is_marked(s, n, PlaceRef::Local(k))
                        == l.is_marked(target, n, PlaceRef::Local(k))
                })
        })
    };
    let dead: Vec<bool> = {
        let mut v = vec![false; g.states.len()];
        for &i in &g.dead {
            v[i as usize] = true;
        }
        v
    };
    report.dead_markings = analysis::dead_markings(p, l, &g, &describe)
        .into_iter()
        .map(|(mut f, i)| {
            // Hundreds of ends after a catastrophic event need no minimal trace each.
            if !f.after_catastrophic {
                let target = g.states[i as usize].to_vec();
                let nets = concerned(&target);
                let intended = f.intended;
                // Still a dead marking of the same kind, the nets it is about where they are.
                f.trace = at(i, &|s| {
                    index_of(s).is_some_and(|k| dead[k as usize])
                        && analysis::intended_end(p, l, &g, s) == intended
                        && same_places(s, &target, &nets)
                });
            }
            f
        })
        .collect();
    report.deadlock = report.dead_markings.iter().any(|d| !d.intended);
    report.invariant_violations = analysis::invariants(p, l, &g, &describe)
        .into_iter()
        .map(|(mut f, i)| {
            let formula = &p
                .invariants
                .iter()
                .find(|x| x.name == f.invariant)
                .map(|x| &x.formula);
            f.trace = at(i, &|s| formula.is_some_and(|fm| !l.holds(fm, s)));
            f
        })
        .collect();
    report.reduced_states = g.reduced;
    report.timed = opts.timed;
    report.partial = g.reduced > 0;
    // What needs every state (loops, what stays reachable) is not asked of a partial graph.
    let whole = !report.partial;
    let ends = analysis::ends(p, l, &g);
    // The strongly connected components of the whole graph, for what is reachable from each
    // state (progress, stuck nets) and for the loops.
    // In the same search: what reaches an end (when progress counts every edge), the nets
    // that can still fire, and the loops.
    let declares_ends = !p.finals.is_empty() || !p.goals.is_empty();
    let every_edge = analysis::progress_allowed(p, &g).iter().all(|&a| a);
    let (all, mut walk) = if !opts.skip_liveness || whole {
        let want = analysis::Folded::new(
            &g,
            (!opts.skip_liveness && declares_ends && every_edge).then_some(ends.as_slice()),
            (!opts.skip_liveness).then(|| analysis::nets_fired(p, l, &g)),
            whole,
        );
        let (all, walk) = analysis::Scc::with_walk(&g, &edges, want);
        (Some(all), Some(walk))
    } else {
        (None, None)
    };
    if let (false, Some(all), Some(walk)) = (opts.skip_liveness, &all, &mut walk) {
        report.no_progress = analysis::progress(
            p,
            l,
            &g,
            &edges,
            all,
            &ends,
            walk.reach.as_deref(),
            &describe,
        )
        .map(|(mut f, first, stays, reach)| {
            // Any state from which no end is reachable will do for the first trace; for the
            // state the mission stays in, the nets not at an end must be where they are.
            f.trace = at(first, &|s| index_of(s).is_some_and(|k| !reach[k as usize]));
            let target = g.states[stays as usize].to_vec();
            let nets = concerned(&target);
            f.stays_in_trace = at(stays, &|s| {
                index_of(s).is_some_and(|k| !reach[k as usize]) && same_places(s, &target, &nets)
            });
            f
        });
        let can = walk
            .can
            .take()
            .expect("asked of the walk without --skip-liveness");
        let (stuck, can) = analysis::stuck_nets(p, l, &g, all, can, &describe);
        // Reduced, a net of another component than the ends' may be met stuck only beside an
        // end (docs/verification.md, "Partial-order reduction"): a witness is put together.
        let beside = if report.partial && declares_ends {
            let reported: Vec<NetId> = stuck.iter().map(|&(_, _, net)| net).collect();
            reduction::stuck_beside_ends(
                p,
                l,
                &g,
                &reduction::Components::new(p, l),
                &ends,
                &reported,
                &|net, i| can.can(all, net, i),
                &m,
            )
        } else {
            Ok(Vec::new())
        };
        let Ok(beside) = beside else {
            // No witness that way: the whole graph decides.
            opts.no_reduction = true;
            return verify_inner(project, opts, start);
        };
        let mut found: Vec<(NetId, StuckFinding)> = stuck
            .into_iter()
            // A net stuck in a dead marking with nothing to wait for: the dead marking says it all.
            .filter(|(f, i, _)| {
                !dead[*i as usize] || !f.waits_for.is_empty() || f.resource_cycle.is_some()
            })
            .map(|(mut f, i, net)| {
                // Any state where this net is active and can never fire again.
                f.trace = at(i, &|s| {
                    l.is_active(s, net)
                        && index_of(s).is_some_and(|k| !can.can(all, net, k))
                        && !analysis::end_for_net(p, l, s, net)
                });
                (net, f)
            })
            .collect();
        for b in beside {
            let trace = b
                .steps
                .iter()
                .map(|&label| g.labels[label as usize].text.clone())
                .collect();
            let f = analysis::stuck_finding(p, l, &b.state, b.net, &b.stuck_here, &describe, trace);
            let dead_here = index_of(&b.state).is_some_and(|k| dead[k as usize]);
            if !dead_here || !f.waits_for.is_empty() || f.resource_cycle.is_some() {
                found.push((b.net, f));
            }
        }
        found.sort_by_key(|&(net, _)| net);
        report.stuck_nets = found.into_iter().map(|(_, f)| f).collect();
    }
    if let (true, Some(all), Some(walk)) = (whole, &all, &mut walk) {
        let loops = walk.loops.take().unwrap_or_default();
        if !opts.skip_liveness {
            report.starvation = analysis::starvation(p, l, &g, all, &loops);
        }
        report.event_loops = analysis::event_loops(p, &g, &edges, all, &loops);
    }
    report.bounds = match &timing {
        Some(tm) if alone.is_none() && start.is_none() => {
            bound::bounds(p, &sem, &env, &g, &edges, tm, &describe)
        }
        _ => {
            let why = if !opts.timed {
                "needs --timed (timers expiring when their durations say)"
            } else if alone.is_some() {
                "not with --net (a bound speaks of the whole project)"
            } else {
                "not from a reload's state (the running timers' remaining times are not known)"
            };
            project
                .bounds
                .iter()
                .map(|b| BoundFinding {
                    name: b.name.clone(),
                    from: b.from_text.clone(),
                    to: b.to_text.clone(),
                    within_seconds: b.within_us.map(|us| us as f64 / 1e6),
                    within: b.within_text.clone(),
                    status: BoundStatus::NotDecided,
                    reason: Some(why.to_string()),
                    min_seconds: None,
                    max_seconds: None,
                    trace: Vec::new(),
                    then: Vec::new(),
                    met: None,
                })
                .collect()
        }
    };
    let cascades = cascade::cascades(
        p,
        &sem,
        &env,
        &g,
        explore::rule_guards(p, &sem),
        start.is_none(),
        opts.max_states
            .unwrap_or(cascade::BUDGET)
            .min(cascade::BUDGET),
    );
    report.cascades = cascades.findings;
    report.cascade_bound = sem.cascade_bound;
    report.cascade_configurations = cascades.configurations;
    report.cascades_incomplete = !cascades.complete;
    report.unsafe_places = g.unsafe_places.clone();
    report.livelocks = g.livelocks.clone();
    report.conflicts = g.conflicts.clone();
    report.never_fired = (0..l.rules.len() as u32)
        .filter(|&r| !g.ever_fired[r as usize])
        .map(|r| {
            let rule = &l.rules[r as usize];
            let net = &p.nets[rule.net as usize];
            format!(
                "{}.{}",
                net.name, net.transitions[rule.transition as usize].name
            )
        })
        .collect();
    report.never_activated = p
        .nets
        .iter()
        .enumerate()
        .filter(|(n, _)| {
            !g.ever_active[*n]
                && !l
                    .rules
                    .iter()
                    .enumerate()
                    .any(|(r, rule)| rule.net as usize == *n && g.ever_fired[r])
        })
        .map(|(_, n)| n.name.clone())
        .collect();
    let builtin = |name: &str| {
        petrel_nets::model::builtin_events()
            .iter()
            .any(|b| b.name.text == name)
    };
    report.unused_events = (0..p.events.len())
        .filter(|&e| l.by_event[e].is_empty() && !builtin(&p.events[e].name))
        .map(|e| p.events[e].name.clone())
        .collect();
    report.templates = p
        .nets
        .iter()
        .map(|n| (n.name.clone(), n.template.clone()))
        .collect();
    if opts.keep_states {
        // The project's own words only: the environment's counters are the verifier's.
        report.reachable = g.states.iter().map(|s| s[..l.words].to_vec()).collect();
        report.reachable.sort();
        report.reachable.dedup();
    }
    report.seconds = started.elapsed().as_secs_f64();
    Ok(report)
}

/// What the environment changes when net `id` of `project` is verified alone (`restricted`,
/// laid out by `l`): the global places this net uses that other nets change (marked if another
/// net puts a token in, emptied if another takes it; read arcs change nothing), and the
/// completion places of its children (a child, not modelled, may finish at any time). A global
/// place no other net changes keeps the value the net gives it.
fn free_places(
    project: &CompiledProject,
    id: NetId,
    restricted: &CompiledProject,
    l: &petrel_nets::semantics::Layout,
) -> Vec<explore::FreePlace> {
    let me = &project.nets[id as usize];
    let uses = |g: u32| {
        let r = PlaceRef::Global(g);
        me.transitions
            .iter()
            .any(|t| t.inputs.contains(&r) || t.outputs.contains(&r) || t.empty.contains(&r))
            || restricted
                .finals
                .iter()
                .chain(&restricted.goals)
                .any(|f| f.iter().any(|&(_, x)| x == r))
    };
    let mut out = Vec::new();
    for (g, gp) in project.globals.iter().enumerate() {
        let g = g as u32;
        if !uses(g) {
            continue;
        }
        let (mut puts, mut takes) = (false, false);
        for (n, net) in project.nets.iter().enumerate() {
            if n as NetId == id {
                continue;
            }
            for t in &net.transitions {
                let r = PlaceRef::Global(g);
                let (i, o) = (t.inputs.contains(&r), t.outputs.contains(&r));
                puts |= o && !i;
                takes |= i && !o;
            }
        }
        if puts || takes {
            out.push(explore::FreePlace {
                bit: l.place_bit(0, PlaceRef::Global(g)),
                name: format!("global.{}", gp.name),
                mark: puts,
                empty: takes,
            });
        }
    }
    for &c in &me.children {
        if let Some((_, place)) = project.nets[c as usize].parent {
            out.push(explore::FreePlace {
                bit: l.place_bit(0, PlaceRef::Local(place)),
                name: format!("{}.{}", me.name, me.places[place as usize].name),
                mark: true,
                empty: false,
            });
        }
    }
    out
}

/// The project reduced to one net, active at start; actions on other nets are dropped.
fn only_net(p: &CompiledProject, id: NetId) -> CompiledProject {
    let mut net = p.nets[id as usize].clone();
    // Alone: no parent, no children (its completion places stay, never marked).
    net.parent = None;
    net.children.clear();
    for t in &mut net.transitions {
        t.actions.retain(|a| match a {
            Action::Activate { net, .. } | Action::Deactivate(net) => *net == id,
            _ => true,
        });
        for a in &mut t.actions {
            match a {
                Action::Activate { net, .. } | Action::Deactivate(net) => *net = 0,
                Action::Emit { target, .. } => {
                    *target = target.filter(|&n| n == id).map(|_| 0);
                }
                _ => {}
            }
        }
    }
    // A final marking (or goal) speaks of this net through its places: those, and the global
    // places, are this net's end.
    let mine = |list: &Vec<Vec<(NetId, PlaceRef)>>| -> Vec<Vec<(NetId, PlaceRef)>> {
        list.iter()
            .filter(|f| {
                f.iter()
                    .any(|&(n, r)| n == id && matches!(r, PlaceRef::Local(_)))
            })
            .map(|f| {
                f.iter()
                    .filter(|&&(n, r)| n == id || matches!(r, PlaceRef::Global(_)))
                    .map(|&(_, r)| (0, r))
                    .collect()
            })
            .collect()
    };
    CompiledProject {
        name: format!("{} (net {} alone)", p.name, net.name),
        nets: vec![net],
        globals: p.globals.clone(),
        events: p.events.clone(),
        programs: p.programs.clone(),
        timers: p.timers.clone(),
        start: vec![0],
        finals: mine(&p.finals),
        goals: mine(&p.goals),
        progress_excludes: p.progress_excludes.clone(),
        // The invariants speak of the whole project.
        invariants: Vec::new(),
        // So do the bounds (not decided with `--net`).
        bounds: Vec::new(),
    }
}
