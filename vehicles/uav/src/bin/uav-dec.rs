//! The simulated decision program (DEC) of the UAV mission (`missions/uav`, the ProCoSA paper's
//! example): it holds the list of waypoints, each with the payload to use there.
//!
//! - `DEC.next_waypoint()` emits `waypoint(position, payload)` for the next waypoint, or
//!   `no_more_waypoints` when every one was given;
//! - `DEC.replan_without(payload)` drops the remaining waypoints that use `payload`, then emits
//!   `replanned`;
//! - `DEC.nearest_site()` emits `emergency_site(site)`.
//!
//! Each answer comes after `--think` simulated seconds (1 by default) scaled by `--speed` (600
//! simulated seconds per second by default). The process stops on SIGINT or SIGTERM, or, with
//! `--idle-exit SECONDS`, after that long without a call once calls have begun. For tests of a
//! supervisor, `--crash-after-answers N` exits with code 3 once its Nth answer is acknowledged
//! by the player, in its first run only (not once `petrel up` has restarted it).
//!
//! `cargo run -p uav --bin uav-dec -- --vehicle uav`

use std::collections::VecDeque;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use clap::Parser;
use petrel_programs::{
    event_text, Call, Program, ProgramConfig, ProgramError, Value, Vehicle, DEFAULT_OUTBOX_CAPACITY,
};

/// The simulated DEC program of the UAV mission.
#[derive(Debug, Parser)]
#[command(name = "uav-dec")]
struct Args {
    /// The vehicle to join.
    #[arg(long, value_name = "NAME")]
    vehicle: String,
    /// Simulated seconds per second of wall-clock time.
    #[arg(long, default_value_t = 600.0, value_parser = positive)]
    speed: f64,
    /// A waypoint, `LAT,LON,ALT,PAYLOAD`; repeat the flag for each, in flight order. Default:
    /// 48.71,2.21,300,camera 48.75,2.30,300,lidar 48.80,2.40,300,camera.
    #[arg(long = "waypoint", value_name = "LAT,LON,ALT,PAYLOAD", value_parser = waypoint)]
    waypoints: Vec<Waypoint>,
    /// The emergency landing site `nearest_site` gives, `LAT,LON,ALT`.
    #[arg(long, value_name = "LAT,LON,ALT", default_value = "48.60,2.10,150", value_parser = site)]
    site: Site,
    /// Simulated seconds DEC thinks before each answer.
    #[arg(long, value_name = "SECONDS", default_value_t = 1.0)]
    think: f64,
    /// Exit after this many seconds (wall clock) without a call, counted from the first call
    /// on (a DEC started early waits for the player as long as it takes).
    #[arg(long, value_name = "SECONDS", value_parser = positive)]
    idle_exit: Option<f64>,
    /// Events kept while no player receives them.
    #[arg(long, value_name = "EVENTS", default_value_t = DEFAULT_OUTBOX_CAPACITY)]
    outbox: usize,
    /// Exit with code 3, as a crash would, once the Nth answer is delivered (and acknowledged,
    /// so the flight can go on). Only in the first run: a DEC that `petrel up` restarted
    /// (environment PETREL_RESTARTS above 0) does not crash again.
    #[arg(long, value_name = "N")]
    crash_after_answers: Option<u32>,
}

fn positive(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v > 0.0 && v.is_finite() => Ok(v),
        _ => Err(format!("`{s}` is not a positive number")),
    }
}

#[derive(Debug, Clone, PartialEq)]
struct Waypoint {
    position: Vec<f64>,
    payload: String,
}

#[derive(Debug, Clone, PartialEq)]
struct Site(Vec<f64>);

fn numbers(parts: &[&str], what: &str) -> Result<Vec<f64>, String> {
    parts
        .iter()
        .map(|p| {
            p.trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("`{p}` is not a number ({what})"))
        })
        .collect()
}

fn waypoint(s: &str) -> Result<Waypoint, String> {
    let parts: Vec<&str> = s.split(',').collect();
    let [lat, lon, alt, payload] = parts.as_slice() else {
        return Err(format!(
            "`{s}` is not a waypoint; write LAT,LON,ALT,PAYLOAD (48.71,2.21,300,camera)"
        ));
    };
    let payload = payload.trim();
    if payload.is_empty() {
        return Err(format!("`{s}` names no payload"));
    }
    Ok(Waypoint {
        position: numbers(&[lat, lon, alt], "LAT,LON,ALT")?,
        payload: payload.to_owned(),
    })
}

fn site(s: &str) -> Result<Site, String> {
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() != 3 {
        return Err(format!(
            "`{s}` is not a site; write LAT,LON,ALT (48.60,2.10,150)"
        ));
    }
    Ok(Site(numbers(&parts, "LAT,LON,ALT")?))
}

fn default_waypoints() -> Vec<Waypoint> {
    [
        ([48.71, 2.21, 300.0], "camera"),
        ([48.75, 2.30, 300.0], "lidar"),
        ([48.80, 2.40, 300.0], "camera"),
    ]
    .into_iter()
    .map(|(position, payload)| Waypoint {
        position: position.to_vec(),
        payload: payload.to_owned(),
    })
    .collect()
}

/// An answer to emit at a given time.
#[derive(Debug)]
struct Answer {
    due: Instant,
    event: &'static str,
    params: Vec<Value>,
}

