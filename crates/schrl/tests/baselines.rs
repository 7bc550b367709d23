//! The paper's baselines: TLTL learns an easy spec from its robustness alone and
//! resumes exactly; HTLTL is joint training with the Lagrange term gone; the spec
//! score every curve plots; TD3's and the meta-controller's gradients against autograd.

mod common;

use std::path::Path;

use schrl::baseline::flat::{MeanPolicy, evaluate};
use schrl::baseline::htltl;
use schrl::baseline::tltl::{TltlSettings, TltlTrainer};
use schrl::control::{ControlConfig, ControlTrainer, PpoConfig};
use schrl::plan::cpg::{CpgConfig, Method};
use schrl::run::joint::{JointConfig, JointTrainer};
use schrl::store::{self, Existing, RunKind, RunWriter};
use schrl::task::{Task, TaskKind};
use sim::Robot;

/// Point in the open, one goal a metre ahead: reachable in well under the 100 steps.
const EASY: &str = r#"
name = "easy"
robot = "point"
map = "empty"
spec = "easy.stl"
steps = 2
step_limit = 100
safe_radius = 0.1

[start]
low = [-0.2, -0.2]
high = [0.2, 0.2]

[[goal]]
name = "g"
center = [1.0, 0.0]
radius = 0.6
"#;

fn easy_settings(seed: u64) -> TltlSettings {
    TltlSettings {
        robot: Robot::Point,
        task_toml: EASY.into(),
        task_spec: "F[1,2] g & G[1,2] safe".into(),
        seed,
        steps: 40_000,
        ppo: PpoConfig { rollout: 1000, ..PpoConfig::reference() },
        eval_groups: 0,
        save_every: 1,
    }
}

#[test]
fn tltl_raises_the_spec_score_and_satisfies_an_easy_spec_well_above_chance() {
    let mut t = TltlTrainer::new(easy_settings(1)).unwrap();
    let mut scores = vec![];
    while !t.finished() {
        let m = t.train_update().unwrap();
        scores.extend(m.episodes.score);
    }
    let mean = |s: &[f64]| s.iter().sum::<f64>() / s.len() as f64;
    let (early, late) = (mean(&scores[..5]), mean(&scores[scores.len() - 5..]));
    assert!(late > early + 0.1, "spec score did not rise: {early:.3} → {late:.3}");
    let e = evaluate(&t.task, &mut MeanPolicy::new(&t.controller()), (1, 50), 7).unwrap();
    // An untrained policy satisfies it in about 2 % of episodes.
    assert!(e.satisfaction[0] >= 0.3, "satisfaction {:?}", e.satisfaction);
    assert_eq!(e.collisions, 0);
    // The mean over satisfying episodes of the sampled step (50 or 100) from which the
    // spec held.
    let steps = e.steps_to_reach[0];
    assert!((50.0..=100.0).contains(&steps), "{steps}");
}

#[test]
fn a_resumed_tltl_run_continues_exactly_as_one_that_never_stopped() {
    let mut straight = TltlTrainer::new(easy_settings(2)).unwrap();
    let scratch = tempfile::tempdir().unwrap();
    let dir = scratch.path().join("tltl-resume");
    let settings = easy_settings(2);
    let mut run = RunWriter::create(&dir, RunKind::Tltl, &settings, Existing::Refuse).unwrap();
    let mut stopped = TltlTrainer::new(settings).unwrap();
    for _ in 0..2 {
        straight.train_update().unwrap();
        stopped.train_update().unwrap();
    }
    run.save(|f| store::tltl::save_into(f, &stopped)).unwrap();
    drop((run, stopped));
    let mut resumed = store::tltl::load(&dir).unwrap();
    let a = straight.train_update().unwrap();
    let b = resumed.train_update().unwrap();
    assert_eq!(a.episodes, b.episodes);
    assert_eq!(straight.policy.params, resumed.policy.params);
    assert_eq!(straight.raw_obs, resumed.raw_obs);
    assert_eq!(straight.trajectories, resumed.trajectories);
    // Another kind's reader refuses it, naming both kinds.
    let err = store::joint::load(&dir).err().expect("a TLTL run is not a joint run").to_string();
    assert!(err.contains("tltl") && err.contains("joint"), "{err}");
}

