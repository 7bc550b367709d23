//! The planner and the constrained policy gradient.

use candle_core::{DType, Device, Tensor};
use candle_nn::{VarBuilder, VarMap};
use schrl::plan::cpg::{CpgConfig, Lagrangian, Method, PlanTrainer, seeded_init};
use schrl::plan::planner::{PathPlanner, PlannerConfig};
use schrl::store::planner::PlanRunSettings;
use schrl::store::{self, Checkpoint, Existing, RunKind, RunWriter};
use schrl::task::SafeAlong;
use schrl::task::{Task, TaskKind};

fn tiny_planner(seed: u64) -> PathPlanner {
    let varmap = VarMap::new();
    let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
    let p = PathPlanner::new(
        PlannerConfig { dim: 2, hidden: 4, bound: 2.0, min_std: 0.1, kind: Default::default() },
        vb,
    )
    .unwrap();
    seeded_init(&varmap, seed).unwrap();
    p
}

#[test]
fn path_log_probability_matches_a_hand_computation() {
    let planner = tiny_planner(3);
    let g0 = Tensor::new(&[[0.5f32, -0.5], [1.0, 2.0]], &Device::Cpu).unwrap();
    let noise = Tensor::new(
        &[[[0.3f32, -1.2], [0.7, 0.1], [-0.4, 2.0]], [[1.5, 0.2], [-0.9, -0.3], [0.0, 0.8]]],
        &Device::Cpu,
    )
    .unwrap();
    let batch = planner.sample(&g0, &noise).unwrap();
    // The same paths scored step by step: Σ log N(x; μ, σ) with μ, σ from the planner.
    let (means, stds) = planner.distributions(&batch.paths).unwrap();
    let paths = batch.paths.to_vec3::<f32>().unwrap();
    let (means, stds) = (means.to_vec3::<f32>().unwrap(), stds.to_vec3::<f32>().unwrap());
    let eps = noise.to_vec3::<f32>().unwrap();
    let sampled = batch.log_prob.to_vec1::<f32>().unwrap();
    let scored = planner.log_prob(&batch.paths).unwrap().to_vec1::<f32>().unwrap();
    for b in 0..2 {
        let mut hand = 0.0f64;
        for t in 0..3 {
            for d in 0..2 {
                let (x, m, s) = (paths[b][t + 1][d] as f64, means[b][t][d] as f64, stds[b][t][d] as f64);
                // The sample is μ + σ ε.
                assert!((x - (m + s * eps[b][t][d] as f64)).abs() < 1e-5);
                hand += -0.5 * ((x - m) / s).powi(2) - s.ln() - 0.5 * (2.0 * std::f64::consts::PI).ln();
            }
        }
        assert!((sampled[b] as f64 - hand).abs() < 1e-4, "{} vs {hand}", sampled[b]);
        assert!((scored[b] as f64 - hand).abs() < 1e-4, "{} vs {hand}", scored[b]);
    }
}

#[test]
fn waypoint_steps_are_bounded() {
    let planner = tiny_planner(1);
    let g0 = Tensor::new(&[[0.0f32, 0.0]], &Device::Cpu).unwrap();
    let path = planner.mean_path(&g0, 5).unwrap().to_vec3::<f32>().unwrap();
    for w in path[0].windows(2) {
        for (next, now) in w[1].iter().zip(&w[0]) {
            assert!((next - now).abs() <= 2.0 + 1e-6, "bound · tanh keeps steps within the bound");
        }
    }
}

#[test]
fn lambda_rises_while_violated_and_returns_to_zero_when_slack() {
    let mut l = Lagrangian { lambda: 0.0, lr: 0.5, epsilon: 0.1 };
    for _ in 0..10 {
        l.update(-1.0);
    }
    assert!((l.lambda - 5.5).abs() < 1e-12, "10 steps of 0.5 · 1.1: {}", l.lambda);
    let mut last = l.lambda;
    while l.lambda > 0.0 {
        l.update(1.0);
        assert!(l.lambda < last);
        last = l.lambda;
    }
    l.update(2.0);
    assert_eq!(l.lambda, 0.0, "λ stays at 0 while the constraint holds with slack");
}

fn train(kind: TaskKind, method: Method, updates: usize) -> (f64, f64) {
    let cfg = CpgConfig { method, batch: 32, seed: 7, ..CpgConfig::default() };
    let mut t = PlanTrainer::new(Task::point(kind), cfg).unwrap();
    let before = t.satisfaction(200).unwrap();
    for _ in 0..updates {
        t.update().unwrap();
    }
    (before, t.satisfaction(200).unwrap())
}

#[test]
fn constrained_policy_gradient_learns_the_sequence_task() {
    let (before, after) = train(TaskKind::Seq, Method::Cpg, 150);
    assert!(before < 0.05, "an untrained planner rarely satisfies Seq: {before}");
    // Sampled paths carry ≥ 0.1 m of noise per waypoint against door clearances of
    // tenths of a metre (segment safety), so most, not all, satisfy this early.
    assert!(after > 0.6, "after 150 updates most sampled paths satisfy Seq: {after}");
}

