//! Reading a PNML document as a Petrel project ([`import_pnml`]): an export back to the exact
//! project, or a plain P/T net to a project of immediate transitions.

use std::collections::HashMap;

use super::read::{parse_document, RawNet, PETREL_DATA_HELP};
use super::view::{nodes, sanitize, structure, Layout, Unique};
use super::xml::Node;
use super::PETREL_VERSION;
use crate::instances::{instances, Instances, MAX_INSTANCES};
use crate::model::*;
use crate::pt::PtNode;
use crate::syntax::{parse_action, parse_args, parse_guard};
use petrel_diag::report::{Diagnostic, Diagnostics};
use petrel_diag::source::{FileId, Span};

/// The hint for nets Petrel cannot take as mission nets but can still analyse.
const VERIFY_HINT: &str = "`petrel verify FILE.pnml` analyses weighted, unsafe P/T nets directly";

/// Reads a PNML document as a Petrel project.
///
/// A document written by [`super::export_pnml`] (it carries a net-level `<toolspecific
/// tool="petrel">` block) gives back the exact project, after checking that the P/T structure
/// still agrees with the Petrel data (`E0506` otherwise). Any other P/T net becomes a project
/// with one net file per net, named from the PNML ids made into identifiers, with immediate
/// transitions and no actions; every arc weight above 1 (`E0504`) and every initial marking
/// above 1 (`E0505`) is reported, since Petrel nets are unary and safe. Returns `None` when any
/// error was found.
pub fn import_pnml(file: FileId, text: &str, diags: &mut Diagnostics) -> Option<Project> {
    let before = diags.error_count();
    let raws = parse_document(file, text, diags);
    let parse_failed = diags.error_count() > before;
    if raws.iter().any(|r| r.petrel.is_some()) {
        if raws.len() > 1 {
            let span = raws.get(1).map(|r| r.span).unwrap_or_default();
            diags.push(
                Diagnostic::error(
                    "E0506",
                    span,
                    format!(
                        "this document holds {} nets and Petrel data: a Petrel export is one net",
                        raws.len()
                    ),
                )
                .label("a second net")
                .help(PETREL_DATA_HELP),
            );
            return None;
        }
        if parse_failed {
            return None;
        }
        let raw = raws.first()?;
        return Rebuild {
            file,
            diags,
            raw,
            before,
        }
        .project();
    }
    if raws.is_empty() {
        if !parse_failed {
            diags.push(
                Diagnostic::error("E0501", Span::new(file, 0, 0), "this document holds no `<net>`")
                    .label("no net to import")
                    .help("a PNML file holds one or more `<net type=\"http://www.pnml.org/version-2009/grammar/ptnet\">`"),
            );
        }
        return None;
    }
    let project = plain_project(&raws, diags);
    if diags.error_count() > before {
        return None;
    }
    Some(project)
}

