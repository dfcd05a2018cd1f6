//! Graphviz DOT drawing of a project's nets: what `petrel dot` prints.
//!
//! The drawing is for people reading a mission, so it follows Petri-net conventions: places are
//! circles (filled when they hold a token), transitions are boxes that say what fires them and
//! what they do, and each net is a cluster. Global places are drawn once, outside every cluster,
//! so a reader sees at a glance which nets share them.
//!
//! The model is drawn as written, before checking: an unresolved place name becomes a dashed red
//! node rather than an error, so the drawing helps to find the mistake instead of refusing.
//! Output follows declaration order and nothing else, so the same project always gives the same
//! text and golden tests stay stable.

use crate::fmt::{format_action, format_transition_header, format_trigger};
use crate::model::{NetDecl, Project, TransitionDecl};
use std::collections::BTreeSet;
use std::fmt::Write as _;

/// Font for every label: a sans-serif that every Graphviz install resolves.
const FONT: &str = "Helvetica";
/// Fill of a place marked at mission start.
const MARKED_FILL: &str = "#303030";
/// Fill of a place marked in a net that is not active at start: its marking only applies once
/// the net is activated, so it must look different from tokens that are really there.
const DORMANT_FILL: &str = "#b8b8b8";
/// Outline, fill and arc colour of global places, so shared places stand out from local ones.
const GLOBAL_COLOR: &str = "#1f6fb2";
/// Colour of unresolved place names: they are mistakes to fix.
const UNKNOWN_COLOR: &str = "#d62728";
/// Prefix of global place ids; a net with this name gets a suffixed prefix so ids stay unique.
const GLOBAL_PREFIX: &str = "global";

/// The Graphviz DOT text of `project`'s nets, or of the one net named `only_net`.
///
/// Every net is a cluster labelled with its name and whether the mission starts with it active.
/// Node ids are `NET.place` for places, `NET.t.transition` for transitions, `global.NAME` for
/// global places and `NET.unknown.NAME` for names that resolve to no place (identifiers have no
/// dots, so these never collide). With `only_net`, the drawing keeps that net's cluster and the
/// global places it uses.
///
/// Fails only when `only_net` names no net of the project; the message lists the nets there are.
pub fn project_to_dot(project: &Project, only_net: Option<&str>) -> Result<String, String> {
    let prefixes = net_prefixes(project);
    // Keep each net with its unique id prefix; the filter then drops the other nets.
    let nets: Vec<(&NetDecl, &str)> = project
        .nets()
        .zip(prefixes.iter().map(String::as_str))
        .filter(|(net, _)| only_net.is_none_or(|name| net.name.text == name))
        .collect();
    if let Some(name) = only_net {
        if nets.is_empty() {
            return Err(no_such_net(project, name));
        }
    }

    let globals = global_names(project);
    let drawn: Vec<NetDrawing> = nets
        .iter()
        .map(|(net, prefix)| draw_net(project, net, prefix, &globals))
        .collect();

    // Every global place in the whole drawing; with one net, only those it touches.
    let used: BTreeSet<&str> = drawn
        .iter()
        .flat_map(|d| d.globals_used.iter().map(String::as_str))
        .collect();
    let shown_globals: Vec<(&str, u32)> = globals
        .iter()
        .filter(|(name, _)| only_net.is_none() || used.contains(name))
        .copied()
        .collect();

    let mut out = String::new();
    let title = match only_net {
        None => project.manifest.name.clone(),
        Some(name) => format!("{}, net {name}", project.manifest.name),
    };
    let _ = writeln!(out, "digraph {} {{", q(&project.manifest.name));
    let _ = writeln!(
        out,
        "  graph [rankdir=LR, fontname={}, fontsize=12, label={}, labelloc=t];",
        q(FONT),
        q(&title)
    );
    let _ = writeln!(out, "  node [fontname={}, fontsize=10];", q(FONT));
    let _ = writeln!(
        out,
        "  edge [fontname={}, fontsize=10, arrowsize=0.7];",
        q(FONT)
    );

    if !shown_globals.is_empty() {
        // Declared at top level, before any cluster, so Graphviz keeps them outside all of them.
        out.push('\n');
        out.push_str("  // Global places, shared by every net.\n");
        for (name, tokens) in &shown_globals {
            out.push_str(&global_node(name, *tokens));
        }
    }

    for d in &drawn {
        out.push('\n');
        out.push_str(&d.cluster);
    }

    // Arcs go at top level: an arc written inside a cluster would pull a global place into
    // that cluster, and a place shared by two clusters would be drawn inside one of them.
    for d in &drawn {
        if d.arcs.is_empty() {
            continue;
        }
        out.push('\n');
        let _ = writeln!(out, "  // Arcs of {}.", d.name);
        for arc in &d.arcs {
            out.push_str(arc);
        }
    }
    out.push_str("}\n");
    Ok(out)
}

