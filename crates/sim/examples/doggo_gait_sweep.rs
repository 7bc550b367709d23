//! The open-loop sweep that chose the Doggo's default gait ([`sim::mujoco::GAIT`]):
//! `cargo run --release -p schrl-sim --features mujoco --example doggo_gait_sweep`.
//!
//! Stage 1 walks every pattern of the grid with the policy at rest (zero actions) from
//! 3 starts for 300 control steps and ranks them by net pace. Stage 2 takes the nine
//! fastest through 12 starts of 1000 steps in five conditions — straight, with uniform
//! ±0.3 random residuals on every motor, and steered by a hip-z residual of +0.5, −0.5
//! and +1 (left legs one way, right legs the other) — and keeps the fastest under the
//! random residuals among those that never fall. Stage 3 gives the chosen rhythm
//! ([`Gait::PRONK`]) its steer: every hip-z swing pattern (which legs swing together)
//! and phase against the stride, walked from 6 starts for 500 steps at steer +1 and
//! −1, ranked by how fast it turns (half the difference of the two yaw rates) among
//! those that never fall. `-- --steer-only` runs stage 3 alone.

use std::f64::consts::PI;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sim::mujoco::{Doggo, Gait};
use sim::{Dynamics, Map};

/// Net pace (m per control step, mean over the starts that did not fall), mean yaw rate
/// (rad per control step) and falls.
struct Walk {
    pace: f64,
    yaw_rate: f64,
    falls: usize,
}

/// Walks `gait` from `starts` random headings for `steps` control steps, the policy's
/// action each step `noise`-wide uniform residuals plus `turn` on the hip-z motors, at
/// full stride and steer `steer`.
fn walk(map: &Map, gait: Gait, starts: u64, steps: usize, noise: f64, turn: f64, steer: f64) -> Walk {
    let (mut paces, mut yaw_rates, mut falls) = (vec![], vec![], 0);
    for seed in 0..starts {
        let mut dog = Doggo::with_gait(map, Some(gait)).expect("a Doggo on the empty map");
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        dog.reset(&[0.0, 0.0], &mut rng);
        let (mut last, mut turned, mut fell) = (dog.yaw(), 0.0, false);
        for _ in 0..steps {
            let action: [f64; 14] = std::array::from_fn(|j| {
                // The gait's amplitude (0: the full stride), then its steer.
                if j >= 12 {
                    return if j == 13 { steer } else { 0.0 };
                }
                let residual = if noise > 0.0 { noise * rng.random_range(-1.0..1.0) } else { 0.0 };
                // Hip z is every third motor; legs alternate left, right.
                let side = if (j / 3) % 2 == 0 { 1.0 } else { -1.0 };
                residual + if j % 3 == 0 { turn * side } else { 0.0 }
            });
            dog.advance(&action, map, &[0.0, 0.0]);
            let yaw = dog.yaw();
            turned += (yaw - last + PI).rem_euclid(2.0 * PI) - PI;
            last = yaw;
            if dog.fallen() {
                fell = true;
                break;
            }
        }
        if fell {
            falls += 1;
        } else {
            let p = dog.plan_position();
            paces.push(p[0].hypot(p[1]) / steps as f64);
            yaw_rates.push(turned / steps as f64);
        }
    }
    let mean = |v: &[f64]| if v.is_empty() { 0.0 } else { v.iter().sum::<f64>() / v.len() as f64 };
    Walk { pace: mean(&paces), yaw_rate: mean(&yaw_rates), falls }
}

fn describe(name: &str, g: &Gait) -> String {
    format!(
        "{name:<8} {:.0} Hz, ankle {:.1}, lag {:+.2}, rear {}",
        g.freq_hz,
        g.ankle,
        g.ankle_lag,
        if g.rear_reversed { "reversed" } else { "as front" }
    )
}

