//! Name resolution and type checking: from the written [`Project`] to a
//! [`CompiledProject`](crate::compiled::CompiledProject).
//!
//! Every problem is reported (the checker never stops at the first), each with the place it was
//! written and what to do. A compiled project is returned only when there is no error, so the
//! verifier and the player never see a project that does not check.
//!
//! It goes in four passes:
//!
//! 1. the manifest's names (globals, events, programs, timers) and the nets' declarations;
//! 2. the **roots**: the nets nobody declares as a child, each one net, or the instances the
//!    manifest makes of it;
//! 3. each net's **body, checked once** (a template's too), into a `Template` whose references
//!    to other nets are left symbolic (`NetRef`), so that an error in a template is reported
//!    once however many instances it has;
//! 4. the **instances**, expanded from the roots down the `children` lines in pre-order (the
//!    project order), each a [`c::Net`] with its references resolved and its fixed parameters
//!    folded into literals; then `start`, final markings, invariants and scoped globals.

use crate::compiled as c;
use crate::model::*;
use petrel_diag::names::{suggest, Candidates};
use petrel_diag::report::{Diagnostic, Diagnostics};
use petrel_diag::source::Span;
use std::collections::{HashMap, HashSet};

/// Checks a project; returns the compiled project when no error was found, and every finding.
pub fn check(project: &Project) -> (Option<c::CompiledProject>, Diagnostics) {
    let mut ck = Checker {
        p: project,
        d: Diagnostics::new(),
        decls: project.nets().collect(),
        decl_ids: HashMap::new(),
        globals: HashMap::new(),
        events: HashMap::new(),
        programs: HashMap::new(),
        timers: HashMap::new(),
        parents_of: Vec::new(),
        roots: Vec::new(),
        root_ids: HashMap::new(),
        reported: HashSet::new(),
    };
    let compiled = ck.run();
    let mut d = ck.d;
    crate::meant_event::immediate_transitions_meant_events(project, &mut d);
    let mut d = crate::follow_on::link_to_missing_files(project, d);
    apply_allows(project, &mut d, AllowPass::Check);
    d.sort();
    let compiled = if d.has_errors() { None } else { compiled };
    (compiled, d)
}

/// The values of an instance's leading parameters, fixed when it was made (manifest
/// `[instances]`, or `children X(args)`); its other parameters are bound at each activation.
type Fixed = Vec<c::Value>;

/// A net that nobody declares as a child: a net of the project, or a manifest instance.
struct Root {
    name: String,
    decl: usize,
    /// How many leading parameters the instance fixes.
    fixed: usize,
    /// The manifest instance, for its arguments.
    instance: Option<usize>,
}

/// A net named in a net's body: itself, one of its children, or a root.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum NetRef {
    SelfNet,
    Child(usize),
    Root(usize),
}

/// A child of a net's `children` line.
struct ChildInfo<'p> {
    decl: usize,
    /// The child's name in the `children` line.
    span: Span,
    args: Option<&'p [Expr]>,
    /// How many leading parameters the `children` line fixes.
    fixed: usize,
}

/// A call whose program a net parameter names (`call self.moves.forward()`), resolved per
/// instance: in the template's compiled call, `program` is [`PROGRAM_PARAM`] plus the
/// parameter's index and `function` the index of this record.
struct PendingCall {
    function: Name,
    /// The arguments' types as written (an int literal may still become a float).
    types: Vec<Type>,
    span: Span,
}

/// Marks, in a template, a call whose program is a parameter (see [`PendingCall`]).
const PROGRAM_PARAM: u32 = u32::MAX / 2;

/// A net's body, checked once: places, transitions whose net references are indices into
/// `refs` (to be resolved per instance), parameters as [`c::Arg::NetParam`].
struct Template<'p> {
    places: Vec<c::Place>,
    transitions: Vec<c::Transition>,
    refs: Vec<NetRef>,
    children: Vec<ChildInfo<'p>>,
    /// Global places the body names, with where (for scoped globals).
    globals_used: Vec<(u32, Span)>,
    /// `finish` appears in the body, at this place.
    finishes: Option<Span>,
    /// Calls whose program a parameter names.
    pending_calls: Vec<PendingCall>,
}

/// One instance, in project order.
struct Inst {
    name: String,
    decl: usize,
    fixed: Fixed,
    parent: Option<(usize, u32)>,
    children: Vec<usize>,
}

struct Checker<'p> {
    p: &'p Project,
    d: Diagnostics,
    decls: Vec<&'p NetDecl>,
    decl_ids: HashMap<&'p str, usize>,
    globals: HashMap<&'p str, u32>,
    events: HashMap<&'p str, u32>,
    programs: HashMap<&'p str, u32>,
    timers: HashMap<&'p str, u32>,
    /// For each declaration, the declarations whose `children` line names it.
    parents_of: Vec<Vec<usize>>,
    roots: Vec<Root>,
    root_ids: HashMap<String, usize>,
    /// Errors found while expanding instances, reported once per place.
    reported: HashSet<(u32, u32, &'static str)>,
}

/// Registers names of one kind, reporting duplicates against the first declaration.
fn unique<'p>(
    d: &mut Diagnostics,
    what: &str,
    scope: &str,
    names: impl Iterator<Item = &'p Name>,
) -> HashMap<&'p str, u32> {
    let mut map: HashMap<&str, u32> = HashMap::new();
    let mut spans: HashMap<&str, Span> = HashMap::new();
    for (i, n) in names.enumerate() {
        if let Some(first) = spans.get(n.as_str()) {
            d.push(
                Diagnostic::error(
                    "E0301",
                    n.span,
                    format!("{what} `{n}` is declared twice{scope}"),
                )
                .label("second declaration")
                .related(*first, "first declared here")
                .help("give one of them another name, or remove one"),
            );
        } else {
            map.insert(n.as_str(), i as u32);
            spans.insert(n.as_str(), n.span);
        }
    }
    map
}

/// The scope of a transition's expressions: its net's parameters, and the names its event binds.
struct Scope<'a> {
    net: &'a NetDecl,
    transition: &'a TransitionDecl,
    bound: &'a HashMap<&'a str, (u32, Type)>,
}

impl<'p> Checker<'p> {
    fn run(&mut self) -> Option<c::CompiledProject> {
        let m = &self.p.manifest;
        let d = &mut self.d;
        let decl_names = unique(
            d,
            "net",
            " in the project",
            self.decls.iter().map(|n| &n.name),
        );
        self.decl_ids = decl_names
            .into_iter()
            .map(|(k, v)| (k, v as usize))
            .collect();
        self.globals = unique(d, "global place", "", m.globals.iter().map(|g| &g.name));
        self.events = unique(d, "event", "", m.events.iter().map(|e| &e.name));
        for (k, b) in builtin_events().iter().enumerate() {
            if let Some(e) = m.events.iter().find(|e| e.name.text == b.name.text) {
                d.push(
                    Diagnostic::error(
                        "E0106",
                        e.name.span,
                        format!("`{}` is a built-in event: it cannot be declared", b.name),
                    )
                    .label("reserved name")
                    .help(format!(
                        "every project has `{}`; use it without declaring it, or give your event another name",
                        crate::fmt::format_trigger(&Trigger {
                            event: b.name.clone(),
                            bindings: b
                                .params
                                .iter()
                                .map(|p| crate::model::Binding {
                                    name: p.name.clone(),
                                    ty: Some((p.ty, Span::default())),
                                })
                                .collect(),
                        })
                    )),
                );
            }
            self.events
                .insert(b.name.as_str(), (m.events.len() + k) as u32);
        }
        self.programs = unique(d, "program", "", m.programs.iter().map(|p| &p.name));
        for p in &m.programs {
            if !petrel_value::is_program_name(&p.name.text) {
                d.push(
                    Diagnostic::error(
                        "E0107",
                        p.name.span,
                        format!("program `{}` cannot name a program of the vehicle", p.name),
                    )
                    .label(format!(
                        "more than {} characters, or a character other than letters, digits, `_` and `-`",
                        petrel_value::MAX_PROGRAM_NAME_LEN
                    ))
                    .help("a program's name names its process on the vehicle's services: keep it short"),
                );
            }
        }
        self.timers = unique(d, "timer", "", m.timers.iter().map(|t| &t.name));
        for e in &m.events {
            let scope = format!(" in event `{}`", e.name);
            unique(d, "parameter", &scope, e.params.iter().map(|p| &p.name));
        }
        for p in &m.programs {
            let scope = format!(" in program `{}`", p.name);
            unique(d, "function", &scope, p.functions.iter().map(|f| &f.name));
            for f in &p.functions {
                let scope = format!(" in function `{}.{}`", p.name, f.name);
                unique(d, "parameter", &scope, f.params.iter().map(|p| &p.name));
            }
        }
        for n in &self.decls {
            let scope = format!(" in net `{}`", n.name);
            unique(d, "parameter", &scope, n.params.iter().map(|p| &p.name));
        }
        let timers = self.timers_compiled();
        self.hierarchy();
        self.cycles();
        self.find_roots();

        // Each body once.
        let templates: Vec<Template> = (0..self.decls.len()).map(|i| self.template(i)).collect();

        // Instances, from the roots down.
        let mut insts: Vec<Inst> = Vec::new();
        let mut root_inst: Vec<usize> = Vec::new();
        let mut name_bytes = 0;
        for r in 0..self.roots.len() {
            let binding = self.root_binding(r);
            root_inst.push(insts.len());
            // Past the limits nothing is compiled: what follows would work on a partial list.
            self.expand(&templates, &mut insts, r, binding, &mut name_bytes)
                .ok()?;
        }
        let nets: Vec<c::Net> = insts
            .iter()
            .enumerate()
            .map(|(i, inst)| self.instantiate(&templates, &root_inst, i, inst))
            .collect();

        let globals = self.globals_compiled(&templates, &insts);
        let events = m
            .events
            .iter()
            .chain(builtin_events())
            .map(|e| c::Event {
                name: e.name.text.clone(),
                category: e.category,
                params: e
                    .params
                    .iter()
                    .map(|p| (p.name.text.clone(), p.ty))
                    .collect(),
                internal: e.internal,
            })
            .collect();
        let programs = m
            .programs
            .iter()
            .map(|p| c::Program {
                name: p.name.text.clone(),
                functions: p
                    .functions
                    .iter()
                    .map(|f| c::Function {
                        name: f.name.text.clone(),
                        params: f
                            .params
                            .iter()
                            .map(|p| (p.name.text.clone(), p.ty))
                            .collect(),
                        answers: f
                            .answers
                            .iter()
                            .filter_map(|a| self.answer(p, f, a))
                            .collect(),
                    })
                    .collect(),
            })
            .collect();
        let mut project = c::CompiledProject {
            name: m.name.clone(),
            nets,
            globals,
            events,
            programs,
            timers,
            start: Vec::new(),
            finals: Vec::new(),
            invariants: Vec::new(),
            goals: Vec::new(),
            progress_excludes: self.progress_excludes(),
            bounds: Vec::new(),
        };
        project.start = self.start(&project, &root_inst);
        project.goals = m
            .goals
            .iter()
            .map(|f| self.final_marking(&project, f))
            .collect();
        project.finals = m
            .finals
            .iter()
            .map(|f| self.final_marking(&project, f))
            .collect();
        project.invariants = self.invariants(&project);
        project.bounds = self.bounds(&project);
        Some(project)
    }

