//! Predicates: functions from a state (and its waypoint index) to a robustness
//! value, with their gradient.
//!
//! A formula refers to predicates by name; a [`crate::SpecBuilder`] binds each name to
//! a [`Predicate`]. This module ships the common ones: goal regions ([`Ball`]),
//! half-spaces ([`Halfspace`]), axis-aligned box obstacles ([`AvoidBoxes`]),
//! time-triggered signals ([`AfterStep`]) and closures ([`FnPredicate`]).

// Index loops mirror the formulas they implement.
#![allow(clippy::needless_range_loop)]

use std::fmt;

/// A state predicate with quantitative semantics: positive means satisfied.
pub trait Predicate: Send + Sync {
    /// The robustness of this predicate on `state`, the path's state at step `t`.
    fn value(&self, t: usize, state: &[f64]) -> f64;

    /// The robustness, adding `scale · ∂value/∂state` into `grad` (same length as
    /// `state`). Where the function is not differentiable, any subgradient.
    fn value_and_grad(&self, t: usize, state: &[f64], scale: f64, grad: &mut [f64]) -> f64;

    /// The number of state dimensions this predicate reads (it reads
    /// `state[..required_dim()]`); checked when a spec is built.
    fn required_dim(&self) -> usize;

    /// The robustness at step `t` of a whole path (`path` holds its states, `dim`
    /// numbers each). State predicates read only `path[t]` (the default); a path
    /// predicate overrides this to read earlier states too, e.g. the clearance of the
    /// segment that arrives at `t`.
    fn value_on_path(&self, path: &[f64], dim: usize, t: usize) -> f64 {
        self.value(t, &path[t * dim..(t + 1) * dim])
    }

    /// [`Predicate::value_on_path`], adding `scale ·` its gradient with respect to
    /// the whole path into `grad` (same length as `path`).
    fn value_and_grad_on_path(
        &self,
        path: &[f64],
        dim: usize,
        t: usize,
        scale: f64,
        grad: &mut [f64],
    ) -> f64 {
        let at = t * dim..(t + 1) * dim;
        self.value_and_grad(t, &path[at.clone()], scale, &mut grad[at])
    }
}

/// Smart pointers to predicates are predicates.
macro_rules! forward_predicate {
    ($($ptr:ident)::+) => {
        impl<P: Predicate + ?Sized> Predicate for $($ptr)::+<P> {
            fn value(&self, t: usize, state: &[f64]) -> f64 {
                (**self).value(t, state)
            }
            fn value_and_grad(&self, t: usize, state: &[f64], scale: f64, grad: &mut [f64]) -> f64 {
                (**self).value_and_grad(t, state, scale, grad)
            }
            fn required_dim(&self) -> usize {
                (**self).required_dim()
            }
            fn value_on_path(&self, path: &[f64], dim: usize, t: usize) -> f64 {
                (**self).value_on_path(path, dim, t)
            }
            fn value_and_grad_on_path(
                &self,
                path: &[f64],
                dim: usize,
                t: usize,
                scale: f64,
                grad: &mut [f64],
            ) -> f64 {
                (**self).value_and_grad_on_path(path, dim, t, scale, grad)
            }
        }
    };
}
forward_predicate!(Box);
forward_predicate!(std::sync::Arc);

/// A goal region: `radius − ‖state[offset..offset+d] − center‖` (the paper's reach
/// predicate, App. D). At the centre the gradient is taken as zero.
#[derive(Clone, Debug, PartialEq)]
pub struct Ball {
    /// Centre, one coordinate per dimension read.
    pub center: Vec<f64>,
    /// Radius.
    pub radius: f64,
    /// First state dimension read.
    pub offset: usize,
}

impl Ball {
    /// A ball over the first `center.len()` state dimensions.
    pub fn new(center: impl Into<Vec<f64>>, radius: f64) -> Self {
        Self { center: center.into(), radius, offset: 0 }
    }
}

impl Predicate for Ball {
    fn value(&self, _t: usize, state: &[f64]) -> f64 {
        let p = &state[self.offset..];
        let d2: f64 = match self.center[..] {
            // The planar and spatial goals of every task: unrolled.
            [cx, cy] => (p[0] - cx) * (p[0] - cx) + (p[1] - cy) * (p[1] - cy),
            [cx, cy, cz] => (p[0] - cx) * (p[0] - cx) + (p[1] - cy) * (p[1] - cy) + (p[2] - cz) * (p[2] - cz),
            _ => p.iter().zip(&self.center).map(|(x, c)| (x - c) * (x - c)).sum(),
        };
        self.radius - d2.sqrt()
    }

