//! In the steady state, processing an event allocates nothing (counted by
//! `allocation-counter`, whose global allocator counts every allocation of the measured code).

use petrel_nets::compiled::Value;
use petrel_nets::project::from_sources;
use petrel_player::engine::{Args, Engine, Sink};
/// Counts what calls carry, without allocating.
struct Sum(f64);
impl Sink for Sum {
    fn call(&mut self, _p: u32, _f: u32, args: Args<'_>) {
        for a in args.iter() {
            if let petrel_player::engine::ArgValue::Float(x) = a {
                self.0 += x;
            }
        }
    }
}

#[test]
fn processing_events_allocates_nothing_in_the_steady_state() {
    let manifest = r#"
[project]
name = "alloc"
files = ["a.pn"]
start = ["A", "B"]
[globals]
g = 1
[events]
tick = { category = "nominal", params = ["x: float"] }
tock = { category = "safety" }
[programs.P]
functions = { f = ["x: float", "k: int"] }
[timers]
t = { event = "tock" }
"#;
    let nets = "net A { place a = 1  place armed  place b
        transition go on tick(x): a -> armed { call P.f(x, 3)  start t after 1s }
        transition settle: armed, g -> b, g
        transition back on tock: b -> a { cancel t } }
      net B { place c = 1  transition loop on tick(x): c -> c { call P.f(2.5, 1) } }";
    let (_, c, d, _) = from_sources(manifest, &[("a.pn", nets)]);
    assert!(!d.has_errors(), "{d:?}");
    let c = c.unwrap();
    let mut e = Engine::new(&c);
    let mut sink = Sum(0.0);
    e.start(0, &mut sink);
    let round = |e: &mut Engine, sink: &mut Sum, i: u64| {
        let mut params = e.param_buffer();
        params.push(Value::Float(i as f64));
        e.submit_named("tick", params).unwrap();
        e.run_until_idle(sink);
        let none = e.param_buffer();
        e.submit_named("tock", none).unwrap();
        e.run_until_idle(sink);
    };
    // Warm up: buffers and queues reach their working size.
    for i in 0..100 {
        round(&mut e, &mut sink, i);
    }
    let info = allocation_counter::measure(|| {
        for i in 0..10_000 {
            round(&mut e, &mut sink, i);
        }
    });
    assert_eq!(
        info.count_total, 0,
        "allocations while processing 20,000 events"
    );
    assert_eq!(e.stats().processed, 20_200);
    assert!(sink.0 > 0.0);
}
