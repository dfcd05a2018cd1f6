//! Place/transition nets: the structure and initial marking of a PNML net, and nothing else.
//!
//! [`crate::pnml::parse_pnml`] builds them from PNML; `petrel_verify::reach` explores them.
//! They live apart from PNML because the explorer does not care where a net came from (a test
//! builds one by hand).

use petrel_diag::source::Span;

/// A place/transition net read from PNML: the structure and the initial marking, nothing else.
#[derive(Clone, Debug, PartialEq)]
pub struct PtNet {
    /// The net's `id` attribute.
    pub id: String,
    /// The net's `<name>` label, or its id when it has none.
    pub name: String,
    /// Places, in document order (pages flattened).
    pub places: Vec<PtPlace>,
    /// Transitions, in document order (pages flattened).
    pub transitions: Vec<PtTransition>,
    /// Arcs, in document order, resolved to places and transitions.
    pub arcs: Vec<PtArc>,
    /// Whether the net carries a `<toolspecific tool="nupn">` block (a split into sequential
    /// units, which some analysers use).
    pub has_nupn: bool,
    /// Whether the net carries a net-level `<toolspecific tool="petrel">` block: it is a
    /// Petrel project's export, and its P/T structure is only the project's skeleton (no
    /// events, activation, emptiness tests or guards), which analysers should say.
    pub petrel_export: bool,
}

/// A place of a [`PtNet`].
#[derive(Clone, Debug, PartialEq)]
pub struct PtPlace {
    /// The `id` attribute.
    pub id: String,
    /// The `<name>` label, or the id when it has none.
    pub name: String,
    /// Tokens in the initial marking (0 when `<initialMarking>` is absent).
    pub initial: u64,
    /// The place's start tag.
    pub span: Span,
}

/// A transition of a [`PtNet`].
#[derive(Clone, Debug, PartialEq)]
pub struct PtTransition {
    /// The `id` attribute.
    pub id: String,
    /// The `<name>` label, or the id when it has none.
    pub name: String,
    /// The transition's start tag.
    pub span: Span,
}

/// One end of an arc: an index into [`PtNet::places`] or [`PtNet::transitions`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PtNode {
    /// Index into [`PtNet::places`].
    Place(usize),
    /// Index into [`PtNet::transitions`].
    Transition(usize),
}

/// An arc of a [`PtNet`]. [`parse_pnml`](crate::pnml::parse_pnml) only builds arcs that join a
/// place and a transition, in either direction.
#[derive(Clone, Debug, PartialEq)]
pub struct PtArc {
    /// The `id` attribute.
    pub id: String,
    /// Where tokens come from.
    pub source: PtNode,
    /// Where tokens go.
    pub target: PtNode,
    /// The inscription: tokens moved per firing (1 when `<inscription>` is absent).
    pub weight: u64,
    /// The arc's start tag.
    pub span: Span,
}

impl PtArc {
    /// The place this arc touches, whichever its direction.
    pub fn place(&self) -> Option<usize> {
        match (self.source, self.target) {
            (PtNode::Place(p), _) | (_, PtNode::Place(p)) => Some(p),
            _ => None,
        }
    }

    /// The transition this arc touches, whichever its direction.
    pub fn transition(&self) -> Option<usize> {
        match (self.source, self.target) {
            (PtNode::Transition(t), _) | (_, PtNode::Transition(t)) => Some(t),
            _ => None,
        }
    }

    /// True for an input arc (place to transition): firing takes tokens from the place.
    pub fn is_input(&self) -> bool {
        matches!(
            (self.source, self.target),
            (PtNode::Place(_), PtNode::Transition(_))
        )
    }
}

impl PtNet {
    /// Number of arcs.
    pub fn arc_count(&self) -> usize {
        self.arcs.len()
    }

    /// Number of input arcs (place to transition).
    pub fn input_arc_count(&self) -> usize {
        self.arcs.iter().filter(|a| a.is_input()).count()
    }

    /// Number of output arcs (transition to place).
    pub fn output_arc_count(&self) -> usize {
        self.arcs.len() - self.input_arc_count()
    }

    /// The largest arc weight, 0 for a net without arcs. Above 1, the net is not unary.
    pub fn max_arc_weight(&self) -> u64 {
        self.arcs.iter().map(|a| a.weight).max().unwrap_or(0)
    }

    /// The largest initial marking of a place, 0 for a net without places. Above 1, the initial
    /// marking is not safe.
    pub fn max_initial_marking(&self) -> u64 {
        self.places.iter().map(|p| p.initial).max().unwrap_or(0)
    }

    /// The index of the place with id `id`.
    pub fn place_index(&self, id: &str) -> Option<usize> {
        self.places.iter().position(|p| p.id == id)
    }

    /// The index of the transition with id `id`.
    pub fn transition_index(&self, id: &str) -> Option<usize> {
        self.transitions.iter().position(|t| t.id == id)
    }
}
