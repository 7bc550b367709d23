//! Which quantitative semantics a robustness evaluation uses.
//!
//! The paper (App. C) defines robustness with `min`/`max`; its authors' code also
//! offers a *soft* mode where both are replaced by a softmax-weighted mean
//! `Σ softmax(α·v)·v` (they used α = 2). We add the log-sum-exp smoothing with a
//! temperature τ (`max ≈ τ·log Σ exp(v/τ)`), common in the smooth-STL literature.
//! Smooth modes apply to `∧`, `∨`, `⇒` and, unless [`Semantics::logic_only`] is
//! asked for, also to the temporal operators. How a smooth `until` is relaxed is a
//! choice of its own ([`UntilSmoothing`]): the two relaxations agree in hard mode and
//! differ in cost and in how closely they follow it.

use std::fmt;
use std::str::FromStr;

/// How `min` and `max` are computed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Smoothing {
    /// Exact `min`/`max` (paper App. C). Gradients are exact subgradients: the
    /// selected child receives the whole gradient; ties go to the first child
    /// (lowest operand index, earliest time step).
    Hard,
    /// Softmax-weighted mean `Σ softmax(α·v)·v` for `max` and `Σ softmax(−α·v)·v` for
    /// `min` (the authors' soft STL, α = 2 in their code). Approaches hard as α → ∞.
    /// The result always lies between the true min and max.
    Soft {
        /// Sharpness α > 0.
        alpha: f64,
    },
    /// Log-sum-exp: `max ≈ τ·log Σ exp(v/τ)`, `min ≈ −τ·log Σ exp(−v/τ)`. An upper
    /// (lower) bound of the true max (min) by at most `τ·ln n`; approaches hard as
    /// τ → 0.
    LogSumExp {
        /// Temperature τ > 0.
        temperature: f64,
    },
}

/// How the smooth modes relax `φ U[a,b] ψ`, whose hard robustness is
/// `max_{k ∈ W} min(ψ_k, min_{j ∈ [lo, k−1]} φ_j)` over the window `W = [lo, hi]`.
/// In hard mode both are that value exactly (and share one O(T) evaluation).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum UntilSmoothing {
    /// Smooths the hard identity `min(max_{k∈W} ψ_k, V(lo))` with the recursion
    /// `V(u) = max(ψ_u, min(φ_u, V(u+1)))`, `V(T−1) = ψ_{T−1}`, one smooth pair at a
    /// time; an unbounded window is `V(lo)` alone (the outer `min` is exact there).
    /// O(T) whatever the window. Nesting compounds the smoothing: a value can sit up
    /// to one pair's smoothing error per step away from hard (LSE: `2·τ·ln 2` per
    /// step), where [`UntilSmoothing::Flat`] is one aggregate deep.
    #[default]
    Recursive,
    /// Smooths the definition as written: an inner smooth `min` per `k` and one outer
    /// smooth `max`. O(T·w) for a window of `w` steps, quadratic when the window is
    /// the whole path. The planner's training semantics (its defaults were tuned on
    /// it; its windows are at most 17 steps).
    Flat,
}

impl UntilSmoothing {
    /// The name used in semantics text (`until=flat`).
    pub fn name(self) -> &'static str {
        match self {
            UntilSmoothing::Recursive => "recursive",
            UntilSmoothing::Flat => "flat",
        }
    }
}

/// The complete choice of semantics for an evaluation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Semantics {
    /// How min/max are computed.
    pub smoothing: Smoothing,
    /// Whether the temporal operators (eventually, globally, until) are smoothed too.
    /// `false` smooths only the Boolean connectives, as the authors' code did.
    pub smooth_temporal: bool,
    /// How a smooth `until` is relaxed (irrelevant in hard mode).
    pub until: UntilSmoothing,
    /// The robustness `k > 0` of `true` (App. C); `false` is `−k`.
    pub top: f64,
}

/// Default robustness of `true`. Large enough to never be the binding operand
/// against metre-scale predicates, small enough to stay finite in `f32`.
pub const DEFAULT_TOP: f64 = 1.0e9;

impl Semantics {
    /// Exact min/max semantics.
    pub fn hard() -> Self {
        Self {
            smoothing: Smoothing::Hard,
            smooth_temporal: true,
            until: UntilSmoothing::Recursive,
            top: DEFAULT_TOP,
        }
    }

