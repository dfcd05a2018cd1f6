//! Verification of a mission project (section 2.4 of the ProCoSA paper): explore every stable
//! state the project can reach, with the firing code the player runs ([`crate::semantics`]),
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
mod reduction;
mod render;
mod store;
mod timed;

pub use render::{
    diagnostics, diagnostics_all, render_human, render_human_all, render_summary, to_json,
};

use crate::compiled::{Action, CompiledProject, NetId, PlaceRef};
use crate::semantics::{Semantics, State};
use std::collections::HashMap;
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
    /// [`crate::semantics::CASCADE_BOUND`]: for cross-checks with an engine given the same
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

/// One step of a trace: the event delivered by the environment (with its parameters' class and
/// target when they matter), a global place the environment changed (single-net verification),
/// or `...` for events that do not matter to the finding.
pub type Trace = Vec<String>;

/// A place that can receive a second token.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct UnsafeFinding {
    /// `NET.transition` whose firing would put the second token.
    pub transition: String,
    /// `NET.place` or `global.place`.
    pub place: String,
    /// The shortest sequence of events that gets there (the last one triggers the firing).
    pub trace: Trace,
}

/// A stable state from which nothing can fire any more.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct DeadFinding {
    /// Active nets with their marked places, global places, running timers.
    pub marking: Vec<String>,
    /// It holds one of the manifest's intended final markings.
    pub intended: bool,
    /// A catastrophic event ended the mission there.
    pub after_catastrophic: bool,
    /// The net verified alone (`--net`) is no longer active there: it finished (or deactivated
    /// itself), its end.
    pub net_done: bool,
    /// The shortest sequence of events that gets there.
    pub trace: Trace,
    /// Its marked places, `NET.place` and `global.place` (where the finding is in the text).
    pub places: Vec<String>,
}

/// A cycle of immediate transitions: the player would spin.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct LivelockFinding {
    /// `NET.transition`s fired in the cycle, in order.
    pub transitions: Vec<String>,
    /// The events that lead to it (the last one starts the cycle; empty: at start).
    pub trace: Trace,
}

/// Events produced at one instant that never settle (E0608, docs/semantics.md, "Zero-time
/// cascades"): a cascade that comes back to a state and a queue it was in, or that takes as
/// many steps as the player's bound with produced events still queued.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct CascadeFinding {
    /// The events of one turn of the loop, in the order the player takes them (`EVENT`,
    /// `EVENT(args)`, `EVENT to NET`); for a cascade that reaches the bound without coming
    /// back, every event it takes, once each, in the order it first takes them.
    pub events: Vec<String>,
    /// The `NET.transition`s that fire in it (immediate ones included), in dispatch order.
    pub transitions: Vec<String>,
    /// It comes back to a state and a queue it was in: it never ends. Otherwise it reaches the
    /// player's bound with produced events still queued (its queue grows).
    pub endless: bool,
    /// The events that lead to it: the last one is the outside event whose step starts it
    /// (empty: the start's own produced events start it).
    pub trace: Trace,
}

/// Two transitions enabled by the same event in the same state, taking a common token.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ConflictFinding {
    /// The event.
    pub event: String,
    /// `NET.transition` that fires (first in dispatch order).
    pub winner: String,
    /// `NET.transition` that does not.
    pub loser: String,
    /// The shortest sequence of events reaching the state where the event shows the conflict.
    pub trace: Trace,
}

/// A reachable stable state that breaks an invariant of the manifest.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct InvariantFinding {
    /// The invariant's name.
    pub invariant: String,
    /// The state: active nets with their marked places, global places, running timers.
    pub marking: Vec<String>,
    /// The shortest sequence of events that gets there.
    pub trace: Trace,
}

/// Reachable states from which no end of the mission can be reached any more without the
/// events of the excluded categories (the mission is stuck, though events may still come).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ProgressFinding {
    /// The first such state met (the one with the shortest trace).
    pub marking: Vec<String>,
    /// How to get there.
    pub trace: Trace,
    /// How many reachable states are like it.
    pub states: u64,
    /// The categories not counted on the way to an end.
    pub excluded: Vec<String>,
    /// The first state (in breadth-first order) the mission then stays in for good: a loop of
    /// failing states with no way out but the excluded events (where the missing transition
    /// is).
    pub stays_in: Vec<String>,
    /// How to get there, the events that do not matter elided.
    pub stays_in_trace: Trace,
    /// The marked places of that state, `NET.place` and `global.place`.
    pub places: Vec<String>,
}

