//! Differentiable robustness of batches of paths as candle operations (feature
//! `candle`).
//!
//! Predicates map a `[batch, steps, state_dim]` tensor of paths to a
//! `[batch, steps]` tensor of values; the formula's structure maps the stacked
//! `[batch, steps, predicates]` values to one robustness per path with a single
//! [`candle_core::CustomOp1`] whose backward pass is the exact gradient of the
//! chosen semantics. Gradients therefore flow into whatever produced the paths (a
//! planner network) *and* into the parameters of neural predicates, which are plain
//! candle computations.
//!
//! ```
//! use candle_core::{Device, Tensor, Var};
//! use stl::{Ball, Formula, Semantics};
//! use stl::tensor::TensorSpec;
//!
//! let spec = TensorSpec::builder("F[1,2] goal".parse::<Formula>().unwrap(), 2)
//!     .bind_predicate("goal", Ball::new([1.0, 1.0], 0.5))
//!     .build()
//!     .unwrap();
//! let paths = Var::from_tensor(&Tensor::zeros((4, 3, 2), candle_core::DType::F32, &Device::Cpu).unwrap()).unwrap();
//! let rho = spec.robustness(paths.as_tensor(), &Semantics::soft(2.0)).unwrap(); // [4]
//! let grads = rho.sum_all().unwrap().backward().unwrap();
//! assert!(grads.get(paths.as_tensor()).is_some());
//! ```

use std::collections::HashMap;
use std::sync::Arc;

use candle_core::backend::BackendStorage;
use candle_core::{CpuStorage, CustomOp1, DType, Layout, Shape, Tensor};

use crate::formula::Formula;
use crate::predicate::Predicate;
use crate::program::{Program, UntilRule, Workspace};
use crate::semantics::Semantics;
use crate::spec::{Resolved, SpecError, resolve};

/// A predicate on batched paths: `[batch, steps, state_dim]` → `[batch, steps]`.
/// Implement it with candle operations (e.g. a neural network) and gradients reach
/// its parameters.
pub trait TensorPredicate: Send + Sync {
    /// The predicate's value at every step of every path.
    fn forward(&self, paths: &Tensor) -> candle_core::Result<Tensor>;
}

impl<F> TensorPredicate for F
where
    F: Fn(&Tensor) -> candle_core::Result<Tensor> + Send + Sync,
{
    fn forward(&self, paths: &Tensor) -> candle_core::Result<Tensor> {
        self(paths)
    }
}

fn to_f64(storage: &CpuStorage, layout: &Layout) -> candle_core::Result<Vec<f64>> {
    let (start, end) = layout
        .contiguous_offsets()
        .ok_or_else(|| candle_core::Error::msg("stl tensor op: input must be contiguous"))?;
    match storage {
        CpuStorage::F32(v) => Ok(v[start..end].iter().map(|&x| x as f64).collect()),
        CpuStorage::F64(v) => Ok(v[start..end].to_vec()),
        _ => candle_core::bail!("stl tensor op: paths must be f32 or f64"),
    }
}

fn from_f64(v: Vec<f64>, dtype: DType) -> candle_core::Result<CpuStorage> {
    match dtype {
        DType::F32 => Ok(CpuStorage::F32(v.into_iter().map(|x| x as f32).collect())),
        DType::F64 => Ok(CpuStorage::F64(v)),
        _ => candle_core::bail!("stl tensor op: paths must be f32 or f64"),
    }
}

fn dims3(layout: &Layout, what: &str) -> candle_core::Result<(usize, usize, usize)> {
    match layout.dims() {
        &[b, t, d] => Ok((b, t, d)),
        other => {
            candle_core::bail!("stl tensor op: {what} must be [batch, steps, dim], got {other:?}")
        }
    }
}

/// A scalar [`Predicate`] applied at every step of `[batch, steps, dim]`, with its exact
/// gradient as the backward pass.
#[derive(Clone)]
pub struct Pointwise(pub Arc<dyn Predicate>);

impl CustomOp1 for Pointwise {
    fn name(&self) -> &'static str {
        "stl-predicate"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> candle_core::Result<(CpuStorage, Shape)> {
        let (b, t, d) = dims3(layout, "paths")?;
        if self.0.required_dim() > d {
            candle_core::bail!("predicate reads {} dimensions, paths have {d}", self.0.required_dim());
        }
        let x = to_f64(storage, layout)?;
        let path = |i: usize| &x[(i / t) * t * d..(i / t + 1) * t * d];
        let out: Vec<f64> = (0..b * t).map(|i| self.0.value_on_path(path(i), d, i % t)).collect();
        Ok((from_f64(out, storage.dtype())?, Shape::from((b, t))))
    }

