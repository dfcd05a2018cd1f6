//! Crafted nesting is an error, never a stack overflow (issue 10, item 5): every recursive
//! reader of the front end is bounded. Each case runs on a thread with a small stack, so that
//! a bound that regressed would overflow it rather than pass on a large main stack.

use petrel_nets::diag::Diagnostics;
use petrel_nets::source::SourceMap;
use std::path::Path;

fn on_small_stack<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    on_stack(512 * 1024, f)
}

fn on_stack<T: Send + 'static>(bytes: usize, f: impl FnOnce() -> T + Send + 'static) -> T {
    std::thread::Builder::new()
        .stack_size(bytes)
        .spawn(f)
        .expect("thread")
        .join()
        .expect("no stack overflow")
}

fn codes(d: &Diagnostics) -> Vec<&'static str> {
    d.iter().map(|d| d.code).collect()
}

/// Found by hand while bounding the parsers: 300,000 nested elements in a petrel block
/// aborted `petrel import` (the tree's recursive drop overflowed the stack).
#[test]
fn a_petrel_block_nested_300000_deep_is_e0501() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../missions/uav");
    let loaded = petrel_nets::project::load(&dir).expect("the UAV reads");
    let pnml = petrel_nets::pnml::export_pnml(&loaded.project);
    let at = pnml.find("<toolspecific tool=\"petrel\"").unwrap();
    let at = at + pnml[at..].find('>').unwrap() + 1;
    let deep = format!(
        "{}{}{}{}",
        &pnml[..at],
        "<x>".repeat(300_000),
        "</x>".repeat(300_000),
        &pnml[at..]
    );
    let d = on_small_stack(move || {
        let mut sources = SourceMap::new();
        let id = sources.add("deep.pnml", deep.as_str());
        let mut d = Diagnostics::new();
        assert!(petrel_nets::pnml::import_pnml(id, &deep, &mut d).is_none());
        d
    });
    assert_eq!(codes(&d), ["E0501"]);
    assert!(d
        .iter()
        .next()
        .unwrap()
        .message
        .contains("nested more than 64"));
}

#[test]
fn an_argument_nested_30000_deep_is_e0001() {
    let d = on_small_stack(|| {
        let manifest = "[project]\nname = \"t\"\nfiles = [\"a.pn\"]\nstart = [\"A\"]\n";
        let net = format!(
            "net A {{\n    place p = 1\n    transition t: p -> p {{ emit e({}1.0{}) }}\n}}\n",
            "[".repeat(30_000),
            "]".repeat(30_000)
        );
        petrel_nets::project::from_sources(manifest, &[("a.pn", &net)]).2
    });
    assert!(codes(&d).iter().all(|c| *c == "E0001"), "{:?}", codes(&d));
    assert!(d
        .iter()
        .any(|d| d.message == "lists nested more than 32 deep"));
}

/// The toml crate bounds its own recursion: the manifest says so, it does not crash. (Its
/// bound fits the 8 MiB of a main thread, which is where every command reads its manifest,
/// but not 512 KiB in a debug build.)
#[test]
fn a_manifest_nested_100000_deep_is_e0101() {
    let d = on_stack(8 << 20, || {
        let manifest = format!(
            "[project]\nname = \"t\"\nfiles = {}{}\nstart = []\n",
            "[".repeat(100_000),
            "]".repeat(100_000)
        );
        petrel_nets::project::from_sources(&manifest, &[]).2
    });
    assert_eq!(codes(&d), ["E0101"]);
    assert!(d.iter().next().unwrap().message.contains("recursion limit"));
}
