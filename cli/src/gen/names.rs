//! How `petrel gen` turns the project's names into Rust identifiers: one rule, for every
//! place a name of the project lands in the generated code.
//!
//! A Petrel name is `[A-Za-z_][A-Za-z0-9_]*` (not `true`, `false`, `self`); most are Rust
//! identifiers as they are. The others, and those that would meet a name Rust or the generated
//! code already gives a meaning to *in the scope where the name lands* (its [`Role`]), change:
//!
//! 1. a name that ends in `_`, or that is taken in its role (a keyword that cannot be raw:
//!    `self` `Self` `super` `crate`; a name of Rust's prelude the role can meet; a name the
//!    generated code uses there itself), gets one more `_`: `out` becomes `out_`, `out_`
//!    becomes `out__`, `_` becomes `__`;
//! 2. else a Rust keyword (strict or reserved, in any edition) becomes a raw identifier:
//!    `type` becomes `r#type`;
//! 3. else the name stays.
//!
//! Why no two names of one role can meet: the three cases give disjoint results (only case 1
//! ends in `_`, only case 2 starts with `r#`, case 3 is neither), and each is one-to-one (case
//! 1 adds one `_`, so removing it gives the name back). No taken name ends in `_` and no
//! keyword does, so case 1 never lands on one either. The rule looks at the name alone, never
//! at the other names of the project: a name's identifier does not change when another name is
//! declared, so a handler or an event helper a user calls keeps its meaning.
//!
//! Two names are converted before the rule, and a conversion can merge names: the handler of a
//! function in a process of several programs is `program_function`, the program in lower case
//! (`GUI.roll` and `gui.roll` both give `gui_roll`; `A_B.c` and `A.b_c` both give `a_b_c`);
//! the state struct is the programs' names in UpperCamelCase. The second of two merged
//! handlers gets more `_` until it is free (the only place the declaration order matters: the
//! regeneration check refuses when a handler the user wrote changes function). Every
//! identifier that is not the name verbatim is listed, with its reason, in the generated
//! `src/interface.rs`.

use std::collections::BTreeSet;
use std::fmt;

/// Where a name of the project lands in the generated code: each role has its own scope, and
/// its own taken names.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// A parameter of a function (the handler's argument, a local of its default body and of
    /// the user's handler, in a format string) or of an event (the event helper's argument).
    Param,
    /// A function's handler: a method of the `Handlers` trait, called by `dispatch`.
    Handler,
    /// An event's helper: an inherent method of `Events`.
    Event,
    /// The programs' state: the struct of `src/handlers.rs`, named in `src/main.rs`.
    State,
}

/// Why a name is not used verbatim.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reason {
    /// A Rust keyword: made raw.
    Keyword,
    /// `self`, `Self`, `super` or `crate`, which cannot be raw.
    NotRaw,
    /// A name of Rust's prelude that this role can meet.
    Prelude,
    /// A name the generated code uses in this role's scope.
    Generated,
    /// Ends in `_`, as renamed names do.
    Underscore,
    /// Two names of the project give the same identifier after the conversion.
    Merged,
}

impl fmt::Display for Reason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Reason::Keyword => "a Rust keyword",
            Reason::NotRaw => "a Rust keyword that cannot be raw",
            Reason::Prelude => "a name of Rust's prelude",
            Reason::Generated => "a name the generated code uses",
            Reason::Underscore => "ends in `_`, as renamed names do",
            Reason::Merged => "another name gives the same identifier",
        })
    }
}

/// The identifier of a name of the project, and why it is not the name itself (`None`: it is).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Ident {
    /// The Rust identifier (`climb`, `r#type`, `tick_`).
    pub rust: String,
    /// Why it differs from the name (or from its case conversion, for the state struct).
    pub reason: Option<Reason>,
}

impl fmt::Display for Ident {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.rust)
    }
}

/// Rust's strict and reserved keywords, of every edition up to 2024, that can be raw.
const KEYWORDS: &[&str] = &[
    "as", "async", "await", "break", "const", "continue", "dyn", "else", "enum", "extern", "false",
    "fn", "for", "if", "impl", "in", "let", "loop", "match", "mod", "move", "mut", "pub", "ref",
    "return", "static", "struct", "trait", "true", "type", "unsafe", "use", "where", "while",
    "abstract", "become", "box", "do", "final", "gen", "macro", "override", "priv", "try",
    "typeof", "unsized", "virtual", "yield",
];

/// The keywords that cannot be raw identifiers.
const NOT_RAW: &[&str] = &["self", "Self", "super", "crate"];