#[test]
fn tltl_refuses_a_task_for_another_robot() {
    let s = TltlSettings { robot: Robot::Car, ..easy_settings(0) };
    let err = TltlTrainer::new(s).err().expect("refused").to_string();
    assert!(err.contains("robot") && err.contains("car"), "{err}");
}

#[test]
fn htltl_is_joint_training_without_the_lagrange_term() {
    let cpg = htltl(CpgConfig { seed: 5, ..CpgConfig::default() });
    assert_eq!(cpg.method, Method::Pg);
    let mut cc = ControlConfig::for_robot(Robot::Point);
    cc.ppo = PpoConfig { rollout: 1000, minibatch: 100, epochs: 2, ..PpoConfig::reference() };
    let control = ControlTrainer::new(cc).unwrap();
    let mut t =
        JointTrainer::new(Task::point(TaskKind::Branch), JointConfig::default(), cpg, control).unwrap();
    let before = t.plan.varmap().all_vars()[0].as_tensor().flatten_all().unwrap().to_vec1::<f32>().unwrap();
    for _ in 0..5 {
        let m = t.iterate().unwrap();
        // λ neither enters the loss nor moves, even while the plans violate the spec.
        assert_eq!(m.lambda, cpg.lambda_init);
        assert!(m.plan_loss.is_some());
        assert!(m.score.is_some_and(f64::is_finite), "{:?}", m.score);
    }
    let after = t.plan.varmap().all_vars()[0].as_tensor().flatten_all().unwrap().to_vec1::<f32>().unwrap();
    assert_ne!(before, after, "the planner never trained");
}

#[test]
fn the_spec_score_is_the_robustness_of_a_finished_run_and_finite_for_an_unfinished_one() {
    let task =
        Task::from_texts(Path::new("easy.toml"), EASY, Path::new("easy.stl"), "F[1,2] g & G[1,2] safe")
            .unwrap();
    let spec = task.execution_spec();
    let trajectory: Vec<Vec<f64>> = (0..=100).map(|k| vec![k as f64 / 100.0, 0.0]).collect();
    let executed = vec![trajectory[0].clone(), trajectory[50].clone(), trajectory[100].clone()];
    let judged = spec.judge(&executed, &trajectory, &[50, 100]).robustness;
    assert_eq!(spec.score(&executed, &trajectory, &[50, 100]), judged);
    assert!((judged - 0.6).abs() < 1e-9, "{judged}");
    // Stopped at step 30 (say, by a collision) before reaching a waypoint: judged −∞,
    // scored as staying at x = 0.3, 0.1 m outside the goal.
    let short = &trajectory[..=30];
    assert_eq!(spec.judge(&executed[..2], short, &[30]).robustness, f64::NEG_INFINITY);
    let s = spec.score(&[trajectory[0].clone()], short, &[]);
    assert!((s - (0.6 - 0.7)).abs() < 1e-9, "{s}");
}

mod reward_machines {
    use std::collections::BTreeSet;
    use std::path::Path;

    use schrl::baseline::reward_machine::{Labels, RewardMachine};
    use schrl::task::{Task, TaskKind};

    fn labels(events: &[&str]) -> Labels {
        Labels(events.iter().map(|e| e.to_string()).collect::<BTreeSet<_>>())
    }

    /// Runs `m` over `trace` from its initial state: the states visited and the return.
    fn run(m: &RewardMachine, trace: &[&[&str]]) -> (Vec<String>, f64) {
        let (mut u, mut total, mut seen) = (m.initial, 0.0, vec![]);
        for events in trace {
            let (next, r) = m.step(u, &labels(events));
            u = next;
            total += r;
            seen.push(m.states[u].clone());
        }
        (seen, total)
    }

