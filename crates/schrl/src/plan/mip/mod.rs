//! The mixed-integer STL planner (paper App. J, Table 5's MIP column; Raman et al.
//! 2014): the task's spec over the plan's waypoints as a mixed-integer linear program,
//! solved to optimality.
//!
//! * Variables: waypoints `1..=T` (the start is given), inside the map's plan region,
//!   each step at most [`MipConfig::max_step`] per coordinate.
//! * Predicates: piecewise-linear lower bounds (module `geometry`): goal discs as inscribed
//!   polygons, staying outside a disc as tangent half-planes, walls as a disjunction
//!   of each box's sides, at waypoints or along segments as the task checks `safe`
//!   and its avoid regions. So `ρ̃ ≤ ρ`: a plan with `ρ̃ > 0` satisfies the spec.
//! * Logic and time: big-M over waypoint indices (module `encode`), negation pushed down.
//! * Objective, in two stages: maximise `ρ̃`; then, with the binaries of that optimum
//!   fixed, minimise the plan's 1-norm length subject to `ρ̃` staying at the optimum (a
//!   linear program). Robustness first, not the shortest path subject to `ρ ≥ ε`; the
//!   corner a plan visits is chosen for robustness alone. With
//!   [`MipConfig::robustness_cap`] `ε`, the first stage maximises `min(ρ̃, ε)`: any plan
//!   at least `ε` robust ends the search, and the second shortens it keeping `ε`.
//!
//! * Satisfying first ([`MipConfig::satisfying_first`], HiGHS's default): stage 1 first
//!   asks for `ρ̃` at least the cap (or 1 mm), with cuts valid only for such plans
//!   (consecutive segments in free cells that meet); the whole program follows only if
//!   no plan meets it. The optimum is the same either way.
//!
//! Every plan is checked with the exact hard robustness of the task's spec
//! ([`MipPlan::robustness`]), which is at least the program's `ρ̃`
//! ([`MipPlan::program_robustness`]) and exceeds it by the polygons' error at most.
//!
//! Loop and Signal are encoded as written (the authors re-encoded them as repeated
//! sequences for their MIP).

mod encode;
mod geometry;

use std::collections::{HashMap, HashSet};
use std::time::Instant;

use good_lp::{Expression, ResolutionError, Solution, SolutionStatus, SolverModel, WithTimeLimit};
use stl::{EvalError, Formula, Semantics, Spec};

use crate::task::{Task, UNTIL};

/// The name the tasks give the walls' clearance.
const WALLS: &str = "safe";

/// The robustness a satisfying plan is asked for without a cap (1 mm): any positive
/// floor makes the cuts valid, and a plan between 0 and it is found by the whole
/// program.
const SATISFYING: f64 = 1e-3;

/// The solver the program is handed to.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MipSolver {
    /// microlp, pure Rust (builds with cargo alone): the default.
    #[default]
    Microlp,
    /// HiGHS (cargo feature `highs`; needs cmake and libclang to build).
    #[cfg(feature = "highs")]
    Highs,
}

impl MipSolver {
    /// Whether [`MipConfig::satisfying_first`] is on by default: for HiGHS, whose
    /// presolve and heuristics use the floor and the cuts (Point Cover capped at 0.3 m:
    /// 0.60 → 0.089 s per plan); not for microlp, whose depth-first search without
    /// heuristics finds its way through plans short of the floor (Cover: 4.2 → 51 s).
    pub fn satisfying_first(self) -> bool {
        match self {
            MipSolver::Microlp => false,
            #[cfg(feature = "highs")]
            MipSolver::Highs => true,
        }
    }

    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            MipSolver::Microlp => "microlp",
            #[cfg(feature = "highs")]
            MipSolver::Highs => "highs",
        }
    }
}

