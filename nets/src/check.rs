//! Name resolution and type checking: from the written [`Project`] to a [`CompiledProject`].
//!
//! Every problem is reported (the checker never stops at the first), each with the place it was
//! written and what to do. A compiled project is returned only when there is no error, so the
//! verifier and the player never see a project that does not check.

use crate::compiled as c;
use crate::diag::{Diagnostic, Diagnostics};
use crate::model::*;
use crate::names::{suggest, Candidates};
use crate::source::Span;
use std::collections::HashMap;

/// Checks a project; returns the compiled project when no error was found, and every finding.
pub fn check(project: &Project) -> (Option<c::CompiledProject>, Diagnostics) {
    let mut ck = Checker {
        p: project,
        d: Diagnostics::new(),
        nets: HashMap::new(),
        globals: HashMap::new(),
        events: HashMap::new(),
        programs: HashMap::new(),
        timers: HashMap::new(),
    };
    let compiled = ck.run();
    let mut d = ck.d;
    d.sort();
    let compiled = if d.has_errors() { None } else { Some(compiled) };
    (compiled, d)
}

struct Checker<'p> {
    p: &'p Project,
    d: Diagnostics,
    nets: HashMap<&'p str, u32>,
    globals: HashMap<&'p str, u32>,
    events: HashMap<&'p str, u32>,
    programs: HashMap<&'p str, u32>,
    timers: HashMap<&'p str, u32>,
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

