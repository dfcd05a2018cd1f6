//! The project model as written: manifest declarations and nets, with names as text, source
//! spans, and the comments and blank lines that `petrel fmt` keeps.
//!
//! This is what the parser produces, what the formatter and the PNML exporter print, and what
//! the checker resolves into a [`crate::compiled::CompiledProject`] for the verifier and the
//! player. Equality ignores spans, so a model read from text equals the same model read back from
//! PNML.

use crate::source::Span;
use std::fmt;

/// A name as written, with where it was written.
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash)]
pub struct Name {
    /// The identifier.
    pub text: String,
    /// Where it stands in its file.
    pub span: Span,
}

impl Name {
    /// A name without a source position (built by code, not read from a file).
    pub fn synthetic(text: impl Into<String>) -> Self {
        Name {
            text: text.into(),
            span: Span::default(),
        }
    }

    /// The identifier as a string slice.
    pub fn as_str(&self) -> &str {
        &self.text
    }
}

impl fmt::Display for Name {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.text)
    }
}

/// True if `s` is a valid Petrel identifier: a letter or `_`, then letters, digits or `_`.
pub fn is_identifier(s: &str) -> bool {
    let mut chars = s.chars();
    match chars.next() {
        Some(c) if c.is_ascii_alphabetic() || c == '_' => {}
        _ => return false,
    }
    chars.all(|c| c.is_ascii_alphanumeric() || c == '_') && !crate::syntax::is_keyword(s)
}

/// The type of an event or function parameter (one type for the whole of Petrel).
pub use petrel_value::Type;

/// An event's category (section 3.2.3 of the ProCoSA paper); it sets dispatch priority.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Category {
    /// Aborts the mission; once processed, no further event is processed.
    Catastrophic,
    /// Changes the flight profile or plan.
    Safety,
    /// Has consequences on the mission only.
    Mission,
    /// Communication breakdowns with the ground.
    Communication,
    /// The nominal course of the mission.
    Nominal,
}

impl Category {
    /// Every category, highest priority first.
    pub const ALL: [Category; 5] = [
        Category::Catastrophic,
        Category::Safety,
        Category::Mission,
        Category::Communication,
        Category::Nominal,
    ];

    /// The spelling used in manifests.
    pub fn keyword(self) -> &'static str {
        match self {
            Category::Catastrophic => "catastrophic",
            Category::Safety => "safety",
            Category::Mission => "mission",
            Category::Communication => "communication",
            Category::Nominal => "nominal",
        }
    }

    /// Parses a category spelling.
    pub fn from_keyword(s: &str) -> Option<Category> {
        Category::ALL.into_iter().find(|c| c.keyword() == s)
    }
}

impl fmt::Display for Category {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.keyword())
    }
}

/// A typed parameter of an event or a program function.
#[derive(Clone, Debug, PartialEq)]
pub struct Param {
    /// Parameter name.
    pub name: Name,
    /// Parameter type.
    pub ty: Type,
}

/// Events every project has without declaring them: the player raises them, and nets may react
/// to them like to any other event. Their names are reserved.
pub fn builtin_events() -> &'static [EventDecl] {
    static BUILTINS: std::sync::OnceLock<Vec<EventDecl>> = std::sync::OnceLock::new();
    BUILTINS.get_or_init(|| {
        let ev = |name: &str, category, params: &[(&str, Type)], description: &str| EventDecl {
            name: Name::synthetic(name),
            category,
            params: params
                .iter()
                .map(|(n, t)| Param {
                    name: Name::synthetic(*n),
                    ty: *t,
                })
                .collect(),
            description: Some(description.to_string()),
        };
        vec![
            ev(
                "program_lost",
                Category::Safety,
                &[("program", Type::Text)],
                "a software program stopped (crashed, killed or disconnected)",
            ),
            ev(
                "call_failed",
                Category::Safety,
                &[("program", Type::Text), ("function", Type::Text)],
                "a call could not be delivered: the program is absent",
            ),
            ev(
                "safety_violation",
                Category::Safety,
                &[
                    ("net", Type::Text),
                    ("transition", Type::Text),
                    ("place", Type::Text),
                ],
                "a firing was refused: it would have put a second token in a place",
            ),
            ev(
                "livelock",
                Category::Safety,
                &[("net", Type::Text), ("transition", Type::Text)],
                "immediate transitions did not settle: the fixpoint was stopped",
            ),
            ev(
                "bad_message",
                Category::Communication,
                &[("sender", Type::Text), ("reason", Type::Text)],
                "a message was refused: unknown event, wrong parameters, or undecodable",
            ),
            ev(
                "recorder_failed",
                Category::Safety,
                &[("reason", Type::Text)],
                "the flight recorder cannot write its journal (a full disk...): events are processed but not acknowledged",
            ),
            ev(
                "recorder_restored",
                Category::Safety,
                &[],
                "the flight recorder writes its journal again",
            ),
        ]
    })
}

