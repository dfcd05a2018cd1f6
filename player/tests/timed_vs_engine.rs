//! The timed verifier against the engine in virtual time (issue 18, "Time"): random scripts of
//! outside events at random moments, the engine expiring its timers when their deadlines come;
//! every stable state the engine reaches is one `petrel verify --timed` reached (its marking,
//! active nets, global places and running timers). On `nets/tests/data/timed/race` the untimed
//! analysis reaches a state no script does, so the check has teeth.

use petrel_nets::compiled::CompiledProject;
use petrel_nets::project::load_and_check;
use petrel_nets::verify::{verify, VerifyOptions};
use petrel_player::engine::{Engine, NullSink};
use petrel_value::{Type, Value};
use std::collections::HashSet;
use std::path::Path;

fn load(dir: &Path) -> CompiledProject {
    let (_, c, d) = load_and_check(dir).expect("loads");
    c.unwrap_or_else(|| panic!("{}: {d:?}", dir.display()))
}

/// The untimed part (the engine's words) of every state the verifier reached.
fn verified(p: &CompiledProject, timed: bool, words: usize) -> HashSet<Vec<u64>> {
    let r = verify(
        p,
        VerifyOptions {
            keep_states: true,
            timed,
            ..Default::default()
        },
    )
    .expect("verifies");
    r.reachable
        .into_iter()
        .map(|s| s[..words].to_vec())
        .collect()
}

/// A small deterministic generator (no dependency; the seed is in the failure message).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self, n: u64) -> u64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 33) % n
    }
}

fn value(ty: Type, r: &mut Lcg) -> Value {
    match ty {
        Type::Int => Value::Int(r.next(4) as i64),
        Type::Float => Value::Float([0.0, 0.5, 10.0, 300.0][r.next(4) as usize]),
        Type::Bool => Value::Bool(r.next(2) == 1),
        Type::Text => Value::Text(["r1", "r2", "camera", ""][r.next(4) as usize].into()),
        Type::FloatList => Value::FloatList(vec![1.0]),
    }
}

/// Plays `runs` random scripts; returns every stable state met.
fn scripts(p: &CompiledProject, runs: u64) -> HashSet<Vec<u64>> {
    let timer_events: Vec<u32> = p.timers.iter().map(|t| t.event).collect();
    let outside: Vec<u32> = (0..p.events.len() as u32)
        .filter(|e| !timer_events.contains(e))
        .collect();
    // Delays between outside events, in microseconds: none, around the timers' durations.
    let delays: [u64; 7] = [
        0,
        500_000,
        1_000_000,
        2_000_000,
        3_000_000,
        60_000_000,
        700_000_000,
    ];
    let mut met = HashSet::new();
    for seed in 0..runs {
        let mut r = Lcg(seed);
        let mut e = Engine::new(p);
        e.start(0, &mut NullSink);
        e.run_until_idle(&mut NullSink);
        met.insert(e.state().to_vec());
        for _ in 0..12 {
            let target = e.now() + delays[r.next(delays.len() as u64) as usize];
            // The timers due before then expire one deadline at a time, in order.
            while let Some(d) = e.next_deadline().filter(|&d| d <= target) {
                e.advance_to(d);
                e.run_until_idle(&mut NullSink);
                met.insert(e.state().to_vec());
            }
            e.advance_to(target);
            if e.is_over() || outside.is_empty() {
                continue;
            }
            let ev = outside[r.next(outside.len() as u64) as usize];
            let params: Vec<Value> = p.events[ev as usize]
                .params
                .iter()
                .map(|(_, t)| value(*t, &mut r))
                .collect();
            if e.submit(ev, params).is_ok() {
                e.run_until_idle(&mut NullSink);
                met.insert(e.state().to_vec());
            }
        }
    }
    met
}

type States = HashSet<Vec<u64>>;

fn check(dir: &Path, runs: u64) -> (States, States, States) {
    let p = load(dir);
    let words = Engine::new(&p).state().len();
    let timed = verified(&p, true, words);
    let untimed = verified(&p, false, words);
    let played = scripts(&p, runs);
    let missed: Vec<_> = played.difference(&timed).collect();
    assert!(
        missed.is_empty(),
        "{}: {} state(s) the engine reached and the timed verifier did not",
        dir.display(),
        missed.len()
    );
    (played, timed, untimed)
}

#[test]
fn every_state_a_script_reaches_is_one_the_timed_verifier_found() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let (played, timed, untimed) = check(&root.join("nets/tests/data/timed/race"), 200);
    // The scripts reach every timed state there; the untimed analysis reaches M{aborted},
    // which no script does.
    assert_eq!(played, timed);
    assert!(untimed.difference(&played).count() > 0);
    for m in ["uav", "auv", "ugv"] {
        let (played, timed, _) = check(&root.join("missions").join(m), 100);
        assert!(played.len() > 1, "{m}: {}", played.len());
        assert!(played.len() <= timed.len());
    }
}
