//! The record of one step: what the engine did while it processed an event.
//!
//! Every reader of the player's steps sees them through [`StepRecord`], a [`Sink`] that keeps
//! the event taken, the transitions fired, the calls made and every action as a line of text
//! (`call GUI.roll()`, `start dec_answer (expires at 12.5)`, `refused MISSION.t: a second token
//! in global.x`). The script runner prints it and checks expectations against it, the player
//! journals it and publishes it to monitors, the replay compares it with the journal. The texts
//! are part of the journal and of `petrel run`'s JSON lines, so they stay stable.
//!
//! What became of an event is said in one vocabulary, [`Outcome`]: `processed`, `unused`,
//! `refused`. The journal records these words, the replay compares them, `petrel run` prints
//! them in each JSON line's `outcome` and a script's `expect processed` / `expect unused` /
//! `expect refused` is read with them, so that what a step says is what a script expects.
//!
//! The player's record ([`StepRecord::without_calls`]) keeps only the texts, written in place
//! ([`write_call_text`]) into strings it reuses from step to step, and hands the journal the
//! fired transitions' names without building them ([`FiredNames`]). [`marked_places`] and
//! [`place_changes`] name a state's marked places, and what two states differ in (the marking
//! deltas name only that).

use crate::engine::{ArgValue, Args, Micros, Sink};
use petrel_nets::compiled::{
    CompiledProject, EventId, FunctionId, NetId, ProgramId, TimerId, Value,
};
use petrel_nets::semantics::{Layout, Notice, StepOutcome};

/// What one step did, for people and for the expectations of scripts. Clear it between steps.
pub struct StepRecord<'p> {
    /// The project the names come from.
    pub project: &'p CompiledProject,
    /// The event taken, with its parameters.
    pub taken: Option<(String, Vec<Value>)>,
    /// Transitions fired, in order.
    pub fired: Vec<(NetId, u32)>,
    /// Every action and notice, as text, in order.
    pub actions: Vec<String>,
    /// Calls made, with their arguments.
    pub calls: Vec<(ProgramId, FunctionId, Vec<Value>)>,
    /// Events emitted by nets and built-in events raised by the engine (`safety_violation`,
    /// `livelock`, `invariant_violated`), with their arguments (queued, not yet processed).
    pub emits: Vec<(EventId, Vec<Value>)>,
    /// Nets activated, in order.
    pub activated: Vec<NetId>,
    /// Nets deactivated, in order.
    pub deactivated: Vec<NetId>,
    /// The step reached the bound of a zero-time cascade: (steps taken, produced events
    /// dropped) (docs/semantics.md, "Zero-time cascades").
    pub cascade_stopped: Option<(u32, u64)>,
    /// Whether [`calls`](Self::calls) is kept (the player's record only needs the texts).
    keep_calls: bool,
    /// Texts of actions cleared, kept for the next ones (no allocation per step).
    spare: Vec<String>,
    /// The name and parameters of the event taken last, kept for the next one.
    taken_spare: Option<(String, Vec<Value>)>,
}

/// The `NET.transition` names of fired transitions, encoded as the journal's `Vec<String>`
/// (bincode: the count, then each name's length and bytes) without building the strings.
#[derive(Clone, Copy)]
pub struct FiredNames<'a> {
    project: &'a CompiledProject,
    fired: &'a [(NetId, u32)],
}

impl bincode::Encode for FiredNames<'_> {
    fn encode<E: bincode::enc::Encoder>(
        &self,
        encoder: &mut E,
    ) -> Result<(), bincode::error::EncodeError> {
        use bincode::enc::write::Writer as _;
        (self.fired.len() as u64).encode(encoder)?;
        for &(n, t) in self.fired {
            let net = &self.project.nets[n as usize];
            let transition = &net.transitions[t as usize].name;
            ((net.name.len() + 1 + transition.len()) as u64).encode(encoder)?;
            let writer = encoder.writer();
            writer.write(net.name.as_bytes())?;
            writer.write(b".")?;
            writer.write(transition.as_bytes())?;
        }
        Ok(())
    }
}

impl<'p> StepRecord<'p> {
    /// An empty record.
    pub fn new(project: &'p CompiledProject) -> Self {
        StepRecord {
            project,
            taken: None,
            fired: Vec::new(),
            actions: Vec::new(),
            calls: Vec::new(),
            emits: Vec::new(),
            activated: Vec::new(),
            deactivated: Vec::new(),
            cascade_stopped: None,
            keep_calls: true,
            spare: Vec::new(),
            taken_spare: None,
        }
    }

    /// The record without [`calls`](Self::calls): the calls are only in
    /// [`actions`](Self::actions), as text (the player's record: nothing reads them apart, and
    /// keeping them would copy every call's arguments).
    pub fn without_calls(mut self) -> Self {
        self.keep_calls = false;
        self
    }

    /// An empty string for the next action's text, reused from a cleared step when there is
    /// one.
    fn action_text(&mut self) -> String {
        self.spare.pop().unwrap_or_default()
    }

