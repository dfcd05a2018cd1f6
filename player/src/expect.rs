//! The expectations of scripts: what an `expect` line says, read against the project, and
//! whether it holds in what a run saw.
//!
//! ```text
//! expect [not] NET.place | NET.transition | global.place     marked / fired since the line
//! expect [not] active NET | inactive NET
//! expect [not] processed | unused | refused                  the last timed line's event
//! expect [not] refused EVENT [since start]                   any step of EVENT refused
//! expect always FORMULA | never FORMULA                      now and after every later step
//! expect [not] timer NAME [expires at SECONDS]               running (with that deadline)
//! expect [not] call P.f(args) [since start]                  at least one such call
//! expect [not] N calls P.f(args) [since start]               exactly N such calls
//! expect [not] calls P.f(args) then P.g(args)... [since start]   in that order
//! expect [not] emit EVENT(args) / N emits ... / emits ... then ...   the same for emissions
//! ```
//!
//! Calls and emissions are counted since the last timed line (what its timers and its event
//! caused), or since the start with `since start`. docs/scripts.md is the reference.

use crate::engine::{Engine, Micros};
use crate::record::{call_text, transition_name, Outcome};
use petrel_diag::report::Diagnostics;
use petrel_diag::source::FileId;
use petrel_nets::compiled::{
    CompiledProject, EventId, FunctionId, NetId, PlaceRef, ProgramId, StateFormula, TimerId, Value,
};
use petrel_nets::model::{Action, Expr, Type};

/// What an `expect` line checks.
#[derive(Clone, Debug, PartialEq)]
pub enum Expectation {
    /// `NET.name` or `global.name`: a place marked, or a transition fired since the last timed
    /// line.
    Name(String, String),
    /// `active NET`.
    Active(String),
    /// `inactive NET`.
    Inactive(String),
    /// `processed`, `unused`, `refused`: what became of the last timed line's event.
    Outcome(Outcome),
    /// `refused EVENT`: a step of this event was refused since the last timed line (or the
    /// start): the line's own event, a timer's, one a net emitted or the engine raised.
    Refused {
        /// The event.
        event: EventId,
        /// Where counting starts.
        since: Since,
    },
    /// `call P.f(args)` or `emit EVENT(args)`: at least one since the last timed line (or the
    /// start).
    Seen {
        /// The call or emission looked for.
        item: Item,
        /// Where counting starts.
        since: Since,
    },
    /// `N calls P.f(args)` or `N emits EVENT(args)`: exactly `count` of them.
    Count {
        /// How many are expected.
        count: u64,
        /// The call or emission counted.
        item: Item,
        /// Where counting starts.
        since: Since,
    },
    /// `calls A then B ...` or `emits a then b ...`: these happened in this order (others may
    /// come between).
    Order {
        /// The calls or emissions, in the expected order; all of one kind.
        items: Vec<Item>,
        /// Where counting starts.
        since: Since,
    },
    /// `timer NAME` (running) or `timer NAME expires at SECONDS` (running, with that deadline).
    Timer {
        /// The timer.
        timer: TimerId,
        /// The deadline expected, microseconds since the start.
        expires: Option<Micros>,
    },
    /// `always FORMULA` or `never FORMULA`: holds now and after every later step.
    Always {
        /// What must hold (`never F` is kept as `not F`).
        formula: StateFormula,
        /// The line as written after `expect`, normalised (`always ...` / `never ...`), for
        /// messages.
        text: String,
    },
}

/// Where counting starts for the expectations on calls and emissions.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Since {
    /// Since the last timed line (the default): what its timers and its event caused.
    LastLine,
    /// Since the start of the script (`since start`).
    Start,
}

/// One call or emission an expectation looks for; a `None` argument is `_` (anything).
#[derive(Clone, Debug, PartialEq)]
pub enum Item {
    /// `P.f(args)`.
    Call {
        /// The program.
        program: ProgramId,
        /// Its function.
        function: FunctionId,
        /// One per parameter.
        args: Vec<Option<Value>>,
    },
    /// `EVENT(args)`, or `EVENT` alone: any parameters.
    Emit {
        /// The event.
        event: EventId,
        /// One per parameter; `None` when the line gives no parentheses.
        args: Option<Vec<Option<Value>>>,
    },
}

