//! A formula compiled to a flat program over predicate columns.
//!
//! Predicates and logic are separate (see the crate docs): the predicates of a path
//! of `T` steps give a `T × P` matrix of values, and a [`Program`] maps that matrix
//! to the robustness signal `ρ(t)` for every start time `t`, and back to `∂ρ/∂values`.
//! Every node is evaluated for all `T` steps in O(T) (windows included), so one
//! evaluation costs O(T · nodes) whatever the interval lengths (a smooth `until`
//! relaxed as written, [`UntilSmoothing::Flat`](crate::UntilSmoothing::Flat), is the
//! exception: O(T · w) for a window of `w` steps).
//!
//! # Finite paths
//! Time indices past the end of the path are clamped to the last step, i.e. the path
//! is read as holding its last state forever. Windows that run past the end are
//! therefore cut at the last step, a window that starts past the end is the last
//! step alone, and `○φ` at the last step is `φ` at the last step. In hard mode this
//! is exactly the semantics of the path extended by repeating its last state; smooth
//! modes aggregate over the cut window (each step counted once).

use std::collections::HashMap;

use crate::aggregate::{self, Agg, Dir, Scratch};
use crate::formula::{CmpOp, Formula, Interval};
use crate::semantics::Semantics;

/// A leaf of a compiled formula: what one predicate column holds.
#[derive(Clone, Debug, PartialEq)]
pub enum Atom {
    /// A bare name: a bound predicate, or a signal's value.
    Name(String),
    /// `name op threshold`.
    Compare {
        /// Predicate or signal name.
        name: String,
        /// Operator.
        op: CmpOp,
        /// The number.
        threshold: f64,
    },
}

impl Atom {
    /// The predicate or signal name this atom reads.
    pub fn name(&self) -> &str {
        match self {
            Atom::Name(n) | Atom::Compare { name: n, .. } => n,
        }
    }
}

/// Where `φ U[a,b] ψ` requires φ before the step `k ∈ [t+a, t+b]` at which ψ holds.
/// The two readings differ only when `a > 0`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum UntilRule {
    /// On `[t, k−1]`: standard discrete-time STL (Maler and Nickovic; rtamt), the
    /// library's default. Compiled as `G[0,a−1] φ ∧ (φ U[a,b] ψ)` under the paper's
    /// reading (exact in hard semantics: the prefix does not depend on `k`), the `∧`
    /// smoothed as the temporal operators are.
    #[default]
    Standard,
    /// On `[t+a, k−1]`: the paper's App. C, which the shipped tasks are written for
    /// (Signal: `… U[1,T] counter` does not ask the start to be at a corner).
    Paper,
}

impl UntilRule {
    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            UntilRule::Standard => "standard",
            UntilRule::Paper => "paper",
        }
    }
}

impl std::str::FromStr for UntilRule {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "standard" => Ok(UntilRule::Standard),
            "paper" => Ok(UntilRule::Paper),
            other => Err(format!("'{other}' is not an until rule: expected standard or paper")),
        }
    }
}

#[derive(Clone, Debug)]
enum Op {
    Const(bool),
    Column(usize),
    Not(usize),
    And(Vec<usize>),
    Or(Vec<usize>),
    /// A conjunction smoothed as the temporal operators are (the standard until's
    /// prefix with the paper's until).
    TemporalAnd(Vec<usize>),
    Next(usize),
    Eventually(Interval, usize),
    Globally(Interval, usize),
    Until(Interval, usize, usize),
}

/// A compiled formula: nodes in topological order (children first), leaves reading
/// predicate columns.
#[derive(Clone, Debug)]
pub struct Program {
    ops: Vec<Op>,
    atoms: Vec<Atom>,
    until: UntilRule,
}

impl Program {
    /// Compiles `formula` with the standard until ([`UntilRule::Standard`]).
    pub fn compile(formula: &Formula) -> Self {
        Self::compile_with(formula, UntilRule::Standard)
    }

    /// Compiles `formula`, reading `U` by `until`. Identical atoms share one column,
    /// identical sub-formulas one node (the Loop task names each goal three times);
    /// `φ ⇒ ψ` becomes `¬φ ∨ ψ`.
    pub fn compile_with(formula: &Formula, until: UntilRule) -> Self {
        let mut p = Program { ops: Vec::new(), atoms: Vec::new(), until };
        let mut index: HashMap<String, usize> = HashMap::new();
        let mut shared: HashMap<String, usize> = HashMap::new();
        p.emit(formula, &mut index, &mut shared);
        p
    }

