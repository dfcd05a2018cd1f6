//! Graphviz DOT drawing of a project's nets: what `petrel dot` prints.
//!
//! The drawing is for people reading a mission, so it follows Petri-net conventions: places are
//! circles (filled when they hold a token), transitions are boxes that say what fires them (the
//! event, the guard) and what they do, and each net is a cluster. Global places are drawn once,
//! outside every cluster, so a reader sees at a glance which nets share them.
//!
//! The nets drawn are the nets the project **runs** ([`crate::instances`]): a template with two
//! instances is drawn twice, as `R1` and `R2`, each with its own places, both reaching the same
//! global places; a child is drawn once per parent (`MISSION/TRANSIT`), its completion place
//! `TRANSIT.done` in the parent's cluster with the `finish` arc that marks it. An emptiness test
//! (`not p`) is an arc ending in a small circle (`arrowhead=odot`, the inhibitor arc of the
//! literature). [`project_tree_dot`] draws the structure alone: one box per net, the tree of
//! `children` lines, and `activate` edges.
//!
//! The model is drawn as written, before checking: an unresolved place name becomes a dashed red
//! node rather than an error, so the drawing helps to find the mistake instead of refusing.
//! Output follows declaration order and nothing else, so the same project always gives the same
//! text and golden tests stay stable.

use crate::fmt::{
    format_action, format_expr, format_guard, format_transition_header, format_trigger,
};
use crate::instances::{instances, Instance, Instances};
use crate::model::{Action, NetDecl, Project, TransitionDecl};
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
/// Colour of completion places and of the `finish` arcs that mark them: the link between a
/// child and its parent.
const COMPLETION_COLOR: &str = "#2a7f3f";
/// Colour of unresolved place names: they are mistakes to fix.
const UNKNOWN_COLOR: &str = "#d62728";
/// Prefix of global place ids; a net with this name gets a suffixed prefix so ids stay unique.
const GLOBAL_PREFIX: &str = "global";

