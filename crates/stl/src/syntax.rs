//! The text syntax: a parser with located errors and a printer that round-trips.
//!
//! # Grammar (ASCII)
//!
//! ```text
//! formula  := implies
//! implies  := or ( "->" implies )?             right-associative
//! or       := and ( "|" and )*                 n-ary
//! and      := until ( "&" until )*             n-ary
//! until    := unary ( "U" interval? until )?   right-associative
//! unary    := "!" unary | "X" unary | "F" interval? unary | "G" interval? unary | atom
//! atom     := "true" | "false" | "(" formula ")" | NAME ( CMP NUMBER )?
//! interval := "[" INT "," ( INT | "inf" ) "]"
//! CMP      := ">" | ">=" | "<" | "<="
//! ```
//!
//! Precedence, loosest first: `->`, `|`, `&`, `U`, then the prefix operators `!`,
//! `X`, `F`, `G`, which bind tightest. So `F[1,2] a & b -> c` is
//! `((F[1,2] a) & b) -> c`, and `a U b U c` is `a U (b U c)`. `&&`, `||` and `=>` are
//! accepted as synonyms. `F φ`, `G φ` and `φ U ψ` without an interval mean `[0,inf]`.
//! `true`, `false`, `inf`, `X`, `F`, `G` and `U` are reserved; a NAME is
//! `[A-Za-z_][A-Za-z0-9_.]*`. `#` starts a comment to the end of the line.
//!
//! The printer emits the fewest parentheses that parse back to the same tree:
//! `parse(print(f)) == f` for every formula whose numbers are finite.

use std::fmt;

use crate::formula::{CmpOp, Formula, Interval};

/// Deepest nesting accepted, so that hostile input cannot overflow the stack: levels
/// of parentheses, prefix operators (`!`, `X`, `F`, `G`) and right-nested `->`/`U`.
pub const MAX_DEPTH: usize = 256;

/// Largest interval bound accepted.
pub const MAX_STEP: usize = 1 << 30;

/// A syntax error, located by line and column (both 1-based, columns in characters).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("line {line}, column {column}: expected {expected}, found {found}")]
pub struct ParseError {
    /// 1-based line.
    pub line: usize,
    /// 1-based column, in characters.
    pub column: usize,
    /// What the parser expected there.
    pub expected: String,
    /// What it found.
    pub found: String,
}

impl ParseError {
    /// The error followed by the offending line and a caret under the column.
    pub fn render(&self, source: &str) -> String {
        let text = source.lines().nth(self.line - 1).unwrap_or("");
        format!("{self}\n  {text}\n  {}^", " ".repeat(self.column.saturating_sub(1)))
    }
}

#[derive(Clone, Debug, PartialEq)]
enum Tok {
    LParen,
    RParen,
    LBrack,
    RBrack,
    Comma,
    Bang,
    Amp,
    Bar,
    Arrow,
    Cmp(CmpOp),
    Num(f64, String),
    Name(String),
    Eof,
}

impl Tok {
    fn describe(&self) -> String {
        match self {
            Tok::LParen => "'('".into(),
            Tok::RParen => "')'".into(),
            Tok::LBrack => "'['".into(),
            Tok::RBrack => "']'".into(),
            Tok::Comma => "','".into(),
            Tok::Bang => "'!'".into(),
            Tok::Amp => "'&'".into(),
            Tok::Bar => "'|'".into(),
            Tok::Arrow => "'->'".into(),
            Tok::Cmp(op) => format!("'{}'", op.symbol()),
            Tok::Num(_, s) => format!("number '{s}'"),
            Tok::Name(n) => format!("'{n}'"),
            Tok::Eof => "end of input".into(),
        }
    }
}

struct Token {
    tok: Tok,
    line: usize,
    column: usize,
}

