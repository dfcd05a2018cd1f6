//! The typed values of Petrel: an event's parameters, a call's arguments.
//!
//! One type from end to end. A value is written in a net or a script (`3`, `2.5`, `true`,
//! `"text"`, `[1.0, 2.0]`), checked against a declared [`Type`], carried by the engine, encoded
//! on the wire (bincode, [`bincode::Encode`]/[`bincode::Decode`]), recorded in the journal and
//! shown to people ([`Value::literal`], the language's own spelling) and tools
//! ([`Value::to_json`]). The crates that do each of these (`petrel-nets`, `petrel-player`,
//! `petrel-ipc`, `petrel-can-bridge`) all use this type, so a value changes form only at the
//! edges: text in, bytes on the wire, JSON out.

#![warn(missing_docs)]

use bincode::{Decode, Encode};
use std::fmt;

/// The type of an event parameter or a function argument.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Type {
    /// A 64-bit signed integer.
    Int,
    /// A 64-bit float.
    Float,
    /// `true` or `false`.
    Bool,
    /// UTF-8 text.
    Text,
    /// A list of floats (waypoints, for instance).
    FloatList,
}

impl Type {
    /// Every type, in documentation order.
    pub const ALL: [Type; 5] = [
        Type::Int,
        Type::Float,
        Type::Bool,
        Type::Text,
        Type::FloatList,
    ];

    /// The spelling used in manifests and nets.
    pub fn keyword(self) -> &'static str {
        match self {
            Type::Int => "int",
            Type::Float => "float",
            Type::Bool => "bool",
            Type::Text => "text",
            Type::FloatList => "[float]",
        }
    }

    /// Parses a type spelling (`int`, `float`, `bool`, `text`, `[float]`; spaces ignored).
    pub fn from_keyword(s: &str) -> Option<Type> {
        let compact: String = s.chars().filter(|c| !c.is_whitespace()).collect();
        Type::ALL.into_iter().find(|t| t.keyword() == compact)
    }

    /// A neutral value of this type (0, 0.0, false, "", []).
    pub fn neutral(self) -> Value {
        match self {
            Type::Int => Value::Int(0),
            Type::Float => Value::Float(0.0),
            Type::Bool => Value::Bool(false),
            Type::Text => Value::Text(String::new()),
            Type::FloatList => Value::FloatList(Vec::new()),
        }
    }
}

impl fmt::Display for Type {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.keyword())
    }
}

/// A typed value: an event parameter, a call argument.
#[derive(Clone, Debug, PartialEq, Encode, Decode)]
pub enum Value {
    /// An `int`.
    Int(i64),
    /// A `float`.
    Float(f64),
    /// A `bool`.
    Bool(bool),
    /// A `text`.
    Text(String),
    /// A `[float]`.
    FloatList(Vec<f64>),
}

impl Value {
    /// The value's type.
    pub fn ty(&self) -> Type {
        match self {
            Value::Int(_) => Type::Int,
            Value::Float(_) => Type::Float,
            Value::Bool(_) => Type::Bool,
            Value::Text(_) => Type::Text,
            Value::FloatList(_) => Type::FloatList,
        }
    }

    /// The name of the value's type, as the net language writes it.
    pub fn type_name(&self) -> &'static str {
        self.ty().keyword()
    }

    /// The value as the net language writes it: `3`, `2.5`, `true`, `"a \"b\""`, `[1.0, 2.0]`.
    /// Reading it back gives the same value, to the bit for floats.
    pub fn literal(&self) -> String {
        match self {
            Value::Int(i) => i.to_string(),
            Value::Float(f) => format_float(*f),
            Value::Bool(b) => b.to_string(),
            Value::Text(s) => quote(s),
            Value::FloatList(l) => format!(
                "[{}]",
                l.iter()
                    .map(|f| format_float(*f))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }
    }

    /// The value as JSON: a number, a boolean, a string or an array of numbers. JSON has no
    /// NaN nor infinity: those floats become `null`.
    pub fn to_json(&self) -> serde_json::Value {
        match self {
            Value::Int(i) => (*i).into(),
            Value::Float(f) => (*f).into(),
            Value::Bool(b) => (*b).into(),
            Value::Text(s) => s.clone().into(),
            Value::FloatList(l) => l.clone().into(),
        }
    }
}

