//! The environment the verifier plays: which events may arrive in a state, with which
//! parameters, addressed to which net.
//!
//! - **Parameters.** An event is delivered once per combination of the classes of values its
//!   guards can tell apart ([`domain`]); guards it cannot decide go both ways ([`Oracle`]).
//! - **Programs' answers.** An event a function declares it answers with (`answers = [...]`)
//!   comes only after a call to that function, once per call ([`Env`]'s counters).
//! - **Internal events.** An event declared `internal = true` comes only after a net emitted
//!   it, once per emission (addressed as it was emitted).
//! - Every other event a transition waits for may come at any time.
//!
//! Counters are 0, 1 or "many": a second call (or emission) while one is outstanding makes the
//! event free from then on, which keeps the model finite and over-approximates.

use crate::compiled::{Action, Arg, CompiledProject, EventId, FunctionId, Guard, NetId, ProgramId};
use crate::semantics::{Effects, Layout};
use crate::verify::VerifyError;
use petrel_value::{Type, Value};
use std::collections::HashMap;

/// Most runs of one event delivery in one state, over the outcomes of the guards the verifier
/// cannot decide (see [`Oracle`]): beyond it the verification stops with an error.
pub const MAX_GUARD_RUNS: usize = 4096;

/// A truth value of a guard the verifier evaluates on representative parameters: known, or
/// not decidable without data it does not track.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Truth {
    True,
    False,
    Unknown,
}

impl Truth {
    fn of(b: bool) -> Truth {
        if b {
            Truth::True
        } else {
            Truth::False
        }
    }
    fn not(self) -> Truth {
        match self {
            Truth::True => Truth::False,
            Truth::False => Truth::True,
            Truth::Unknown => Truth::Unknown,
        }
    }
}

/// The outcomes of undecidable guards for one run of a delivery: the first ones replayed from
/// `prefix`, the rest taken false (and counted, so that the caller explores them true too).
#[derive(Default, Clone)]
pub(super) struct Oracle {
    pub prefix: Vec<bool>,
    pub used: usize,
}

impl Oracle {
    pub fn choose(&mut self) -> bool {
        let c = self.prefix.get(self.used).copied().unwrap_or(false);
        self.used += 1;
        c
    }

    /// The prefixes to explore after a run of `prefix` that asked `used` questions: each
    /// question answered false in that run, answered true.
    pub fn next_prefixes(prefix: &[bool], used: usize, out: &mut Vec<Vec<bool>>) {
        for k in prefix.len()..used {
            let mut next = prefix.to_vec();
            next.resize(k, false);
            next.push(true);
            out.push(next);
        }
    }
}

/// Evaluates a guard on the event's representative parameters. Comparisons of a parameter with
/// a constant are decided; what involves data the verifier does not track (two parameters of
/// the event, a parameter bound at activation) is unknown.
pub(super) fn truth(g: &Guard, params: &[Value]) -> Truth {
    match g {
        Guard::Const(b) => Truth::of(*b),
        Guard::Not(a) => truth(a, params).not(),
        Guard::And(list) => {
            let mut out = Truth::True;
            for a in list {
                match truth(a, params) {
                    Truth::False => return Truth::False,
                    Truth::Unknown => out = Truth::Unknown,
                    Truth::True => {}
                }
            }
            out
        }
        Guard::Or(list) => {
            let mut out = Truth::False;
            for a in list {
                match truth(a, params) {
                    Truth::True => return Truth::True,
                    Truth::Unknown => out = Truth::Unknown,
                    Truth::False => {}
                }
            }
            out
        }
        Guard::Value(a) => match a {
            Arg::Literal(Value::Bool(b)) => Truth::of(*b),
            Arg::EventParam(i) => match params.get(*i as usize) {
                Some(Value::Bool(b)) => Truth::of(*b),
                _ => Truth::Unknown,
            },
            _ => Truth::Unknown,
        },
        Guard::Compare(op, a, b) => {
            let known = |x: &Arg| -> Option<(Value, bool)> {
                match x {
                    Arg::Literal(v) => Some((v.clone(), false)),
                    Arg::EventParam(i) => params.get(*i as usize).map(|v| (v.clone(), true)),
                    Arg::NetParam(_) => None,
                }
            };
            match (known(a), known(b)) {
                // Two parameters of the event: representatives do not cover their relations.
                (Some((_, true)), Some((_, true))) => Truth::Unknown,
                (Some((x, _)), Some((y, _))) => Truth::of(crate::compiled::compare(*op, &x, &y)),
                _ => Truth::Unknown,
            }
        }
    }
}

