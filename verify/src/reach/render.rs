//! The P/T explorer's reports and errors as text for people and as JSON for tools, each node
//! named by its id (and its name when it has one), each trace by its transitions.

use super::{ExploreError, PtReport, Representation, Trace};
use petrel_diag::plural::count;
use petrel_nets::pt::{PtNet, PtNode};
use std::fmt::Write as _;

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
