//! A spec as a mixed-integer linear program over a plan's waypoints (Raman et al.
//! 2014; Belta & Sadraddini 2019), in the one-sided form that suffices when robustness
//! is maximised.
//!
//! Each sub-formula at each waypoint gets a value `r` that is only bounded *above* by
//! what it stands for, so `r` is a lower bound of the (linearised) robustness and the
//! maximum of the root's `r` is the maximum robustness:
//!
//! * `min` (`∧`, `□`, the predicates' inscribed polygons): `r ≤ rᵢ` for every operand,
//!   no binaries;
//! * `max` (`∨`, `◇`, `U`): one binary `bᵢ` per operand, `Σ bᵢ = 1`,
//!   `r ≤ rᵢ + Mᵢ (1 − bᵢ)`.
//!
//! Negation is pushed down to the predicates (`¬□ = ◇¬`, `¬(φ U ψ)` = the dual
//! min-max), so no constraint ever bounds `r` from below. Time follows the STL
//! library's finite-path rule (indices past the end read the last waypoint) and its
//! until readings, so the program's robustness is that of [`stl::Spec`] with the
//! predicates replaced by their [`Shape`]s.
//!
//! Clauses that keep out of something (they negate, e.g. an avoid region) and look at
//! one waypoint and its next (no `◇`, `□`, `U` inside) are *lazy*, in a program without
//! claims (below), where they are operands of a conjunction in positive position: until a round of
//! [`super::plan`] finds a plan that violates one of them at some waypoint, that
//! occurrence is left out (read as `⊤`). Leaving out a conjunct only raises the
//! optimum, and the robustness is monotone in every positive occurrence, so a plan
//! whose left-out occurrences are all at least the optimum `ρ*` has robustness at
//! least `ρ*` (for any min-max formula, `f(s ∧ c) ≥ f(s) ∧ c`).
//!
//! *Claims* (specs that keep out of a goal disc, as Loop's and Signal's alternation):
//! each waypoint `t` and goal disc `j` has one binary `a_tj`, shared by every `max`
//! that mentions it, standing for "waypoint `t` is in `j`". Reaching `j` at `t` as an
//! option of a `max` is gated by `a_tj` instead of a binary of its own; staying out of
//! disc `k` at `t` gains the options `ρ̃_j(x_t) + gap_jk`, gated by `a_tj`, for every
//! other disc `j` with `gap_jk = ‖c_j − c_k‖ − r_j − r_k > 0`. That is a lower bound
//! everywhere (triangle inequality: `‖x − c_k‖ − r_k ≥ r_j − ‖x − c_j‖ + gap_jk`), so
//! any claim is sound; a `max` with claimed options asks `Σ own bᵢ + Σ claims ≥ 1`. So
//! a plan that is at some goal at every waypoint, as Loop's, needs none of the tangent
//! binaries to keep out of the others: choosing the corners decides the alternation.
//! Two `max`es that mention the same goal at the same waypoint share its claim, which
//! can only lower the optimum, never make it unsound; specs that never keep out of a
//! goal are encoded without claims. With claims no clause is lazy: left out one
//! waypoint at a time, Loop's alternation was violated somewhere new round after round.
//!
//! Every value carries an interval `[lo, hi]` from the plan region, so each big-M is
//! the tightest the interval allows (`Mᵢ = hi(r) − lo(rᵢ)`), and operands that can
//! never decide a `min` or `max` are dropped before they cost a binary.

use std::collections::{HashMap, HashSet};

use good_lp::{Constraint, Expression, ProblemVariables, Variable, variable};
use stl::{Formula, Interval, UntilRule};

use super::MipError;
use super::geometry::{Atoms, Shape};
use crate::task::OPEN_CLEARANCE;

/// A lower bound of a robustness value: a number, or an affine expression in the
/// program's variables with the interval it can take.
#[derive(Clone, Debug)]
pub(super) enum Rob {
    /// Known in advance.
    Const(f64),
    /// Depends on the plan.
    Lin {
        /// The value.
        e: Expression,
        /// Its least possible value.
        lo: f64,
        /// Its greatest possible value.
        hi: f64,
    },
}