    fn column(&mut self, atom: Atom, index: &mut HashMap<String, usize>) -> usize {
        let key = match &atom {
            Atom::Name(n) => n.clone(),
            Atom::Compare { name, op, threshold } => {
                format!("{name} {} {}", op.symbol(), threshold.to_bits())
            }
        };
        *index.entry(key).or_insert_with(|| {
            self.atoms.push(atom);
            self.atoms.len() - 1
        })
    }

    fn emit(
        &mut self,
        f: &Formula,
        index: &mut HashMap<String, usize>,
        shared: &mut HashMap<String, usize>,
    ) -> usize {
        // `Debug` names every variant and quotes every name, so equal keys mean
        // structurally equal sub-formulas.
        let key = format!("{f:?}");
        if let Some(&node) = shared.get(&key) {
            return node;
        }
        let node = self.emit_new(f, index, shared);
        shared.insert(key, node);
        node
    }

    fn emit_new(
        &mut self,
        f: &Formula,
        index: &mut HashMap<String, usize>,
        shared: &mut HashMap<String, usize>,
    ) -> usize {
        let op = match f {
            Formula::True => Op::Const(true),
            Formula::False => Op::Const(false),
            Formula::Atom(n) => Op::Column(self.column(Atom::Name(n.clone()), index)),
            Formula::Compare { signal, op, threshold } => {
                let atom = Atom::Compare { name: signal.clone(), op: *op, threshold: *threshold };
                Op::Column(self.column(atom, index))
            }
            Formula::Not(c) => Op::Not(self.emit(c, index, shared)),
            Formula::And(v) if v.is_empty() => Op::Const(true),
            Formula::Or(v) if v.is_empty() => Op::Const(false),
            Formula::And(v) | Formula::Or(v) if v.len() == 1 => {
                return self.emit(&v[0], index, shared);
            }
            Formula::And(v) => Op::And(v.iter().map(|c| self.emit(c, index, shared)).collect()),
            Formula::Or(v) => Op::Or(v.iter().map(|c| self.emit(c, index, shared)).collect()),
            Formula::Implies(l, r) => {
                let l = self.emit(l, index, shared);
                self.ops.push(Op::Not(l));
                let nl = self.ops.len() - 1;
                Op::Or(vec![nl, self.emit(r, index, shared)])
            }
            Formula::Next(c) => Op::Next(self.emit(c, index, shared)),
            Formula::Eventually(iv, c) => Op::Eventually(*iv, self.emit(c, index, shared)),
            Formula::Globally(iv, c) => Op::Globally(*iv, self.emit(c, index, shared)),
            Formula::Until(iv, l, r) => {
                let l = self.emit(l, index, shared);
                let until = Op::Until(*iv, l, self.emit(r, index, shared));
                if self.until == UntilRule::Paper || iv.start == 0 {
                    until
                } else {
                    self.ops.push(until);
                    let u = self.ops.len() - 1;
                    self.ops.push(Op::Globally(Interval::bounded(0, iv.start - 1), l));
                    Op::TemporalAnd(vec![self.ops.len() - 1, u])
                }
            }
        };
        self.ops.push(op);
        self.ops.len() - 1
    }

    /// The predicate columns, in column order.
    pub fn atoms(&self) -> &[Atom] {
        &self.atoms
    }

    /// How `U` was read.
    pub fn until_rule(&self) -> UntilRule {
        self.until
    }

    /// Number of compiled nodes.
    pub fn len(&self) -> usize {
        self.ops.len()
    }

    /// `true` if the program has no nodes (never, for a compiled formula).
    pub fn is_empty(&self) -> bool {
        self.ops.is_empty()
    }

    fn root(&self) -> usize {
        self.ops.len() - 1
    }

