//! Tests of the Graphviz DOT drawing (`petrel_nets::dot`).
//!
//! A small structural validator below parses the subset of DOT the drawing uses and checks what
//! Graphviz would trip on or silently get wrong: balanced braces and brackets, terminated
//! strings, unique node declarations, and edges whose ends are all declared nodes (Graphviz
//! would invent an unstyled node for a typo instead of failing). The drawings of the language's
//! newer constructs also go through the real `dot` (`scripts/test.sh` installs Graphviz), which
//! must accept them without a warning.
//!
//! The whole-project golden is `tests/data/dot/survey.dot`; run with `PETREL_BLESS=1` to rewrite
//! it after an intended change, then review the difference.

use petrel_diag::duration::TimeUnit;
use petrel_diag::source::Span;
use petrel_nets::dot::{instance_dot, overview_tree_dot, project_to_dot, project_tree_dot};
use petrel_nets::model::*;

// ---------------------------------------------------------------------------------------------
// Building projects.

fn name(s: &str) -> Name {
    Name::synthetic(s)
}

fn names(list: &[&str]) -> Vec<Name> {
    list.iter().map(|s| name(s)).collect()
}

fn place(n: &str, tokens: u32) -> Item {
    item(ItemKind::Place(PlaceDecl {
        name: name(n),
        tokens,
        tokens_span: None,
    }))
}

fn item(kind: ItemKind) -> Item {
    Item {
        allows: Vec::new(),
        trivia: Trivia::default(),
        kind,
        trailing: None,
    }
}

fn transition(
    n: &str,
    trigger: Option<Trigger>,
    inputs: &[&str],
    outputs: &[&str],
    actions: Vec<Action>,
) -> Item {
    item(ItemKind::Transition(TransitionDecl {
        guard: None,
        empty: Vec::new(),
        name: name(n),
        trigger,
        inputs: names(inputs),
        outputs: names(outputs),
        actions: actions
            .into_iter()
            .map(|action| ActionItem {
                trivia: Trivia::default(),
                action,
                trailing: None,
            })
            .collect(),
        end_comments: Vec::new(),
    }))
}

fn trigger(event: &str, bindings: &[(&str, Option<Type>)]) -> Option<Trigger> {
    Some(Trigger {
        event: name(event),
        bindings: bindings
            .iter()
            .map(|(n, ty)| Binding {
                name: name(n),
                ty: ty.map(|t| (t, Span::default())),
            })
            .collect(),
    })
}

fn net(n: &str, items: Vec<Item>) -> NetDecl {
    NetDecl {
        allows: Vec::new(),
        params: Vec::new(),
        trivia: Trivia::default(),
        name: name(n),
        items,
        end_comments: Vec::new(),
    }
}

fn global(n: &str, tokens: u32) -> GlobalPlaceDecl {
    GlobalPlaceDecl {
        nets: None,
        name: name(n),
        tokens,
    }
}

fn project(
    project_name: &str,
    start: &[&str],
    globals: Vec<GlobalPlaceDecl>,
    nets: Vec<NetDecl>,
) -> Project {
    Project {
        manifest: Manifest {
            name: project_name.to_string(),
            files: vec![FileRef {
                path: "nets/main.pn".to_string(),
                span: Span::default(),
            }],
            start: names(start),
            globals,
            ..Manifest::default()
        },
        files: vec![NetFile {
            path: "nets/main.pn".to_string(),
            nets,
            end_comments: Vec::new(),
        }],
    }
}

/// Two nets, `Flight` active at start and `Payload` not; the global place `link` is used by
/// both, `comms` only by `Flight`; `Payload` names a place `ghost` that exists nowhere.
fn survey() -> Project {
    let flight = net(
        "Flight",
        vec![
            place("idle", 1),
            place("flying", 0),
            transition(
                "takeoff",
                trigger("go", &[("alt", None), ("reason", Some(Type::Text))]),
                &["idle", "link"],
                &["flying"],
                vec![
                    Action::Call {
                        program: name("GUI"),
                        function: name("say"),
                        args: vec![
                            Expr::Text("say \"hi\" \\ now".to_string(), Span::default()),
                            Expr::Var(name("alt")),
                        ],
                        span: Span::default(),
                    },
                    Action::StartTimer {
                        timer: name("watchdog"),
                        after: DurationExpr::Literal {
                            value: 30.0,
                            unit: TimeUnit::Seconds,
                            span: Span::default(),
                        },
                    },
                    Action::Activate {
                        net: name("Payload"),
                        args: Vec::new(),
                        span: Default::default(),
                    },
                ],
            ),
            transition(
                "land",
                None,
                &["flying"],
                &["idle", "link", "comms"],
                vec![],
            ),
        ],
    );
    let payload = net(
        "Payload",
        vec![
            place("ready", 1),
            place("busy", 0),
            transition(
                "work",
                trigger("tick", &[]),
                &["ready", "link"],
                &["busy"],
                vec![Action::Emit {
                    to: None,
                    event: name("done"),
                    args: vec![],
                    span: Span::default(),
                }],
            ),
            transition(
                "finish",
                None,
                &["busy", "ghost"],
                &["ready", "link"],
                vec![],
            ),
        ],
    );
    project(
        "survey",
        &["Flight"],
        vec![global("link", 1), global("comms", 0)],
        vec![flight, payload],
    )
}