/// One way the environment can deliver an event: to every net or to one, with representative
/// parameters (docs/semantics.md, "What the verifier explores").
#[derive(Clone, Debug)]
pub(super) struct Delivery {
    pub event: EventId,
    pub target: Option<NetId>,
    pub params: Vec<Value>,
    /// `event`, `event(args)`, `event to NET`, for traces.
    pub label: String,
}

/// The values a guard can tell apart for one parameter: each constant it is compared with,
/// the intervals between them for numbers (and NaN for floats), and one other value.
pub(super) fn domain(ty: Type, comparands: &[Value], used: bool) -> Vec<Value> {
    if !used && comparands.is_empty() {
        return vec![ty.neutral()];
    }
    match ty {
        Type::Bool => vec![Value::Bool(false), Value::Bool(true)],
        Type::Text => {
            let mut out: Vec<Value> = Vec::new();
            for c in comparands {
                if let Value::Text(_) = c {
                    if !out.contains(c) {
                        out.push(c.clone());
                    }
                }
            }
            let mut other = String::from("other");
            while out.contains(&Value::Text(other.clone())) {
                other.push('_');
            }
            out.push(Value::Text(other));
            out
        }
        Type::FloatList => {
            let mut out: Vec<Value> = Vec::new();
            for c in comparands {
                if let Value::FloatList(_) = c {
                    if !out.contains(c) {
                        out.push(c.clone());
                    }
                }
            }
            let mut other = Vec::new();
            while out.contains(&Value::FloatList(other.clone())) {
                other.push(0.5);
            }
            out.push(Value::FloatList(other));
            out
        }
        Type::Int | Type::Float => {
            let mut t: Vec<f64> = comparands
                .iter()
                .filter_map(|c| match c {
                    Value::Int(i) => Some(*i as f64),
                    Value::Float(f) if f.is_finite() => Some(*f),
                    _ => None,
                })
                .collect();
            t.sort_by(f64::total_cmp);
            t.dedup();
            if ty == Type::Float {
                let mut out = Vec::new();
                match (t.first(), t.last()) {
                    (Some(&lo), Some(&hi)) => {
                        out.push(lo - 1.0);
                        for (k, &x) in t.iter().enumerate() {
                            out.push(x);
                            if let Some(&y) = t.get(k + 1) {
                                out.push(x + (y - x) / 2.0);
                            }
                        }
                        out.push(hi + 1.0);
                    }
                    _ => out.push(0.0),
                }
                let mut out: Vec<Value> = out.into_iter().map(Value::Float).collect();
                out.push(Value::Float(f64::NAN));
                out
            } else {
                let mut out: Vec<i64> = Vec::new();
                match (t.first(), t.last()) {
                    (Some(&lo), Some(&hi)) => {
                        out.push((lo.ceil() as i64).saturating_sub(1));
                        for (k, &x) in t.iter().enumerate() {
                            if x.fract() == 0.0 {
                                out.push(x as i64);
                            }
                            if let Some(&y) = t.get(k + 1) {
                                let between = (x.floor() as i64).saturating_add(1);
                                if (between as f64) < y && (between as f64) > x {
                                    out.push(between);
                                }
                            }
                        }
                        out.push((hi.floor() as i64).saturating_add(1));
                    }
                    _ => out.push(0),
                }
                out.sort_unstable();
                out.dedup();
                out.into_iter().map(Value::Int).collect()
            }
        }
    }
}

/// What the guards of an event's transitions compare each of its parameters with.
fn comparands(g: &Guard, out: &mut [(Vec<Value>, bool)]) {
    match g {
        Guard::Const(_) => {}
        Guard::Not(a) => comparands(a, out),
        Guard::And(list) | Guard::Or(list) => list.iter().for_each(|a| comparands(a, out)),
        Guard::Value(Arg::EventParam(i)) => {
            if let Some(slot) = out.get_mut(*i as usize) {
                slot.1 = true;
            }
        }
        Guard::Value(_) => {}
        Guard::Compare(_, a, b) => {
            for (x, y) in [(a, b), (b, a)] {
                if let Arg::EventParam(i) = x {
                    if let Some(slot) = out.get_mut(*i as usize) {
                        slot.1 = true;
                        if let Arg::Literal(v) = y {
                            slot.0.push(v.clone());
                        }
                    }
                }
            }
        }
    }
}

