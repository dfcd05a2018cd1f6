//! Mission scripts (and `petrel send`, which reads its event as a script line): numbers are
//! read exactly or refused, times are numbers of seconds, nesting is bounded (issue 10, item 5).

use petrel_nets::compiled::{CompiledProject, Value};
use petrel_player::script::{parse_script, Line};

fn uav() -> CompiledProject {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../missions/uav");
    let (_, compiled, d) =
        petrel_nets::project::load_and_check(std::path::Path::new(dir)).expect("the UAV reads");
    compiled.unwrap_or_else(|| panic!("the UAV mission checks: {d:?}"))
}

fn error_of(text: &str) -> String {
    match parse_script(text, &uav()) {
        Ok(s) => panic!("`{text}` was accepted as {:?}", s.lines),
        Err(e) => {
            assert_eq!(e.len(), 1, "{e:?}");
            e[0].1.clone()
        }
    }
}

/// Before: `waypoint([1e999], "x")` reached the player as `waypoint([0.0], "x")`.
#[test]
fn a_float_out_of_range_is_refused_not_zero() {
    let e = error_of("0 waypoint([1e999], \"x\")");
    assert!(e.contains("too large for a float"), "{e}");
    let e = error_of("0 waypoint([1e-400], \"x\")");
    assert!(e.contains("too small for a float"), "{e}");
}

#[test]
fn an_integer_out_of_range_is_refused_not_zero() {
    let e = error_of("0 waypoint([99999999999999999999], \"x\")");
    assert!(e.contains("does not fit in 64 bits"), "{e}");
    // An integer that no float holds exactly is not rounded either.
    let e = error_of("0 waypoint([9007199254740993], \"x\")");
    assert!(e.contains("is [float]"), "{e}");
}

#[test]
fn exact_numbers_are_read_as_written() {
    let s = parse_script(
        "0 waypoint([9007199254740992, 1.5e300, -0.25], \"x\")",
        &uav(),
    )
    .expect("reads");
    let Line::At {
        event: Some((_, params)),
        ..
    } = &s.lines[0].1
    else {
        panic!("{s:?}")
    };
    assert_eq!(
        params[0],
        Value::FloatList(vec![9007199254740992.0, 1.5e300, -0.25])
    );
}

/// Before: `nan` was refused as a time that "goes back"; `inf` too. Now each says what a time
/// is, and a time past what microseconds in 64 bits hold is refused rather than saturated.
#[test]
fn times_are_finite_non_negative_seconds() {
    for bad in ["nan", "NaN", "inf", "-inf", "-1", "1e300"] {
        let e = error_of(&format!("{bad} start_mission"));
        assert!(e.contains("is not a time"), "{bad}: {e}");
    }
}

/// Before: 30,000 `[` overflowed the stack of `petrel send` (abort).
#[test]
fn nesting_is_bounded_without_overflowing_the_stack() {
    let deep = format!(
        "0 waypoint({}1.0{}, \"x\")",
        "[".repeat(30_000),
        "]".repeat(30_000)
    );
    // On a small stack, as a thread of the player or a tool could have.
    let e = std::thread::Builder::new()
        .stack_size(256 * 1024)
        .spawn(move || error_of(&deep))
        .expect("thread")
        .join()
        .expect("no stack overflow");
    assert!(e.contains("nested more than"), "{e}");
}
