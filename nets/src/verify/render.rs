//! The report for people ([`render_human`], grouped; [`render_human_all`], every finding), for
//! tools ([`to_json`]), and as diagnostics on the project's text ([`diagnostics`], what
//! `petrel check` and `petrel verify` print with file, line and caret).

use super::{Report, Trace};
use crate::plural::count;
use std::fmt::Write as _;

/// How many findings of one kind the grouped report shows before "and N more".
const SHOWN: usize = 3;

fn trace_text(t: &Trace) -> String {
    if t.is_empty() {
        "at start".to_string()
    } else {
        format!("after {}", t.join(" → "))
    }
}

/// What a cascade finding says (E0608): the loop's turn, or the events that reach the bound.
fn cascade_text(c: &super::CascadeFinding, bound: u32) -> String {
    if c.endless {
        format!(
            "events produced at one instant loop for ever: {} → {} → ... (each turn fires {})",
            c.events.join(" → "),
            c.events.first().map_or("", String::as_str),
            c.transitions.join(", ")
        )
    } else {
        format!(
            "events produced at one instant do not settle: the cascade of {} takes {} steps with events still queued (it fires {})",
            c.events.join(", "),
            bound,
            c.transitions.join(", ")
        )
    }
}

fn marking_text(m: &[String]) -> String {
    if m.is_empty() {
        "nothing marked".to_string()
    } else {
        m.join(" ")
    }
}

/// The report for people, on its own: a summary with every error and warning on one line, and
/// the expected findings grouped with counts (the details are in [`render_human_all`] and
/// [`to_json`]).
pub fn render_human(project_name: &str, r: &Report) -> String {
    render(project_name, r, false, true)
}

/// [`render_human`] with every finding listed (intended ends, loops, conflicts).
pub fn render_human_all(project_name: &str, r: &Report) -> String {
    render(project_name, r, true, true)
}

/// The summary `petrel verify` prints after the findings' diagnostics ([`diagnostics`]): the
/// counts of each kind, errors and warnings named by their code rather than repeated, and the
/// expected findings grouped (every one with `all`).
pub fn render_summary(project_name: &str, r: &Report, all: bool) -> String {
    render(project_name, r, all, false)
}