/// The project of plain P/T nets, reporting whatever Petrel nets cannot express.
fn plain_project(raws: &[RawNet], diags: &mut Diagnostics) -> Project {
    let mut net_names = Unique::default();
    let mut manifest = Manifest::default();
    let mut files = Vec::new();
    for raw in raws {
        let pt = &raw.net;
        for p in &pt.places {
            if p.initial > 1 {
                diags.push(
                    Diagnostic::error(
                        "E0505",
                        p.span,
                        format!(
                            "place `{}` starts with {} tokens, but a Petrel place holds at most one",
                            p.id, p.initial
                        ),
                    )
                    .label(format!("initial marking {}", p.initial))
                    .help(format!("Petrel mission nets are safe, so this net cannot become one; {VERIFY_HINT}")),
                );
            }
        }
        let mut seen: HashMap<(usize, usize, bool), &str> = HashMap::new();
        for a in &pt.arcs {
            let end = |n: PtNode| match n {
                PtNode::Place(i) => pt.places.get(i).map(|p| p.id.as_str()),
                PtNode::Transition(i) => pt.transitions.get(i).map(|t| t.id.as_str()),
            };
            let (from, to) = (end(a.source).unwrap_or("?"), end(a.target).unwrap_or("?"));
            let key = (
                a.place().unwrap_or(0),
                a.transition().unwrap_or(0),
                a.is_input(),
            );
            if a.weight > 1 {
                diags.push(
                    Diagnostic::error(
                        "E0504",
                        a.span,
                        format!(
                            "arc `{}` from `{from}` to `{to}` has weight {}, but Petrel nets have unary arcs",
                            a.id, a.weight
                        ),
                    )
                    .label(format!("weight {}", a.weight))
                    .help(format!("a Petrel transition moves one token per place, so this net cannot become a mission net; {VERIFY_HINT}")),
                );
            } else if let Some(first) = seen.get(&key) {
                diags.push(
                    Diagnostic::error(
                        "E0504",
                        a.span,
                        format!(
                            "arc `{}` from `{from}` to `{to}` repeats arc `{first}`: together they weigh 2, but Petrel nets have unary arcs",
                            a.id
                        ),
                    )
                    .label("parallel arc")
                    .help(format!("merge the two arcs if one is a mistake; {VERIFY_HINT}")),
                );
            }
            seen.entry(key).or_insert(a.id.as_str());
        }
        let net_name = net_names.take(&sanitize(&pt.id), "_");
        let origin = |id: &str, name: &str| {
            if id == name {
                Vec::new()
            } else {
                vec![format!("PNML id {id:?}")]
            }
        };
        let mut names = Unique::default();
        let place_names: Vec<String> = pt
            .places
            .iter()
            .map(|p| names.take(&sanitize(&p.id), "_"))
            .collect();
        let mut items = Vec::new();
        for (p, name) in pt.places.iter().zip(&place_names) {
            items.push(Item {
                allows: Vec::new(),
                trivia: Trivia {
                    blank_before: false,
                    comments: origin(&p.id, name),
                },
                kind: ItemKind::Place(PlaceDecl {
                    name: Name {
                        text: name.clone(),
                        span: p.span,
                    },
                    tokens: u32::try_from(p.initial).unwrap_or(u32::MAX),
                    tokens_span: (p.initial > 0).then_some(p.span),
                }),
                trailing: None,
            });
        }
        let mut inputs: Vec<Vec<Name>> = vec![Vec::new(); pt.transitions.len()];
        let mut outputs: Vec<Vec<Name>> = vec![Vec::new(); pt.transitions.len()];
        for a in &pt.arcs {
            let (Some(p), Some(t)) = (a.place(), a.transition()) else {
                continue;
            };
            let (Some(name), Some(list)) = (
                place_names.get(p),
                if a.is_input() {
                    inputs.get_mut(t)
                } else {
                    outputs.get_mut(t)
                },
            ) else {
                continue;
            };
            list.push(Name {
                text: name.clone(),
                span: a.span,
            });
        }
        for ((t, ins), outs) in pt.transitions.iter().zip(inputs).zip(outputs) {
            let name = names.take(&sanitize(&t.id), "_");
            items.push(Item {
                allows: Vec::new(),
                trivia: Trivia {
                    blank_before: false,
                    comments: origin(&t.id, &name),
                },
                kind: ItemKind::Transition(TransitionDecl {
                    guard: None,
                    empty: Vec::new(),
                    name: Name {
                        text: name,
                        span: t.span,
                    },
                    trigger: None,
                    inputs: ins,
                    outputs: outs,
                    actions: Vec::new(),
                    end_comments: Vec::new(),
                }),
                trailing: None,
            });
        }
        let path = format!("{net_name}.pn");
        manifest.files.push(FileRef {
            path: path.clone(),
            span: raw.span,
        });
        manifest.start.push(Name {
            text: net_name.clone(),
            span: raw.span,
        });
        files.push(NetFile {
            path,
            nets: vec![NetDecl {
                allows: Vec::new(),
                params: Vec::new(),
                trivia: Trivia {
                    blank_before: false,
                    comments: origin(&pt.id, &net_name),
                },
                name: Name {
                    text: net_name,
                    span: raw.span,
                },
                items,
                end_comments: Vec::new(),
            }],
            end_comments: Vec::new(),
        });
    }
    manifest.name = raws
        .first()
        .map(|r| sanitize(&r.net.id))
        .unwrap_or_default();
    Project { manifest, files }
}

/// The P/T net's places and transitions by id (the first of an id: a repeated id is E0501).
struct Ids<'r> {
    places: HashMap<&'r str, usize>,
    transitions: HashMap<&'r str, usize>,
}

impl<'r> Ids<'r> {
    fn of(pt: &'r crate::pt::PtNet) -> Self {
        let mut places = HashMap::new();
        for (i, p) in pt.places.iter().enumerate() {
            places.entry(p.id.as_str()).or_insert(i);
        }
        let mut transitions = HashMap::new();
        for (i, t) in pt.transitions.iter().enumerate() {
            transitions.entry(t.id.as_str()).or_insert(i);
        }
        Ids {
            places,
            transitions,
        }
    }
}

/// One node's P/T ids, as the Petrel block gives them: one copy per instance of its net.
struct NodeCopies {
    /// The node's Petrel data, for messages.
    span: Span,
    copies: Vec<Copy>,
}

/// `<copy net="R1" ref="R1.moving"/>` (version 2), or `<item ref="nav.idle"/>` (version 1,
/// which names no instance: each net is its one instance).
struct Copy {
    id: String,
    net: Option<String>,
    span: Span,
}

