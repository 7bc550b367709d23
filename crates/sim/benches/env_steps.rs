//! Environment steps per second: single and vectorised (N = 64) on one core, and with
//! `--features mujoco` the Doggo single and as PPO's 8 environments on all of rayon's
//! threads (`env_vec8`).
//!
//! Run: `cargo bench -p schrl-sim --bench env_steps` (figures in BENCHMARKS.md).
//! Actions change every 20 steps and goals are re-drawn as they are reached, so the
//! robots cross the map and meet walls as they would in training.

use std::hint::black_box;
use std::time::Duration;

use criterion::measurement::WallTime;
use criterion::{BenchmarkGroup, BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use sim::{Robot, Step, VecEnv, make_env};

const STEPS: usize = 1000;

fn actions(dim: usize, n: usize) -> Vec<f64> {
    let mut s = 0x1234_5678_9abc_def0u64;
    (0..dim * n * (STEPS / 20 + 1))
        .map(|_| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        })
        .collect()
}

fn single(c: &mut Criterion) {
    let mut g = c.benchmark_group("env_single");
    g.throughput(Throughput::Elements(STEPS as u64));
    for robot in Robot::ALL.into_iter().filter(|r| r.is_available()) {
        let mut env = make_env(robot, robot.default_map()).unwrap();
        let dim = env.action_space().dim();
        let acts = actions(dim, 1);
        let mut obs = vec![0.0; env.observation_space().dim()];
        env.reset_into(1, None, &mut obs).unwrap();
        g.bench_function(BenchmarkId::from_parameter(robot.name()), |b| {
            b.iter(|| {
                for t in 0..STEPS {
                    let a = &acts[(t / 20) * dim..(t / 20 + 1) * dim];
                    let s = env.step_into(a, &mut obs).unwrap();
                    if s.fell {
                        env.reset_into(t as u64, None, &mut obs).unwrap();
                    }
                    if s.reached {
                        let goal = env.sample_goal();
                        env.set_goal(&goal).unwrap();
                    }
                    black_box(s);
                }
                env.reset_into(t_seed(), None, &mut obs).unwrap();
            })
        });
    }
    g.finish();
}

fn t_seed() -> u64 {
    7
}

fn vectorised(c: &mut Criterion) {
    let n = 64;
    let mut g = c.benchmark_group("env_vec64");
    g.throughput(Throughput::Elements((STEPS * n) as u64));
    for robot in Robot::NATIVE {
        bench_vec(&mut g, robot, n);
    }
    g.finish();
}

/// PPO's 8 environments of each robot that steps them in parallel
/// ([`Robot::steps_in_parallel`]), on as many threads as rayon has.
fn parallel(c: &mut Criterion) {
    let n = 8;
    let mut g = c.benchmark_group("env_vec8");
    g.throughput(Throughput::Elements((STEPS * n) as u64));
    for robot in Robot::ALL.into_iter().filter(|r| r.is_available() && r.steps_in_parallel()) {
        bench_vec(&mut g, robot, n);
    }
    g.finish();
}

/// `n` environments of `robot` in one [`VecEnv`], [`STEPS`] steps; a fallen robot is
/// reset, as the trainer does.
fn bench_vec(g: &mut BenchmarkGroup<'_, WallTime>, robot: Robot, n: usize) {
    let mut v = VecEnv::new(robot, robot.default_map(), n, 3).unwrap();
    let dim = v.act_dim();
    let acts = actions(dim, n);
    let mut obs = vec![0.0; n * v.obs_dim()];
    let mut one = vec![0.0; v.obs_dim()];
    let mut steps = vec![Step::default(); n];
    g.bench_function(BenchmarkId::from_parameter(robot.name()), |b| {
        b.iter(|| {
            for t in 0..STEPS {
                let a = &acts[(t / 20) * dim * n..(t / 20 + 1) * dim * n];
                v.step_all(a, &mut obs, &mut steps).unwrap();
                for (i, _) in steps.iter().enumerate().filter(|(_, s)| s.fell) {
                    v.envs_mut()[i].reset_into(t as u64, None, &mut one).unwrap();
                }
            }
            v.reset_all(5, &mut obs).unwrap();
            black_box(&obs);
        })
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().warm_up_time(Duration::from_millis(500)).measurement_time(Duration::from_secs(3)).sample_size(20);
    targets = single, vectorised, parallel
}
criterion_main!(benches);
