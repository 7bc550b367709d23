//! PPO speed on one core: a minibatch step (hand-written kernel vs the same
//! networks in candle), and end-to-end training throughput (rollout + update) for
//! each robot with the reference hyper-parameters.
//!
//! `RAYON_NUM_THREADS=1 cargo bench -p schrl --bench ppo`

use candle_core::{DType, Device, Tensor};
use candle_nn::{AdamW, Module, Optimizer, ParamsAdamW, VarBuilder, VarMap};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use schrl::control::policy::{ActorCritic, PolicyCache};
use schrl::control::ppo::{Minibatch, loss_and_grad};
use schrl::control::{ControlConfig, ControlTrainer, PpoConfig};
use schrl::nn::adam::Adam;
use sim::Robot;

const BATCH: usize = 256;

fn minibatch(policy: &ActorCritic, rng: &mut ChaCha8Rng) -> Minibatch {
    let (od, ad) = (policy.obs_dim(), policy.act_dim());
    let obs: Vec<f32> = (0..BATCH * od).map(|_| rng.random_range(-2.0..2.0)).collect();
    let mut actions = vec![0.0; BATCH * ad];
    let mut logp = vec![0.0; BATCH];
    let mut values = vec![0.0; BATCH];
    policy.act(&obs, BATCH, rng, &mut PolicyCache::default(), &mut actions, &mut logp, &mut values);
    Minibatch {
        n: BATCH,
        obs,
        actions,
        old_log_probs: logp,
        old_values: values,
        advantages: (0..BATCH).map(|_| rng.random_range(-1.0..1.0)).collect(),
        returns: (0..BATCH).map(|_| rng.random_range(-1.0..1.0)).collect(),
    }
}

fn minibatch_step(c: &mut Criterion) {
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let mut policy = ActorCritic::new(14, 2, &[64, 64], &mut rng);
    let mb = minibatch(&policy, &mut rng);
    let cfg = PpoConfig::reference();
    let mut adam = Adam::new(policy.params.len());
    let mut grads = vec![0.0; policy.params.len()];
    let mut cache = PolicyCache::default();
    let mut g = c.benchmark_group("ppo_minibatch_256");
    g.bench_function("hand_written", |b| {
        b.iter(|| {
            loss_and_grad(&policy, &cfg, &mb, &mut cache, &mut grads);
            adam.step(&mut policy.params, &mut grads, 3e-4, 0.5);
        })
    });

    // The same 14-64-64-2 actor and 14-64-64-1 critic in candle, forward, backward
    // and AdamW, with a loss of the same shape (Gaussian log-likelihood ratio and a
    // squared value error), for comparison.
    let dev = Device::Cpu;
    let vm = VarMap::new();
    let vb = VarBuilder::from_varmap(&vm, DType::F32, &dev);
    let layer = |i, o, name: &str| candle_nn::linear(i, o, vb.pp(name)).unwrap();
    let (a1, a2, a3) = (layer(14, 64, "a1"), layer(64, 64, "a2"), layer(64, 2, "a3"));
    let (c1, c2, c3) = (layer(14, 64, "c1"), layer(64, 64, "c2"), layer(64, 1, "c3"));
    let log_std = vb.get_with_hints(2, "log_std", candle_nn::Init::Const(0.0)).unwrap();
    let mut opt =
        AdamW::new(vm.all_vars(), ParamsAdamW { lr: 3e-4, weight_decay: 0.0, ..Default::default() }).unwrap();
    let x = Tensor::from_slice(&mb.obs, (BATCH, 14), &dev).unwrap();
    let act = Tensor::from_slice(&mb.actions, (BATCH, 2), &dev).unwrap();
    let adv = Tensor::from_slice(&mb.advantages, BATCH, &dev).unwrap();
    let ret = Tensor::from_slice(&mb.returns, BATCH, &dev).unwrap();
    let old = Tensor::from_slice(&mb.old_log_probs, BATCH, &dev).unwrap();
    g.bench_function("candle", |b| {
        b.iter(|| {
            let mean = a3
                .forward(&a2.forward(&a1.forward(&x).unwrap().tanh().unwrap()).unwrap().tanh().unwrap())
                .unwrap();
            let v = c3
                .forward(&c2.forward(&c1.forward(&x).unwrap().tanh().unwrap()).unwrap().tanh().unwrap())
                .unwrap();
            let z = act.sub(&mean).unwrap().broadcast_div(&log_std.exp().unwrap()).unwrap();
            let logp = (z.sqr().unwrap() * -0.5).unwrap().broadcast_sub(&log_std).unwrap().sum(1).unwrap();
            let ratio = logp.sub(&old).unwrap().exp().unwrap();
            let pg =
                adv.neg().unwrap().mul(&ratio.clamp(0.8f32, 1.2f32).unwrap()).unwrap().mean_all().unwrap();
            let vl = v.squeeze(1).unwrap().sub(&ret).unwrap().sqr().unwrap().mean_all().unwrap();
            let loss = (pg + (vl * 0.25).unwrap()).unwrap();
            opt.backward_step(&loss).unwrap();
        })
    });
    g.finish();
}

fn training_throughput(c: &mut Criterion) {
    let mut g = c.benchmark_group("ppo_train_update");
    g.sample_size(10);
    for robot in Robot::NATIVE {
        let mut cfg = ControlConfig::for_robot(robot);
        cfg.total_steps = usize::MAX / 2;
        let mut t = ControlTrainer::new(cfg).unwrap();
        g.throughput(Throughput::Elements(t.config.ppo.rollout as u64));
        g.bench_function(robot.name(), |b| b.iter(|| t.train_update().unwrap()));
    }
    g.finish();
}

criterion_group!(benches, minibatch_step, training_throughput);
criterion_main!(benches);
