//! Scripts (`petrel run --script`): every expectation holding and failing, with the line it
//! names; the outcome words of the JSON lines; errors of reading, each on its line; numbers,
//! times and nesting in script lines (and in `petrel send`, which reads its event as one).

use petrel_nets::compiled::{CompiledProject, Value};
use petrel_nets::project::from_sources;
use petrel_nets::semantics::StepOutcome;
use petrel_player::record::{outcome_name, Outcome};
use petrel_player::script::{parse_script, run_script, Line, RunOutcome};
use serde_json::Value as Json;

const MANIFEST: &str = r#"
[project]
name = "s"
files = ["a.pn"]
start = ["A"]

[globals]
up = 0

[events]
go = { category = "nominal" }
tick = { category = "nominal", params = ["n: int"] }
ping = { category = "nominal", params = ["label: text", "x: float"] }
ack = { category = "nominal" }
hello = { category = "nominal" }
late = { category = "nominal" }
panic = { category = "nominal" }
boom = { category = "catastrophic" }
tock = { category = "nominal" }

[programs.P]
functions = { a = [], b = ["n: int"], c = ["label: text"] }

[timers]
t = { event = "tock" }
"#;

/// `go` calls, emits `ping` (whose step emits `ack`, which nothing takes) and starts `t`;
/// `hello` is emitted at the start; `panic` emits a catastrophic event, then `ack`.
const NETS: &str = r#"
net A {
    place boot = 1
    place idle = 1
    place running
    place done

    transition init: boot -> {
        emit hello
    }
    transition start on go: idle -> running, up {
        call P.a()
        call P.b(1)
        call P.b(2)
        emit ping("hello", 2.5)
        start t after 10s
    }
    transition count on tick(n): running -> running {
        call P.b(n)
    }
    transition pinged on ping(label, _): running -> running {
        call P.c(label)
        emit ack
    }
    transition expire on tock: running, up -> done {
        call P.a()
    }
    transition panicking on panic: running -> running {
        emit boom
        emit ack
    }
    transition stop on boom: running -> done
}
"#;

fn project() -> CompiledProject {
    let (_, c, d, _) = from_sources(MANIFEST, &[("a.pn", NETS)]);
    assert!(!d.has_errors(), "{d:?}");
    c.unwrap()
}

fn run(text: &str) -> RunOutcome {
    let p = project();
    let script = parse_script(text, &p).unwrap_or_else(|e| panic!("{e:?}"));
    run_script(&p, &script, |_| {})
}

/// The script runs to its end with every expectation met.
fn passes(text: &str) -> Vec<Json> {
    let out = run(text);
    assert!(out.failure.is_none(), "{text}\n{:?}", out.failure);
    out.steps
}

/// The script fails at `line`; the message is returned.
fn fails_at(text: &str, line: usize) -> String {
    let out = run(text);
    let (n, msg) = out
        .failure
        .unwrap_or_else(|| panic!("expected a failure at line {line}:\n{text}"));
    assert_eq!(n, line, "{msg}");
    msg
}

/// The script does not read; the errors are returned, as (line, message).
fn errors(text: &str) -> Vec<(usize, String)> {
    let e = parse_script(text, &project()).expect_err(text);
    e.into_iter().map(|e| (e.line, e.message)).collect()
}

fn one_error(text: &str, line: usize, needle: &str) {
    let e = errors(text);
    assert!(
        e.iter().any(|(n, m)| *n == line && m.contains(needle)),
        "expected `{needle}` at line {line}, got {e:?}"
    );
}

#[test]
fn outcome_expectations_speak_of_the_timed_lines_own_event() {
    // `go`'s cascade ends with `ack`, unused: the line's event is `go`, processed.
    passes("0 go\nexpect processed\nexpect not unused\nexpect not refused\n");
    let msg = fails_at("0 go\nexpect unused\n", 2);
    assert_eq!(
        msg,
        "expected event `go` (line 1) unused\n  found: processed"
    );
    passes("0 go\n1 late\nexpect unused\n");
    let msg = fails_at("0 go\n1 late\n\nexpect processed\n", 4);
    assert_eq!(
        msg,
        "expected event `late` (line 2) processed\n  found: unused"
    );
    let msg = fails_at("0 go\n1 late\nexpect not unused\n", 3);
    assert!(
        msg.starts_with("expected event `late` (line 2) not unused"),
        "{msg}"
    );
}