/// An active net that, from some reachable state, can never fire again.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct StuckFinding {
    /// The net.
    pub net: String,
    /// The first state it is stuck in.
    pub marking: Vec<String>,
    /// How to get there.
    pub trace: Trace,
    /// The global places its transitions lack there (their local inputs all marked).
    pub waits_for: Vec<String>,
    /// The nets stuck with it, each waiting for a place the next one holds, if any.
    pub resource_cycle: Option<Vec<String>>,
    /// Its marked places there, `NET.place` (where it is stuck in the text).
    pub places: Vec<String>,
}

/// A loop the environment can keep the mission in forever, in which a net waits for a global
/// place that the loop's firings keep giving back and taking again.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct StarvationFinding {
    /// The waiting net.
    pub net: String,
    /// `NET.transition` it waits at: it takes the place, and never fires in the loop.
    pub transition: String,
    /// The place it waits for.
    pub resource: String,
    /// The events of the loop.
    pub loop_events: Vec<String>,
    /// How to get into the loop.
    pub trace: Trace,
}

/// A loop of stable states that needs outside events to go round (the waypoint loop, say).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct LoopFinding {
    /// Every event that moves the mission around inside the loop.
    pub events: Vec<String>,
    /// The events of one shortest turn.
    pub turn: Vec<String>,
    /// Stable states in the strongly connected components that show this loop.
    pub states: u64,
    /// How many strongly connected components show this same loop.
    pub components: u64,
}

/// What became of a time bound.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum BoundStatus {
    /// `to` always comes, within `max_seconds` of `from`.
    Bounded,
    /// Some path waits forever for `to` after `from` (`reason` says how).
    Unbounded,
    /// `from` never happens: there is nothing to bound.
    FromNeverHappens,
    /// Not computed: without `--timed`, with `--net`, from a reload's state, or the search
    /// stopped (`reason` says which).
    NotDecided,
}

/// A time bound (`[verify.bounds]`, `--bound`): over every occurrence of `from`, the least and
/// greatest time until the next `to` (docs/verification.md, "Time bounds").
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct BoundFinding {
    /// The bound's name (the manifest's key, or the command line's text).
    pub name: String,
    /// `from` as written: an event, or a marking formula.
    pub from: String,
    /// `to` as written.
    pub to: String,
    /// The requirement (`within`), in seconds.
    pub within_seconds: Option<f64>,
    /// The requirement as written in petrel.toml (`10min`).
    pub within: Option<String>,
    /// Bounded, unbounded, `from` never happens, or not decided.
    pub status: BoundStatus,
    /// Why it is unbounded (what `to` may wait for forever), or not decided.
    pub reason: Option<String>,
    /// The least time from `from` to the next `to`, over every path where `to` comes.
    pub min_seconds: Option<f64>,
    /// The greatest, when bounded.
    pub max_seconds: Option<f64>,
    /// The witness (the longest wait, or the one that may last forever): the events up to and
    /// including the step where `from` happened.
    pub trace: Trace,
    /// Then the events after it, to the step where `to` happened (bounded) or to the state that
    /// waits forever (unbounded).
    pub then: Trace,
    /// With `within`: whether the bound meets it (an unbounded one does not; E0607).
    pub met: Option<bool>,
}