/// The value names of Rust's prelude: a parameter named `None` would be a pattern that
/// refutes, one named `drop` would hide the function.
const PRELUDE_VALUES: &[&str] = &["Some", "None", "Ok", "Err", "drop"];

/// The type, trait and derive names of Rust's prelude (2021 and 2024): a struct named `Result`
/// would change the handlers' return type.
const PRELUDE_TYPES: &[&str] = &[
    "AsMut",
    "AsRef",
    "AsyncFn",
    "AsyncFnMut",
    "AsyncFnOnce",
    "Box",
    "Clone",
    "Copy",
    "Debug",
    "Default",
    "DoubleEndedIterator",
    "Drop",
    "Eq",
    "ExactSizeIterator",
    "Extend",
    "Fn",
    "FnMut",
    "FnOnce",
    "From",
    "FromIterator",
    "Future",
    "Hash",
    "Into",
    "IntoFuture",
    "IntoIterator",
    "Iterator",
    "Ord",
    "Option",
    "PartialEq",
    "PartialOrd",
    "Result",
    "Send",
    "Sized",
    "String",
    "Sync",
    "ToOwned",
    "ToString",
    "TryFrom",
    "TryInto",
    "Unpin",
    "Vec",
];

/// The names the generated code uses in each role's scope (keep in step with the templates of
/// `gen.rs`; the corpus test of tests/tests/gen.rs tries every identifier of the generated
/// files in every role):
/// - a parameter meets the handler's `out`, the function its default body calls, and the
///   constant of `src/interface.rs` (a parameter named after a constant is a pattern that
///   refutes);
/// - a handler meets the trait's own method `tick`;
/// - an event helper meets the helpers `Events` has for every program;
/// - the state struct meets the names `src/handlers.rs` and `src/main.rs` import.
fn generated(role: Role) -> &'static [&'static str] {
    match role {
        Role::Param => &["out", "unhandled", "PROGRAMS"],
        Role::Handler => &["tick"],
        Role::Event => &["from", "send_as", "emit"],
        Role::State => &["Events", "Handlers", "ProgramError", "ExitCode"],
    }
}

/// Why `name` cannot stay as it is in `role` (before the keyword rule).
fn taken(name: &str, role: Role) -> Option<Reason> {
    if NOT_RAW.contains(&name) {
        Some(Reason::NotRaw)
    } else if generated(role).contains(&name) {
        Some(Reason::Generated)
    } else if match role {
        Role::Param => PRELUDE_VALUES.contains(&name),
        Role::State => PRELUDE_VALUES.contains(&name) || PRELUDE_TYPES.contains(&name),
        Role::Handler | Role::Event => false,
    } {
        Some(Reason::Prelude)
    } else {
        None
    }
}

/// The identifier of `name` in `role`, by the rule of this module.
pub fn ident(name: &str, role: Role) -> Ident {
    let (rust, reason) = if name.ends_with('_') {
        (format!("{name}_"), Some(Reason::Underscore))
    } else if let Some(reason) = taken(name, role) {
        (format!("{name}_"), Some(reason))
    } else if KEYWORDS.contains(&name) {
        (format!("r#{name}"), Some(Reason::Keyword))
    } else {
        (name.to_string(), None)
    };
    Ident { rust, reason }
}

/// The handlers of `functions` (program, function), in order: the function's name, or
/// `program_function` (program in lower case) in a process of several programs.
pub fn handlers(functions: &[(&str, &str)], programs: usize) -> Vec<Ident> {
    let mut used = BTreeSet::new();
    functions
        .iter()
        .map(|(program, function)| {
            let mut id = if programs > 1 {
                ident(
                    &format!("{}_{function}", program.to_lowercase()),
                    Role::Handler,
                )
            } else {
                ident(function, Role::Handler)
            };
            while used.contains(&id.rust) {
                id.rust.push('_');
                id.reason = Some(Reason::Merged);
            }
            used.insert(id.rust.clone());
            id
        })
        .collect()
}