    /// The paper's soft semantics with sharpness `alpha` (authors used 2).
    pub fn soft(alpha: f64) -> Self {
        Self { smoothing: Smoothing::Soft { alpha }, ..Self::hard() }
    }

    /// Log-sum-exp semantics with the given temperature.
    pub fn lse(temperature: f64) -> Self {
        Self { smoothing: Smoothing::LogSumExp { temperature }, ..Self::hard() }
    }

    /// Smooth only `∧`, `∨`, `⇒`; temporal operators stay hard.
    pub fn logic_only(mut self) -> Self {
        self.smooth_temporal = false;
        self
    }

    /// Relaxes a smooth `until` by `until` (default [`UntilSmoothing::Recursive`]).
    pub fn with_until(mut self, until: UntilSmoothing) -> Self {
        self.until = until;
        self
    }

    /// Sets the robustness of `true`.
    pub fn with_top(mut self, top: f64) -> Self {
        self.top = top;
        self
    }

    /// Checks the parameters: α, τ and `top` must be finite and positive.
    pub fn validate(&self) -> Result<(), SemanticsError> {
        let bad = |what: &'static str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(SemanticsError::NotPositive { what, value: v })
            }
        };
        match self.smoothing {
            Smoothing::Hard => {}
            Smoothing::Soft { alpha } => bad("alpha", alpha)?,
            Smoothing::LogSumExp { temperature } => bad("temperature", temperature)?,
        }
        bad("top", self.top)
    }

    pub(crate) fn logic(&self) -> Smoothing {
        self.smoothing
    }

    pub(crate) fn temporal(&self) -> Smoothing {
        if self.smooth_temporal { self.smoothing } else { Smoothing::Hard }
    }
}

impl Default for Semantics {
    fn default() -> Self {
        Self::hard()
    }
}

/// A semantics string that could not be understood, or a bad parameter.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SemanticsError {
    /// The text is not one of the accepted forms.
    #[error(
        "unknown semantics '{0}': expected 'hard', 'soft:<alpha>' or 'lse:<temperature>', \
         the smooth ones optionally followed by ',until=recursive' or ',until=flat'"
    )]
    Unknown(String),
    /// An until relaxation was given to hard semantics, which has none.
    #[error("'{0}': hard semantics has no until relaxation to choose (drop ',until=…')")]
    UntilOnHard(String),
    /// A parameter is zero, negative, or not finite.
    #[error("{what} must be a finite number > 0, got {value}")]
    NotPositive {
        /// Which parameter.
        what: &'static str,
        /// Its value.
        value: f64,
    },
}

impl FromStr for Semantics {
    type Err = SemanticsError;

    /// Parses `hard`, `soft:<alpha>` or `lse:<temperature>`; a smooth one may add
    /// `,until=recursive` (the default) or `,until=flat`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let unknown = || SemanticsError::Unknown(s.to_string());
        let (t, until) = match s.trim().split_once(',') {
            None => (s.trim(), None),
            Some((mode, option)) => {
                let until = match option.trim().strip_prefix("until=").map(str::trim) {
                    Some("recursive") => UntilSmoothing::Recursive,
                    Some("flat") => UntilSmoothing::Flat,
                    _ => return Err(unknown()),
                };
                (mode.trim(), Some(until))
            }
        };
        let sem = if t == "hard" {
            if until.is_some() {
                return Err(SemanticsError::UntilOnHard(s.to_string()));
            }
            Self::hard()
        } else if let Some(rest) = t.strip_prefix("soft:") {
            Self::soft(rest.trim().parse().map_err(|_| unknown())?)
        } else if let Some(rest) = t.strip_prefix("lse:") {
            Self::lse(rest.trim().parse().map_err(|_| unknown())?)
        } else {
            return Err(unknown());
        };
        sem.validate()?;
        Ok(sem.with_until(until.unwrap_or_default()))
    }
}

impl fmt::Display for Semantics {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.smoothing {
            // Both relaxations are the hard value exactly: nothing to say.
            Smoothing::Hard => return write!(f, "hard"),
            Smoothing::Soft { alpha } => write!(f, "soft:{alpha}")?,
            Smoothing::LogSumExp { temperature } => write!(f, "lse:{temperature}")?,
        }
        match self.until {
            UntilSmoothing::Recursive => Ok(()),
            UntilSmoothing::Flat => write!(f, ",until=flat"),
        }
    }
}
