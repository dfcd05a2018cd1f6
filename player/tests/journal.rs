//! The journal's format: round trip, rotation, torn records against corruption.

use petrel_ipc::Value;
use petrel_player::journal::{read_journal, segments, Entry, FlushPolicy, JournalWriter};

fn header() -> Entry {
    Entry::Header {
        version: 1,
        project: "t".into(),
        project_dir: "missions/t".into(),
        digest: 42,
        vehicle: "v".into(),
        started_unix_ms: 1,
    }
}

fn step(i: u64) -> Entry {
    Entry::Step {
        time: i * 1000,
        event: format!("e{i}"),
        params: vec![Value::Int(i as i64), Value::Text("x".repeat(20))],
        outcome: "processed".into(),
        fired: vec!["A.t".into()],
        actions: vec!["call P.f(1)".into()],
        state: vec![i, !i],
        deadlines: vec![None, Some(i)],
    }
}

fn write(dir: &std::path::Path, n: u64, rotate: u64) -> Vec<Entry> {
    let mut w = JournalWriter::open(dir, header(), FlushPolicy::EveryRecord, rotate).unwrap();
    let mut all = vec![header()];
    for i in 0..n {
        let e = step(i);
        w.append(&e).unwrap();
        all.push(e);
    }
    w.flush().unwrap();
    all
}

#[test]
fn entries_read_back_as_written() {
    let dir = tempfile::tempdir().unwrap();
    let written = write(dir.path(), 100, 64 << 20);
    let read = read_journal(dir.path()).unwrap();
    assert_eq!(read.entries, written);
    assert!(read.torn.is_none() && read.corrupt.is_none());
}

#[test]
fn segments_rotate_by_size_and_each_starts_with_the_header() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), 400, 8192);
    let files = segments(dir.path()).unwrap();
    assert!(files.len() >= 3, "{files:?}");
    for f in &files {
        assert!(std::fs::metadata(f).unwrap().len() <= 8192 + 200);
        let one = read_journal(f).unwrap();
        assert_eq!(one.entries[0], header());
    }
    let read = read_journal(dir.path()).unwrap();
    let steps = read
        .entries
        .iter()
        .filter(|e| matches!(e, Entry::Step { .. }))
        .count();
    assert_eq!(steps, 400);
}

#[test]
fn a_record_cut_by_a_crash_is_torn_and_dropped() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), 10, 64 << 20);
    let f = &segments(dir.path()).unwrap()[0];
    let len = std::fs::metadata(f).unwrap().len();
    let file = std::fs::OpenOptions::new().write(true).open(f).unwrap();
    file.set_len(len - 7).unwrap();
    let read = read_journal(dir.path()).unwrap();
    assert!(read.corrupt.is_none());
    let torn = read.torn.expect("torn");
    assert!(
        !read.unwritten,
        "a record cut short is lost, not unwritten space"
    );
    assert_eq!(torn.record, 10, "the last record (header is 0)");
    assert_eq!(read.entries.len(), 10, "header and the nine complete steps");
}

#[test]
fn a_byte_changed_in_the_middle_is_corruption_naming_the_record() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), 10, 64 << 20);
    let f = &segments(dir.path()).unwrap()[0];
    let mut bytes = std::fs::read(f).unwrap();
    let middle = bytes.len() / 2;
    bytes[middle] ^= 0x01;
    std::fs::write(f, &bytes).unwrap();
    let read = read_journal(dir.path()).unwrap();
    let c = read.corrupt.expect("corruption detected");
    assert!(c.record > 0 && c.record < 10, "{c:?}");
    assert!(c.offset as usize <= middle);
    assert_eq!(
        read.entries.len() as u64,
        c.record,
        "entries stop before the bad record"
    );
}

#[test]
fn a_file_that_is_not_a_journal_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("journal-000001.pj");
    std::fs::write(&f, b"hello, not a journal").unwrap();
    let e = read_journal(dir.path()).unwrap_err();
    assert!(e.to_string().contains("not a Petrel journal"), "{e}");
    assert!(read_journal(&dir.path().join("nothing")).is_err());
}