    /// The transitions fired since the last clear, as `NET.transition`.
    pub fn fired_names(&self) -> Vec<String> {
        self.fired
            .iter()
            .map(|&(n, t)| transition_name(self.project, n, t))
            .collect()
    }

    /// The transitions fired since the last clear as the journal encodes
    /// [`fired_names`](Self::fired_names), without building the names.
    pub fn fired_encoded(&self) -> FiredNames<'_> {
        FiredNames {
            project: self.project,
            fired: &self.fired,
        }
    }

    /// Forgets the event taken, keeping its buffers for the next one.
    pub fn forget_taken(&mut self) {
        if let Some(taken) = self.taken.take() {
            self.taken_spare = Some(taken);
        }
    }

    /// Forgets what was recorded (the step is over).
    pub fn clear(&mut self) {
        self.forget_taken();
        self.fired.clear();
        for mut text in self.actions.drain(..) {
            text.clear();
            self.spare.push(text);
        }
        self.calls.clear();
        self.emits.clear();
        self.activated.clear();
        self.deactivated.clear();
        self.cascade_stopped = None;
    }
}

/// `NET.transition`.
pub fn transition_name(project: &CompiledProject, net: NetId, transition: u32) -> String {
    let n = &project.nets[net as usize];
    format!("{}.{}", n.name, n.transitions[transition as usize].name)
}

/// `PROGRAM.function(args)`, arguments as the language writes them.
pub fn call_text(
    project: &CompiledProject,
    program: ProgramId,
    function: FunctionId,
    args: &[Value],
) -> String {
    let mut out = String::new();
    write_call_text(
        &mut out,
        project,
        program,
        function,
        args.iter().map(ArgValue::of),
    );
    out
}

/// Appends [`call_text`]'s text to `out`, the arguments written in place (the player writes
/// one per round trip: no intermediate string).
pub fn write_call_text<'a>(
    out: &mut String,
    project: &CompiledProject,
    program: ProgramId,
    function: FunctionId,
    args: impl IntoIterator<Item = ArgValue<'a>>,
) {
    let prog = &project.programs[program as usize];
    out.push_str(&prog.name);
    out.push('.');
    out.push_str(&prog.functions[function as usize].name);
    out.push('(');
    for (i, arg) in args.into_iter().enumerate() {
        if i > 0 {
            out.push_str(", ");
        }
        arg.write_literal(out);
    }
    out.push(')');
}

/// What became of an event, in the words the journal, the replay, `petrel run`'s JSON lines and
/// scripts' expectations share.
///
/// The words are those journals have always recorded: changing one would make old journals
/// diverge on replay. Why an event was refused is not part of the word; it travels apart (the
/// journal's refused entries, the `reason` of a JSON line).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// The event fired or offered at least one transition.
    Processed,
    /// No transition waited for the event in the state it found.
    Unused,
    /// The event was not processed: refused at submission (unknown event, wrong parameters, a
    /// catastrophic event already processed) or when taken after a catastrophic event.
    Refused,
}

impl Outcome {
    /// Every outcome, in the order documentation lists them.
    pub const ALL: [Outcome; 3] = [Outcome::Processed, Outcome::Unused, Outcome::Refused];

    /// The outcome's word: `processed`, `unused` or `refused`.
    pub fn name(self) -> &'static str {
        match self {
            Outcome::Processed => "processed",
            Outcome::Unused => "unused",
            Outcome::Refused => "refused",
        }
    }

    /// The outcome named `word`, if it is one of the words.
    pub fn from_name(word: &str) -> Option<Outcome> {
        Outcome::ALL.into_iter().find(|o| o.name() == word)
    }

    /// The outcome of a step the engine took.
    pub fn of(step: StepOutcome) -> Outcome {
        match step {
            StepOutcome::Processed => Outcome::Processed,
            StepOutcome::Unused => Outcome::Unused,
            StepOutcome::RefusedAfterCatastrophic => Outcome::Refused,
        }
    }
}

impl std::fmt::Display for Outcome {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// How the journal and the replay name a step's outcome: [`Outcome::name`] of the step.
pub fn outcome_name(outcome: StepOutcome) -> &'static str {
    Outcome::of(outcome).name()
}

fn seconds(t: Micros) -> f64 {
    t as f64 / 1e6
}