#[test]
fn same_seed_same_training() {
    let run = || {
        let mut t = PlanTrainer::new(
            Task::point(TaskKind::Branch),
            CpgConfig { batch: 16, seed: 5, ..CpgConfig::default() },
        )
        .unwrap();
        (0..5).map(|_| t.update().unwrap().loss).collect::<Vec<_>>()
    };
    assert_eq!(run(), run());
}

#[test]
fn task_specs_parse_bind_and_round_trip() {
    for kind in TaskKind::ALL {
        let task = Task::point(kind);
        let f = task.formula();
        assert_eq!(stl::parse(&f.to_string()).unwrap(), f);
        let spec = task.spec();
        let path = vec![1.5; (task.steps + 1) * 2];
        assert!(spec.robustness(&path, &stl::Semantics::hard()).unwrap().is_finite());
    }
}

#[test]
fn checkpoint_round_trip_gives_the_same_paths() {
    let mut t = PlanTrainer::new(
        Task::point(TaskKind::Seq),
        CpgConfig { batch: 16, seed: 2, ..CpgConfig::default() },
    )
    .unwrap();
    for _ in 0..3 {
        t.update().unwrap();
    }
    let scratch = tempfile::tempdir().unwrap();
    let dir = scratch.path().join("ckpt");
    let settings = PlanRunSettings {
        task: TaskKind::Seq,
        safe_along: SafeAlong::Segments,
        cpg: *t.config(),
        updates: 3,
        target: 0.95,
    };
    let mut run = RunWriter::create(&dir, RunKind::Planner, &settings, Existing::Refuse).unwrap();
    run.save(|f| store::planner::save_into(f, &t, 3, false)).unwrap();
    drop(run);
    let loaded = store::planner::load(&dir).unwrap();
    assert_eq!(loaded.meta.updates, 3);
    assert_eq!(loaded.meta.cpg, *t.config());
    let g0 = Tensor::new(&[[1.5f32, -1.5]], &Device::Cpu).unwrap();
    let a = t.planner().mean_path(&g0, 8).unwrap().to_vec3::<f32>().unwrap();
    let b = loaded.planner.mean_path(&g0, 8).unwrap().to_vec3::<f32>().unwrap();
    assert_eq!(a, b);
    // The restored trainer continues exactly as the original does.
    let ckpt = Checkpoint::open(&dir, RunKind::Planner).unwrap();
    let (mut resumed, updates, _) = store::planner::load_trainer(&ckpt, &settings).unwrap();
    assert_eq!(updates, 3);
    assert_eq!(resumed.update().unwrap(), t.update().unwrap());
    // A corrupt state file is a clear error naming the file.
    std::fs::write(dir.join("gen-0/planner.json"), "{ not json").unwrap();
    let err = store::planner::load(&dir).err().unwrap().to_string();
    assert!(err.contains("planner.json"), "{err}");
}

#[test]
fn planners_with_unusable_weights_or_shapes_are_refused_when_loaded() {
    // Regression: NaN weights evaluated as "satisfaction: 0" with exit 0.
    let t =
        PlanTrainer::new(Task::point(TaskKind::Seq), CpgConfig { batch: 8, ..CpgConfig::default() }).unwrap();
    {
        let data = t.varmap().data().lock().unwrap();
        let var = data.values().next().unwrap();
        var.set(&(var.as_tensor() * f64::NAN).unwrap()).unwrap();
    }
    let scratch = tempfile::tempdir().unwrap();
    let dir = scratch.path().join("nan");
    let settings = PlanRunSettings {
        task: TaskKind::Seq,
        safe_along: SafeAlong::Segments,
        cpg: *t.config(),
        updates: 0,
        target: 0.95,
    };
    let mut run = RunWriter::create(&dir, RunKind::Planner, &settings, Existing::Refuse).unwrap();
    run.save(|f| store::planner::save_into(f, &t, 0, false)).unwrap();
    drop(run);
    let err = store::planner::load(&dir).err().unwrap().to_string();
    assert!(err.contains("planner.safetensors") && err.contains("NaN"), "{err}");
    // Regression: `min_std: -1` and `bound: 0` were accepted.
    use schrl::plan::planner::{PathPlanner, PlannerConfig};
    for (cfg, key) in [
        (PlannerConfig { min_std: -1.0, ..PlannerConfig::reference(2) }, "min_std"),
        (PlannerConfig { bound: 0.0, ..PlannerConfig::reference(2) }, "bound"),
        (PlannerConfig { hidden: 0, ..PlannerConfig::reference(2) }, "hidden"),
    ] {
        let vm = candle_nn::VarMap::new();
        let vb = candle_nn::VarBuilder::from_varmap(&vm, candle_core::DType::F32, &Device::Cpu);
        let err = PathPlanner::new(cfg, vb).err().unwrap().to_string();
        assert!(err.contains(key), "{err}");
    }
}

