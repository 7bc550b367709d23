//! Shared test helpers: random formulas, a spec over 2-D paths, and an independent
//! reference evaluator written straight from the paper's App. C.

#![allow(dead_code)]

use proptest::prelude::*;
use stl::{Ball, Formula, Halfspace, Interval, Semantics, Smoothing, Spec, UntilRule, UntilSmoothing};

pub const SIGNALS: [&str; 2] = ["x", "y"];

/// Binds `a`, `b`, `c` (and the signals `x`, `y`) for 2-D paths.
pub fn bind(f: Formula) -> Spec {
    bind_with(f, UntilRule::Standard)
}

/// [`bind`] with `U` read by `rule`.
pub fn bind_with(f: Formula, rule: UntilRule) -> Spec {
    Spec::builder(f)
        .until(rule)
        .signals(SIGNALS)
        .bind("a", Ball::new([1.0, 0.0], 0.5))
        .bind("b", Ball::new([0.0, 1.0], 0.7))
        .bind("c", Halfspace { normal: vec![1.0, -0.5], bound: 0.2 })
        .build()
        .expect("all names bound")
}

fn interval() -> impl Strategy<Value = Interval> {
    (0usize..4, prop::option::of(0usize..6))
        .prop_map(|(a, len)| Interval { start: a, end: len.map(|l| a + l) })
}

fn leaf() -> impl Strategy<Value = Formula> {
    prop_oneof![
        4 => prop::sample::select(vec!["a", "b", "c", "x"]).prop_map(Formula::atom),
        2 => (prop::sample::select(vec!["x", "y", "a"]), prop::sample::select(vec![stl::CmpOp::Gt, stl::CmpOp::Le]), -2.0f64..2.0)
            .prop_map(|(s, op, c)| Formula::compare(s, op, (c * 100.0).round() / 100.0)),
        1 => Just(Formula::True),
        1 => Just(Formula::False),
    ]
}

/// Random formulas over `a`, `b`, `c`, `x`, `y` using every operator.
pub fn formula() -> impl Strategy<Value = Formula> {
    leaf().prop_recursive(4, 24, 3, |inner| {
        prop_oneof![
            inner.clone().prop_map(|f| !f),
            prop::collection::vec(inner.clone(), 2..4).prop_map(Formula::And),
            prop::collection::vec(inner.clone(), 2..4).prop_map(Formula::Or),
            (inner.clone(), inner.clone()).prop_map(|(l, r)| l.implies(r)),
            inner.clone().prop_map(Formula::next),
            (interval(), inner.clone()).prop_map(|(i, f)| Formula::Eventually(i, Box::new(f))),
            (interval(), inner.clone()).prop_map(|(i, f)| Formula::Globally(i, Box::new(f))),
            (interval(), inner.clone(), inner).prop_map(|(i, l, r)| Formula::Until(
                i,
                Box::new(l),
                Box::new(r)
            )),
        ]
    })
}

/// A random 2-D path of 1..=12 states.
pub fn path() -> impl Strategy<Value = Vec<f64>> {
    (1usize..=12).prop_flat_map(|n| prop::collection::vec(-2.0f64..2.0, 2 * n))
}

/// Every semantics the crate offers, smooth ones with mild parameters.
pub fn semantics() -> impl Strategy<Value = Semantics> {
    prop_oneof![
        Just(Semantics::hard()),
        (0.5f64..4.0).prop_map(Semantics::soft),
        (0.2f64..2.0).prop_map(Semantics::lse),
        (0.5f64..4.0).prop_map(|a| Semantics::soft(a).with_until(UntilSmoothing::Flat)),
        (0.2f64..2.0).prop_map(|t| Semantics::lse(t).with_until(UntilSmoothing::Flat)),
        (0.5f64..4.0).prop_map(|a| Semantics::soft(a).logic_only()),
        (0.2f64..2.0).prop_map(|t| Semantics::lse(t).logic_only()),
    ]
}

// ---------------------------------------------------------------------------
// Reference evaluator (App. C, written directly; windows clamp to the last step)
// ---------------------------------------------------------------------------

fn agg(sm: Smoothing, max: bool, v: &[f64]) -> f64 {
    let s = if max { 1.0 } else { -1.0 };
    match sm {
        Smoothing::Hard => {
            v.iter().copied().fold(if max { f64::NEG_INFINITY } else { f64::INFINITY }, |m, x| {
                if max { m.max(x) } else { m.min(x) }
            })
        }
        Smoothing::Soft { alpha } => {
            let m = v.iter().map(|x| s * alpha * x).fold(f64::NEG_INFINITY, f64::max);
            let w: Vec<f64> = v.iter().map(|x| (s * alpha * x - m).exp()).collect();
            w.iter().zip(v).map(|(w, x)| w * x).sum::<f64>() / w.iter().sum::<f64>()
        }
        Smoothing::LogSumExp { temperature } => {
            let m = v.iter().map(|x| s * x / temperature).fold(f64::NEG_INFINITY, f64::max);
            let z: f64 = v.iter().map(|x| (s * x / temperature - m).exp()).sum();
            s * temperature * (m + z.ln())
        }
    }
}