    /// An event a function declares it answers with: declared, and not `internal` (nets emit
    /// those, programs do not).
    fn answer(&mut self, p: &ProgramDecl, f: &FunctionDecl, a: &Name) -> Option<u32> {
        let Some(&e) = self.events.get(a.as_str()) else {
            self.unknown("E0203", "event", a, self.events.keys().copied().collect());
            return None;
        };
        if self.event_decl(e).internal {
            self.d.push(
                Diagnostic::error(
                    "E0419",
                    a.span,
                    format!(
                        "`{}.{}` answers with `{a}`, which is internal: only nets emit it",
                        p.name, f.name
                    ),
                )
                .label("an internal event")
                .help("remove `internal = true` from the event, or the event from the answers"),
            );
            return None;
        }
        Some(e)
    }

    /// The categories the progress check leaves out (default: catastrophic).
    fn progress_excludes(&mut self) -> Vec<Category> {
        let Some(list) = &self.p.manifest.progress_excludes else {
            return vec![Category::Catastrophic];
        };
        let mut out = Vec::new();
        for n in list {
            match Category::from_keyword(&n.text) {
                Some(c) => out.push(c),
                None => self.d.push(
                    Diagnostic::error("E0102", n.span, format!("unknown event category `{n}`"))
                        .label("not a category")
                        .help("the categories are catastrophic, safety, mission, communication and nominal"),
                ),
            }
        }
        out
    }

    fn timers_compiled(&mut self) -> Vec<c::Timer> {
        let mut timers = Vec::new();
        for t in &self.p.manifest.timers {
            let event = match self.events.get(t.event.as_str()) {
                Some(&e) => {
                    let decl = self.event_decl(e);
                    if !decl.params.is_empty() {
                        self.d.push(
                            Diagnostic::error(
                                "E0407",
                                t.event.span,
                                format!(
                                    "timer `{}` emits event `{}`, which takes {} parameter(s)",
                                    t.name,
                                    t.event,
                                    decl.params.len()
                                ),
                            )
                            .label("a timer's event carries no parameters")
                            .help("declare a parameterless event for the timer's expiry"),
                        );
                    }
                    e
                }
                None => {
                    self.unknown(
                        "E0203",
                        "event",
                        &t.event,
                        self.events.keys().copied().collect(),
                    );
                    0
                }
            };
            timers.push(c::Timer {
                name: t.name.text.clone(),
                event,
            });
        }
        timers
    }

    /// Who declares whom as a child; unknown children reported.
    fn hierarchy(&mut self) {
        self.parents_of = vec![Vec::new(); self.decls.len()];
        for (i, n) in self.decls.clone().into_iter().enumerate() {
            let scope = format!(" in the children of net `{}`", n.name);
            unique(&mut self.d, "child", &scope, n.children().map(|c| &c.net));
            for ch in n.children() {
                match self.decl_ids.get(ch.net.as_str()) {
                    Some(&k) if !self.parents_of[k].contains(&i) => self.parents_of[k].push(i),
                    Some(_) => {}
                    None => self.unknown(
                        "E0202",
                        "net",
                        &ch.net,
                        self.decl_ids.keys().copied().collect(),
                    ),
                }
            }
        }
    }

    /// Reports the `children` lines that lead from a net back to itself (such nets would have
    /// no root to be instantiated from).
    fn cycles(&mut self) {
        let n = self.decls.len();
        let children: Vec<Vec<usize>> = self
            .decls
            .iter()
            .map(|d| {
                d.children()
                    .filter_map(|c| self.decl_ids.get(c.net.as_str()).copied())
                    .collect()
            })
            .collect();
        // 0 unseen, 1 on the path, 2 done.
        let mut state = vec![0u8; n];
        for root in 0..n {
            if state[root] != 0 {
                continue;
            }
            let mut stack: Vec<(usize, usize)> = vec![(root, 0)];
            state[root] = 1;
            while let Some(&mut (v, ref mut k)) = stack.last_mut() {
                if let Some(&w) = children[v].get(*k) {
                    *k += 1;
                    match state[w] {
                        0 => {
                            state[w] = 1;
                            stack.push((w, 0));
                        }
                        1 => {
                            let path: Vec<String> = stack
                                .iter()
                                .skip_while(|(x, _)| *x != w)
                                .map(|(x, _)| self.decls[*x].name.text.clone())
                                .collect();
                            let name = &self.decls[w].name;
                            self.d.push(
                                Diagnostic::error(
                                    "E0304",
                                    name.span,
                                    format!("the children of net `{name}` lead back to it: {} -> {name}", path.join(" -> ")),
                                )
                                .label("a net is its own descendant")
                                .help("the `children` lines must form a tree: remove one of the lines that closes the cycle"),
                            );
                        }
                        _ => {}
                    }
                } else {
                    state[v] = 2;
                    stack.pop();
                }
            }
        }
    }

    /// The nets nobody declares as a child, and the manifest's instances.
    fn find_roots(&mut self) {
        let m = &self.p.manifest;
        let mut instanced: HashMap<usize, Vec<usize>> = HashMap::new();
        let mut seen: HashMap<&str, Span> = self
            .decls
            .iter()
            .map(|n| (n.name.as_str(), n.name.span))
            .collect();
        for (k, inst) in m.instances.iter().enumerate() {
            if let Some(first) = seen.get(inst.name.as_str()) {
                self.d.push(
                    Diagnostic::error(
                        "E0301",
                        inst.name.span,
                        format!("net `{}` is declared twice in the project", inst.name),
                    )
                    .label("an instance with the name of a net or of another instance")
                    .related(*first, "first declared here")
                    .help("give the instance another name"),
                );
                continue;
            }
            seen.insert(inst.name.as_str(), inst.name.span);
            match self.decl_ids.get(inst.net.as_str()) {
                None => self.unknown(
                    "E0202",
                    "net",
                    &inst.net,
                    self.decl_ids.keys().copied().collect(),
                ),
                Some(&decl) if !self.parents_of[decl].is_empty() => {
                    let parent = &self.decls[self.parents_of[decl][0]].name;
                    self.d.push(
                        Diagnostic::error(
                            "E0303",
                            inst.net.span,
                            format!("net `{}` is a child of `{parent}`: it cannot also be instantiated in the manifest", inst.net),
                        )
                        .label("a child net")
                        .related(self.decls[decl].name.span, "declared here")
                        .help(format!("each parent makes its own instance of its children; remove `{}` from `children`, or this instance", inst.net)),
                    );
                }
                Some(&decl) => instanced.entry(decl).or_default().push(k),
            }
        }
        for (i, n) in self.decls.clone().into_iter().enumerate() {
            if !self.parents_of[i].is_empty() {
                continue;
            }
            match instanced.get(&i) {
                Some(list) => {
                    for &k in list {
                        let inst = &m.instances[k];
                        self.root_ids
                            .insert(inst.name.text.clone(), self.roots.len());
                        self.roots.push(Root {
                            name: inst.name.text.clone(),
                            decl: i,
                            fixed: inst.args.len().min(n.params.len()),
                            instance: Some(k),
                        });
                    }
                }
                None => {
                    self.root_ids.insert(n.name.text.clone(), self.roots.len());
                    self.roots.push(Root {
                        name: n.name.text.clone(),
                        decl: i,
                        fixed: 0,
                        instance: None,
                    });
                }
            }
        }
    }

    /// The fixed parameters of a root: an instance's arguments checked against its template.
    fn root_binding(&mut self, r: usize) -> Fixed {
        let (decl, instance) = (self.roots[r].decl, self.roots[r].instance);
        let net = self.decls[decl];
        match instance {
            Some(k) => {
                let inst = &self.p.manifest.instances[k];
                let what = format!("net `{}`", net.name);
                let values = self.constant_args(&what, &net.params, &inst.args, inst.name.span);
                // After an error the values are unknown: the instance fixes nothing.
                values.unwrap_or_default()
            }
            None => Vec::new(),
        }
    }

    /// Literal arguments (an instance's) checked against the leading parameters: an instance
    /// fixes as many as it gives, the others are bound at activation.
    fn constant_args(
        &mut self,
        what: &str,
        params: &[Param],
        args: &[Expr],
        span: Span,
    ) -> Option<Vec<c::Value>> {
        if args.len() > params.len() {
            self.arity(what, params, args.len(), span);
            return None;
        }
        let mut out = Vec::new();
        for (p, a) in params.iter().zip(args) {
            match literal(a, p.ty) {
                Some(v) => out.push(v),
                None => {
                    self.mismatch(what, p, a.span(), "this value");
                    return None;
                }
            }
        }
        Some(out)
    }

    fn arity(&mut self, what: &str, params: &[Param], given: usize, span: Span) {
        let sig = params
            .iter()
            .map(|p| format!("{}: {}", p.name, p.ty))
            .collect::<Vec<_>>()
            .join(", ");
        self.d.push(
            Diagnostic::error(
                "E0401",
                span,
                format!("{what} takes {} argument(s), {given} given", params.len()),
            )
            .label("wrong number of arguments")
            .help(format!("its parameters are ({sig})")),
        );
    }

