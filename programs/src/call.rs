//! A call received from the player, and typed access to its arguments.

use std::fmt;

use petrel_ipc::Value;

use crate::error::ProgramError;

/// A call of the player to one of the programs this process hosts: `PROGRAM.FUNCTION(args)`.
///
/// The player checked the arguments against the manifest before sending, but a program must not
/// trust its peer: the typed accessors ([`float`](Self::float), [`text`](Self::text)...) return
/// an [`ArgError`] naming the function, the position and the types when an argument is missing
/// or of another type.
///
/// `Call::default()` is an empty call, for [`Program::recv_into`](crate::Program::recv_into) to
/// receive calls into.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Call {
    /// The program the call was addressed to (one of the names the process connected as).
    pub program: String,
    /// The function called.
    pub function: String,
    /// The arguments, by position.
    pub args: Vec<Value>,
}

/// An argument of a [`Call`] is missing or of the wrong type.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ArgError {
    /// The call has fewer arguments than asked for.
    Missing {
        /// `PROGRAM.FUNCTION` of the call.
        function: String,
        /// Position of the argument asked for (from 0).
        index: usize,
        /// The type asked for, as the net language writes it.
        expected: &'static str,
        /// Number of arguments the call has.
        count: usize,
    },
    /// The argument has another type.
    WrongType {
        /// `PROGRAM.FUNCTION` of the call.
        function: String,
        /// Position of the argument (from 0).
        index: usize,
        /// The type asked for, as the net language writes it.
        expected: &'static str,
        /// The type found.
        found: &'static str,
    },
    /// The call has another number of arguments than the function takes.
    Count {
        /// `PROGRAM.FUNCTION` of the call.
        function: String,
        /// Number of arguments the function takes.
        expected: usize,
        /// Number of arguments the call has.
        found: usize,
    },
}

fn arguments(n: usize) -> String {
    match n {
        0 => "no argument".to_owned(),
        1 => "1 argument".to_owned(),
        n => format!("{n} arguments"),
    }
}

impl fmt::Display for ArgError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ArgError::Missing {
                function,
                index,
                expected,
                count,
            } => write!(
                f,
                "call {function}: argument {index} ({expected}) is missing, the call has {}; \
                 check the function's parameters in petrel.toml",
                arguments(*count)
            ),
            ArgError::WrongType {
                function,
                index,
                expected,
                found,
            } => write!(
                f,
                "call {function}: argument {index} should be {} {expected}, found {} {found}; \
                 check the function's parameters in petrel.toml",
                article(expected),
                article(found)
            ),
            ArgError::Count {
                function,
                expected,
                found,
            } => write!(
                f,
                "call {function}: the function takes {}, the call has {}; check the function's \
                 parameters in petrel.toml",
                arguments(*expected),
                arguments(*found)
            ),
        }
    }
}

impl std::error::Error for ArgError {}

fn article(type_name: &str) -> &'static str {
    if type_name.starts_with(['a', 'e', 'i', 'o', 'u']) {
        "an"
    } else {
        "a"
    }
}

impl Call {
    /// A call of `program.function(args)`.
    pub fn new(program: impl Into<String>, function: impl Into<String>, args: Vec<Value>) -> Self {
        Call {
            program: program.into(),
            function: function.into(),
            args,
        }
    }

    /// `PROGRAM.FUNCTION`, as errors and logs name the call.
    pub fn qualified_name(&self) -> String {
        format!("{}.{}", self.program, self.function)
    }

    /// The error for a call of a function the program does not have, to log.
    pub fn unknown_function(&self) -> ProgramError {
        ProgramError::UnknownFunction {
            program: self.program.clone(),
            function: self.function.clone(),
        }
    }

    /// Argument `index`, whatever its type.
    pub fn arg(&self, index: usize) -> Result<&Value, ArgError> {
        self.arg_of(index, "value")
    }

    fn arg_of(&self, index: usize, expected: &'static str) -> Result<&Value, ArgError> {
        self.args.get(index).ok_or_else(|| ArgError::Missing {
            function: self.qualified_name(),
            index,
            expected,
            count: self.args.len(),
        })
    }

    fn wrong(&self, index: usize, expected: &'static str, found: &Value) -> ArgError {
        ArgError::WrongType {
            function: self.qualified_name(),
            index,
            expected,
            found: found.type_name(),
        }
    }

    /// Checks that the call has exactly `n` arguments.
    pub fn expect_arity(&self, n: usize) -> Result<(), ArgError> {
        if self.args.len() == n {
            Ok(())
        } else {
            Err(ArgError::Count {
                function: self.qualified_name(),
                expected: n,
                found: self.args.len(),
            })
        }
    }

    /// Argument `index` as a float. An int is accepted and converted, as the net language
    /// accepts an int literal where a float is declared (`climb(300)`).
    pub fn float(&self, index: usize) -> Result<f64, ArgError> {
        match self.arg_of(index, "float")? {
            Value::Float(v) => Ok(*v),
            Value::Int(v) => Ok(*v as f64),
            other => Err(self.wrong(index, "float", other)),
        }
    }