/// The error for a net name that matches no net, listing the nets there are.
fn no_such_net(project: &Project, name: &str) -> String {
    let names: Vec<&str> = project.nets().map(|n| n.name.text.as_str()).collect();
    if names.is_empty() {
        format!("no net named `{name}`; the project has no nets")
    } else {
        format!("no net named `{name}`; the nets are: {}", names.join(", "))
    }
}

/// A unique id prefix per net, in dispatch order.
///
/// Usually the net's name. Two nets with one name (a checker error) or a net named `global`
/// would otherwise share node ids and Graphviz would merge their nodes, hiding the problem;
/// a `#N` suffix (never part of an identifier) keeps them apart.
fn net_prefixes(project: &Project) -> Vec<String> {
    let mut taken: BTreeSet<String> = BTreeSet::new();
    taken.insert(GLOBAL_PREFIX.to_string());
    project
        .nets()
        .map(|net| {
            let base = net.name.text.as_str();
            let mut prefix = base.to_string();
            let mut n = 2;
            while taken.contains(&prefix) {
                prefix = format!("{base}#{n}");
                n += 1;
            }
            taken.insert(prefix.clone());
            prefix
        })
        .collect()
}

/// The global places with their initial tokens, in manifest order; a repeated name (a checker
/// error) keeps its first declaration so the place is still drawn exactly once.
fn global_names(project: &Project) -> Vec<(&str, u32)> {
    let mut seen = BTreeSet::new();
    project
        .manifest
        .globals
        .iter()
        .filter(|g| seen.insert(g.name.text.as_str()))
        .map(|g| (g.name.text.as_str(), g.tokens))
        .collect()
}

/// One net, drawn: its cluster text and its arcs, kept apart because arcs go at top level.
struct NetDrawing {
    /// The net's name as written, for the arcs' comment.
    name: String,
    /// The `subgraph "cluster_..." { ... }` text, with its trailing newline.
    cluster: String,
    /// One line per arc, in declaration order.
    arcs: Vec<String>,
    /// The global places its transitions use, for the one-net drawing.
    globals_used: BTreeSet<String>,
}

/// Where a place name used by a transition leads.
enum Target {
    /// A place of the transition's own net.
    Local,
    /// A global place of the manifest.
    Global,
    /// Neither: drawn as a dashed red node so the reader finds the mistake.
    Unknown,
}

