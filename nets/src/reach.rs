//! Reachability of plain place/transition nets: the explorer behind `petrel verify`.
//!
//! [`explore`] builds the full reachability graph of a [`PtNet`] breadth first, with the standard
//! firing rule (a transition is enabled when every input place holds at least the arc's weight;
//! firing takes those tokens and puts the output arcs' weights into the output places). It counts
//! the reachable markings and the firings between them, the largest token counts, the dead
//! markings, and keeps the shortest firing sequences to the first deadlock and to the first
//! marking that puts two tokens in a place.
//!
//! # Design
//!
//! The graph is never stored: only the set of markings is, and edges are counted as they are
//! found. Markings live back to back in one flat arena `Vec`, in the order they are discovered, so
//! the arena is also the breadth-first queue (state `i` is expanded when the cursor reaches `i`)
//! and a state is named by its `u32` position. An open-addressing table of those positions
//! deduplicates: 8 bytes a slot (the position and a 32-bit hash tag), no copy of the marking, and
//! it grows from the tags alone. A `u32` parent per state gives the shortest traces; the
//! transition of each step is found again at the end by trying the transitions of the parent, so
//! no transition id is stored.
//!
//! Two representations, the cheap one first:
//!
//! - **Bits**, when every arc weight is 1 and the initial marking is safe: one bit per place,
//!   `ceil(places / 64)` words per state (24 bytes for 160 places). Each transition is
//!   precompiled to sparse `(word, pre mask, post mask)` triples, so the enabling test and the
//!   firing are a few word operations. Transitions are indexed by one input place, chosen as the
//!   least often marked one over a sample of the first states, and only the transitions indexed
//!   by the places of the current marking are tested. The first firing that would put a second
//!   token in a place proves the net unsafe: the run stops and starts again with counts.
//! - **Counts**, for weighted or unsafe nets: one unsigned integer per place, 8 bits first. A
//!   count that no longer fits restarts the run with 16, then 32, then 64 bits.
//!
//! The hash of a marking is the XOR of one multiply-fold hash per word (or per place), so a
//! successor's hash is the parent's corrected for the few words the transition touches, rather
//! than a pass over the whole marking.
//!
//! An unbounded net has no finite graph. In the count representation, whenever a new marking
//! sets a record for the tokens in one marking (within a work budget) and whenever a count
//! overflows, the marking is compared with its ancestors on the breadth-first tree: a marking
//! that strictly covers an ancestor proves the net unbounded (the firings between them can be
//! repeated forever, each time adding tokens), and the run stops with that witness. Otherwise
//! `max_states`, the `u32` store limit, or a 64-bit token overflow stop it with a clear error.

#![forbid(unsafe_code)]
#![deny(missing_docs)]

use crate::plural::count;
use crate::pt::{PtNet, PtNode};
use crate::stubborn::Stubborn;
use std::fmt;
use std::fmt::Write as _;
use std::time::Instant;

// ---------------------------------------------------------------------------------------------
// Public API
// ---------------------------------------------------------------------------------------------

/// How [`explore`] runs.
pub struct ExploreOptions {
    /// Stop with [`ExploreError::TooManyStates`] when more than this many markings are
    /// reachable. `None` explores until done (or until the store's own limit of `u32::MAX - 1`
    /// markings).
    pub max_states: Option<u64>,
    /// Called about once a second with the progress so far, so a long run can show that it is
    /// alive. Not called at all on runs shorter than a second.
    pub progress: Option<Box<dyn FnMut(Progress)>>,
    /// Keep a parent pointer per marking (4 bytes each) so the report can give the shortest
    /// traces to the first deadlock and the first unsafe marking. Without it the verdicts are the
    /// same but the traces are `None`. The count representation keeps parents regardless: it
    /// needs them to prove a net unbounded.
    pub keep_traces: bool,
    /// Decide deadlocks alone, firing in each marking only the enabled transitions of a stubborn
    /// set (partial-order reduction, see the `stubborn` module's conditions): every dead marking
    /// is still reached, usually through far fewer markings. The report's sizes are then the
    /// reduced graph's, its bounds are not decided ([`PtReport::reduced`]), and its trace to a
    /// deadlock is a witness, not necessarily the shortest.
    pub deadlocks_only: bool,
}

impl Default for ExploreOptions {
    /// No state limit, no progress callback, traces kept, the full graph.
    fn default() -> Self {
        ExploreOptions {
            max_states: None,
            progress: None,
            keep_traces: true,
            deadlocks_only: false,
        }
    }
}

impl fmt::Debug for ExploreOptions {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("ExploreOptions")
            .field("max_states", &self.max_states)
            .field(
                "progress",
                &self.progress.as_ref().map(|_| "FnMut(Progress)"),
            )
            .field("keep_traces", &self.keep_traces)
            .field("deadlocks_only", &self.deadlocks_only)
            .finish()
    }
}

/// A snapshot handed to [`ExploreOptions::progress`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Progress {
    /// Distinct markings found so far.
    pub states: u64,
    /// Markings already expanded (the rest wait in the breadth-first queue).
    pub expanded: u64,
    /// Firings counted so far.
    pub edges: u64,
    /// Seconds since the exploration started.
    pub seconds: f64,
    /// Markings found per second over the whole run so far.
    pub states_per_second: f64,
}

/// A firing sequence from the initial marking: indices into [`PtNet::transitions`].
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Trace {
    /// The transitions, in firing order.
    pub transitions: Vec<usize>,
}

impl Trace {
    /// Number of firings.
    pub fn len(&self) -> usize {
        self.transitions.len()
    }

    /// True for the empty sequence (the property already holds in the initial marking).
    pub fn is_empty(&self) -> bool {
        self.transitions.is_empty()
    }
}

/// Where a net first stops being 1-safe.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct UnsafeWitness {
    /// The place holding more than one token (index into [`PtNet::places`]).
    pub place: usize,
    /// How many tokens it holds in that marking.
    pub tokens: u64,
    /// A shortest firing sequence reaching that marking (`None` when traces were not kept).
    pub trace: Option<Trace>,
}

/// How the markings were stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Representation {
    /// One bit per place: unit arc weights and a safe net.
    Bits,
    /// One unsigned integer of this many bits per place.
    Counts {
        /// 8, 16, 32 or 64.
        bits: u32,
    },
}

impl fmt::Display for Representation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Representation::Bits => f.write_str("one bit per place"),
            Representation::Counts { bits: 8 } => f.write_str("an 8-bit count per place"),
            Representation::Counts { bits } => write!(f, "a {bits}-bit count per place"),
        }
    }
}

/// What [`explore`] found: the full reachability graph's size and verdicts.
#[derive(Clone, Debug, PartialEq)]
pub struct PtReport {
    /// Reachable markings, the initial one included.
    pub states: u64,
    /// Firings between reachable markings: every (marking, enabled transition) pair counts once,
    /// even when two transitions lead to the same marking.
    pub edges: u64,
    /// The most tokens one place holds in any reachable marking.
    pub max_tokens_in_place: u64,
    /// The most tokens in one reachable marking, all places together (saturates at `u64::MAX`).
    pub max_tokens_per_marking: u64,
    /// True when no reachable marking has more than one token in a place.
    pub safe: bool,
    /// True when some reachable marking enables no transition.
    pub deadlock: bool,
    /// How many reachable markings enable no transition.
    pub dead_markings: u64,
    /// A shortest firing sequence to a dead marking (`None` without deadlock or without traces).
    pub first_deadlock: Option<Trace>,
    /// The first marking, breadth first, with two tokens in a place (`None` for a safe net).
    pub first_unsafe: Option<UnsafeWitness>,
    /// Wall-clock seconds, restarts included.
    pub seconds: f64,
    /// Bytes held by the final run's store (markings, hash table, parents): its peak, since the
    /// store only grows.
    pub store_bytes: u64,
    /// How the final run stored markings.
    pub representation: Representation,
    /// True when the exploration was reduced ([`ExploreOptions::deadlocks_only`]): `deadlock`,
    /// `dead_markings` and a found `first_unsafe` hold for the full graph; `states`, `edges` and
    /// the token maxima are the reduced graph's; `safe` means only that no marking explored had
    /// two tokens in a place; `first_deadlock` is a witness, not necessarily the shortest.
    pub reduced: bool,
}