    fn value_and_grad(&self, _t: usize, state: &[f64], scale: f64, grad: &mut [f64]) -> f64 {
        let k = self.center.len();
        let p = &state[self.offset..self.offset + k];
        let d = p.iter().zip(&self.center).map(|(x, c)| (x - c) * (x - c)).sum::<f64>().sqrt();
        if d > 0.0 {
            let g = &mut grad[self.offset..self.offset + k];
            for ((gi, x), c) in g.iter_mut().zip(p).zip(&self.center) {
                *gi -= scale * (x - c) / d;
            }
        }
        self.radius - d
    }

    fn required_dim(&self) -> usize {
        self.offset + self.center.len()
    }
}

/// A half-space `normal · state[..d] − bound ≥ 0`, robustness `normal · x − bound`.
#[derive(Clone, Debug, PartialEq)]
pub struct Halfspace {
    /// Coefficients, one per state dimension read.
    pub normal: Vec<f64>,
    /// Right-hand side.
    pub bound: f64,
}

impl Predicate for Halfspace {
    fn value(&self, _t: usize, state: &[f64]) -> f64 {
        self.normal.iter().zip(state).map(|(a, x)| a * x).sum::<f64>() - self.bound
    }

    fn value_and_grad(&self, t: usize, state: &[f64], scale: f64, grad: &mut [f64]) -> f64 {
        for (g, a) in grad.iter_mut().zip(&self.normal) {
            *g += scale * a;
        }
        self.value(t, state)
    }

    fn required_dim(&self) -> usize {
        self.normal.len()
    }
}

/// An axis-aligned box: centre and half-sizes.
#[derive(Clone, Debug, PartialEq)]
pub struct AxisBox {
    /// Centre.
    pub center: Vec<f64>,
    /// Half the size along each axis.
    pub half: Vec<f64>,
}

impl AxisBox {
    /// Signed distance from `p` to the box (negative inside) and, if `grad` is given,
    /// its gradient written into it.
    pub fn signed_distance(&self, p: &[f64], grad: Option<&mut [f64]>) -> f64 {
        let k = self.center.len();
        let mut outside2 = 0.0;
        let mut inside_max = f64::NEG_INFINITY;
        let mut inside_axis = 0;
        for i in 0..k {
            let q = (p[i] - self.center[i]).abs() - self.half[i];
            if q > 0.0 {
                outside2 += q * q;
            }
            if q > inside_max {
                inside_max = q;
                inside_axis = i;
            }
        }
        let outside = outside2.sqrt();
        let sd = if outside > 0.0 { outside } else { inside_max };
        if let Some(g) = grad {
            for i in 0..k {
                let dir = if p[i] >= self.center[i] { 1.0 } else { -1.0 };
                let q = (p[i] - self.center[i]).abs() - self.half[i];
                g[i] = if outside > 0.0 {
                    if q > 0.0 { dir * q / outside } else { 0.0 }
                } else if i == inside_axis {
                    dir
                } else {
                    0.0
                };
            }
        }
        sd
    }
}

/// Staying out of a set of axis-aligned boxes: robustness is the signed distance to
/// the nearest box minus a `margin` (e.g. the robot's radius), so positive means
/// clear of every box by more than the margin. Reads the first `d` dimensions, `d`
/// the boxes' dimension. Inside overlapping or touching boxes the depth is that of
/// the deepest single box (exact outside, a lower bound on depth inside).
#[derive(Clone, Debug, PartialEq)]
pub struct AvoidBoxes {
    boxes: Vec<AxisBox>,
    margin: f64,
    dim: usize,
    // Struct-of-arrays copy for the hot loop: centres and half-sizes, box-major.
    centers: Vec<f64>,
    halves: Vec<f64>,
}

