//! The reload's decisions on compiled projects, with the real mapping and verification: each
//! refusal and its reasons, a second request while one is verified, a dry run, a swap, and the
//! milliseconds of each answer from the injected clock.

use super::*;
use crate::engine::NullSink;
use petrel_nets::reload::{source_digest, verify_mapped, Mapping};
use std::time::Duration;

const MANIFEST: &str = "[project]\nname = \"r\"\nfiles = [\"a.pn\"]\nstart = [\"A\"]\n\n[events]\ngo = { category = \"nominal\" }\nback = { category = \"nominal\" }\n";
const OLD: &str = "net A {\n    place p = 1\n    place q\n    transition go on go: p -> q\n    transition back on back: q -> p\n}\n";
/// The new version renames `q` to `r`.
const NEW: &str = "net A {\n    place p = 1\n    place r\n    transition go on go: p -> r\n    transition back on back: r -> p\n}\n";
const RENAME: &str = "[rename]\nplaces = { \"A.q\" = \"A.r\" }\n";
/// From `r` marked, `back` marks `p` as well, and `go` puts a second token in `r`.
const UNSAFE: &str = "net A {\n    place p = 1\n    place r\n    transition go on go: p -> r\n    transition spill on back: r -> r, p\n}\n";

fn compile(net: &str) -> CompiledProject {
    let (_, c, d, _) = petrel_nets::project::from_sources(MANIFEST, &[("a.pn", net)]);
    assert!(!d.has_errors(), "{d:?}");
    c.unwrap()
}

/// The new version `net`, read, with the mapping file `mapping`.
fn candidate(net: &str, mapping: &str) -> Candidate {
    let files = vec![
        ("petrel.toml".to_string(), MANIFEST.to_string()),
        ("a.pn".to_string(), net.to_string()),
    ];
    Candidate {
        project: compile(net),
        source_hash: source_digest(files.iter().map(|(p, t)| (p.as_str(), t.as_str()))),
        files,
        mapping_text: mapping.to_string(),
        mapping: Mapping::parse(mapping).unwrap(),
    }
}

fn request(dir: &str, hash: &str, dry_run: bool) -> ReloadRequest {
    ReloadRequest {
        dir: dir.into(),
        source_hash: hash.into(),
        mapping: RENAME.into(),
        dry_run,
    }
}

const FIRST: Requester = Requester { sender: 7, seq: 1 };
const SECOND: Requester = Requester { sender: 9, seq: 4 };

/// The old version's engine after `go`: `A.q` marked.
fn running(old: &CompiledProject) -> Engine<'_> {
    let mut engine = Engine::new(old);
    engine.start(0, &mut NullSink);
    engine.submit_named("go", vec![]).unwrap();
    engine.step(&mut NullSink).unwrap();
    engine
}

/// A reload of `net` requested by `from` at `t0`, read and mapped at `t0` + 3 ms: the
/// verifier's project and state.
fn begun(
    job: &mut ReloadJob,
    engine: &Engine,
    from: Requester,
    net: &str,
    dry_run: bool,
    t0: Instant,
) -> (CompiledProject, Mapped) {
    let c = candidate(net, RENAME);
    let req = request("/v2", &c.source_hash, dry_run);
    let admitted = job.request(from, req, t0).map_err(|a| a.reasons).unwrap();
    let running = (engine.project(), &running_state(engine));
    match job.begin(admitted, Ok(c), running, t0 + Duration::from_millis(3)) {
        Begin::Verify { project, mapped } => (*project, mapped),
        Begin::Refuse(a) => panic!("refused: {:?}", a.reasons),
    }
}

#[test]
fn a_request_while_another_is_verified_is_refused_at_once_and_the_first_goes_on() {
    let old = compile(OLD);
    let engine = running(&old);
    let mut job = ReloadJob::default();
    let t0 = Instant::now();
    let (project, mapped) = begun(&mut job, &engine, FIRST, NEW, false, t0);
    assert!(job.is_verifying() && job.holds_steps());

    let second = request("/v3", "0123456789abcdef", true);
    let Err(answer) = job.request(SECOND, second, t0 + Duration::from_millis(5)) else {
        panic!("a second request is admitted while the first is verified");
    };
    assert_eq!(
        (answer.request_sender, answer.request_seq, answer.accepted),
        (9, 4, false)
    );
    assert_eq!(
        answer.reasons,
        ["another reload is being verified: ask again when it is answered"]
    );
    assert_eq!(
        (answer.dir.as_str(), answer.source_hash.as_str()),
        ("/v3", "0123456789abcdef")
    );
    assert!(answer.dry_run);
    assert_eq!(answer.millis, 0, "refused as it arrives");

    // The first is still the one verified: its verdict answers its requester.
    assert!(job.is_verifying());
    let verdict = verify_mapped(&project, &mapped, Some(1000));
    let Some(Settle::Swap { answer, .. }) = job.verdict(verdict, 1, t0 + Duration::from_millis(8))
    else {
        panic!("the first reload is not swapped");
    };
    let answer = answer.after_swap(Ok("handed".into()), t0 + Duration::from_millis(9));
    assert_eq!((answer.request_sender, answer.request_seq), (7, 1));
}