impl std::str::FromStr for MipSolver {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "microlp" => Ok(MipSolver::Microlp),
            #[cfg(feature = "highs")]
            "highs" => Ok(MipSolver::Highs),
            #[cfg(not(feature = "highs"))]
            "highs" => {
                Err("this build has no HiGHS: build with `--features highs` (scripts/setup-highs.sh)".into())
            }
            other => Err(format!("unknown solver '{other}': expected microlp or highs")),
        }
    }
}

/// Settings of the MIP planner (this project's; the paper gives none).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MipConfig {
    /// Sides of the polygon inscribed in a goal disc (16: at most 2 % low).
    pub sides: usize,
    /// Tangent directions for staying outside a disc; each is a binary (8: at most
    /// 7.6 % low).
    pub outside_sides: usize,
    /// Largest step between waypoints, per coordinate (10 m: the planner network's
    /// step bound, reference setup).
    pub max_step: f64,
    /// Seconds the solver may take; the best plan found by then is returned.
    pub time_limit: f64,
    /// Maximise `min(ρ̃, cap)` instead of `ρ̃`: robustness up to the cap, then the
    /// shortest plan (off by default: the most robust plan).
    pub robustness_cap: Option<f64>,
    /// The second stage chooses afresh: the shortest plan at least as robust as the
    /// first stage's optimum, over every discrete choice (a mixed-integer program, so
    /// slower), instead of the shortest with the first stage's choices fixed (a linear
    /// program). Robustness does not care which goals a plan alternates between, so
    /// with the choices fixed Point Signal's plans hopped across the diagonals (40 m,
    /// too long to execute in its step limit). If the second stage runs out of time,
    /// the first stage's plan comes back unshortened.
    pub shortest: bool,
    /// The solver.
    pub solver: MipSolver,
    /// Ask first for a satisfying plan: `ρ̃` at least the cap (or 1 mm without one),
    /// with cuts that hold only for such plans (consecutive segments lie in free cells
    /// of the walls that meet); if there is none, solve the whole program. The plan's
    /// robustness is the same either way. `None`: the solver's default
    /// ([`MipSolver::satisfying_first`]).
    pub satisfying_first: Option<bool>,
}

impl Default for MipConfig {
    fn default() -> Self {
        Self {
            sides: 16,
            outside_sides: 8,
            max_step: 10.0,
            time_limit: 60.0,
            robustness_cap: None,
            shortest: false,
            solver: MipSolver::default(),
            satisfying_first: None,
        }
    }
}

impl MipConfig {
    /// Checks the settings; the message names the field.
    pub fn validate(&self) -> Result<(), String> {
        if !(3..=256).contains(&self.sides) {
            return Err(format!("mip.sides: {} is not in 3..=256", self.sides));
        }
        if !(3..=256).contains(&self.outside_sides) {
            return Err(format!("mip.outside_sides: {} is not in 3..=256", self.outside_sides));
        }
        if !(self.max_step > 0.0 && self.max_step.is_finite()) {
            return Err(format!("mip.max_step: {} is not a positive number of metres", self.max_step));
        }
        if let Some(c) = self.robustness_cap
            && !(c > 0.0 && c.is_finite())
        {
            return Err(format!("mip.robustness_cap: {c} is not a positive number of metres"));
        }
        if !(self.time_limit > 0.0 && self.time_limit.is_finite()) {
            return Err(format!("mip.time_limit: {} is not a positive number of seconds", self.time_limit));
        }
        Ok(())
    }
}

/// Why no plan came back.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MipError {
    /// Something in the task the encoding does not cover.
    #[error("cannot encode {0}")]
    Unsupported(String),
    /// A setting is out of range.
    #[error("invalid setting {0}")]
    Setting(String),
    /// The time limit passed before the solver found any plan.
    #[error("time-out: no plan found within the time limit of {0} s; raise it (--time-limit)")]
    TimeOut(f64),
    /// The solver failed.
    #[error("solver {solver} failed: {message}")]
    Solver {
        /// The solver's name.
        solver: &'static str,
        /// Its message.
        message: String,
    },
    /// The exact robustness of the plan could not be evaluated.
    #[error("checking the plan: {0}")]
    Eval(#[from] EvalError),
}