    #[test]
    fn the_sequence_machine_advances_only_on_the_next_goal_in_order() {
        let m = RewardMachine::shipped(&Task::point(TaskKind::Seq)).unwrap();
        let (seen, total) = run(&m, &[&[], &["g1"], &["g0"], &["g0"], &["g2"], &["g1"], &["g2"], &["g3"]]);
        assert_eq!(seen, ["u0", "u0", "u1", "u1", "u1", "u2", "u3", "done"]);
        assert_eq!(total, 4.0);
        assert!(m.terminal[m.states.iter().position(|s| s == "done").unwrap()]);
        let (seen, total) = run(&m, &[&["g0"], &["collision", "g1"]]);
        assert_eq!(seen, ["u1", "fail"], "a collision wins over progress");
        assert_eq!(total, 0.0);
    }

    #[test]
    fn the_coverage_machine_accepts_any_order() {
        let m = RewardMachine::shipped(&Task::point(TaskKind::Cover)).unwrap();
        let (seen, total) = run(&m, &[&["g2"], &["g0"], &["g2"], &["g3"], &["g1"]]);
        assert_eq!(seen, ["v2", "v02", "v02", "v023", "all"]);
        assert_eq!(total, 4.0);
    }

    #[test]
    fn the_branch_machine_holds_to_the_first_pair_chosen() {
        let m = RewardMachine::shipped(&Task::point(TaskKind::Branch)).unwrap();
        let (seen, _) = run(&m, &[&["a1"], &["b0"], &["b1"]]);
        assert_eq!(seen, ["after_a1", "after_a1", "done"]);
    }

    #[test]
    fn the_signal_machine_pays_corners_until_the_counter_then_the_final_goal() {
        let m = RewardMachine::shipped(&Task::point(TaskKind::Signal)).unwrap();
        let trace: &[&[&str]] =
            &[&["l0"], &["l0"], &["final"], &["l1"], &["l2", "counter"], &["final", "counter"]];
        let (seen, total) = run(&m, trace);
        assert_eq!(seen, ["at_l0", "at_l0", "at_l0", "at_l1", "at_l1", "done"]);
        assert_eq!(total, 3.0);
    }

    #[test]
    fn the_loop_machine_never_pays_the_same_corner_twice_in_a_row() {
        let m = RewardMachine::shipped(&Task::point(TaskKind::Loop)).unwrap();
        let (seen, total) = run(&m, &[&["l0"], &["l0"], &["l3"], &["l0"]]);
        assert_eq!(seen, ["at_l0", "at_l0", "at_l3", "at_l0"]);
        assert_eq!(total, 3.0);
        let (start, fail) = (m.initial, m.states.iter().position(|s| s == "fail").unwrap());
        let options = m.options();
        assert_eq!(options.iter().filter(|(from, _)| *from == start).count(), 4, "one per corner");
        assert!(options.iter().all(|(_, to)| *to != fail), "a collision is not an option");
    }

    #[test]
    fn events_are_goals_the_robot_is_in_collisions_and_the_counter() {
        let task = Task::point(TaskKind::Signal);
        let final_goal = task.goals.iter().find(|g| g.name == "final").unwrap().center.clone();
        assert_eq!(Labels::of(&task, &final_goal, false, 3.0), labels(&["final"]));
        assert_eq!(Labels::of(&task, &[-2.0, -2.0], true, 10.0), labels(&["collision", "counter", "l0"]));
    }

