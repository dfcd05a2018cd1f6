//! can.toml: the checker's diagnostics, and the rules driven in virtual time.

mod common;

use common::{check, codes, config, dbc};
use petrel_can_bridge::bridge::BridgeCore;
use petrel_can_bridge::config::RuleKind;
use petrel_can_bridge::event::{EventCause, EventOut};
use petrel_can_bridge::frame::Frame;
use petrel_can_bridge::Dbc;
use petrel_nets::compiled::Value;

const MS: u64 = 1000;

fn frame(dbc: &Dbc, msg: &str, values: &[(&str, f64)]) -> Frame {
    dbc.encode(msg, values).unwrap()
}

fn depth(dbc: &Dbc, m: f64) -> Frame {
    frame(dbc, "Depth", &[("depth", m), ("status", 0.0)])
}

fn names(events: &[EventOut]) -> Vec<(u64, String, Vec<Value>)> {
    events
        .iter()
        .map(|e| (e.time_us, e.name.clone(), e.params.clone()))
        .collect()
}

/// A core over the bench configuration without the stale rules and the heartbeat (tests of one
/// rule at a time stay quiet), started at 0.
fn core_without_staleness() -> BridgeCore {
    let mut c = config();
    c.rules
        .retain(|r| !matches!(r.kind, RuleKind::Stale { .. }));
    c.heartbeat = None;
    BridgeCore::new(dbc(), c, 0)
}

#[test]
fn the_bench_configuration_checks_clean() {
    let (c, diags) = check(&common::can_toml()).unwrap();
    assert!(diags.is_empty(), "{diags:?}");
    assert_eq!(c.rules.len(), 6);
    assert_eq!(c.dbc_path.as_deref(), Some("auv.dbc"));
    assert_eq!(c.interface.as_deref(), Some("vcan0"));
    assert_eq!(c.bus.state_event.as_deref(), Some("bus_fault"));
    let hb = c.heartbeat.as_ref().unwrap();
    assert_eq!(hb.period_us, 100 * MS);
    assert_eq!(c.commands.program.as_deref(), Some("CAN"));
    // Staleness of Depth: 3 periods of its GenMsgCycleTime (100 ms).
    assert!(matches!(
        c.rules[2].kind,
        RuleKind::Stale {
            timeout_us: 300_000,
            ..
        }
    ));
}

#[test]
fn load_project_can_reads_the_dbc_it_names() {
    let mut sources = petrel_diag::source::SourceMap::new();
    let mut diags = petrel_diag::report::Diagnostics::new();
    let got = petrel_can_bridge::load_project_can(
        &common::data("auv"),
        &common::project(),
        &mut sources,
        &mut diags,
    )
    .unwrap();
    assert!(diags.is_empty(), "{}", diags.render_human(&sources));
    let (config, dbc) = got.unwrap();
    assert_eq!(config.rules.len(), 6);
    assert_eq!(dbc.messages().len(), 12);
    // A project without can.toml has nothing to check.
    let none = petrel_can_bridge::load_project_can(
        &common::data(""),
        &common::project(),
        &mut sources,
        &mut diags,
    )
    .unwrap();
    assert!(none.is_none());
}

#[test]
fn a_broken_dbc_is_reported_where_it_breaks() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("can.toml"), "dbc = \"bad.dbc\"\n").unwrap();
    std::fs::write(
        dir.path().join("bad.dbc"),
        "VERSION \"\"\nNS_ :\nBS_:\nBU_: A\nBO_ 16 M: 1 A\n SG_ s : 4|8@1+ (1,0) [0|1] \"\" A\n",
    )
    .unwrap();
    let mut sources = petrel_diag::source::SourceMap::new();
    let mut diags = petrel_diag::report::Diagnostics::new();
    let got = petrel_can_bridge::load_project_can(
        dir.path(),
        &common::project(),
        &mut sources,
        &mut diags,
    )
    .unwrap();
    assert!(got.is_none());
    assert_eq!(codes(&diags), ["E0702"]);
    let text = diags.render_human(&sources);
    assert!(text.contains("signal `M.s` needs 2 bytes"), "{text}");
    assert!(text.contains("bad.dbc:6"), "{text}");
    // A missing DBC, at the `dbc` value.
    std::fs::write(dir.path().join("can.toml"), "dbc = \"none.dbc\"\n").unwrap();
    let mut diags = petrel_diag::report::Diagnostics::new();
    petrel_can_bridge::load_project_can(dir.path(), &common::project(), &mut sources, &mut diags)
        .unwrap();
    assert_eq!(codes(&diags), ["E0702"]);
    assert_eq!(diags.iter().next().unwrap().span.unwrap().start, 6);
}