/// A plan from the MIP planner.
#[derive(Clone, Debug, PartialEq)]
pub struct MipPlan {
    /// `(T + 1) · 2` numbers, the start first.
    pub path: Vec<f64>,
    /// Exact hard robustness of the plan (> 0: satisfied).
    pub robustness: f64,
    /// The program's robustness `ρ̃ ≤ ρ` (the linearised predicates).
    pub program_robustness: f64,
    /// `true` if the solver proved the plan optimal; `false` if the time limit cut it.
    pub optimal: bool,
    /// Seconds to build and solve the program.
    pub seconds: f64,
    /// Binary variables in the program.
    pub binaries: usize,
    /// Constraints in the program.
    pub constraints: usize,
    /// Programs solved: one, plus one per round that found left-out clauses violated,
    /// plus one if keeping out of goals by claims alone fell short of the cap, plus
    /// one if no satisfying plan was found first ([`MipConfig::satisfying_first`]).
    pub rounds: usize,
}

impl MipPlan {
    /// `true` if the path satisfies the spec.
    pub fn satisfied(&self) -> bool {
        self.robustness > 0.0
    }
}

/// Plans for `task` from `start` with the MIP planner. A spec no plan satisfies is
/// not an error here: the plan maximising `ρ̃` comes back with `ρ̃ ≤ 0` (see
/// [`MipPlan::satisfied`]).
pub fn plan(task: &Task, start: &[f64], cfg: &MipConfig) -> Result<MipPlan, MipError> {
    cfg.validate().map_err(MipError::Setting)?;
    if task.map.dim() != 2 || start.len() != 2 {
        return Err(MipError::Unsupported(format!(
            "a {}-D plan: the MIP planner encodes 2-D tasks (Point, Car, Doggo)",
            task.map.dim()
        )));
    }
    let t0 = Instant::now();
    let formula = task.planning_formula();
    let atoms = geometry::Atoms::of_task(task, start, cfg.sides, cfg.outside_sides)?;
    let hard = Semantics::hard();
    let mut clauses: HashMap<usize, Spec> = HashMap::new();
    let mut active: HashSet<encode::Occurrence> = HashSet::new();
    let left = |t0: Instant| (cfg.time_limit - t0.elapsed().as_secs_f64()).max(1e-3);
    // The plan of the last round, for a time-out in the next.
    let mut last: Option<MipPlan> = None;
    let timed_out = |e: &MipError| matches!(e, MipError::TimeOut(_));
    // With a cap, keeping out of a goal goes first by the claims alone (a lower bound of
    // the full program, without its tangent binaries): a plan at the cap is as good as
    // any; short of it, the tangents are added.
    let mut tangents = cfg.robustness_cap.is_none();
    // Satisfying first: a plan at the cap (or at least `SATISFYING` robust) is asked for,
    // with the cuts that hold for such plans alone; if there is none, the whole program.
    let mut satisfying_first = cfg.satisfying_first.unwrap_or(cfg.solver.satisfying_first());
    // Which free cells meet: read on a grid, once per plan and only when the cuts are used.
    let meet = if satisfying_first { atoms.cells_meet(WALLS) } else { vec![] };
    for round in 1.. {
        // Stage 1: the most robust plan (the discrete choices that matter).
        let mut most = Built::new(task, &formula, &atoms, &active, start, tangents)?;
        let without_tangents = most.without_tangents;
        let root = match cfg.robustness_cap {
            Some(cap) => most.capped(cap),
            None => most.root.clone(),
        };
        if satisfying_first {
            most.require(cfg.robustness_cap.unwrap_or(SATISFYING), &meet);
        }
        let size = Round {
            binaries: most.program.binaries.len(),
            constraints: most.program.constraints.len(),
            number: round,
        };
        let (status, (first, choices, best)) = match most.solve(cfg, left(t0), root, true, satisfying_first) {
            Err(e) if timed_out(&e) && last.is_some() => return Ok(out_of_time(last, t0)),
            Ok(None) => {
                // No satisfying plan: with the tangents (if keeping out of goals went by
                // the claims alone), then the whole program.
                if without_tangents {
                    tangents = true;
                } else {
                    satisfying_first = false;
                }
                continue;
            }
            other => other?.expect("only a program asking for the cap may be infeasible"),
        };
        if without_tangents && cfg.robustness_cap.is_some_and(|cap| best < cap - 1e-6) {
            // Short of the cap by the claims alone: its plan (not shortened) stands if
            // the program with tangents runs out of time.
            last = Some(size.plan(task, [start, &first].concat(), best, false, false, t0)?);
            tangents = true;
            continue;
        }
        // Stage 2: the shortest plan as robust, with those choices fixed (a linear
        // program) or, `shortest`, chosen afresh.
        let mut short = Built::new(task, &formula, &atoms, &active, start, tangents)?;
        debug_assert_eq!(short.program.binaries.len(), choices.len(), "the encoding is deterministic");
        if cfg.shortest {
            // Its time-out leaves the first stage's plan.
            let unshortened = [start, &first].concat();
            last = Some(size.plan(task, unshortened, best, false, false, t0)?);
        } else {
            for (b, v) in short.program.binaries.clone().into_iter().zip(choices) {
                short.program.constraints.push(Expression::from(b).eq(v.round()));
            }
        }
        // A hair below the optimum, so rounding in the first solve cannot make it infeasible.
        let floor = best - 1e-7 * (1.0 + best.abs());
        short.program.constraints.push(short.root.clone().geq(floor));
        let length = short.length(cfg);
        let omitted = short.omitted.clone();
        let (shortened, (waypoints, _, program_robustness)) =
            match short.solve(cfg, left(t0), -length, false, false) {
                Err(e) if timed_out(&e) && last.is_some() => return Ok(out_of_time(last, t0)),
                other => other?.expect("a program that does not ask for the cap is feasible"),
            };
        let mut path = start.to_vec();
        path.extend(waypoints);
        // The clauses left out must hold at least as well as the optimum.
        let mut violated = 0;
        for (f, t) in &omitted {
            let spec = clauses.entry(f.0).or_insert_with(|| task.spec_of(f.1.clone()));
            if spec.robustness_signal(&path, &hard)?[*t] < floor {
                active.insert((f.0, *t));
                violated += 1;
            }
        }

        // With clauses violated, the program's figure is not a bound on the plan's.
        let optimal = violated == 0
            && matches!(status, SolutionStatus::Optimal)
            && (!cfg.shortest || matches!(shortened, SolutionStatus::Optimal));
        let plan = size.plan(task, path, program_robustness, violated == 0, optimal, t0)?;
        if violated == 0 || plan.seconds >= cfg.time_limit {
            return Ok(plan);
        }
        last = Some(plan);
    }
    unreachable!("the rounds end by returning")
}