fn lex(src: &str) -> Result<Vec<Token>, ParseError> {
    let chars: Vec<char> = src.chars().collect();
    let mut out = Vec::new();
    let (mut i, mut line, mut col) = (0, 1, 1);
    let err = |line, column, expected: &str, found: String| ParseError {
        line,
        column,
        expected: expected.into(),
        found,
    };
    while i < chars.len() {
        let c = chars[i];
        let (l0, c0) = (line, col);
        let peek = chars.get(i + 1).copied();
        let mut take = |n: usize, tok: Tok, i: &mut usize, col: &mut usize| {
            out.push(Token { tok, line: l0, column: c0 });
            *i += n;
            *col += n;
        };
        match c {
            '\n' => {
                i += 1;
                line += 1;
                col = 1;
            }
            c if c.is_whitespace() => {
                i += 1;
                col += 1;
            }
            // A UTF-8 byte-order mark (editors on Windows write one) is not text.
            '\u{feff}' if i == 0 => i += 1,
            '#' => {
                while i < chars.len() && chars[i] != '\n' {
                    i += 1;
                    col += 1;
                }
            }
            '(' => take(1, Tok::LParen, &mut i, &mut col),
            ')' => take(1, Tok::RParen, &mut i, &mut col),
            '[' => take(1, Tok::LBrack, &mut i, &mut col),
            ']' => take(1, Tok::RBrack, &mut i, &mut col),
            ',' => take(1, Tok::Comma, &mut i, &mut col),
            '!' => take(1, Tok::Bang, &mut i, &mut col),
            '&' => take(if peek == Some('&') { 2 } else { 1 }, Tok::Amp, &mut i, &mut col),
            '|' => take(if peek == Some('|') { 2 } else { 1 }, Tok::Bar, &mut i, &mut col),
            '=' if peek == Some('>') => take(2, Tok::Arrow, &mut i, &mut col),
            '-' if peek == Some('>') => take(2, Tok::Arrow, &mut i, &mut col),
            '>' | '<' => {
                let eq = peek == Some('=');
                let op = match (c, eq) {
                    ('>', false) => CmpOp::Gt,
                    ('>', true) => CmpOp::Ge,
                    ('<', false) => CmpOp::Lt,
                    _ => CmpOp::Le,
                };
                take(if eq { 2 } else { 1 }, Tok::Cmp(op), &mut i, &mut col)
            }
            c if c.is_ascii_digit() || c == '.' || c == '-' || c == '+' => {
                let start = i;
                let mut j = i + 1;
                while j < chars.len() {
                    let d = chars[j];
                    let exp_sign = (d == '-' || d == '+') && matches!(chars[j - 1], 'e' | 'E');
                    if d.is_ascii_digit() || d == '.' || d == 'e' || d == 'E' || exp_sign {
                        j += 1;
                    } else {
                        break;
                    }
                }
                let text: String = chars[start..j].iter().collect();
                match text.parse::<f64>() {
                    Ok(v) if v.is_finite() => take(j - start, Tok::Num(v, text), &mut i, &mut col),
                    _ => return Err(err(l0, c0, "a finite number", format!("'{text}'"))),
                }
            }
            c if c.is_ascii_alphabetic() || c == '_' => {
                let start = i;
                let mut j = i;
                while j < chars.len()
                    && (chars[j].is_ascii_alphanumeric() || chars[j] == '_' || chars[j] == '.')
                {
                    j += 1;
                }
                let text: String = chars[start..j].iter().collect();
                take(j - start, Tok::Name(text), &mut i, &mut col)
            }
            other => {
                return Err(err(l0, c0, "a formula token", format!("unexpected character '{other}'")));
            }
        }
    }
    out.push(Token { tok: Tok::Eof, line, column: col });
    Ok(out)
}

const RESERVED: [&str; 7] = ["true", "false", "inf", "X", "F", "G", "U"];

/// `true` if `name` can be used as a predicate or signal name in the text syntax.
pub fn is_valid_name(name: &str) -> bool {
    let mut cs = name.chars();
    matches!(cs.next(), Some(c) if c.is_ascii_alphabetic() || c == '_')
        && cs.all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '.')
        && !RESERVED.contains(&name)
}

struct Parser {
    toks: Vec<Token>,
    pos: usize,
    depth: usize,
}

const FORMULA_START: &str = "a formula (true, false, a name, '(', '!', 'X', 'F' or 'G')";

impl Parser {
    fn peek(&self) -> &Tok {
        &self.toks[self.pos].tok
    }

    fn bump(&mut self) -> &Token {
        let t = &self.toks[self.pos];
        if self.pos + 1 < self.toks.len() {
            self.pos += 1;
        }
        t
    }