fn render(project_name: &str, r: &Report, all: bool, details: bool) -> String {
    let mut o = String::new();
    let limit = |n: usize| if all { n } else { n.min(SHOWN) };
    let more = |o: &mut String, n: usize, what: &str| {
        if !all && n > SHOWN {
            let _ = writeln!(o, "  ... and {} more {what} (--all lists them)", n - SHOWN);
        }
    };
    // An error or warning: its line in the stand-alone report, its code in the summary.
    let item = |o: &mut String, code: &str, severity: &str, text: String| {
        if details {
            let _ = writeln!(o, "  {severity}: {text}");
        } else {
            let _ = writeln!(o, "  {severity}[{code}]: {text}");
        }
    };
    let _ = writeln!(
        o,
        "verified `{project_name}`: {}, {}, {:.3} s",
        count(r.states, "stable state"),
        count(r.edges, "event delivery"),
        r.seconds
    );
    if r.timed {
        let _ = writeln!(
            o,
            "timed: timers expire in the order their durations impose (a zone over their clocks beside each state; no partial-order reduction; traces kept whole)"
        );
    }
    if r.partial {
        let _ = writeln!(
            o,
            "partial-order reduction: {} expanded with one independent group of nets only; dead markings, safety, loops of immediate transitions, cascades of produced events, invariants, conflicts, progress and stuck nets are exact, traces other than to dead markings are witnesses (not always the shortest); starvation and loops need every state: not checked (--no-reduction checks them)",
            count(r.reduced_states, "state")
        );
    }
    let _ = writeln!(
        o,
        "marked places: at most {} in one state; no place ever holds two tokens",
        r.max_tokens_per_marking
    );
    if r.safe {
        let _ = writeln!(o, "safe: yes, no firing asks for a second token in a place");
    } else {
        let _ = writeln!(
            o,
            "safe: NO, {} would put a second token in a place (the player refuses them):",
            count(r.unsafe_places.len(), "firing")
        );
        for u in &r.unsafe_places {
            item(
                &mut o,
                "E0601",
                "error",
                format!(
                    "{} would put a second token in {}, {}",
                    u.transition,
                    u.place,
                    trace_text(&u.trace)
                ),
            );
        }
    }
    let unintended: Vec<_> = r.dead_markings.iter().filter(|d| !d.intended).collect();
    let finals: Vec<_> = r
        .dead_markings
        .iter()
        .filter(|d| d.intended && !d.after_catastrophic)
        .collect();
    let catastrophic = r
        .dead_markings
        .iter()
        .filter(|d| d.after_catastrophic)
        .count();
    let _ = writeln!(
        o,
        "dead markings: {} ({} intended, {} not)",
        r.dead_markings.len(),
        r.dead_markings.len() - unintended.len(),
        unintended.len()
    );
    for d in unintended.iter().take(if details {
        unintended.len()
    } else {
        limit(unintended.len())
    }) {
        item(
            &mut o,
            "E0602",
            "error",
            format!(
                "dead marking: {}, {}",
                marking_text(&d.marking),
                trace_text(&d.trace)
            ),
        );
    }
    if !details {
        more(&mut o, unintended.len(), "dead markings");
    }
    for d in finals.iter().take(limit(finals.len())) {
        let what = if d.net_done {
            "end of the net (it finished)"
        } else {
            "intended final marking"
        };
        let _ = writeln!(
            o,
            "  {what}: {}, {}",
            marking_text(&d.marking),
            trace_text(&d.trace)
        );
    }
    more(&mut o, finals.len(), "intended final markings");
    if catastrophic > 0 {
        if all {
            for d in r.dead_markings.iter().filter(|d| d.after_catastrophic) {
                let _ = writeln!(
                    o,
                    "  end after a catastrophic event: {}, {}",
                    marking_text(&d.marking),
                    trace_text(&d.trace)
                );
            }
        } else {
            let _ = writeln!(
                o,
                "  {catastrophic} end(s) after a catastrophic event (the mission is over there; --all lists them)"
            );
        }
    }
    match &r.no_progress {
        None if r.declares_ends => {
            let _ = writeln!(
                o,
                "progress: a declared end stays reachable from every state{}",
                excluded_text(&r.progress_excludes)
            );
        }
        None => {
            let _ = writeln!(
                o,
                "progress: not checked (no [verify] final or goal declared)"
            );
        }
        Some(f) => {
            let _ = writeln!(
                o,
                "progress: NO, from {} no declared end can be reached{}:",
                count(f.states, "state"),
                excluded_text(&f.excluded)
            );
            item(
                &mut o,
                "E0605",
                "error",
                format!(
                    "the mission cannot finish from {}, {}; it stays in {}, {}",
                    marking_text(&f.marking),
                    trace_text(&f.trace),
                    marking_text(&f.stays_in),
                    trace_text(&f.stays_in_trace)
                ),
            );
        }
    }
    let _ = writeln!(o, "stuck nets: {}", r.stuck_nets.len());
    for s in &r.stuck_nets {
        let mut line = format!(
            "net {} can never fire again from {}, {}",
            s.net,
            marking_text(&s.marking),
            trace_text(&s.trace)
        );
        if let Some(cycle) = &s.resource_cycle {
            let _ = write!(line, "; a resource cycle: {}", cycle.join("; "));
        } else if !s.waits_for.is_empty() {
            let _ = write!(line, "; it waits for {}", s.waits_for.join(", "));
        }
        item(&mut o, "E0606", "error", line);
    }
    let _ = writeln!(o, "loops of immediate transitions: {}", r.livelocks.len());
    for l in &r.livelocks {
        item(
            &mut o,
            "E0603",
            "error",
            format!(
                "immediate transitions loop forever: {}, {}",
                l.transitions.join(" → "),
                trace_text(&l.trace)
            ),
        );
    }
    let _ = writeln!(
        o,
        "loops of events produced at one instant: {}{}",
        r.cascades.len(),
        if r.cascades_incomplete {
            format!(
                " (not checked in full: stopped after {} configurations)",
                r.cascade_configurations
            )
        } else {
            String::new()
        }
    );
    for c in &r.cascades {
        item(
            &mut o,
            "E0608",
            "error",
            format!(
                "{}, {}",
                cascade_text(c, r.cascade_bound),
                trace_text(&c.trace)
            ),
        );
    }
    if !r.invariants.is_empty() {
        let _ = writeln!(
            o,
            "invariants: {} checked, {} broken",
            r.invariants.len(),
            r.invariant_violations.len()
        );
        for v in &r.invariant_violations {
            item(
                &mut o,
                "E0604",
                "error",
                format!(
                    "invariant `{}` is broken in {}, {}",
                    v.invariant,
                    marking_text(&v.marking),
                    trace_text(&v.trace)
                ),
            );
        }
    }
    if !r.bounds.is_empty() {
        let _ = writeln!(o, "time bounds: {}", r.bounds.len());
    }
    for b in &r.bounds {
        let line = bound_text(b);
        if b.met == Some(false) {
            item(&mut o, "E0607", "error", line);
        } else {
            let _ = writeln!(o, "  {line}");
        }
    }
    if r.partial {
        let _ = writeln!(o, "starvation: not checked (partial-order reduction)");
    } else {
        let _ = writeln!(o, "starvation: {}", r.starvation.len());
    }
    for s in &r.starvation {
        item(
            &mut o,
            "W0606",
            "warning",
            format!(
                "{} can wait forever for {} while the loop on {{{}}} takes and gives it back, {}",
                s.transition,
                s.resource,
                s.loop_events.join(", "),
                trace_text(&s.trace)
            ),
        );
    }
    if r.partial {
        let _ = writeln!(
            o,
            "loops that need outside events: not checked (partial-order reduction)"
        );
    } else {
        let _ = writeln!(
            o,
            "loops that need outside events (expected): {}",
            r.event_loops.len()
        );
    }
    for l in r.event_loops.iter().take(limit(r.event_loops.len())) {
        let _ = writeln!(
            o,
            "  info: a loop on {{{}}}, {} in {}; one turn: {}",
            l.events.join(", "),
            count(l.states, "state"),
            count(l.components, "component"),
            l.turn.join(" → ")
        );
    }
    more(&mut o, r.event_loops.len(), "loops");
    let _ = writeln!(o, "conflicts: {}", r.conflicts.len());
    for c in r.conflicts.iter().take(limit(r.conflicts.len())) {
        item(
            &mut o,
            "W0601",
            "warning",
            format!(
                "on {}, {} fires and {} does not (written order), {}",
                c.event,
                c.winner,
                c.loser,
                trace_text(&c.trace)
            ),
        );
    }
    more(&mut o, r.conflicts.len(), "conflicts");
    let list = |o: &mut String, what: &str, v: &[String]| {
        if v.is_empty() {
            let _ = writeln!(o, "{what}: none");
        } else {
            let _ = writeln!(o, "{what}: {}", v.join(", "));
        }
    };
    list(&mut o, "transitions that never fire", &r.never_fired);
    list(&mut o, "nets never activated", &r.never_activated);
    list(&mut o, "events no transition waits for", &r.unused_events);
    if !r.protocols.is_empty() {
        let _ = writeln!(
            o,
            "environment: {} answer(s) and internal event(s) delivered only when asked for ({})",
            r.protocols.len(),
            r.protocols.join(", ")
        );
    }
    let (errors, warnings) = (r.errors(), r.warnings());
    if errors == 0 && warnings == 0 {
        let _ = writeln!(o, "result: verified, no error");
    } else if errors == 0 {
        let _ = writeln!(
            o,
            "result: verified, no error, {}",
            count(warnings, "warning")
        );
    } else {
        let _ = writeln!(
            o,
            "result: {}, {}",
            count(errors, "error"),
            count(warnings, "warning")
        );
    }
    o
}