/// Proof that a net is unbounded: `prefix` reaches a marking M, and `pump` fired from M reaches a
/// marking that strictly covers M, so `pump` can be fired again and again, each time adding
/// tokens to `place`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct UnboundedWitness {
    /// A place that grows without limit (index into [`PtNet::places`]).
    pub place: usize,
    /// A shortest firing sequence from the initial marking to M.
    pub prefix: Trace,
    /// A firing sequence from M to a strictly larger marking.
    pub pump: Trace,
    /// Markings found when the proof was found.
    pub states_so_far: u64,
}

/// Why [`explore`] gave no report.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ExploreError {
    /// More markings than [`ExploreOptions::max_states`] (or than the store's `u32` positions)
    /// are reachable.
    TooManyStates {
        /// The limit that was hit.
        limit: u64,
        /// Markings found when the exploration stopped.
        states_so_far: u64,
    },
    /// The net is unbounded: its reachability graph is infinite.
    Unbounded(Box<UnboundedWitness>),
    /// A place would hold more than `u64::MAX` tokens, and no covering proof was found.
    TokenOverflow {
        /// The place (index into [`PtNet::places`]).
        place: usize,
        /// Markings found when the exploration stopped.
        states_so_far: u64,
    },
    /// Memory for the store could not be had.
    OutOfMemory {
        /// Markings found when the exploration stopped.
        states_so_far: u64,
        /// Bytes held by the store at that point.
        store_bytes: u64,
    },
    /// The net is malformed (an arc joining two places, an index out of range...): only
    /// possible for a [`PtNet`] built by hand, since [`crate::pnml::parse_pnml`] builds none.
    InvalidNet {
        /// What is wrong.
        message: String,
    },
}

impl fmt::Display for ExploreError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ExploreError::TooManyStates {
                limit,
                states_so_far,
            } => write!(
                f,
                "more than {limit} reachable markings (stopped after {states_so_far}); raise the state limit, or the net may be too large (or unbounded) to explore"
            ),
            ExploreError::Unbounded(w) => write!(
                f,
                "the net is unbounded: place #{} grows without limit (a firing sequence of {} transitions from the initial marking, then a repeatable sequence of {} transitions; found after {} markings)",
                w.place,
                w.prefix.len(),
                w.pump.len(),
                w.states_so_far
            ),
            ExploreError::TokenOverflow {
                place,
                states_so_far,
            } => write!(
                f,
                "place #{place} would hold more than {} tokens (after {states_so_far} markings): the net is unbounded or too large to count",
                u64::MAX
            ),
            ExploreError::OutOfMemory {
                states_so_far,
                store_bytes,
            } => write!(
                f,
                "out of memory after {states_so_far} markings ({} MB stored); set a state limit or use a larger machine",
                store_bytes / 1_000_000
            ),
            ExploreError::InvalidNet { message } => write!(f, "invalid net: {message}"),
        }
    }
}

impl std::error::Error for ExploreError {}

/// Explores the full reachability graph of `net` breadth first.
///
/// Returns the report, or why there is none: a state limit, an unbounded net (with a proof),
/// memory. Never panics and always terminates: an unbounded net is caught by its covering proof,
/// a 64-bit token overflow, `max_states`, or the `u32` limit of the store.
pub fn explore(net: &PtNet, mut opts: ExploreOptions) -> Result<PtReport, ExploreError> {
    let start = Instant::now();
    let compiled = Compiled::new(net)?;
    let mut ctl = Ctl {
        limit: opts
            .max_states
            .unwrap_or(u64::MAX)
            .min(u64::from(MAX_STORE_STATES)),
        keep_traces: opts.keep_traces,
        deadlocks_only: opts.deadlocks_only,
        progress: opts.progress.as_deref_mut(),
        start,
        last: start,
    };
    let max_initial = compiled.initial.iter().copied().max().unwrap_or(0);
    let unit = compiled
        .pre
        .iter()
        .chain(&compiled.post)
        .all(|&(_, w)| w <= 1);
    let mut report = None;
    if unit && max_initial <= 1 {
        let mut bits = BitNet::new(&compiled);
        report = match bits.words {
            1 => run_bits::<1>(&compiled, &mut bits, &mut ctl)?,
            2 => run_bits::<2>(&compiled, &mut bits, &mut ctl)?,
            3 => run_bits::<3>(&compiled, &mut bits, &mut ctl)?,
            4 => run_bits::<4>(&compiled, &mut bits, &mut ctl)?,
            5 => run_bits::<5>(&compiled, &mut bits, &mut ctl)?,
            6 => run_bits::<6>(&compiled, &mut bits, &mut ctl)?,
            7 => run_bits::<7>(&compiled, &mut bits, &mut ctl)?,
            8 => run_bits::<8>(&compiled, &mut bits, &mut ctl)?,
            _ => run_bits::<0>(&compiled, &mut bits, &mut ctl)?,
        };
    }
    // Counts: the smallest width that holds the initial marking, widened on overflow.
    let mut bits = match max_initial {
        0..=0xff => 8,
        0x100..=0xffff => 16,
        0x1_0000..=0xffff_ffff => 32,
        _ => 64,
    };
    while report.is_none() {
        let outcome = match bits {
            8 => run_counts::<u8>(&compiled, &mut ctl)?,
            16 => run_counts::<u16>(&compiled, &mut ctl)?,
            32 => run_counts::<u32>(&compiled, &mut ctl)?,
            _ => run_counts::<u64>(&compiled, &mut ctl)?,
        };
        match outcome {
            Some(r) => report = Some(r),
            None if bits < 64 => bits *= 2,
            // run_counts::<u64> reports its overflow itself; this arm only keeps the loop total.
            None => {
                return Err(ExploreError::TokenOverflow {
                    place: 0,
                    states_so_far: 0,
                })
            }
        }
    }
    let mut report = report.unwrap_or_else(|| empty_report(Representation::Bits));
    report.seconds = start.elapsed().as_secs_f64();
    Ok(report)
}

