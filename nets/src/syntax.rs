//! The net language: lexer and parser from text to [`crate::model::NetFile`].
//!
//! Hand-written so that every error can say exactly what was expected and the parser can carry
//! on to report the next one. Newlines separate nothing (every statement starts with a keyword),
//! but the lexer notes them so comments and blank lines stay where the author put them.

use crate::model::*;
use petrel_diag::duration::TimeUnit;
use petrel_diag::report::{Diagnostic, Diagnostics};
use petrel_diag::source::{FileId, Span};

#[derive(Clone, Debug, PartialEq)]
enum Tok {
    Ident(String),
    Int(i64),
    Float(f64),
    Duration(f64, TimeUnit),
    Text(String),
    Comment(String),
    LBrace,
    RBrace,
    LParen,
    RParen,
    LBracket,
    RBracket,
    Comma,
    Colon,
    Dot,
    Arrow,
    Equals,
    EqEq,
    NotEq,
    Lt,
    Le,
    Gt,
    Ge,
    At,
    Eof,
}

impl Tok {
    fn describe(&self) -> String {
        match self {
            Tok::Ident(s) => format!("`{s}`"),
            Tok::Int(i) => format!("the number `{i}`"),
            Tok::Float(f) => format!("the number `{f:?}`"),
            Tok::Duration(..) => "a duration".into(),
            Tok::Text(_) => "a text literal".into(),
            Tok::Comment(_) => "a comment".into(),
            Tok::LBrace => "`{`".into(),
            Tok::RBrace => "`}`".into(),
            Tok::LParen => "`(`".into(),
            Tok::RParen => "`)`".into(),
            Tok::LBracket => "`[`".into(),
            Tok::RBracket => "`]`".into(),
            Tok::Comma => "`,`".into(),
            Tok::Colon => "`:`".into(),
            Tok::Dot => "`.`".into(),
            Tok::Arrow => "`->`".into(),
            Tok::Equals => "`=`".into(),
            Tok::EqEq => "`==`".into(),
            Tok::NotEq => "`!=`".into(),
            Tok::Lt => "`<`".into(),
            Tok::Le => "`<=`".into(),
            Tok::Gt => "`>`".into(),
            Tok::Ge => "`>=`".into(),
            Tok::At => "`@`".into(),
            Tok::Eof => "the end of the file".into(),
        }
    }
}

#[derive(Clone, Debug)]
struct Token {
    tok: Tok,
    span: Span,
    /// First token on its line.
    line_start: bool,
    /// A blank line stands between this token and the previous one.
    blank_before: bool,
}

