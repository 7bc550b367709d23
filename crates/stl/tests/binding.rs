//! Binding names, errors on bad specs and paths, predicates, and batches.

mod common;

use stl::{
    AfterStep, AvoidBoxes, Ball, EvalError, FnPredicate, Predicate, Semantics, Spec, SpecError, parse,
};

#[test]
fn unbound_name_is_an_error_that_names_it() {
    let err = Spec::builder(parse("F goal & x > 1").unwrap()).signals(["x"]).build().unwrap_err();
    assert_eq!(err, SpecError::Unbound { name: "goal".into(), signals: vec!["x".into()] });
    assert!(err.to_string().contains("'goal' is not bound"));
    assert_eq!(stl::locate_name("F goal & x > 1", "goal"), Some((1, 3)));
}

#[test]
fn ambiguous_dimension_and_threshold_errors() {
    let f = parse("x").unwrap();
    let err = Spec::builder(f).signals(["x"]).bind("x", Ball::new([0.0], 1.0)).build().unwrap_err();
    assert_eq!(err, SpecError::Ambiguous("x".into()));
    let err =
        Spec::builder(parse("g").unwrap()).state_dim(2).bind("g", Ball::new([0.0, 0.0, 0.0], 1.0)).build();
    assert!(matches!(err, Err(SpecError::Dimension { needs: 3, state_dim: 2, .. })));
    let f = stl::Formula::gt("x", f64::NAN);
    assert!(matches!(Spec::builder(f).signals(["x"]).build(), Err(SpecError::NonFiniteThreshold { .. })));
}

#[test]
fn bad_paths_and_semantics_are_errors() {
    let spec = common::bind(parse("F a").unwrap());
    assert_eq!(spec.robustness(&[], &Semantics::hard()), Err(EvalError::Empty));
    assert_eq!(
        spec.robustness(&[1.0, 2.0, 3.0], &Semantics::hard()),
        Err(EvalError::Shape { len: 3, dim: 2 })
    );
    assert!(matches!(spec.robustness(&[0.0, 0.0], &Semantics::soft(-1.0)), Err(EvalError::Semantics(_))));
    assert!(matches!(
        spec.robustness_batch(&[0.0; 6], 2, &Semantics::hard()),
        Err(EvalError::BatchShape { .. })
    ));
    assert!("soft:abc".parse::<Semantics>().is_err());
    assert!("lse:0".parse::<Semantics>().is_err());
    assert_eq!("soft:2".parse::<Semantics>().unwrap(), Semantics::soft(2.0));
}

#[test]
fn comparisons_apply_to_bound_predicates_too() {
    // `a > 0.2`: the goal predicate's value must exceed 0.2 (a tighter reach).
    let spec = common::bind(parse("a > 0.2").unwrap());
    let (r, g) = spec.gradient(&[1.0, 0.1], &Semantics::hard()).unwrap();
    assert!((r - (0.5 - 0.1 - 0.2)).abs() < 1e-12);
    assert!((g[1] + 1.0).abs() < 1e-12, "{g:?}");
}

fn fd_check(p: &dyn Predicate, x: &[f64]) {
    let mut g = vec![0.0; x.len()];
    p.value_and_grad(0, x, 1.0, &mut g);
    for i in 0..x.len() {
        let mut q = x.to_vec();
        q[i] += 1e-7;
        let up = p.value(0, &q);
        q[i] -= 2e-7;
        let down = p.value(0, &q);
        let fd = (up - down) / 2e-7;
        assert!((fd - g[i]).abs() < 1e-5, "{x:?} dim {i}: {} vs {fd}", g[i]);
    }
}

#[test]
fn box_obstacle_signed_distance_and_gradient() {
    let walls = AvoidBoxes::cubes(&[vec![0.0, 0.0], vec![0.5, 0.0], vec![3.0, 0.0]], 0.25, 0.1);
    // Outside: nearest box (0.5,0) is 0.45 away in x → 0.45 − margin.
    assert!((walls.value(0, &[1.2, 0.0]) - (0.45 - 0.1)).abs() < 1e-12);
    // Corner region: Euclidean distance to the corner.
    assert!((walls.value(0, &[1.05, 0.55]) - ((0.3f64.powi(2) + 0.3f64.powi(2)).sqrt() - 0.1)).abs() < 1e-12);
    // Inside: negative.
    assert!(walls.value(0, &[0.05, 0.1]) < 0.0);
    for x in [[1.2, 0.0], [1.05, 0.55], [0.05, 0.1], [-2.0, 1.0], [3.1, -0.05], [2.3, 0.7]] {
        fd_check(&walls, &x);
    }
    fd_check(&Ball::new([1.0, -1.0, 0.5], 0.3), &[0.2, 0.4, -0.1]);
}

