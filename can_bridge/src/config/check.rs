//! Reading and checking the text of `can.toml` against the DBC and the project (codes E07xx).

use petrel_diag::duration::parse_duration_us;
use petrel_diag::names::{self, Candidates};
use petrel_diag::report::{Diagnostic, Diagnostics};
use petrel_diag::source::{FileId, Span};
use petrel_diag::toml::Ordered;
use petrel_nets::compiled::{CompiledProject, Value};
use petrel_nets::model::Type;
use serde::Deserialize;
use toml::Spanned;

use super::{
    BusEvents, CanConfig, CommandSpec, Condition, Edge, HeartbeatSpec, ParamSource, Rule, RuleKind,
    Target,
};
use crate::bus_state::BusState;
use crate::dbc::{Dbc, Message, MessageId, SignalRef};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCan {
    dbc: Option<Spanned<String>>,
    #[serde(default)]
    bus: RawBus,
    heartbeat: Option<Spanned<RawHeartbeat>>,
    #[serde(default)]
    commands: RawCommands,
    #[serde(default, rename = "rule")]
    rules: Vec<Spanned<RawRule>>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawBus {
    interface: Option<Spanned<String>>,
    #[serde(default)]
    fd: bool,
    state_event: Option<Spanned<String>>,
    #[serde(default)]
    on_state: Ordered<Spanned<String>>,
    #[serde(default)]
    restart_after_bus_off: bool,
    receive: Option<Spanned<String>>,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum NumberOrText {
    Number(f64),
    Text(String),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawHeartbeat {
    message: Spanned<String>,
    period: Option<Spanned<String>>,
    counter: Option<Spanned<String>>,
    #[serde(default)]
    signals: Ordered<Spanned<toml::Value>>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawCommands {
    #[serde(default)]
    messages: Vec<Spanned<String>>,
    program: Option<Spanned<String>>,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum RawParam {
    Bool(bool),
    Int(i64),
    Float(f64),
    Signal(String),
    Table(RawParamTable),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawParamTable {
    text: String,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRule {
    name: Option<Spanned<String>>,
    event: Spanned<String>,
    kind: Spanned<String>,
    signal: Option<Spanned<String>>,
    message: Option<Spanned<String>>,
    above: Option<Spanned<f64>>,
    below: Option<Spanned<f64>>,
    target: Option<Spanned<NumberOrText>>,
    within: Option<Spanned<f64>>,
    equals: Option<Spanned<NumberOrText>>,
    hysteresis: Option<Spanned<f64>>,
    #[serde(rename = "for")]
    hold: Option<Spanned<String>>,
    edge: Option<Spanned<String>>,
    timeout: Option<Spanned<String>>,
    periods: Option<Spanned<i64>>,
    period: Option<Spanned<String>>,
    #[serde(default)]
    params: Option<Spanned<Vec<Spanned<RawParam>>>>,
}

/// The hint for a misspelt name: can.toml's names come from the DBC and fixed lists, known
/// rather than declared by the user.
fn suggest(name: &str, candidates: &[String]) -> String {
    names::suggest(
        name,
        candidates.iter().map(String::as_str),
        Candidates::Known,
    )
}

struct Checker<'a> {
    file: FileId,
    dbc: &'a Dbc,
    project: &'a CompiledProject,
    diags: &'a mut Diagnostics,
    errors: usize,
}

impl Checker<'_> {
    fn span(&self, r: std::ops::Range<usize>) -> Span {
        Span::new(self.file, r.start, r.end)
    }

    fn error(&mut self, d: Diagnostic) {
        self.errors += 1;
        self.diags.push(d);
    }

    fn message(&mut self, name: &Spanned<String>) -> Option<MessageId> {
        if let Some(m) = self.dbc.message_by_name(name.get_ref()) {
            return Some(m);
        }
        let names: Vec<String> = self.dbc.messages().iter().map(|m| m.name.clone()).collect();
        let hint = suggest(name.get_ref(), &names);
        self.error(
            Diagnostic::error(
                "E0703",
                self.span(name.span()),
                format!("unknown message `{}`", name.get_ref()),
            )
            .label("no message of this name in the DBC")
            .help(hint),
        );
        None
    }

    fn signal(&mut self, path: &str, span: std::ops::Range<usize>) -> Option<SignalRef> {
        if let Some(r) = self.dbc.signal_ref(path) {
            return Some(r);
        }
        let span = self.span(span);
        let (label, hint) = match path.split_once('.') {
            None => ("not MESSAGE.signal".to_owned(), {
                let same: Vec<String> = self
                    .dbc
                    .signal_paths()
                    .filter(|p| p.ends_with(&format!(".{path}")))
                    .collect();
                match same.as_slice() {
                    [one] => format!("name the message too: did you mean `{one}`?"),
                    _ => format!(
                        "name the message too: {}",
                        suggest(path, &self.dbc.signal_paths().collect::<Vec<_>>())
                    ),
                }
            }),
            Some((m, s)) => match self.dbc.message_by_name(m) {
                Some(mi) => {
                    let names: Vec<String> = self.dbc.messages()[mi]
                        .signals
                        .iter()
                        .map(|s| s.name.clone())
                        .collect();
                    (
                        format!("message `{m}` has no signal `{s}`"),
                        suggest(s, &names),
                    )
                }
                None => {
                    let names: Vec<String> =
                        self.dbc.messages().iter().map(|m| m.name.clone()).collect();
                    (format!("the DBC has no message `{m}`"), suggest(m, &names))
                }
            },
        };
        self.error(
            Diagnostic::error("E0703", span, format!("unknown signal `{path}`"))
                .label(label)
                .help(hint),
        );
        None
    }

    fn event(&mut self, name: &Spanned<String>) -> Option<&'_ petrel_nets::compiled::Event> {
        let project = self.project;
        if let Some(e) = project.events.iter().find(|e| e.name == *name.get_ref()) {
            return Some(e);
        }
        let names: Vec<String> = project.events.iter().map(|e| e.name.clone()).collect();
        let hint = suggest(name.get_ref(), &names);
        self.error(
            Diagnostic::error(
                "E0704",
                self.span(name.span()),
                format!("unknown event `{}`", name.get_ref()),
            )
            .label("not declared in the project")
            .help(format!(
                "{hint}; declare it in petrel.toml's [events], for instance `{} = {{ category = \"safety\" }}`",
                name.get_ref()
            )),
        );
        None
    }

    fn duration(&mut self, d: &Spanned<String>, what: &str) -> Option<u64> {
        match parse_duration_us(d.get_ref()) {
            Some(us) if us > 0 => Some(us),
            _ => {
                self.error(
                    Diagnostic::error(
                        "E0707",
                        self.span(d.span()),
                        format!("`{}` is not a valid {what}", d.get_ref()),
                    )
                    .label("not a positive duration")
                    .help("write a number and a unit: `200ms`, `1.5s`, `2min` (units us, ms, s, min, h)"),
                );
                None
            }
        }
    }

    fn bad_field(&mut self, span: std::ops::Range<usize>, message: String, help: &str) {
        self.error(
            Diagnostic::error("E0708", self.span(span), message)
                .label("invalid here")
                .help(help.to_owned()),
        );
    }

    /// Checks a rule's event parameters against the event's declaration.
    fn params(
        &mut self,
        rule: &Spanned<RawRule>,
        decl: &petrel_nets::compiled::Event,
    ) -> Option<Vec<ParamSource>> {
        let r = rule.get_ref();
        let empty = Vec::new();
        let (given, list_span) = match &r.params {
            Some(p) => (p.get_ref(), p.span()),
            None => (&empty, r.event.span()),
        };
        if given.len() != decl.params.len() {
            let declared = decl
                .params
                .iter()
                .map(|(n, t)| format!("{n}: {}", t.keyword()))
                .collect::<Vec<_>>()
                .join(", ");
            self.error(
                Diagnostic::error(
                    "E0705",
                    self.span(list_span),
                    format!(
                        "event `{}` takes {} parameter{}, the rule gives {}",
                        decl.name,
                        decl.params.len(),
                        if decl.params.len() == 1 { "" } else { "s" },
                        given.len()
                    ),
                )
                .label("wrong number of parameters")
                .help(format!(
                    "the event is declared `{}({declared})`; give `params` one entry per parameter: a signal \"MESSAGE.signal\", a number, true/false or {{ text = \"...\" }}",
                    decl.name
                )),
            );
            return None;
        }
        let mut out = Vec::new();
        let mut ok = true;
        for (p, (pname, ty)) in given.iter().zip(&decl.params) {
            let span = p.span();
            let file = self.file;
            let mismatch = |found: &str| {
                Diagnostic::error(
                    "E0706",
                    Span::new(file, span.start, span.end),
                    format!(
                        "parameter `{pname}` of event `{}` is {}, the rule gives {found}",
                        decl.name,
                        ty.keyword()
                    ),
                )
                .label(format!("expected {}", ty.keyword()))
            };
            let source = match (p.get_ref(), ty) {
                (RawParam::Bool(b), Type::Bool) => Some(ParamSource::Literal(Value::Bool(*b))),
                (RawParam::Int(i), Type::Int) => Some(ParamSource::Literal(Value::Int(*i))),
                // Exactly, or not at all: an int a float does not hold exactly (beyond 2^53),
                // and TOML's `nan` and `inf`, are refused below.
                (RawParam::Int(i), Type::Float) if (*i as f64) as i128 == i128::from(*i) => {
                    Some(ParamSource::Literal(Value::Float(*i as f64)))
                }
                (RawParam::Float(f), Type::Float) if f.is_finite() => {
                    Some(ParamSource::Literal(Value::Float(*f)))
                }
                (RawParam::Table(t), Type::Text) => {
                    Some(ParamSource::Literal(Value::Text(t.text.clone())))
                }
                (RawParam::Signal(path), _) => match self.signal(path, span.clone()) {
                    None => {
                        ok = false;
                        None
                    }
                    Some(sr) => {
                        let sig = self.dbc.signal(sr);
                        let fits = match ty {
                            Type::Float | Type::Bool => true,
                            Type::Int => sig.is_some_and(|s| s.is_integral()),
                            Type::Text => true,
                            Type::FloatList => false,
                        };
                        if fits {
                            Some(ParamSource::Signal {
                                signal: sr,
                                ty: *ty,
                            })
                        } else {
                            let d = mismatch(&format!("the value of signal `{path}`"));
                            let help = match ty {
                                Type::Int => "the signal has a fractional factor or offset: declare the parameter `float`",
                                _ => "a signal gives one value: declare the parameter float, int, bool or text",
                            };
                            self.error(d.help(help));
                            None
                        }
                    }
                },
                (found, _) => {
                    let what = match found {
                        RawParam::Bool(_) => "a bool",
                        RawParam::Int(_) if *ty == Type::Float => {
                            "an int that no float holds exactly (above 2^53)"
                        }
                        RawParam::Int(_) => "an int",
                        RawParam::Float(f) if !f.is_finite() => "a float that is not finite",
                        RawParam::Float(_) => "a float",
                        RawParam::Table(_) => "a text",
                        RawParam::Signal(_) => "a signal",
                    };
                    let d = mismatch(what).help(
                        "write a literal of the declared type (a text is { text = \"...\" }), or a signal \"MESSAGE.signal\"",
                    );
                    self.error(d);
                    None
                }
            };
            match source {
                Some(s) => out.push(s),
                None => ok = false,
            }
        }
        ok.then_some(out)
    }

    fn rule(&mut self, rule: &Spanned<RawRule>) -> Option<Rule> {
        let r = rule.get_ref();
        let errors_before = self.errors;
        let kind = r.kind.get_ref().as_str();
        const KINDS: [&str; 5] = ["threshold", "band", "debounce", "edge", "stale"];
        if !KINDS.contains(&kind) {
            self.error(
                Diagnostic::error(
                    "E0708",
                    self.span(r.kind.span()),
                    format!("unknown rule kind `{kind}`"),
                )
                .label("not a kind of rule")
                .help(format!(
                    "{}; a rule is one of threshold, band, debounce, edge, stale",
                    suggest(kind, &KINDS.map(str::to_owned))
                )),
            );
            return None;
        }
        let decl = self.event(&r.event).cloned();
        let params = match &decl {
            Some(d) => self.params(rule, d),
            None => None,
        };
        // Fields that the kind does not take.
        let before_fields = self.errors;
        let stale = kind == "stale";
        let not_for = |checker: &mut Self,
                       present: bool,
                       span: Option<std::ops::Range<usize>>,
                       field: &str| {
            if present {
                checker.bad_field(
                    span.unwrap_or(r.kind.span()),
                    format!("`{field}` does not apply to a `{kind}` rule"),
                    "remove it, or choose the kind that uses it (see the fields of each kind in can_bridge/README.md)",
                );
            }
        };
        let sp = |s: &Option<Spanned<f64>>| s.as_ref().map(|v| v.span());
        if stale {
            for (present, span, field) in [
                (r.above.is_some(), sp(&r.above), "above"),
                (r.below.is_some(), sp(&r.below), "below"),
                (r.within.is_some(), sp(&r.within), "within"),
                (r.hysteresis.is_some(), sp(&r.hysteresis), "hysteresis"),
                (
                    r.target.is_some(),
                    r.target.as_ref().map(|t| t.span()),
                    "target",
                ),
                (
                    r.equals.is_some(),
                    r.equals.as_ref().map(|t| t.span()),
                    "equals",
                ),
                (r.hold.is_some(), r.hold.as_ref().map(|t| t.span()), "for"),
                (r.edge.is_some(), r.edge.as_ref().map(|t| t.span()), "edge"),
            ] {
                not_for(self, present, span, field);
            }
        } else {
            for (present, span, field) in [
                (
                    r.message.is_some(),
                    r.message.as_ref().map(|t| t.span()),
                    "message",
                ),
                (
                    r.timeout.is_some(),
                    r.timeout.as_ref().map(|t| t.span()),
                    "timeout",
                ),
                (
                    r.periods.is_some(),
                    r.periods.as_ref().map(|t| t.span()),
                    "periods",
                ),
                (
                    r.period.is_some(),
                    r.period.as_ref().map(|t| t.span()),
                    "period",
                ),
            ] {
                not_for(self, present, span, field);
            }
            match kind {
                "threshold" => {
                    for (present, span, field) in [
                        (
                            r.target.is_some(),
                            r.target.as_ref().map(|t| t.span()),
                            "target",
                        ),
                        (r.within.is_some(), sp(&r.within), "within"),
                        (
                            r.equals.is_some(),
                            r.equals.as_ref().map(|t| t.span()),
                            "equals",
                        ),
                    ] {
                        not_for(self, present, span, field);
                    }
                }
                "band" => {
                    for (present, span, field) in [
                        (r.above.is_some(), sp(&r.above), "above"),
                        (r.below.is_some(), sp(&r.below), "below"),
                        (
                            r.equals.is_some(),
                            r.equals.as_ref().map(|t| t.span()),
                            "equals",
                        ),
                    ] {
                        not_for(self, present, span, field);
                    }
                }
                _ => {}
            }
        }
        if self.errors != before_fields {
            // Fields that do not belong: the condition would only repeat it.
            return None;
        }
        let kind_out = if stale {
            self.stale(r)
        } else {
            self.condition(r, kind)
        };
        if self.errors != errors_before {
            return None;
        }
        let name = r
            .name
            .as_ref()
            .map(|n| n.get_ref().clone())
            .unwrap_or_else(|| r.event.get_ref().clone());
        Some(Rule {
            name,
            event: r.event.get_ref().clone(),
            kind: kind_out?,
            params: params?,
        })
    }

    fn stale(&mut self, r: &RawRule) -> Option<RuleKind> {
        let message = match (&r.message, &r.signal) {
            (Some(m), None) => self.message(m),
            (None, Some(s)) => self.signal(s.get_ref(), s.span()).map(|s| s.message),
            (Some(m), Some(_)) => {
                self.bad_field(
                    m.span(),
                    "a `stale` rule watches a `message` or the message of a `signal`, not both"
                        .into(),
                    "keep one of them",
                );
                None
            }
            (None, None) => {
                self.bad_field(
                    r.kind.span(),
                    "a `stale` rule needs the `message` it watches".into(),
                    "add `message = \"NAME\"` (a message of the DBC)",
                );
                None
            }
        }?;
        if let Some(t) = &r.timeout {
            if r.periods.is_some() || r.period.is_some() {
                self.bad_field(
                    t.span(),
                    "give either `timeout` or `periods`/`period`, not both".into(),
                    "`timeout = \"300ms\"`, or `periods = 3` times the message's period",
                );
                return None;
            }
            let timeout_us = self.duration(t, "timeout")?;
            return Some(RuleKind::Stale {
                message,
                timeout_us,
            });
        }
        let periods = match &r.periods {
            None => 3,
            Some(p) if *p.get_ref() >= 1 && *p.get_ref() <= 1_000_000 => *p.get_ref() as u64,
            Some(p) => {
                self.bad_field(
                    p.span(),
                    format!(
                        "`periods = {}`: the count of periods is 1 or more",
                        p.get_ref()
                    ),
                    "write how many periods of silence make the message stale, for instance 3",
                );
                return None;
            }
        };
        let m = &self.dbc.messages()[message];
        let period_us = match &r.period {
            Some(p) => self.duration(p, "period")?,
            None => match m.cycle_time_ms {
                Some(ms) => ms.saturating_mul(1000),
                None => {
                    let span = r.message.as_ref().map_or(r.kind.span(), |m| m.span());
                    let name = m.name.clone();
                    self.error(
                        Diagnostic::error(
                            "E0709",
                            self.span(span),
                            format!("message `{name}` has no period"),
                        )
                        .label("no GenMsgCycleTime in the DBC")
                        .help("give the rule `period = \"100ms\"` or `timeout = \"300ms\"`, or the message a GenMsgCycleTime attribute"),
                    );
                    return None;
                }
            },
        };
        Some(RuleKind::Stale {
            message,
            timeout_us: period_us.saturating_mul(periods),
        })
    }

    fn condition(&mut self, r: &RawRule, kind: &str) -> Option<RuleKind> {
        let Some(sig) = &r.signal else {
            self.bad_field(
                r.kind.span(),
                format!("a `{kind}` rule needs the `signal` it watches"),
                "add `signal = \"MESSAGE.signal\"`",
            );
            return None;
        };
        let signal = self.signal(sig.get_ref(), sig.span())?;
        let s = self.dbc.signal(signal)?.clone();
        let hysteresis = match &r.hysteresis {
            None => 0.0,
            Some(h) if h.get_ref().is_finite() && *h.get_ref() >= 0.0 => *h.get_ref(),
            Some(h) => {
                self.bad_field(
                    h.span(),
                    format!("hysteresis {} is not a non-negative number", h.get_ref()),
                    "the hysteresis is how far the value must go back past the threshold to end the condition: 0 or more",
                );
                return None;
            }
        };
        let finite = |c: &mut Self, v: &Spanned<f64>, field: &str| -> Option<f64> {
            if v.get_ref().is_finite() {
                Some(*v.get_ref())
            } else {
                c.bad_field(
                    v.span(),
                    format!("`{field}` is not a finite number"),
                    "write a number in the signal's unit",
                );
                None
            }
        };
        let given: Vec<&str> = [
            (r.above.is_some(), "above"),
            (r.below.is_some(), "below"),
            (r.target.is_some() || r.within.is_some(), "band"),
            (r.equals.is_some(), "equals"),
        ]
        .iter()
        .filter(|(p, _)| *p)
        .map(|(_, n)| *n)
        .collect();
        if given.len() != 1 {
            let help = match kind {
                "threshold" => "a threshold rule has `above = X` or `below = X`",
                "band" => "a band rule has `target` and `within`",
                _ => "give one condition: `above`, `below`, `target` with `within`, or `equals`",
            };
            self.bad_field(
                r.kind.span(),
                if given.is_empty() {
                    format!("a `{kind}` rule needs a condition")
                } else {
                    format!(
                        "a rule has one condition, this one has {}",
                        given.join(" and ")
                    )
                },
                help,
            );
            return None;
        }
        let (lo, hi) = s.physical_bounds();
        let unreachable = |c: &mut Self, span: std::ops::Range<usize>, what: String| {
            c.diags.push(
                Diagnostic::warning("W0701", c.span(span), what)
                    .label("outside the signal's range")
                    .help(format!(
                        "signal `{}` takes values from {lo} to {hi} {}; the rule can never fire",
                        sig.get_ref(),
                        s.unit
                    )),
            );
        };
        let condition = if let Some(a) = &r.above {
            let threshold = finite(self, a, "above")?;
            if threshold > hi {
                unreachable(
                    self,
                    a.span(),
                    format!("`{}` never reaches {threshold}", sig.get_ref()),
                );
            }
            Condition::Above {
                signal,
                threshold,
                hysteresis,
            }
        } else if let Some(b) = &r.below {
            let threshold = finite(self, b, "below")?;
            if threshold < lo {
                unreachable(
                    self,
                    b.span(),
                    format!("`{}` never goes down to {threshold}", sig.get_ref()),
                );
            }
            Condition::Below {
                signal,
                threshold,
                hysteresis,
            }
        } else if let Some(e) = &r.equals {
            if r.hysteresis.is_some() {
                self.bad_field(
                    r.hysteresis.as_ref().map_or(e.span(), |h| h.span()),
                    "`hysteresis` does not apply to `equals`".into(),
                    "remove it: an equality has no threshold to go back past",
                );
                return None;
            }
            let raw = match e.get_ref() {
                NumberOrText::Number(n) if n.fract() == 0.0 && n.abs() < 9e18 => *n as i64,
                NumberOrText::Number(n) => {
                    self.bad_field(
                        e.span(),
                        format!("`equals = {n}`: a raw value is an integer"),
                        "`equals` compares the raw value of the signal (a bit, a value-table entry): write an integer or a value name",
                    );
                    return None;
                }
                NumberOrText::Text(label) => match s.raw_of(label) {
                    Some(v) => v,
                    None => {
                        let names: Vec<String> = s.choices.iter().map(|(_, n)| n.clone()).collect();
                        self.error(
                            Diagnostic::error(
                                "E0710",
                                self.span(e.span()),
                                format!("signal `{}` has no value named `{label}`", sig.get_ref()),
                            )
                            .label("not in the signal's value table")
                            .help(if names.is_empty() {
                                "the signal has no value table (VAL_) in the DBC: compare with a raw number".to_owned()
                            } else {
                                suggest(label, &names)
                            }),
                        );
                        return None;
                    }
                },
            };
            Condition::Equals { signal, raw }
        } else {
            let (Some(t), Some(w)) = (&r.target, &r.within) else {
                self.bad_field(
                    r.kind.span(),
                    "a band needs both `target` and `within`".into(),
                    "`target = 30.0` (or a signal) and `within = 0.5`: the condition is abs(signal - target) <= within",
                );
                return None;
            };
            let within = finite(self, w, "within")?;
            if within <= 0.0 {
                self.bad_field(
                    w.span(),
                    format!("`within = {within}`: the half-width of the band is above 0"),
                    "write how close to the target the signal must be, for instance 0.5",
                );
                return None;
            }
            let target = match t.get_ref() {
                NumberOrText::Number(n) if n.is_finite() => {
                    if *n + within < lo || *n - within > hi {
                        unreachable(
                            self,
                            t.span(),
                            format!("`{}` never comes within {within} of {n}", sig.get_ref()),
                        );
                    }
                    Target::Value(*n)
                }
                NumberOrText::Number(_) => {
                    self.bad_field(
                        t.span(),
                        "`target` is not a finite number".into(),
                        "write a number or a signal",
                    );
                    return None;
                }
                NumberOrText::Text(path) => Target::Signal(self.signal(path, t.span())?),
            };
            Condition::Band {
                signal,
                target,
                within,
                hysteresis,
            }
        };
        if kind == "threshold"
            && matches!(condition, Condition::Band { .. } | Condition::Equals { .. })
        {
            return None;
        }
        let hold_us = match &r.hold {
            Some(h) => self.duration(h, "hold time (`for`)")?,
            None if kind == "debounce" => {
                self.bad_field(
                    r.kind.span(),
                    "a `debounce` rule needs `for`, how long the condition must hold".into(),
                    "add `for = \"200ms\"`",
                );
                return None;
            }
            None => 0,
        };
        let edge = match r.edge.as_ref().map(|e| e.get_ref().as_str()) {
            None | Some("rising") => Edge::Rising,
            Some("falling") => Edge::Falling,
            Some("both") => Edge::Both,
            Some(other) => {
                let span = r.edge.as_ref().map_or(r.kind.span(), |e| e.span());
                self.bad_field(
                    span,
                    format!("unknown edge `{other}`"),
                    "an edge is `rising` (the condition becomes true), `falling` or `both`",
                );
                return None;
            }
        };
        Some(RuleKind::Condition {
            condition,
            edge,
            hold_us,
        })
    }

    fn bus(&mut self, raw: &RawBus) -> BusEvents {
        let mut out = BusEvents {
            restart_after_bus_off: raw.restart_after_bus_off,
            ..BusEvents::default()
        };
        if let Some(e) = &raw.state_event {
            if let Some(decl) = self.event(e).cloned() {
                let ok = decl.params.len() == 1 && decl.params[0].1 == Type::Text;
                if ok {
                    out.state_event = Some(decl.name.clone());
                } else {
                    let code = if decl.params.len() == 1 {
                        "E0706"
                    } else {
                        "E0705"
                    };
                    self.error(
                        Diagnostic::error(
                            code,
                            self.span(e.span()),
                            format!("the bus state event `{}` must take one text parameter", decl.name),
                        )
                        .label("sent with the state's name")
                        .help(format!(
                            "declare it `{} = {{ category = \"safety\", params = [\"state: text\"] }}`; it is sent with error_active, error_warning, error_passive, bus_off, stopped or sleeping",
                            decl.name
                        )),
                    );
                }
            }
        }
        for (state, event) in &raw.on_state.0 {
            let Some(s) = BusState::from_name(state.get_ref()) else {
                let names: Vec<String> =
                    BusState::ALL.iter().map(|s| s.name().to_owned()).collect();
                let hint = suggest(state.get_ref(), &names);
                self.error(
                    Diagnostic::error(
                        "E0708",
                        self.span(state.span()),
                        format!("unknown bus state `{}` in [bus.on_state]", state.get_ref()),
                    )
                    .label("not a bus state")
                    .help(format!("{hint}; the states are error_active, error_warning, error_passive, bus_off, stopped, sleeping")),
                );
                continue;
            };
            let name = event.get_ref().as_str();
            match self.project.events.iter().find(|e| e.name == name) {
                None => {
                    self.event(event);
                }
                Some(decl) if !decl.params.is_empty() => {
                    let n = decl.params.len();
                    self.error(
                        Diagnostic::error(
                            "E0705",
                            self.span(event.span()),
                            format!("event `{name}` takes {n} parameters; a state's own event takes none"),
                        )
                        .label("sent without parameters")
                        .help("use `state_event` for an event that receives the state's name"),
                    );
                }
                Some(_) => out.on_state.push((s, name.to_owned())),
            }
        }
        out
    }

    fn heartbeat(&mut self, raw: &Spanned<RawHeartbeat>) -> Option<HeartbeatSpec> {
        let hb = raw.get_ref();
        let message = self.message(&hb.message)?;
        let m: Message = self.dbc.messages()[message].clone();
        let period_us = match &hb.period {
            Some(p) => self.duration(p, "heartbeat period")?,
            None => match m.cycle_time_ms {
                Some(ms) => ms.saturating_mul(1000),
                None => {
                    self.error(
                        Diagnostic::error(
                            "E0709",
                            self.span(hb.message.span()),
                            format!("heartbeat message `{}` has no period", m.name),
                        )
                        .label("no GenMsgCycleTime in the DBC")
                        .help("give [heartbeat] `period = \"100ms\"`, or the message a GenMsgCycleTime attribute"),
                    );
                    return None;
                }
            },
        };
        let mut ok = true;
        let counter = match &hb.counter {
            None => None,
            Some(c) => match m.signal_index(c.get_ref()) {
                Some(i) => Some(i),
                None => {
                    let names: Vec<String> = m.signals.iter().map(|s| s.name.clone()).collect();
                    let hint = suggest(c.get_ref(), &names);
                    self.error(
                        Diagnostic::error(
                            "E0703",
                            self.span(c.span()),
                            format!("message `{}` has no signal `{}`", m.name, c.get_ref()),
                        )
                        .label("unknown signal")
                        .help(hint),
                    );
                    ok = false;
                    None
                }
            },
        };
        let mut values = Vec::new();
        for (name, v) in &hb.signals.0 {
            let Some(i) = m.signal_index(name.get_ref()) else {
                let names: Vec<String> = m.signals.iter().map(|s| s.name.clone()).collect();
                let hint = suggest(name.get_ref(), &names);
                self.error(
                    Diagnostic::error(
                        "E0703",
                        self.span(name.span()),
                        format!(
                            "heartbeat message `{}` has no signal `{}`",
                            m.name,
                            name.get_ref()
                        ),
                    )
                    .label("unknown signal")
                    .help(hint),
                );
                ok = false;
                continue;
            };
            let s = &m.signals[i];
            let vspan = self.span(v.span());
            let value = match v.get_ref() {
                toml::Value::Integer(n) => Some(*n as f64),
                toml::Value::Float(f) => Some(*f),
                toml::Value::Boolean(b) => Some(f64::from(u8::from(*b))),
                toml::Value::String(label) => match s.value_of(label) {
                    Some(v) => Some(v),
                    None => {
                        self.error(
                            Diagnostic::error(
                                "E0710",
                                vspan,
                                format!(
                                    "signal `{}.{}` has no value named `{label}`",
                                    m.name, s.name
                                ),
                            )
                            .label("not in the signal's value table")
                            .help(if s.choices.is_empty() {
                                "the signal has no value table: give a number".to_owned()
                            } else {
                                suggest(
                                    label,
                                    &s.choices.iter().map(|(_, n)| n.clone()).collect::<Vec<_>>(),
                                )
                            }),
                        );
                        None
                    }
                },
                _ => {
                    self.error(
                        Diagnostic::error(
                            "E0708",
                            vspan,
                            format!(
                                "heartbeat signal `{}`: give a number, a bool or a value name",
                                s.name
                            ),
                        )
                        .label("not a value"),
                    );
                    None
                }
            };
            match value {
                Some(v) => values.push((i, v)),
                None => ok = false,
            }
        }
        if !ok {
            return None;
        }
        // Every signal needs a value: given, the counter, or the DBC's start value.
        let mut all = Vec::new();
        for (i, s) in m.signals.iter().enumerate() {
            if Some(i) == counter {
                let start = s.physical_bounds().0.max(s.offset);
                all.push((i, start));
                continue;
            }
            match values.iter().find(|(j, _)| *j == i) {
                Some(v) => all.push(*v),
                None => {
                    match s.start_value {
                        Some(v) => {
                            values.push((i, v));
                            all.push((i, v));
                        }
                        None => {
                            self.error(
                            Diagnostic::error(
                                "E0708",
                                self.span(raw.span()),
                                format!("heartbeat signal `{}.{}` has no value", m.name, s.name),
                            )
                            .label("in this heartbeat")
                            .help(format!("give it in `signals = {{ {} = ... }}`, or make it the `counter`", s.name)),
                        );
                            ok = false;
                        }
                    }
                }
            }
        }
        if !ok {
            return None;
        }
        let names: Vec<(&str, f64)> = all
            .iter()
            .map(|(i, v)| (m.signals[*i].name.as_str(), *v))
            .collect();
        if let Err(e) = self.dbc.encode_message(message, &names) {
            self.error(
                Diagnostic::error(
                    "E0708",
                    self.span(raw.span()),
                    format!("the heartbeat cannot be encoded: {e}"),
                )
                .label("in this heartbeat")
                .help("give values inside the signals' ranges"),
            );
            return None;
        }
        Some(HeartbeatSpec {
            message,
            period_us,
            counter,
            values,
        })
    }

    fn commands(&mut self, raw: &RawCommands) -> CommandSpec {
        let mut out = CommandSpec::default();
        for m in &raw.messages {
            if let Some(id) = self.message(m) {
                out.messages.push(id);
            }
        }
        if let Some(p) = &raw.program {
            if !petrel_value::is_program_name(p.get_ref()) {
                self.bad_field(
                    p.span(),
                    format!("`{}` is not a program name", p.get_ref()),
                    "1 to 24 letters, digits, `_` or `-`",
                );
            } else {
                // If the project declares the program, its functions must be command messages
                // with one parameter per signal.
                if let Some(prog) = self
                    .project
                    .programs
                    .iter()
                    .find(|q| q.name == *p.get_ref())
                {
                    for f in &prog.functions {
                        let found = self
                            .dbc
                            .message_by_name(&f.name)
                            .filter(|id| out.messages.contains(id));
                        match found {
                            None => self.error(
                                Diagnostic::error(
                                    "E0703",
                                    self.span(p.span()),
                                    format!("function `{}.{}` of the project is not a command message", prog.name, f.name),
                                )
                                .label("the bridge receives this program's calls")
                                .help("list the message in [commands] messages, or rename the function after a DBC message"),
                            ),
                            Some(id) => {
                                let n = self.dbc.messages()[id].signals.len();
                                if f.params.len() != n {
                                    self.error(
                                        Diagnostic::error(
                                            "E0705",
                                            self.span(p.span()),
                                            format!(
                                                "function `{}.{}` has {} parameters; message `{}` has {n} signals",
                                                prog.name, f.name, f.params.len(), f.name
                                            ),
                                        )
                                        .label("the bridge receives this program's calls")
                                        .help("declare one parameter per signal, in the DBC's order"),
                                    );
                                }
                            }
                        }
                    }
                }
                out.program = Some(p.get_ref().clone());
            }
        }
        out
    }
}

/// Reads and checks the text of `can.toml` against the DBC and the project's events; every
/// finding goes to `diags` (codes E07xx, W0701) with its span in `file`. Returns the checked
/// configuration when there is no error.
pub fn check_rules(
    file: FileId,
    text: &str,
    dbc: &Dbc,
    project: &CompiledProject,
    diags: &mut Diagnostics,
) -> Option<CanConfig> {
    let raw: RawCan = petrel_diag::toml::parse(
        file,
        text,
        "E0701",
        "can.toml",
        "can.toml has `dbc`, and optional [bus], [heartbeat], [commands] tables and [[rule]] entries; see can_bridge/README.md",
        diags,
    )?;
    let mut c = Checker {
        file,
        dbc,
        project,
        diags,
        errors: 0,
    };
    let commands = c.commands(&raw.commands);
    let bus = c.bus(&raw.bus);
    let receive_only_dbc = match raw.bus.receive.as_ref() {
        None => false,
        Some(r) => match r.get_ref().as_str() {
            "all" => false,
            "dbc" => true,
            other => {
                c.bad_field(
                    r.span(),
                    format!("`receive = \"{other}\"` in [bus]: not a choice"),
                    "write `receive = \"all\"` (every frame; those the DBC does not know are counted) or `receive = \"dbc\"` (the kernel passes only the DBC's messages, and error frames)",
                );
                false
            }
        },
    };
    let heartbeat = raw.heartbeat.as_ref().and_then(|h| c.heartbeat(h));
    let rules: Vec<Option<Rule>> = raw.rules.iter().map(|r| c.rule(r)).collect();
    if c.errors > 0 {
        return None;
    }
    Some(CanConfig {
        dbc_path: raw.dbc.as_ref().map(|d| d.get_ref().clone()),
        interface: raw.bus.interface.as_ref().map(|i| i.get_ref().clone()),
        fd: raw.bus.fd,
        receive_only_dbc,
        rules: rules.into_iter().flatten().collect(),
        bus,
        heartbeat,
        commands,
    })
}
