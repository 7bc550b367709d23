//! The baselines' speed on one core: TLTL's PPO iteration (a 4000-step rollout of flat
//! episodes and the update), one TD3 update, and CRM's 4000-step chunk (each step: the
//! environment, one counterfactual experience per live machine state, one TD3 update).
//!
//! `RAYON_NUM_THREADS=1 cargo bench -p schrl --bench baselines`

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use schrl::baseline::crm::{CHUNK, CrmSettings, CrmTrainer};
use schrl::baseline::dhrm::DhrmConfig;
use schrl::baseline::reward_machine::RewardMachine;
use schrl::baseline::td3::{Batch, Td3, Td3Config};
use schrl::baseline::tltl::{TltlSettings, TltlTrainer};
use schrl::control::PpoConfig;
use schrl::task::{Task, TaskKind};
use sim::Robot;

fn tltl(c: &mut Criterion) {
    let seq = Task::point(TaskKind::Seq);
    let mut t = TltlTrainer::new(TltlSettings {
        robot: Robot::Point,
        task_toml: seq.toml.clone(),
        task_spec: seq.spec.clone(),
        seed: 0,
        steps: usize::MAX / 2,
        ppo: PpoConfig::reference(),
        eval_groups: 0,
        save_every: 1,
    })
    .unwrap();
    let mut g = c.benchmark_group("tltl_train_update");
    g.sample_size(10);
    g.throughput(Throughput::Elements(t.settings.ppo.rollout as u64));
    g.bench_function("point_seq", |b| b.iter(|| t.train_update().unwrap()));
    g.finish();
}

fn td3_update(c: &mut Criterion) {
    // Point Seq's CRM shapes: 17 flat observations ⊕ 6 machine states, 2 actions.
    let (input, act) = (23, 2);
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let cfg = Td3Config::default();
    let n = cfg.batch;
    let mut td3 = Td3::new(input, act, cfg, &mut rng);
    let mut v = |k: usize| (0..k).map(|_| rng.random_range(-1.0f32..1.0)).collect::<Vec<f32>>();
    let (x, a, r, x_next) = (v(n * input), v(n * act), v(n), v(n * input));
    let done = vec![false; n];
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut g = c.benchmark_group("td3_update");
    g.throughput(Throughput::Elements(1));
    g.bench_function("batch_100_64x64", |b| {
        b.iter(|| td3.update(&Batch { n, x: &x, a: &a, r: &r, x_next: &x_next, done: &done }, &mut rng))
    });
    g.finish();
}

fn crm(c: &mut Criterion) {
    let mut g = c.benchmark_group("crm_train_chunk");
    g.sample_size(10);
    g.throughput(Throughput::Elements(CHUNK as u64));
    for (name, dhrm) in [("point_seq", None), ("point_seq_dhrm", Some(DhrmConfig::default()))] {
        let mut t = seq_trainer(dhrm);
        t.train_chunk().unwrap();
        g.bench_function(name, |b| b.iter(|| t.train_chunk().unwrap()));
    }
    g.finish();
}

/// CRM (or DHRM) on Point Seq, past its learning start after one chunk.
fn seq_trainer(dhrm: Option<DhrmConfig>) -> CrmTrainer {
    let seq = Task::point(TaskKind::Seq);
    CrmTrainer::new(CrmSettings {
        robot: Robot::Point,
        task_toml: seq.toml.clone(),
        task_spec: seq.spec.clone(),
        machine: RewardMachine::shipped_text("seq").unwrap().into(),
        seed: 0,
        steps: usize::MAX / 2,
        td3: Td3Config { learning_starts: 1000, ..Td3Config::default() },
        eval_groups: 0,
        save_every: 1,
        dhrm,
    })
    .unwrap()
}

criterion_group!(benches, tltl, td3_update, crm);
criterion_main!(benches);