fn lex(file: FileId, text: &str, diags: &mut Diagnostics) -> Vec<Token> {
    let bytes = text.as_bytes();
    let mut toks = Vec::new();
    let mut i = 0;
    let mut newlines = 2; // start of file counts as line start, not as blank line
    let mut first = true;
    while i < bytes.len() {
        let c = bytes[i];
        if c == b'\n' {
            newlines += 1;
            i += 1;
            continue;
        }
        if c.is_ascii_whitespace() {
            i += 1;
            continue;
        }
        let start = i;
        let line_start = newlines > 0;
        let blank_before = newlines > 1 && !first;
        let sp = |e: usize| Span::new(file, start, e);
        let tok = if c == b'/' && bytes.get(i + 1) == Some(&b'/') {
            let end = text[i..].find('\n').map(|n| i + n).unwrap_or(text.len());
            let body = text[i + 2..end].trim_end();
            let body = body.strip_prefix(' ').unwrap_or(body);
            i = end;
            Tok::Comment(body.to_string())
        } else if c.is_ascii_alphabetic() || c == b'_' {
            while i < bytes.len() && (bytes[i].is_ascii_alphanumeric() || bytes[i] == b'_') {
                i += 1;
            }
            Tok::Ident(text[start..i].to_string())
        } else if c.is_ascii_digit()
            || (c == b'-' && bytes.get(i + 1).is_some_and(u8::is_ascii_digit))
        {
            i += 1;
            let mut is_float = false;
            while i < bytes.len() {
                let b = bytes[i];
                if b.is_ascii_digit() || b == b'_' {
                    i += 1;
                } else if b == b'.' && bytes.get(i + 1).is_some_and(u8::is_ascii_digit) && !is_float
                {
                    is_float = true;
                    i += 1;
                } else if (b == b'e' || b == b'E')
                    && (bytes.get(i + 1).is_some_and(u8::is_ascii_digit)
                        || (matches!(bytes.get(i + 1), Some(b'-' | b'+'))
                            && bytes.get(i + 2).is_some_and(u8::is_ascii_digit)))
                {
                    is_float = true;
                    i += 2;
                } else {
                    break;
                }
            }
            let number: String = text[start..i].chars().filter(|&c| c != '_').collect();
            let suffix_start = i;
            while i < bytes.len() && bytes[i].is_ascii_alphabetic() {
                i += 1;
            }
            let suffix = &text[suffix_start..i];
            if !suffix.is_empty() {
                match TimeUnit::from_suffix(suffix) {
                    Some(unit) => match number.parse::<f64>() {
                        Ok(v) => Tok::Duration(v, unit),
                        Err(_) => {
                            diags.push(
                                Diagnostic::error(
                                    "E0001",
                                    sp(i),
                                    format!("`{number}{suffix}` is not a duration"),
                                )
                                .label("not a number")
                                .help("durations are written `200ms`, `30s`, `1.5min` or `2h`"),
                            );
                            Tok::Duration(0.0, unit)
                        }
                    },
                    None => {
                        diags.push(
                            Diagnostic::error(
                                "E0001",
                                sp(i),
                                format!("unknown time unit `{suffix}`"),
                            )
                            .label("not a unit")
                            .help("durations are written `200ms`, `30s`, `1.5min` or `2h`"),
                        );
                        Tok::Duration(0.0, TimeUnit::Seconds)
                    }
                }
            } else if is_float {
                // A non-zero literal that rounds to zero (`1e-400`) is refused like one that
                // rounds to infinity: a number is read exactly enough or not at all.
                let mantissa = number.split(['e', 'E']).next().unwrap_or("");
                let nonzero = mantissa.bytes().any(|b| (b'1'..=b'9').contains(&b));
                match number.parse::<f64>() {
                    Ok(v) if v == 0.0 && nonzero => {
                        diags.push(
                            Diagnostic::error(
                                "E0001",
                                sp(i),
                                format!("the number `{number}` is too small for a float"),
                            )
                            .label("rounds to 0")
                            .help("floats reach down to about 4.9e-324; write 0.0 for zero"),
                        );
                        Tok::Float(0.0)
                    }
                    Ok(v) if v.is_finite() => Tok::Float(v),
                    _ => {
                        diags.push(
                            Diagnostic::error(
                                "E0001",
                                sp(i),
                                format!("the number `{number}` is too large for a float"),
                            )
                            .label("not a finite 64-bit float")
                            .help("floats range up to about 1.8e308"),
                        );
                        Tok::Float(0.0)
                    }
                }
            } else {
                match number.parse::<i64>() {
                    Ok(v) => Tok::Int(v),
                    Err(_) => {
                        diags.push(
                            Diagnostic::error(
                                "E0001",
                                sp(i),
                                format!("the integer `{number}` does not fit in 64 bits"),
                            )
                            .label("too large")
                            .help("integers range from -9223372036854775808 to 9223372036854775807; write a float (with a `.`) for larger values"),
                        );
                        Tok::Int(0)
                    }
                }
            }
        } else if c == b'"' {
            i += 1;
            let mut s = String::new();
            let mut closed = false;
            while i < bytes.len() {
                let ch = text[i..].chars().next().unwrap_or('\0');
                if ch == '"' {
                    i += 1;
                    closed = true;
                    break;
                }
                if ch == '\n' {
                    break;
                }
                if ch == '\\' {
                    let esc = text[i + 1..].chars().next();
                    match esc {
                        Some('n') => s.push('\n'),
                        Some('t') => s.push('\t'),
                        Some('"') => s.push('"'),
                        Some('\\') => s.push('\\'),
                        other => {
                            let w = other.map(char::len_utf8).unwrap_or(0);
                            diags.push(
                                Diagnostic::error(
                                    "E0001",
                                    Span::new(file, i, i + 1 + w),
                                    "unknown escape in text",
                                )
                                .label("not an escape")
                                .help(r#"the escapes are \n, \t, \" and \\"#),
                            );
                        }
                    }
                    i += 1 + esc.map(char::len_utf8).unwrap_or(0);
                    continue;
                }
                s.push(ch);
                i += ch.len_utf8();
            }
            if !closed {
                diags.push(
                    Diagnostic::error("E0001", sp(i), "text is not closed")
                        .label("this text has no closing `\"` on its line")
                        .help("add a `\"` at the end of the text"),
                );
            }
            Tok::Text(s)
        } else {
            i += 1;
            match c {
                b'{' => Tok::LBrace,
                b'}' => Tok::RBrace,
                b'(' => Tok::LParen,
                b')' => Tok::RParen,
                b'[' => Tok::LBracket,
                b']' => Tok::RBracket,
                b',' => Tok::Comma,
                b':' => Tok::Colon,
                b'.' => Tok::Dot,
                b'=' if bytes.get(i) == Some(&b'=') => {
                    i += 1;
                    Tok::EqEq
                }
                b'=' => Tok::Equals,
                b'!' if bytes.get(i) == Some(&b'=') => {
                    i += 1;
                    Tok::NotEq
                }
                b'<' if bytes.get(i) == Some(&b'=') => {
                    i += 1;
                    Tok::Le
                }
                b'<' => Tok::Lt,
                b'>' if bytes.get(i) == Some(&b'=') => {
                    i += 1;
                    Tok::Ge
                }
                b'>' => Tok::Gt,
                b'@' => Tok::At,
                b'-' if bytes.get(i) == Some(&b'>') => {
                    i += 1;
                    Tok::Arrow
                }
                _ => {
                    let ch = text[start..].chars().next().unwrap_or('?');
                    i = start + ch.len_utf8();
                    diags.push(
                        Diagnostic::error("E0001", sp(i), format!("unexpected character `{ch}`"))
                            .label("not part of the net language")
                            .help("names use letters, digits and `_`; comments start with `//`"),
                    );
                    continue;
                }
            }
        };
        toks.push(Token {
            tok,
            span: sp(i),
            line_start,
            blank_before,
        });
        newlines = 0;
        first = false;
    }
    toks.push(Token {
        tok: Tok::Eof,
        span: Span::new(file, text.len(), text.len()),
        line_start: true,
        blank_before: false,
    });
    toks
}

/// The comments before a closing `}`: a blank line above them is kept as a leading
/// [`BLANK_LINE`](crate::model::BLANK_LINE) (the canonical layout has none of its own there).
fn closing_comments(t: Trivia) -> Vec<String> {
    let mut comments = t.comments;
    if t.blank_before && !comments.is_empty() {
        comments.insert(0, crate::model::BLANK_LINE.to_string());
    }
    comments
}

/// How deeply lists may nest in an argument. The language's only list type is `[float]`, so
/// one level is all a valid file holds; the bound keeps the recursive descent (and every
/// recursive walk of the expressions it builds) from overflowing the stack on crafted input
/// such as 30,000 `[`.
pub const MAX_NESTING: usize = 32;

/// Marks a syntax error already reported; the parser then skips ahead.
struct Recover;

type PResult<T> = Result<T, Recover>;

struct Parser<'d> {
    toks: Vec<Token>,
    pos: usize,
    diags: &'d mut Diagnostics,
    /// End-of-line comments that have no item of their own (after `net X {` or a closing
    /// brace): they become leading comments of whatever follows, so none is lost.
    pending: Vec<String>,
    /// Nesting of guards being parsed: bounded, so no text can exhaust the stack.
    depth: usize,
    /// Lists open around the expression being read (bounded by [`MAX_NESTING`]).
    list_depth: usize,
}

