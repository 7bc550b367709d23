//! One constrained policy-gradient update of the GRU-ODE planner on a batch of 64
//! sampled paths, per Point task: sampling, robustness and its gradient, the
//! hand-written backward ([`schrl::plan::gru_ode_backprop`]), Adam and the dual step.
//! For comparison, the same update of the plain-GRU ablation, which trains through
//! candle's autodiff (as the GRU-ODE did before).
//!
//! Run: `RAYON_NUM_THREADS=1 cargo bench -p schrl --bench cpg_update` (figures in
//! BENCHMARKS.md). Restarts are off so every iteration is one update.

use std::time::Duration;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use schrl::plan::cpg::{CpgConfig, PlanTrainer};
use schrl::plan::planner::PlannerKind;
use schrl::task::{Task, TaskKind};

fn cpg_update(c: &mut Criterion) {
    let mut g = c.benchmark_group("cpg_update_b64");
    for kind in TaskKind::ALL {
        for planner in [PlannerKind::GruOde, PlannerKind::Gru] {
            let cfg = CpgConfig { restart_after: None, planner, ..CpgConfig::default() };
            let mut trainer = PlanTrainer::new(Task::point(kind), cfg).unwrap();
            let id = BenchmarkId::new(planner.name(), format!("{}_T{}", kind.name(), trainer.task().steps));
            g.bench_function(id, |b| b.iter(|| trainer.update().unwrap()));
        }
    }
    g.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20).measurement_time(Duration::from_secs(3));
    targets = cpg_update
}
criterion_main!(benches);