/// The kind of item a word names: `call`/`calls` or `emit`/`emits`.
#[derive(Clone, Copy, PartialEq)]
enum Kind {
    Call,
    Emit,
}

impl Kind {
    fn of(word: &str) -> Option<Kind> {
        match word {
            "call" | "calls" => Some(Kind::Call),
            "emit" | "emits" => Some(Kind::Emit),
            _ => None,
        }
    }

    fn plural(self) -> &'static str {
        match self {
            Kind::Call => "calls",
            Kind::Emit => "emits",
        }
    }
}

/// `text` without its first word if that word is `word` (followed by a space or a tab).
fn strip_word<'a>(text: &'a str, word: &str) -> Option<&'a str> {
    let rest = text.strip_prefix(word)?;
    rest.starts_with(char::is_whitespace)
        .then(|| rest.trim_start())
}

/// Reads what follows `expect`: `(negated, expectation)`, or a message for the line.
pub fn parse_expect(rest: &str, p: &CompiledProject) -> Result<(bool, Expectation), String> {
    let rest = rest.trim();
    let (not, rest) = match strip_word(rest, "not") {
        Some(r) => (true, r),
        None => (false, rest),
    };
    if not && strip_word(rest, "not").is_some() {
        return Err("`not not` does not read: write the expectation without both".into());
    }
    // A keyword with nothing after it: say what it needs rather than that nothing matched.
    let needs = match rest {
        "not" => Some("an expectation after it, such as `expect not MISSION.landed`"),
        "always" | "never" => Some("a formula, such as `MISSION.landed and not global.in_flight`"),
        "timer" => Some("a timer: `timer NAME` or `timer NAME expires at SECONDS`"),
        "active" | "inactive" => Some("a net, such as `MISSION`"),
        "call" | "calls" => Some("a call, such as `GUI.roll()`"),
        "emit" | "emits" => Some("an event, such as `name` or `name(1, _)`"),
        _ => None,
    };
    if let Some(needs) = needs {
        return Err(format!("`expect {rest}` needs {needs}"));
    }
    if let Some(o) = Outcome::from_name(rest) {
        return Ok((not, Expectation::Outcome(o)));
    }
    if let Some(text) = strip_word(rest, "refused") {
        return parse_refused(text, p).map(|what| (not, what));
    }
    for (word, never) in [("always", false), ("never", true)] {
        if let Some(text) = strip_word(rest, word) {
            if not {
                return Err(format!(
                    "`not {word}` does not read: write `expect {}` or put `not` in the formula",
                    if never { "always ..." } else { "never ..." }
                ));
            }
            return parse_always(text, never, p).map(|what| (false, what));
        }
    }
    if let Some(text) = strip_word(rest, "timer") {
        return parse_timer(text, p).map(|what| (not, what));
    }
    if let Some(net) = strip_word(rest, "active") {
        return known_net(p, net).map(|n| (not, Expectation::Active(n)));
    }
    if let Some(net) = strip_word(rest, "inactive") {
        return known_net(p, net).map(|n| (not, Expectation::Inactive(n)));
    }
    // `N calls ...`, `calls ... then ...`, `call ...`, and the same for emits.
    let first = rest.split_whitespace().next().unwrap_or("");
    let (count, body) = if first.starts_with(|c: char| c.is_ascii_digit() || c == '-' || c == '+') {
        let n: u64 = first
            .parse()
            .map_err(|_| format!("`{first}` is not a count (a whole number, 0 or more)"))?;
        (Some(n), rest[first.len()..].trim_start())
    } else {
        (None, rest)
    };
    let word = body.split_whitespace().next().unwrap_or("");
    if let Some(kind) = Kind::of(word) {
        return parse_items(kind, count, body[word.len()..].trim_start(), p).map(|w| (not, w));
    }
    if count.is_some() {
        let found = if body.is_empty() {
            "nothing".to_string()
        } else {
            format!("`{body}`")
        };
        return Err(format!(
            "a count is followed by `calls P.f(args)` or `emits EVENT(args)`, found {found}"
        ));
    }
    parse_name(rest, p).map(|w| (not, w))
}

