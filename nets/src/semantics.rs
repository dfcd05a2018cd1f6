//! The firing rules of `docs/semantics.md`, once, for everything that runs a project.
//!
//! The verifier explores with this code and the player executes with it, so what is verified is
//! what runs. It is sans-I/O: a [`State`] is a bit vector (active nets, every place, running
//! timers, the catastrophic flag), and what a firing does outside the state (calls, emitted
//! events, timer deadlines, refusals) goes to an [`Effects`] implementation. Processing an event
//! allocates nothing once a [`Scratch`] has warmed up.

use crate::compiled::{
    Action, Arg, CompiledProject, EventId, FunctionId, NetId, PlaceRef, ProgramId, StateFormula,
    TimerDuration, TimerId,
};
use crate::model::Category;

/// A state of the project, as bits; see [`Layout`] for what each bit means.
pub type State = Vec<u64>;

/// A set of bits within a state, as (word, mask) pairs, sorted by word, one pair per word.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Bits(Vec<(u32, u64)>);

impl Bits {
    fn from_bits(bits: impl IntoIterator<Item = u32>) -> Bits {
        let mut v: Vec<(u32, u64)> = Vec::new();
        let mut sorted: Vec<u32> = bits.into_iter().collect();
        sorted.sort_unstable();
        for b in sorted {
            let (w, m) = (b / 64, 1u64 << (b % 64));
            match v.last_mut() {
                Some((lw, lm)) if *lw == w => *lm |= m,
                _ => v.push((w, m)),
            }
        }
        Bits(v)
    }

    /// True when every bit is set in `s`.
    #[inline]
    pub fn all_in(&self, s: &[u64]) -> bool {
        self.0.iter().all(|&(w, m)| s[w as usize] & m == m)
    }

    /// True when some bit is set in `s`.
    #[inline]
    pub fn any_in(&self, s: &[u64]) -> bool {
        self.0.iter().any(|&(w, m)| s[w as usize] & m != 0)
    }

    #[inline]
    fn set(&self, s: &mut [u64]) {
        for &(w, m) in &self.0 {
            s[w as usize] |= m;
        }
    }

    #[inline]
    fn clear(&self, s: &mut [u64]) {
        for &(w, m) in &self.0 {
            s[w as usize] &= !m;
        }
    }

    /// The bit numbers, in increasing order.
    pub fn iter(&self) -> impl Iterator<Item = u32> + '_ {
        self.0.iter().flat_map(|&(w, m)| {
            (0..64)
                .filter(move |b| m & (1 << b) != 0)
                .map(move |b| w * 64 + b)
        })
    }
}

/// A transition, precompiled to bit operations.
#[derive(Clone, Debug)]
pub struct FiringRule {
    /// Its net.
    pub net: NetId,
    /// Its index in the net.
    pub transition: u32,
    /// Bits that must be set for it to be enabled: its input places and its net's active bit.
    enable: Bits,
    /// Bits that must be clear for it to be enabled: the places it tests for emptiness.
    inhibit: Bits,
    /// It has a guard, which the [`Effects`] evaluate.
    pub guarded: bool,
    /// The parent's completion place it marks by `finish`, and the parent's active bit.
    finish: Option<(u32, u32)>,
    /// Input places: tokens taken.
    consume: Bits,
    /// Output places that are not inputs: tokens put, and where a second token would go.
    produce_new: Bits,
    /// Output places that are also inputs: their token is put back.
    produce_back: Bits,
}

/// Where each part of the project lives in a [`State`], and the precompiled transitions.
#[derive(Clone, Debug)]
pub struct Layout {
    /// Words in a state.
    pub words: usize,
    /// Bit of each net's "active" flag.
    pub net_active: Vec<u32>,
    /// First bit of each net's local places (place `p` of net `n` is `net_base[n] + p`).
    pub net_base: Vec<u32>,
    /// First bit of the global places.
    pub global_base: u32,
    /// First bit of the timers' "running" flags.
    pub timer_base: u32,
    /// The bit set once a catastrophic event has been processed.
    pub catastrophic: u32,
    net_places: Vec<Bits>,
    net_initial: Vec<Bits>,
    /// Every transition, in dispatch order.
    pub rules: Vec<FiringRule>,
    /// For each event, the indices in `rules` of the transitions it triggers, in dispatch order.
    pub by_event: Vec<Vec<u32>>,
    /// Indices in `rules` of the immediate transitions, in dispatch order.
    pub immediate: Vec<u32>,
    /// Index in `rules` of each net's first transition.
    pub net_first_rule: Vec<u32>,
    /// Each net's descendants, deepest first (what `deactivate` takes down before the net).
    pub subtree: Vec<Vec<NetId>>,
}