/// One round's program, as a plan reports it.
#[derive(Clone, Copy)]
struct Round {
    binaries: usize,
    constraints: usize,
    number: usize,
}

impl Round {
    /// This round's plan `path` (the start first), checked with the exact robustness.
    /// `program` is the program's robustness: reported as it is where it `bounds` the
    /// plan's, and otherwise no higher than the plan's (an unshortened stage-1 plan, or
    /// clauses left out that the plan violates).
    fn plan(
        self,
        task: &Task,
        path: Vec<f64>,
        program: f64,
        bounds: bool,
        optimal: bool,
        t0: Instant,
    ) -> Result<MipPlan, MipError> {
        let robustness = task.spec().robustness(&path, &Semantics::hard())?;
        Ok(MipPlan {
            path,
            robustness,
            program_robustness: if bounds { program } else { robustness.min(program) },
            optimal,
            seconds: t0.elapsed().as_secs_f64(),
            binaries: self.binaries,
            constraints: self.constraints,
            rounds: self.number,
        })
    }
}

/// The last round's plan, when the next round ran out of time: not optimal, and timed
/// to now.
fn out_of_time(last: Option<MipPlan>, t0: Instant) -> MipPlan {
    let plan = last.expect("only called with a plan");
    MipPlan { optimal: false, seconds: t0.elapsed().as_secs_f64(), ..plan }
}