fn known_net(p: &CompiledProject, net: &str) -> Result<String, String> {
    let net = net.trim();
    p.net_id(net).map(|_| net.to_string()).ok_or_else(|| {
        let hint = suggest(net, p.nets.iter().map(|n| n.name.as_str()));
        format!("unknown net `{net}`: {hint}")
    })
}

/// The "did you mean" hint for a name of the project a script misspelt.
fn suggest<'a>(name: &str, declared: impl IntoIterator<Item = &'a str>) -> String {
    petrel_diag::names::suggest(name, declared, petrel_diag::names::Candidates::Declared)
}

/// `NET.place`, `NET.transition` or `global.place`.
fn parse_name(rest: &str, p: &CompiledProject) -> Result<Expectation, String> {
    let Some((net, name)) = rest.split_once('.') else {
        return Err(format!(
            "expected `NET.place`, `NET.transition`, `global.place`, `active NET`, `inactive NET`, \
             `processed`, `unused`, `refused`, `always FORMULA`, `never FORMULA`, `timer NAME`, \
             `call P.f(...)`, `emit EVENT(...)`, `N calls ...`, `calls ... then ...`, found `{rest}`"
        ));
    };
    if net == "global" {
        if !p.globals.iter().any(|g| g.name == name) {
            let hint = suggest(name, p.globals.iter().map(|g| g.name.as_str()));
            return Err(format!("no global place `{name}`: {hint}"));
        }
    } else {
        let n = known_net(p, net)?;
        let Some(id) = p.net_id(&n) else {
            return Err(format!("unknown net `{net}`"));
        };
        let decl = &p.nets[id as usize];
        if !decl.places.iter().any(|x| x.name == name)
            && !decl.transitions.iter().any(|x| x.name == name)
        {
            let names = decl.places.iter().map(|x| x.name.as_str());
            let hint = suggest(
                name,
                names.chain(decl.transitions.iter().map(|x| x.name.as_str())),
            );
            return Err(format!(
                "net `{net}` has no place or transition `{name}`: {hint}"
            ));
        }
    }
    Ok(Expectation::Name(net.to_string(), name.to_string()))
}

/// `always FORMULA` / `never FORMULA`, in the language of the manifest's invariants.
fn parse_always(text: &str, never: bool, p: &CompiledProject) -> Result<Expectation, String> {
    let mut d = Diagnostics::new();
    // The code never leaves this function: the problems become the script line's message.
    let Some(formula) = petrel_nets::formula::parse_formula(FileId(0), 0, text, "E0108", &mut d)
    else {
        let why: Vec<String> = d.iter().map(|x| x.message.clone()).collect();
        return Err(format!(
            "`{text}` is not a formula ({}); a formula combines `NET.place`, `global.place` and \
             `active NET` with `not`, `and`, `or`, `implies` and parentheses",
            why.join("; ")
        ));
    };
    let mut unknown = Vec::new();
    let resolved = petrel_nets::check::resolve_formula(p, &formula, &mut |n, what| {
        unknown.push(format!("unknown {what} `{n}`"));
    });
    let Some(resolved) = resolved.filter(|_| unknown.is_empty()) else {
        return Err(format!(
            "{} in the formula (write `NET.place`, `global.place` or `active NET`)",
            unknown.join(", ")
        ));
    };
    let shown = petrel_nets::fmt::format_formula(&formula);
    Ok(if never {
        Expectation::Always {
            formula: StateFormula::Not(Box::new(resolved)),
            text: format!("never {shown}"),
        }
    } else {
        Expectation::Always {
            formula: resolved,
            text: format!("always {shown}"),
        }
    })
}

/// `EVENT` or `EVENT since start`, after `refused`.
fn parse_refused(text: &str, p: &CompiledProject) -> Result<Expectation, String> {
    let (name, since) = match text.split_whitespace().collect::<Vec<_>>().as_slice() {
        [name] => (*name, Since::LastLine),
        [name, "since", "start"] => (*name, Since::Start),
        _ => {
            return Err(format!(
                "expected `refused`, `refused EVENT` or `refused EVENT since start`, found \
                 `refused {text}`"
            ))
        }
    };
    let event = p.event_id(name).ok_or_else(|| unknown_event(name, p))?;
    Ok(Expectation::Refused { event, since })
}

