//! PNML interchange: reading the MCC benchmark nets, importing plain P/T nets, the exact round
//! trip of a Petrel project, and the diagnostics for broken documents.

use petrel_diag::duration::TimeUnit;
use petrel_diag::report::{Diagnostic, Diagnostics};
use petrel_diag::source::{FileId, LineCol, SourceMap, Span};
use petrel_nets::model::*;
use petrel_nets::pnml::{export_pnml, import_pnml, parse_pnml, PtNode};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

fn mcc_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../verify/tests/data/mcc")
}

/// One row of answers.csv, by column name.
struct Answer {
    model: String,
    file: String,
    places: usize,
    transitions: usize,
    arcs: usize,
    max_arc_weight: u64,
    nupn: bool,
}

fn answers() -> Vec<Answer> {
    let text = std::fs::read_to_string(mcc_dir().join("answers.csv")).expect("answers.csv");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let col = |name: &str| {
        header
            .iter()
            .position(|h| *h == name)
            .unwrap_or_else(|| panic!("answers.csv has no column {name}"))
    };
    let (model, file, places, transitions, arcs, weight, nupn) = (
        col("model"),
        col("file"),
        col("places"),
        col("transitions"),
        col("arcs"),
        col("max_arc_weight"),
        col("nupn"),
    );
    lines
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            assert_eq!(f.len(), header.len(), "bad CSV row {l}");
            Answer {
                model: f[model].to_string(),
                file: f[file].to_string(),
                places: f[places].parse().unwrap(),
                transitions: f[transitions].parse().unwrap(),
                arcs: f[arcs].parse().unwrap(),
                max_arc_weight: f[weight].parse().unwrap(),
                nupn: match f[nupn] {
                    "yes" => true,
                    "no" => false,
                    other => panic!("nupn column holds {other}"),
                },
            }
        })
        .collect()
}

fn read_mcc(file: &str) -> String {
    std::fs::read_to_string(mcc_dir().join(file)).unwrap_or_else(|e| panic!("{file}: {e}"))
}

fn codes(diags: &Diagnostics) -> Vec<&'static str> {
    diags.iter().map(|d| d.code).collect()
}

fn pos(map: &SourceMap, span: Span) -> LineCol {
    map.get(span.file).line_col(span.start as usize)
}

/// The one diagnostic of a run, with its position.
fn only(map: &SourceMap, diags: &Diagnostics) -> (Diagnostic, LineCol) {
    let list: Vec<&Diagnostic> = diags.iter().collect();
    assert_eq!(list.len(), 1, "expected one diagnostic, got {list:#?}");
    let d = list[0].clone();
    let at = pos(map, d.span.expect("the diagnostic has a position"));
    (d, at)
}

#[test]
fn corpus_matches_answers_csv() {
    let answers = answers();
    assert_eq!(answers.len(), 30);
    let mut on_disk: BTreeSet<String> = std::fs::read_dir(mcc_dir())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".pnml"))
        .collect();
    for a in &answers {
        assert!(on_disk.remove(&a.file), "{} listed but absent", a.file);
        assert_eq!(a.file, format!("{}.pnml", a.model));
    }
    assert!(on_disk.is_empty(), "unlisted files: {on_disk:?}");
}

#[test]
fn every_mcc_net_parses_with_the_published_counts() {
    for a in answers() {
        let text = read_mcc(&a.file);
        let mut diags = Diagnostics::new();
        let nets = parse_pnml(FileId(0), &text, &mut diags);
        assert!(diags.is_empty(), "{}: {:?}", a.file, codes(&diags));
        assert_eq!(nets.len(), 1, "{}", a.file);
        let net = &nets[0];
        assert_eq!(net.id, a.model, "{}", a.file);
        assert_eq!(net.places.len(), a.places, "{} places", a.file);
        assert_eq!(
            net.transitions.len(),
            a.transitions,
            "{} transitions",
            a.file
        );
        assert_eq!(net.arc_count(), a.arcs, "{} arcs", a.file);
        assert_eq!(net.max_arc_weight(), a.max_arc_weight, "{} weight", a.file);
        assert_eq!(net.has_nupn, a.nupn, "{} nupn", a.file);
        assert_eq!(
            net.input_arc_count() + net.output_arc_count(),
            net.arc_count()
        );
        // Every arc joins a place and a transition that exist.
        for arc in &net.arcs {
            let p = arc.place().expect("arc touches a place");
            let t = arc.transition().expect("arc touches a transition");
            assert!(p < net.places.len() && t < net.transitions.len());
            assert_eq!(arc.is_input(), matches!(arc.source, PtNode::Place(_)));
        }
    }
}

#[test]
fn arcs_and_markings_are_read_exactly() {
    // Sudoku-PT-AN01 is small enough to check whole.
    let text = read_mcc("Sudoku-PT-AN01.pnml");
    let mut diags = Diagnostics::new();
    let net = parse_pnml(FileId(0), &text, &mut diags).remove(0);
    let marked: Vec<(&str, u64)> = net
        .places
        .iter()
        .map(|p| (p.id.as_str(), p.initial))
        .collect();
    assert_eq!(
        marked,
        [
            ("Rows_0_0", 1),
            ("Board_0_0_0", 0),
            ("Cells_0_0", 1),
            ("Columns_0_0", 1)
        ]
    );
    let arcs: Vec<(String, String, u64)> = net
        .arcs
        .iter()
        .map(|a| {
            let name = |n: PtNode| match n {
                PtNode::Place(i) => net.places[i].id.clone(),
                PtNode::Transition(i) => net.transitions[i].id.clone(),
            };
            (name(a.source), name(a.target), a.weight)
        })
        .collect();
    assert_eq!(
        arcs,
        [
            ("select_0_0_0".into(), "Board_0_0_0".into(), 1),
            ("Columns_0_0".into(), "select_0_0_0".into(), 1),
            ("Rows_0_0".into(), "select_0_0_0".into(), 1),
            ("Cells_0_0".into(), "select_0_0_0".into(), 1),
        ]
    );
    // Spans point at the start tags.
    let mut map = SourceMap::new();
    let id = map.add("Sudoku-PT-AN01.pnml", text.clone());
    let net = parse_pnml(id, &text, &mut diags).remove(0);
    let arc = &net.arcs[0];
    assert!(text[arc.span.start as usize..].starts_with("<arc id=\"id1\""));
    assert_eq!(
        pos(&map, arc.span),
        LineCol {
            line: 49,
            column: 4
        }
    );
}

#[test]
fn the_biggest_file_parses_quickly() {
    let text = read_mcc("NeoElection-PT-3.pnml");
    assert!(text.len() > 900_000);
    let started = std::time::Instant::now();
    let mut diags = Diagnostics::new();
    let nets = parse_pnml(FileId(0), &text, &mut diags);
    let took = started.elapsed();
    assert_eq!(nets[0].arc_count(), 5840);
    // Generous for unoptimised test builds on a slow machine; a DOM reader takes longer.
    assert!(took.as_secs_f64() < 3.0, "took {took:?}");
}