/// The state struct of `programs`: their names in UpperCamelCase (`GUI`, `PLD`: `GuiPld`;
/// `use_payload`: `UsePayload`), `Program` before a name that has no letter to start with,
/// then the rule.
pub fn state(programs: &[String]) -> Ident {
    let camel: String = programs
        .iter()
        .flat_map(|p| p.split('_'))
        .filter(|part| !part.is_empty())
        .map(|part| {
            let lower = part.to_lowercase();
            let mut chars = lower.chars();
            match chars.next() {
                Some(first) => first.to_uppercase().collect::<String>() + chars.as_str(),
                None => String::new(),
            }
        })
        .collect();
    let camel = if camel.starts_with(|c: char| c.is_ascii_alphabetic()) {
        camel
    } else {
        format!("Program{camel}")
    };
    ident(&camel, Role::State)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rust(name: &str, role: Role) -> String {
        ident(name, role).rust
    }

    #[test]
    fn names_stay_unless_rust_or_the_generated_code_needs_them() {
        assert_eq!(rust("climb", Role::Param), "climb");
        assert_eq!(rust("type", Role::Param), "r#type");
        assert_eq!(rust("gen", Role::Handler), "r#gen");
        assert_eq!(rust("self", Role::Param), "self_");
        assert_eq!(rust("Self", Role::Handler), "Self_");
        assert_eq!(rust("_", Role::Param), "__");
        assert_eq!(rust("out", Role::Param), "out_");
        assert_eq!(rust("out_", Role::Param), "out__");
        assert_eq!(rust("None", Role::Param), "None_");
        assert_eq!(rust("tick", Role::Handler), "tick_");
        assert_eq!(rust("emit", Role::Event), "emit_");
        // Each role has its own scope: `out` and `tick` are free elsewhere.
        assert_eq!(rust("out", Role::Event), "out");
        assert_eq!(rust("tick", Role::Param), "tick");
        assert_eq!(rust("None", Role::Handler), "None");
        assert_eq!(ident("type", Role::Param).reason, Some(Reason::Keyword));
        assert_eq!(ident("Some", Role::Param).reason, Some(Reason::Prelude));
    }

    /// The proof of the module's doc, checked over every name the rule treats apart, their
    /// neighbours, and every role: no two names give one identifier, none gives a taken one.
    #[test]
    fn no_two_names_meet_and_none_meets_a_taken_one() {
        let mut names: Vec<String> = Vec::new();
        for role in [Role::Param, Role::Handler, Role::Event, Role::State] {
            names.extend(generated(role).iter().map(|s| s.to_string()));
        }
        for list in [KEYWORDS, NOT_RAW, PRELUDE_VALUES, PRELUDE_TYPES] {
            names.extend(list.iter().map(|s| s.to_string()));
        }
        for n in names.clone() {
            names.push(format!("{n}_"));
            names.push(format!("{n}__"));
        }
        names.extend(["_", "__", "___", "x", "x_"].map(String::from));
        names.sort();
        names.dedup();
        for role in [Role::Param, Role::Handler, Role::Event, Role::State] {
            let mut seen = std::collections::BTreeMap::new();
            for n in &names {
                let id = ident(n, role);
                assert!(
                    taken(&id.rust, role).is_none(),
                    "{n} gives {id} in {role:?}"
                );
                assert_ne!(id.rust, "_");
                // `r#x` is the identifier `x`.
                let plain = id.rust.trim_start_matches("r#").to_string();
                if let Some(first) = seen.insert(plain, n.clone()) {
                    panic!("{first} and {n} both give {id} in {role:?}");
                }
            }
        }
    }

    #[test]
    fn converted_names_that_merge_are_told_apart_in_order() {
        let h = handlers(
            &[("GUI", "roll"), ("gui", "roll"), ("A_B", "c"), ("A", "b_c")],
            3,
        );
        let r: Vec<&str> = h.iter().map(|i| i.rust.as_str()).collect();
        assert_eq!(r, ["gui_roll", "gui_roll_", "a_b_c", "a_b_c_"]);
        assert_eq!(h[1].reason, Some(Reason::Merged));
        assert_eq!(handlers(&[("GUI", "tick")], 1)[0].rust, "tick_");
        assert_eq!(handlers(&[("GUI", "tick")], 2)[0].rust, "gui_tick");
    }

    #[test]
    fn the_state_struct_is_upper_camel_case_and_never_a_taken_name() {
        let s = |p: &[&str]| state(&p.iter().map(|s| s.to_string()).collect::<Vec<_>>()).rust;
        assert_eq!(s(&["GUI", "PLD"]), "GuiPld");
        assert_eq!(s(&["use_payload"]), "UsePayload");
        assert_eq!(s(&["SELF"]), "Self_");
        assert_eq!(s(&["EVENTS"]), "Events_");
        assert_eq!(s(&["RESULT"]), "Result_");
        assert_eq!(s(&["PROGRAM_ERROR"]), "ProgramError_");
        assert_eq!(s(&["_"]), "Program");
        assert_eq!(s(&["_2"]), "Program2");
    }
}