/// Checking the deployed (mean) paths must not change training: an early version
/// drew its starts from the training generator, and the same seed then trained
/// differently depending on how often it was checked.
#[test]
fn mean_path_check_does_not_shift_training() {
    let cfg = CpgConfig { batch: 8, ..CpgConfig::default() };
    let mut plain = PlanTrainer::new(Task::point(TaskKind::Branch), cfg).unwrap();
    let mut checked = PlanTrainer::new(Task::point(TaskKind::Branch), cfg).unwrap();
    for _ in 0..3 {
        let a = plain.update().unwrap();
        let fraction = checked.mean_satisfaction(16).unwrap();
        assert!((0.0..=1.0).contains(&fraction));
        assert_eq!(checked.mean_satisfaction(16).unwrap(), fraction, "same validation starts each call");
        let b = checked.update().unwrap();
        assert_eq!(a, b);
    }
}

/// The deployed planner (plain Rust, no autodiff) plans the paths candle plans: for
/// a fresh planner and after training has moved its weights.
#[test]
fn deployed_plans_match_candle_mean_paths() {
    use schrl::plan::deployed::DeployedPlanner;
    let mut trainer =
        PlanTrainer::new(Task::point(TaskKind::Seq), CpgConfig { batch: 8, ..Default::default() }).unwrap();
    let check = |trainer: &PlanTrainer| {
        let cfg = *trainer.planner().config();
        let deployed = DeployedPlanner::from_varmap(trainer.varmap(), &cfg).unwrap();
        let starts = Tensor::new(&[[1.5f32, -1.5], [1.2, -1.9], [-2.0, 2.5]], &Device::Cpu).unwrap();
        let steps = trainer.task().steps;
        let want = trainer.planner().mean_path(&starts, steps).unwrap().to_vec3::<f32>().unwrap();
        let got = deployed.mean_paths_tensor(&starts, steps).unwrap().to_vec3::<f64>().unwrap();
        let mut worst = 0.0f64;
        for (a, b) in want.iter().flatten().flatten().zip(got.iter().flatten().flatten()) {
            worst = worst.max((*a as f64 - b).abs());
        }
        assert!(worst < 1e-4, "deployed and candle paths differ by {worst}");
        // The single-path call agrees with the batch call.
        assert_eq!(deployed.mean_path(&[1.5, -1.5], steps), got[0]);
    };
    check(&trainer);
    for _ in 0..30 {
        trainer.update().unwrap();
    }
    check(&trainer);
}

/// The gradient planner (App. J) finds a satisfying Seq plan from a given start,
/// keeps the start, and is deterministic under its generator.
#[test]
fn gradient_planner_satisfies_seq_and_keeps_the_start() {
    use rand::SeedableRng;
    use schrl::plan::gradient_planner::{GradientPlannerConfig, plan};
    let task = Task::point(TaskKind::Seq);
    let spec = task.spec();
    let cfg = GradientPlannerConfig::default();
    let run =
        |seed| plan(&task, &spec, &[1.5, -1.5], &cfg, &mut rand_chacha::ChaCha8Rng::seed_from_u64(seed));
    let p = run(3).unwrap();
    assert!(p.satisfied(), "robustness {} after {} attempts", p.robustness, p.attempts);
    assert_eq!(&p.path[..2], &[1.5, -1.5]);
    assert_eq!(p.path.len(), (task.steps + 1) * 2);
    assert!(spec.robustness(&p.path, &stl::Semantics::hard()).unwrap() > 0.0);
    assert_eq!(run(3).unwrap(), p);
    // One attempt of one step cannot satisfy it: the best failed path comes back.
    let short = GradientPlannerConfig { iterations: 1, restarts: 1, ..cfg };
    let q = plan(&task, &spec, &[1.5, -1.5], &short, &mut rand_chacha::ChaCha8Rng::seed_from_u64(3)).unwrap();
    assert!(!q.satisfied() && q.attempts == 1 && q.iterations == 1);
}

/// Regression: plain gradient ascent satisfied 0 of 100 Loop plans (each attempt
/// settled with a waypoint in a wrong corner: a diagonal through the central walls or
/// two waypoints in one corner). Redrawing a binding waypoint every 20 steps solves it,
/// and every waypoint stays inside the map's region.
#[test]
fn gradient_planner_solves_loop_by_redrawing_binding_waypoints() {
    use rand::SeedableRng;
    use schrl::plan::gradient_planner::{GradientPlannerConfig, plan};
    let task = Task::point(TaskKind::Loop);
    let spec = task.spec();
    let (lo, hi) = task.map.region();
    let run = |cfg: &GradientPlannerConfig, seed| {
        plan(&task, &spec, &[1.5, -1.5], cfg, &mut rand_chacha::ChaCha8Rng::seed_from_u64(seed)).unwrap()
    };
    let cfg = GradientPlannerConfig::default();
    for seed in 0..3 {
        let p = run(&cfg, seed);
        assert!(p.satisfied(), "seed {seed}: robustness {} after {} attempts", p.robustness, p.attempts);
        for (i, x) in p.path.iter().enumerate() {
            assert!(
                (lo[i % 2]..=hi[i % 2]).contains(x),
                "seed {seed}: coordinate {i} = {x} outside the region"
            );
        }
    }
    // The same two long attempts without the repair stay stuck.
    let stuck = run(&GradientPlannerConfig { repair_every: 0, restarts: 2, ..cfg }, 0);
    assert!(!stuck.satisfied(), "robustness {}", stuck.robustness);
}