#[test]
fn every_mcc_net_imports_or_fails_with_e0504_e0505_only() {
    let mut failed = BTreeMap::new();
    for a in answers() {
        let text = read_mcc(&a.file);
        let mut diags = Diagnostics::new();
        let net = parse_pnml(FileId(0), &text, &mut Diagnostics::new()).remove(0);
        match import_pnml(FileId(0), &text, &mut diags) {
            Some(project) => {
                assert!(diags.is_empty(), "{}: {:?}", a.file, codes(&diags));
                assert_eq!(project.files.len(), 1);
                let n = &project.files[0].nets[0];
                assert_eq!(n.places().count(), a.places, "{}", a.file);
                assert_eq!(n.transitions().count(), a.transitions, "{}", a.file);
                let arcs: usize = n
                    .transitions()
                    .map(|t| t.inputs.len() + t.outputs.len())
                    .sum();
                assert_eq!(arcs, a.arcs, "{}", a.file);
                let tokens: u64 = n.places().map(|p| u64::from(p.tokens)).sum();
                let initial: u64 = net.places.iter().map(|p| p.initial).sum();
                assert_eq!(tokens, initial, "{}", a.file);
                // Every name is a Petrel identifier, unique in its net.
                let mut names = BTreeSet::new();
                for item in &n.items {
                    let name = match &item.kind {
                        ItemKind::Place(p) => &p.name,
                        ItemKind::Transition(t) => &t.name,
                        ItemKind::Children(_) => panic!("{}: an import made children", a.file),
                    };
                    assert!(is_identifier(name.as_str()), "{}: {name}", a.file);
                    assert!(names.insert(name.text.clone()), "{}: {name} twice", a.file);
                }
                assert!(is_identifier(n.name.as_str()));
                assert_eq!(project.manifest.start, vec![n.name.clone()]);
                assert_eq!(project.files[0].path, format!("{}.pn", n.name));
            }
            None => {
                let cs = codes(&diags);
                assert!(
                    cs.iter().all(|c| *c == "E0504" || *c == "E0505"),
                    "{}: {cs:?}",
                    a.file
                );
                let weighted = net.arcs.iter().filter(|x| x.weight > 1).count();
                let overfull = net.places.iter().filter(|p| p.initial > 1).count();
                let e0504 = cs.iter().filter(|c| **c == "E0504").count();
                let e0505 = cs.iter().filter(|c| **c == "E0505").count();
                assert_eq!((e0504, e0505), (weighted, overfull), "{}", a.file);
                failed.insert(a.model.clone(), (e0504, e0505));
            }
        }
    }
    // From the files themselves: DrinkVendingMachine-PT-02 has 64 arcs of weight 2 and 16 of
    // weight 3; FMS-PT-00002 marks five places with 2 or 3 tokens; TwoPhaseLocking-PT-nC00004vD
    // marks three places with 2 or 4.
    let expected: BTreeMap<String, (usize, usize)> = [
        ("DrinkVendingMachine-PT-02", (80, 0)),
        ("FMS-PT-00002", (0, 5)),
        ("TwoPhaseLocking-PT-nC00004vD", (0, 3)),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect();
    assert_eq!(failed, expected);
}

#[test]
fn each_weighted_arc_of_drink_vending_machine_gets_e0504() {
    let text = read_mcc("DrinkVendingMachine-PT-02.pnml");
    let mut map = SourceMap::new();
    let file = map.add("DrinkVendingMachine-PT-02.pnml", text.clone());
    let net = parse_pnml(file, &text, &mut Diagnostics::new()).remove(0);
    let mut diags = Diagnostics::new();
    assert!(import_pnml(file, &text, &mut diags).is_none());
    let reported: BTreeSet<u32> = diags
        .iter()
        .map(|d| {
            assert_eq!(d.code, "E0504");
            assert!(d.message.contains("unary"), "{}", d.message);
            assert!(d.help.as_deref().unwrap().contains("petrel verify"));
            d.span.unwrap().start
        })
        .collect();
    let weighted: BTreeSet<u32> = net
        .arcs
        .iter()
        .filter(|a| a.weight > 1)
        .map(|a| a.span.start)
        .collect();
    assert_eq!(weighted.len(), 80);
    assert_eq!(reported, weighted);
    // The first one names its arc and points at it.
    let d = diags.iter().next().unwrap();
    let arc = net.arcs.iter().find(|a| a.weight > 1).unwrap();
    assert!(
        d.message.contains(&format!("`{}`", arc.id)),
        "{}",
        d.message
    );
    assert!(text[d.span.unwrap().start as usize..].starts_with("<arc "));
}

#[test]
fn overfull_initial_markings_get_e0505_at_their_places() {
    let text = read_mcc("TwoPhaseLocking-PT-nC00004vD.pnml");
    let mut map = SourceMap::new();
    let file = map.add("TwoPhaseLocking-PT-nC00004vD.pnml", text.clone());
    let mut diags = Diagnostics::new();
    assert!(import_pnml(file, &text, &mut diags).is_none());
    let found: Vec<(String, usize)> = diags
        .iter()
        .map(|d| {
            assert_eq!(d.code, "E0505");
            assert!(d.help.as_deref().unwrap().contains("petrel verify"));
            (d.message.clone(), pos(&map, d.span.unwrap()).line)
        })
        .collect();
    assert_eq!(found.len(), 3);
    for (message, line) in &found {
        let at = map.get(file).line_text(*line);
        assert!(at.trim_start().starts_with("<place id="), "{at}");
        let id = at.split('"').nth(1).unwrap();
        assert!(message.contains(&format!("`{id}`")), "{message}");
    }
    assert!(found[0].0.contains("2 tokens"), "{}", found[0].0);
}

const PLAIN: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<!-- a hand-written net exercising the PNML corners -->
<pnml xmlns="http://www.pnml.org/version-2009/grammar/pnml">
  <net id="my-net" type="http://www.pnml.org/version-2009/grammar/ptnet">
    <name><text>  My net  </text></name>
    <toolspecific tool="other" version="9"><place id="fake"/><weird>&amp;</weird></toolspecific>
    <page id="outer">
      <place id="start">
        <name><graphics><offset x="1" y="2"/></graphics><text>Start</text></name>
        <initialMarking>
          <text>
            1
          </text>
        </initialMarking>
      </place>
      <!-- <place id="commented-out"/> -->
      <transition id="go-1"/>
      <page id="inner">
        <page id="innermost">
          <place id="a-b"/>
          <place id="a_b"><initialMarking><text>0</text></initialMarking></place>
        </page>
        <transition id="1st"><name><text>first</text></name></transition>
      </page>
      <arc id="x1" source="start" target="go-1"/>
      <arc id="x2" source="go-1" target="a-b"><inscription><text> 1 </text></inscription></arc>
      <arc id="x3" source="go-1" target="a_b"></arc>
      <arc id="x4" source="a-b" target="1st"/><arc id="x5" source="1st" target="start"/>
      <toolspecific tool="nupn" version="1.1"><size places="3"/></toolspecific>
    </page>
  </net>
  <net id="second" type="http://www.pnml.org/version-2009/grammar/ptnet">
    <page id="p2"><place id="only"/></page>
  </net>
</pnml>
"#;

#[test]
fn plain_pnml_corners_are_read() {
    let mut diags = Diagnostics::new();
    let nets = parse_pnml(FileId(0), PLAIN, &mut diags);
    assert!(diags.is_empty(), "{:?}", codes(&diags));
    assert_eq!(nets.len(), 2);
    let n = &nets[0];
    assert_eq!((n.id.as_str(), n.name.as_str()), ("my-net", "My net"));
    assert!(n.has_nupn);
    assert!(!nets[1].has_nupn);
    let places: Vec<(&str, &str, u64)> = n
        .places
        .iter()
        .map(|p| (p.id.as_str(), p.name.as_str(), p.initial))
        .collect();
    assert_eq!(
        places,
        [("start", "Start", 1), ("a-b", "a-b", 0), ("a_b", "a_b", 0)]
    );
    let transitions: Vec<(&str, &str)> = n
        .transitions
        .iter()
        .map(|t| (t.id.as_str(), t.name.as_str()))
        .collect();
    assert_eq!(transitions, [("go-1", "go-1"), ("1st", "first")]);
    assert_eq!(n.arc_count(), 5);
    assert_eq!((n.input_arc_count(), n.output_arc_count()), (2, 3));
    assert_eq!(n.max_arc_weight(), 1);
    assert_eq!(n.max_initial_marking(), 1);
    assert_eq!(n.place_index("a_b"), Some(2));
    assert_eq!(n.transition_index("1st"), Some(1));
}

#[test]
fn plain_pnml_imports_as_named_immediate_transitions() {
    let mut diags = Diagnostics::new();
    let project = import_pnml(FileId(0), PLAIN, &mut diags).expect("imports");
    assert!(diags.is_empty());
    let name = |s: &str| Name::synthetic(s);
    let trivia = |c: &[&str]| Trivia {
        blank_before: false,
        comments: c.iter().map(|s| s.to_string()).collect(),
    };
    let place = |n: &str, tokens: u32, c: &[&str]| Item {
        allows: Vec::new(),
        trivia: trivia(c),
        kind: ItemKind::Place(PlaceDecl {
            name: name(n),
            tokens,
            tokens_span: (tokens > 0).then(Span::default),
        }),
        trailing: None,
    };
    let transition = |n: &str, i: &[&str], o: &[&str], c: &[&str]| Item {
        allows: Vec::new(),
        trivia: trivia(c),
        kind: ItemKind::Transition(TransitionDecl {
            guard: None,
            empty: Vec::new(),
            name: name(n),
            trigger: None,
            inputs: i.iter().map(|s| name(s)).collect(),
            outputs: o.iter().map(|s| name(s)).collect(),
            actions: vec![],
            end_comments: vec![],
        }),
        trailing: None,
    };
    let expected = Project {
        manifest: Manifest {
            name: "my_net".into(),
            files: vec![
                FileRef {
                    path: "my_net.pn".into(),
                    span: Span::default(),
                },
                FileRef {
                    path: "second.pn".into(),
                    span: Span::default(),
                },
            ],
            start: vec![name("my_net"), name("second")],
            ..Manifest::default()
        },
        files: vec![
            NetFile {
                path: "my_net.pn".into(),
                nets: vec![NetDecl {
                    allows: Vec::new(),
                    params: Vec::new(),
                    trivia: trivia(&["PNML id \"my-net\""]),
                    name: name("my_net"),
                    items: vec![
                        place("start", 1, &[]),
                        place("a_b", 0, &["PNML id \"a-b\""]),
                        // `a_b` is taken by the sanitized `a-b`, which came first.
                        place("a_b_2", 0, &["PNML id \"a_b\""]),
                        transition("go_1", &["start"], &["a_b", "a_b_2"], &["PNML id \"go-1\""]),
                        transition("_1st", &["a_b"], &["start"], &["PNML id \"1st\""]),
                    ],
                    end_comments: vec![],
                }],
                end_comments: vec![],
            },
            NetFile {
                path: "second.pn".into(),
                nets: vec![NetDecl {
                    allows: Vec::new(),
                    params: Vec::new(),
                    trivia: trivia(&[]),
                    name: name("second"),
                    items: vec![place("only", 0, &[])],
                    end_comments: vec![],
                }],
                end_comments: vec![],
            },
        ],
    };
    assert_eq!(project, expected);
    // Every imported name is an identifier the net language accepts.
    for net in project.nets() {
        for item in &net.items {
            if let ItemKind::Place(p) = &item.kind {
                assert!(is_identifier(p.name.as_str()));
            }
        }
    }
    // `PlaceDecl` equality ignores where a marking is written, so check it by hand: a marked
    // place reads as written `= 1`, an empty one as not written, as the formatter prints them.
    let written: Vec<bool> = project
        .nets()
        .flat_map(|net| net.places().map(|p| p.tokens_span.is_some()))
        .collect();
    assert_eq!(written, [true, false, false, false]);
    // Names point at the PNML elements they come from.
    let start = project.files[0].nets[0].places().next().unwrap();
    assert!(PLAIN[start.name.span.start as usize..].starts_with("<place id=\"start\""));
}

#[test]
fn weights_and_markings_are_all_reported_in_one_run() {
    let text = r#"<pnml><net id="n" type="http://www.pnml.org/version-2009/grammar/ptnet"><page id="g">
<place id="p"><initialMarking><text>2</text></initialMarking></place>
<place id="q"><initialMarking><text>5</text></initialMarking></place>
<transition id="t"/>
<arc id="a1" source="p" target="t"><inscription><text>2</text></inscription></arc>
<arc id="a2" source="t" target="q"/>
<arc id="a3" source="t" target="q"/>
</page></net></pnml>"#;
    let mut map = SourceMap::new();
    let file = map.add("w.pnml", text);
    let mut diags = Diagnostics::new();
    assert!(import_pnml(file, text, &mut diags).is_none());
    let found: Vec<(&str, usize)> = diags
        .iter()
        .map(|d| (d.code, pos(&map, d.span.unwrap()).line))
        .collect();
    // Two overfull places, one weighted arc, and two parallel arcs that together weigh 2.
    assert_eq!(
        found,
        [("E0505", 2), ("E0505", 3), ("E0504", 5), ("E0504", 7)]
    );
    let parallel = diags.iter().last().unwrap();
    assert!(parallel.message.contains("`a3`") && parallel.message.contains("`a2`"));
}

// ---------------------------------------------------------------------------------------------
// Malformed documents
// ---------------------------------------------------------------------------------------------

fn net_doc(body: &str, ty: &str) -> String {
    format!(
        "<?xml version=\"1.0\"?>\n<pnml xmlns=\"http://www.pnml.org/version-2009/grammar/pnml\">\n  <net id=\"n1\" type=\"{ty}\">\n    <page id=\"pg\">\n{body}    </page>\n  </net>\n</pnml>\n"
    )
}

const PT: &str = "http://www.pnml.org/version-2009/grammar/ptnet";

fn parse_with_map(text: &str) -> (SourceMap, Diagnostics, usize) {
    let mut map = SourceMap::new();
    let file = map.add("bad.pnml", text);
    let mut diags = Diagnostics::new();
    let nets = parse_pnml(file, text, &mut diags);
    // Importing reports the same problems and gives nothing.
    let mut again = Diagnostics::new();
    assert!(import_pnml(file, text, &mut again).is_none());
    assert_eq!(codes(&again), codes(&diags));
    (map, diags, nets.len())
}

#[test]
fn an_unclosed_element_is_reported_where_it_opens() {
    let text = net_doc(
        "      <place id=\"p1\">\n        <name><text>p1</text></name>\n      <transition id=\"t1\"/>\n",
        PT,
    );
    let (map, diags, _) = parse_with_map(&text);
    let (d, at) = only(&map, &diags);
    assert_eq!(d.code, "E0501");
    assert_eq!(at, LineCol { line: 5, column: 7 });
    assert!(d.message.contains("`<place id=\"p1\">`"), "{}", d.message);
    assert!(d.message.contains("`</page>` at 8:5"), "{}", d.message);
    assert!(d.help.unwrap().contains("</place>"));
}

#[test]
fn a_truncated_file_is_reported_at_the_open_element() {
    let full = net_doc(
        "      <place id=\"p1\"/>\n      <transition id=\"t1\">\n",
        PT,
    );
    let cut = full.find("<transition id=\"t1\">").unwrap() + "<transition id=\"t1\">\n".len();
    let text = &full[..cut];
    let (map, diags, nets) = parse_with_map(text);
    assert_eq!(nets, 0);
    let (d, at) = only(&map, &diags);
    assert_eq!(d.code, "E0501");
    assert_eq!(at, LineCol { line: 6, column: 7 });
    assert!(d.message.contains("end of the file"), "{}", d.message);
}

#[test]
fn a_tag_without_its_closing_bracket_is_reported_at_its_start() {
    let text = net_doc("      <place id=\"p1\"\n", PT);
    let (map, diags, _) = parse_with_map(&text);
    let (d, at) = only(&map, &diags);
    assert_eq!(d.code, "E0501");
    assert_eq!(at, LineCol { line: 5, column: 7 });
    assert!(d.message.starts_with("malformed XML"), "{}", d.message);
}

#[test]
fn an_arc_to_an_unknown_id_is_e0502_at_the_arc() {
    let text = net_doc(
        "      <place id=\"p1\"/>\n      <transition id=\"t1\"/>\n      <arc id=\"a1\" source=\"p1\" target=\"t1\"/>\n      <arc id=\"a2\" source=\"t1\" target=\"nowhere\"/>\n",
        PT,
    );
    let (map, diags, nets) = parse_with_map(&text);
    assert_eq!(nets, 1, "the net is still read");
    let (d, at) = only(&map, &diags);
    assert_eq!(d.code, "E0502");
    assert_eq!(at, LineCol { line: 8, column: 7 });
    assert!(
        d.message.contains("`a2`") && d.message.contains("`nowhere`"),
        "{}",
        d.message
    );
}

#[test]
fn an_arc_between_two_places_is_e0502() {
    let text = net_doc(
        "      <place id=\"p1\"/>\n      <place id=\"p2\"/>\n      <arc id=\"a1\" source=\"p1\" target=\"p2\"/>\n",
        PT,
    );
    let (map, diags, _) = parse_with_map(&text);
    let (d, at) = only(&map, &diags);
    assert_eq!(d.code, "E0502");
    assert_eq!(at, LineCol { line: 7, column: 7 });
    assert!(
        d.message.contains("place `p1` to place `p2`"),
        "{}",
        d.message
    );
}

#[test]
fn a_colored_net_is_e0503_at_the_net() {
    let text = net_doc(
        "      <place id=\"p1\"><type><text>Dot</text></type></place>\n",
        "http://www.pnml.org/version-2009/grammar/symmetricnet",
    );
    let (map, diags, nets) = parse_with_map(&text);
    assert_eq!(nets, 0);
    let (d, at) = only(&map, &diags);
    assert_eq!(d.code, "E0503");
    assert_eq!(at, LineCol { line: 3, column: 3 });
    assert!(d.message.contains("`n1`"), "{}", d.message);
    assert!(d.message.contains("P/T nets only"), "{}", d.message);
}

#[test]
fn other_malformed_content_is_e0501() {
    let cases = [
        (net_doc("      <place/>\n", PT), 5, "no `id`"),
        (
            net_doc(
                "      <place id=\"p\"><initialMarking><text>x</text></initialMarking></place>\n",
                PT,
            ),
            5,
            "not a natural number",
        ),
        (
            net_doc(
                "      <place id=\"p\"/>\n      <transition id=\"p\"/>\n",
                PT,
            ),
            6,
            "used twice",
        ),
        (
            net_doc("      <arc id=\"a\" source=\"p\"/>\n", PT),
            5,
            "no `target`",
        ),
        ("<html><body/></html>".to_string(), 1, "not a PNML document"),
        (
            net_doc(
                "      <place id=\"p\"><name><text>&nbsp;</text></name></place>\n",
                PT,
            ),
            5,
            "unknown entity",
        ),
    ];
    for (text, line, words) in cases {
        let (map, diags, _) = parse_with_map(&text);
        let (d, at) = only(&map, &diags);
        assert_eq!(d.code, "E0501", "{text}");
        assert_eq!(at.line, line, "{text}");
        assert!(d.message.contains(words), "{}", d.message);
    }
}

// ---------------------------------------------------------------------------------------------
// Round trip of a Petrel project
// ---------------------------------------------------------------------------------------------

fn n(s: &str) -> Name {
    Name::synthetic(s)
}

fn sp() -> Span {
    Span::default()
}

fn trivia(blank: bool, comments: &[&str]) -> Trivia {
    Trivia {
        blank_before: blank,
        comments: comments.iter().map(|s| s.to_string()).collect(),
    }
}

fn param(name: &str, ty: Type) -> Param {
    Param { name: n(name), ty }
}

fn place_item(t: Trivia, name: &str, tokens: u32, written: bool, trailing: Option<&str>) -> Item {
    Item {
        allows: Vec::new(),
        trivia: t,
        kind: ItemKind::Place(PlaceDecl {
            name: n(name),
            tokens,
            tokens_span: written.then(sp),
        }),
        trailing: trailing.map(String::from),
    }
}

fn action(t: Trivia, a: Action, trailing: Option<&str>) -> ActionItem {
    ActionItem {
        trivia: t,
        action: a,
        trailing: trailing.map(String::from),
    }
}

/// A project using every construct of the model, with awkward text everywhere.
fn sample_project() -> Project {
    let events = Type::ALL
        .iter()
        .zip(Category::ALL)
        .enumerate()
        .map(|(i, (ty, category))| EventDecl {
            name: n(&format!("ev_{}", category.keyword())),
            category,
            params: vec![param(&format!("x{i}"), *ty), param("flag", Type::Bool)],
            description: (i % 2 == 0).then(|| format!("event {i}: \"<&>\"\nsecond line")),
            params_unread: false,
            internal: false,
        })
        .chain([EventDecl {
            name: n("tick"),
            category: Category::Nominal,
            params: vec![],
            params_unread: false,
            description: Some(String::new()),
            internal: false,
        }])
        .collect();
    let formula = |t: &str| {
        petrel_nets::formula::parse_formula(FileId(0), 0, t, "E0108", &mut Diagnostics::new())
    };
    let manifest = Manifest {
        instances: Vec::new(),
        invariants: Vec::new(),
        bounds: vec![
            BoundDecl {
                name: n("reaction"),
                from: BoundEnd::Event(n("tick")),
                to: BoundEnd::Marking {
                    text: "nav.a and not global.ready".into(),
                    formula: formula("nav.a and not global.ready"),
                },
                within: Some(n("1.5s")),
            },
            BoundDecl {
                name: n("open"),
                from: BoundEnd::Marking {
                    text: " active nav or (global.ready implies nav.b) ".into(),
                    formula: formula(" active nav or (global.ready implies nav.b) "),
                },
                to: BoundEnd::Event(n("ev_nominal")),
                within: None,
            },
        ],
        goals: Vec::new(),
        progress_excludes: None,
        name: "uav mission <&> \"quoted\"".into(),
        description: Some("  leading spaces\r\nand CRLF\ttab ]]> end  ".into()),
        files: vec![
            FileRef {
                path: "nets/nav.pn".into(),
                span: sp(),
            },
            FileRef {
                path: "nets/safety & more.pn".into(),
                span: sp(),
            },
            FileRef {
                path: "missing.pn".into(),
                span: sp(),
            },
        ],
        start: vec![n("nav"), n("monitor")],
        globals: vec![
            GlobalPlaceDecl {
                nets: None,
                name: n("ready"),
                tokens: 1,
            },
            GlobalPlaceDecl {
                nets: None,
                name: n("link_up"),
                tokens: 0,
            },
        ],
        events,
        programs: vec![
            ProgramDecl {
                name: n("PLN"),
                description: Some("planner".into()),
                functions: vec![
                    FunctionDecl {
                        name: n("goto"),
                        answers: Vec::new(),
                        params_unread: false,
                        params: vec![
                            param("x", Type::Float),
                            param("path", Type::FloatList),
                            param("label", Type::Text),
                        ],
                    },
                    FunctionDecl {
                        name: n("stop"),
                        answers: Vec::new(),
                        params_unread: false,
                        params: vec![],
                    },
                ],
            },
            ProgramDecl {
                name: n("GUI"),
                description: None,
                functions: vec![FunctionDecl {
                    name: n("show"),
                    answers: Vec::new(),
                    params_unread: false,
                    params: vec![param("n", Type::Int)],
                }],
            },
        ],
        timers: vec![TimerDecl {
            name: n("watchdog"),
            event: n("tick"),
        }],
        finals: vec![vec![n("Nav.done"), n("global.ok")], vec![n("Nav.idle")]],
    };

    let nav_go = TransitionDecl {
        guard: None,
        empty: Vec::new(),
        name: n("go"),
        trigger: Some(Trigger {
            event: n("ev_safety"),
            bindings: vec![
                Binding {
                    name: n("speed"),
                    ty: Some((Type::Float, sp())),
                },
                Binding {
                    name: n("_"),
                    ty: None,
                },
            ],
        }),
        inputs: vec![n("idle"), n("ready")],
        outputs: vec![n("moving"), n("ready")],
        actions: vec![
            action(
                trivia(false, &["first the call"]),
                Action::Call {
                    program: n("PLN"),
                    function: n("goto"),
                    args: vec![
                        Expr::Float(0.1, sp()),
                        Expr::List(
                            vec![
                                Expr::Float(1e-7, sp()),
                                Expr::Float(-2.5, sp()),
                                Expr::Float(1e300, sp()),
                            ],
                            sp(),
                        ),
                        Expr::Text("say \"hi\"\n<&> \\ \t done".into(), sp()),
                    ],
                    span: sp(),
                },
                Some("trailing <b>&amp;</b>"),
            ),
            action(
                trivia(true, &[]),
                Action::StartTimer {
                    timer: n("watchdog"),
                    after: DurationExpr::Literal {
                        value: 1.5,
                        unit: TimeUnit::Minutes,
                        span: sp(),
                    },
                },
                None,
            ),
            action(
                trivia(false, &[]),
                Action::StartTimer {
                    timer: n("watchdog"),
                    after: DurationExpr::Seconds(n("speed")),
                },
                None,
            ),
            action(
                trivia(false, &["", "two comments, one empty"]),
                Action::Emit {
                    to: None,
                    event: n("ev_nominal"),
                    args: vec![
                        Expr::Var(n("speed")),
                        Expr::Bool(true, sp()),
                        Expr::Int(-42, sp()),
                        Expr::List(vec![], sp()),
                    ],
                    span: sp(),
                },
                None,
            ),
            action(
                trivia(false, &[]),
                Action::Emit {
                    to: None,
                    event: n("tick"),
                    args: vec![],
                    span: sp(),
                },
                None,
            ),
            action(
                trivia(false, &[]),
                Action::Activate {
                    net: n("monitor"),
                    args: Vec::new(),
                    span: Default::default(),
                },
                None,
            ),
            action(trivia(false, &[]), Action::Deactivate(n("nav")), None),
            action(
                trivia(false, &[]),
                Action::StartTimer {
                    timer: n("watchdog"),
                    after: DurationExpr::Literal {
                        value: 200.0,
                        unit: TimeUnit::Millis,
                        span: sp(),
                    },
                },
                None,
            ),
            action(trivia(false, &[]), Action::CancelTimer(n("watchdog")), None),
            action(
                trivia(false, &[]),
                Action::Call {
                    program: n("GUI"),
                    function: n("show"),
                    args: vec![Expr::Int(i64::MIN, sp())],
                    span: sp(),
                },
                None,
            ),
        ],
        end_comments: vec!["before the brace -- with dashes --> and <!-- markup".into()],
    };
    let nav_back = TransitionDecl {
        guard: None,
        empty: Vec::new(),
        name: n("back"),
        trigger: Some(Trigger {
            event: n("tick"),
            bindings: vec![],
        }),
        inputs: vec![n("moving")],
        // `ghost` names no place: it is kept, but draws no arc.
        outputs: vec![n("idle"), n("ghost")],
        actions: vec![],
        end_comments: vec![],
    };
    let nav_spin = TransitionDecl {
        guard: None,
        empty: Vec::new(),
        name: n("spin"),
        trigger: Some(Trigger {
            event: n("ev_mission"),
            bindings: vec![
                Binding {
                    name: n("a"),
                    ty: Some((Type::Text, sp())),
                },
                Binding {
                    name: n("b"),
                    ty: Some((Type::FloatList, sp())),
                },
                Binding {
                    name: n("c"),
                    ty: Some((Type::Int, sp())),
                },
                Binding {
                    name: n("d"),
                    ty: Some((Type::Bool, sp())),
                },
            ],
        }),
        // A place named twice is one arc of weight 2 in the P/T view.
        inputs: vec![n("moving"), n("moving")],
        outputs: vec![n("moving")],
        actions: vec![],
        end_comments: vec!["only a comment in the block".into()],
    };
    let nav = NetDecl {
        allows: Vec::new(),
        params: Vec::new(),
        trivia: trivia(false, &["The navigation net.", "  indented comment  "]),
        name: n("nav"),
        items: vec![
            place_item(trivia(false, &[]), "idle", 1, true, Some("starts here")),
            Item {
                allows: Vec::new(),
                trivia: trivia(true, &["go when ready"]),
                kind: ItemKind::Transition(nav_go),
                trailing: Some("end of header".into()),
            },
            place_item(trivia(true, &[]), "moving", 0, false, None),
            Item {
                allows: Vec::new(),
                trivia: trivia(false, &[]),
                kind: ItemKind::Transition(nav_back),
                trailing: None,
            },
            // Written `place ready = 0`: shadows the global of the same name.
            place_item(trivia(false, &["local ready"]), "ready", 0, true, None),
            Item {
                allows: Vec::new(),
                trivia: trivia(false, &[]),
                kind: ItemKind::Transition(nav_spin),
                trailing: None,
            },
        ],
        end_comments: vec!["end of nav".into()],
    };
    let monitor = NetDecl {
        allows: Vec::new(),
        params: Vec::new(),
        trivia: trivia(true, &[]),
        name: n("monitor"),
        items: vec![
            place_item(trivia(false, &[]), "watching", 1, true, None),
            Item {
                allows: Vec::new(),
                trivia: trivia(false, &[]),
                kind: ItemKind::Transition(TransitionDecl {
                    guard: None,
                    empty: Vec::new(),
                    name: n("alarm"),
                    trigger: Some(Trigger {
                        event: n("ev_catastrophic"),
                        bindings: vec![Binding {
                            name: n("code"),
                            ty: None,
                        }],
                    }),
                    // Both resolve to the globals: this net declares neither.
                    inputs: vec![n("watching"), n("ready")],
                    outputs: vec![n("link_up")],
                    actions: vec![action(
                        trivia(false, &[]),
                        Action::Emit {
                            to: None,
                            event: n("ev_communication"),
                            args: vec![Expr::Text(String::new(), sp()), Expr::Var(n("code"))],
                            span: sp(),
                        },
                        Some(""),
                    )],
                    end_comments: vec![],
                }),
                trailing: None,
            },
        ],
        end_comments: vec![],
    };
    // Not started: its marked place is exported with no token.
    let spare = NetDecl {
        allows: Vec::new(),
        params: Vec::new(),
        trivia: trivia(false, &[]),
        name: n("spare"),
        items: vec![
            Item {
                allows: Vec::new(),
                trivia: trivia(false, &[]),
                kind: ItemKind::Transition(TransitionDecl {
                    guard: None,
                    empty: Vec::new(),
                    name: n("wake"),
                    trigger: None,
                    inputs: vec![n("sleeping")],
                    outputs: vec![],
                    actions: vec![],
                    end_comments: vec![],
                }),
                trailing: None,
            },
            place_item(trivia(false, &[]), "sleeping", 1, true, None),
        ],
        end_comments: vec![],
    };
    Project {
        manifest,
        files: vec![
            NetFile {
                path: "nets/nav.pn".into(),
                nets: vec![nav],
                end_comments: vec![],
            },
            NetFile {
                path: "nets/safety & more.pn".into(),
                nets: vec![monitor, spare],
                end_comments: vec!["file ends".into(), "\u{1}control\u{7f} é ✓".into()],
            },
        ],
    }
}

fn count(xml: &str, needle: &str) -> usize {
    xml.matches(needle).count()
}

#[test]
fn a_project_survives_export_and_import() {
    let project = sample_project();
    let xml = export_pnml(&project);

    let mut map = SourceMap::new();
    let file = map.add("mission.pnml", xml.clone());
    let mut diags = Diagnostics::new();
    let back = import_pnml(file, &xml, &mut diags);
    assert!(diags.is_empty(), "{}\n{xml}", diags.render_human(&map));
    let back = back.expect("imports");
    assert_eq!(back, project);
    // Exporting again gives the same document, byte for byte.
    assert_eq!(export_pnml(&back), xml);

    // Names of the imported project point at their PNML elements.
    let idle = back.files[0].nets[0].places().next().unwrap();
    assert!(
        xml[idle.name.span.start as usize..].starts_with("<toolspecific")
            || xml[idle.name.span.start as usize..].starts_with("<place")
    );

    // 2 globals + 3 nav + 1 monitor + 1 spare places; 3 + 1 + 1 transitions. Arcs: go has
    // idle, ready (local) in and moving, ready out; back moving in, idle out (ghost draws
    // nothing); spin moving in (weight 2) and out; alarm watching, ready (global) in,
    // link_up out; wake sleeping in.
    assert_eq!(count(&xml, "<place id="), 7);
    assert_eq!(count(&xml, "<transition id="), 5);
    assert_eq!(count(&xml, "<arc id="), 12);
    assert_eq!(count(&xml, "<page id="), 1);
    assert_eq!(count(&xml, "<net id="), 1);
    assert!(xml.contains(
        "<net id=\"uav_mission______quoted_\" type=\"http://www.pnml.org/version-2009/grammar/ptnet\">"
    ));

    let mut diags = Diagnostics::new();
    let nets = parse_pnml(file, &xml, &mut diags);
    assert!(diags.is_empty());
    assert_eq!(nets.len(), 1);
    let pt = &nets[0];
    assert_eq!(pt.name, "uav mission <&> \"quoted\"");
    assert_eq!(pt.places.len(), 7);
    assert_eq!(pt.transitions.len(), 5);
    assert_eq!(pt.arc_count(), 12);
    assert_eq!((pt.input_arc_count(), pt.output_arc_count()), (7, 5));
    assert_eq!(pt.max_arc_weight(), 2);
    assert!(!pt.has_nupn);
    let ids: Vec<&str> = pt.places.iter().map(|p| p.id.as_str()).collect();
    assert_eq!(
        ids,
        [
            "global.ready",
            "global.link_up",
            "nav.idle",
            "nav.moving",
            "nav.ready",
            "monitor.watching",
            "spare.sleeping"
        ]
    );
    let tids: Vec<&str> = pt.transitions.iter().map(|t| t.id.as_str()).collect();
    assert_eq!(
        tids,
        [
            "nav.go",
            "nav.back",
            "nav.spin",
            "monitor.alarm",
            "spare.wake"
        ]
    );
    // The initial state: started nets and globals marked, `spare` not started.
    let marking: Vec<u64> = pt.places.iter().map(|p| p.initial).collect();
    assert_eq!(marking, [1, 0, 1, 0, 0, 1, 0]);
    // `ready` in `alarm` resolves to the global, in `go` to nav's own place.
    let arc = |from: &str, to: &str| {
        pt.arcs.iter().any(|a| {
            let id = |n: PtNode| match n {
                PtNode::Place(i) => &pt.places[i].id,
                PtNode::Transition(i) => &pt.transitions[i].id,
            };
            id(a.source) == from && id(a.target) == to
        })
    };
    assert!(arc("global.ready", "monitor.alarm"));
    assert!(arc("nav.ready", "nav.go"));
    assert!(!arc("global.ready", "nav.go"));
}

#[test]
fn the_import_is_exact_even_where_equality_is_lenient() {
    // Spans compare equal whatever they hold, so check the span-shaped facts by hand.
    let project = sample_project();
    let back = import_pnml(FileId(0), &export_pnml(&project), &mut Diagnostics::new()).unwrap();
    let written: Vec<bool> = back
        .nets()
        .flat_map(|net| net.places().map(|p| p.tokens_span.is_some()))
        .collect();
    assert_eq!(written, [true, false, true, true, true]);
    let typed: Vec<bool> = back
        .nets()
        .flat_map(|net| net.transitions())
        .filter_map(|t| t.trigger.as_ref())
        .flat_map(|t| t.bindings.iter().map(|b| b.ty.is_some()))
        .collect();
    assert_eq!(typed, [true, false, true, true, true, true, false]);
}

#[test]
fn tampered_petrel_exports_are_e0506() {
    let xml = export_pnml(&sample_project());
    // Remove one arc, change a marking, drop a transition's Petrel data.
    let arc_start = xml.find("<arc id=\"nav.back.in\"").unwrap();
    let arc_end = arc_start + xml[arc_start..].find('\n').unwrap() + 1;
    let mut tampered = format!("{}{}", &xml[..arc_start], &xml[arc_end..]);
    let watching = tampered.find("<place id=\"monitor.watching\">").unwrap();
    let marking = "<initialMarking><text>1</text>";
    let at = watching + tampered[watching..].find(marking).unwrap();
    assert!(at < watching + 100, "the marking belongs to the place");
    tampered.replace_range(at..at + marking.len(), "<initialMarking><text>3</text>");
    let mut map = SourceMap::new();
    let file = map.add("t.pnml", tampered.clone());
    let mut diags = Diagnostics::new();
    assert!(import_pnml(file, &tampered, &mut diags).is_none());
    assert!(
        codes(&diags).iter().all(|c| *c == "E0506"),
        "{:?}",
        codes(&diags)
    );
    let messages: Vec<String> = diags.iter().map(|d| d.message.clone()).collect();
    assert_eq!(messages.len(), 2, "{messages:#?}");
    assert!(messages
        .iter()
        .any(|m| m.contains("`monitor.watching` starts with 3")));
    assert!(messages
        .iter()
        .any(|m| m.contains("lacks the arc from `nav.moving` to `nav.back`")));
    for d in diags.iter() {
        let at = pos(&map, d.span.unwrap());
        let line = map.get(file).line_text(at.line);
        assert!(line.trim_start().starts_with('<'), "{line}");
    }

    // An action that no longer parses is reported at its code.
    let broken = xml.replacen("<code>cancel watchdog</code>", "<code>cancel</code>", 1);
    let mut map = SourceMap::new();
    let file = map.add("b.pnml", broken.clone());
    let mut diags = Diagnostics::new();
    assert!(import_pnml(file, &broken, &mut diags).is_none());
    let (d, at) = only(&map, &diags);
    assert_eq!(d.code, "E0506");
    assert!(map
        .get(file)
        .line_text(at.line)
        .contains("<code>cancel</code>"));
}

#[test]
fn an_empty_project_round_trips() {
    let project = Project::default();
    let xml = export_pnml(&project);
    let back = import_pnml(FileId(0), &xml, &mut Diagnostics::new()).expect("imports");
    assert_eq!(back, project);
}

// ---------------------------------------------------------------------------------------------
// Robustness
// ---------------------------------------------------------------------------------------------

#[test]
fn every_truncation_is_an_error_and_never_a_panic() {
    for text in [
        read_mcc("Sudoku-PT-AN01.pnml"),
        export_pnml(&sample_project()),
    ] {
        let end = text.rfind("</pnml>").unwrap();
        let cuts = (0..end).filter(|i| text.is_char_boundary(*i)).step_by(3);
        for cut in cuts {
            let mut diags = Diagnostics::new();
            let project = import_pnml(FileId(0), &text[..cut], &mut diags);
            assert!(project.is_none(), "cut at {cut} imported");
            assert!(diags.has_errors(), "cut at {cut} gave no error");
            for d in diags.iter() {
                let span = d.span.unwrap();
                assert!(span.start <= span.end && span.end as usize <= cut, "{d:?}");
            }
        }
    }
}

mod properties {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// Comments, descriptions, paths, names in Petrel data and text literals may hold any
        /// character, and all come back exactly (paths: any that stays inside the project;
        /// the others are E0508, tests/paths.rs).
        #[test]
        fn any_text_survives_the_round_trip(
            comment in any::<String>(),
            description in any::<String>(),
            literal in "[^\n]*",
            path in any::<String>().prop_filter("a path inside the project", |p| {
                petrel_diag::paths::check_relative(p).is_ok()
            }),
        ) {
            let mut project = sample_project();
            project.manifest.description = Some(description);
            project.files[0].path = path;
            project.files[0].end_comments.push(comment.clone());
            project.files[0].nets[0].items[0].trailing = Some(comment.clone());
            if let ItemKind::Transition(t) = &mut project.files[1].nets[0].items[1].kind {
                t.actions[0].action = Action::Emit {
                    to: None,
                    event: n("ev_communication"),
                    args: vec![Expr::Text(literal, sp()), Expr::Var(n("code"))],
                    span: sp(),
                };
            }
            let xml = export_pnml(&project);
            let mut diags = Diagnostics::new();
            let back = import_pnml(FileId(0), &xml, &mut diags);
            prop_assert!(diags.is_empty(), "{:?}", codes(&diags));
            prop_assert_eq!(back, Some(project));
        }

        /// Whatever the bytes, reading reports or succeeds, and never panics.
        #[test]
        fn garbage_never_panics(
            at in 0usize..1900,
            junk in "[<>&;\"'/= a-z!?\\[\\]-]{0,12}",
        ) {
            let text = read_mcc("Sudoku-PT-AN01.pnml");
            let mut at = at.min(text.len());
            while !text.is_char_boundary(at) {
                at -= 1;
            }
            let mangled = format!("{}{junk}{}", &text[..at], &text[at..]);
            let mut diags = Diagnostics::new();
            let _ = parse_pnml(FileId(0), &mangled, &mut diags);
            let _ = import_pnml(FileId(0), &mangled, &mut diags);
        }
    }
}

