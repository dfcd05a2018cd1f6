//! The checker on any net file, in a project whose manifest declares events, programs, globals
//! and timers of every type, so that the fuzzer reaches resolution and typing, then the quick
//! verification (bounded) when the project compiles.
#![no_main]
use libfuzzer_sys::fuzz_target;

const MANIFEST: &str = r#"
[project]
name = "fuzz"
files = ["a.pn"]
start = ["A", "B"]

[globals]
ok = 1
down = 0

[events]
go = { category = "nominal" }
stop = { category = "safety", params = ["why: text"] }
at = { category = "mission", params = ["n: int", "x: float", "b: bool", "w: [float]"] }
tick = { category = "nominal" }

[programs.P]
functions = { f = ["n: int"], g = [], h = ["w: [float]", "s: text"] }

[timers]
t = { event = "tick" }
"#;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    let (_, compiled, d, sources) =
        petrel_nets::project::from_sources(MANIFEST, &[("a.pn", text.as_ref())]);
    // As in net_parse: rendering is fuzzed on the shorter inputs, where it is cheap enough.
    if data.len() <= 4096 {
        let _ = d.render_human(&sources);
    }
    if let Some(c) = compiled {
        let opts = petrel_verify::VerifyOptions {
            max_states: Some(200),
            ..Default::default()
        };
        let _ = petrel_verify::verify(&c, opts);
    }
});