// ---------------------------------------------------------------------------------------------
// A structural DOT validator for the subset the drawing uses.

#[derive(Clone, Debug, PartialEq)]
enum Tok {
    /// An unquoted identifier or numeral.
    Id(String),
    /// A quoted string, inner text as written (escapes kept).
    Str(String),
    /// `{ } [ ] ; , =` or `->`.
    Punct(&'static str),
}

fn tokenize(text: &str) -> Result<Vec<Tok>, String> {
    let chars: Vec<char> = text.chars().collect();
    let mut toks = Vec::new();
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        if c.is_whitespace() {
            i += 1;
        } else if c == '/' && chars.get(i + 1) == Some(&'/') {
            while i < chars.len() && chars[i] != '\n' {
                i += 1;
            }
        } else if c == '"' {
            let mut s = String::new();
            i += 1;
            loop {
                match chars.get(i) {
                    None => return Err("unterminated string".to_string()),
                    Some('"') => break,
                    Some('\\') => {
                        let next = chars
                            .get(i + 1)
                            .ok_or_else(|| "backslash at end of input".to_string())?;
                        s.push('\\');
                        s.push(*next);
                        i += 2;
                    }
                    Some(&ch) => {
                        s.push(ch);
                        i += 1;
                    }
                }
            }
            i += 1;
            toks.push(Tok::Str(s));
        } else if c == '-' && chars.get(i + 1) == Some(&'>') {
            toks.push(Tok::Punct("->"));
            i += 2;
        } else if let Some(p) = ["{", "}", "[", "]", ";", ",", "="]
            .into_iter()
            .find(|p| p.starts_with(c))
        {
            toks.push(Tok::Punct(p));
            i += 1;
        } else if c.is_ascii_alphabetic() || c == '_' {
            let start = i;
            while i < chars.len() && (chars[i].is_ascii_alphanumeric() || chars[i] == '_') {
                i += 1;
            }
            toks.push(Tok::Id(chars[start..i].iter().collect()));
        } else if c.is_ascii_digit() || c == '.' || c == '-' {
            // A numeral: -?(.digits | digits(.digits?)?).
            let start = i;
            if c == '-' {
                i += 1;
            }
            let digits_start = i;
            while i < chars.len() && (chars[i].is_ascii_digit() || chars[i] == '.') {
                i += 1;
            }
            let body: String = chars[digits_start..i].iter().collect();
            if body.is_empty() || body == "." || body.matches('.').count() > 1 {
                return Err(format!("bad numeral at character {start}"));
            }
            toks.push(Tok::Id(chars[start..i].iter().collect()));
        } else {
            return Err(format!("unexpected character {c:?} at {i}"));
        }
    }
    Ok(toks)
}

/// Attributes as written: key, then the value's raw text (escapes kept).
type Attrs = Vec<(String, String)>;

/// What the validator learnt from a drawing.
#[derive(Debug, Default)]
struct Dot {
    /// Declared nodes: id, attributes, and the cluster they are declared in (if any).
    nodes: Vec<(String, Attrs, Option<String>)>,
    /// Edges: from, to, attributes.
    edges: Vec<(String, String, Attrs)>,
    /// Subgraph names with their graph attributes (`label=...` statements).
    clusters: Vec<(String, Attrs)>,
}

impl Dot {
    fn node(&self, id: &str) -> &[(String, String)] {
        let found: Vec<_> = self.nodes.iter().filter(|n| n.0 == id).collect();
        assert_eq!(found.len(), 1, "node {id} declared {} times", found.len());
        &found[0].1
    }

    fn node_ids(&self) -> Vec<&str> {
        self.nodes.iter().map(|n| n.0.as_str()).collect()
    }
}

fn attr<'a>(attrs: &'a [(String, String)], key: &str) -> Option<&'a str> {
    attrs
        .iter()
        .find(|(k, _)| k == key)
        .map(|(_, v)| v.as_str())
}

struct Parser {
    toks: Vec<Tok>,
    pos: usize,
    dot: Dot,
}

impl Parser {
    fn peek(&self) -> Option<&Tok> {
        self.toks.get(self.pos)
    }

    fn next(&mut self) -> Result<Tok, String> {
        let t = self
            .toks
            .get(self.pos)
            .cloned()
            .ok_or_else(|| "unexpected end of input".to_string())?;
        self.pos += 1;
        Ok(t)
    }