impl Rob {
    fn bounds(&self) -> (f64, f64) {
        match self {
            Rob::Const(c) => (*c, *c),
            Rob::Lin { lo, hi, .. } => (*lo, *hi),
        }
    }

    /// The value plus `d`.
    fn plus(self, d: f64) -> Rob {
        match self {
            Rob::Const(c) => Rob::Const(c + d),
            Rob::Lin { e, lo, hi } => Rob::Lin { e: e + d, lo: lo + d, hi: hi + d },
        }
    }
}

/// An operand of a `max`: with a binary of its own, or gated by a claim.
enum Opt {
    Own(Rob),
    Claimed(Rob, Variable),
}

/// The program under construction: waypoint variables, constraints, binaries.
pub(super) struct Program {
    /// Variables of the program.
    pub vars: ProblemVariables,
    /// Its constraints.
    pub constraints: Vec<Constraint>,
    /// Waypoints `1..=T` (index `t − 1`), two coordinates each.
    pub x: Vec<[Variable; 2]>,
    /// Binary variables, in the order they were created.
    pub binaries: Vec<Variable>,
    /// Claims: "waypoint `t` is in goal disc `j`", by `(t, j)`.
    claims: HashMap<(usize, usize), Variable>,
    /// "The segment into waypoint `t` (or the waypoint) lies in the walls' free cell
    /// `c`", by `(t, c)`.
    cells: HashMap<(usize, usize), Variable>,
    start: [f64; 2],
    lo: [f64; 2],
    hi: [f64; 2],
}

impl Program {
    /// Waypoint variables for a plan of `steps` waypoints after `start`, inside the
    /// region `(lo, hi)`.
    pub fn new(start: [f64; 2], steps: usize, (lo, hi): ([f64; 2], [f64; 2])) -> Self {
        let mut vars = ProblemVariables::new();
        let x = (0..steps).map(|_| [0, 1].map(|k| vars.add(variable().min(lo[k]).max(hi[k])))).collect();
        let (claims, cells) = (HashMap::new(), HashMap::new());
        Self { vars, constraints: vec![], x, binaries: vec![], claims, cells, start, lo, hi }
    }

    /// The start (waypoint 0).
    pub fn start(&self) -> [f64; 2] {
        self.start
    }

    /// `constant + Σ c · x_t[k]`, the start's coordinates folded into the constant.
    fn affine(&mut self, terms: &[(usize, usize, f64)], constant: f64) -> Rob {
        let (mut e, mut lo, mut hi) = (Expression::from(constant), constant, constant);
        let mut any = false;
        for &(t, k, c) in terms {
            if t == 0 {
                e += c * self.start[k];
                lo += c * self.start[k];
                hi += c * self.start[k];
            } else {
                any = true;
                e.add_mul(c, self.x[t - 1][k]);
                lo += (c * self.lo[k]).min(c * self.hi[k]);
                hi += (c * self.lo[k]).max(c * self.hi[k]);
            }
        }
        if any { Rob::Lin { e, lo, hi } } else { Rob::Const(lo) }
    }

    /// A fresh continuous variable in `[lo, hi]`.
    fn value(&mut self, lo: f64, hi: f64) -> Variable {
        self.vars.add(variable().min(lo).max(hi))
    }

    /// `min` of the operands.
    pub fn min(&mut self, items: Vec<Rob>) -> Rob {
        let hi = items.iter().map(|r| r.bounds().1).fold(f64::INFINITY, f64::min);
        // An operand that is never below another's greatest value never decides the
        // min; the rest are constants, or equal to one at their least (`lo = hi`).
        let (mut lins, mut fixed) = (vec![], f64::INFINITY);
        for r in items {
            match r {
                Rob::Lin { e, lo: l, hi: h } if l < hi => lins.push((e, l, h)),
                other => fixed = fixed.min(other.bounds().0),
            }
        }
        if lins.is_empty() {
            return Rob::Const(fixed);
        }
        if lins.len() == 1 && fixed >= lins[0].2 {
            let (e, lo, hi) = lins.pop().expect("one operand");
            return Rob::Lin { e, lo, hi };
        }
        let lo = lins.iter().map(|l| l.1).fold(f64::INFINITY, f64::min);
        // r ≤ every operand; the constants through r's upper bound.
        let r = self.value(lo, hi);
        for (e, _, _) in lins {
            self.constraints.push(Expression::from(r).leq(e));
        }
        Rob::Lin { e: r.into(), lo, hi }
    }

