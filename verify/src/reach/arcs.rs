//! The net reduced to what firing needs ([`Arcs`]), from which each representation of
//! markings (`bits`, `counts`) and the stubborn sets compile their own tables.

use super::ExploreError;
use petrel_nets::pt::{PtNet, PtNode};

/// The net reduced to what firing needs: arcs summed per (transition, place, direction), weight-0
/// arcs dropped, per-transition lists sorted by place.
pub(crate) struct Arcs {
    pub(crate) places: usize,
    pub(crate) transitions: usize,
    /// Tokens per place in the initial marking.
    pub(super) initial: Vec<u64>,
    /// `pre[pre_start[t]..pre_start[t + 1]]`: `(place, weight)` taken by transition `t`.
    pub(super) pre_start: Vec<usize>,
    pub(super) pre: Vec<(usize, u64)>,
    /// Same layout: `(place, weight)` produced by transition `t`.
    post_start: Vec<usize>,
    pub(super) post: Vec<(usize, u64)>,
}

impl Arcs {
    pub(super) fn new(net: &PtNet) -> Result<Self, ExploreError> {
        let (places, transitions) = (net.places.len(), net.transitions.len());
        if transitions > u32::MAX as usize {
            return Err(ExploreError::InvalidNet {
                message: format!("{transitions} transitions is more than this explorer indexes"),
            });
        }
        let mut pre: Vec<Vec<(usize, u64)>> = vec![Vec::new(); transitions];
        let mut post: Vec<Vec<(usize, u64)>> = vec![Vec::new(); transitions];
        for a in &net.arcs {
            let (list, p, t) = match (a.source, a.target) {
                (PtNode::Place(p), PtNode::Transition(t)) => (&mut pre, p, t),
                (PtNode::Transition(t), PtNode::Place(p)) => (&mut post, p, t),
                _ => {
                    return Err(ExploreError::InvalidNet {
                        message: format!("arc `{}` must join a place and a transition", a.id),
                    })
                }
            };
            if p >= places || t >= transitions {
                return Err(ExploreError::InvalidNet {
                    message: format!("arc `{}` refers to a node that does not exist", a.id),
                });
            }
            if a.weight == 0 {
                continue;
            }
            let l = &mut list[t];
            match l.iter_mut().find(|(q, _)| *q == p) {
                Some((_, w)) => {
                    *w = w.checked_add(a.weight).ok_or_else(|| ExploreError::InvalidNet {
                        message: format!(
                            "the arcs between place `{}` and transition `{}` weigh more than {} together",
                            net.places[p].id,
                            net.transitions[t].id,
                            u64::MAX
                        ),
                    })?
                }
                None => l.push((p, a.weight)),
            }
        }
        let flatten = |lists: Vec<Vec<(usize, u64)>>| {
            let mut start = Vec::with_capacity(lists.len() + 1);
            let mut flat = Vec::new();
            start.push(0);
            for mut l in lists {
                l.sort_unstable();
                flat.extend(l);
                start.push(flat.len());
            }
            (start, flat)
        };
        let (pre_start, pre) = flatten(pre);
        let (post_start, post) = flatten(post);
        Ok(Arcs {
            places,
            transitions,
            initial: net.places.iter().map(|p| p.initial).collect(),
            pre_start,
            pre,
            post_start,
            post,
        })
    }

    /// `(place, weight)` taken by transition `t`.
    pub(crate) fn pre(&self, t: usize) -> &[(usize, u64)] {
        &self.pre[self.pre_start[t]..self.pre_start[t + 1]]
    }

    /// `(place, weight)` produced by transition `t`.
    pub(crate) fn post(&self, t: usize) -> &[(usize, u64)] {
        &self.post[self.post_start[t]..self.post_start[t + 1]]
    }
}