    fn error_here(&self, expected: impl Into<String>) -> ParseError {
        let t = &self.toks[self.pos];
        ParseError { line: t.line, column: t.column, expected: expected.into(), found: t.tok.describe() }
    }

    fn is_keyword(&self, kw: &str) -> bool {
        matches!(self.peek(), Tok::Name(n) if n == kw)
    }

    fn expect(&mut self, tok: Tok, expected: &str) -> Result<(), ParseError> {
        if *self.peek() == tok {
            self.bump();
            Ok(())
        } else {
            Err(self.error_here(expected))
        }
    }

    /// Parses one more level of nesting with `inner`.
    fn nested<T>(&mut self, inner: impl FnOnce(&mut Self) -> Result<T, ParseError>) -> Result<T, ParseError> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            return Err(self.error_here(format!(
                "at most {MAX_DEPTH} levels of nesting (parentheses, !, X, F, G, and -> or U chained to the right)"
            )));
        }
        let out = inner(self);
        self.depth -= 1;
        out
    }

    fn implies(&mut self) -> Result<Formula, ParseError> {
        let lhs = self.or()?;
        if *self.peek() != Tok::Arrow {
            return Ok(lhs);
        }
        self.bump();
        let rhs = self.nested(Self::implies)?;
        Ok(Formula::Implies(Box::new(lhs), Box::new(rhs)))
    }

    fn or(&mut self) -> Result<Formula, ParseError> {
        let mut v = vec![self.and()?];
        while *self.peek() == Tok::Bar {
            self.bump();
            v.push(self.and()?);
        }
        Ok(if v.len() == 1 { v.pop().unwrap() } else { Formula::Or(v) })
    }

    fn and(&mut self) -> Result<Formula, ParseError> {
        let mut v = vec![self.until()?];
        while *self.peek() == Tok::Amp {
            self.bump();
            v.push(self.until()?);
        }
        Ok(if v.len() == 1 { v.pop().unwrap() } else { Formula::And(v) })
    }

    fn until(&mut self) -> Result<Formula, ParseError> {
        let lhs = self.unary()?;
        if !self.is_keyword("U") {
            return Ok(lhs);
        }
        self.bump();
        let iv = self.opt_interval()?;
        let rhs = self.nested(Self::until)?;
        Ok(Formula::Until(iv, Box::new(lhs), Box::new(rhs)))
    }

    fn unary(&mut self) -> Result<Formula, ParseError> {
        Ok(match self.peek().clone() {
            Tok::Bang => {
                self.bump();
                Formula::Not(Box::new(self.nested(Self::unary)?))
            }
            Tok::Name(n) if n == "X" => {
                self.bump();
                Formula::Next(Box::new(self.nested(Self::unary)?))
            }
            Tok::Name(n) if n == "F" || n == "G" => {
                self.bump();
                let iv = self.opt_interval()?;
                let body = Box::new(self.nested(Self::unary)?);
                if n == "F" { Formula::Eventually(iv, body) } else { Formula::Globally(iv, body) }
            }
            _ => self.atom()?,
        })
    }

    fn atom(&mut self) -> Result<Formula, ParseError> {
        match self.peek().clone() {
            Tok::LParen => {
                self.bump();
                let f = self.nested(Self::implies)?;
                self.expect(Tok::RParen, "')' to close the '(' or an operator (&, |, ->, U)")?;
                Ok(f)
            }
            Tok::Name(n) if n == "true" => {
                self.bump();
                Ok(Formula::True)
            }
            Tok::Name(n) if n == "false" => {
                self.bump();
                Ok(Formula::False)
            }
            Tok::Name(n) if !RESERVED.contains(&n.as_str()) => {
                self.bump();
                if let Tok::Cmp(op) = *self.peek() {
                    self.bump();
                    match self.peek().clone() {
                        Tok::Num(v, _) => {
                            self.bump();
                            Ok(Formula::Compare { signal: n, op, threshold: v })
                        }
                        _ => Err(self.error_here(format!("a number after '{n} {}'", op.symbol()))),
                    }
                } else {
                    Ok(Formula::Atom(n))
                }
            }
            _ => Err(self.error_here(FORMULA_START)),
        }
    }

    fn step(&mut self, what: &str) -> Result<usize, ParseError> {
        match self.peek().clone() {
            Tok::Num(v, text) if v >= 0.0 && v.fract() == 0.0 && !text.contains(['.', 'e', 'E']) => {
                if v > MAX_STEP as f64 {
                    return Err(self.error_here(format!("{what} at most {MAX_STEP}")));
                }
                self.bump();
                Ok(v as usize)
            }
            _ => Err(self.error_here(format!("{what} (a whole number of steps >= 0)"))),
        }
    }

    fn opt_interval(&mut self) -> Result<Interval, ParseError> {
        if *self.peek() != Tok::LBrack {
            return Ok(Interval::all());
        }
        self.bump();
        let start = self.step("the interval's start")?;
        self.expect(Tok::Comma, "',' between the interval's bounds")?;
        let end = if self.is_keyword("inf") {
            self.bump();
            None
        } else {
            let at = self.pos;
            let e = self.step("the interval's end or 'inf'")?;
            if e < start {
                let t = &self.toks[at];
                return Err(ParseError {
                    line: t.line,
                    column: t.column,
                    expected: format!("an interval end >= its start {start}"),
                    found: e.to_string(),
                });
            }
            Some(e)
        };
        self.expect(Tok::RBrack, "']' to close the interval")?;
        Ok(Interval { start, end })
    }
}

