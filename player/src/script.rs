//! Missions as unit tests: `petrel run DIR --script FILE`.
//!
//! No process, virtual time. A script is a timeline of events and expectations:
//!
//! ```text
//! # the nominal flight
//! 0.0 start_mission
//! expect MISSION.rolling            # a place marked (or a transition fired since the line)
//! expect call GUI.roll()            # a call made since the last timed line (`_`: any argument)
//! expect processed                  # what became of the line's event (or `unused`, `refused`)
//! expect never MISSION.landed and global.in_flight   # now and after every later step
//! 12.5 payload_failure("camera")
//! expect not MISSION.transiting     # the opposite
//! expect inactive MISSION           # or `expect active NET`
//! expect 2 calls DEC.replan_without(_) since start
//! expect calls PLD.stop_payload() then DEC.replan_without("camera")
//! expect emit replanned             # an event emitted by a net
//! expect timer dec_answer expires at 22.5
//! 40 wait                           # let time pass: timers expire
//! ```
//!
//! Each step prints as one JSON line (time, the script line, event, parameters, outcome and
//! the reason of a refusal, fired transitions, actions, running timers, the marking of every
//! active net). Timers fire in virtual time, in deadline order. The format is documented in
//! docs/scripts.md; the expectations are read and checked in [`crate::expect`].

use crate::engine::{Engine, Micros, Refusal};
use crate::expect::{check, holds, marking_text, Observed};
pub use crate::expect::{Expectation, Item, Since};
use crate::record::{Outcome, StepRecord};
use petrel_diag::report::Diagnostics;
use petrel_diag::source::FileId;
use petrel_nets::compiled::{
    CompiledProject, EventId, FunctionId, NetId, ProgramId, StateFormula, Value,
};
use petrel_nets::model::Action;

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
    /// A check on what happened since the last timed line, or on the state.
    Expect {
        /// Negated (`expect not ...`).
        not: bool,
        /// What is expected.
        what: Expectation,
    },
}

/// A script with the line number of each line.
#[derive(Clone, Debug, PartialEq)]
pub struct Script {
    /// (line number, line).
    pub lines: Vec<(usize, Line)>,
}

/// The last timed line read, for the expectations on its event's outcome.
#[derive(Clone, Copy)]
enum LastTimed {
    /// None yet: only the start happened.
    None,
    /// A `wait` (no event) at this line.
    Wait(usize),
    /// A line with an event.
    Event,
    /// A line that did not read (already reported: no second error about it).
    Unknown,
}

/// A line of a script that does not read.
#[derive(Clone, Debug, PartialEq)]
pub struct ScriptError {
    /// The line, from 1.
    pub line: usize,
    /// The column, from 1, in characters: where the name or word the message is about starts
    /// (else the start of what follows `expect`, or of the timed line).
    pub column: usize,
    /// What is wrong, and what to write.
    pub message: String,
}

impl std::fmt::Display for ScriptError {
    /// `LINE:COLUMN: message`, to follow a file name.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}:{}: {}", self.line, self.column, self.message)
    }
}

/// Reads a script; every line that does not read is reported.
pub fn parse_script(text: &str, project: &CompiledProject) -> Result<Script, Vec<ScriptError>> {
    let mut lines = Vec::new();
    let mut errors = Vec::new();
    let mut last_time = 0.0f64;
    let mut last_timed = LastTimed::None;
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
        let expect = line
            .strip_prefix("expect")
            .filter(|r| r.is_empty() || r.starts_with(char::is_whitespace));
        let start = raw.len() - raw.trim_start().len();
        let body = match expect {
            Some(rest) => start + line.len() - rest.trim_start().len(),
            None => start,
        };
        let result = if let Some(rest) = expect {
            parse_expect(rest.trim(), project).and_then(|(not, what)| {
                outcome_has_event(&what, last_timed)?;
                Ok(Line::Expect { not, what })
            })
        } else {
            let timed = parse_timed(line, project, &mut last_time);
            last_timed = match &timed {
                Ok(Line::At { event: None, .. }) => LastTimed::Wait(n),
                Ok(_) => LastTimed::Event,
                Err(_) => LastTimed::Unknown,
            };
            timed
        };
        match result {
            Ok(l) => lines.push((n, l)),
            Err(message) => errors.push(ScriptError {
                line: n,
                column: column(raw, body, &message),
                message,
            }),
        }
    }
    if errors.is_empty() {
        Ok(Script { lines })
    } else {
        Err(errors)
    }
}

/// The column (from 1, in characters) a message about `raw` points at: the first name or word
/// the message quotes in backticks, where it stands in the line at or after byte `body`; else
/// `body`.
fn column(raw: &str, body: usize, message: &str) -> usize {
    let quoted = message.split('`').nth(1).filter(|q| !q.is_empty());
    let at = quoted
        .and_then(|q| raw.get(body..)?.find(q).map(|i| body + i))
        .unwrap_or(body);
    raw[..at].chars().count() + 1
}