/// `unknown event `x``, with the close name the script may have meant.
pub(crate) fn unknown_event(name: &str, p: &CompiledProject) -> String {
    let hint = suggest(name, p.events.iter().map(|e| e.name.as_str()));
    format!("unknown event `{name}`: {hint}")
}

/// `NAME` or `NAME expires at SECONDS`.
fn parse_timer(text: &str, p: &CompiledProject) -> Result<Expectation, String> {
    let words: Vec<&str> = text.split_whitespace().collect();
    let (name, expires) = match words.as_slice() {
        [name] => (*name, None),
        [name, "expires", "at", t] => (*name, Some(seconds(t)?)),
        _ => {
            return Err(format!(
                "expected `timer NAME` or `timer NAME expires at SECONDS`, found `timer {text}`"
            ))
        }
    };
    let timer = p
        .timers
        .iter()
        .position(|t| t.name == name)
        .ok_or_else(|| {
            let hint = suggest(name, p.timers.iter().map(|t| t.name.as_str()));
            format!("unknown timer `{name}`: {hint}")
        })?;
    Ok(Expectation::Timer {
        timer: timer as TimerId,
        expires,
    })
}

/// A deadline in seconds, as microseconds: read as a timed line's time is
/// ([`crate::script::parse_time`]), so that what a line may say and a deadline may be agree.
fn seconds(text: &str) -> Result<Micros, String> {
    let s = crate::script::parse_time(text)?;
    Ok((s * 1e6).round() as Micros)
}

/// The items after `call`/`calls`/`emit`/`emits`, with an optional count before and an
/// optional `since start` after.
fn parse_items(
    kind: Kind,
    count: Option<u64>,
    text: &str,
    p: &CompiledProject,
) -> Result<Expectation, String> {
    let (text, since) = match text.trim_end().strip_suffix("since start") {
        Some(t) if t.is_empty() || t.ends_with(char::is_whitespace) => (t.trim_end(), Since::Start),
        _ => (text.trim_end(), Since::LastLine),
    };
    let parts = split_then(text);
    let mut items = Vec::new();
    for part in &parts {
        // `calls A then B` or `call A then call B`: a repeated keyword is allowed, and must be
        // of the same kind.
        let first = part.split_whitespace().next().unwrap_or("");
        let part = match Kind::of(first) {
            Some(k) if k == kind => part[first.len()..].trim_start(),
            Some(_) => {
                return Err(format!(
                    "an order lists {} only, found `{first}` after `then`",
                    kind.plural()
                ))
            }
            None => part,
        };
        if part.is_empty() {
            return Err(format!(
                "expected {} after `{}` or `then`",
                match kind {
                    Kind::Call => "a call such as `GUI.roll()`",
                    Kind::Emit => "an event such as `name` or `name(1, _)`",
                },
                kind.plural()
            ));
        }
        items.push(match kind {
            Kind::Call => parse_call(part, p)?,
            Kind::Emit => parse_emit(part, p)?,
        });
    }
    match (count, items.len()) {
        (_, 0) => Err(format!(
            "expected what is expected after `{}`",
            kind.plural()
        )),
        (Some(count), 1) => Ok(Expectation::Count {
            count,
            item: items.remove(0),
            since,
        }),
        (Some(_), _) => Err(format!(
            "a count goes with one call or emission, not with an order (`then`): write \
             `expect N {} ...` and `expect {} ... then ...` on two lines",
            kind.plural(),
            kind.plural()
        )),
        (None, 1) => Ok(Expectation::Seen {
            item: items.remove(0),
            since,
        }),
        (None, _) => Ok(Expectation::Order { items, since }),
    }
}

