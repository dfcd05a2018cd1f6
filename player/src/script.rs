//! Missions as unit tests: `petrel run DIR --script FILE`.
//!
//! No process, virtual time. A script is a timeline of events and expectations:
//!
//! ```text
//! # the nominal flight
//! 0.0 start_mission
//! expect MISSION.rolling            # a place marked (or a transition fired since the last event)
//! expect call GUI.roll()            # a call made since the last event (`_` matches any argument)
//! 12.5 payload_failure("camera")
//! expect not MISSION.transiting     # the opposite
//! expect inactive MISSION           # or `expect active NET`
//! expect unused                     # the last event fired nothing
//! 40 wait                           # let time pass: timers expire
//! ```
//!
//! Each step prints as one JSON line (time, event, parameters, outcome, fired transitions,
//! actions, the marking of every active net). Timers fire in virtual time, in deadline order.

use crate::engine::{Engine, Micros};
use crate::record::{call_text, transition_name, StepRecord};
use petrel_nets::compiled::{CompiledProject, FunctionId, NetId, PlaceRef, ProgramId, Value};
use petrel_nets::diag::Diagnostics;
use petrel_nets::model::{Action, Expr};
use petrel_nets::semantics::StepOutcome;
use petrel_nets::source::FileId;

/// A line of a script.
#[derive(Clone, Debug, PartialEq)]
pub enum Line {
    /// At `time` seconds, the event arrives (or only time passes, for `wait`).
    At {
        /// Seconds since the start.
        time: f64,
        /// The event and its parameters; `None` for `wait`.
        event: Option<(String, Vec<Value>)>,
    },
    /// A check on what happened since the last timed line.
    Expect {
        /// Negated (`expect not ...`).
        not: bool,
        /// What is expected.
        what: Expectation,
    },
}

/// What an `expect` line checks.
#[derive(Clone, Debug, PartialEq)]
pub enum Expectation {
    /// `NET.name` or `global.name`: a place marked, or a transition fired.
    Name(String, String),
    /// `active NET`.
    Active(String),
    /// `inactive NET`.
    Inactive(String),
    /// `call P.f(args)`; `None` arguments are `_`.
    Call {
        /// The program.
        program: String,
        /// The function.
        function: String,
        /// Expected arguments; `None` matches anything.
        args: Vec<Option<Value>>,
    },
    /// `unused`: the last event fired nothing.
    Unused,
}

/// A script with the line number of each line.
#[derive(Clone, Debug, PartialEq)]
pub struct Script {
    /// (line number, line).
    pub lines: Vec<(usize, Line)>,
}

/// Reads a script; every problem is reported as (line, message).
pub fn parse_script(text: &str, project: &CompiledProject) -> Result<Script, Vec<(usize, String)>> {
    let mut lines = Vec::new();
    let mut errors = Vec::new();
    let mut last_time = 0.0f64;
    for (i, raw) in text.lines().enumerate() {
        let n = i + 1;
        let line = match raw.find('#') {
            // A `#` inside a text literal is kept: strip only outside quotes.
            Some(_) => strip_comment(raw),
            None => raw,
        }
        .trim();
        if line.is_empty() {
            continue;
        }
        let result = if let Some(rest) = line.strip_prefix("expect ") {
            parse_expect(rest.trim(), project).map(|(not, what)| Line::Expect { not, what })
        } else {
            parse_timed(line, project, &mut last_time)
        };
        match result {
            Ok(l) => lines.push((n, l)),
            Err(e) => errors.push((n, e)),
        }
    }
    if errors.is_empty() {
        Ok(Script { lines })
    } else {
        Err(errors)
    }
}

fn strip_comment(line: &str) -> &str {
    let mut in_text = false;
    let mut escaped = false;
    for (i, c) in line.char_indices() {
        match c {
            '\\' if in_text => escaped = !escaped,
            '"' if !escaped => in_text = !in_text,
            '#' if !in_text => return &line[..i],
            _ => escaped = false,
        }
        if c != '\\' {
            escaped = false;
        }
    }
    line
}