    /// Argument `index` as an int.
    pub fn int(&self, index: usize) -> Result<i64, ArgError> {
        match self.arg_of(index, "int")? {
            Value::Int(v) => Ok(*v),
            other => Err(self.wrong(index, "int", other)),
        }
    }

    /// Argument `index` as a bool.
    pub fn bool(&self, index: usize) -> Result<bool, ArgError> {
        match self.arg_of(index, "bool")? {
            Value::Bool(v) => Ok(*v),
            other => Err(self.wrong(index, "bool", other)),
        }
    }

    /// Argument `index` as a text.
    pub fn text(&self, index: usize) -> Result<&str, ArgError> {
        match self.arg_of(index, "text")? {
            Value::Text(v) => Ok(v),
            other => Err(self.wrong(index, "text", other)),
        }
    }

    /// Argument `index` as a list of floats (`[float]`, a position for instance).
    pub fn floats(&self, index: usize) -> Result<&[f64], ArgError> {
        match self.arg_of(index, "[float]")? {
            Value::FloatList(v) => Ok(v),
            other => Err(self.wrong(index, "[float]", other)),
        }
    }
}

/// Writes a value as the net language writes a literal: `300`, `2.5`, `true`, `"camera"`,
/// `[48.71, 2.21, 300.0]`.
pub fn write_value(f: &mut impl fmt::Write, value: &Value) -> fmt::Result {
    match value {
        Value::Int(v) => write!(f, "{v}"),
        Value::Float(v) => write!(f, "{v:?}"),
        Value::Bool(v) => write!(f, "{v}"),
        Value::Text(v) => write!(f, "{v:?}"),
        Value::FloatList(v) => {
            f.write_char('[')?;
            for (i, x) in v.iter().enumerate() {
                if i > 0 {
                    f.write_str(", ")?;
                }
                write!(f, "{x:?}")?;
            }
            f.write_char(']')
        }
    }
}

/// Writes `name(v1, v2)`, as logs show calls and events.
pub fn write_invocation(f: &mut impl fmt::Write, name: &str, values: &[Value]) -> fmt::Result {
    f.write_str(name)?;
    f.write_char('(')?;
    for (i, v) in values.iter().enumerate() {
        if i > 0 {
            f.write_str(", ")?;
        }
        write_value(f, v)?;
    }
    f.write_char(')')
}

impl fmt::Display for Call {
    /// `GUI.transit([48.71, 2.21, 300.0])`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}.", self.program)?;
        write_invocation(f, &self.function, &self.args)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn climb(args: Vec<Value>) -> Call {
        Call::new("GUI", "climb", args)
    }

    #[test]
    fn typed_accessors() {
        let call = Call::new(
            "GUI",
            "f",
            vec![
                Value::Float(2.5),
                Value::Int(3),
                Value::Bool(true),
                Value::Text("camera".into()),
                Value::FloatList(vec![1.0, 2.0]),
            ],
        );
        assert_eq!(call.float(0).unwrap(), 2.5);
        assert_eq!(call.float(1).unwrap(), 3.0);
        assert_eq!(call.int(1).unwrap(), 3);
        assert!(call.bool(2).unwrap());
        assert_eq!(call.text(3).unwrap(), "camera");
        assert_eq!(call.floats(4).unwrap(), &[1.0, 2.0]);
        assert_eq!(call.arg(0).unwrap(), &Value::Float(2.5));
        call.expect_arity(5).unwrap();
    }

    #[test]
    fn errors_name_the_function_the_index_and_the_types() {
        let call = climb(vec![Value::Text("high".into())]);
        let e = call.float(0).unwrap_err();
        assert_eq!(
            e,
            ArgError::WrongType {
                function: "GUI.climb".into(),
                index: 0,
                expected: "float",
                found: "text",
            }
        );
        let text = e.to_string();
        assert!(
            text.starts_with("call GUI.climb: argument 0 should be a float, found a text"),
            "{text}"
        );
        let e = call.int(0).unwrap_err().to_string();
        assert!(e.contains("should be an int, found a text"), "{e}");
        let e = call.floats(2).unwrap_err();
        assert!(matches!(
            e,
            ArgError::Missing {
                index: 2,
                count: 1,
                expected: "[float]",
                ..
            }
        ));
        assert!(
            e.to_string().starts_with(
                "call GUI.climb: argument 2 ([float]) is missing, the call has 1 argument"
            ),
            "{e}"
        );
        let e = call.expect_arity(0).unwrap_err().to_string();
        assert!(
            e.starts_with(
                "call GUI.climb: the function takes no argument, the call has 1 argument"
            ),
            "{e}"
        );
        assert!(call.bool(0).is_err() && call.text(1).is_err());
    }

    #[test]
    fn display_writes_literals() {
        let call = Call::new(
            "GUI",
            "transit",
            vec![
                Value::FloatList(vec![48.71, 2.21, 300.0]),
                Value::Text("a \"b\"".into()),
                Value::Int(-2),
                Value::Bool(false),
                Value::Float(1.0),
            ],
        );
        assert_eq!(
            call.to_string(),
            r#"GUI.transit([48.71, 2.21, 300.0], "a \"b\"", -2, false, 1.0)"#
        );
        assert_eq!(Call::new("GUI", "roll", vec![]).to_string(), "GUI.roll()");
    }
}