    /// Expands a root instance and its children, pre-order, over an explicit stack (a chain of
    /// children as deep as the project is long cannot overflow the call stack). `fixed` holds
    /// the values of the root's leading parameters; the rest are bound at activation.
    ///
    /// The expansion is bounded like [`crate::instances`]'s, with the same limits: children
    /// multiply at each level (24 levels of two children are 16 million nets), so past
    /// [`MAX_INSTANCES`](crate::instances::MAX_INSTANCES) nets or
    /// [`MAX_NAME_BYTES`](crate::instances::MAX_NAME_BYTES) of their names, E0305 says where and
    /// the expansion stops (`Err`).
    fn expand(
        &mut self,
        templates: &[Template<'p>],
        insts: &mut Vec<Inst>,
        root: usize,
        fixed: Fixed,
        name_bytes: &mut usize,
    ) -> Result<(), ()> {
        use crate::instances::{MAX_INSTANCES, MAX_NAME_BYTES};
        let (decl, name) = (self.roots[root].decl, self.roots[root].name.clone());
        if insts.len() >= MAX_INSTANCES || *name_bytes + name.len() > MAX_NAME_BYTES {
            self.too_many_nets(insts.len(), root, None, self.decls[decl].name.span);
            return Err(());
        }
        *name_bytes += name.len();
        let me = insts.len();
        insts.push(Inst {
            name,
            decl,
            fixed,
            parent: None,
            children: Vec::new(),
        });
        // The declarations on the path from the root: a child that is its own ancestor (the
        // cycle is reported by `cycles`) is made, but not expanded further.
        let mut on_path = vec![false; self.decls.len()];
        on_path[decl] = true;
        let mut stack: Vec<(usize, usize)> = vec![(me, 0)];
        while let Some(top) = stack.last_mut() {
            let (parent, k) = *top;
            let pdecl = insts[parent].decl;
            let Some(ch) = templates[pdecl].children.get(k) else {
                on_path[pdecl] = false;
                stack.pop();
                continue;
            };
            top.1 += 1;
            let child_fixed = match ch.args {
                Some(args) if ch.fixed > 0 => {
                    let parent_fixed = insts[parent].fixed.clone();
                    self.child_args(pdecl, &parent_fixed, ch, args)
                        .unwrap_or_default()
                }
                _ => Vec::new(),
            };
            let child_name = format!("{}/{}", insts[parent].name, self.decls[ch.decl].name);
            if insts.len() >= MAX_INSTANCES || *name_bytes + child_name.len() > MAX_NAME_BYTES {
                self.too_many_nets(insts.len(), root, Some(stack.len()), ch.span);
                return Err(());
            }
            *name_bytes += child_name.len();
            let own_places = self.decls[pdecl].places().count() as u32;
            let id = insts.len();
            insts.push(Inst {
                name: child_name,
                decl: ch.decl,
                fixed: child_fixed,
                parent: Some((parent, own_places + k as u32)),
                children: Vec::new(),
            });
            insts[parent].children.push(id);
            if !on_path[ch.decl] {
                on_path[ch.decl] = true;
                stack.push((id, 0));
            }
        }
        Ok(())
    }

    /// E0305: the expansion of `root` stopped at a limit, `depth` levels of children down (at
    /// the `children` line `span`), with `made` nets made so far.
    fn too_many_nets(&mut self, made: usize, root: usize, depth: Option<usize>, span: Span) {
        use crate::instances::{MAX_INSTANCES, MAX_NAME_BYTES};
        let root = &self.roots[root].name;
        let (limit, label) = if made >= MAX_INSTANCES {
            (
                format!("more than {MAX_INSTANCES} nets"),
                format!("net number {} would be made here", made + 1),
            )
        } else {
            (
                format!("nets whose names take more than {MAX_NAME_BYTES} bytes in all"),
                "the names of nested children grow with their depth".to_string(),
            )
        };
        let at = match depth {
            Some(depth) => format!(", {depth} level(s) of children below `{root}`"),
            None => String::new(),
        };
        self.d.push(
            Diagnostic::error(
                "E0305",
                span,
                format!("the project expands to {limit} (instances and their children){at}"),
            )
            .label(label)
            .help(format!(
                "each `children` line makes an instance of the child for every instance of its parent, so children multiply at each level; the expansion from root `{root}` stopped here: a mission runs tens of nets, make the tree shallower or narrower"
            )),
        );
    }

    /// The values of a `children X(args)` line for one instance of its parent: literals, or the
    /// parent's fixed parameters.
    fn child_args(
        &mut self,
        parent_decl: usize,
        parent: &Fixed,
        ch: &ChildInfo<'p>,
        args: &[Expr],
    ) -> Option<Vec<c::Value>> {
        let child = self.decls[ch.decl];
        let mut out = Vec::new();
        for (p, a) in child.params.iter().zip(args) {
            match a {
                Expr::SelfParam(n) => {
                    let i = self.decls[parent_decl]
                        .params
                        .iter()
                        .position(|q| q.name.text == n.text)?;
                    match parent.get(i) {
                        Some(value) => out.push(convert(value, p.ty)?),
                        None => {
                            if self.reported.insert((n.span.file.0, n.span.start, "E0415")) {
                                self.d.push(
                                    Diagnostic::error(
                                        "E0415",
                                        n.span,
                                        format!("`self.{n}` is not fixed when the children of `{}` are made", self.decls[parent_decl].name),
                                    )
                                    .label("bound only at activation")
                                    .help("a child's arguments are literals or parameters of an instance of the parent (manifest `[instances]`, or the parent's own `children` line with arguments)"),
                                );
                            }
                            return None;
                        }
                    }
                }
                _ => out.push(literal(a, p.ty)?),
            }
        }
        Some(out)
    }

    /// A compiled instance: its template with references resolved and fixed parameters folded.
    fn instantiate(
        &mut self,
        templates: &[Template<'p>],
        root_inst: &[usize],
        me: usize,
        inst: &Inst,
    ) -> c::Net {
        let t = &templates[inst.decl];
        let decl = self.decls[inst.decl];
        let resolve = |r: u32| -> c::NetId {
            match t.refs[r as usize] {
                NetRef::SelfNet => me as c::NetId,
                NetRef::Child(k) => inst.children.get(k).copied().unwrap_or(me) as c::NetId,
                NetRef::Root(k) => root_inst.get(k).copied().unwrap_or(me) as c::NetId,
            }
        };
        let fixed = inst.fixed.as_slice();
        let mut transitions = Vec::new();
        for tr in &t.transitions {
            let mut tr = tr.clone();
            for a in &mut tr.actions {
                if let c::Action::Call {
                    program,
                    function,
                    args,
                } = a
                {
                    if *program >= PROGRAM_PARAM {
                        let param = (*program - PROGRAM_PARAM) as usize;
                        let pending = &t.pending_calls[*function as usize];
                        fold_args(args, fixed);
                        match self.program_of(
                            decl,
                            &inst.name,
                            fixed.get(param),
                            param,
                            pending,
                            args,
                        ) {
                            Some((p, f)) => {
                                *program = p;
                                *function = f;
                            }
                            // Reported; the instance keeps a call that is never compiled.
                            None => {
                                *program = 0;
                                *function = 0;
                            }
                        }
                        continue;
                    }
                }
                match a {
                    c::Action::Activate { net, args } => {
                        *net = resolve(*net);
                        fold_args(args, fixed);
                    }
                    c::Action::Deactivate(net) => *net = resolve(*net),
                    c::Action::Emit { target, args, .. } => {
                        if let Some(n) = target {
                            *n = resolve(*n);
                        }
                        fold_args(args, fixed);
                    }
                    c::Action::Call { args, .. } => fold_args(args, fixed),
                    c::Action::StartTimer { after, .. } => {
                        if let c::TimerDuration::NetParamSeconds(i) = &*after {
                            let i = *i as usize;
                            *after = match fixed.get(i) {
                                Some(v) => c::TimerDuration::Millis(seconds_to_millis(v)),
                                None => c::TimerDuration::NetParamSeconds((i - fixed.len()) as u32),
                            };
                        }
                    }
                    c::Action::CancelTimer(_) | c::Action::Finish => {}
                }
            }
            if let Some(g) = tr.guard.take() {
                tr.guard = match fold_guard(g, fixed) {
                    c::Guard::Const(true) => None,
                    g => Some(g),
                };
            }
            transitions.push(tr);
        }
        c::Net {
            name: inst.name.clone(),
            template: decl.name.text.clone(),
            params: decl
                .params
                .iter()
                .skip(inst.fixed.len())
                .map(|p| (p.name.text.clone(), p.ty))
                .collect(),
            places: t.places.clone(),
            transitions,
            children: inst.children.iter().map(|&c| c as c::NetId).collect(),
            parent: inst.parent.map(|(p, i)| (p as c::NetId, i)),
        }
    }

    /// The program and function of `call self.PARAM.f(args)` in one instance, its arguments
    /// (parameters already folded) converted to the function's types; errors reported once.
    fn program_of(
        &mut self,
        decl: &NetDecl,
        instance: &str,
        value: Option<&c::Value>,
        param: usize,
        pending: &PendingCall,
        args: &mut [c::Arg],
    ) -> Option<(u32, u32)> {
        let pname = &decl.params[param].name;
        let program = match value {
            Some(c::Value::Text(t)) => t.clone(),
            _ => {
                if self
                    .reported
                    .insert((pending.span.file.0, pending.span.start, "E0418"))
                {
                    self.d.push(
                        Diagnostic::error(
                            "E0418",
                            pending.span,
                            format!("in net `{instance}`, `self.{pname}` is not fixed: the program it names must be known before the mission"),
                        )
                        .label("a program named by a parameter bound at activation")
                        .help(format!("fix `{pname}` in the instance (manifest [instances], or the parent's `children` line)")),
                    );
                }
                return None;
            }
        };
        let report = |ck: &mut Self, code: &'static str, msg: String, help: String| {
            if ck
                .reported
                .insert((pending.span.file.0, pending.span.start, code))
            {
                ck.d.push(
                    Diagnostic::error(code, pending.span, msg)
                        .label(format!(
                            "in net `{instance}`, `self.{pname}` is \"{program}\""
                        ))
                        .help(help),
                );
            }
        };
        let Some(&pid) = self.programs.get(program.as_str()) else {
            let hint = suggest(
                &program,
                self.programs.keys().copied(),
                Candidates::Declared,
            );
            report(self, "E0204", format!("unknown program `{program}`"), hint);
            return None;
        };
        let pdecl = &self.p.manifest.programs[pid as usize];
        let Some(fid) = pdecl
            .functions
            .iter()
            .position(|f| f.name.text == pending.function.text)
        else {
            report(
                self,
                "E0205",
                format!("program `{program}` has no function `{}`", pending.function),
                format!(
                    "declare it in [programs.{program}.functions], or fix the instance's `{pname}`"
                ),
            );
            return None;
        };
        let params = &pdecl.functions[fid].params;
        if params.len() != args.len() {
            report(
                self,
                "E0401",
                format!(
                    "function `{program}.{}` takes {} argument(s), {} given",
                    pending.function,
                    params.len(),
                    args.len()
                ),
                "every program a parameter may name must take the same arguments".into(),
            );
            return None;
        }
        for ((p, a), written) in params.iter().zip(args.iter_mut()).zip(&pending.types) {
            let ty = match a {
                c::Arg::Literal(v) => v.ty(),
                _ => *written,
            };
            if ty == p.ty {
                continue;
            }
            match a {
                c::Arg::Literal(c::Value::Int(i)) if p.ty == Type::Float => {
                    *a = c::Arg::Literal(c::Value::Float(*i as f64));
                }
                _ => {
                    report(
                        self,
                        "E0402",
                        format!(
                            "parameter `{}` of function `{program}.{}` is {}, {ty} given",
                            p.name, pending.function, p.ty
                        ),
                        "every program a parameter may name must take the same argument types"
                            .into(),
                    );
                    return None;
                }
            }
        }
        Some((pid, fid as u32))
    }

    fn globals_compiled(
        &mut self,
        templates: &[Template<'p>],
        insts: &[Inst],
    ) -> Vec<c::GlobalPlace> {
        let m = &self.p.manifest;
        let mut out = Vec::new();
        for (g, decl) in m.globals.iter().enumerate() {
            let nets = decl.nets.as_ref().map(|names| {
                let mut ids = Vec::new();
                for n in names {
                    let matched: Vec<usize> = insts
                        .iter()
                        .enumerate()
                        .filter(|(_, i)| i.name == n.text || self.decls[i.decl].name.text == n.text)
                        .map(|(k, _)| k)
                        .collect();
                    if matched.is_empty() {
                        let mut cands: Vec<&str> = insts.iter().map(|i| i.name.as_str()).collect();
                        cands.extend(self.decls.iter().map(|d| d.name.as_str()));
                        cands.sort_unstable();
                        cands.dedup();
                        let hint = suggest(n.as_str(), cands, Candidates::Declared);
                        self.d.push(
                            Diagnostic::error("E0202", n.span, format!("unknown net `{n}`"))
                                .label("no net or template of this name")
                                .help(hint),
                        );
                    }
                    ids.extend(matched.into_iter().map(|k| k as c::NetId));
                }
                ids.sort_unstable();
                ids.dedup();
                ids
            });
            if let Some(scope) = &nets {
                // Every instance that names the place must be in its group.
                for (k, inst) in insts.iter().enumerate() {
                    if scope.contains(&(k as c::NetId)) {
                        continue;
                    }
                    for &(used, span) in &templates[inst.decl].globals_used {
                        if used as usize == g
                            && self.reported.insert((span.file.0, span.start, "E0417"))
                        {
                            self.d.push(
                                Diagnostic::error(
                                    "E0417",
                                    span,
                                    format!("global place `{}` is not visible in net `{}`", decl.name, inst.name),
                                )
                                .label("outside the place's group of nets")
                                .related(decl.name.span, "its group is declared here")
                                .help(format!("add `{}` (or its template `{}`) to the place's `nets`, or use a place of its own", inst.name, self.decls[inst.decl].name)),
                            );
                        }
                    }
                }
            }
            out.push(c::GlobalPlace {
                name: decl.name.text.clone(),
                initial: decl.tokens > 0,
                nets,
            });
        }
        out
    }

    fn start(&mut self, project: &c::CompiledProject, root_inst: &[usize]) -> Vec<c::NetId> {
        let mut start = Vec::new();
        for s in &self.p.manifest.start {
            match self.root_ids.get(s.as_str()).copied() {
                Some(r) => {
                    let id = root_inst[r] as c::NetId;
                    if start.contains(&id) {
                        self.d.push(
                            Diagnostic::warning(
                                "W0103",
                                s.span,
                                format!("net `{s}` is listed twice in `start`"),
                            )
                            .label("already listed")
                            .help("remove the second entry"),
                        );
                        continue;
                    }
                    if !project.nets[id as usize].params.is_empty() {
                        // Its parameters (or those its instance leaves) come at activation.
                        self.d.push(
                            Diagnostic::error(
                                "E0412",
                                s.span,
                                format!("net `{s}` takes arguments when it is activated: it cannot start the mission"),
                            )
                            .label("parameters bound at activation")
                            .help(format!("activate it from a transition with its arguments (`activate {s}(...)`), or declare an instance with fixed arguments in the manifest's [instances] and start that")),
                        );
                        continue;
                    }
                    start.push(id);
                }
                None => self.not_a_root("E0202", s, None),
            }
        }
        start
    }

    /// Resolves the places of an intended final marking, `NET.place` or `global.place`.
    fn final_marking(
        &mut self,
        project: &c::CompiledProject,
        places: &[Name],
    ) -> Vec<(u32, c::PlaceRef)> {
        let mut out = Vec::new();
        for n in places {
            match project.place_ref(&n.text) {
                Some(f) => out.push(f),
                None => self.d.push(
                    Diagnostic::error(
                        "E0208",
                        n.span,
                        format!("unknown place `{n}` in a final marking"),
                    )
                    .label("no such place")
                    .help("write places of final markings as `NET.place` or `global.place` (an instance's name for a template's place: `R1.waiting`)"),
                ),
            }
        }
        out
    }

    fn invariants(&mut self, project: &c::CompiledProject) -> Vec<c::Invariant> {
        let decls = &self.p.manifest.invariants;
        unique(&mut self.d, "invariant", "", decls.iter().map(|i| &i.name));
        let mut out = Vec::new();
        for inv in decls {
            let Some(f) = &inv.formula else { continue };
            if let Some(formula) = self.state_formula(project, f) {
                out.push(c::Invariant {
                    name: inv.name.text.clone(),
                    formula,
                });
            }
        }
        out
    }

    /// The manifest's time bounds: each end an event or a formula, `within` a duration.
    fn bounds(&mut self, project: &c::CompiledProject) -> Vec<c::Bound> {
        let decls = &self.p.manifest.bounds;
        unique(&mut self.d, "bound", "", decls.iter().map(|b| &b.name));
        let mut out = Vec::new();
        for b in decls {
            let from = self.occurrence(project, &b.from);
            let to = self.occurrence(project, &b.to);
            let within_us = match &b.within {
                None => Some(None),
                Some(w) => match petrel_diag::duration::parse_duration_us(&w.text) {
                    Some(us) => Some(Some(us)),
                    None => {
                        self.d.push(
                            Diagnostic::error(
                                "E0420",
                                w.span,
                                format!("bound `{}`: `{}` is not a duration", b.name, w.text),
                            )
                            .label("not a duration")
                            .help("write a number and a unit: `500ms`, `90s`, `10min`, `1.5h`"),
                        );
                        None
                    }
                },
            };
            if let (Some(from), Some(to), Some(within_us)) = (from, to, within_us) {
                out.push(c::Bound {
                    name: b.name.text.clone(),
                    from,
                    to,
                    from_text: b.from.text().trim().to_string(),
                    to_text: b.to.text().trim().to_string(),
                    within_us,
                    within_text: b.within.as_ref().map(|w| w.text.trim().to_string()),
                });
            }
        }
        out
    }

    /// One end of a bound: a declared event, or a formula over the state.
    fn occurrence(
        &mut self,
        project: &c::CompiledProject,
        end: &BoundEnd,
    ) -> Option<c::Occurrence> {
        match end {
            BoundEnd::Event(n) => match self.events.get(n.as_str()) {
                Some(&e) => Some(c::Occurrence::Event(e)),
                None => {
                    self.unknown("E0203", "event", n, self.events.keys().copied().collect());
                    None
                }
            },
            BoundEnd::Marking { formula, .. } => formula
                .as_ref()
                .and_then(|f| self.state_formula(project, f))
                .map(c::Occurrence::Marking),
        }
    }

    /// A formula of the manifest resolved against the project's nets and places.
    pub(crate) fn state_formula(
        &mut self,
        project: &c::CompiledProject,
        f: &Formula,
    ) -> Option<c::StateFormula> {
        let mut bad = false;
        let r = resolve_formula(project, f, &mut |n: &Name, what: &str| {
            bad = true;
            let mut cands: Vec<&str> = project.nets.iter().map(|n| n.name.as_str()).collect();
            cands.sort_unstable();
            let hint = if what == "place" {
                "write `NET.place` (an instance's name for a template's place) or `global.place`"
                    .to_string()
            } else {
                suggest(n.as_str(), cands, Candidates::Declared)
            };
            self.d.push(
                Diagnostic::error(
                    "E0211",
                    n.span,
                    format!("unknown {what} `{n}` in a formula"),
                )
                .label(format!("no {what} of this name"))
                .help(hint),
            );
        });
        if bad {
            None
        } else {
            r
        }
    }

    /// A declared or built-in event.
    fn event_decl(&self, e: u32) -> &'p EventDecl {
        let m = &self.p.manifest.events;
        m.get(e as usize)
            .unwrap_or_else(|| &builtin_events()[e as usize - m.len()])
    }

    fn unknown(&mut self, code: &'static str, what: &str, n: &Name, mut candidates: Vec<&str>) {
        candidates.sort_unstable();
        let mut hint = suggest(n.as_str(), candidates.iter().copied(), Candidates::Declared);
        if what == "event" && !hint.starts_with("did you mean") {
            // List what the user declared; built-ins are documented, not declared.
            let declared = candidates
                .iter()
                .copied()
                .filter(|c| !builtin_events().iter().any(|b| b.name.text == *c));
            hint = suggest(n.as_str(), declared, Candidates::Declared);
        }
        let declare = match what {
            "net" => "nets are declared with `net NAME { ... }` in a file the manifest lists",
            "event" => "declare events in the manifest's [events] table",
            "program" => "declare programs in the manifest's [programs.NAME] tables",
            "timer" => "declare timers in the manifest's [timers] table",
            _ => "",
        };
        self.d.push(
            Diagnostic::error(code, n.span, format!("unknown {what} `{n}`"))
                .label(format!("no {what} of this name"))
                .help(if declare.is_empty() {
                    hint
                } else {
                    format!("{hint} ({declare})")
                }),
        );
    }

    /// `n` names no root net: say why (a template with instances, someone's child, unknown).
    fn not_a_root(&mut self, code: &'static str, n: &Name, from: Option<&NetDecl>) {
        if let Some(&k) = self.decl_ids.get(n.as_str()) {
            if !self.parents_of[k].is_empty() {
                let parents: Vec<String> = self.parents_of[k]
                    .iter()
                    .map(|&p| format!("`{}`", self.decls[p].name))
                    .collect();
                self.d.push(
                    Diagnostic::error(
                        "E0210",
                        n.span,
                        format!("net `{n}` is a child of {}: only its parent names it", parents.join(" and ")),
                    )
                    .label(match from {
                        Some(f) => format!("not a child of `{}`", f.name),
                        None => "a child net".to_string(),
                    })
                    .help(format!("declare it in this net's `children` line to run an instance of its own, or act on it from its parent {}", parents.join(" or "))),
                );
                return;
            }
            let instances: Vec<String> = self
                .roots
                .iter()
                .filter(|r| r.decl == k && r.instance.is_some())
                .map(|r| format!("`{}`", r.name))
                .collect();
            if !instances.is_empty() {
                self.d.push(
                    Diagnostic::error(
                        "E0210",
                        n.span,
                        format!("net `{n}` is a template: name one of its instances"),
                    )
                    .label("a template with instances")
                    .help(format!("its instances are {}", instances.join(", "))),
                );
                return;
            }
        }
        let mut owned: Vec<String> = self.root_ids.keys().cloned().collect();
        if let Some(f) = from {
            owned.extend(f.children().map(|c| c.net.text.clone()));
        }
        self.unknown(code, "net", n, owned.iter().map(String::as_str).collect());
    }

    /// A net's body, checked once.
    fn template(&mut self, i: usize) -> Template<'p> {
        let net = self.decls[i];
        let scope = format!(" in net `{}`", net.name);
        // Places and transitions share one namespace: a name means one thing in a net.
        let names: Vec<&Name> = net
            .items
            .iter()
            .filter_map(|i| match &i.kind {
                ItemKind::Place(p) => Some(&p.name),
                ItemKind::Transition(t) => Some(&t.name),
                ItemKind::Children(_) => None,
            })
            .collect();
        unique(&mut self.d, "name", &scope, names.into_iter());
        for p in &net.params {
            if p.name.text == "self" {
                self.d.push(
                    Diagnostic::error("E0105", p.name.span, "`self` is not a parameter name")
                        .label("reserved")
                        .help("give the parameter another name"),
                );
            }
        }
        let mut places: HashMap<String, u32> = HashMap::new();
        let mut cplaces = Vec::new();
        for p in net.places() {
            if self.globals.contains_key(p.name.as_str()) {
                self.d.push(
                    Diagnostic::error(
                        "E0302",
                        p.name.span,
                        format!("place `{}` of net `{}` has the name of a global place", p.name, net.name),
                    )
                    .label("hides the global place")
                    .help("rename the local place; transitions refer to the global place by its plain name"),
                );
            }
            if p.tokens > 1 {
                self.d.push(
                    Diagnostic::error(
                        "E0405",
                        p.tokens_span.unwrap_or(p.name.span),
                        format!("place `{}` starts with {} tokens", p.name, p.tokens),
                    )
                    .label("a place holds 0 or 1 token")
                    .help("Petrel nets are safe: write `= 1` for a marked place, or nothing for an empty one"),
                );
            }
            places
                .entry(p.name.text.clone())
                .or_insert(cplaces.len() as u32);
            cplaces.push(c::Place {
                name: p.name.text.clone(),
                initial: p.tokens > 0,
            });
        }
        // Children, and their completion places after the net's own places.
        let mut children = Vec::new();
        for ch in net.children() {
            let Some(&k) = self.decl_ids.get(ch.net.as_str()) else {
                continue;
            };
            let child = self.decls[k];
            let fixed = match &ch.args {
                None => 0,
                Some(args) => {
                    self.child_args_typed(net, child, args, ch.net.span);
                    args.len().min(child.params.len())
                }
            };
            places.insert(format!("{}.done", ch.net), cplaces.len() as u32);
            cplaces.push(c::Place {
                name: format!("{}.done", ch.net),
                initial: false,
            });
            children.push(ChildInfo {
                decl: k,
                span: ch.net.span,
                args: ch.args.as_deref(),
                fixed,
            });
        }
        let mut t = Template {
            places: cplaces,
            transitions: Vec::new(),
            refs: Vec::new(),
            children,
            globals_used: Vec::new(),
            finishes: None,
            pending_calls: Vec::new(),
        };
        for tr in net.transitions() {
            let compiled = self.transition(net, &places, tr, &mut t);
            t.transitions.push(compiled);
        }
        if let (Some(span), true) = (t.finishes, self.parents_of[i].is_empty()) {
            self.d.push(
                Diagnostic::error(
                    "E0413",
                    span,
                    format!(
                        "net `{}` finishes, but no net declares it as a child",
                        net.name
                    ),
                )
                .label("no parent to tell")
                .help(format!(
                    "declare `{}` in its parent's `children` line, or use `deactivate self`",
                    net.name
                )),
            );
        }
        t
    }