/// Rebuilds a project from an export's Petrel blocks, reporting every problem (`E0506`,
/// `E0507` for a version this Petrel does not read).
struct Rebuild<'r, 'd> {
    file: FileId,
    diags: &'d mut Diagnostics,
    raw: &'r RawNet,
    /// Error count when the import began: any more means failure.
    before: usize,
}

impl Rebuild<'_, '_> {
    fn bad(&mut self, span: Span, message: impl Into<String>) {
        self.diags.push(
            Diagnostic::error("E0506", span, message)
                .label("Petrel data in question")
                .help(PETREL_DATA_HELP),
        );
    }

    /// E0508: a net file path that would leave the project directory the import writes.
    fn confined(&mut self, path: &str, span: Span) {
        // A missing `path` is reported by `req`, and `project::write` refuses an empty one.
        if path.is_empty() {
            return;
        }
        if let Err(why) = petrel_diag::paths::check_relative(path) {
            self.diags.push(
                Diagnostic::error(
                    "E0508",
                    span,
                    format!(
                        "net file path `{}` is outside the project directory: {why}",
                        path.escape_debug()
                    ),
                )
                .label("this path")
                .help("the imported project's net files go in its directory: paths relative to it, without `..`"),
            );
        }
    }

    fn req<'n>(&mut self, n: &'n Node, key: &str) -> &'n str {
        match n.attr(key) {
            Some(v) => v,
            None => {
                self.bad(
                    n.span,
                    format!("petrel element `<{}>` lacks its `{key}` attribute", n.name),
                );
                ""
            }
        }
    }

    /// A name attribute, which must be a Petrel identifier: a file that passes import must
    /// give a project `petrel fmt` can write and the parser read back.
    fn name(&mut self, n: &Node, key: &str) -> Name {
        let text = self.req(n, key).to_string();
        if n.attr(key).is_some() && !is_identifier(&text) {
            self.bad(
                n.span,
                format!(
                    "petrel attribute `{key}` of `<{}>` is `{text}`, which is not a Petrel name",
                    n.name
                ),
            );
        }
        Name { text, span: n.span }
    }

    /// A place named in an arc: a name, or a child's completion place `CHILD.done`.
    fn place_ref(&mut self, n: &Node, key: &str) -> Name {
        let text = self.req(n, key).to_string();
        let plain = text.strip_suffix(".done").unwrap_or(&text);
        if n.attr(key).is_some() && !is_identifier(plain) {
            self.bad(
                n.span,
                format!(
                    "petrel attribute `{key}` of `<{}>` is `{text}`, which is not a place name",
                    n.name
                ),
            );
        }
        Name { text, span: n.span }
    }

    fn flag(&mut self, n: &Node, key: &str) -> bool {
        match n.attr(key) {
            None | Some("false") => false,
            Some("true") => true,
            Some(other) => {
                self.bad(
                    n.span,
                    format!(
                        "petrel attribute `{key}` of `<{}>` is `{other}`, not `true` or `false`",
                        n.name
                    ),
                );
                false
            }
        }
    }

    fn number<T: std::str::FromStr + Default>(&mut self, n: &Node, key: &str) -> T {
        let v = self.req(n, key).to_string();
        match v.parse() {
            Ok(x) => x,
            Err(_) => {
                if n.attr(key).is_some() {
                    self.bad(
                        n.span,
                        format!(
                            "petrel attribute `{key}` of `<{}>` is `{v}`, not a number",
                            n.name
                        ),
                    );
                }
                T::default()
            }
        }
    }

    fn ty(&mut self, n: &Node) -> Type {
        let v = self.req(n, "type").to_string();
        Type::from_keyword(&v).unwrap_or_else(|| {
            if n.attr("type").is_some() {
                self.bad(n.span, format!("`{v}` is not a Petrel type"));
            }
            Type::Int
        })
    }

    fn trivia(&mut self, n: &Node) -> Trivia {
        Trivia {
            blank_before: self.flag(n, "blank-before"),
            comments: texts(n, "comment"),
        }
    }

    fn params(&mut self, n: &Node) -> Vec<Param> {
        n.children("param")
            .map(|p| Param {
                name: self.name(p, "name"),
                ty: self.ty(p),
            })
            .collect()
    }

    /// `<allow code="W0602" reason="..."/>`: warnings intended for a net or an item.
    fn allows(&mut self, n: &Node) -> Vec<Allow> {
        n.children("allow")
            .map(|a| Allow {
                code: self.name(a, "code"),
                reason: a.attr("reason").map(str::to_string),
            })
            .collect()
    }

    /// Text of the net language carried in a block (an action, a guard, arguments, a
    /// formula), read by the language's own parser. Its diagnostics have offsets into the
    /// text, not the file, so a failure is summarised at the element that holds it.
    fn parsed<T>(
        &mut self,
        at: &Node,
        what: &str,
        text: &str,
        parse: impl FnOnce(FileId, &str, &mut Diagnostics) -> Option<T>,
    ) -> Option<T> {
        let mut inner = Diagnostics::new();
        match parse(self.file, text, &mut inner) {
            Some(v) if !inner.has_errors() => Some(v),
            _ => {
                let why = inner
                    .iter()
                    .next()
                    .map(|d| d.message.clone())
                    .unwrap_or_else(|| format!("it is not {what}"));
                self.bad(
                    at.span,
                    format!("petrel {what} `{text}` does not parse: {why}"),
                );
                None
            }
        }
    }

    /// Arguments written as text in an attribute (`args="&quot;r1&quot;, 0.5"`).
    fn args(&mut self, n: &Node, key: &str) -> Option<Vec<Expr>> {
        let text = n.attr(key)?.to_string();
        let args = self.parsed(n, "argument list", &text, parse_args)?;
        Some(args.into_iter().map(|e| respan_expr(e, n.span)).collect())
    }

    fn manifest(&mut self, n: &Node) -> Manifest {
        let mut m = Manifest {
            name: self.req(n, "name").to_string(),
            description: n.child("description").map(|d| d.text.clone()),
            ..Manifest::default()
        };
        for f in n.children("file") {
            let path = self.req(f, "path").to_string();
            self.confined(&path, f.span);
            m.files.push(FileRef { path, span: f.span });
        }
        for s in n.children("start") {
            m.start.push(self.name(s, "net"));
        }
        for g in n.children("global") {
            // `<scope>` present: the place is visible to the nets listed (maybe none).
            let nets = g
                .child("scope")
                .map(|s| s.children("net").map(|x| self.name(x, "name")).collect());
            m.globals.push(GlobalPlaceDecl {
                nets,
                name: self.name(g, "name"),
                tokens: self.number(g, "tokens"),
            });
        }
        for i in n.children("instance") {
            let name = self.name(i, "name");
            let net = self.name(i, "net");
            if i.attr("args").is_none() {
                self.req(i, "args");
            }
            let args = self.args(i, "args").unwrap_or_default();
            // The manifest holds values only: a name would not survive `petrel.toml`.
            if args
                .iter()
                .any(|a| matches!(a, Expr::Var(_) | Expr::SelfParam(_)))
            {
                self.bad(
                    i.span,
                    format!("the arguments of instance `{name}` are not all values"),
                );
            }
            m.instances.push(InstanceDecl { name, net, args });
        }
        for i in n.children("invariant") {
            let name = self.name(i, "name");
            let text = i.text.clone();
            let formula = self
                .parsed(i, "invariant", &text, |file, t, d| {
                    crate::formula::parse_formula(file, 0, t, "E0506", d)
                })
                .map(|f| respan_formula(f, i.span));
            m.invariants.push(InvariantDecl {
                name,
                text,
                formula,
            });
        }
        for e in n.children("event") {
            let cat = self.req(e, "category").to_string();
            let category = Category::from_keyword(&cat).unwrap_or_else(|| {
                if e.attr("category").is_some() {
                    self.bad(e.span, format!("`{cat}` is not an event category"));
                }
                Category::Nominal
            });
            m.events.push(EventDecl {
                name: self.name(e, "name"),
                category,
                params: self.params(e),
                params_unread: false,
                description: e.child("description").map(|d| d.text.clone()),
                internal: self.flag(e, "internal"),
            });
        }
        for p in n.children("program") {
            let functions = p
                .children("function")
                .map(|f| FunctionDecl {
                    name: self.name(f, "name"),
                    params: self.params(f),
                    params_unread: false,
                    answers: f
                        .children("answer")
                        .map(|a| self.name(a, "event"))
                        .collect(),
                })
                .collect();
            m.programs.push(ProgramDecl {
                name: self.name(p, "name"),
                description: p.child("description").map(|d| d.text.clone()),
                functions,
            });
        }
        for t in n.children("timer") {
            m.timers.push(TimerDecl {
                name: self.name(t, "name"),
                event: self.name(t, "event"),
            });
        }
        for kind in ["final", "goal"] {
            for f in n.children(kind) {
                let places = f
                    .children("place")
                    .map(|p| Name {
                        text: self.req(p, "name").to_string(),
                        span: p.span,
                    })
                    .collect();
                if kind == "final" {
                    m.finals.push(places);
                } else {
                    m.goals.push(places);
                }
            }
        }
        for b in n.children("bound") {
            let name = self.name(b, "name");
            let mut end = |key: &str| {
                let text = self.req(b, key).to_string();
                let end = self.parsed(b, "bound end", &text, |file, t, d| {
                    Some(crate::manifest::bound_end(file, 0, t, d))
                });
                match end {
                    Some(BoundEnd::Event(n)) => BoundEnd::Event(Name {
                        text: n.text,
                        span: b.span,
                    }),
                    Some(BoundEnd::Marking { text, formula }) => BoundEnd::Marking {
                        text,
                        formula: formula.map(|f| respan_formula(f, b.span)),
                    },
                    None => BoundEnd::Marking {
                        text,
                        formula: None,
                    },
                }
            };
            let (from, to) = (end("from"), end("to"));
            let within = b.attr("within").map(|w| Name {
                text: w.to_string(),
                span: b.span,
            });
            m.bounds.push(BoundDecl {
                name,
                from,
                to,
                within,
            });
        }
        // Absent: the default (catastrophic); present and empty: every category counts.
        m.progress_excludes = n.child("progress-excludes").map(|x| {
            x.children("category")
                .map(|c| Name {
                    text: self.req(c, "name").to_string(),
                    span: c.span,
                })
                .collect()
        });
        m
    }

    /// The data node (`<place>` or `<transition>`) of an element's version-1 Petrel block.
    fn element_data<'n>(
        &mut self,
        block: Option<&'n Node>,
        kind: &str,
        id: &str,
        span: Span,
    ) -> Option<&'n Node> {
        let found = block.and_then(|b| b.child(kind));
        if found.is_none() {
            self.bad(
                span,
                format!("{kind} `{id}` has no petrel data, though the net's petrel block lists it"),
            );
        }
        found
    }

    fn place(&mut self, n: &Node) -> Item {
        let tokens = self.number(n, "tokens");
        let tokens_span = self.flag(n, "marking-written").then_some(n.span);
        Item {
            allows: self.allows(n),
            trivia: self.trivia(n),
            kind: ItemKind::Place(PlaceDecl {
                name: self.name(n, "name"),
                tokens,
                tokens_span,
            }),
            trailing: n.child("trailing").map(|t| t.text.clone()),
        }
    }

    fn transition(&mut self, n: &Node) -> Item {
        let trigger = n.child("trigger").map(|tr| Trigger {
            event: self.name(tr, "event"),
            bindings: tr
                .children("binding")
                .map(|b| Binding {
                    name: self.name(b, "name"),
                    ty: b.attr("type").is_some().then(|| (self.ty(b), b.span)),
                })
                .collect(),
        });
        let guard = n.child("guard").and_then(|g| {
            let text = g.text.clone();
            self.parsed(g, "guard", &text, parse_guard)
                .map(|guard| respan_guard(guard, g.span))
        });
        let inputs = n
            .children("input")
            .map(|i| self.place_ref(i, "place"))
            .collect();
        let empty = n
            .children("empty")
            .map(|i| self.place_ref(i, "place"))
            .collect();
        let outputs = n
            .children("output")
            .map(|o| self.place_ref(o, "place"))
            .collect();
        let actions = n
            .children("action")
            .filter_map(|a| self.action(a))
            .collect();
        Item {
            allows: self.allows(n),
            trivia: self.trivia(n),
            kind: ItemKind::Transition(TransitionDecl {
                guard,
                empty,
                name: self.name(n, "name"),
                trigger,
                inputs,
                outputs,
                actions,
                end_comments: texts(n, "end-comment"),
            }),
            trailing: n.child("trailing").map(|t| t.text.clone()),
        }
    }

    /// A `children` line, and the P/T copies of each child's completion place.
    fn children_line(&mut self, n: &Node) -> (Item, Vec<NodeCopies>) {
        let mut list = Vec::new();
        let mut copies = Vec::new();
        for c in n.children("child") {
            // No `args` attribute: written without parentheses.
            let args = c
                .attr("args")
                .map(|_| self.args(c, "args").unwrap_or_default());
            list.push(ChildDecl {
                net: self.name(c, "net"),
                args,
            });
            copies.push(self.copies(c));
        }
        if list.is_empty() {
            self.bad(n.span, "a petrel `<children>` line names no child");
        }
        let item = Item {
            allows: self.allows(n),
            trivia: self.trivia(n),
            kind: ItemKind::Children(list),
            trailing: n.child("trailing").map(|t| t.text.clone()),
        };
        (item, copies)
    }

    /// The `<copy>`s of a version-2 node.
    fn copies(&mut self, n: &Node) -> NodeCopies {
        let copies = n
            .children("copy")
            .map(|c| Copy {
                id: self.req(c, "ref").to_string(),
                net: Some(self.req(c, "net").to_string()),
                span: c.span,
            })
            .collect();
        NodeCopies {
            span: n.span,
            copies,
        }
    }

    fn action(&mut self, n: &Node) -> Option<ActionItem> {
        let Some(code) = n.child("code") else {
            self.bad(n.span, "petrel `<action>` lacks its `<code>`");
            return None;
        };
        let action = self.parsed(code, "action", &code.text, parse_action)?;
        Some(ActionItem {
            trivia: self.trivia(n),
            action: respan_action(action, code.span),
            trailing: n.child("trailing").map(|t| t.text.clone()),
        })
    }

    /// The items of a version-1 net: `<item ref>` in written order, each P/T element holding
    /// its own Petrel data.
    fn items_v1(
        &mut self,
        n: &Node,
        ids: &Ids,
        items: &mut Vec<Item>,
        nodes: &mut Vec<NodeCopies>,
    ) {
        let raw = self.raw;
        let pt = &raw.net;
        for item in n.children("item") {
            let id = self.req(item, "ref").to_string();
            let copy = NodeCopies {
                span: item.span,
                copies: vec![Copy {
                    id: id.clone(),
                    net: None,
                    span: item.span,
                }],
            };
            if let Some(&i) = ids.places.get(id.as_str()) {
                let data = raw.place_petrel.get(i).and_then(Option::as_ref);
                let span = pt.places.get(i).map(|p| p.span).unwrap_or(item.span);
                if let Some(d) = self.element_data(data, "place", &id, span) {
                    items.push(self.place(d));
                    nodes.push(copy);
                }
            } else if let Some(&i) = ids.transitions.get(id.as_str()) {
                let data = raw.transition_petrel.get(i).and_then(Option::as_ref);
                let span = pt.transitions.get(i).map(|t| t.span).unwrap_or(item.span);
                if let Some(d) = self.element_data(data, "transition", &id, span) {
                    items.push(self.transition(d));
                    nodes.push(copy);
                }
            } else {
                self.bad(
                    item.span,
                    format!("item `{id}` is no place or transition of the P/T net"),
                );
            }
        }
    }

    /// The items of a version-2 net, inline in written order, each with its P/T copies.
    fn items_v2(&mut self, n: &Node, items: &mut Vec<Item>, nodes: &mut Vec<NodeCopies>) {
        for c in &n.children {
            match c.name.as_str() {
                "place" => {
                    items.push(self.place(c));
                    nodes.push(self.copies(c));
                }
                "transition" => {
                    items.push(self.transition(c));
                    nodes.push(self.copies(c));
                }
                "children" => {
                    let (item, copies) = self.children_line(c);
                    items.push(item);
                    nodes.extend(copies);
                }
                // The net's own data (`param`, `allow`, `comment`...) is read apart.
                _ => {}
            }
        }
    }

    fn project(mut self) -> Option<Project> {
        let raw = self.raw;
        let pt = &raw.net;
        let block = raw.petrel.as_ref()?;
        let v1 = match block.attr("version") {
            Some("1") => true,
            Some(v) if v == PETREL_VERSION => false,
            other => {
                self.diags.push(
                    Diagnostic::error(
                        "E0507",
                        block.span,
                        format!(
                            "this Petrel export is of version `{}`; this Petrel reads versions 1 and {PETREL_VERSION}",
                            other.unwrap_or("")
                        ),
                    )
                    .label("unknown version of the Petrel data")
                    .help("import it with the Petrel that exported it, or export the project again with this one"),
                );
                return None;
            }
        };
        let Some(mnode) = block.child("manifest") else {
            self.bad(block.span, "the petrel block has no `<manifest>`");
            return None;
        };
        let manifest = self.manifest(mnode);
        let ids = Ids::of(pt);

        let mut files = Vec::new();
        // Per net in project order, per node: its P/T copies.
        let mut net_copies: Vec<Vec<NodeCopies>> = Vec::new();
        for f in block.children("netfile") {
            let mut nets = Vec::new();
            for n in f.children("net") {
                let mut items = Vec::new();
                let mut nodes = Vec::new();
                if v1 {
                    self.items_v1(n, &ids, &mut items, &mut nodes);
                } else {
                    self.items_v2(n, &mut items, &mut nodes);
                }
                net_copies.push(nodes);
                nets.push(NetDecl {
                    allows: self.allows(n),
                    params: self.params(n),
                    trivia: self.trivia(n),
                    name: self.name(n, "name"),
                    items,
                    end_comments: texts(n, "end-comment"),
                });
            }
            let path = self.req(f, "path").to_string();
            self.confined(&path, f.span);
            files.push(NetFile {
                path,
                nets,
                end_comments: texts(f, "end-comment"),
            });
        }
        if self.diags.error_count() > self.before {
            return None;
        }
        let project = Project { manifest, files };
        let expanded = instances(&project);
        if expanded.truncated {
            self.bad(
                block.span,
                format!("the nets of this project expand into more than {MAX_INSTANCES} instances"),
            );
            return None;
        }

        // Every P/T element must be claimed by exactly one node of one instance.
        let mut place_used = vec![false; pt.places.len()];
        let mut transition_used = vec![false; pt.transitions.len()];
        let mut claim = |this: &mut Self, id: &str, place: bool, span: Span| {
            let (index, used, kind) = if place {
                (ids.places.get(id), &mut place_used, "place")
            } else {
                (ids.transitions.get(id), &mut transition_used, "transition")
            };
            match index.copied() {
                Some(i) if !used[i] => used[i] = true,
                Some(_) => this.bad(span, format!("{kind} `{id}` is claimed twice")),
                None => this.bad(
                    span,
                    format!(
                        "{kind} `{id}` named in the petrel data is not a {kind} of the P/T net"
                    ),
                ),
            }
        };
        let mut layout = Layout::default();
        for g in mnode.children("global") {
            let id = self.req(g, "ref").to_string();
            claim(&mut self, &id, true, g.span);
            layout.globals.push(id);
        }
        let by_net = expanded.names_by_net(net_copies.len());
        for ((net, copies), names) in project.nets().zip(&net_copies).zip(&by_net) {
            let mut net_ids = Vec::new();
            for (node, nc) in nodes(net).iter().zip(copies) {
                if nc.copies.len() != names.len() {
                    self.bad(
                        nc.span,
                        format!(
                            "`{}` of net `{}` has {} P/T copies, but the project runs {} instance(s) of the net",
                            node.name(),
                            net.name,
                            nc.copies.len(),
                            names.len()
                        ),
                    );
                }
                for (c, name) in nc.copies.iter().zip(names) {
                    if let Some(named) = c.net.as_deref().filter(|n| n != name) {
                        self.bad(
                            c.span,
                            format!("this copy is said to be instance `{named}`'s, but the instance in its place is `{name}`"),
                        );
                    }
                    claim(&mut self, &c.id, node.is_place(), c.span);
                }
                net_ids.push(nc.copies.iter().map(|c| c.id.clone()).collect());
            }
            layout.nets.push(net_ids);
        }
        for (p, used) in pt.places.iter().zip(&place_used) {
            if !used {
                self.bad(
                    p.span,
                    format!(
                        "place `{}` is not in the Petrel data: the P/T net was changed",
                        p.id
                    ),
                );
            }
        }
        for (t, used) in pt.transitions.iter().zip(&transition_used) {
            if !used {
                self.bad(
                    t.span,
                    format!(
                        "transition `{}` is not in the Petrel data: the P/T net was changed",
                        t.id
                    ),
                );
            }
        }
        if self.diags.error_count() > self.before {
            return None;
        }
        self.check_structure(&project, &expanded, &layout, &ids);
        (self.diags.error_count() == self.before).then_some(project)
    }

    /// Compares the P/T net with the skeleton the rebuilt project implies.
    fn check_structure(
        &mut self,
        project: &Project,
        expanded: &Instances,
        layout: &Layout,
        ids: &Ids,
    ) {
        let raw = self.raw;
        let pt = &raw.net;
        let expected = structure(project, expanded, layout);
        for (id, tokens) in &expected.marking {
            if let Some(p) = ids.places.get(id.as_str()).and_then(|&i| pt.places.get(i)) {
                if p.initial != *tokens {
                    self.bad(
                        p.span,
                        format!(
                            "place `{id}` starts with {} tokens in the P/T net, but the Petrel data gives {tokens}",
                            p.initial
                        ),
                    );
                }
            }
        }
        let mut actual: Vec<((String, String, bool), u64, Span)> = Vec::new();
        let mut index: HashMap<(String, String, bool), usize> = HashMap::new();
        for a in &pt.arcs {
            let (Some(p), Some(t)) = (
                a.place().and_then(|i| pt.places.get(i)),
                a.transition().and_then(|i| pt.transitions.get(i)),
            ) else {
                continue;
            };
            let key = (p.id.clone(), t.id.clone(), a.is_input());
            match index.get(&key) {
                Some(&i) => actual[i].1 = actual[i].1.saturating_add(a.weight),
                None => {
                    index.insert(key.clone(), actual.len());
                    actual.push((key, a.weight, a.span));
                }
            }
        }
        let wanted: HashMap<&(String, String, bool), u64> =
            expected.arcs.iter().map(|(k, w)| (k, *w)).collect();
        let describe = |(p, t, input): &(String, String, bool)| {
            if *input {
                format!("from `{p}` to `{t}`")
            } else {
                format!("from `{t}` to `{p}`")
            }
        };
        for (key, weight, span) in &actual {
            match wanted.get(key) {
                Some(w) if w == weight => {}
                Some(w) => self.bad(
                    *span,
                    format!(
                        "the arc {} weighs {weight} in the P/T net, but the Petrel data gives {w}",
                        describe(key)
                    ),
                ),
                None => self.bad(
                    *span,
                    format!(
                        "the arc {} is not in the Petrel data: the P/T net was changed",
                        describe(key)
                    ),
                ),
            }
        }
        for (key, _) in &expected.arcs {
            if !index.contains_key(key) {
                let span = ids
                    .transitions
                    .get(key.1.as_str())
                    .and_then(|&i| pt.transitions.get(i))
                    .map(|t| t.span)
                    .unwrap_or(raw.span);
                self.bad(
                    span,
                    format!(
                        "the P/T net lacks the arc {} that the transition's Petrel inputs, outputs and `finish` imply",
                        describe(key)
                    ),
                );
            }
        }
    }
}

