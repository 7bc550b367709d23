//! Plan waypoints by gradient ascent on robustness (Leung et al.; paper App. J).
//!
//! The Point "Seq" task: from a start in the lower-right room, visit (2,2) at
//! waypoint 1–2, (-1,2) at 3–4, (-2,-1) at 5–6 and (1,-2) at 7–8, never inside the
//! walls. Waypoints start random and follow the gradient of the soft robustness
//! (with Adam) until the hard robustness is positive.
//!
//! Run: `cargo run --release -p schrl-stl --example gradient_planner`

use stl::Semantics;

// The five Point task specs, shared with the benchmarks.
#[path = "../benches/point_tasks.rs"]
#[allow(dead_code)]
mod point_tasks;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let seq = point_tasks::point_tasks().into_iter().find(|t| t.name == "seq").expect("the Seq task");
    let spec = seq.spec;

    let (steps, dim) = (seq.steps, 2);
    let mut rng = 0x2545F4914F6CDD1Du64;
    let mut uniform = move || {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        (rng >> 11) as f64 / (1u64 << 53) as f64
    };
    let soft = Semantics::soft(4.0);
    for restart in 0.. {
        let mut path: Vec<f64> = (0..steps * dim).map(|_| uniform() * 6.0 - 3.0).collect();
        path[..2].copy_from_slice(&[1.5, -1.5]); // the start is given, not planned
        let (mut m, mut v) = (vec![0.0; path.len()], vec![0.0; path.len()]);
        let (lr, b1, b2) = (0.05, 0.9, 0.999);
        for it in 1..=2000 {
            let (_, grad) = spec.gradient(&path, &soft)?;
            for i in dim..path.len() {
                m[i] = b1 * m[i] + (1.0 - b1) * grad[i];
                v[i] = b2 * v[i] + (1.0 - b2) * grad[i] * grad[i];
                let (mh, vh) = (m[i] / (1.0 - b1.powi(it)), v[i] / (1.0 - b2.powi(it)));
                path[i] += lr * mh / (vh.sqrt() + 1e-8); // ascent: maximise robustness
            }
            let hard = spec.robustness(&path, &Semantics::hard())?;
            if hard > 0.0 {
                println!("satisfied after {restart} restart(s) and {it} steps: robustness {hard:.3}");
                for w in path.chunks(dim) {
                    println!("  ({:6.2}, {:6.2})", w[0], w[1]);
                }
                return Ok(());
            }
        }
    }
    unreachable!("the loop returns once a path satisfies the spec")
}