#[test]
fn a_new_version_that_does_not_read_is_refused_with_the_reader_s_reasons() {
    let old = compile(OLD);
    let engine = running(&old);
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("petrel.toml"), MANIFEST).unwrap();
    std::fs::write(dir.path().join("a.pn"), NEW).unwrap();
    let mut job = ReloadJob::default();
    let t0 = Instant::now();
    // The files changed since the requester hashed them.
    let req = request(&dir.path().display().to_string(), "0000000000000000", false);
    let admitted = job.request(FIRST, req, t0).map_err(|a| a.reasons).unwrap();
    let read = version::load_candidate(dir.path(), "0000000000000000", RENAME);
    let running = (engine.project(), &running_state(&engine));
    let Begin::Refuse(answer) = job.begin(admitted, read, running, t0 + Duration::from_millis(4))
    else {
        panic!("a version whose files changed is verified");
    };
    assert!(!answer.accepted);
    assert_eq!(answer.reasons.len(), 1);
    assert!(
        answer.reasons[0].contains("changed between `petrel reload` reading them"),
        "{:?}",
        answer.reasons
    );
    assert_eq!(
        answer.millis, 4,
        "from the request to the answer, reading included"
    );
    assert!(!job.is_verifying());

    // A version that does not check: the checker's errors, where they are.
    std::fs::write(
        dir.path().join("a.pn"),
        "net A {\n    place p = 1\n    transition go on nothing: p -> p\n}\n",
    )
    .unwrap();
    let admitted = job
        .request(FIRST, request("d", "", false), t0)
        .map_err(|a| a.reasons)
        .unwrap();
    let read = version::load_candidate(dir.path(), "", "");
    let running = (engine.project(), &running_state(&engine));
    let Begin::Refuse(answer) = job.begin(admitted, read, running, t0) else {
        panic!("a version that does not check is verified");
    };
    assert_eq!(answer.reasons[0], "the new version does not check");
    let at = dir.path().join("a.pn");
    let error = "3:22: error[E0203]: unknown event `nothing`";
    assert_eq!(answer.reasons[1], format!("{}:{error}", at.display()));
}

#[test]
fn a_state_that_does_not_map_is_refused_with_the_mapping_s_reasons() {
    let old = compile(OLD);
    let engine = running(&old);
    let mut job = ReloadJob::default();
    let t0 = Instant::now();
    let mapping = "[rename]\nplaces = { \"A.zz\" = \"A.r\" }\n";
    let admitted = job
        .request(FIRST, request("/v2", "", false), t0)
        .map_err(|a| a.reasons)
        .unwrap();
    let running = (engine.project(), &running_state(&engine));
    let Begin::Refuse(answer) = job.begin(admitted, Ok(candidate(NEW, mapping)), running, t0)
    else {
        panic!("a mapping naming no place is verified");
    };
    assert!(
        answer.reasons.contains(
            &"mapping: [rename] places: the running version has no place `A.zz`".to_string()
        ),
        "{:?}",
        answer.reasons
    );
    assert!(!job.is_verifying());
}

#[test]
fn a_finding_of_the_verification_refuses_the_reload_with_its_trace() {
    let old = compile(OLD);
    let engine = running(&old);
    let mut job = ReloadJob::default();
    let t0 = Instant::now();
    let (project, mapped) = begun(&mut job, &engine, FIRST, UNSAFE, false, t0);
    let verdict = verify_mapped(&project, &mapped, Some(1000));
    let Some(Settle::Answer(answer)) = job.verdict(verdict, 3, t0 + Duration::from_millis(40))
    else {
        panic!("an unsafe version is swapped");
    };
    assert!(!answer.accepted && !answer.dry_run);
    assert!(
        answer.reasons[0].starts_with("verification from the mapped state: unsafe place"),
        "{:?}",
        answer.reasons
    );
    assert!(!answer.trace.is_empty());
    assert_eq!(
        answer.reasons[1],
        format!("from the mapped state by: {}", answer.trace.join(", "))
    );
    assert_eq!(
        answer.summary, mapped.summary,
        "what the mapping did, said with the refusal"
    );
    assert_eq!(answer.source_hash, candidate(UNSAFE, RENAME).source_hash);
    assert_eq!(answer.millis, 40);
    assert!(!job.is_verifying() && !job.holds_steps());

    // A finding in the mapped state itself has no trace.
    begun(&mut job, &engine, FIRST, NEW, false, t0);
    let finding = Finding {
        what: "invariant `x` broken in []".into(),
        trace: Vec::new(),
    };
    let Some(Settle::Answer(answer)) = job.verdict(Err(finding), 3, t0) else {
        panic!("a finding is swapped");
    };
    assert_eq!(answer.reasons[1], "in the mapped state itself");
}

