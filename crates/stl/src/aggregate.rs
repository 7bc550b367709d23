//! Min/max aggregation in every mode, over operand lists and over sliding time
//! windows, with exact backward passes.
//!
//! Windows are evaluated in O(T) whatever their length: hard mode with a monotone
//! deque, smooth modes with the van Herk / Gil–Werman block decomposition over an
//! associative, numerically stable accumulator. Backward passes of smooth windows
//! are O(T) too: the gradient reaching `v_i` is a sum over the windows containing
//! `i`, and those windows form another sliding range, aggregated the same way.

// Index loops mirror the formulas they implement.
#![allow(clippy::needless_range_loop)]

use crate::semantics::{Smoothing, UntilSmoothing};

/// Direction of an aggregation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Dir {
    Max,
    Min,
}

/// A smoothing resolved for one direction: `beta` is `+α` (or `+1/τ`) for max and
/// `−α` for min, so every formula below is written once, for "max of β·v".
#[derive(Clone, Copy, Debug)]
pub(crate) enum Agg {
    Hard(Dir),
    Soft { beta: f64 },
    Lse { beta: f64 },
}

impl Agg {
    pub(crate) fn new(smoothing: Smoothing, dir: Dir) -> Self {
        let sign = if dir == Dir::Max { 1.0 } else { -1.0 };
        match smoothing {
            Smoothing::Hard => Agg::Hard(dir),
            Smoothing::Soft { alpha } => Agg::Soft { beta: sign * alpha },
            Smoothing::LogSumExp { temperature } => Agg::Lse { beta: sign / temperature },
        }
    }

    /// `true` when `a` is strictly preferred to `b` in hard mode.
    #[inline]
    fn better(dir: Dir, a: f64, b: f64) -> bool {
        match dir {
            Dir::Max => a > b,
            Dir::Min => a < b,
        }
    }
}

/// Stable accumulator of `Σ e^{β v}` and `Σ e^{β v}·v`, stored relative to a shift
/// `m` (the largest `β v` seen) so that nothing overflows.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Acc {
    m: f64,
    s: f64,
    sv: f64,
}

impl Acc {
    const EMPTY: Acc = Acc { m: f64::NEG_INFINITY, s: 0.0, sv: 0.0 };

    #[inline]
    fn lift(beta: f64, v: f64) -> Acc {
        Acc { m: beta * v, s: 1.0, sv: v }
    }

    #[inline]
    fn combine(a: Acc, b: Acc) -> Acc {
        if a.s == 0.0 {
            return b;
        }
        if b.s == 0.0 {
            return a;
        }
        if a.m >= b.m {
            let k = (b.m - a.m).exp();
            Acc { m: a.m, s: a.s + k * b.s, sv: a.sv + k * b.sv }
        } else {
            let k = (a.m - b.m).exp();
            Acc { m: b.m, s: k * a.s + b.s, sv: k * a.sv + b.sv }
        }
    }

    /// `ln Σ e^{β v}`.
    #[inline]
    fn log_weight(&self) -> f64 {
        self.m + self.s.ln()
    }

    #[inline]
    fn value(&self, agg: Agg) -> f64 {
        match agg {
            Agg::Soft { .. } => self.sv / self.s,
            Agg::Lse { beta } => self.log_weight() / beta,
            Agg::Hard(_) => unreachable!("hard aggregation does not use Acc"),
        }
    }
}

/// Stable accumulator for backward passes: `Σ g_t e^{−L_t}` and `Σ g_t out_t e^{−L_t}`
/// relative to a shift `m` (the largest `−L_t`), where `L_t` is a window's log weight.
#[derive(Clone, Copy, Debug)]
pub(crate) struct BAcc {
    m: f64,
    a: f64,
    b: f64,
}

impl BAcc {
    const EMPTY: BAcc = BAcc { m: f64::NEG_INFINITY, a: 0.0, b: 0.0 };

    #[inline]
    fn lift(log_weight: f64, g: f64, out: f64) -> BAcc {
        BAcc { m: -log_weight, a: g, b: g * out }
    }

