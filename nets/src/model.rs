//! The project model as written: manifest declarations and nets, with names as text, source
//! spans, and the comments and blank lines that `petrel fmt` keeps.
//!
//! This is what the parser produces, what the formatter and the PNML exporter print, and what
//! the checker resolves into a [`crate::compiled::CompiledProject`] for the verifier and the
//! player. Equality ignores spans, so a model read from text equals the same model read back from
//! PNML.

use petrel_diag::duration::TimeUnit;
use petrel_diag::source::Span;
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

/// Words that cannot be used as names anywhere.
pub fn is_keyword(s: &str) -> bool {
    matches!(s, "true" | "false" | "self")
}

/// True if `s` is a valid Petrel identifier: a letter or `_`, then letters, digits or `_`.
pub fn is_identifier(s: &str) -> bool {
    let mut chars = s.chars();
    match chars.next() {
        Some(c) if c.is_ascii_alphabetic() || c == '_' => {}
        _ => return false,
    }
    chars.all(|c| c.is_ascii_alphanumeric() || c == '_') && !is_keyword(s)
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
            params_unread: false,
            description: Some(description.to_string()),
            internal: false,
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
                "immediate transitions, or events produced at one instant, did not settle: the fixpoint or the cascade was stopped",
            ),
            ev(
                "bad_message",
                Category::Communication,
                &[("sender", Type::Text), ("reason", Type::Text)],
                "a message was refused: unknown event, wrong parameters, or undecodable",
            ),
            ev(
                "invariant_violated",
                Category::Safety,
                &[("name", Type::Text)],
                "an invariant of the manifest stopped holding after a step",
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
    /// A parameter did not read (E0103: no type, an unknown type): the count and the types
    /// of the parameters are unknown, and the uses of the declaration are not checked against
    /// `params` (which holds only the parameters that read), so that one typo gives one error.
    pub params_unread: bool,
    /// Free text for people.
    pub description: Option<String>,
    /// Only the nets emit it (`internal = true`): no program or operator sends it, so the
    /// verifier delivers it only after a net emitted it.
    pub internal: bool,
}

