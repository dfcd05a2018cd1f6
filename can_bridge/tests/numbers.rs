//! can.toml's literal event parameters are exact or refused (issue 10, item 5): TOML reads
//! `nan` and `inf` as floats, and an int beyond 2^53 would round in a float parameter.

mod common;

use common::{can_toml, check, codes};

#[test]
fn a_literal_float_parameter_is_finite_and_exact() {
    let text = can_toml();
    let original = "params = [\"Battery.voltage\", \"Battery.state\"]";
    assert!(text.contains(original));
    for (literal, found) in [
        ("nan", "a float that is not finite"),
        ("inf", "a float that is not finite"),
        ("-inf", "a float that is not finite"),
        ("9007199254740993", "an int that no float holds exactly"),
    ] {
        let bad = text.replace(
            original,
            &format!("params = [{literal}, \"Battery.state\"]"),
        );
        let (d, rendered) = check(&bad).map(|_| ()).unwrap_err();
        assert_eq!(codes(&d), ["E0706"], "{literal}: {rendered}");
        assert!(rendered.contains(found), "{literal}: {rendered}");
    }
    // What a float holds exactly passes.
    let fine = text.replace(original, "params = [9007199254740992, \"Battery.state\"]");
    assert!(check(&fine).is_ok());
}