/// One diagnostic: its code and its rendering.
fn only_error(text: &str) -> (&'static str, String) {
    let (diags, rendered) = check(text).map(|_| ()).unwrap_err();
    let list: Vec<_> = diags.iter().collect();
    assert_eq!(list.len(), 1, "{rendered}");
    (list[0].code, rendered)
}

#[test]
fn every_mistake_has_its_code_and_its_place() {
    let rule = |body: &str| format!("dbc = \"x.dbc\"\n[[rule]]\n{body}\n");
    let cases: &[(&str, &str, &str)] = &[
        ("E0701", "dbc = \"x.dbc\"\n[[rule]]\nevent = \"leak\"\nkind = \"edge\"\nsignal = \"Leak.leak\"\nequals = 1\ncolour = \"red\"\n", "unknown field `colour`"),
        ("E0703", &rule("event = \"leak\"\nkind = \"edge\"\nsignal = \"Leak.leek\"\nequals = 1"), "did you mean `leak`?"),
        ("E0703", &rule("event = \"leak\"\nkind = \"edge\"\nsignal = \"Laek.leak\"\nequals = 1"), "did you mean `Leak`?"),
        ("E0703", &rule("event = \"leak\"\nkind = \"edge\"\nsignal = \"leak\"\nequals = 1"), "name the message too: did you mean `Leak.leak`?"),
        ("E0704", &rule("event = \"leek\"\nkind = \"edge\"\nsignal = \"Leak.leak\"\nequals = 1"), "did you mean `leak`?"),
        ("E0705", &rule("event = \"depth_reached\"\nkind = \"threshold\"\nsignal = \"Depth.depth\"\nabove = 30"), "event `depth_reached` takes 1 parameter, the rule gives 0"),
        ("E0705", &rule("event = \"leak\"\nkind = \"edge\"\nsignal = \"Leak.leak\"\nequals = 1\nparams = [1]"), "takes 0 parameters, the rule gives 1"),
        ("E0706", &rule("event = \"sensor_lost\"\nkind = \"stale\"\nmessage = \"Depth\"\nparams = [3]"), "parameter `name` of event `sensor_lost` is text, the rule gives an int"),
        ("E0706", &rule("event = \"thruster_fault\"\nkind = \"edge\"\nsignal = \"ThrusterStatus.fault\"\nequals = 1\nparams = [{ text = \"x\" }]"), "is bool, the rule gives a text"),
        ("E0707", &rule("event = \"leak\"\nkind = \"debounce\"\nsignal = \"Leak.leak\"\nequals = 1\nfor = \"200 parsecs\""), "`200 parsecs` is not a valid hold time"),
        ("E0707", &rule("event = \"sensor_lost\"\nkind = \"stale\"\nmessage = \"Depth\"\ntimeout = \"0s\"\nparams = [{ text = \"d\" }]"), "not a positive duration"),
        ("E0708", &rule("event = \"leak\"\nkind = \"debounce\"\nsignal = \"Leak.leak\"\nequals = 1"), "needs `for`"),
        ("E0708", &rule("event = \"leak\"\nkind = \"treshold\"\nsignal = \"Leak.leak\"\nabove = 1"), "did you mean `threshold`?"),
        ("E0708", &rule("event = \"leak\"\nkind = \"threshold\"\nsignal = \"Leak.leak\"\nabove = 1\nwithin = 2"), "`within` does not apply to a `threshold` rule"),
        ("E0708", &rule("event = \"leak\"\nkind = \"threshold\"\nsignal = \"Leak.leak\"\nabove = 1\nhysteresis = -1"), "hysteresis -1 is not a non-negative number"),
        ("E0708", &rule("event = \"leak\"\nkind = \"edge\"\nsignal = \"Leak.leak\"\nabove = 1\nedge = \"up\""), "unknown edge `up`"),
        ("E0708", &rule("event = \"leak\"\nkind = \"edge\"\nsignal = \"Leak.leak\"\nabove = 1\nbelow = 0"), "this one has above and below"),
        ("E0708", &rule("event = \"sensor_lost\"\nkind = \"stale\"\nmessage = \"Depth\"\nfor = \"1s\"\nparams = [{ text = \"d\" }]"), "`for` does not apply to a `stale` rule"),
        ("E0709", &rule("event = \"sensor_lost\"\nkind = \"stale\"\nmessage = \"DepthCmd\"\nparams = [{ text = \"d\" }]"), "message `DepthCmd` has no period"),
        ("E0710", &rule("event = \"leak\"\nkind = \"edge\"\nsignal = \"Battery.state\"\nequals = \"charing\""), "did you mean `charging`?"),
    ];
    for (code, text, needle) in cases {
        let (got, rendered) = only_error(text);
        assert_eq!(got, *code, "{rendered}");
        assert!(
            rendered.contains(needle),
            "expected `{needle}` in:\n{rendered}"
        );
        assert!(rendered.contains("can.toml:"), "no location:\n{rendered}");
    }
}

