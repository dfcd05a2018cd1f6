//! A reload's mapping file on any text, applied to the UAV mission in transit mapped onto
//! itself: the mapping never panics, whatever names and shapes it holds.
#![no_main]
use libfuzzer_sys::fuzz_target;
use petrel_nets::compiled::CompiledProject;
use petrel_nets::reload::{map_state, Mapping, OldState};
use petrel_nets::semantics::{NoEffects, Scratch, Semantics};
use std::sync::OnceLock;

fn uav() -> &'static (CompiledProject, Vec<u64>) {
    static UAV: OnceLock<(CompiledProject, Vec<u64>)> = OnceLock::new();
    UAV.get_or_init(|| {
        let (_, compiled, d, _) = petrel_nets::project::from_sources(
            include_str!("../../missions/uav/petrel.toml"),
            &[
                ("mission.pn", include_str!("../../missions/uav/mission.pn")),
                ("events.pn", include_str!("../../missions/uav/events.pn")),
            ],
        );
        let c = compiled.unwrap_or_else(|| panic!("the UAV mission checks: {d:?}"));
        let sem = Semantics::new(&c);
        let mut scratch = Scratch::default();
        let mut s = sem.initial(&mut NoEffects, &mut scratch);
        for e in ["start_mission", "rotation_speed", "airborne", "altitude_reached"] {
            let id = c.event_id(e).expect("declared");
            sem.process_event(&mut s, id, None, &mut NoEffects, &mut scratch);
        }
        (c, s)
    })
}

fuzz_target!(|data: &[u8]| {
    let (p, s) = uav();
    let text = String::from_utf8_lossy(data);
    if let Ok(m) = Mapping::parse(&text) {
        let args = vec![Vec::new(); p.nets.len()];
        let deadlines = vec![Some(10_000_000); p.timers.len()];
        let from = OldState {
            state: s,
            deadlines: &deadlines,
            net_args: &args,
        };
        let _ = map_state(p, &from, p, &m);
    }
});
