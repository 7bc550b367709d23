//! `schrl.stl` over the `stl` crate: a spec is parsed and bound once
//! ([`PySpec`]), then evaluated on NumPy arrays `[T, D]` (one path) or `[B, T, D]` (a
//! batch) in any semantics, with the GIL released while Rust computes. Paths are copied
//! into a contiguous buffer first (any dtype NumPy can cast to float64, any strides);
//! the copy is small next to the evaluation and lets other Python threads run.

use numpy::{IntoPyArray, PyArrayDyn, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::create_exception;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use stl::{AfterStep, AvoidBoxes, AxisBox, Ball, Halfspace, Semantics, Spec, UntilRule};

create_exception!(
    _schrl,
    SpecError,
    PyValueError,
    "A spec that does not parse or bind, or a path it cannot read."
);

/// A predicate a spec's names can be bound to.
#[derive(Clone, Debug)]
enum Predicate {
    Ball(Ball),
    Halfspace(Halfspace),
    AvoidBoxes(AvoidBoxes),
    AfterStep(AfterStep),
}

/// A goal ball: `radius − ‖x[offset:offset+d] − center‖`.
#[pyclass(name = "Ball", module = "schrl.stl", frozen)]
#[derive(Clone)]
pub struct PyBall(Ball);

#[pymethods]
impl PyBall {
    #[new]
    #[pyo3(signature = (center, radius, offset = 0))]
    fn new(center: Vec<f64>, radius: f64, offset: usize) -> PyResult<Self> {
        finite("center", &center)?;
        finite("radius", &[radius])?;
        if center.is_empty() {
            return Err(SpecError::new_err("Ball: center needs at least one coordinate"));
        }
        if radius <= 0.0 {
            return Err(SpecError::new_err(format!("Ball: radius must be > 0, got {radius}")));
        }
        Ok(Self(Ball { center, radius, offset }))
    }

    fn __repr__(&self) -> String {
        format!("Ball(center={:?}, radius={}, offset={})", self.0.center, self.0.radius, self.0.offset)
    }
}

/// A half-space `normal · x[:d] − bound ≥ 0`.
#[pyclass(name = "Halfspace", module = "schrl.stl", frozen)]
#[derive(Clone)]
pub struct PyHalfspace(Halfspace);

#[pymethods]
impl PyHalfspace {
    #[new]
    fn new(normal: Vec<f64>, bound: f64) -> PyResult<Self> {
        finite("normal", &normal)?;
        finite("bound", &[bound])?;
        if normal.is_empty() {
            return Err(SpecError::new_err("Halfspace: normal needs at least one coefficient"));
        }
        Ok(Self(Halfspace { normal, bound }))
    }

    fn __repr__(&self) -> String {
        format!("Halfspace(normal={:?}, bound={})", self.0.normal, self.0.bound)
    }
}

/// Staying out of axis-aligned boxes: the signed distance to the nearest box, minus
/// `margin`. Each box is `(center, half_sizes)`.
#[pyclass(name = "AvoidBoxes", module = "schrl.stl", frozen)]
#[derive(Clone)]
pub struct PyAvoidBoxes(AvoidBoxes);

#[pymethods]
impl PyAvoidBoxes {
    #[new]
    #[pyo3(signature = (boxes, margin = 0.0))]
    fn new(boxes: Vec<(Vec<f64>, Vec<f64>)>, margin: f64) -> PyResult<Self> {
        if boxes.is_empty() {
            return Err(SpecError::new_err("AvoidBoxes: give at least one (center, half_sizes) box"));
        }
        let mut out = Vec::with_capacity(boxes.len());
        for (i, (center, half)) in boxes.into_iter().enumerate() {
            finite(&format!("box {i} center"), &center)?;
            finite(&format!("box {i} half sizes"), &half)?;
            if center.len() != half.len() || center.is_empty() {
                return Err(SpecError::new_err(format!(
                    "AvoidBoxes: box {i} has a {}-dimensional center and {} half sizes; they must match",
                    center.len(),
                    half.len()
                )));
            }
            if half.iter().any(|h| *h < 0.0) {
                return Err(SpecError::new_err(format!("AvoidBoxes: box {i} has a negative half size")));
            }
            out.push(AxisBox { center, half });
        }
        let dims: Vec<usize> = out.iter().map(|b| b.center.len()).collect();
        if dims.iter().any(|d| *d != dims[0]) {
            return Err(SpecError::new_err("AvoidBoxes: every box must have the same dimension"));
        }
        finite("margin", &[margin])?;
        Ok(Self(AvoidBoxes::new(out, margin)))
    }

    fn __repr__(&self) -> String {
        format!("AvoidBoxes({} boxes, margin={})", self.0.boxes().len(), self.0.margin())
    }
}

/// A signal of time alone: `−truth` before step `step`, `+truth` from it on.
#[pyclass(name = "AfterStep", module = "schrl.stl", frozen)]
#[derive(Clone)]
pub struct PyAfterStep(AfterStep);

#[pymethods]
impl PyAfterStep {
    #[new]
    #[pyo3(signature = (step, truth = 1.0))]
    fn new(step: usize, truth: f64) -> PyResult<Self> {
        if !(truth.is_finite() && truth > 0.0) {
            return Err(SpecError::new_err(format!("AfterStep: truth must be finite and > 0, got {truth}")));
        }
        Ok(Self(AfterStep { step, truth }))
    }

    fn __repr__(&self) -> String {
        format!("AfterStep(step={}, truth={})", self.0.step, self.0.truth)
    }
}

fn finite(what: &str, xs: &[f64]) -> PyResult<()> {
    match xs.iter().position(|x| !x.is_finite()) {
        Some(i) => Err(SpecError::new_err(format!("{what}: entry {i} is {}, not a finite number", xs[i]))),
        None => Ok(()),
    }
}

fn predicate(name: &str, value: &Bound<'_, PyAny>) -> PyResult<Predicate> {
    if let Ok(p) = value.downcast::<PyBall>() {
        return Ok(Predicate::Ball(p.get().0.clone()));
    }
    if let Ok(p) = value.downcast::<PyHalfspace>() {
        return Ok(Predicate::Halfspace(p.get().0.clone()));
    }
    if let Ok(p) = value.downcast::<PyAvoidBoxes>() {
        return Ok(Predicate::AvoidBoxes(p.get().0.clone()));
    }
    if let Ok(p) = value.downcast::<PyAfterStep>() {
        return Ok(Predicate::AfterStep(p.get().0));
    }
    Err(SpecError::new_err(format!(
        "predicates['{name}']: expected a schrl.stl Ball, Halfspace, AvoidBoxes or AfterStep, got {}",
        value.get_type().name()?
    )))
}

/// A spec bound to its signals and predicates.
#[pyclass(name = "Spec", module = "schrl.stl", frozen)]
pub struct PySpec {
    spec: Spec,
    text: String,
}

/// A path or batch copied out of NumPy: its numbers, and `(batch, steps, dim)` with
/// `batch = None` for a single `[T, D]` path.
struct Paths {
    data: Vec<f64>,
    batch: Option<usize>,
    steps: usize,
    dim: usize,
}

impl Paths {
    /// One value per path as Python sees it: a float for a single path, an array for a
    /// batch.
    fn values(&self, py: Python<'_>, values: Vec<f64>) -> PyResult<PyObject> {
        Ok(match self.batch {
            None => values[0].into_pyobject(py)?.into_any().unbind(),
            Some(_) => values.into_pyarray(py).into_any().unbind(),
        })
    }
}

fn semantics(text: &str) -> PyResult<Semantics> {
    text.parse::<Semantics>().map_err(|e| SpecError::new_err(format!("semantics '{text}': {e}")))
}

#[pymethods]
impl PySpec {
    /// Parses `text` and binds its names: `signals` name the path's columns in order
    /// (a formula may compare them, `x > 0.5`), `predicates` bind the other names.
    /// `until`: "standard" (φ holds from t, as rtamt) or "paper" (App. C).
    #[new]
    #[pyo3(signature = (text, signals = None, predicates = None, until = "standard"))]
    fn new(
        text: &str,
        signals: Option<Vec<String>>,
        predicates: Option<&Bound<'_, PyDict>>,
        until: &str,
    ) -> PyResult<Self> {
        let formula = stl::parse(text).map_err(|e| SpecError::new_err(format!("spec: {e}")))?;
        let rule = match until {
            "standard" => UntilRule::Standard,
            "paper" => UntilRule::Paper,
            other => {
                return Err(SpecError::new_err(format!(
                    "until: '{other}' is neither 'standard' nor 'paper'"
                )));
            }
        };
        let mut builder = Spec::builder(formula).until(rule);
        if let Some(signals) = signals {
            builder = builder.signals(signals);
        }
        if let Some(predicates) = predicates {
            for (name, value) in predicates.iter() {
                let name: String =
                    name.extract().map_err(|_| SpecError::new_err("predicates: keys must be names (str)"))?;
                builder = match predicate(&name, &value)? {
                    Predicate::Ball(p) => builder.bind(name, p),
                    Predicate::Halfspace(p) => builder.bind(name, p),
                    Predicate::AvoidBoxes(p) => builder.bind(name, p),
                    Predicate::AfterStep(p) => builder.bind(name, p),
                };
            }
        }
        let spec = builder.build().map_err(|e| SpecError::new_err(format!("spec: {e}")))?;
        Ok(Self { spec, text: text.to_string() })
    }

    /// The state dimension D a path's rows must have.
    #[getter]
    fn state_dim(&self) -> usize {
        self.spec.state_dim()
    }

    /// The formula as the printer writes it.
    fn __repr__(&self) -> String {
        format!("Spec({:?})", self.spec.formula().to_string())
    }

    /// The text the spec was made from.
    #[getter]
    fn text(&self) -> &str {
        &self.text
    }

    /// ρ at step 0 of a path `[T, D]` (a float), or of each path of a batch
    /// `[B, T, D]` (an array of B floats). `semantics`: "hard", "soft:<α>" or
    /// "lse:<τ>", a smooth one optionally with ",until=flat|recursive".
    #[pyo3(signature = (paths, semantics = "hard"))]
    fn robustness<'py>(
        &self,
        py: Python<'py>,
        paths: &Bound<'py, PyAny>,
        semantics: &str,
    ) -> PyResult<PyObject> {
        let sem = self::semantics(semantics)?;
        let p = self.paths(paths)?;
        let spec = &self.spec;
        let out = py.allow_threads(|| spec.robustness_batch(&p.data, p.steps, &sem)).map_err(eval_error)?;
        p.values(py, out)
    }

    /// `(ρ, ∂ρ/∂paths)`: ρ as `robustness` returns it, and the gradient with the
    /// paths' shape (float64).
    #[pyo3(signature = (paths, semantics = "hard"))]
    fn gradient<'py>(
        &self,
        py: Python<'py>,
        paths: &Bound<'py, PyAny>,
        semantics: &str,
    ) -> PyResult<(PyObject, Bound<'py, PyArrayDyn<f64>>)> {
        let sem = self::semantics(semantics)?;
        let p = self.paths(paths)?;
        let spec = &self.spec;
        let mut grads = vec![0.0; p.data.len()];
        let rho = py
            .allow_threads(|| spec.gradient_batch(&p.data, p.steps, &sem, &mut grads))
            .map_err(eval_error)?;
        let shape: Vec<usize> = match p.batch {
            None => vec![p.steps, p.dim],
            Some(b) => vec![b, p.steps, p.dim],
        };
        let grads = grads.into_pyarray(py).reshape(shape)?;
        Ok((p.values(py, rho)?, grads))
    }
}