    fn expect(&mut self, p: &str) -> Result<(), String> {
        match self.next()? {
            Tok::Punct(q) if q == p => Ok(()),
            t => Err(format!("expected `{p}`, found {t:?}")),
        }
    }

    fn id(&mut self) -> Result<String, String> {
        match self.next()? {
            Tok::Id(s) | Tok::Str(s) => Ok(s),
            t => Err(format!("expected an id, found {t:?}")),
        }
    }

    fn is_punct(&self, p: &str) -> bool {
        matches!(self.peek(), Some(Tok::Punct(q)) if *q == p)
    }

    fn graph(mut self) -> Result<Dot, String> {
        match self.next()? {
            Tok::Id(k) if k == "digraph" => {}
            t => return Err(format!("expected `digraph`, found {t:?}")),
        }
        if !self.is_punct("{") {
            self.id()?;
        }
        self.expect("{")?;
        self.stmts(None)?;
        self.expect("}")?;
        if self.pos != self.toks.len() {
            return Err("text after the closing brace".to_string());
        }
        Ok(self.dot)
    }

    fn stmts(&mut self, cluster: Option<&str>) -> Result<(), String> {
        while !self.is_punct("}") {
            if self.peek().is_none() {
                return Err("missing `}`".to_string());
            }
            self.stmt(cluster)?;
            if self.is_punct(";") {
                self.pos += 1;
            }
        }
        Ok(())
    }

    fn attrs(&mut self) -> Result<Attrs, String> {
        let mut out = Vec::new();
        while self.is_punct("[") {
            self.pos += 1;
            while !self.is_punct("]") {
                let k = self.id()?;
                self.expect("=")?;
                let v = self.id()?;
                out.push((k, v));
                if self.is_punct(",") || self.is_punct(";") {
                    self.pos += 1;
                }
            }
            self.expect("]")?;
        }
        Ok(out)
    }

    fn stmt(&mut self, cluster: Option<&str>) -> Result<(), String> {
        if let Some(Tok::Id(k)) = self.peek() {
            match k.as_str() {
                "graph" | "node" | "edge" => {
                    self.pos += 1;
                    self.attrs()?;
                    return Ok(());
                }
                "subgraph" => {
                    self.pos += 1;
                    let sub = self.id()?;
                    if cluster.is_some() {
                        return Err("nested subgraph".to_string());
                    }
                    self.dot.clusters.push((sub.clone(), Vec::new()));
                    self.expect("{")?;
                    self.stmts(Some(&sub))?;
                    self.expect("}")?;
                    return Ok(());
                }
                _ => {}
            }
        }
        let first = self.id()?;
        if self.is_punct("=") {
            self.pos += 1;
            let v = self.id()?;
            if cluster.is_some() {
                if let Some(c) = self.dot.clusters.last_mut() {
                    c.1.push((first, v));
                }
            }
            return Ok(());
        }
        if self.is_punct("->") {
            let mut ends = vec![first];
            while self.is_punct("->") {
                self.pos += 1;
                ends.push(self.id()?);
            }
            let attrs = self.attrs()?;
            for w in ends.windows(2) {
                self.dot
                    .edges
                    .push((w[0].clone(), w[1].clone(), attrs.clone()));
            }
            return Ok(());
        }
        let attrs = self.attrs()?;
        self.dot
            .nodes
            .push((first, attrs, cluster.map(str::to_string)));
        Ok(())
    }
}

/// Parses `text` as DOT and checks its structure; the parsed drawing on success.
fn validate(text: &str) -> Result<Dot, String> {
    // Braces and brackets balance outside strings (checked apart from the parser, so a broken
    // parser cannot hide an imbalance).
    let toks = tokenize(text)?;
    let mut depth = [0i64; 2];
    for t in &toks {
        match t {
            Tok::Punct("{") => depth[0] += 1,
            Tok::Punct("}") => depth[0] -= 1,
            Tok::Punct("[") => depth[1] += 1,
            Tok::Punct("]") => depth[1] -= 1,
            _ => {}
        }
        if depth[0] < 0 || depth[1] < 0 {
            return Err("closing brace or bracket before its opening".to_string());
        }
    }
    if depth != [0, 0] {
        return Err(format!("unbalanced braces or brackets: {depth:?}"));
    }
    let dot = Parser {
        toks,
        pos: 0,
        dot: Dot::default(),
    }
    .graph()?;
    let mut seen = std::collections::BTreeSet::new();
    for (id, _, _) in &dot.nodes {
        if !seen.insert(id.as_str()) {
            return Err(format!("node {id} declared twice"));
        }
    }
    for (from, to, _) in &dot.edges {
        for end in [from, to] {
            if !seen.contains(end.as_str()) {
                return Err(format!("edge {from} -> {to}: {end} is not a declared node"));
            }
        }
    }
    Ok(dot)
}

