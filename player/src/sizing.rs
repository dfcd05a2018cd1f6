//! The sizes of the player's services, from the project: each call sender's ([`call_bound`]),
//! the events service's ([`event_bound`]), the marking publisher's ([`marking_bound`]) and the
//! heartbeat publisher's ([`status_bound`]), so that the messages this project can give fit
//! the fixed samples (docs/benchmarks.md, "Footprint").
//!
//! A call sender is a fixed segment when the program's functions take only fixed-size
//! parameters; the events service records the longest event a process may send (int, float
//! and bool exact, 256 bytes per text or list) for the programs' senders to size theirs from,
//! and takes one sender per program and a few more (`petrel_ipc::EVENT_SENDERS_SPARE`); the
//! marking publisher holds twice the largest snapshot; the heartbeat publisher the largest
//! status, so that no status is ever refused for its size. Longer texts and lists still go, in
//! pieces (`petrel_ipc::wire::FRAGMENT`).

use crate::status::{status_json, StatusSnapshot};
use petrel_ipc::{CallMsg, EventMsg, MarkingMsg};
use petrel_nets::compiled::{CompiledProject, Program, Value};
use petrel_nets::model::Type;

/// The longest call the project can make to `program`, encoded, when its functions take only
/// fixed-size parameters (`None`: text or lists, whose length the project does not bound): the
/// size of the player's call sender to it (docs/benchmarks.md, "Footprint").
pub(crate) fn call_bound(program: &Program) -> Option<usize> {
    let mut bound = 0;
    for function in &program.functions {
        // The longest encoding of each type: a varint takes the most bytes at i64::MIN.
        let args = function
            .params
            .iter()
            .map(|(_, ty)| match ty {
                Type::Int => Some(Value::Int(i64::MIN)),
                Type::Float => Some(Value::Float(f64::MAX)),
                Type::Bool => Some(Value::Bool(true)),
                Type::Text | Type::FloatList => None,
            })
            .collect::<Option<Vec<_>>>()?;
        let len = petrel_ipc::wire::encoded_len(&CallMsg::new(function.name.clone(), args)).ok()?;
        bound = bound.max(len);
    }
    Some(bound)
}

/// What a text or list parameter of an event counts for in [`event_bound`]: 256 bytes (a
/// 256-byte text, 32 floats). Longer ones still go, in pieces (`petrel_ipc::wire::FRAGMENT`).
const TEXT_ALLOWANCE: usize = 256;

/// The longest event a process may send `project`, encoded: the events service records it
/// when the player creates it, and each program's sender sizes its fixed samples from it
/// (docs/benchmarks.md, "Footprint"). Exact for `int`, `float` and `bool` parameters (the
/// longest encoding of each), [`TEXT_ALLOWANCE`] for each text or list; at least 64 bytes.
/// Internal and built-in events are left out: no process sends them (the data server's
/// `call_failed`, short names, fits the senders' 512 bytes at least).
pub(crate) fn event_bound(project: &CompiledProject) -> usize {
    let allowance_floats = TEXT_ALLOWANCE / 8;
    let builtin = |name: &str| {
        petrel_nets::model::builtin_events()
            .iter()
            .any(|b| b.name.text == name)
    };
    project
        .events
        .iter()
        .filter(|e| !e.internal && !builtin(&e.name))
        .filter_map(|e| {
            let params = e
                .params
                .iter()
                .map(|(_, ty)| match ty {
                    Type::Int => Value::Int(i64::MIN),
                    Type::Float => Value::Float(f64::MAX),
                    Type::Bool => Value::Bool(true),
                    Type::Text => Value::Text("x".repeat(TEXT_ALLOWANCE)),
                    Type::FloatList => Value::FloatList(vec![f64::MAX; allowance_floats]),
                })
                .collect();
            petrel_ipc::wire::encoded_len(&EventMsg::new(e.name.clone(), params)).ok()
        })
        .fold(64, usize::max)
}

/// The length of the marking publisher's fixed samples: twice the largest snapshot `project`
/// can give (every place marked, every net active, the longest event's name), at least 1 KiB.
/// Deltas name only what changed and fit with room to spare; a step whose actions or
/// parameters are longer still goes, in pieces (`petrel_ipc::wire::FRAGMENT`).
pub(crate) fn marking_bound(project: &CompiledProject) -> usize {
    let worst = MarkingMsg {
        step: u64::MAX,
        event: project
            .events
            .iter()
            .map(|e| e.name.clone())
            .max_by_key(|n| n.len()),
        fired: Vec::new(),
        marked: project
            .nets
            .iter()
            .flat_map(|n| n.places.iter().map(|p| format!("{}.{}", n.name, p.name)))
            .chain(project.globals.iter().map(|g| format!("global.{}", g.name)))
            .collect(),
        unmarked: Vec::new(),
        activated: project.nets.iter().map(|n| n.name.clone()).collect(),
        deactivated: Vec::new(),
        snapshot: true,
        time_us: u64::MAX,
        params: Vec::new(),
        actions: Vec::new(),
    };
    let snapshot = petrel_ipc::wire::encoded_len(&worst).unwrap_or(0);
    (2 * snapshot).max(1024)
}