    #[inline]
    fn combine(x: BAcc, y: BAcc) -> BAcc {
        if x.m == f64::NEG_INFINITY {
            return y;
        }
        if y.m == f64::NEG_INFINITY {
            return x;
        }
        if x.m >= y.m {
            let k = (y.m - x.m).exp();
            BAcc { m: x.m, a: x.a + k * y.a, b: x.b + k * y.b }
        } else {
            let k = (x.m - y.m).exp();
            BAcc { m: y.m, a: k * x.a + y.a, b: k * x.b + y.b }
        }
    }

    /// The gradient these windows send to an element of value `v`.
    ///
    /// Soft: `Σ_t g_t w_t(v) (1 + β(v − out_t))` with `w_t(v) = e^{βv − L_t}`;
    /// log-sum-exp: `Σ_t g_t e^{βv − L_t}`. `βv + m ≤ 0` always, so no overflow.
    #[inline]
    fn grad(&self, agg: Agg, v: f64) -> f64 {
        if self.m == f64::NEG_INFINITY {
            return 0.0;
        }
        match agg {
            Agg::Soft { beta } => (beta * v + self.m).exp() * (self.a + beta * (v * self.a - self.b)),
            Agg::Lse { beta } => (beta * v + self.m).exp() * self.a,
            Agg::Hard(_) => unreachable!("hard aggregation does not use BAcc"),
        }
    }
}

/// Reusable buffers, so that evaluation allocates nothing once warm.
#[derive(Default, Debug, Clone)]
pub struct Scratch {
    deque: Vec<usize>,
    acc: Vec<Acc>,
    pre: Vec<Acc>,
    suf: Vec<Acc>,
    bpre: Vec<BAcc>,
    bsuf: Vec<BAcc>,
    terms: Vec<f64>,
    tacc: Vec<Acc>,
    gterm: Vec<f64>,
    vwin: Vec<f64>,
}

/// Prefix/suffix tables of the van Herk / Gil–Werman decomposition: blocks of
/// length `w`; any range `[lo, hi]` of length ≤ `w` that is either clipped to the
/// ends of the sequence or exactly `w` long is `suffix[lo] ⊕ prefix[hi]`.
fn build_blocks<M: Copy>(
    items: impl Fn(usize) -> M,
    n: usize,
    w: usize,
    empty: M,
    combine: impl Fn(M, M) -> M,
    pre: &mut Vec<M>,
    suf: &mut Vec<M>,
) {
    pre.clear();
    pre.resize(n, empty);
    suf.clear();
    suf.resize(n, empty);
    let mut start = 0;
    while start < n {
        let end = (start + w).min(n);
        let mut acc = empty;
        for i in start..end {
            acc = combine(acc, items(i));
            pre[i] = acc;
        }
        let mut acc = empty;
        for i in (start..end).rev() {
            acc = combine(items(i), acc);
            suf[i] = acc;
        }
        start = end;
    }
}

#[inline]
fn query_blocks<M: Copy>(
    pre: &[M],
    suf: &[M],
    w: usize,
    lo: usize,
    hi: usize,
    combine: impl Fn(M, M) -> M,
) -> M {
    if lo / w == hi / w {
        if lo.is_multiple_of(w) { pre[hi] } else { suf[lo] }
    } else {
        combine(suf[lo], pre[hi])
    }
}

/// The window of a temporal operator with interval `[a, b]` (`b = None`: to the end)
/// evaluated at time `t` on a path of `n` steps. Indices past the end are clamped to
/// the last step: the path is read as holding its last state forever.
#[inline]
pub(crate) fn window(t: usize, a: usize, b: Option<usize>, n: usize) -> (usize, usize) {
    let last = n - 1;
    let lo = t.saturating_add(a).min(last);
    let hi = match b {
        Some(b) => t.saturating_add(b).min(last),
        None => last,
    };
    (lo, hi)
}

fn window_len(a: usize, b: Option<usize>, n: usize) -> usize {
    match b {
        Some(b) => (b - a + 1).min(n),
        None => n,
    }
}

// ---------------------------------------------------------------------------
// Operand lists (n-ary and/or at one time step)
// ---------------------------------------------------------------------------