// ---------------------------------------------------------------------------------------------
// The constructs of structured missions: parameters, instances, children, guards, emptiness
// tests, events addressed to a net, invariants, scoped globals, intended warnings
// ---------------------------------------------------------------------------------------------

fn data_dir(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

/// `nets/tests/data/language`, checked: it must check clean, without a warning.
fn language() -> Project {
    let (loaded, compiled, diags) =
        petrel_nets::project::load_and_check(&data_dir("language")).expect("readable");
    assert!(diags.is_empty(), "{}", diags.render_human(&loaded.sources));
    assert!(compiled.is_some());
    loaded.project
}

/// What the language project must use, so that editing it cannot silently drop a construct
/// from the round trip.
#[test]
fn the_language_project_uses_every_construct() {
    let p = language();
    let m = &p.manifest;
    assert_eq!(m.instances.len(), 2, "two instances of one template");
    assert_eq!(m.instances[0].net, m.instances[1].net);
    assert!(!m.invariants.is_empty() && m.invariants.iter().all(|i| i.formula.is_some()));
    assert!(
        m.globals.iter().any(|g| g.nets.is_some()),
        "a scoped global"
    );
    let nets: Vec<&NetDecl> = p.nets().collect();
    assert!(nets.iter().any(|n| !n.params.is_empty()), "net parameters");
    assert!(
        nets.iter().any(|n| !n.allows.is_empty()),
        "@allow before a net"
    );
    let items: Vec<&Item> = nets.iter().flat_map(|n| &n.items).collect();
    assert!(items
        .iter()
        .any(|i| matches!(i.kind, ItemKind::Children(_))));
    assert!(items
        .iter()
        .any(|i| matches!(i.kind, ItemKind::Place(_)) && !i.allows.is_empty()));
    assert!(items
        .iter()
        .any(|i| matches!(i.kind, ItemKind::Transition(_)) && !i.allows.is_empty()));
    let children: Vec<&ChildDecl> = nets.iter().flat_map(|n| n.children()).collect();
    assert!(children.iter().any(|c| c.args.is_some()) && children.iter().any(|c| c.args.is_none()));
    let transitions: Vec<&TransitionDecl> = nets.iter().flat_map(|n| n.transitions()).collect();
    assert!(transitions.iter().any(|t| t.guard.is_some()), "a guard");
    assert!(
        transitions.iter().any(|t| !t.empty.is_empty()),
        "an emptiness test"
    );
    assert!(
        transitions
            .iter()
            .any(|t| t.inputs.iter().any(|n| n.text.ends_with(".done"))),
        "a completion place"
    );
    let actions: Vec<&Action> = transitions
        .iter()
        .flat_map(|t| t.actions.iter().map(|a| &a.action))
        .collect();
    assert!(actions.iter().any(|a| matches!(a, Action::Finish(_))));
    assert!(actions
        .iter()
        .any(|a| matches!(a, Action::Activate { args, .. } if !args.is_empty())));
    assert!(actions
        .iter()
        .any(|a| matches!(a, Action::Deactivate(n) if n.text == "self")));
    assert!(actions
        .iter()
        .any(|a| matches!(a, Action::Emit { to: Some(_), .. })));
    assert!(actions.iter().any(|a| matches!(
        a,
        Action::StartTimer {
            after: DurationExpr::SelfSeconds(_),
            ..
        }
    )));
    assert!(actions.iter().any(|a| matches!(a, Action::Call { args, .. }
        if args.iter().any(|e| matches!(e, Expr::SelfParam(_))))));
}

#[test]
fn the_language_project_survives_export_and_import() {
    let project = language();
    let xml = export_pnml(&project);
    assert!(xml.contains("<toolspecific tool=\"petrel\" version=\"2\">"));
    let mut map = SourceMap::new();
    let file = map.add("language.pnml", xml.clone());
    let mut diags = Diagnostics::new();
    let back = import_pnml(file, &xml, &mut diags);
    assert!(diags.is_empty(), "{}\n{xml}", diags.render_human(&map));
    let back = back.expect("imports");
    assert_eq!(back, project);
    assert_eq!(
        export_pnml(&back),
        xml,
        "a second export is the same document"
    );
    // The imported project checks as the original does, and prints as the files are written.
    let (compiled, found) = petrel_nets::check::check(&back);
    assert!(found.is_empty(), "{:?}", codes(&found));
    assert!(compiled.is_some());
    for f in &back.files {
        let written = std::fs::read_to_string(data_dir("language").join(&f.path)).unwrap();
        assert_eq!(petrel_nets::fmt::format_file(f), written, "{}", f.path);
    }
    // Spans of what was parsed from text (guards, arguments, invariants) point into the file.
    for t in back.nets().flat_map(|n| n.transitions()) {
        if let Some(g) = &t.guard {
            assert!(xml[g.span().start as usize..].starts_with("<guard>"));
        }
    }
}

#[test]
fn instances_expand_as_the_checker_does() {
    for dir in [
        data_dir("language"),
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../missions/uav"),
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../missions/auv"),
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../missions/redermor"),
    ] {
        let (loaded, compiled, diags) = petrel_nets::project::load_and_check(&dir).unwrap();
        let compiled = compiled.unwrap_or_else(|| panic!("{}: {:?}", dir.display(), codes(&diags)));
        let expanded = petrel_nets::instances::instances(&loaded.project);
        assert!(!expanded.truncated);
        let decls: Vec<&NetDecl> = loaded.project.nets().collect();
        let ours: Vec<(String, String, Option<usize>, Vec<usize>)> = expanded
            .list
            .iter()
            .map(|i| {
                (
                    i.name.clone(),
                    decls[i.net].name.text.clone(),
                    i.parent.map(|p| p.0),
                    i.children.clone(),
                )
            })
            .collect();
        let theirs: Vec<(String, String, Option<usize>, Vec<usize>)> = compiled
            .nets
            .iter()
            .map(|n| {
                (
                    n.name.clone(),
                    n.template.clone(),
                    n.parent.map(|p| p.0 as usize),
                    n.children.iter().map(|&c| c as usize).collect(),
                )
            })
            .collect();
        assert_eq!(ours, theirs, "{}", dir.display());
    }
}

/// `(source, target)` of every arc of a P/T net, by id.
fn arc_ids(pt: &petrel_nets::pnml::PtNet) -> BTreeSet<(String, String)> {
    let id = |n: PtNode| match n {
        PtNode::Place(i) => pt.places[i].id.clone(),
        PtNode::Transition(i) => pt.transitions[i].id.clone(),
    };
    pt.arcs
        .iter()
        .map(|a| (id(a.source), id(a.target)))
        .collect()
}

#[test]
fn the_skeleton_has_one_copy_per_instance_and_the_finish_arcs() {
    let xml = export_pnml(&language());
    let mut diags = Diagnostics::new();
    let pt = parse_pnml(FileId(0), &xml, &mut diags).remove(0);
    assert!(diags.is_empty());
    assert!(pt.petrel_export);
    let places: Vec<(&str, &str, u64)> = pt
        .places
        .iter()
        .map(|p| (p.id.as_str(), p.name.as_str(), p.initial))
        .collect();
    assert_eq!(
        places,
        [
            ("global.bottleneck_free", "global.bottleneck_free", 1),
            ("global.alarm", "global.alarm", 0),
            ("R1.moving", "R1.moving", 1),
            ("R1.waiting", "R1.waiting", 0),
            ("R1.in_bottleneck", "R1.in_bottleneck", 0),
            ("R2.moving", "R2.moving", 1),
            ("R2.waiting", "R2.waiting", 0),
            ("R2.in_bottleneck", "R2.in_bottleneck", 0),
            ("SYNC.watching", "SYNC.watching", 1),
            // PLAN is not started: its place is empty until an activation, which P/T lacks.
            ("PLAN.computing", "PLAN.computing", 0),
            ("PHASES.idle", "PHASES.idle", 1),
            ("PHASES.transiting", "PHASES.transiting", 0),
            ("PHASES.surveying", "PHASES.surveying", 0),
            ("PHASES.finished", "PHASES.finished", 0),
            ("PHASES.TRANSIT.done", "PHASES.TRANSIT.done", 0),
            ("PHASES.SURVEY.done", "PHASES.SURVEY.done", 0),
            ("PHASES-TRANSIT.cruising", "PHASES/TRANSIT.cruising", 0),
            ("PHASES-SURVEY.scanning", "PHASES/SURVEY.scanning", 0),
        ]
    );
    let s = |a: &str, b: &str| (a.to_string(), b.to_string());
    let expected: BTreeSet<(String, String)> = [
        // Each robot has its own copy, and both take the one global token.
        s("R1.moving", "R1.enter"),
        s("R1.enter", "R1.waiting"),
        s("R1.waiting", "R1.pass"),
        s("global.bottleneck_free", "R1.pass"),
        s("R1.pass", "R1.in_bottleneck"),
        s("R1.in_bottleneck", "R1.leave_it"),
        s("R1.leave_it", "R1.moving"),
        s("R1.leave_it", "global.bottleneck_free"),
        s("R2.moving", "R2.enter"),
        s("R2.enter", "R2.waiting"),
        s("R2.waiting", "R2.pass"),
        s("global.bottleneck_free", "R2.pass"),
        s("R2.pass", "R2.in_bottleneck"),
        s("R2.in_bottleneck", "R2.leave_it"),
        s("R2.leave_it", "R2.moving"),
        s("R2.leave_it", "global.bottleneck_free"),
        // `raise` tests `alarm` for emptiness: no arc from it, only the output.
        s("SYNC.watching", "SYNC.raise"),
        s("SYNC.raise", "SYNC.watching"),
        s("SYNC.raise", "global.alarm"),
        s("PLAN.computing", "PLAN.done"),
        s("PHASES.idle", "PHASES.begin"),
        s("PHASES.begin", "PHASES.transiting"),
        s("PHASES.transiting", "PHASES.nudge"),
        s("PHASES.nudge", "PHASES.transiting"),
        s("PHASES.transiting", "PHASES.next"),
        s("PHASES.TRANSIT.done", "PHASES.next"),
        s("PHASES.next", "PHASES.surveying"),
        s("PHASES.surveying", "PHASES.wrap"),
        s("PHASES.SURVEY.done", "PHASES.wrap"),
        s("PHASES.wrap", "PHASES.finished"),
        // The children's `finish` marks their parent's completion places.
        s("PHASES-TRANSIT.cruising", "PHASES-TRANSIT.arrive"),
        s("PHASES-TRANSIT.arrive", "PHASES.TRANSIT.done"),
        s("PHASES-SURVEY.scanning", "PHASES-SURVEY.done"),
        s("PHASES-SURVEY.done", "PHASES.SURVEY.done"),
    ]
    .into_iter()
    .collect();
    assert_eq!(arc_ids(&pt), expected);
    assert_eq!(pt.arcs.len(), expected.len());
    assert_eq!(pt.max_arc_weight(), 1);
    assert_eq!(pt.transitions.len(), 14);

    // A project without the Petrel block is not an export.
    let plain = parse_pnml(FileId(0), &read_mcc("Sudoku-PT-AN01.pnml"), &mut diags).remove(0);
    assert!(!plain.petrel_export);
}

#[test]
fn a_version_1_export_still_imports() {
    // Written by Petrel before nets had parameters (`petrel export --pnml missions/uav`).
    let path = data_dir("pnml/uav-v1.pnml");
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains("<toolspecific tool=\"petrel\" version=\"1\">"));
    let mut map = SourceMap::new();
    let file = map.add("uav-v1.pnml", text.clone());
    let mut diags = Diagnostics::new();
    let back = import_pnml(file, &text, &mut diags);
    assert!(diags.is_empty(), "{}", diags.render_human(&map));
    let uav = petrel_nets::project::load(
        &PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../missions/uav"),
    )
    .unwrap();
    // Version 1 carried no invariants (the project gained them since): all else is equal.
    let mut today = uav.project;
    assert!(!today.manifest.invariants.is_empty());
    today.manifest.invariants.clear();
    assert_eq!(back.expect("imports"), today);

    // Its checks still hold: a version-1 element without its data is refused.
    let broken = text.replacen(
        "<toolspecific tool=\"petrel\" version=\"1\">\n          <place name=\"ready\"",
        "<toolspecific tool=\"other\" version=\"1\">\n          <place name=\"ready\"",
        1,
    );
    assert_ne!(broken, text);
    let mut diags = Diagnostics::new();
    assert!(import_pnml(FileId(0), &broken, &mut diags).is_none());
    assert!(diags
        .iter()
        .any(|d| d.code == "E0506" && d.message.contains("has no petrel data")));
}