    fn bwd(&self, arg: &Tensor, _res: &Tensor, grad_res: &Tensor) -> candle_core::Result<Option<Tensor>> {
        let (b, t, d) = arg.dims3()?;
        let x: Vec<f64> = arg.to_dtype(DType::F64)?.flatten_all()?.to_vec1()?;
        let g: Vec<f64> = grad_res.to_dtype(DType::F64)?.flatten_all()?.to_vec1()?;
        let mut out = vec![0.0; x.len()];
        for (i, &gi) in g.iter().enumerate().take(b * t) {
            if gi != 0.0 {
                let at = (i / t) * t * d..(i / t + 1) * t * d;
                self.0.value_and_grad_on_path(&x[at.clone()], d, i % t, gi, &mut out[at]);
            }
        }
        Ok(Some(Tensor::from_vec(out, (b, t, d), arg.device())?.to_dtype(arg.dtype())?))
    }
}

impl TensorPredicate for Pointwise {
    fn forward(&self, paths: &Tensor) -> candle_core::Result<Tensor> {
        paths.contiguous()?.apply_op1(self.clone())
    }
}

/// The formula's structure as one candle op: `[batch, steps, predicates]` values →
/// `[batch]` robustness at step `start`.
#[derive(Clone)]
pub struct RobustnessOp {
    program: Arc<Program>,
    semantics: Semantics,
    start: usize,
}

impl RobustnessOp {
    /// The op for `program` under `semantics`, robustness taken at step `start`.
    pub fn new(program: Arc<Program>, semantics: Semantics, start: usize) -> Self {
        Self { program, semantics, start }
    }

    fn per_path<R: Send>(
        &self,
        x: &[f64],
        b: usize,
        t: usize,
        p: usize,
        f: impl Fn(&mut Workspace, &[f64]) -> R + Sync + Send,
    ) -> Vec<R> {
        let chunk = (t * p).max(1);
        #[cfg(feature = "parallel")]
        {
            use rayon::prelude::*;
            x.par_chunks(chunk).take(b).map_init(Workspace::new, |ws, v| f(ws, v)).collect()
        }
        #[cfg(not(feature = "parallel"))]
        {
            let mut ws = Workspace::new();
            x.chunks(chunk).take(b).map(|v| f(&mut ws, v)).collect()
        }
    }
}

impl CustomOp1 for RobustnessOp {
    fn name(&self) -> &'static str {
        "stl-robustness"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> candle_core::Result<(CpuStorage, Shape)> {
        let (b, t, p) = dims3(layout, "predicate values")?;
        if p != self.program.atoms().len() || t == 0 {
            candle_core::bail!(
                "expected [batch, steps>0, {}] predicate values, got [{b}, {t}, {p}]",
                self.program.atoms().len()
            );
        }
        let x = to_f64(storage, layout)?;
        let out = self.per_path(&x, b, t, p, |ws, v| {
            self.program.forward(v, t, &self.semantics, ws);
            ws.signal()[self.start.min(t - 1)]
        });
        Ok((from_f64(out, storage.dtype())?, Shape::from(b)))
    }

    fn bwd(&self, arg: &Tensor, _res: &Tensor, grad_res: &Tensor) -> candle_core::Result<Option<Tensor>> {
        let (b, t, p) = arg.dims3()?;
        let x: Vec<f64> = arg.to_dtype(DType::F64)?.flatten_all()?.to_vec1()?;
        let g: Vec<f64> = grad_res.to_dtype(DType::F64)?.to_vec1()?;
        let parts = self.per_path(&x, b, t, p, |ws, v| {
            self.program.forward(v, t, &self.semantics, ws);
            let mut d = Vec::new();
            self.program.backward(self.start.min(t - 1), &self.semantics, ws, &mut d);
            d
        });
        let mut out = Vec::with_capacity(x.len());
        for (gi, d) in g.iter().zip(parts) {
            out.extend(d.into_iter().map(|v| v * gi));
        }
        Ok(Some(Tensor::from_vec(out, (b, t, p), arg.device())?.to_dtype(arg.dtype())?))
    }
}

enum Column {
    Signal { index: usize, sign: f64, threshold: f64 },
    Predicate { pred: Arc<dyn TensorPredicate>, sign: f64, threshold: f64, shifted: bool },
}

/// Builds a [`TensorSpec`].
pub struct TensorSpecBuilder {
    formula: Formula,
    until: UntilRule,
    state_dim: usize,
    signals: Vec<String>,
    bindings: HashMap<String, Box<dyn TensorPredicate>>,
}

impl TensorSpecBuilder {
    /// Names the state dimensions, in order (for comparisons such as `x > 0.5`).
    pub fn signals<S: Into<String>>(mut self, names: impl IntoIterator<Item = S>) -> Self {
        self.signals = names.into_iter().map(Into::into).collect();
        self
    }

    /// How `U` is read (default: [`UntilRule::Standard`]).
    pub fn until(mut self, rule: UntilRule) -> Self {
        self.until = rule;
        self
    }