/// An event declared in the manifest.
#[derive(Clone, Debug, PartialEq)]
pub struct EventDecl {
    /// Event name.
    pub name: Name,
    /// Dispatch category.
    pub category: Category,
    /// Parameters, in order.
    pub params: Vec<Param>,
    /// Free text for people.
    pub description: Option<String>,
}

/// A function a software program offers to the nets.
#[derive(Clone, Debug, PartialEq)]
pub struct FunctionDecl {
    /// Function name.
    pub name: Name,
    /// Parameters, in order.
    pub params: Vec<Param>,
}

/// A software program (PLN, GUI, DEC...) and the functions nets may call.
#[derive(Clone, Debug, PartialEq)]
pub struct ProgramDecl {
    /// Program name.
    pub name: Name,
    /// Free text for people.
    pub description: Option<String>,
    /// Functions, in declaration order.
    pub functions: Vec<FunctionDecl>,
}

/// A timer: started by a net action, it emits its event when it expires.
#[derive(Clone, Debug, PartialEq)]
pub struct TimerDecl {
    /// Timer name.
    pub name: Name,
    /// The parameterless event emitted on expiry.
    pub event: Name,
}

/// A place shared by every net, with its initial marking.
#[derive(Clone, Debug, PartialEq)]
pub struct GlobalPlaceDecl {
    /// Place name.
    pub name: Name,
    /// Initial tokens as written (more than one is an error).
    pub tokens: u32,
}

/// A net file named by the manifest.
#[derive(Clone, Debug, PartialEq)]
pub struct FileRef {
    /// Path relative to the project directory, with `/` separators.
    pub path: String,
    /// Where the manifest names it.
    pub span: Span,
}

/// The manifest, `petrel.toml`: everything a project declares besides its nets.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Manifest {
    /// Project name.
    pub name: String,
    /// Free text for people.
    pub description: Option<String>,
    /// Net files, in order: this order is the nets' dispatch order.
    pub files: Vec<FileRef>,
    /// Nets activated when the mission starts.
    pub start: Vec<Name>,
    /// Global places.
    pub globals: Vec<GlobalPlaceDecl>,
    /// Events.
    pub events: Vec<EventDecl>,
    /// Software programs.
    pub programs: Vec<ProgramDecl>,
    /// Timers.
    pub timers: Vec<TimerDecl>,
    /// Intended final markings: a dead state holding every place of one of these is the
    /// mission's planned end, not an error. Places are written `NET.place` or `global.place`.
    pub finals: Vec<Vec<Name>>,
}

/// Comments and spacing that belong before an item, kept so `petrel fmt` loses nothing.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Trivia {
    /// Whether a blank line separates this item from the previous one.
    pub blank_before: bool,
    /// Whole-line comments before the item, without the `//`.
    pub comments: Vec<String>,
}

/// A literal or a name in an action's argument list.
#[derive(Clone, Debug, PartialEq)]
pub enum Expr {
    /// Integer literal.
    Int(i64, Span),
    /// Float literal.
    Float(f64, Span),
    /// `true` or `false`.
    Bool(bool, Span),
    /// Text literal (unescaped).
    Text(String, Span),
    /// List literal `[1.0, 2.5]`.
    List(Vec<Expr>, Span),
    /// A name bound by the triggering event.
    Var(Name),
}

impl Expr {
    /// Where the expression stands.
    pub fn span(&self) -> Span {
        match self {
            Expr::Int(_, s)
            | Expr::Float(_, s)
            | Expr::Bool(_, s)
            | Expr::Text(_, s)
            | Expr::List(_, s) => *s,
            Expr::Var(n) => n.span,
        }
    }
}

pub use crate::duration::TimeUnit;

/// How long a timer runs.
#[derive(Clone, Debug, PartialEq)]
pub enum DurationExpr {
    /// A literal such as `30s`, `1.5min` or `200ms`.
    Literal {
        /// The number as written.
        value: f64,
        /// Its unit.
        unit: TimeUnit,
        /// Where it stands.
        span: Span,
    },
    /// An event parameter (int or float) read as seconds.
    Seconds(Name),
}

/// What a transition does when it fires.
#[derive(Clone, Debug, PartialEq)]
pub enum Action {
    /// `activate NET`: the net receives its initial marking.
    Activate(Name),
    /// `deactivate NET`: the net loses its marking.
    Deactivate(Name),
    /// `start TIMER after DURATION`.
    StartTimer {
        /// The timer.
        timer: Name,
        /// Its duration.
        after: DurationExpr,
    },
    /// `cancel TIMER`.
    CancelTimer(Name),
    /// `call PROGRAM.FUNCTION(args)`.
    Call {
        /// The program.
        program: Name,
        /// The function.
        function: Name,
        /// Arguments.
        args: Vec<Expr>,
        /// The whole call, for diagnostics.
        span: Span,
    },
    /// `emit EVENT(args)`.
    Emit {
        /// The event.
        event: Name,
        /// Arguments.
        args: Vec<Expr>,
        /// The whole emission, for diagnostics.
        span: Span,
    },
}

