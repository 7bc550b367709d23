//! Regions a spec says to stay out of hold between waypoints: the planner's spec sees
//! them on the straight segments, and an executed run is judged on every step of its
//! trajectory (`schrl::task::along`). Built from hand-made paths that cross a region
//! between waypoints whose own positions are all outside it.

use std::path::Path;

use schrl::task::Task;
use stl::Semantics;

/// The shipped example (examples/tasks/keys.toml): key_a by waypoint 2, key_b by 4,
/// home by 6, out of the hazard throughout.
fn keys() -> Task {
    let t = keys_with("F[1,2] key_a & F[3,4] key_b & F[5,6] home & G[1,6] !hazard & G[1,6] safe");
    assert_eq!(t.formula, example().formula, "the shipped example changed");
    t
}

fn example() -> Task {
    let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/tasks/keys.toml");
    Task::from_file(&file).unwrap_or_else(|e| panic!("{e}"))
}

/// The example with another spec.
fn keys_with(spec: &str) -> Task {
    Task::from_texts(Path::new("keys.toml"), &example().toml, Path::new("keys.stl"), spec)
        .unwrap_or_else(|e| panic!("{e}"))
}

/// Waypoints through the door at (2, 0) straight up to the top key and back: every
/// waypoint is 1 m from the hazard at (2, 1), both segments cross its centre.
const THROUGH: [[f64; 2]; 7] =
    [[1.5, -1.5], [2.0, 0.0], [2.0, 2.0], [2.0, 0.0], [2.0, -2.0], [0.0, -2.0], [-2.0, -2.0]];
/// The same visits passing the hazard on its right.
const AROUND: [[f64; 2]; 7] =
    [[1.5, -1.5], [2.55, 0.0], [2.45, 2.0], [2.55, 0.0], [2.0, -2.0], [0.0, -2.0], [-2.0, -2.0]];

fn flat(path: &[[f64; 2]]) -> Vec<f64> {
    path.concat()
}

fn hard(task: &Task, path: &[[f64; 2]]) -> f64 {
    task.spec().robustness(&flat(path), &Semantics::hard()).unwrap()
}

#[test]
fn avoid_regions_are_the_negated_goals_of_clauses_that_hold_over_a_window() {
    let names =
        |spec: &str| keys_with(spec).avoid_regions().iter().map(|g| g.name.clone()).collect::<Vec<_>>();
    assert_eq!(names("F[1,2] key_a & G[1,6] !hazard & G[1,6] safe"), ["hazard"]);
    assert_eq!(names("G[1,6] (safe & !hazard)"), ["hazard"]);
    assert_eq!(names("G[1,6] !(hazard | key_b)"), ["hazard", "key_b"]);
    assert_eq!(names("!hazard U[1,6] key_a"), ["hazard"]);
    assert_eq!(names("F[1,3] G[0,2] !hazard"), ["hazard"]);
    // Reaching is read at waypoints, and so is every clause that is not a promise to
    // stay out: being at one of several places, an implication, a single step.
    assert!(names("F[1,6] key_a & G[1,6] (key_a | key_b)").is_empty());
    assert!(names("G[1,5] (key_a -> !X key_a)").is_empty());
    assert!(names("F[1,6] !hazard & !key_a").is_empty());
    // Every shipped task reads its goals at waypoints, as the paper does.
    for robot in ["point", "car", "doggo", "drone"] {
        for kind in schrl::task::TaskKind::ALL {
            let t = Task::builtin(robot, kind).unwrap();
            assert!(t.avoid_regions().is_empty(), "{robot} {}", kind.name());
            assert_eq!(t.planning_formula(), t.formula);
        }
    }
}