/// The gradient planner returns the first plan with ρ > 0 (Leung et al.), on the very
/// edge of every margin; with a target (the network's ε here) it climbs on to
/// `ρ ≥ target` in the same attempt.
#[test]
fn gradient_planner_climbs_past_the_first_satisfying_plan_to_its_target() {
    use rand::SeedableRng;
    use schrl::plan::gradient_planner::{GradientPlannerConfig, plan};
    let task = Task::point(TaskKind::Seq);
    let spec = task.spec();
    let run = |cfg: &GradientPlannerConfig, seed| {
        plan(&task, &spec, &[1.5, -1.5], cfg, &mut rand_chacha::ChaCha8Rng::seed_from_u64(seed)).unwrap()
    };
    let first = GradientPlannerConfig::default();
    assert_eq!(first.target, 0.0, "the default is the first satisfying plan");
    let eps = CpgConfig::default().epsilon;
    let target = GradientPlannerConfig { target: eps, ..first };
    let mut edge = 0;
    for seed in 0..4 {
        let (a, b) = (run(&first, seed), run(&target, seed));
        assert!(a.satisfied() && b.robustness >= eps, "seed {seed}: {} then {}", a.robustness, b.robustness);
        assert_eq!(b.attempts, a.attempts, "seed {seed}: the climb stays in the satisfying attempt");
        if a.robustness < eps {
            assert!(b.iterations > a.iterations, "seed {seed}: climbed on");
            edge += 1;
        } else {
            assert_eq!(b, a, "seed {seed}: a first plan at the target is the plan");
        }
    }
    assert!(edge >= 2, "the first satisfying plans were already robust ({edge} of 4 below {eps})");
    assert!(
        GradientPlannerConfig { target: -0.1, ..Default::default() }
            .validate()
            .unwrap_err()
            .starts_with("target")
    );
}

/// Drone Loop with the joint run's margins is satisfiable only by bouncing between two
/// goals. Waypoints drawn in the region (and redrawn there by repairs) never found the
/// bounce; drawn at goal centres, the search is over which goal each waypoint visits.
#[test]
fn gradient_planner_finds_drone_loops_bounce_by_drawing_at_goal_centres() {
    use rand::SeedableRng;
    use schrl::plan::gradient_planner::{GradientPlannerConfig, WaypointDraw, plan};
    let task = Task::builtin("drone", TaskKind::Loop).unwrap().with_goal_margin(0.6);
    let spec = task.spec();
    let cfg = GradientPlannerConfig { iterations: 2000, restarts: 2, ..Default::default() };
    let centres = GradientPlannerConfig { draw: WaypointDraw::GoalCentres, ..cfg };
    let start = [1.5, -1.5, 1.0];
    let run = |cfg: &GradientPlannerConfig, seed| {
        plan(&task, &spec, &start, cfg, &mut rand_chacha::ChaCha8Rng::seed_from_u64(seed)).unwrap()
    };
    let (mut found, mut region) = (0, 0);
    for seed in 0..3 {
        found += run(&centres, seed).satisfied() as usize;
        region += run(&cfg, seed).satisfied() as usize;
    }
    assert!(found >= 2 && region == 0, "goal centres {found} of 3, region {region} of 3");
    assert_eq!("goal-centres".parse::<WaypointDraw>(), Ok(WaypointDraw::GoalCentres));
    assert!("centres".parse::<WaypointDraw>().unwrap_err().contains("region or goal-centres"));
}

/// A plan refined for a nearby start keeps its shape (the guide's per-start plans):
/// Point Seq's plan from one corner of the start region, refined from the other,
/// satisfies with every planned waypoint within a metre of where it was, where a fresh
/// search from there may visit the goals another way.
#[test]
fn gradient_planner_refines_a_plan_for_another_start_keeping_its_shape() {
    use rand::SeedableRng;
    use schrl::plan::gradient_planner::{GradientPlannerConfig, plan, refine};
    let task = Task::point(TaskKind::Seq);
    let spec = task.spec();
    let cfg = GradientPlannerConfig::default();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    let (lo, hi) = task.start.clone();
    let first = plan(&task, &spec, &lo, &cfg, &mut rng).unwrap();
    assert!(first.satisfied());
    let mut moved = first.path.clone();
    moved[..lo.len()].copy_from_slice(&hi);
    let refined =
        refine(&task, &spec, moved, &GradientPlannerConfig { repair_every: 0, ..cfg }, &mut rng).unwrap();
    assert!(refined.satisfied(), "refined plan robustness {}", refined.robustness);
    assert_eq!((refined.attempts, &refined.path[..hi.len()]), (1, &hi[..]), "one attempt from the new start");
    let far = refined
        .path
        .chunks(2)
        .zip(first.path.chunks(2))
        .skip(1)
        .map(|(a, b)| ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt())
        .fold(0.0, f64::max);
    assert!(far < 1.0, "a waypoint moved {far} m");
}

