//! Robustness of every operator, forward and backward, against the paper's
//! definitions (App. C) and against finite differences.

mod common;

use common::{bind, formula, path, semantics};
use proptest::prelude::*;
use stl::{Formula, Semantics, UntilRule, UntilSmoothing, parse};

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * (1.0 + a.abs().max(b.abs()))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    /// The O(T) evaluator equals the direct definitions, in every mode and at every
    /// start time.
    #[test]
    fn forward_matches_definition(
        f in formula(),
        p in path(),
        sem in semantics(),
        rule in prop_oneof![Just(UntilRule::Standard), Just(UntilRule::Paper)],
    ) {
        let spec = common::bind_with(f.clone(), rule);
        let signal = spec.robustness_signal(&p, &sem).unwrap();
        for (t, got) in signal.iter().enumerate() {
            let want = common::reference_with(&f, &p, t, &sem, rule);
            prop_assert!(close(*got, want, 1e-9), "t={t} {f} ({rule:?}): got {got}, want {want}");
        }
    }

    /// ∂ρ/∂path equals central finite differences in the smooth modes.
    #[test]
    fn smooth_gradient_matches_finite_differences(f in formula(), p in path(), sem in semantics()) {
        prop_assume!(sem != Semantics::hard());
        check_gradient(&f, &p, &sem, false)?;
    }

    /// Hard mode: exact subgradient, equal to the derivative wherever ρ is
    /// differentiable (points where the two one-sided slopes differ are skipped).
    #[test]
    fn hard_gradient_matches_finite_differences(f in formula(), p in path()) {
        check_gradient(&f, &p, &Semantics::hard(), true)?;
    }

    /// Smooth modes approach hard ones as α grows or the temperature falls.
    #[test]
    fn smooth_modes_approach_hard(f in formula(), p in path()) {
        let spec = bind(f.clone());
        let hard = spec.robustness(&p, &Semantics::hard()).unwrap();
        // Soft max of n values is within n/(e·α) of the max; LSE within τ·ln n; errors
        // add up at most once per node, and the recursive until's once per pair (two
        // per step of the path).
        let n = (p.len() / 2).max(4) as f64;
        let size = f.size() as f64 + 2.0 * n;
        for alpha in [1e3, 1e5] {
            let soft = spec.robustness(&p, &Semantics::soft(alpha)).unwrap();
            prop_assert!((soft - hard).abs() <= size * n / alpha, "α={alpha}: {soft} vs {hard}");
        }
        for tau in [1e-3, 1e-5] {
            let lse = spec.robustness(&p, &Semantics::lse(tau)).unwrap();
            prop_assert!((lse - hard).abs() <= size * tau * n.ln() + 1e-9, "τ={tau}: {lse} vs {hard}");
        }
    }
}

fn check_gradient(f: &Formula, p: &[f64], sem: &Semantics, hard: bool) -> Result<(), TestCaseError> {
    let spec = bind(f.clone());
    let (rho, grad) = spec.gradient(p, sem).unwrap();
    // `true`/`false` are ±1e9: keep finite differences meaningful.
    prop_assume!(rho.abs() < 1e6);
    let h = 1e-6;
    for i in 0..p.len() {
        let mut q = p.to_vec();
        q[i] = p[i] + h;
        let up = spec.robustness(&q, sem).unwrap();
        q[i] = p[i] - h;
        let down = spec.robustness(&q, sem).unwrap();
        let (right, left) = ((up - rho) / h, (rho - down) / h);
        if hard && (right - left).abs() > 1e-4 {
            continue; // a kink: any value between the slopes is a subgradient
        }
        let fd = (up - down) / (2.0 * h);
        prop_assert!(
            (fd - grad[i]).abs() <= 1e-4 * (1.0 + fd.abs()),
            "{f} {sem}: d/dp[{i}] = {} vs fd {fd}",
            grad[i]
        );
    }
    Ok(())
}

// ---------------------------------------------------------------------------
// Hand-computed examples, one per operator
// ---------------------------------------------------------------------------

/// A path of scalar signal `x` (other signal `y` = 0).
fn xs(v: &[f64]) -> Vec<f64> {
    v.iter().flat_map(|&x| [x, 0.0]).collect()
}

fn hard(src: &str, x: &[f64]) -> (f64, Vec<f64>) {
    let spec = bind(parse(src).unwrap());
    let (r, g) = spec.gradient(&xs(x), &Semantics::hard()).unwrap();
    (r, g.iter().step_by(2).copied().collect())
}