/// Aggregates the operand values `v`.
pub(crate) fn reduce(agg: Agg, v: &[f64]) -> f64 {
    reduce_logw(agg, v).0
}

/// Aggregates `v`, also returning the log-weight `L = ln Σ e^{βv}` that
/// [`reduce_backward`] needs (0 in hard mode).
pub(crate) fn reduce_logw(agg: Agg, v: &[f64]) -> (f64, f64) {
    match agg {
        Agg::Hard(dir) => (v[arg_best(dir, v)], 0.0),
        Agg::Soft { beta } | Agg::Lse { beta } => {
            let acc = v.iter().fold(Acc::EMPTY, |acc, &x| Acc::combine(acc, Acc::lift(beta, x)));
            (acc.value(agg), acc.log_weight())
        }
    }
}

/// First index of the best operand (ties go to the earliest).
fn arg_best(dir: Dir, v: &[f64]) -> usize {
    let mut best = 0;
    for i in 1..v.len() {
        if Agg::better(dir, v[i], v[best]) {
            best = i;
        }
    }
    best
}

/// Adds `g · ∂reduce(v)/∂v_i` to `gv[i]`; `out` and `logw` come from
/// [`reduce_logw`], so each weight `e^{βv_i − L}` costs one `exp`.
pub(crate) fn reduce_backward(agg: Agg, v: &[f64], out: f64, logw: f64, g: f64, gv: &mut [f64]) {
    match agg {
        Agg::Hard(dir) => gv[arg_best(dir, v)] += g,
        Agg::Soft { beta } => {
            for (gi, &x) in gv.iter_mut().zip(v) {
                let w = (beta * x - logw).exp();
                *gi += g * w * (1.0 + beta * (x - out));
            }
        }
        Agg::Lse { beta } => {
            for (gi, &x) in gv.iter_mut().zip(v) {
                *gi += g * (beta * (x - out)).exp();
            }
        }
    }
}

// ---------------------------------------------------------------------------
// Sliding windows (eventually = max, globally = min)
// ---------------------------------------------------------------------------

/// `out[t] = agg over x[window(t)]` for every `t`; smooth modes also write each
/// window's log-weight into `logw` for the backward pass.
pub(crate) fn window_forward(
    agg: Agg,
    x: &[f64],
    (a, b): (usize, Option<usize>),
    out: &mut [f64],
    logw: &mut [f64],
    sc: &mut Scratch,
) {
    let n = x.len();
    match agg {
        Agg::Hard(dir) => {
            hard_window_argbest(dir, x, a, b, sc, |t, j| out[t] = x[j]);
        }
        Agg::Soft { beta } | Agg::Lse { beta } => {
            soft_window_accs(beta, x, a, b, sc);
            for t in 0..n {
                out[t] = sc.acc[t].value(agg);
                logw[t] = sc.acc[t].log_weight();
            }
        }
    }
}

/// Adds the gradient of [`window_forward`] with upstream `gout` into `gx`; `out` and
/// `logw` are what the forward pass wrote.
#[allow(clippy::too_many_arguments)]
pub(crate) fn window_backward(
    agg: Agg,
    x: &[f64],
    (a, b): (usize, Option<usize>),
    out: &[f64],
    logw: &[f64],
    gout: &[f64],
    gx: &mut [f64],
    sc: &mut Scratch,
) {
    let n = x.len();
    match agg {
        Agg::Hard(dir) => {
            hard_window_argbest(dir, x, a, b, sc, |t, j| gx[j] += gout[t]);
        }
        Agg::Soft { .. } | Agg::Lse { .. } => {
            let w = window_len(a, b, n);
            let item = |t: usize| BAcc::lift(logw[t], gout[t], out[t]);
            build_blocks(item, n, w, BAcc::EMPTY, BAcc::combine, &mut sc.bpre, &mut sc.bsuf);
            // For i < n−1 the windows containing i are t ∈ [i−b, i−a]: a sliding range.
            for (i, gxi) in gx.iter_mut().enumerate().take(n - 1) {
                if i < a {
                    continue;
                }
                let hi = i - a;
                let lo = match b {
                    Some(b) => i.saturating_sub(b),
                    None => 0,
                };
                let q = query_blocks(&sc.bpre, &sc.bsuf, w, lo, hi, BAcc::combine);
                *gxi += q.grad(agg, x[i]);
            }
            // The last step is in every window that reaches the end (clamping).
            let lo = match b {
                Some(b) => (n - 1).saturating_sub(b),
                None => 0,
            };
            let q = (lo..n).map(item).fold(BAcc::EMPTY, BAcc::combine);
            gx[n - 1] += q.grad(agg, x[n - 1]);
        }
    }
}