    /// `max` of the operands.
    pub fn max(&mut self, items: Vec<Rob>) -> Rob {
        let lo = items.iter().map(|r| r.bounds().0).fold(f64::NEG_INFINITY, f64::max);
        // An operand that is never above another's least value never decides the max;
        // the rest are constants, or equal to one at their greatest (`lo = hi`).
        let (mut lins, mut fixed) = (vec![], f64::NEG_INFINITY);
        for r in items {
            match r {
                Rob::Lin { e, lo: l, hi: h } if h > lo => lins.push((e, l, h)),
                other => fixed = fixed.max(other.bounds().1),
            }
        }
        if lins.is_empty() {
            return Rob::Const(fixed);
        }
        let best_lin_lo = lins.iter().map(|l| l.1).fold(f64::NEG_INFINITY, f64::max);
        if lins.len() == 1 && fixed <= best_lin_lo {
            let (e, lo, hi) = lins.pop().expect("one operand");
            return Rob::Lin { e, lo, hi };
        }
        let hi = lins.iter().map(|l| l.2).fold(fixed, f64::max);
        let r = self.value(lo, hi);
        let mut choice = Expression::from(0.0);
        // The constant is an option only where no operand is always at least as large.
        let constant = (fixed > best_lin_lo).then_some((Expression::from(fixed), fixed, fixed));
        for (e, l, _) in lins.into_iter().chain(constant) {
            let b = self.binary();
            choice += b;
            self.at_most_if(r, (e, l), hi, b);
        }
        self.constraints.push(choice.eq(1.0));
        Rob::Lin { e: r.into(), lo, hi }
    }

    /// A fresh binary.
    fn binary(&mut self) -> Variable {
        let b = self.vars.add(variable().binary());
        self.binaries.push(b);
        b
    }

    /// `r ≤ e + (hi − l)(1 − b)`: `r` at most the operand `e` (least value `l`) when `b`
    /// is set, free below `hi` otherwise.
    fn at_most_if(&mut self, r: Variable, (e, l): (Expression, f64), hi: f64, b: Variable) {
        self.constraints.push((Expression::from(r) + (hi - l) * b).leq(e + (hi - l)));
    }

    /// The claim that waypoint `t` is in goal disc `disc` (one binary, made once).
    fn claim(&mut self, t: usize, disc: usize) -> Variable {
        if let Some(&a) = self.claims.get(&(t, disc)) {
            return a;
        }
        let a = self.binary();
        self.claims.insert((t, disc), a);
        a
    }

    /// The binary "the segment into waypoint `t` lies in free cell `cell`" (made once:
    /// every occurrence of the walls at `t` has the same best cell).
    fn in_cell(&mut self, t: usize, cell: usize) -> Variable {
        if let Some(&z) = self.cells.get(&(t, cell)) {
            return z;
        }
        let z = self.binary();
        self.cells.insert((t, cell), z);
        z
    }

    /// Consecutive segments in cells that meet: for each `t` with `t + 1` also in
    /// `at`, a cell chosen for one segment needs a cell that `meet`s it chosen for the
    /// other (they share waypoint `t`). Valid only for plans in which the walls hold at
    /// every waypoint of `at` (each segment truly in a cell it claims): the planner adds
    /// these with `ρ̃ ≥ cap > 0` required.
    pub fn link_cells(&mut self, at: &[usize], meet: &[Vec<bool>]) {
        for &t in at.iter().filter(|&&t| at.contains(&(t + 1))) {
            for (a, b) in [(t, t + 1), (t + 1, t)] {
                for c in 0..meet.len() {
                    let (Some(&z), true) =
                        (self.cells.get(&(a, c)), (0..meet.len()).all(|d| self.cells.contains_key(&(b, d))))
                    else {
                        continue;
                    };
                    let mut next = Expression::from(0.0);
                    for d in (0..meet.len()).filter(|&d| meet[c][d]) {
                        next += self.cells[&(b, d)];
                    }
                    self.constraints.push(Expression::from(z).leq(next));
                }
            }
        }
    }