fn draw(p: &Project, only: Option<&str>) -> (String, Dot) {
    let text = project_to_dot(p, only).expect("drawing");
    let dot = validate(&text).unwrap_or_else(|e| panic!("invalid DOT: {e}\n{text}"));
    (text, dot)
}

// ---------------------------------------------------------------------------------------------
// Tests.

#[test]
fn whole_project_matches_golden() {
    let text = project_to_dot(&survey(), None).expect("drawing");
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/dot/survey.dot");
    if std::env::var_os("PETREL_BLESS").is_some() {
        std::fs::create_dir_all(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/dot"))
            .expect("create golden directory");
        std::fs::write(path, &text).expect("write golden");
    }
    let golden = std::fs::read_to_string(path).expect("read golden (PETREL_BLESS=1 writes it)");
    assert_eq!(text, golden, "DOT differs from {path}");
}

#[test]
fn output_is_deterministic() {
    let p = survey();
    assert_eq!(project_to_dot(&p, None), project_to_dot(&p, None));
    assert_eq!(
        project_to_dot(&p, Some("Payload")),
        project_to_dot(&p, Some("Payload"))
    );
}

#[test]
fn whole_and_filtered_drawings_are_valid_dot() {
    let p = survey();
    for only in [None, Some("Flight"), Some("Payload")] {
        draw(&p, only);
    }
}

#[test]
fn validator_rejects_broken_dot() {
    assert!(
        validate("digraph \"a\" { \"x\" -> \"y\"; }").is_err(),
        "undeclared ends"
    );
    assert!(
        validate("digraph \"a\" { \"x\"; ").is_err(),
        "missing brace"
    );
    assert!(
        validate("digraph \"a\" { \"x\" [label=\"a]; }").is_err(),
        "open string"
    );
    assert!(
        validate("digraph \"a\" { \"x\"; \"x\"; }").is_err(),
        "duplicate node"
    );
    assert!(validate("digraph \"a\" { \"x\"; \"y\"; \"x\" -> \"y\"; }").is_ok());
}

#[test]
fn graph_has_layout_font_and_one_cluster_per_net() {
    let (text, dot) = draw(&survey(), None);
    assert!(text.starts_with("digraph \"survey\" {\n"));
    assert!(text.contains("rankdir=LR"));
    assert!(text.contains("fontname=\"Helvetica\""));
    let clusters: Vec<&str> = dot.clusters.iter().map(|c| c.0.as_str()).collect();
    assert_eq!(clusters, ["cluster_Flight", "cluster_Payload"]);
    let label = |i: usize| {
        attr(&dot.clusters[i].1, "label")
            .unwrap_or_default()
            .to_string()
    };
    assert_eq!(label(0), "Flight: active at start");
    assert!(label(1).starts_with("Payload: inactive at start"));
    assert!(label(1).contains("marking when activated"));
}

#[test]
fn global_place_is_drawn_once_outside_clusters_with_arcs_from_both_nets() {
    let (text, dot) = draw(&survey(), None);
    let declared: Vec<_> = dot.nodes.iter().filter(|n| n.0 == "global.link").collect();
    assert_eq!(declared.len(), 1);
    assert_eq!(declared[0].2, None, "global place drawn inside a cluster");
    let lines = text
        .lines()
        .filter(|l| l.trim_start().starts_with("\"global.link\" [shape"));
    assert_eq!(lines.count(), 1);
    let link = dot.node("global.link");
    assert_eq!(attr(link, "shape"), Some("doublecircle"));
    assert_eq!(attr(link, "style"), Some("filled"), "link holds a token");
    assert_eq!(
        attr(dot.node("global.comms"), "style"),
        None,
        "comms is empty"
    );

    // Arcs touch it from transitions of both nets, in both directions.
    let touching: Vec<(&str, &str)> = dot
        .edges
        .iter()
        .filter(|e| e.0 == "global.link" || e.1 == "global.link")
        .map(|e| (e.0.as_str(), e.1.as_str()))
        .collect();
    assert_eq!(
        touching,
        [
            ("global.link", "Flight.t.takeoff"),
            ("Flight.t.land", "global.link"),
            ("global.link", "Payload.t.work"),
            ("Payload.t.finish", "global.link"),
        ]
    );
    // No net has a node of its own for it.
    assert!(!dot
        .node_ids()
        .iter()
        .any(|id| id.ends_with(".link") && *id != "global.link"));
}

#[test]
fn marked_places_are_filled_and_dormant_marking_is_lighter() {
    let (_, dot) = draw(&survey(), None);
    let idle = dot.node("Flight.idle");
    assert_eq!(attr(idle, "shape"), Some("circle"));
    assert_eq!(attr(idle, "xlabel"), Some("idle"));
    assert_eq!(attr(idle, "style"), Some("filled"));
    let dark = attr(idle, "fillcolor").expect("fill");
    assert_eq!(attr(dot.node("Flight.flying"), "style"), None);

    let ready = dot.node("Payload.ready");
    assert_eq!(attr(ready, "style"), Some("filled"));
    let light = attr(ready, "fillcolor").expect("fill");
    assert_ne!(dark, light, "a dormant net's marking must look different");
    assert!(attr(ready, "tooltip").is_some_and(|t| t.contains("when activated")));
    assert_eq!(attr(dot.node("Payload.busy"), "style"), None);
}

#[test]
fn transitions_show_trigger_or_immediate_and_escaped_actions() {
    let (_, dot) = draw(&survey(), None);
    let takeoff = dot.node("Flight.t.takeoff");
    assert_eq!(attr(takeoff, "shape"), Some("box"));
    // Raw DOT text: the action's own quotes and backslash are escaped once more for DOT.
    assert_eq!(
        attr(takeoff, "label"),
        Some(
            r#"takeoff\lon go(alt, reason: text)\lcall GUI.say(\"say \\\"hi\\\" \\\\ now\", alt)\lstart watchdog after 30s\lactivate Payload\l"#
        )
    );
    assert_eq!(
        attr(dot.node("Flight.t.land"), "label"),
        Some(r"land\limmediate\l")
    );
    assert_eq!(
        attr(dot.node("Payload.t.work"), "label"),
        Some(r"work\lon tick\lemit done\l")
    );
}

#[test]
fn arcs_follow_inputs_and_outputs_in_order() {
    let (_, dot) = draw(&survey(), None);
    let flight: Vec<(&str, &str)> = dot
        .edges
        .iter()
        .filter(|e| e.0.starts_with("Flight.") || e.1.starts_with("Flight."))
        .map(|e| (e.0.as_str(), e.1.as_str()))
        .collect();
    assert_eq!(
        flight,
        [
            ("Flight.idle", "Flight.t.takeoff"),
            ("global.link", "Flight.t.takeoff"),
            ("Flight.t.takeoff", "Flight.flying"),
            ("Flight.flying", "Flight.t.land"),
            ("Flight.t.land", "Flight.idle"),
            ("Flight.t.land", "global.link"),
            ("Flight.t.land", "global.comms"),
        ]
    );
}

#[test]
fn unknown_place_is_a_dashed_red_node_in_its_net() {
    let (_, dot) = draw(&survey(), None);
    let ghost = dot
        .nodes
        .iter()
        .find(|n| n.0 == "Payload.unknown.ghost")
        .expect("unknown place node");
    assert_eq!(ghost.2.as_deref(), Some("cluster_Payload"));
    assert_eq!(attr(&ghost.1, "xlabel"), Some("unknown place ghost"));
    assert_eq!(attr(&ghost.1, "style"), Some("dashed"));
    assert!(attr(&ghost.1, "color").is_some());
    assert!(dot.edges.iter().any(|e| e.0 == "Payload.unknown.ghost"
        && e.1 == "Payload.t.finish"
        && attr(&e.2, "style") == Some("dashed")));
}

#[test]
fn only_net_keeps_that_net_and_the_globals_it_touches() {
    let p = survey();
    let (text, dot) = draw(&p, Some("Payload"));
    let clusters: Vec<&str> = dot.clusters.iter().map(|c| c.0.as_str()).collect();
    assert_eq!(clusters, ["cluster_Payload"]);
    assert!(!text.contains("Flight."), "Flight leaked into:\n{text}");
    assert!(dot
        .node_ids()
        .iter()
        .all(|id| id.starts_with("Payload.") || id.starts_with("global.")));
    assert!(dot.node_ids().contains(&"global.link"));
    assert!(
        !dot.node_ids().contains(&"global.comms"),
        "Payload does not use comms"
    );

    let (_, flight) = draw(&p, Some("Flight"));
    let globals: Vec<&str> = flight
        .node_ids()
        .into_iter()
        .filter(|id| id.starts_with("global."))
        .collect();
    assert_eq!(globals, ["global.link", "global.comms"], "manifest order");
    assert!(!flight
        .node_ids()
        .iter()
        .any(|id| id.starts_with("Payload.")));
}

#[test]
fn unknown_net_is_an_error_naming_the_nets() {
    let err = project_to_dot(&survey(), Some("Nope")).expect_err("no such net");
    assert_eq!(err, "no net named `Nope`; the nets are: Flight, Payload");
    let empty = project("empty", &[], vec![], vec![]);
    let err = project_to_dot(&empty, Some("Nope")).expect_err("no such net");
    assert!(err.contains("`Nope`") && err.contains("no nets"), "{err}");
}

#[test]
fn local_place_shadows_global_of_same_name() {
    let p = project(
        "shadow",
        &["A", "B"],
        vec![global("link", 1)],
        vec![
            net(
                "A",
                vec![
                    place("link", 0),
                    transition("t", None, &["link"], &[], vec![]),
                ],
            ),
            net("B", vec![transition("t", None, &[], &["link"], vec![])]),
        ],
    );
    let (_, dot) = draw(&p, None);
    let pairs: Vec<(&str, &str)> = dot
        .edges
        .iter()
        .map(|e| (e.0.as_str(), e.1.as_str()))
        .collect();
    assert_eq!(pairs, [("A.link", "A.t.t"), ("B.t.t", "global.link")]);
    // Only B touches the global place.
    let (_, only_a) = draw(&p, Some("A"));
    assert!(!only_a.node_ids().contains(&"global.link"));
}

#[test]
fn awkward_names_still_give_valid_unique_dot() {
    // A quote and a newline in the project name, two nets with one name, a net named `global`
    // with a place named like a global place, a place and a transition with one name.
    let p = project(
        "say \"hi\"\nback\\slash",
        &["global"],
        vec![global("x", 1)],
        vec![
            net(
                "global",
                vec![place("x", 1), transition("x", None, &["x"], &["x"], vec![])],
            ),
            net("N", vec![place("p", 0)]),
            net(
                "N",
                vec![place("p", 1), transition("u", None, &["x"], &["p"], vec![])],
            ),
        ],
    );
    let (text, dot) = draw(&p, None);
    assert!(text.starts_with("digraph \"say \\\"hi\\\"\\lback\\\\slash\" {"));
    assert_eq!(dot.clusters.len(), 3);
    // The second N's arc to x reaches the global place, not the net `global`'s own x.
    assert!(dot
        .edges
        .iter()
        .any(|e| e.0 == "global.x" && e.1 == "N#2.t.u"));
    let (_, both) = draw(&p, Some("N"));
    assert_eq!(both.clusters.len(), 2);
}

#[test]
fn empty_project_is_valid_dot() {
    let (text, dot) = draw(&Project::default(), None);
    assert!(dot.nodes.is_empty() && dot.edges.is_empty());
    assert!(text.starts_with("digraph \"\" {"));
}

// ---------------------------------------------------------------------------------------------
// The constructs of structured missions (nets/tests/data/language).

/// The language project, which must check clean.
fn language() -> Project {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/language");
    let (loaded, compiled, diags) = petrel_nets::project::load_and_check(&dir).expect("readable");
    assert!(compiled.is_some() && diags.is_empty(), "{diags:?}");
    loaded.project
}

/// Runs the real Graphviz on `text`: it must lay it out without an error or a warning.
fn graphviz(text: &str) {
    use std::io::Write as _;
    use std::process::{Command, Stdio};
    let child = Command::new("dot")
        .arg("-Tsvg")
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn();
    let mut child = child
        .expect("graphviz `dot` is missing: run the suite with scripts/test.sh, which installs it");
    child
        .stdin
        .take()
        .expect("stdin")
        .write_all(text.as_bytes())
        .expect("write to dot");
    let out = child.wait_with_output().expect("dot runs");
    assert!(
        out.status.success() && out.stderr.is_empty(),
        "graphviz rejects the drawing: {}\n{text}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("<svg"));
}

fn edge<'a>(dot: &'a Dot, from: &str, to: &str) -> Vec<&'a Attrs> {
    dot.edges
        .iter()
        .filter(|e| e.0 == from && e.1 == to)
        .map(|e| &e.2)
        .collect()
}

