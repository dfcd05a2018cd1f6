//! Round-trip latency between two processes through Petrel's services, for each wait strategy.
//!
//! The "player" process sends a call to program `ECHO`; the echo process (this binary run
//! again with `pong`) answers with an event; the player measures the time from send to
//! receipt. Both sides use the same [`WaitStrategy`].
//!
//! ```text
//! cargo run --release -p petrel-ipc --example latency -- [--rounds N] [--gap-us N]
//!     [--strategies block,spin,spin-then-block:200]
//! ```
//!
//! `--gap-us` pauses between rounds (as events arrive in flight, with idle time between them);
//! without it, rounds follow each other at once and both processes stay busy.

use std::error::Error;
use std::io::{BufRead, BufReader, Write};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use petrel_ipc::{
    remove_vehicle_files, wire, CallMsg, EventMsg, Participant, Reactor, Role, Value, Vehicle,
    WaitStrategy,
};

fn payload(i: usize) -> Vec<Value> {
    vec![Value::Int(i as i64), Value::FloatList(vec![0.5; 6])]
}

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().map(String::as_str) == Some("pong") {
        return pong(&args[1..]);
    }
    let mut rounds = 5_000usize;
    let mut strategies = vec![
        WaitStrategy::Block,
        WaitStrategy::Spin,
        WaitStrategy::SpinThenBlock(Duration::from_micros(200)),
    ];
    let mut gap = Duration::ZERO;
    let mut it = args.iter();
    while let Some(arg) = it.next() {
        match arg.as_str() {
            "--rounds" => rounds = it.next().ok_or("--rounds needs a number")?.parse()?,
            "--gap-us" => {
                gap = Duration::from_micros(it.next().ok_or("--gap-us needs a number")?.parse()?)
            }
            "--strategies" => {
                strategies = it
                    .next()
                    .ok_or("--strategies needs a list")?
                    .split(',')
                    .map(str::parse)
                    .collect::<Result<_, _>>()?
            }
            other => return Err(format!("unknown argument `{other}`").into()),
        }
    }
    let body = wire::encoded_len(&CallMsg::new("ping", payload(0)))?;
    println!(
        "round trip call -> event, {body}-byte body, {rounds} rounds after 500 of warm-up, \
         {} µs between rounds, {} build",
        gap.as_micros(),
        if cfg!(debug_assertions) {
            "debug"
        } else {
            "release"
        }
    );
    println!(
        "{:<22} {:>9} {:>9} {:>9} {:>9} {:>9}",
        "strategy", "p50 µs", "p90 µs", "p99 µs", "p99.9 µs", "max µs"
    );
    for strategy in strategies {
        let mut samples = ping(strategy, rounds, gap)?;
        samples.sort_unstable();
        let pct = |p: f64| {
            let i = ((samples.len() as f64 - 1.0) * p).round() as usize;
            samples[i].as_secs_f64() * 1e6
        };
        println!(
            "{:<22} {:>9.2} {:>9.2} {:>9.2} {:>9.2} {:>9.2}",
            strategy.to_string(),
            pct(0.5),
            pct(0.9),
            pct(0.99),
            pct(0.999),
            pct(1.0)
        );
    }
    Ok(())
}

fn ping(
    strategy: WaitStrategy,
    rounds: usize,
    gap: Duration,
) -> Result<Vec<Duration>, Box<dyn Error>> {
    let vehicle = Vehicle::isolated("latency")?;
    let samples = {
        let player = Participant::join(&vehicle, Role::Player)?;
        let events = player.event_receiver()?;
        let calls = player.call_sender("ECHO")?;
        let mut echo = Command::new(std::env::current_exe()?)
            .args([
                "pong",
                vehicle.name(),
                vehicle.prefix(),
                &strategy.to_string(),
            ])
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()?;
        let mut line = String::new();
        BufReader::new(echo.stdout.take().ok_or("no stdout")?).read_line(&mut line)?;
        if line.trim() != "READY" {
            return Err(format!("echo process said `{}`", line.trim()).into());
        }
        let reactor = Reactor::new(strategy)?;
        let warmup = 500;
        let mut samples = Vec::with_capacity(rounds);
        for i in 0..warmup + rounds {
            if !gap.is_zero() {
                std::thread::sleep(gap);
            }
            let start = Instant::now();
            calls.send(&CallMsg::new("ping", payload(i)))?;
            'wait: loop {
                let ready = reactor.wait(&[&events], Some(Duration::from_secs(5)))?;
                if ready.timed_out() {
                    return Err(format!("no answer to round {i}").into());
                }
                while let Some(answer) = events.try_recv()? {
                    if answer.msg.params.first() == Some(&Value::Int(i as i64)) {
                        break 'wait;
                    }
                }
            }
            if i >= warmup {
                samples.push(start.elapsed());
            }
        }
        calls.send(&CallMsg::new("stop", vec![]))?;
        if let Some(mut stdin) = echo.stdin.take() {
            let _ = stdin.flush();
        }
        echo.wait()?;
        samples
    };
    let _ = remove_vehicle_files(&vehicle);
    Ok(samples)
}

fn pong(args: &[String]) -> Result<(), Box<dyn Error>> {
    let [name, prefix, strategy] = args else {
        return Err("usage: latency pong NAME PREFIX STRATEGY".into());
    };
    let vehicle = Vehicle::with_prefix(name, prefix)?;
    let me = Participant::join(&vehicle, Role::program("ECHO")?)?;
    let calls = me.call_receiver()?;
    let events = me.event_sender()?;
    let reactor = Reactor::new(strategy.parse()?)?;
    println!("READY");
    std::io::stdout().flush()?;
    loop {
        let ready = reactor.wait(&[&calls], Some(Duration::from_secs(30)))?;
        if ready.timed_out() || ready.termination_requested() {
            return Ok(());
        }
        while let Some(call) = calls.try_recv()? {
            if call.msg.function == "stop" {
                return Ok(());
            }
            events.send(&EventMsg::new("pong", call.msg.args))?;
        }
    }
}