/// Fitting the planner's mean paths to given paths brings them there, and says what is
/// wrong with targets of the wrong size.
#[test]
fn planner_mean_paths_fit_given_paths() {
    let task = Task::point(TaskKind::Seq);
    let mut t = PlanTrainer::new(task.clone(), CpgConfig::default()).unwrap();
    let (steps, n) = (task.steps, 8);
    let starts: Vec<f32> = (0..n).flat_map(|k| [1.0 + 0.1 * k as f32, -1.5]).collect();
    // Each path a straight line from its start towards (−2, 2), 0.4 m a waypoint.
    let mut targets = vec![];
    for s in starts.chunks(2) {
        for i in 0..=steps {
            let f = (0.4 * i as f32 / 5.0).min(1.0);
            targets.extend([s[0] + f * (-2.0 - s[0]), s[1] + f * (2.0 - s[1])]);
        }
    }
    let before = t.fit_mean_paths(&starts, &targets, 0, 3e-3).unwrap();
    let after = t.fit_mean_paths(&starts, &targets, 1500, 3e-3).unwrap();
    assert!(after < 0.2 && after < before / 5.0, "rms {before} m before, {after} m after");
    let err = t.fit_mean_paths(&starts, &targets[2..], 1, 3e-3).unwrap_err().to_string();
    assert!(err.contains("target numbers"), "{err}");
}

/// The Fig. 6 ablation planners (plain GRU, MLP) sample, score and train like the
/// GRU-ODE; the MLP has no memory, so its step depends on the current waypoint only.
#[test]
fn ablation_planners_sample_score_and_train() {
    use schrl::plan::planner::PlannerKind;
    for kind in [PlannerKind::Gru, PlannerKind::Mlp] {
        let cfg = CpgConfig { batch: 16, planner: kind, ..Default::default() };
        let mut t = PlanTrainer::new(Task::point(TaskKind::Seq), cfg).unwrap();
        let batch = t.sample(16).unwrap();
        assert_eq!(batch.paths.dims(), &[16, 9, 2]);
        let lp = t.planner().log_prob(&batch.paths).unwrap().to_vec1::<f32>().unwrap();
        let sampled = batch.log_prob.to_vec1::<f32>().unwrap();
        for (a, b) in lp.iter().zip(&sampled) {
            assert!((a - b).abs() < 1e-3 * a.abs().max(1.0), "{kind:?}: {a} vs {b}");
        }
        let before =
            t.planner().mean_path(&Tensor::new(&[[1.5f32, -1.5]], &Device::Cpu).unwrap(), 8).unwrap();
        for _ in 0..5 {
            let s = t.update().unwrap();
            assert!(s.mean_rho.is_finite() && s.loss.is_finite());
        }
        let after = t.planner().mean_path(&Tensor::new(&[[1.5f32, -1.5]], &Device::Cpu).unwrap(), 8).unwrap();
        let moved = (after - before).unwrap().abs().unwrap().sum_all().unwrap().to_scalar::<f32>().unwrap();
        assert!(moved > 1e-3, "{kind:?}: training moved the plan by {moved}");
        // Deployment in plain Rust is for the GRU-ODE only, and says so.
        let cfg = *t.planner().config();
        let err = schrl::plan::deployed::DeployedPlanner::from_varmap(t.varmap(), &cfg).unwrap_err();
        assert!(err.to_string().contains(kind.name()), "{err}");
    }
    // Memoryless: the MLP's next mean from a waypoint is the same whatever came before.
    let t = PlanTrainer::new(
        Task::point(TaskKind::Seq),
        CpgConfig { planner: PlannerKind::Mlp, ..Default::default() },
    )
    .unwrap();
    let paths = Tensor::new(
        &[[[0.0f32, 0.0], [1.0, 1.0], [0.5, 0.5]], [[3.0, -2.0], [1.0, 1.0], [0.5, 0.5]]],
        &Device::Cpu,
    )
    .unwrap();
    let (means, _) = t.planner().distributions(&paths).unwrap();
    let m = means.to_vec3::<f32>().unwrap();
    assert_eq!(m[0][1], m[1][1]);
    assert_ne!(m[0][0], m[1][0]);
}