/// The report for humans: sizes, bounds, verdicts, and the shortest traces by transition name.
pub fn render_human(net: &PtNet, r: &PtReport) -> String {
    let mut out = String::new();
    let yes_no = |b: bool| if b { "yes" } else { "no" };
    let _ = writeln!(
        out,
        "net {}: {}, {}, {}",
        net.name,
        count(net.places.len(), "place"),
        count(net.transitions.len(), "transition"),
        count(net.arcs.len(), "arc")
    );
    if r.reduced {
        // Sizes and maxima of the reduced graph would read as the net's: say what they are.
        let _ = writeln!(
            out,
            "markings explored:       {} (deadlocks only: stubborn sets, the full graph is larger)",
            r.states
        );
        let _ = writeln!(out, "edges (firings):         {}", r.edges);
        let safe = match (&r.first_unsafe, r.safe) {
            (Some(_), _) | (None, false) => "no",
            (None, true) => "not decided (no explored marking has two tokens in a place)",
        };
        let _ = writeln!(out, "safe (1-bounded):        {safe}");
    } else {
        let _ = writeln!(out, "reachable markings:      {}", r.states);
        let _ = writeln!(out, "edges (firings):         {}", r.edges);
        let _ = writeln!(out, "max tokens in a place:   {}", r.max_tokens_in_place);
        let _ = writeln!(out, "max tokens in a marking: {}", r.max_tokens_per_marking);
        let _ = writeln!(out, "safe (1-bounded):        {}", yes_no(r.safe));
    }
    if let Some(u) = &r.first_unsafe {
        let _ = write!(
            out,
            "  place {} holds {} tokens",
            place_label(net, u.place),
            u.tokens
        );
        match &u.trace {
            Some(t) => {
                let _ = writeln!(out, " after {}", describe_trace(net, t));
            }
            None => out.push_str(" (run with traces for the firing sequence)\n"),
        }
    }
    let _ = write!(out, "deadlock:                {}", yes_no(r.deadlock));
    if r.deadlock {
        let _ = write!(
            out,
            " ({} dead marking{})",
            r.dead_markings,
            if r.dead_markings == 1 { "" } else { "s" }
        );
    }
    out.push('\n');
    if let Some(t) = &r.first_deadlock {
        let _ = writeln!(
            out,
            "  {} to a deadlock: {}",
            if r.reduced {
                "a way (a witness, not necessarily the shortest)"
            } else {
                "shortest way"
            },
            describe_trace(net, t)
        );
    }
    let _ = writeln!(
        out,
        "explored in {:.2} s, {:.1} MB stored as {}",
        r.seconds,
        r.store_bytes as f64 / 1e6,
        r.representation
    );
    out
}

/// The report as JSON for tools: `states`, `edges`, `max_tokens_in_place`,
/// `max_tokens_per_marking`, `safe`, `deadlock`, `dead_markings`, `seconds`, `store_bytes`,
/// `representation`, `first_deadlock` (a trace or null) and `first_unsafe` (`{place, tokens,
/// trace}` or null), where a trace is a list of `{index, id, name}` transitions; `reduced`
/// (deadlocks only): then `safe` is null unless an unsafe marking was found, and the sizes and
/// maxima are the reduced graph's.
pub fn to_json(net: &PtNet, r: &PtReport) -> serde_json::Value {
    let safe = if r.reduced && r.safe && r.first_unsafe.is_none() {
        serde_json::Value::Null
    } else {
        serde_json::Value::Bool(r.safe)
    };
    serde_json::json!({
        "reduced": r.reduced,
        "net": net.name,
        "places": net.places.len(),
        "transitions": net.transitions.len(),
        "arcs": net.arcs.len(),
        "states": r.states,
        "edges": r.edges,
        "max_tokens_in_place": r.max_tokens_in_place,
        "max_tokens_per_marking": r.max_tokens_per_marking,
        "safe": safe,
        "deadlock": r.deadlock,
        "dead_markings": r.dead_markings,
        "first_deadlock": r.first_deadlock.as_ref().map(|t| trace_json(net, t)),
        "first_unsafe": r.first_unsafe.as_ref().map(|u| serde_json::json!({
            "place": node_json(net, PtNode::Place(u.place)),
            "tokens": u.tokens,
            "trace": u.trace.as_ref().map(|t| trace_json(net, t)),
        })),
        "seconds": r.seconds,
        "store_bytes": r.store_bytes,
        "representation": match r.representation {
            Representation::Bits => "bits".to_string(),
            Representation::Counts { bits } => format!("u{bits}"),
        },
    })
}

/// An [`ExploreError`] for humans, naming places and transitions (the `Display` form only has
/// their indices).
pub fn render_error(net: &PtNet, e: &ExploreError) -> String {
    match e {
        ExploreError::Unbounded(w) => format!(
            "the net is unbounded: place {} grows without limit.\n  from the initial marking, {}\n  reaches a marking M; then {}\n  leads from M to a marking with at least as many tokens everywhere and more in that place, so it can be repeated forever (found after {} markings)\n",
            place_label(net, w.place),
            describe_trace(net, &w.prefix),
            describe_trace(net, &w.pump),
            w.states_so_far
        ),
        ExploreError::TokenOverflow {
            place,
            states_so_far,
        } => format!(
            "place {} would hold more than {} tokens (after {states_so_far} markings): the net is unbounded or too large to count\n",
            place_label(net, *place),
            u64::MAX
        ),
        other => format!("{other}\n"),
    }
}

/// An [`ExploreError`] as JSON for tools: `{"error": kind, "message": text, ...details}`.
pub fn error_to_json(net: &PtNet, e: &ExploreError) -> serde_json::Value {
    let message = render_error(net, e).trim_end().to_string();
    match e {
        ExploreError::TooManyStates {
            limit,
            states_so_far,
        } => serde_json::json!({
            "error": "too_many_states", "message": message,
            "limit": limit, "states_so_far": states_so_far,
        }),
        ExploreError::Unbounded(w) => serde_json::json!({
            "error": "unbounded", "message": message,
            "place": node_json(net, PtNode::Place(w.place)),
            "prefix": trace_json(net, &w.prefix),
            "pump": trace_json(net, &w.pump),
            "states_so_far": w.states_so_far,
        }),
        ExploreError::TokenOverflow {
            place,
            states_so_far,
        } => serde_json::json!({
            "error": "token_overflow", "message": message,
            "place": node_json(net, PtNode::Place(*place)),
            "states_so_far": states_so_far,
        }),
        ExploreError::OutOfMemory {
            states_so_far,
            store_bytes,
        } => serde_json::json!({
            "error": "out_of_memory", "message": message,
            "states_so_far": states_so_far, "store_bytes": store_bytes,
        }),
        ExploreError::InvalidNet { .. } => serde_json::json!({
            "error": "invalid_net", "message": message,
        }),
    }
}

// ---------------------------------------------------------------------------------------------
// Rendering helpers
// ---------------------------------------------------------------------------------------------

/// Longest trace spelled out in the human report; JSON always has the whole trace.
const HUMAN_TRACE_MAX: usize = 60;

fn node_label(id: &str, name: &str) -> String {
    if id == name {
        format!("`{id}`")
    } else {
        format!("`{name}` ({id})")
    }
}

fn place_label(net: &PtNet, p: usize) -> String {
    match net.places.get(p) {
        Some(pl) => node_label(&pl.id, &pl.name),
        None => format!("#{p}"),
    }
}

fn transition_label(net: &PtNet, t: usize) -> String {
    match net.transitions.get(t) {
        Some(tr) => node_label(&tr.id, &tr.name),
        None => format!("#{t}"),
    }
}

fn describe_trace(net: &PtNet, t: &Trace) -> String {
    if t.is_empty() {
        return "no firing (the initial marking)".to_string();
    }
    let shown: Vec<String> = t
        .transitions
        .iter()
        .take(HUMAN_TRACE_MAX)
        .map(|&i| transition_label(net, i))
        .collect();
    let mut s = format!(
        "firing {} transition{}: {}",
        t.len(),
        if t.len() == 1 { "" } else { "s" },
        shown.join(" ")
    );
    if t.len() > HUMAN_TRACE_MAX {
        let _ = write!(s, " ... ({} more)", t.len() - HUMAN_TRACE_MAX);
    }
    s
}

fn node_json(net: &PtNet, n: PtNode) -> serde_json::Value {
    let (index, id, name) = match n {
        PtNode::Place(i) => (
            i,
            net.places.get(i).map(|p| p.id.as_str()),
            net.places.get(i).map(|p| p.name.as_str()),
        ),
        PtNode::Transition(i) => (
            i,
            net.transitions.get(i).map(|t| t.id.as_str()),
            net.transitions.get(i).map(|t| t.name.as_str()),
        ),
    };
    serde_json::json!({ "index": index, "id": id, "name": name })
}

fn trace_json(net: &PtNet, t: &Trace) -> serde_json::Value {
    serde_json::Value::Array(
        t.transitions
            .iter()
            .map(|&i| node_json(net, PtNode::Transition(i)))
            .collect(),
    )
}

