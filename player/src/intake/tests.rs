//! Every message answered, every path counted: random mixes of accepted, unused and refused
//! messages (unknown, wrong parameters, built-in, undecodable, foreign, after a catastrophic
//! end, leaves good and bad), with steps of the engine between them.

use super::*;
use crate::engine::NullSink;
use petrel_nets::compiled::{CompiledProject, EventId};
use proptest::prelude::*;
use std::collections::HashMap;

fn project() -> CompiledProject {
    let manifest = "[project]\nname = \"p\"\nfiles = [\"a.pn\"]\nstart = [\"A\"]\n\n[events]\ntick = { category = \"nominal\", params = [\"n: int\"] }\nnoise = { category = \"nominal\" }\ndoom = { category = \"catastrophic\" }\n\n[programs.WORKER]\nfunctions = { work = [\"n: int\"] }\n";
    let net = "net A {\n    place up = 1\n    place over\n    transition t on tick(n): up -> up\n    transition d on doom: up -> over\n}\n";
    let (_, c, d, _) = petrel_nets::project::from_sources(manifest, &[("a.pn", net)]);
    assert!(!d.has_errors(), "{d:?}");
    c.unwrap()
}

/// The parts of a player an intake borrows, the engine started on `p`.
struct Parts<'p> {
    engine: Engine<'p>,
    journal: Journal,
    ledger: Ledger,
    messages: u64,
    bad_messages: u64,
    leaves: BTreeSet<String>,
    bad_message: Option<EventId>,
}

impl<'p> Parts<'p> {
    fn new(p: &'p CompiledProject) -> Self {
        let mut engine = Engine::new(p);
        engine.start(0, &mut NullSink);
        Parts {
            engine,
            journal: Journal::new(None),
            ledger: Ledger::new(),
            messages: 0,
            bad_messages: 0,
            leaves: BTreeSet::new(),
            bad_message: p.event_id("bad_message"),
        }
    }

    fn intake(&mut self) -> Intake<'_, 'p> {
        Intake {
            engine: &mut self.engine,
            journal: &mut self.journal,
            ledger: &mut self.ledger,
            messages: &mut self.messages,
            bad_messages: &mut self.bad_messages,
            bad_message: self.bad_message,
            leaves: &mut self.leaves,
        }
    }
}

/// One thing that happens to the player.
#[derive(Clone, Debug)]
enum Op {
    /// A message from sender `usize` (an index into [`SENDERS`]).
    Message(usize, Msg),
    /// The engine takes up to this many events.
    Steps(u8),
    /// The receiver fails (not a message).
    Failed,
}

#[derive(Clone, Debug)]
enum Msg {
    /// Declared, and a transition waits for it: processed.
    Tick(i64),
    /// Declared, nothing waits for it: unused.
    Noise,
    /// Catastrophic: what comes after is refused.
    Doom,
    Unknown,
    Arity,
    WrongType,
    Builtin,
    Undecodable,
    Foreign,
    Leave,
}

/// The senders: two tools and the project's program.
const SENDERS: [&str; 3] = ["tool/a", "tool/b", "program/WORKER"];

fn msg() -> impl Strategy<Value = Msg> {
    prop_oneof![
        6 => any::<i64>().prop_map(Msg::Tick),
        4 => Just(Msg::Noise),
        1 => Just(Msg::Doom),
        2 => Just(Msg::Unknown),
        2 => Just(Msg::Arity),
        2 => Just(Msg::WrongType),
        2 => Just(Msg::Builtin),
        2 => Just(Msg::Undecodable),
        1 => Just(Msg::Foreign),
        1 => Just(Msg::Leave),
    ]
}

fn op() -> impl Strategy<Value = Op> {
    prop_oneof![
        8 => (0..SENDERS.len(), msg()).prop_map(|(s, m)| Op::Message(s, m)),
        3 => (0u8..6).prop_map(Op::Steps),
        1 => Just(Op::Failed),
    ]
}