/// The length of the largest status JSON `project` can give: every net active with every place
/// marked, the ledger full of senders whose origins need the most escaping, every counter at
/// its largest. The heartbeat's publisher is sized from it, so that no status is ever refused.
pub(crate) fn status_bound(project: &CompiledProject) -> usize {
    let mut marking: Vec<(String, Vec<String>)> = project
        .nets
        .iter()
        .map(|n| {
            (
                n.name.clone(),
                n.places.iter().map(|p| p.name.clone()).collect(),
            )
        })
        .collect();
    marking.push((
        "global".into(),
        project.globals.iter().map(|g| g.name.clone()).collect(),
    ));
    // A control character is escaped in six bytes (`\u0001`), the most any byte takes; the
    // ledger keys senders by id, so that every one of them may show under its own origin:
    // origins of control characters 1 and 2 only, distinct by the bits of their index.
    let origin = |i: usize| -> String {
        (0..petrel_ipc::wire::ORIGIN_LEN)
            .map(|k| char::from(1 + ((i >> (k % 8)) & 1) as u8))
            .collect()
    };
    let worst = StatusSnapshot {
        project: project.name.clone(),
        time_s: -f64::MAX,
        over: false,
        marking: Some(marking),
        stats: [u64::MAX; 16],
        senders: (0..petrel_ipc::wire::MAX_ACKS)
            .map(|i| (origin(i), [u64::MAX; 9]))
            .collect(),
        recorder: (
            "dropping",
            "\u{1}".repeat(petrel_ipc::wire::MAX_REASON_LEN),
            [u64::MAX; 4],
        ),
        version: Some("f".repeat(16)),
        reloading: true,
    };
    status_json(&worst).len()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn programs() -> CompiledProject {
        let manifest = "[project]\nname = \"p\"\nfiles = [\"a.pn\"]\nstart = [\"A\"]\n\n[events]\ngo = { category = \"nominal\" }\n\n[programs.NAV.functions]\ngoto = { params = [\"x: int\", \"speed: float\", \"fast: bool\"] }\nstop = []\n\n[programs.PLN.functions]\nroute = { params = [\"points: [float]\"] }\n\n[programs.LOG.functions]\nsay = { params = [\"what: text\"] }\n";
        let net = "net A {\n    place a = 1\n    transition t on go: a -> a\n}\n";
        let (_, c, d, _) = petrel_nets::project::from_sources(manifest, &[("a.pn", net)]);
        assert!(!d.has_errors(), "{d:?}");
        c.unwrap()
    }

    #[test]
    fn a_call_bound_covers_the_longest_call_and_only_fixed_size_parameters_have_one() {
        let p = programs();
        let program = |name: &str| p.programs.iter().find(|q| q.name == name).unwrap();
        let bound = call_bound(program("NAV")).expect("int, float and bool have a bound");
        // Every extreme of each type encodes within it, the longest exactly at it.
        let mut longest = 0;
        for x in [0, 1, -1, i64::MAX, i64::MIN] {
            for speed in [0.0, f64::MIN, f64::MAX, f64::NAN] {
                for fast in [false, true] {
                    let call = CallMsg::new(
                        "goto",
                        vec![Value::Int(x), Value::Float(speed), Value::Bool(fast)],
                    );
                    let len = petrel_ipc::wire::encoded_len(&call).unwrap();
                    assert!(len <= bound, "{call:?}: {len} > {bound}");
                    longest = longest.max(len);
                }
            }
        }
        assert_eq!(longest, bound);
        assert_eq!(call_bound(program("PLN")), None, "a list has no bound");
        assert_eq!(call_bound(program("LOG")), None, "a text has no bound");
    }

    #[test]
    fn the_event_bound_covers_the_longest_event_a_process_sends_and_leaves_out_built_ins() {
        let manifest = "[project]\nname = \"p\"\nfiles = [\"a.pn\"]\nstart = [\"A\"]\n\n[events]\narrived = { category = \"nominal\", params = [\"x: int\", \"speed: float\", \"fast: bool\"] }\nnote = { category = \"nominal\", params = [\"what: text\", \"xs: [float]\"] }\n";
        let net = "net A {\n    place a = 1\n    transition t on arrived(x, s, f): a -> a\n    transition n on note(w, xs): a -> a\n}\n";
        let (_, c, d, _) = petrel_nets::project::from_sources(manifest, &[("a.pn", net)]);
        assert!(!d.has_errors(), "{d:?}");
        let p = c.unwrap();
        let bound = event_bound(&p);
        let len = |e: EventMsg| petrel_ipc::wire::encoded_len(&e).unwrap();
        let arrived = len(EventMsg::new(
            "arrived",
            vec![
                Value::Int(i64::MIN),
                Value::Float(f64::MAX),
                Value::Bool(true),
            ],
        ));
        let note = len(EventMsg::new(
            "note",
            vec![
                Value::Text("é".repeat(TEXT_ALLOWANCE / 2)),
                Value::FloatList(vec![0.5; TEXT_ALLOWANCE / 8]),
            ],
        ));
        assert!(arrived < bound);
        assert_eq!(note, bound, "a text and a list at their allowance");
        // Built-in events (program_lost, call_failed... with their texts) do not count.
        let only_ints = programs();
        assert_eq!(
            event_bound(&only_ints),
            64,
            "a project of parameterless events"
        );
        // The marking's fixed samples hold a snapshot of every place and net, twice over.
        let snapshot = MarkingMsg {
            step: 1,
            event: Some("note".into()),
            fired: Vec::new(),
            marked: vec!["A.a".into()],
            unmarked: Vec::new(),
            activated: vec!["A".into()],
            deactivated: Vec::new(),
            snapshot: true,
            time_us: 5,
            params: Vec::new(),
            actions: Vec::new(),
        };
        assert!(2 * petrel_ipc::wire::encoded_len(&snapshot).unwrap() <= marking_bound(&p));
    }
}