#[test]
fn a_dry_run_is_answered_without_a_swap_and_never_holds_the_steps() {
    let old = compile(OLD);
    let engine = running(&old);
    let mut job = ReloadJob::default();
    let t0 = Instant::now();
    let (project, mapped) = begun(&mut job, &engine, FIRST, NEW, true, t0);
    assert!(job.is_verifying() && !job.holds_steps());
    let verdict = verify_mapped(&project, &mapped, Some(1000));
    let states = *verdict.as_ref().unwrap();
    let Some(Settle::Answer(answer)) = job.verdict(verdict, 6, t0 + Duration::from_millis(12))
    else {
        panic!("a dry run is swapped");
    };
    assert!(answer.accepted && answer.dry_run);
    assert_eq!((answer.step, answer.states, answer.millis), (6, states, 12));
    assert_eq!(answer.summary, mapped.summary);
    assert!(!job.is_verifying());
}

#[test]
fn an_accepted_reload_is_swapped_then_answered_with_what_the_swap_did() {
    let old = compile(OLD);
    let engine = running(&old);
    let mut job = ReloadJob::default();
    let t0 = Instant::now();
    let (project, mapped) = begun(&mut job, &engine, FIRST, NEW, false, t0);
    assert!(
        mapped.summary.iter().any(|l| l.contains("A.q")),
        "{:?}",
        mapped.summary
    );
    let verdict = verify_mapped(&project, &mapped, Some(1000));
    let Some(Settle::Swap {
        candidate: c,
        dir,
        answer,
    }) = job.verdict(verdict, 6, t0 + Duration::from_millis(12))
    else {
        panic!("an accepted reload is not swapped");
    };
    assert!(!job.is_verifying() && !job.holds_steps());
    assert_eq!(dir, "/v2");
    assert_eq!(c.source_hash, candidate(NEW, RENAME).source_hash);
    assert_eq!(c.mapping_text, RENAME);
    let handed = "queue: 1 event(s) handed over to the new version, 0 refused";
    let answer = answer.after_swap(Ok(handed.into()), t0 + Duration::from_millis(15));
    assert!(answer.accepted && !answer.dry_run);
    assert_eq!((answer.step, answer.millis), (6, 15));
    assert_eq!(answer.summary.last().map(String::as_str), Some(handed));
    assert_eq!(answer.summary.len(), mapped.summary.len() + 1);

    // A swap that cannot be done refuses the reload, with its reasons.
    let (project, mapped) = begun(&mut job, &engine, FIRST, NEW, false, t0);
    let verdict = verify_mapped(&project, &mapped, Some(1000));
    let Some(Settle::Swap { answer, .. }) = job.verdict(verdict, 6, t0) else {
        panic!("an accepted reload is not swapped");
    };
    let answer = answer.after_swap(Err(vec!["cannot keep the new version".into()]), t0);
    assert!(!answer.accepted);
    assert_eq!(answer.reasons, ["cannot keep the new version"]);
}

#[test]
fn a_verification_that_cannot_start_refuses_the_reload() {
    let old = compile(OLD);
    let engine = running(&old);
    let mut job = ReloadJob::default();
    let t0 = Instant::now();
    assert!(
        job.abandon("no thread".into(), t0).is_none(),
        "nothing to abandon"
    );
    begun(&mut job, &engine, SECOND, NEW, false, t0);
    let answer = job.abandon(
        "cannot start the verification: no thread".into(),
        t0 + Duration::from_millis(2),
    );
    let answer = answer.expect("the reload verified is refused");
    assert_eq!(
        (answer.request_sender, answer.accepted, answer.millis),
        (9, false, 2)
    );
    assert_eq!(answer.reasons, ["cannot start the verification: no thread"]);
    assert!(!job.is_verifying());
    assert!(
        job.verdict(Ok(1), 0, t0).is_none(),
        "no verdict without a reload verified"
    );
}