/// Draws one net: its places, transitions and unresolved names, then its arcs.
fn draw_net(project: &Project, net: &NetDecl, prefix: &str, globals: &[(&str, u32)]) -> NetDrawing {
    let active = project
        .manifest
        .start
        .iter()
        .any(|s| s.text == net.name.text);
    let locals: BTreeSet<&str> = net.places().map(|p| p.name.text.as_str()).collect();
    // A net's own place shadows a global place of the same name.
    let resolve = |name: &str| {
        if locals.contains(name) {
            Target::Local
        } else if globals.iter().any(|(g, _)| *g == name) {
            Target::Global
        } else {
            Target::Unknown
        }
    };

    let mut arcs = Vec::new();
    let mut globals_used = BTreeSet::new();
    // Unknown names in first-use order, each drawn once per net.
    let mut unknown: Vec<&str> = Vec::new();
    for t in net.transitions() {
        let tid = transition_id(prefix, t);
        let ends = t
            .inputs
            .iter()
            .map(|n| (n, true))
            .chain(t.outputs.iter().map(|n| (n, false)));
        for (name, is_input) in ends {
            let name = name.text.as_str();
            let (pid, style) = match resolve(name) {
                Target::Local => (format!("{prefix}.{name}"), String::new()),
                Target::Global => {
                    globals_used.insert(name.to_string());
                    (
                        format!("{GLOBAL_PREFIX}.{name}"),
                        format!(" [color={}]", q(GLOBAL_COLOR)),
                    )
                }
                Target::Unknown => {
                    if !unknown.contains(&name) {
                        unknown.push(name);
                    }
                    (
                        format!("{prefix}.unknown.{name}"),
                        format!(" [color={}, style=dashed]", q(UNKNOWN_COLOR)),
                    )
                }
            };
            let (from, to) = if is_input {
                (q(&pid), q(&tid))
            } else {
                (q(&tid), q(&pid))
            };
            arcs.push(format!("  {from} -> {to}{style};\n"));
        }
    }

    let mut c = String::new();
    let _ = writeln!(c, "  subgraph {} {{", q(&format!("cluster_{prefix}")));
    let name = &net.name.text;
    if active {
        let _ = writeln!(c, "    label={};", q(&format!("{name}: active at start")));
        c.push_str("    style=solid;\n    color=\"#606060\";\n");
    } else {
        let label = format!("{name}: inactive at start (light fill: marking when activated)");
        let _ = writeln!(c, "    label={};", q(&label));
        c.push_str("    style=dashed;\n    color=\"#909090\";\n");
    }
    for p in net.places() {
        let id = format!("{prefix}.{}", p.name);
        let when = if active { "at start" } else { "when activated" };
        let marking = match p.tokens {
            0 => format!("empty {when}"),
            1 => format!("1 token {when}"),
            n => format!("{n} tokens {when}"),
        };
        let fill = match (p.tokens, active) {
            (0, _) => String::new(),
            (_, true) => format!(", style=filled, fillcolor={}", q(MARKED_FILL)),
            (_, false) => format!(", style=filled, fillcolor={}", q(DORMANT_FILL)),
        };
        let _ = writeln!(
            c,
            "    {} [shape=circle, label=\"\", xlabel={}, width=0.3, fixedsize=true{fill}, tooltip={}];",
            q(&id),
            q(&p.name.text),
            q(&format!("{name}.{}: {marking}", p.name))
        );
    }
    for t in net.transitions() {
        let _ = writeln!(
            c,
            "    {} [shape=box, label={}, tooltip={}];",
            q(&transition_id(prefix, t)),
            transition_label(t),
            q(&format_transition_header(t))
        );
    }
    for u in &unknown {
        let _ = writeln!(
            c,
            "    {} [shape=circle, label=\"\", xlabel={}, width=0.3, fixedsize=true, style=dashed, color={}, fontcolor={}, tooltip={}];",
            q(&format!("{prefix}.unknown.{u}")),
            q(&format!("unknown place {u}")),
            q(UNKNOWN_COLOR),
            q(UNKNOWN_COLOR),
            q(&format!("{name} has no place {u} and there is no global place {u}"))
        );
    }
    c.push_str("  }\n");

    NetDrawing {
        name: name.clone(),
        cluster: c,
        arcs,
        globals_used,
    }
}

/// The node of a global place: a double circle in its own colour, filled when marked.
fn global_node(name: &str, tokens: u32) -> String {
    let fill = if tokens > 0 {
        format!(", style=filled, fillcolor={}", q(GLOBAL_COLOR))
    } else {
        String::new()
    };
    let marking = match tokens {
        0 => "empty at start".to_string(),
        1 => "1 token at start".to_string(),
        n => format!("{n} tokens at start"),
    };
    format!(
        "  {} [shape=doublecircle, label=\"\", xlabel={}, width=0.3, fixedsize=true, color={}, fontcolor={}{fill}, tooltip={}];\n",
        q(&format!("{GLOBAL_PREFIX}.{name}")),
        q(name),
        q(GLOBAL_COLOR),
        q(GLOBAL_COLOR),
        q(&format!("global place {name}, shared by every net: {marking}"))
    )
}

/// The id of a transition; the `.t.` keeps it apart from a place with the same name.
fn transition_id(prefix: &str, t: &TransitionDecl) -> String {
    format!("{prefix}.t.{}", t.name)
}

/// A transition's label, quoted: its name, what fires it, then one line per action.
///
/// Every line ends in `\l` (left-justified), so actions line up under the name.
fn transition_label(t: &TransitionDecl) -> String {
    let mut lines = vec![t.name.text.clone()];
    lines.push(match &t.trigger {
        Some(trigger) => format!("on {}", format_trigger(trigger)),
        None => "immediate".to_string(),
    });
    lines.extend(t.actions.iter().map(|a| format_action(&a.action)));
    let mut s = String::from("\"");
    for line in &lines {
        s.push_str(&escape(line));
        s.push_str("\\l");
    }
    s.push('"');
    s
}

/// `s` as a quoted DOT string.
fn q(s: &str) -> String {
    format!("\"{}\"", escape(s))
}

/// Escapes `s` for the inside of a DOT string.
///
/// Quotes and backslashes are escaped so text such as `call GUI.say("a \"b\"")` shows exactly as
/// written (Graphviz would otherwise read `\l` or `\N` in it as its own escapes). A newline
/// becomes `\l`, the one line break this module uses; a carriage return is dropped.
fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\l"),
            '\r' => {}
            c => out.push(c),
        }
    }
    out
}