/// Everything verification found.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Report {
    /// Stable states reached.
    pub states: u64,
    /// Event deliveries that change the state (self-loops included).
    pub edges: u64,
    /// Most tokens in one place over all reachable states: 1 (0 if nothing is ever marked).
    /// Petrel refuses a second token ([`Report::unsafe_places`] lists the firings that ask).
    pub max_tokens_in_place: u64,
    /// Most marked places in one reachable state.
    pub max_tokens_per_marking: u64,
    /// No firing ever asks for a second token in a place.
    pub safe: bool,
    /// Some reachable stable state has no way out and is not an intended final marking.
    pub deadlock: bool,
    /// Places that can receive a second token.
    pub unsafe_places: Vec<UnsafeFinding>,
    /// Dead markings, intended or not.
    pub dead_markings: Vec<DeadFinding>,
    /// Cycles of immediate transitions.
    pub livelocks: Vec<LivelockFinding>,
    /// Cascades of events produced at one instant that never settle.
    pub cascades: Vec<CascadeFinding>,
    /// The bound of a zero-time cascade the check looked for (the player's).
    pub cascade_bound: u32,
    /// Configurations (a state and a queue of produced events) the cascade check went through.
    pub cascade_configurations: u64,
    /// The cascade check stopped before it went through them all (too many).
    pub cascades_incomplete: bool,
    /// Invariants checked in every reachable stable state.
    pub invariants: Vec<String>,
    /// Invariants broken, each with the shortest trace to a state that breaks it.
    pub invariant_violations: Vec<InvariantFinding>,
    /// The project declares ends ([verify] final or goal): progress is checked.
    pub declares_ends: bool,
    /// The categories whose events progress does not count on.
    pub progress_excludes: Vec<String>,
    /// States from which no end is reachable any more (when the project declares ends).
    pub no_progress: Option<ProgressFinding>,
    /// Nets that get stuck.
    pub stuck_nets: Vec<StuckFinding>,
    /// Nets the environment can keep waiting forever for a place others take.
    pub starvation: Vec<StarvationFinding>,
    /// Loops that need outside events (information).
    pub event_loops: Vec<LoopFinding>,
    /// Conflicts between transitions enabled by one event.
    pub conflicts: Vec<ConflictFinding>,
    /// `NET.transition`s that never fire.
    pub never_fired: Vec<String>,
    /// Nets never active.
    pub never_activated: Vec<String>,
    /// Declared events that no transition waits for.
    pub unused_events: Vec<String>,
    /// The environment's counters (declared answers, internal events), for people.
    pub protocols: Vec<String>,
    /// States the partial-order reduction expanded with one component's deliveries only.
    pub reduced_states: u64,
    /// The reduction left states out: starvation and loops need every state and were not
    /// checked (`--no-reduction` checks them); traces are witnesses, not necessarily the
    /// shortest (those to dead markings are).
    pub partial: bool,
    /// Timed exploration (`--timed`): timers with literal durations expire in duration order;
    /// states are stable states with a zone over the timers' clocks.
    pub timed: bool,
    /// The time bounds of the project, each decided with `--timed`.
    pub bounds: Vec<BoundFinding>,
    /// Seconds spent.
    pub seconds: f64,
    /// Of those, the seconds until the exploration ended (the graph built, before the
    /// analyses and the findings' traces), for the benchmarks (docs/benchmarks.md).
    #[serde(skip)]
    pub explore_seconds: f64,
    /// Bytes the explored graph holds (its states, parent pointers, and edges when it keeps
    /// them), for the benchmarks (docs/benchmarks.md).
    #[serde(skip)]
    pub graph_bytes: u64,
    /// Each net's template (its declaration in the net files), for locating findings.
    #[serde(skip)]
    pub templates: HashMap<String, String>,
    /// Every reachable stable state, when [`VerifyOptions::keep_states`] asked for them.
    #[serde(skip)]
    pub reachable: Vec<State>,
}

impl Report {
    /// True when nothing needs fixing: safe, no unintended dead marking, no livelock, no
    /// cascade that never settles, every invariant holding, an end always reachable, no net
    /// stuck.
    pub fn is_clean(&self) -> bool {
        self.safe
            && !self.deadlock
            && self.livelocks.is_empty()
            && self.cascades.is_empty()
            && self.invariant_violations.is_empty()
            && self.no_progress.is_none()
            && self.stuck_nets.is_empty()
            && self.bounds.iter().all(|b| b.met != Some(false))
    }

    /// The number of errors (each finding that is one), as the reports count them.
    pub fn errors(&self) -> usize {
        self.unsafe_places.len()
            + self.dead_markings.iter().filter(|d| !d.intended).count()
            + self.livelocks.len()
            + self.cascades.len()
            + self.invariant_violations.len()
            + usize::from(self.no_progress.is_some())
            + self.stuck_nets.len()
            + self.bounds.iter().filter(|b| b.met == Some(false)).count()
    }

    /// The number of warnings the diagnostics give: conflicts, starvation, transitions that
    /// never fire, nets never activated, events no transition waits for.
    pub fn warnings(&self) -> usize {
        self.conflicts.len()
            + self.starvation.len()
            + self.never_fired.len()
            + self.never_activated.len()
            + self.unused_events.len()
    }
}