impl AvoidBoxes {
    /// Avoid `boxes` (all of one dimension) by more than `margin`.
    ///
    /// # Panics
    /// If the boxes differ in dimension or a half-size is negative.
    pub fn new(boxes: Vec<AxisBox>, margin: f64) -> Self {
        let dim = boxes.first().map_or(0, |b| b.center.len());
        for b in &boxes {
            assert!(b.center.len() == dim && b.half.len() == dim, "boxes must all have dimension {dim}");
            assert!(b.half.iter().all(|h| *h >= 0.0), "box half-sizes must be >= 0");
        }
        let centers = boxes.iter().flat_map(|b| b.center.iter().copied()).collect();
        let halves = boxes.iter().flat_map(|b| b.half.iter().copied()).collect();
        Self { boxes, margin, dim, centers, halves }
    }

    /// Squares/cubes of half-size `half` centred at `centers`.
    pub fn cubes(centers: &[Vec<f64>], half: f64, margin: f64) -> Self {
        let boxes =
            centers.iter().map(|c| AxisBox { center: c.clone(), half: vec![half; c.len()] }).collect();
        Self::new(boxes, margin)
    }

    /// The obstacles.
    pub fn boxes(&self) -> &[AxisBox] {
        &self.boxes
    }

    /// The clearance subtracted from the distance.
    pub fn margin(&self) -> f64 {
        self.margin
    }

    /// The nearest box and the signed distance to it. Hot path (the walls clause of
    /// every ground task): each box gets a score, its squared distance outside or
    /// its (negative) depth inside, so that one branch-free minimum and one square
    /// root suffice.
    fn nearest(&self, p: &[f64]) -> (usize, f64) {
        match self.dim {
            2 => self.nearest_d::<2>(p),
            3 => self.nearest_d::<3>(p),
            _ => self.nearest_any(p),
        }
    }

    fn nearest_d<const D: usize>(&self, p: &[f64]) -> (usize, f64) {
        let p: &[f64; D] = p[..D].try_into().expect("state has the boxes' dimension");
        let mut best = (usize::MAX, f64::INFINITY);
        for (i, (c, h)) in self.centers.chunks_exact(D).zip(self.halves.chunks_exact(D)).enumerate() {
            let mut out2 = 0.0;
            let mut qmax = f64::NEG_INFINITY;
            for k in 0..D {
                let q = (p[k] - c[k]).abs() - h[k];
                out2 += q.max(0.0) * q.max(0.0);
                qmax = qmax.max(q);
            }
            let score = if qmax > 0.0 { out2 } else { qmax };
            if score < best.1 {
                best = (i, score);
            }
        }
        Self::finish(best)
    }

    fn nearest_any(&self, p: &[f64]) -> (usize, f64) {
        let mut best = (usize::MAX, f64::INFINITY);
        for (i, b) in self.boxes.iter().enumerate() {
            let d = b.signed_distance(p, None);
            let score = if d > 0.0 { d * d } else { d };
            if score < best.1 {
                best = (i, score);
            }
        }
        Self::finish(best)
    }

    fn finish((i, score): (usize, f64)) -> (usize, f64) {
        if score > 0.0 { (i, score.sqrt()) } else { (i, score) }
    }
}

impl Predicate for AvoidBoxes {
    fn value(&self, _t: usize, state: &[f64]) -> f64 {
        self.nearest(state).1 - self.margin
    }

    fn value_and_grad(&self, _t: usize, state: &[f64], scale: f64, grad: &mut [f64]) -> f64 {
        let (i, d) = self.nearest(state);
        if let Some(b) = self.boxes.get(i) {
            let mut g = vec![0.0; self.dim];
            b.signed_distance(state, Some(&mut g));
            for (o, gi) in grad.iter_mut().zip(&g) {
                *o += scale * gi;
            }
        }
        d - self.margin
    }

    fn required_dim(&self) -> usize {
        self.dim
    }
}

/// A signal of time alone: `−k` (⊥) before waypoint `step`, `+k` (⊤) from it on,
/// with `k = truth` (paper App. C: ⊤ is some `k > 0`, ⊥ is `−k`). The paper's Signal
/// task uses one as its counter ("false until the 10th waypoint", App. G).
///
/// Choose `k` above every value the rest of a formula can take. In `φ U[a,b] counter`
/// the first term is `min(⊥, ∅) = −k`, a floor on the until's robustness: with the
/// paper's `k = 1` any loop body violated by more than 1 m sits on that floor, where
/// the robustness has no gradient, and the Signal planner never trains (0 of 5 seeds;
/// 3 of 3 with `k = 100`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AfterStep {
    /// First step at which the predicate holds.
    pub step: usize,
    /// `k`: the value when it holds (`−k` before).
    pub truth: f64,
}

