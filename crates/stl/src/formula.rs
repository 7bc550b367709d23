//! The formula syntax tree and a builder API.
//!
//! Every operator of the paper's grammar (§2, App. B) is here: `⊤`, `⊥`, predicates,
//! `¬`, `∧`, `∨`, `⇒`, `○` (next), `◇[a,b]` (eventually), `□[a,b]` (globally) and
//! `U[a,b]` (until), plus comparisons of a named signal with a number. Conjunction and
//! disjunction are n-ary. Intervals count time steps (waypoint indices) relative to
//! the evaluation time, both ends inclusive; an unbounded interval runs to the end of
//! the path.
//!
//! ```
//! use stl::Formula;
//! let a = Formula::atom("goal_a");
//! let safe = Formula::atom("safe");
//! let spec = a.eventually(1, 2) & safe.globally(1, 8);
//! assert_eq!(spec.to_string(), "F[1,2] goal_a & G[1,8] safe");
//! ```

use std::ops::{BitAnd, BitOr, Not};

/// A closed interval `[start, end]` of time steps; `end = None` means "to the end of
/// the path".
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Interval {
    /// First step, relative to the evaluation time.
    pub start: usize,
    /// Last step (inclusive), or `None` for unbounded.
    pub end: Option<usize>,
}

impl Interval {
    /// `[start, end]`.
    pub fn bounded(start: usize, end: usize) -> Self {
        Self { start, end: Some(end) }
    }

    /// `[start, ∞)`: to the end of the path.
    pub fn from(start: usize) -> Self {
        Self { start, end: None }
    }

    /// `[0, ∞)`.
    pub fn all() -> Self {
        Self::from(0)
    }

    /// `true` if the interval is `[0, ∞)`, printed without brackets.
    pub fn is_all(&self) -> bool {
        self.start == 0 && self.end.is_none()
    }

    /// `true` if `start <= end`.
    pub fn is_valid(&self) -> bool {
        self.end.is_none_or(|e| self.start <= e)
    }
}

/// A comparison operator between a signal and a number.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum CmpOp {
    /// `>`: robustness `x − c`.
    Gt,
    /// `>=`: robustness `x − c` (quantitatively identical to `>`).
    Ge,
    /// `<`: robustness `c − x`.
    Lt,
    /// `<=`: robustness `c − x`.
    Le,
}

impl CmpOp {
    /// The ASCII spelling.
    pub fn symbol(self) -> &'static str {
        match self {
            CmpOp::Gt => ">",
            CmpOp::Ge => ">=",
            CmpOp::Lt => "<",
            CmpOp::Le => "<=",
        }
    }

    /// `+1` for `>`/`>=` (robustness `x − c`), `−1` for `<`/`<=` (robustness `c − x`).
    pub fn sign(self) -> f64 {
        match self {
            CmpOp::Gt | CmpOp::Ge => 1.0,
            CmpOp::Lt | CmpOp::Le => -1.0,
        }
    }
}

/// A Signal Temporal Logic formula.
///
/// `And` and `Or` are n-ary. The builder functions ([`Formula::and`],
/// [`Formula::or`], the `&` and `|` operators) keep them normalised: at least two
/// operands, and a chain `a & b & c` is flat. A hand-built `And`/`Or` with fewer
/// operands is accepted (no operand is `true`/`false`, one is that operand).
#[derive(Clone, Debug, PartialEq)]
pub enum Formula {
    /// `⊤`: robustness `+k`.
    True,
    /// `⊥`: robustness `−k`.
    False,
    /// A predicate referred to by name, bound to a function when the spec is built.
    /// A name may also refer to a signal (state dimension): robustness is its value.
    Atom(String),
    /// `signal op threshold`: robustness `x − c` (`>`, `>=`) or `c − x` (`<`, `<=`).
    /// `signal` may name a state dimension or a bound predicate.
    Compare {
        /// Signal or predicate name.
        signal: String,
        /// Comparison.
        op: CmpOp,
        /// The number compared against.
        threshold: f64,
    },
    /// `¬φ`: robustness `−ρ(φ)`.
    Not(Box<Formula>),
    /// `φ1 ∧ … ∧ φn`: min.
    And(Vec<Formula>),
    /// `φ1 ∨ … ∨ φn`: max.
    Or(Vec<Formula>),
    /// `φ ⇒ ψ`: `max(−ρ(φ), ρ(ψ))`.
    Implies(Box<Formula>, Box<Formula>),
    /// `○φ`: φ at the next step.
    Next(Box<Formula>),
    /// `◇[a,b] φ`: max over the window.
    Eventually(Interval, Box<Formula>),
    /// `□[a,b] φ`: min over the window.
    Globally(Interval, Box<Formula>),
    /// `φ U[a,b] ψ`: `max_{k∈[t+a,t+b]} min(ψ_k, min_{j∈[s,k−1]} φ_j)`, with `s = t`
    /// (standard) or `s = t+a` (the paper's App. C), by [`crate::UntilRule`].
    Until(Interval, Box<Formula>, Box<Formula>),
}