    /// Evaluates the robustness signal from `values` (`steps × atoms().len()`,
    /// row-major) into `ws`; read it with [`Workspace::signal`].
    ///
    /// # Panics
    /// If `values.len() != steps * atoms().len()` or `steps == 0`; [`crate::Spec`]
    /// checks these and returns errors instead.
    pub fn forward(&self, values: &[f64], steps: usize, sem: &Semantics, ws: &mut Workspace) {
        let n = steps;
        let p = self.atoms.len();
        assert!(n > 0 && values.len() == n * p, "values must be steps × columns");
        ws.n = n;
        ws.vals.clear();
        ws.vals.resize(self.ops.len() * n, 0.0);
        ws.logw.clear();
        ws.logw.resize(self.ops.len() * n, 0.0);
        let logic = sem.logic();
        let temporal = sem.temporal();
        for (i, op) in self.ops.iter().enumerate() {
            let (done, rest) = ws.vals.split_at_mut(i * n);
            let out = &mut rest[..n];
            let logw = &mut ws.logw[i * n..(i + 1) * n];
            let sig = |j: usize| &done[j * n..(j + 1) * n];
            match op {
                Op::Const(b) => out.fill(if *b { sem.top } else { -sem.top }),
                Op::Column(c) => {
                    for (t, o) in out.iter_mut().enumerate() {
                        *o = values[t * p + c];
                    }
                }
                Op::Not(c) => {
                    for (o, x) in out.iter_mut().zip(sig(*c)) {
                        *o = -x;
                    }
                }
                Op::And(cs) | Op::Or(cs) | Op::TemporalAnd(cs) => {
                    let agg = nary_agg(op, logic, temporal);
                    nary_forward(agg, cs, done, n, out, logw, &mut ws.operands);
                }
                Op::Next(c) => {
                    let x = sig(*c);
                    for (t, o) in out.iter_mut().enumerate() {
                        *o = x[(t + 1).min(n - 1)];
                    }
                }
                Op::Eventually(iv, c) | Op::Globally(iv, c) => {
                    let dir = if matches!(op, Op::Eventually(..)) { Dir::Max } else { Dir::Min };
                    let agg = Agg::new(temporal, dir);
                    aggregate::window_forward(agg, sig(*c), (iv.start, iv.end), out, logw, &mut ws.scratch);
                }
                Op::Until(iv, l, r) => {
                    aggregate::until_forward(
                        temporal,
                        sem.until,
                        sig(*l),
                        sig(*r),
                        iv.start,
                        iv.end,
                        out,
                        &mut ws.scratch,
                    );
                }
            }
        }
    }

    /// After [`Program::forward`], computes `∂ρ(t)/∂values` for the start time `t`
    /// into `grad` (resized to `steps × columns`, overwritten).
    pub fn backward(&self, t: usize, sem: &Semantics, ws: &mut Workspace, grad: &mut Vec<f64>) {
        let n = ws.n;
        let p = self.atoms.len();
        grad.clear();
        grad.resize(n * p, 0.0);
        ws.adj.clear();
        ws.adj.resize(self.ops.len() * n, 0.0);
        ws.adj[self.root() * n + t.min(n - 1)] = 1.0;
        let logic = sem.logic();
        let temporal = sem.temporal();
        for i in (0..self.ops.len()).rev() {
            let (adj_done, adj_rest) = ws.adj.split_at_mut(i * n);
            let g = &adj_rest[..n];
            if g.iter().all(|&x| x == 0.0) {
                continue;
            }
            let vals = &ws.vals;
            let sig = |j: usize| &vals[j * n..(j + 1) * n];
            match &self.ops[i] {
                Op::Const(_) => {}
                Op::Column(c) => {
                    for (tt, gi) in g.iter().enumerate() {
                        grad[tt * p + c] += gi;
                    }
                }
                Op::Not(c) => {
                    for (a, gi) in adj_done[c * n..(c + 1) * n].iter_mut().zip(g) {
                        *a -= gi;
                    }
                }
                op @ (Op::And(cs) | Op::Or(cs) | Op::TemporalAnd(cs)) => {
                    let agg = nary_agg(op, logic, temporal);
                    let out = sig(i);
                    let mut gv = std::mem::take(&mut ws.operand_grads);
                    for tt in 0..n {
                        if g[tt] == 0.0 {
                            continue;
                        }
                        ws.operands.clear();
                        ws.operands.extend(cs.iter().map(|&c| vals[c * n + tt]));
                        gv.clear();
                        gv.resize(cs.len(), 0.0);
                        let lw = ws.logw[i * n + tt];
                        aggregate::reduce_backward(agg, &ws.operands, out[tt], lw, g[tt], &mut gv);
                        for (&c, gc) in cs.iter().zip(&gv) {
                            adj_done[c * n + tt] += gc;
                        }
                    }
                    ws.operand_grads = gv;
                }
                Op::Next(c) => {
                    for (tt, gi) in g.iter().enumerate() {
                        adj_done[c * n + (tt + 1).min(n - 1)] += gi;
                    }
                }
                op @ (Op::Eventually(iv, c) | Op::Globally(iv, c)) => {
                    let dir = if matches!(op, Op::Eventually(..)) { Dir::Max } else { Dir::Min };
                    let gc = &mut adj_done[c * n..(c + 1) * n];
                    let (agg, lw) = (Agg::new(temporal, dir), &ws.logw[i * n..(i + 1) * n]);
                    let range = (iv.start, iv.end);
                    aggregate::window_backward(agg, sig(*c), range, sig(i), lw, g, gc, &mut ws.scratch);
                }
                Op::Until(iv, l, r) if l == r => {
                    // `φ U φ`: both operands are one shared node; accumulate separately.
                    let mut gl = vec![0.0; n];
                    let mut gr = vec![0.0; n];
                    let x = sig(*l);
                    aggregate::until_backward(
                        temporal,
                        sem.until,
                        x,
                        x,
                        iv.start,
                        iv.end,
                        sig(i),
                        g,
                        &mut gl,
                        &mut gr,
                        &mut ws.scratch,
                    );
                    for ((a, x), y) in adj_done[l * n..(l + 1) * n].iter_mut().zip(gl).zip(gr) {
                        *a += x + y;
                    }
                }
                Op::Until(iv, l, r) => {
                    // Children come before the parent, so both slices are in adj_done.
                    let (gl, gr) = two_mut(adj_done, *l, *r, n);
                    aggregate::until_backward(
                        temporal,
                        sem.until,
                        sig(*l),
                        sig(*r),
                        iv.start,
                        iv.end,
                        sig(i),
                        g,
                        gl,
                        gr,
                        &mut ws.scratch,
                    );
                }
            }
        }
    }
}