fn parse_timed(line: &str, p: &CompiledProject, last: &mut f64) -> Result<Line, String> {
    let (time_text, rest) = line.split_once(char::is_whitespace).ok_or_else(|| {
        format!("expected `TIME EVENT(args)`, `TIME wait` or `expect ...`, found `{line}`")
    })?;
    let time = parse_time(time_text)?;
    if time < *last {
        return Err(format!(
            "time {time_text} goes back: lines are in time order (the previous one was at {last})"
        ));
    }
    *last = time;
    let rest = rest.trim();
    if rest == "wait" {
        return Ok(Line::At { time, event: None });
    }
    let mut d = Diagnostics::new();
    let parsed = petrel_nets::syntax::parse_action(FileId(0), &format!("emit {rest}"), &mut d);
    // A number the lexer refused (`1e999`, `99999999999999999999`) is read as 0 so that the
    // parser can go on: the action is not to be used then.
    refused_literals(&d)?;
    let Some(Action::Emit { event, args, .. }) = parsed else {
        return Err(format!(
            "`{rest}` is not an event such as `name` or `name(1, \"text\")`"
        ));
    };
    let Some(id) = p.event_id(&event.text) else {
        return Err(format!("unknown event `{}`", event.text));
    };
    let decl = &p.events[id as usize];
    if decl.params.len() != args.len() {
        return Err(format!(
            "event `{}` takes {} parameter(s), {} given",
            decl.name,
            decl.params.len(),
            args.len()
        ));
    }
    let mut params = Vec::new();
    for ((name, ty), a) in decl.params.iter().zip(&args) {
        match petrel_nets::check::literal(a, *ty) {
            Some(v) => params.push(v),
            None => return Err(format!("parameter `{name}` of `{}` is {ty}", decl.name)),
        }
    }
    Ok(Line::At {
        time,
        event: Some((event.text, params)),
    })
}

/// The largest script time, in seconds: mission time is counted in microseconds in a `u64`,
/// and a time past it would silently saturate.
pub const MAX_TIME_S: f64 = u64::MAX as f64 / 1e6;

/// Reads a time in seconds: a finite number from 0 to [`MAX_TIME_S`], nothing else (`nan`,
/// `inf` and `-1` are refused, not clamped).
pub fn parse_time(text: &str) -> Result<f64, String> {
    let time: f64 = text
        .parse()
        .map_err(|_| format!("`{text}` is not a time in seconds"))?;
    if !time.is_finite() || !(0.0..=MAX_TIME_S).contains(&time) {
        return Err(format!(
            "`{text}` is not a time: a time is a number of seconds from 0 to {MAX_TIME_S:e}"
        ));
    }
    Ok(time)
}

/// The errors the lexer and parser found in a line's action, as one message: a line is used
/// only when its action reads without any (a refused number would otherwise become 0).
fn refused_literals(d: &Diagnostics) -> Result<(), String> {
    if !d.has_errors() {
        return Ok(());
    }
    let why: Vec<String> = d
        .iter()
        .map(|e| match &e.help {
            Some(h) => format!("{} ({h})", e.message),
            None => e.message.clone(),
        })
        .collect();
    Err(why.join("; "))
}

fn parse_expect(rest: &str, p: &CompiledProject) -> Result<(bool, Expectation), String> {
    let (not, rest) = match rest.strip_prefix("not ") {
        Some(r) => (true, r.trim()),
        None => (false, rest),
    };
    if rest == "unused" {
        return Ok((not, Expectation::Unused));
    }
    if let Some(net) = rest.strip_prefix("active ") {
        return known_net(p, net.trim()).map(|n| (not, Expectation::Active(n)));
    }
    if let Some(net) = rest.strip_prefix("inactive ") {
        return known_net(p, net.trim()).map(|n| (not, Expectation::Inactive(n)));
    }
    if rest.starts_with("call ") {
        let mut d = Diagnostics::new();
        let parsed = petrel_nets::syntax::parse_action(FileId(0), rest, &mut d);
        refused_literals(&d)?;
        let Some(Action::Call {
            program,
            function,
            args,
            ..
        }) = parsed
        else {
            return Err(format!(
                "`{rest}` is not a call such as `call PROGRAM.function(1, _)`"
            ));
        };
        let prog = p
            .programs
            .iter()
            .find(|x| x.name == program.text)
            .ok_or_else(|| format!("unknown program `{program}`"))?;
        let func = prog
            .functions
            .iter()
            .find(|f| f.name == function.text)
            .ok_or_else(|| format!("program `{program}` has no function `{function}`"))?;
        if func.params.len() != args.len() {
            return Err(format!(
                "`{program}.{function}` takes {} argument(s), {} given",
                func.params.len(),
                args.len()
            ));
        }
        let mut expected = Vec::new();
        for ((name, ty), a) in func.params.iter().zip(&args) {
            if matches!(a, Expr::Var(n) if n.text == "_") {
                expected.push(None);
                continue;
            }
            match petrel_nets::check::literal(a, *ty) {
                Some(v) => expected.push(Some(v)),
                None => {
                    return Err(format!(
                        "argument `{name}` is {ty}; write a {ty} literal or `_`"
                    ))
                }
            }
        }
        return Ok((
            not,
            Expectation::Call {
                program: program.text,
                function: function.text,
                args: expected,
            },
        ));
    }
    let (net, name) = rest
        .split_once('.')
        .ok_or_else(|| format!("expected `NET.place`, `NET.transition`, `global.place`, `active NET`, `inactive NET`, `call P.f(...)` or `unused`, found `{rest}`"))?;
    if net == "global" {
        if !p.globals.iter().any(|g| g.name == name) {
            return Err(format!("no global place `{name}`"));
        }
    } else {
        let n = known_net(p, net)?;
        let decl = &p.nets[p.net_id(&n).unwrap_or(0) as usize];
        if !decl.places.iter().any(|x| x.name == name)
            && !decl.transitions.iter().any(|x| x.name == name)
        {
            return Err(format!("net `{net}` has no place or transition `{name}`"));
        }
    }
    Ok((not, Expectation::Name(net.to_string(), name.to_string())))
}