    /// `max` of operands with binaries of their own and operands gated by claims:
    /// `r ≤ eᵢ + Mᵢ (1 − bᵢ)` for either kind, `Σ bᵢ + Σ claims ≥ 1` ([`Program::max`]
    /// when none is claimed). A claim may be set by another `max`, so `r`'s least value
    /// is the least of the operands' (it must stay feasible under any operand), not the
    /// greatest.
    fn max_of(&mut self, options: Vec<Opt>) -> Rob {
        if options.iter().all(|o| matches!(o, Opt::Own(_))) {
            let own = options.into_iter().map(|o| match o {
                Opt::Own(r) | Opt::Claimed(r, _) => r,
            });
            return self.max(own.collect());
        }
        let bounds = options.iter().map(|(Opt::Own(r) | Opt::Claimed(r, _))| r.bounds());
        let (lo, hi) = bounds.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), (a, b)| (l.min(a), h.max(b)));
        let r = self.value(lo, hi);
        let mut chosen = Expression::from(0.0);
        for option in options {
            let (e, b) = match option {
                Opt::Own(e) => (e, self.binary()),
                Opt::Claimed(e, a) => (e, a),
            };
            chosen += b;
            let operand = match e {
                Rob::Const(c) => (Expression::from(c), c),
                Rob::Lin { e, lo, .. } => (e, lo),
            };
            self.at_most_if(r, operand, hi, b);
        }
        self.constraints.push(chosen.geq(1.0));
        Rob::Lin { e: r.into(), lo, hi }
    }

    /// The value of a shape.
    fn shape(&mut self, s: &Shape) -> Rob {
        match s {
            Shape::Const(c) => Rob::Const(*c),
            Shape::Affine { terms, constant } => self.affine(terms, *constant),
            Shape::Min(v) => {
                let items = v.iter().map(|s| self.shape(s)).collect();
                self.min(items)
            }
            Shape::Max(v) => {
                let items = v.iter().map(|s| self.shape(s)).collect();
                self.max(items)
            }
        }
    }
}

/// An occurrence of a sub-formula at a waypoint: its address in the encoded formula
/// (stable while the formula is borrowed) and the waypoint.
pub(super) type Occurrence = (usize, usize);

fn address(f: &Formula) -> usize {
    f as *const Formula as usize
}

/// Whether `f` is a clause that may be left out until violated: it keeps out of a
/// goal (negates) and reads only its waypoint and the next ones. (`safe` is always
/// encoded: through the walls' few free cells it is cheap, and left out it cost
/// rounds.)
fn lazy_kind(f: &Formula) -> bool {
    fn local(f: &Formula) -> bool {
        match f {
            Formula::Eventually(..) | Formula::Globally(..) | Formula::Until(..) => false,
            _ => f.children().all(local),
        }
    }
    fn keeps_out(f: &Formula) -> bool {
        match f {
            Formula::Not(_) | Formula::Implies(..) => true,
            Formula::Atom(_) | Formula::Compare { .. } => false,
            _ => f.children().any(keeps_out),
        }
    }
    local(f) && keeps_out(f)
}