impl Layout {
    /// Lays out `p`.
    pub fn new(p: &CompiledProject) -> Layout {
        let mut next = 0u32;
        let net_active: Vec<u32> = p
            .nets
            .iter()
            .map(|_| {
                next += 1;
                next - 1
            })
            .collect();
        let mut net_base = Vec::new();
        for n in &p.nets {
            net_base.push(next);
            next += n.places.len() as u32;
        }
        let global_base = next;
        next += p.globals.len() as u32;
        let timer_base = next;
        next += p.timers.len() as u32;
        let catastrophic = next;
        next += 1;
        let words = (next as usize).div_ceil(64);
        let bit = |net: usize, r: PlaceRef| match r {
            PlaceRef::Local(i) => net_base[net] + i,
            PlaceRef::Global(g) => global_base + g,
        };
        let mut rules = Vec::new();
        let mut by_event = vec![Vec::new(); p.events.len()];
        let mut immediate = Vec::new();
        let mut net_first_rule = Vec::new();
        for (ni, n) in p.nets.iter().enumerate() {
            net_first_rule.push(rules.len() as u32);
            for (ti, t) in n.transitions.iter().enumerate() {
                let inputs: Vec<u32> = t.inputs.iter().map(|&r| bit(ni, r)).collect();
                let outputs: Vec<u32> = t.outputs.iter().map(|&r| bit(ni, r)).collect();
                let finish = if t.actions.iter().any(|a| matches!(a, Action::Finish)) {
                    n.parent.map(|(parent, place)| {
                        (
                            net_base[parent as usize] + place,
                            net_active[parent as usize],
                        )
                    })
                } else {
                    None
                };
                let idx = rules.len() as u32;
                match t.event {
                    Some(e) => by_event[e as usize].push(idx),
                    None => immediate.push(idx),
                }
                rules.push(FiringRule {
                    net: ni as NetId,
                    transition: ti as u32,
                    enable: Bits::from_bits(inputs.iter().copied().chain([net_active[ni]])),
                    inhibit: Bits::from_bits(t.empty.iter().map(|&r| bit(ni, r))),
                    guarded: t.guard.is_some(),
                    finish,
                    consume: Bits::from_bits(inputs.iter().copied()),
                    produce_new: Bits::from_bits(
                        outputs.iter().copied().filter(|o| !inputs.contains(o)),
                    ),
                    produce_back: Bits::from_bits(
                        outputs.iter().copied().filter(|o| inputs.contains(o)),
                    ),
                });
            }
        }
        let net_places = p
            .nets
            .iter()
            .enumerate()
            .map(|(i, n)| Bits::from_bits((0..n.places.len() as u32).map(|k| net_base[i] + k)))
            .collect();
        let net_initial = p
            .nets
            .iter()
            .enumerate()
            .map(|(i, n)| {
                Bits::from_bits(
                    n.places
                        .iter()
                        .enumerate()
                        .filter(|(_, pl)| pl.initial)
                        .map(|(k, _)| net_base[i] + k as u32),
                )
            })
            .collect();
        let mut subtree = Vec::new();
        for n in 0..p.nets.len() {
            let mut out = Vec::new();
            descendants(p, n as NetId, &mut out, &mut vec![false; p.nets.len()]);
            subtree.push(out);
        }
        Layout {
            subtree,
            words,
            net_active,
            net_base,
            global_base,
            timer_base,
            catastrophic,
            net_places,
            net_initial,
            rules,
            by_event,
            immediate,
            net_first_rule,
        }
    }

    /// True if bit `b` is set in `s`.
    #[inline]
    pub fn bit(s: &[u64], b: u32) -> bool {
        s[(b / 64) as usize] & (1 << (b % 64)) != 0
    }

    #[inline]
    fn set(s: &mut [u64], b: u32) {
        s[(b / 64) as usize] |= 1 << (b % 64);
    }

    #[inline]
    fn clear(s: &mut [u64], b: u32) {
        s[(b / 64) as usize] &= !(1 << (b % 64));
    }