#[test]
fn bus_heartbeat_and_commands_are_checked_too() {
    let (code, r) = only_error("[bus]\nstate_event = \"leak\"\n");
    assert_eq!(code, "E0705", "{r}");
    assert!(r.contains("must take one text parameter"), "{r}");
    let (code, r) = only_error("[bus.on_state]\nbus_of = \"bus_lost\"\n");
    assert_eq!(code, "E0708", "{r}");
    assert!(r.contains("did you mean `bus_off`?"), "{r}");
    let (code, r) = only_error("[bus.on_state]\nbus_off = \"bus_fault\"\n");
    assert_eq!(code, "E0705", "{r}");
    let (code, r) = only_error("[bus]\nreceive = \"known\"\n");
    assert_eq!(code, "E0708", "{r}");
    assert!(
        r.contains("`receive = \"known\"` in [bus]: not a choice"),
        "{r}"
    );
    assert!(r.contains("receive = \"dbc\""), "{r}");
    let (code, r) =
        only_error("[heartbeat]\nmessage = \"SupervisorHeartbeat\"\ncounter = \"alive\"\n");
    assert_eq!(code, "E0708", "{r}");
    assert!(
        r.contains("heartbeat signal `SupervisorHeartbeat.mode` has no value"),
        "{r}"
    );
    let (code, r) = only_error("[heartbeat]\nmessage = \"SupervisorHeartbeat\"\ncounter = \"alive\"\nsignals = { mode = 7 }\n");
    assert_eq!(code, "E0708", "{r}");
    assert!(r.contains("outside its range"), "{r}");
    let (code, r) = only_error("[heartbeat]\nmessage = \"DepthCmd\"\nsignals = { target = 1 }\n");
    assert_eq!(code, "E0709", "{r}");
    let (code, r) = only_error("[commands]\nmessages = [\"ThrusterCmd\", \"Thruster\"]\n");
    assert_eq!(code, "E0703", "{r}");
    // The project's CAN program declares DepthCmd: it must be a command message.
    let (code, r) = only_error("[commands]\nmessages = [\"ThrusterCmd\"]\nprogram = \"CAN\"\n");
    assert_eq!(code, "E0703", "{r}");
    assert!(
        r.contains("function `CAN.DepthCmd` of the project is not a command message"),
        "{r}"
    );
}