fn cluster_of<'a>(dot: &'a Dot, node: &str) -> Option<&'a str> {
    dot.nodes
        .iter()
        .find(|n| n.0 == node)
        .and_then(|n| n.2.as_deref())
}

#[test]
fn instances_are_drawn_apart_and_share_their_globals() {
    let p = language();
    let (text, dot) = draw(&p, None);
    graphviz(&text);
    let clusters: Vec<&str> = dot.clusters.iter().map(|c| c.0.as_str()).collect();
    assert_eq!(
        clusters,
        [
            "cluster_R1",
            "cluster_R2",
            "cluster_SYNC",
            "cluster_PLAN",
            "cluster_PHASES",
            "cluster_PHASES/TRANSIT",
            "cluster_PHASES/SURVEY"
        ],
        "the template ROBOT is drawn once per instance, never alone"
    );
    let label = |c: &str| {
        let attrs = &dot.clusters.iter().find(|x| x.0 == c).unwrap().1;
        attr(attrs, "label").unwrap().to_string()
    };
    // Parameters with their values, or their types when bound at activation.
    assert_eq!(
        label("cluster_R1"),
        r#"R1 = ROBOT(robot: text = \"r1\", speed: float = 0.5): active at start"#
    );
    assert!(label("cluster_PLAN").starts_with("PLAN(heading: float): inactive at start"));
    assert!(label("cluster_PHASES/TRANSIT")
        .starts_with("PHASES/TRANSIT = TRANSIT(speed: float = 0.5): inactive"));
    // Each instance has its own places; both take and give back the one global token.
    assert_eq!(cluster_of(&dot, "R1.moving"), Some("cluster_R1"));
    assert_eq!(cluster_of(&dot, "R2.moving"), Some("cluster_R2"));
    assert_eq!(cluster_of(&dot, "global.bottleneck_free"), None);
    for r in ["R1", "R2"] {
        assert_eq!(
            edge(&dot, "global.bottleneck_free", &format!("{r}.t.pass")).len(),
            1
        );
        assert_eq!(
            edge(&dot, &format!("{r}.t.leave_it"), "global.bottleneck_free").len(),
            1
        );
    }
    // A scoped global says which nets see it.
    assert!(attr(dot.node("global.bottleneck_free"), "tooltip")
        .unwrap()
        .contains("shared by ROBOT, SYNC"));
}