    /// True if net `n` is active in `s`.
    pub fn is_active(&self, s: &[u64], n: NetId) -> bool {
        Self::bit(s, self.net_active[n as usize])
    }

    /// True if place `r` of net `n` is marked in `s`.
    pub fn is_marked(&self, s: &[u64], n: NetId, r: PlaceRef) -> bool {
        Self::bit(s, self.place_bit(n, r))
    }

    /// The bit of place `r` seen from net `n`.
    pub fn place_bit(&self, n: NetId, r: PlaceRef) -> u32 {
        match r {
            PlaceRef::Local(i) => self.net_base[n as usize] + i,
            PlaceRef::Global(g) => self.global_base + g,
        }
    }

    /// True if timer `t` runs in `s`.
    pub fn timer_running(&self, s: &[u64], t: TimerId) -> bool {
        Self::bit(s, self.timer_base + t)
    }

    /// True once a catastrophic event has been processed.
    pub fn is_over(&self, s: &[u64]) -> bool {
        Self::bit(s, self.catastrophic)
    }

    /// True if rule `r` is enabled in `s` (its guard aside): its net active, its inputs marked,
    /// the places it tests for emptiness empty.
    #[inline]
    pub fn enabled(&self, s: &[u64], r: u32) -> bool {
        let rule = &self.rules[r as usize];
        rule.enable.all_in(s) && !rule.inhibit.any_in(s)
    }

    /// Whether `f` holds in `s`.
    pub fn holds(&self, f: &StateFormula, s: &[u64]) -> bool {
        match f {
            StateFormula::Const(b) => *b,
            StateFormula::Marked(n, r) => self.is_marked(s, *n, *r),
            StateFormula::Active(n) => self.is_active(s, *n),
            StateFormula::Not(a) => !self.holds(a, s),
            StateFormula::And(a, b) => self.holds(a, s) && self.holds(b, s),
            StateFormula::Or(a, b) => self.holds(a, s) || self.holds(b, s),
            StateFormula::Implies(a, b) => !self.holds(a, s) || self.holds(b, s),
        }
    }

    /// True if rules `a` and `b` take a token from a common place (they conflict when both are
    /// enabled by the same event).
    pub fn share_input(&self, a: u32, b: u32) -> bool {
        let (x, y) = (
            &self.rules[a as usize].consume.0,
            &self.rules[b as usize].consume.0,
        );
        x.iter()
            .any(|&(w, m)| y.iter().any(|&(w2, m2)| w == w2 && m & m2 != 0))
    }

    /// Number of marked places (local and global) in `s`.
    pub fn tokens(&self, s: &[u64]) -> u32 {
        let mut n = 0;
        for b in self.net_base.first().copied().unwrap_or(self.global_base)..self.timer_base {
            n += u32::from(Self::bit(s, b));
        }
        n
    }

    /// The marked places of `s`, as `NET.place` and `global.place`, and the active nets.
    pub fn describe_state(&self, p: &CompiledProject, s: &[u64]) -> Vec<String> {
        let mut out = Vec::new();
        for (n, net) in p.nets.iter().enumerate() {
            if !self.is_active(s, n as NetId) {
                continue;
            }
            let marked: Vec<&str> = net
                .places
                .iter()
                .enumerate()
                .filter(|(i, _)| Self::bit(s, self.net_base[n] + *i as u32))
                .map(|(_, pl)| pl.name.as_str())
                .collect();
            out.push(format!("{}{{{}}}", net.name, marked.join(", ")));
        }
        for (g, gp) in p.globals.iter().enumerate() {
            if Self::bit(s, self.global_base + g as u32) {
                out.push(format!("global.{}", gp.name));
            }
        }
        for (t, tm) in p.timers.iter().enumerate() {
            if Self::bit(s, self.timer_base + t as u32) {
                out.push(format!("timer {} running", tm.name));
            }
        }
        out
    }

