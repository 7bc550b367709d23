//! One deployed plan: the mean path of a trained-shape GRU-ODE planner (hidden 64)
//! from one start, in plain Rust ([`schrl::plan::deployed::DeployedPlanner`]) and, for
//! comparison, through candle ([`schrl::plan::planner::PathPlanner::mean_path`]).
//!
//! Run: `cargo bench -p schrl --bench deployed_plan` (figures in BENCHMARKS.md). The
//! weights are a seeded initialisation: the arithmetic per waypoint does not depend on
//! their values.

use std::hint::black_box;
use std::time::Duration;

use candle_core::{Device, Tensor};
use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use schrl::plan::cpg::{CpgConfig, PlanTrainer};
use schrl::plan::deployed::{DeployedPlanner, PlanScratch};
use schrl::task::{Task, TaskKind};

fn deployed_plan(c: &mut Criterion) {
    let mut g = c.benchmark_group("deployed_plan");
    for kind in [TaskKind::Seq, TaskKind::Loop] {
        let trainer = PlanTrainer::new(Task::point(kind), CpgConfig::default()).unwrap();
        let steps = trainer.task().steps;
        let cfg = *trainer.planner().config();
        let deployed = DeployedPlanner::from_varmap(trainer.varmap(), &cfg).unwrap();
        let (mut scratch, mut out) = (PlanScratch::default(), Vec::new());
        let name = format!("{}_T{steps}", kind.name());
        g.bench_function(BenchmarkId::new("rust", &name), |b| {
            b.iter(|| {
                deployed.mean_path_into(black_box(&[1.5, -1.5]), steps, &mut scratch, &mut out);
                black_box(&out);
            })
        });
        let start = Tensor::new(&[[1.5f32, -1.5]], &Device::Cpu).unwrap();
        g.bench_function(BenchmarkId::new("candle", &name), |b| {
            b.iter(|| black_box(trainer.planner().mean_path(&start, steps).unwrap()))
        });
    }
    g.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().warm_up_time(Duration::from_millis(500)).measurement_time(Duration::from_secs(3)).sample_size(30);
    targets = deployed_plan
}
criterion_main!(benches);
