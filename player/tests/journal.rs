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
