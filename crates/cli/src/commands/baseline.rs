//! `schrl baseline`: the paper's baselines, trained and evaluated as `schrl train` and
//! `schrl eval` do SCHRL.

use std::path::PathBuf;

use anyhow::{Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use schrl::baseline::tltl::{self, TltlMetrics, TltlSettings, TltlTrainer};
use schrl::control::PpoConfig;
use schrl::run::evaluate::{EVAL_GROUPS, EVAL_PER_GROUP, EVAL_SEED, Plans, TaskEval, evaluate_task};
use schrl::store::{self, MetricsLog, RunKind, RunWriter, StoreError};
use sim::Robot;
use sim::render::{ChartPanel, Series};

use super::train::{draw, print_eval};

/// Subcommands of `schrl baseline`.
#[derive(clap::Subcommand, Debug)]
pub enum Command {
    /// Train a baseline on a task, then evaluate it.
    Train(TrainArgs),
    /// Evaluate a trained baseline: satisfaction and steps to reach over 5 groups of 100
    /// runs, as `schrl eval`.
    Eval(EvalArgs),
}

/// The baselines.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Algo {
    /// One flat PPO policy rewarded by the spec's robustness at the episode's end
    /// (Li et al. 2017).
    Tltl,
    /// SCHRL without the Lagrange term: the planner on the plain policy gradient of
    /// ρ + r_l (`schrl train --method pg`).
    Htltl,
}

/// The flags every baseline takes.
#[derive(clap::Args, Debug)]
pub struct CommonArgs {
    /// Robot of a built-in task: point, car, drone, or doggo [default: point; a task
    /// file names its own].
    #[arg(long)]
    pub robot: Option<Robot>,
    /// Task: seq, cover, branch, loop, signal, or a task file (TOML). Required for a new run.
    #[arg(long)]
    pub task: Option<String>,
    /// Seed of everything [default: 0].
    #[arg(long)]
    pub seed: Option<u64>,
    /// Environment steps [default: 4000000 for tltl, SCHRL's 1 M of the general
    /// controller and 3 M of joint training; htltl: SCHRL's].
    #[arg(long)]
    pub steps: Option<usize>,
    #[command(flatten)]
    pub run: super::RunDirArgs,
    /// Evaluation groups of 100 runs after training; 0: none [default: 5].
    #[arg(long, value_parser = super::count::<0, 100>)]
    pub eval_groups: Option<usize>,
    /// Updates (tltl) or iterations (htltl) between checkpoints [default: 25 / 50].
    #[arg(long)]
    pub save_every: Option<usize>,
}

/// Arguments of `schrl baseline train`.
#[derive(clap::Args, Debug)]
pub struct TrainArgs {
    /// Which baseline.
    #[arg(long, value_enum)]
    algo: Algo,
    #[command(flatten)]
    common: CommonArgs,
}

/// Arguments of `schrl baseline eval`.
#[derive(clap::Args, Debug)]
pub struct EvalArgs {
    /// Run directory of `schrl baseline train` (or of `schrl train`).
    #[arg(long)]
    ckpt: PathBuf,
    /// Groups of runs.
    #[arg(long, default_value_t = EVAL_GROUPS, value_parser = super::count::<1, 100>)]
    groups: usize,
    /// Runs per group.
    #[arg(long, default_value_t = EVAL_PER_GROUP, value_parser = super::count::<1, 10_000>)]
    per_group: usize,
    /// Seed of starts.
    #[arg(long, default_value_t = EVAL_SEED)]
    seed: u64,
    /// Picture of a few evaluated runs (PNG or SVG).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Replace the picture.
    #[arg(long)]
    force: bool,
}

/// TLTL's budget when `--steps` is not given: SCHRL's whole budget on Point (1 M steps
/// of the general controller, 3 M of joint training), so the curves compare.
const TLTL_STEPS: usize = 4_000_000;
/// PPO updates between TLTL checkpoints when `--save-every` is not given.
const TLTL_SAVE_EVERY: usize = 25;

