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
        let mut out = String::new();
        self.write_literal(&mut out);
        out
    }

    /// Appends [`literal`](Self::literal) to `out`, without allocating anything but `out`'s
    /// growth (the player writes every call's text this way, once per round trip).
    pub fn write_literal(&self, out: &mut String) {
        match self {
            Value::Int(i) => write_int(out, *i),
            Value::Float(f) => write_float(out, *f),
            Value::Bool(b) => out.push_str(if *b { "true" } else { "false" }),
            Value::Text(s) => write_quoted(out, s),
            Value::FloatList(l) => write_float_list(out, l),
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
    let mut out = String::new();
    write_float(&mut out, v);
    out
}

/// Appends [`format_float`]'s text to `out`.
///
/// The text is Rust's `{:?}` of the float, which journals and `petrel run`'s JSON lines have
/// always held (replay compares them): decimal with at least one fractional digit from 1e-4 to
/// 1e16, `1.5e-7` / `1e16` outside, `NaN`, `inf`, `-inf`, `-0.0`. The shortest digits come from
/// `ryu` (several times faster than `{:?}`: the player formats every call's arguments) and are
/// laid out here as `{:?}` lays them out; both pick the shortest digits that read back to the
/// same bits, the closest to the float when there are several (a test compares the two on
/// random bit patterns).
pub fn write_float(out: &mut String, v: f64) {
    if !v.is_finite() {
        out.push_str(if v.is_nan() {
            "NaN"
        } else if v > 0.0 {
            "inf"
        } else {
            "-inf"
        });
        return;
    }
    if v == 0.0 {
        out.push_str(if v.is_sign_negative() { "-0.0" } else { "0.0" });
        return;
    }
    if write_short_decimal(out, v) {
        return;
    }
    let mut buffer = ryu::Buffer::new();
    let text = buffer.format_finite(v);
    let Some(shortest) = Shortest::parse(text).filter(|s| !is_tie(v, s.len())) else {
        // A tie, or not a form ryu writes: `{:?}` itself says it.
        use std::fmt::Write as _;
        let _ = write!(out, "{v:?}");
        return;
    };
    if v.is_sign_negative() {
        out.push('-');
    }
    let digits = shortest.digits();
    // The value is 0.DIGITS x 10^exp.
    let exp = shortest.exp;
    let n = digits.len() as i32;
    let abs = v.abs();
    if !(1e-4..1e16).contains(&abs) {
        // `{:?}`'s exponential form: `1e16`, `1.25e-7` (no `+`, no `.0`).
        out.push_str(&digits[..1]);
        if n > 1 {
            out.push('.');
            out.push_str(&digits[1..]);
        }
        out.push('e');
        write_int(out, i64::from(exp - 1));
    } else if exp <= 0 {
        out.push_str("0.");
        push_zeros(out, -exp);
        out.push_str(digits);
    } else if exp < n {
        out.push_str(&digits[..exp as usize]);
        out.push('.');
        out.push_str(&digits[exp as usize..]);
    } else {
        out.push_str(digits);
        push_zeros(out, exp - n);
        out.push_str(".0");
    }
}

/// Writes `v` when it has few decimals (`0.5`, `12.25`, `-3.0`, most values a mission
/// holds) without the general shortest-digits search; false, having written nothing, when it
/// has more than [`SHORT_DECIMALS`] or lies outside the decimal form.
///
/// For the fewest decimals `k` such that `m = v x 10^k` (as a float) is a whole number below
/// 2^52 and `m / 10^k` reads back as `v`, the text `m x 10^-k` reads back to `v` (the
/// division of exact operands rounds as parsing does), no text with fewer decimals does (`k`
/// is the least), and `m` is the closest such text (the product is within a quarter of `m`
/// below 2^52, any other whole number at least three quarters away): what `{:?}` writes.
fn write_short_decimal(out: &mut String, v: f64) -> bool {
    let abs = v.abs();
    if !(1e-4..1e15).contains(&abs) {
        return false;
    }
    let mut scale = 1.0f64;
    for k in 0..=SHORT_DECIMALS {
        let m = abs * scale;
        if m >= 4_503_599_627_370_496.0 {
            return false;
        }
        let whole = m as u64;
        if whole as f64 == m && m / scale == abs {
            if v.is_sign_negative() {
                out.push('-');
            }
            let pow = 10u64.pow(k);
            write_int(out, (whole / pow) as i64);
            out.push('.');
            let mut fraction = whole % pow;
            let mut width = k;
            if width == 0 {
                out.push('0');
                return true;
            }
            while fraction.is_multiple_of(10) && width > 1 {
                fraction /= 10;
                width -= 1;
            }
            let mut digits = [b'0'; SHORT_DECIMALS as usize];
            for d in digits[..width as usize].iter_mut().rev() {
                *d = b'0' + (fraction % 10) as u8;
                fraction /= 10;
            }
            for &d in &digits[..width as usize] {
                out.push(d as char);
            }
            return true;
        }
        scale *= 10.0;
    }
    false
}

/// The most decimals [`write_short_decimal`] tries (powers of ten up to 10^9 are exact).
const SHORT_DECIMALS: u32 = 9;

/// Whether `v`'s shortest `digits` digits dropped exactly a half: its exact decimal has one
/// digit more, a final 5, and the two shortest candidates are equally close. `ryu` then
/// takes the even one and `{:?}` the one above (`1191008530710395.25`: `.2` and `.3`).
///
/// `v = m x 2^e` with `m` odd. A whole number (`e >= 0`) never ties: the digit it would drop
/// is worth less than half its spacing. Otherwise its exact decimal is the digits of
/// `m x 5^-e` (ending in 5), which has more than 18 digits, more than any tie, once `-e > 30`.
fn is_tie(v: f64, digits: usize) -> bool {
    let bits = v.to_bits();
    let field = ((bits >> 52) & 0x7ff) as i32;
    let fraction = bits & ((1 << 52) - 1);
    let (m, e) = if field == 0 {
        (fraction, -1074)
    } else {
        (fraction | (1 << 52), field - 1075)
    };
    if m == 0 {
        return false;
    }
    let zeros = m.trailing_zeros();
    let (m, e) = (m >> zeros, e + zeros as i32);
    if !(-30..0).contains(&e) {
        return false;
    }
    let exact = u128::from(m) * 5u128.pow((-e) as u32);
    exact.ilog10() as usize + 1 == digits + 1
}

fn push_zeros(out: &mut String, n: i32) {
    for _ in 0..n {
        out.push('0');
    }
}

/// The shortest digits of a float, without sign, leading or trailing zeros, and where the
/// decimal point goes: the value is `0.DIGITS x 10^exp`.
struct Shortest {
    digits: [u8; 24],
    len: usize,
    exp: i32,
}

impl Shortest {
    /// Reads ryu's text of a finite, non-zero float: `-?D*(.D*)?(e-?D+)?`.
    fn parse(text: &str) -> Option<Shortest> {
        let text = text.strip_prefix('-').unwrap_or(text);
        let (mantissa, e) = match text.split_once('e') {
            Some((m, e)) => (m, e.parse::<i32>().ok()?),
            None => (text, 0),
        };
        let mut all = [0u8; 24];
        let (mut len, mut point) = (0, None);
        for b in mantissa.bytes() {
            match b {
                b'.' if point.is_none() => point = Some(len),
                b'0'..=b'9' if len < all.len() => {
                    all[len] = b;
                    len += 1;
                }
                _ => return None,
            }
        }
        let start = all[..len].iter().take_while(|&&d| d == b'0').count();
        let end = len
            - all[start..len]
                .iter()
                .rev()
                .take_while(|&&d| d == b'0')
                .count();
        if start == end {
            return None;
        }
        let exp = point.unwrap_or(len) as i32 - start as i32 + e;
        let mut digits = [0u8; 24];
        digits[..end - start].copy_from_slice(&all[start..end]);
        Some(Shortest {
            digits,
            len: end - start,
            exp,
        })
    }

    fn len(&self) -> usize {
        self.len
    }

    fn digits(&self) -> &str {
        // Only ASCII digits were copied in.
        std::str::from_utf8(&self.digits[..self.len]).unwrap_or("0")
    }
}

/// Appends an int as the language writes it.
fn write_int(out: &mut String, v: i64) {
    let mut digits = [0u8; 20];
    let mut at = digits.len();
    let mut rest = v.unsigned_abs();
    loop {
        at -= 1;
        digits[at] = b'0' + (rest % 10) as u8;
        rest /= 10;
        if rest == 0 {
            break;
        }
    }
    if v < 0 {
        out.push('-');
    }
    for &d in &digits[at..] {
        out.push(d as char);
    }
}

/// Appends a list of floats as the language writes it: `[1.0, -2.5]`.
pub fn write_float_list(out: &mut String, list: &[f64]) {
    out.push('[');
    for (i, f) in list.iter().enumerate() {
        if i > 0 {
            out.push_str(", ");
        }
        write_float(out, *f);
    }
    out.push(']');
}

/// A text literal with its escapes (`"`, `\`, newline, tab).
pub fn quote(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    write_quoted(&mut out, s);
    out
}

/// Appends [`quote`]'s text to `out`.
pub fn write_quoted(out: &mut String, s: &str) {
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

    /// What the language wrote floats as before `write_float`: Rust's `{:?}`.
    fn reference(v: f64) -> String {
        format!("{v:?}")
    }

    #[test]
    fn floats_are_written_as_debug_writes_them() {
        let special = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            0.1,
            0.3,
            2.5,
            1e-4,
            -1e-4,
            9.999999999999999e-5,
            1e-5,
            1.5e-7,
            1e16,
            9999999999999998.0,
            1e15,
            123456789012345680.0,
            1e300,
            1.7976931348623157e308,
            f64::MAX,
            f64::MIN,
            f64::MIN_POSITIVE,
            f64::EPSILON,
            5e-324,
            -5e-324,
            f64::from_bits(0x000f_ffff_ffff_ffff), // the largest subnormal
            f64::NAN,
            -f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            1234.5678,
            100.0,
            4503599627370496.0,
            9007199254740993.0,
            0.001,
            0.000123,
        ];
        for v in special {
            let mut out = String::from("x");
            write_float(&mut out, v);
            assert_eq!(&out[1..], reference(v), "{v:e}");
            assert_eq!(format_float(v), reference(v));
        }
        // Whole numbers and powers of ten across the decimal/exponential boundaries.
        for e in -330..=310 {
            for m in [1.0, 1.5, 9.99, 7.0, 123.0] {
                let v = m * 10f64.powi(e);
                assert_eq!(format_float(v), reference(v), "{v:e}");
                assert_eq!(format_float(-v), reference(-v), "{v:e}");
            }
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(20_000))]

        #[test]
        fn any_bits_are_written_as_debug_writes_them(bits in proptest::prelude::any::<u64>()) {
            let v = f64::from_bits(bits);
            proptest::prop_assert_eq!(format_float(v), reference(v));
        }

        #[test]
        fn subnormals_are_written_as_debug_writes_them(bits in 0u64..(1u64 << 52), negative: bool) {
            let v = f64::from_bits(bits | (u64::from(negative) << 63));
            proptest::prop_assert_eq!(format_float(v), reference(v));
        }

        /// Floats with a short exact decimal (`m x 2^e`, small `-e`): where ties are.
        #[test]
        fn short_exact_floats_are_written_as_debug_writes_them(m in 1u64..(1u64 << 53), e in -40i32..4, negative: bool) {
            let v = m as f64 * 2f64.powi(e) * if negative { -1.0 } else { 1.0 };
            proptest::prop_assert_eq!(format_float(v), reference(v));
        }

        /// Floats with few decimals (the fast path) and their neighbours.
        #[test]
        fn few_decimal_floats_are_written_as_debug_writes_them(m in -10_000_000_000i64..10_000_000_000, k in 0i32..12, ulps in -2i64..=2) {
            let v = m as f64 / 10f64.powi(k);
            proptest::prop_assert_eq!(format_float(v), reference(v));
            let near = f64::from_bits((v.to_bits() as i64 + ulps) as u64);
            proptest::prop_assert_eq!(format_float(near), reference(near));
        }

        #[test]
        fn ordinary_floats_are_written_as_debug_writes_them(v in -1e20f64..1e20) {
            proptest::prop_assert_eq!(format_float(v), reference(v));
            let whole = v.trunc();
            proptest::prop_assert_eq!(format_float(whole), reference(whole));
            let tiny = v * 1e-25;
            proptest::prop_assert_eq!(format_float(tiny), reference(tiny));
        }

        #[test]
        fn ints_and_lists_are_written_as_before(i: i64, list in proptest::collection::vec(proptest::prelude::any::<f64>(), 0..8)) {
            proptest::prop_assert_eq!(Value::Int(i).literal(), i.to_string());
            let before = format!(
                "[{}]",
                list.iter().map(|f| reference(*f)).collect::<Vec<_>>().join(", ")
            );
            proptest::prop_assert_eq!(Value::FloatList(list).literal(), before);
        }
    }

    #[test]
    fn ints_at_the_ends_are_written_as_before() {
        for i in [0, -1, 9, 10, -10, i64::MAX, i64::MIN] {
            assert_eq!(Value::Int(i).literal(), i.to_string());
        }
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