/// The aggregation of an n-ary node: and/or smoothed as the logic is, the until's
/// conjunction as the temporal operators are.
fn nary_agg(op: &Op, logic: crate::semantics::Smoothing, temporal: crate::semantics::Smoothing) -> Agg {
    match op {
        Op::And(_) => Agg::new(logic, Dir::Min),
        Op::TemporalAnd(_) => Agg::new(temporal, Dir::Min),
        _ => Agg::new(logic, Dir::Max),
    }
}

/// Two distinct node slices of one buffer, mutably.
fn two_mut(buf: &mut [f64], l: usize, r: usize, n: usize) -> (&mut [f64], &mut [f64]) {
    if l < r {
        let (a, b) = buf.split_at_mut(r * n);
        (&mut a[l * n..(l + 1) * n], &mut b[..n])
    } else {
        let (a, b) = buf.split_at_mut(l * n);
        (&mut b[..n], &mut a[r * n..(r + 1) * n])
    }
}

fn nary_forward(
    agg: Agg,
    cs: &[usize],
    done: &[f64],
    n: usize,
    out: &mut [f64],
    logw: &mut [f64],
    tmp: &mut Vec<f64>,
) {
    if let Agg::Hard(dir) = agg {
        // Elementwise min/max over whole signals: no per-step gathering needed.
        out.copy_from_slice(&done[cs[0] * n..(cs[0] + 1) * n]);
        for &c in &cs[1..] {
            let x = &done[c * n..(c + 1) * n];
            for (o, &v) in out.iter_mut().zip(x) {
                let better = match dir {
                    Dir::Max => v > *o,
                    Dir::Min => v < *o,
                };
                if better {
                    *o = v;
                }
            }
        }
        return;
    }
    for (t, o) in out.iter_mut().enumerate() {
        tmp.clear();
        tmp.extend(cs.iter().map(|&c| done[c * n + t]));
        (*o, logw[t]) = aggregate::reduce_logw(agg, tmp);
    }
}

/// Buffers for evaluating a [`Program`]; reuse one per thread to avoid allocation.
#[derive(Default, Debug, Clone)]
pub struct Workspace {
    n: usize,
    vals: Vec<f64>,
    // ln Σ e^{βv} of each smooth and/or/window node and step, for the backward pass.
    logw: Vec<f64>,
    adj: Vec<f64>,
    operands: Vec<f64>,
    operand_grads: Vec<f64>,
    scratch: Scratch,
}

impl Workspace {
    /// A fresh workspace.
    pub fn new() -> Self {
        Self::default()
    }

    /// The robustness signal `ρ(t)` for every start time, after a forward pass.
    pub fn signal(&self) -> &[f64] {
        let n = self.n;
        &self.vals[self.vals.len() - n..]
    }
}
