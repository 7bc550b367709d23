//! The MIP planner: optima known by hand, specs no plan satisfies, and the program's
//! robustness against the exact robustness of the plan it returns.

use std::path::Path;

use schrl::plan::mip::{self, MipConfig, MipError};
use schrl::task::{Task, TaskKind};

/// Two goals 4 m apart on the open plane, and a hazard between them.
const OPEN: &str = r#"
name = "open"
robot = "point"
map = "empty"
spec = "open.stl"
steps = 4
step_limit = 1000
safe_radius = 0.1

[start]
low = [-3.0, -1.0]
high = [-3.0, -1.0]

[[goal]]
name = "a"
center = [2.0, 0.0]
radius = 0.5

[[goal]]
name = "b"
center = [-2.0, 0.0]
radius = 0.5

[[goal]]
name = "hazard"
center = [0.0, 0.0]
radius = 1.0
"#;

fn open(spec: &str) -> Task {
    Task::from_texts(Path::new("open.toml"), OPEN, Path::new("open.stl"), spec)
        .unwrap_or_else(|e| panic!("{e}"))
}

fn plan(task: &Task, start: [f64; 2]) -> mip::MipPlan {
    mip::plan(task, &start, &MipConfig::default()).unwrap_or_else(|e| panic!("{e}"))
}

