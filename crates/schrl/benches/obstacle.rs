//! The Drone's `safe` along one planned segment: the exact duck's closed form
//! ([`sim::Map::segment_sdf`]) against a fitted 64-64 neural SDF sampled every
//! 0.2 m in one batched pass ([`schrl::task::neural_sdf::NeuralClearance`]), value
//! alone and value with gradient (what the planner's update asks for).
//!
//! Run: `cargo bench -p schrl --bench obstacle` (figures in BENCHMARKS.md). The network
//! is a short fit (the arithmetic per sample does not depend on its weights).

use std::hint::black_box;
use std::sync::Arc;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use schrl::task::neural_sdf::{NeuralSdf, SdfFitConfig};
use schrl::task::{MapClearance, SafeAlong};
use sim::Map;
use stl::Predicate;

fn obstacle(c: &mut Criterion) {
    let map = Map::by_name("duck").unwrap();
    let (net, _) = NeuralSdf::fit(&map, &SdfFitConfig { steps: 200, ..Default::default() }).unwrap();
    let neural = Arc::new(net).clearance(0.1).along(SafeAlong::Segments);
    let exact = MapClearance::new(map, 0.1).along(SafeAlong::Segments);
    // A 4 m segment past the duck: 21 samples for the network.
    let path = [-2.0, 1.5, 1.0, 1.8, 0.3, 1.6];
    let mut g = c.benchmark_group("drone_segment_safe");
    let mut grad = [0.0; 6];
    for (name, pred) in [("exact", &exact as &dyn Predicate), ("neural", &neural as &dyn Predicate)] {
        g.bench_function(format!("{name}/value"), |b| {
            b.iter(|| black_box(pred.value_on_path(black_box(&path), 3, 1)))
        });
        g.bench_function(format!("{name}/value_and_grad"), |b| {
            b.iter(|| black_box(pred.value_and_grad_on_path(black_box(&path), 3, 1, 1.0, &mut grad)))
        });
    }
    g.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().warm_up_time(Duration::from_millis(500)).measurement_time(Duration::from_secs(3)).sample_size(30);
    targets = obstacle
}
criterion_main!(benches);
