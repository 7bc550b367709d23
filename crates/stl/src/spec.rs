//! A formula with its names bound: robustness of paths and its gradient.
//!
//! ```
//! use stl::{Ball, Formula, Semantics, Spec};
//! let f: Formula = "F[1,2] goal & G[1,2] x > -5".parse().unwrap();
//! let spec = Spec::builder(f)
//!     .signals(["x", "y"])
//!     .bind("goal", Ball::new([2.0, 2.0], 0.5))
//!     .build()
//!     .unwrap();
//! // A path of 3 states (x, y), row-major.
//! let path = [0.0, 0.0, 1.0, 1.0, 2.0, 2.1];
//! let (rho, grad) = spec.gradient(&path, &Semantics::hard()).unwrap();
//! assert!((rho - 0.4).abs() < 1e-12);
//! assert_eq!(grad.len(), path.len());
//! ```

use std::collections::HashMap;
use std::sync::Arc;

use crate::formula::Formula;
use crate::predicate::{Predicate, Shifted, SignalCompare};
use crate::program::{Atom, Program, UntilRule, Workspace};
use crate::semantics::{Semantics, SemanticsError};

/// A problem found while binding a formula's names.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SpecError {
    /// A name is neither a bound predicate nor a signal.
    #[error("'{name}' is not bound: it is neither a predicate given to the spec nor a signal{}", signal_list(.signals))]
    Unbound {
        /// The unbound name.
        name: String,
        /// The signals that exist.
        signals: Vec<String>,
    },
    /// A name is both a signal and a bound predicate.
    #[error("'{0}' is both a signal and a bound predicate; rename one")]
    Ambiguous(String),
    /// A comparison with NaN or an infinity.
    #[error("the comparison '{name} {op} {threshold}' needs a finite number")]
    NonFiniteThreshold {
        /// Signal or predicate.
        name: String,
        /// Operator symbol.
        op: &'static str,
        /// The number.
        threshold: f64,
    },
    /// A predicate reads more state dimensions than the spec's state has.
    #[error("predicate '{name}' reads {needs} state dimensions but the state has {state_dim}")]
    Dimension {
        /// Predicate name.
        name: String,
        /// Dimensions it reads.
        needs: usize,
        /// The spec's state dimension.
        state_dim: usize,
    },
}

fn signal_list(signals: &[String]) -> String {
    if signals.is_empty() { String::new() } else { format!(" (signals: {})", signals.join(", ")) }
}

/// A path or semantics that cannot be evaluated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EvalError {
    /// The path is empty.
    #[error("the path is empty: robustness needs at least one state")]
    Empty,
    /// The path's length is not a whole number of states.
    #[error("the path has {len} numbers, not a multiple of the state dimension {dim}")]
    Shape {
        /// Numbers given.
        len: usize,
        /// The spec's state dimension.
        dim: usize,
    },
    /// A batch's length is not a whole number of paths of the given length.
    #[error("the batch has {len} numbers, not a multiple of steps × state dimension = {steps} × {dim}")]
    BatchShape {
        /// Numbers given.
        len: usize,
        /// Steps per path.
        steps: usize,
        /// State dimension.
        dim: usize,
    },
    /// Bad semantics parameters.
    #[error(transparent)]
    Semantics(#[from] SemanticsError),
    /// The start step lies past the path's end.
    #[error("start step {at} is past the path's last step {last}")]
    Start {
        /// The start step asked for.
        at: usize,
        /// The path's last step.
        last: usize,
    },
}

/// How an atom was resolved against the bindings and signals.
pub(crate) enum Resolved {
    Predicate { sign: f64, threshold: f64, shifted: bool },
    Signal(SignalCompare),
}

/// Resolves every atom of `program` against the bound names and `signals`.
pub(crate) fn resolve<P: ?Sized>(
    program: &Program,
    signals: &[String],
    bindings: &HashMap<String, Box<P>>,
) -> Result<Vec<Resolved>, SpecError> {
    program
        .atoms()
        .iter()
        .map(|atom| {
            let name = atom.name();
            let (sign, threshold, shifted) = match atom {
                Atom::Name(_) => (1.0, 0.0, false),
                Atom::Compare { op, threshold, .. } => {
                    if !threshold.is_finite() {
                        return Err(SpecError::NonFiniteThreshold {
                            name: name.into(),
                            op: op.symbol(),
                            threshold: *threshold,
                        });
                    }
                    (op.sign(), *threshold, true)
                }
            };
            let signal = signals.iter().position(|s| s == name);
            match (bindings.contains_key(name), signal) {
                (true, Some(_)) => Err(SpecError::Ambiguous(name.into())),
                (true, None) => Ok(Resolved::Predicate { sign, threshold, shifted }),
                (false, Some(index)) => Ok(Resolved::Signal(SignalCompare { index, sign, threshold })),
                (false, None) => Err(SpecError::Unbound { name: name.into(), signals: signals.to_vec() }),
            }
        })
        .collect()
}