/// Seconds for people: `600s`, `7.5s`, `0.2s` (to the millisecond, the unit of timers).
fn secs(v: f64) -> String {
    let text = format!("{v:.3}");
    let text = text.trim_end_matches('0').trim_end_matches('.');
    format!("{text}s")
}

/// A bound's `within` as written in petrel.toml (`10min`), or in seconds when it was not written.
fn within_text(b: &super::BoundFinding) -> Option<String> {
    b.within.clone().or_else(|| b.within_seconds.map(secs))
}

/// A time bound on one line: `bound NAME (FROM .. TO): 0s to 600s, ...`.
fn bound_text(b: &super::BoundFinding) -> String {
    use super::BoundStatus as S;
    let mut line = format!("bound {} ({} .. {}): ", b.name, b.from, b.to);
    let path = |b: &super::BoundFinding| {
        let then = if b.then.is_empty() {
            "at once".to_string()
        } else {
            b.then.join(" → ")
        };
        format!("{}, then {then}", trace_text(&b.trace))
    };
    match b.status {
        S::Bounded => {
            let _ = write!(
                line,
                "{} to {}; the longest: {}",
                b.min_seconds.map_or("?".into(), secs),
                b.max_seconds.map_or("?".into(), secs),
                path(b)
            );
        }
        S::Unbounded => {
            if let Some(min) = b.min_seconds {
                let _ = write!(line, "at least {}, ", secs(min));
            }
            // The path to where it may wait forever.
            let mut to = trace_text(&b.trace);
            if !b.then.is_empty() {
                let _ = write!(to, ", then {}", b.then.join(" → "));
            }
            let _ = write!(
                line,
                "unbounded: {}; {to}",
                b.reason.as_deref().unwrap_or("")
            );
        }
        S::FromNeverHappens => {
            let _ = write!(line, "{} never happens", b.from);
        }
        S::NotDecided => {
            let _ = write!(line, "not decided: {}", b.reason.as_deref().unwrap_or(""));
        }
    }
    if let Some(w) = within_text(b) {
        let verdict = match b.met {
            Some(true) => "met",
            Some(false) => "VIOLATED",
            None => "not decided",
        };
        let _ = write!(line, "; within {w}: {verdict}");
    }
    line
}