    /// The types of a `children X(args)` line: literals, or the parent's parameters.
    fn child_args_typed(&mut self, parent: &NetDecl, child: &NetDecl, args: &[Expr], span: Span) {
        let what = format!("net `{}`", child.name);
        // The arguments fix the leading parameters; the others are bound at activation.
        if args.len() > child.params.len() {
            self.arity(&what, &child.params, args.len(), span);
            return;
        }
        for (p, a) in child.params.iter().zip(args) {
            match a {
                Expr::SelfParam(n) => match parent.params.iter().find(|q| q.name.text == n.text) {
                    None => self.unknown_param(parent, n),
                    Some(q) if q.ty != p.ty && !(q.ty == Type::Int && p.ty == Type::Float) => {
                        self.mismatch(&what, p, a.span(), &format!("`self.{n}` is {}", q.ty))
                    }
                    Some(_) => {}
                },
                Expr::Var(n) => {
                    self.d.push(
                        Diagnostic::error(
                            "E0207",
                            n.span,
                            format!("`{n}` is not known in a `children` line"),
                        )
                        .label("no event binds names here")
                        .help("a child's arguments are literals or `self.PARAM`"),
                    );
                }
                _ => {
                    if literal(a, p.ty).is_none() {
                        self.mismatch(&what, p, a.span(), "this value");
                    }
                }
            }
        }
    }

