//! Crafted nesting is an error, never a stack overflow (issue 10, item 5): every recursive
//! reader of the front end is bounded. Each case runs on a thread with a small stack, so that
//! a bound that regressed would overflow it rather than pass on a large main stack.

use petrel_diag::report::Diagnostics;
use petrel_diag::source::SourceMap;
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

/// A project whose nets form a tree: `levels` levels below the root `N0`, each net with
/// `width` children (the same net `width` times is not allowed, so each level has `width`
/// nets of its own, each declaring the next level's).
fn tree_of_nets(levels: usize, width: usize) -> String {
    let mut text = String::new();
    for l in 0..=levels {
        for w in 0..width {
            let children: Vec<String> = (0..width).map(|k| format!("N{}_{k}", l + 1)).collect();
            // One net at the root level, `width` at every other.
            if l == 0 && w > 0 {
                continue;
            }
            let name = format!("N{l}_{w}");
            if l < levels {
                text.push_str(&format!(
                    "net {name} {{\n    children {}\n    place p = 1\n}}\n",
                    children.join(", ")
                ));
            } else {
                text.push_str(&format!("net {name} {{\n    place p = 1\n}}\n"));
            }
        }
    }
    text
}

fn check_tree(levels: usize, width: usize) -> Diagnostics {
    let nets = tree_of_nets(levels, width);
    let manifest = "[project]\nname = \"t\"\nfiles = [\"a.pn\"]\nstart = [\"N0_0\"]\n";
    let (_, compiled, d, _) = petrel_nets::project::from_sources(manifest, &[("a.pn", &nets)]);
    assert!(compiled.is_none(), "a bounded expansion compiles nothing");
    d
}

/// Before: the checker expanded children recursively, one call per level: a chain of 20,000
/// nets, each the child of the one before, aborted `petrel check` with a stack overflow.
#[test]
fn a_chain_of_20000_children_is_e0305_not_a_stack_overflow() {
    let d = on_small_stack(|| check_tree(20_000, 1));
    assert_eq!(codes(&d), ["E0305"], "{d:?}");
    let e = d.iter().next().unwrap();
    assert!(e.message.contains("nets"), "{}", e.message);
    assert!(e.help.as_deref().unwrap_or("").contains("N0_0"), "{e:?}");
}

/// Before: 24 levels of nets with two children each expanded to 2^25 - 1 nets (16.7 million,
/// 11 GB) before anything was reported. The expansion stops at the limit and says where.
#[test]
fn a_tree_of_two_children_per_net_over_24_levels_is_e0305() {
    let d = check_tree(24, 2);
    assert_eq!(codes(&d), ["E0305"], "{d:?}");
    let e = d.iter().next().unwrap();
    assert!(
        e.message
            .contains(&petrel_nets::instances::MAX_INSTANCES.to_string()),
        "{}",
        e.message
    );
}

/// Below the limits, a tree expands as before: 2^13 - 1 instances check clean.
#[test]
fn a_tree_below_the_limits_checks_clean() {
    let nets = tree_of_nets(12, 2);
    let manifest = "[project]\nname = \"t\"\nfiles = [\"a.pn\"]\nstart = [\"N0_0\"]\n";
    let (_, compiled, d, _) = petrel_nets::project::from_sources(manifest, &[("a.pn", &nets)]);
    assert!(!d.has_errors(), "{d:?}");
    assert_eq!(compiled.expect("compiles").nets.len(), (1 << 13) - 1);
}

/// Before: a guard that did not read kept the nesting levels it had opened, so that after a few
/// such errors a simple guard later in the file was refused as "nested too deep".
#[test]
fn a_guard_that_does_not_read_gives_back_its_nesting_levels() {
    let mut text = String::from("net A {\n    place a = 1\n    place b\n");
    for i in 0..10 {
        text.push_str(&format!(
            "    transition bad{i} on e(x) if ((((((((((x ==: a -> b\n"
        ));
    }
    text.push_str("    transition good on e(x) if ((((x == 1) and not (x == 2)))): a -> b\n}\n");
    let mut sources = SourceMap::new();
    let id = sources.add("a.pn", text.as_str());
    let mut d = Diagnostics::new();
    let file = petrel_nets::syntax::parse_file(id, "a.pn", &text, &mut d);
    let messages: Vec<String> = d
        .iter()
        .map(|x| {
            format!(
                "{}: {} ({})",
                x.code,
                x.message,
                x.help.as_deref().unwrap_or("")
            )
        })
        .collect();
    assert_eq!(messages.len(), 10, "one error per bad guard: {messages:?}");
    assert!(
        messages.iter().all(|m| !m.contains("nest at most")),
        "{messages:?}"
    );
    assert!(
        format!("{file:?}").contains("\"good\""),
        "the good transition reads"
    );
}

/// The guard nesting bound itself still holds: 65 levels are refused, 64 read.
#[test]
fn guards_nest_at_most_64_levels() {
    let guard = |levels: usize| {
        format!(
            "net A {{\n    place a = 1\n    transition t on e(x) if {}x == 1{}: a -> a\n}}\n",
            "(".repeat(levels - 1),
            ")".repeat(levels - 1)
        )
    };
    let errors = |text: String| {
        let mut sources = SourceMap::new();
        let id = sources.add("a.pn", text.as_str());
        let mut d = Diagnostics::new();
        petrel_nets::syntax::parse_file(id, "a.pn", &text, &mut d);
        d.iter()
            .map(|x| format!("{} ({})", x.message, x.help.as_deref().unwrap_or("")))
            .collect::<Vec<_>>()
    };
    assert_eq!(errors(guard(64)), Vec::<String>::new());
    let e = errors(guard(65));
    assert!(e.iter().any(|m| m.contains("nest at most 64")), "{e:?}");
}