/// A function a software program offers to the nets.
#[derive(Clone, Debug, PartialEq)]
pub struct FunctionDecl {
    /// Function name.
    pub name: Name,
    /// Parameters, in order.
    pub params: Vec<Param>,
    /// A parameter did not read (E0103: no type, an unknown type): the count and the types
    /// of the parameters are unknown, and the uses of the declaration are not checked against
    /// `params` (which holds only the parameters that read), so that one typo gives one error.
    pub params_unread: bool,
    /// The events the program answers a call with (`answers = [...]`): they come only after a
    /// call to a function that lists them (the verifier's model of the program).
    pub answers: Vec<Name>,
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

/// A place shared by nets, with its initial marking.
#[derive(Clone, Debug, PartialEq)]
pub struct GlobalPlaceDecl {
    /// Place name.
    pub name: Name,
    /// Initial tokens as written (more than one is an error).
    pub tokens: u32,
    /// The nets (or templates: all their instances) that may use it; `None`: every net.
    pub nets: Option<Vec<Name>>,
}

/// A named instance of a net template, declared in the manifest's `[instances]`.
#[derive(Clone, Debug, PartialEq)]
pub struct InstanceDecl {
    /// The instance's name, a net name of the project.
    pub name: Name,
    /// The template.
    pub net: Name,
    /// Its arguments, one per parameter of the template, in order.
    pub args: Vec<Expr>,
}

/// A formula over the state of the project: places, net activity, and logic. Invariants and
/// scripts' `expect always` are written with it.
#[derive(Clone, Debug, PartialEq)]
pub enum Formula {
    /// `NET.place` or `global.place`: the place is marked.
    Marked(Name),
    /// `active NET`.
    Active(Name),
    /// `true` or `false`.
    Const(bool, Span),
    /// `not F`.
    Not(Box<Formula>),
    /// `F and G`.
    And(Box<Formula>, Box<Formula>),
    /// `F or G`.
    Or(Box<Formula>, Box<Formula>),
    /// `F implies G`.
    Implies(Box<Formula>, Box<Formula>),
}

/// An invariant of the manifest's `[invariants]`: a formula every stable state must satisfy.
#[derive(Clone, Debug, PartialEq)]
pub struct InvariantDecl {
    /// Its name.
    pub name: Name,
    /// The formula as written (kept for the manifest's round trip).
    pub text: String,
    /// The formula, when it reads.
    pub formula: Option<Formula>,
}

/// One end of a time bound: an event, or a marking (a formula over the state).
#[derive(Clone, Debug, PartialEq)]
pub enum BoundEnd {
    /// A bare name: the event happens (a transition takes it).
    Event(Name),
    /// Anything else: the marking formula (as `[invariants]` write them) holds.
    Marking {
        /// The formula as written (kept for the manifest's round trip).
        text: String,
        /// The formula, when it reads.
        formula: Option<Formula>,
    },
}

impl BoundEnd {
    /// The end as written.
    pub fn text(&self) -> &str {
        match self {
            BoundEnd::Event(n) => &n.text,
            BoundEnd::Marking { text, .. } => text,
        }
    }
}

/// A time bound of the manifest's `[verify.bounds]`: `petrel verify --timed` reports, over
/// every occurrence of `from`, the least and greatest time until the next `to`
/// (docs/verification.md, "Time bounds").
#[derive(Clone, Debug, PartialEq)]
pub struct BoundDecl {
    /// Its name.
    pub name: Name,
    /// Where the observer's clock starts.
    pub from: BoundEnd,
    /// What stops it.
    pub to: BoundEnd,
    /// The requirement, a duration as written (`90s`), if any: a greater bound is an error.
    pub within: Option<Name>,
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
    /// Markings that count as the mission's ends for the progress check, besides `finals`
    /// (`[verify] goal`); not necessarily dead.
    pub goals: Vec<Vec<Name>>,
    /// Categories whose events are not counted on the way to an end by the progress check
    /// (`[verify] progress_excludes`; `None`: the default, catastrophic).
    pub progress_excludes: Option<Vec<Name>>,
    /// Named instances of net templates.
    pub instances: Vec<InstanceDecl>,
    /// Invariants, in the order written.
    pub invariants: Vec<InvariantDecl>,
    /// Time bounds to report (`[verify.bounds]`), in the order written.
    pub bounds: Vec<BoundDecl>,
}

/// Comments and spacing that belong before an item, kept so `petrel fmt` loses nothing.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Trivia {
    /// Whether a blank line separates this item from the previous one.
    pub blank_before: bool,
    /// Whole-line comments before the item, without the `//`; a blank line between two of
    /// them (or, in end comments, above the first) is an entry [`BLANK_LINE`] (a comment's
    /// text never holds a line break).
    pub comments: Vec<String>,
}

/// The entry of a comment list that stands for a blank line between two comments, so that
/// `petrel fmt` keeps a file's header comment apart from the first net's own comment.
pub const BLANK_LINE: &str = "\n";

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
    /// `self.NAME`: a parameter of the net (the name, with the span of the whole `self.NAME`).
    SelfParam(Name),
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
            Expr::Var(n) | Expr::SelfParam(n) => n.span,
        }
    }
}

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
    /// `self.NAME`: a net parameter (int or float) read as seconds.
    SelfSeconds(Name),
}

/// What a transition does when it fires.
#[derive(Clone, Debug, PartialEq)]
pub enum Action {
    /// `activate NET` or `activate NET(args)`: the net receives its initial marking (and, if
    /// its parameters are bound at activation, the arguments).
    Activate {
        /// The net.
        net: Name,
        /// Arguments for its parameters; empty when written without parentheses.
        args: Vec<Expr>,
        /// The whole action, for diagnostics.
        span: Span,
    },
    /// `deactivate NET` (or `deactivate self`): the net and its subtree lose their marking.
    Deactivate(Name),
    /// `finish`: the parent's completion place of this net receives a token, and the net
    /// deactivates itself.
    Finish(Span),
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
    /// `emit EVENT(args)` or `emit EVENT(args) to NET`.
    Emit {
        /// The event.
        event: Name,
        /// Arguments.
        args: Vec<Expr>,
        /// The one net it is addressed to, if any.
        to: Option<Name>,
        /// The whole emission, for diagnostics.
        span: Span,
    },
}