#[derive(Debug)]
struct Dec {
    remaining: VecDeque<Waypoint>,
    site: Site,
    think: Duration,
    answers: VecDeque<Answer>,
}

impl Dec {
    fn answer(&mut self, event: &'static str, params: Vec<Value>) {
        self.answers.push_back(Answer {
            due: Instant::now() + self.think,
            event,
            params,
        });
    }

    fn handle(&mut self, call: &Call) -> Result<(), ProgramError> {
        match call.function.as_str() {
            "next_waypoint" => {
                call.expect_arity(0)?;
                match self.remaining.pop_front() {
                    Some(w) => self.answer(
                        "waypoint",
                        vec![Value::FloatList(w.position), Value::Text(w.payload)],
                    ),
                    None => self.answer("no_more_waypoints", vec![]),
                }
            }
            "replan_without" => {
                call.expect_arity(1)?;
                let payload = call.text(0)?;
                let before = self.remaining.len();
                self.remaining.retain(|w| w.payload != payload);
                println!(
                    "uav-dec: replanned without the {payload}: {} of {before} waypoints left",
                    self.remaining.len()
                );
                self.answer("replanned", vec![]);
            }
            "nearest_site" => {
                call.expect_arity(0)?;
                let site = self.site.0.clone();
                self.answer("emergency_site", vec![Value::FloatList(site)]);
            }
            _ => return Err(call.unknown_function()),
        }
        Ok(())
    }
}

fn main() -> ExitCode {
    let args = Args::parse();
    let vehicle = match Vehicle::new(&args.vehicle) {
        Ok(v) => v,
        Err(e) => {
            eprintln!("uav-dec: {e}");
            return ExitCode::from(2);
        }
    };
    let config = ProgramConfig {
        outbox_capacity: args.outbox,
        ..ProgramConfig::default()
    };
    let mut program = match Program::connect_with(&vehicle, &["DEC"], config) {
        Ok(p) => p,
        Err(e) => {
            eprintln!("uav-dec: {e}");
            return ExitCode::from(2);
        }
    };
    let waypoints = if args.waypoints.is_empty() {
        default_waypoints()
    } else {
        args.waypoints.clone()
    };
    println!(
        "uav-dec: DEC ready on vehicle {} with {} waypoints (speed x{})",
        args.vehicle,
        waypoints.len(),
        args.speed
    );
    let mut dec = Dec {
        remaining: waypoints.into(),
        site: args.site.clone(),
        think: Duration::from_secs_f64(args.think.max(0.0) / args.speed),
        answers: VecDeque::new(),
    };
    let idle = args.idle_exit.map(Duration::from_secs_f64);
    let restarted = std::env::var("PETREL_RESTARTS")
        .ok()
        .and_then(|n| n.parse::<u32>().ok())
        .is_some_and(|n| n > 0);
    let crash_after = args.crash_after_answers.filter(|_| !restarted);
    let mut answered = 0u32;
    let mut last_call: Option<Instant> = None;
    let mut status = ExitCode::SUCCESS;
    loop {
        while dec.answers.front().is_some_and(|a| a.due <= Instant::now()) {
            let Some(a) = dec.answers.pop_front() else {
                break;
            };
            println!("uav-dec: DEC emits {}", event_text(a.event, &a.params));
            if let Err(e) = program.emit(a.event, a.params) {
                eprintln!("uav-dec: {e}");
            }
            answered += 1;
            if crash_after == Some(answered) {
                println!("uav-dec: crashing after {answered} answers (--crash-after-answers)");
                // A crash says no goodbye: once the player has the answer on record, the
                // process ends without `close` (no leave on the wire), so the player reports
                // `program_lost`, as it would for a real crash.
                match program.acknowledged_within(Duration::from_secs(2)) {
                    Ok(true) => {}
                    Ok(false) => eprintln!("uav-dec: the answer is not acknowledged"),
                    Err(e) => eprintln!("uav-dec: {e}"),
                }
                std::process::exit(3);
            }
        }
        let now = Instant::now();
        let idle_deadline = idle.zip(last_call).map(|(d, last)| last + d);
        if dec.answers.is_empty() && idle_deadline.is_some_and(|d| now >= d) {
            println!(
                "uav-dec: no call for {:.1} s, leaving",
                args.idle_exit.unwrap_or(0.0)
            );
            break;
        }
        let next = dec
            .answers
            .front()
            .map(|a| a.due)
            .into_iter()
            .chain(idle_deadline)
            .min();
        match program.recv(next.map(|d| d.saturating_duration_since(now))) {
            Ok(Some(call)) => {
                last_call = Some(Instant::now());
                println!("uav-dec: call {call}");
                if let Err(e) = dec.handle(&call) {
                    eprintln!("uav-dec: error: {e}; the call is ignored");
                }
            }
            Ok(None) => {}
            Err(e) if e.is_termination() => {
                println!("uav-dec: termination requested, leaving");
                break;
            }
            Err(e) if e.is_fatal() => {
                eprintln!("uav-dec: {e}");
                status = ExitCode::FAILURE;
                break;
            }
            Err(e) => eprintln!("uav-dec: error: {e}"),
        }
    }
    match program.close(Duration::from_secs(2)) {
        Ok(stats) => println!(
            "uav-dec: done: {} calls, {} events delivered, {} dropped, {} undelivered",
            stats.calls, stats.delivered, stats.dropped, stats.queued
        ),
        Err(e) => eprintln!("uav-dec: {e}"),
    }
    status
}