    /// The places (as bits) where firing rule `r` in `s` would put a second token.
    pub fn unsafe_outputs(&self, s: &[u64], r: u32) -> impl Iterator<Item = u32> + '_ {
        let rule = &self.rules[r as usize];
        let s = s.to_vec();
        rule.produce_new.iter().filter(move |&b| Self::bit(&s, b))
    }

    /// Describes bit `b` for people: `NET.place`, `global.place`, `NET (active)`, `timer T`.
    pub fn describe_bit(&self, p: &CompiledProject, b: u32) -> String {
        if b == self.catastrophic {
            return "catastrophic".into();
        }
        if b >= self.timer_base {
            return format!("timer {}", p.timers[(b - self.timer_base) as usize].name);
        }
        if b >= self.global_base {
            return format!("global.{}", p.globals[(b - self.global_base) as usize].name);
        }
        if let Some(n) = self.net_active.iter().position(|&a| a == b) {
            return format!("{} (active)", p.nets[n].name);
        }
        let n = self
            .net_base
            .iter()
            .rposition(|&base| base <= b)
            .unwrap_or(0);
        format!(
            "{}.{}",
            p.nets[n].name,
            p.nets[n].places[(b - self.net_base[n]) as usize].name
        )
    }
}

/// The descendants of `n` by its declared children, deepest first, each once.
fn descendants(p: &CompiledProject, n: NetId, out: &mut Vec<NetId>, seen: &mut Vec<bool>) {
    for &c in &p.nets[n as usize].children {
        if !std::mem::replace(&mut seen[c as usize], true) {
            descendants(p, c, out, seen);
            out.push(c);
        }
    }
}

/// A notice about a step that changes no state but must not pass unseen.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Notice {
    /// `activate` of a net that was already active: nothing changed.
    AlreadyActive(NetId),
    /// `deactivate` of a net that was not active: nothing changed.
    AlreadyInactive(NetId),
    /// `finish` in a net whose parent is not active: no completion place was marked.
    ParentInactive(NetId),
}

/// What firing does outside the state. Every method has a default that ignores it, so an
/// implementation listens only to what it needs.
pub trait Effects {
    /// Rule `rule` (an index in [`Layout::rules`]) fired.
    fn fired(&mut self, _rule: u32) {}
    /// A firing of `rule` was refused: it would have put a second token in place bit `place`.
    fn refused(&mut self, _rule: u32, _place: u32) {}
    /// Candidate `rule` of the current event was skipped: an earlier firing of the same event
    /// took a token it needed (a conflict), or deactivated its net.
    fn conflict(&mut self, _rule: u32) {}
    /// `call PROGRAM.FUNCTION(args)`; `Arg::EventParam` refers to the triggering event, which
    /// the caller of [`Semantics::process_event`] holds.
    fn call(&mut self, _program: ProgramId, _function: FunctionId, _args: &[Arg]) {}
    /// `emit EVENT(args)`, addressed to `target` if it is `Some`.
    fn emit(&mut self, _event: EventId, _args: &[Arg], _target: Option<NetId>) {}
    /// `start TIMER after D`.
    fn start_timer(&mut self, _timer: TimerId, _after: &TimerDuration) {}
    /// `cancel TIMER`.
    fn cancel_timer(&mut self, _timer: TimerId) {}
    /// A notice (activation of an active net...).
    fn notice(&mut self, _notice: Notice) {}
    /// Net `net` was activated (it received its initial marking), with `args` for its
    /// parameters bound at activation (empty otherwise; [`Arg::EventParam`] and
    /// [`Arg::NetParam`] refer to the triggering event and the net that fired).
    fn activated(&mut self, _net: NetId, _args: &[Arg]) {}
    /// Whether the guard of rule `rule` holds now, on the current event's parameters and the
    /// parameters of the rule's net. Asked only of rules that have a guard: once per candidate
    /// on the snapshot of the step, and for an immediate transition when it is enabled.
    fn guard(&mut self, _rule: u32) -> bool {
        true
    }
    /// Net `net` was deactivated (it lost its marking).
    fn deactivated(&mut self, _net: NetId) {}
    /// An immediate transition fired during a fixpoint, leading to `state`. Return `false` to
    /// stop the fixpoint (the verifier does when it sees a state twice: a livelock).
    fn immediate_step(&mut self, _state: &[u64]) -> bool {
        true
    }
    /// The fixpoint hit the firing bound without settling.
    fn livelock(&mut self) {}
}

/// Effects that are all ignored.
pub struct NoEffects;
impl Effects for NoEffects {}

/// Reusable buffers, so that processing an event allocates nothing in the steady state.
#[derive(Default)]
pub struct Scratch {
    candidates: Vec<u32>,
    refused_immediate: Vec<u32>,
}

