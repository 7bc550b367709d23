//! `schrl baseline`: the paper's baselines, trained and evaluated as `schrl train` and
//! `schrl eval` do SCHRL.

use std::path::PathBuf;

use anyhow::{Result, bail};
use schrl::baseline::crm::{CrmMetrics, CrmSettings, CrmTrainer};
use schrl::baseline::dhrm::DhrmConfig;
use schrl::baseline::flat::{self, EpisodeSummary, MeanPolicy};
use schrl::baseline::reward_machine::RewardMachine;
use schrl::baseline::td3::Td3Config;
use schrl::baseline::tltl::{TltlMetrics, TltlSettings, TltlTrainer};
use schrl::control::PpoConfig;
use schrl::run::evaluate::{EVAL_GROUPS, EVAL_PER_GROUP, EVAL_SEED, Plans, TaskEval, evaluate_task};
use schrl::store::{self, Checkpoint, MetricsLog, RunKind, RunWriter, SaveFiles, StoreError};
use schrl::task::Task;
use serde::Serialize;
use serde::de::DeserializeOwned;
use sim::Robot;
use sim::render::{ChartPanel, Series};

use super::train::print_eval;

use crate::progress::LoggedBar;

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
    /// Counterfactual reward machines on TD3 (Icarte et al. 2022).
    Crm,
    /// Hierarchical RL over a reward machine: an option per progress edge (TD3) under
    /// a DQN meta-controller (Icarte et al. 2022).
    Dhrm,
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
    /// Environment steps [default: 4000000 for tltl, crm and dhrm, SCHRL's 1 M of the general
    /// controller and 3 M of joint training; htltl: SCHRL's].
    #[arg(long)]
    pub steps: Option<usize>,
    #[command(flatten)]
    pub run: super::RunDirArgs,
    /// Evaluation groups of 100 runs after training; 0: none [default: 5].
    #[arg(long, value_parser = super::count::<0, 100>)]
    pub eval_groups: Option<usize>,
    /// Updates (tltl), iterations (htltl) or 4000-step chunks (crm, dhrm) between checkpoints
    /// [default: 25 / 50 / 25].
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
    /// Discount γ of TLTL's PPO [default: 0.99, the controller's]: its reward is paid at
    /// the episode's end, so γ sets how much of it reaches the first steps.
    #[arg(long)]
    gamma: Option<f64>,
    /// The reward machine (crm, dhrm): a machine file [default: the task's shipped machine,
    /// tasks/machines/TASK.toml].
    #[arg(long)]
    machine: Option<PathBuf>,
}

/// Arguments of `schrl baseline eval`.
#[derive(clap::Args, Debug)]
pub struct EvalArgs {
    /// Run directory of `schrl baseline train` (or of `schrl train`).
    #[arg(long)]
    ckpt: PathBuf,
    #[command(flatten)]
    runs: super::EvalRunsArgs,
    /// Picture of a few evaluated runs (PNG or SVG).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Replace the picture.
    #[arg(long)]
    force: bool,
}

/// The default budget of the flat baselines: SCHRL's whole budget on Point (1 M steps
/// of the general controller, 3 M of joint training), so the curves compare.
const FLAT_STEPS: usize = 4_000_000;
/// Checkpoint spacing when `--save-every` is not given (PPO updates or CRM chunks of
/// 4000 steps: 100 000 environment steps).
const FLAT_SAVE_EVERY: usize = 25;

/// Runs `schrl baseline ...`.
pub fn run(cmd: Command) -> Result<()> {
    match cmd {
        Command::Train(args) if args.gamma.is_some() && args.algo != Algo::Tltl => {
            bail!("--gamma is TLTL's discount; {} takes none", format!("{:?}", args.algo).to_lowercase())
        }
        Command::Train(args) if args.machine.is_some() && !matches!(args.algo, Algo::Crm | Algo::Dhrm) => {
            bail!(
                "--machine is a reward machine for --algo crm or dhrm; {} takes none",
                format!("{:?}", args.algo).to_lowercase()
            )
        }
        Command::Train(args) => match args.algo {
            Algo::Htltl => super::train::train(super::train::TrainArgs::htltl(args.common)),
            Algo::Tltl => train_flat::<TltlTrainer>(&args),
            Algo::Crm | Algo::Dhrm => train_flat::<CrmTrainer>(&args),
        },
        Command::Eval(args) => eval(args),
    }
}

