//! Resident memory (from /proc) and start-up time of the vehicle's processes.

use std::collections::BTreeMap;
use std::path::Path;
use std::time::{Duration, Instant};

use petrel_ipc::{Participant, Reactor, Role, Vehicle, WaitStrategy};

use crate::measure::{clear_vehicle, vehicle_name, Kid};
use crate::roles::Res;

/// A field of /proc/PID/status in kB (`VmRSS`, `VmHWM`...).
pub fn status_kb(pid: u32, key: &str) -> Option<u64> {
    let text = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    text.lines()
        .find_map(|l| l.strip_prefix(key)?.strip_prefix(':'))
        .and_then(|v| v.split_whitespace().next()?.parse().ok())
}

/// Where a process's resident memory is, from /proc/PID/smaps: kB per kind of mapping.
#[derive(Clone, Debug, Default)]
pub struct Breakdown {
    /// kB per kind: "shared memory (iceoryx2)", "heap and anonymous", "binary", "libraries",
    /// "stack", "other".
    pub kinds: BTreeMap<String, u64>,
}

/// Reads /proc/PID/smaps.
pub fn breakdown(pid: u32) -> Option<Breakdown> {
    let text = std::fs::read_to_string(format!("/proc/{pid}/smaps")).ok()?;
    let exe = std::fs::read_link(format!("/proc/{pid}/exe")).ok();
    let mut b = Breakdown::default();
    let mut current: Option<String> = None; // the kind of the mapping being read
    for line in text.lines() {
        let first = line.split_whitespace().next().unwrap_or("");
        if first.contains('-') && first.chars().all(|c| c.is_ascii_hexdigit() || c == '-') {
            let fields: Vec<&str> = line.split_whitespace().collect();
            let path = fields.get(5).copied().unwrap_or("").to_owned();
            let kind = if path.starts_with("/dev/shm") || path.contains("iceoryx2") {
                "shared memory (iceoryx2)"
            } else if path.is_empty() || path == "[heap]" {
                "heap and anonymous"
            } else if path == "[stack]" {
                "stack"
            } else if exe
                .as_ref()
                .is_some_and(|e| Path::new(&path) == e.as_path())
            {
                "binary"
            } else if path.contains(".so") {
                "libraries"
            } else {
                "other"
            };
            current = Some(kind.to_owned());
        } else if let Some(v) = line.strip_prefix("Rss:") {
            let kb: u64 = v.split_whitespace().next()?.parse().ok()?;
            if let Some(kind) = &current {
                *b.kinds.entry(kind.clone()).or_default() += kb;
            }
        }
    }
    Some(b)
}

/// One process's footprint.
#[derive(Clone, Debug)]
pub struct Footprint {
    /// What it is.
    pub what: String,
    /// The command that starts it.
    pub command: String,
    /// Time from start to ready (its first heartbeat, or its ready line).
    pub ready: Option<Duration>,
    /// Resident memory a second after ready (kB).
    pub rss_kb: u64,
    /// Peak resident memory (kB).
    pub hwm_kb: u64,
    /// Where it is.
    pub breakdown: Option<Breakdown>,
}