impl Formula {
    /// A named predicate.
    pub fn atom(name: impl Into<String>) -> Self {
        Formula::Atom(name.into())
    }

    /// `signal op threshold`.
    pub fn compare(signal: impl Into<String>, op: CmpOp, threshold: f64) -> Self {
        Formula::Compare { signal: signal.into(), op, threshold }
    }

    /// `signal > threshold`.
    pub fn gt(signal: impl Into<String>, threshold: f64) -> Self {
        Self::compare(signal, CmpOp::Gt, threshold)
    }

    /// `signal < threshold`.
    pub fn lt(signal: impl Into<String>, threshold: f64) -> Self {
        Self::compare(signal, CmpOp::Lt, threshold)
    }

    /// The n-ary conjunction of `operands`: `true` if empty, the operand itself if
    /// there is one; nested conjunctions built with `&` are flattened.
    pub fn and(operands: impl IntoIterator<Item = Formula>) -> Self {
        let v: Vec<Formula> = operands.into_iter().collect();
        match v.len() {
            0 => Formula::True,
            1 => v.into_iter().next().unwrap(),
            _ => Formula::And(v),
        }
    }

    /// The n-ary disjunction of `operands`: `false` if empty.
    pub fn or(operands: impl IntoIterator<Item = Formula>) -> Self {
        let v: Vec<Formula> = operands.into_iter().collect();
        match v.len() {
            0 => Formula::False,
            1 => v.into_iter().next().unwrap(),
            _ => Formula::Or(v),
        }
    }

    /// `self ⇒ rhs`.
    pub fn implies(self, rhs: Formula) -> Self {
        Formula::Implies(Box::new(self), Box::new(rhs))
    }

    /// `○ self`.
    pub fn next(self) -> Self {
        Formula::Next(Box::new(self))
    }

    /// `◇[a,b] self`.
    pub fn eventually(self, a: usize, b: usize) -> Self {
        Formula::Eventually(Interval::bounded(a, b), Box::new(self))
    }

    /// `◇[a,∞) self`: at some step from `a` to the end of the path.
    pub fn eventually_from(self, a: usize) -> Self {
        Formula::Eventually(Interval::from(a), Box::new(self))
    }

    /// `□[a,b] self`.
    pub fn globally(self, a: usize, b: usize) -> Self {
        Formula::Globally(Interval::bounded(a, b), Box::new(self))
    }

    /// `□[a,∞) self`: at every step from `a` to the end of the path.
    pub fn globally_from(self, a: usize) -> Self {
        Formula::Globally(Interval::from(a), Box::new(self))
    }

    /// `self U[a,b] rhs`.
    pub fn until(self, a: usize, b: usize, rhs: Formula) -> Self {
        Formula::Until(Interval::bounded(a, b), Box::new(self), Box::new(rhs))
    }

    /// `self U[a,∞) rhs`.
    pub fn until_from(self, a: usize, rhs: Formula) -> Self {
        Formula::Until(Interval::from(a), Box::new(self), Box::new(rhs))
    }

    /// Number of nodes in the tree.
    pub fn size(&self) -> usize {
        1 + self.children().map(Formula::size).sum::<usize>()
    }

    /// The direct sub-formulas.
    pub fn children(&self) -> impl Iterator<Item = &Formula> {
        let v: Vec<&Formula> = match self {
            Formula::True | Formula::False | Formula::Atom(_) | Formula::Compare { .. } => vec![],
            Formula::Not(f) | Formula::Next(f) | Formula::Eventually(_, f) | Formula::Globally(_, f) => {
                vec![f]
            }
            Formula::And(v) | Formula::Or(v) => v.iter().collect(),
            Formula::Implies(l, r) | Formula::Until(_, l, r) => vec![l, r],
        };
        v.into_iter()
    }

    /// The names this formula refers to (predicates and signals), each once, in
    /// order of first appearance.
    pub fn names(&self) -> Vec<&str> {
        let mut out: Vec<&str> = Vec::new();
        self.visit_names(&mut |n| {
            if !out.contains(&n) {
                out.push(n);
            }
        });
        out
    }

    fn visit_names<'a>(&'a self, f: &mut impl FnMut(&'a str)) {
        match self {
            Formula::Atom(n) | Formula::Compare { signal: n, .. } => f(n),
            _ => self.children().for_each(|c| c.visit_names(f)),
        }
    }