    /// Binds `name` to a tensor predicate (e.g. a neural network).
    pub fn bind(mut self, name: impl Into<String>, pred: impl TensorPredicate + 'static) -> Self {
        self.bindings.insert(name.into(), Box::new(pred));
        self
    }

    /// Binds `name` to a scalar predicate, applied pointwise with its exact gradient.
    pub fn bind_predicate(self, name: impl Into<String>, pred: impl Predicate + 'static) -> Self {
        self.bind_shared_predicate(name, Arc::new(pred))
    }

    /// Binds `name` to a shared scalar predicate.
    pub fn bind_shared_predicate(self, name: impl Into<String>, pred: Arc<dyn Predicate>) -> Self {
        self.bind(name, Pointwise(pred))
    }

    /// Checks every name and builds the spec.
    pub fn build(self) -> Result<TensorSpec, SpecError> {
        let program = Program::compile_with(&self.formula, self.until);
        if self.signals.len() > self.state_dim {
            return Err(SpecError::Dimension {
                name: "signals".into(),
                needs: self.signals.len(),
                state_dim: self.state_dim,
            });
        }
        let resolved = resolve(&program, &self.signals, &self.bindings)?;
        let names: Vec<String> = program.atoms().iter().map(|a| a.name().to_string()).collect();
        let kinds: Vec<_> = resolved
            .into_iter()
            .map(|r| match r {
                Resolved::Signal(s) => Ok((s.index, s.sign, s.threshold)),
                Resolved::Predicate { sign, threshold, shifted, .. } => Err((sign, threshold, shifted)),
            })
            .collect();
        let mut bindings: HashMap<String, Arc<dyn TensorPredicate>> =
            self.bindings.into_iter().map(|(k, v)| (k, Arc::from(v))).collect();
        let columns = kinds
            .into_iter()
            .zip(names)
            .map(|(k, name)| match k {
                Ok((index, sign, threshold)) => Column::Signal { index, sign, threshold },
                Err((sign, threshold, shifted)) => {
                    let pred = bindings.get_mut(&name).expect("resolved").clone();
                    Column::Predicate { pred, sign, threshold, shifted }
                }
            })
            .collect();
        Ok(TensorSpec {
            formula: self.formula,
            program: Arc::new(program),
            columns,
            state_dim: self.state_dim,
        })
    }
}

/// A formula bound to tensor predicates: differentiable robustness of path batches.
pub struct TensorSpec {
    formula: Formula,
    program: Arc<Program>,
    columns: Vec<Column>,
    state_dim: usize,
}

impl TensorSpec {
    /// Starts binding `formula` for paths whose states have `state_dim` numbers.
    pub fn builder(formula: Formula, state_dim: usize) -> TensorSpecBuilder {
        TensorSpecBuilder {
            formula,
            until: UntilRule::default(),
            state_dim,
            signals: Vec::new(),
            bindings: HashMap::new(),
        }
    }

    /// The formula.
    pub fn formula(&self) -> &Formula {
        &self.formula
    }

    /// Predicate values `[batch, steps, predicates]` of `paths` `[batch, steps, state_dim]`.
    pub fn predicate_values(&self, paths: &Tensor) -> candle_core::Result<Tensor> {
        let (_, _, d) = paths.dims3()?;
        if d != self.state_dim {
            candle_core::bail!("paths have {d} numbers per state, the spec expects {}", self.state_dim);
        }
        let cols = self
            .columns
            .iter()
            .map(|c| match c {
                Column::Signal { index, sign, threshold } => {
                    paths.narrow(2, *index, 1)?.squeeze(2)?.affine(*sign, -sign * threshold)
                }
                Column::Predicate { pred, sign, threshold, shifted } => {
                    let v = pred.forward(paths)?;
                    if *shifted { v.affine(*sign, -sign * threshold) } else { Ok(v) }
                }
            })
            .collect::<candle_core::Result<Vec<_>>>()?;
        Tensor::stack(&cols, 2)
    }

    /// Robustness at step 0 of each path: `[batch, steps, state_dim]` → `[batch]`,
    /// differentiable with respect to `paths` and to neural predicate parameters.
    pub fn robustness(&self, paths: &Tensor, sem: &Semantics) -> candle_core::Result<Tensor> {
        self.robustness_at(paths, 0, sem)
    }

    /// Robustness at step `start` of each path.
    pub fn robustness_at(
        &self,
        paths: &Tensor,
        start: usize,
        sem: &Semantics,
    ) -> candle_core::Result<Tensor> {
        sem.validate().map_err(candle_core::Error::msg)?;
        let steps = paths.dims().get(1).copied().unwrap_or(0);
        if start >= steps {
            return Err(candle_core::Error::msg(format!(
                "start step {start} is past the paths' last step ({steps} steps)"
            )));
        }
        let values = self.predicate_values(paths)?.contiguous()?;
        values.apply_op1(RobustnessOp::new(self.program.clone(), *sem, start))
    }
}