// ---------------------------------------------------------------------------------------------
// Shared machinery
// ---------------------------------------------------------------------------------------------

/// The store names states by `u32` positions; the last value is kept free so a position plus one
/// never wraps.
const MAX_STORE_STATES: u32 = u32::MAX - 1;

/// States sampled before transitions are re-indexed by their least often marked input place.
const INDEX_SAMPLE: usize = 4096;

/// The net reduced to what firing needs: arcs summed per (transition, place, direction), weight-0
/// arcs dropped, per-transition lists sorted by place.
pub(crate) struct Compiled {
    pub(crate) places: usize,
    pub(crate) transitions: usize,
    initial: Vec<u64>,
    /// `pre[pre_start[t]..pre_start[t + 1]]`: `(place, weight)` taken by transition `t`.
    pre_start: Vec<usize>,
    pre: Vec<(usize, u64)>,
    /// Same layout: `(place, weight)` produced by transition `t`.
    post_start: Vec<usize>,
    post: Vec<(usize, u64)>,
}

impl Compiled {
    fn new(net: &PtNet) -> Result<Self, ExploreError> {
        let (places, transitions) = (net.places.len(), net.transitions.len());
        if transitions > u32::MAX as usize {
            return Err(ExploreError::InvalidNet {
                message: format!("{transitions} transitions is more than this explorer indexes"),
            });
        }
        let mut pre: Vec<Vec<(usize, u64)>> = vec![Vec::new(); transitions];
        let mut post: Vec<Vec<(usize, u64)>> = vec![Vec::new(); transitions];
        for a in &net.arcs {
            let (list, p, t) = match (a.source, a.target) {
                (PtNode::Place(p), PtNode::Transition(t)) => (&mut pre, p, t),
                (PtNode::Transition(t), PtNode::Place(p)) => (&mut post, p, t),
                _ => {
                    return Err(ExploreError::InvalidNet {
                        message: format!("arc `{}` must join a place and a transition", a.id),
                    })
                }
            };
            if p >= places || t >= transitions {
                return Err(ExploreError::InvalidNet {
                    message: format!("arc `{}` refers to a node that does not exist", a.id),
                });
            }
            if a.weight == 0 {
                continue;
            }
            let l = &mut list[t];
            match l.iter_mut().find(|(q, _)| *q == p) {
                Some((_, w)) => {
                    *w = w.checked_add(a.weight).ok_or_else(|| ExploreError::InvalidNet {
                        message: format!(
                            "the arcs between place `{}` and transition `{}` weigh more than {} together",
                            net.places[p].id,
                            net.transitions[t].id,
                            u64::MAX
                        ),
                    })?
                }
                None => l.push((p, a.weight)),
            }
        }
        let flatten = |lists: Vec<Vec<(usize, u64)>>| {
            let mut start = Vec::with_capacity(lists.len() + 1);
            let mut flat = Vec::new();
            start.push(0);
            for mut l in lists {
                l.sort_unstable();
                flat.extend(l);
                start.push(flat.len());
            }
            (start, flat)
        };
        let (pre_start, pre) = flatten(pre);
        let (post_start, post) = flatten(post);
        Ok(Compiled {
            places,
            transitions,
            initial: net.places.iter().map(|p| p.initial).collect(),
            pre_start,
            pre,
            post_start,
            post,
        })
    }

    /// `(place, weight)` taken by transition `t`.
    pub(crate) fn pre(&self, t: usize) -> &[(usize, u64)] {
        &self.pre[self.pre_start[t]..self.pre_start[t + 1]]
    }

    /// `(place, weight)` produced by transition `t`.
    pub(crate) fn post(&self, t: usize) -> &[(usize, u64)] {
        &self.post[self.post_start[t]..self.post_start[t + 1]]
    }
}

/// Limits, the progress callback and the clock, shared by every run of one exploration.
struct Ctl<'a> {
    /// The effective state limit: the user's or the store's.
    limit: u64,
    keep_traces: bool,
    deadlocks_only: bool,
    progress: Option<&'a mut (dyn FnMut(Progress) + 'static)>,
    start: Instant,
    last: Instant,
}

impl Ctl<'_> {
    /// Reports progress when a second has passed; cheap enough to call per expanded state
    /// because it looks at the clock only every 1024 calls.
    #[inline]
    fn tick(&mut self, states: usize, expanded: usize, edges: u64) {
        if expanded & 1023 != 0 {
            return;
        }
        let Some(cb) = self.progress.as_mut() else {
            return;
        };
        let now = Instant::now();
        if now.duration_since(self.last).as_secs_f64() < 1.0 {
            return;
        }
        self.last = now;
        let seconds = now.duration_since(self.start).as_secs_f64();
        cb(Progress {
            states: states as u64,
            expanded: expanded as u64,
            edges,
            seconds,
            states_per_second: states as f64 / seconds.max(1e-9),
        });
    }

    /// The error for a store about to exceed the limit.
    fn too_many(&self, states: usize) -> ExploreError {
        ExploreError::TooManyStates {
            limit: self.limit,
            states_so_far: states as u64,
        }
    }
}

fn empty_report(representation: Representation) -> PtReport {
    PtReport {
        states: 0,
        edges: 0,
        max_tokens_in_place: 0,
        max_tokens_per_marking: 0,
        safe: true,
        deadlock: false,
        dead_markings: 0,
        first_deadlock: None,
        first_unsafe: None,
        seconds: 0.0,
        store_bytes: 0,
        representation,
        reduced: false,
    }
}

/// wyhash's multiply-fold: the 128-bit product's halves XORed, so every input bit reaches the
/// high bits, which pick the home slot and the tag in [`StateTable`].
#[inline(always)]
fn fold_mul(a: u64, b: u64) -> u64 {
    let r = u128::from(a) * u128::from(b);
    (r as u64) ^ ((r >> 64) as u64)
}

/// The hash contribution of value `x` at position `i` (a word or a place). The seed depends on
/// the position, so equal values at different positions do not cancel in the XOR.
#[inline(always)]
fn mix(i: usize, x: u64) -> u64 {
    let seed = (i as u64)
        .wrapping_add(1)
        .wrapping_mul(0x9E37_79B9_7F4A_7C15);
    fold_mul(x ^ seed, 0xA076_1D64_78BD_642F)
}

/// Equality of two markings without a `memcmp` call: a branch-free fold the compiler unrolls
/// when the length is a constant. Most comparisons are of equal markings (a successor already
/// stored), so an early exit would not save anything.
#[inline(always)]
fn words_eq(a: &[u64], b: &[u64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0, |acc, (x, y)| acc | (x ^ y)) == 0
}

#[inline(always)]
fn hash_words(words: &[u64]) -> u64 {
    words.iter().enumerate().fold(0, |h, (i, &x)| h ^ mix(i, x))
}

fn oom(states: usize, store_bytes: usize) -> ExploreError {
    ExploreError::OutOfMemory {
        states_so_far: states as u64,
        store_bytes: store_bytes as u64,
    }
}

/// The set of stored markings: an open-addressing table of state positions, linear probing.
///
/// Each slot is one `u64`: the top 32 bits of the marking's hash (the tag) above the state's
/// position plus one (0 marks an empty slot). A marking's home slot is given by the top bits of
/// its hash, so the tag alone says where an entry goes in a table twice as large: growing never
/// reads the markings again. The tag also filters nearly every probe that is not a match, so the
/// arena is read (one cache miss) only for the marking that is almost surely the one sought.
/// 8 bytes a slot, at most half full (short probes matter more than the bytes): 16 to 32
/// bytes per state.
struct StateTable {
    slots: Vec<u64>,
    /// `slots.len() == 1 << bits`, `bits <= 32` (the tag's width bounds the home index).
    bits: u32,
    len: usize,
}