/// How an event step ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StepOutcome {
    /// At least one transition was a candidate (it fired, lost a conflict or was refused).
    Processed,
    /// No transition waited for the event in this state; the state is unchanged.
    Unused,
    /// A catastrophic event was processed earlier: the event is refused.
    RefusedAfterCatastrophic,
}

/// Most steps a zero-time cascade takes (steps on events the nets emitted or the player raised
/// about a step, while such events stay queued) before the player stops it
/// (docs/semantics.md, "Zero-time cascades"): what the verifier's cascade check looks for too.
pub const CASCADE_BOUND: u32 = 10_000;

/// Where an event of category `c` waits in the queue: catastrophic first (0), nominal last
/// (4). The queue gives the oldest event of the first non-empty category.
pub fn queue_index(c: Category) -> usize {
    match c {
        Category::Catastrophic => 0,
        Category::Safety => 1,
        Category::Mission => 2,
        Category::Communication => 3,
        Category::Nominal => 4,
    }
}

/// The engine's and the verifier's shared step function.
pub struct Semantics<'p> {
    /// The compiled project.
    pub project: &'p CompiledProject,
    /// Its layout.
    pub layout: Layout,
    /// Most immediate firings in one fixpoint before it is called a livelock.
    pub fixpoint_bound: u32,
    /// Most steps of one zero-time cascade ([`CASCADE_BOUND`] unless set).
    pub cascade_bound: u32,
}

impl<'p> Semantics<'p> {
    /// The semantics of `project`, with the default bounds (10,000 firings in a fixpoint,
    /// 10,000 steps in a cascade).
    pub fn new(project: &'p CompiledProject) -> Self {
        Semantics {
            project,
            layout: Layout::new(project),
            fixpoint_bound: 10_000,
            cascade_bound: CASCADE_BOUND,
        }
    }

    /// The initial state: global places marked, start nets activated in order, then the
    /// immediate fixpoint.
    pub fn initial(&self, fx: &mut impl Effects, scratch: &mut Scratch) -> State {
        let mut s = vec![0u64; self.layout.words];
        for (g, gp) in self.project.globals.iter().enumerate() {
            if gp.initial {
                Layout::set(&mut s, self.layout.global_base + g as u32);
            }
        }
        for &n in &self.project.start {
            self.activate(&mut s, n, &[], fx);
        }
        self.fixpoint(&mut s, fx, scratch);
        s
    }

    fn activate(&self, s: &mut [u64], n: NetId, args: &[Arg], fx: &mut impl Effects) {
        let l = &self.layout;
        if l.is_active(s, n) {
            fx.notice(Notice::AlreadyActive(n));
            return;
        }
        Layout::set(s, l.net_active[n as usize]);
        l.net_initial[n as usize].set(s);
        fx.activated(n, args);
    }

    /// Deactivates `n`'s active descendants, deepest first, then `n`.
    fn deactivate(&self, s: &mut [u64], n: NetId, fx: &mut impl Effects) {
        let l = &self.layout;
        if !l.is_active(s, n) {
            fx.notice(Notice::AlreadyInactive(n));
            return;
        }
        for &d in &l.subtree[n as usize] {
            if l.is_active(s, d) {
                Layout::clear(s, l.net_active[d as usize]);
                l.net_places[d as usize].clear(s);
                fx.deactivated(d);
            }
        }
        Layout::clear(s, l.net_active[n as usize]);
        l.net_places[n as usize].clear(s);
        fx.deactivated(n);
    }

