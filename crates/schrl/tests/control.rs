//! The PPO controller: gradients against candle's autograd, learning on a tiny
//! budget, determinism, checkpoints and exact resume.

mod common;

use candle_core::{Device, Tensor, Var};
use common::candle_mlp;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use schrl::control::policy::{ActorCritic, PolicyCache};
use schrl::control::ppo::{Minibatch, loss_and_grad};
use schrl::control::trainer::open_map;
use schrl::control::{ControlConfig, ControlTrainer, NearGoals, PpoConfig};
use schrl::run::evaluate::{GoalDraw, evaluate_controller as evaluate};
use schrl::store::{self, Existing, RunKind, RunWriter};
use sim::Robot;

fn random_minibatch(policy: &ActorCritic, n: usize, rng: &mut ChaCha8Rng) -> Minibatch {
    let (od, ad) = (policy.obs_dim(), policy.act_dim());
    let mut cache = PolicyCache::default();
    let obs: Vec<f32> = (0..n * od).map(|_| rng.random_range(-2.0..2.0)).collect();
    let mut actions = vec![0.0; n * ad];
    let mut logp = vec![0.0; n];
    let mut values = vec![0.0; n];
    policy.act(&obs, n, rng, &mut cache, &mut actions, &mut logp, &mut values);
    Minibatch {
        n,
        // Old log-probabilities off by up to ±0.5 so that some ratios leave the clip range.
        old_log_probs: logp.iter().map(|l| l + rng.random_range(-0.5..0.5)).collect(),
        old_values: values.iter().map(|v| v + rng.random_range(-0.6..0.6)).collect(),
        advantages: (0..n).map(|_| rng.random_range(-2.0..2.0)).collect(),
        returns: (0..n).map(|_| rng.random_range(-1.0..1.0)).collect(),
        obs,
        actions,
    }
}

#[test]
fn ppo_loss_gradient_matches_candle_autograd() -> candle_core::Result<()> {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut policy = ActorCritic::new(5, 2, &[8, 8], &mut rng);
    // Non-trivial networks: perturb every parameter, and the log-std.
    for p in policy.params.iter_mut() {
        *p += rng.random_range(-0.3..0.3);
    }
    let cfg = PpoConfig { ent_coef: 0.01, ..PpoConfig::reference() };
    let mb = random_minibatch(&policy, 32, &mut rng);
    let mut grads = vec![0.0; policy.params.len()];
    let parts = loss_and_grad(&policy, &cfg, &mb, &mut PolicyCache::default(), &mut grads);
    assert!(parts.clip_fraction > 0.05 && parts.clip_fraction < 0.95, "the test must exercise clipping");

    // The same loss, built from candle ops as CleanRL builds it from torch ops.
    let dev = Device::Cpu;
    let (n, d) = (mb.n, 2);
    let (pa, pc, pl) = policy.split(&policy.params);
    let x = Tensor::from_slice(&mb.obs, (n, 5), &dev)?;
    let (mean, actor_vars) = candle_mlp(policy.actor(), pa, &x)?;
    let (value, critic_vars) = candle_mlp(policy.critic(), pc, &x)?;
    let value = value.squeeze(1)?;
    let log_std = Var::from_tensor(&Tensor::from_slice(pl, d, &dev)?)?;
    let act = Tensor::from_slice(&mb.actions, (n, d), &dev)?;
    let z = act.sub(&mean)?.broadcast_div(&log_std.as_tensor().exp()?)?;
    let half_ln_2pi = 0.5 * (2.0 * std::f64::consts::PI).ln();
    let log_prob = ((z.sqr()? * -0.5)?.broadcast_sub(log_std.as_tensor())? - half_ln_2pi)?.sum(1)?;
    let old = Tensor::from_slice(&mb.old_log_probs, n, &dev)?;
    let ratio = log_prob.sub(&old)?.exp()?;
    let adv_raw = Tensor::from_slice(&mb.advantages, n, &dev)?;
    let m = adv_raw.mean_all()?;
    let centered = adv_raw.broadcast_sub(&m)?;
    let std = (centered.sqr()?.sum_all()? / (n as f64 - 1.0))?.sqrt()?;
    let adv = centered.broadcast_div(&(std + 1e-8)?)?;
    let pg1 = adv.neg()?.mul(&ratio)?;
    let pg2 = adv.neg()?.mul(&ratio.clamp(0.8f32, 1.2f32)?)?;
    let pg_loss = pg1.maximum(&pg2)?.mean_all()?;
    let ret = Tensor::from_slice(&mb.returns, n, &dev)?;
    let old_v = Tensor::from_slice(&mb.old_values, n, &dev)?;
    let v_unclipped = value.sub(&ret)?.sqr()?;
    let v_clipped = (&old_v + value.sub(&old_v)?.clamp(-0.2f32, 0.2f32)?)?.sub(&ret)?.sqr()?;
    let v_loss = (v_unclipped.maximum(&v_clipped)?.mean_all()? * 0.5)?;
    let entropy = (log_std.as_tensor().sum_all()? + d as f64 * (0.5 + half_ln_2pi))?;
    let loss = ((pg_loss - (entropy * 0.01)?)? + (v_loss * 0.5)?)?;
    let expected_total = loss.to_scalar::<f32>()?;
    assert!((expected_total - parts.total).abs() < 1e-4, "loss {expected_total} vs {}", parts.total);

    let g = loss.backward()?;
    let mut expected = Vec::new();
    for (w, b) in actor_vars.iter().chain(&critic_vars) {
        for v in [w, b] {
            expected.extend(g.get(v.as_tensor()).expect("gradient").flatten_all()?.to_vec1::<f32>()?);
        }
    }
    expected.extend(g.get(log_std.as_tensor()).expect("gradient").to_vec1::<f32>()?);
    assert_eq!(expected.len(), grads.len());
    let scale = expected.iter().fold(0.0f32, |a, b| a.max(b.abs()));
    for (i, (a, b)) in grads.iter().zip(&expected).enumerate() {
        assert!((a - b).abs() <= 1e-4 * scale.max(1.0), "parameter {i}: hand-written {a}, candle {b}");
    }
    Ok(())
}