/// A cross-check for tests (docs/verification.md, "The state store"): explores `project` in
/// full (no partial-order reduction, whatever `opts` says), keeping every edge, then recomputes
/// each state's edges as the analyses do when the graph does not keep them, and compares.
/// Returns how many edges were compared, or the first state whose recomputed edges differ from
/// the explored ones.
pub fn check_replay(project: &CompiledProject, mut opts: VerifyOptions) -> Result<u64, String> {
    opts.no_reduction = true;
    opts.edges = EdgeMemory::Keep;
    if opts.only_net.is_some() {
        return Err("--net: the environment's moves are not replayed".into());
    }
    let sem = Semantics::new(project);
    let env = env::Env::new(project, sem.layout.words);
    let (g, mut replay) =
        explore::explore(project, &sem, &env, &[], &mut opts, Instant::now(), None)
            .map_err(|e| e.to_string())?;
    let (mut kept, mut replayed) = (Vec::new(), Vec::new());
    let mut compared = 0u64;
    for i in 0..g.states.len() as u32 {
        kept.clear();
        g.kept_edges(i, &mut kept);
        replayed.clear();
        replay.edges(&g, i, &mut replayed);
        if kept != replayed {
            return Err(format!(
                "state {i}: explored edges {kept:?}, replayed {replayed:?}"
            ));
        }
        compared += kept.len() as u64;
    }
    if compared != g.edge_count() as u64 || !g.edges_kept() {
        return Err(format!("{compared} edges compared of {}", g.edge_count()));
    }
    Ok(compared)
}

/// A cross-check for tests (docs/verification.md, "The transition cache"): explores `project`
/// in full (no partial-order reduction, edges kept, whatever `opts` says) with the transition
/// cache and without it, and compares the two graphs: the states in order, each state's
/// parent and label (the traces), its edges in order, the labels, fired sets and step kinds,
/// and what the exploration found (dead states, unsafe places, loops of immediate
/// transitions, conflicts, transitions fired, nets active); then the edges each recomputes
/// for the analyses. Returns how many components' moves the cache gave (0 when it did not
/// apply), or the first difference.
pub fn check_cache(project: &CompiledProject, mut opts: VerifyOptions) -> Result<u64, String> {
    opts.no_reduction = true;
    opts.edges = EdgeMemory::Keep;
    if opts.only_net.is_some() {
        return Err("--net: no transition cache".into());
    }
    let sem = Semantics::new(project);
    let env = env::Env::new(project, sem.layout.words);
    let mut run = |no_cache: bool| {
        opts.no_cache = no_cache;
        explore::explore(project, &sem, &env, &[], &mut opts, Instant::now(), None)
            .map_err(|e| e.to_string())
    };
    let (cached, mut cached_replay) = run(false)?;
    let (plain, mut plain_replay) = run(true)?;
    let (a, b) = (&cached, &plain);
    if a.states.len() != b.states.len() {
        return Err(format!(
            "{} states with the cache, {} without",
            a.states.len(),
            b.states.len()
        ));
    }
    let (mut ea, mut eb) = (Vec::new(), Vec::new());
    for i in 0..a.states.len() as u32 {
        if a.states[i as usize] != b.states[i as usize] || a.parent(i) != b.parent(i) {
            return Err(format!("state {i} or its parent differ"));
        }
        ea.clear();
        eb.clear();
        a.kept_edges(i, &mut ea);
        b.kept_edges(i, &mut eb);
        if ea != eb {
            return Err(format!(
                "state {i}: edges {ea:?} with the cache, {eb:?} without"
            ));
        }
        // What the analyses recompute when they do not keep the edges.
        ea.clear();
        eb.clear();
        cached_replay.edges(a, i, &mut ea);
        plain_replay.edges(b, i, &mut eb);
        if ea != eb {
            return Err(format!(
                "state {i}: replayed edges {ea:?} with the cache, {eb:?} without"
            ));
        }
    }
    let labels = |g: &explore::Graph| format!("{:?}", g.labels);
    let same = labels(a) == labels(b)
        && a.fired_sets == b.fired_sets
        && a.steps() == b.steps()
        && a.dead == b.dead
        && a.unsafe_places == b.unsafe_places
        && a.livelocks == b.livelocks
        && a.conflicts == b.conflicts
        && a.ever_fired == b.ever_fired
        && a.ever_active == b.ever_active
        && a.max_tokens_per_marking == b.max_tokens_per_marking;
    if !same {
        return Err("the labels, step kinds or findings differ".into());
    }
    if b.cache_hits != 0 {
        return Err("the cache was used when it was turned off".into());
    }
    Ok(a.cache_hits)
}

/// Verifies a compiled project.
pub fn verify(project: &CompiledProject, opts: VerifyOptions) -> Result<Report, VerifyError> {
    verify_inner(project, opts, None)
}

/// Verifies `project` from `state` (a stable state of its [`crate::semantics::Layout`])
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
        crate::model::builtin_events()
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
    l: &crate::semantics::Layout,
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