/// An action with its comments.
#[derive(Clone, Debug, PartialEq)]
pub struct ActionItem {
    /// Comments before it.
    pub trivia: Trivia,
    /// The action.
    pub action: Action,
    /// A comment at the end of its line.
    pub trailing: Option<String>,
}

/// A name bound to an event parameter in a trigger: `alarm(reason)` or `alarm(reason: text)`.
#[derive(Clone, Debug, PartialEq)]
pub struct Binding {
    /// The bound name; `_` ignores the parameter.
    pub name: Name,
    /// The type written beside it, checked against the manifest.
    pub ty: Option<(Type, Span)>,
}

/// The event that fires a transition.
#[derive(Clone, Debug, PartialEq)]
pub struct Trigger {
    /// The event.
    pub event: Name,
    /// Parameter bindings, in the event's parameter order; empty with no parentheses.
    pub bindings: Vec<Binding>,
}

/// A place of a net.
#[derive(Clone, Debug)]
pub struct PlaceDecl {
    /// Place name.
    pub name: Name,
    /// Initial tokens as written (more than one is an error).
    pub tokens: u32,
    /// Where the marking is written, if it is.
    pub tokens_span: Option<Span>,
}

// Where the marking was written is a location, and locations do not make models differ.
impl PartialEq for PlaceDecl {
    fn eq(&self, other: &Self) -> bool {
        self.name == other.name && self.tokens == other.tokens
    }
}

/// A transition of a net.
#[derive(Clone, Debug, PartialEq)]
pub struct TransitionDecl {
    /// Transition name.
    pub name: Name,
    /// The triggering event; none makes the transition immediate.
    pub trigger: Option<Trigger>,
    /// Input places (one token taken from each).
    pub inputs: Vec<Name>,
    /// Output places (one token put in each).
    pub outputs: Vec<Name>,
    /// Actions run in order when it fires.
    pub actions: Vec<ActionItem>,
    /// Comments before the closing brace of the action block.
    pub end_comments: Vec<String>,
}

/// A declaration inside a net.
#[derive(Clone, Debug, PartialEq)]
pub enum ItemKind {
    /// `place NAME [= N]`.
    Place(PlaceDecl),
    /// `transition NAME [on EVENT(...)]: INPUTS -> OUTPUTS [{ ACTIONS }]`.
    Transition(TransitionDecl),
}

/// A declaration with its comments.
#[derive(Clone, Debug, PartialEq)]
pub struct Item {
    /// Comments and spacing before it.
    pub trivia: Trivia,
    /// The declaration.
    pub kind: ItemKind,
    /// A comment at the end of its first line.
    pub trailing: Option<String>,
}

/// One net: `net NAME { ... }`.
#[derive(Clone, Debug, PartialEq)]
pub struct NetDecl {
    /// Comments and spacing before it.
    pub trivia: Trivia,
    /// Net name.
    pub name: Name,
    /// Places and transitions in written order (the order is the firing priority).
    pub items: Vec<Item>,
    /// Comments before the closing brace.
    pub end_comments: Vec<String>,
}

impl NetDecl {
    /// The places, in written order.
    pub fn places(&self) -> impl Iterator<Item = &PlaceDecl> {
        self.items.iter().filter_map(|i| match &i.kind {
            ItemKind::Place(p) => Some(p),
            _ => None,
        })
    }

    /// The transitions, in written order.
    pub fn transitions(&self) -> impl Iterator<Item = &TransitionDecl> {
        self.items.iter().filter_map(|i| match &i.kind {
            ItemKind::Transition(t) => Some(t),
            _ => None,
        })
    }
}

/// A net file: one or more nets.
#[derive(Clone, Debug, PartialEq)]
pub struct NetFile {
    /// Path relative to the project directory, with `/` separators.
    pub path: String,
    /// Nets in written order.
    pub nets: Vec<NetDecl>,
    /// Comments after the last net.
    pub end_comments: Vec<String>,
}

/// A whole mission project: manifest and net files.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Project {
    /// The manifest.
    pub manifest: Manifest,
    /// The net files the manifest names, in the same order (missing ones are absent).
    pub files: Vec<NetFile>,
}

impl Project {
    /// Every net of the project in dispatch order (file order, then written order).
    pub fn nets(&self) -> impl Iterator<Item = &NetDecl> {
        self.files.iter().flat_map(|f| f.nets.iter())
    }
}
