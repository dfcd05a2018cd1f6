//! The journal's cost per step under each flush policy.
//!
//! Run: `cargo bench -p petrel-player --bench journal`. Appends 20,000 step records (the size a
//! UAV step has: an event with a waypoint, two fired transitions, three actions, a 4-word state)
//! to a fresh journal under each policy, and prints microseconds per record, with a baseline
//! measured in the same run: encoding the same records into memory only (what any recorder must
//! do). Best of three runs per policy (the machine is shared).

use petrel_ipc::Value;
use petrel_player::journal::{Entry, FlushPolicy, JournalWriter};
use std::time::{Duration, Instant};

const RECORDS: u64 = 20_000;

fn step(i: u64) -> Entry {
    Entry::Step {
        time: i * 1000,
        event: "waypoint".into(),
        params: vec![
            Value::FloatList(vec![48.71, 2.21, 300.0]),
            Value::Text("camera".into()),
        ],
        outcome: "processed".into(),
        fired: vec!["MISSION.transit".into(), "EVENTS.watch".into()],
        actions: vec![
            "cancel dec_answer".into(),
            "call GUI.transit([48.71, 2.21, 300.0])".into(),
            "call PLD.use_payload(\"camera\")".into(),
        ],
        state: vec![i, !i, i << 3, 7],
        deadlines: vec![Some(i * 1000 + 10_000_000)],
    }
}

fn header() -> Entry {
    Entry::Header {
        version: 1,
        project: "bench".into(),
        project_dir: ".".into(),
        digest: 0,
        vehicle: "bench".into(),
        started_unix_ms: 0,
    }
}

fn per_record(policy: FlushPolicy, records: u64) -> (f64, f64) {
    let mut best = f64::INFINITY;
    let mut worst_single = 0.0f64;
    for _ in 0..3 {
        let dir = tempfile::tempdir().expect("temporary directory");
        let mut w = JournalWriter::open(dir.path(), header(), policy, 64 << 20).expect("journal");
        let entries: Vec<Entry> = (0..records).map(step).collect();
        let t = Instant::now();
        let mut slowest = Duration::ZERO;
        for e in &entries {
            let s = Instant::now();
            w.append(e).expect("append");
            slowest = slowest.max(s.elapsed());
        }
        w.flush().expect("flush");
        best = best.min(t.elapsed().as_secs_f64() * 1e6 / records as f64);
        worst_single = worst_single.max(slowest.as_secs_f64() * 1e6);
    }
    (best, worst_single)
}

fn main() {
    let entries: Vec<Entry> = (0..RECORDS).map(step).collect();
    let mut buf = Vec::with_capacity(512);
    let mut baseline = f64::INFINITY;
    for _ in 0..3 {
        let t = Instant::now();
        for e in &entries {
            buf.clear();
            bincode::encode_into_std_write(e, &mut buf, bincode::config::standard())
                .expect("encode");
            std::hint::black_box(&buf);
        }
        baseline = baseline.min(t.elapsed().as_secs_f64() * 1e6 / RECORDS as f64);
    }
    println!("journal cost per step record ({RECORDS} records, best of 3)");
    println!("  baseline, encoding in memory only: {baseline:>8.2} us/record");
    for (name, policy, n) in [
        (
            "interval 50ms",
            FlushPolicy::Interval(Duration::from_millis(50)),
            RECORDS,
        ),
        (
            "every record (to the OS)",
            FlushPolicy::EveryRecord,
            RECORDS,
        ),
        ("sync (fdatasync every record)", FlushPolicy::Sync, 500),
    ] {
        let (us, worst) = per_record(policy, n);
        println!(
            "  {name:<32} {us:>8.2} us/record (slowest single append {worst:.0} us), {:.1}x the baseline",
            us / baseline
        );
    }
}