/// Imports `xml`, expecting failure; the diagnostics with their lines.
fn refused(xml: &str) -> Vec<(&'static str, String, String)> {
    let mut map = SourceMap::new();
    let file = map.add("t.pnml", xml.to_string());
    let mut diags = Diagnostics::new();
    assert!(import_pnml(file, xml, &mut diags).is_none(), "imported");
    diags
        .iter()
        .map(|d| {
            let line = d
                .span
                .map(|s| {
                    map.get(file)
                        .line_text(pos(&map, s).line)
                        .trim()
                        .to_string()
                })
                .unwrap_or_default();
            (d.code, d.message.clone(), line)
        })
        .collect()
}

#[test]
fn tampered_new_constructs_are_e0506_where_they_are_written() {
    let xml = export_pnml(&language());
    let cases: [(&str, &str, &str, &str); 9] = [
        // A guard, arguments, an invariant that no longer parse.
        (
            "<guard>r == self.robot</guard>",
            "<guard>r == == self.robot</guard>",
            "petrel guard `r == == self.robot` does not parse",
            "<guard>",
        ),
        (
            "args=\"0.5\"",
            "args=\"0.5 0.6\"",
            "petrel argument list `0.5 0.6` does not parse",
            "<child net=\"TRANSIT\"",
        ),
        (
            "<invariant name=\"bottleneck\">not (",
            "<invariant name=\"bottleneck\">not ((",
            "petrel invariant",
            "<invariant name=\"bottleneck\">",
        ),
        // A name that is not a name.
        (
            "<param name=\"robot\" type=\"text\"/>",
            "<param name=\"ro bot\" type=\"text\"/>",
            "`ro bot`, which is not a Petrel name",
            "<param name=\"ro bot\"",
        ),
        // An instance's argument that is not a value.
        (
            "args=\"&quot;r1&quot;, 0.5\"",
            "args=\"robot, 0.5\"",
            "the arguments of instance `R1` are not all values",
            "<instance name=\"R1\"",
        ),
        // A copy lost, or given to the wrong instance.
        (
            "            <copy net=\"R2\" ref=\"R2.waiting\"/>\n",
            "",
            "`waiting` of net `ROBOT` has 1 P/T copies, but the project runs 2 instance(s) of the net",
            "<place name=\"waiting\"",
        ),
        (
            "<copy net=\"R2\" ref=\"R2.moving\"/>",
            "<copy net=\"R3\" ref=\"R2.moving\"/>",
            "said to be instance `R3`'s, but the instance in its place is `R2`",
            "<copy net=\"R3\"",
        ),
        // The `finish` arc removed from the skeleton.
        (
            "      <arc id=\"PHASES-TRANSIT.arrive.out\" source=\"PHASES-TRANSIT.arrive\" target=\"PHASES.TRANSIT.done\"/>\n",
            "",
            "lacks the arc from `PHASES-TRANSIT.arrive` to `PHASES.TRANSIT.done`",
            "<transition id=\"PHASES-TRANSIT.arrive\">",
        ),
        // An arc for the emptiness test added: the skeleton has none.
        (
            "    </page>",
            "      <arc id=\"extra\" source=\"global.alarm\" target=\"SYNC.raise\"/>\n    </page>",
            "the arc from `global.alarm` to `SYNC.raise` is not in the Petrel data",
            "<arc id=\"extra\"",
        ),
    ];
    for (from, to, message, line) in cases {
        assert!(xml.contains(from), "{from}");
        let found = refused(&xml.replacen(from, to, 1));
        assert!(
            found
                .iter()
                .any(|(c, m, l)| *c == "E0506" && m.contains(message) && l.starts_with(line)),
            "{from} -> {to}: {found:#?}"
        );
    }
}

