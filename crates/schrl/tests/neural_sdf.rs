//! Neural signed-distance predicates: the fit, saving and loading, and gradients
//! through robustness.

use schrl::store;
use schrl::task::neural_sdf::{NeuralSdf, SdfFitConfig};
use sim::Map;
use stl::{Predicate, Semantics, Spec};

fn fitted() -> (NeuralSdf, schrl::task::neural_sdf::FitReport) {
    // A short fit: the direction is what matters here (the default fit reaches
    // 1.9 cm mean error, 99 % sign agreement; README).
    NeuralSdf::fit(&Map::by_name("walls").unwrap(), &SdfFitConfig { steps: 2000, ..Default::default() })
        .unwrap()
}

#[test]
fn fit_learns_the_walls_distance() {
    let (net, report) = fitted();
    assert!(report.mean_abs_error < 0.1, "{report:?}");
    assert!(report.sign_agreement > 0.95, "{report:?}");
    // Inside a wall negative, in a room's middle positive and near the exact value.
    assert!(net.distance(&[0.0, 0.0]) < 0.0);
    let exact = Map::by_name("walls").unwrap().sdf(&[2.0, 2.0]);
    assert!((net.distance(&[2.0, 2.0]) - exact).abs() < 0.3, "{} vs {exact}", net.distance(&[2.0, 2.0]));
    // An untrained network (no steps) is far worse: the fit is what made it good.
    let (_, untrained) =
        NeuralSdf::fit(&Map::by_name("walls").unwrap(), &SdfFitConfig { steps: 1, ..Default::default() })
            .unwrap();
    assert!(untrained.mean_abs_error > 3.0 * report.mean_abs_error, "{untrained:?}");
}

#[test]
fn maps_without_obstacles_have_nothing_to_learn() {
    let err = NeuralSdf::fit(&Map::by_name("empty").unwrap(), &SdfFitConfig::default()).unwrap_err();
    assert!(err.contains("no obstacle"), "{err}");
}

#[test]
fn input_gradient_matches_finite_differences_and_flows_through_robustness() {
    let (net, _) = fitted();
    let pred = std::sync::Arc::new(net.clone()).clearance(0.1);
    for p in [[1.3, 0.7], [-2.0, 0.4], [0.1, -2.6]] {
        let mut g = [0.0; 2];
        let v = pred.value_and_grad(0, &p, 1.0, &mut g);
        assert!((v - (net.distance(&p) - 0.1)).abs() < 1e-12);
        for k in 0..2 {
            // The network runs in f32 (the kernel it was fitted with): steps of 1e-3.
            let h = 1e-3;
            let (mut a, mut b) = (p, p);
            a[k] += h;
            b[k] -= h;
            let fd = (pred.value(0, &a) - pred.value(0, &b)) / (2.0 * h);
            assert!((fd - g[k]).abs() < 2e-3, "∂/∂x{k} at {p:?}: {} vs {fd}", g[k]);
        }
    }
    // Bound as `safe` in G safe over a 3-state path: the spec's gradient is the
    // network's, on the waypoint that decides the minimum.
    let spec =
        Spec::builder(stl::parse("G[0,2] safe").unwrap()).state_dim(2).bind("safe", pred).build().unwrap();
    let path = [2.0, 2.0, 1.6, 0.5, 2.0, -2.0];
    let (rho, grad) = spec.gradient(&path, &Semantics::hard()).unwrap();
    let worst = (0..3).map(|t| net.distance(&path[2 * t..2 * t + 2]) - 0.1).fold(f64::INFINITY, f64::min);
    assert!((rho - worst).abs() < 1e-12);
    let mut g = [0.0; 2];
    net.distance_and_grad(&path[2..4], &mut g);
    assert!((grad[2] - g[0]).abs() < 1e-12 && (grad[3] - g[1]).abs() < 1e-12, "{grad:?}");
}

#[test]
fn saves_loads_and_refuses_bad_files() {
    let (net, _) =
        NeuralSdf::fit(&Map::by_name("duck").unwrap(), &SdfFitConfig { steps: 50, ..Default::default() })
            .unwrap();
    let scratch = tempfile::tempdir().unwrap();
    let dir = scratch.path();
    let path = dir.join("duck.json");
    let _ = std::fs::remove_file(&path);
    store::sdf::save(&net, &path, false).unwrap();
    assert_eq!(store::sdf::load(&path).unwrap(), net);
    assert!(store::sdf::save(&net, &path, false).unwrap_err().to_string().contains("already exists"));
    store::sdf::save(&net, &path, true).unwrap();
    // A truncated parameter list is named as such, with the file.
    let mut bad = net.clone();
    bad.params.pop();
    std::fs::write(&path, serde_json::to_string(&bad).unwrap()).unwrap();
    let err = store::sdf::load(&path).unwrap_err().to_string();
    assert!(err.contains("duck.json") && err.contains("parameters"), "{err}");
    assert!(store::sdf::load(&dir.join("missing.json")).unwrap_err().to_string().contains("missing.json"));
    // The duck is 3-D and is checked against its own map only.
    assert!(net.evaluate(&Map::by_name("walls").unwrap(), 1, 10).is_err());
}

