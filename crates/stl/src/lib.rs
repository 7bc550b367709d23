//! Differentiable Signal Temporal Logic.
//!
//! This crate turns a temporal-logic specification into a robustness score for a
//! path and the gradient of that score, as in *Constrained hierarchical deep RL with
//! differentiable formal specifications* (§2, App. C, App. D). It knows nothing of
//! robots or learning and can be used on its own for monitoring or for gradient-based
//! planning.
//!
//! * [`Formula`] — the syntax tree, with a builder API and every operator of the
//!   paper's grammar. [`parse`] reads the text syntax with located errors (grammar,
//!   precedence and associativity in [`syntax`]); `Display` prints it back.
//! * [`Spec`] — a formula whose names are bound to [`Predicate`]s or to state
//!   signals; computes `ρ(path)` at any start time and `∂ρ/∂path`.
//! * [`Semantics`] — hard `min`/`max` (exact subgradients), the paper's softmax-weighted
//!   soft mode, or log-sum-exp with a temperature; optionally smoothing only the
//!   Boolean connectives; a smooth `until` relaxed recursively in O(T) or as written.
//! * [`tensor`] (feature `candle`) — robustness of a batch of paths as one candle
//!   operation, differentiable into the paths and into neural predicates.
//!
//! Predicates and logic are kept apart: predicates map each state to a value, and a
//! compiled [`Program`] maps the `steps × predicates` matrix of values to the
//! robustness with an exact backward pass. Every temporal window is evaluated in
//! O(T), so long bounded windows are not quadratic.
//!
//! ```
//! use stl::{parse, Ball, Semantics, Spec};
//! let f = parse("F[1,2] a & G[1,2] !b").unwrap();
//! let spec = Spec::builder(f)
//!     .bind("a", Ball::new([1.0, 0.0], 0.5))
//!     .bind("b", Ball::new([0.0, 1.0], 0.3))
//!     .build()
//!     .unwrap();
//! let path = [0.0, 0.0, 0.9, 0.1, 1.0, 0.0]; // 3 states (x, y)
//! let rho = spec.robustness(&path, &Semantics::hard()).unwrap();
//! assert!((rho - 0.5).abs() < 1e-12);
//! ```

#![warn(missing_docs)]

mod aggregate;
pub mod formula;
pub mod predicate;
pub mod program;
pub mod semantics;
pub mod spec;
pub mod syntax;
#[cfg(feature = "candle")]
pub mod tensor;

pub use formula::{CmpOp, Formula, Interval};
pub use predicate::{AfterStep, AvoidBoxes, AxisBox, Ball, FnPredicate, Halfspace, Predicate};
pub use program::{Atom, Program, UntilRule, Workspace};
pub use semantics::{Semantics, SemanticsError, Smoothing, UntilSmoothing};
pub use spec::{EvalError, Evaluator, Spec, SpecBuilder, SpecError};
pub use syntax::{ParseError, is_valid_name, locate_name, parse};