fn known_net(p: &CompiledProject, net: &str) -> Result<String, String> {
    p.net_id(net)
        .map(|_| net.to_string())
        .ok_or_else(|| format!("unknown net `{net}`"))
}

/// What a run produced: JSON lines, and the first failed expectation.
pub struct RunOutcome {
    /// One JSON document per step.
    pub steps: Vec<serde_json::Value>,
    /// `(line, message)` of the first failed expectation.
    pub failure: Option<(usize, String)>,
}

/// Runs a script on a fresh engine. `emit_step` receives each JSON line as it is produced.
pub fn run_script(
    project: &CompiledProject,
    script: &Script,
    emit_step: impl FnMut(&serde_json::Value),
) -> RunOutcome {
    let mut r = Runner {
        engine: Engine::new(project),
        rec: StepRecord::new(project),
        steps: Vec::new(),
        emit_step,
        since_fired: Vec::new(),
        since_calls: Vec::new(),
        last_unused: false,
    };
    r.engine.start(0, &mut r.rec);
    r.collect();
    r.record(None, "start");
    for (n, line) in &script.lines {
        match line {
            Line::At { time, event } => {
                r.since_fired.clear();
                r.since_calls.clear();
                r.last_unused = false;
                let target = (time * 1e6).round() as Micros;
                // Timers that expire before this line go first, each at its own time.
                while let Some(d) = r.engine.next_deadline().filter(|&d| d <= target) {
                    r.engine.advance_to(d);
                    r.process();
                }
                r.engine.advance_to(target);
                if let Some((name, params)) = event {
                    if let Err(refusal) = r.engine.submit_named(name, params.clone()) {
                        r.rec.actions.push(format!("refused: {refusal}"));
                        r.record(Some((name.clone(), params.clone())), "refused");
                        continue;
                    }
                }
                r.process();
            }
            Line::Expect { not, what } => {
                let (holds, expected, found) = check(
                    project,
                    &r.engine,
                    what,
                    &r.since_fired,
                    &r.since_calls,
                    r.last_unused,
                );
                if holds == *not {
                    let neg = if *not { "not " } else { "" };
                    return RunOutcome {
                        steps: r.steps,
                        failure: Some((*n, format!("expected {neg}{expected}\n  found: {found}"))),
                    };
                }
            }
        }
    }
    RunOutcome {
        steps: r.steps,
        failure: None,
    }
}

struct Runner<'p, F: FnMut(&serde_json::Value)> {
    engine: Engine<'p>,
    rec: StepRecord<'p>,
    steps: Vec<serde_json::Value>,
    emit_step: F,
    /// What happened since the last timed line, for the expectations.
    since_fired: Vec<(NetId, u32)>,
    since_calls: Vec<(ProgramId, FunctionId, Vec<Value>)>,
    last_unused: bool,
}