/// `text` cut at each word `then` that stands outside text literals, lists and parentheses.
fn split_then(text: &str) -> Vec<&str> {
    let mut parts = Vec::new();
    let (mut depth, mut in_text, mut escaped) = (0i32, false, false);
    let mut start = 0;
    let bytes = text.as_bytes();
    for (i, c) in text.char_indices() {
        if in_text {
            match c {
                '\\' if !escaped => escaped = true,
                '"' if !escaped => in_text = false,
                _ => escaped = false,
            }
            continue;
        }
        match c {
            '"' => in_text = true,
            '(' | '[' => depth += 1,
            ')' | ']' => depth -= 1,
            't' if depth == 0
                && text[i..].starts_with("then")
                && (i == 0 || bytes[i - 1].is_ascii_whitespace())
                && bytes.get(i + 4).is_none_or(|b| b.is_ascii_whitespace()) =>
            {
                parts.push(text[start..i].trim());
                start = i + 4;
            }
            _ => {}
        }
    }
    parts.push(text[start..].trim());
    parts
}

/// The arguments of an expected call or emission: literals of the declared types, or `_`.
fn expected_args(
    args: &[Expr],
    params: &[(String, Type)],
    what: &str,
) -> Result<Vec<Option<Value>>, String> {
    if params.len() != args.len() {
        return Err(format!(
            "`{what}` takes {} argument(s), {} given",
            params.len(),
            args.len()
        ));
    }
    let mut expected = Vec::new();
    for ((name, ty), a) in params.iter().zip(args) {
        if matches!(a, Expr::Var(n) if n.text == "_") {
            expected.push(None);
            continue;
        }
        match petrel_nets::check::literal(a, *ty) {
            Some(v) => expected.push(Some(v)),
            None => {
                return Err(format!(
                    "argument `{name}` of `{what}` is {ty}; write a {ty} literal or `_`"
                ))
            }
        }
    }
    Ok(expected)
}

/// The first problem the action parser found, for a message.
fn first_problem(d: &Diagnostics) -> String {
    d.iter()
        .next()
        .map(|x| format!(": {}", x.message))
        .unwrap_or_default()
}

/// `P.f(args)`.
fn parse_call(text: &str, p: &CompiledProject) -> Result<Item, String> {
    let mut d = Diagnostics::new();
    let action = petrel_nets::syntax::parse_action(FileId(0), &format!("call {text}"), &mut d);
    let Some(Action::Call {
        program,
        function,
        args,
        ..
    }) = action.filter(|_| !d.has_errors())
    else {
        return Err(format!(
            "`{text}` is not a call such as `PROGRAM.function(1, _)`{}",
            first_problem(&d)
        ));
    };
    let prog = p
        .programs
        .iter()
        .position(|x| x.name == program.text)
        .ok_or_else(|| {
            let hint = suggest(&program.text, p.programs.iter().map(|x| x.name.as_str()));
            format!("unknown program `{program}`: {hint}")
        })?;
    let func = p.programs[prog]
        .functions
        .iter()
        .position(|f| f.name == function.text)
        .ok_or_else(|| {
            let names = p.programs[prog].functions.iter().map(|f| f.name.as_str());
            let hint = suggest(&function.text, names);
            format!("program `{program}` has no function `{function}`: {hint}")
        })?;
    let params = &p.programs[prog].functions[func].params;
    let args = expected_args(&args, params, &format!("{program}.{function}"))?;
    Ok(Item::Call {
        program: prog as ProgramId,
        function: func as FunctionId,
        args,
    })
}

/// `EVENT` or `EVENT(args)`.
fn parse_emit(text: &str, p: &CompiledProject) -> Result<Item, String> {
    let mut d = Diagnostics::new();
    let action = petrel_nets::syntax::parse_action(FileId(0), &format!("emit {text}"), &mut d);
    let Some(Action::Emit {
        event, args, to, ..
    }) = action.filter(|_| !d.has_errors())
    else {
        return Err(format!(
            "`{text}` is not an event such as `name` or `name(1, _)`{}",
            first_problem(&d)
        ));
    };
    if to.is_some() {
        return Err(format!(
            "`{text}`: the net an emission is addressed to is not checked; write the event alone"
        ));
    }
    let id = p
        .event_id(&event.text)
        .ok_or_else(|| unknown_event(&event.text, p))?;
    // No parentheses (or empty ones): any parameters.
    let args = if args.is_empty() {
        None
    } else {
        Some(expected_args(
            &args,
            &p.events[id as usize].params,
            &event.text,
        )?)
    };
    Ok(Item::Emit { event: id, args })
}

