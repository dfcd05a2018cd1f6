//! A mission script of any text (`petrel run --script`, and the event of `petrel send`),
//! against the UAV mission; a script that reads is run in virtual time.
#![no_main]
use libfuzzer_sys::fuzz_target;
use petrel_nets::compiled::CompiledProject;
use std::sync::OnceLock;

fn uav() -> &'static CompiledProject {
    static UAV: OnceLock<CompiledProject> = OnceLock::new();
    UAV.get_or_init(|| {
        let (_, compiled, d, _) = petrel_nets::project::from_sources(
            include_str!("../../missions/uav/petrel.toml"),
            &[
                ("mission.pn", include_str!("../../missions/uav/mission.pn")),
                ("events.pn", include_str!("../../missions/uav/events.pn")),
            ],
        );
        compiled.unwrap_or_else(|| panic!("the UAV mission checks: {d:?}"))
    })
}

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    if let Ok(script) = petrel_player::script::parse_script(&text, uav()) {
        // Bounded: a script of a few lines at most, in virtual time.
        if script.lines.len() <= 64 {
            let _ = petrel_player::script::run_script(uav(), &script, |_| {});
        }
    }
});