/// Calls `f(t, j)` with `j` the first best index of each window, in O(n).
fn hard_window_argbest(
    dir: Dir,
    x: &[f64],
    a: usize,
    b: Option<usize>,
    sc: &mut Scratch,
    mut f: impl FnMut(usize, usize),
) {
    let n = x.len();
    let dq = &mut sc.deque;
    dq.clear();
    let mut head = 0;
    let mut next = 0;
    for t in 0..n {
        let (lo, hi) = window(t, a, b, n);
        while next <= hi {
            // Strict comparison keeps the earlier of equal values in front.
            while dq.len() > head && Agg::better(dir, x[next], x[*dq.last().unwrap()]) {
                dq.pop();
            }
            dq.push(next);
            next += 1;
        }
        while dq[head] < lo {
            head += 1;
        }
        f(t, dq[head]);
    }
}

/// Fills `sc.acc[t]` with the accumulator of window `t`.
fn soft_window_accs(beta: f64, x: &[f64], a: usize, b: Option<usize>, sc: &mut Scratch) {
    let n = x.len();
    let w = window_len(a, b, n);
    build_blocks(|i| Acc::lift(beta, x[i]), n, w, Acc::EMPTY, Acc::combine, &mut sc.pre, &mut sc.suf);
    sc.acc.clear();
    for t in 0..n {
        let (lo, hi) = window(t, a, b, n);
        sc.acc.push(query_blocks(&sc.pre, &sc.suf, w, lo, hi, Acc::combine));
    }
}

// ---------------------------------------------------------------------------
// Until
// ---------------------------------------------------------------------------
//
// ρ(φ U[a,b] ψ, t) = max_{k ∈ W(t)} min(ψ_k, min_{j ∈ [lo, k−1]} φ_j), W(t) = [lo, hi]
// the clamped window (paper App. C: ψ at k, φ on [a, k−1] relative to t).
//
// Hard mode and the recursive relaxation use the identity
// ρ = min(max_{k∈W} ψ_k, V(lo)), V(u) = max(ψ_u, min(φ_u, V(u+1))), V(n−1) = ψ_{n−1}:
// V(lo) may also count some k > hi, but each such term is at most min φ over W, which
// already bounds the k ∈ W terms, so the outer min removes exactly the excess. With an
// unbounded window the outer min never binds and is dropped.

/// Forward pass of until, writing `out[t]` for every `t`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn until_forward(
    smoothing: Smoothing,
    relax: UntilSmoothing,
    phi: &[f64],
    psi: &[f64],
    a: usize,
    b: Option<usize>,
    out: &mut [f64],
    sc: &mut Scratch,
) {
    let n = phi.len();
    match smoothing {
        Smoothing::Hard => {
            // max_k min(ψ_k, Φ[lo,k−1]) = min(max_{k∈W} ψ_k, V(lo)) with the O(n)
            // recursion V(u) = max(ψ_u, min(φ_u, V(u+1))), V(n−1) = ψ_{n−1}.
            let mut v = std::mem::take(&mut sc.terms);
            until_v(phi, psi, &mut v);
            window_forward(Agg::Hard(Dir::Max), psi, (a, b), out, &mut [], sc);
            for (t, o) in out.iter_mut().enumerate() {
                let (lo, _) = window(t, a, b, n);
                *o = o.min(v[lo]);
            }
            sc.terms = v;
        }
        _ if relax == UntilSmoothing::Recursive => {
            let (inner, outer) = (Agg::new(smoothing, Dir::Min), Agg::new(smoothing, Dir::Max));
            let mut v = std::mem::take(&mut sc.terms);
            smooth_until_v(inner, outer, phi, psi, &mut v);
            if b.is_none() {
                for (t, o) in out.iter_mut().enumerate() {
                    *o = v[window(t, a, b, n).0];
                }
            } else {
                let mut logw = std::mem::take(&mut sc.vwin);
                logw.clear();
                logw.resize(n, 0.0);
                window_forward(outer, psi, (a, b), out, &mut logw, sc);
                for (t, o) in out.iter_mut().enumerate() {
                    *o = pair(inner, *o, v[window(t, a, b, n).0]).0;
                }
                sc.vwin = logw;
            }
            sc.terms = v;
        }
        _ => {
            let inner = Agg::new(smoothing, Dir::Min);
            let outer = Agg::new(smoothing, Dir::Max);
            for (t, o) in out.iter_mut().enumerate() {
                soft_until_terms(inner, phi, psi, window(t, a, b, n), sc);
                *o = reduce(outer, &sc.terms);
            }
        }
    }
}