    fn unknown_param(&mut self, net: &NetDecl, n: &Name) {
        let hint = if net.params.is_empty() {
            format!(
                "net `{}` has no parameter: declare them as `net {}(name: type) {{`",
                net.name, net.name
            )
        } else {
            suggest(
                n.as_str(),
                net.params.iter().map(|p| p.name.as_str()),
                Candidates::Declared,
            )
        };
        self.d.push(
            Diagnostic::error(
                "E0209",
                n.span,
                format!("net `{}` has no parameter `{n}`", net.name),
            )
            .label("unknown parameter")
            .help(hint),
        );
    }

    /// A net name in a body: `self`, a child, or a root.
    fn net_ref(
        &mut self,
        net: &NetDecl,
        t: &mut Template<'p>,
        n: &Name,
        self_ok: bool,
    ) -> Option<u32> {
        let r = if n.text == "self" {
            if !self_ok {
                self.d.push(
                    Diagnostic::error("E0202", n.span, "`self` cannot be activated")
                        .label("the net that runs this action is already active")
                        .help("write `deactivate self`, or name another net"),
                );
                return None;
            }
            NetRef::SelfNet
        } else if net.children().any(|c| c.net.text == n.text) {
            // A child's instance of this net, if the child exists. The template lists only the
            // children whose net is declared (the others are reported where they are named),
            // so the index is the one among those, as the instances are made.
            let k = t
                .children
                .iter()
                .position(|c| self.decls[c.decl].name.text == n.text)?;
            NetRef::Child(k)
        } else if let Some(&r) = self.root_ids.get(n.as_str()) {
            NetRef::Root(r)
        } else {
            self.not_a_root("E0202", n, Some(net));
            return None;
        };
        let idx = match t.refs.iter().position(|x| *x == r) {
            Some(i) => i,
            None => {
                t.refs.push(r);
                t.refs.len() - 1
            }
        };
        Some(idx as u32)
    }

    /// The parameters a referenced net takes at activation (those its instance does not fix),
    /// whether it has others, and its name.
    fn target_params(&self, t: &Template<'p>, r: u32) -> (&'p [Param], bool, String) {
        let (decl, fixed, name) = match t.refs[r as usize] {
            NetRef::SelfNet => return (&[], false, "self".into()),
            NetRef::Child(k) => {
                let ch = &t.children[k];
                let decl = self.decls[ch.decl];
                (decl, ch.fixed, decl.name.text.clone())
            }
            NetRef::Root(k) => {
                let root = &self.roots[k];
                (self.decls[root.decl], root.fixed, root.name.clone())
            }
        };
        let fixed = fixed.min(decl.params.len());
        (&decl.params[fixed..], fixed > 0, name)
    }

    fn places(
        &mut self,
        net: &NetDecl,
        locals: &HashMap<String, u32>,
        t: &TransitionDecl,
        list: &[Name],
        side: &str,
        tpl: &mut Template<'p>,
    ) -> Vec<c::PlaceRef> {
        let mut out = Vec::new();
        for n in list {
            let r = if let Some(&i) = locals.get(n.as_str()) {
                if n.text.ends_with(".done") && side == "outputs" {
                    self.d.push(
                        Diagnostic::error(
                            "E0414",
                            n.span,
                            format!("the completion place `{n}` cannot be an output"),
                        )
                        .label("only the child's `finish` marks it")
                        .help("the child says it is done with `finish`; the parent only takes the token"),
                    );
                    continue;
                }
                c::PlaceRef::Local(i)
            } else if let Some(&g) = self.globals.get(n.as_str()) {
                tpl.globals_used.push((g, n.span));
                c::PlaceRef::Global(g)
            } else if let Some(child) = n.text.strip_suffix(".done") {
                self.d.push(
                    Diagnostic::error(
                        "E0414",
                        n.span,
                        format!("`{child}` is not a child of net `{}`", net.name),
                    )
                    .label("no completion place of this name")
                    .help(format!("declare the child in the net: `children {child}`; its completion place is then `{child}.done`")),
                );
                continue;
            } else {
                let mut cands: Vec<&str> = locals.keys().map(String::as_str).collect();
                cands.extend(self.globals.keys().copied());
                cands.sort_unstable();
                let hint = suggest(n.as_str(), cands, Candidates::Declared);
                self.d.push(
                    Diagnostic::error(
                        "E0201",
                        n.span,
                        format!("unknown place `{n}` in transition `{}` of net `{}`", t.name, net.name),
                    )
                    .label(format!("no place `{n}` in net `{}` nor among the global places", net.name))
                    .help(format!("{hint} (declare it with `place {n}` in the net, or in the manifest's [globals])")),
                );
                continue;
            };
            if out.contains(&r) {
                self.d.push(
                    Diagnostic::error(
                        "E0406",
                        n.span,
                        format!(
                            "place `{n}` is listed twice among the {side} of transition `{}`",
                            t.name
                        ),
                    )
                    .label("listed again")
                    .help("arcs are unary in Petrel nets: list each place once"),
                );
                continue;
            }
            out.push(r);
        }
        out
    }