/// ρ(f, t) on a 2-D path, evaluated by the definitions (standard until), for
/// checking the fast code.
pub fn reference(f: &Formula, path: &[f64], t: usize, sem: &Semantics) -> f64 {
    reference_with(f, path, t, sem, UntilRule::Standard)
}

/// [`reference`] with `U` read by `rule`: the paper's φ on `[t+a, k−1]`, or the
/// standard φ on `[t, k−1]` written as `G[0,a−1] φ ∧` the paper's until.
pub fn reference_with(f: &Formula, path: &[f64], t: usize, sem: &Semantics, rule: UntilRule) -> f64 {
    let reference =
        |f: &Formula, path: &[f64], t: usize, sem: &Semantics| reference_with(f, path, t, sem, rule);
    let n = path.len() / 2;
    let last = n - 1;
    let clamp = |k: usize| k.min(last);
    let logic = sem.smoothing;
    let temporal = if sem.smooth_temporal { sem.smoothing } else { Smoothing::Hard };
    let state = &path[2 * clamp(t)..2 * clamp(t) + 2];
    let pred = |name: &str| -> f64 {
        match name {
            "a" => 0.5 - ((state[0] - 1.0).powi(2) + state[1].powi(2)).sqrt(),
            "b" => 0.7 - (state[0].powi(2) + (state[1] - 1.0).powi(2)).sqrt(),
            "c" => state[0] - 0.5 * state[1] - 0.2,
            "x" => state[0],
            "y" => state[1],
            other => panic!("unknown name {other}"),
        }
    };
    let window = |i: &Interval| {
        let lo = clamp(t + i.start);
        let hi = i.end.map_or(last, |e| clamp(t + e));
        lo..=hi
    };
    match f {
        Formula::True => sem.top,
        Formula::False => -sem.top,
        Formula::Atom(n) => pred(n),
        Formula::Compare { signal, op, threshold } => op.sign() * (pred(signal) - threshold),
        Formula::Not(g) => -reference(g, path, t, sem),
        Formula::And(v) => {
            agg(logic, false, &v.iter().map(|g| reference(g, path, t, sem)).collect::<Vec<_>>())
        }
        Formula::Or(v) => agg(logic, true, &v.iter().map(|g| reference(g, path, t, sem)).collect::<Vec<_>>()),
        Formula::Implies(l, r) => {
            agg(logic, true, &[-reference(l, path, t, sem), reference(r, path, t, sem)])
        }
        Formula::Next(g) => reference(g, path, clamp(t + 1), sem),
        Formula::Eventually(i, g) => {
            agg(temporal, true, &window(i).map(|k| reference(g, path, k, sem)).collect::<Vec<_>>())
        }
        Formula::Globally(i, g) => {
            agg(temporal, false, &window(i).map(|k| reference(g, path, k, sem)).collect::<Vec<_>>())
        }
        Formula::Until(i, l, r) => {
            let w = window(i);
            let lo = *w.start();
            let paper = if temporal != Smoothing::Hard && sem.until == UntilSmoothing::Recursive {
                // V(u) = max(ψ_u, min(φ_u, V(u+1))) from the last step down to lo.
                let mut v = reference(r, path, last, sem);
                for u in (lo..last).rev() {
                    let m = agg(temporal, false, &[reference(l, path, u, sem), v]);
                    v = agg(temporal, true, &[reference(r, path, u, sem), m]);
                }
                match i.end {
                    None => v,
                    Some(_) => {
                        let psi: Vec<f64> = w.map(|k| reference(r, path, k, sem)).collect();
                        agg(temporal, false, &[agg(temporal, true, &psi), v])
                    }
                }
            } else {
                let terms: Vec<f64> = w
                    .map(|k| {
                        let mut inner = vec![reference(r, path, k, sem)];
                        inner.extend((lo..k).map(|j| reference(l, path, j, sem)));
                        agg(temporal, false, &inner)
                    })
                    .collect();
                agg(temporal, true, &terms)
            };
            if rule == UntilRule::Paper || i.start == 0 {
                return paper;
            }
            let before = Formula::Globally(Interval::bounded(0, i.start - 1), l.clone());
            agg(temporal, false, &[reference(&before, path, t, sem), paper])
        }
    }
}