fn waypoint(p: &mip::MipPlan, t: usize) -> [f64; 2] {
    [p.path[2 * t], p.path[2 * t + 1]]
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

#[test]
fn a_sequence_on_the_open_plane_puts_each_visit_at_the_goal_centre() {
    // The best robustness of reaching a disc is its radius, at the centre; the
    // inscribed polygon is exact there.
    let p = plan(&open("F[1,2] a & F[3,4] b"), [-3.0, -1.0]);
    assert!(p.optimal);
    assert!(close(p.program_robustness, 0.5, 1e-6), "{}", p.program_robustness);
    assert!(close(p.robustness, 0.5, 1e-6), "{}", p.robustness);
    let at = |c: [f64; 2]| {
        (1..=4).any(|t| close(waypoint(&p, t)[0], c[0], 1e-6) && close(waypoint(&p, t)[1], c[1], 1e-6))
    };
    assert!(at([2.0, 0.0]) && at([-2.0, 0.0]), "{:?}", p.path);
    // The first visit within the first two waypoints, the second in the next two.
    let dist = |t: usize, c: [f64; 2]| (waypoint(&p, t)[0] - c[0]).hypot(waypoint(&p, t)[1] - c[1]);
    assert!((1..=2).any(|t| dist(t, [2.0, 0.0]) < 0.5) && (3..=4).any(|t| dist(t, [-2.0, 0.0]) < 0.5));
}

#[test]
fn a_spec_no_plan_satisfies_comes_back_with_its_best_negative_robustness() {
    // In both discs at waypoint 1: the best is midway, 2 m from each centre,
    // robustness 0.5 − 2. The polygons' face normals point along the x axis, where they
    // are lowest: 0.5 − 2 / cos(π/16), reached on the faces they share at x = 0
    // (|y| ≤ 2 tan(π/16)).
    let p = plan(&open("F[1,1] a & F[1,1] b"), [-3.0, -1.0]);
    assert!(p.optimal && !p.satisfied());
    let polygon = 0.5 - 2.0 / (std::f64::consts::PI / 16.0).cos();
    assert!(close(p.program_robustness, polygon, 1e-6), "{}", p.program_robustness);
    let w = waypoint(&p, 1);
    assert!(
        close(w[0], 0.0, 1e-6) && w[1].abs() <= 2.0 * (std::f64::consts::PI / 16.0).tan() + 1e-6,
        "{w:?}"
    );
    assert!(p.robustness >= p.program_robustness - 1e-9 && p.robustness <= -1.5 + 1e-9, "{}", p.robustness);
}

#[test]
fn staying_out_of_a_region_between_waypoints_routes_around_it() {
    // From b's side to a, out of the hazard along every segment: the straight line
    // crosses it, so the plan bends; robustness is bounded by the goal's radius.
    let task = open("F[3,4] a & G[1,4] !hazard");
    let p = plan(&task, [-3.0, 0.0]);
    assert!(p.satisfied(), "{p:?}");
    // Sound: the program never claims more than the plan has.
    assert!(p.program_robustness <= p.robustness + 1e-9);
    for t in 1..=4 {
        let (a, b) = (waypoint(&p, t - 1), waypoint(&p, t));
        // Every point of the segment at least the hazard's radius from its centre.
        for s in 0..=20 {
            let q = [a[0] + (b[0] - a[0]) * s as f64 / 20.0, a[1] + (b[1] - a[1]) * s as f64 / 20.0];
            assert!(q[0].hypot(q[1]) >= 1.0 - 1e-6, "segment {t} enters the hazard at {q:?}");
        }
    }
}

#[test]
fn until_and_negation_match_the_exact_semantics() {
    // Stay out of a until reaching b; then reach a: negation is pushed through U.
    for spec in ["(!a U[1,2] b) & F[3,4] a", "!(F[1,4] hazard) & F[1,4] a", "G[1,3] (a -> X b) & F[1,3] a"] {
        let p = plan(&open(spec), [-3.0, -1.0]);
        assert!(p.optimal, "{spec}");
        assert!(p.program_robustness <= p.robustness + 1e-9, "{spec}: {p:?}");
        // Low by at most the polygons' error: 8 tangent directions at a few metres.
        assert!(p.robustness - p.program_robustness < 0.3, "{spec}: {p:?}");
        assert!(p.satisfied(), "{spec}: {p:?}");
    }
}

#[test]
fn point_seq_is_solved_through_the_doors_at_the_goal_radius() {
    let task = Task::point(TaskKind::Seq);
    let p = plan(&task, [1.5, -1.5]);
    assert!(p.optimal);
    // 0.5 is the goals' radius: every visit at a centre, every segment clear.
    assert!(close(p.robustness, 0.5, 1e-6) && close(p.program_robustness, 0.5, 1e-6), "{p:?}");
    let clearance = task.map.clone();
    for t in 1..=task.steps {
        let (a, b) = (waypoint(&p, t - 1), waypoint(&p, t));
        assert!(clearance.segment_sdf(&a, &b) >= task.safe_radius - 1e-9, "segment {t} cuts a wall");
    }
}

#[test]
fn what_the_encoding_does_not_cover_is_a_clear_error() {
    let drone = Task::builtin("drone", TaskKind::Seq).unwrap();
    let e = mip::plan(&drone, &[0.0, 0.0, 1.0], &MipConfig::default()).unwrap_err();
    assert!(matches!(e, MipError::Unsupported(_)) && e.to_string().contains("2-D"), "{e}");
    let walls = Task::point(TaskKind::Seq);
    let inside =
        Task::from_texts(Path::new("w.toml"), &walls.toml, Path::new("w.stl"), "F[1,8] !safe").unwrap();
    let e = mip::plan(&inside, &[1.5, -1.5], &MipConfig::default()).unwrap_err();
    assert!(e.to_string().contains("!safe"), "{e}");
    let bad = MipConfig { sides: 2, ..MipConfig::default() };
    let e = mip::plan(&walls, &[1.5, -1.5], &bad).unwrap_err();
    assert!(e.to_string().contains("mip.sides"), "{e}");
}

#[test]
fn a_robustness_cap_gives_a_shorter_plan_at_least_that_robust() {
    let task = open("F[1,2] a & F[3,4] b");
    let length = |p: &mip::MipPlan| {
        (1..=4)
            .map(|t| {
                let (a, b) = (waypoint(p, t - 1), waypoint(p, t));
                (a[0] - b[0]).hypot(a[1] - b[1])
            })
            .sum::<f64>()
    };
    let most = plan(&task, [-3.0, -1.0]);
    let capped =
        mip::plan(&task, &[-3.0, -1.0], &MipConfig { robustness_cap: Some(0.2), ..MipConfig::default() })
            .unwrap_or_else(|e| panic!("{e}"));
    assert!(capped.robustness >= 0.2 - 1e-6 && capped.program_robustness >= 0.2 - 1e-6, "{capped:?}");
    assert!(capped.robustness < most.robustness);
    // Each visit 0.3 m short of a centre it no longer has to reach.
    assert!(length(&capped) < length(&most) - 0.5, "{} vs {}", length(&capped), length(&most));
    let bad = MipConfig { robustness_cap: Some(-1.0), ..MipConfig::default() };
    let e = mip::plan(&task, &[-3.0, -1.0], &bad).unwrap_err();
    assert!(e.to_string().contains("mip.robustness_cap"), "{e}");
}

#[test]
fn shortest_chooses_the_near_goal_the_most_robust_plan_passes_over() {
    // From (2.8, 0) goal a (radius 0.5) is 0.8 m away, the wider hazard disc (radius
    // 1) 2.8 m: the most robust plan goes to the hazard's centre (robustness 1); the
    // shortest at least 0.4 robust stops 0.4 m inside a.
    let task = open("F[1,4] (a | hazard)");
    let start = [2.8, 0.0];
    let most = plan(&task, start);
    assert!(close(most.robustness, 1.0, 1e-6), "{most:?}");
    let near = |p: &mip::MipPlan| (1..=4).any(|t| (waypoint(p, t)[0] - 2.0).hypot(waypoint(p, t)[1]) < 0.5);
    assert!(!near(&most), "{:?}", most.path);
    let cfg = MipConfig { robustness_cap: Some(0.4), shortest: true, ..MipConfig::default() };
    let short = mip::plan(&task, &start, &cfg).unwrap_or_else(|e| panic!("{e}"));
    assert!(short.optimal && short.robustness >= 0.4 - 1e-6, "{short:?}");
    assert!(near(&short), "{:?}", short.path);
    let length: f64 = (1..=4)
        .map(|t| {
            let (a, b) = (waypoint(&short, t - 1), waypoint(&short, t));
            (a[0] - b[0]).abs() + (a[1] - b[1]).abs()
        })
        .sum();
    assert!(length < 0.75, "{length} m: {:?}", short.path);
}

#[test]
fn alternating_between_goals_is_solved_through_claims() {
    // Loop's shape on two goals: at a goal at every waypoint, never the same one twice
    // in a row. The best plan alternates between the centres (robustness 0.5, the
    // radius); keeping out of one goal is decided by the claim to be in the other.
    let spec = "G[1,4] (a | b) & G[1,3] ((a -> !X a) & (b -> !X b))";
    let p = plan(&open(spec), [-3.0, -1.0]);
    assert!(p.optimal && p.satisfied(), "{p:?}");
    assert!(close(p.program_robustness, 0.5, 1e-6) && close(p.robustness, 0.5, 1e-6), "{p:?}");
    let goal = |t: usize| if waypoint(&p, t)[0] > 0.0 { 'a' } else { 'b' };
    for t in 1..4 {
        assert_ne!(goal(t), goal(t + 1), "{:?}", p.path);
    }
    // Keeping out of the hazard at a waypoint the plan cannot spend at a goal: the
    // claims are lower bounds there too.
    let p = plan(&open("F[1,1] !hazard & G[1,2] !a & F[2,2] b"), [1.0, 1.5]);
    assert!(p.optimal && p.satisfied() && p.program_robustness <= p.robustness + 1e-9, "{p:?}");
}

#[test]
fn satisfying_first_reaches_the_whole_programs_optimum_through_the_doors() {
    // The floor and the cell cuts hold for the optimum, so it is the same plan's
    // robustness, found in one program.
    let task = Task::point(TaskKind::Seq);
    let cfg = MipConfig { satisfying_first: Some(true), ..MipConfig::default() };
    let p = mip::plan(&task, &[1.5, -1.5], &cfg).unwrap_or_else(|e| panic!("{e}"));
    assert!(p.optimal && p.rounds == 1, "{p:?}");
    assert!(close(p.robustness, 0.5, 1e-6) && close(p.program_robustness, 0.5, 1e-6), "{p:?}");
    for t in 1..=task.steps {
        let (a, b) = (waypoint(&p, t - 1), waypoint(&p, t));
        assert!(task.map.segment_sdf(&a, &b) >= task.safe_radius - 1e-9, "segment {t} cuts a wall");
    }
    // With a cap: a plan at the cap, asked for first.
    let capped = MipConfig { robustness_cap: Some(0.3), ..cfg };
    let p = mip::plan(&task, &[1.5, -1.5], &capped).unwrap_or_else(|e| panic!("{e}"));
    assert!(p.optimal && p.rounds == 1 && p.program_robustness >= 0.3 - 1e-6, "{p:?}");
    assert!(p.robustness >= p.program_robustness - 1e-9, "{p:?}");
}

#[test]
fn satisfying_first_falls_back_to_the_whole_program_when_no_plan_satisfies() {
    let task = open("F[1,1] a & F[1,1] b");
    let cfg = MipConfig { satisfying_first: Some(true), ..MipConfig::default() };
    let first = mip::plan(&task, &[-3.0, -1.0], &cfg).unwrap_or_else(|e| panic!("{e}"));
    let whole = plan(&task, [-3.0, -1.0]);
    // Two programs: the one asking for a satisfying plan (infeasible), then the whole.
    assert_eq!(first.rounds, 2, "{first:?}");
    assert!(first.optimal && !first.satisfied());
    assert!(close(first.program_robustness, whole.program_robustness, 1e-6), "{first:?} {whole:?}");
}