/// How a process says it is ready.
pub enum ReadySign {
    /// Its first heartbeat on the vehicle.
    Heartbeat(String),
    /// A `READY` line (a role of this binary).
    ReadyLine,
    /// A line containing this text on its standard output.
    Line(&'static str),
}

/// Starts `exe args`, times it to ready, lets it settle a second and reads its memory.
pub fn measure(
    what: &str,
    exe: &Path,
    args: &[&str],
    command: String,
    sign: ReadySign,
) -> Res<Footprint> {
    // Listen before the process starts, so its first heartbeat is seen.
    let watch = match &sign {
        ReadySign::Heartbeat(vehicle) => {
            let v = Vehicle::new(vehicle).map_err(|e| e.to_string())?;
            let me = Participant::join(&v, Role::tool("benchfoot").map_err(|e| e.to_string())?)
                .map_err(|e| e.to_string())?;
            let beats = me.heartbeat_subscriber().map_err(|e| e.to_string())?;
            Some((me, beats))
        }
        _ => None,
    };
    let start = Instant::now();
    let mut kid = Kid::spawn(exe, args, what)?;
    let ready = match (&sign, &watch) {
        (ReadySign::Heartbeat(_), Some((_, beats))) => {
            let reactor =
                Reactor::without_signal_handling(WaitStrategy::Block).map_err(|e| e.to_string())?;
            let mut at = None;
            while start.elapsed() < Duration::from_secs(30) {
                reactor
                    .wait(&[beats], Some(Duration::from_millis(100)))
                    .map_err(|e| e.to_string())?;
                if beats.try_recv().map_err(|e| e.to_string())?.is_some() {
                    at = Some(start.elapsed());
                    break;
                }
            }
            at
        }
        (ReadySign::ReadyLine, _) => {
            kid.ready()?;
            Some(start.elapsed())
        }
        (ReadySign::Line(text), _) => loop {
            let line = kid.line()?;
            if line.is_empty() {
                break None;
            }
            if line.contains(text) {
                break Some(start.elapsed());
            }
        },
        _ => None,
    };
    std::thread::sleep(Duration::from_secs(1));
    let pid = kid.pid();
    let rss_kb = status_kb(pid, "VmRSS").unwrap_or(0);
    let hwm_kb = status_kb(pid, "VmHWM").unwrap_or(0);
    let breakdown = breakdown(pid);
    let _ = kid.terminate(Duration::from_secs(5));
    drop(watch);
    if let ReadySign::Heartbeat(v) = &sign {
        clear_vehicle(v);
    }
    Ok(Footprint {
        what: what.to_owned(),
        command,
        ready,
        rss_kb,
        hwm_kb,
        breakdown,
    })
}

/// The footprints of the vehicle's processes, and the baselines, in one run.
pub fn all(s: &crate::measure::Settings) -> Vec<Res<Footprint>> {
    let me = match std::env::current_exe() {
        Ok(p) => p,
        Err(e) => return vec![Err(format!("current exe: {e}"))],
    };
    let mut out = Vec::new();
    out.push(measure(
        "baseline: a Rust process that waits",
        &me,
        &["role", "idle"],
        "petrel-bench role idle".to_owned(),
        ReadySign::ReadyLine,
    ));
    out.push(measure(
        "baseline: a raw iceoryx2 node, one publish-subscribe service (64 B)",
        &me,
        &["role", "idle", "--iox"],
        "petrel-bench role idle --iox".to_owned(),
        ReadySign::ReadyLine,
    ));
    let journal = tempfile::tempdir();
    let uav = s.repo.join("missions/uav");
    let auv = s.repo.join("missions/auv");
    let redermor = s.repo.join("missions/redermor");
    let jdir = |name: &str| {
        journal
            .as_ref()
            .map(|d| d.path().join(name).display().to_string())
            .unwrap_or_else(|_| format!("/nonexistent/{name}"))
    };
    let players: Vec<(&str, &Path)> =
        vec![("UAV", uav.as_path()), ("Redermor", redermor.as_path())];
    for (name, dir) in players {
        let v = vehicle_name("fp");
        let j = jdir(&v);
        let d = dir.display().to_string();
        out.push(match &s.petrel {
            Some(petrel) => measure(
                &format!("player, {name} mission (`petrel play`)"),
                petrel,
                &["play", &d, "--vehicle", &v, "--journal", &j],
                format!("petrel play missions/{} --journal DIR", name.to_lowercase()),
                ReadySign::Heartbeat(v.clone()),
            ),
            None => measure(
                &format!("player, {name} mission (this binary's player role)"),
                &me,
                &[
                    "role",
                    "player",
                    "--dir",
                    &d,
                    "--vehicle",
                    &v,
                    "--journal",
                    &j,
                ],
                format!(
                    "petrel-bench role player --dir missions/{}",
                    name.to_lowercase()
                ),
                ReadySign::Heartbeat(v.clone()),
            ),
        });
    }
    if let Some(petrel) = &s.petrel {
        let v = vehicle_name("fpb");
        let d = auv.display().to_string();
        out.push(measure(
            "data server alone, AUV project (`petrel bridge --bus memory`)",
            petrel,
            &["bridge", &d, "--vehicle", &v, "--bus", "memory"],
            "petrel bridge missions/auv --bus memory".to_owned(),
            ReadySign::Heartbeat(v.clone()),
        ));
    } else {
        out.push(Err(
            "data server: no `petrel` binary next to this one".to_owned()
        ));
    }
    match &s.echo {
        Some(echo) => {
            let v = vehicle_name("fpe");
            out.push(measure(
                "program (the SDK's `echo` example)",
                echo,
                &[&v, "ECHO"],
                "target/release/examples/echo VEHICLE ECHO".to_owned(),
                ReadySign::Line("ready"),
            ));
            clear_vehicle(&v);
        }
        None => out.push(Err(
            "program: no `examples/echo` next to this binary".to_owned()
        )),
    }
    // The same program once a player runs: the player created the events service and
    // recorded its project's longest event there, so the program's sender is sized from it
    // (alone, above, the program created the service: 512-byte samples).
    if let (Some(echo), Some(petrel)) = (&s.echo, &s.petrel) {
        let v = vehicle_name("fpp");
        let j = jdir(&v);
        out.push(start_player(petrel, &uav, &v, &j).and_then(|player| {
            let m = measure(
                "program (`echo`) started after a player (UAV): events sized from the project",
                echo,
                &[&v, "ECHO"],
                "petrel play missions/uav, then target/release/examples/echo VEHICLE ECHO"
                    .to_owned(),
                ReadySign::Line("ready"),
            );
            let _ = player.terminate(Duration::from_secs(5));
            m
        }));
        clear_vehicle(&v);
    }
    out
}

/// Starts `petrel play DIR` on `vehicle` and returns it once its first heartbeat is seen.
fn start_player(petrel: &Path, dir: &Path, vehicle: &str, journal: &str) -> Res<Kid> {
    let v = Vehicle::new(vehicle).map_err(|e| e.to_string())?;
    let me = Participant::join(&v, Role::tool("benchwait").map_err(|e| e.to_string())?)
        .map_err(|e| e.to_string())?;
    let beats = me.heartbeat_subscriber().map_err(|e| e.to_string())?;
    let d = dir.display().to_string();
    let kid = Kid::spawn(
        petrel,
        &["play", &d, "--vehicle", vehicle, "--journal", journal],
        "player",
    )?;
    let reactor =
        Reactor::without_signal_handling(WaitStrategy::Block).map_err(|e| e.to_string())?;
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(30) {
        reactor
            .wait(&[&beats], Some(Duration::from_millis(100)))
            .map_err(|e| e.to_string())?;
        if beats.try_recv().map_err(|e| e.to_string())?.is_some() {
            return Ok(kid);
        }
    }
    let _ = kid.terminate(Duration::from_secs(5));
    Err("the player did not start within 30 s".to_owned())
}

/// Runs `petrel-bench role ports` and reads its steps.
pub fn ports() -> Res<Vec<(String, u64)>> {
    let me = std::env::current_exe().map_err(|e| format!("current exe: {e}"))?;
    let out = std::process::Command::new(me)
        .args(["role", "ports"])
        .output()
        .map_err(|e| format!("role ports: {e}"))?;
    if !out.status.success() {
        return Err(format!(
            "role ports failed: {}",
            String::from_utf8_lossy(&out.stderr).trim()
        ));
    }
    Ok(String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| {
            let (what, kb) = l.strip_prefix("STEP ")?.split_once('\t')?;
            Some((what.to_owned(), kb.trim().parse().ok()?))
        })
        .collect())
}