/// Runs `schrl baseline ...`.
pub fn run(cmd: Command) -> Result<()> {
    match cmd {
        Command::Train(args) => match args.algo {
            Algo::Htltl => super::train::train(super::train::TrainArgs::htltl(args.common)),
            Algo::Tltl => train_tltl(args.common),
        },
        Command::Eval(args) => eval(args),
    }
}

impl CommonArgs {
    /// The settings of a new TLTL run.
    fn tltl_settings(&self) -> Result<TltlSettings> {
        let Some(task_arg) = &self.task else { bail!("--task is required for a new run") };
        let task = super::task::resolve(self.robot, task_arg)?;
        let s = TltlSettings {
            robot: task.robot,
            task_toml: task.toml.clone(),
            task_spec: task.spec.clone(),
            seed: self.seed.unwrap_or(0),
            steps: self.steps.unwrap_or(TLTL_STEPS),
            ppo: PpoConfig::reference(),
            eval_groups: self.eval_groups.unwrap_or(EVAL_GROUPS),
            save_every: self.save_every.unwrap_or(TLTL_SAVE_EVERY),
        };
        check(&s)?;
        Ok(s)
    }

    /// The saved settings of a resumed TLTL run with the flags that may change
    /// (`--steps`, `--eval-groups`, `--save-every`) applied; others that differ are
    /// refused by name.
    fn tltl_resumed(&self, saved: &TltlSettings) -> Result<TltlSettings> {
        use super::differs;
        let task_differs = super::task::differs_from_saved(
            self.robot,
            self.task.as_deref(),
            saved.robot,
            (&saved.task_toml, &saved.task_spec),
        )?;
        super::refuse_conflicts(
            RunKind::Tltl,
            &[
                ("--robot", differs(&self.robot, &saved.robot)),
                ("--task", task_differs),
                ("--seed", differs(&self.seed, &saved.seed)),
            ],
        )?;
        let s = TltlSettings {
            steps: self.steps.unwrap_or(saved.steps),
            eval_groups: self.eval_groups.unwrap_or(saved.eval_groups),
            save_every: self.save_every.unwrap_or(saved.save_every),
            ..saved.clone()
        };
        check(&s)?;
        Ok(s)
    }
}

fn check(s: &TltlSettings) -> Result<()> {
    if s.save_every == 0 {
        bail!("--save-every must be at least 1");
    }
    if s.steps == 0 {
        bail!("--steps must be at least 1");
    }
    Ok(())
}

fn train_tltl(args: CommonArgs) -> Result<()> {
    let out = args.run.out.clone();
    let start = std::time::Instant::now();
    let (mut run, mut trainer, resumed) = if args.run.resume {
        let (mut run, ckpt) = RunWriter::resume(&out, RunKind::Tltl).map_err(super::store_error)?;
        let settings = args.tltl_resumed(&run.settings().map_err(super::store_error)?)?;
        run.set_settings(&settings).map_err(super::store_error)?;
        let trainer = if ckpt.has_files() {
            let mut t = store::tltl::load_from(&ckpt)?;
            t.settings = settings;
            t
        } else {
            TltlTrainer::new(settings)?
        };
        (run, trainer, true)
    } else {
        let settings = args.tltl_settings()?;
        for w in settings.task()?.warnings() {
            eprintln!("warning: {w}");
        }
        let trainer = TltlTrainer::new(settings.clone())?;
        let run = RunWriter::create(&out, RunKind::Tltl, &settings, args.run.existing())
            .map_err(super::store_error)?;
        (run, trainer, false)
    };
    crate::interrupt::install();
    let updates = trainer.updates;
    let (mut log, mut history) =
        MetricsLog::open(&run, resumed, |m: &TltlMetrics| m.update <= updates).map_err(super::store_error)?;
    let bar = ProgressBar::new(trainer.total_updates() as u64);
    bar.set_style(ProgressStyle::with_template(
        "      tltl {bar:40} {pos}/{len} updates {elapsed_precise} {msg}",
    )?);
    bar.set_position(trainer.updates as u64);
    let mut interrupted = false;
    while !trainer.finished() {
        let m = trainer.train_update()?;
        log.append(&m)?;
        bar.set_position(m.update as u64);
        let recent = &history[history.len().saturating_sub(19)..];
        let (score, sat) = window(recent.iter().chain([&m]));
        bar.set_message(format!("score {score:.3} satisfaction {sat:.2} {:.0} steps/s", m.steps_per_sec));
        history.push(m);
        if trainer.updates % trainer.settings.save_every == 0 {
            run.save(|f| store::tltl::save_into(f, &trainer))?;
        }
        if crate::interrupt::requested() {
            interrupted = true;
            break;
        }
    }
    bar.finish_and_clear();
    run.save(|f| store::tltl::save_into(f, &trainer))?;
    if interrupted {
        return Err(crate::interrupt::stopped(&out, format!("update {}", trainer.updates)));
    }
    save_curve(&history, &out.join("training_curve.png"))?;
    println!(
        "trained tltl on {} {} for {} environment steps in {:.1} s; run in {}",
        trainer.task.robot,
        trainer.task.name,
        trainer.steps,
        start.elapsed().as_secs_f64(),
        out.display()
    );
    if trainer.settings.eval_groups > 0 {
        let sizes = (trainer.settings.eval_groups, EVAL_PER_GROUP);
        let e = tltl::evaluate(&trainer.task, &trainer.controller(), sizes, EVAL_SEED)?;
        let png = out.join("episodes.png");
        draw(&trainer.task, &e, &png, true)?;
        println!("wrote {}", png.display());
        print_eval(&e);
    }
    Ok(())
}