/// The exact texts of the children named `name`.
fn texts(n: &Node, name: &str) -> Vec<String> {
    n.children(name).map(|c| c.text.clone()).collect()
}

/// Points every span of an action parsed from a Petrel block at the block's `<code>` element:
/// the parser's offsets are into the action text, which is not the file.
fn respan_action(a: Action, span: Span) -> Action {
    let name = |n: Name| Name { text: n.text, span };
    match a {
        Action::Activate { net, args, .. } => Action::Activate {
            net: name(net),
            args: args.into_iter().map(|e| respan_expr(e, span)).collect(),
            span,
        },
        Action::Deactivate(n) => Action::Deactivate(name(n)),
        Action::Finish(_) => Action::Finish(span),
        Action::CancelTimer(n) => Action::CancelTimer(name(n)),
        Action::StartTimer { timer, after } => Action::StartTimer {
            timer: name(timer),
            after: match after {
                DurationExpr::Literal { value, unit, .. } => {
                    DurationExpr::Literal { value, unit, span }
                }
                DurationExpr::Seconds(n) => DurationExpr::Seconds(name(n)),
                DurationExpr::SelfSeconds(n) => DurationExpr::SelfSeconds(name(n)),
            },
        },
        Action::Call {
            program,
            function,
            args,
            ..
        } => Action::Call {
            program: name(program),
            function: name(function),
            args: args.into_iter().map(|e| respan_expr(e, span)).collect(),
            span,
        },
        Action::Emit {
            event, args, to, ..
        } => Action::Emit {
            event: name(event),
            args: args.into_iter().map(|e| respan_expr(e, span)).collect(),
            to: to.map(name),
            span,
        },
    }
}