#[test]
fn refused_after_a_catastrophic_event_at_submission_and_in_the_queue() {
    // `panic` is processed; `boom` ends the mission; the `ack` queued with it is refused when
    // taken; `late` is refused when submitted.
    let steps = passes(
        "0 go\n1 panic\nexpect processed\nexpect call P.c(_) since start\n2 late\nexpect refused\n",
    );
    let refused: Vec<&Json> = steps.iter().filter(|s| s["outcome"] == "refused").collect();
    assert_eq!(refused.len(), 2, "{steps:#?}");
    assert_eq!(refused[0]["event"], "ack");
    assert_eq!(refused[1]["event"], "late");
    for s in &refused {
        let reason = s["reason"].as_str().unwrap();
        assert!(
            reason.contains("a catastrophic event ended the mission"),
            "{s}"
        );
        // The reason is not an action: actions are what the engine did.
        assert!(s["actions"].as_array().unwrap().is_empty(), "{s}");
    }
    let msg = fails_at("0 go\n1 panic\n2 late\nexpect processed\n", 4);
    assert!(
        msg.starts_with("expected event `late` (line 3) processed\n  found: refused: event `late` refused: a catastrophic event ended the mission"),
        "{msg}"
    );
    let msg = fails_at("0 go\nexpect refused\n", 2);
    assert_eq!(
        msg,
        "expected event `go` (line 1) refused\n  found: processed"
    );
}

#[test]
fn the_json_outcome_is_the_journals_word_and_what_expect_reads() {
    let steps = passes("0 go\n1 late\n2 panic\n3 late\n");
    let words: Vec<&str> = Outcome::ALL.iter().map(|o| o.name()).collect();
    assert_eq!(words, ["processed", "unused", "refused"]);
    for (o, s) in [
        (Outcome::Processed, StepOutcome::Processed),
        (Outcome::Unused, StepOutcome::Unused),
        (Outcome::Refused, StepOutcome::RefusedAfterCatastrophic),
    ] {
        assert_eq!(outcome_name(s), o.name());
        assert_eq!(Outcome::from_name(o.name()), Some(o));
    }
    assert_eq!(steps[0]["outcome"], "start");
    for s in &steps[1..] {
        let word = s["outcome"].as_str().unwrap();
        assert!(words.contains(&word), "{s}");
        assert_eq!(s["reason"].is_null(), word != "refused", "{s}");
        for key in [
            "time", "line", "event", "params", "fired", "actions", "timers", "marking",
        ] {
            assert!(s.get(key).is_some(), "{key} missing in {s}");
        }
    }
    // Every word reads as an expectation.
    for w in words {
        assert!(parse_script(&format!("0 go\nexpect {w}\n"), &project()).is_ok());
    }
}

#[test]
fn steps_carry_their_timed_line_and_the_start_is_processed_at_time_zero() {
    let steps = passes("# comment\n\n0 go\n15 late\n");
    // start, then `hello` emitted by the start's immediate transition, at time 0, no line.
    assert_eq!(steps[1]["event"], "hello");
    assert_eq!(steps[1]["time"], 0.0);
    assert!(steps[1]["line"].is_null());
    let go = steps.iter().find(|s| s["event"] == "go").unwrap();
    assert_eq!(go["line"], 3);
    assert_eq!(go["timers"]["t"], 10.0);
    // The timer expires at its own time, as part of the next timed line.
    let tock = steps.iter().find(|s| s["event"] == "tock").unwrap();
    assert_eq!(
        (tock["time"].as_f64(), tock["line"].as_u64()),
        (Some(10.0), Some(4))
    );
    // What the start emitted is seen before the first timed line.
    passes("expect emit hello\n0 go\nexpect not emit hello\nexpect emit hello since start\n");
}

#[test]
fn expect_always_holds_now_and_after_every_later_step() {
    passes("expect always not A.done\n0 go\n1 tick(3)\n");
    passes("expect never A.done and global.up\n0 go\n20 wait\nexpect A.done\n");
    // Broken by the timer's step at 10 s, during line 4: reported at the `expect` line.
    let msg = fails_at(
        "0 go\nexpect always active A and not A.done\n5 tick(1)\n20 late\nexpect unused\n",
        2,
    );
    assert!(
        msg.starts_with("expected always active A and not A.done (from line 2 on)\n  found: broken at 10 by the step of `tock` (timed line 4): marking A{done}"),
        "{msg}"
    );
    // Checked at once, too.
    let msg = fails_at("expect always A.running\n", 1);
    assert!(
        msg.starts_with(
            "expected always A.running\n  found: it does not hold now, at 0: marking A{idle}"
        ),
        "{msg}"
    );
    let msg = fails_at("0 go\nexpect never A.running implies global.up\n", 2);
    assert!(
        msg.starts_with("expected never A.running implies global.up"),
        "{msg}"
    );
    // A later expectation's failure stays its own.
    fails_at("expect always true\n0 go\nexpect A.done\n", 3);
}