#[test]
fn a_plan_crossing_the_hazard_between_waypoints_violates_the_spec() {
    let task = keys();
    for p in THROUGH {
        assert!(((p[0] - 2.0f64).powi(2) + (p[1] - 1.0).powi(2)).sqrt() > 0.9, "{p:?} is outside the hazard");
    }
    // Read at the waypoints only (the paper's literal reading), the crossing plan holds...
    let literal = keys().formula;
    let at_waypoints = task
        .predicates()
        .into_iter()
        .fold(stl::Spec::builder(literal).state_dim(2), |b, (n, p)| b.bind_shared(n, p))
        .build()
        .unwrap();
    assert!(at_waypoints.robustness(&flat(&THROUGH), &Semantics::hard()).unwrap() > 0.0);
    // ...along the segments it misses the hazard by minus its radius.
    let rho = hard(&task, &THROUGH);
    assert!((rho + 0.4).abs() < 1e-9, "{rho}");
    assert!(hard(&task, &AROUND) > 0.0, "{}", hard(&task, &AROUND));
    // The batched tensor spec the planner trains on agrees.
    let paths = candle_core::Tensor::from_vec(
        [flat(&THROUGH), flat(&AROUND)].concat().iter().map(|x| *x as f32).collect::<Vec<_>>(),
        (2, 7, 2),
        &candle_core::Device::Cpu,
    )
    .unwrap();
    let tensor: Vec<f32> =
        task.tensor_spec().robustness(&paths, &Semantics::hard()).unwrap().to_vec1().unwrap();
    assert!((tensor[0] as f64 - rho).abs() < 1e-5 && tensor[1] > 0.0, "{tensor:?}");
}

#[test]
fn the_segment_gradient_pushes_the_path_out_of_the_region() {
    let task = keys_with("G[1,6] !hazard");
    let spec = task.spec();
    // Off-centre crossings (the closest points strictly inside the segments, the
    // way up the deeper one, so the hard minimum is unique).
    let mut path = flat(&THROUGH);
    path[2] = 1.9;
    path[6] = 2.2;
    let sem = Semantics::hard();
    let (rho, grad) = spec.gradient(&path, &sem).unwrap();
    for (i, g) in grad.iter().enumerate() {
        let h = 1e-6;
        let mut up = path.clone();
        up[i] += h;
        let mut down = path.clone();
        down[i] -= h;
        let fd = (spec.robustness(&up, &sem).unwrap() - spec.robustness(&down, &sem).unwrap()) / (2.0 * h);
        assert!((fd - g).abs() < 1e-5, "∂ρ/∂x[{i}]: {g} vs {fd}");
    }
    // One step along the gradient moves the crossing away from the hazard.
    let stepped: Vec<f64> = path.iter().zip(&grad).map(|(x, g)| x + 0.05 * g).collect();
    assert!(spec.robustness(&stepped, &sem).unwrap() > rho);
}

/// A trajectory of 8 steps per segment along straight lines through `points`, and
/// the steps at which each point after the first was reached.
fn drive(points: &[[f64; 2]]) -> (Vec<Vec<f64>>, Vec<usize>) {
    let mut traj = vec![points[0].to_vec()];
    let mut reached_at = vec![];
    for w in points.windows(2) {
        for k in 1..=8 {
            let s = k as f64 / 8.0;
            traj.push(vec![w[0][0] + s * (w[1][0] - w[0][0]), w[0][1] + s * (w[1][1] - w[0][1])]);
        }
        reached_at.push(traj.len() - 1);
    }
    (traj, reached_at)
}