    #[test]
    fn a_bad_machine_file_is_refused_with_where_and_why() {
        let task = Task::point(TaskKind::Seq);
        let parse =
            |text: &str| RewardMachine::parse(Path::new("m.toml"), text, &task).unwrap_err().to_string();
        let edge = "[[edge]]\nfrom = \"u0\"\nto = \"u1\"\non = \"g9\"\nreward = 1.0\n";
        let e = parse(&format!("initial = \"u0\"\n{edge}"));
        assert!(
            e.starts_with("m.toml: edge 1 (u0 -> u1): unknown event 'g9'") && e.contains("g0, g1"),
            "{e}"
        );
        let e = parse("initial = \"u0\"\nedge = 3\n");
        assert!(e.contains("line 2, column"), "{e}");
        let e = parse(&format!("initial = \"u0\"\nterminal = [\"nowhere\"]\n{}", edge.replace("g9", "g0")));
        assert!(e.contains("terminal state 'nowhere'"), "{e}");
        let counter = parse(&format!("initial = \"u0\"\n{}", edge.replace("g9", "counter")));
        assert!(counter.contains("unknown event 'counter'"), "Seq has no counter: {counter}");
    }
}

mod crm {
    use schrl::baseline::crm::{CHUNK, CrmMetrics, CrmSettings, CrmTrainer};
    use schrl::baseline::dhrm::DhrmConfig;
    use schrl::baseline::reward_machine::RewardMachine;
    use schrl::baseline::td3::Td3Config;
    use schrl::store::{self, Existing, RunKind, RunWriter};
    use schrl::task::{Task, TaskKind};
    use sim::Robot;

    /// Seq with every episode starting at the centre of g1.
    fn seq_from_g1(td3: Td3Config, steps: usize) -> CrmSettings {
        let seq = Task::point(TaskKind::Seq);
        let toml = seq
            .toml
            .replace("low = [1.0, -2.0]", "low = [-1.0, 2.0]")
            .replace("high = [2.0, -1.0]", "high = [-1.0, 2.0]");
        assert_ne!(toml, seq.toml);
        CrmSettings {
            robot: Robot::Point,
            task_toml: toml,
            task_spec: seq.spec.clone(),
            machine: RewardMachine::shipped_text("seq").unwrap().into(),
            seed: 4,
            steps,
            td3,
            eval_groups: 0,
            save_every: 1,
            dhrm: None,
        }
    }

    #[test]
    fn every_real_step_adds_one_counterfactual_experience_per_live_machine_state() {
        let mut t = CrmTrainer::new(seq_from_g1(Td3Config::default(), 1)).unwrap();
        let live: Vec<usize> = (0..t.machine.len()).filter(|u| !t.machine.terminal[*u]).collect();
        t.train_chunk().unwrap();
        let name = |u: u32| t.machine.states[u as usize].clone();
        let b = &t.buffer;
        assert_eq!(b.len(), live.len(), "one experience per live state (u0..u3)");
        // The robot is in g1 throughout its first step: only u1 moves on, to u2, paid 1.
        let states: Vec<String> = b.states.iter().map(|u| name(*u)).collect();
        let next: Vec<String> = b.next_states.iter().map(|u| name(*u)).collect();
        assert_eq!(states, ["u0", "u1", "u2", "u3"]);
        assert_eq!(next, ["u0", "u2", "u2", "u3"]);
        assert_eq!(b.rewards, [0.0, 1.0, 0.0, 0.0]);
        assert!(b.dones.iter().all(|d| !d));
        // They share the real step's observations and action.
        let od = b.obs_dim;
        for k in 1..b.len() {
            assert_eq!(b.obs[..od], b.obs[k * od..(k + 1) * od]);
            assert_eq!(b.next_obs[..od], b.next_obs[k * od..(k + 1) * od]);
            assert_eq!(b.actions[..b.act_dim], b.actions[k * b.act_dim..(k + 1) * b.act_dim]);
        }
        // The real machine moved as u0 would: still u0 (g0 first).
        assert_eq!(t.machine.states[t.state], "u0");
    }