fn duck_net() -> std::sync::Arc<NeuralSdf> {
    let (net, _) =
        NeuralSdf::fit(&Map::by_name("duck").unwrap(), &SdfFitConfig { steps: 2000, ..Default::default() })
            .unwrap();
    std::sync::Arc::new(net)
}

/// Along a segment the network's clearance is its smallest sampled distance: through
/// the duck negative, past it positive and near the exact segment distance; its
/// gradient moves both ends (finite differences), and the forward-only distance
/// equals the one computed with the gradient.
#[test]
fn neural_clearance_along_segments_follows_the_exact_segment_distance() {
    use schrl::task::SafeAlong;
    let net = duck_net();
    let map = Map::by_name("duck").unwrap();
    let pred = net.clearance(0.0).along(SafeAlong::Segments);
    let through = [-1.5, 0.0, 0.5, 1.5, 0.0, 0.5];
    assert!(pred.value_on_path(&through, 3, 1) < -0.2, "{}", pred.value_on_path(&through, 3, 1));
    // At the waypoint alone (the path's ends are outside the duck) it is positive.
    assert!(net.clearance(0.0).value_on_path(&through, 3, 1) > 0.0);
    let past = [-2.0, 1.5, 1.0, 1.93, 1.45, 1.1];
    let (v, exact) = (pred.value_on_path(&past, 3, 1), map.segment_sdf(&past[..3], &past[3..]));
    assert!(v > 0.0 && (v - exact).abs() < 0.15, "{v} vs exact {exact}");
    let mut g = [0.0; 6];
    let value = pred.value_and_grad_on_path(&past, 3, 1, 1.0, &mut g);
    assert!((value - v).abs() < 1e-5, "{value} vs {v}");
    for k in 0..6 {
        let (mut a, mut b) = (past, past);
        a[k] += 1e-3;
        b[k] -= 1e-3;
        let fd = (pred.value_on_path(&a, 3, 1) - pred.value_on_path(&b, 3, 1)) / 2e-3;
        assert!((fd - g[k]).abs() < 5e-3, "∂/∂x{k}: {} vs {fd}", g[k]);
    }
    for p in [[0.3, -1.2, 0.8], [2.0, 2.0, 2.0], [0.0, 0.0, 0.5]] {
        let mut g = [0.0; 3];
        assert!((net.distance(&p) - net.distance_and_grad(&p, &mut g)).abs() < 1e-12);
    }
}

/// A task planned with a neural obstacle binds `safe` to the network, while the
/// spec runs are judged by keeps the exact geometry; a network of another map is
/// refused, naming both maps.
#[test]
fn a_neural_obstacle_is_what_the_planner_sees_not_what_runs_are_judged_by() {
    use schrl::task::{ObstacleModel, Task, TaskKind};
    let net = duck_net();
    let task = Task::builtin("drone", TaskKind::Seq).unwrap();
    let planned = task.with_obstacle(ObstacleModel::Neural(net.clone())).unwrap();
    let safe = stl::parse("G[1,1] safe").unwrap();
    // A path whose one segment grazes the duck: the two distances differ there.
    let path = [-1.8, 0.2, 0.6, 1.8, 0.9, 1.2];
    let hard = Semantics::hard();
    let exact = task.spec_of(safe.clone()).robustness(&path, &hard).unwrap();
    let neural = planned.spec_of(safe).robustness(&path, &hard).unwrap();
    let sampled = net.clearance(task.safe_radius).along(task.safe_along).value_on_path(&path, 3, 1);
    assert!((neural - sampled).abs() < 1e-12 && (neural - exact).abs() > 1e-6, "{neural} {exact}");
    // Judging: a task whose spec is `safe` alone, run near the duck, is judged on
    // the exact distance at the reached positions whichever obstacle the planner saw.
    let only_safe = Task::from_texts(
        std::path::Path::new("safe.toml"),
        &task.toml,
        std::path::Path::new("safe.stl"),
        "G[1,8] safe",
    )
    .unwrap();
    let positions: Vec<Vec<f64>> =
        (0..=8).map(|i| vec![0.25 * i as f64 - 1.0, 0.75 + 0.02 * i as f64, 0.6]).collect();
    let reached: Vec<usize> = (1..=8).collect();
    let judged = |t: &Task| t.execution_spec().judge(&positions, &positions, &reached).robustness;
    let map = Map::by_name("duck").unwrap();
    let truth = positions[1..].iter().map(|p| map.sdf(p) - task.safe_radius).fold(f64::INFINITY, f64::min);
    let seen =
        positions[1..].iter().map(|p| net.distance(p) - task.safe_radius).fold(f64::INFINITY, f64::min);
    assert!((seen - truth).abs() > 1e-6, "the network should differ from the exact distance here");
    let with_net = only_safe.with_obstacle(ObstacleModel::Neural(net.clone())).unwrap();
    assert!((judged(&only_safe) - truth).abs() < 1e-9, "{} vs {truth}", judged(&only_safe));
    assert_eq!(judged(&with_net), judged(&only_safe));
    let (walls, _) =
        NeuralSdf::fit(&Map::by_name("walls").unwrap(), &SdfFitConfig { steps: 1, ..Default::default() })
            .unwrap();
    let err = task.with_obstacle(ObstacleModel::Neural(std::sync::Arc::new(walls))).unwrap_err();
    assert!(err.contains("walls") && err.contains("duck"), "{err}");
}
