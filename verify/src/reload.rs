//! The verifier's half of a reload (docs/semantics.md, "Reloading a project mid-mission"):
//! the new version verified from the state the running one's is mapped to
//! ([`petrel_nets::reload::map_state`]), and the first finding that refuses the swap.

use petrel_nets::compiled::CompiledProject;
use petrel_nets::reload::Mapped;

/// Why a reload is refused after its mapping: a finding of the verification from the mapped
/// state (what, and the shortest trace from that state), or a verification that could not
/// finish.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Finding {
    /// What the verifier found, in words.
    pub what: String,
    /// The events from the mapped state to it (empty: the mapped state itself).
    pub trace: Vec<String>,
}

/// The first finding of `report` that refuses a reload (docs/semantics.md): an unsafe place,
/// a cycle of immediate transitions, a cascade of produced events that does not settle, an
/// unintended dead marking, a broken invariant.
pub fn refusing_finding(report: &crate::Report) -> Option<Finding> {
    if let Some(u) = report.unsafe_places.first() {
        return Some(Finding {
            what: format!(
                "unsafe place: `{}` would put a second token in `{}`",
                u.transition, u.place
            ),
            trace: u.trace.clone(),
        });
    }
    if let Some(l) = report.livelocks.first() {
        return Some(Finding {
            what: format!(
                "livelock: immediate transitions fire forever ({})",
                l.transitions.join(" -> ")
            ),
            trace: l.trace.clone(),
        });
    }
    if let Some(c) = report.cascades.first() {
        return Some(Finding {
            what: format!(
                "livelock: events produced at one instant do not settle ({}; {})",
                c.events.join(" -> "),
                c.transitions.join(", ")
            ),
            trace: c.trace.clone(),
        });
    }
    if let Some(d) = report.dead_markings.iter().find(|d| !d.intended) {
        return Some(Finding {
            what: format!(
                "unintended dead marking: nothing can fire any more in [{}]",
                d.marking.join(", ")
            ),
            trace: d.trace.clone(),
        });
    }
    if let Some(i) = report.invariant_violations.first() {
        return Some(Finding {
            what: format!(
                "invariant `{}` broken in [{}]",
                i.invariant,
                i.marking.join(", ")
            ),
            trace: i.trace.clone(),
        });
    }
    None
}

/// Verifies `new` from the mapped state: `Ok` with the states explored, or the finding that
/// refuses the reload (a verification that cannot finish refuses it too, said as the finding).
pub fn verify_mapped(
    new: &CompiledProject,
    mapped: &Mapped,
    max_states: Option<u64>,
) -> Result<u64, Finding> {
    let opts = crate::VerifyOptions {
        max_states,
        ..Default::default()
    };
    match crate::verify_from(new, &mapped.state, opts) {
        Ok(report) => match refusing_finding(&report) {
            Some(f) => Err(f),
            None => Ok(report.states),
        },
        Err(e) => Err(Finding {
            what: format!("the verification from the mapped state did not finish: {e}"),
            trace: Vec::new(),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use petrel_nets::reload::{map_state, Mapping, OldState};
    use petrel_nets::semantics::{NoEffects, Scratch, Semantics};

    const MANIFEST: &str = "[project]\nname = \"p\"\nfiles = [\"a.pn\"]\nstart = [\"A\"]\n\n[globals]\ng = 1\n\n[events]\ngo = { category = \"nominal\" }\nback = { category = \"nominal\" }\ntick = { category = \"nominal\" }\n\n[timers]\nt = { event = \"tick\" }\n";
    const NET: &str = "net A {\n    place p = 1\n    place q\n    transition go on go: p -> q {\n        start t after 10s\n    }\n    transition back on back: q -> p\n}\n";

    fn compile(manifest: &str, net: &str) -> CompiledProject {
        let (_, c, d, _) = petrel_nets::project::from_sources(manifest, &[("a.pn", net)]);
        assert!(!d.has_errors(), "{d:?}");
        c.expect("compiles")
    }

    #[test]
    fn verification_from_the_mapped_state_finds_what_the_start_does_not() {
        // `again` would put a second token in q, but only from a state where q is marked and
        // p is too: unreachable from the start, reached by mapping a version where both are.
        let net = NET.replace(
            "    transition back",
            "    transition again on back: p -> q\n    transition back",
        );
        let new = compile(MANIFEST, &net);
        let from_start = crate::verify(&new, Default::default()).unwrap();
        assert!(from_start.safe, "{from_start:?}");
        let two = compile(
            MANIFEST,
            "net A {\n    place p = 1\n    place q = 1\n    transition go on go: p -> p\n    transition back on back: q -> q\n    transition tick on tick: p -> p\n}\n",
        );
        let sem = Semantics::new(&two);
        let s = sem.initial(&mut NoEffects, &mut Scratch::default());
        let args = vec![Vec::new()];
        let m = map_state(
            &two,
            &OldState {
                state: &s,
                deadlines: &[None],
                net_args: &args,
            },
            &new,
            &Mapping::default(),
        )
        .unwrap();
        let f = verify_mapped(&new, &m, None).unwrap_err();
        assert_eq!(
            f.what,
            "unsafe place: `A.go` would put a second token in `A.q`"
        );
        assert_eq!(f.trace, vec!["go"]);
        let r = crate::verify_from(&new, &m.state, Default::default()).unwrap();
        assert!(!r.safe);
        assert_eq!(r.unsafe_places[0].place, "A.q");
        assert_eq!(r.unsafe_places[0].trace, vec!["go"]);
    }
}