    /// Fires rule `r` if it is enabled and safe; returns whether it fired.
    fn fire(&self, s: &mut [u64], r: u32, fx: &mut impl Effects) -> bool {
        let rule = &self.layout.rules[r as usize];
        if !self.layout.enabled(s, r) {
            return false;
        }
        // Refuse a second token: checked on the marking after the inputs are taken, which is
        // the marking before for outputs that are not inputs.
        if rule.produce_new.any_in(s) {
            let place = rule
                .produce_new
                .iter()
                .find(|&b| Layout::bit(s, b))
                .unwrap_or(0);
            fx.refused(r, place);
            return false;
        }
        // `finish` is an output arc to the parent's completion place (when the parent runs).
        if let Some((done, parent_active)) = rule.finish {
            if Layout::bit(s, parent_active) && Layout::bit(s, done) {
                fx.refused(r, done);
                return false;
            }
        }
        rule.consume.clear(s);
        rule.produce_new.set(s);
        rule.produce_back.set(s);
        fx.fired(r);
        let t = &self.project.nets[rule.net as usize].transitions[rule.transition as usize];
        for a in &t.actions {
            match a {
                Action::Activate { net, args } => self.activate(s, *net, args, fx),
                Action::Deactivate(n) => self.deactivate(s, *n, fx),
                Action::Finish => {
                    match rule.finish {
                        Some((done, parent_active)) if Layout::bit(s, parent_active) => {
                            Layout::set(s, done)
                        }
                        _ => fx.notice(Notice::ParentInactive(rule.net)),
                    }
                    if self.layout.is_active(s, rule.net) {
                        self.deactivate(s, rule.net, fx);
                    }
                }
                Action::StartTimer { timer, after } => {
                    Layout::set(s, self.layout.timer_base + timer);
                    fx.start_timer(*timer, after);
                }
                Action::CancelTimer(timer) => {
                    Layout::clear(s, self.layout.timer_base + timer);
                    fx.cancel_timer(*timer);
                }
                Action::Call {
                    program,
                    function,
                    args,
                } => fx.call(*program, *function, args),
                Action::Emit {
                    event,
                    args,
                    target,
                } => fx.emit(*event, args, *target),
            }
        }
        true
    }

    /// Marks timer `t` as expired (not running) before its event is processed.
    pub fn timer_expired(&self, s: &mut [u64], t: TimerId) {
        Layout::clear(s, self.layout.timer_base + t);
    }

    /// The candidates for `event` (addressed to `target`, if any) in `s`: triggered, enabled,
    /// guard holding, in dispatch order.
    pub fn candidates(
        &self,
        s: &[u64],
        event: EventId,
        target: Option<NetId>,
        fx: &mut impl Effects,
        out: &mut Vec<u32>,
    ) {
        let l = &self.layout;
        out.clear();
        for &r in &l.by_event[event as usize] {
            let rule = &l.rules[r as usize];
            if target.is_some_and(|t| t != rule.net) || !l.enabled(s, r) {
                continue;
            }
            if rule.guarded && !fx.guard(r) {
                continue;
            }
            out.push(r);
        }
    }

    /// Processes one event on a stable state: candidates from the snapshot (in the target net
    /// only, for an addressed event), fired in dispatch order, then the immediate fixpoint.
    pub fn process_event(
        &self,
        s: &mut [u64],
        event: EventId,
        target: Option<NetId>,
        fx: &mut impl Effects,
        scratch: &mut Scratch,
    ) -> StepOutcome {
        let l = &self.layout;
        if l.is_over(s) {
            return StepOutcome::RefusedAfterCatastrophic;
        }
        let mut candidates = std::mem::take(&mut scratch.candidates);
        self.candidates(s, event, target, fx, &mut candidates);
        scratch.candidates = candidates;
        let outcome = if scratch.candidates.is_empty() {
            StepOutcome::Unused
        } else {
            for i in 0..scratch.candidates.len() {
                let r = scratch.candidates[i];
                if !l.enabled(s, r) {
                    fx.conflict(r);
                    continue;
                }
                self.fire(s, r, fx);
            }
            self.fixpoint(s, fx, scratch);
            StepOutcome::Processed
        };
        if self.project.events[event as usize].category == Category::Catastrophic {
            Layout::set(s, l.catastrophic);
        }
        outcome
    }

    /// Fires the first enabled immediate transition, again and again, until none is enabled.
    pub fn fixpoint(&self, s: &mut [u64], fx: &mut impl Effects, scratch: &mut Scratch) {
        let l = &self.layout;
        scratch.refused_immediate.clear();
        let mut fired = 0u32;
        'search: loop {
            for &r in &l.immediate {
                if !l.enabled(s, r) || scratch.refused_immediate.contains(&r) {
                    continue;
                }
                if l.rules[r as usize].guarded && !fx.guard(r) {
                    continue;
                }
                if self.fire(s, r, fx) {
                    fired += 1;
                    if fired > self.fixpoint_bound {
                        fx.livelock();
                        return;
                    }
                    if !fx.immediate_step(s) {
                        return;
                    }
                } else {
                    // Refused for safety: not retried during this fixpoint.
                    scratch.refused_immediate.push(r);
                }
                continue 'search;
            }
            return;
        }
    }
}