/// Encodes sub-formulas at waypoints, each (sub-formula, waypoint, sign) once.
pub(super) struct Encoder<'a> {
    program: &'a mut Program,
    atoms: &'a Atoms,
    /// Lazy occurrences to encode (the others are left out).
    active: &'a HashSet<Occurrence>,
    /// Lazy occurrences left out, with their formula.
    omitted: Vec<(&'a Formula, usize)>,
    /// States in the path (`T + 1`).
    n: usize,
    until: UntilRule,
    /// The robustness of `true`.
    top: f64,
    memo: HashMap<(usize, usize, bool), Rob>,
    /// The goal discs `(name, centre, radius)` when the spec keeps out of one (claims
    /// are used); empty otherwise.
    discs: Vec<(String, [f64; 2], f64)>,
    /// Each disc's inscribed polygon at each waypoint, by `(t, disc)`.
    polygons: HashMap<(usize, usize), Rob>,
    /// Whether keeping out of a disc that has claims also gets its tangents.
    tangents: bool,
    /// Whether some keep-out went without its tangents.
    without_tangents: bool,
}

impl<'a> Encoder<'a> {
    /// An encoder writing `root`'s sub-formulas into `program` (claims if `root` keeps
    /// out of a goal disc; then, without `tangents`, keeping out of a disc is by the
    /// claims alone wherever another disc gives one: a lower bound of the full program).
    pub fn new(
        program: &'a mut Program,
        atoms: &'a Atoms,
        active: &'a HashSet<Occurrence>,
        (until, top): (UntilRule, f64),
        root: &Formula,
        tangents: bool,
    ) -> Self {
        let n = program.x.len() + 1;
        let mut discs = atoms.goal_discs();
        if !keeps_out_of_a_goal(root, true, &discs) {
            discs.clear();
        }
        let (memo, polygons) = (HashMap::new(), HashMap::new());
        let omitted = vec![];
        let without_tangents = false;
        Self {
            program,
            atoms,
            active,
            omitted,
            n,
            until,
            top,
            memo,
            discs,
            polygons,
            tangents,
            without_tangents,
        }
    }

    /// Whether some keep-out was encoded by its claims alone (see [`Encoder::new`]).
    pub fn without_tangents(&self) -> bool {
        self.without_tangents
    }