#[test]
fn guards_emptiness_tests_emit_targets_and_finish_are_drawn() {
    let (text, dot) = draw(&language(), None);
    // The guard follows the trigger; an emission says where it goes.
    assert_eq!(
        attr(dot.node("R1.t.enter"), "label"),
        Some(r"enter\lon at_bottleneck(r) if r == self.robot\l")
    );
    assert_eq!(
        attr(dot.node("PHASES.t.nudge"), "label"),
        Some(r"nudge\lon heading(d) if d > 10.0\lemit arrived to TRANSIT\l")
    );
    // `not alarm`: an inhibitor arc, ending in a small circle at the transition.
    let tested = edge(&dot, "global.alarm", "SYNC.t.raise");
    assert_eq!(tested.len(), 1, "{text}");
    assert_eq!(attr(tested[0], "arrowhead"), Some("odot"));
    // The output arc to alarm is an ordinary one.
    let marked = edge(&dot, "SYNC.t.raise", "global.alarm");
    assert_eq!(marked.len(), 1);
    assert_eq!(attr(marked[0], "arrowhead"), None);
    // Completion places are the parent's; `finish` marks them from the child's instance.
    assert_eq!(
        cluster_of(&dot, "PHASES.done.TRANSIT"),
        Some("cluster_PHASES")
    );
    assert_eq!(
        attr(dot.node("PHASES.done.TRANSIT"), "xlabel"),
        Some("TRANSIT.done")
    );
    assert_eq!(edge(&dot, "PHASES.done.TRANSIT", "PHASES.t.next").len(), 1);
    let finish = edge(&dot, "PHASES/TRANSIT.t.arrive", "PHASES.done.TRANSIT");
    assert_eq!(finish.len(), 1, "{text}");
    assert_eq!(attr(finish[0], "label"), Some("finish"));
    assert_eq!(
        attr(dot.node("PHASES/TRANSIT.t.arrive"), "label"),
        Some(r"arrive\lon arrived\lfinish\l")
    );
}