/// Mean score and satisfaction over `metrics`, weighting each update by its episodes.
fn window<'a>(metrics: impl Iterator<Item = &'a TltlMetrics>) -> (f64, f64) {
    let (mut n, mut score, mut sat) = (0.0, 0.0, 0.0);
    for m in metrics {
        let k = m.episodes as f64;
        if let (Some(s), Some(f)) = (m.score, m.satisfaction) {
            n += k;
            score += s * k;
            sat += f * k;
        }
    }
    if n > 0.0 { (score / n, sat / n) } else { (f64::NAN, f64::NAN) }
}

/// The spec score (top) and satisfaction (below) of training episodes against
/// environment steps, each over the last 20 updates' episodes.
fn save_curve(history: &[TltlMetrics], out: &std::path::Path) -> Result<()> {
    let series = |label: &str, pick: fn((f64, f64)) -> f64| Series {
        label: label.into(),
        points: (0..history.len())
            .map(|i| (history[i].env_steps as f64, pick(window(history[i.saturating_sub(19)..=i].iter()))))
            .filter(|(_, y)| y.is_finite())
            .collect(),
        band: vec![],
    };
    let panels = [
        ChartPanel {
            series: vec![series("spec score of training episodes", |w| w.0)],
            y_range: None,
            y_label: "spec score".into(),
        },
        ChartPanel {
            series: vec![series("satisfying training episodes", |w| w.1)],
            y_range: Some((0.0, 1.0)),
            y_label: "satisfaction".into(),
        },
    ];
    sim::render::save_chart(&panels, "environment steps", out, true)?;
    Ok(())
}

/// Runs `schrl baseline eval`: a TLTL run's flat policy, or an HTLTL (joint) run's
/// planner and controller.
fn eval(args: EvalArgs) -> Result<()> {
    if let Some(out) = &args.out {
        sim::render::check_target(out, args.force)?;
    }
    let sizes = (args.groups, args.per_group);
    let (task, e): (_, TaskEval) = match store::tltl::load(&args.ckpt) {
        Ok(t) => {
            let e = tltl::evaluate(&t.task, &t.controller(), sizes, args.seed)?;
            (t.task, e)
        }
        Err(StoreError::OtherKind { found: RunKind::Joint, .. }) => {
            let t = store::joint::load(&args.ckpt).map_err(super::store_error)?;
            let plans = Plans::Mean(t.plan.planner());
            let e = evaluate_task(&t.task, plans, &t.control.controller(), sizes, args.seed)?;
            (t.task.clone(), e)
        }
        Err(e) => return Err(super::store_error(e)),
    };
    print_eval(&e);
    if let Some(out) = &args.out {
        draw(&task, &e, out, args.force)?;
        println!("wrote {}", out.display());
    }
    Ok(())
}