/// The restart rule re-initialises the planner when an attempt has not been
/// promising within `restart_after` updates, resets λ, and is deterministic.
#[test]
fn stagnation_restarts_reinitialise_deterministically() {
    let run = |restart_after| {
        let cfg = CpgConfig { batch: 8, restart_after, ..Default::default() };
        let mut t = PlanTrainer::new(Task::point(TaskKind::Loop), cfg).unwrap();
        let mut lambdas = Vec::new();
        for _ in 0..12 {
            // An untrained planner satisfies Loop with none of its samples.
            assert_eq!(t.update().unwrap().satisfaction, 0.0);
            lambdas.push(t.lagrangian().lambda);
        }
        let start = Tensor::new(&[[1.5f32, -1.5]], &Device::Cpu).unwrap();
        let plan = t.planner().mean_path(&start, 4).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap();
        (t.restarts(), lambdas, plan)
    };
    let (n, lambdas, plan) = run(Some(5));
    assert_eq!(n, 2, "restarts after updates 5 and 10");
    // λ climbs while the constraint is violated and starts over at each restart.
    assert_eq!(lambdas[4], CpgConfig::default().lambda_init);
    assert!(lambdas[3] > lambdas[0] && lambdas[5] > lambdas[4]);
    assert_eq!(run(Some(5)), (n, lambdas, plan.clone()), "deterministic");
    let (none, _, kept) = run(None);
    assert_eq!(none, 0);
    assert_ne!(kept, plan, "a restart changes the planner");
}

/// The hand-written gradient of the constrained loss (`schrl::plan::gru_ode_backprop`)
/// equals candle's autodiff of the same loss, parameter by parameter, on the Seq task.
#[test]
fn hand_written_update_gradient_matches_candle_autodiff() {
    use schrl::plan::gru_ode_backprop::{GruOdeBackprop, Source, Tape};
    use stl::Semantics;
    let task = Task::point(TaskKind::Loop);
    let varmap = VarMap::new();
    let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
    let cfg = PlannerConfig { dim: 2, hidden: 8, bound: 10.0, min_std: 0.1, kind: Default::default() };
    let planner = PathPlanner::new(cfg, vb).unwrap();
    seeded_init(&varmap, 5).unwrap();
    let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(9);
    let (b, steps) = (6, task.steps);
    let g0 = task.sample_starts(&mut rng, b).unwrap();
    let noise = task.sample_noise(&mut rng, b).unwrap();
    let batch = planner.sample(&g0, &noise).unwrap();
    let sem = Semantics::soft(10.0);
    let (lambda, w) = (0.7f64, 0.1f64);
    let adv = [0.5f32, -1.0, 1.5, 0.2, -0.7, -0.5];
    // candle: the loss of `PlanTrainer::update_on` at ratio 1.
    let rho = task.tensor_spec().robustness(&batch.paths, &sem).unwrap();
    let logp = planner.log_prob(&batch.paths.detach()).unwrap();
    let advt = Tensor::new(&adv, &Device::Cpu).unwrap();
    let ratio = (&logp - logp.detach()).unwrap().exp().unwrap();
    let clipped = ratio.clamp(0.95, 1.05).unwrap();
    let surrogate =
        (&ratio * &advt).unwrap().minimum(&(&clipped * &advt).unwrap()).unwrap().mean_all().unwrap();
    let objective = ((surrogate * w).unwrap() + (rho.mean_all().unwrap() * lambda).unwrap()).unwrap();
    let grads = objective.neg().unwrap().backward().unwrap();
    // By hand: the same paths, ρ's gradient from the plain-Rust spec.
    let mut net = GruOdeBackprop::from_varmap(&varmap, &cfg).unwrap();
    let paths: Vec<f32> = batch.paths.flatten_all().unwrap().to_vec1().unwrap();
    let mut tape = Tape::default();
    net.forward(Source::Paths(&paths), b, steps, &mut tape);
    let paths64: Vec<f64> = paths.iter().map(|v| *v as f64).collect();
    let mut drho = vec![0.0; paths64.len()];
    task.spec().gradient_batch(&paths64, steps + 1, &sem, &mut drho).unwrap();
    let drho: Vec<f32> = drho.iter().map(|g| (g * lambda / b as f64) as f32).collect();
    let score: Vec<f32> = adv.iter().map(|a| a * (w / b as f64) as f32).collect();
    let mut grad = Vec::new();
    net.backward(&tape, &drho, &score, &mut grad);
    // log π agrees too.
    let hand_logp = net.log_probs(&tape);
    for (a, c) in hand_logp.iter().zip(logp.to_vec1::<f32>().unwrap()) {
        assert!((a - c).abs() < 1e-3 * (1.0 + c.abs()), "log π {a} vs {c}");
    }
    let data = varmap.data().lock().unwrap();
    let mut off = 0;
    for name in [
        "gru.weight_ih_l0",
        "gru.weight_hh_l0",
        "gru.bias_ih_l0",
        "gru.bias_hh_l0",
        "mean.weight",
        "mean.bias",
        "std.weight",
        "std.bias",
    ] {
        let var = &data[name];
        let want: Vec<f32> = grads.get(var.as_tensor()).unwrap().flatten_all().unwrap().to_vec1().unwrap();
        let got = &grad[off..off + want.len()];
        let scale = want.iter().map(|g| g.abs()).fold(1e-3, f32::max);
        for (i, (g, c)) in got.iter().zip(&want).enumerate() {
            assert!((g - c).abs() <= 2e-3 * scale, "{name}[{i}]: hand {g} vs candle {c} (scale {scale})");
        }
        off += want.len();
    }
    assert_eq!(off, net.num_params());
}

