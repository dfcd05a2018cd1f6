//! What a reload costs the player, on the UAV mission in transit.
//!
//! Run: `cargo bench -p petrel-player --bench reload`. The new version is the UAV mission with
//! a BIRDS net added (the reload of `tests/tests/reload.rs`), written to a temporary directory.
//! Measured, best of 20 runs each (the machine is shared): reading and checking the new
//! version from its directory (`load_candidate`, content hash included), mapping the state,
//! and verifying from the mapped state; with, as baselines of the same run, checking the
//! project (`load_and_check`) and verifying it from its initial state (`petrel verify`).

use petrel_nets::reload::{map_state, verify_mapped, OldState};
use petrel_nets::semantics::{NoEffects, Scratch, Semantics};
use std::path::Path;
use std::time::{Duration, Instant};

fn best<T>(runs: u32, mut f: impl FnMut() -> T) -> Duration {
    (0..runs)
        .map(|_| {
            let t = Instant::now();
            std::hint::black_box(f());
            t.elapsed()
        })
        .min()
        .unwrap_or_default()
}

fn main() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let uav = repo.join("missions/uav");
    let dir = tempfile::tempdir().expect("temporary directory");
    for f in ["petrel.toml", "mission.pn", "events.pn"] {
        let text = std::fs::read_to_string(uav.join(f)).expect("the UAV mission");
        let text = if f == "petrel.toml" {
            text.replace(
                "files = [\"mission.pn\", \"events.pn\"]",
                "files = [\"mission.pn\", \"events.pn\", \"birds.pn\"]",
            )
            .replace(
                "start = [\"MISSION\", \"EVENTS\"]",
                "start = [\"MISSION\", \"EVENTS\", \"BIRDS\"]",
            )
            .replace(
                "[programs.GUI]",
                "bird_strike = { category = \"mission\" }\nbird_checked = { category = \"mission\" }\n\n[programs.GUI]",
            )
        } else {
            text
        };
        std::fs::write(dir.path().join(f), text).expect("written");
    }
    std::fs::write(
        dir.path().join("birds.pn"),
        "net BIRDS {\n    place watching = 1\n    place struck\n    transition strike on bird_strike: watching -> struck\n    transition checked on bird_checked: struck -> watching\n}\n",
    )
    .expect("written");

    let (_, old, _) = petrel_nets::project::load_and_check(&uav).expect("the UAV mission");
    let old = old.expect("the UAV mission checks");
    let sem = Semantics::new(&old);
    let mut scratch = Scratch::default();
    let mut s = sem.initial(&mut NoEffects, &mut scratch);
    for e in [
        "start_mission",
        "rotation_speed",
        "airborne",
        "altitude_reached",
    ] {
        let id = old.event_id(e).expect("declared");
        sem.process_event(&mut s, id, None, &mut NoEffects, &mut scratch);
    }
    let deadlines = vec![Some(10_000_000u64)];
    let args = vec![Vec::new(); old.nets.len()];
    let from = OldState {
        state: &s,
        deadlines: &deadlines,
        net_args: &args,
    };
    let candidate = petrel_player::reload::version::load_candidate(dir.path(), "", "")
        .expect("the new version");
    let mapped = map_state(&old, &from, &candidate.project, &candidate.mapping).expect("maps");

    let runs = 20;
    let check = best(runs, || petrel_nets::project::load_and_check(dir.path()));
    let load = best(runs, || {
        petrel_player::reload::version::load_candidate(dir.path(), "", "").map(|c| c.source_hash)
    });
    let map = best(runs, || {
        map_state(&old, &from, &candidate.project, &candidate.mapping).map(|m| m.state)
    });
    let verify_from = best(runs, || verify_mapped(&candidate.project, &mapped, None));
    let verify_all = best(runs, || {
        petrel_nets::verify::verify(&candidate.project, Default::default()).map(|r| r.states)
    });
    let states = verify_mapped(&candidate.project, &mapped, None).expect("verified");
    let total = load + map + verify_from;
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    println!("reload of the UAV mission in transit (BIRDS added), best of {runs}:");
    println!(
        "  read + check + hash the new version: {:8.3} ms  ({:.2} x `load_and_check` alone, {:.3} ms)",
        ms(load),
        load.as_secs_f64() / check.as_secs_f64(),
        ms(check)
    );
    println!("  map the state:                       {:8.3} ms", ms(map));
    println!(
        "  verify from the mapped state:        {:8.3} ms  ({states} states; {:.2} x verifying from the start, {:.3} ms)",
        ms(verify_from),
        verify_from.as_secs_f64() / verify_all.as_secs_f64(),
        ms(verify_all)
    );
    println!(
        "  the player's whole check:            {:8.3} ms  ({:.2} x `load_and_check` + `verify`)",
        ms(total),
        total.as_secs_f64() / (check + verify_all).as_secs_f64()
    );
}