#[test]
fn flush_policies_parse() {
    assert_eq!(
        "record".parse::<FlushPolicy>(),
        Ok(FlushPolicy::EveryRecord)
    );
    assert_eq!("sync".parse::<FlushPolicy>(), Ok(FlushPolicy::Sync));
    assert_eq!(
        "50ms".parse::<FlushPolicy>(),
        Ok(FlushPolicy::Interval(std::time::Duration::from_millis(50)))
    );
    assert!("often".parse::<FlushPolicy>().is_err());
}

/// A record with a valid checksum around `body`, appended to the journal's last segment.
fn append_record(dir: &std::path::Path, body: &[u8]) {
    use std::io::Write;
    let f = segments(dir).unwrap().pop().unwrap();
    let mut out = std::fs::OpenOptions::new().append(true).open(f).unwrap();
    out.write_all(&(body.len() as u32).to_le_bytes()).unwrap();
    out.write_all(&crc32fast_hash(body).to_le_bytes()).unwrap();
    out.write_all(body).unwrap();
}

fn crc32fast_hash(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= b as u32;
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

#[test]
fn crafted_lengths_with_a_valid_checksum_are_corruption_not_a_crash() {
    // Entry::Start { time: 0, state: 2^61 words }, then Entry::Submit { event: 2^40 bytes }.
    let mut huge_vec = vec![1u8, 0, 253];
    huge_vec.extend_from_slice(&(1u64 << 61).to_le_bytes());
    let mut huge_text = vec![3u8, 0, 253];
    huge_text.extend_from_slice(&(1u64 << 40).to_le_bytes());
    let mut many_values = vec![3u8, 0, 1, b'e', 253];
    many_values.extend_from_slice(&(1u64 << 33).to_le_bytes());
    for body in [huge_vec, huge_text, many_values] {
        let dir = tempfile::tempdir().unwrap();
        write(dir.path(), 3, 64 << 20);
        append_record(dir.path(), &body);
        let read = read_journal(dir.path()).unwrap();
        let c = read.corrupt.expect("refused as damage");
        assert_eq!(c.record, 4, "{c}");
        assert!(c.what.contains("undecodable"), "{c}");
        assert_eq!(read.entries.len(), 4, "the good records before it");
    }
}

#[test]
fn the_widest_valid_records_decode_within_the_limit() {
    // Entries whose in-memory size is largest for their encoded size.
    let entries = [
        Entry::Step {
            time: 0,
            event: String::new(),
            params: vec![Value::Int(0); 5000],
            outcome: String::new(),
            fired: vec![String::new(); 5000],
            actions: vec![String::new(); 5000],
            state: vec![0; 5000],
            deadlines: vec![None; 5000],
        },
        Entry::Submit {
            time: 0,
            event: "e".into(),
            params: vec![Value::FloatList(vec![]); 3000],
            origin: String::new(),
            seq: 0,
        },
    ];
    let dir = tempfile::tempdir().unwrap();
    let mut w =
        JournalWriter::open(dir.path(), header(), FlushPolicy::EveryRecord, 64 << 20).unwrap();
    for e in &entries {
        w.append(e).unwrap();
    }
    w.flush().unwrap();
    let read = read_journal(dir.path()).unwrap();
    assert!(read.corrupt.is_none(), "{:?}", read.corrupt);
    assert_eq!(&read.entries[1..], &entries[..]);
}

#[test]
fn a_zero_filled_tail_is_torn_and_can_be_cut_off() {
    for (cut, zeros) in [(0usize, 4096usize), (0, 3), (11, 4096)] {
        let dir = tempfile::tempdir().unwrap();
        write(dir.path(), 5, 64 << 20);
        let f = segments(dir.path()).unwrap().pop().unwrap();
        let mut bytes = std::fs::read(&f).unwrap();
        let good = bytes.len();
        // The last record's end did not reach the disk (`cut` bytes of it became zeros), then
        // zeros where the file grew.
        let n = bytes.len();
        bytes[n - cut..].fill(0);
        bytes.extend(std::iter::repeat_n(0u8, zeros));
        std::fs::write(&f, &bytes).unwrap();
        let read = read_journal(dir.path()).unwrap();
        assert!(read.corrupt.is_none(), "{:?}", read.corrupt);
        let torn = read.torn.clone().expect("a torn tail");
        let complete = if cut == 0 { 6 } else { 5 };
        assert_eq!(read.entries.len(), complete, "{torn}");
        petrel_player::journal::cut_torn_tail(&torn).unwrap();
        let len = std::fs::metadata(&f).unwrap().len() as usize;
        assert!(len <= good, "{len} > {good}");
        let again = read_journal(dir.path()).unwrap();
        assert!(again.torn.is_none() && again.corrupt.is_none());
        assert_eq!(again.entries.len(), complete);
    }
}

#[test]
fn zeros_in_the_middle_are_damage() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), 5, 64 << 20);
    let f = segments(dir.path()).unwrap().pop().unwrap();
    let mut bytes = std::fs::read(&f).unwrap();
    let at = bytes.len() / 2;
    bytes[at..at + 16].fill(0);
    std::fs::write(&f, &bytes).unwrap();
    let read = read_journal(dir.path()).unwrap();
    assert!(read.corrupt.is_some(), "{:?}", read.torn);
}

