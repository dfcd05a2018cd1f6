//! Engine throughput: events per second on a 100-net project, one core.
//!
//! Run: `cargo bench -p petrel-player --bench engine`. Prints events per second for the engine
//! and, measured in the same run, for a baseline that does the least any event dispatcher
//! must do (a queue, a lookup of who waits for the event, a bit test and set per firing), and
//! the ratio. Timings are best-of-five, since the machine is shared.

use petrel_nets::compiled::Value;
use petrel_nets::project::from_sources;
use petrel_player::engine::{Args, Engine, Sink};
use std::collections::VecDeque;
use std::hint::black_box;
use std::time::Instant;

const NETS: usize = 100;
const EVENTS: u64 = 2_000_000;

/// A project of 100 nets, each a ring of four places moved round by four events, with a call on
/// one transition of every ring. `shared`: the four events are shared by every net (each event
/// fires 100 transitions); otherwise every net has its own four events (each event fires one
/// transition, the usual case in a mission).
fn project(shared: bool) -> (String, String) {
    let mut manifest =
        String::from("[project]\nname = \"bench\"\nfiles = [\"nets.pn\"]\nstart = [");
    manifest.push_str(
        &(0..NETS)
            .map(|i| format!("\"N{i}\""))
            .collect::<Vec<_>>()
            .join(", "),
    );
    manifest.push_str("]\n\n[events]\n");
    let event = |net: usize, k: usize| {
        if shared {
            format!("e{k}")
        } else {
            format!("n{net}e{k}")
        }
    };
    for n in 0..if shared { 1 } else { NETS } {
        for k in 0..4 {
            manifest.push_str(&format!(
                "{} = {{ category = \"nominal\", params = [\"x: float\"] }}\n",
                event(n, k)
            ));
        }
    }
    manifest.push_str("\n[programs.P]\nfunctions = { f = [\"x: float\"] }\n");
    let mut nets = String::new();
    for i in 0..NETS {
        nets.push_str(&format!(
            "net N{i} {{\n    place p0 = 1\n    place p1\n    place p2\n    place p3\n"
        ));
        for k in 0..4 {
            let action = if k == 0 { " { call P.f(x) }" } else { "" };
            nets.push_str(&format!(
                "    transition t{k} on {}(x): p{k} -> p{}{action}\n",
                event(i, k),
                (k + 1) % 4
            ));
        }
        nets.push_str("}\n");
    }
    (manifest, nets)
}

struct Count(u64);
impl Sink for Count {
    fn call(&mut self, _p: u32, _f: u32, args: Args<'_>) {
        self.0 += args.len() as u64;
    }
}

fn best_of<F: FnMut() -> f64>(mut f: F) -> f64 {
    (0..5).map(|_| f()).fold(f64::INFINITY, f64::min)
}

/// Events per second of the engine on `project(shared)`, best of five.
fn engine_rate(shared: bool) -> f64 {
    let (manifest, nets) = project(shared);
    let (_, compiled, d, _) = from_sources(&manifest, &[("nets.pn", &nets)]);
    assert!(!d.has_errors(), "{d:?}");
    let c = compiled.expect("bench project compiles");
    let events = c.events.iter().filter(|e| e.params.len() == 1).count() as u64;
    let secs = best_of(|| {
        let mut e = Engine::new(&c);
        let mut sink = Count(0);
        e.start(0, &mut sink);
        let t = Instant::now();
        for i in 0..EVENTS {
            let mut params = e.param_buffer();
            params.push(Value::Float(i as f64));
            // Events in ring order: each one finds its transition enabled.
            let ev = if shared {
                i % 4
            } else {
                (i / 4 % (events / 4)) * 4 + i % 4
            };
            e.submit(ev as u32, params).expect("valid event");
            e.step(&mut sink);
        }
        black_box(sink.0);
        t.elapsed().as_secs_f64()
    });
    EVENTS as f64 / secs
}

/// Events per second of the least any dispatcher does: a queue, the list of (net, bit) waiting
/// for the event, a bit test and a bit move per waiting net, a counter per call. No semantics,
/// no safety check, no actions. `per_event` nets wait for each event.
fn baseline_rate(per_event: usize) -> f64 {
    let secs = best_of(|| {
        let waiting: Vec<Vec<(usize, u32)>> = (0..4)
            .map(|k| (0..per_event).map(|n| (n, k as u32)).collect())
            .collect();
        let mut marking = vec![1u64; per_event];
        let mut queue: VecDeque<(u32, f64)> = VecDeque::with_capacity(16);
        let mut calls = 0u64;
        let t = Instant::now();
        for i in 0..EVENTS {
            queue.push_back(((i % 4) as u32, i as f64));
            let (e, x) = queue.pop_front().unwrap_or((0, 0.0));
            for &(n, bit) in &waiting[e as usize] {
                if marking[n] & (1 << bit) != 0 {
                    marking[n] = 1 << ((bit + 1) % 4);
                    if bit == 0 {
                        calls += black_box(x) as u64 & 1;
                    }
                }
            }
        }
        black_box((calls, &marking));
        t.elapsed().as_secs_f64()
    });
    EVENTS as f64 / secs
}

fn main() {
    let one = engine_rate(false);
    let all = engine_rate(true);
    let baseline_one = baseline_rate(1);
    let baseline_all = baseline_rate(NETS);
    println!(
        "engine throughput on a {NETS}-net project, one core, best of 5 runs of {EVENTS} events"
    );
    println!("  engine, each event fires 1 transition (own events per net): {one:>12.0} events/s");
    println!(
        "  engine, each event fires {NETS} transitions (events shared):  {all:>12.0} events/s ({:.1} M firings/s)",
        all * NETS as f64 / 1e6
    );
    println!("  baseline, bare queue + 1 bit move per event (same run):       {baseline_one:>12.0} events/s");
    println!("  baseline, bare queue + {NETS} bit moves per event (same run):   {baseline_all:>12.0} events/s");
    println!(
        "  ratio engine/baseline, 1 firing per event:   {:.2}",
        one / baseline_one
    );
    println!(
        "  ratio engine/baseline, {NETS} firings per event: {:.2}",
        all / baseline_all
    );
}
