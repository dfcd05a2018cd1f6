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
//! deduplicates (`table`). A `u32` parent per state gives the shortest traces; the
//! transition of each step is found again at the end by trying the transitions of the parent, so
//! no transition id is stored. This loop is written once (`search`), generic over how a marking
//! is stored.
//!
//! Two representations, the cheap one first:
//!
//! - **Bits** (`bits`), when every arc weight is 1 and the initial marking is safe: one bit
//!   per place, `ceil(places / 64)` words per state (24 bytes for 160 places). The first firing
//!   that would put a second token in a place proves the net unsafe: the run stops and starts
//!   again with counts.
//! - **Counts** (`counts`), for weighted or unsafe nets: one unsigned integer per place, 8
//!   bits first. A count that no longer fits restarts the run with 16, then 32, then 64 bits.
//!
//! The hash of a marking is the XOR of one multiply-fold hash per word (or per place), so a
//! successor's hash is the parent's corrected for the few words the transition touches, rather
//! than a pass over the whole marking.
//!
//! An unbounded net has no finite graph: the counts catch it by a marking that strictly covers
//! one of its ancestors (`counts`). Otherwise `max_states`, the `u32` store limit, or a 64-bit
//! token overflow stop it with a clear error.
//!
//! Files: `arcs` (the net reduced to what firing needs), `search` (the one exploration),
//! `bits`, `counts`, `table` (the set of markings, hashing), `stubborn` (the stubborn
//! sets of `--deadlocks`), `render` (text and JSON).

#![forbid(unsafe_code)]
#![deny(missing_docs)]

mod arcs;
mod bits;
mod counts;
mod render;
mod search;
mod stubborn;
mod table;

pub use render::{error_to_json, render_error, render_human, to_json};

use arcs::Arcs;
use bits::{BitNet, Bits};
use counts::Counts;
use petrel_nets::pt::PtNet;
use search::{search, Ctl, MAX_STORE_STATES};
use std::fmt;
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
    /// possible for a [`PtNet`] built by hand, since [`petrel_nets::pnml::parse_pnml`] builds none.
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
    let arcs = Arcs::new(net)?;
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
    let max_initial = arcs.initial.iter().copied().max().unwrap_or(0);
    let unit = arcs.pre.iter().chain(&arcs.post).all(|&(_, w)| w <= 1);
    let mut report = None;
    if unit && max_initial <= 1 {
        let net = BitNet::new(&arcs);
        let places = arcs.places;
        report = match net.words {
            1 => search(&arcs, &mut Bits::<1>::new(net, places), &mut ctl)?,
            2 => search(&arcs, &mut Bits::<2>::new(net, places), &mut ctl)?,
            3 => search(&arcs, &mut Bits::<3>::new(net, places), &mut ctl)?,
            4 => search(&arcs, &mut Bits::<4>::new(net, places), &mut ctl)?,
            5 => search(&arcs, &mut Bits::<5>::new(net, places), &mut ctl)?,
            6 => search(&arcs, &mut Bits::<6>::new(net, places), &mut ctl)?,
            7 => search(&arcs, &mut Bits::<7>::new(net, places), &mut ctl)?,
            8 => search(&arcs, &mut Bits::<8>::new(net, places), &mut ctl)?,
            _ => search(&arcs, &mut Bits::<0>::new(net, places), &mut ctl)?,
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
            8 => search(&arcs, &mut Counts::<u8>::new(&arcs), &mut ctl)?,
            16 => search(&arcs, &mut Counts::<u16>::new(&arcs), &mut ctl)?,
            32 => search(&arcs, &mut Counts::<u32>::new(&arcs), &mut ctl)?,
            _ => search(&arcs, &mut Counts::<u64>::new(&arcs), &mut ctl)?,
        };
        match outcome {
            Some(r) => report = Some(r),
            None if bits < 64 => bits *= 2,
            // Counts of 64 bits report their overflow themselves; this arm only keeps the loop
            // total.
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