#[test]
fn an_unknown_version_is_e0507() {
    let xml = export_pnml(&language()).replacen("version=\"2\"", "version=\"3\"", 1);
    let found = refused(&xml);
    assert_eq!(found.len(), 1, "{found:#?}");
    assert_eq!(found[0].0, "E0507");
    assert!(found[0].1.contains("version `3`"), "{}", found[0].1);
    assert!(found[0].2.starts_with("<toolspecific tool=\"petrel\""));
}

#[test]
fn deeply_nested_lists_in_petrel_text_are_refused_not_a_crash() {
    // Parsing recurses into list literals: a hostile file must not exhaust the stack.
    let xml = export_pnml(&language());
    let deep = format!("{}1{}", "[".repeat(100_000), "]".repeat(100_000));
    for (from, to) in [
        (
            "<code>call GUI.say(self.robot)</code>".to_string(),
            format!("<code>call GUI.say({deep})</code>"),
        ),
        (
            "<guard>d &gt; 10.0</guard>".to_string(),
            format!("<guard>d &gt; {deep}</guard>"),
        ),
        ("args=\"0.5\"".to_string(), format!("args=\"{deep}\"")),
    ] {
        assert!(xml.contains(&from), "{from}");
        let found = refused(&xml.replacen(&from, &to, 1));
        let ends: Vec<String> = found
            .iter()
            .map(|(c, m, _)| format!("{c} ...{}", &m[m.len().saturating_sub(80)..]))
            .collect();
        assert!(
            found
                .iter()
                .any(|(c, m, _)| *c == "E0506" && m.ends_with("lists nested more than 32 deep")),
            "{ends:#?}"
        );
    }
}