/// `expect processed`/`unused`/`refused` speak of the last timed line's event: there must be
/// one, or the expectation could only fail.
fn outcome_has_event(what: &Expectation, last: LastTimed) -> Result<(), String> {
    let Expectation::Outcome(o) = what else {
        return Ok(());
    };
    match last {
        LastTimed::None => Err(format!(
            "`expect {o}` checks the event of the last timed line, and there is none yet"
        )),
        LastTimed::Wait(w) => Err(format!(
            "`expect {o}` checks the event of the last timed line, and line {w} is a `wait`: \
             it sends no event"
        )),
        LastTimed::Event | LastTimed::Unknown => Ok(()),
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
        return Err(crate::expect::unknown_event(&event.text, p));
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
    if rest.is_empty() {
        return Err("`expect` alone: say what is expected (docs/scripts.md lists it)".into());
    }
    crate::expect::parse_expect(rest, p)
}

/// What a run produced: JSON lines, and the first failed expectation.
pub struct RunOutcome {
    /// One JSON document per step.
    pub steps: Vec<serde_json::Value>,
    /// `(line, message)` of the first failed expectation.
    pub failure: Option<(usize, String)>,
}

/// Runs a script on a fresh engine. `emit_step` receives each JSON line as it is produced.
///
/// The run stops at the first failed expectation: an `expect` line that does not hold, or an
/// `expect always`/`expect never` broken by a later step (reported with the `expect` line).
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
        line: None,
        fired: Vec::new(),
        calls: Vec::new(),
        calls_from: 0,
        emits: Vec::new(),
        emits_from: 0,
        refusals: Vec::new(),
        refusals_from: 0,
        outcome: None,
        awaiting: false,
        always: Vec::new(),
        failure: None,
    };
    r.engine.start(0, &mut r.rec);
    r.collect();
    r.record(None, "start", None);
    // What the start queued (events emitted by immediate transitions, invariants already
    // broken) happens at time 0, not at the first line's time.
    r.process();
    for (n, line) in &script.lines {
        if r.failure.is_some() {
            break;
        }
        match line {
            Line::At { time, event } => r.at(*n, *time, event.as_ref()),
            Line::Expect { not, what } => r.expect(*n, *not, what),
        }
    }
    RunOutcome {
        steps: r.steps,
        failure: r.failure,
    }
}

struct Runner<'p, F: FnMut(&serde_json::Value)> {
    engine: Engine<'p>,
    rec: StepRecord<'p>,
    steps: Vec<serde_json::Value>,
    emit_step: F,
    /// The last timed line, if any: the steps it causes carry its number.
    line: Option<usize>,
    /// Transitions fired since the last timed line.
    fired: Vec<(NetId, u32)>,
    /// Every call since the start, and where the last timed line's calls begin.
    calls: Vec<(ProgramId, FunctionId, Vec<Value>)>,
    calls_from: usize,
    /// Every emission since the start, and where the last timed line's emissions begin.
    emits: Vec<(EventId, Vec<Value>)>,
    emits_from: usize,
    /// Every refused step since the start (event, reason), and where the last timed line's
    /// begin.
    refusals: Vec<(EventId, String)>,
    refusals_from: usize,
    /// The last timed line's event, what became of it, and why if it was refused.
    outcome: Option<(String, Outcome, Option<String>)>,
    /// The last timed line's event was queued and its step is the next one.
    awaiting: bool,
    /// `expect always`/`never` in force: (line, formula, text).
    always: Vec<(usize, StateFormula, String)>,
    /// The first failed expectation; the run stops there.
    failure: Option<(usize, String)>,
}

