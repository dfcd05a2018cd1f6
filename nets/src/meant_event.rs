//! W0108: an immediate transition that was probably meant to wait for an event.
//!
//! A transition written without `on EVENT` is immediate: it fires as soon as its input places
//! are marked. Forgetting `on EVENT` therefore checks clean, and the only trace was W0604 on the
//! event left unused, reported on the manifest, far from the transition. The warning points at
//! the transition when all of these hold, so that it does not fire on deliberate immediate
//! transitions:
//!
//! - the transition has no event and at least one input place;
//! - an event declared in the manifest (not a built-in one) is waited for by no transition of
//!   the project (no `on EVENT` anywhere: the event would be unused);
//! - the two names are close: equal ignoring case, one a `_`-separated part of the other
//!   (`reached` and `wp_reached`) of at least 4 characters, or at edit distance 1 (2 for names
//!   of 8 characters or more) with both names at least 4 characters long.
//!
//! `@allow(W0108)` on the transition silences it, as for every warning.

use crate::model::Project;
use petrel_diag::names::distance;
use petrel_diag::report::{Diagnostic, Diagnostics};
use std::collections::HashSet;

/// Reports W0108 for each immediate transition whose name is close to an unused event's.
pub(crate) fn immediate_transitions_meant_events(project: &Project, d: &mut Diagnostics) {
    let waited: HashSet<&str> = project
        .nets()
        .flat_map(|n| n.transitions())
        .filter_map(|t| t.trigger.as_ref().map(|tr| tr.event.text.as_str()))
        .collect();
    let unused: Vec<&str> = project
        .manifest
        .events
        .iter()
        .map(|e| e.name.text.as_str())
        .filter(|e| !waited.contains(e))
        .collect();
    if unused.is_empty() {
        return;
    }
    for net in project.nets() {
        for t in net.transitions() {
            if t.trigger.is_some() || t.inputs.is_empty() {
                continue;
            }
            let Some(event) = unused.iter().find(|e| close(&t.name.text, e)) else {
                continue;
            };
            d.push(
                Diagnostic::warning(
                    "W0108",
                    t.name.span,
                    format!(
                        "transition `{}` of net `{}` has no event: it fires as soon as its input places are marked, and event `{event}` is waited for by no transition",
                        t.name, net.name
                    ),
                )
                .label("immediate: no `on EVENT`")
                .help(format!(
                    "did you mean `transition {} on {event}: ...`? If it is meant to be immediate, write @allow(W0108, \"why\") before it",
                    t.name
                )),
            );
        }
    }
}

/// Whether a transition's name and an event's are close enough that one was meant for the
/// other (the rule of the module's documentation).
fn close(transition: &str, event: &str) -> bool {
    let (t, e) = (transition.to_lowercase(), event.to_lowercase());
    if t == e {
        return true;
    }
    let (short, long) = if t.len() <= e.len() {
        (&t, &e)
    } else {
        (&e, &t)
    };
    // A part between `_`s (or the ends): `reached` in `wp_reached`, not `each` in `reached`.
    let part_of = long.match_indices(short.as_str()).any(|(i, _)| {
        let end = i + short.len();
        (i == 0 || long.as_bytes()[i - 1] == b'_')
            && (end == long.len() || long.as_bytes()[end] == b'_')
    });
    if short.len() >= 4 && part_of {
        return true;
    }
    let bound = if short.len() >= 8 { 2 } else { 1 };
    short.len() >= 4 && distance(&t, &e) <= bound
}

#[cfg(test)]
mod tests {
    use super::close;

    #[test]
    fn close_names() {
        assert!(close("wp_reached", "wp_reached"));
        assert!(close("Landed", "landed"));
        assert!(close("reached", "wp_reached"));
        assert!(close("wp_reachd", "wp_reached"));
        assert!(close("touchdown", "touch_down"));
        // Not close: short names, parts inside a word, far names.
        assert!(!close("go", "do"));
        assert!(!close("t", "go"));
        assert!(!close("each", "reached"));
        assert!(!close("init", "abort"));
        assert!(!close("done", "gone_away"));
    }
}