    /// The lazy occurrences left out of the program.
    pub fn omitted(&self) -> &[(&'a Formula, usize)] {
        &self.omitted
    }

    /// The waypoints `t ≥ 1` at which `name` is a conjunct of `f` at `t`: reached from
    /// the root through `∧`, `□` and `○` alone, so a plan with `ρ̃(f) > 0` has `name`
    /// positive at each of them.
    pub fn required(&self, f: &Formula, t: usize, name: &str, out: &mut Vec<usize>) {
        match f {
            Formula::Atom(a) if a == name && t >= 1 && !out.contains(&t) => out.push(t),
            Formula::And(v) => v.iter().for_each(|c| self.required(c, t, name, out)),
            Formula::Globally(iv, c) => self.window(t, iv).for_each(|k| self.required(c, k, name, out)),
            Formula::Next(c) => self.required(c, (t + 1).min(self.n - 1), name, out),
            _ => {}
        }
    }

    /// The window `[t + a, t + b]` cut at the last waypoint (the library's rule).
    fn window(&self, t: usize, iv: &Interval) -> std::ops::RangeInclusive<usize> {
        let last = self.n - 1;
        let lo = t.saturating_add(iv.start).min(last);
        let hi = iv.end.map_or(last, |b| t.saturating_add(b).min(last));
        lo..=hi
    }

    /// The robustness of `f` (of `¬f` when `positive` is false) at waypoint `t`.
    pub fn encode(&mut self, f: &'a Formula, t: usize, positive: bool) -> Result<Rob, MipError> {
        let key = (address(f), t, positive);
        if let Some(r) = self.memo.get(&key) {
            return Ok(r.clone());
        }
        let r = self.encode_new(f, t, positive)?;
        self.memo.insert(key, r.clone());
        Ok(r)
    }

    /// `min` when `conjunctive` holds in the positive reading (its dual negated).
    fn combine(&mut self, conjunctive: bool, positive: bool, items: Vec<Rob>) -> Rob {
        let min = conjunctive == positive;
        match (items.is_empty(), min) {
            (true, true) => Rob::Const(self.top),
            (true, false) => Rob::Const(-self.top),
            (false, true) => self.program.min(items),
            (false, false) => self.program.max(items),
        }
    }

    fn all(&mut self, fs: &[&'a Formula], at: &[usize], positive: bool) -> Result<Vec<Rob>, MipError> {
        let mut out = Vec::with_capacity(fs.len() * at.len());
        for f in fs {
            for &t in at {
                out.push(self.encode(f, t, positive)?);
            }
        }
        Ok(out)
    }

    /// The operands of a conjunction (`∧`, `□`) in positive position, lazy ones that
    /// are not active left out.
    fn conjuncts(&mut self, fs: &[&'a Formula], at: &[usize]) -> Result<Vec<Rob>, MipError> {
        let mut out = Vec::with_capacity(fs.len() * at.len());
        for &f in fs {
            for &t in at {
                // With claims a keep-out is cheap, and left out one waypoint at a time its
                // violations moved round after round (Loop: 2 of 5 starts within 30 s).
                if lazy_kind(f) && self.discs.is_empty() && !self.active.contains(&(address(f), t)) {
                    if !self.omitted.iter().any(|&(g, u)| address(g) == address(f) && u == t) {
                        self.omitted.push((f, t));
                    }
                } else {
                    out.push(self.encode(f, t, true)?);
                }
            }
        }
        Ok(out)
    }

    fn encode_new(&mut self, f: &'a Formula, t: usize, positive: bool) -> Result<Rob, MipError> {
        let sign = if positive { 1.0 } else { -1.0 };
        if self.is_max(f, positive) {
            // One disjunction over all the options of nested ones (fewer binaries, and
            // no big-M between the levels).
            let mut options = vec![];
            self.options(f, t, positive, &mut options)?;
            return Ok(self.max_of(options));
        }
        Ok(match f {
            Formula::True => Rob::Const(sign * self.top),
            Formula::False => Rob::Const(-sign * self.top),
            Formula::Atom(name) => self.atom(name, t, sign, 0.0)?,
            // `op.sign() · (ρ − threshold)`, negated when `positive` is false.
            Formula::Compare { signal, op, threshold } => {
                let s = sign * op.sign();
                self.atom(signal, t, s, -s * threshold)?
            }
            Formula::Not(c) => self.encode(c, t, !positive)?,
            Formula::And(v) if positive => {
                let items = self.conjuncts(&v.iter().collect::<Vec<_>>(), &[t])?;
                self.combine(true, positive, items)
            }
            Formula::And(v) => {
                let items = self.all(&v.iter().collect::<Vec<_>>(), &[t], positive)?;
                self.combine(true, positive, items)
            }
            Formula::Or(v) => {
                let items = self.all(&v.iter().collect::<Vec<_>>(), &[t], positive)?;
                self.combine(false, positive, items)
            }
            // l → r = ¬l ∨ r
            Formula::Implies(l, r) => {
                let items = vec![self.encode(l, t, !positive)?, self.encode(r, t, positive)?];
                self.combine(false, positive, items)
            }
            Formula::Next(c) => self.encode(c, (t + 1).min(self.n - 1), positive)?,
            Formula::Eventually(iv, c) => {
                let at: Vec<usize> = self.window(t, iv).collect();
                let items = self.all(&[c], &at, positive)?;
                self.combine(false, positive, items)
            }
            Formula::Globally(iv, c) => {
                let at: Vec<usize> = self.window(t, iv).collect();
                let items =
                    if positive { self.conjuncts(&[c], &at)? } else { self.all(&[c], &at, positive)? };
                self.combine(true, positive, items)
            }
            Formula::Until(iv, l, r) => {
                // max over k of min(ψ_k, φ_j for j in [from, k − 1])
                let window = self.window(t, iv);
                let from = *window.start();
                let mut options = vec![];
                for k in window {
                    let mut terms = vec![self.encode(r, k, positive)?];
                    terms.extend(self.all(&[l], &(from..k).collect::<Vec<_>>(), positive)?);
                    options.push(self.combine(true, positive, terms));
                }
                let until = self.combine(false, positive, options);
                if self.until == UntilRule::Standard && iv.start > 0 {
                    // The standard reading also needs φ on [t, t + a − 1].
                    let before = self.window(t, &Interval::bounded(0, iv.start - 1));
                    let mut terms = self.all(&[l], &before.collect::<Vec<_>>(), positive)?;
                    terms.push(until);
                    self.combine(true, positive, terms)
                } else {
                    until
                }
            }
        })
    }

    fn atom(&mut self, name: &str, t: usize, sign: f64, offset: f64) -> Result<Rob, MipError> {
        let (cells, _) = self.atoms.cells(name);
        if sign > 0.0 && t >= 1 && cells > 0 {
            // Clear of the walls: in one of their free cells, each a labelled binary.
            let mut options = vec![];
            for c in 0..cells {
                let shape = self.atoms.in_cell(name, t, c, offset).expect("the walls have cells");
                let value = self.program.shape(&shape);
                options.push(Opt::Claimed(value, self.program.in_cell(t, c)));
            }
            let in_some_cell = self.max_of(options);
            return Ok(self.program.min(vec![Rob::Const(OPEN_CLEARANCE + offset), in_some_cell]));
        }
        if sign < 0.0 && t >= 1 && self.disc(name).is_some() {
            // Keeping out of a goal disc: its tangents and the claims of the other discs.
            let mut options = vec![];
            self.atom_options(name, t, sign, offset, &mut options)?;
            return Ok(self.max_of(options));
        }
        let shape = self.atoms.shape(name, t, sign, offset)?;
        Ok(self.program.shape(&shape))
    }

    /// The `max` of options, own and claimed (`⊥` when there are none).
    fn max_of(&mut self, options: Vec<Opt>) -> Rob {
        if options.is_empty() {
            return Rob::Const(-self.top);
        }
        self.program.max_of(options)
    }

    /// The index of `name` among the goal discs claims are kept for.
    fn disc(&self, name: &str) -> Option<usize> {
        self.discs.iter().position(|d| d.0 == name)
    }

    /// Whether `f` (negated unless `positive`) is a `max` of its operands.
    fn is_max(&self, f: &Formula, positive: bool) -> bool {
        matches!(
            (f, positive),
            (Formula::Or(_) | Formula::Implies(..) | Formula::Eventually(..), true)
                | (Formula::And(_) | Formula::Globally(..), false)
        )
    }

    /// The operands of the `max` that `f` is, with nested `max`es (of sub-formulas and
    /// of predicates' pieces) spread out into their own operands.
    fn options(
        &mut self,
        f: &'a Formula,
        t: usize,
        positive: bool,
        out: &mut Vec<Opt>,
    ) -> Result<(), MipError> {
        let sign = if positive { 1.0 } else { -1.0 };
        match f {
            Formula::Not(c) => self.options(c, t, !positive, out)?,
            Formula::Next(c) => self.options(c, (t + 1).min(self.n - 1), positive, out)?,
            Formula::Or(v) | Formula::And(v) if self.is_max(f, positive) => {
                for c in v {
                    self.options(c, t, positive, out)?;
                }
            }
            Formula::Implies(l, r) if positive => {
                self.options(l, t, false, out)?;
                self.options(r, t, true, out)?;
            }
            Formula::Eventually(iv, c) | Formula::Globally(iv, c) if self.is_max(f, positive) => {
                for k in self.window(t, iv) {
                    self.options(c, k, positive, out)?;
                }
            }
            Formula::Atom(name) => self.atom_options(name, t, sign, 0.0, out)?,
            Formula::Compare { signal, op, threshold } => {
                let s = sign * op.sign();
                self.atom_options(signal, t, s, -s * threshold, out)?
            }
            _ => out.push(Opt::Own(self.encode(f, t, positive)?)),
        }
        Ok(())
    }

    fn atom_options(
        &mut self,
        name: &str,
        t: usize,
        sign: f64,
        offset: f64,
        out: &mut Vec<Opt>,
    ) -> Result<(), MipError> {
        if let Some(k) = self.disc(name).filter(|_| t >= 1) {
            if sign > 0.0 {
                // Reaching disc k: gated by the claim that waypoint t is in it.
                let a = self.program.claim(t, k);
                out.push(Opt::Claimed(self.polygon(t, k)?.plus(offset), a));
                return Ok(());
            }
            // Keeping out of disc k: being in another disc j is at least gap_jk out.
            let (ck, rk) = (self.discs[k].1, self.discs[k].2);
            let mut claimed = false;
            for j in 0..self.discs.len() {
                let (cj, rj) = (self.discs[j].1, self.discs[j].2);
                let gap = (cj[0] - ck[0]).hypot(cj[1] - ck[1]) - rj - rk;
                if j != k && gap > 0.0 {
                    let a = self.program.claim(t, j);
                    out.push(Opt::Claimed(self.polygon(t, j)?.plus(gap + offset), a));
                    claimed = true;
                }
            }
            if claimed && !self.tangents {
                self.without_tangents = true;
                return Ok(());
            }
        }
        match self.atoms.shape(name, t, sign, offset)? {
            Shape::Max(pieces) => out.extend(pieces.iter().map(|p| Opt::Own(self.program.shape(p)))),
            shape => out.push(Opt::Own(self.program.shape(&shape))),
        }
        Ok(())
    }

    /// Disc `disc`'s inscribed polygon at waypoint `t ≥ 1` (encoded once).
    fn polygon(&mut self, t: usize, disc: usize) -> Result<Rob, MipError> {
        if let Some(r) = self.polygons.get(&(t, disc)) {
            return Ok(r.clone());
        }
        let shape = self.atoms.shape(&self.discs[disc].0, t, 1.0, 0.0)?;
        let r = self.program.shape(&shape);
        self.polygons.insert((t, disc), r.clone());
        Ok(r)
    }
}

/// Whether `f` (negated unless `positive`) keeps out of one of the goal discs somewhere.
fn keeps_out_of_a_goal(f: &Formula, positive: bool, discs: &[(String, [f64; 2], f64)]) -> bool {
    let goal = |name: &str| discs.iter().any(|d| d.0 == name);
    match f {
        Formula::Atom(name) => !positive && goal(name),
        Formula::Compare { signal, op, .. } => (positive == (op.sign() < 0.0)) && goal(signal),
        Formula::Not(c) => keeps_out_of_a_goal(c, !positive, discs),
        Formula::Implies(l, r) => {
            keeps_out_of_a_goal(l, !positive, discs) || keeps_out_of_a_goal(r, positive, discs)
        }
        _ => f.children().any(|c| keeps_out_of_a_goal(c, positive, discs)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::task::{Task, TaskKind};

    /// The waypoints at which `spec` requires the walls, on Point Cover's 8 waypoints.
    fn required(spec: &str) -> Vec<usize> {
        let task = Task::point(TaskKind::Cover);
        let atoms = Atoms::of_task(&task, &[1.5, -1.5], 16, 8).expect("Cover encodes");
        let mut program = Program::new([1.5, -1.5], task.steps, ([-3.5, -3.5], [3.5, 3.5]));
        let formula = stl::parse(spec).expect("a valid spec");
        let active = HashSet::new();
        let encoder = Encoder::new(&mut program, &atoms, &active, (UntilRule::Standard, 1e9), &formula, true);
        let mut out = vec![];
        encoder.required(&formula, 0, "safe", &mut out);
        out.sort();
        out
    }

    #[test]
    fn the_walls_are_required_only_where_every_satisfying_plan_keeps_them() {
        assert_eq!(required("F[1,8] g0 & G[1,8] safe"), (1..=8).collect::<Vec<_>>());
        assert_eq!(required("G[2,3] (safe & F[0,8] g1)"), vec![2, 3]);
        assert_eq!(required("X safe & G[7,20] safe"), vec![1, 7, 8], "windows cut at the last waypoint");
        // Under a disjunction, an eventually or a negation a plan may do without them.
        assert!(required("G[1,8] (safe | g0)").is_empty());
        assert!(required("F[1,8] safe").is_empty());
        assert!(required("!(F[1,8] !safe)").is_empty());
    }
}