/// Parses a formula from its text syntax.
pub fn parse(src: &str) -> Result<Formula, ParseError> {
    let toks = lex(src)?;
    let mut p = Parser { toks, pos: 0, depth: 0 };
    let f = p.implies()?;
    if *p.peek() != Tok::Eof {
        return Err(p.error_here("an operator (&, |, ->, U) or the end of the formula"));
    }
    Ok(f)
}

impl std::str::FromStr for Formula {
    type Err = ParseError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        parse(s)
    }
}

/// Where `name` first occurs as a name in `src` (1-based line and column), so that
/// errors about a name (unbound, unknown signal) can point into the spec text.
pub fn locate_name(src: &str, name: &str) -> Option<(usize, usize)> {
    lex(src)
        .ok()?
        .into_iter()
        .find(|t| matches!(&t.tok, Tok::Name(n) if n == name))
        .map(|t| (t.line, t.column))
}

// ---------------------------------------------------------------------------
// Printer
// ---------------------------------------------------------------------------

/// Binding strength, loosest first; a child printed where a higher level is
/// required gets parentheses.
fn level(f: &Formula) -> u8 {
    match f {
        Formula::Implies(..) => 1,
        Formula::Or(v) if v.len() >= 2 => 2,
        Formula::And(v) if v.len() >= 2 => 3,
        Formula::Or(v) | Formula::And(v) => v.first().map_or(6, level),
        Formula::Until(..) => 4,
        Formula::Not(_) | Formula::Next(_) | Formula::Eventually(..) | Formula::Globally(..) => 5,
        Formula::True | Formula::False | Formula::Atom(_) | Formula::Compare { .. } => 6,
    }
}

fn write_at(f: &Formula, min_level: u8, out: &mut fmt::Formatter<'_>) -> fmt::Result {
    if level(f) < min_level {
        write!(out, "(")?;
        write_formula(f, out)?;
        write!(out, ")")
    } else {
        write_formula(f, out)
    }
}

fn write_interval(iv: &Interval, out: &mut fmt::Formatter<'_>) -> fmt::Result {
    match iv.end {
        _ if iv.is_all() => Ok(()),
        Some(e) => write!(out, "[{},{}]", iv.start, e),
        None => write!(out, "[{},inf]", iv.start),
    }
}

fn write_nary(
    v: &[Formula],
    sep: &str,
    child_level: u8,
    empty: &str,
    out: &mut fmt::Formatter<'_>,
) -> fmt::Result {
    match v {
        [] => write!(out, "{empty}"),
        [one] => write_formula(one, out),
        _ => {
            for (i, c) in v.iter().enumerate() {
                if i > 0 {
                    write!(out, " {sep} ")?;
                }
                write_at(c, child_level, out)?;
            }
            Ok(())
        }
    }
}