#[test]
fn true_false_and_predicates() {
    assert_eq!(hard("true", &[0.0]).0, stl::semantics::DEFAULT_TOP);
    assert_eq!(hard("false", &[0.0]).0, -stl::semantics::DEFAULT_TOP);
    assert_eq!(hard("x > 0.5", &[2.0]), (1.5, vec![1.0]));
    assert_eq!(hard("x <= 0.5", &[2.0]), (-1.5, vec![-1.0]));
    assert_eq!(hard("!x > 0.5", &[2.0]), (-1.5, vec![-1.0]));
}

#[test]
fn and_or_implies_route_the_gradient_to_the_selected_operand() {
    // x at step 0 only: operands x−1 (=2) and 3−x... use Next to read another step.
    assert_eq!(hard("x > 1 & X x > 0", &[3.0, 1.0]), (1.0, vec![0.0, 1.0]));
    assert_eq!(hard("x > 1 | X x > 0", &[3.0, 1.0]), (2.0, vec![1.0, 0.0]));
    // φ ⇒ ψ = max(−φ, ψ): −(3−1) = −2 vs 1 → ψ.
    assert_eq!(hard("x > 1 -> X x > 0", &[3.0, 1.0]), (1.0, vec![0.0, 1.0]));
    // Ties go to the first operand.
    assert_eq!(hard("x > 0 & X x > 0", &[1.0, 1.0]), (1.0, vec![1.0, 0.0]));
}

#[test]
fn next_clamps_at_the_end() {
    assert_eq!(hard("X x > 0", &[1.0, 5.0]), (5.0, vec![0.0, 1.0]));
    assert_eq!(hard("X X X x > 0", &[1.0, 5.0]), (5.0, vec![0.0, 1.0]));
}

#[test]
fn eventually_and_globally_windows() {
    let x = [0.0, 4.0, 1.0, 3.0, 9.0];
    assert_eq!(hard("F[1,3] x > 0", &x), (4.0, vec![0.0, 1.0, 0.0, 0.0, 0.0]));
    assert_eq!(hard("G[1,3] x > 0", &x), (1.0, vec![0.0, 0.0, 1.0, 0.0, 0.0]));
    assert_eq!(hard("F x > 0", &x).0, 9.0);
    assert_eq!(hard("G[2,inf] x > 0", &x).0, 1.0);
    // A window past the end is cut at the last step; one starting past it is the last step.
    assert_eq!(hard("G[3,10] x > 0", &x).0, 3.0);
    assert_eq!(hard("F[7,9] x > 0", &x), (9.0, vec![0.0, 0.0, 0.0, 0.0, 1.0]));
}

#[test]
fn until_follows_app_c_when_asked() {
    // φ = x > 0, ψ = x > 5; the paper asks φ on [a, k−1] before ψ at k.
    let x = [-1.0, 2.0, 3.0, 7.0, 1.0];
    let paper = common::bind_with(parse("x > 0 U[1,3] x > 5").unwrap(), UntilRule::Paper);
    // k=1: min(ψ1=-3) ; k=2: min(ψ2=-2, φ1=2) = -2; k=3: min(ψ3=2, φ1=2, φ2=3) = 2.
    let (r, g) = paper.gradient(&xs(&x), &Semantics::hard()).unwrap();
    assert_eq!(r, 2.0);
    assert_eq!(
        g.iter().step_by(2).copied().collect::<Vec<_>>(),
        vec![0.0, 0.0, 0.0, 1.0, 0.0],
        "ties go to ψ"
    );
    // The standard reading also asks φ at t itself: φ_0 = −1 binds.
    assert_eq!(hard("x > 0 U[1,3] x > 5", &x), (-1.0, vec![1.0, 0.0, 0.0, 0.0, 0.0]));
    // With the window starting at 0 the two agree.
    assert_eq!(hard("x > 0 U[0,3] x > 5", &x), (-1.0, vec![1.0, 0.0, 0.0, 0.0, 0.0]));
    // The soft modes agree with the definitions on the same example.
    for rule in [UntilRule::Standard, UntilRule::Paper] {
        let spec = common::bind_with(parse("x > 0 U[1,3] x > 5").unwrap(), rule);
        for sem in [Semantics::soft(2.0), Semantics::lse(0.5)] {
            let got = spec.robustness(&xs(&x), &sem).unwrap();
            let want = common::reference_with(spec.formula(), &xs(&x), 0, &sem, rule);
            assert!((got - want).abs() < 1e-12);
        }
    }
}