/// Deepest nesting of parentheses in a guard.
const MAX_GUARD_DEPTH: usize = 64;

/// Words that start an item of a net.
const ITEM_WORDS: [&str; 4] = ["place", "transition", "children", "net"];

impl Parser<'_> {
    fn peek(&self) -> &Token {
        &self.toks[self.pos]
    }

    fn bump(&mut self) -> Token {
        let t = self.toks[self.pos].clone();
        if self.pos + 1 < self.toks.len() {
            self.pos += 1;
        }
        t
    }

    fn at_ident(&self, kw: &str) -> bool {
        matches!(&self.peek().tok, Tok::Ident(s) if s == kw)
    }

    fn at(&self, t: &Tok) -> bool {
        &self.peek().tok == t
    }

    fn error(&mut self, expected: &str, help: &str) -> Recover {
        let t = self.peek().clone();
        self.diags.push(
            Diagnostic::error(
                "E0001",
                t.span,
                format!("expected {expected}, found {}", t.tok.describe()),
            )
            .label(format!("expected {expected} here"))
            .help(help),
        );
        Recover
    }

    fn expect(&mut self, t: Tok, help: &str) -> PResult<Span> {
        if self.at(&t) {
            Ok(self.bump().span)
        } else {
            Err(self.error(&t.describe(), help))
        }
    }

    fn name(&mut self, what: &str, help: &str) -> PResult<Name> {
        match &self.peek().tok {
            Tok::Ident(s) if !is_keyword(s) => {
                let t = self.bump();
                let Tok::Ident(text) = t.tok else {
                    unreachable!()
                };
                Ok(Name { text, span: t.span })
            }
            _ => Err(self.error(what, help)),
        }
    }

    /// Whole-line comments (and the blank line before the first of them) ahead of an item.
    fn leading(&mut self) -> Trivia {
        let blank_before = self.peek().blank_before;
        let mut comments = std::mem::take(&mut self.pending);
        while let Tok::Comment(c) = &self.peek().tok {
            if self.peek().blank_before && !comments.is_empty() {
                comments.push(crate::model::BLANK_LINE.to_string());
            }
            comments.push(c.clone());
            self.bump();
        }
        Trivia {
            blank_before,
            comments,
        }
    }

    /// A comment at the end of the line just parsed.
    fn trailing(&mut self) -> Option<String> {
        match &self.peek().tok {
            Tok::Comment(c) if !self.peek().line_start => {
                let c = c.clone();
                self.bump();
                Some(c)
            }
            _ => None,
        }
    }

    /// At `place`, `transition`, `children`, `net` or `@` starting a line: where an item may
    /// begin.
    fn at_item_start(&self) -> bool {
        let t = self.peek();
        t.line_start
            && (t.tok == Tok::At
                || matches!(&t.tok, Tok::Ident(s) if ITEM_WORDS.contains(&s.as_str())))
    }

    /// `@allow(CODE, "reason")` lines.
    fn allows(&mut self) -> PResult<Vec<Allow>> {
        const HELP: &str = "write `@allow(W0602, \"why it is intended\")` on the line before the net, place or transition";
        let mut out = Vec::new();
        while self.at(&Tok::At) {
            self.bump();
            if !self.at_ident("allow") {
                return Err(self.error("`allow`", HELP));
            }
            self.bump();
            self.expect(Tok::LParen, HELP)?;
            let code = self.name("a warning code such as `W0602`", HELP)?;
            let reason = if self.at(&Tok::Comma) {
                self.bump();
                match self.peek().tok.clone() {
                    Tok::Text(t) => {
                        self.bump();
                        Some(t)
                    }
                    _ => return Err(self.error("a reason in quotes", HELP)),
                }
            } else {
                None
            };
            self.expect(Tok::RParen, HELP)?;
            self.stash_trailing();
            // Comments between the allow and its item stay with the item.
            while let Tok::Comment(c) = &self.peek().tok {
                self.pending.push(c.clone());
                self.bump();
            }
            out.push(Allow { code, reason });
        }
        Ok(out)
    }

    /// `(name: type, ...)` after a net's name.
    fn params(&mut self) -> PResult<Vec<Param>> {
        const HELP: &str = "a net's parameters are written `net NAME(robot: text, speed: float) {`";
        let mut out = Vec::new();
        self.expect(Tok::LParen, HELP)?;
        while !self.at(&Tok::RParen) {
            let name = self.name("a parameter name", HELP)?;
            self.expect(Tok::Colon, HELP)?;
            let (ty, _) = self.ty()?;
            out.push(Param { name, ty });
            if !self.at(&Tok::RParen) {
                self.expect(Tok::Comma, "separate parameters with `,`")?;
            }
        }
        self.bump();
        Ok(out)
    }

    /// Keeps an end-of-line comment that belongs to no item for what follows.
    fn stash_trailing(&mut self) {
        if let Some(c) = self.trailing() {
            self.pending.push(c);
        }
    }

    /// Skips to the next token that starts a line and satisfies `stop`.
    fn skip_until(&mut self, stop: impl Fn(&Tok) -> bool) {
        loop {
            let t = self.peek();
            if t.tok == Tok::Eof || (t.line_start && stop(&t.tok)) {
                return;
            }
            self.bump();
        }
    }

    fn file(&mut self, path: &str) -> NetFile {
        let mut nets = Vec::new();
        loop {
            let trivia = self.leading();
            if self.at(&Tok::Eof) {
                return NetFile {
                    path: path.to_string(),
                    nets,
                    end_comments: trivia.comments,
                };
            }
            // Nets are always one blank line apart: that is layout, not content.
            let mut trivia = Trivia {
                blank_before: false,
                ..trivia
            };
            let allows = match self.allows() {
                Ok(a) => a,
                Err(Recover) => {
                    self.bump();
                    self.skip_until(|t| matches!(t, Tok::Ident(s) if s == "net"));
                    continue;
                }
            };
            trivia.comments.append(&mut self.pending);
            match self.net(trivia, allows) {
                Ok(n) => nets.push(n),
                Err(Recover) => {
                    self.bump();
                    self.skip_until(|t| matches!(t, Tok::Ident(s) if s == "net"));
                }
            }
        }
    }

    fn net(&mut self, outer: Trivia, allows: Vec<Allow>) -> PResult<NetDecl> {
        if !self.at_ident("net") {
            return Err(self.error(
                "`net`",
                "a net file holds nets: `net NAME { place ... transition ... }`",
            ));
        }
        self.bump();
        let name = self.name("a net name", "write `net NAME {`")?;
        let params = if self.at(&Tok::LParen) {
            self.params()?
        } else {
            Vec::new()
        };
        self.expect(
            Tok::LBrace,
            "the net's places and transitions go between `{` and `}`",
        )?;
        self.stash_trailing();
        let mut items = Vec::new();
        loop {
            let trivia = self.leading();
            if self.at(&Tok::RBrace) {
                self.bump();
                self.stash_trailing();
                return Ok(NetDecl {
                    trivia: outer,
                    allows,
                    name,
                    params,
                    items,
                    end_comments: closing_comments(trivia),
                });
            }
            if self.at(&Tok::Eof) {
                return Err(self.error(
                    "`}`",
                    &format!("net `{name}` is not closed: add `}}` after its last transition"),
                ));
            }
            match self.item(trivia) {
                Ok(item) => items.push(item),
                Err(Recover) => {
                    self.skip_item();
                    if self.at_ident("net") {
                        return Ok(NetDecl {
                            trivia: outer,
                            allows,
                            name,
                            params,
                            items,
                            end_comments: Vec::new(),
                        });
                    }
                }
            }
        }
    }

    /// Skips the rest of a broken item, over any action block it has, up to the next item.
    fn skip_item(&mut self) {
        let mut depth = 0usize;
        if !self.at_item_start() {
            self.bump();
        }
        loop {
            let t = self.peek();
            match &t.tok {
                Tok::Eof => return,
                Tok::Ident(s) if depth == 0 && t.line_start && ITEM_WORDS.contains(&s.as_str()) => {
                    return
                }
                Tok::At if depth == 0 && t.line_start => return,
                Tok::LBrace => depth += 1,
                Tok::RBrace if depth == 0 => return,
                Tok::RBrace => depth -= 1,
                _ => {}
            }
            self.bump();
        }
    }

    fn item(&mut self, mut trivia: Trivia) -> PResult<Item> {
        let allows = self.allows()?;
        trivia.comments.append(&mut self.pending);
        if self.at_ident("children") {
            const HELP: &str =
                "write `children NET, OTHER(args)`: the nets this net runs, each its own instance";
            self.bump();
            let mut children = Vec::new();
            loop {
                let net = self.name("a net name", HELP)?;
                let args = if self.at(&Tok::LParen) {
                    self.bump();
                    Some(self.args(Tok::RParen)?.0)
                } else {
                    None
                };
                children.push(ChildDecl { net, args });
                if !self.at(&Tok::Comma) {
                    break;
                }
                self.bump();
            }
            let trailing = self.trailing();
            return Ok(Item {
                trivia,
                allows,
                kind: ItemKind::Children(children),
                trailing,
            });
        }
        if self.at_ident("place") {
            self.bump();
            let name = self.name("a place name", "write `place NAME` or `place NAME = 1`")?;
            let (tokens, tokens_span) = if self.at(&Tok::Equals) {
                self.bump();
                match self.peek().tok {
                    Tok::Int(n) if n >= 0 => {
                        let t = self.bump();
                        (u32::try_from(n).unwrap_or(u32::MAX), Some(t.span))
                    }
                    _ => {
                        return Err(self.error(
                            "an initial marking (0 or 1)",
                            "write `place NAME = 1` for a marked place, or `place NAME` for an empty one",
                        ))
                    }
                }
            } else {
                (0, None)
            };
            let trailing = self.trailing();
            return Ok(Item {
                trivia,
                allows,
                kind: ItemKind::Place(PlaceDecl {
                    name,
                    tokens,
                    tokens_span,
                }),
                trailing,
            });
        }
        if self.at_ident("transition") {
            self.bump();
            let t = self.transition()?;
            return Ok(Item {
                trivia,
                allows,
                kind: ItemKind::Transition(t.0),
                trailing: t.1,
            });
        }
        Err(self.error(
            "`place`, `transition`, `children` or `}`",
            "a net holds `place NAME [= 1]`, `transition NAME [on EVENT] [if GUARD]: INPUTS -> OUTPUTS [{ ACTIONS }]` and `children NET, ...`",
        ))
    }

    fn transition(&mut self) -> PResult<(TransitionDecl, Option<String>)> {
        const SHAPE: &str =
            "a transition reads `transition NAME [on EVENT(params)] [if GUARD]: INPUTS -> OUTPUTS [{ ACTIONS }]`";
        let name = self.name("a transition name", SHAPE)?;
        let trigger = if self.at_ident("on") {
            self.bump();
            let event = self.name("an event name", SHAPE)?;
            let mut bindings = Vec::new();
            if self.at(&Tok::LParen) {
                self.bump();
                while !self.at(&Tok::RParen) {
                    let name = self.name(
                        "a name for the event parameter",
                        "bind each event parameter to a name, in order: `on alarm(reason)`; `_` ignores one",
                    )?;
                    let ty = if self.at(&Tok::Colon) {
                        self.bump();
                        Some(self.ty()?)
                    } else {
                        None
                    };
                    bindings.push(Binding { name, ty });
                    if !self.at(&Tok::RParen) {
                        self.expect(Tok::Comma, "separate parameters with `,`")?;
                    }
                }
                self.bump();
            }
            Some(Trigger { event, bindings })
        } else {
            None
        };
        let guard = if self.at_ident("if") {
            self.bump();
            Some(self.guard()?)
        } else {
            None
        };
        self.expect(Tok::Colon, SHAPE)?;
        let (inputs, empty) = self.input_list()?;
        self.expect(Tok::Arrow, SHAPE)?;
        let outputs = self.place_list()?;
        let mut actions = Vec::new();
        let mut end_comments = Vec::new();
        let trailing;
        if self.at(&Tok::LBrace) {
            self.bump();
            trailing = self.trailing();
            loop {
                let trivia = self.leading();
                if self.at(&Tok::RBrace) {
                    self.bump();
                    end_comments = closing_comments(trivia);
                    break;
                }
                if self.at(&Tok::Eof) {
                    return Err(self.error(
                        "`}`",
                        &format!("the actions of transition `{name}` are not closed: add `}}`"),
                    ));
                }
                match self.action() {
                    Ok(action) => {
                        let trailing = self.trailing();
                        actions.push(ActionItem {
                            trivia,
                            action,
                            trailing,
                        })
                    }
                    Err(Recover) => {
                        // A new item means this block was never closed.
                        if self.at_item_start() {
                            return Err(Recover);
                        }
                        // Stay inside the block: skip to the next action or its end.
                        let t = self.peek();
                        let at_sync = t.line_start
                            && (t.tok == Tok::RBrace
                                || matches!(&t.tok, Tok::Ident(s) if ACTION_WORDS.contains(&s.as_str())));
                        if !at_sync {
                            self.bump();
                        }
                        self.skip_until(|t| {
                            matches!(t, Tok::RBrace | Tok::At)
                                || matches!(t, Tok::Ident(s) if ACTION_WORDS.contains(&s.as_str())
                                    || ITEM_WORDS.contains(&s.as_str()))
                        });
                    }
                }
            }
            self.stash_trailing();
        } else {
            trailing = self.trailing();
        }
        Ok((
            TransitionDecl {
                name,
                trigger,
                guard,
                inputs,
                empty,
                outputs,
                actions,
                end_comments,
            },
            trailing,
        ))
    }

    fn place_list(&mut self) -> PResult<Vec<Name>> {
        let mut out = Vec::new();
        // An empty list followed by a new item on the next line: `transition t: a ->`.
        if !matches!(self.peek().tok, Tok::Ident(_)) || self.at_item_start() {
            return Ok(out);
        }
        loop {
            out.push(self.place_ref()?);
            if !self.at(&Tok::Comma) {
                return Ok(out);
            }
            self.bump();
        }
    }

    /// The inputs of a transition: places to take a token from, and `not p`, places that must
    /// be empty.
    fn input_list(&mut self) -> PResult<(Vec<Name>, Vec<Name>)> {
        let (mut inputs, mut empty) = (Vec::new(), Vec::new());
        if !matches!(self.peek().tok, Tok::Ident(_)) || self.at_item_start() {
            return Ok((inputs, empty));
        }
        loop {
            // `not p` tests p for emptiness; a place named `not` still reads as a place.
            let negated = self.at_ident("not")
                && matches!(
                    self.toks.get(self.pos + 1).map(|t| &t.tok),
                    Some(Tok::Ident(_))
                );
            if negated {
                self.bump();
                empty.push(self.place_ref()?);
            } else {
                inputs.push(self.place_ref()?);
            }
            if !self.at(&Tok::Comma) {
                return Ok((inputs, empty));
            }
            self.bump();
        }
    }

    /// A place in an arc: `NAME`, or `CHILD.done`, a child's completion place.
    fn place_ref(&mut self) -> PResult<Name> {
        const HELP: &str =
            "list places separated by `,`: `a, b -> c`; a child's completion place is `CHILD.done`";
        let mut name = self.name("a place name", HELP)?;
        if self.at(&Tok::Dot) {
            self.bump();
            let done = self.name("`done`", HELP)?;
            if done.text != "done" {
                self.diags.push(
                    Diagnostic::error("E0001", done.span, format!("`{name}.{done}` is not a place"))
                        .label("expected `done`")
                        .help("a net names another net's place only as a child's completion place, `CHILD.done`"),
                );
                return Err(Recover);
            }
            name = Name {
                text: format!("{}.done", name.text),
                span: name.span.to(done.span),
            };
        }
        Ok(name)
    }

    /// A guard: `or` of `and` of `not` of comparisons.
    fn guard(&mut self) -> PResult<Guard> {
        self.nested_guard(|p| {
            let mut g = p.guard_and()?;
            while p.at_ident("or") {
                p.bump();
                let rhs = p.guard_and()?;
                g = Guard::Or(Box::new(g), Box::new(rhs));
            }
            Ok(g)
        })
    }

    /// Runs `read` one guard level deeper, refusing past [`MAX_GUARD_DEPTH`]. The level is
    /// given back on every path, errors included: a guard that does not read must not count
    /// against the guards after it.
    fn nested_guard(&mut self, read: impl FnOnce(&mut Self) -> PResult<Guard>) -> PResult<Guard> {
        if self.depth >= MAX_GUARD_DEPTH {
            return Err(self.error(
                "a simpler guard",
                &format!("guards nest at most {MAX_GUARD_DEPTH} levels deep"),
            ));
        }
        self.depth += 1;
        let g = read(self);
        self.depth -= 1;
        g
    }

    fn guard_and(&mut self) -> PResult<Guard> {
        let mut g = self.guard_not()?;
        while self.at_ident("and") {
            self.bump();
            let rhs = self.guard_not()?;
            g = Guard::And(Box::new(g), Box::new(rhs));
        }
        Ok(g)
    }

    fn guard_not(&mut self) -> PResult<Guard> {
        if self.at_ident("not") {
            self.bump();
            let inner = self.nested_guard(Self::guard_not)?;
            return Ok(Guard::Not(Box::new(inner)));
        }
        if self.at(&Tok::LParen) {
            self.bump();
            let g = self.guard()?;
            self.expect(Tok::RParen, "close the parenthesis of the guard")?;
            return Ok(g);
        }
        let lhs = self.expr()?;
        let op = match self.peek().tok {
            Tok::EqEq => CmpOp::Eq,
            Tok::NotEq => CmpOp::Ne,
            Tok::Lt => CmpOp::Lt,
            Tok::Le => CmpOp::Le,
            Tok::Gt => CmpOp::Gt,
            Tok::Ge => CmpOp::Ge,
            _ => return Ok(Guard::Value(lhs)),
        };
        self.bump();
        let rhs = self.expr()?;
        Ok(Guard::Compare(op, lhs, rhs))
    }

    fn ty(&mut self) -> PResult<(Type, Span)> {
        const HELP: &str = "the types are int, float, bool, text and [float]";
        let start = self.peek().span;
        if self.at(&Tok::LBracket) {
            self.bump();
            let inner = self.name("a type", HELP)?;
            let end = self.expect(Tok::RBracket, HELP)?;
            if inner.text == "float" {
                return Ok((Type::FloatList, start.to(end)));
            }
            self.diags.push(
                Diagnostic::error("E0001", inner.span, format!("no list type `[{inner}]`"))
                    .label("only lists of floats exist")
                    .help(HELP),
            );
            return Err(Recover);
        }
        let name = self.name("a type", HELP)?;
        match Type::from_keyword(&name.text) {
            Some(t) if t != Type::FloatList => Ok((t, name.span)),
            _ => {
                self.diags.push(
                    Diagnostic::error("E0001", name.span, format!("unknown type `{name}`"))
                        .label("not a type")
                        .help(HELP),
                );
                Err(Recover)
            }
        }
    }

    fn action(&mut self) -> PResult<Action> {
        let word = match &self.peek().tok {
            Tok::Ident(s) if ACTION_WORDS.contains(&s.as_str()) => s.clone(),
            _ => {
                return Err(self.error(
                    "an action",
                    "the actions are `activate NET`, `deactivate NET`, `finish`, `start TIMER after 30s`, `cancel TIMER`, `call PROGRAM.FUNCTION(args)` and `emit EVENT(args) [to NET]`",
                ))
            }
        };
        let start = self.bump().span;
        Ok(match word.as_str() {
            "activate" => {
                let net =
                    self.name("a net name", "write `activate NET` or `activate NET(args)`")?;
                let mut span = start.to(net.span);
                let args = if self.at(&Tok::LParen) {
                    self.bump();
                    let (args, end) = self.args(Tok::RParen)?;
                    span = span.to(end);
                    args
                } else {
                    Vec::new()
                };
                Action::Activate { net, args, span }
            }
            "deactivate" if self.at_ident("self") => {
                let t = self.bump();
                Action::Deactivate(Name {
                    text: "self".into(),
                    span: t.span,
                })
            }
            "deactivate" => Action::Deactivate(
                self.name("a net name", "write `deactivate NET` or `deactivate self`")?,
            ),
            "finish" => Action::Finish(start),
            "cancel" => Action::CancelTimer(self.name("a timer name", "write `cancel TIMER`")?),
            "start" => {
                const HELP: &str = "write `start TIMER after 30s`, or `after NAME` with an event parameter in seconds";
                let timer = self.name("a timer name", HELP)?;
                if !self.at_ident("after") {
                    return Err(self.error("`after`", HELP));
                }
                self.bump();
                let t = self.peek().clone();
                let after = match t.tok {
                    Tok::Duration(value, unit) => {
                        self.bump();
                        DurationExpr::Literal {
                            value,
                            unit,
                            span: t.span,
                        }
                    }
                    Tok::Ident(ref w) if w == "self" => match self.expr()? {
                        Expr::SelfParam(n) => DurationExpr::SelfSeconds(n),
                        _ => return Err(self.error("`self.NAME`", HELP)),
                    },
                    Tok::Ident(_) => DurationExpr::Seconds(self.name("a duration", HELP)?),
                    _ => return Err(self.error("a duration such as `30s`", HELP)),
                };
                Action::StartTimer { timer, after }
            }
            "call" => {
                const HELP: &str = "write `call PROGRAM.FUNCTION(arg, ...)`, or `call self.PARAM.FUNCTION(...)` for the program a net parameter names";
                // `self.PARAM`: the program a parameter of the net names.
                let program = if self.at_ident("self") {
                    let s = self.bump().span;
                    self.expect(Tok::Dot, HELP)?;
                    let param = self.name("a parameter name", HELP)?;
                    Name {
                        text: format!("self.{}", param.text),
                        span: s.to(param.span),
                    }
                } else {
                    self.name("a program name", HELP)?
                };
                self.expect(Tok::Dot, HELP)?;
                let function = self.name("a function name", HELP)?;
                self.expect(Tok::LParen, HELP)?;
                let (args, end) = self.args(Tok::RParen)?;
                Action::Call {
                    program,
                    function,
                    args,
                    span: start.to(end),
                }
            }
            "emit" => {
                let event = self.name(
                    "an event name",
                    "write `emit EVENT` or `emit EVENT(arg, ...)`",
                )?;
                let mut span = start.to(event.span);
                let args = if self.at(&Tok::LParen) {
                    self.bump();
                    let (args, end) = self.args(Tok::RParen)?;
                    span = span.to(end);
                    args
                } else {
                    Vec::new()
                };
                let to = if self.at_ident("to") {
                    self.bump();
                    let net = self.name("a net name", "write `emit EVENT(args) to NET`")?;
                    span = span.to(net.span);
                    Some(net)
                } else {
                    None
                };
                Action::Emit {
                    event,
                    args,
                    to,
                    span,
                }
            }
            _ => unreachable!("ACTION_WORDS lists exactly the words matched above"),
        })
    }

    /// Arguments up to and including `close`; returns them and the closing span.
    fn args(&mut self, close: Tok) -> PResult<(Vec<Expr>, Span)> {
        let mut args = Vec::new();
        loop {
            if self.at(&close) {
                return Ok((args, self.bump().span));
            }
            args.push(self.expr()?);
            if !self.at(&close) {
                self.expect(Tok::Comma, "separate arguments with `,`")?;
            }
        }
    }

    fn expr(&mut self) -> PResult<Expr> {
        let t = self.peek().clone();
        let e = match t.tok {
            Tok::Int(v) => Expr::Int(v, t.span),
            Tok::Float(v) => Expr::Float(v, t.span),
            Tok::Text(s) => Expr::Text(s, t.span),
            Tok::Ident(ref s) if s == "true" => Expr::Bool(true, t.span),
            Tok::Ident(ref s) if s == "false" => Expr::Bool(false, t.span),
            Tok::Ident(ref s)
                if s == "self"
                    && matches!(self.toks.get(self.pos + 1).map(|t| &t.tok), Some(Tok::Dot)) =>
            {
                self.bump();
                self.bump();
                let n = self.name("a parameter name", "write `self.PARAMETER`")?;
                return Ok(Expr::SelfParam(Name {
                    text: n.text,
                    span: t.span.to(n.span),
                }));
            }
            Tok::Ident(_) => return Ok(Expr::Var(self.name("a value", "")?)),
            Tok::LBracket if self.list_depth >= MAX_NESTING => {
                self.diags.push(
                    Diagnostic::error(
                        "E0001",
                        t.span,
                        format!("lists nested more than {MAX_NESTING} deep"),
                    )
                    .label("too deep")
                    .help("an argument is at most a list of floats `[1.0, 2.0]`"),
                );
                return Err(Recover);
            }
            Tok::LBracket => {
                self.bump();
                self.list_depth += 1;
                let list = self.args(Tok::RBracket);
                self.list_depth -= 1;
                let (items, end) = list?;
                return Ok(Expr::List(items, t.span.to(end)));
            }
            _ => {
                return Err(self.error(
                    "a value",
                    "an argument is a number, `true`, `false`, a \"text\", a list `[1.0, 2.0]` or a name bound by the event",
                ))
            }
        };
        self.bump();
        Ok(e)
    }
}