/// What the training loop needs of a flat baseline's settings.
trait FlatSettings: Serialize + DeserializeOwned + Clone {
    /// The kind of run these settings are of.
    const KIND: RunKind;
    /// The settings of a new run from the flags.
    fn new(args: &TrainArgs, task: &Task) -> Result<Self>;
    /// Robot, task texts and seed: what a resumed run may not change.
    fn identity(&self) -> (Robot, &str, &str, u64);
    /// Flags a resumed run refuses when they differ, beyond robot, task and seed.
    fn conflicts(&self, args: &TrainArgs) -> Result<Vec<(&'static str, bool)>>;
    /// `(steps, eval_groups, save_every)`, mutable (the flags a resumed run may change).
    fn budget(&mut self) -> (&mut usize, &mut usize, &mut usize);
}

/// What the training loop needs of a flat baseline's trainer.
trait FlatBaseline: Sized {
    type Settings: FlatSettings;
    type Metrics: Serialize + DeserializeOwned + EpisodeStats;
    const KIND: RunKind = <Self::Settings as FlatSettings>::KIND;
    fn create(s: Self::Settings) -> Result<Self>;
    fn load(ckpt: &Checkpoint) -> Result<Self, StoreError>;
    fn save(&self, files: &mut SaveFiles) -> Result<(), StoreError>;
    fn settings(&mut self) -> &mut Self::Settings;
    fn task(&self) -> &Task;
    /// What the progress bar counts: updates or steps.
    const UNIT: &'static str;
    /// `(done, total)` in the progress bar's [`Self::UNIT`].
    fn progress(&self) -> (u64, u64);
    fn finished(&self) -> bool;
    fn train(&mut self) -> Result<Self::Metrics>;
    fn env_steps(&self) -> usize;
    fn evaluate(&self, sizes: (usize, usize), seed: u64) -> Result<TaskEval>;
}

/// A metrics line: its index in the log (update or chunk) and its episodes.
trait EpisodeStats {
    fn index(&self) -> usize;
    fn summary(&self) -> &EpisodeSummary;
}

impl FlatSettings for TltlSettings {
    const KIND: RunKind = RunKind::Tltl;
    fn new(args: &TrainArgs, task: &Task) -> Result<Self> {
        let c = &args.common;
        Ok(TltlSettings {
            robot: task.robot,
            task_toml: task.toml.clone(),
            task_spec: task.spec.clone(),
            seed: c.seed.unwrap_or(0),
            steps: c.steps.unwrap_or(FLAT_STEPS),
            ppo: PpoConfig {
                gamma: args.gamma.unwrap_or(PpoConfig::reference().gamma),
                ..PpoConfig::reference()
            },
            eval_groups: c.eval_groups.unwrap_or(EVAL_GROUPS),
            save_every: c.save_every.unwrap_or(FLAT_SAVE_EVERY),
        })
    }
    fn identity(&self) -> (Robot, &str, &str, u64) {
        (self.robot, &self.task_toml, &self.task_spec, self.seed)
    }
    fn conflicts(&self, args: &TrainArgs) -> Result<Vec<(&'static str, bool)>> {
        Ok(vec![("--gamma", super::differs(&args.gamma, &self.ppo.gamma))])
    }
    fn budget(&mut self) -> (&mut usize, &mut usize, &mut usize) {
        (&mut self.steps, &mut self.eval_groups, &mut self.save_every)
    }
}

impl FlatSettings for CrmSettings {
    const KIND: RunKind = RunKind::Crm;
    fn new(args: &TrainArgs, task: &Task) -> Result<Self> {
        let c = &args.common;
        Ok(CrmSettings {
            robot: task.robot,
            task_toml: task.toml.clone(),
            task_spec: task.spec.clone(),
            machine: machine_text(args.machine.as_deref(), task)?,
            seed: c.seed.unwrap_or(0),
            steps: c.steps.unwrap_or(FLAT_STEPS),
            td3: Td3Config::default(),
            eval_groups: c.eval_groups.unwrap_or(EVAL_GROUPS),
            save_every: c.save_every.unwrap_or(FLAT_SAVE_EVERY),
            dhrm: (args.algo == Algo::Dhrm).then(DhrmConfig::default),
        })
    }
    fn identity(&self) -> (Robot, &str, &str, u64) {
        (self.robot, &self.task_toml, &self.task_spec, self.seed)
    }
    fn conflicts(&self, args: &TrainArgs) -> Result<Vec<(&'static str, bool)>> {
        let differs = match &args.machine {
            None => false,
            Some(path) => {
                let here = std::path::Path::new("settings");
                let task = Task::from_texts(here, &self.task_toml, here, &self.task_spec)?;
                machine_text(Some(path), &task)? != self.machine
            }
        };
        Ok(vec![("--machine", differs), ("--algo", self.dhrm.is_some() != (args.algo == Algo::Dhrm))])
    }
    fn budget(&mut self) -> (&mut usize, &mut usize, &mut usize) {
        (&mut self.steps, &mut self.eval_groups, &mut self.save_every)
    }
}

/// The reward machine's text: the file given, or the task's shipped machine; checked
/// against the task.
fn machine_text(path: Option<&std::path::Path>, task: &Task) -> Result<String> {
    Ok(match path {
        Some(p) => {
            RewardMachine::from_file(p, task)?;
            schrl::task::read_text(p, schrl::task::MAX_TASK_FILE_BYTES)?
        }
        None => {
            RewardMachine::shipped(task)?;
            RewardMachine::shipped_text(&task.name).expect("a machine that loaded is shipped").to_string()
        }
    })
}

impl EpisodeStats for TltlMetrics {
    fn index(&self) -> usize {
        self.update
    }
    fn summary(&self) -> &EpisodeSummary {
        &self.episodes
    }
}

impl EpisodeStats for CrmMetrics {
    fn index(&self) -> usize {
        self.chunk
    }
    fn summary(&self) -> &EpisodeSummary {
        &self.episodes
    }
}

impl FlatBaseline for TltlTrainer {
    type Settings = TltlSettings;
    type Metrics = TltlMetrics;
    fn create(s: TltlSettings) -> Result<Self> {
        Ok(TltlTrainer::new(s)?)
    }
    fn load(ckpt: &Checkpoint) -> Result<Self, StoreError> {
        store::tltl::load_from(ckpt)
    }
    fn save(&self, files: &mut SaveFiles) -> Result<(), StoreError> {
        store::tltl::save_into(files, self)
    }
    fn settings(&mut self) -> &mut TltlSettings {
        &mut self.settings
    }
    fn task(&self) -> &Task {
        &self.task
    }
    const UNIT: &'static str = "updates";
    fn progress(&self) -> (u64, u64) {
        (self.updates as u64, self.total_updates() as u64)
    }
    fn finished(&self) -> bool {
        TltlTrainer::finished(self)
    }
    fn train(&mut self) -> Result<TltlMetrics> {
        Ok(self.train_update()?)
    }
    fn env_steps(&self) -> usize {
        self.steps
    }
    fn evaluate(&self, sizes: (usize, usize), seed: u64) -> Result<TaskEval> {
        Ok(flat::evaluate(&self.task, &mut MeanPolicy::new(&self.controller()), sizes, seed)?)
    }
}

impl FlatBaseline for CrmTrainer {
    type Settings = CrmSettings;
    type Metrics = CrmMetrics;
    fn create(s: CrmSettings) -> Result<Self> {
        Ok(CrmTrainer::new(s)?)
    }
    fn load(ckpt: &Checkpoint) -> Result<Self, StoreError> {
        store::crm::load_from(ckpt)
    }
    fn save(&self, files: &mut SaveFiles) -> Result<(), StoreError> {
        store::crm::save_into(files, self)
    }
    fn settings(&mut self) -> &mut CrmSettings {
        &mut self.settings
    }
    fn task(&self) -> &Task {
        &self.task
    }
    const UNIT: &'static str = "steps";
    fn progress(&self) -> (u64, u64) {
        (self.steps as u64, self.settings.steps as u64)
    }
    fn finished(&self) -> bool {
        CrmTrainer::finished(self)
    }
    fn train(&mut self) -> Result<CrmMetrics> {
        Ok(self.train_chunk()?)
    }
    fn env_steps(&self) -> usize {
        self.steps
    }
    fn evaluate(&self, sizes: (usize, usize), seed: u64) -> Result<TaskEval> {
        Ok(flat::evaluate(&self.task, &mut self.policy(), sizes, seed)?)
    }
}

/// The settings of a run: new from the flags, or the saved ones with the flags that
/// may change (`--steps`, `--eval-groups`, `--save-every`) applied; other flags that
/// differ are refused by name.
fn settings_of<S: FlatSettings>(args: &TrainArgs, saved: Option<&S>) -> Result<S> {
    let c = &args.common;
    let mut s = match saved {
        None => {
            let Some(task_arg) = &c.task else { bail!("--task is required for a new run") };
            S::new(args, &super::task::resolve(c.robot, task_arg)?)?
        }
        Some(saved) => {
            let (robot, toml, spec, seed) = saved.identity();
            let task_differs =
                super::task::differs_from_saved(c.robot, c.task.as_deref(), robot, (toml, spec))?;
            let mut conflicts = vec![
                ("--robot", super::differs(&c.robot, &robot)),
                ("--task", task_differs),
                ("--seed", super::differs(&c.seed, &seed)),
            ];
            conflicts.extend(saved.conflicts(args)?);
            super::refuse_conflicts(S::KIND, &conflicts)?;
            saved.clone()
        }
    };
    let (steps, groups, every) = s.budget();
    *steps = c.steps.unwrap_or(*steps);
    *groups = c.eval_groups.unwrap_or(*groups);
    *every = c.save_every.unwrap_or(*every);
    if *every == 0 {
        bail!("--save-every must be at least 1");
    }
    if *steps == 0 {
        bail!("--steps must be at least 1");
    }
    Ok(s)
}

/// `schrl baseline train` for a flat baseline: progress, metrics, checkpoints, resume,
/// the training curve, then the evaluation.
fn train_flat<B: FlatBaseline>(args: &TrainArgs) -> Result<()> {
    let out = args.common.run.out.clone();
    let start = std::time::Instant::now();
    let (mut run, mut trainer, resumed) = if args.common.run.resume {
        let (mut run, ckpt) = RunWriter::resume(&out, B::KIND).map_err(super::store_error)?;
        let saved: B::Settings = run.settings().map_err(super::store_error)?;
        let settings = settings_of(args, Some(&saved))?;
        run.set_settings(&settings).map_err(super::store_error)?;
        let trainer = if ckpt.has_files() {
            let mut t = B::load(&ckpt)?;
            *t.settings() = settings;
            t
        } else {
            B::create(settings)?
        };
        (run, trainer, true)
    } else {
        let settings: B::Settings = settings_of(args, None)?;
        let trainer = B::create(settings.clone())?;
        for w in trainer.task().warnings() {
            eprintln!("warning: {w}");
        }
        let run = RunWriter::create(&out, B::KIND, &settings, args.common.run.existing())
            .map_err(super::store_error)?;
        (run, trainer, false)
    };
    crate::interrupt::install();
    let steps_done = trainer.env_steps();
    let (mut log, mut history) =
        MetricsLog::open(&run, resumed, |m: &B::Metrics| m.summary().env_steps <= steps_done)
            .map_err(super::store_error)?;
    let (done, total) = trainer.progress();
    // The algorithm, not the run kind: CRM and DHRM share one kind.
    let label = clap::ValueEnum::to_possible_value(&args.algo).map(|v| v.get_name().to_owned());
    let mut bar = LoggedBar::new(total, label.as_deref().unwrap_or(B::KIND.name()), B::UNIT);
    bar.start_at(done);
    let mut interrupted = false;
    let save_every = trainer.settings().budget().2.to_owned();
    while !trainer.finished() {
        let m = trainer.train()?;
        log.append(&m)?;
        history.push(m);
        let (score, sat) = window(&history[history.len().saturating_sub(20)..]);
        bar.set(trainer.progress().0, format!("score {score:.3} satisfaction {sat:.2}"));
        if history.last().is_some_and(|m| m.index().is_multiple_of(save_every)) {
            run.save(|f| trainer.save(f))?;
        }
        if crate::interrupt::requested() {
            interrupted = true;
            break;
        }
    }
    bar.clear();
    run.save(|f| trainer.save(f))?;
    if interrupted {
        return Err(crate::interrupt::stopped(&out, format!("step {}", trainer.env_steps())));
    }
    save_curve(&history, &out.join("training_curve.png"))?;
    let task = trainer.task().clone();
    println!(
        "trained {} on {} {} for {} environment steps in {:.1} s; run in {}",
        format!("{:?}", args.algo).to_lowercase(),
        task.robot,
        task.name,
        trainer.env_steps(),
        start.elapsed().as_secs_f64(),
        out.display()
    );
    let groups = *trainer.settings().budget().1;
    if groups > 0 {
        let e = trainer.evaluate((groups, EVAL_PER_GROUP), EVAL_SEED)?;
        let png = out.join("episodes.png");
        e.save_picture(&task, &png, true)?;
        println!("wrote {}", png.display());
        print_eval(&e);
    }
    Ok(())
}

/// Mean score and satisfaction over `metrics`, weighting each line by its episodes.
fn window<M: EpisodeStats>(metrics: &[M]) -> (f64, f64) {
    let (mut n, mut score, mut sat) = (0.0, 0.0, 0.0);
    for m in metrics.iter().map(EpisodeStats::summary) {
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
/// environment steps, each over the last 20 lines' episodes.
fn save_curve<M: EpisodeStats>(history: &[M], out: &std::path::Path) -> Result<()> {
    let series = |label: &str, pick: fn((f64, f64)) -> f64| Series {
        label: label.into(),
        points: (0..history.len())
            .map(|i| {
                (history[i].summary().env_steps as f64, pick(window(&history[i.saturating_sub(19)..=i])))
            })
            .filter(|(_, y)| y.is_finite())
            .collect(),
        band: vec![],
        colour: None,
    };
    let panels = [
        ChartPanel {
            series: vec![series("spec score of training episodes", |w| w.0)],
            y_range: None,
            y_label: "spec score".into(),
            reference: None,
        },
        ChartPanel {
            series: vec![series("satisfying training episodes", |w| w.1)],
            y_range: Some((0.0, 1.0)),
            y_label: "satisfaction".into(),
            reference: None,
        },
    ];
    sim::render::save_chart(&panels, "environment steps", out, true)?;
    Ok(())
}

/// Runs `schrl baseline eval`: a TLTL or CRM run's flat policy, or an HTLTL (joint)
/// run's planner and controller.
fn eval(args: EvalArgs) -> Result<()> {
    if let Some(out) = &args.out {
        sim::render::check_target(out, args.force)?;
    }
    let sizes = args.runs.sizes();
    let kind = Checkpoint::open(&args.ckpt, RunKind::Tltl).map(|_| RunKind::Tltl).or_else(|e| match e {
        StoreError::OtherKind { found, .. } => Ok(found),
        e => Err(super::store_error(e)),
    })?;
    let (task, e): (Task, TaskEval) = match kind {
        RunKind::Tltl => {
            let t = store::tltl::load(&args.ckpt).map_err(super::store_error)?;
            (t.task.clone(), FlatBaseline::evaluate(&t, sizes, args.runs.seed)?)
        }
        RunKind::Crm => {
            let t = store::crm::load(&args.ckpt).map_err(super::store_error)?;
            (t.task.clone(), FlatBaseline::evaluate(&t, sizes, args.runs.seed)?)
        }
        RunKind::Joint => {
            let (t, _) = store::joint::load_deployed(&args.ckpt).map_err(super::store_error)?;
            let plans = Plans::Mean(t.plan.planner());
            let e = evaluate_task(&t.task, plans, &t.control.controller(), sizes, args.runs.seed)?;
            (t.task.clone(), e)
        }
        other => bail!(
            "{}: a {other} run ({}) is not a baseline; expected a run of `schrl baseline train` or `schrl train`",
            args.ckpt.display(),
            other.command()
        ),
    };
    print_eval(&e);
    if let Some(out) = &args.out {
        e.save_picture(&task, out, args.force)?;
        println!("wrote {}", out.display());
    }
    Ok(())
}