#[test]
fn paper_coverage_example_app_d() {
    // ◇[0,2] A ∧ ◇[0,2] B on three waypoints: the gradient moves only the waypoint
    // closest to the goal that is furthest away (paper Fig. 9).
    let spec = stl::Spec::builder(parse("F[0,2] a & F[0,2] b").unwrap())
        .bind("a", stl::Ball::new([1.0, 0.0], 0.1))
        .bind("b", stl::Ball::new([0.0, 1.0], 0.1))
        .build()
        .unwrap();
    let path = [0.0, 0.0, 0.8, 0.0, 0.0, 0.5];
    let (rho, g) = spec.gradient(&path, &Semantics::hard()).unwrap();
    assert!((rho - (0.1 - 0.5)).abs() < 1e-12);
    assert_eq!(g, vec![0.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
}

#[test]
fn logic_only_smoothing_keeps_temporal_operators_hard() {
    let spec = bind(parse("F[0,3] x > 0").unwrap());
    let p = xs(&[0.0, 1.0, 2.0, 3.0]);
    let s = Semantics::soft(1.0).logic_only();
    assert_eq!(spec.robustness(&p, &s).unwrap(), 3.0);
    assert!(spec.robustness(&p, &Semantics::soft(1.0)).unwrap() < 3.0);
}

/// Regression: the smooth `until` was quadratic (`x>0 U y>2.999` at lse:0.5 took 10 s
/// on 3·10^4 rows). The recursive relaxation visits each step a bounded number of
/// times; on a long path it must agree with its own definition (small paths, the
/// property tests) and, at a low temperature, with hard mode.
#[test]
fn recursive_until_is_linear_and_close_to_hard_on_a_long_path() {
    let n = 30_000;
    let x: Vec<f64> = (0..n).map(|i| ((i * 7919) % 101) as f64 / 50.0 - 0.9).collect();
    let path: Vec<f64> =
        x.iter().enumerate().flat_map(|(i, &v)| [v, if i == 5 { 3.0 } else { 0.0 }]).collect();
    let spec = bind(parse("x > -1 U y > 2.999").unwrap());
    let hard = spec.robustness(&path, &Semantics::hard()).unwrap();
    let lse = spec.robustness(&path, &Semantics::lse(1e-3)).unwrap();
    assert!((hard - 0.001).abs() < 1e-9, "{hard}");
    // One pair's error per step at most: 2·τ·ln 2 · n bounds it loosely.
    assert!((lse - hard).abs() < 2.0 * 1e-3 * 2f64.ln() * n as f64, "{lse} vs {hard}");
    let (_, grad) = spec.gradient(&path, &Semantics::soft(2.0)).unwrap();
    assert!(grad.iter().all(|g| g.is_finite()));
    // The reaching step's y carries the gradient in both modes.
    assert!(grad[2 * 5 + 1] > 0.0);
}

#[test]
fn the_two_until_relaxations_are_named_in_text_and_agree_in_hard_mode() {
    let flat: Semantics = "soft:2,until=flat".parse().unwrap();
    assert_eq!(flat, Semantics::soft(2.0).with_until(UntilSmoothing::Flat));
    assert_eq!(flat.to_string(), "soft:2,until=flat");
    let rec: Semantics = "lse:0.5, until=recursive".parse().unwrap();
    assert_eq!(rec, Semantics::lse(0.5));
    assert_eq!(rec.to_string(), "lse:0.5");
    assert!("hard,until=flat".parse::<Semantics>().unwrap_err().to_string().contains("hard semantics"));
    assert!("soft:2,until=lazy".parse::<Semantics>().unwrap_err().to_string().contains("until=flat"));
    let spec = bind(parse("x > 0 U[1,3] x > 5").unwrap());
    let x = xs(&[-1.0, 2.0, 3.0, 7.0, 1.0]);
    let a = spec.gradient(&x, &Semantics::hard()).unwrap();
    let b = spec.gradient(&x, &Semantics::hard().with_until(UntilSmoothing::Flat)).unwrap();
    assert_eq!(a, b);
    // Smooth, they differ: two relaxations of one value.
    let r = spec.robustness(&x, &Semantics::soft(2.0)).unwrap();
    let f = spec.robustness(&x, &flat).unwrap();
    assert!((r - f).abs() > 1e-6, "{r} {f}");
}
