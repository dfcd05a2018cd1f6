//! The example mission of the paper (Figures 4 and 5) checks clean.

use petrel_nets::project::load_and_check;
use std::path::Path;

#[test]
fn uav_mission_checks_clean() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../missions/uav");
    let (loaded, compiled, d) = load_and_check(&dir).expect("the UAV project reads");
    assert!(d.is_empty(), "{}", d.render_human(&loaded.sources));
    let c = compiled.expect("compiled");
    let names: Vec<_> = c.nets.iter().map(|n| n.name.as_str()).collect();
    assert_eq!(names, ["MISSION", "EVENTS"]);
    assert_eq!(c.start.len(), 2);
    let programs: Vec<_> = c.programs.iter().map(|p| p.name.as_str()).collect();
    assert!(programs.contains(&"GUI") && programs.contains(&"DEC"));
    // The replanning transition of MISSION exists and waits for DEC's answer.
    let mission = &c.nets[0];
    let replanning = mission
        .transitions
        .iter()
        .find(|t| t.name == "replanning")
        .expect("MISSION has a replanning transition");
    assert_eq!(replanning.event, c.event_id("replanned"));
}