#[test]
fn path_length_gradient_matches_finite_differences_and_keeps_paths_apart() {
    use schrl::plan::cpg::PathLengthReward;
    let r = PathLengthReward { weight: 0.05 };
    // Two paths of three 2-D states each: a segment never joins the end of one path
    // to the start of the next.
    let paths = vec![0.0, 0.0, 1.0, 0.5, 2.0, -1.0, 5.0, 5.0, 5.5, 4.0, 3.0, 3.0];
    assert_gradient_matches_finite_differences(&r, &paths, 2, 2);
}

/// `reward`'s `add_gradient` against central differences of its summed reward.
fn assert_gradient_matches_finite_differences(
    reward: &dyn schrl::plan::cpg::ControlReward,
    paths: &[f64],
    steps: usize,
    dim: usize,
) {
    let mut g = vec![0.0; paths.len()];
    reward.add_gradient(paths, steps, dim, &mut g);
    let total = |p: &[f64]| reward.reward(p, steps, dim).iter().sum::<f64>();
    for i in 0..paths.len() {
        let (mut hi, mut lo) = (paths.to_vec(), paths.to_vec());
        hi[i] += 1e-6;
        lo[i] -= 1e-6;
        let fd = (total(&hi) - total(&lo)) / 2e-6;
        assert!((fd - g[i]).abs() < 1e-6, "entry {i}: finite difference {fd}, gradient {}", g[i]);
    }
}

#[test]
fn turn_term_counts_the_inner_turns_and_its_gradient_matches_finite_differences() {
    use schrl::plan::cpg::{ControlReward, PathLengthReward, TurnReward};
    let r = TurnReward { weight: 0.03 };
    // A right angle, then a straight run: π/2 in all (the start's heading is unknown,
    // the last waypoint has no segment leaving it).
    let square = [0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 1.0, 2.0];
    let want = -0.03 * std::f64::consts::FRAC_PI_2;
    assert!((r.reward(&square, 3, 2)[0] - want).abs() < 1e-12, "{:?}", r.reward(&square, 3, 2));
    // A U-turn is π; a repeated waypoint turns through nothing.
    assert!((r.reward(&[0.0, 0.0, 1.0, 0.0, 0.0, 0.0], 2, 2)[0] + 0.03 * std::f64::consts::PI).abs() < 1e-12);
    assert_eq!(r.reward(&[0.0, 0.0, 1.0, 0.0, 1.0, 0.0], 2, 2)[0], 0.0);
    // Two 3-D paths of four states: a turn never joins one path to the next.
    let paths = vec![
        0.0, 0.0, 0.0, 1.0, 0.5, 0.2, 2.0, -1.0, 0.1, 2.5, 0.3, 0.4, //
        5.0, 5.0, 1.0, 5.5, 4.0, 1.2, 3.0, 3.0, 0.9, 2.0, 4.0, 1.0,
    ];
    assert_gradient_matches_finite_differences(&(PathLengthReward { weight: 0.05 }, r), &paths, 3, 3);
}

#[test]
fn pathwise_length_gradient_shortens_plans_more_than_the_score_function_alone() {
    // Branch seed 0 once kept a first waypoint 8 m out, around the cross: through the
    // score function alone, the length stand-in barely moved it.
    use schrl::plan::cpg::{ControlReward, PathLengthReward};
    /// The same reward, without its gradient.
    struct ScoreOnly(PathLengthReward);
    impl ControlReward for ScoreOnly {
        fn reward(&self, paths: &[f64], steps: usize, dim: usize) -> Vec<f64> {
            self.0.reward(paths, steps, dim)
        }
    }
    let length = PathLengthReward { weight: 0.5 };
    let train = |reward: Box<dyn ControlReward>| {
        let cfg = CpgConfig { seed: 3, ..CpgConfig::default() };
        let mut t = PlanTrainer::new(Task::point(TaskKind::Seq), cfg).unwrap();
        t.set_control_reward(reward);
        for _ in 0..300 {
            t.update().unwrap();
        }
        t.mean_path_length(32).unwrap()
    };
    let (pathwise, score_only) = (train(Box::new(length)), train(Box::new(ScoreOnly(length))));
    assert!(
        pathwise < score_only,
        "mean plan {pathwise:.2} m with the pathwise gradient, {score_only:.2} m without"
    );
}

