//! Formulas over the state of a project: `not (R1.in_bottleneck and R2.in_bottleneck)`,
//! `PHASES.surfaced implies not global.thrusters_on`, `active MISSION`.
//!
//! The manifest's invariants and the scripts' `expect always` are written in this small
//! language; the checker resolves the names ([`crate::check`]), the semantics evaluates them
//! ([`crate::semantics::Layout::holds`]).
//!
//! ```text
//! formula = or ("implies" formula)?          implies groups to the right
//! or      = and ("or" and)*
//! and     = unary ("and" unary)*
//! unary   = "not" unary | "(" formula ")" | "active" NET | "true" | "false" | NET "." PLACE
//! ```
//!
//! A net's name may hold `/` (`MISSION_PHASES/TRANSIT`, a child instance) and a place's `.`
//! (`TRANSIT.done`, a completion place): a reference is read whole, the checker splits it.

use crate::model::{Formula, Name};
use petrel_diag::report::{Diagnostic, Diagnostics};
use petrel_diag::source::{FileId, Span};

/// Deepest nesting accepted (parentheses and `not`s): no text can exhaust the stack.
pub const MAX_DEPTH: usize = 64;

#[derive(Clone, Debug, PartialEq)]
enum Tok {
    Word(String),
    LParen,
    RParen,
    Bad(char),
    End,
}

fn is_word_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_' || c == '.' || c == '/'
}

fn lex(text: &str) -> Vec<(Tok, usize, usize)> {
    let mut out = Vec::new();
    let mut chars = text.char_indices().peekable();
    while let Some(&(i, c)) = chars.peek() {
        if c.is_whitespace() {
            chars.next();
        } else if c == '(' {
            chars.next();
            out.push((Tok::LParen, i, i + 1));
        } else if c == ')' {
            chars.next();
            out.push((Tok::RParen, i, i + 1));
        } else if is_word_char(c) {
            let mut end = i;
            while let Some(&(j, d)) = chars.peek() {
                if !is_word_char(d) {
                    break;
                }
                end = j + d.len_utf8();
                chars.next();
            }
            out.push((Tok::Word(text[i..end].to_string()), i, end));
        } else {
            chars.next();
            out.push((Tok::Bad(c), i, i + c.len_utf8()));
        }
    }
    out.push((Tok::End, text.len(), text.len()));
    out
}

struct Parser<'a> {
    toks: Vec<(Tok, usize, usize)>,
    pos: usize,
    file: FileId,
    /// Byte offset of the formula's text in its file, for spans.
    offset: usize,
    depth: usize,
    diags: &'a mut Diagnostics,
    code: &'static str,
}

/// Why a formula did not read (already reported).
struct Fail;

impl Parser<'_> {
    fn span(&self, start: usize, end: usize) -> Span {
        Span::new(self.file, self.offset + start, self.offset + end)
    }

    fn peek(&self) -> &(Tok, usize, usize) {
        &self.toks[self.pos]
    }

    fn at_word(&self, w: &str) -> bool {
        matches!(&self.peek().0, Tok::Word(x) if x == w)
    }

    fn error(&mut self, expected: &str) -> Fail {
        let (tok, s, e) = self.peek().clone();
        let found = match tok {
            Tok::Word(w) => format!("`{w}`"),
            Tok::LParen => "`(`".into(),
            Tok::RParen => "`)`".into(),
            Tok::Bad(c) => format!("`{c}`"),
            Tok::End => "the end of the formula".into(),
        };
        let span = self.span(
            s,
            e.max(s + 1).min(self.toks.last().map_or(e, |t| t.2).max(s)),
        );
        self.diags.push(
            Diagnostic::error(self.code, span, format!("expected {expected}, found {found}"))
                .label(format!("expected {expected}"))
                .help("a formula combines `NET.place`, `global.place` and `active NET` with `not`, `and`, `or`, `implies` and parentheses"),
        );
        Fail
    }

    fn deeper(&mut self) -> Result<(), Fail> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            return Err(self.error(&format!("a formula nested at most {MAX_DEPTH} deep")));
        }
        Ok(())
    }

    fn formula(&mut self) -> Result<Formula, Fail> {
        self.deeper()?;
        let lhs = self.or()?;
        let f = if self.at_word("implies") {
            self.pos += 1;
            let rhs = self.formula()?;
            Formula::Implies(Box::new(lhs), Box::new(rhs))
        } else {
            lhs
        };
        self.depth -= 1;
        Ok(f)
    }

    fn or(&mut self) -> Result<Formula, Fail> {
        let mut f = self.and()?;
        while self.at_word("or") {
            self.pos += 1;
            let rhs = self.and()?;
            f = Formula::Or(Box::new(f), Box::new(rhs));
        }
        Ok(f)
    }

    fn and(&mut self) -> Result<Formula, Fail> {
        let mut f = self.unary()?;
        while self.at_word("and") {
            self.pos += 1;
            let rhs = self.unary()?;
            f = Formula::And(Box::new(f), Box::new(rhs));
        }
        Ok(f)
    }

    fn unary(&mut self) -> Result<Formula, Fail> {
        let (tok, s, e) = self.peek().clone();
        match tok {
            Tok::Word(w) if w == "not" => {
                self.pos += 1;
                self.deeper()?;
                let inner = self.unary()?;
                self.depth -= 1;
                Ok(Formula::Not(Box::new(inner)))
            }
            Tok::LParen => {
                self.pos += 1;
                let f = self.formula()?;
                if self.peek().0 != Tok::RParen {
                    return Err(self.error("`)`"));
                }
                self.pos += 1;
                Ok(f)
            }
            Tok::Word(w) if w == "true" || w == "false" => {
                self.pos += 1;
                Ok(Formula::Const(w == "true", self.span(s, e)))
            }
            Tok::Word(w) if w == "active" => {
                self.pos += 1;
                match self.peek().clone() {
                    (Tok::Word(net), s2, e2) if !is_operator(&net) => {
                        self.pos += 1;
                        Ok(Formula::Active(Name {
                            text: net,
                            span: self.span(s2, e2),
                        }))
                    }
                    _ => Err(self.error("a net name after `active`")),
                }
            }
            Tok::Word(w) if !is_operator(&w) && w.contains('.') => {
                self.pos += 1;
                Ok(Formula::Marked(Name {
                    text: w,
                    span: self.span(s, e),
                }))
            }
            _ => Err(self.error("`NET.place`, `global.place`, `active NET`, `not` or `(`")),
        }
    }
}