    fn transition(
        &mut self,
        net: &'p NetDecl,
        locals: &HashMap<String, u32>,
        t: &'p TransitionDecl,
        tpl: &mut Template<'p>,
    ) -> c::Transition {
        let inputs = self.places(net, locals, t, &t.inputs, "inputs", tpl);
        let empty = self.places(net, locals, t, &t.empty, "places tested for emptiness", tpl);
        for (n, r) in t.empty.iter().zip(&empty) {
            if inputs.contains(r) {
                self.d.push(
                    Diagnostic::error(
                        "E0416",
                        n.span,
                        format!(
                            "transition `{}` takes a token from `{n}` and tests it for emptiness",
                            t.name
                        ),
                    )
                    .label("never enabled: the place cannot be marked and empty")
                    .help(format!("keep `{n}` or `not {n}`, not both")),
                );
            }
        }
        let outputs = self.places(net, locals, t, &t.outputs, "outputs", tpl);
        // Names the event binds, with the parameter index and type.
        let mut bound: HashMap<&str, (u32, Type)> = HashMap::new();
        let mut event = None;
        match &t.trigger {
            None => {
                if t.inputs.is_empty() {
                    self.d.push(
                        Diagnostic::error(
                            "E0409",
                            t.name.span,
                            format!("transition `{}` has no event and no input place", t.name),
                        )
                        .label("always enabled: it would fire forever")
                        .help("give it an input place, or a triggering event with `on EVENT`"),
                    );
                }
            }
            Some(trigger) => match self.events.get(trigger.event.as_str()).copied() {
                None => self.unknown(
                    "E0203",
                    "event",
                    &trigger.event,
                    self.events.keys().copied().collect(),
                ),
                Some(e) => {
                    event = Some(e);
                    let decl = self.event_decl(e);
                    if !trigger.bindings.is_empty()
                        && trigger.bindings.len() != decl.params.len()
                        && !decl.params_unread
                    {
                        let expected = decl
                            .params
                            .iter()
                            .map(|p| p.name.text.as_str())
                            .collect::<Vec<_>>()
                            .join(", ");
                        self.d.push(
                            Diagnostic::error(
                                "E0403",
                                trigger.event.span,
                                format!(
                                    "event `{}` has {} parameter(s), and the trigger binds {}",
                                    trigger.event,
                                    decl.params.len(),
                                    trigger.bindings.len()
                                ),
                            )
                            .label("wrong number of names")
                            .help(if decl.params.is_empty() {
                                format!("write `on {}` without parentheses", trigger.event)
                            } else {
                                format!("bind every parameter in order, `_` for those you do not use: `on {}({expected})`", trigger.event)
                            }),
                        );
                    }
                    let names = trigger
                        .bindings
                        .iter()
                        .map(|b| &b.name)
                        .filter(|n| n.text != "_");
                    unique(
                        &mut self.d,
                        "name",
                        &format!(" in the trigger of `{}`", t.name),
                        names,
                    );
                    for (i, (b, p)) in trigger.bindings.iter().zip(&decl.params).enumerate() {
                        if let Some((ty, span)) = b.ty {
                            if ty != p.ty {
                                self.d.push(
                                    Diagnostic::error(
                                        "E0404",
                                        span,
                                        format!(
                                            "parameter `{}` of event `{}` is {}, not {ty}",
                                            p.name, trigger.event, p.ty
                                        ),
                                    )
                                    .label(format!("the manifest declares {}", p.ty))
                                    .help(format!(
                                        "write `{}: {}`, or change the event in the manifest",
                                        b.name, p.ty
                                    )),
                                );
                            }
                        }
                        if b.name.text != "_" {
                            bound.entry(b.name.as_str()).or_insert((i as u32, p.ty));
                        }
                    }
                }
            },
        }
        let scope = Scope {
            net,
            transition: t,
            bound: &bound,
        };
        let guard = t.guard.as_ref().and_then(|g| self.guard(&scope, g));
        let actions = t
            .actions
            .iter()
            .filter_map(|a| self.action(&scope, &a.action, tpl))
            .collect();
        c::Transition {
            name: t.name.text.clone(),
            event,
            guard,
            inputs,
            empty,
            outputs,
            actions,
        }
    }

    /// An operand of a guard: its compiled form and type (ints and floats are numbers).
    fn operand(&mut self, s: &Scope, e: &Expr) -> Option<(c::Arg, Type)> {
        match e {
            Expr::Var(n) => {
                let (i, ty) = self.var(s, n)?;
                Some((c::Arg::EventParam(i), ty))
            }
            Expr::SelfParam(n) => {
                let Some(i) = s.net.params.iter().position(|p| p.name.text == n.text) else {
                    self.unknown_param(s.net, n);
                    return None;
                };
                Some((c::Arg::NetParam(i as u32), s.net.params[i].ty))
            }
            Expr::Int(v, _) => Some((c::Arg::Literal(c::Value::Int(*v)), Type::Int)),
            Expr::Float(v, _) => Some((c::Arg::Literal(c::Value::Float(*v)), Type::Float)),
            Expr::Bool(v, _) => Some((c::Arg::Literal(c::Value::Bool(*v)), Type::Bool)),
            Expr::Text(v, _) => Some((c::Arg::Literal(c::Value::Text(v.clone())), Type::Text)),
            Expr::List(..) => match literal(e, Type::FloatList) {
                Some(v) => Some((c::Arg::Literal(v), Type::FloatList)),
                None => {
                    self.guard_type(
                        e.span(),
                        "this list is not a list of numbers",
                        "write lists of numbers only",
                    );
                    None
                }
            },
        }
    }

    fn guard_type(&mut self, span: Span, label: &str, help: &str) {
        self.d.push(
            Diagnostic::error("E0410", span, "this guard does not type-check")
                .label(label.to_string())
                .help(help.to_string()),
        );
    }

    fn guard(&mut self, s: &Scope, g: &Guard) -> Option<c::Guard> {
        Some(match g {
            Guard::Or(a, b) => {
                let (a, b) = (self.guard(s, a), self.guard(s, b));
                c::Guard::Or(vec![a?, b?])
            }
            Guard::And(a, b) => {
                let (a, b) = (self.guard(s, a), self.guard(s, b));
                c::Guard::And(vec![a?, b?])
            }
            Guard::Not(a) => c::Guard::Not(Box::new(self.guard(s, a)?)),
            Guard::Value(e) => {
                let (arg, ty) = self.operand(s, e)?;
                if ty != Type::Bool {
                    self.guard_type(
                        e.span(),
                        &format!("this is {ty}, not bool"),
                        "a value alone in a guard must be a bool; compare it: `x == 3`",
                    );
                    return None;
                }
                c::Guard::Value(arg)
            }
            Guard::Compare(op, a, b) => {
                let (l, r) = (self.operand(s, a), self.operand(s, b));
                let ((la, lt), (ra, rt)) = (l?, r?);
                let numeric = |t: Type| matches!(t, Type::Int | Type::Float);
                let ordering = !matches!(op, CmpOp::Eq | CmpOp::Ne);
                if ordering && !(numeric(lt) && numeric(rt)) {
                    self.guard_type(
                        a.span().to(b.span()),
                        &format!(
                            "`{}` compares numbers; these are {lt} and {rt}",
                            op.symbol()
                        ),
                        "order comparisons (`<`, `<=`, `>`, `>=`) take ints and floats",
                    );
                    return None;
                }
                if !ordering && lt != rt && !(numeric(lt) && numeric(rt)) {
                    self.guard_type(
                        a.span().to(b.span()),
                        &format!("{lt} and {rt} cannot be equal"),
                        "compare values of one type (an int and a float compare as numbers)",
                    );
                    return None;
                }
                c::Guard::Compare(*op, la, ra)
            }
        })
    }