impl StateTable {
    const FIRST_BITS: u32 = 10;

    fn new() -> Result<Self, ()> {
        Ok(StateTable {
            slots: zeroed(1 << Self::FIRST_BITS)?,
            bits: Self::FIRST_BITS,
            len: 0,
        })
    }

    #[inline(always)]
    fn home(&self, hash: u64) -> usize {
        (hash >> (64 - self.bits)) as usize
    }

    /// The stored state whose marking `eq` accepts among those with this hash, or the empty
    /// slot where it belongs.
    #[inline(always)]
    fn find(&self, hash: u64, mut eq: impl FnMut(u32) -> bool) -> Result<u32, usize> {
        let tag = hash >> 32;
        let mask = self.slots.len() - 1;
        let mut pos = self.home(hash);
        // The table is never full (`grow` keeps half of it free), so the probe ends.
        loop {
            let e = self.slots[pos];
            if e == 0 {
                return Err(pos);
            }
            if e >> 32 == tag {
                let j = (e as u32).wrapping_sub(1);
                if eq(j) {
                    return Ok(j);
                }
            }
            pos = (pos + 1) & mask;
        }
    }

    /// Stores state `state` in the empty slot `slot` that `find` returned.
    #[inline(always)]
    fn insert_at(&mut self, slot: usize, hash: u64, state: u32) {
        if let Some(e) = self.slots.get_mut(slot) {
            *e = (hash >> 32) << 32 | (u64::from(state) + 1);
            self.len += 1;
        }
    }

    /// True when the next insertion must wait for `grow`.
    #[inline(always)]
    fn full(&self) -> bool {
        self.len * 2 >= self.slots.len()
    }

    /// Brings into cache the home slot of each hash and the first word of the marking it
    /// names, without acting on them. The loads are independent and branch-free, so the
    /// processor overlaps their cache misses; the real lookups that follow then hit the cache.
    /// (Prefetch instructions would say this more directly but need `unsafe`.)
    #[inline(always)]
    fn touch<T: Copy + Default + Into<u64>>(&self, hashes: &[u64], arena: &[T], stride: usize) {
        let mut sink = 0u64;
        for &h in hashes {
            let e = self.slots[self.home(h)];
            let j = if e >> 32 == h >> 32 {
                (e as u32).wrapping_sub(1) as usize
            } else {
                0
            };
            sink ^= arena
                .get(j.wrapping_mul(stride))
                .copied()
                .unwrap_or_default()
                .into();
        }
        std::hint::black_box(sink);
    }

    /// Doubles the table, placing each entry by its tag.
    fn grow(&mut self) -> Result<(), ()> {
        let bits = self.bits + 1;
        if bits > 32 || bits >= usize::BITS {
            // 2^32 slots would hold more states than `u32` positions name; unreachable
            // because the state limit stops first, but refuse rather than misplace entries.
            return Err(());
        }
        let mut slots = zeroed(1usize << bits)?;
        let mask = slots.len() - 1;
        for &e in &self.slots {
            if e != 0 {
                let mut pos = ((e >> 32) >> (32 - bits)) as usize;
                while slots[pos] != 0 {
                    pos = (pos + 1) & mask;
                }
                slots[pos] = e;
            }
        }
        self.slots = slots;
        self.bits = bits;
        Ok(())
    }

    fn bytes(&self) -> usize {
        self.slots.capacity() * 8
    }
}

/// `len` zeros, or the allocation failure instead of an abort.
fn zeroed(len: usize) -> Result<Vec<u64>, ()> {
    let mut v = Vec::new();
    v.try_reserve_exact(len).map_err(|_| ())?;
    v.resize(len, 0);
    Ok(v)
}

/// The positions on the breadth-first tree from the root to `state`, both included.
fn tree_path(parents: &[u32], state: usize) -> Vec<usize> {
    let mut path = vec![state];
    let mut s = state;
    // Parents always precede their children, so this walk ends at the root (state 0).
    while s != 0 {
        match parents.get(s) {
            Some(&p) if (p as usize) < s => s = p as usize,
            _ => break,
        }
        path.push(s);
    }
    path.reverse();
    path
}

// ---------------------------------------------------------------------------------------------
// Bits: safe nets with unit weights
// ---------------------------------------------------------------------------------------------

/// One word of a marking that a transition reads or writes.
#[derive(Clone, Copy, Debug)]
struct Touch {
    word: u32,
    /// Input places in this word: all must be marked, all are emptied.
    pre: u64,
    /// Output places in this word: all are marked after the firing.
    post: u64,
}

/// A safe unit-weight net compiled to word operations.
struct BitNet {
    words: usize,
    initial: Vec<u64>,
    /// `touches[touch_start[t]..touch_start[t + 1]]`: the words transition `t` touches.
    touch_start: Vec<u32>,
    touches: Vec<Touch>,
    /// `index[index_start[p]..index_start[p + 1]]`: the transitions to test when place `p` is
    /// marked. Each transition with inputs sits under exactly one of its input places.
    index_start: Vec<u32>,
    index: Vec<u32>,
    /// Transitions without input places: enabled in every marking.
    sources: Vec<u32>,
}

impl BitNet {
    fn new(c: &Compiled) -> Self {
        let words = c.places.div_ceil(64).max(1);
        let mut initial = vec![0u64; words];
        for (p, &m) in c.initial.iter().enumerate() {
            if m > 0 {
                initial[p / 64] |= 1 << (p % 64);
            }
        }
        let mut touch_start = Vec::with_capacity(c.transitions + 1);
        let mut touches: Vec<Touch> = Vec::new();
        let mut sources = Vec::new();
        touch_start.push(0);
        for t in 0..c.transitions {
            let first = touches.len();
            let mut add = |p: usize, is_pre: bool| {
                let word = (p / 64) as u32;
                let bit = 1u64 << (p % 64);
                let i = match touches[first..].iter().position(|x| x.word == word) {
                    Some(i) => first + i,
                    None => {
                        touches.push(Touch {
                            word,
                            pre: 0,
                            post: 0,
                        });
                        touches.len() - 1
                    }
                };
                if is_pre {
                    touches[i].pre |= bit;
                } else {
                    touches[i].post |= bit;
                }
            };
            for &(p, _) in c.pre(t) {
                add(p, true);
            }
            for &(p, _) in c.post(t) {
                add(p, false);
            }
            if c.pre(t).is_empty() {
                sources.push(t as u32);
            }
            touch_start.push(touches.len() as u32);
        }
        let mut net = BitNet {
            words,
            initial,
            touch_start,
            touches,
            index_start: Vec::new(),
            index: Vec::new(),
            sources,
        };
        // Before any state is seen, guess: places marked initially often stay marked (free
        // resources, idle processes), so prefer an input place that starts empty.
        let guess: Vec<u64> = (0..c.places)
            .map(|p| u64::from(net.initial[p / 64] >> (p % 64) & 1 == 1))
            .collect();
        net.build_index(c.places, &guess);
        net
    }

    fn touches(&self, t: usize) -> &[Touch] {
        &self.touches[self.touch_start[t] as usize..self.touch_start[t + 1] as usize]
    }

