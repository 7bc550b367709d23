//! Robustness plus gradient: the five Point task specs for one path and for a batch
//! of 1024, and how cost grows with path length and formula size.
//!
//! Run: `cargo bench -p schrl-stl --bench robustness` (figures in BENCHMARKS.md).

use std::hint::black_box;
use std::time::Duration;

use criterion::measurement::WallTime;
use criterion::{BenchmarkGroup, BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use stl::{Ball, Formula, Semantics, Spec, UntilSmoothing, parse};

mod point_tasks;
use point_tasks::{point_tasks, random_paths};

fn one_path(c: &mut Criterion) {
    let mut g = c.benchmark_group("one_path");
    for task in point_tasks() {
        let paths = random_paths(64, task.steps, 7);
        let per = task.steps * 2;
        for (mode, sem) in [("hard", Semantics::hard()), ("soft2", Semantics::soft(2.0))] {
            let mut ev = task.spec.evaluator();
            let mut grad = vec![0.0; per];
            let mut i = 0;
            g.bench_function(BenchmarkId::new(task.name, mode), |b| {
                b.iter(|| {
                    i = (i + 1) % 64;
                    let p = &paths[i * per..(i + 1) * per];
                    grad.fill(0.0);
                    black_box(ev.gradient(black_box(p), 0, &sem, &mut grad).unwrap())
                })
            });
        }
    }
    g.finish();
}

fn batch(c: &mut Criterion) {
    let mut g = c.benchmark_group("batch1024");
    g.throughput(Throughput::Elements(1024));
    for task in point_tasks() {
        let paths = random_paths(1024, task.steps, 11);
        let mut grads = vec![0.0; paths.len()];
        for (mode, sem) in [("hard", Semantics::hard()), ("soft2", Semantics::soft(2.0))] {
            g.bench_function(BenchmarkId::new(task.name, mode), |b| {
                b.iter(|| black_box(task.spec.gradient_batch(&paths, task.steps, &sem, &mut grads).unwrap()))
            });
        }
    }
    g.finish();
}

fn three_modes() -> [(&'static str, Semantics); 3] {
    [("hard", Semantics::hard()), ("soft2", Semantics::soft(2.0)), ("lse", Semantics::lse(0.5))]
}

/// Robustness and gradient of `path` under `spec` in the three modes, named by `steps`.
fn every_mode(g: &mut BenchmarkGroup<'_, WallTime>, spec: &Spec, path: &[f64], steps: usize) {
    modes(g, spec, path, steps, &three_modes());
}

/// Robustness and gradient of `path` under `spec` in each of `modes`.
fn modes(
    g: &mut BenchmarkGroup<'_, WallTime>,
    spec: &Spec,
    path: &[f64],
    steps: usize,
    modes: &[(&str, Semantics)],
) {
    let mut grad = vec![0.0; path.len()];
    for &(mode, sem) in modes {
        let mut ev = spec.evaluator();
        g.bench_function(BenchmarkId::new(mode, steps), |b| {
            b.iter(|| {
                grad.fill(0.0);
                black_box(ev.gradient(path, 0, &sem, &mut grad).unwrap())
            })
        });
    }
}

/// Long windows: `G[0,T] (F[0,T/2] a) & F[0,T] b` is linear in T if windows are O(T),
/// quadratic if each window is scanned.
fn path_length(c: &mut Criterion) {
    let mut g = c.benchmark_group("path_length");
    for steps in [8usize, 32, 128, 512, 1024] {
        let f: Formula = format!("G[0,{steps}] (F[0,{}] a) & F[0,{steps}] b", steps / 2).parse().unwrap();
        let spec = Spec::builder(f)
            .signals(["x", "y"])
            .bind("a", Ball::new([1.0, 1.0], 0.5))
            .bind("b", Ball::new([-1.0, 1.0], 0.5))
            .build()
            .unwrap();
        let path = random_paths(1, steps, 3);
        g.throughput(Throughput::Elements(steps as u64));
        every_mode(&mut g, &spec, &path, steps);
    }
    g.finish();
}

/// `until` over growing paths, robustness and gradient, with a 21-step window and
/// unbounded: O(T) in hard mode and with the recursive relaxation (the default),
/// O(T·w) with the flat one (run unbounded only on the shortest path: quadratic).
fn until_length(c: &mut Criterion) {
    let flat = |sem: Semantics| sem.with_until(UntilSmoothing::Flat);
    let [hard, soft, lse] = three_modes();
    let with_flat = [
        hard,
        soft,
        lse,
        ("soft2-flat", flat(Semantics::soft(2.0))),
        ("lse-flat", flat(Semantics::lse(0.5))),
    ];
    for (group, text) in [("until_length", "x > 0 U[0,20] y > 1"), ("until_unbounded", "x > 0 U y > 1")] {
        let mut g = c.benchmark_group(group);
        let spec = Spec::builder(parse(text).unwrap()).signals(["x", "y"]).build().unwrap();
        for steps in [1_000usize, 10_000, 100_000] {
            let path = random_paths(1, steps, 7);
            g.throughput(Throughput::Elements(steps as u64));
            let quadratic = group == "until_unbounded" && steps > 1_000;
            modes(&mut g, &spec, &path, steps, &with_flat[..if quadratic { 3 } else { 5 }]);
        }
        g.finish();
    }
}

/// Formula size: a conjunction of k reach clauses over 64 steps.
fn formula_size(c: &mut Criterion) {
    let mut g = c.benchmark_group("formula_size");
    let steps = 64;
    let path = random_paths(1, steps, 5);
    for k in [1usize, 4, 16, 64] {
        let f = Formula::and((0..k).map(|i| Formula::atom(format!("g{i}")).eventually(i % 8, i % 8 + 8)));
        let spec = (0..k)
            .fold(Spec::builder(f).signals(["x", "y"]), |b, i| {
                b.bind(format!("g{i}"), Ball::new([i as f64 * 0.1, 1.0], 0.5))
            })
            .build()
            .unwrap();
        let mut ev = spec.evaluator();
        let mut grad = vec![0.0; path.len()];
        g.throughput(Throughput::Elements(k as u64));
        g.bench_function(BenchmarkId::new("hard", k), |b| {
            b.iter(|| {
                grad.fill(0.0);
                black_box(ev.gradient(&path, 0, &Semantics::hard(), &mut grad).unwrap())
            })
        });
    }
    g.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().warm_up_time(Duration::from_millis(500)).measurement_time(Duration::from_secs(2)).sample_size(30);
    targets = one_path, batch, path_length, until_length, formula_size
}
criterion_main!(benches);