#[test]
fn expect_always_errors_name_their_line() {
    one_error(
        "0 go\nexpect always A.nowhere\n",
        2,
        "unknown place `A.nowhere`",
    );
    one_error("expect always active B\n", 1, "unknown net `B`");
    one_error("expect always A.done and\n", 1, "is not a formula");
    one_error(
        "expect not always A.done\n",
        1,
        "`not always` does not read",
    );
    one_error("expect never\n", 1, "needs a formula");
}

#[test]
fn expect_emit_with_wildcards_and_without_parameters() {
    passes(
        "0 go\nexpect emit ping(\"hello\", _)\nexpect emit ping(_, 2.5)\nexpect emit ping\nexpect emit ack\nexpect not emit ping(\"bye\", _)\n",
    );
    let msg = fails_at("0 go\nexpect emit ping(\"bye\", _)\n", 2);
    assert_eq!(
        msg,
        "expected emit ping(\"bye\", _)\n  found: emits ping(\"hello\", 2.5), ack"
    );
    let msg = fails_at("0 go\n1 late\nexpect emit ack\n", 3);
    assert_eq!(msg, "expected emit ack\n  found: no emission since line 2");
    let msg = fails_at("0 go\nexpect not emit ack\n", 2);
    assert!(msg.starts_with("expected not emit ack\n"), "{msg}");
    one_error("0 go\nexpect emit pong\n", 2, "unknown event `pong`");
    one_error(
        "0 go\nexpect emit ping(1)\n",
        2,
        "takes 2 argument(s), 1 given",
    );
    one_error(
        "0 go\nexpect emit ping(1, 2)\n",
        2,
        "argument `label` of `ping` is text",
    );
    one_error("0 go\nexpect emit ack to A\n", 2, "not checked");
    one_error("0 go\nexpect emit ping(\n", 2, "is not an event");
}

#[test]
fn expect_timer_running_and_its_deadline() {
    passes(
        "expect not timer t\n2 go\nexpect timer t\nexpect timer t expires at 12\nexpect not timer t expires at 11\n20 wait\nexpect not timer t\n",
    );
    let msg = fails_at("2 go\nexpect timer t expires at 11.5\n", 2);
    assert_eq!(
        msg,
        "expected timer t running, expiring at 11.5\n  found: running t (expires at 12)"
    );
    let msg = fails_at("0 go\n20 wait\nexpect timer t\n", 3);
    assert_eq!(
        msg,
        "expected timer t running\n  found: no timer running at 20"
    );
    let msg = fails_at("0 go\nexpect not timer t\n", 2);
    assert!(msg.starts_with("expected not timer t running\n"), "{msg}");
    one_error("expect timer u\n", 1, "unknown timer `u`");
    // Deadlines read as timed lines' times do.
    one_error(
        "expect timer t expires at -1\n",
        1,
        "`-1` is not a time: a time is a number of seconds from 0",
    );
    one_error(
        "expect timer t expires at 1e400\n",
        1,
        "`1e400` is not a time",
    );
    one_error("expect timer t expires at NaN\n", 1, "`NaN` is not a time");
    one_error("expect timer t at 3\n", 1, "expected `timer NAME` or");
}

#[test]
fn expect_counts_of_calls_and_emits_since_the_line_or_the_start() {
    passes(concat!(
        "0 go\n",
        "expect 2 calls P.b(_)\nexpect 1 call P.b(2)\nexpect 0 calls P.b(3)\nexpect 1 emits ack\n",
        "1 tick(5)\n",
        "expect 1 calls P.b(_)\nexpect 3 calls P.b(_) since start\nexpect 0 calls P.a()\n",
        "expect 1 emits ack since start\nexpect 0 emits ack\n",
    ));
    let msg = fails_at("0 go\nexpect 3 calls P.b(_)\n", 2);
    assert_eq!(
        msg,
        "expected 3 calls P.b(_) since line 1\n  found: 2, among calls P.a(), P.b(1), P.b(2), P.c(\"hello\")"
    );
    let msg = fails_at("0 go\n1 tick(5)\nexpect 2 calls P.b(_) since start\n", 3);
    assert!(
        msg.starts_with("expected 2 calls P.b(_) since the start\n  found: 3, among"),
        "{msg}"
    );
    let msg = fails_at("0 go\nexpect not 2 calls P.b(_)\n", 2);
    assert!(msg.starts_with("expected not 2 calls P.b(_)"), "{msg}");
    one_error("expect -1 calls P.a()\n", 1, "`-1` is not a count");
    one_error("expect 1.5 calls P.a()\n", 1, "`1.5` is not a count");
    one_error(
        "expect 99999999999999999999999 calls P.a()\n",
        1,
        "is not a count",
    );
    one_error("expect 2 A.done\n", 1, "a count is followed by");
    one_error(
        "expect 2 calls P.a() then P.a()\n",
        1,
        "a count goes with one",
    );
    one_error("expect 2 calls Q.a()\n", 1, "unknown program `Q`");
    one_error(
        "expect 2 calls P.z()\n",
        1,
        "program `P` has no function `z`",
    );
    one_error("expect 2 calls P.b()\n", 1, "takes 1 argument(s), 0 given");
}

