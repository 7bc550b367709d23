//! The five Point task specs of the paper (App. G) with the walls obstacle clause,
//! coordinates from the reference setup, for benchmarking.

use stl::{AfterStep, AvoidBoxes, Ball, Formula, Spec};

/// Centres of the 17 walls (0.5 m squares) of the four-room map.
pub const WALLS: [[f64; 2]; 17] = [
    [0.0, 0.0],
    [0.0, 0.5],
    [0.0, 1.0],
    [0.0, 3.0],
    [0.0, 3.5],
    [0.5, 0.0],
    [1.0, 0.0],
    [3.0, 0.0],
    [3.5, 0.0],
    [0.0, -0.5],
    [0.0, -1.0],
    [0.0, -3.0],
    [0.0, -3.5],
    [-0.5, 0.0],
    [-1.0, 0.0],
    [-3.0, 0.0],
    [-3.5, 0.0],
];

/// One task: its name, spec and plan length T (the path has T + 1 states).
pub struct Task {
    pub name: &'static str,
    pub spec: Spec,
    pub steps: usize,
}

fn goals(builder: stl::SpecBuilder, prefix: &str, centers: &[[f64; 2]], r: f64) -> stl::SpecBuilder {
    centers.iter().enumerate().fold(builder, |b, (i, c)| b.bind(format!("{prefix}{i}"), Ball::new(*c, r)))
}

fn walls() -> AvoidBoxes {
    AvoidBoxes::cubes(&WALLS.iter().map(|c| c.to_vec()).collect::<Vec<_>>(), 0.25, 0.1)
}

fn build(
    name: &'static str,
    text: String,
    t: usize,
    bind: impl FnOnce(stl::SpecBuilder) -> stl::SpecBuilder,
) -> Task {
    let f: Formula = format!("({text}) & G[1,{t}] safe").parse().expect("task spec parses");
    let spec =
        bind(Spec::builder(f).signals(["x", "y"]).bind("safe", walls())).build().expect("task spec binds");
    Task { name, spec, steps: t + 1 }
}

/// The loop body: be at some corner, and never at the same corner twice in a row.
fn loop_body(n: usize) -> String {
    let any = (0..n).map(|i| format!("l{i}")).collect::<Vec<_>>().join(" | ");
    let alt = (0..n).map(|i| format!("(l{i} -> !X l{i})")).collect::<Vec<_>>().join(" & ");
    format!("({any}) & {alt}")
}

/// Seq, Cover, Branch, Loop, Signal for Point.
pub fn point_tasks() -> Vec<Task> {
    let seq_goals = [[2.0, 2.0], [-1.0, 2.0], [-2.0, -1.0], [1.0, -2.0]];
    let cover_goals = [[2.0, 2.0], [1.0, -2.0], [-2.0, -1.0], [-1.0, 2.0]];
    let corners = [[-2.0, -2.0], [-2.0, 2.0], [2.0, 2.0], [2.0, -2.0]];
    let pairs = [([0.0, 2.0], [0.0, -2.0]), ([2.0, -2.0], [-2.0, 2.0]), ([2.0, 0.0], [-2.0, 0.0])];
    vec![
        build("seq", "F[1,2] g0 & F[3,4] g1 & F[5,6] g2 & F[7,8] g3".into(), 8, |b| {
            goals(b, "g", &seq_goals, 0.5)
        }),
        build("cover", "F[1,8] g0 & F[1,8] g1 & F[1,8] g2 & F[1,8] g3".into(), 8, |b| {
            goals(b, "g", &cover_goals, 0.5)
        }),
        build(
            "branch",
            "(F[1,2] a0 & F[3,4] b0) | (F[1,2] a1 & F[3,4] b1) | (F[1,2] a2 & F[3,4] b2)".into(),
            4,
            |b| {
                let b = goals(b, "a", &pairs.map(|p| p.0), 0.6);
                goals(b, "b", &pairs.map(|p| p.1), 0.6)
            },
        ),
        build("loop", format!("G[1,17] ({})", loop_body(4)), 17, |b| goals(b, "l", &corners, 0.6)),
        build("signal", format!("F[1,12] final & ({}) U[1,12] counter", loop_body(4)), 12, |b| {
            goals(b, "l", &corners, 0.8)
                .bind("final", Ball::new([0.0, 0.0], 0.8))
                .bind("counter", AfterStep { step: 10, truth: 100.0 })
        }),
    ]
}

/// Deterministic pseudo-random paths in the map's square [-4, 4]².
pub fn random_paths(count: usize, steps: usize, seed: u64) -> Vec<f64> {
    let mut s = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
    (0..count * steps * 2)
        .map(|_| {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((s >> 11) as f64 / (1u64 << 53) as f64) * 8.0 - 4.0
        })
        .collect()
}
