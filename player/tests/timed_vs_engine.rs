//! The timed verifier against the engine in virtual time (issue 18, "Time"): random scripts of
//! outside events at random moments, the engine expiring its timers when their deadlines come;
//! every stable state the engine reaches is one `petrel verify --timed` reached (its marking,
//! active nets, global places and running timers). On `verify/tests/data/timed/race` the untimed
//! analysis reaches a state no script does, so the check has teeth.

use petrel_nets::compiled::{Bound, CompiledProject, Occurrence};
use petrel_nets::project::load_and_check;
use petrel_player::engine::{Engine, NullSink};
use petrel_value::{Type, Value};
use petrel_verify::{verify, BoundStatus, VerifyOptions};
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

/// Plays `runs` random scripts (seeds `0..runs` mixed with `salt`): outside events at random
/// moments, the timers due before each expiring one deadline at a time, in order. `settle` is
/// called after the start (with `true`) and after every expiry and accepted event, to let the
/// engine run and look at it.
fn play(p: &CompiledProject, runs: u64, salt: u64, mut settle: impl FnMut(&mut Engine, bool)) {
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
    for seed in 0..runs {
        let mut r = Lcg(seed ^ salt);
        let mut e = Engine::new(p);
        e.start(0, &mut NullSink);
        settle(&mut e, true);
        for _ in 0..12 {
            let target = e.now() + delays[r.next(delays.len() as u64) as usize];
            while let Some(d) = e.next_deadline().filter(|&d| d <= target) {
                e.advance_to(d);
                settle(&mut e, false);
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
                settle(&mut e, false);
            }
        }
    }
}

/// Plays `runs` random scripts; returns every stable state met.
fn scripts(p: &CompiledProject, runs: u64) -> HashSet<Vec<u64>> {
    let mut met = HashSet::new();
    play(p, runs, 0, |e, _| {
        e.run_until_idle(&mut NullSink);
        met.insert(e.state().to_vec());
    });
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
    let (played, timed, untimed) = check(&root.join("verify/tests/data/timed/race"), 200);
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

/// Records what one engine step did: the event taken and whether a transition fired.
#[derive(Default)]
struct Taken {
    event: Option<u32>,
    fired: bool,
}
impl petrel_player::engine::Sink for Taken {
    fn taken(&mut self, event: u32, _params: &[Value]) {
        self.event = Some(event);
        self.fired = false;
    }
    fn fired(&mut self, _net: u32, _transition: u32) {
        self.fired = true;
    }
}

/// Watches one bound on the engine's steps: the occurrences of `from` waiting for `to`, and
/// the delays seen, as docs/verification.md defines them.
struct Observer<'b> {
    b: &'b Bound,
    /// The times of the occurrences of `from` still waiting for `to`.
    pending: Vec<u64>,
    from_held: bool,
    /// The delays seen (microseconds).
    out: Vec<u64>,
}

impl Observer<'_> {
    fn holds(e: &Engine, o: &Occurrence) -> bool {
        match o {
            Occurrence::Marking(f) => e.layout().holds(f, e.state()),
            Occurrence::Event(_) => false,
        }
    }

    /// After a step (or at the start, with nothing taken): `to` answers what was pending;
    /// `from` may start a wait, which a `to` marking holding there answers at once.
    fn after(&mut self, e: &Engine, taken: &Taken) {
        let by_event = |o: &Occurrence| match o {
            Occurrence::Event(ev) => taken.event == Some(*ev) && taken.fired,
            Occurrence::Marking(_) => false,
        };
        let now = e.now();
        if by_event(&self.b.to) || Self::holds(e, &self.b.to) {
            self.out.extend(self.pending.drain(..).map(|t0| now - t0));
        }
        let now_holds = Self::holds(e, &self.b.from);
        if by_event(&self.b.from) || (now_holds && !self.from_held) {
            self.pending.push(now);
            if Self::holds(e, &self.b.to) {
                self.out.extend(self.pending.drain(..).map(|t0| now - t0));
            }
        }
        self.from_held = now_holds;
    }

    /// Processes the engine's queue one step at a time.
    fn steps(&mut self, e: &mut Engine) {
        loop {
            let mut t = Taken::default();
            if e.step(&mut t).is_none() {
                break;
            }
            self.after(e, &t);
        }
    }
}

/// The delays (microseconds) the engine shows between each occurrence of a bound's `from` and
/// the next `to` on `runs` random scripts.
fn observed(p: &CompiledProject, b: &Bound, runs: u64) -> Vec<u64> {
    let mut o = Observer {
        b,
        pending: Vec::new(),
        from_held: false,
        out: Vec::new(),
    };
    play(p, runs, 0x5eed, |e, start| {
        if start {
            o.pending.clear();
            o.from_held = false;
            // The initial state, where a `from` marking may already hold, then what start
            // queued.
            o.after(e, &Taken::default());
        }
        o.steps(e);
    });
    o.out
}

#[test]
fn every_delay_a_script_shows_lies_within_the_bound_the_timed_verifier_reports() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut checked = 0usize;
    for dir in [
        "verify/tests/data/timed/relay",
        "verify/tests/data/timed/race",
        "missions/uav",
    ] {
        let mut p = load(&root.join(dir));
        // Every event to every event and marking the project declares, and every place to its
        // leaving and to every timer's event.
        let timers: Vec<String> = p
            .timers
            .iter()
            .map(|t| p.events[t.event as usize].name.clone())
            .collect();
        let mut texts: Vec<String> = Vec::new();
        for e in &p.events {
            for t in &timers {
                texts.push(format!("{}..{t}", e.name));
            }
        }
        for n in &p.nets {
            for place in &n.places {
                let q = format!("{}.{}", n.name, place.name);
                texts.push(format!("{q}..not {q}"));
                for t in &timers {
                    texts.push(format!("{q}..{t}"));
                }
            }
        }
        for t in &texts {
            let b = petrel_nets::check::command_line_bound(&p, t).expect("reads");
            p.bounds.push(b);
        }
        let r = verify(
            &p,
            VerifyOptions {
                timed: true,
                ..Default::default()
            },
        )
        .expect("verifies");
        for (b, f) in p.bounds.iter().zip(&r.bounds) {
            let seen = observed(&p, b, 60);
            if seen.is_empty() {
                continue;
            }
            assert_ne!(
                f.status,
                BoundStatus::FromNeverHappens,
                "{dir} {}: {seen:?}",
                b.name
            );
            let min = (f.min_seconds.expect("a delay was seen") * 1e6).round() as u64;
            for &d in &seen {
                assert!(d >= min, "{dir} {}: {d} us < {f:?}", b.name);
                if let Some(max) = f.max_seconds {
                    assert!(
                        d <= (max * 1e6).round() as u64,
                        "{dir} {}: {d} us > {f:?}",
                        b.name
                    );
                }
            }
            checked += seen.len();
        }
    }
    assert!(checked > 100, "{checked}");
}