/// Every delivery the environment may make: each awaited event, to every net and to each net
/// some `emit ... to` addresses it to, with each combination of its parameters' classes.
pub(super) fn deliveries(p: &CompiledProject, l: &Layout) -> Result<Vec<Delivery>, VerifyError> {
    let mut out = Vec::new();
    for e in 0..p.events.len() as EventId {
        if l.by_event[e as usize].is_empty() {
            continue;
        }
        event_deliveries(p, e, &own_comparands(p, l, e), &mut out)?;
    }
    Ok(out)
}

/// What the guards of `e`'s transitions compare each of its parameters with, and whether they
/// read it at all.
fn own_comparands(p: &CompiledProject, l: &Layout, e: EventId) -> Vec<(Vec<Value>, bool)> {
    let mut slots: Vec<(Vec<Value>, bool)> =
        vec![(Vec::new(), false); p.events[e as usize].params.len()];
    for &r in &l.by_event[e as usize] {
        let rule = &l.rules[r as usize];
        if let Some(g) = &p.nets[rule.net as usize].transitions[rule.transition as usize].guard {
            comparands(g, &mut slots);
        }
    }
    slots
}

/// The deliveries of `e` (awaited), its parameters split by `slots` ([`own_comparands`]),
/// appended to `out`.
fn event_deliveries(
    p: &CompiledProject,
    e: EventId,
    slots: &[(Vec<Value>, bool)],
    out: &mut Vec<Delivery>,
) -> Result<(), VerifyError> {
    let decl = &p.events[e as usize];
    let mut targets: Vec<Option<NetId>> = vec![None];
    for net in &p.nets {
        for t in &net.transitions {
            for a in &t.actions {
                if let Action::Emit {
                    event,
                    target: Some(n),
                    ..
                } = a
                {
                    if *event == e && !targets.contains(&Some(*n)) {
                        targets.push(Some(*n));
                    }
                }
            }
        }
    }
    let domains: Vec<Vec<Value>> = decl
        .params
        .iter()
        .zip(slots)
        .map(|((_, ty), (c, used))| domain(*ty, c, *used))
        .collect();
    let combinations: usize = domains.iter().map(Vec::len).product();
    if combinations > MAX_GUARD_RUNS {
        return Err(VerifyError::TooManyUndecidedGuards {
            event: decl.name.clone(),
        });
    }
    let shown = domains.iter().any(|d| d.len() > 1);
    let mut tuple = vec![0usize; domains.len()];
    loop {
        let params: Vec<Value> = tuple
            .iter()
            .zip(&domains)
            .map(|(&k, d)| d[k].clone())
            .collect();
        for &target in &targets {
            let mut label = decl.name.clone();
            if shown {
                label = format!(
                    "{label}({})",
                    params
                        .iter()
                        .map(Value::literal)
                        .collect::<Vec<_>>()
                        .join(", ")
                );
            }
            if let Some(n) = target {
                label = format!("{label} to {}", p.nets[n as usize].name);
            }
            out.push(Delivery {
                event: e,
                target,
                params: params.clone(),
                label,
            });
        }
        // The next combination, odometer-wise.
        let mut k = 0;
        loop {
            if k == tuple.len() {
                break;
            }
            tuple[k] += 1;
            if tuple[k] < domains[k].len() {
                break;
            }
            tuple[k] = 0;
            k += 1;
        }
        if k == tuple.len() {
            break;
        }
    }
    Ok(())
}