    /// Indexes every transition with inputs under its input place with the lowest `freq` (how
    /// often the place was seen marked), so it is tested in as few markings as possible.
    fn build_index(&mut self, places: usize, freq: &[u64]) {
        let transitions = self.touch_start.len() - 1;
        let mut chosen: Vec<Option<usize>> = vec![None; transitions];
        let mut counts = vec![0u32; places + 1];
        for (t, slot) in chosen.iter_mut().enumerate() {
            let mut best: Option<(u64, usize)> = None;
            for tc in self.touches(t) {
                let mut m = tc.pre;
                while m != 0 {
                    let p = tc.word as usize * 64 + m.trailing_zeros() as usize;
                    m &= m - 1;
                    let f = freq.get(p).copied().unwrap_or(0);
                    if best.is_none_or(|(bf, _)| f < bf) {
                        best = Some((f, p));
                    }
                }
            }
            if let Some((_, p)) = best {
                *slot = Some(p);
                counts[p] += 1;
            }
        }
        let mut start = Vec::with_capacity(places + 1);
        let mut acc = 0u32;
        for &n in &counts[..places] {
            start.push(acc);
            acc += n;
        }
        start.push(acc);
        let mut fill = start.clone();
        let mut index = vec![0u32; acc as usize];
        for (t, p) in chosen.iter().enumerate() {
            if let Some(p) = *p {
                index[fill[p] as usize] = t as u32;
                fill[p] += 1;
            }
        }
        self.index_start = start;
        self.index = index;
    }

    /// The transitions indexed under place `p`.
    #[inline(always)]
    fn indexed(&self, p: usize) -> &[u32] {
        match (self.index_start.get(p), self.index_start.get(p + 1)) {
            (Some(&a), Some(&b)) => &self.index[a as usize..b as usize],
            _ => &[],
        }
    }
}

#[inline(always)]
fn bits_enabled(touches: &[Touch], cur: &[u64]) -> bool {
    touches.iter().all(|tc| {
        cur.get(tc.word as usize)
            .is_some_and(|&w| w & tc.pre == tc.pre)
    })
}

/// Fires an enabled transition from `cur` into `next`. Returns the change to the marking's hash,
/// or the first output place that already holds a token (the net is not safe).
#[inline(always)]
fn bits_fire(touches: &[Touch], cur: &[u64], next: &mut [u64]) -> Result<u64, usize> {
    next.copy_from_slice(cur);
    let mut delta = 0;
    for tc in touches {
        let wi = tc.word as usize;
        let (Some(&old), Some(slot)) = (cur.get(wi), next.get_mut(wi)) else {
            continue;
        };
        let rest = old & !tc.pre;
        let clash = rest & tc.post;
        if clash != 0 {
            return Err(wi * 64 + clash.trailing_zeros() as usize);
        }
        let new = rest | tc.post;
        *slot = new;
        delta ^= mix(wi, old) ^ mix(wi, new);
    }
    Ok(delta)
}

/// The shortest firing sequence to `target`, each transition found again by firing the parent's
/// transitions.
fn bits_trace(
    c: &Compiled,
    bn: &BitNet,
    arena: &[u64],
    w: usize,
    parents: &[u32],
    target: usize,
) -> Option<Trace> {
    let state = |s: usize| arena.get(s * w..(s + 1) * w);
    let mut next = vec![0u64; w];
    let path = tree_path(parents, target);
    let mut transitions = Vec::with_capacity(path.len());
    for pair in path.windows(2) {
        let (a, b) = (state(pair[0])?, state(pair[1])?);
        let t = (0..c.transitions).find(|&t| {
            let tc = bn.touches(t);
            bits_enabled(tc, a) && bits_fire(tc, a, &mut next).is_ok() && next[..] == *b
        })?;
        transitions.push(t);
    }
    Some(Trace { transitions })
}

/// Explores with one bit per place. `N` is the number of words when it is known at compile time
/// (1 to 8: most nets), so copies, compares and hashes unroll; 0 means `bn.words`.
///
/// Returns `None` when a firing would put a second token in a place: the caller starts again
/// with counts.
fn run_bits<const N: usize>(
    c: &Compiled,
    bn: &mut BitNet,
    ctl: &mut Ctl,
) -> Result<Option<PtReport>, ExploreError> {
    let w = if N > 0 { N } else { bn.words };
    let mut arena: Vec<u64> = Vec::new();
    let mut parents: Vec<u32> = Vec::new();
    let mut table = StateTable::new().map_err(|_| oom(0, 0))?;
    let store_bytes = |arena: &Vec<u64>, parents: &Vec<u32>, table: &StateTable| {
        arena.capacity() * 8 + parents.capacity() * 4 + table.bytes()
    };

    let init = bn.initial.clone();
    if ctl.limit == 0 {
        return Err(ctl.too_many(0));
    }
    arena.try_reserve(w).map_err(|_| oom(0, 0))?;
    arena.extend_from_slice(&init[..w]);
    if ctl.keep_traces {
        parents.push(0);
    }
    let h0 = hash_words(&init[..w]);
    if let Err(slot) = table.find(h0, |_| false) {
        table.insert_at(slot, h0, 0);
    }

    let mut cur = vec![0u64; w];
    let mut succ: Vec<u64> = Vec::new();
    let mut hashes: Vec<u64> = Vec::new();
    let mut enabled: Vec<u32> = Vec::new();
    let (mut n, mut i) = (1usize, 0usize);
    let mut edges = 0u64;
    let mut dead = 0u64;
    let mut first_dead: Option<usize> = None;
    let mut max_total = 0u64;
    let mut reindexed = false;
    let mut stubborn = ctl.deadlocks_only.then(|| Stubborn::new(c));

    while i < n {
        if !reindexed && n >= INDEX_SAMPLE {
            // The first states show which places are rarely marked: index by those.
            reindexed = true;
            let mut freq = vec![0u64; c.places];
            for s in arena.chunks_exact(w) {
                for (wi, &word) in s.iter().enumerate() {
                    let mut m = word;
                    while m != 0 {
                        let p = wi * 64 + m.trailing_zeros() as usize;
                        m &= m - 1;
                        if let Some(f) = freq.get_mut(p) {
                            *f += 1;
                        }
                    }
                }
            }
            bn.build_index(c.places, &freq);
        }
        // Slicing to `w` everywhere lets the compiler see the constant length (N > 0).
        let cur = &mut cur[..w];
        cur.copy_from_slice(&arena[i * w..][..w]);
        let cur = &*cur;
        let h = hash_words(cur);
        let total: u64 = cur.iter().map(|x| u64::from(x.count_ones())).sum();
        max_total = max_total.max(total);

        enabled.clear();
        for (wi, &word) in cur.iter().enumerate() {
            let mut m = word;
            while m != 0 {
                let p = wi * 64 + m.trailing_zeros() as usize;
                m &= m - 1;
                for &t in bn.indexed(p) {
                    if bits_enabled(bn.touches(t as usize), cur) {
                        enabled.push(t);
                    }
                }
            }
        }
        // Sources need no token: always enabled.
        enabled.extend_from_slice(&bn.sources);
        if enabled.is_empty() {
            dead += 1;
            first_dead.get_or_insert(i);
        }
        if let Some(sb) = stubborn.as_mut() {
            sb.reduce(c, &mut enabled, |p| {
                cur.get(p / 64).map_or(0, |&word| word >> (p % 64) & 1)
            });
        }
        edges += enabled.len() as u64;

        // All successors first, then their lookups: see `StateTable::touch`.
        succ.clear();
        succ.resize(enabled.len() * w, 0);
        hashes.clear();
        for (&t, next) in enabled.iter().zip(succ.chunks_exact_mut(w)) {
            match bits_fire(bn.touches(t as usize), cur, &mut next[..w]) {
                Ok(delta) => hashes.push(h ^ delta),
                Err(_) => return Ok(None),
            }
        }
        table.touch(&hashes, &arena, w);
        for (&hn, next) in hashes.iter().zip(succ.chunks_exact(w)) {
            let next = &next[..w];
            let slot = match table.find(hn, |j| words_eq(&arena[j as usize * w..][..w], next)) {
                Ok(_) => continue,
                Err(slot) => slot,
            };
            if n as u64 >= ctl.limit {
                return Err(ctl.too_many(n));
            }
            if arena.try_reserve(w).is_err() || (ctl.keep_traces && parents.try_reserve(1).is_err())
            {
                return Err(oom(n, store_bytes(&arena, &parents, &table)));
            }
            table.insert_at(slot, hn, n as u32);
            arena.extend_from_slice(next);
            if ctl.keep_traces {
                parents.push(i as u32);
            }
            n += 1;
            if table.full() && table.grow().is_err() {
                return Err(oom(n, store_bytes(&arena, &parents, &table)));
            }
        }
        i += 1;
        ctl.tick(n, i, edges);
    }

    let first_deadlock = match (ctl.keep_traces, first_dead) {
        (true, Some(s)) => bits_trace(c, bn, &arena, w, &parents, s),
        _ => None,
    };
    Ok(Some(PtReport {
        states: n as u64,
        edges,
        max_tokens_in_place: u64::from(max_total > 0),
        max_tokens_per_marking: max_total,
        safe: true,
        deadlock: dead > 0,
        dead_markings: dead,
        first_deadlock,
        first_unsafe: None,
        seconds: 0.0,
        store_bytes: store_bytes(&arena, &parents, &table) as u64,
        representation: Representation::Bits,
        reduced: stubborn.is_some(),
    }))
}

