//! The canonical text of a net file: what `petrel fmt` writes, and what PNML import writes.
//!
//! Printing a parsed file and parsing the result gives the same model, and printing that again
//! gives the same text: formatting twice changes nothing.

use crate::model::*;
use std::fmt::Write as _;

const INDENT: &str = "    ";

/// The canonical text of a whole net file.
pub fn format_file(file: &NetFile) -> String {
    let mut out = String::new();
    for (i, net) in file.nets.iter().enumerate() {
        if i > 0 {
            out.push('\n');
        }
        format_net(&mut out, net);
    }
    if !file.end_comments.is_empty() && !file.nets.is_empty() {
        out.push('\n');
    }
    comments(&mut out, "", &file.end_comments);
    out
}

fn comments(out: &mut String, indent: &str, list: &[String]) {
    for c in list {
        if c == crate::model::BLANK_LINE {
            out.push('\n');
            continue;
        }
        out.push_str(indent);
        out.push_str(&comment(c));
        out.push('\n');
    }
}

fn comment(text: &str) -> String {
    if text.is_empty() {
        "//".to_string()
    } else {
        format!("// {text}")
    }
}

fn trailing(out: &mut String, c: &Option<String>) {
    if let Some(c) = c {
        out.push_str("  ");
        out.push_str(&comment(c));
    }
}

/// `@allow(CODE, "reason")`.
pub fn format_allow(a: &Allow) -> String {
    match &a.reason {
        Some(r) => format!("@allow({}, {})", a.code, quote(r)),
        None => format!("@allow({})", a.code),
    }
}

/// `net NAME` or `net NAME(p: type, ...)`, without the brace.
pub fn format_net_header(net: &NetDecl) -> String {
    if net.params.is_empty() {
        format!("net {}", net.name)
    } else {
        let params: Vec<String> = net
            .params
            .iter()
            .map(|p| format!("{}: {}", p.name, p.ty))
            .collect();
        format!("net {}({})", net.name, params.join(", "))
    }
}

/// `children A, B(args)`.
pub fn format_children(children: &[ChildDecl]) -> String {
    let list: Vec<String> = children
        .iter()
        .map(|c| match &c.args {
            Some(args) => format!("{}({})", c.net, format_args(args)),
            None => c.net.text.clone(),
        })
        .collect();
    format!("children {}", list.join(", "))
}

fn format_net(out: &mut String, net: &NetDecl) {
    comments(out, "", &net.trivia.comments);
    for a in &net.allows {
        out.push_str(&format_allow(a));
        out.push('\n');
    }
    let _ = writeln!(out, "{} {{", format_net_header(net));
    for (i, item) in net.items.iter().enumerate() {
        if i > 0 && item.trivia.blank_before {
            out.push('\n');
        }
        comments(out, INDENT, &item.trivia.comments);
        for a in &item.allows {
            out.push_str(INDENT);
            out.push_str(&format_allow(a));
            out.push('\n');
        }
        out.push_str(INDENT);
        match &item.kind {
            ItemKind::Children(c) => {
                out.push_str(&format_children(c));
                trailing(out, &item.trailing);
                out.push('\n');
            }
            ItemKind::Place(p) => {
                out.push_str(&format_place(p));
                trailing(out, &item.trailing);
                out.push('\n');
            }
            ItemKind::Transition(t) => {
                out.push_str(&format_transition_header(t));
                let block = !t.actions.is_empty() || !t.end_comments.is_empty();
                if block {
                    out.push_str(" {");
                }
                trailing(out, &item.trailing);
                out.push('\n');
                if block {
                    let inner = format!("{INDENT}{INDENT}");
                    for (j, a) in t.actions.iter().enumerate() {
                        if j > 0 && a.trivia.blank_before {
                            out.push('\n');
                        }
                        comments(out, &inner, &a.trivia.comments);
                        out.push_str(&inner);
                        out.push_str(&format_action(&a.action));
                        trailing(out, &a.trailing);
                        out.push('\n');
                    }
                    comments(out, &inner, &t.end_comments);
                    out.push_str(INDENT);
                    out.push_str("}\n");
                }
            }
        }
    }
    comments(out, INDENT, &net.end_comments);
    out.push_str("}\n");
}

/// `place NAME` or `place NAME = N`.
pub fn format_place(p: &PlaceDecl) -> String {
    if p.tokens == 0 {
        format!("place {}", p.name)
    } else {
        format!("place {} = {}", p.name, p.tokens)
    }
}

/// `transition NAME on EVENT(bindings) if GUARD: INPUTS, not EMPTY -> OUTPUTS`, without the
/// action block.
pub fn format_transition_header(t: &TransitionDecl) -> String {
    let mut s = format!("transition {}", t.name);
    if let Some(trigger) = &t.trigger {
        s.push_str(" on ");
        s.push_str(&format_trigger(trigger));
    }
    if let Some(g) = &t.guard {
        s.push_str(" if ");
        s.push_str(&format_guard(g));
    }
    s.push(':');
    let inputs: Vec<String> = t
        .inputs
        .iter()
        .map(|n| n.text.clone())
        .chain(t.empty.iter().map(|n| format!("not {n}")))
        .collect();
    if !inputs.is_empty() {
        s.push(' ');
        s.push_str(&inputs.join(", "));
    }
    s.push_str(" ->");
    if !t.outputs.is_empty() {
        s.push(' ');
        s.push_str(&join_names(&t.outputs));
    }
    s
}