impl Sink for StepRecord<'_> {
    fn taken(&mut self, event: EventId, params: &[Value]) {
        let (mut name, mut values) = self
            .taken
            .take()
            .or_else(|| self.taken_spare.take())
            .unwrap_or_default();
        name.clear();
        name.push_str(&self.project.events[event as usize].name);
        values.clear();
        values.extend_from_slice(params);
        self.taken = Some((name, values));
    }
    fn fired(&mut self, net: NetId, transition: u32) {
        self.fired.push((net, transition));
    }
    fn call(&mut self, program: ProgramId, function: FunctionId, args: Args<'_>) {
        let mut text = self.action_text();
        text.push_str("call ");
        write_call_text(&mut text, self.project, program, function, args.iter());
        self.actions.push(text);
        if self.keep_calls {
            let values = args.iter().map(ArgValue::to_value).collect();
            self.calls.push((program, function, values));
        }
    }
    fn emitted(&mut self, event: EventId, params: &[Value]) {
        // The action's text stays `emit NAME` (journals hold it); the arguments are in `emits`.
        self.actions
            .push(format!("emit {}", self.project.events[event as usize].name));
        self.emits.push((event, params.to_vec()));
    }
    fn timer_started(&mut self, timer: TimerId, deadline: Micros) {
        self.actions.push(format!(
            "start {} (expires at {})",
            self.project.timers[timer as usize].name,
            seconds(deadline)
        ));
    }
    fn timer_cancelled(&mut self, timer: TimerId) {
        self.actions.push(format!(
            "cancel {}",
            self.project.timers[timer as usize].name
        ));
    }
    fn safety_violation(&mut self, net: NetId, transition: u32, place: &str) {
        self.actions.push(format!(
            "refused {}: a second token in {place}",
            transition_name(self.project, net, transition)
        ));
    }
    fn conflict(&mut self, net: NetId, transition: u32) {
        self.actions.push(format!(
            "conflict: {} does not fire",
            transition_name(self.project, net, transition)
        ));
    }
    fn notice(&mut self, notice: Notice) {
        let text = match notice {
            Notice::AlreadyActive(n) => format!(
                "activate {}: already active",
                self.project.nets[n as usize].name
            ),
            Notice::AlreadyInactive(n) => format!(
                "deactivate {}: already inactive",
                self.project.nets[n as usize].name
            ),
            Notice::ParentInactive(n) => format!(
                "finish {}: its parent is not active",
                self.project.nets[n as usize].name
            ),
        };
        self.actions.push(text);
    }
    fn activated(&mut self, net: NetId) {
        self.activated.push(net);
        self.actions
            .push(format!("activate {}", self.project.nets[net as usize].name));
    }
    fn deactivated(&mut self, net: NetId) {
        self.deactivated.push(net);
        self.actions.push(format!(
            "deactivate {}",
            self.project.nets[net as usize].name
        ));
    }
    fn livelock(&mut self) {
        self.actions
            .push("livelock: immediate transitions did not settle".into());
    }
    fn invariant_violated(&mut self, name: &str) {
        self.actions.push(format!("invariant {name} broken"));
    }
    fn raised(&mut self, event: EventId, params: &[Value]) {
        // The action's text is already there (`refused NET.t: ...`, `livelock: ...`,
        // `invariant NAME broken`): only the event, for a script's `expect emit`.
        self.emits.push((event, params.to_vec()));
    }
    fn cascade_stopped(&mut self, steps: u32, dropped: u64) {
        self.actions.push(format!(
            "cascade stopped: {steps} steps at one instant, {dropped} produced event(s) dropped"
        ));
        self.cascade_stopped = Some((steps, dropped));
    }
}

/// The marked places of `state` as `NET.place` and `global.place` (every net's places, active
/// or not: an inactive net has none), in layout order. What marking messages carry.
pub fn marked_places(project: &CompiledProject, layout: &Layout, state: &[u64]) -> Vec<String> {
    let mut out = Vec::new();
    for (n, net) in project.nets.iter().enumerate() {
        for (i, p) in net.places.iter().enumerate() {
            if Layout::bit(state, layout.net_base[n] + i as u32) {
                out.push(format!("{}.{}", net.name, p.name));
            }
        }
    }
    for (g, gp) in project.globals.iter().enumerate() {
        if Layout::bit(state, layout.global_base + g as u32) {
            out.push(format!("global.{}", gp.name));
        }
    }
    out
}

/// The places whose token changed from `before` to `after`, named as [`marked_places`] names
/// them, in the same order: those that received a token, and those that lost one. Only the
/// changed places are named (a step changes a few places of many).
pub fn place_changes(
    project: &CompiledProject,
    layout: &Layout,
    before: &[u64],
    after: &[u64],
) -> (Vec<String>, Vec<String>) {
    let (mut marked, mut unmarked) = (Vec::new(), Vec::new());
    let mut sort = |bit: u32, name: &dyn Fn() -> String| match (
        Layout::bit(before, bit),
        Layout::bit(after, bit),
    ) {
        (false, true) => marked.push(name()),
        (true, false) => unmarked.push(name()),
        _ => {}
    };
    for (n, net) in project.nets.iter().enumerate() {
        for (i, p) in net.places.iter().enumerate() {
            sort(layout.net_base[n] + i as u32, &|| {
                format!("{}.{}", net.name, p.name)
            });
        }
    }
    for (g, gp) in project.globals.iter().enumerate() {
        sort(layout.global_base + g as u32, &|| {
            format!("global.{}", gp.name)
        });
    }
    (marked, unmarked)
}
