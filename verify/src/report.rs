//! What a verification found ([`Report`]): every finding kind, each with the shortest trace
//! that shows it, and the counts the summaries and exit codes use.

use petrel_nets::semantics::State;
use std::collections::HashMap;

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