#[test]
fn expect_call_keeps_its_meaning_and_may_look_since_the_start() {
    passes("0 go\nexpect call P.b(2)\nexpect call P.c(\"hello\")\n1 tick(7)\nexpect call P.b(7)\nexpect not call P.a()\nexpect call P.a() since start\n");
    let msg = fails_at("0 go\n1 tick(7)\nexpect call P.a()\n", 3);
    assert_eq!(msg, "expected call P.a()\n  found: calls P.b(7)");
    let msg = fails_at("0 go\n1 late\nexpect call P.a()\n", 3);
    assert_eq!(msg, "expected call P.a()\n  found: no call since line 2");
    let msg = fails_at("0 go\nexpect call P.b(9) since start\n", 2);
    assert!(
        msg.starts_with("expected call P.b(9) since the start\n  found: calls P.a(), "),
        "{msg}"
    );
}

#[test]
fn expect_order_of_calls_and_of_emits() {
    passes(concat!(
        "0 go\n",
        "expect calls P.a() then P.b(2)\n",
        "expect call P.a() then call P.b(_) then call P.c(_)\n",
        "expect calls P.b(_) then P.b(_) then P.c(_)\n",
        "expect not calls P.b(1) then P.b(1)\n",
        "expect emits ping then ack\n",
        "expect not calls P.b(2) then P.b(1)\n",
        "1 tick(4)\n",
        "expect calls P.c(_) then P.b(4) since start\n",
    ));
    let msg = fails_at("0 go\nexpect calls P.b(2) then P.b(1)\n", 2);
    assert_eq!(
        msg,
        "expected calls P.b(2) then P.b(1) in this order since line 1\n  found: calls P.a(), P.b(1), P.b(2), P.c(\"hello\") (no P.b(1) after P.b(2))"
    );
    let msg = fails_at("0 go\nexpect emits ack then ping\n", 2);
    assert!(msg.ends_with("(no ping after ack)"), "{msg}");
    let msg = fails_at("0 go\n1 tick(4)\nexpect calls P.c(_) then P.b(4)\n", 3);
    assert!(msg.ends_with("found: calls P.b(4) (no P.c(_))"), "{msg}");
    // `then` inside a text is text.
    passes("0 go\nexpect not call P.c(\"a then b\")\n");
    one_error(
        "expect calls P.a() then emit ack\n",
        1,
        "an order lists calls only",
    );
    one_error("expect calls P.a() then\n", 1, "expected a call");
    one_error("expect calls then P.a()\n", 1, "expected a call");
    one_error("expect calls P.a() then P.q()\n", 1, "has no function `q`");
}

#[test]
fn places_transitions_and_activity_still_read_and_name_the_line() {
    passes("0 go\nexpect A.running\nexpect A.start\nexpect global.up\nexpect active A\nexpect not inactive A\n");
    let msg = fails_at("0 go\n1 late\nexpect A.start\n", 3);
    assert_eq!(
        msg,
        "expected transition A.start fired since line 2\n  found: nothing fired"
    );
    let msg = fails_at("0 go\nexpect not A.running\n", 2);
    assert!(
        msg.starts_with(
            "expected not place A.running marked\n  found: marking A{running} global{up}"
        ),
        "{msg}"
    );
}

