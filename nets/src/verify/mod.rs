//! Verification of a mission project (section 2.4 of the ProCoSA paper): explore every stable
//! state the project can reach, with the firing code the player runs ([`crate::semantics`]),
//! and report what would go wrong in flight, each finding with the shortest sequence of events
//! that shows it (the events that do not matter to it elided).
//!
//! - [`env`]: the environment: which events may come, with which parameters (the classes guards
//!   tell apart), addressed to which net; programs' declared answers and internal events come
//!   only when asked for.
//! - [`explore`]: breadth first over the stable states; what one step shows (refused firings,
//!   loops of immediate transitions, conflicts).
//! - [`analysis`]: what the whole graph shows: dead markings, invariants, progress (an end stays
//!   reachable), stuck nets and resource cycles, starvation, loops.
//! - [`minimize`]: the events of a trace that matter.
//! - [`render`]: the report for people, for tools, and as diagnostics on the project's text.
//!
//! docs/verification.md says exactly what is checked; docs/semantics.md what is explored.

mod analysis;
mod env;
mod explore;
mod minimize;
mod render;

pub use render::{diagnostics, render_human, render_human_all, to_json};

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
    /// The shortest sequence of events that gets there.
    pub trace: Trace,
}

/// A cycle of immediate transitions: the player would spin.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct LivelockFinding {
    /// `NET.transition`s fired in the cycle, in order.
    pub transitions: Vec<String>,
    /// The events that lead to it (the last one starts the cycle; empty: at start).
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
    /// The nets stuck with it, each waiting for a place the next would give back, if any.
    pub resource_cycle: Option<Vec<String>>,
}

/// A loop the environment can keep the mission in forever, in which a net waits for a global
/// place that the loop's firings keep giving back and taking again.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct StarvationFinding {
    /// The waiting net.
    pub net: String,
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
    /// Invariants checked in every reachable stable state.
    pub invariants: Vec<String>,
    /// Invariants broken, each with the shortest trace to a state that breaks it.
    pub invariant_violations: Vec<InvariantFinding>,
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
    /// Seconds spent.
    pub seconds: f64,
    /// Each net's template (its declaration in the net files), for locating findings.
    #[serde(skip)]
    pub templates: HashMap<String, String>,
    /// Every reachable stable state, when [`VerifyOptions::keep_states`] asked for them.
    #[serde(skip)]
    pub reachable: Vec<State>,
}

impl Report {
    /// True when nothing needs fixing: safe, no unintended dead marking, no livelock, every
    /// invariant holding, an end always reachable, no net stuck.
    pub fn is_clean(&self) -> bool {
        self.safe
            && !self.deadlock
            && self.livelocks.is_empty()
            && self.invariant_violations.is_empty()
            && self.no_progress.is_none()
            && self.stuck_nets.is_empty()
    }

    /// The number of errors (each finding that is one), as the reports count them.
    pub fn errors(&self) -> usize {
        self.unsafe_places.len()
            + self.dead_markings.iter().filter(|d| !d.intended).count()
            + self.livelocks.len()
            + self.invariant_violations.len()
            + usize::from(self.no_progress.is_some())
            + self.stuck_nets.len()
    }
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
    let (p, free_globals) = match &opts.only_net {
        None => (project, Vec::new()),
        Some(name) => {
            let id = project
                .net_id(name)
                .ok_or_else(|| VerifyError::UnknownNet(name.clone()))?;
            let free = globals_written_by_others(project, id);
            restricted = only_net(project, id);
            (&restricted, free)
        }
    };
    let started = Instant::now();
    let sem = Semantics::new(p);
    let l = &sem.layout;
    let env = env::Env::new(p, l.words);
    let g = explore::explore(p, &sem, &env, &free_globals, &mut opts, started, start)?;
    let describe = |s: &[u64]| {
        let mut out = l.describe_state(p, s);
        out.extend(env.describe(s));
        out
    };
    let mut report = Report {
        states: g.states.len() as u64,
        edges: g.edges.len() as u64,
        max_tokens_per_marking: g.max_tokens_per_marking,
        max_tokens_in_place: u64::from(g.max_tokens_per_marking > 0),
        safe: g.unsafe_places.is_empty(),
        invariants: p.invariants.iter().map(|i| i.name.clone()).collect(),
        protocols: env.names.clone(),
        ..Report::default()
    };
    // Each finding at a state: its trace keeps the events that matter to it.
    let m = minimize::Minimizer::new(p, &sem, &env, &g);
    let at = |i: u32, keep: &dyn Fn(&[u64]) -> bool| m.trace(i, keep);
    report.dead_markings = analysis::dead_markings(p, l, &g, &describe)
        .into_iter()
        .map(|(mut f, i)| {
            // Hundreds of ends after a catastrophic event need no minimal trace each.
            if !f.after_catastrophic {
                let target = g.states[i as usize].clone();
                f.trace = at(i, &|s| s == target.as_slice());
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
    let ends = analysis::ends(p, l, &g);
    report.no_progress = analysis::progress(p, &g, &ends, &describe).map(|(mut f, i)| {
        let target = g.states[i as usize].clone();
        f.trace = at(i, &|s| s == target.as_slice());
        f
    });
    report.stuck_nets = analysis::stuck_nets(p, l, &g, &describe)
        .into_iter()
        .map(|(mut f, i)| {
            let target = g.states[i as usize].clone();
            f.trace = at(i, &|s| s == target.as_slice());
            f
        })
        .collect();
    let components = analysis::components(&g);
    report.starvation = analysis::starvation(p, l, &g, &components);
    report.event_loops = analysis::event_loops(p, &g, &components);
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
        report.reachable = g
            .states
            .into_iter()
            .map(|mut s| {
                s.truncate(l.words);
                s
            })
            .collect();
        report.reachable.sort();
        report.reachable.dedup();
    }
    report.seconds = started.elapsed().as_secs_f64();
    Ok(report)
}

/// The global places a net other than `id` changes (takes a token from, or puts one in): the
/// ones the environment changes when `id` is verified alone.
fn globals_written_by_others(p: &CompiledProject, id: NetId) -> Vec<u32> {
    let mut out = Vec::new();
    for (n, net) in p.nets.iter().enumerate() {
        if n as NetId == id {
            continue;
        }
        for t in &net.transitions {
            for r in t.inputs.iter().chain(&t.outputs) {
                if let PlaceRef::Global(g) = r {
                    // Read arcs (in and out) change nothing.
                    let read = t.inputs.contains(r) && t.outputs.contains(r);
                    if !read && !out.contains(g) {
                        out.push(*g);
                    }
                }
            }
        }
    }
    out.sort_unstable();
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
    let keep = |f: &Vec<(NetId, PlaceRef)>| {
        f.iter()
            .all(|&(n, r)| n == id || matches!(r, PlaceRef::Global(_)))
    };
    CompiledProject {
        name: format!("{} (net {} alone)", p.name, net.name),
        nets: vec![net],
        globals: p.globals.clone(),
        events: p.events.clone(),
        programs: p.programs.clone(),
        timers: p.timers.clone(),
        start: vec![0],
        finals: p
            .finals
            .iter()
            .filter(|f| keep(f))
            .map(|f| f.iter().map(|&(_, r)| (0, r)).collect())
            .collect(),
        goals: p
            .goals
            .iter()
            .filter(|f| keep(f))
            .map(|f| f.iter().map(|&(_, r)| (0, r)).collect())
            .collect(),
        progress_excludes: p.progress_excludes.clone(),
        // The invariants speak of the whole project.
        invariants: Vec::new(),
    }
}