/// A task's program from one start, and the expression of its root's robustness.
struct Built {
    program: encode::Program,
    root: Expression,
    /// Lazy occurrences left out: (address, the clause) and the waypoint.
    omitted: Vec<((usize, Formula), usize)>,
    /// Whether some keep-out went by its claims alone.
    without_tangents: bool,
    /// The waypoints at which the walls are a conjunct of the spec (the segments a
    /// satisfying plan keeps inside a free cell).
    walls_required: Vec<usize>,
}

/// What a solve gives: waypoints, the binaries' values, the root's value.
type Solved = (Vec<f64>, Vec<f64>, f64);

impl Built {
    fn new(
        task: &Task,
        formula: &Formula,
        atoms: &geometry::Atoms,
        active: &HashSet<encode::Occurrence>,
        start: &[f64],
        tangents: bool,
    ) -> Result<Built, MipError> {
        let (lo, hi) = task.map.region();
        let mut program =
            encode::Program::new([start[0], start[1]], task.steps, ([lo[0], lo[1]], [hi[0], hi[1]]));
        let mut encoder = encode::Encoder::new(
            &mut program,
            atoms,
            active,
            (UNTIL, Semantics::hard().top),
            formula,
            tangents,
        );
        let root = encoder.encode(formula, 0, true)?;
        let mut required = vec![];
        if atoms.cells(WALLS).1 == crate::task::SafeAlong::Segments {
            encoder.required(formula, 0, WALLS, &mut required);
        }
        let omitted =
            encoder.omitted().iter().map(|&(f, t)| ((f as *const Formula as usize, f.clone()), t)).collect();
        let without_tangents = encoder.without_tangents();
        let root = match root {
            encode::Rob::Const(c) => Expression::from(c),
            encode::Rob::Lin { e, .. } => e,
        };
        Ok(Built { program, root, omitted, without_tangents, walls_required: required })
    }

    /// Asks for `ρ̃ ≥ floor` (`floor > 0`) and adds what holds for such plans alone:
    /// consecutive segments the spec keeps clear of the walls lie in free cells that
    /// `meet` (which free cells meet, [`geometry::Atoms::cells_meet`]).
    fn require(&mut self, floor: f64, meet: &[Vec<bool>]) {
        self.program.constraints.push(self.root.clone().geq(floor));
        self.program.link_cells(&self.walls_required, meet);
    }

    /// `min(ρ̃, cap)` as a variable, the objective that ends the search at any plan at
    /// least `cap` robust.
    fn capped(&mut self, cap: f64) -> Expression {
        let c = self.program.vars.add(good_lp::variable().max(cap));
        self.program.constraints.push(Expression::from(c).leq(self.root.clone()));
        Expression::from(c)
    }

    /// The plan's 1-norm length `Σ |x_t − x_{t−1}|` through `s ≥ ±(x_t − x_{t−1})`, with
    /// the step bound `s ≤ max_step`.
    fn length(&mut self, cfg: &MipConfig) -> Expression {
        let p = &mut self.program;
        let mut length = Expression::from(0.0);
        let mut prev: Vec<Expression> = p.start().iter().map(|&c| Expression::from(c)).collect();
        for x in p.x.clone() {
            for k in 0..2 {
                let s = p.vars.add(good_lp::variable().min(0.0).max(cfg.max_step));
                let step = Expression::from(x[k]) - prev[k].clone();
                p.constraints.push(step.clone().leq(s));
                p.constraints.push((-step).leq(s));
                length += s;
                prev[k] = x[k].into();
            }
        }
        length
    }