/// Builds a [`Spec`]: names the state's signals and binds predicate names.
pub struct SpecBuilder {
    formula: Formula,
    until: UntilRule,
    signals: Vec<String>,
    state_dim: Option<usize>,
    bindings: HashMap<String, Box<dyn Predicate>>,
}

impl SpecBuilder {
    /// Names the state dimensions, in order; a formula may compare them (`x > 0.5`)
    /// or use them bare (robustness = the value). Sets the state dimension.
    pub fn signals<S: Into<String>>(mut self, names: impl IntoIterator<Item = S>) -> Self {
        self.signals = names.into_iter().map(Into::into).collect();
        self
    }

    /// Sets the state dimension (default: the number of signals, or if none, the
    /// most any bound predicate reads).
    pub fn state_dim(mut self, dim: usize) -> Self {
        self.state_dim = Some(dim);
        self
    }

    /// How `U` is read (default: [`UntilRule::Standard`]).
    pub fn until(mut self, rule: UntilRule) -> Self {
        self.until = rule;
        self
    }

    /// Binds `name` to a predicate.
    pub fn bind(mut self, name: impl Into<String>, predicate: impl Predicate + 'static) -> Self {
        self.bindings.insert(name.into(), Box::new(predicate));
        self
    }

    /// Binds `name` to a shared predicate.
    pub fn bind_shared(self, name: impl Into<String>, predicate: Arc<dyn Predicate>) -> Self {
        self.bind(name, predicate)
    }

    /// Checks every name and builds the spec.
    pub fn build(mut self) -> Result<Spec, SpecError> {
        let program = Program::compile_with(&self.formula, self.until);
        let state_dim = self.state_dim.unwrap_or_else(|| {
            if self.signals.is_empty() {
                self.bindings.values().map(|p| p.required_dim()).max().unwrap_or(0)
            } else {
                self.signals.len()
            }
        });
        let resolved = resolve(&program, &self.signals, &self.bindings)?;
        // Which binding each column uses, by name; taken out of the map below.
        let plan: Vec<_> = resolved
            .into_iter()
            .zip(program.atoms())
            .map(|(r, atom)| match r {
                Resolved::Predicate { sign, threshold, shifted, .. } => {
                    Err((atom.name().to_string(), sign, threshold, shifted))
                }
                Resolved::Signal(s) => Ok(s),
            })
            .collect();
        let mut shared: HashMap<String, Arc<dyn Predicate>> = HashMap::new();
        let mut predicates: Vec<Box<dyn Predicate>> = Vec::with_capacity(plan.len());
        for item in plan {
            match item {
                Ok(sig) => predicates.push(Box::new(sig)),
                Err((name, sign, threshold, shifted)) => {
                    let p = match shared.get(&name) {
                        Some(p) => p.clone(),
                        None => {
                            let p: Arc<dyn Predicate> =
                                Arc::from(self.bindings.remove(&name).expect("resolved"));
                            if p.required_dim() > state_dim {
                                return Err(SpecError::Dimension {
                                    name,
                                    needs: p.required_dim(),
                                    state_dim,
                                });
                            }
                            shared.insert(name, p.clone());
                            p
                        }
                    };
                    predicates.push(if shifted {
                        Box::new(Shifted { inner: p, sign, threshold })
                    } else {
                        Box::new(p)
                    });
                }
            }
        }
        Ok(Spec { formula: self.formula, program, predicates, state_dim, signals: self.signals })
    }
}

/// A formula with every name bound to a predicate or a signal: evaluates robustness
/// and its gradient on paths.
///
/// A path is a row-major `steps × state_dim` slice of `f64`; step 0 is the start.
/// Robustness is taken at step 0 unless a start time is given. NaN in a path or a
/// predicate propagates to the result.
pub struct Spec {
    formula: Formula,
    program: Program,
    predicates: Vec<Box<dyn Predicate>>,
    state_dim: usize,
    signals: Vec<String>,
}

impl std::fmt::Debug for Spec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Spec")
            .field("formula", &self.formula.to_string())
            .field("state_dim", &self.state_dim)
            .field("signals", &self.signals)
            .finish()
    }
}

