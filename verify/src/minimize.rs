//! The events of a trace that matter to a finding.
//!
//! A finding's trace is the shortest path to the state that shows it. Some of its events may
//! not matter (another net moved meanwhile, and moved back): each event is taken out in turn,
//! the rest replayed from the start with the same firing code, and if the finding still shows
//! the event did not matter. What is left is printed with `...` where events were elided.

use super::env::{Env, Gate};
use super::explore::{run_step, Graph, Recorder, NO_EVENT};
use crate::report::Trace;
use petrel_nets::compiled::CompiledProject;
use petrel_nets::semantics::{Scratch, Semantics, State};
use std::cell::RefCell;

/// Longest trace worth minimizing: each event costs a replay of the whole trace.
const MAX_MINIMIZED: usize = 64;

/// Replays traces of one exploration.
pub(super) struct Minimizer<'a> {
    sem: &'a Semantics<'a>,
    env: &'a Env,
    g: &'a Graph,
    rec: RefCell<Recorder>,
    scratch: RefCell<Scratch>,
}

impl<'a> Minimizer<'a> {
    /// A minimizer over the graph `g` built with `sem` and `env`.
    pub fn new(p: &'a CompiledProject, sem: &'a Semantics<'a>, env: &'a Env, g: &'a Graph) -> Self {
        let guards = super::explore::rule_guards(p, sem);
        Minimizer {
            sem,
            env,
            g,
            rec: RefCell::new(Recorder::with_guards(guards)),
            scratch: RefCell::new(Scratch::default()),
        }
    }

    /// The state reached by replaying `steps` (labels) from `root`; `None` if the environment
    /// could not make one of the steps (an answer with no call outstanding, an internal event
    /// nobody emitted).
    pub(super) fn replay(&self, root: &State, steps: &[u32]) -> Option<State> {
        let mut rec = self.rec.borrow_mut();
        let mut scratch = self.scratch.borrow_mut();
        let mut s = root.clone();
        for &l in steps {
            let label = &self.g.labels[l as usize];
            let d = &self.g.deliveries[label.delivery as usize];
            let possible = match self.env.gate(&s, d.event, d.target) {
                Gate::Free => label.counter.is_none(),
                Gate::Closed => false,
                Gate::Counters(open) => label.counter.is_some_and(|c| open.contains(&c)),
            };
            if !possible || self.sem.layout.is_over(&s) {
                return None;
            }
            s = run_step(
                self.sem,
                self.env,
                &mut rec,
                &mut scratch,
                &s,
                Some(d),
                &label.choices,
                label.counter,
            );
        }
        Some(s)
    }

    /// The trace to state `i`, with the events that `keep` does not need elided: an event is
    /// dropped when the state the rest of the trace leads to still satisfies `keep`.
    pub fn trace(&self, i: u32, keep: &dyn Fn(&[u64]) -> bool) -> Trace {
        let full = self.g.trace(i);
        let steps = self.g.trace_steps(i);
        // The environment's own moves (single-net mode) are not replayed: keep the trace.
        if steps.len() < 2 || steps.len() > MAX_MINIMIZED || steps.iter().any(Option::is_none) {
            return full;
        }
        if steps
            .iter()
            .flatten()
            .any(|&l| self.g.labels[l as usize].event == NO_EVENT)
        {
            return full;
        }
        let root = self.g.states[self.g.root(i) as usize].to_vec();
        let labels: Vec<u32> = steps.into_iter().flatten().collect();
        let mut needed = vec![true; labels.len()];
        for k in 0..labels.len() {
            needed[k] = false;
            let rest: Vec<u32> = labels
                .iter()
                .zip(&needed)
                .filter(|(_, n)| **n)
                .map(|(l, _)| *l)
                .collect();
            if !self.replay(&root, &rest).is_some_and(|s| keep(&s)) {
                needed[k] = true;
            }
        }
        let mut out: Trace = Vec::new();
        for (k, text) in full.into_iter().enumerate() {
            if needed[k] {
                out.push(text);
            } else if out.last().map(String::as_str) != Some("...") {
                out.push("...".into());
            }
        }
        out
    }
}
