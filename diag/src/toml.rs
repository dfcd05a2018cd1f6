//! TOML files of a project read the same way everywhere: the manifest (`petrel.toml`),
//! `can.toml` and `vehicle.toml` (and its scenarios).
//!
//! [`parse`] turns the TOML parser's one error into a located diagnostic (the parser stops at
//! the first structure error, so there is at most one); [`Ordered`] reads a table keeping its
//! keys' order and places, which serde's maps forget.

use crate::report::{Diagnostic, Diagnostics};
use crate::source::{FileId, Span};
use ::toml::Spanned;
use serde::de::{Deserialize, DeserializeOwned, Deserializer, MapAccess, Visitor};

/// A TOML table read in document order, each key with its span: serde's maps forget the order
/// (meaningful for nets, events, rules...) and the keys' places (where diagnostics point).
pub struct Ordered<V>(pub Vec<(Spanned<String>, V)>);

impl<V> Default for Ordered<V> {
    fn default() -> Self {
        Ordered(Vec::new())
    }
}

impl<'de, V: Deserialize<'de>> Deserialize<'de> for Ordered<V> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V2<V>(std::marker::PhantomData<V>);
        impl<'de, V: Deserialize<'de>> Visitor<'de> for V2<V> {
            type Value = Ordered<V>;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a table")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
                let mut out = Vec::new();
                while let Some((k, v)) = map.next_entry()? {
                    out.push((k, v));
                }
                Ok(Ordered(out))
            }
        }
        d.deserialize_map(V2(std::marker::PhantomData))
    }
}

/// Reads `text` (the contents of `file`) as TOML into `T`. When it cannot (bad TOML, a
/// missing or unknown key, a wrong type), pushes one error `code` at the parser's location,
/// "`{what}` is not valid: `{the parser's message}`", labelled with that message, with `help`
/// (what the file holds and where it is documented), and returns `None`.
pub fn parse<T: DeserializeOwned>(
    file: FileId,
    text: &str,
    code: &'static str,
    what: &str,
    help: &str,
    diags: &mut Diagnostics,
) -> Option<T> {
    match ::toml::from_str(text) {
        Ok(t) => Some(t),
        Err(e) => {
            let (span, msg) = located(file, &e);
            diags.push(
                Diagnostic::error(code, span, format!("{what} is not valid: {msg}"))
                    .label(msg)
                    .help(help),
            );
            None
        }
    }
}

/// Where a TOML parse error is and what it says, on one line.
fn located(file: FileId, e: &::toml::de::Error) -> (Span, String) {
    let span = e
        .span()
        .map(|r| Span::new(file, r.start, r.end))
        .unwrap_or(Span::new(file, 0, 0));
    let msg = e
        .message()
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect::<Vec<_>>()
        .join(": ");
    (span, msg)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::source::SourceMap;

    #[derive(serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    struct File {
        #[serde(default)]
        table: Ordered<u32>,
    }

    #[test]
    fn a_table_keeps_its_keys_order_and_places() {
        let text = "[table]\nzulu = 1\nalpha = 2\nmike = 3\n";
        let mut diags = Diagnostics::new();
        let f: File = parse(FileId(0), text, "E0101", "the file", "", &mut diags).unwrap();
        let keys: Vec<(&str, u32)> = f
            .table
            .0
            .iter()
            .map(|(k, v)| (k.get_ref().as_str(), *v))
            .collect();
        assert_eq!(keys, [("zulu", 1), ("alpha", 2), ("mike", 3)]);
        assert_eq!(&text[f.table.0[1].0.span()], "alpha");
        assert!(diags.is_empty());
    }

    #[test]
    fn an_unreadable_file_is_one_error_at_its_line() {
        let mut sources = SourceMap::new();
        let text = "[table]\nzulu = 1\nwhat = \"x\"\n[other]\n";
        let file = sources.add("x.toml", text.to_string());
        let mut diags = Diagnostics::new();
        let f: Option<File> = parse(
            file,
            text,
            "E0101",
            "x.toml",
            "x.toml has [table]",
            &mut diags,
        );
        assert!(f.is_none());
        assert_eq!(diags.len(), 1);
        let d = diags.iter().next().unwrap();
        assert_eq!(d.code, "E0101");
        assert!(
            d.message.starts_with("x.toml is not valid: "),
            "{}",
            d.message
        );
        assert!(!d.message.contains('\n'), "one line: {}", d.message);
        let human = diags.render_human(&sources);
        assert!(human.contains("x.toml:3:"), "{human}");
        assert!(human.contains("x.toml has [table]"), "{human}");
    }
}