#[test]
fn truncated_and_mangled_language_exports_never_panic() {
    let text = export_pnml(&language());
    let end = text.rfind("</pnml>").unwrap();
    for cut in (0..end).filter(|i| text.is_char_boundary(*i)).step_by(7) {
        let mut diags = Diagnostics::new();
        assert!(import_pnml(FileId(0), &text[..cut], &mut diags).is_none());
        assert!(diags.has_errors(), "cut at {cut} gave no error");
    }
    // Each Petrel element dropped in turn: refused or read, never a panic.
    let lines: Vec<&str> = text.lines().collect();
    let block_end = lines
        .iter()
        .position(|l| l.trim() == "</toolspecific>")
        .unwrap();
    for skip in 5..block_end {
        if !lines[skip].trim_end().ends_with("/>") {
            continue;
        }
        let mangled: String = lines
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != skip)
            .map(|(_, l)| format!("{l}\n"))
            .collect();
        let _ = import_pnml(FileId(0), &mangled, &mut Diagnostics::new());
    }
}

/// A project of nets `N0 ... N{depth-1}`, each declaring the next as its child; with
/// `doubling`, `N{k}` and `M{k}` both declare `N{k+1}` and `M{k+1}`, so the instances double
/// at each level.
fn tower(depth: usize, doubling: bool) -> Project {
    let n = |s: String| Name::synthetic(s);
    let mut nets = Vec::new();
    for k in 0..depth {
        for prefix in ["N", "M"] {
            if prefix == "M" && (!doubling || k == 0) {
                continue;
            }
            let mut children = vec![ChildDecl {
                net: n(format!("N{}", k + 1)),
                args: None,
            }];
            if doubling {
                children.push(ChildDecl {
                    net: n(format!("M{}", k + 1)),
                    args: None,
                });
            }
            let items = if k + 1 < depth {
                vec![Item {
                    trivia: Trivia::default(),
                    allows: Vec::new(),
                    kind: ItemKind::Children(children),
                    trailing: None,
                }]
            } else {
                Vec::new()
            };
            nets.push(NetDecl {
                trivia: Trivia::default(),
                allows: Vec::new(),
                name: n(format!("{prefix}{k}")),
                params: Vec::new(),
                items,
                end_comments: Vec::new(),
            });
        }
    }
    Project {
        manifest: Manifest {
            name: "tower".into(),
            files: vec![FileRef {
                path: "t.pn".into(),
                span: sp(),
            }],
            start: vec![n("N0".into())],
            ..Manifest::default()
        },
        files: vec![NetFile {
            path: "t.pn".into(),
            nets,
            end_comments: Vec::new(),
        }],
    }
}