/// The deliveries of the awaited events of `wanted` that start the cascade check
/// ([`super::cascade`]). A parameter's classes also tell apart what the guards of the events
/// it is passed on to (`on e(x) ... emit f(x)`, and on from `f`) compare it with, so that a
/// value handed along a cascade is one value for every guard it meets. (Where that makes too
/// many combinations, the event's own classes.)
pub(super) fn cascade_deliveries(
    p: &CompiledProject,
    l: &Layout,
    wanted: &[bool],
) -> Vec<Delivery> {
    let mut slots: Vec<Vec<(Vec<Value>, bool)>> = (0..p.events.len() as EventId)
        .map(|e| own_comparands(p, l, e))
        .collect();
    // Where each event's parameters go: (event, parameter) to (event emitted, position).
    let mut flows: Vec<(EventId, u32, EventId, usize)> = Vec::new();
    for net in &p.nets {
        for t in &net.transitions {
            let Some(from) = t.event else { continue };
            for a in &t.actions {
                if let Action::Emit { event, args, .. } = a {
                    for (j, arg) in args.iter().enumerate() {
                        if let Arg::EventParam(i) = arg {
                            flows.push((from, *i, *event, j));
                        }
                    }
                }
            }
        }
    }
    // A value goes at most once through each flow on a path that adds something.
    for _ in 0..=flows.len() {
        let mut changed = false;
        for &(from, i, to, j) in &flows {
            let (theirs, used) = slots[to as usize][j].clone();
            let mine = &mut slots[from as usize][i as usize];
            for v in theirs {
                if !mine.0.iter().any(|x| x.literal() == v.literal()) {
                    mine.0.push(v);
                    changed = true;
                }
            }
            if used && !mine.1 {
                mine.1 = true;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    let mut out = Vec::new();
    for e in 0..p.events.len() as EventId {
        if l.by_event[e as usize].is_empty() || !wanted[e as usize] {
            continue;
        }
        let mut mine = Vec::new();
        if event_deliveries(p, e, &slots[e as usize], &mut mine).is_err() {
            mine.clear();
            // The exploration made these already: they fit.
            let _ = event_deliveries(p, e, &own_comparands(p, l, e), &mut mine);
        }
        out.append(&mut mine);
    }
    out
}

/// Answers "may this guard hold?" for the conflict check: true unless it is decided false.
pub(super) struct MayHold<'a> {
    pub guards: &'a [Option<Guard>],
    pub params: &'a [Value],
}

impl Effects for MayHold<'_> {
    fn guard(&mut self, rule: u32) -> bool {
        match self.guards.get(rule as usize) {
            Some(Some(g)) => truth(g, self.params) != Truth::False,
            _ => true,
        }
    }
}

/// What a step asked of the environment: calls to functions with declared answers, and
/// emissions of internal events; the environment's counters follow them.
#[derive(Default, Clone)]
pub(super) struct Requests {
    pub calls: Vec<(ProgramId, FunctionId)>,
    pub emits: Vec<(EventId, Option<NetId>)>,
}

impl Requests {
    pub fn clear(&mut self) {
        self.calls.clear();
        self.emits.clear();
    }
}

/// The environment's memory of outstanding calls and emissions, kept in words after the
/// project's own in each state: two bits per counter, 0, 1 or many.
pub(super) struct Env {
    /// First bit of the counters.
    base: u32,
    /// Words in a state, counters included.
    pub words: usize,
    function_counter: HashMap<(ProgramId, FunctionId), u32>,
    internal_counter: HashMap<(EventId, Option<NetId>), u32>,
    /// Per event, the counters of the functions that answer with it (none for an event no
    /// function answers with): indexed, where a hashed lookup per delivery and state cost a
    /// twentieth of the exploration.
    answered_by: Vec<Vec<u32>>,
    internal: Vec<bool>,
    /// Counters in order, for people: `PROGRAM.function` or `event to NET`.
    pub names: Vec<String>,
}

/// How the environment may deliver an event in a state.
pub(super) enum Gate {
    /// At any time.
    Free,
    /// Not now: no outstanding call or emission asks for it.
    Closed,
    /// As the answer to one of these outstanding counters (each a way the step may go).
    Counters(Vec<u32>),
}

impl Env {
    /// The counters `p` needs, after `words` words of project state.
    pub fn new(p: &CompiledProject, words: usize) -> Env {
        let mut names = Vec::new();
        let mut function_counter = HashMap::new();
        let mut answered_by: Vec<Vec<u32>> = vec![Vec::new(); p.events.len()];
        for (pi, prog) in p.programs.iter().enumerate() {
            for (fi, f) in prog.functions.iter().enumerate() {
                if f.answers.is_empty() {
                    continue;
                }
                let c = names.len() as u32;
                names.push(format!("{}.{}", prog.name, f.name));
                function_counter.insert((pi as ProgramId, fi as FunctionId), c);
                for &e in &f.answers {
                    answered_by[e as usize].push(c);
                }
            }
        }
        let mut internal_counter = HashMap::new();
        for net in &p.nets {
            for t in &net.transitions {
                for a in &t.actions {
                    if let Action::Emit { event, target, .. } = a {
                        if p.events[*event as usize].internal
                            && !internal_counter.contains_key(&(*event, *target))
                        {
                            let c = names.len() as u32;
                            let mut name = p.events[*event as usize].name.clone();
                            if let Some(n) = target {
                                name = format!("{name} to {}", p.nets[*n as usize].name);
                            }
                            names.push(name);
                            internal_counter.insert((*event, *target), c);
                        }
                    }
                }
            }
        }
        let base = (words * 64) as u32;
        let bits = 2 * names.len();
        Env {
            base,
            words: words + bits.div_ceil(64),
            function_counter,
            internal_counter,
            answered_by,
            internal: p.events.iter().map(|e| e.internal).collect(),
            names,
        }
    }

    fn get(&self, s: &[u64], c: u32) -> u8 {
        let b = self.base + 2 * c;
        let lo = Layout::bit(s, b) as u8;
        let hi = Layout::bit(s, b + 1) as u8;
        lo | (hi << 1)
    }

    fn set(&self, s: &mut [u64], c: u32, v: u8) {
        for (k, on) in [(0, v & 1 != 0), (1, v & 2 != 0)] {
            let b = self.base + 2 * c + k;
            let (w, m) = ((b / 64) as usize, 1u64 << (b % 64));
            if on {
                s[w] |= m;
            } else {
                s[w] &= !m;
            }
        }
    }

    /// One more outstanding: 0 to 1, 1 to many.
    fn up(&self, s: &mut [u64], c: u32) {
        let v = self.get(s, c);
        self.set(s, c, if v == 0 { 1 } else { 3 });
    }

    /// Every counter at "many": every answer and internal event free, for an exploration that
    /// starts from a state whose outstanding calls and emissions are not known (a reload).
    pub fn saturate(&self, s: &mut [u64]) {
        for c in 0..self.names.len() as u32 {
            self.set(s, c, 3);
        }
    }

    /// Exactly one call or emission outstanding on counter `c` (not none, not many).
    pub fn is_once(&self, s: &[u64], c: u32) -> bool {
        self.get(s, c) == 1
    }

    /// One answered: 1 to 0; many stays many.
    pub fn down(&self, s: &mut [u64], c: u32) {
        if self.get(s, c) == 1 {
            self.set(s, c, 0);
        }
    }

    /// Each function counter's function and first bit (its two bits are this one and the
    /// next), for the transition cache.
    pub fn function_counter_bits(
        &self,
    ) -> impl Iterator<Item = ((ProgramId, FunctionId), u32)> + '_ {
        self.function_counter
            .iter()
            .map(|(&k, &c)| (k, self.base + 2 * c))
    }

    /// Each internal event counter's event and first bit, likewise.
    pub fn internal_counter_bits(&self) -> impl Iterator<Item = (EventId, u32)> + '_ {
        self.internal_counter
            .iter()
            .map(|(&(e, _), &c)| (e, self.base + 2 * c))
    }

    /// Whether, and how, `event` addressed to `target` may come in `s`.
    pub fn gate(&self, s: &[u64], event: EventId, target: Option<NetId>) -> Gate {
        let list = &self.answered_by[event as usize];
        if !list.is_empty() {
            let open: Vec<u32> = list
                .iter()
                .copied()
                .filter(|&c| self.get(s, c) > 0)
                .collect();
            return if open.is_empty() {
                Gate::Closed
            } else {
                Gate::Counters(open)
            };
        }
        if self.internal[event as usize] {
            return match self.internal_counter.get(&(event, target)) {
                Some(&c) if self.get(s, c) > 0 => Gate::Counters(vec![c]),
                _ => Gate::Closed,
            };
        }
        Gate::Free
    }

    /// Records what a step asked for in the state it led to.
    pub fn apply(&self, s: &mut [u64], requests: &Requests) {
        for k in &requests.calls {
            if let Some(&c) = self.function_counter.get(k) {
                self.up(s, c);
            }
        }
        for k in &requests.emits {
            if let Some(&c) = self.internal_counter.get(k) {
                self.up(s, c);
            }
        }
    }

    /// The outstanding counters of `s`, for people.
    pub fn describe(&self, s: &[u64]) -> Vec<String> {
        (0..self.names.len() as u32)
            .filter_map(|c| match self.get(s, c) {
                0 => None,
                1 => Some(format!("awaiting {}", self.names[c as usize])),
                _ => Some(format!("awaiting {} (repeatedly)", self.names[c as usize])),
            })
            .collect()
    }
}