#[test]
fn a_template_name_draws_all_its_instances() {
    let p = language();
    let (text, dot) = draw(&p, Some("ROBOT"));
    graphviz(&text);
    let clusters: Vec<&str> = dot.clusters.iter().map(|c| c.0.as_str()).collect();
    assert_eq!(clusters, ["cluster_R1", "cluster_R2"]);
    let globals: Vec<&str> = dot
        .node_ids()
        .into_iter()
        .filter(|id| id.starts_with("global."))
        .collect();
    assert_eq!(globals, ["global.bottleneck_free"]);
    // A child alone: its `finish` arc has no parent to reach, and is left out.
    let (text, dot) = draw(&p, Some("PHASES/TRANSIT"));
    graphviz(&text);
    assert_eq!(dot.clusters.len(), 1);
    assert!(
        dot.edges.iter().all(|e| !e.1.starts_with("PHASES.")),
        "{text}"
    );
    // The error lists the nets and the templates.
    let err = project_to_dot(&p, Some("NOPE")).unwrap_err();
    assert!(
        err.contains("R1, R2, SYNC, PLAN, PHASES, PHASES/TRANSIT, PHASES/SURVEY")
            && err.contains("templates (all their instances): ROBOT"),
        "{err}"
    );
}

/// Before `instance_dot`, a net's view was the whole drawing zoomed on its frame: the arcs to
/// the global places it uses crossed the canvas. Alone, everything is inside its frame.
#[test]
fn one_instance_alone_has_its_globals_and_its_parents_completion_place_as_ports() {
    let p = language();
    let text = instance_dot(&p, "R1").expect("R1 is a net");
    let dot = validate(&text).unwrap_or_else(|e| panic!("invalid DOT: {e}\n{text}"));
    graphviz(&text);
    assert_eq!(dot.clusters.len(), 1);
    // Every node in the net's frame, the global place too, as a port saying what it is.
    for (id, _, cluster) in &dot.nodes {
        assert_eq!(
            cluster.as_deref(),
            Some("cluster_R1"),
            "{id} outside R1's frame"
        );
    }
    let port = dot.node("global.bottleneck_free");
    assert_eq!(attr(port, "shape"), Some("box"));
    assert_eq!(attr(port, "label"), Some("global bottleneck_free"));
    assert_eq!(edge(&dot, "global.bottleneck_free", "R1.t.pass").len(), 1);
    assert!(!text.contains("R2."), "only R1:\n{text}");
    // A child: its parent's completion place, which its `finish` marks, is a port too.
    let text = instance_dot(&p, "PHASES/TRANSIT").expect("a child");
    let dot = validate(&text).unwrap_or_else(|e| panic!("invalid DOT: {e}\n{text}"));
    graphviz(&text);
    assert_eq!(
        cluster_of(&dot, "PHASES.done.TRANSIT"),
        Some("cluster_PHASES/TRANSIT")
    );
    assert_eq!(
        attr(dot.node("PHASES.done.TRANSIT"), "label"),
        Some("PHASES: TRANSIT.done")
    );
    assert_eq!(
        edge(&dot, "PHASES/TRANSIT.t.arrive", "PHASES.done.TRANSIT").len(),
        1
    );
    // A template's name is not one net: the error lists the nets there are.
    let err = instance_dot(&p, "ROBOT").unwrap_err();
    assert!(err.contains("no net named `ROBOT`"), "{err}");
}