impl Spec {
    /// Starts binding `formula`.
    pub fn builder(formula: Formula) -> SpecBuilder {
        SpecBuilder {
            formula,
            until: UntilRule::default(),
            signals: Vec::new(),
            state_dim: None,
            bindings: HashMap::new(),
        }
    }

    /// The formula.
    pub fn formula(&self) -> &Formula {
        &self.formula
    }

    /// The compiled program (for evaluating on predicate values computed elsewhere).
    pub fn program(&self) -> &Program {
        &self.program
    }

    /// The state dimension paths must have.
    pub fn state_dim(&self) -> usize {
        self.state_dim
    }

    /// The named signals.
    pub fn signals(&self) -> &[String] {
        &self.signals
    }

    /// A reusable evaluator (allocation-free once warm).
    pub fn evaluator(&self) -> Evaluator<'_> {
        Evaluator { spec: self, ws: Workspace::new(), values: Vec::new(), dvalues: Vec::new(), steps: 0 }
    }

    /// Robustness at step 0.
    pub fn robustness(&self, path: &[f64], sem: &Semantics) -> Result<f64, EvalError> {
        self.evaluator().robustness(path, sem)
    }

    /// Robustness at every start step.
    pub fn robustness_signal(&self, path: &[f64], sem: &Semantics) -> Result<Vec<f64>, EvalError> {
        let mut ev = self.evaluator();
        ev.forward(path, sem)?;
        Ok(ev.ws.signal().to_vec())
    }

    /// Robustness at step 0 and its gradient with respect to every number of the path.
    pub fn gradient(&self, path: &[f64], sem: &Semantics) -> Result<(f64, Vec<f64>), EvalError> {
        let mut grad = vec![0.0; path.len()];
        let rho = self.evaluator().gradient(path, 0, sem, &mut grad)?;
        Ok((rho, grad))
    }

    fn check_batch(&self, len: usize, steps: usize) -> Result<usize, EvalError> {
        let per = steps * self.state_dim;
        if steps == 0 {
            return Err(EvalError::Empty);
        }
        if per == 0 || !len.is_multiple_of(per) {
            return Err(EvalError::BatchShape { len, steps, dim: self.state_dim });
        }
        Ok(per)
    }

    /// Robustness at step 0 of each path of a batch (`batch × steps × state_dim`,
    /// row-major), in parallel when the `parallel` feature is on.
    pub fn robustness_batch(
        &self,
        paths: &[f64],
        steps: usize,
        sem: &Semantics,
    ) -> Result<Vec<f64>, EvalError> {
        let per = self.check_batch(paths.len(), steps)?;
        sem.validate()?;
        let run = |ev: &mut Evaluator<'_>, p: &[f64]| ev.robustness(p, sem).expect("shape checked");
        #[cfg(feature = "parallel")]
        {
            use rayon::prelude::*;
            Ok(paths.par_chunks(per).with_min_len(64).map_init(|| self.evaluator(), run).collect())
        }
        #[cfg(not(feature = "parallel"))]
        {
            let mut ev = self.evaluator();
            Ok(paths.chunks(per).map(|p| run(&mut ev, p)).collect())
        }
    }

    /// Robustness at step 0 of each path and, into `grads` (same shape as `paths`),
    /// its gradient.
    pub fn gradient_batch(
        &self,
        paths: &[f64],
        steps: usize,
        sem: &Semantics,
        grads: &mut [f64],
    ) -> Result<Vec<f64>, EvalError> {
        Ok(self.gradient_batch_impl(paths, steps, sem, grads, None)?.0)
    }

    /// [`Spec::gradient_batch`] under `sem`, and each path's robustness under `other`
    /// from the same predicate values (e.g. the hard robustness that decides
    /// satisfaction next to the soft one a loss differentiates).
    pub fn gradient_batch_and_robustness(
        &self,
        paths: &[f64],
        steps: usize,
        sem: &Semantics,
        grads: &mut [f64],
        other: &Semantics,
    ) -> Result<(Vec<f64>, Vec<f64>), EvalError> {
        self.gradient_batch_impl(paths, steps, sem, grads, Some(other))
    }

    fn gradient_batch_impl(
        &self,
        paths: &[f64],
        steps: usize,
        sem: &Semantics,
        grads: &mut [f64],
        other: Option<&Semantics>,
    ) -> Result<(Vec<f64>, Vec<f64>), EvalError> {
        let per = self.check_batch(paths.len(), steps)?;
        if grads.len() != paths.len() {
            return Err(EvalError::BatchShape { len: grads.len(), steps, dim: self.state_dim });
        }
        sem.validate()?;
        if let Some(o) = other {
            o.validate()?;
        }
        let run = |ev: &mut Evaluator<'_>, (p, g): (&[f64], &mut [f64])| {
            g.fill(0.0);
            let rho = ev.gradient(p, 0, sem, g).expect("shape checked");
            (rho, other.map_or(rho, |o| ev.reevaluate(0, o).expect("validated")))
        };
        #[cfg(feature = "parallel")]
        {
            use rayon::prelude::*;
            Ok(paths
                .par_chunks(per)
                .zip(grads.par_chunks_mut(per))
                .with_min_len(64)
                .map_init(|| self.evaluator(), run)
                .unzip())
        }
        #[cfg(not(feature = "parallel"))]
        {
            let mut ev = self.evaluator();
            Ok(paths.chunks(per).zip(grads.chunks_mut(per)).map(|pg| run(&mut ev, pg)).unzip())
        }
    }
}

