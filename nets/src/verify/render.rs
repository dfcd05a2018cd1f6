//! The report for people ([`render_human`], grouped; [`render_human_all`], every finding), for
//! tools ([`to_json`]), and as diagnostics on the project's text ([`diagnostics`], what
//! `petrel check` and `petrel verify` print with file, line and caret).

use super::{Report, Trace};
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

fn marking_text(m: &[String]) -> String {
    if m.is_empty() {
        "nothing marked".to_string()
    } else {
        m.join(" ")
    }
}

/// The report for people: every error, and the expected findings grouped with counts (the
/// details are in [`render_human_all`] and [`to_json`]).
pub fn render_human(project_name: &str, r: &Report) -> String {
    render(project_name, r, false)
}

/// The report for people with every finding listed (`petrel verify --all`).
pub fn render_human_all(project_name: &str, r: &Report) -> String {
    render(project_name, r, true)
}

fn render(project_name: &str, r: &Report, all: bool) -> String {
    let mut o = String::new();
    let limit = |n: usize| if all { n } else { n.min(SHOWN) };
    let more = |o: &mut String, n: usize, what: &str| {
        if !all && n > SHOWN {
            let _ = writeln!(o, "  ... and {} more {what} (--all lists them)", n - SHOWN);
        }
    };
    let _ = writeln!(
        o,
        "verified `{project_name}`: {} stable states, {} event deliveries, {:.3} s",
        r.states, r.edges, r.seconds
    );
    let _ = writeln!(
        o,
        "max tokens in a place: {}, max tokens in a marking: {}",
        r.max_tokens_in_place, r.max_tokens_per_marking
    );
    if r.safe {
        let _ = writeln!(o, "safe: yes, no place can receive a second token");
    } else {
        let _ = writeln!(
            o,
            "safe: NO, {} firing(s) would put a second token in a place (the player refuses them):",
            r.unsafe_places.len()
        );
        for u in &r.unsafe_places {
            let _ = writeln!(
                o,
                "  error: {} would put a second token in {}, {}",
                u.transition,
                u.place,
                trace_text(&u.trace)
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
    for d in &unintended {
        let _ = writeln!(
            o,
            "  error: dead marking: {}, {}",
            marking_text(&d.marking),
            trace_text(&d.trace)
        );
    }
    for d in finals.iter().take(limit(finals.len())) {
        let _ = writeln!(
            o,
            "  intended final marking: {}, {}",
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
        None => {
            let _ = writeln!(
                o,
                "progress: an end of the mission stays reachable from every state"
            );
        }
        Some(f) => {
            let _ = writeln!(
                o,
                "progress: NO, from {} state(s) no end of the mission can be reached{}:",
                f.states,
                if f.excluded.is_empty() {
                    String::new()
                } else {
                    format!(" without {} events", f.excluded.join(" or "))
                }
            );
            let _ = writeln!(
                o,
                "  error: the mission cannot finish from {}, {}",
                marking_text(&f.marking),
                trace_text(&f.trace)
            );
        }
    }
    let _ = writeln!(o, "stuck nets: {}", r.stuck_nets.len());
    for s in &r.stuck_nets {
        let mut line = format!(
            "  error: net {} can never fire again from {}, {}",
            s.net,
            marking_text(&s.marking),
            trace_text(&s.trace)
        );
        if let Some(cycle) = &s.resource_cycle {
            let _ = write!(line, "; a resource cycle: {}", cycle.join("; "));
        } else if !s.waits_for.is_empty() {
            let _ = write!(line, "; it waits for {}", s.waits_for.join(", "));
        }
        let _ = writeln!(o, "{line}");
    }
    let _ = writeln!(o, "loops of immediate transitions: {}", r.livelocks.len());
    for l in &r.livelocks {
        let _ = writeln!(
            o,
            "  error: immediate transitions loop forever: {}, {}",
            l.transitions.join(" → "),
            trace_text(&l.trace)
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
            let _ = writeln!(
                o,
                "  error: invariant `{}` is broken in {}, {}",
                v.invariant,
                marking_text(&v.marking),
                trace_text(&v.trace)
            );
        }
    }
    if !r.starvation.is_empty() {
        let _ = writeln!(o, "starvation: {}", r.starvation.len());
        for s in &r.starvation {
            let _ = writeln!(
                o,
                "  warning: net {} can wait forever for {} while the loop on {{{}}} takes and gives it back, {}",
                s.net,
                s.resource,
                s.loop_events.join(", "),
                trace_text(&s.trace)
            );
        }
    }
    let _ = writeln!(
        o,
        "loops that need outside events (expected): {}",
        r.event_loops.len()
    );
    for l in r.event_loops.iter().take(limit(r.event_loops.len())) {
        let _ = writeln!(
            o,
            "  info: a loop on {{{}}}, {} states in {} component(s); one turn: {}",
            l.events.join(", "),
            l.states,
            l.components,
            l.turn.join(" → ")
        );
    }
    more(&mut o, r.event_loops.len(), "loops");
    let _ = writeln!(o, "conflicts: {}", r.conflicts.len());
    for c in r.conflicts.iter().take(limit(r.conflicts.len())) {
        let _ = writeln!(
            o,
            "  warning: on {}, {} fires and {} does not (written order), {}",
            c.event,
            c.winner,
            c.loser,
            trace_text(&c.trace)
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
    let errors = r.errors();
    if errors == 0 {
        let _ = writeln!(o, "result: verified, no error");
    } else {
        let _ = writeln!(o, "result: {errors} error(s)");
    }
    o
}

/// The report for tools.
pub fn to_json(r: &Report) -> serde_json::Value {
    serde_json::to_value(r).unwrap_or(serde_json::Value::Null)
}

/// The findings as diagnostics on the project's text, for `petrel check` and `petrel verify`:
/// errors for unsafe places, unintended dead markings, livelocks, broken invariants, a mission
/// that cannot finish and stuck nets; warnings for conflicts, starvation, transitions that
/// never fire, nets never activated and events nobody waits for. Each is located at the
/// transition, net, place or declaration concerned (an instance's at its template's text).
pub fn diagnostics(project: &crate::model::Project, r: &Report) -> crate::diag::Diagnostics {
    use crate::diag::{Diagnostic, Diagnostics};
    let mut d = Diagnostics::new();
    let at = |span: Option<crate::source::Span>, diag: Diagnostic| Diagnostic { span, ..diag };
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
    for x in r.dead_markings.iter().filter(|x| !x.intended) {
        d.push(
            Diagnostic::global(
                "E0602",
                format!("dead marking {}: {}", trace_text(&x.trace), marking_text(&x.marking)),
            )
            .help("no event can move the mission on from there: add a transition out of it, or declare it a planned end in the manifest's [verify] final"),
        );
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
    if let Some(f) = &r.no_progress {
        d.push(
            Diagnostic::global(
                "E0605",
                format!(
                    "the mission cannot finish from {} reachable state(s); the first: {}, {}",
                    f.states,
                    marking_text(&f.marking),
                    trace_text(&f.trace)
                ),
            )
            .help(if f.excluded.is_empty() {
                "no declared end ([verify] final or goal) can be reached from there: look for the transition the mission lacks to go on".to_string()
            } else {
                format!("no declared end ([verify] final or goal) can be reached from there without {} events: look for the transition the mission lacks to go on", f.excluded.join(" or "))
            }),
        );
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
        d.push(at(
            net_span(&s.net),
            Diagnostic::error("E0606", Default::default(), msg)
                .label(format!("stuck {}", trace_text(&s.trace)))
                .help(if s.waits_for.is_empty() {
                    "whatever events come, no transition of this net is enabled again: add the way out, or declare the state a planned end of this net in [verify] final".to_string()
                } else {
                    format!("it waits for {} that nothing gives back: take the places in one order everywhere, or give them back on every path", s.waits_for.join(", "))
                }),
        ));
    }
    for s in &r.starvation {
        d.push(at(
            net_span(&s.net),
            Diagnostic::warning(
                "W0606",
                Default::default(),
                format!(
                    "net {} can wait forever for {} while the loop on {{{}}} takes and gives it back",
                    s.net,
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