impl<F: FnMut(&serde_json::Value)> Runner<'_, F> {
    fn collect(&mut self) {
        self.since_fired.extend(self.rec.fired.iter().copied());
        self.since_calls.append(&mut self.rec.calls);
    }

    /// Processes the queue, one JSON line per step.
    fn process(&mut self) {
        while let Some(step) = self.engine.step(&mut self.rec) {
            self.collect();
            self.last_unused = step.outcome == StepOutcome::Unused;
            let outcome = match step.outcome {
                StepOutcome::Processed => "processed",
                StepOutcome::Unused => "unused",
                StepOutcome::RefusedAfterCatastrophic => "refused after a catastrophic event",
            };
            let taken = self.rec.taken.take();
            self.record(taken, outcome);
        }
    }

    fn record(&mut self, event: Option<(String, Vec<Value>)>, outcome: &str) {
        let marking: serde_json::Map<String, serde_json::Value> = self
            .engine
            .marking()
            .into_iter()
            .map(|(n, places)| (n, places.into()))
            .collect();
        let fired = self.rec.fired_names();
        let (name, params) = match &event {
            Some((n, ps)) => (Some(n.as_str()), ps.iter().map(Value::to_json).collect()),
            None => (None, Vec::new()),
        };
        let doc = serde_json::json!({
            "time": self.engine.now() as f64 / 1e6,
            "event": name,
            "params": params,
            "outcome": outcome,
            "fired": fired,
            "actions": self.rec.actions,
            "marking": marking,
        });
        (self.emit_step)(&doc);
        self.steps.push(doc);
        self.rec.fired.clear();
        self.rec.actions.clear();
    }
}

/// Whether an expectation holds, what it expects, and what was found.
fn check(
    p: &CompiledProject,
    engine: &Engine,
    what: &Expectation,
    fired: &[(NetId, u32)],
    calls: &[(ProgramId, FunctionId, Vec<Value>)],
    last_unused: bool,
) -> (bool, String, String) {
    let marking_text = || {
        engine
            .marking()
            .into_iter()
            .map(|(n, pl)| format!("{n}{{{}}}", pl.join(", ")))
            .collect::<Vec<_>>()
            .join(" ")
    };
    match what {
        Expectation::Name(net, name) if net == "global" => {
            let g = p.globals.iter().position(|g| &g.name == name).unwrap_or(0) as u32;
            (
                engine.is_marked(0, PlaceRef::Global(g)),
                format!("global place {name} marked"),
                format!("marking {}", marking_text()),
            )
        }
        Expectation::Name(net, name) => {
            let n = p.net_id(net).unwrap_or(0);
            let decl = &p.nets[n as usize];
            if let Some(i) = decl.places.iter().position(|x| &x.name == name) {
                (
                    engine.is_marked(n, PlaceRef::Local(i as u32)),
                    format!("place {net}.{name} marked"),
                    format!("marking {}", marking_text()),
                )
            } else {
                let t = decl
                    .transitions
                    .iter()
                    .position(|x| &x.name == name)
                    .unwrap_or(0) as u32;
                let names: Vec<String> = fired
                    .iter()
                    .map(|&(fn_, ft)| transition_name(p, fn_, ft))
                    .collect();
                (
                    fired.contains(&(n, t)),
                    format!("transition {net}.{name} fired since the last event"),
                    if names.is_empty() {
                        "nothing fired".to_string()
                    } else {
                        format!("fired {}", names.join(", "))
                    },
                )
            }
        }
        Expectation::Active(net) | Expectation::Inactive(net) => {
            let active = engine.is_active(p.net_id(net).unwrap_or(0));
            let want_active = matches!(what, Expectation::Active(_));
            (
                active == want_active,
                format!(
                    "net {net} {}",
                    if want_active { "active" } else { "inactive" }
                ),
                format!("marking {}", marking_text()),
            )
        }
        Expectation::Call {
            program,
            function,
            args,
        } => {
            let shown: Vec<String> = calls
                .iter()
                .map(|(pr, f, a)| call_text(p, *pr, *f, a))
                .collect();
            let holds = calls.iter().any(|(pr, f, a)| {
                let x = &p.programs[*pr as usize];
                x.name == *program
                    && x.functions[*f as usize].name == *function
                    && a.len() == args.len()
                    && a.iter()
                        .zip(args)
                        .all(|(v, e)| e.as_ref().is_none_or(|e| e == v))
            });
            let want: Vec<String> = args
                .iter()
                .map(|a| a.as_ref().map(Value::literal).unwrap_or_else(|| "_".into()))
                .collect();
            (
                holds,
                format!("call {program}.{function}({})", want.join(", ")),
                if shown.is_empty() {
                    "no call since the last event".to_string()
                } else {
                    format!("calls {}", shown.join(", "))
                },
            )
        }
        Expectation::Unused => (
            last_unused,
            "the last event unused".to_string(),
            if last_unused {
                "unused"
            } else {
                "it was processed"
            }
            .to_string(),
        ),
    }
}