    /// Maximises `objective`; with `bound_steps`, adds the step bound first (the
    /// second stage's length term carries it).
    fn solve(
        mut self,
        cfg: &MipConfig,
        time_limit: f64,
        objective: Expression,
        bound_steps: bool,
        may_be_infeasible: bool,
    ) -> Result<Option<(SolutionStatus, Solved)>, MipError> {
        if bound_steps {
            self.bound_steps(cfg);
        }
        let Built { program, root, .. } = self;
        let encode::Program { vars, constraints, x, binaries, .. } = program;
        let unsolved = vars.maximise(objective);
        match cfg.solver {
            MipSolver::Microlp => {
                let model =
                    unsolved.using(good_lp::microlp).with_time_limit(time_limit).with_all(constraints);
                solution_of(model.solve(), cfg, may_be_infeasible, |s| {
                    (s.status(), read(s, &x, &binaries, &root))
                })
            }
            #[cfg(feature = "highs")]
            MipSolver::Highs => {
                let mut model = unsolved.using(good_lp::highs).set_threads(1).set_time_limit(time_limit);
                model.set_verbose(false);
                let model = model.with_all(constraints);
                solution_of(model.solve(), cfg, may_be_infeasible, |s| {
                    (s.status(), read(s, &x, &binaries, &root))
                })
            }
        }
    }

    /// `|x_t − x_{t−1}| ≤ max_step` per coordinate.
    fn bound_steps(&mut self, cfg: &MipConfig) {
        let p = &mut self.program;
        let mut prev: Vec<Expression> = p.start().iter().map(|&c| Expression::from(c)).collect();
        for x in p.x.clone() {
            for k in 0..2 {
                let step = Expression::from(x[k]) - prev[k].clone();
                p.constraints.push(step.clone().leq(cfg.max_step));
                p.constraints.push(step.geq(-cfg.max_step));
                prev[k] = x[k].into();
            }
        }
    }
}

/// The waypoints, the binaries and the root's value in a solution.
fn read(
    s: &impl Solution,
    x: &[[good_lp::Variable; 2]],
    binaries: &[good_lp::Variable],
    root: &Expression,
) -> Solved {
    let waypoints = x.iter().flat_map(|w| [s.value(w[0]), s.value(w[1])]).collect();
    (waypoints, binaries.iter().map(|&b| s.value(b)).collect(), s.eval(root))
}

/// The solver's answer, or the error that says what went wrong.
fn solution_of<S, T>(
    solved: Result<S, ResolutionError>,
    cfg: &MipConfig,
    may_be_infeasible: bool,
    take: impl FnOnce(&S) -> T,
) -> Result<Option<T>, MipError> {
    let solver = cfg.solver.name();
    match solved {
        Ok(s) => Ok(Some(take(&s))),
        Err(ResolutionError::Infeasible) if may_be_infeasible => Ok(None),
        // microlp's and HiGHS's words for a time limit without any plan.
        Err(ResolutionError::Other(m)) if m.contains("Time limit") || m.contains("NoSolutionFound") => {
            Err(MipError::TimeOut(cfg.time_limit))
        }
        Err(ResolutionError::Str(m)) if m.contains("NoSolutionFound") => {
            Err(MipError::TimeOut(cfg.time_limit))
        }
        // Every program built here is feasible (any plan has some robustness) and
        // bounded (every variable is), so these are numerical failures.
        Err(ResolutionError::Infeasible) => Err(MipError::Solver {
            solver,
            message: "reported the program infeasible (a numerical failure)".into(),
        }),
        Err(ResolutionError::Unbounded) => Err(MipError::Solver {
            solver,
            message: "reported the program unbounded (a numerical failure)".into(),
        }),
        Err(e) => Err(MipError::Solver { solver, message: e.to_string() }),
    }
}