/// `V(u)` of the hard until recursion, for every `u`.
fn until_v(phi: &[f64], psi: &[f64], v: &mut Vec<f64>) {
    let n = phi.len();
    v.clear();
    v.resize(n, 0.0);
    v[n - 1] = psi[n - 1];
    for u in (0..n - 1).rev() {
        v[u] = psi[u].max(phi[u].min(v[u + 1]));
    }
}

/// `V(u)` of the recursive relaxation: each `max`/`min` of the hard recursion made a
/// smooth pair.
fn smooth_until_v(inner: Agg, outer: Agg, phi: &[f64], psi: &[f64], v: &mut Vec<f64>) {
    let n = phi.len();
    v.clear();
    v.resize(n, 0.0);
    v[n - 1] = psi[n - 1];
    for u in (0..n - 1).rev() {
        v[u] = pair(outer, psi[u], pair(inner, phi[u], v[u + 1]).0).0;
    }
}

/// The smooth aggregate of two values and its partial derivatives `(value, ∂/∂x, ∂/∂y)`.
///
/// Soft: `w·x + (1−w)·y`, `w = σ(β(x−y))`; log-sum-exp: `ln(e^{βx} + e^{βy})/β`, whose
/// partials are `σ(β(x−y))` and its complement.
#[inline]
fn pair(agg: Agg, x: f64, y: f64) -> (f64, f64, f64) {
    match agg {
        Agg::Soft { beta } => {
            let w = sigmoid(beta * (x - y));
            // w(1−w) is exactly 0 once σ saturates, so ±top operands stay finite.
            let c = beta * w * (1.0 - w) * (x - y);
            (w * x + (1.0 - w) * y, w + c, 1.0 - w - c)
        }
        Agg::Lse { beta } => {
            let (bx, by) = (beta * x, beta * y);
            let value = (bx.max(by) + (-(bx - by).abs()).exp().ln_1p()) / beta;
            let w = sigmoid(bx - by);
            (value, w, 1.0 - w)
        }
        Agg::Hard(_) => unreachable!("hard until has its own recursion"),
    }
}

#[inline]
fn sigmoid(z: f64) -> f64 {
    if z >= 0.0 {
        1.0 / (1.0 + (-z).exp())
    } else {
        let e = z.exp();
        e / (1.0 + e)
    }
}

/// Fills `sc.terms` (and `sc.tacc`) with the inner terms `min(ψ_k, φ_lo..φ_{k−1})`.
fn soft_until_terms(inner: Agg, phi: &[f64], psi: &[f64], (lo, hi): (usize, usize), sc: &mut Scratch) {
    let beta = match inner {
        Agg::Soft { beta } | Agg::Lse { beta } => beta,
        Agg::Hard(_) => unreachable!(),
    };
    sc.terms.clear();
    sc.tacc.clear();
    let mut run = Acc::EMPTY;
    for k in lo..=hi {
        let acc = Acc::combine(run, Acc::lift(beta, psi[k]));
        sc.terms.push(acc.value(inner));
        sc.tacc.push(acc);
        run = Acc::combine(run, Acc::lift(beta, phi[k]));
    }
}

