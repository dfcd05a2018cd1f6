//! The projects the benchmarks run, written into a temporary directory.
//!
//! - The round-trip project: program `P<k>` emits `pong_<k>(n, data)`, net `R<k>` answers with
//!   the call `P<k>.ping(n, data)` (one program and one net per measured program), and net
//!   `LOAD` takes the background stream's `tick(n)`.
//! - The vehicle-path project: the data server turns a `Ping` frame into `ping(seq)` (an edge
//!   rule), net `V` answers with `CAN.Pong(seq)`, which the data server sends as a `Pong` frame.

use std::fmt::Write as _;
use std::path::Path;

/// The program name of the `k`-th measured program.
pub fn program_name(k: usize) -> String {
    format!("P{k}")
}

/// Writes the round-trip project for `programs` measured programs into `dir`.
pub fn write_round_trip(dir: &Path, programs: usize) -> std::io::Result<()> {
    let mut manifest = String::from(
        "# Written by petrel-bench: the round trip call -> program -> event -> transition -> call.\n\
         [project]\nname = \"bench\"\nfiles = [\"bench.pn\"]\n",
    );
    let mut start: Vec<String> = (0..programs).map(|k| format!("\"R{k}\"")).collect();
    start.push("\"LOAD\"".to_owned());
    let _ = writeln!(manifest, "start = [{}]\n\n[events]", start.join(", "));
    for k in 0..programs {
        let _ = writeln!(
            manifest,
            "pong_{k} = {{ category = \"nominal\", params = [\"n: int\", \"data: [float]\"] }}"
        );
    }
    let _ = writeln!(
        manifest,
        "tick = {{ category = \"nominal\", params = [\"n: int\"] }}\n"
    );
    for k in 0..programs {
        let name = program_name(k);
        let _ = writeln!(
            manifest,
            "[programs.{name}]\n[programs.{name}.functions]\nping = [\"n: int\", \"data: [float]\"]\n"
        );
    }
    let mut nets = String::new();
    for k in 0..programs {
        let name = program_name(k);
        let _ = writeln!(
            nets,
            "net R{k} {{\n    place idle = 1\n    transition answer on pong_{k}(n, data): idle -> idle {{\n        call {name}.ping(n, data)\n    }}\n}}\n"
        );
    }
    nets.push_str(
        "// The background stream: every tick fires a transition (and is journaled).\n\
         net LOAD {\n    place on = 1\n    transition count on tick(n): on -> on\n}\n",
    );
    std::fs::create_dir_all(dir)?;
    std::fs::write(dir.join("petrel.toml"), manifest)?;
    std::fs::write(dir.join("bench.pn"), nets)
}

/// The DBC of the vehicle-path project.
pub const VEHICLE_DBC: &str = r#"VERSION "petrel-bench-1"


NS_ :

BS_:

BU_: SUPERVISOR PROBE


BO_ 512 Ping: 5 PROBE
 SG_ flip : 0|1@1+ (1,0) [0|1] "" SUPERVISOR
 SG_ seq : 8|32@1+ (1,0) [0|4294967295] "" SUPERVISOR

BO_ 256 Pong: 5 SUPERVISOR
 SG_ seq : 8|32@1+ (1,0) [0|4294967295] "" PROBE

"#;

/// CAN id of the sensor frame the probe writes.
pub const PING_ID: u32 = 512;
/// CAN id of the command frame the data server writes.
pub const PONG_ID: u32 = 256;

/// Writes the vehicle-path project into `dir`; `interface` is can.toml's bus.
pub fn write_vehicle(dir: &Path, interface: &str) -> std::io::Result<()> {
    let manifest =
        "# Written by petrel-bench: a sensor frame -> data server rule -> event -> transition\n\
         # -> call to CAN -> command frame.\n\
         [project]\nname = \"vbench\"\nfiles = [\"v.pn\"]\nstart = [\"V\"]\n\n[events]\n\
         ping = { category = \"nominal\", params = [\"seq: float\"] }\n\n\
         [programs.CAN]\n[programs.CAN.functions]\nPong = [\"seq: float\"]\n";
    let net = "net V {\n    place idle = 1\n    transition answer on ping(seq): idle -> idle {\n        call CAN.Pong(seq)\n    }\n}\n";
    let can = format!(
        "dbc = \"v.dbc\"\n\n[bus]\ninterface = \"{interface}\"\n\n[commands]\nmessages = [\"Pong\"]\nprogram = \"CAN\"\n\n\
         # Every Ping frame flips `flip`: each one is an edge, each edge the event ping(seq).\n\
         [[rule]]\nevent = \"ping\"\nkind = \"edge\"\nsignal = \"Ping.flip\"\nequals = 1\nedge = \"both\"\nparams = [\"Ping.seq\"]\n"
    );
    std::fs::create_dir_all(dir)?;
    std::fs::write(dir.join("petrel.toml"), manifest)?;
    std::fs::write(dir.join("v.pn"), net)?;
    std::fs::write(dir.join("can.toml"), can)?;
    std::fs::write(dir.join("v.dbc"), VEHICLE_DBC)
}

/// The payload of the Ping frame for round `seq`: `flip` is 1 on even rounds, so that round 0
/// is already an edge (a rule's condition starts false).
pub fn ping_payload(seq: u32) -> [u8; 5] {
    let s = seq.to_le_bytes();
    [(!seq & 1) as u8, s[0], s[1], s[2], s[3]]
}

/// The sequence number a Pong frame carries.
pub fn pong_seq(payload: &[u8]) -> Option<u32> {
    let b: [u8; 4] = payload.get(1..5)?.try_into().ok()?;
    Some(u32::from_le_bytes(b))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(dir: &Path) -> petrel_nets::compiled::CompiledProject {
        let (_, compiled, diags) = petrel_nets::project::load_and_check(dir).expect("loads");
        assert!(!diags.has_errors(), "{diags:?}");
        compiled.expect("compiles")
    }

    #[test]
    fn the_round_trip_project_checks() {
        let dir = tempfile::tempdir().expect("tempdir");
        write_round_trip(dir.path(), 3).expect("written");
        let c = check(dir.path());
        assert_eq!(c.programs.len(), 3);
        assert_eq!(c.nets.len(), 4);
    }

    #[test]
    fn the_vehicle_project_checks_with_its_can_files() {
        let dir = tempfile::tempdir().expect("tempdir");
        write_vehicle(dir.path(), "vcan0").expect("written");
        let (mut loaded, compiled, mut diags) =
            petrel_nets::project::load_and_check(dir.path()).expect("loads");
        let compiled = compiled.expect("compiles");
        let can = petrel_can_bridge::load_project_can(
            dir.path(),
            &compiled,
            &mut loaded.sources,
            &mut diags,
        )
        .expect("reads");
        assert!(!diags.has_errors(), "{diags:?}");
        assert!(can.is_some());
    }

    #[test]
    fn ping_and_pong_payloads_carry_the_sequence() {
        let p = ping_payload(0x0102_0304);
        assert_eq!(p[0], 1);
        assert_eq!(ping_payload(1)[0], 0);
        assert_eq!(pong_seq(&p), Some(0x0102_0304));
        assert_eq!(pong_seq(&[1, 2]), None);
    }
}