/// Evaluates one [`Spec`] repeatedly without allocating.
pub struct Evaluator<'s> {
    spec: &'s Spec,
    ws: Workspace,
    values: Vec<f64>,
    dvalues: Vec<f64>,
    /// Steps of the path last evaluated (0: none yet). Kept apart from `values`,
    /// which is empty for a spec without predicates (`true`, `false`).
    steps: usize,
}

impl Evaluator<'_> {
    fn steps(&self, path: &[f64]) -> Result<usize, EvalError> {
        let dim = self.spec.state_dim;
        if path.is_empty() {
            return Err(EvalError::Empty);
        }
        if dim == 0 || !path.len().is_multiple_of(dim) {
            return Err(EvalError::Shape { len: path.len(), dim });
        }
        Ok(path.len() / dim)
    }

    fn forward(&mut self, path: &[f64], sem: &Semantics) -> Result<usize, EvalError> {
        sem.validate()?;
        let n = self.steps(path)?;
        let dim = self.spec.state_dim;
        let preds = &self.spec.predicates;
        self.values.clear();
        for t in 0..n {
            self.values.extend(preds.iter().map(|p| p.value_on_path(path, dim, t)));
        }
        self.spec.program.forward(&self.values, n, sem, &mut self.ws);
        self.steps = n;
        Ok(n)
    }

    /// Robustness at step 0.
    pub fn robustness(&mut self, path: &[f64], sem: &Semantics) -> Result<f64, EvalError> {
        self.forward(path, sem)?;
        Ok(self.ws.signal()[0])
    }

    /// Robustness at start step `t` (a step of the path).
    pub fn robustness_at(&mut self, path: &[f64], t: usize, sem: &Semantics) -> Result<f64, EvalError> {
        let n = self.forward(path, sem)?;
        Ok(self.ws.signal()[start(t, n)?])
    }

    /// Robustness at start step `t` (a step of the path), adding its gradient with respect to the path
    /// into `grad` (same length as `path`).
    pub fn gradient(
        &mut self,
        path: &[f64],
        t: usize,
        sem: &Semantics,
        grad: &mut [f64],
    ) -> Result<f64, EvalError> {
        let n = self.forward(path, sem)?;
        if grad.len() != path.len() {
            return Err(EvalError::Shape { len: grad.len(), dim: self.spec.state_dim });
        }
        let t = start(t, n)?;
        let rho = self.ws.signal()[t];
        self.spec.program.backward(t, sem, &mut self.ws, &mut self.dvalues);
        let dim = self.spec.state_dim;
        let np = self.spec.predicates.len();
        for step in 0..n {
            for (p, pred) in self.spec.predicates.iter().enumerate() {
                let d = self.dvalues[step * np + p];
                if d != 0.0 {
                    pred.value_and_grad_on_path(path, dim, step, d, grad);
                }
            }
        }
        Ok(rho)
    }

    /// Robustness at start step `t` of the path last evaluated, under `sem`, from the
    /// predicate values already computed (no predicate is evaluated again: with
    /// map-clearance predicates those are the expensive part).
    pub fn reevaluate(&mut self, t: usize, sem: &Semantics) -> Result<f64, EvalError> {
        sem.validate()?;
        let n = self.steps;
        if n == 0 {
            return Err(EvalError::Empty);
        }
        self.spec.program.forward(&self.values, n, sem, &mut self.ws);
        Ok(self.ws.signal()[start(t, n)?])
    }
}

/// `t` when it is a step of an `n`-step path.
fn start(t: usize, n: usize) -> Result<usize, EvalError> {
    if t < n { Ok(t) } else { Err(EvalError::Start { at: t, last: n - 1 }) }
}