// ---------------------------------------------------------------------------------------------
// Counts: any net
// ---------------------------------------------------------------------------------------------

/// A token count stored per place.
trait Count: Copy + Eq + Default + Into<u64> + TryFrom<u64> + 'static {
    const BITS: u32;
}

impl Count for u8 {
    const BITS: u32 = 8;
}
impl Count for u16 {
    const BITS: u32 = 16;
}
impl Count for u32 {
    const BITS: u32 = 32;
}
impl Count for u64 {
    const BITS: u32 = 64;
}

#[inline(always)]
fn hash_counts<C: Count>(m: &[C]) -> u64 {
    m.iter()
        .enumerate()
        .fold(0, |h, (p, &x)| h ^ mix(p, x.into()))
}

/// A net compiled for counts.
struct CountNet {
    /// `(place, weight)` inputs per transition, as in [`Compiled`].
    pre_start: Vec<usize>,
    pre: Vec<(usize, u64)>,
    /// `(place, taken, produced)` per transition: every place a firing changes or tests.
    effect_start: Vec<usize>,
    effects: Vec<(usize, u64, u64)>,
    /// As in [`BitNet`]: transitions to test when a place is marked, and sources.
    index_start: Vec<usize>,
    index: Vec<u32>,
    sources: Vec<u32>,
}

impl CountNet {
    fn new(c: &Compiled) -> Self {
        let mut effect_start = vec![0];
        let mut effects = Vec::new();
        let mut by_place: Vec<Vec<u32>> = vec![Vec::new(); c.places];
        let mut sources = Vec::new();
        for t in 0..c.transitions {
            let mut e: Vec<(usize, u64, u64)> = c.pre(t).iter().map(|&(p, w)| (p, w, 0)).collect();
            for &(p, w) in c.post(t) {
                match e.iter_mut().find(|x| x.0 == p) {
                    Some(x) => x.2 = w,
                    None => e.push((p, 0, w)),
                }
            }
            effects.extend(e);
            effect_start.push(effects.len());
            // Index by the input place needing the most tokens: the rarest to be enabling.
            match c.pre(t).iter().max_by_key(|&&(_, w)| w) {
                Some(&(p, _)) => by_place[p].push(t as u32),
                None => sources.push(t as u32),
            }
        }
        let mut index_start = vec![0];
        let mut index = Vec::new();
        for l in by_place {
            index.extend(l);
            index_start.push(index.len());
        }
        CountNet {
            pre_start: c.pre_start.clone(),
            pre: c.pre.clone(),
            effect_start,
            effects,
            index_start,
            index,
            sources,
        }
    }

    fn pre(&self, t: usize) -> &[(usize, u64)] {
        &self.pre[self.pre_start[t]..self.pre_start[t + 1]]
    }

    fn effects(&self, t: usize) -> &[(usize, u64, u64)] {
        &self.effects[self.effect_start[t]..self.effect_start[t + 1]]
    }

    fn enabled<C: Count>(&self, t: usize, cur: &[C]) -> bool {
        self.pre(t)
            .iter()
            .all(|&(p, w)| cur.get(p).is_some_and(|&x| x.into() >= w))
    }

    /// Fires an enabled transition from `cur` into `next`. Returns the hash change, or the place
    /// whose count no longer fits in `C`.
    #[inline]
    fn fire<C: Count>(&self, t: usize, cur: &[C], next: &mut [C]) -> Result<u64, usize> {
        next.copy_from_slice(cur);
        let mut delta = 0;
        for &(p, take, put) in self.effects(t) {
            let (Some(&old), Some(slot)) = (cur.get(p), next.get_mut(p)) else {
                continue;
            };
            let old: u64 = old.into();
            let new = old
                .checked_sub(take)
                .and_then(|v| v.checked_add(put))
                .and_then(|v| C::try_from(v).ok());
            match new {
                Some(v) => {
                    *slot = v;
                    delta ^= mix(p, old) ^ mix(p, v.into());
                }
                None => return Err(p),
            }
        }
        Ok(delta)
    }

    /// The marking after firing `t` from `cur`, in 64 bits saturated: the overflowing successor
    /// that `fire` could not store, for the covering check. Saturation only lowers counts, so a
    /// covering found on it holds for the real marking.
    fn fire_wide<C: Count>(&self, t: usize, cur: &[C]) -> Vec<u64> {
        let mut m: Vec<u64> = cur.iter().map(|&x| x.into()).collect();
        for &(p, take, put) in self.effects(t) {
            if let Some(x) = m.get_mut(p) {
                *x = x.saturating_sub(take).saturating_add(put);
            }
        }
        m
    }
}

/// Looks for an ancestor of `candidate` on the breadth-first tree, starting at `from`, that
/// `candidate` strictly covers. Returns it and a place where `candidate` has more tokens. Stops
/// early (finding nothing, which is always sound) once `budget` place comparisons are spent.
fn covered_ancestor<C: Count>(
    arena: &[C],
    stride: usize,
    parents: &[u32],
    candidate: &[u64],
    from: usize,
    budget: &mut u64,
) -> Option<(usize, usize)> {
    let mut s = from;
    loop {
        if *budget < stride as u64 {
            return None;
        }
        *budget -= stride as u64;
        let a = arena.get(s * stride..(s + 1) * stride)?;
        let mut greater = None;
        let covers = a.iter().zip(candidate).enumerate().all(|(p, (&x, &y))| {
            let x: u64 = x.into();
            if y > x && greater.is_none() {
                greater = Some(p);
            }
            y >= x
        });
        if let (true, Some(p)) = (covers, greater) {
            return Some((s, p));
        }
        if s == 0 {
            return None;
        }
        match parents.get(s) {
            Some(&p) if (p as usize) < s => s = p as usize,
            _ => return None,
        }
    }
}