/// Feeds `ops` to an intake and checks after each that the counters balance and that every
/// message of a known sender is answered.
fn run(ops: &[Op]) -> Result<(), TestCaseError> {
    let p = project();
    let mut parts = Parts::new(&p);
    let mut seqs: HashMap<usize, u64> = HashMap::new();
    let mut messages = 0;
    let mut decoded = Vec::new();
    for op in ops {
        let mut intake = parts.intake();
        match op {
            Op::Message(s, m) => {
                messages += 1;
                let seq = seqs.entry(*s).or_default();
                *seq += 1;
                let from = Header {
                    sender: *s as u64 + 1,
                    origin: Origin::new(SENDERS[*s]),
                    seq: *seq,
                    missed: 0,
                };
                let (name, params) = match m {
                    Msg::Tick(n) => ("tick", vec![Value::Int(*n)]),
                    Msg::Noise => ("noise", vec![]),
                    Msg::Doom => ("doom", vec![]),
                    Msg::Unknown => ("no_such_event", vec![]),
                    Msg::Arity => ("tick", vec![]),
                    Msg::WrongType => ("tick", vec![Value::Text("one".into())]),
                    Msg::Builtin => ("program_lost", vec![Value::Text("WORKER".into())]),
                    Msg::Leave => (petrel_ipc::wire::LEAVE, vec![]),
                    Msg::Undecodable => {
                        intake.undecodable(from, "a corrupt body");
                        continue;
                    }
                    Msg::Foreign => {
                        // No sender to answer: another Petrel could not read it.
                        *seq -= 1;
                        intake.foreign(SENDERS[*s], "wire version 1");
                        continue;
                    }
                };
                decoded.extend(params);
                intake.event(from, name, &mut decoded);
                prop_assert!(decoded.is_empty(), "the parameters were taken or dropped");
            }
            Op::Steps(n) => {
                for _ in 0..*n {
                    parts.engine.step(&mut NullSink);
                }
            }
            Op::Failed => intake.failed(&"a transport error"),
        }
        let s = parts.engine.stats();
        prop_assert_eq!(
            s.received,
            s.processed + s.unused + s.refused + parts.engine.queued() as u64,
            "{:?} after {:?}",
            s,
            op
        );
        prop_assert_eq!(parts.messages, messages);
        for a in parts.ledger.recent() {
            let k = &a.ack;
            prop_assert_eq!(k.received, k.taken + k.refused, "{:?}", k);
            // Every message of the sender was answered (taken or refused).
            let sent = seqs[&(k.sender as usize - 1)];
            prop_assert_eq!(k.last_seq, sent, "{:?}", k);
        }
    }
    // The queue emptied, everything is settled one way or the other.
    parts.engine.run_until_idle(&mut NullSink);
    let s = parts.engine.stats();
    prop_assert_eq!(s.received, s.processed + s.unused + s.refused);
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn the_counters_balance_and_every_message_is_answered(ops in prop::collection::vec(op(), 0..80)) {
        run(&ops)?;
    }
}

#[test]
fn a_built_in_event_from_another_process_is_answered_refused_with_its_reason() {
    let p = project();
    let mut parts = Parts::new(&p);
    let from = Header {
        sender: 7,
        origin: Origin::new("tool/send1"),
        seq: 1,
        missed: 0,
    };
    parts
        .intake()
        .event(from, "program_lost", &mut vec![Value::Text("GUI".into())]);
    let acks = parts.ledger.acks();
    assert_eq!(acks.len(), 1);
    assert_eq!((acks[0].refused, acks[0].last_seq), (1, 1));
    assert!(
        acks[0].refusals[0]
            .reason
            .contains("`program_lost` is a built-in event"),
        "{:?}",
        acks[0]
    );
    // Counted as received and refused; the player's bad_message is queued (received too).
    let s = parts.engine.stats();
    assert_eq!((s.received, s.refused, parts.engine.queued()), (2, 1, 1));
    assert_eq!(parts.bad_messages, 1);
}

#[test]
fn a_leave_is_taken_from_the_program_itself_only() {
    let p = project();
    let mut parts = Parts::new(&p);
    let mut intake = parts.intake();
    let from = |sender, origin| Header {
        sender,
        origin: Origin::new(origin),
        seq: 1,
        missed: 0,
    };
    let leave = petrel_ipc::wire::LEAVE;
    intake.event(from(1, "program/WORKER"), leave, &mut vec![]);
    intake.event(from(2, "tool/x"), leave, &mut vec![]);
    intake.event(from(3, "program/OTHER"), leave, &mut vec![]);
    assert_eq!(parts.leaves.iter().collect::<Vec<_>>(), ["WORKER"]);
    let by_sender: HashMap<u64, (u64, u64)> = parts
        .ledger
        .acks()
        .iter()
        .map(|a| (a.sender, (a.taken, a.refused)))
        .collect();
    assert_eq!(by_sender[&1], (1, 0));
    assert_eq!(by_sender[&2], (0, 1));
    assert_eq!(by_sender[&3], (0, 1));
    // The good leave is no event; the two bad ones are refused messages (and bad_messages).
    let s = parts.engine.stats();
    assert_eq!((s.received, s.refused, parts.engine.queued()), (4, 2, 2));
}