#[test]
fn reading_errors_each_name_their_line() {
    one_error("expect unused\n0 go\n", 1, "there is none yet");
    one_error("0 go\n5 wait\nexpect refused\n", 3, "line 2 is a `wait`");
    one_error("expect\n", 1, "`expect` alone");
    one_error("expect nothing\n", 1, "expected `NET.place`");
    one_error("expect B.x\n", 1, "unknown net `B`");
    one_error("expect A.x\n", 1, "net `A` has no place or transition `x`");
    one_error("expect active B\n", 1, "unknown net `B`");
    one_error("expect global.nope\n", 1, "no global place `nope`");
    // A keyword alone says what it needs.
    one_error("expect timer\n", 1, "`expect timer` needs a timer");
    one_error("expect never\n", 1, "`expect never` needs a formula");
    one_error("expect not\n", 1, "`expect not` needs an expectation");
    one_error(
        "expect 3 calls\n",
        1,
        "expected a call such as `GUI.roll()`",
    );
    one_error("expect 3\n", 1, "found nothing");
    one_error("expect not not A.idle\n", 1, "`not not` does not read");
    // Several errors: each on its line; a timed line that does not read gives no second error.
    let e = errors("0 gone\nexpect processed\nexpect timer\n");
    assert_eq!(
        e.iter().map(|(n, _)| *n).collect::<Vec<_>>(),
        [1, 3],
        "{e:?}"
    );
}

// Mission scripts (and `petrel send`, which reads its event as a script line): numbers are read
// exactly or refused, times are numbers of seconds, nesting is bounded (issue 10, item 5).

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
            e[0].message.clone()
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

/// Before: `expect refused EVENT` did not read; a refusal of an event a net emitted after a
/// catastrophic one was visible only in the JSON lines.
#[test]
fn a_refusal_of_any_step_is_expectable_with_its_event() {
    // `panic` emits `boom` (catastrophic, processed) and `ack`, refused after it.
    passes("0 go\n1 panic\nexpect processed\nexpect refused ack\nexpect not refused boom\n");
    passes("0 go\n1 panic\n2 wait\nexpect not refused ack\nexpect refused ack since start\n");
    // The line's own event, refused, is one too.
    passes("0 go\n1 panic\n2 tick(1)\nexpect refused\nexpect refused tick\n");
    let msg = fails_at("0 go\n1 panic\nexpect refused go\n", 3);
    assert!(
        msg.starts_with("expected refused go since line 2\n  found: refused ack (")
            && msg.contains("catastrophic"),
        "{msg}"
    );
    one_error(
        "0 go\nexpect refused ak\n",
        2,
        "unknown event `ak`: did you mean `ack`?",
    );
    one_error(
        "0 go\nexpect refused ack now\n",
        2,
        "expected `refused`, `refused EVENT`",
    );
}

const SAFETY_NETS: &str = r#"
net A {
    place idle = 1
    place full = 1
    transition fill on go: idle -> full
}
"#;

/// Before: `expect emit safety_violation` found nothing: only events emitted by nets were
/// counted, not the built-in events the engine raises about a step.
#[test]
fn the_built_in_events_the_engine_raises_are_expectable_as_emissions() {
    let (_, c, d, _) = from_sources(MANIFEST, &[("a.pn", SAFETY_NETS)]);
    assert!(!d.has_errors(), "{d:?}");
    let p = c.unwrap();
    let text = "0 go\nexpect emit safety_violation(\"A\", \"fill\", _)\n\
                expect 1 emits safety_violation\nexpect not emit livelock\n";
    let script = parse_script(text, &p).unwrap_or_else(|e| panic!("{e:?}"));
    let out = run_script(&p, &script, |_| {});
    assert!(out.failure.is_none(), "{:?}", out.failure);
}

/// Before: an unknown name had no hint and an error no column.
#[test]
fn a_misspelt_name_gets_a_hint_and_the_error_its_column() {
    let e = parse_script("  0 pingg(\"a\", 1)\nexpect  timer tt\n", &project()).unwrap_err();
    let shown: Vec<String> = e.iter().map(ToString::to_string).collect();
    assert_eq!(
        shown,
        [
            "1:5: unknown event `pingg`: did you mean `ping`?",
            "2:15: unknown timer `tt`: did you mean `t`?",
        ]
    );
    one_error("expect A.runing\n", 1, "did you mean `running`?");
    one_error(
        "expect active AA\n",
        1,
        "unknown net `AA`: did you mean `A`?",
    );
    one_error("expect call P.aa()\n", 1, "did you mean `a`?");
    one_error(
        "expect call PP.a()\n",
        1,
        "unknown program `PP`: did you mean `P`?",
    );
    // Nothing quoted that stands in the line: the column of what follows `expect`.
    let e = parse_script("0 go\n  expect  2 calls\n", &project()).unwrap_err();
    assert_eq!((e[0].line, e[0].column), (2, 11), "{e:?}");
}