#[test]
fn joint_updates_hold_the_spec_against_a_low_level_reward_that_pulls_off_it() {
    // With `--joint-planner` on 8 executed runs, normalised advantages and the spec
    // estimated on those 8 paths alone, Point Seq's plans drifted off the spec (mean ρ
    // 0.135 → −0.17). The spec's terms now come from a fresh batch of samples.
    let trained = || {
        let mut t =
            PlanTrainer::new(Task::point(TaskKind::Branch), CpgConfig { seed: 2, ..CpgConfig::default() })
                .unwrap();
        for _ in 0..600 {
            t.update().unwrap();
        }
        t
    };
    // A low-level reward that prefers the least robust of each start's paths.
    let adversary = |t: &PlanTrainer, batch: &schrl::plan::planner::PlanBatch| -> Vec<f64> {
        let rho = t.hard_robustness(&batch.paths).unwrap();
        schrl::run::joint::leave_one_out(&rho.iter().map(|r| -5.0 * r).collect::<Vec<_>>(), 4)
    };
    let (mut joint, mut old) = (trained(), trained());
    let before = joint.mean_satisfaction(200).unwrap();
    assert!(before >= 0.9, "pre-training reached {before}");
    for _ in 0..200 {
        let batch = joint.sample_grouped(2, 4).unwrap();
        let adv = adversary(&joint, &batch);
        joint.update_joint(&batch, &adv).unwrap();
        let batch = old.sample_grouped(2, 4).unwrap();
        let adv = adversary(&old, &batch);
        old.update_on(&batch, &adv).unwrap();
    }
    let (after, drifted) = (joint.mean_satisfaction(200).unwrap(), old.mean_satisfaction(200).unwrap());
    assert!(after >= before - 0.05, "mean-path satisfaction {before} → {after}");
    assert!(drifted < after, "the 8-path update held too ({drifted}): the test no longer tells them apart");
}

/// Settings saved before the until relaxation was a choice say `soft:10` and meant
/// the flat relaxation; new ones name it.
#[test]
fn saved_semantics_without_an_until_relaxation_read_as_flat() {
    use stl::{Semantics, UntilSmoothing};
    let cfg = CpgConfig::default();
    assert_eq!(cfg.semantics, Semantics::soft(10.0).with_until(UntilSmoothing::Flat));
    let text = serde_json::to_string(&cfg).unwrap();
    assert!(text.contains("\"soft:10,until=flat\""), "{text}");
    let old: CpgConfig = serde_json::from_str(&text.replace("soft:10,until=flat", "soft:10")).unwrap();
    assert_eq!(old, cfg);
    let rec = CpgConfig { semantics: Semantics::soft(10.0), ..cfg };
    let back: CpgConfig = serde_json::from_str(&serde_json::to_string(&rec).unwrap()).unwrap();
    assert_eq!(back.semantics.until, UntilSmoothing::Recursive);
}

/// Regression (2026-12-02): the joint phase's fresh samples were scored on `ρ` alone,
/// without pre-training's length stand-in, and the jointly trained plans grew longer
/// than pre-training's (Point Branch 6 % slower to reach than the frozen planner). A
/// joint update with no executed runs is exactly a pre-training update.
#[test]
fn a_joint_update_without_executed_runs_is_a_pretraining_update() {
    use schrl::plan::cpg::PathLengthReward;
    use schrl::plan::planner::PlanBatch;
    let trainer = || {
        let cfg = CpgConfig { batch: 16, seed: 4, ..CpgConfig::default() };
        PlanTrainer::new(Task::point(TaskKind::Branch), cfg)
            .unwrap()
            .with_control_reward(PathLengthReward { weight: 0.5 })
    };
    let (mut pre, mut joint) = (trainer(), trainer());
    let none = PlanBatch {
        paths: Tensor::zeros((0, Task::point(TaskKind::Branch).steps + 1, 2), DType::F32, &Device::Cpu)
            .unwrap(),
        log_prob: Tensor::zeros(0, DType::F32, &Device::Cpu).unwrap(),
    };
    // The joint update replays its paths through the network (the pre-training one
    // reads them off the sampling pass): the same to float rounding.
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-5 * (1.0 + a.abs());
    for _ in 0..3 {
        let (a, b) = (pre.update().unwrap(), joint.update_joint(&none, &[]).unwrap());
        assert!(close(a.mean_rho, b.mean_rho) && close(a.loss, b.loss), "{a:?} against {b:?}");
    }
    let (a, b) = (pre.state().adam, joint.state().adam);
    let worst = a.m.iter().zip(&b.m).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max);
    let scale = a.m.iter().map(|x| x.abs()).fold(0.0, f32::max);
    assert!(worst <= 1e-3 * scale, "Adam's first moments differ by {worst} (largest {scale})");
}