#[test]
fn a_journal_directory_is_locked_by_one_player_and_a_dead_ones_lock_is_stale() {
    use petrel_player::journal::{JournalLock, LockError, LOCK_FILE};
    let dir = tempfile::tempdir().unwrap();
    let mut first = JournalLock::acquire(dir.path()).unwrap();
    assert!(first.stale_owner().is_none());
    first.claim("auv1").unwrap();
    match JournalLock::acquire(dir.path()) {
        Err(LockError::InUse { owner: Some(o), .. }) => {
            assert_eq!((o.vehicle.as_str(), o.pid), ("auv1", std::process::id()));
        }
        other => panic!("{other:?}"),
    }
    drop(first);
    // Released in good order: nobody's.
    let again = JournalLock::acquire(dir.path()).unwrap();
    assert!(again.stale_owner().is_none());
    drop(again);
    // A lock file naming a process, found unlocked: its player died holding it.
    std::fs::write(dir.path().join(LOCK_FILE), "vehicle=auv2\npid=4242\n").unwrap();
    let taken = JournalLock::acquire(dir.path()).unwrap();
    let stale = taken.stale_owner().unwrap();
    assert_eq!((stale.vehicle.as_str(), stale.pid), ("auv2", 4242));
    // Not claimed (a refused player): what the file said stays.
    drop(taken);
    let text = std::fs::read_to_string(dir.path().join(LOCK_FILE)).unwrap();
    assert!(text.contains("auv2"), "{text}");
}

#[test]
fn replay_reports_spliced_headers_and_time_going_backwards() {
    use petrel_player::replay::{replay, DivergenceKind};
    let manifest = "[project]\nname = \"t\"\nfiles = [\"a.pn\"]\nstart = [\"A\"]\n\n[events]\ngo = { category = \"nominal\" }\n";
    let net = "net A {\n    place p = 1\n    transition t on go: p -> p\n}\n";
    let (_, c, d, _) = petrel_nets::project::from_sources(manifest, &[("a.pn", net)]);
    assert!(!d.has_errors(), "{d:?}");
    let c = c.unwrap();
    let mut engine = petrel_player::engine::Engine::new(&c);
    engine.start(0, &mut petrel_player::engine::NullSink);
    let start = Entry::Start {
        time: 0,
        state: engine.state().to_vec(),
    };
    let header = |vehicle: &str, started| Entry::Header {
        version: 2,
        project: "t".into(),
        project_dir: ".".into(),
        digest: 1,
        vehicle: vehicle.into(),
        started_unix_ms: started,
    };
    let resume = |time| Entry::Resume { time };
    let cases = [
        (
            vec![header("a", 5), start.clone(), header("b", 5)],
            "vehicle `b`",
        ),
        (
            vec![header("a", 5), start.clone(), header("a", 6)],
            "another mission",
        ),
        (
            vec![
                header("a", 5),
                start.clone(),
                resume(9),
                header("a", 5),
                resume(3),
            ],
            "backwards",
        ),
    ];
    for (entries, what) in cases {
        let (_, r) = replay(&c, &entries, None);
        let d = r.divergence.expect("an inconsistency");
        assert_eq!(d.kind, DivergenceKind::Journal);
        assert!(d.what.contains(what), "{}", d.what);
    }
    let (_, r) = replay(
        &c,
        &[header("a", 5), start, resume(9), header("a", 5), resume(9)],
        None,
    );
    assert!(r.divergence.is_none(), "{:?}", r.divergence);
}

