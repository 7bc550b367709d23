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
    let pred = net.clone().clearance(0.1);
    for p in [[1.3, 0.7], [-2.0, 0.4], [0.1, -2.6]] {
        let mut g = [0.0; 2];
        let v = pred.value_and_grad(0, &p, 1.0, &mut g);
        assert!((v - (net.distance(&p) - 0.1)).abs() < 1e-12);
        for k in 0..2 {
            let h = 1e-5;
            let (mut a, mut b) = (p, p);
            a[k] += h;
            b[k] -= h;
            let fd = (pred.value(0, &a) - pred.value(0, &b)) / (2.0 * h);
            assert!((fd - g[k]).abs() < 1e-5, "∂/∂x{k} at {p:?}: {} vs {fd}", g[k]);
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
    let dir = std::env::temp_dir().join(format!("schrl-neural-sdf-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
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