impl<F: FnMut(&serde_json::Value)> Runner<'_, F> {
    /// A timed line: the timers due before `time` expire, each at its own time, then the
    /// event (if any) is submitted and processed with whatever it causes.
    fn at(&mut self, n: usize, time: f64, event: Option<&(String, Vec<Value>)>) {
        self.line = Some(n);
        self.fired.clear();
        self.calls_from = self.calls.len();
        self.emits_from = self.emits.len();
        self.refusals_from = self.refusals.len();
        self.outcome = None;
        let target = (time * 1e6).round() as Micros;
        while let Some(d) = self.engine.next_deadline().filter(|&d| d <= target) {
            self.engine.advance_to(d);
            self.process();
            if self.failure.is_some() {
                return;
            }
        }
        self.engine.advance_to(target);
        self.process();
        let Some((name, params)) = event else {
            return;
        };
        if self.failure.is_some() {
            return;
        }
        match self.engine.submit_named(name, params.clone()) {
            Ok(()) => {
                // The queue is empty (processed above): the next step is this event's.
                self.awaiting = true;
                self.process();
            }
            Err(refusal) => {
                let reason = refusal.to_string();
                if let Some(e) = self.engine.project().event_id(name) {
                    self.refusals.push((e, reason.clone()));
                }
                self.outcome = Some((name.clone(), Outcome::Refused, Some(reason.clone())));
                self.record(
                    Some((name.clone(), params.clone())),
                    Outcome::Refused.name(),
                    Some(reason),
                );
            }
        }
    }

    /// An `expect` line: checked now; `always`/`never` are kept and checked after each step.
    fn expect(&mut self, n: usize, not: bool, what: &Expectation) {
        let seen = Observed {
            engine: &self.engine,
            line: self.line,
            fired: &self.fired,
            calls: &self.calls,
            calls_from: self.calls_from,
            emits: &self.emits,
            emits_from: self.emits_from,
            outcome: self
                .outcome
                .as_ref()
                .map(|(e, o, r)| (e.as_str(), *o, r.as_deref())),
            refusals: &self.refusals,
            refusals_from: self.refusals_from,
        };
        if let Err(message) = check(what, not, &seen) {
            self.failure = Some((n, message));
            return;
        }
        if let Expectation::Always { formula, text } = what {
            self.always.push((n, formula.clone(), text.clone()));
        }
    }

    fn collect(&mut self) {
        self.fired.extend(self.rec.fired.iter().copied());
        self.calls.append(&mut self.rec.calls);
        self.emits.append(&mut self.rec.emits);
    }

    /// Processes the queue, one JSON line per step, until it is empty or an expectation fails.
    fn process(&mut self) {
        while self.failure.is_none() {
            let Some(step) = self.engine.step(&mut self.rec) else {
                break;
            };
            self.collect();
            let outcome = Outcome::of(step.outcome);
            let name = &self.engine.project().events[step.event as usize].name;
            let reason = (outcome == Outcome::Refused)
                .then(|| Refusal::AfterCatastrophic(name.clone()).to_string());
            if let Some(r) = &reason {
                self.refusals.push((step.event, r.clone()));
            }
            if std::mem::take(&mut self.awaiting) {
                self.outcome = Some((name.clone(), outcome, reason.clone()));
            }
            let taken = self.rec.taken.take();
            self.record(taken, outcome.name(), reason);
        }
    }

    /// Prints one step's JSON line, then checks the `always`/`never` expectations on the
    /// state it left.
    fn record(
        &mut self,
        event: Option<(String, Vec<Value>)>,
        outcome: &str,
        reason: Option<String>,
    ) {
        let marking: serde_json::Map<String, serde_json::Value> = self
            .engine
            .marking()
            .into_iter()
            .map(|(n, places)| (n, places.into()))
            .collect();
        let p = self.engine.project();
        let timers: serde_json::Map<String, serde_json::Value> = self
            .engine
            .deadlines()
            .iter()
            .enumerate()
            .filter_map(|(t, d)| d.map(|d| (p.timers[t].name.clone(), (d as f64 / 1e6).into())))
            .collect();
        let fired = self.rec.fired_names();
        let (name, params) = match &event {
            Some((n, ps)) => (Some(n.as_str()), ps.iter().map(Value::to_json).collect()),
            None => (None, Vec::new()),
        };
        let time = self.engine.now() as f64 / 1e6;
        let doc = serde_json::json!({
            "time": time,
            "line": self.line,
            "event": name,
            "params": params,
            "outcome": outcome,
            "reason": reason,
            "fired": fired,
            "actions": self.rec.actions,
            "cascade_stopped": self.rec.cascade_stopped.map(|(steps, dropped)| {
                serde_json::json!({"steps": steps, "dropped": dropped})
            }),
            "timers": timers,
            "marking": marking,
        });
        (self.emit_step)(&doc);
        self.steps.push(doc);
        self.rec.clear();
        if self.failure.is_some() {
            return;
        }
        let broken = self
            .always
            .iter()
            .find(|(_, f, _)| !holds(&self.engine, f))
            .map(|(n, _, text)| (*n, text.clone()));
        if let Some((n, text)) = broken {
            let by = match (name, self.line) {
                (Some(e), Some(l)) => format!("the step of `{e}` (timed line {l})"),
                (Some(e), None) => format!("the step of `{e}`"),
                (None, _) => "the start".to_string(),
            };
            self.failure = Some((
                n,
                format!(
                    "expected {text} (from line {n} on)\n  found: broken at {time} by {by}: marking {}",
                    marking_text(&self.engine)
                ),
            ));
        }
    }
}