    /// How many steps past the evaluation time the formula reads: a path of
    /// `horizon + 1` states holds everything it looks at; `None` if some interval is
    /// unbounded.
    pub fn horizon(&self) -> Option<usize> {
        let sub = |f: &Formula| f.horizon();
        match self {
            Formula::True | Formula::False | Formula::Atom(_) | Formula::Compare { .. } => Some(0),
            Formula::Not(f) => sub(f),
            Formula::Next(f) => sub(f).map(|h| h + 1),
            Formula::And(v) | Formula::Or(v) => v.iter().try_fold(0, |m, f| sub(f).map(|h| m.max(h))),
            Formula::Implies(l, r) => Some(sub(l)?.max(sub(r)?)),
            Formula::Eventually(i, f) | Formula::Globally(i, f) => Some(i.end? + sub(f)?),
            // ψ is read at k ≤ b, φ only on [a, k − 1] (App. C), so at most at b − 1.
            Formula::Until(i, l, r) => {
                let (b, hl, hr) = (i.end?, sub(l)?, sub(r)?);
                Some((b + hr).max(if b > i.start { b - 1 + hl } else { 0 }))
            }
        }
    }
}

impl Formula {
    /// The formula for a path of `to` waypoints instead of `steps`, where that is
    /// plain: every temporal window reads up to the path's last waypoint (its end
    /// plus what its operand looks ahead is `steps`) and holds no window inside it
    /// (`○` may appear); each such window then ends `steps − to` steps earlier, so
    /// the result asks of the first `to` waypoints what the formula asks of all of
    /// them (`□[1,17](l0 ∨ l1)` → `□[1,4](l0 ∨ l1)`). `None` when some window does
    /// not reach the end (`◇[1,2] g0` on 8 waypoints: a fixed-time obligation), is
    /// nested or unbounded, would become empty, or `to > steps`. What pre-training's
    /// horizon curriculum trains on.
    pub fn end_anchored_prefix(&self, steps: usize, to: usize) -> Option<Formula> {
        if to > steps {
            return None;
        }
        let cut = steps - to;
        let flat = |f: &Formula| f.windows() == 0;
        // This window, shortened: it must read up to the last waypoint exactly.
        let shorten = |i: &Interval| -> Option<Interval> {
            let b = i.end?;
            (self.horizon()? == steps && b >= i.start + cut).then(|| Interval::bounded(i.start, b - cut))
        };
        let each =
            |v: &[Formula]| v.iter().map(|f| f.end_anchored_prefix(steps, to)).collect::<Option<Vec<_>>>();
        let rec = |f: &Formula| f.end_anchored_prefix(steps, to).map(Box::new);
        Some(match self {
            f if flat(f) => f.clone(),
            Formula::Not(f) => Formula::Not(rec(f)?),
            Formula::And(v) => Formula::And(each(v)?),
            Formula::Or(v) => Formula::Or(each(v)?),
            Formula::Implies(l, r) => Formula::Implies(rec(l)?, rec(r)?),
            Formula::Eventually(i, f) if flat(f) => Formula::Eventually(shorten(i)?, f.clone()),
            Formula::Globally(i, f) if flat(f) => Formula::Globally(shorten(i)?, f.clone()),
            Formula::Until(i, l, r) if flat(l) && flat(r) => {
                Formula::Until(shorten(i)?, l.clone(), r.clone())
            }
            // A window under `○` or inside another window: its reach is not the path's end.
            _ => return None,
        })
    }

    /// Temporal windows (`◇`, `□`, `U`) in the formula.
    fn windows(&self) -> usize {
        let own = matches!(self, Formula::Eventually(..) | Formula::Globally(..) | Formula::Until(..));
        usize::from(own) + self.children().map(Formula::windows).sum::<usize>()
    }
}

fn flatten_into(f: Formula, conj: bool, out: &mut Vec<Formula>) {
    match (f, conj) {
        (Formula::And(v), true) | (Formula::Or(v), false) => out.extend(v),
        (f, _) => out.push(f),
    }
}

impl BitAnd for Formula {
    type Output = Formula;

    /// `a & b`, flattening `And` operands into one n-ary conjunction.
    fn bitand(self, rhs: Formula) -> Formula {
        let mut v = Vec::new();
        flatten_into(self, true, &mut v);
        flatten_into(rhs, true, &mut v);
        Formula::And(v)
    }
}

impl BitOr for Formula {
    type Output = Formula;

    /// `a | b`, flattening `Or` operands into one n-ary disjunction.
    fn bitor(self, rhs: Formula) -> Formula {
        let mut v = Vec::new();
        flatten_into(self, false, &mut v);
        flatten_into(rhs, false, &mut v);
        Formula::Or(v)
    }
}

impl Not for Formula {
    type Output = Formula;

    fn not(self) -> Formula {
        Formula::Not(Box::new(self))
    }
}