fn excluded_text(excluded: &[String]) -> String {
    if excluded.is_empty() {
        String::new()
    } else {
        format!(" without {} events", excluded.join(" or "))
    }
}

/// The report for tools.
pub fn to_json(r: &Report) -> serde_json::Value {
    serde_json::to_value(r).unwrap_or(serde_json::Value::Null)
}

/// The findings as diagnostics on the project's text, grouped (what `petrel check` and
/// `petrel verify` print with file, line and caret): errors for unsafe places, unintended dead
/// markings (one diagnostic for all of them, the first in full), livelocks, broken invariants,
/// a mission that cannot finish and stuck nets; warnings for conflicts, starvation, transitions
/// that never fire, nets never activated and events nobody waits for. Each is located at the
/// transition, net, place or declaration concerned (an instance's at its template's text).
pub fn diagnostics(project: &crate::model::Project, r: &Report) -> crate::diag::Diagnostics {
    diagnostics_with(project, r, false)
}

/// [`diagnostics`] with every finding apart (`petrel verify --all`): one diagnostic per dead
/// marking.
pub fn diagnostics_all(project: &crate::model::Project, r: &Report) -> crate::diag::Diagnostics {
    diagnostics_with(project, r, true)
}

fn diagnostics_with(
    project: &crate::model::Project,
    r: &Report,
    all: bool,
) -> crate::diag::Diagnostics {
    use crate::diag::{Diagnostic, Diagnostics};
    use crate::source::Span;
    let mut d = Diagnostics::new();
    let at = |span: Option<Span>, diag: Diagnostic| Diagnostic { span, ..diag };
    // An instance's findings point at its template's text.
    let decl_of = |net: &str| {
        let template = r.templates.get(net).map(String::as_str).unwrap_or(net);
        project.nets().find(|n| n.name.text == template)
    };
    let transition_span = |qualified: &str| {
        let (net, t) = qualified.rsplit_once('.')?;
        decl_of(net)?
            .transitions()
            .find(|x| x.name.text == t)
            .map(|x| x.name.span)
    };
    let net_span = |net: &str| decl_of(net).map(|n| n.name.span);
    // `NET.place` (a completion place `NET.CHILD.done` at its net) or `global.place`.
    let place_span = |qualified: &str| -> Option<Span> {
        let (net, place) = qualified.split_once('.')?;
        if net == "global" {
            return project
                .manifest
                .globals
                .iter()
                .find(|g| g.name.text == place)
                .map(|g| g.name.span);
        }
        let decl = decl_of(net)?;
        decl.places()
            .find(|x| x.name.text == place)
            .map(|x| x.name.span)
            .or(Some(decl.name.span))
    };
    // A state's places: the first local one is where the finding is; the others explain it.
    let on_places = |diag: Diagnostic, places: &[String], first_label: &str| {
        let mut located: Vec<(Span, &String)> = places
            .iter()
            .filter_map(|q| place_span(q).map(|s| (s, q)))
            .collect();
        // A net's place before a global one: the net is where the mission is.
        located.sort_by_key(|(_, q)| q.starts_with("global."));
        let mut it = located.into_iter();
        let Some((first, _)) = it.next() else {
            return diag;
        };
        let mut diag = at(Some(first), diag).label(first_label.to_string());
        for (span, q) in it {
            if span != first {
                diag = diag.related(span, format!("{q} is marked too"));
            }
        }
        diag
    };
    for v in &r.invariant_violations {
        let span = project
            .manifest
            .invariants
            .iter()
            .find(|i| i.name.text == v.invariant)
            .map(|i| i.name.span);
        d.push(at(
            span,
            Diagnostic::error(
                "E0604",
                Default::default(),
                format!("invariant `{}` is broken: {}", v.invariant, marking_text(&v.marking)),
            )
            .label(format!("broken {}", trace_text(&v.trace)))
            .help("the nets can reach a stable state where the formula is false: follow the trace, and fix the nets (or the invariant)"),
        ));
    }
    for u in &r.unsafe_places {
        d.push(at(
            transition_span(&u.transition),
            Diagnostic::error(
                "E0601",
                Default::default(),
                format!("{} can put a second token in {}", u.transition, u.place),
            )
            .label(format!("unsafe firing {}", trace_text(&u.trace)))
            .help("the player refuses such a firing: make sure the place is empty when this transition fires (an extra input, or an emptiness test `not PLACE`)"),
        ));
    }
    let dead: Vec<_> = r.dead_markings.iter().filter(|x| !x.intended).collect();
    let shown = if all { dead.len() } else { dead.len().min(1) };
    for x in &dead[..shown] {
        let mut message = format!(
            "dead marking {}: {}",
            trace_text(&x.trace),
            marking_text(&x.marking)
        );
        if !all && dead.len() > 1 {
            message = format!(
                "{} dead markings; the first {message} (--all lists them)",
                dead.len()
            );
        }
        d.push(on_places(
            Diagnostic::global("E0602", message)
                .help("no event can move the mission on from there: add a transition out of it, or declare it a planned end in the manifest's [verify] final"),
            &x.places,
            "marked in the dead marking",
        ));
    }
    for l in &r.livelocks {
        d.push(at(
            l.transitions.first().and_then(|t| transition_span(t)),
            Diagnostic::error(
                "E0603",
                Default::default(),
                format!(
                    "immediate transitions loop forever: {}",
                    l.transitions.join(" → ")
                ),
            )
            .label(format!("the player would spin {}", trace_text(&l.trace)))
            .help("give one transition of the loop a triggering event"),
        ));
    }
    for c in &r.cascades {
        d.push(at(
            c.transitions.first().and_then(|t| transition_span(t)),
            Diagnostic::error("E0608", Default::default(), cascade_text(c, r.cascade_bound))
                .label(format!(
                    "the player would stop it after {} steps at one instant and raise livelock, {}",
                    r.cascade_bound,
                    trace_text(&c.trace)
                ))
                .help("nothing in the loop waits for time or for an outside event: let a timer (`start T after D`, then `on` its event) or an outside event drive it, or give it a place it empties on the way"),
        ));
    }
    if r.cascades_incomplete {
        d.push(at(
            None,
            Diagnostic::warning(
                "W0607",
                Default::default(),
                format!(
                    "the search for cascades of events produced at one instant stopped after {} configurations: a loop may be missed",
                    r.cascade_configurations
                ),
            )
            .help("its budget is --max-states (at most 1,000,000): raise it, or verify one net with --net"),
        ));
    }
    if let Some(f) = &r.no_progress {
        let without = if f.excluded.is_empty() {
            String::new()
        } else {
            format!(" without {} events", f.excluded.join(" or "))
        };
        d.push(on_places(
            Diagnostic::global(
                "E0605",
                format!(
                    "the mission cannot finish{without} from {}; the first: {}, {}",
                    count(f.states, "reachable state"),
                    marking_text(&f.marking),
                    trace_text(&f.trace)
                ),
            )
            .help(format!(
                "no declared end ([verify] final or goal) can be reached{without} once the mission is in {}: look for the transition it lacks to go on from there",
                marking_text(&f.stays_in)
            )),
            &f.places,
            &format!("the mission stays here {}", trace_text(&f.stays_in_trace)),
        ));
    }
    for s in &r.stuck_nets {
        let mut msg = format!(
            "net {} can never fire again from {}",
            s.net,
            marking_text(&s.marking)
        );
        if let Some(cycle) = &s.resource_cycle {
            let _ = write!(msg, "; a resource cycle: {}", cycle.join("; "));
        }
        let mut diag = at(
            net_span(&s.net),
            Diagnostic::error("E0606", Default::default(), msg)
                .label(format!("stuck {}", trace_text(&s.trace)))
                .help(if s.resource_cycle.is_some() {
                    "each net holds a place another waits for: take the places in one order everywhere, or take them together in one transition".to_string()
                } else if s.waits_for.is_empty() {
                    "whatever events come, no transition of this net is enabled again: add the way out, or declare the state a planned end of this net in [verify] final".to_string()
                } else {
                    format!("it waits for {}, which nothing gives back from there: give it back on every path", s.waits_for.join(", "))
                }),
        );
        for q in &s.places {
            if let Some(span) = place_span(q) {
                diag = diag.related(span, format!("{q} stays marked"));
            }
        }
        d.push(diag);
    }
    for b in r.bounds.iter().filter(|b| b.met == Some(false)) {
        let decl = project
            .manifest
            .bounds
            .iter()
            .find(|x| x.name.text == b.name);
        let span = decl.map(|x| x.within.as_ref().map_or(x.name.span, |w| w.span));
        let within = within_text(b).unwrap_or_default();
        let what = match (b.status, b.max_seconds) {
            (super::BoundStatus::Bounded, Some(max)) => {
                format!("{} after {} can take up to {}", b.to, b.from, secs(max))
            }
            _ => format!(
                "{} may never come after {}: {}",
                b.to,
                b.from,
                b.reason.as_deref().unwrap_or("")
            ),
        };
        let mut path = trace_text(&b.trace);
        if !b.then.is_empty() {
            let _ = write!(path, ", then {}", b.then.join(" → "));
        } else if b.status == super::BoundStatus::Bounded {
            path.push_str(", then at once");
        }
        d.push(at(
            span,
            Diagnostic::error(
                "E0607",
                Default::default(),
                format!("bound `{}` is not met: {what}, more than {within}", b.name),
            )
            .label(path)
            .help("follow the path: a watchdog timer in the nets (a fallback after at most the time allowed) bounds a wait for an outside event; or allow more time"),
        ));
    }
    for s in &r.starvation {
        d.push(at(
            transition_span(&s.transition).or_else(|| net_span(&s.net)),
            Diagnostic::warning(
                "W0606",
                Default::default(),
                format!(
                    "{} can wait forever for {} while the loop on {{{}}} takes and gives it back",
                    s.transition,
                    s.resource,
                    s.loop_events.join(", ")
                ),
            )
            .label(format!("starved {}", trace_text(&s.trace)))
            .help("if the environment may keep the mission in that loop, share the place fairly (a turn place, or give it to the waiting net first)"),
        ));
    }
    for c in &r.conflicts {
        d.push(at(
            transition_span(&c.loser),
            Diagnostic::warning(
                "W0601",
                Default::default(),
                format!("{} and {} conflict on {}", c.winner, c.loser, c.event),
            )
            .label(format!("does not fire when both are enabled ({})", trace_text(&c.trace)))
            .help("written order decides; if that is intended, say so with @allow(W0601, \"why\"), otherwise make their input places (or guards) exclusive"),
        ));
    }
    for t in &r.never_fired {
        let immediate = t.rsplit_once('.').and_then(|(net, name)| {
            decl_of(net)?
                .transitions()
                .find(|x| x.name.text == name)
                .map(|x| x.trigger.is_none())
        });
        let (label, help) = if immediate == Some(true) {
            (
                "never enabled",
                "check its input places (and its guard); remove it if it is dead code, or say it is intended with @allow(W0602, \"why\")",
            )
        } else {
            (
                "never enabled (guard included) when its event comes",
                "check its input places, its guard and its event; remove it if it is dead code, or say it is intended with @allow(W0602, \"why\")",
            )
        };
        d.push(at(
            transition_span(t),
            Diagnostic::warning("W0602", Default::default(), format!("{t} can never fire"))
                .label(label)
                .help(help),
        ));
    }
    for n in &r.never_activated {
        d.push(at(
            net_span(n),
            Diagnostic::warning(
                "W0603",
                Default::default(),
                format!("net `{n}` is never activated"),
            )
            .label("never active")
            .help("list it in `start`, or activate it from a transition"),
        ));
    }
    for e in &r.unused_events {
        let span = project
            .manifest
            .events
            .iter()
            .find(|x| &x.name.text == e)
            .map(|x| x.name.span);
        d.push(at(
            span,
            Diagnostic::warning("W0604", Default::default(), format!("no transition waits for event `{e}`"))
                .label("never used")
                .help("the player will count it as unused each time it comes; remove it, or add a transition `on` it"),
        ));
    }
    d
}