#[test]
fn instance_expansion_is_bounded_in_count_and_size() {
    use petrel_nets::instances::{instances, MAX_INSTANCES};
    let started = std::time::Instant::now();
    // 2^30 instances if nothing stopped it.
    let wide = instances(&tower(30, true));
    assert!(wide.truncated);
    assert_eq!(wide.list.len(), MAX_INSTANCES);
    // A chain 20,000 deep: no stack overflow, names bounded in total.
    let deep = instances(&tower(20_000, false));
    assert!(deep.truncated);
    assert!(deep.list.len() < 20_000);
    assert_eq!(deep.list[2].name, "N0/N1/N2");
    assert!(
        started.elapsed().as_secs_f64() < 20.0,
        "{:?}",
        started.elapsed()
    );
    // Such a project does not import back.
    let xml = export_pnml(&tower(30, true));
    let found = refused(&xml);
    assert!(
        found
            .iter()
            .any(|(c, m, _)| *c == "E0506" && m.contains("expand into more than")),
        "{:?}",
        found.iter().take(3).collect::<Vec<_>>()
    );
}

#[test]
fn a_child_that_is_its_own_ancestor_is_made_once_without_children() {
    let n = |s: &str| Name::synthetic(s);
    let net = |name: &str, child: &str| NetDecl {
        trivia: Trivia::default(),
        allows: Vec::new(),
        name: n(name),
        params: Vec::new(),
        items: vec![Item {
            trivia: Trivia::default(),
            allows: Vec::new(),
            kind: ItemKind::Children(vec![ChildDecl {
                net: n(child),
                args: None,
            }]),
            trailing: None,
        }],
        end_comments: Vec::new(),
    };
    let mut p = tower(1, false);
    p.files[0].nets = vec![net("ROOT", "A"), net("A", "B"), net("B", "A")];
    let names: Vec<String> = petrel_nets::instances::instances(&p)
        .list
        .into_iter()
        .map(|i| i.name)
        .collect();
    assert_eq!(names, ["ROOT", "ROOT/A", "ROOT/A/B", "ROOT/A/B/A"]);
    // Export and import agree on it, whatever the checker says of the cycle.
    let xml = export_pnml(&p);
    let back = import_pnml(FileId(0), &xml, &mut Diagnostics::new());
    assert_eq!(back, Some(p));
}