/// What a run has seen when an expectation is checked.
pub(crate) struct Observed<'a, 'p> {
    /// The engine, in the state the run reached.
    pub engine: &'a Engine<'p>,
    /// The last timed line, if any.
    pub line: Option<usize>,
    /// Transitions fired since the last timed line.
    pub fired: &'a [(NetId, u32)],
    /// Every call since the start.
    pub calls: &'a [(ProgramId, FunctionId, Vec<Value>)],
    /// Index in `calls` of the first call since the last timed line.
    pub calls_from: usize,
    /// Every emission since the start.
    pub emits: &'a [(EventId, Vec<Value>)],
    /// Index in `emits` of the first emission since the last timed line.
    pub emits_from: usize,
    /// The last timed line's event and what became of it (with the refusal's reason).
    pub outcome: Option<(&'a str, Outcome, Option<&'a str>)>,
    /// Every refused step since the start: its event and why.
    pub refusals: &'a [(EventId, String)],
    /// Index in `refusals` of the first refusal since the last timed line.
    pub refusals_from: usize,
}

/// One call or emission seen, as the item matching sees it.
enum Act<'a> {
    Call(ProgramId, FunctionId, &'a [Value]),
    Emit(EventId, &'a [Value]),
}

fn args_match(expected: &[Option<Value>], found: &[Value]) -> bool {
    expected.len() == found.len()
        && found
            .iter()
            .zip(expected)
            .all(|(v, e)| e.as_ref().is_none_or(|e| e == v))
}

impl Item {
    fn matches(&self, act: &Act) -> bool {
        match (self, act) {
            (
                Item::Call {
                    program,
                    function,
                    args,
                },
                Act::Call(pr, f, a),
            ) => program == pr && function == f && args_match(args, a),
            (Item::Emit { event, args }, Act::Emit(e, a)) => {
                event == e && args.as_ref().is_none_or(|x| args_match(x, a))
            }
            _ => false,
        }
    }

    fn kind(&self) -> Kind {
        match self {
            Item::Call { .. } => Kind::Call,
            Item::Emit { .. } => Kind::Emit,
        }
    }

    /// As written in a script: `P.f(1, _)`, `name(_)`, `name`.
    fn text(&self, p: &CompiledProject) -> String {
        let args = |a: &[Option<Value>]| {
            a.iter()
                .map(|x| x.as_ref().map(Value::literal).unwrap_or_else(|| "_".into()))
                .collect::<Vec<_>>()
                .join(", ")
        };
        match self {
            Item::Call {
                program,
                function,
                args: a,
            } => {
                let prog = &p.programs[*program as usize];
                format!(
                    "{}.{}({})",
                    prog.name,
                    prog.functions[*function as usize].name,
                    args(a)
                )
            }
            Item::Emit { event, args: a } => {
                let name = &p.events[*event as usize].name;
                match a {
                    Some(a) => format!("{name}({})", args(a)),
                    None => name.clone(),
                }
            }
        }
    }
}

/// An emission as people read it: `name` or `name(1, "x")`.
fn emit_text(p: &CompiledProject, event: EventId, args: &[Value]) -> String {
    let name = &p.events[event as usize].name;
    if args.is_empty() {
        name.clone()
    } else {
        let a: Vec<String> = args.iter().map(Value::literal).collect();
        format!("{name}({})", a.join(", "))
    }
}

impl Observed<'_, '_> {
    /// The calls or emissions in the window, oldest first.
    fn acts(&self, kind: Kind, since: Since) -> Vec<Act<'_>> {
        let whole = since == Since::Start;
        match kind {
            Kind::Call => self.calls[if whole { 0 } else { self.calls_from }..]
                .iter()
                .map(|(pr, f, a)| Act::Call(*pr, *f, a))
                .collect(),
            Kind::Emit => self.emits[if whole { 0 } else { self.emits_from }..]
                .iter()
                .map(|(e, a)| Act::Emit(*e, a))
                .collect(),
        }
    }

    /// `since line 12` or `since the start`.
    fn window(&self, since: Since) -> String {
        match (since, self.line) {
            (Since::LastLine, Some(n)) => format!("since line {n}"),
            _ => "since the start".to_string(),
        }
    }

    fn act_text(&self, act: &Act) -> String {
        let p = self.engine.project();
        match act {
            Act::Call(pr, f, a) => call_text(p, *pr, *f, a),
            Act::Emit(e, a) => emit_text(p, *e, a),
        }
    }

    /// `calls A, B since line 3`, or `no call since line 3`.
    fn listing(&self, kind: Kind, since: Since) -> String {
        let acts = self.acts(kind, since);
        if acts.is_empty() {
            let one = match kind {
                Kind::Call => "call",
                Kind::Emit => "emission",
            };
            return format!("no {one} {}", self.window(since));
        }
        let shown: Vec<String> = acts.iter().map(|a| self.act_text(a)).collect();
        format!(
            "{} {}",
            match kind {
                Kind::Call => "calls",
                Kind::Emit => "emits",
            },
            shown.join(", ")
        )
    }

    fn marking_text(&self) -> String {
        marking_text(self.engine)
    }
}