    fn action(&mut self, s: &Scope, a: &Action, tpl: &mut Template<'p>) -> Option<c::Action> {
        Some(match a {
            Action::Activate { net, args, span } => {
                let r = self.net_ref(s.net, tpl, net, false)?;
                let (params, some_fixed, target) = self.target_params(tpl, r);
                if params.is_empty() && !args.is_empty() {
                    self.d.push(
                        Diagnostic::error(
                            "E0401",
                            *span,
                            format!("net `{target}` takes no argument when it is activated"),
                        )
                        .label(if some_fixed {
                            "its parameters are fixed by its instance".to_string()
                        } else {
                            "it has no parameter".to_string()
                        })
                        .help(format!("write `activate {target}`")),
                    );
                    return None;
                }
                let what = format!("the activation of net `{target}`");
                let args = self.args(s, &what, params, args, *span)?;
                c::Action::Activate { net: r, args }
            }
            Action::Deactivate(n) => c::Action::Deactivate(self.net_ref(s.net, tpl, n, true)?),
            Action::Finish(span) => {
                tpl.finishes.get_or_insert(*span);
                c::Action::Finish
            }
            Action::CancelTimer(n) => c::Action::CancelTimer(self.timer(n)?),
            Action::StartTimer { timer, after } => {
                let timer = self.timer(timer);
                let after = match after {
                    DurationExpr::Literal { value, unit, span } => {
                        let ms = value * unit.millis();
                        if !(0.0..=1e15).contains(&ms) {
                            self.d.push(
                                Diagnostic::error(
                                    "E0408",
                                    *span,
                                    "a timer duration must be positive and finite",
                                )
                                .label("not a usable duration")
                                .help("write a duration such as `30s` or `1.5min`"),
                            );
                            return None;
                        }
                        c::TimerDuration::Millis(ms.round() as u64)
                    }
                    DurationExpr::Seconds(n) => {
                        let (i, ty) = self.var(s, n)?;
                        if !matches!(ty, Type::Int | Type::Float) {
                            self.seconds_type(n, ty);
                            return None;
                        }
                        c::TimerDuration::EventParamSeconds(i)
                    }
                    DurationExpr::SelfSeconds(n) => {
                        let Some(i) = s.net.params.iter().position(|p| p.name.text == n.text)
                        else {
                            self.unknown_param(s.net, n);
                            return None;
                        };
                        let ty = s.net.params[i].ty;
                        if !matches!(ty, Type::Int | Type::Float) {
                            self.seconds_type(n, ty);
                            return None;
                        }
                        c::TimerDuration::NetParamSeconds(i as u32)
                    }
                };
                c::Action::StartTimer {
                    timer: timer?,
                    after,
                }
            }
            Action::Call {
                program,
                function,
                args,
                span,
            } if program.text.starts_with("self.") => {
                // The program a parameter names: resolved per instance, which must fix it.
                let name = &program.text["self.".len()..];
                let param = Name {
                    text: name.to_string(),
                    span: program.span,
                };
                let Some(i) = s.net.params.iter().position(|p| p.name.text == name) else {
                    self.unknown_param(s.net, &param);
                    return None;
                };
                if s.net.params[i].ty != Type::Text {
                    self.d.push(
                        Diagnostic::error(
                            "E0402",
                            program.span,
                            format!(
                                "parameter `{name}` of net `{}` is {}: it cannot name a program",
                                s.net.name, s.net.params[i].ty
                            ),
                        )
                        .label("not a text")
                        .help("a program is named by a text parameter: `net ROBOT(moves: text)`"),
                    );
                    return None;
                }
                let mut compiled = Vec::new();
                let mut types = Vec::new();
                for a in args {
                    let (arg, ty) = self.operand(s, a)?;
                    compiled.push(arg);
                    types.push(ty);
                }
                tpl.pending_calls.push(PendingCall {
                    function: function.clone(),
                    types,
                    span: *span,
                });
                c::Action::Call {
                    program: PROGRAM_PARAM + i as u32,
                    function: (tpl.pending_calls.len() - 1) as u32,
                    args: compiled,
                }
            }
            Action::Call {
                program,
                function,
                args,
                span,
            } => {
                let Some(&pid) = self.programs.get(program.as_str()) else {
                    self.unknown(
                        "E0204",
                        "program",
                        program,
                        self.programs.keys().copied().collect(),
                    );
                    return None;
                };
                let decl = &self.p.manifest.programs[pid as usize];
                let Some(fid) = decl
                    .functions
                    .iter()
                    .position(|f| f.name.text == function.text)
                else {
                    let hint = suggest(
                        function.as_str(),
                        decl.functions.iter().map(|f| f.name.as_str()),
                        Candidates::Declared,
                    );
                    self.d.push(
                        Diagnostic::error(
                            "E0205",
                            function.span,
                            format!("program `{program}` has no function `{function}`"),
                        )
                        .label("unknown function")
                        .help(format!("{hint} (functions are declared in the manifest's [programs.{program}.functions])")),
                    );
                    return None;
                };
                let f = &decl.functions[fid];
                if f.params_unread {
                    // Its parameters are unknown (E0103 said why): nothing to check against.
                    return None;
                }
                let what = format!("function `{program}.{function}`");
                let args = self.args(s, &what, &f.params, args, *span)?;
                c::Action::Call {
                    program: pid,
                    function: fid as u32,
                    args,
                }
            }
            Action::Emit {
                event,
                args,
                to,
                span,
            } => {
                let Some(&eid) = self.events.get(event.as_str()) else {
                    self.unknown(
                        "E0203",
                        "event",
                        event,
                        self.events.keys().copied().collect(),
                    );
                    return None;
                };
                let target = match to {
                    Some(n) => Some(self.net_ref(s.net, tpl, n, true)?),
                    None => None,
                };
                let decl = self.event_decl(eid);
                if decl.params_unread {
                    // Its parameters are unknown (E0103 said why): nothing to check against.
                    return None;
                }
                let params = &decl.params;
                let what = format!("event `{event}`");
                let args = self.args(s, &what, params, args, *span)?;
                c::Action::Emit {
                    event: eid,
                    args,
                    target,
                }
            }
        })
    }

    fn seconds_type(&mut self, n: &Name, ty: Type) {
        self.d.push(
            Diagnostic::error(
                "E0408",
                n.span,
                format!("`{n}` is {ty}; a timer duration in seconds must be int or float"),
            )
            .label("not a number of seconds")
            .help("pass an int or float parameter, or write a literal such as `30s`"),
        );
    }

    fn timer(&mut self, n: &Name) -> Option<u32> {
        let t = self.timers.get(n.as_str()).copied();
        if t.is_none() {
            self.unknown("E0206", "timer", n, self.timers.keys().copied().collect());
        }
        t
    }

    fn var(&mut self, s: &Scope, n: &Name) -> Option<(u32, Type)> {
        if let Some(&b) = s.bound.get(n.as_str()) {
            return Some(b);
        }
        let t = s.transition;
        let help = match &t.trigger {
            None => format!(
                "transition `{}` is immediate and binds no names: use a literal, or trigger it with an event that carries the value",
                t.name
            ),
            Some(tr) if tr.bindings.is_empty() => format!(
                "bind the event's parameters to names in the trigger: `on {}(name, ...)`",
                tr.event
            ),
            Some(tr) => {
                let names: Vec<String> = tr
                    .bindings
                    .iter()
                    .filter(|b| b.name.text != "_")
                    .map(|b| format!("`{}`", b.name))
                    .collect();
                if names.is_empty() {
                    "the trigger binds no names".to_string()
                } else {
                    format!("the trigger binds {}", names.join(", "))
                }
            }
        };
        let help = if s.net.params.iter().any(|p| p.name.text == n.text) {
            format!(
                "`{n}` is a parameter of net `{}`: write `self.{n}`",
                s.net.name
            )
        } else {
            help
        };
        self.d.push(
            Diagnostic::error(
                "E0207",
                n.span,
                format!("`{n}` is not bound by the event of transition `{}`", t.name),
            )
            .label("unbound name")
            .help(help),
        );
        None
    }

    fn args(
        &mut self,
        s: &Scope,
        what: &str,
        params: &[Param],
        args: &[Expr],
        span: Span,
    ) -> Option<Vec<c::Arg>> {
        if params.len() != args.len() {
            self.arity(what, params, args.len(), span);
            // Still type-check what lines up, to report everything in one run.
        }
        let mut out = Vec::new();
        let mut ok = params.len() == args.len();
        for (p, a) in params.iter().zip(args) {
            match self.arg(s, what, p, a) {
                Some(arg) => out.push(arg),
                None => ok = false,
            }
        }
        ok.then_some(out)
    }

    fn arg(&mut self, s: &Scope, what: &str, p: &Param, a: &Expr) -> Option<c::Arg> {
        if let Expr::Var(n) = a {
            let (i, ty) = self.var(s, n)?;
            if ty != p.ty {
                self.mismatch(what, p, a.span(), &format!("`{n}` is {ty}"));
                return None;
            }
            return Some(c::Arg::EventParam(i));
        }
        if let Expr::SelfParam(n) = a {
            let Some(i) = s.net.params.iter().position(|q| q.name.text == n.text) else {
                self.unknown_param(s.net, n);
                return None;
            };
            let ty = s.net.params[i].ty;
            if ty != p.ty {
                self.mismatch(what, p, a.span(), &format!("`self.{n}` is {ty}"));
                return None;
            }
            return Some(c::Arg::NetParam(i as u32));
        }
        match literal(a, p.ty) {
            Some(v) => Some(c::Arg::Literal(v)),
            None => {
                let found = match a {
                    Expr::Int(..) if p.ty == Type::Float => {
                        "an int that no float holds exactly (above 2^53)"
                    }
                    Expr::Int(..) => "an int",
                    Expr::Float(..) => "a float",
                    Expr::Bool(..) => "a bool",
                    Expr::Text(..) => "a text",
                    Expr::List(..) => "a list that is not a list of numbers (each exactly a float)",
                    Expr::Var(_) | Expr::SelfParam(_) => "a name",
                };
                self.mismatch(what, p, a.span(), &format!("this is {found}"));
                None
            }
        }
    }

    fn mismatch(&mut self, what: &str, p: &Param, span: Span, found: &str) {
        let example = match p.ty {
            Type::Int => "3",
            Type::Float => "2.5",
            Type::Bool => "true",
            Type::Text => "\"camera\"",
            Type::FloatList => "[1.0, 2.5]",
        };
        self.d.push(
            Diagnostic::error(
                "E0402",
                span,
                format!("parameter `{}` of {what} is {}", p.name, p.ty),
            )
            .label(format!("{found}, expected {}", p.ty))
            .help(format!(
                "pass a value of type {}, such as {example}, or a name bound to one",
                p.ty
            )),
        );
    }
}

/// A value converted to type `ty` (an int where a float is declared).
fn convert(v: &c::Value, ty: Type) -> Option<c::Value> {
    match (v, ty) {
        (c::Value::Int(i), Type::Float) => Some(c::Value::Float(*i as f64)),
        (v, t) if v.ty() == t => Some(v.clone()),
        _ => None,
    }
}

/// A net parameter read as seconds, in milliseconds (negative or not a number: zero).
fn seconds_to_millis(v: &c::Value) -> u64 {
    let secs = match v {
        c::Value::Int(i) => *i as f64,
        c::Value::Float(f) => *f,
        _ => 0.0,
    };
    if secs.is_finite() && secs > 0.0 {
        (secs * 1e3).round().min(u64::MAX as f64) as u64
    } else {
        0
    }
}

/// A net parameter fixed by the instance becomes its value; the others are renumbered among the
/// activation arguments (which hold only the parameters the instance leaves).
fn fold_arg(a: &mut c::Arg, fixed: &[c::Value]) {
    if let c::Arg::NetParam(i) = &*a {
        let i = *i as usize;
        *a = match fixed.get(i) {
            Some(v) => c::Arg::Literal(v.clone()),
            None => c::Arg::NetParam((i - fixed.len()) as u32),
        };
    }
}

fn fold_args(args: &mut [c::Arg], fixed: &[c::Value]) {
    for a in args {
        fold_arg(a, fixed);
    }
}

