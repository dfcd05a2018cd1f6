//! The checker on the constructs for real missions (the verifier's half is in
//! verify/tests/language.rs).

/// Found by the fuzzer (CI, net_check on the Redermor DECISION net alone): a net whose
/// `children` names an undeclared net before the one a transition activates indexed the
/// declared children by the position in the list, and the checker panicked. The unknown
/// child is reported and the activation of the declared one resolves.
#[test]
fn an_undeclared_child_before_an_activated_one_is_reported_not_a_panic() {
    let manifest = "[project]\nname = \"t\"\nfiles = [\"a.pn\"]\nstart = [\"A\"]\n";
    let nets = "net A {\n    children Missing, B\n    place p = 1\n    \
                transition t: p -> { activate B }\n}\n\
                net B {\n    place q = 1\n}\n";
    let (_, compiled, d, _) = petrel_nets::project::from_sources(manifest, &[("a.pn", nets)]);
    assert!(compiled.is_none());
    let codes: Vec<&str> = d.iter().map(|d| d.code).collect();
    assert_eq!(codes.len(), 1, "{d:?}");
    assert!(
        d.iter().next().unwrap().message.contains("Missing"),
        "{d:?}"
    );
}