impl Predicate for AfterStep {
    fn value(&self, t: usize, _state: &[f64]) -> f64 {
        if t >= self.step { self.truth } else { -self.truth }
    }

    fn value_and_grad(&self, t: usize, state: &[f64], _scale: f64, _grad: &mut [f64]) -> f64 {
        self.value(t, state)
    }

    fn required_dim(&self) -> usize {
        0
    }
}

/// One state dimension compared with a number: `sign · (state[index] − threshold)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct SignalCompare {
    pub index: usize,
    pub sign: f64,
    pub threshold: f64,
}

impl Predicate for SignalCompare {
    fn value(&self, _t: usize, state: &[f64]) -> f64 {
        self.sign * (state[self.index] - self.threshold)
    }

    fn value_and_grad(&self, t: usize, state: &[f64], scale: f64, grad: &mut [f64]) -> f64 {
        grad[self.index] += scale * self.sign;
        self.value(t, state)
    }

    fn required_dim(&self) -> usize {
        self.index + 1
    }
}

/// A bound predicate compared with a number: `sign · (inner − threshold)`.
pub(crate) struct Shifted<P> {
    pub inner: P,
    pub sign: f64,
    pub threshold: f64,
}

impl<P: Predicate> Predicate for Shifted<P> {
    fn value(&self, t: usize, state: &[f64]) -> f64 {
        self.sign * (self.inner.value(t, state) - self.threshold)
    }

    fn value_and_grad(&self, t: usize, state: &[f64], scale: f64, grad: &mut [f64]) -> f64 {
        self.sign * (self.inner.value_and_grad(t, state, scale * self.sign, grad) - self.threshold)
    }

    fn required_dim(&self) -> usize {
        self.inner.required_dim()
    }
}

type ValueFn = dyn Fn(usize, &[f64]) -> f64 + Send + Sync;
type GradFn = dyn Fn(usize, &[f64], &mut [f64]) + Send + Sync;

/// A predicate from closures: a value function and, optionally, its gradient
/// (without one, central finite differences with step `1e-6` are used).
pub struct FnPredicate {
    value: Box<ValueFn>,
    grad: Option<Box<GradFn>>,
    dim: usize,
}

impl FnPredicate {
    /// A predicate reading `dim` state dimensions, differentiated numerically.
    pub fn new(dim: usize, value: impl Fn(usize, &[f64]) -> f64 + Send + Sync + 'static) -> Self {
        Self { value: Box::new(value), grad: None, dim }
    }

    /// Supplies the exact gradient: `grad(t, state, out)` writes `∂value/∂state` into `out`.
    pub fn with_gradient(mut self, grad: impl Fn(usize, &[f64], &mut [f64]) + Send + Sync + 'static) -> Self {
        self.grad = Some(Box::new(grad));
        self
    }
}

impl fmt::Debug for FnPredicate {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("FnPredicate")
            .field("dim", &self.dim)
            .field("exact_gradient", &self.grad.is_some())
            .finish()
    }
}

impl Predicate for FnPredicate {
    fn value(&self, t: usize, state: &[f64]) -> f64 {
        (self.value)(t, state)
    }

    fn value_and_grad(&self, t: usize, state: &[f64], scale: f64, grad: &mut [f64]) -> f64 {
        let v = (self.value)(t, state);
        let mut g = vec![0.0; state.len()];
        match &self.grad {
            Some(gf) => gf(t, state, &mut g),
            None => {
                const H: f64 = 1e-6;
                let mut s = state.to_vec();
                for i in 0..self.dim.min(state.len()) {
                    let x = s[i];
                    s[i] = x + H;
                    let up = (self.value)(t, &s);
                    s[i] = x - H;
                    let down = (self.value)(t, &s);
                    s[i] = x;
                    g[i] = (up - down) / (2.0 * H);
                }
            }
        }
        for (o, gi) in grad.iter_mut().zip(&g) {
            *o += scale * gi;
        }
        v
    }

    fn required_dim(&self) -> usize {
        self.dim
    }
}