#[test]
fn a_reload_entry_round_trips_and_leaves_the_earlier_entries_encoded_as_before() {
    use petrel_player::journal::decode_entry;
    let enc = |e: &Entry| bincode::encode_to_vec(e, bincode::config::standard()).unwrap();
    // Variants are numbered by bincode: a journal of format 2 decodes the same.
    let checkpoint = Entry::Checkpoint {
        time: 1,
        state: vec![3],
        deadlines: vec![None],
    };
    assert_eq!(enc(&checkpoint)[0], 7);
    let reload = Entry::Reload {
        time: 2,
        dir: "/x/uav-v2".into(),
        source_hash: "0123456789abcdef".into(),
        digest: 42,
        mapping: "[vanished]\nplaces = [\"A.q\"]\n".into(),
        state: vec![5, 0],
        deadlines: vec![Some(9), None],
        queued: vec![("low".into(), vec![Value::Int(1)], Some("A".into()))],
    };
    let bytes = enc(&reload);
    assert_eq!(bytes[0], 8);
    assert_eq!(decode_entry(&bytes).unwrap(), reload);
    assert_eq!(reload.time(), Some(2));
}

/// A player killed while it writes never drops its writer: the records it flushed are in the
/// segment's mapped window (in the page cache), followed by the window's reserved zeros. They
/// read back whole, the zeros as a torn tail, which `--resume` cuts off.
#[test]
fn a_writer_that_never_stops_leaves_every_flushed_record_before_its_reserved_zeros() {
    let dir = tempfile::tempdir().unwrap();
    let mut w =
        JournalWriter::open(dir.path(), header(), FlushPolicy::EveryRecord, 64 << 20).unwrap();
    let mut all = vec![header()];
    for i in 0..50 {
        let e = step(i);
        w.append(&e).unwrap();
        all.push(e);
    }
    // What a SIGKILL leaves: no drop (no cut of the zeros, no unmap).
    std::mem::forget(w);
    let read = read_journal(dir.path()).unwrap();
    assert_eq!(read.entries, all);
    assert!(read.corrupt.is_none());
    let torn = read.torn.expect("the window's zeros are a torn tail");
    assert!(torn.what.contains("zero bytes"), "{torn}");
    assert!(read.unwritten, "reserved space, nothing lost");
    petrel_player::journal::cut_torn_tail(&torn).unwrap();
    let again = read_journal(dir.path()).unwrap();
    assert_eq!(again.entries, all);
    assert!(again.torn.is_none() && again.corrupt.is_none());
}

/// A writer dropped in good order cuts its window's zeros off every segment, the last one
/// included: each ends at its last record.
#[test]
fn segments_end_at_their_last_record_once_the_writer_is_dropped() {
    let dir = tempfile::tempdir().unwrap();
    let written = write(dir.path(), 400, 8192);
    let files = segments(dir.path()).unwrap();
    assert!(files.len() >= 3, "{files:?}");
    for f in &files {
        let one = read_journal(f).unwrap();
        // Read alone, each is the last segment: zeros at its end would read as torn.
        assert!(one.torn.is_none() && one.corrupt.is_none(), "{f:?}");
    }
    // Every record, and each later segment's header.
    let read = read_journal(dir.path()).unwrap();
    assert_eq!(read.entries.len(), written.len() + files.len() - 1);
}

#[test]
fn a_journal_is_for_its_owner_alone() {
    use petrel_player::journal::{JournalLock, LOCK_FILE};
    use std::os::unix::fs::PermissionsExt;
    let mode = |p: &std::path::Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
    let base = tempfile::tempdir().unwrap();
    let dir = base.path().join("run/journal");
    let lock = JournalLock::acquire(&dir).unwrap();
    write(&dir, 400, 8192);
    drop(lock);
    assert_eq!(mode(&dir), 0o700);
    assert_eq!(mode(&base.path().join("run")), 0o700);
    assert_eq!(mode(&dir.join(LOCK_FILE)), 0o600);
    let files = segments(&dir).unwrap();
    assert!(files.len() >= 3, "{files:?}");
    for f in &files {
        assert_eq!(mode(f), 0o600, "{}", f.display());
    }
}