#[test]
fn unreachable_thresholds_are_warnings() {
    let (c, diags) = check("[[rule]]\nevent = \"low_battery\"\nkind = \"threshold\"\nsignal = \"Battery.voltage\"\nbelow = -1\nparams = [\"Battery.voltage\", \"Battery.state\"]\n").unwrap();
    assert_eq!(codes(&diags), ["W0701"]);
    assert_eq!(c.rules.len(), 1);
}

#[test]
fn threshold_with_hysteresis() {
    let dbc = dbc();
    let mut core = core_without_staleness();
    let battery = |v: f64, state: f64| {
        frame(
            &dbc,
            "Battery",
            &[("voltage", v), ("current", 0.0), ("state", state)],
        )
    };
    let mut seen = Vec::new();
    // below = 22, hysteresis = 0.5: true at <= 22, false again only above 22.5.
    for (t, v) in [
        (0, 23.0),
        (1, 21.9),
        (2, 22.2),
        (3, 21.8),
        (4, 22.4),
        (5, 22.6),
        (6, 23.0),
        (7, 21.9),
    ] {
        seen.extend(core.on_frame(t * MS, &battery(v, 1.0)).events);
    }
    let got = names(&seen);
    assert_eq!(
        got,
        [
            (
                MS,
                "low_battery".to_owned(),
                vec![Value::Float(21.9), Value::Text("discharging".into())]
            ),
            (
                7 * MS,
                "low_battery".to_owned(),
                vec![Value::Float(21.9), Value::Text("discharging".into())]
            ),
        ],
        "{got:?}"
    );
}

#[test]
fn band_around_a_commanded_target() {
    let dbc = dbc();
    let mut core = core_without_staleness();
    // No target yet: no depth is "reached".
    assert!(core.on_frame(0, &depth(&dbc, 30.0)).events.is_empty());
    // The supervisor commands 30 m; the bridge sees its own frame.
    let cmd = core
        .command("DepthCmd", &[("target", Value::Float(30.0))])
        .unwrap();
    assert_eq!(cmd.payload(), &[0xB8, 0x0B]); // 30.00 / 0.01 = 3000 = 0x0BB8, LE
    let at_target = core.on_sent(MS, &cmd);
    // Already at 30 m when the target arrives: reached at once.
    assert_eq!(names(&at_target)[0].1, "depth_reached");
    let mut seen = Vec::new();
    // within 0.5, hysteresis 0.2: leaves the band beyond 0.7 only.
    for (t, m) in [
        (2, 30.6),
        (3, 30.8),
        (4, 30.3),
        (5, 29.4),
        (6, 29.2),
        (7, 29.6),
    ] {
        seen.extend(core.on_frame(t * MS, &depth(&dbc, m)).events);
    }
    let got: Vec<(u64, f64)> = seen
        .iter()
        .map(|e| match e.params[..] {
            [Value::Float(d)] => (e.time_us, (d * 100.0).round() / 100.0),
            _ => panic!("{e:?}"),
        })
        .collect();
    assert_eq!(got, [(4 * MS, 30.3), (7 * MS, 29.6)]);
}

#[test]
fn debounce_in_virtual_time() {
    let dbc = dbc();
    let mut core = core_without_staleness();
    let leak = |on: bool| {
        frame(
            &dbc,
            "Leak",
            &[("leak", f64::from(u8::from(on))), ("sensor_ok", 1.0)],
        )
    };
    // A bounce shorter than 200 ms: nothing.
    assert!(core.on_frame(0, &leak(true)).events.is_empty());
    assert!(core.on_frame(150 * MS, &leak(false)).events.is_empty());
    assert!(core.on_time(400 * MS).is_empty());
    // Set for good at 1 s: the leak is reported at 1.2 s exactly, whatever the polling.
    assert!(core.on_frame(1000 * MS, &leak(true)).events.is_empty());
    assert!(core.on_frame(1100 * MS, &leak(true)).events.is_empty());
    assert_eq!(core.next_deadline(), Some(1200 * MS));
    assert!(core.on_time(1199 * MS).is_empty());
    let got = core.on_time(5000 * MS);
    assert_eq!(names(&got), [(1200 * MS, "leak".to_owned(), vec![])]);
    assert_eq!(got[0].cause, EventCause::Rule(1));
    // Still set: no repetition.
    assert!(core.on_frame(5100 * MS, &leak(true)).events.is_empty());
    assert!(core.on_time(9000 * MS).is_empty());
}