#[test]
fn closures_and_time_predicates() {
    let sq = FnPredicate::new(2, |_, s| 1.0 - s[0] * s[0] - s[1] * s[1]);
    fd_check(&sq, &[0.3, -0.4]);
    let exact = FnPredicate::new(2, |_, s| s[0] * s[1]).with_gradient(|_, s, g| {
        g[0] = s[1];
        g[1] = s[0];
    });
    fd_check(&exact, &[0.3, -0.4]);
    // The Signal task's counter: false until step 10.
    let c = AfterStep { step: 10, truth: 1.0 };
    assert_eq!((c.value(9, &[]), c.value(10, &[])), (-1.0, 1.0));
    let spec = Spec::builder(parse("F counter").unwrap()).state_dim(1).bind("counter", c).build().unwrap();
    assert_eq!(spec.robustness(&[0.0; 5], &Semantics::hard()).unwrap(), -1.0);
    assert_eq!(spec.robustness(&[0.0; 11], &Semantics::hard()).unwrap(), 1.0);
    let c = AfterStep { step: 10, truth: 100.0 };
    assert_eq!((c.value(9, &[]), c.value(10, &[])), (-100.0, 100.0));
}

#[test]
fn batches_equal_single_paths() {
    let spec = common::bind(parse("F[1,2] a & G b -> c U[0,2] !b").unwrap());
    let steps = 5;
    let paths: Vec<f64> = (0..7 * steps * 2).map(|i| ((i * 7919) % 97) as f64 / 30.0 - 1.5).collect();
    for sem in [Semantics::hard(), Semantics::soft(2.0), Semantics::lse(0.3)] {
        let rs = spec.robustness_batch(&paths, steps, &sem).unwrap();
        let mut grads = vec![0.0; paths.len()];
        let rg = spec.gradient_batch(&paths, steps, &sem, &mut grads).unwrap();
        for (b, p) in paths.chunks(steps * 2).enumerate() {
            let (r, g) = spec.gradient(p, &sem).unwrap();
            assert_eq!(rs[b], r);
            assert_eq!(rg[b], r);
            assert_eq!(&grads[b * steps * 2..(b + 1) * steps * 2], &g[..]);
        }
        // The same gradient plus the hard robustness from the same predicate values.
        let mut both = vec![0.0; paths.len()];
        let (rb, hard) =
            spec.gradient_batch_and_robustness(&paths, steps, &sem, &mut both, &Semantics::hard()).unwrap();
        assert_eq!((rb, both), (rg, grads));
        assert_eq!(hard, spec.robustness_batch(&paths, steps, &Semantics::hard()).unwrap());
    }
}

/// Regression (Signal trained on 0/5 seeds): with a counter of `±1`, `φ U counter`
/// floored at `−1` and gave the loop body `φ` no gradient once `φ < −1`. With `⊥`
/// below every value of `φ`, the until reads `φ` and its gradient reaches it.
#[test]
fn until_a_counter_passes_the_gradient_of_a_badly_violated_left_side() {
    let until = |truth: f64| {
        Spec::builder(parse("x > 0 U[1,3] counter").unwrap())
            .until(stl::UntilRule::Paper)
            .signals(["x"])
            .bind("counter", AfterStep { step: 3, truth })
            .build()
            .unwrap()
    };
    // x = −5 throughout: the left side is violated by 5.
    let path = [-5.0; 4];
    let (rho, grad) = until(1.0).gradient(&path, &Semantics::hard()).unwrap();
    assert_eq!(rho, -1.0);
    assert!(grad.iter().all(|g| *g == 0.0), "the floor hides x: {grad:?}");
    let (rho, grad) = until(100.0).gradient(&path, &Semantics::hard()).unwrap();
    assert_eq!(rho, -5.0);
    assert!(grad.iter().any(|g| *g != 0.0), "x gets a gradient: {grad:?}");
}

#[test]
fn constant_specs_evaluate_in_batches_under_two_semantics() {
    // `schrl train` on a task whose spec was only `true` panicked here: re-evaluating
    // under a second semantics read the step count from the predicate values, of
    // which a spec without predicates has none.
    for (text, sign) in [("true", 1.0), ("false", -1.0)] {
        let spec = Spec::builder(parse(text).unwrap()).signals(["x", "y"]).build().unwrap();
        let paths = vec![0.5; 2 * 3 * 2];
        let mut grads = vec![0.0; paths.len()];
        let (rho, hard) = spec
            .gradient_batch_and_robustness(&paths, 3, &Semantics::soft(10.0), &mut grads, &Semantics::hard())
            .unwrap();
        assert_eq!(rho.len(), 2);
        assert!(rho.iter().chain(&hard).all(|r| r * sign > 0.0), "{text}: {rho:?} {hard:?}");
        assert!(grads.iter().all(|g| *g == 0.0));
    }
    let spec = Spec::builder(parse("true").unwrap()).signals(["x"]).build().unwrap();
    assert_eq!(spec.evaluator().reevaluate(0, &Semantics::hard()), Err(EvalError::Empty));
}