#[test]
fn a_run_that_enters_the_hazard_between_waypoints_fails_and_says_where() {
    let task = keys();
    let spec = task.execution_spec();
    // Executed positions are the AROUND waypoints, but the robot drove through the
    // hazard on the way to the top key (8 steps per leg, so the second leg is steps
    // 9..=16; up x = 2 from y = 0.25 in steps of 0.25, it is inside at y = 0.75).
    let executed: Vec<Vec<f64>> = AROUND.iter().map(|p| p.to_vec()).collect();
    let (mut traj, reached_at) = drive(&AROUND);
    for (k, s) in (9..=15).enumerate() {
        traj[s] = vec![2.0, 0.25 * (k + 1) as f64];
    }
    let judged = spec.judge(&executed, &traj, &reached_at);
    assert!(judged.robustness < 0.0, "{}", judged.robustness);
    let entry = judged.entered.expect("the entry is named");
    assert_eq!(entry.to_string(), "entered hazard at step 11");
    // Driven as planned: satisfied, nothing entered.
    let (clean, reached_at) = drive(&AROUND);
    let judged = spec.judge(&executed, &clean, &reached_at);
    assert!(judged.robustness > 0.0 && judged.entered.is_none(), "{judged:?}");
}

#[test]
fn entering_a_region_outside_its_clause_window_does_not_fail_the_run() {
    // `G[3,6] !hazard`: out of the hazard from reaching waypoint 2 on. Crossing it on
    // the way up to the top key (segment 2, inside at step 11) is allowed; crossing it
    // on the way back down (segment 3: steps 17..=24, inside at y = 1.25, step 19) is not.
    let task = keys_with("F[1,2] key_a & F[3,4] key_b & F[5,6] home & G[3,6] !hazard");
    let spec = task.execution_spec();
    let executed: Vec<Vec<f64>> = THROUGH.iter().map(|p| p.to_vec()).collect();
    let (traj, reached_at) = drive(&THROUGH);
    let j = spec.judge(&executed, &traj, &reached_at);
    assert!(j.robustness < 0.0 && j.entered.as_ref().map(|e| e.step) == Some(19), "{j:?}");
    // From reaching waypoint 3 on, the path stays clear.
    let task = keys_with("F[1,2] key_a & F[3,4] key_b & F[5,6] home & G[4,6] !hazard");
    let j = task.execution_spec().judge(&executed, &traj, &reached_at);
    assert!(j.robustness > 0.0 && j.entered.is_none(), "{j:?}");
}

#[test]
fn a_run_failing_for_another_reason_is_not_blamed_on_the_region() {
    let task = keys();
    let spec = task.execution_spec();
    // Through the hazard, and never at the bottom key in its window (waypoints 3–4):
    // that fails it whatever the hazard.
    let wrong = [THROUGH[0], [2.0, 0.0], [2.0, 2.0], [2.0, 0.0], [2.0, 0.0], [0.0, -2.0], [-2.0, -2.0]];
    let executed: Vec<Vec<f64>> = wrong.iter().map(|p| p.to_vec()).collect();
    let (traj, reached_at) = drive(&wrong);
    let j = spec.judge(&executed, &traj, &reached_at);
    assert!(j.robustness < 0.0 && j.entered.is_none(), "{j:?}");
}

#[test]
fn the_planner_keeps_a_margin_from_regions_to_avoid_and_never_shrinks_them() {
    // Regression (Point keys seed 0): the goal margin shrank the hazard with the goals,
    // plans grazed it, and 86 % of runs cut into it on the controller's curves.
    let task = keys_with("G[1,6] !hazard");
    let planned = task.with_goal_margin(0.3).with_safe_margin(0.1);
    let hazard = |t: &Task| t.goals.iter().find(|g| g.name == "hazard").unwrap().radius;
    assert_eq!(hazard(&planned), hazard(&task));
    assert!(planned.goals.iter().filter(|g| g.name != "hazard").all(|g| g.radius < 0.5));
    // A path passing 0.45 m from the hazard's centre: clear of it by 5 cm, which is
    // enough for the run but not for the planner's 10 cm margin.
    let mut path = flat(&AROUND);
    path[2] = 2.45;
    path[4] = 2.45;
    path[6] = 2.45;
    let rho = |t: &Task| t.spec().robustness(&path, &Semantics::hard()).unwrap();
    assert!((rho(&task) - 0.05).abs() < 1e-9, "{}", rho(&task));
    assert!((rho(&planned) + 0.05).abs() < 1e-9, "{}", rho(&planned));
}