/// Adds the gradient of [`until_forward`] into `gphi` and `gpsi`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn until_backward(
    smoothing: Smoothing,
    relax: UntilSmoothing,
    phi: &[f64],
    psi: &[f64],
    a: usize,
    b: Option<usize>,
    out: &[f64],
    gout: &[f64],
    gphi: &mut [f64],
    gpsi: &mut [f64],
    sc: &mut Scratch,
) {
    let n = phi.len();
    match smoothing {
        Smoothing::Hard => {
            let mut v = std::mem::take(&mut sc.terms);
            until_v(phi, psi, &mut v);
            let mut fpsi = std::mem::take(&mut sc.vwin);
            fpsi.clear();
            fpsi.resize(n, 0.0);
            window_forward(Agg::Hard(Dir::Max), psi, (a, b), &mut fpsi, &mut [], sc);
            // Route each t to the window max of ψ or to V(lo); ties go to the window.
            let mut gv = std::mem::take(&mut sc.gterm);
            gv.clear();
            gv.resize(n, 0.0);
            let mut gwin = vec![0.0; n];
            for t in 0..n {
                let (lo, _) = window(t, a, b, n);
                if fpsi[t] <= v[lo] {
                    gwin[t] += gout[t];
                } else {
                    gv[lo] += gout[t];
                }
            }
            window_backward(Agg::Hard(Dir::Max), psi, (a, b), &[], &[], &gwin, gpsi, sc);
            for u in 0..n {
                let g = gv[u];
                if g == 0.0 {
                    continue;
                }
                if u == n - 1 || psi[u] >= phi[u].min(v[u + 1]) {
                    gpsi[u] += g;
                } else if phi[u] <= v[u + 1] {
                    gphi[u] += g;
                } else {
                    gv[u + 1] += g;
                }
            }
            sc.terms = v;
            sc.vwin = fpsi;
            sc.gterm = gv;
        }
        _ if relax == UntilSmoothing::Recursive => {
            let (inner, outer) = (Agg::new(smoothing, Dir::Min), Agg::new(smoothing, Dir::Max));
            let mut v = std::mem::take(&mut sc.terms);
            smooth_until_v(inner, outer, phi, psi, &mut v);
            let mut gv = std::mem::take(&mut sc.gterm);
            gv.clear();
            gv.resize(n, 0.0);
            if b.is_none() {
                for t in 0..n {
                    gv[window(t, a, b, n).0] += gout[t];
                }
            } else {
                // Recompute the window max of ψ, then split each gradient between it
                // and V(lo) by the outer pair's partials.
                let (mut fpsi, mut logw, mut gwin) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
                window_forward(outer, psi, (a, b), &mut fpsi, &mut logw, sc);
                for t in 0..n {
                    let lo = window(t, a, b, n).0;
                    let (_, dwin, dv) = pair(inner, fpsi[t], v[lo]);
                    gwin[t] = gout[t] * dwin;
                    gv[lo] += gout[t] * dv;
                }
                window_backward(outer, psi, (a, b), &fpsi, &logw, &gwin, gpsi, sc);
            }
            // V(u) feeds V(u−1) only: one forward sweep carries the gradient down.
            for u in 0..n {
                let g = gv[u];
                if g == 0.0 {
                    continue;
                }
                if u == n - 1 {
                    gpsi[u] += g;
                    continue;
                }
                let (m, dphi, dnext) = pair(inner, phi[u], v[u + 1]);
                let (_, dpsi, dm) = pair(outer, psi[u], m);
                gpsi[u] += g * dpsi;
                gphi[u] += g * dm * dphi;
                gv[u + 1] += g * dm * dnext;
            }
            sc.terms = v;
            sc.gterm = gv;
        }
        _ => {
            let inner = Agg::new(smoothing, Dir::Min);
            let outer = Agg::new(smoothing, Dir::Max);
            for t in 0..n {
                if gout[t] == 0.0 {
                    continue;
                }
                let (lo, hi) = window(t, a, b, n);
                soft_until_terms(inner, phi, psi, (lo, hi), sc);
                let mut gterm = std::mem::take(&mut sc.gterm);
                gterm.clear();
                gterm.resize(sc.terms.len(), 0.0);
                let (_, logw) = reduce_logw(outer, &sc.terms);
                reduce_backward(outer, &sc.terms, out[t], logw, gout[t], &mut gterm);
                // ψ_k only enters term k.
                for (i, k) in (lo..=hi).enumerate() {
                    let q = BAcc::lift(sc.tacc[i].log_weight(), gterm[i], sc.terms[i]);
                    gpsi[k] += q.grad(inner, psi[k]);
                }
                // φ_j enters every term k > j: suffix sums over k.
                let mut q = BAcc::EMPTY;
                for k in (lo + 1..=hi).rev() {
                    let i = k - lo;
                    q = BAcc::combine(q, BAcc::lift(sc.tacc[i].log_weight(), gterm[i], sc.terms[i]));
                    gphi[k - 1] += q.grad(inner, phi[k - 1]);
                }
                sc.gterm = gterm;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn naive_window(agg: Agg, x: &[f64], a: usize, b: Option<usize>) -> Vec<f64> {
        (0..x.len())
            .map(|t| {
                let (lo, hi) = window(t, a, b, x.len());
                reduce(agg, &x[lo..=hi])
            })
            .collect()
    }

    #[test]
    fn windows_match_naive_in_every_mode() {
        let x: Vec<f64> = (0..37).map(|i| ((i * 7919) % 23) as f64 * 0.37 - 3.0).collect();
        let aggs = [
            Agg::Hard(Dir::Max),
            Agg::Hard(Dir::Min),
            Agg::Soft { beta: 2.0 },
            Agg::Soft { beta: -3.0 },
            Agg::Lse { beta: 1.5 },
            Agg::Lse { beta: -0.5 },
        ];
        let mut sc = Scratch::default();
        for agg in aggs {
            for (a, b) in [(0, Some(0)), (0, Some(3)), (2, Some(9)), (5, None), (0, None), (30, Some(50))] {
                let mut out = vec![0.0; x.len()];
                let mut logw = vec![0.0; x.len()];
                window_forward(agg, &x, (a, b), &mut out, &mut logw, &mut sc);
                let want = naive_window(agg, &x, a, b);
                for (o, w) in out.iter().zip(&want) {
                    assert!((o - w).abs() < 1e-9, "{agg:?} [{a},{b:?}]: {o} vs {w}");
                }
            }
        }
    }

    #[test]
    fn window_backward_matches_naive_in_every_mode() {
        let x: Vec<f64> = (0..29).map(|i| ((i * 104729) % 31) as f64 * 0.21 - 2.0).collect();
        let g: Vec<f64> = (0..29).map(|i| ((i * 37) % 11) as f64 * 0.1 - 0.4).collect();
        let mut sc = Scratch::default();
        for agg in [
            Agg::Soft { beta: 2.0 },
            Agg::Soft { beta: -1.0 },
            Agg::Lse { beta: 0.7 },
            Agg::Lse { beta: -2.0 },
        ] {
            for (a, b) in [(0, Some(4)), (3, Some(7)), (1, None), (25, Some(40))] {
                let mut gx = vec![0.0; x.len()];
                let (mut out, mut logw) = (vec![0.0; x.len()], vec![0.0; x.len()]);
                window_forward(agg, &x, (a, b), &mut out, &mut logw, &mut sc);
                window_backward(agg, &x, (a, b), &out, &logw, &g, &mut gx, &mut sc);
                let mut want = vec![0.0; x.len()];
                for t in 0..x.len() {
                    let (lo, hi) = window(t, a, b, x.len());
                    let (out, logw) = reduce_logw(agg, &x[lo..=hi]);
                    reduce_backward(agg, &x[lo..=hi], out, logw, g[t], &mut want[lo..=hi]);
                }
                for (o, w) in gx.iter().zip(&want) {
                    assert!((o - w).abs() < 1e-9, "{agg:?} [{a},{b:?}]: {o} vs {w}");
                }
            }
        }
    }
}