const ACTION_WORDS: [&str; 7] = [
    "activate",
    "deactivate",
    "finish",
    "start",
    "cancel",
    "call",
    "emit",
];

/// Parses one net file. Syntax errors go to `diags`; the returned file holds every net and item
/// that could be read, so later checks still run on the rest.
pub fn parse_file(file: FileId, path: &str, text: &str, diags: &mut Diagnostics) -> NetFile {
    let toks = lex(file, text, diags);
    let mut p = Parser {
        toks,
        pos: 0,
        diags,
        pending: Vec::new(),
        depth: 0,
        list_depth: 0,
    };
    p.file(path)
}

/// Parses one action written alone, as PNML's `<toolspecific tool="petrel">` blocks carry them.
pub fn parse_action(file: FileId, text: &str, diags: &mut Diagnostics) -> Option<Action> {
    let toks = lex(file, text, diags);
    let mut p = Parser {
        toks,
        pos: 0,
        diags,
        pending: Vec::new(),
        depth: 0,
        list_depth: 0,
    };
    let action = p.action().ok()?;
    if !p.at(&Tok::Eof) {
        p.error("the end of the action", "write one action only");
        return None;
    }
    Some(action)
}

/// Parses a guard written alone (the text after `if`), as PNML's Petrel blocks carry them.
pub fn parse_guard(file: FileId, text: &str, diags: &mut Diagnostics) -> Option<Guard> {
    let mut p = Parser {
        toks: lex(file, text, diags),
        pos: 0,
        diags,
        pending: Vec::new(),
        depth: 0,
        list_depth: 0,
    };
    let guard = p.guard().ok()?;
    if !p.at(&Tok::Eof) {
        p.error(
            "the end of the guard",
            "write one guard only: join conditions with `and`, `or`",
        );
        return None;
    }
    Some(guard)
}

/// Parses arguments written alone (`"r1", 0.5, self.speed`, without parentheses; empty text for
/// none), as PNML's Petrel blocks carry the arguments of instances and `children` lines.
pub fn parse_args(file: FileId, text: &str, diags: &mut Diagnostics) -> Option<Vec<Expr>> {
    let mut p = Parser {
        toks: lex(file, text, diags),
        pos: 0,
        diags,
        pending: Vec::new(),
        depth: 0,
        list_depth: 0,
    };
    // The end of the text closes the list as `)` would.
    p.args(Tok::Eof).ok().map(|(args, _)| args)
}
