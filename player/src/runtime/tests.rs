use super::*;
use crate::ack::Ledger;
use crate::engine::Engine;
use crate::journal::Journal;
use crate::record::{marked_places, place_changes, StepRecord};
use crate::sizing::status_bound;
use crate::status::{status_json, StatusSnapshot};
use petrel_ipc::{Heartbeat, Origin};

fn project() -> CompiledProject {
    let manifest = "[project]\nname = \"p\"\nfiles = [\"a.pn\"]\nstart = [\"A\", \"B\"]\n\n[globals]\ng_one = 1\n\n[events]\ngo = { category = \"nominal\" }\n";
    let net = "net A {\n    place a_very_long_place_name_one = 1\n    place two = 1\n    transition t on go: two -> two\n}\nnet B {\n    place b = 1\n    transition u on go: b -> b\n}\n";
    let (_, c, d, _) = petrel_nets::project::from_sources(manifest, &[("a.pn", net)]);
    assert!(!d.has_errors(), "{d:?}");
    c.unwrap()
}

#[test]
fn the_journal_s_fired_names_are_the_record_s() {
    let p = project();
    let mut engine = Engine::new(&p);
    let mut record = StepRecord::new(&p).without_calls();
    engine.start(0, &mut record);
    record.clear();
    engine.submit(p.event_id("go").unwrap(), vec![]).unwrap();
    engine.step(&mut record).unwrap();
    let names = record.fired_names();
    assert_eq!(names, ["A.t", "B.u"]);
    let config = bincode::config::standard();
    assert_eq!(
        bincode::encode_to_vec(record.fired_encoded(), config).unwrap(),
        bincode::encode_to_vec(&names, config).unwrap()
    );
    // The next step's record starts empty, whatever it keeps for reuse.
    record.clear();
    assert!(record.taken.is_none() && record.fired.is_empty() && record.actions.is_empty());
}

#[test]
fn the_status_never_exceeds_its_bound() {
    let p = project();
    let bound = status_bound(&p);
    let mut engine = Engine::new(&p);
    engine.start(0, &mut crate::engine::NullSink);
    let mut ledger = Ledger::new();
    // More senders than a heartbeat carries, with origins that escape the most.
    for i in 0..200u64 {
        let origin: String = format!("{i:03}")
            .chars()
            .chain((3..32).map(|k| char::from(((i + k) % 31 + 1) as u8)))
            .collect();
        ledger.taken(i, Origin::new(&origin), u64::MAX, u64::MAX / 2);
    }
    let report = PlayReport {
        messages: u64::MAX,
        heartbeats_refused: u64::MAX,
        ..PlayReport::default()
    };
    let journal = Journal::new(None);
    let json = status_json(&StatusSnapshot::of(&engine, &report, &ledger, &journal));
    assert!(json.len() <= bound, "{} > {bound}", json.len());
    let doc: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(doc["marking"]["A"].as_array().map(Vec::len), Some(2));
    assert_eq!(doc["senders"].as_object().map(|m| m.len()), Some(64));
    assert!(Heartbeat::max_encoded_len(bound) < petrel_ipc::wire::MAX_BODY_LEN);
}

#[test]
fn place_changes_name_what_the_two_markings_differ_in() {
    let p = project();
    let engine = Engine::new(&p);
    let layout = engine.layout();
    let words = engine.state().len();
    // Pseudo-random markings (every bit pattern of the places matters, not realism).
    let mut seed = 0x9e37_79b9_7f4a_7c15u64;
    let mut state = || -> Vec<u64> {
        (0..words)
            .map(|_| {
                seed ^= seed << 13;
                seed ^= seed >> 7;
                seed ^= seed << 17;
                seed
            })
            .collect()
    };
    for _ in 0..200 {
        let (before, after) = (state(), state());
        let (b, a) = (
            marked_places(&p, layout, &before),
            marked_places(&p, layout, &after),
        );
        let expected_marked: Vec<_> = a.iter().filter(|x| !b.contains(x)).cloned().collect();
        let expected_unmarked: Vec<_> = b.iter().filter(|x| !a.contains(x)).cloned().collect();
        let (marked, unmarked) = place_changes(&p, layout, &before, &after);
        assert_eq!(marked, expected_marked);
        assert_eq!(unmarked, expected_unmarked);
    }
}