/// The Graphviz DOT text of the nets `project` runs, or of those named `only_net`.
///
/// Every net (a plain net, an instance of a template, a child instance) is a cluster labelled
/// with its name, its template and arguments when it has any, and whether the mission starts
/// with it active. Node ids are `NET.place` for places, `NET.done.CHILD` for completion places,
/// `NET.t.transition` for transitions, `global.NAME` for global places and `NET.unknown.NAME`
/// for names that resolve to no place (identifiers have no dots, so these never collide). With
/// `only_net` (a net's name, or a template's: all its instances), the drawing keeps those
/// clusters and the global places they use.
///
/// Fails only when `only_net` names no net of the project; the message lists the nets there are.
pub fn project_to_dot(project: &Project, only_net: Option<&str>) -> Result<String, String> {
    let decls: Vec<&NetDecl> = project.nets().collect();
    let expanded = instances(project);
    let prefixes = net_prefixes(&expanded);
    let chosen: Vec<usize> = (0..expanded.list.len())
        .filter(|&i| {
            only_net.is_none_or(|name| {
                let inst = &expanded.list[i];
                inst.name == name || decls[inst.net].name.text == name
            })
        })
        .collect();
    if let Some(name) = only_net {
        if chosen.is_empty() {
            return Err(no_such_net(&expanded, &decls, name));
        }
    }

    let globals = global_names(project);
    let ctx = Context {
        project,
        decls: &decls,
        expanded: &expanded,
        prefixes: &prefixes,
        drawn: chosen.iter().copied().collect(),
        globals: &globals,
    };
    let drawn: Vec<NetDrawing> = chosen.iter().map(|&i| ctx.draw_net(i)).collect();

    // Every global place in the whole drawing; with one net, only those it touches.
    let used: BTreeSet<&str> = drawn
        .iter()
        .flat_map(|d| d.globals_used.iter().map(String::as_str))
        .collect();
    let shown_globals: Vec<&Global> = globals
        .iter()
        .filter(|g| only_net.is_none() || used.contains(g.name))
        .collect();

    let mut out = String::new();
    let mut title = match only_net {
        None => project.manifest.name.clone(),
        Some(name) => format!("{}, net {name}", project.manifest.name),
    };
    if expanded.truncated {
        let _ = write!(
            title,
            " (the first {} nets only)",
            crate::instances::MAX_INSTANCES
        );
    }
    header(&mut out, &project.manifest.name, &title, "LR", "");

    if !shown_globals.is_empty() {
        // Declared at top level, before any cluster, so Graphviz keeps them outside all of them.
        out.push('\n');
        out.push_str("  // Global places, shared by every net.\n");
        for g in &shown_globals {
            out.push_str(&global_node(g));
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

/// The Graphviz DOT text of one net the project runs (`name`: an instance's exact name, as
/// `petrel status` and the player name it), for a view of that net alone, where no arc leaves
/// its frame: the global places its transitions use are drawn inside the frame as ports (a
/// box `global NAME`, id `global.NAME`), and so is, for a child, its parent's completion place
/// that its `finish` marks (a box `PARENT: CHILD.done`, id `PARENT.done.CHILD`). Ids are
/// [`project_to_dot`]'s, so a marking colours both drawings the same way.
///
/// Fails only when `name` is not a net the project runs; the message lists the nets there are.
pub fn instance_dot(project: &Project, name: &str) -> Result<String, String> {
    let decls: Vec<&NetDecl> = project.nets().collect();
    let expanded = instances(project);
    let prefixes = net_prefixes(&expanded);
    let Some(me) = expanded.list.iter().position(|i| i.name == name) else {
        return Err(no_such_net(&expanded, &decls, name));
    };
    let globals = global_names(project);
    let parent = expanded.list[me].parent;
    // The parent counts as drawn so that the `finish` arcs are made; its completion place
    // becomes a port below.
    let drawn: BTreeSet<usize> = std::iter::once(me).chain(parent.map(|(p, _)| p)).collect();
    let ctx = Context {
        project,
        decls: &decls,
        expanded: &expanded,
        prefixes: &prefixes,
        drawn,
        globals: &globals,
    };
    let d = ctx.draw_net(me);
    let mut cluster = d
        .cluster
        .strip_suffix("  }\n")
        .unwrap_or(&d.cluster)
        .to_string();
    for g in globals.iter().filter(|g| d.globals_used.contains(g.name)) {
        let _ = writeln!(
            cluster,
            "    {} [shape=box, style=\"rounded,bold\", label={}, color={}, fontcolor={}, tooltip={}];",
            q(&format!("{GLOBAL_PREFIX}.{}", g.name)),
            q(&format!("global {}", g.name)),
            q(GLOBAL_COLOR),
            q(GLOBAL_COLOR),
            q(&format!("global place {}, shared with other nets", g.name))
        );
    }
    if let Some((p, pos)) = parent {
        let parent_inst = &expanded.list[p];
        let finishes = d.arcs.iter().any(|a| a.contains("label=\"finish\""));
        if let (Some(child), true) = (decls[parent_inst.net].children().nth(pos), finishes) {
            let _ = writeln!(
                cluster,
                "    {} [shape=box, style=\"rounded,bold\", label={}, color={}, fontcolor={}, tooltip={}];",
                q(&completion_id(&prefixes[p], &child.net.text)),
                q(&format!("{}: {}.done", parent_inst.name, child.net)),
                q(COMPLETION_COLOR),
                q(COMPLETION_COLOR),
                q(&format!(
                    "completion place {}.done of the parent {}, marked by this net's finish",
                    child.net, parent_inst.name
                ))
            );
        }
    }
    cluster.push_str("  }\n");
    let mut out = String::new();
    let title = format!("{}: net {name}", project.manifest.name);
    header(&mut out, &project.manifest.name, &title, "LR", "");
    out.push('\n');
    out.push_str(&cluster);
    if !d.arcs.is_empty() {
        out.push('\n');
        for arc in &d.arcs {
            out.push_str(arc);
        }
    }
    out.push_str("}\n");
    Ok(out)
}

/// The Graphviz DOT text of the tree of nets (Figure 8 of the ProCoSA paper): one box per net
/// the project runs, a solid arrow from each parent to each child its `children` lines declare,
/// and a dashed arrow labelled `activate` from each net to each net one of its transitions
/// activates. Nets active at start are filled. The places and transitions are left out, so a
/// mission of forty nets reads at a glance; [`project_to_dot`] draws them.
pub fn project_tree_dot(project: &Project) -> String {
    tree_dot(project, false)
}

/// [`project_tree_dot`] for a mission's overview (`petrel monitor`), laid out left to right:
/// a child says only the last part of its name (its parent is the box its arrow comes from),
/// and an `activate` edge that goes along a child's arrow is left out.
pub fn overview_tree_dot(project: &Project) -> String {
    tree_dot(project, true)
}

fn tree_dot(project: &Project, overview: bool) -> String {
    let decls: Vec<&NetDecl> = project.nets().collect();
    let expanded = instances(project);
    let prefixes = net_prefixes(&expanded);
    let start: BTreeSet<&str> = project.manifest.start.iter().map(|s| s.as_str()).collect();
    let mut out = String::new();
    let mut title = format!("{}: tree of nets", project.manifest.name);
    if expanded.truncated {
        let _ = write!(
            title,
            " (the first {} nets only)",
            crate::instances::MAX_INSTANCES
        );
    }
    header(
        &mut out,
        &project.manifest.name,
        &title,
        if overview { "LR" } else { "TB" },
        "shape=box, style=rounded, ",
    );
    if !expanded.list.is_empty() {
        out.push_str("\n  // Nets: filled when active at start.\n");
    }
    for (inst, prefix) in expanded.list.iter().zip(&prefixes) {
        let decl = decls[inst.net];
        let origin = origin(inst, decl);
        // An instance says its template on a second line; a net bound at activation its
        // parameters after its name.
        let shown = match (overview, inst.parent) {
            (true, Some(_)) => inst.name.rsplit('/').next().unwrap_or(&inst.name),
            _ => inst.name.as_str(),
        };
        let label = match (origin.strip_prefix(" = "), overview) {
            // The overview names the template only when it is another name, without its
            // parameters: the box stays as narrow as its name.
            (Some(_), true) if decl.name.text == shown => escape(shown),
            (Some(_), true) => format!("{}\\n= {}", escape(shown), escape(&decl.name.text)),
            (None, true) => escape(shown),
            (Some(template), false) => format!("{}\\n{}", escape(shown), escape(template)),
            (None, false) => escape(&format!("{shown}{origin}")),
        };
        let style = if start.contains(inst.name.as_str()) {
            ", style=\"rounded,filled\", fillcolor=\"#d8d8d8\""
        } else {
            ""
        };
        let _ = writeln!(out, "  {} [label=\"{label}\"{style}];", q(prefix));
    }

    let mut tree = Vec::new();
    for (i, inst) in expanded.list.iter().enumerate() {
        for &c in &inst.children {
            tree.push((i, c));
        }
    }
    if !tree.is_empty() {
        out.push_str("\n  // Children: each parent runs its own instance of each child.\n");
        for &(p, c) in &tree {
            let _ = writeln!(out, "  {} -> {};", q(&prefixes[p]), q(&prefixes[c]));
        }
    }

    let mut activations: Vec<(usize, usize)> = Vec::new();
    for (i, inst) in expanded.list.iter().enumerate() {
        for t in decls[inst.net].transitions() {
            for a in &t.actions {
                let Action::Activate { net, .. } = &a.action else {
                    continue;
                };
                let target = resolve_net(&expanded, &decls, i, &net.text);
                if let Some(target) = target.filter(|t| !activations.contains(&(i, *t))) {
                    activations.push((i, target));
                }
            }
        }
    }
    if !activations.is_empty() {
        out.push_str(
            "\n  // Activations: `activate NET` in a transition of the net at the tail.\n",
        );
        for &(from, to) in &activations {
            if overview && tree.contains(&(from, to)) {
                continue;
            }
            // Along a parent-child edge the tree already places the nodes: this one must not
            // pull on the layout a second time.
            let constraint = if tree.contains(&(from, to)) {
                ", constraint=false"
            } else {
                ""
            };
            let _ = writeln!(
                out,
                "  {} -> {} [style=dashed, label=\"activate\"{constraint}];",
                q(&prefixes[from]),
                q(&prefixes[to])
            );
        }
    }
    out.push_str("}\n");
    out
}

/// The graph's opening: name, layout direction, fonts, and the nodes' default shape (empty, or
/// attributes ending in `, `).
fn header(out: &mut String, name: &str, title: &str, rankdir: &str, node: &str) {
    let _ = writeln!(out, "digraph {} {{", q(name));
    let _ = writeln!(
        out,
        "  graph [rankdir={rankdir}, fontname={}, fontsize=12, label={}, labelloc=t];",
        q(FONT),
        q(title)
    );
    let _ = writeln!(out, "  node [{node}fontname={}, fontsize=10];", q(FONT));
    let _ = writeln!(
        out,
        "  edge [fontname={}, fontsize=10, arrowsize=0.7];",
        q(FONT)
    );
}

/// The net a net name in an action of instance `from` means: a child of its net (its own
/// instance of it), else a net nobody declares as a child. `self` and unknown names mean none.
fn resolve_net(expanded: &Instances, decls: &[&NetDecl], from: usize, name: &str) -> Option<usize> {
    let inst = &expanded.list[from];
    if let Some(pos) = decls[inst.net].children().position(|c| c.net.text == name) {
        return inst
            .children
            .iter()
            .copied()
            .find(|&c| expanded.list[c].parent.map(|p| p.1) == Some(pos));
    }
    expanded
        .list
        .iter()
        .position(|i| i.parent.is_none() && i.name == name)
}

/// What a net is made from, for its label: nothing for a plain net; `(p: type)` for a net
/// bound at activation; ` = TEMPLATE(p: type = value)` for an instance.
fn origin(inst: &Instance, decl: &NetDecl) -> String {
    if decl.params.is_empty() {
        return String::new();
    }
    let params: Vec<String> = match &inst.args {
        Some(args) => decl
            .params
            .iter()
            .enumerate()
            .map(|(k, p)| match args.get(k) {
                Some(a) => format!("{}: {} = {}", p.name, p.ty, format_expr(a)),
                None => format!("{}: {}", p.name, p.ty),
            })
            .collect(),
        None => decl
            .params
            .iter()
            .map(|p| format!("{}: {}", p.name, p.ty))
            .collect(),
    };
    if inst.args.is_none() && inst.name == decl.name.text {
        format!("({})", params.join(", "))
    } else {
        format!(" = {}({})", decl.name, params.join(", "))
    }
}

/// The error for a net name that matches no net, listing the nets there are.
fn no_such_net(expanded: &Instances, decls: &[&NetDecl], name: &str) -> String {
    let names: Vec<&str> = expanded.list.iter().map(|i| i.name.as_str()).collect();
    if names.is_empty() {
        return format!("no net named `{name}`; the project has no nets");
    }
    let mut msg = format!("no net named `{name}`; the nets are: {}", names.join(", "));
    let templates: BTreeSet<&str> = expanded
        .list
        .iter()
        .filter(|i| i.name != decls[i.net].name.text && i.parent.is_none())
        .map(|i| decls[i.net].name.as_str())
        .collect();
    if !templates.is_empty() {
        let list: Vec<&str> = templates.into_iter().collect();
        let _ = write!(
            msg,
            "; templates (all their instances): {}",
            list.join(", ")
        );
    }
    msg
}

/// A unique id prefix per net, in project order.
///
/// Usually the net's name. Two nets with one name (a checker error) or a net named `global`
/// would otherwise share node ids and Graphviz would merge their nodes, hiding the problem;
/// a `#N` suffix (never part of an identifier) keeps them apart.
fn net_prefixes(expanded: &Instances) -> Vec<String> {
    let mut taken: BTreeSet<String> = BTreeSet::new();
    taken.insert(GLOBAL_PREFIX.to_string());
    expanded
        .list
        .iter()
        .map(|inst| {
            let base = inst.name.as_str();
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

/// A global place as drawn.
struct Global<'a> {
    name: &'a str,
    tokens: u32,
    /// The nets that may use it, as the manifest lists them; `None`: every net.
    nets: Option<Vec<&'a str>>,
}

/// The global places with their initial tokens, in manifest order; a repeated name (a checker
/// error) keeps its first declaration so the place is still drawn exactly once.
fn global_names(project: &Project) -> Vec<Global<'_>> {
    let mut seen = BTreeSet::new();
    project
        .manifest
        .globals
        .iter()
        .filter(|g| seen.insert(g.name.text.as_str()))
        .map(|g| Global {
            name: g.name.as_str(),
            tokens: g.tokens,
            nets: g
                .nets
                .as_ref()
                .map(|list| list.iter().map(|n| n.as_str()).collect()),
        })
        .collect()
}

/// One net, drawn: its cluster text and its arcs, kept apart because arcs go at top level.
struct NetDrawing {
    /// The net's name, for the arcs' comment.
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
    /// The completion place of a child of the transition's net.
    Completion,
    /// A global place of the manifest.
    Global,
    /// Neither: drawn as a dashed red node so the reader finds the mistake.
    Unknown,
}

/// What every net's drawing needs to know of the others.
struct Context<'a> {
    project: &'a Project,
    decls: &'a [&'a NetDecl],
    expanded: &'a Instances,
    /// Node id prefix per instance.
    prefixes: &'a [String],
    /// The instances drawn: a `finish` arc reaches its parent only if the parent is drawn.
    drawn: BTreeSet<usize>,
    globals: &'a [Global<'a>],
}

impl Context<'_> {
    /// Draws one net: its places, completion places, transitions and unresolved names, then
    /// its arcs.
    fn draw_net(&self, me: usize) -> NetDrawing {
        let inst = &self.expanded.list[me];
        let net = self.decls[inst.net];
        let prefix = self.prefixes[me].as_str();
        let active = self
            .project
            .manifest
            .start
            .iter()
            .any(|s| s.text == inst.name);
        let locals: BTreeSet<&str> = net.places().map(|p| p.name.text.as_str()).collect();
        let children: BTreeSet<String> =
            net.children().map(|c| format!("{}.done", c.net)).collect();
        // A net's own place shadows a global place of the same name.
        let resolve = |name: &str| {
            if locals.contains(name) {
                Target::Local
            } else if children.contains(name) {
                Target::Completion
            } else if self.globals.iter().any(|g| g.name == name) {
                Target::Global
            } else {
                Target::Unknown
            }
        };
        // The completion place a `finish` of this net marks, if its parent is drawn.
        let finish_to = inst.parent.and_then(|(p, pos)| {
            let parent = &self.expanded.list[p];
            let child = self.decls[parent.net].children().nth(pos)?;
            self.drawn
                .contains(&p)
                .then(|| completion_id(&self.prefixes[p], &child.net.text))
        });

        let mut arcs = Vec::new();
        let mut globals_used = BTreeSet::new();
        // Unknown names in first-use order, each drawn once per net.
        let mut unknown: Vec<&str> = Vec::new();
        for t in net.transitions() {
            let tid = transition_id(prefix, t);
            // Inputs, emptiness tests (drawn as inhibitor arcs), outputs.
            let ends = t
                .inputs
                .iter()
                .map(|n| (n, End::Input))
                .chain(t.empty.iter().map(|n| (n, End::Empty)))
                .chain(t.outputs.iter().map(|n| (n, End::Output)));
            for (name, end) in ends {
                let name = name.text.as_str();
                let mut style: Vec<String> = Vec::new();
                let pid = match resolve(name) {
                    Target::Local => format!("{prefix}.{name}"),
                    Target::Completion => {
                        style.push(format!("color={}", q(COMPLETION_COLOR)));
                        completion_id(prefix, name.strip_suffix(".done").unwrap_or(name))
                    }
                    Target::Global => {
                        globals_used.insert(name.to_string());
                        style.push(format!("color={}", q(GLOBAL_COLOR)));
                        format!("{GLOBAL_PREFIX}.{name}")
                    }
                    Target::Unknown => {
                        if !unknown.contains(&name) {
                            unknown.push(name);
                        }
                        style.push(format!("color={}", q(UNKNOWN_COLOR)));
                        style.push("style=dashed".to_string());
                        format!("{prefix}.unknown.{name}")
                    }
                };
                if let End::Empty = end {
                    style.push("arrowhead=odot".to_string());
                    style.push(format!("tooltip={}", q(&format!("{name} must be empty"))));
                }
                let (from, to) = match end {
                    End::Output => (q(&tid), q(&pid)),
                    End::Input | End::Empty => (q(&pid), q(&tid)),
                };
                arcs.push(arc_line(&from, &to, &style));
            }
            if let Some(done) = &finish_to {
                if t.actions
                    .iter()
                    .any(|a| matches!(a.action, Action::Finish(_)))
                {
                    let style = [
                        format!("color={}", q(COMPLETION_COLOR)),
                        "style=dashed".to_string(),
                        "label=\"finish\"".to_string(),
                    ];
                    arcs.push(arc_line(&q(&tid), &q(done), &style));
                }
            }
        }

        let mut c = String::new();
        let _ = writeln!(c, "  subgraph {} {{", q(&format!("cluster_{prefix}")));
        let name = format!("{}{}", inst.name, origin(inst, net));
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
                q(&format!("{}.{}: {marking}", inst.name, p.name))
            );
        }
        // One completion place per declared child (a repeated child is one node).
        let mut done_drawn = BTreeSet::new();
        for ch in net.children() {
            let place = format!("{}.done", ch.net);
            if !done_drawn.insert(place.clone()) {
                continue;
            }
            let _ = writeln!(
                c,
                "    {} [shape=circle, label=\"\", xlabel={}, width=0.3, fixedsize=true, color={}, fontcolor={}, tooltip={}];",
                q(&completion_id(prefix, &ch.net.text)),
                q(&place),
                q(COMPLETION_COLOR),
                q(COMPLETION_COLOR),
                q(&format!(
                    "{}.{place}: completion place of child {}, marked by its finish",
                    inst.name, ch.net
                ))
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
                q(&format!("{} has no place {u} and there is no global place {u}", inst.name))
            );
        }
        c.push_str("  }\n");

        NetDrawing {
            name: inst.name.clone(),
            cluster: c,
            arcs,
            globals_used,
        }
    }
}