    /// Trains `settings` for two chunks straight, and for one chunk, saved, loaded and
    /// one more; returns both trainers and the first chunk's and second chunks' metrics.
    fn straight_and_resumed(settings: CrmSettings, name: &str) -> (CrmTrainer, CrmTrainer, [CrmMetrics; 3]) {
        let scratch = tempfile::tempdir().unwrap();
        let dir = scratch.path().join(format!("{name}-resume"));
        let mut run = RunWriter::create(&dir, RunKind::Crm, &settings, Existing::Refuse).unwrap();
        let mut straight = CrmTrainer::new(settings.clone()).unwrap();
        let mut stopped = CrmTrainer::new(settings).unwrap();
        straight.train_chunk().unwrap();
        let first = stopped.train_chunk().unwrap();
        run.save(|f| store::crm::save_into(f, &stopped)).unwrap();
        drop((run, stopped));
        let mut resumed = store::crm::load(&dir).unwrap();
        let (a, b) = (straight.train_chunk().unwrap(), resumed.train_chunk().unwrap());
        (straight, resumed, [first, a, b])
    }

    #[test]
    fn a_resumed_crm_run_continues_exactly_as_one_that_never_stopped() {
        // Learning starts 300 steps before the first chunk ends; the second (last) chunk
        // is the budget's remaining 600 steps.
        let td3 = Td3Config { learning_starts: CHUNK - 300, buffer: 10_000, ..Td3Config::default() };
        let (straight, resumed, [first, a, b]) = straight_and_resumed(seq_from_g1(td3, CHUNK + 600), "crm");
        assert!(first.critic_loss.is_some(), "learning started within the first chunk");
        assert_eq!((a.critic_loss, &a.episodes), (b.critic_loss, &b.episodes));
        assert_eq!(straight.td3.actor_params, resumed.td3.actor_params);
        assert_eq!(straight.buffer, resumed.buffer);
        assert_eq!((straight.state, &straight.raw_obs), (resumed.state, &resumed.raw_obs));
    }

    #[test]
    fn dhrm_adds_one_experience_per_option_and_follows_an_option_of_the_current_state() {
        let settings =
            CrmSettings { dhrm: Some(DhrmConfig::default()), ..seq_from_g1(Td3Config::default(), 1) };
        let mut t = CrmTrainer::new(settings).unwrap();
        let h = t.hierarchy.as_ref().unwrap();
        let name = |u: usize| t.machine.states[u].clone();
        let edges: Vec<(String, String)> = h.options.iter().map(|(a, b)| (name(*a), name(*b))).collect();
        let want = [("u0", "u1"), ("u1", "u2"), ("u2", "u3"), ("u3", "done")];
        assert_eq!(edges, want.map(|(a, b)| (a.to_string(), b.to_string())), "collisions are not options");
        assert_eq!(h.options[h.current.option].0, t.machine.initial);
        t.train_chunk().unwrap();
        let b = &t.buffer;
        assert_eq!(b.len(), 4, "one experience per option");
        assert_eq!(b.states, [0, 1, 2, 3]);
        assert_eq!(b.next_states, b.states, "an option's experience stays with it");
        // In g1 on the first step: option u1 → u2 reaches its target and ends.
        assert_eq!(b.rewards, [0.0, 1.0, 0.0, 0.0]);
        assert_eq!(b.dones, [false, true, false, false]);
        let h = t.hierarchy.as_ref().unwrap();
        assert_eq!((h.current.steps, h.buffer.len()), (1, 0), "the option still runs: the machine is in u0");
    }