fn tiny_config(robot: Robot, seed: u64, steps: usize) -> ControlConfig {
    let mut c = ControlConfig::for_robot(robot);
    c.seed = seed;
    c.total_steps = steps;
    c.ppo = PpoConfig { rollout: 2000, minibatch: 100, epochs: 4, ..PpoConfig::reference() };
    c
}

/// Metrics without the wall-clock fields, for comparisons.
fn numbers(m: &schrl::control::ControlMetrics) -> String {
    let mut m = m.clone();
    m.steps_per_sec = 0.0;
    m.rollout_s = 0.0;
    m.update_s = 0.0;
    serde_json::to_string(&m).unwrap()
}

#[test]
fn a_tiny_budget_lowers_the_value_loss_and_beats_the_untrained_policy() {
    let mut t = ControlTrainer::new(tiny_config(Robot::Point, 3, 80_000)).unwrap();
    let map = open_map(Robot::Point);
    let before = evaluate(&t.controller(), &map, 100, 99, 1000, GoalDraw::Anywhere).unwrap();
    let mut value_losses = Vec::new();
    while !t.finished() {
        value_losses.push(t.train_update().unwrap().update_stats.loss.value_loss);
    }
    let after = evaluate(&t.controller(), &map, 100, 99, 1000, GoalDraw::Anywhere).unwrap();
    let early = value_losses[..3].iter().sum::<f32>();
    let late = value_losses[value_losses.len() - 3..].iter().sum::<f32>();
    assert!(late < early, "value loss did not fall: {value_losses:?}");
    assert!(
        after.success_rate >= before.success_rate + 0.3,
        "success {} → {}",
        before.success_rate,
        after.success_rate
    );
}

#[test]
fn identical_seeds_give_identical_runs_for_every_robot() {
    for robot in Robot::NATIVE {
        let run = |seed| {
            let mut t = ControlTrainer::new(tiny_config(robot, seed, 4000)).unwrap();
            let m: Vec<String> = (0..2).map(|_| numbers(&t.train_update().unwrap())).collect();
            (m, t.policy.params.clone())
        };
        let a = run(5);
        assert_eq!(a, run(5), "{robot}");
        assert_ne!(a.1, run(6).1, "{robot}: the seed changes nothing");
    }
}

/// A controller run directory holding `t`'s checkpoint.
fn save_run(dir: &std::path::Path, t: &ControlTrainer) {
    let mut run = RunWriter::create(dir, RunKind::Controller, &t.config, Existing::Replace).unwrap();
    run.save(|f| store::controller::save_into(f, t)).unwrap();
}

#[test]
fn resuming_from_a_checkpoint_continues_exactly() {
    let scratch = tempfile::tempdir().unwrap();
    let dir = scratch.path().join("control-resume");
    // Near goals too: their draws come from the checkpointed random streams; the
    // off-track penalty, measured from where each environment's goal was set; and the
    // track in the observation, whose length the checkpoint must agree with.
    let cfg = ControlConfig {
        near_goals: Some(NearGoals { fraction: 0.5, within: 1.0 }),
        off_track_weight: 0.2,
        observe_track: true,
        ..tiny_config(Robot::Car, 8, 8000)
    };
    let mut straight = ControlTrainer::new(cfg.clone()).unwrap();
    let first = numbers(&straight.train_update().unwrap());
    save_run(&dir, &straight);
    let second = numbers(&straight.train_update().unwrap());

    let mut resumed = store::controller::load(&dir).unwrap();
    assert_eq!(resumed.updates, 1);
    assert_eq!(numbers(&resumed.train_update().unwrap()), second);
    assert_eq!(resumed.policy.params, straight.policy.params);
    assert_ne!(first, second);
    assert_eq!(resumed.policy.obs_dim(), 26 + 2, "the Car's observation and its track offset");
    let deployed = resumed.controller();
    assert!(deployed.observe_track);
    evaluate(&deployed, &open_map(Robot::Car), 4, 1, 50, GoalDraw::Anywhere).unwrap();

    // Starting another run there without permission to replace it is refused.
    let err = RunWriter::create(&dir, RunKind::Controller, &cfg, Existing::Refuse).err().unwrap();
    assert!(err.to_string().contains("already holds a controller run"), "{err}");
}