fn respan_expr(e: Expr, span: Span) -> Expr {
    match e {
        Expr::Int(v, _) => Expr::Int(v, span),
        Expr::Float(v, _) => Expr::Float(v, span),
        Expr::Bool(v, _) => Expr::Bool(v, span),
        Expr::Text(v, _) => Expr::Text(v, span),
        // Lists nest only as deep as the action text, which the parser already read.
        Expr::List(items, _) => Expr::List(
            items.into_iter().map(|i| respan_expr(i, span)).collect(),
            span,
        ),
        Expr::Var(n) => Expr::Var(Name { text: n.text, span }),
        Expr::SelfParam(n) => Expr::SelfParam(Name { text: n.text, span }),
    }
}

/// Points every span of a guard read from a Petrel block at its `<guard>` element.
fn respan_guard(g: Guard, span: Span) -> Guard {
    match g {
        Guard::Or(a, b) => Guard::Or(
            Box::new(respan_guard(*a, span)),
            Box::new(respan_guard(*b, span)),
        ),
        Guard::And(a, b) => Guard::And(
            Box::new(respan_guard(*a, span)),
            Box::new(respan_guard(*b, span)),
        ),
        Guard::Not(a) => Guard::Not(Box::new(respan_guard(*a, span))),
        Guard::Compare(op, a, b) => Guard::Compare(op, respan_expr(a, span), respan_expr(b, span)),
        Guard::Value(e) => Guard::Value(respan_expr(e, span)),
    }
}

/// Points every span of an invariant read from a Petrel block at its `<invariant>` element.
fn respan_formula(f: Formula, span: Span) -> Formula {
    let name = |n: Name| Name { text: n.text, span };
    let sub = |f: Box<Formula>| Box::new(respan_formula(*f, span));
    match f {
        Formula::Marked(n) => Formula::Marked(name(n)),
        Formula::Active(n) => Formula::Active(name(n)),
        Formula::Const(b, _) => Formula::Const(b, span),
        Formula::Not(a) => Formula::Not(sub(a)),
        Formula::And(a, b) => Formula::And(sub(a), sub(b)),
        Formula::Or(a, b) => Formula::Or(sub(a), sub(b)),
        Formula::Implies(a, b) => Formula::Implies(sub(a), sub(b)),
    }
}