/// A guard, with the parentheses its precedence needs and no more (`not` binds tightest, then
/// `and`, then `or`).
pub fn format_guard(g: &Guard) -> String {
    guard_at(g, 0)
}

/// `level`: 0 inside an `or`, 1 inside an `and`, 2 under a `not`.
fn guard_at(g: &Guard, level: u8) -> String {
    let (text, own) = match g {
        Guard::Or(a, b) => (format!("{} or {}", guard_at(a, 0), guard_at(b, 1)), 0),
        Guard::And(a, b) => (format!("{} and {}", guard_at(a, 1), guard_at(b, 2)), 1),
        Guard::Not(a) => (format!("not {}", guard_at(a, 2)), 2),
        Guard::Compare(op, a, b) => (
            format!("{} {} {}", format_expr(a), op.symbol(), format_expr(b)),
            3,
        ),
        Guard::Value(e) => (format_expr(e), 3),
    };
    if own < level {
        format!("({text})")
    } else {
        text
    }
}

/// A formula of an invariant or a script, with the parentheses its precedence needs (`not`,
/// then `and`, then `or`, then `implies`, which groups to the right).
pub fn format_formula(f: &Formula) -> String {
    formula_at(f, 0)
}

/// `level`: 0 top or right of `implies`, 1 left of `implies` / inside `or`, 2 inside `and`,
/// 3 under `not`.
fn formula_at(f: &Formula, level: u8) -> String {
    let (text, own) = match f {
        Formula::Implies(a, b) => (
            format!("{} implies {}", formula_at(a, 1), formula_at(b, 0)),
            0,
        ),
        Formula::Or(a, b) => (format!("{} or {}", formula_at(a, 1), formula_at(b, 2)), 1),
        Formula::And(a, b) => (format!("{} and {}", formula_at(a, 2), formula_at(b, 3)), 2),
        Formula::Not(a) => (format!("not {}", formula_at(a, 3)), 3),
        Formula::Marked(n) => (n.text.clone(), 4),
        Formula::Active(n) => (format!("active {n}"), 4),
        Formula::Const(b, _) => (b.to_string(), 4),
    };
    if own < level {
        format!("({text})")
    } else {
        text
    }
}

/// `EVENT` or `EVENT(a, b: text)`.
pub fn format_trigger(trigger: &Trigger) -> String {
    let mut s = trigger.event.text.clone();
    if !trigger.bindings.is_empty() {
        let b: Vec<String> = trigger
            .bindings
            .iter()
            .map(|b| match &b.ty {
                Some((ty, _)) => format!("{}: {}", b.name, ty),
                None => b.name.text.clone(),
            })
            .collect();
        let _ = write!(s, "({})", b.join(", "));
    }
    s
}

fn join_names(names: &[Name]) -> String {
    names
        .iter()
        .map(|n| n.text.as_str())
        .collect::<Vec<_>>()
        .join(", ")
}

/// One action as written in a net, such as `call GUI.goto(x, 3.5)`.
pub fn format_action(a: &Action) -> String {
    match a {
        Action::Activate { net, args, .. } => {
            if args.is_empty() {
                format!("activate {net}")
            } else {
                format!("activate {net}({})", format_args(args))
            }
        }
        Action::Deactivate(n) => format!("deactivate {n}"),
        Action::Finish(_) => "finish".to_string(),
        Action::CancelTimer(n) => format!("cancel {n}"),
        Action::StartTimer { timer, after } => {
            format!("start {timer} after {}", format_duration(after))
        }
        Action::Call {
            program,
            function,
            args,
            ..
        } => format!("call {program}.{function}({})", format_args(args)),
        Action::Emit {
            event, args, to, ..
        } => {
            let mut s = if args.is_empty() {
                format!("emit {event}")
            } else {
                format!("emit {event}({})", format_args(args))
            };
            if let Some(net) = to {
                let _ = write!(s, " to {net}");
            }
            s
        }
    }
}

fn format_duration(d: &DurationExpr) -> String {
    match d {
        DurationExpr::Literal { value, unit, .. } => {
            format!("{}{}", format_number(*value), unit.suffix())
        }
        DurationExpr::Seconds(n) => n.text.clone(),
        DurationExpr::SelfSeconds(n) => format!("self.{n}"),
    }
}

/// A number without a needless `.0` (durations), exact to the bit.
fn format_number(v: f64) -> String {
    if v.fract() == 0.0 && v.abs() < 1e15 {
        format!("{}", v as i64)
    } else {
        format!("{v:?}")
    }
}

pub use petrel_value::format_float;

fn format_args(args: &[Expr]) -> String {
    args.iter().map(format_expr).collect::<Vec<_>>().join(", ")
}

/// An argument as written.
pub fn format_expr(e: &Expr) -> String {
    match e {
        Expr::Int(v, _) => v.to_string(),
        Expr::Float(v, _) => format_float(*v),
        Expr::Bool(b, _) => b.to_string(),
        Expr::Text(s, _) => quote(s),
        Expr::List(items, _) => format!("[{}]", format_args(items)),
        Expr::Var(n) => n.text.clone(),
        Expr::SelfParam(n) => format!("self.{n}"),
    }
}

pub use petrel_value::quote;