#[test]
fn staleness_in_virtual_time() {
    let dbc = dbc();
    let mut core = BridgeCore::new(dbc.clone(), config(), 0);
    // Depth arrives every 100 ms until 200 ms; Ahrs never.
    for t in [0, 100, 200] {
        assert!(core.on_frame(t * MS, &depth(&dbc, 1.0)).events.is_empty());
    }
    assert!(core.on_time(499 * MS).is_empty());
    // Both due at 500 ms (Depth: 200 + 3 x 100; Ahrs: start + 500): in rule order.
    let got = core.on_time(500 * MS);
    assert_eq!(
        names(&got),
        [
            (
                500 * MS,
                "sensor_lost".to_owned(),
                vec![Value::Text("depth".into())]
            ),
            (
                500 * MS,
                "sensor_lost".to_owned(),
                vec![Value::Text("ahrs".into())]
            ),
        ]
    );
    // Once.
    assert!(core.on_time(2000 * MS).is_empty());
    // Back at 2 s, lost again at 2.3 s; a late frame's deadline is handled before the frame.
    assert!(core
        .on_frame(2000 * MS, &depth(&dbc, 1.0))
        .events
        .is_empty());
    let got = core.on_frame(2300 * MS, &depth(&dbc, 1.0)).events;
    assert_eq!(
        names(&got),
        [(
            2300 * MS,
            "sensor_lost".to_owned(),
            vec![Value::Text("depth".into())]
        )]
    );
}

#[test]
fn edges_both_ways_with_a_bool_parameter() {
    let dbc = dbc();
    let mut core = core_without_staleness();
    let status = |fault: f64| {
        frame(
            &dbc,
            "ThrusterStatus",
            &[
                ("rpm_left", 0.0),
                ("rpm_right", 0.0),
                ("temperature", 20.0),
                ("fault", fault),
            ],
        )
    };
    let mut seen = Vec::new();
    for (t, f) in [(0, 0.0), (1, 1.0), (2, 1.0), (3, 0.0), (4, 0.0)] {
        seen.extend(core.on_frame(t * MS, &status(f)).events);
    }
    assert_eq!(
        names(&seen),
        [
            (MS, "thruster_fault".to_owned(), vec![Value::Bool(true)]),
            (
                3 * MS,
                "thruster_fault".to_owned(),
                vec![Value::Bool(false)]
            ),
        ]
    );
}

#[test]
fn the_same_input_gives_the_same_events() {
    let dbc = dbc();
    let run = || {
        let mut core = BridgeCore::new(dbc.clone(), config(), 0);
        let mut out = Vec::new();
        for i in 0..200u64 {
            let t = i * 37 * MS;
            out.extend(core.on_frame(t, &depth(&dbc, 40.0 - i as f64 * 0.1)).events);
            out.extend(core.on_time(t + 13 * MS));
        }
        out
    };
    let a = run();
    assert!(!a.is_empty());
    assert_eq!(a, run());
}

#[test]
fn receive_dbc_asks_for_the_dbc_s_identifier_filters() {
    let (c, _) = check("[bus]\nreceive = \"dbc\"\n").unwrap();
    assert!(c.receive_only_dbc);
    let (c, _) = check("[bus]\nreceive = \"all\"\n").unwrap();
    assert!(!c.receive_only_dbc);
    let (c, _) = check("").unwrap();
    assert!(!c.receive_only_dbc);
    // One exact filter a message: standard 0x200 (Depth) and extended NavTime kept apart.
    let filters = dbc().socket_filters();
    assert_eq!(filters.len(), dbc().messages().len());
    assert!(filters.contains(&(0x200, 0x7FF | 0x8000_0000)));
    assert!(filters.contains(&(0x18FF_0100 | 0x8000_0000, 0x1FFF_FFFF | 0x8000_0000)));
}
