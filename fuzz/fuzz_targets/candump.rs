//! `candump -L` text of any content: the line reader, then the replay of what it read through
//! the AUV mission's data server core (`petrel bridge --replay`), with its real can.toml and
//! DBC.
#![no_main]
use libfuzzer_sys::fuzz_target;
use petrel_can_bridge::{BridgeCore, CanConfig, Dbc, ManualClock};
use petrel_diag::report::Diagnostics;
use petrel_diag::source::FileId;
use std::sync::{Arc, OnceLock};

fn auv() -> &'static (CanConfig, Arc<Dbc>) {
    static AUV: OnceLock<(CanConfig, Arc<Dbc>)> = OnceLock::new();
    AUV.get_or_init(|| {
        let (_, compiled, d, _) = petrel_nets::project::from_sources(
            include_str!("../../missions/auv/petrel.toml"),
            &[
                ("phases.pn", include_str!("../../missions/auv/phases.pn")),
                ("safety.pn", include_str!("../../missions/auv/safety.pn")),
            ],
        );
        let c = compiled.unwrap_or_else(|| panic!("the AUV mission checks: {d:?}"));
        let dbc = Dbc::parse(include_str!("../../missions/auv/auv.dbc")).expect("auv.dbc reads");
        let mut d = Diagnostics::new();
        let config = petrel_can_bridge::check_rules(
            FileId(0),
            include_str!("../../missions/auv/can.toml"),
            &dbc,
            &c,
            &mut d,
        )
        .unwrap_or_else(|| panic!("the AUV can.toml checks: {d:?}"));
        (config, Arc::new(dbc))
    })
}

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    for line in text.lines() {
        if let Ok(r) = petrel_can_bridge::log::parse_line(line) {
            let _ = petrel_can_bridge::log::format_record(&r);
        }
    }
    let (config, dbc) = auv();
    let start = petrel_can_bridge::log::read_log(&text)
        .ok()
        .and_then(|r| r.first().map(|r| r.time_us))
        .unwrap_or(0);
    let mut core = BridgeCore::new(dbc.clone(), config.clone(), start);
    let _ = petrel_can_bridge::replay::replay_text(
        &mut core,
        &text,
        petrel_can_bridge::replay::Pacing::AsFastAsPossible,
        &ManualClock::new(0),
    );
});