fn write_formula(f: &Formula, out: &mut fmt::Formatter<'_>) -> fmt::Result {
    match f {
        Formula::True => write!(out, "true"),
        Formula::False => write!(out, "false"),
        Formula::Atom(n) => write!(out, "{n}"),
        Formula::Compare { signal, op, threshold } => write!(out, "{signal} {} {threshold}", op.symbol()),
        Formula::Not(c) => {
            write!(out, "!")?;
            write_at(c, 5, out)
        }
        Formula::Next(c) => {
            write!(out, "X ")?;
            write_at(c, 5, out)
        }
        Formula::Eventually(iv, c) | Formula::Globally(iv, c) => {
            write!(out, "{}", if matches!(f, Formula::Eventually(..)) { "F" } else { "G" })?;
            write_interval(iv, out)?;
            write!(out, " ")?;
            write_at(c, 5, out)
        }
        Formula::And(v) => write_nary(v, "&", 4, "true", out),
        Formula::Or(v) => write_nary(v, "|", 3, "false", out),
        Formula::Implies(l, r) => {
            write_at(l, 2, out)?;
            write!(out, " -> ")?;
            write_at(r, 1, out)
        }
        Formula::Until(iv, l, r) => {
            write_at(l, 5, out)?;
            write!(out, " U")?;
            write_interval(iv, out)?;
            write!(out, " ")?;
            write_at(r, 4, out)
        }
    }
}

impl fmt::Display for Formula {
    /// Prints the text syntax; `parse(&f.to_string()) == Ok(f)`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write_formula(self, f)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn precedence_and_associativity() {
        let f = parse("F[1,2] a & b -> c").unwrap();
        let want = (Formula::atom("a").eventually(1, 2) & Formula::atom("b")).implies(Formula::atom("c"));
        assert_eq!(f, want);
        let f = parse("a U b U c").unwrap();
        let want = Formula::atom("a").until_from(0, Formula::atom("b").until_from(0, Formula::atom("c")));
        assert_eq!(f, want);
        let f = parse("a -> b -> c").unwrap();
        assert_eq!(f, Formula::atom("a").implies(Formula::atom("b").implies(Formula::atom("c"))));
        let f = parse("a | b & c").unwrap();
        assert_eq!(f, Formula::atom("a") | (Formula::atom("b") & Formula::atom("c")));
        assert_eq!(parse("!x > 0.5").unwrap(), !Formula::gt("x", 0.5));
    }

    #[test]
    fn errors_are_located() {
        let e = parse("F[1,2] a &\n  (b | )").unwrap_err();
        assert_eq!((e.line, e.column), (2, 8));
        assert!(e.expected.starts_with("a formula"), "{e}");
        assert_eq!(e.found, "')'");
        let e = parse("G[3,1] a").unwrap_err();
        assert_eq!((e.line, e.column), (1, 5));
        assert!(e.to_string().contains("interval end >= its start 3"), "{e}");
        let e = parse("x > ").unwrap_err();
        assert!(e.expected.contains("a number after 'x >'"), "{e}");
        let e = parse("a $ b").unwrap_err();
        assert_eq!((e.line, e.column), (1, 3));
    }

    #[test]
    fn deep_nesting_is_an_error_not_a_crash() {
        let src = "(".repeat(100_000) + "a" + &")".repeat(100_000);
        assert!(parse(&src).unwrap_err().expected.contains("nesting"));
        let src = "!".repeat(100_000) + "a";
        assert!(parse(&src).is_err());
        let src = "a U ".repeat(100_000) + "b";
        assert!(parse(&src).unwrap_err().expected.contains("nesting"));
    }

    #[test]
    fn nesting_is_counted_as_the_message_says() {
        // Regression: each parenthesis once counted three levels, so "at most 256
        // levels" refused 86 parentheses.
        let parens = |n: usize| "(".repeat(n) + "a" + &")".repeat(n);
        assert!(parse(&parens(MAX_DEPTH)).is_ok());
        assert!(parse(&parens(MAX_DEPTH + 1)).unwrap_err().expected.contains("at most 256 levels"));
        assert!(parse(&("!".repeat(MAX_DEPTH) + "a")).is_ok());
        assert!(parse(&("G ".repeat(MAX_DEPTH + 1) + "a")).is_err());
    }

    #[test]
    fn a_byte_order_mark_is_skipped() {
        assert_eq!(parse("\u{feff}F a").unwrap(), parse("F a").unwrap());
    }

    #[test]
    fn locates_names() {
        assert_eq!(locate_name("F a &\n  G  bee", "bee"), Some((2, 6)));
    }
}