/// Whether `what` (negated if `not`) holds in what the run saw; if not, the message: what was
/// expected, then what was found.
pub(crate) fn check(what: &Expectation, not: bool, seen: &Observed) -> Result<(), String> {
    let p = seen.engine.project();
    let engine = seen.engine;
    let neg = if not { "not " } else { "" };
    let (holds, expected, found) = match what {
        Expectation::Name(net, name) if net == "global" => {
            let g = p.globals.iter().position(|g| &g.name == name).unwrap_or(0) as u32;
            (
                engine.is_marked(0, PlaceRef::Global(g)),
                format!("{neg}global place {name} marked"),
                format!("marking {}", seen.marking_text()),
            )
        }
        Expectation::Name(net, name) => {
            let n = p.net_id(net).unwrap_or(0);
            let decl = &p.nets[n as usize];
            if let Some(i) = decl.places.iter().position(|x| &x.name == name) {
                (
                    engine.is_marked(n, PlaceRef::Local(i as u32)),
                    format!("{neg}place {net}.{name} marked"),
                    format!("marking {}", seen.marking_text()),
                )
            } else {
                let t = decl
                    .transitions
                    .iter()
                    .position(|x| &x.name == name)
                    .unwrap_or(0) as u32;
                let names: Vec<String> = seen
                    .fired
                    .iter()
                    .map(|&(fn_, ft)| transition_name(p, fn_, ft))
                    .collect();
                (
                    seen.fired.contains(&(n, t)),
                    format!(
                        "{neg}transition {net}.{name} fired {}",
                        seen.window(Since::LastLine)
                    ),
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
                    "{neg}net {net} {}",
                    if want_active { "active" } else { "inactive" }
                ),
                format!("marking {}", seen.marking_text()),
            )
        }
        Expectation::Outcome(want) => {
            // The parser refuses an outcome expectation with no event before it; a run that
            // reaches one without an outcome has a bug, said as a failure rather than a panic.
            let Some((event, outcome, reason)) = seen.outcome else {
                return Err(format!(
                    "expected {neg}{want}\n  found: no event since the start or the last `wait`"
                ));
            };
            let line = seen
                .line
                .map(|n| format!(" (line {n})"))
                .unwrap_or_default();
            (
                outcome == *want,
                format!("event `{event}`{line} {neg}{want}"),
                match reason {
                    Some(r) => format!("{outcome}: {r}"),
                    None => outcome.to_string(),
                },
            )
        }
        Expectation::Refused { event, since } => {
            let from = match since {
                Since::LastLine => seen.refusals_from,
                Since::Start => 0,
            };
            let window = &seen.refusals[from..];
            let name = &p.events[*event as usize].name;
            let found: Vec<String> = window
                .iter()
                .map(|(e, why)| format!("{} ({why})", p.events[*e as usize].name))
                .collect();
            (
                window.iter().any(|(e, _)| e == event),
                format!("{neg}refused {name} {}", seen.window(*since)),
                if found.is_empty() {
                    format!("no refusal {}", seen.window(*since))
                } else {
                    format!("refused {}", found.join(", "))
                },
            )
        }
        Expectation::Seen { item, since } => {
            let acts = seen.acts(item.kind(), *since);
            let keyword = match item.kind() {
                Kind::Call => "call",
                Kind::Emit => "emit",
            };
            let window = match since {
                Since::LastLine => String::new(),
                Since::Start => " since the start".to_string(),
            };
            (
                acts.iter().any(|a| item.matches(a)),
                format!("{neg}{keyword} {}{window}", item.text(p)),
                seen.listing(item.kind(), *since),
            )
        }
        Expectation::Count { count, item, since } => {
            let acts = seen.acts(item.kind(), *since);
            let n = acts.iter().filter(|a| item.matches(a)).count() as u64;
            (
                n == *count,
                format!(
                    "{neg}{count} {} {} {}",
                    item.kind().plural(),
                    item.text(p),
                    seen.window(*since)
                ),
                format!("{n}, among {}", seen.listing(item.kind(), *since)),
            )
        }
        Expectation::Order { items, since } => {
            let kind = items.first().map_or(Kind::Call, Item::kind);
            let acts = seen.acts(kind, *since);
            // Greedy: each item matches the first act after the previous item's.
            let mut next = 0;
            let mut matched = 0;
            for item in items {
                match acts[next..].iter().position(|a| item.matches(a)) {
                    Some(k) => {
                        next += k + 1;
                        matched += 1;
                    }
                    None => break,
                }
            }
            let order: Vec<String> = items.iter().map(|i| i.text(p)).collect();
            let missing = match (matched, items.get(matched)) {
                (_, None) => String::new(),
                (0, Some(i)) => format!(" (no {})", i.text(p)),
                (m, Some(i)) => format!(" (no {} after {})", i.text(p), items[m - 1].text(p)),
            };
            (
                matched == items.len(),
                format!(
                    "{neg}{} {} in this order {}",
                    kind.plural(),
                    order.join(" then "),
                    seen.window(*since)
                ),
                format!("{}{missing}", seen.listing(kind, *since)),
            )
        }
        Expectation::Timer { timer, expires } => {
            let deadline = engine.deadlines().get(*timer as usize).copied().flatten();
            let name = &p.timers[*timer as usize].name;
            let running: Vec<String> = engine
                .deadlines()
                .iter()
                .enumerate()
                .filter_map(|(t, d)| {
                    d.map(|d| format!("{} (expires at {})", p.timers[t].name, d as f64 / 1e6))
                })
                .collect();
            (
                match expires {
                    Some(e) => deadline == Some(*e),
                    None => deadline.is_some(),
                },
                match expires {
                    Some(e) => {
                        format!("{neg}timer {name} running, expiring at {}", *e as f64 / 1e6)
                    }
                    None => format!("{neg}timer {name} running"),
                },
                if running.is_empty() {
                    format!("no timer running at {}", engine.now() as f64 / 1e6)
                } else {
                    format!("running {}", running.join(", "))
                },
            )
        }
        Expectation::Always { formula, text } => (
            holds(engine, formula),
            text.clone(),
            format!(
                "it does not hold now, at {}: marking {}",
                engine.now() as f64 / 1e6,
                seen.marking_text()
            ),
        ),
    };
    if holds == not {
        Err(format!("expected {expected}\n  found: {found}"))
    } else {
        Ok(())
    }
}

/// Whether `formula` holds in the engine's state.
pub(crate) fn holds(engine: &Engine, formula: &StateFormula) -> bool {
    engine.layout().holds(formula, engine.state())
}

/// The marking as `NET{a, b} global{c}`, for messages.
pub(crate) fn marking_text(engine: &Engine) -> String {
    engine
        .marking()
        .into_iter()
        .map(|(n, pl)| format!("{n}{{{}}}", pl.join(", ")))
        .collect::<Vec<_>>()
        .join(" ")
}