/// A comparison in a guard.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum CmpOp {
    /// `==`
    Eq,
    /// `!=`
    Ne,
    /// `<`
    Lt,
    /// `<=`
    Le,
    /// `>`
    Gt,
    /// `>=`
    Ge,
}

impl CmpOp {
    /// The operator as written.
    pub fn symbol(self) -> &'static str {
        match self {
            CmpOp::Eq => "==",
            CmpOp::Ne => "!=",
            CmpOp::Lt => "<",
            CmpOp::Le => "<=",
            CmpOp::Gt => ">",
            CmpOp::Ge => ">=",
        }
    }
}

/// A guard: when a transition may take its event, over the event's and the net's parameters.
#[derive(Clone, Debug, PartialEq)]
pub enum Guard {
    /// `A or B`.
    Or(Box<Guard>, Box<Guard>),
    /// `A and B`.
    And(Box<Guard>, Box<Guard>),
    /// `not A`.
    Not(Box<Guard>),
    /// `x == y`, `x < y`...
    Compare(CmpOp, Expr, Expr),
    /// A bool value standing alone (a parameter, `self.flag`, `true`).
    Value(Expr),
}

impl Guard {
    /// Where the guard stands (from its first operand to its last).
    pub fn span(&self) -> Span {
        match self {
            Guard::Or(a, b) | Guard::And(a, b) => a.span().to(b.span()),
            Guard::Not(a) => a.span(),
            Guard::Compare(_, a, b) => a.span().to(b.span()),
            Guard::Value(e) => e.span(),
        }
    }
}

/// `@allow(CODE, "reason")`: a warning the author intends, written before what it is about.
#[derive(Clone, Debug, PartialEq)]
pub struct Allow {
    /// The warning's code, such as `W0602`.
    pub code: Name,
    /// Why it is intended.
    pub reason: Option<String>,
}

/// A child of a net, as its `children` line declares it.
#[derive(Clone, Debug, PartialEq)]
pub struct ChildDecl {
    /// The child net (a net of the project, often a template).
    pub net: Name,
    /// Arguments fixing its parameters; `None` when written without parentheses.
    pub args: Option<Vec<Expr>>,
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
    /// The guard (`if ...`), if any.
    pub guard: Option<Guard>,
    /// Input places (one token taken from each).
    pub inputs: Vec<Name>,
    /// Places that must be empty (`not p` among the inputs); no token moves.
    pub empty: Vec<Name>,
    /// Output places (one token put in each).
    pub outputs: Vec<Name>,
    /// Actions run in order when it fires.
    pub actions: Vec<ActionItem>,
    /// Comments before the closing brace of the action block.
    pub end_comments: Vec<String>,
}

/// A declaration inside a net.
#[derive(Clone, Debug, PartialEq)]
#[allow(clippy::large_enum_variant)] // Transitions are most items: boxing them would cost more.
pub enum ItemKind {
    /// `place NAME [= N]`.
    Place(PlaceDecl),
    /// `transition NAME [on EVENT(...)] [if GUARD]: INPUTS -> OUTPUTS [{ ACTIONS }]`.
    Transition(TransitionDecl),
    /// `children A, B(args)`.
    Children(Vec<ChildDecl>),
}

/// A declaration with its comments.
#[derive(Clone, Debug, PartialEq)]
pub struct Item {
    /// Comments and spacing before it.
    pub trivia: Trivia,
    /// Warnings intended for it (`@allow` lines before it).
    pub allows: Vec<Allow>,
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
    /// Warnings intended for the whole net (`@allow` lines before it).
    pub allows: Vec<Allow>,
    /// Net name.
    pub name: Name,
    /// Parameters: a net with parameters is a template.
    pub params: Vec<Param>,
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

    /// The declared children, in written order (over every `children` line).
    pub fn children(&self) -> impl Iterator<Item = &ChildDecl> {
        self.items.iter().flat_map(|i| match &i.kind {
            ItemKind::Children(c) => c.as_slice(),
            _ => &[],
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