#[test]
fn the_overview_tree_names_children_briefly_and_draws_each_edge_once() {
    let p = language();
    let text = overview_tree_dot(&p);
    let dot = validate(&text).unwrap_or_else(|e| panic!("invalid DOT: {e}\n{text}"));
    graphviz(&text);
    assert!(text.contains("rankdir=LR"));
    // A child says its last name only; an instance its template, without its parameters.
    assert_eq!(attr(dot.node("PHASES/TRANSIT"), "label"), Some("TRANSIT"));
    assert_eq!(attr(dot.node("R1"), "label"), Some(r"R1\n= ROBOT"));
    // Between a parent and its child, the tree's edge alone.
    for (from, to, _) in &dot.edges {
        let n = dot
            .edges
            .iter()
            .filter(|e| &e.0 == from && &e.1 == to)
            .count();
        assert_eq!(n, 1, "{from} -> {to} drawn {n} times:\n{text}");
    }
}

#[test]
fn the_tree_shows_children_and_activations() {
    let p = language();
    let text = project_tree_dot(&p);
    let dot = validate(&text).unwrap_or_else(|e| panic!("invalid DOT: {e}\n{text}"));
    graphviz(&text);
    assert!(text.contains("rankdir=TB"));
    assert!(
        dot.clusters.is_empty(),
        "the tree draws no place or transition"
    );
    assert_eq!(
        dot.node_ids(),
        [
            "R1",
            "R2",
            "SYNC",
            "PLAN",
            "PHASES",
            "PHASES/TRANSIT",
            "PHASES/SURVEY"
        ]
    );
    assert_eq!(
        attr(dot.node("R2"), "label"),
        Some(r#"R2\nROBOT(robot: text = \"r2\", speed: float = 0.4)"#)
    );
    assert_eq!(
        attr(dot.node("PLAN"), "label"),
        Some("PLAN(heading: float)")
    );
    // Active at start: filled.
    assert!(attr(dot.node("SYNC"), "style").unwrap().contains("filled"));
    assert_eq!(attr(dot.node("PLAN"), "style"), None);
    // Children: solid; activations: dashed, labelled, along the tree or across it.
    let solid: Vec<(&str, &str)> = dot
        .edges
        .iter()
        .filter(|e| attr(&e.2, "style").is_none())
        .map(|e| (e.0.as_str(), e.1.as_str()))
        .collect();
    assert_eq!(
        solid,
        [("PHASES", "PHASES/TRANSIT"), ("PHASES", "PHASES/SURVEY")]
    );
    let dashed: Vec<(&str, &str)> = dot
        .edges
        .iter()
        .filter(|e| attr(&e.2, "style") == Some("dashed"))
        .map(|e| {
            assert_eq!(attr(&e.2, "label"), Some("activate"));
            (e.0.as_str(), e.1.as_str())
        })
        .collect();
    assert_eq!(
        dashed,
        [
            ("SYNC", "PLAN"),
            ("PHASES", "PHASES/TRANSIT"),
            ("PHASES", "PHASES/SURVEY")
        ]
    );
    // The survey project has no children: its tree is its activation.
    let text = project_tree_dot(&survey());
    let dot = validate(&text).unwrap();
    graphviz(&text);
    let edges: Vec<(&str, &str)> = dot
        .edges
        .iter()
        .map(|e| (e.0.as_str(), e.1.as_str()))
        .collect();
    assert_eq!(edges, [("Flight", "Payload")]);
}

#[test]
fn the_older_drawings_are_still_accepted_by_graphviz() {
    let p = survey();
    for only in [None, Some("Flight"), Some("Payload")] {
        graphviz(&project_to_dot(&p, only).unwrap());
    }
}