/// Which end of a transition an arc is.
enum End {
    Input,
    /// An emptiness test: an inhibitor arc.
    Empty,
    Output,
}

/// `  "from" -> "to" [a, b];` (no brackets without attributes).
fn arc_line(from: &str, to: &str, style: &[String]) -> String {
    if style.is_empty() {
        format!("  {from} -> {to};\n")
    } else {
        format!("  {from} -> {to} [{}];\n", style.join(", "))
    }
}

/// The node of a global place: a double circle in its own colour, filled when marked.
fn global_node(g: &Global) -> String {
    let fill = if g.tokens > 0 {
        format!(", style=filled, fillcolor={}", q(GLOBAL_COLOR))
    } else {
        String::new()
    };
    let marking = match g.tokens {
        0 => "empty at start".to_string(),
        1 => "1 token at start".to_string(),
        n => format!("{n} tokens at start"),
    };
    let shared = match &g.nets {
        None => "every net".to_string(),
        Some(nets) if nets.is_empty() => "no net".to_string(),
        Some(nets) => nets.join(", "),
    };
    format!(
        "  {} [shape=doublecircle, label=\"\", xlabel={}, width=0.3, fixedsize=true, color={}, fontcolor={}{fill}, tooltip={}];\n",
        q(&format!("{GLOBAL_PREFIX}.{}", g.name)),
        q(g.name),
        q(GLOBAL_COLOR),
        q(GLOBAL_COLOR),
        q(&format!("global place {}, shared by {shared}: {marking}", g.name))
    )
}

/// The id of the completion place of `child` in a net: `.done.` keeps it apart from the
/// places (`NET.place`), transitions (`NET.t.name`) and unknown names (`NET.unknown.name`),
/// whatever the child is called.
fn completion_id(prefix: &str, child: &str) -> String {
    format!("{prefix}.done.{child}")
}

/// The id of a transition; the `.t.` keeps it apart from a place with the same name.
fn transition_id(prefix: &str, t: &TransitionDecl) -> String {
    format!("{prefix}.t.{}", t.name)
}

/// A transition's label, quoted: its name, what fires it (event and guard), then one line per
/// action.
///
/// Every line ends in `\l` (left-justified), so actions line up under the name.
fn transition_label(t: &TransitionDecl) -> String {
    let mut lines = vec![t.name.text.clone()];
    let mut fired_by = match &t.trigger {
        Some(trigger) => format!("on {}", format_trigger(trigger)),
        None => "immediate".to_string(),
    };
    if let Some(g) = &t.guard {
        let _ = write!(fired_by, " if {}", format_guard(g));
    }
    lines.push(fired_by);
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