/// Every mission of the repository survives export and import as it was written: Redermor's
/// program answers and internal events were once lost, and the imported project failed its
/// check.
#[test]
fn every_mission_of_the_repository_survives_export_and_import() {
    let missions = Path::new(env!("CARGO_MANIFEST_DIR")).join("../missions");
    let mut seen = 0;
    for entry in std::fs::read_dir(&missions).unwrap() {
        let dir = entry.unwrap().path();
        if !dir.join("petrel.toml").exists() {
            continue;
        }
        let loaded = petrel_nets::project::load(&dir).expect("the mission reads");
        let xml = export_pnml(&loaded.project);
        let mut map = SourceMap::new();
        let file = map.add("mission.pnml", xml.clone());
        let mut diags = Diagnostics::new();
        let back = import_pnml(file, &xml, &mut diags).expect("imports");
        assert!(
            diags.is_empty(),
            "{}: {}",
            dir.display(),
            diags.render_human(&map)
        );
        assert_eq!(back.manifest, loaded.project.manifest, "{}", dir.display());
        assert_eq!(back.files, loaded.project.files, "{}", dir.display());
        assert_eq!(export_pnml(&back), xml, "{}", dir.display());
        seen += 1;
    }
    assert!(seen >= 4, "missions found: {seen}");
}

/// Blank lines between comments (kept by `petrel fmt`) survive a PNML round trip too.
#[test]
fn blank_lines_between_comments_survive_export_and_import() {
    let manifest = "[project]\nname = \"t\"\nfiles = [\"a.pn\"]\nstart = [\"A\"]\n";
    let text = "// Header.\n\n// About A.\nnet A {\n    // One.\n\n    // Two.\n    place p = 1\n\n    // End.\n}\n\n// After, one.\n\n// After, two.\n";
    let (project, _, d, _) = petrel_nets::project::from_sources(manifest, &[("a.pn", text)]);
    assert!(d.is_empty(), "{d:?}");
    let xml = export_pnml(&project);
    let back = import_pnml(FileId(0), &xml, &mut Diagnostics::new()).expect("imports");
    assert_eq!(back, project);
    assert_eq!(petrel_nets::fmt::format_file(&back.files[0]), text);
}