impl PySpec {
    /// Reads `[T, D]` or `[B, T, D]` as float64, checking the shape against the spec.
    fn paths(&self, obj: &Bound<'_, PyAny>) -> PyResult<Paths> {
        let np = obj.py().import("numpy")?;
        let array = np.call_method1("ascontiguousarray", (obj, "float64"))?;
        let array = array
            .downcast::<PyArrayDyn<f64>>()
            .map_err(|_| SpecError::new_err("paths: expected a numeric array"))?;
        let shape = array.shape().to_vec();
        let dim = self.spec.state_dim();
        let (batch, steps, d) = match shape[..] {
            [t, d] => (None, t, d),
            [b, t, d] => (Some(b), t, d),
            _ => {
                return Err(SpecError::new_err(format!(
                    "paths: expected [T, D] or [B, T, D] with D = {dim}, got shape {shape:?}"
                )));
            }
        };
        if d != dim {
            return Err(SpecError::new_err(format!(
                "paths: each state has {d} numbers, the spec reads {dim} (shape {shape:?})"
            )));
        }
        if steps == 0 || batch == Some(0) {
            return Err(SpecError::new_err(format!("paths: empty (shape {shape:?})")));
        }
        let data = array.readonly().as_slice()?.to_vec();
        if let Some(i) = data.iter().position(|x| x.is_nan()) {
            return Err(SpecError::new_err(format!("paths: NaN at flat index {i}")));
        }
        Ok(Paths { data, batch, steps, dim: d })
    }
}

fn eval_error(e: stl::EvalError) -> PyErr {
    SpecError::new_err(e.to_string())
}

/// Adds the STL classes to `m`.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("SpecError", m.py().get_type::<SpecError>())?;
    m.add_class::<PySpec>()?;
    m.add_class::<PyBall>()?;
    m.add_class::<PyHalfspace>()?;
    m.add_class::<PyAvoidBoxes>()?;
    m.add_class::<PyAfterStep>()?;
    Ok(())
}