/// Explores with one `C` per place. Returns `None` when a count no longer fits in `C` (and no
/// covering proves the net unbounded): the caller widens and starts again.
fn run_counts<C: Count>(c: &Compiled, ctl: &mut Ctl) -> Result<Option<PtReport>, ExploreError> {
    let cn = CountNet::new(c);
    let stride = c.places.max(1);
    let mut arena: Vec<C> = Vec::new();
    let mut parents: Vec<u32> = Vec::new();
    let mut table = StateTable::new().map_err(|_| oom(0, 0))?;
    let size = std::mem::size_of::<C>();
    let store_bytes = |arena: &Vec<C>, parents: &Vec<u32>, table: &StateTable| {
        arena.capacity() * size + parents.capacity() * 4 + table.bytes()
    };

    let mut init = vec![C::default(); stride];
    for (p, &m) in c.initial.iter().enumerate() {
        match C::try_from(m) {
            Ok(v) => init[p] = v,
            // The caller picked a width that holds the initial marking; be total anyway.
            Err(_) => return Ok(None),
        }
    }
    if ctl.limit == 0 {
        return Err(ctl.too_many(0));
    }
    arena.try_reserve(stride).map_err(|_| oom(0, 0))?;
    arena.extend_from_slice(&init);
    parents.push(0);
    let h0 = hash_counts(&init);
    if let Err(slot) = table.find(h0, |_| false) {
        table.insert_at(slot, h0, 0);
    }

    // Bounds and the first unsafe marking are measured as states are stored.
    let mut max_place = 0u64;
    let mut max_total = 0u64;
    let mut first_unsafe: Option<(usize, usize, u64)> = None;
    let mut measure = |s: usize, m: &[C]| -> u64 {
        let mut total = 0u64;
        for (p, &x) in m.iter().enumerate() {
            let x: u64 = x.into();
            total = total.saturating_add(x);
            max_place = max_place.max(x);
            if x > 1 && first_unsafe.is_none() {
                first_unsafe = Some((s, p, x));
            }
        }
        max_total = max_total.max(total);
        total
    };
    let mut record = measure(0, &init);
    // Covering checks on new token records are rationed to a few times the work of storing
    // states, so bounded nets with many tokens do not pay much for them.
    let mut budget: u64 = 1 << 22;

    let mut cur = vec![C::default(); stride];
    let mut next = vec![C::default(); stride];
    let mut enabled: Vec<u32> = Vec::new();
    let (mut n, mut i) = (1usize, 0usize);
    let mut edges = 0u64;
    let mut dead = 0u64;
    let mut first_dead: Option<usize> = None;
    let mut stubborn = ctl.deadlocks_only.then(|| Stubborn::new(c));

    while i < n {
        cur.copy_from_slice(&arena[i * stride..][..stride]);
        let h = hash_counts(&cur);
        enabled.clear();
        for (p, &x) in cur.iter().enumerate() {
            if x == C::default() {
                continue;
            }
            if let (Some(&a), Some(&b)) = (cn.index_start.get(p), cn.index_start.get(p + 1)) {
                for &t in &cn.index[a..b] {
                    if cn.enabled(t as usize, &cur) {
                        enabled.push(t);
                    }
                }
            }
        }
        enabled.extend_from_slice(&cn.sources);
        if enabled.is_empty() {
            dead += 1;
            first_dead.get_or_insert(i);
        }
        if let Some(sb) = stubborn.as_mut() {
            sb.reduce(c, &mut enabled, |p| cur.get(p).map_or(0, |&x| x.into()));
        }
        edges += enabled.len() as u64;

        for &t in &enabled {
            let t = t as usize;
            let delta = match cn.fire(t, &cur, &mut next) {
                Ok(d) => d,
                Err(place) => {
                    // A count outgrew `C`: either the net is unbounded (and a covering shows
                    // it), or it needs wider counts.
                    let wide = cn.fire_wide(t, &cur);
                    let mut all = u64::MAX;
                    if let Some((a, p)) =
                        covered_ancestor(&arena, stride, &parents, &wide, i, &mut all)
                    {
                        return Err(unbounded(
                            &cn,
                            &arena,
                            stride,
                            &parents,
                            a,
                            i,
                            Some(t),
                            p,
                            n,
                        ));
                    }
                    if C::BITS == 64 {
                        return Err(ExploreError::TokenOverflow {
                            place,
                            states_so_far: n as u64,
                        });
                    }
                    return Ok(None);
                }
            };
            let hn = h ^ delta;
            let slot = match table.find(hn, |j| arena[j as usize * stride..][..stride] == next[..])
            {
                Ok(_) => continue,
                Err(slot) => slot,
            };
            if n as u64 >= ctl.limit {
                return Err(ctl.too_many(n));
            }
            if arena.try_reserve(stride).is_err() || parents.try_reserve(1).is_err() {
                return Err(oom(n, store_bytes(&arena, &parents, &table)));
            }
            table.insert_at(slot, hn, n as u32);
            arena.extend_from_slice(&next);
            parents.push(i as u32);
            let s = n;
            n += 1;
            if table.full() && table.grow().is_err() {
                return Err(oom(n, store_bytes(&arena, &parents, &table)));
            }
            let total = measure(s, &next);
            if total > record {
                record = total;
                budget = budget.saturating_add(8 * stride as u64);
                let wide: Vec<u64> = next.iter().map(|&x| x.into()).collect();
                if let Some((a, p)) =
                    covered_ancestor(&arena, stride, &parents, &wide, i, &mut budget)
                {
                    return Err(unbounded(&cn, &arena, stride, &parents, a, s, None, p, n));
                }
            }
        }
        // Earn covering budget with ordinary work.
        budget = budget.saturating_add(stride as u64);
        i += 1;
        ctl.tick(n, i, edges);
    }

    let trace = |target: usize| -> Option<Trace> {
        if !ctl.keep_traces {
            return None;
        }
        count_trace(&cn, &arena, stride, &parents, 0, target)
            .map(|transitions| Trace { transitions })
    };
    let first_deadlock = first_dead.and_then(trace);
    let first_unsafe = first_unsafe.map(|(s, place, tokens)| UnsafeWitness {
        place,
        tokens,
        trace: trace(s),
    });
    Ok(Some(PtReport {
        states: n as u64,
        edges,
        max_tokens_in_place: max_place,
        max_tokens_per_marking: max_total,
        safe: max_place <= 1,
        deadlock: dead > 0,
        dead_markings: dead,
        first_deadlock,
        first_unsafe,
        seconds: 0.0,
        store_bytes: store_bytes(&arena, &parents, &table) as u64,
        representation: Representation::Counts { bits: C::BITS },
        reduced: stubborn.is_some(),
    }))
}

/// The transitions along the breadth-first tree from state `from` down to its descendant `to`,
/// each found again by firing the parent's transitions.
fn count_trace<C: Count>(
    cn: &CountNet,
    arena: &[C],
    stride: usize,
    parents: &[u32],
    from: usize,
    to: usize,
) -> Option<Vec<usize>> {
    let path = tree_path(parents, to);
    let at = path.iter().position(|&s| s == from)?;
    let state = |s: usize| arena.get(s * stride..(s + 1) * stride);
    let mut next = vec![C::default(); stride];
    let transitions = cn.effect_start.len().saturating_sub(1);
    let mut out = Vec::with_capacity(path.len());
    for pair in path[at..].windows(2) {
        let (a, b) = (state(pair[0])?, state(pair[1])?);
        let t = (0..transitions)
            .find(|&t| cn.enabled(t, a) && cn.fire(t, a, &mut next).is_ok() && next[..] == *b)?;
        out.push(t);
    }
    Some(out)
}

/// The unboundedness error: `ancestor` is strictly covered by the marking reached from `end`
/// (by firing `last` from it, when the covering marking could not be stored).
#[allow(clippy::too_many_arguments)]
fn unbounded<C: Count>(
    cn: &CountNet,
    arena: &[C],
    stride: usize,
    parents: &[u32],
    ancestor: usize,
    end: usize,
    last: Option<usize>,
    place: usize,
    states: usize,
) -> ExploreError {
    let prefix = count_trace(cn, arena, stride, parents, 0, ancestor).unwrap_or_default();
    let mut pump = count_trace(cn, arena, stride, parents, ancestor, end).unwrap_or_default();
    pump.extend(last);
    ExploreError::Unbounded(Box::new(UnboundedWitness {
        place,
        prefix: Trace {
            transitions: prefix,
        },
        pump: Trace { transitions: pump },
        states_so_far: states as u64,
    }))
}