fn is_operator(w: &str) -> bool {
    matches!(
        w,
        "not" | "and" | "or" | "implies" | "active" | "true" | "false"
    )
}

/// Reads a formula written at byte `offset` of `file`; problems are reported with `code`.
/// `None` when it does not read.
pub fn parse_formula(
    file: FileId,
    offset: usize,
    text: &str,
    code: &'static str,
    diags: &mut Diagnostics,
) -> Option<Formula> {
    let mut p = Parser {
        toks: lex(text),
        pos: 0,
        file,
        offset,
        depth: 0,
        diags,
        code,
    };
    let f = p.formula().ok()?;
    if p.peek().0 != Tok::End {
        p.error("the end of the formula (or `and`, `or`, `implies`)");
        return None;
    }
    Some(f)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fmt::format_formula;

    fn read(text: &str) -> Result<Formula, String> {
        let mut d = Diagnostics::new();
        parse_formula(FileId(0), 0, text, "E0108", &mut d).ok_or_else(|| {
            d.iter()
                .map(|x| x.message.clone())
                .collect::<Vec<_>>()
                .join("; ")
        })
    }

    #[test]
    fn precedence_and_printing() {
        for (text, canonical) in [
            ("not (R1.in and R2.in)", "not (R1.in and R2.in)"),
            ("a.x or b.y and c.z", "a.x or b.y and c.z"),
            ("(a.x or b.y) and c.z", "(a.x or b.y) and c.z"),
            ("a.x implies b.y implies c.z", "a.x implies b.y implies c.z"),
            (
                "(a.x implies b.y) implies c.z",
                "(a.x implies b.y) implies c.z",
            ),
            (
                "active MISSION and P/T.done.x",
                "active MISSION and P/T.done.x",
            ),
            ("global.ok or true", "global.ok or true"),
        ] {
            let f = read(text).unwrap();
            assert_eq!(format_formula(&f), canonical);
            assert_eq!(read(&format_formula(&f)).unwrap(), f);
        }
    }

    #[test]
    fn errors_say_what_was_expected() {
        assert!(read("R1.in and").unwrap_err().contains("expected"));
        assert!(read("R1.in && R2.in").unwrap_err().contains("`&`"));
        assert!(read("active").unwrap_err().contains("net name"));
        assert!(read("(R1.in").unwrap_err().contains("`)`"));
        assert!(read("R1").unwrap_err().contains("NET.place"));
        let deep = format!("{}a.b{}", "(".repeat(10_000), ")".repeat(10_000));
        assert!(read(&deep).unwrap_err().contains("nested"));
        let nots = format!("{}a.b", "not ".repeat(10_000));
        assert!(read(&nots).unwrap_err().contains("nested"));
    }
}