    #[test]
    fn a_resumed_dhrm_run_continues_exactly_as_one_that_never_stopped() {
        let td3 = Td3Config { learning_starts: CHUNK - 300, buffer: 10_000, ..Td3Config::default() };
        // A meta batch of one: the meta-controller learns from the first option run on.
        let dhrm = DhrmConfig { batch: 1, target_every: 50, ..DhrmConfig::default() };
        let settings = CrmSettings { dhrm: Some(dhrm), ..seq_from_g1(td3, CHUNK + 600) };
        let (straight, resumed, [first, a, b]) = straight_and_resumed(settings, "dhrm");
        assert!(first.meta_loss.is_some(), "the meta-controller learned within the first chunk");
        assert_eq!((a.critic_loss, a.meta_loss, &a.episodes), (b.critic_loss, b.meta_loss, &b.episodes));
        assert_eq!(straight.td3.actor_params, resumed.td3.actor_params);
        let (hs, hr) = (straight.hierarchy.as_ref().unwrap(), resumed.hierarchy.as_ref().unwrap());
        assert_eq!((&hs.q_params, &hs.q_target, &hs.buffer), (&hr.q_params, &hr.q_target, &hr.buffer));
        assert_eq!(hs.current, hr.current);
    }

    #[test]
    fn dhrm_refuses_a_machine_with_a_live_state_it_cannot_leave() {
        let mut settings =
            CrmSettings { dhrm: Some(DhrmConfig::default()), ..seq_from_g1(Td3Config::default(), 1) };
        // u3 → done pays nothing: u3 is live with no option.
        settings.machine = settings
            .machine
            .replace("to = \"done\"\non = \"g3\"\nreward = 1.0", "to = \"done\"\non = \"g3\"\nreward = 0.0");
        let err = CrmTrainer::new(settings).err().expect("refused").to_string();
        assert!(err.contains("'u3'") && err.contains("no option"), "{err}");
    }
}

/// TD3's and the DQN meta-controller's hand-written gradients against candle's
/// autograd of the same losses (as PPO's are checked in `control.rs`).
mod autodiff {
    use super::common::{assert_grads_close, candle_mlp, flat_grads};
    use candle_core::{Device, Tensor};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use schrl::baseline::dhrm::{DhrmConfig, Hierarchy};
    use schrl::baseline::reward_machine::RewardMachine;
    use schrl::baseline::td3::{Td3, Td3Config};
    use schrl::nn::mlp::TanhMlp;
    use schrl::task::{Task, TaskKind};

    const IN: usize = 5;
    const ACT: usize = 2;
    const HIDDEN: [usize; 2] = [7, 6];

    fn uniform(rng: &mut ChaCha8Rng, n: usize, r: f32) -> Vec<f32> {
        (0..n).map(|_| rng.random_range(-r..r)).collect()
    }

    fn td3(rng: &mut ChaCha8Rng) -> Td3 {
        let mut t = Td3::new(IN, ACT, Td3Config { hidden: HIDDEN.to_vec(), ..Td3Config::default() }, rng);
        // Non-trivial networks: perturb every parameter.
        for p in t.actor_params.iter_mut().chain(t.critic_params.iter_mut()) {
            *p += rng.random_range(-0.3..0.3);
        }
        t
    }

    fn sizes(i: usize, o: usize) -> Vec<usize> {
        [vec![i], HIDDEN.to_vec(), vec![o]].concat()
    }

    #[test]
    fn td3_critic_gradient_matches_candle_autograd() -> candle_core::Result<()> {
        let mut rng = ChaCha8Rng::seed_from_u64(21);
        let t = td3(&mut rng);
        let n = 16;
        let (x, a, y) =
            (uniform(&mut rng, n * IN, 2.0), uniform(&mut rng, n * ACT, 1.0), uniform(&mut rng, n, 1.0));
        let (loss, grad) = t.critic_gradient(&x, &a, &y, n);
        let critic = TanhMlp::new(&sizes(IN + ACT, 1));
        let qn = critic.num_params();
        let dev = Device::Cpu;
        let xa = Tensor::cat(
            &[Tensor::from_slice(&x, (n, IN), &dev)?, Tensor::from_slice(&a, (n, ACT), &dev)?],
            1,
        )?;
        let yt = Tensor::from_slice(&y, n, &dev)?;
        let mut expected = Vec::new();
        let mut total = 0.0;
        for c in 0..2 {
            let (q, vars) = candle_mlp(&critic, &t.critic_params[c * qn..(c + 1) * qn], &xa)?;
            let l = q.squeeze(1)?.sub(&yt)?.sqr()?.mean_all()?;
            total += l.to_scalar::<f32>()? as f64;
            expected.extend(flat_grads(&l.backward()?, &vars)?);
        }
        assert!((total - loss).abs() < 1e-4 * (1.0 + loss.abs()), "loss {total} vs {loss}");
        assert_grads_close(&grad, &expected, 1e-4, "critic");
        Ok(())
    }