#[test]
fn corrupt_or_mismatched_checkpoints_are_clear_errors() {
    let scratch = tempfile::tempdir().unwrap();
    let base = scratch.path().join("control-bad");
    let (a, b) = (base.join("a"), base.join("b"));
    let point = ControlTrainer::new(tiny_config(Robot::Point, 1, 4000)).unwrap();
    let car = ControlTrainer::new(tiny_config(Robot::Car, 1, 4000)).unwrap();
    save_run(&a, &point);
    save_run(&b, &car);

    // Weights of another run in place of this run's.
    std::fs::copy(b.join("gen-0/controller.safetensors"), a.join("gen-0/controller.safetensors")).unwrap();
    let err = store::controller::load(&a).err().expect("mixed files must not load").to_string();
    assert!(err.contains("controller.safetensors") && err.contains("checksum"), "{err}");

    // Truncated state.
    let state = b.join("gen-0/controller.json");
    let text = std::fs::read_to_string(&state).unwrap();
    std::fs::write(&state, &text[..text.len() / 2]).unwrap();
    let err = store::controller::load(&b).err().expect("truncated state must not load").to_string();
    assert!(err.contains("controller.json"), "{err}");

    let err = store::controller::load(&base.join("missing")).err().expect("no checkpoint").to_string();
    assert!(err.contains("missing"), "{err}");
}

#[test]
fn bad_configurations_name_the_field() {
    let mut c = tiny_config(Robot::Point, 0, 1000);
    c.ppo.rollout = 1001;
    let err = ControlTrainer::new(c).err().unwrap().to_string();
    assert!(err.contains("ppo.rollout"), "{err}");
    let mut c = tiny_config(Robot::Point, 0, 1000);
    c.ppo.gamma = 1.5;
    assert!(ControlTrainer::new(c).err().unwrap().to_string().contains("ppo.gamma"));
    let mut c = tiny_config(Robot::Point, 0, 1000);
    c.map = "moon".into();
    assert!(ControlTrainer::new(c).err().unwrap().to_string().contains("moon"));
    for bad in [NearGoals { fraction: 1.5, within: 1.0 }, NearGoals { fraction: 0.2, within: 0.0 }] {
        let mut c = tiny_config(Robot::Car, 0, 1000);
        c.near_goals = Some(bad);
        assert!(ControlTrainer::new(c).err().unwrap().to_string().contains("near_goals"), "{bad:?}");
    }
    for bad in [-1.0, f64::NAN] {
        let mut c = tiny_config(Robot::Point, 0, 1000);
        c.fall_penalty = bad;
        assert!(ControlTrainer::new(c).err().unwrap().to_string().contains("fall_penalty"), "{bad}");
        let mut c = tiny_config(Robot::Point, 0, 1000);
        c.off_track_weight = bad;
        assert!(ControlTrainer::new(c).err().unwrap().to_string().contains("off_track_weight"), "{bad}");
    }
}

/// An option (paper App. K) chases its one goal: every reach ends the episode, and
/// every environment's goal stays the given one through resets.
#[test]
fn an_option_chases_one_goal_and_each_reach_ends_its_episode() {
    let goal = vec![0.5, 0.5];
    let mut c = tiny_config(Robot::Point, 2, 40_000);
    c.goal = Some(goal.clone());
    let mut t = ControlTrainer::new(c).unwrap();
    let (mut reached, mut episodes, mut settled) = (0, 0, 0);
    while !t.finished() {
        let m = t.train_update().unwrap();
        (reached, episodes, settled) =
            (reached + m.goals_reached, episodes + m.episodes, settled + m.goals_settled);
        assert!(t.envs.envs().iter().all(|e| e.goal() == goal.as_slice()), "the goal never changes");
    }
    assert!(reached > 0, "a goal 0.7 m away is reached on a tiny budget");
    assert_eq!(settled, episodes, "one goal per episode: reached (ending it) or lost with it");
    let mut off = tiny_config(Robot::Point, 2, 2000);
    off.goal = Some(vec![99.0, 0.0]);
    assert!(ControlTrainer::new(off).err().expect("refused").to_string().contains("goal"));
}

/// The Doggo alone observes and pays for its track by default, 0.1 a metre in
/// controller training and 0.3 in the joint phase (README, *The track in the
/// controller's observation*, *A heavier off-track weight in the joint phase*); the
/// other robots keep the paper's reward and observation.
#[test]
fn only_the_doggo_observes_and_pays_for_its_track_by_default() {
    for robot in Robot::ALL {
        let c = ControlConfig::for_robot(robot);
        let doggo = robot == Robot::Doggo;
        assert_eq!(c.observe_track, doggo, "{robot:?}");
        assert_eq!(c.off_track_weight, if doggo { 0.1 } else { 0.0 }, "{robot:?}");
        let joint = schrl::control::TrackDefaults::for_robot(robot).joint_off_track_weight;
        assert_eq!(joint, if doggo { 0.3 } else { 0.0 }, "{robot:?}");
    }
}