impl<'p> Checker<'p> {
    fn run(&mut self) -> c::CompiledProject {
        let m = &self.p.manifest;
        let d = &mut self.d;
        self.nets = unique(d, "net", " in the project", self.p.nets().map(|n| &n.name));
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
                                .map(|p| Binding {
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

        let mut start = Vec::new();
        for s in &m.start {
            match self.nets.get(s.as_str()) {
                Some(&id) if start.contains(&id) => self.d.push(
                    Diagnostic::warning(
                        "W0103",
                        s.span,
                        format!("net `{s}` is listed twice in `start`"),
                    )
                    .label("already listed")
                    .help("remove the second entry"),
                ),
                Some(&id) => start.push(id),
                None => self.unknown("E0202", "net", s, self.nets.keys().copied().collect()),
            }
        }

        let mut timers = Vec::new();
        for t in &m.timers {
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

        let globals = m
            .globals
            .iter()
            .map(|g| c::GlobalPlace {
                name: g.name.text.clone(),
                initial: g.tokens > 0,
            })
            .collect();
        let nets = self.p.nets().map(|n| self.net(n)).collect();
        let finals = m.finals.iter().map(|f| self.final_marking(f)).collect();
        c::CompiledProject {
            name: m.name.clone(),
            nets,
            globals,
            events: m
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
                })
                .collect(),
            programs: m
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
                        })
                        .collect(),
                })
                .collect(),
            timers,
            start,
            finals,
        }
    }

    /// A declared or built-in event.
    fn event_decl(&self, e: u32) -> &'p EventDecl {
        let m = &self.p.manifest.events;
        m.get(e as usize)
            .unwrap_or_else(|| &builtin_events()[e as usize - m.len()])
    }

    /// Resolves the places of an intended final marking, `NET.place` or `global.place`.
    fn final_marking(&mut self, places: &[Name]) -> Vec<(u32, c::PlaceRef)> {
        let mut out = Vec::new();
        for n in places {
            let found = match n.text.split_once('.') {
                Some(("global", g)) => self.globals.get(g).map(|&i| (0, c::PlaceRef::Global(i))),
                Some((net, place)) => self.nets.get(net).and_then(|&ni| {
                    let decl = self.p.nets().nth(ni as usize)?;
                    decl.places()
                        .position(|p| p.name.text == place)
                        .map(|i| (ni, c::PlaceRef::Local(i as u32)))
                }),
                None => None,
            };
            match found {
                Some(f) => out.push(f),
                None => self.d.push(
                    Diagnostic::error(
                        "E0208",
                        n.span,
                        format!("unknown place `{n}` in a final marking"),
                    )
                    .label("no such place")
                    .help("write places of final markings as `NET.place` or `global.place`"),
                ),
            }
        }
        out
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

    fn net(&mut self, net: &'p NetDecl) -> c::Net {
        let scope = format!(" in net `{}`", net.name);
        // Places and transitions share one namespace: a name means one thing in a net.
        let names: Vec<&Name> = net
            .items
            .iter()
            .map(|i| match &i.kind {
                ItemKind::Place(p) => &p.name,
                ItemKind::Transition(t) => &t.name,
            })
            .collect();
        unique(&mut self.d, "name", &scope, names.into_iter());
        let mut places: HashMap<&str, u32> = HashMap::new();
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
                .entry(p.name.as_str())
                .or_insert(cplaces.len() as u32);
            cplaces.push(c::Place {
                name: p.name.text.clone(),
                initial: p.tokens > 0,
            });
        }
        let transitions = net
            .transitions()
            .map(|t| self.transition(net, &places, t))
            .collect();
        c::Net {
            name: net.name.text.clone(),
            places: cplaces,
            transitions,
        }
    }

    fn places(
        &mut self,
        net: &NetDecl,
        locals: &HashMap<&str, u32>,
        t: &TransitionDecl,
        list: &[Name],
        side: &str,
    ) -> Vec<c::PlaceRef> {
        let mut out = Vec::new();
        for n in list {
            let r = if let Some(&i) = locals.get(n.as_str()) {
                c::PlaceRef::Local(i)
            } else if let Some(&g) = self.globals.get(n.as_str()) {
                c::PlaceRef::Global(g)
            } else {
                let mut cands: Vec<&str> = locals.keys().copied().collect();
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
        net: &NetDecl,
        locals: &HashMap<&str, u32>,
        t: &TransitionDecl,
    ) -> c::Transition {
        let inputs = self.places(net, locals, t, &t.inputs, "inputs");
        let outputs = self.places(net, locals, t, &t.outputs, "outputs");
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
                    if !trigger.bindings.is_empty() && trigger.bindings.len() != decl.params.len() {
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
            transition: t,
            bound: &bound,
        };
        let actions = t
            .actions
            .iter()
            .filter_map(|a| self.action(&scope, &a.action))
            .collect();
        c::Transition {
            name: t.name.text.clone(),
            event,
            inputs,
            outputs,
            actions,
        }
    }

    fn action(&mut self, s: &Scope, a: &Action) -> Option<c::Action> {
        Some(match a {
            Action::Activate(n) | Action::Deactivate(n) => {
                let Some(&id) = self.nets.get(n.as_str()) else {
                    self.unknown("E0202", "net", n, self.nets.keys().copied().collect());
                    return None;
                };
                if matches!(a, Action::Activate(_)) {
                    c::Action::Activate(id)
                } else {
                    c::Action::Deactivate(id)
                }
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
                            self.d.push(
                                Diagnostic::error(
                                    "E0408",
                                    n.span,
                                    format!("`{n}` is {ty}; a timer duration in seconds must be int or float"),
                                )
                                .label("not a number of seconds")
                                .help("pass an int or float event parameter, or write a literal such as `30s`"),
                            );
                            return None;
                        }
                        c::TimerDuration::EventParamSeconds(i)
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
                let params = &decl.functions[fid].params;
                let what = format!("function `{program}.{function}`");
                let args = self.args(s, &what, params, args, *span)?;
                c::Action::Call {
                    program: pid,
                    function: fid as u32,
                    args,
                }
            }
            Action::Emit { event, args, span } => {
                let Some(&eid) = self.events.get(event.as_str()) else {
                    self.unknown(
                        "E0203",
                        "event",
                        event,
                        self.events.keys().copied().collect(),
                    );
                    return None;
                };
                let params = &self.event_decl(eid).params;
                let what = format!("event `{event}`");
                let args = self.args(s, &what, params, args, *span)?;
                c::Action::Emit { event: eid, args }
            }
        })
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
            let sig = params
                .iter()
                .map(|p| format!("{}: {}", p.name, p.ty))
                .collect::<Vec<_>>()
                .join(", ");
            self.d.push(
                Diagnostic::error(
                    "E0401",
                    span,
                    format!(
                        "{what} takes {} argument(s), {} given",
                        params.len(),
                        args.len()
                    ),
                )
                .label("wrong number of arguments")
                .help(format!("its parameters are ({sig})")),
            );
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
                    Expr::Var(_) => unreachable!("handled above"),
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

struct Scope<'a> {
    transition: &'a TransitionDecl,
    bound: &'a HashMap<&'a str, (u32, Type)>,
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