    #[test]
    fn td3_actor_gradient_matches_candle_autograd() -> candle_core::Result<()> {
        let mut rng = ChaCha8Rng::seed_from_u64(22);
        let t = td3(&mut rng);
        let n = 16;
        let x = uniform(&mut rng, n * IN, 2.0);
        let (loss, grad) = t.actor_gradient(&x, n);
        let (actor, critic) = (TanhMlp::new(&sizes(IN, ACT)), TanhMlp::new(&sizes(IN + ACT, 1)));
        let dev = Device::Cpu;
        let xt = Tensor::from_slice(&x, (n, IN), &dev)?;
        let (z, vars) = candle_mlp(&actor, &t.actor_params, &xt)?;
        let xa = Tensor::cat(&[xt, z.tanh()?], 1)?;
        let (q, _) = candle_mlp(&critic, &t.critic_params[..critic.num_params()], &xa)?;
        let l = q.mean_all()?.neg()?;
        let want = l.to_scalar::<f32>()? as f64;
        assert!((want - loss).abs() < 1e-4 * (1.0 + loss.abs()), "loss {want} vs {loss}");
        assert_grads_close(&grad, &flat_grads(&l.backward()?, &vars)?, 1e-4, "actor");
        Ok(())
    }

    #[test]
    fn dqn_meta_gradient_matches_candle_autograd() -> candle_core::Result<()> {
        let mut rng = ChaCha8Rng::seed_from_u64(23);
        let machine = RewardMachine::shipped(&Task::point(TaskKind::Branch)).unwrap();
        let cfg = DhrmConfig { hidden: HIDDEN.to_vec(), ..DhrmConfig::default() };
        let mut h = Hierarchy::new(cfg, &machine, IN, &mut rng).unwrap();
        for p in h.q_params.iter_mut() {
            *p += rng.random_range(-0.3..0.3);
        }
        let (n, k, m) = (12, h.len(), machine.len());
        let x = uniform(&mut rng, n * (IN + m), 2.0);
        let chosen: Vec<usize> = (0..n).map(|_| rng.random_range(0..k)).collect();
        let y = uniform(&mut rng, n, 1.0);
        let (loss, grad) = h.gradient(&x, &chosen, &y);
        let q_net = TanhMlp::new(&sizes(IN + m, k));
        let dev = Device::Cpu;
        let (q, vars) = candle_mlp(&q_net, &h.q_params, &Tensor::from_slice(&x, (n, IN + m), &dev)?)?;
        let mask: Vec<f32> = (0..n * k).map(|i| f32::from(u8::from(i % k == chosen[i / k]))).collect();
        let picked = q.mul(&Tensor::from_slice(&mask, (n, k), &dev)?)?.sum(1)?;
        let l = picked.sub(&Tensor::from_slice(&y, n, &dev)?)?.sqr()?.mean_all()?;
        let want = l.to_scalar::<f32>()? as f64;
        assert!((want - loss).abs() < 1e-4 * (1.0 + loss.abs()), "loss {want} vs {loss}");
        assert_grads_close(&grad, &flat_grads(&l.backward()?, &vars)?, 1e-4, "meta Q");
        Ok(())
    }
}