impl fmt::Display for Value {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.literal())
    }
}

impl From<i64> for Value {
    fn from(v: i64) -> Self {
        Value::Int(v)
    }
}
impl From<f64> for Value {
    fn from(v: f64) -> Self {
        Value::Float(v)
    }
}
impl From<bool> for Value {
    fn from(v: bool) -> Self {
        Value::Bool(v)
    }
}
impl From<String> for Value {
    fn from(v: String) -> Self {
        Value::Text(v)
    }
}
impl From<&str> for Value {
    fn from(v: &str) -> Self {
        Value::Text(v.to_owned())
    }
}
impl From<Vec<f64>> for Value {
    fn from(v: Vec<f64>) -> Self {
        Value::FloatList(v)
    }
}

/// Longest program name (the node name `program/NAME` of its process must fit in the 32-byte
/// origin field of every message header).
pub const MAX_PROGRAM_NAME_LEN: usize = 24;

/// Whether `name` can name a software program of a vehicle: 1 to [`MAX_PROGRAM_NAME_LEN`]
/// ASCII letters, digits, `_` or `-`. The manifest's checker, the CAN data server's
/// configuration and the shared-memory transport all hold program names to this one rule.
pub fn is_program_name(name: &str) -> bool {
    (1..=MAX_PROGRAM_NAME_LEN).contains(&name.len())
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
}

/// A float as the language writes it: the shortest text that reads back to the same bits, with
/// `.0` kept on whole numbers (`2.0`, not `2`).
pub fn format_float(v: f64) -> String {
    // Debug prints the shortest round-tripping text and keeps `.0`.
    format!("{v:?}")
}

/// A text literal with its escapes (`"`, `\`, newline, tab).
pub fn quote(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\t' => out.push_str("\\t"),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn literals_are_the_language_spelling() {
        assert_eq!(Value::Int(-3).literal(), "-3");
        assert_eq!(Value::Float(2.0).literal(), "2.0");
        assert_eq!(Value::Float(0.1).literal(), "0.1");
        assert_eq!(Value::Bool(true).literal(), "true");
        assert_eq!(Value::Text("a \"b\"\n".into()).literal(), r#""a \"b\"\n""#);
        assert_eq!(Value::FloatList(vec![1.0, -2.5]).literal(), "[1.0, -2.5]");
        assert_eq!(Value::Text("x".into()).to_string(), "\"x\"");
    }

    #[test]
    fn types_and_keywords() {
        for t in Type::ALL {
            assert_eq!(Type::from_keyword(t.keyword()), Some(t));
            assert_eq!(t.neutral().ty(), t);
        }
        assert_eq!(Type::from_keyword("[ float ]"), Some(Type::FloatList));
        assert_eq!(Type::from_keyword("double"), None);
        assert_eq!(Value::FloatList(vec![]).type_name(), "[float]");
    }

    #[test]
    fn program_names() {
        for ok in ["CAN", "can_bridge", "a-b", "PLN9", &"P".repeat(24)] {
            assert!(is_program_name(ok), "{ok}");
        }
        for bad in ["", "a b", "a.b", "é", "a/b", &"P".repeat(25)] {
            assert!(!is_program_name(bad), "{bad}");
        }
    }

    #[test]
    fn json() {
        assert_eq!(Value::Int(4).to_json(), serde_json::json!(4));
        assert_eq!(Value::Float(f64::NAN).to_json(), serde_json::Value::Null);
        assert_eq!(
            Value::FloatList(vec![1.5]).to_json(),
            serde_json::json!([1.5])
        );
        assert_eq!(Value::Text("t".into()).to_json(), serde_json::json!("t"));
    }
}
