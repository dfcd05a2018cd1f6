//! Replay across a reload, in one process: a journal written as the player writes it (an event
//! still queued when the version changes), replayed whole from the first version, and from the
//! reload on (what `--resume` does); a kept version whose files changed is a divergence.

use petrel_nets::compiled::CompiledProject;
use petrel_nets::reload::{map_state, source_digest, Mapping, OldState};
use petrel_player::engine::{Engine, NullSink};
use petrel_player::journal::Entry;
use petrel_player::record::{outcome_name, StepRecord};
use petrel_player::replay::replay_in;

const MANIFEST: &str = "[project]\nname = \"r\"\nfiles = [\"a.pn\"]\nstart = [\"A\"]\n\n[events]\ngo = { category = \"nominal\" }\nback = { category = \"nominal\" }\n";
const OLD: &str = "net A {\n    place p = 1\n    place q\n    transition go on go: p -> q\n    transition back on back: q -> p\n}\n";
// The new version renames `q` to `r`.
const NEW: &str = "net A {\n    place p = 1\n    place r\n    transition go on go: p -> r\n    transition back on back: r -> p\n}\n";
const MAPPING: &str = "[rename]\nplaces = { \"A.q\" = \"A.r\" }\n";

fn compile(net: &str) -> CompiledProject {
    let (_, c, d, _) = petrel_nets::project::from_sources(MANIFEST, &[("a.pn", net)]);
    assert!(!d.has_errors(), "{d:?}");
    c.unwrap()
}

fn submit(e: &mut Engine, out: &mut Vec<Entry>, time: u64, event: &str) {
    e.advance_to(time);
    e.submit_named(event, vec![]).unwrap();
    out.push(Entry::Submit {
        time,
        event: event.into(),
        params: vec![],
        origin: "tool/t".into(),
        seq: 0,
    });
}

fn step(e: &mut Engine, out: &mut Vec<Entry>) {
    let mut log = StepRecord::new(e.project());
    let s = e.step(&mut log).unwrap();
    out.push(Entry::Step {
        time: e.now(),
        event: e.project().events[s.event as usize].name.clone(),
        params: vec![],
        outcome: outcome_name(s.outcome).into(),
        fired: log.fired_names(),
        actions: log.actions.clone(),
        state: e.state().to_vec(),
        deadlines: e.deadlines().to_vec(),
    });
}

/// The journal of a mission reloaded with one event queued, and the kept version's hash.
fn journal(dir: &std::path::Path, old: &CompiledProject, new: &CompiledProject) -> Vec<Entry> {
    let files = vec![
        ("petrel.toml".to_string(), MANIFEST.to_string()),
        ("a.pn".to_string(), NEW.to_string()),
    ];
    let hash = source_digest(files.iter().map(|(p, t)| (p.as_str(), t.as_str())));
    petrel_player::reload::version::keep(dir, &hash, &files).unwrap();
    let mut out = vec![Entry::Header {
        version: petrel_player::journal::FORMAT_VERSION,
        project: "r".into(),
        project_dir: "r".into(),
        digest: petrel_player::journal::project_digest(old),
        vehicle: "v".into(),
        started_unix_ms: 1,
    }];
    let mut e = Engine::new(old);
    e.start(0, &mut NullSink);
    out.push(Entry::Start {
        time: 0,
        state: e.state().to_vec(),
    });
    submit(&mut e, &mut out, 10, "go");
    step(&mut e, &mut out);
    // `back` arrives while the reload is verified: queued, carried over.
    submit(&mut e, &mut out, 20, "back");
    let mapping = Mapping::parse(MAPPING).unwrap();
    let from = OldState {
        state: e.state(),
        deadlines: e.deadlines(),
        net_args: e.all_net_args(),
    };
    let mapped = map_state(old, &from, new, &mapping).unwrap();
    let queued = e.take_queue();
    let mut n = Engine::new(new);
    n.adopt(
        30,
        &mapped.state,
        &mapped.deadlines,
        mapped.net_args.clone(),
        e.stats(),
        queued.clone(),
        &mapping.nets,
    )
    .unwrap();
    out.push(Entry::Reload {
        time: 30,
        dir: "/elsewhere".into(),
        source_hash: hash,
        digest: petrel_player::journal::project_digest(new),
        mapping: MAPPING.into(),
        state: mapped.state,
        deadlines: mapped.deadlines,
        queued,
    });
    step(&mut n, &mut out);
    submit(&mut n, &mut out, 40, "go");
    step(&mut n, &mut out);
    out
}

#[test]
fn a_journal_replays_across_a_reload_whole_or_from_the_reload() {
    let dir = tempfile::tempdir().unwrap();
    let (old, new) = (compile(OLD), compile(NEW));
    let entries = journal(dir.path(), &old, &new);

    let (engine, r) = replay_in(&old, &entries, None, Some(dir.path()), false);
    assert!(r.divergence.is_none(), "{:?}", r.divergence);
    assert_eq!((r.steps, r.reloads), (3, 1));
    assert_eq!(
        engine.marking()[0],
        ("A".to_string(), vec!["r".to_string()])
    );

    // From the reload on, as `--resume` does: the queued `back` is queued again.
    let (engine, r) = replay_in(&old, &entries, None, Some(dir.path()), true);
    assert!(r.divergence.is_none(), "{:?}", r.divergence);
    assert_eq!((r.steps, r.reloads), (2, 1));
    assert_eq!(
        engine.marking()[0],
        ("A".to_string(), vec!["r".to_string()])
    );

    // Without the journal directory, the reload cannot be replayed: said, not a panic.
    let (_, r) = replay_in(&old, &entries, None, None, false);
    let d = r.divergence.expect("a divergence");
    assert!(d.what.contains("the journal directory is needed"), "{d:?}");
}

#[test]
fn a_kept_version_whose_files_changed_is_a_divergence() {
    let dir = tempfile::tempdir().unwrap();
    let (old, new) = (compile(OLD), compile(NEW));
    let entries = journal(dir.path(), &old, &new);
    let kept = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| {
            p.file_name()
                .unwrap()
                .to_string_lossy()
                .starts_with("project-")
        })
        .unwrap();
    std::fs::write(kept.join("a.pn"), NEW.replace("go on go", "go2 on go")).unwrap();
    let (_, r) = replay_in(&old, &entries, None, Some(dir.path()), false);
    let d = r.divergence.expect("a divergence");
    assert!(
        d.what.contains("its files changed since the reload"),
        "{d:?}"
    );
}