fn main() {
    let map = Map::by_name("empty").expect("the empty map");
    if std::env::args().any(|a| a == "--steer-only") {
        return steer_sweep(&map);
    }
    let patterns = [
        ("trot", [0.0, PI, PI, 0.0]),
        ("pace", [0.0, PI, 0.0, PI]),
        ("bound", [0.0, 0.0, PI, PI]),
        ("pronk", [0.0; 4]),
        ("bound90", [0.0, 0.0, PI / 2.0, PI / 2.0]),
        ("bound270", [0.0, 0.0, -PI / 2.0, -PI / 2.0]),
    ];
    let mut grid = vec![];
    for (name, offsets) in patterns {
        for freq_hz in [2.0, 3.0, 4.0, 6.0, 8.0] {
            for ankle in [0.5, 1.0] {
                for ankle_lag in [-PI / 2.0, 0.0, PI / 2.0, PI] {
                    for rear_reversed in [false, true] {
                        let g = Gait {
                            freq_hz,
                            offsets,
                            hip_y: 1.0,
                            ankle,
                            ankle_lag,
                            rear_reversed,
                            ..Gait::PRONK
                        };
                        grid.push((name, g, walk(&map, g, 3, 300, 0.0, 0.0, 0.0)));
                    }
                }
            }
        }
    }
    grid.sort_by(|a, b| b.2.pace.total_cmp(&a.2.pace));
    println!("stage 1: {} patterns, policy at rest, 3 starts x 300 steps; the fastest:", grid.len());
    for (name, g, w) in &grid[..12] {
        println!("  {}: {:.4} m/step, falls {}/3", describe(name, g), w.pace, w.falls);
    }
    let conditions = [
        ("straight", 0.0, 0.0),
        ("±0.3 residuals", 0.3, 0.0),
        ("hip z +0.5", 0.0, 0.5),
        ("hip z −0.5", 0.0, -0.5),
        ("hip z +1", 0.0, 1.0),
    ];
    println!(
        "\nstage 2: the nine fastest, 12 starts x 1000 steps (pace m/step, yaw rate rad/step, falls of 12):"
    );
    let mut best: Option<(f64, String)> = None;
    for (name, g, _) in &grid[..9] {
        let walks: Vec<Walk> =
            conditions.iter().map(|(_, noise, turn)| walk(&map, *g, 12, 1000, *noise, *turn, 0.0)).collect();
        let cells: Vec<String> = conditions
            .iter()
            .zip(&walks)
            .map(|((c, ..), w)| format!("{c} {:.4} {:+.4} {}", w.pace, w.yaw_rate, w.falls))
            .collect();
        println!("  {}\n    {}", describe(name, g), cells.join(" | "));
        if walks.iter().all(|w| w.falls == 0) && best.as_ref().is_none_or(|(p, _)| walks[1].pace > *p) {
            best = Some((walks[1].pace, describe(name, g)));
        }
    }
    match best {
        Some((pace, gait)) => println!("\nchosen: {gait} ({pace:.4} m/step with ±0.3 residuals, no fall)"),
        None => println!("\nno pattern walked without a fall in every condition"),
    }
    steer_sweep(&map);
}

/// Stage 3: the pronk's hip-z swing, by leg pattern and phase.
fn steer_sweep(map: &Map) {
    let patterns = [
        ("all legs", [1.0, 1.0, 1.0, 1.0]),
        ("left against right", [1.0, -1.0, 1.0, -1.0]),
        ("front against rear", [1.0, 1.0, -1.0, -1.0]),
        ("diagonals", [1.0, -1.0, -1.0, 1.0]),
    ];
    println!(
        "\nstage 3: the pronk steered, 6 starts x 500 steps at steer +1 and -1 (yaw rad/step, pace m/step, falls of 6):"
    );
    let mut best: Option<(f64, String)> = None;
    for (name, signs) in patterns {
        for k in 0..8 {
            let steer_lag = k as f64 * PI / 4.0;
            let g = Gait { steer_lag, steer_signs: signs, ..Gait::PRONK };
            let (left, right) = (walk(map, g, 6, 500, 0.0, 0.0, 1.0), walk(map, g, 6, 500, 0.0, 0.0, -1.0));
            let turn = (left.yaw_rate - right.yaw_rate) / 2.0;
            println!(
                "  {name:<18} lag {steer_lag:.2}: +1 {:+.4} {:.4} {} | -1 {:+.4} {:.4} {} | turn {turn:+.4}",
                left.yaw_rate, left.pace, left.falls, right.yaw_rate, right.pace, right.falls
            );
            if left.falls + right.falls == 0 && best.as_ref().is_none_or(|(t, _)| turn.abs() > t.abs()) {
                best = Some((turn, format!("{name}, lag {steer_lag:.2}")));
            }
        }
    }
    match best {
        Some((turn, pattern)) => {
            println!("\nchosen steer: {pattern} ({turn:+.4} rad/step at steer +1, no fall)")
        }
        None => println!("\nno steer pattern walked without a fall"),
    }
}