/// A guard with an instance's fixed parameters replaced by their values, and what is then
/// constant computed.
fn fold_guard(g: c::Guard, fixed: &[c::Value]) -> c::Guard {
    use c::Guard as G;
    match g {
        G::Const(b) => G::Const(b),
        G::Not(a) => match fold_guard(*a, fixed) {
            G::Const(b) => G::Const(!b),
            a => G::Not(Box::new(a)),
        },
        G::And(list) => {
            let mut out = Vec::new();
            for a in list {
                match fold_guard(a, fixed) {
                    G::Const(true) => {}
                    G::Const(false) => return G::Const(false),
                    a => out.push(a),
                }
            }
            if out.is_empty() {
                G::Const(true)
            } else {
                G::And(out)
            }
        }
        G::Or(list) => {
            let mut out = Vec::new();
            for a in list {
                match fold_guard(a, fixed) {
                    G::Const(false) => {}
                    G::Const(true) => return G::Const(true),
                    a => out.push(a),
                }
            }
            if out.is_empty() {
                G::Const(false)
            } else {
                G::Or(out)
            }
        }
        G::Compare(op, mut a, mut b) => {
            fold_arg(&mut a, fixed);
            fold_arg(&mut b, fixed);
            match (&a, &b) {
                (c::Arg::Literal(x), c::Arg::Literal(y)) => G::Const(c::compare(op, x, y)),
                _ => G::Compare(op, a, b),
            }
        }
        G::Value(mut a) => {
            fold_arg(&mut a, fixed);
            match a {
                c::Arg::Literal(c::Value::Bool(b)) => G::Const(b),
                a => G::Value(a),
            }
        }
    }
}

/// A bound given on the command line (`petrel verify --bound FROM..TO`), each end an event's
/// name or a marking formula as in `[verify.bounds]`; the error says which end does not read.
pub fn command_line_bound(project: &c::CompiledProject, text: &str) -> Result<c::Bound, String> {
    let Some((from, to)) = text.split_once("..") else {
        return Err(format!(
            "bound `{text}`: write FROM..TO, each an event or a marking formula (`leak..EMERGENCY.surfacing`)"
        ));
    };
    let end = |what: &str, t: &str| -> Result<c::Occurrence, String> {
        let mut d = Diagnostics::new();
        let read = crate::manifest::bound_end(petrel_diag::source::FileId::default(), 0, t, &mut d);
        if let Some(first) = d.iter().next() {
            return Err(format!(
                "bound `{text}`: {what} `{}`: {}",
                t.trim(),
                first.message
            ));
        }
        match read {
            BoundEnd::Event(n) => project
                .events
                .iter()
                .position(|e| e.name == n.text)
                .map(|e| c::Occurrence::Event(e as c::EventId))
                .ok_or_else(|| {
                    format!("bound `{text}`: {what} `{n}` is not a declared event (write `NET.place` for a marking)")
                }),
            BoundEnd::Marking { formula, .. } => {
                let mut bad = Vec::new();
                let f = formula.and_then(|f| {
                    resolve_formula(project, &f, &mut |n: &Name, kind: &str| {
                        bad.push(format!("unknown {kind} `{n}`"))
                    })
                });
                match f {
                    Some(f) if bad.is_empty() => Ok(c::Occurrence::Marking(f)),
                    _ => Err(format!("bound `{text}`: {what} `{}`: {}", t.trim(), bad.join(", "))),
                }
            }
        }
    };
    Ok(c::Bound {
        name: text.to_string(),
        from: end("from", from)?,
        to: end("to", to)?,
        from_text: from.trim().to_string(),
        to_text: to.trim().to_string(),
        within_us: None,
        within_text: None,
    })
}

/// Resolves a formula's names against a compiled project; `unknown` is told of each name that
/// does not resolve (with "place" or "net"), and the result is then `None`.
pub fn resolve_formula(
    project: &c::CompiledProject,
    f: &Formula,
    unknown: &mut dyn FnMut(&Name, &str),
) -> Option<c::StateFormula> {
    use c::StateFormula as S;
    Some(match f {
        Formula::Const(b, _) => S::Const(*b),
        Formula::Marked(n) => match project.place_ref(&n.text) {
            Some((net, r)) => S::Marked(net, r),
            None => {
                unknown(n, "place");
                return None;
            }
        },
        Formula::Active(n) => match project.net_id(&n.text) {
            Some(id) => S::Active(id),
            None => {
                unknown(n, "net");
                return None;
            }
        },
        Formula::Not(a) => S::Not(Box::new(resolve_formula(project, a, unknown)?)),
        Formula::And(a, b) => {
            let (a, b) = (
                resolve_formula(project, a, unknown),
                resolve_formula(project, b, unknown),
            );
            S::And(Box::new(a?), Box::new(b?))
        }
        Formula::Or(a, b) => {
            let (a, b) = (
                resolve_formula(project, a, unknown),
                resolve_formula(project, b, unknown),
            );
            S::Or(Box::new(a?), Box::new(b?))
        }
        Formula::Implies(a, b) => {
            let (a, b) = (
                resolve_formula(project, a, unknown),
                resolve_formula(project, b, unknown),
            );
            S::Implies(Box::new(a?), Box::new(b?))
        }
    })
}

/// A literal as a value of type `ty`; an int literal is accepted where a float is expected.
/// `None` when the literal does not fit the type (or is a name).
pub fn literal(e: &Expr, ty: Type) -> Option<c::Value> {
    Some(match (e, ty) {
        (Expr::Int(v, _), Type::Int) => c::Value::Int(*v),
        // An integer where a float is expected converts only when the float holds it exactly
        // (every integer up to 2^53 does; 2^53 + 1 would silently become 2^53).
        (Expr::Int(v, _), Type::Float) if (*v as f64) as i128 == i128::from(*v) => {
            c::Value::Float(*v as f64)
        }
        (Expr::Float(v, _), Type::Float) => c::Value::Float(*v),
        (Expr::Bool(b, _), Type::Bool) => c::Value::Bool(*b),
        (Expr::Text(s, _), Type::Text) => c::Value::Text(s.clone()),
        (Expr::List(items, _), Type::FloatList) => {
            let mut out = Vec::with_capacity(items.len());
            for i in items {
                match literal(i, Type::Float)? {
                    c::Value::Float(f) => out.push(f),
                    _ => return None,
                }
            }
            c::Value::FloatList(out)
        }
        _ => return None,
    })
}

/// Which pass of [`apply_allows`] this is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AllowPass {
    /// The checker's: silences, and reports an `@allow` of a code that is not a warning's
    /// (W0106).
    Check,
    /// Silences the warnings added since (a verification that did not finish), nothing more.
    FilterOnly,
    /// The last, once the verification's warnings are in: silences, and reports an `@allow`
    /// that silenced nothing (W0105).
    Final,
}

/// The warnings an `@allow` stands for, and the `@allow`s that stand for nothing.
///
/// An `@allow(CODE)` before a transition or a place silences the warnings of that code whose
/// location is the item's name; before a net, those located at the net's name or any of its
/// items.
pub fn apply_allows(project: &Project, d: &mut Diagnostics, pass: AllowPass) {
    let (final_pass, judged_all) = (pass != AllowPass::Check, pass == AllowPass::Final);
    struct Allowed<'a> {
        allow: &'a Allow,
        covers: Vec<Span>,
        used: bool,
    }
    let mut allows: Vec<Allowed> = Vec::new();
    for net in project.nets() {
        let items: Vec<Span> = net
            .items
            .iter()
            .filter_map(|i| match &i.kind {
                ItemKind::Place(p) => Some(p.name.span),
                ItemKind::Transition(t) => Some(t.name.span),
                ItemKind::Children(_) => None,
            })
            .collect();
        for a in &net.allows {
            let mut covers = vec![net.name.span];
            covers.extend(items.iter().copied());
            allows.push(Allowed {
                allow: a,
                covers,
                used: false,
            });
        }
        for item in &net.items {
            let span = match &item.kind {
                ItemKind::Place(p) => p.name.span,
                ItemKind::Transition(t) => t.name.span,
                ItemKind::Children(_) => continue,
            };
            for a in &item.allows {
                allows.push(Allowed {
                    allow: a,
                    covers: vec![span],
                    used: false,
                });
            }
        }
    }
    if allows.is_empty() {
        return;
    }
    let same = |a: Span, b: Span| a.file == b.file && a.start == b.start && a.end == b.end;
    let mut kept = Diagnostics::new();
    for diag in std::mem::take(d).into_iter() {
        let silenced = diag.severity == petrel_diag::report::Severity::Warning
            && diag.span.is_some_and(|s| {
                let mut hit = false;
                for a in allows.iter_mut() {
                    if a.allow.code.text == diag.code && a.covers.iter().any(|c| same(*c, s)) {
                        a.used = true;
                        hit = true;
                    }
                }
                hit
            });
        if !silenced {
            kept.push(diag);
        }
    }
    for a in &allows {
        let code = a.allow.code.text.as_str();
        let a_warning = code.starts_with('W')
            && code.len() == 5
            && code[1..].chars().all(|c| c.is_ascii_digit());
        if !a_warning && !final_pass {
            kept.push(
                Diagnostic::warning("W0106", a.allow.code.span, format!("`{code}` is not the code of a warning"))
                    .label("nothing to allow")
                    .help("only warnings (codes Wxxxx, listed in docs/diagnostics.md) can be intended; errors must be fixed"),
            );
        } else if a_warning && judged_all && !a.used {
            kept.push(
                Diagnostic::warning(
                    "W0105",
                    a.allow.code.span,
                    format!("`@allow({code})` silences nothing"),
                )
                .label("no such warning here")
                .help("remove it: the construct no longer gives this warning"),
            );
        }
    }
    *d = kept;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn comparisons_follow_the_types() {
        use c::compare;
        use c::Value as V;
        assert!(compare(CmpOp::Eq, &V::Int(3), &V::Float(3.0)));
        assert!(compare(CmpOp::Lt, &V::Int(2), &V::Float(2.5)));
        assert!(!compare(
            CmpOp::Eq,
            &V::Float(f64::NAN),
            &V::Float(f64::NAN)
        ));
        assert!(compare(CmpOp::Ne, &V::Float(f64::NAN), &V::Float(f64::NAN)));
        assert!(compare(
            CmpOp::Eq,
            &V::Text("r1".into()),
            &V::Text("r1".into())
        ));
        assert!(!compare(
            CmpOp::Lt,
            &V::Text("a".into()),
            &V::Text("b".into())
        ));
        assert!(compare(CmpOp::Gt, &V::Int(i64::MAX), &V::Int(i64::MAX - 1)));
    }
}
