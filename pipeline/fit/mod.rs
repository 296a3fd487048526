//! Continuous-time transfer-function fitting to measured frequency-response
//! bins: H(jw) = N(jw)/D(jw) exp(-jw tau) Z(jw) A(jw), with D monic, Z the
//! command's sample-and-hold, A the aliases the sampling folds onto each
//! bin and tau none, fixed or fitted. For the paper's procedure the model is
//! x1/u = n0/(s^2 + d1 s + d0) (Eqs. 11-14), whose coefficients and
//! covariance feed Eqs. 18-20 (`identify`).
//!
//! Procedure: frequency scaled by w0 ([`Scaling`]); Levy and
//! Sanathanan-Koerner ([`linear`]), over a grid of delays for a fitted one;
//! Levenberg-Marquardt ([`LevenbergMarquardt`]) with an analytic Jacobian
//! ([`FrfProblem`]); the covariance at the optimum ([`covariance`]). A
//! ([`alias_factor`]) is taken at the fit's own estimate until it would move
//! no parameter by [`ALIAS_SETTLED`] of its std, or left out where its whole
//! effect is below that; [`TfFit::as_logged`] is the model as the fit
//! compared it. The derivation: docs/methods.md, "The per-run fit".

pub mod adequacy;
pub mod band;
pub mod delay_significance;
pub mod linear;
pub mod lm;
pub mod problem;
mod settings;
pub mod transient;

#[cfg(test)]
mod tests;

use crate::warning::Warning;
use argmin::core::{Executor, State, TerminationReason};
use nalgebra::{Complex, DMatrix, DVector};

use crate::lti::{LtiError, TransferFunction};

pub use linear::{RankDeficient, levy, sanathanan_koerner};
pub use lm::LevenbergMarquardt;
pub use problem::{FrfProblem, ModelShape, Scaling, alias_factor, hold_response, sampled_response};

pub use settings::{DelayPlan, Intersample};

/// The bins to fit: already restricted to the band and to coherent bins.
#[derive(Debug, Clone, Copy)]
pub struct FitInput<'a> {
    /// Bin frequencies (Hz), positive.
    pub freq_hz: &'a [f64],
    /// Measured response at those bins.
    pub h: &'a [Complex<f64>],
    /// Variance of each complex h, E|h - E h|^2; the weights are 1/variance.
    pub variance: &'a [f64],
}

/// What to fit and how.
#[derive(Debug, Clone, PartialEq)]
pub struct FitOptions {
    /// Degree of N (numerator_order + 1 free coefficients).
    pub numerator_order: usize,
    /// Degree of the monic D (at least 1, at least `numerator_order`).
    pub denominator_order: usize,
    /// Intersample behaviour of the command.
    pub intersample: Intersample,
    /// Sample rate of the command (Hz); used by the hold.
    pub sample_rate_hz: f64,
    /// Pure delay: none, known, or fitted within a bound.
    pub delay: DelayPlan,
    /// Levenberg-Marquardt iterations allowed (at least 1).
    pub max_iterations: u64,
    /// Sanathanan-Koerner re-weightings after Levy's solve.
    pub sk_iterations: usize,
    /// The lag in bins from which the FRF's bins are independent
    /// (`frf::FrfPlan::independent_lag`): above 1, bins closer than that
    /// share data and the covariance is [`correlated_covariance`]'s.
    pub independent_lag: usize,
}

/// The Levenberg-Marquardt iteration limit of every fit `servoid run` makes
/// (a run's transfer function, the joint fit's legs, the Monte Carlo's
/// draws): decided here once. These problems converge in tens of
/// iterations from the linear start; 200 leaves room for a poor one, and a
/// fit that still has not converged is refused, not used.
pub const RUN_MAX_ITERATIONS: u64 = 200;

impl FitOptions {
    /// Options with a sample-and-hold command, no delay, 100 iterations and
    /// 10 SK re-weightings.
    pub fn new(numerator_order: usize, denominator_order: usize, sample_rate_hz: f64) -> Self {
        Self {
            numerator_order,
            denominator_order,
            intersample: Intersample::SampleAndHold,
            sample_rate_hz,
            delay: DelayPlan::None,
            max_iterations: 100,
            sk_iterations: 10,
            independent_lag: 1,
        }
    }
}

/// A fitted transfer function with its uncertainty and diagnostics.
#[derive(Debug, Clone)]
pub struct TfFit {
    /// The plant n(s)/d(s) with `den[0] == 1` and `delay_s` = tau (fixed or
    /// fitted); the hold is not part of it.
    pub tf: TransferFunction,
    /// Orders and whether the delay was fitted.
    pub shape: ModelShape,
    /// Numerator coefficients (highest power first), the denominator's after
    /// its leading 1, then tau (s) if fitted.
    pub params: Vec<f64>,
    /// Names of `params`: n_m .. n0, d_{n-1} .. d0, tau_s.
    pub param_names: Vec<String>,
    /// Covariance of `params`, (J^T W J)^-1 scaled by `reduced_chi2`.
    pub covariance: DMatrix<f64>,
    /// sqrt(diag(covariance)).
    pub std: Vec<f64>,
    /// 100 (1 - ||h - h_model|| / ||h - mean(h)||) over the complex bins,
    /// unweighted, h_model including hold and delay (MATLAB tfest's
    /// FitPercent). 100 is a perfect fit; it can be negative.
    pub fit_percent: f64,
    /// chi2 / (2N - p): sum of |h - h_model|^2 / (variance / 2) over the
    /// 2N real and imaginary parts, per degree of freedom; about 1 when the
    /// model is right and the variances are honest.
    pub reduced_chi2: f64,
    /// Levenberg-Marquardt iterations.
    pub iterations: u64,
    /// argmin's termination reason, verbatim.
    pub termination: String,
    /// Whether the solver reported convergence.
    pub converged: bool,
    /// Whether every pole is in the open left half-plane.
    pub stable: bool,
    /// Number of bins fitted.
    pub n_bins: usize,
    /// What the caller should know (not converged, unstable, delay at bound).
    pub warnings: Vec<Warning>,
    /// The record's transient fitted beside the model
    /// ([`fit_with_transient`]); None for a plain fit.
    pub transient: Option<transient::Transient>,
    /// Whether the model held the hold's aliases ([`ALIAS_SETTLED`]): its
    /// response as the log shows it is then [`sampled_response`], else the
    /// hold's continuous factor alone ([`TfFit::as_logged`]).
    pub aliases: bool,
}

impl TfFit {
    /// The model as the fit compared it with the log at `freq_hz`: the plant
    /// (its delay included) times the hold's continuous factor, and its
    /// aliases where the fit modelled them.
    pub fn as_logged(
        &self,
        intersample: Intersample,
        sample_rate_hz: f64,
        freq_hz: &[f64],
    ) -> Vec<Complex<f64>> {
        if self.aliases {
            sampled_response(intersample, sample_rate_hz, &self.tf, freq_hz)
        } else {
            freq_hz
                .iter()
                .map(|&f| self.tf.freq_response(f) * hold_response(intersample, sample_rate_hz, f))
                .collect()
        }
    }

    /// Covariance of (n0, d1, d0) for a 0/2 model, in that order (the input
    /// of `identify`). With a fitted delay this is the marginal covariance,
    /// which accounts for the delay's correlation with the coefficients.
    /// `None` for other orders.
    pub fn second_order_cov(&self) -> Option<[[f64; 3]; 3]> {
        if self.shape.numerator_order != 0 || self.shape.denominator_order != 2 {
            return None;
        }
        let mut out = [[0.0; 3]; 3];
        for (i, row) in out.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = self.covariance[(i, j)];
            }
        }
        Some(out)
    }
}

/// Why a fit could not be made.
#[derive(Debug, thiserror::Error)]
pub enum FitError {
    #[error("invalid fit option {option}: {reason}")]
    InvalidOption {
        option: &'static str,
        reason: String,
    },
    #[error("input lengths differ: {freq} frequencies, {h} responses, {variance} variances")]
    LengthMismatch {
        freq: usize,
        h: usize,
        variance: usize,
    },
    #[error("{field}[{index}] is not finite ({value})")]
    NonFinite {
        field: &'static str,
        index: usize,
        value: InputValue,
    },
    #[error("freq_hz[{index}] must be positive (got {value} Hz)")]
    NonPositiveFrequency { index: usize, value: f64 },
    #[error("variance[{index}] must be positive (got {value})")]
    NonPositiveVariance { index: usize, value: f64 },
    #[error(
        "freq_hz[{index}] = {value} Hz is above the Nyquist frequency {nyquist_hz} Hz of the command's sample-and-hold"
    )]
    AboveNyquist {
        index: usize,
        value: f64,
        nyquist_hz: f64,
    },
    #[error(
        "{bins} bins give {equations} real equations, which does not exceed the {params} parameters ({names}); at least {needed} bins are needed"
    )]
    TooFewBins {
        bins: usize,
        equations: usize,
        params: usize,
        names: String,
        needed: usize,
    },
    #[error(
        "parameter {parameter} is not identifiable from these {bins} bins: the {matrix} is singular (smallest/largest singular value {ratio:.1e} after column scaling)"
    )]
    NotIdentifiable {
        parameter: String,
        bins: usize,
        matrix: &'static str,
        ratio: f64,
    },
    #[error("the optimiser failed: {0}")]
    Solver(#[from] SolverError),
    #[error("the optimiser failed: argmin returned no parameters")]
    NoSolution,
    #[error("the fitted model is not a valid transfer function: {0}")]
    Model(#[from] LtiError),
}

/// An input value as an error reports it: a frequency or variance is real,
/// a response complex, and each prints as its own type does.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum InputValue {
    Real(f64),
    Complex(Complex<f64>),
}

impl std::fmt::Display for InputValue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            InputValue::Real(v) => std::fmt::Display::fmt(v, f),
            InputValue::Complex(z) => std::fmt::Display::fmt(z, f),
        }
    }
}

/// An error from argmin. Its `Error` is an `anyhow::Error`, which does not
/// implement `std::error::Error` itself; this wrapper does, and keeps the
/// original as the source.
#[derive(Debug)]
pub struct SolverError(argmin::core::Error);

impl std::fmt::Display for SolverError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.0.fmt(f)
    }
}

impl std::error::Error for SolverError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        self.0.source()
    }
}

impl From<argmin::core::Error> for FitError {
    fn from(e: argmin::core::Error) -> Self {
        FitError::Solver(SolverError(e))
    }
}

/// Everything the fit needs, checked.
struct Prepared {
    problem: FrfProblem,
    /// The bins' frequencies (Hz).
    freq_hz: Vec<f64>,
    /// The hold's continuous factor and any fixed delay at each bin: the
    /// known factor without the aliases.
    held: Vec<Complex<f64>>,
    /// Whether the known factors hold the aliases ([`Prepared::follow_aliases`]).
    aliased: bool,
    scaling: Scaling,
    names: Vec<String>,
    fixed_delay_s: f64,
    max_delay_s: Option<f64>,
    /// The command's DFT at the bins, for a fit with the transient.
    transient: Option<TransientData>,
}

/// What a fit with the transient knows besides the bins: the command's DFT
/// at each (any common scale: the coefficients absorb it).
struct TransientData {
    u: Vec<Complex<f64>>,
}

impl TransientData {
    /// The projector of the columns for the model at `theta` (scaled).
    fn projector(&self, prep: &Prepared, theta: &[f64]) -> Option<transient::Projector> {
        let problem = &prep.problem;
        transient::Projector::new(transient::weighted_columns(
            &problem.s,
            &self.u,
            &problem.weight,
            den_of(&problem.shape, theta),
            delay_of(prep, theta),
        ))
    }

    /// The transient the columns of `q` hold at the optimum `theta`.
    fn found(
        &self,
        prep: &Prepared,
        q: &transient::Projector,
        theta: &[f64],
    ) -> transient::Transient {
        let problem = &prep.problem;
        // The residuals before the projection, data less model, weighted
        // as the columns are: their coefficients are the unweighted
        // columns'.
        let plain = FrfProblem {
            projector: None,
            last: Default::default(),
            ..problem.clone()
        };
        let w0 = prep.scaling.w0_rad_per_s;
        transient::Transient {
            w0_rad_per_s: w0,
            den: den_of(&problem.shape, theta).to_vec(),
            delay_s: delay_of(prep, theta) / w0,
            coefficients: q
                .coefficients(&plain.residuals(theta))
                .iter()
                .copied()
                .collect(),
        }
    }
}

/// The monic denominator's coefficients (after the leading 1) in `theta`.
fn den_of<'a>(shape: &ModelShape, theta: &'a [f64]) -> &'a [f64] {
    &theta[shape.numerator_order + 1..shape.n_rational()]
}

/// The model's whole delay in units of 1/w0: the fitted one in `theta`
/// and the fixed one (which the known factor holds with the hold; the
/// transient passes the delay but not the hold).
fn delay_of(prep: &Prepared, theta: &[f64]) -> f64 {
    let fitted = if prep.problem.shape.fit_delay {
        theta[prep.problem.shape.n_rational()]
    } else {
        0.0
    };
    fitted + prep.fixed_delay_s * prep.scaling.w0_rad_per_s
}

fn check_options(opts: &FitOptions) -> Result<(), FitError> {
    let bad = |option, reason: String| Err(FitError::InvalidOption { option, reason });
    if opts.denominator_order == 0 {
        return bad("denominator_order", "must be at least 1 (got 0)".into());
    }
    if opts.numerator_order > opts.denominator_order {
        return bad(
            "numerator_order",
            format!(
                "must not exceed denominator_order (got {} > {})",
                opts.numerator_order, opts.denominator_order
            ),
        );
    }
    if opts.intersample == Intersample::SampleAndHold
        && !(opts.sample_rate_hz.is_finite() && opts.sample_rate_hz > 0.0)
    {
        return bad(
            "sample_rate_hz",
            format!(
                "must be positive for a sample-and-hold command (got {} Hz)",
                opts.sample_rate_hz
            ),
        );
    }
    if opts.max_iterations == 0 {
        return bad("max_iterations", "must be at least 1 (got 0)".into());
    }
    match opts.delay {
        DelayPlan::None => {}
        DelayPlan::Fixed { delay_s } => {
            if !(delay_s.is_finite() && delay_s >= 0.0) {
                return bad(
                    "delay",
                    format!("a fixed delay must be finite and non-negative (got {delay_s} s)"),
                );
            }
        }
        DelayPlan::Fit { max_s } => {
            if !(max_s.is_finite() && max_s > 0.0) {
                return bad(
                    "delay",
                    format!("the bound on a fitted delay must be positive (got {max_s} s)"),
                );
            }
        }
    }
    Ok(())
}

fn check_input(input: &FitInput, opts: &FitOptions, shape: &ModelShape) -> Result<(), FitError> {
    let (nf, nh, nv) = (input.freq_hz.len(), input.h.len(), input.variance.len());
    if nf != nh || nf != nv {
        return Err(FitError::LengthMismatch {
            freq: nf,
            h: nh,
            variance: nv,
        });
    }
    for (index, &f) in input.freq_hz.iter().enumerate() {
        if !f.is_finite() {
            return Err(FitError::NonFinite {
                field: "freq_hz",
                index,
                value: InputValue::Real(f),
            });
        }
        if f <= 0.0 {
            return Err(FitError::NonPositiveFrequency { index, value: f });
        }
        if opts.intersample == Intersample::SampleAndHold && f > 0.5 * opts.sample_rate_hz {
            return Err(FitError::AboveNyquist {
                index,
                value: f,
                nyquist_hz: 0.5 * opts.sample_rate_hz,
            });
        }
    }
    if let Some((index, h)) = input
        .h
        .iter()
        .enumerate()
        .find(|(_, h)| !(h.re.is_finite() && h.im.is_finite()))
    {
        return Err(FitError::NonFinite {
            field: "h",
            index,
            value: InputValue::Complex(*h),
        });
    }
    for (index, &v) in input.variance.iter().enumerate() {
        if !v.is_finite() {
            return Err(FitError::NonFinite {
                field: "variance",
                index,
                value: InputValue::Real(v),
            });
        }
        if v <= 0.0 {
            return Err(FitError::NonPositiveVariance { index, value: v });
        }
    }
    let p = shape.n_params();
    if 2 * nf <= p {
        return Err(FitError::TooFewBins {
            bins: nf,
            equations: 2 * nf,
            params: p,
            names: shape.names().join(", "),
            needed: p / 2 + 1,
        });
    }
    Ok(())
}

fn prepare(input: &FitInput, opts: &FitOptions) -> Result<Prepared, FitError> {
    check_options(opts)?;
    let shape = ModelShape {
        numerator_order: opts.numerator_order,
        denominator_order: opts.denominator_order,
        fit_delay: matches!(opts.delay, DelayPlan::Fit { .. }),
    };
    check_input(input, opts, &shape)?;
    let (fixed_delay_s, max_delay_s) = match opts.delay {
        DelayPlan::None => (0.0, None),
        DelayPlan::Fixed { delay_s } => (delay_s, None),
        DelayPlan::Fit { max_s } => (0.0, Some(max_s)),
    };
    let scaling = Scaling::for_band(input.freq_hz);
    let held: Vec<Complex<f64>> = input
        .freq_hz
        .iter()
        .map(|&f| {
            let z = hold_response(opts.intersample, opts.sample_rate_hz, f);
            if fixed_delay_s == 0.0 {
                return z;
            }
            let phase = -2.0 * std::f64::consts::PI * f * fixed_delay_s;
            z * Complex::from_polar(1.0, phase)
        })
        .collect();
    let problem = FrfProblem {
        shape,
        s: input.freq_hz.iter().map(|&f| scaling.s(f)).collect(),
        h: input.h.to_vec(),
        known: held.clone(),
        weight: input.variance.iter().map(|v| (2.0 / v).sqrt()).collect(),
        projector: None,
        last: Default::default(),
    };
    Ok(Prepared {
        names: shape.names(),
        problem,
        freq_hz: input.freq_hz.to_vec(),
        held,
        aliased: false,
        scaling,
        fixed_delay_s,
        max_delay_s,
        transient: None,
    })
}

fn not_identifiable(p: &Prepared, e: RankDeficient, matrix: &'static str) -> FitError {
    FitError::NotIdentifiable {
        parameter: p.names[e.column].clone(),
        bins: p.problem.n_bins(),
        matrix,
        ratio: e.ratio,
    }
}

/// Fits `input` with the procedure of the module documentation.
pub fn fit(input: &FitInput, opts: &FitOptions) -> Result<TfFit, FitError> {
    let mut prep = prepare(input, opts)?;
    let start = match prep.max_delay_s {
        Some(max_s) => linear::delay_grid_start(
            &prep.problem,
            max_s * prep.scaling.w0_rad_per_s,
            opts.sk_iterations,
        ),
        None => linear::linear_start(&prep.problem, 0.0, opts.sk_iterations).map(|r| r.theta),
    }
    .map_err(|e| not_identifiable(&prep, e, "Levy least-squares matrix"))?;
    refine_held(&mut prep, opts, start)
}

/// As [`fit`] but skips the linear steps and starts the nonlinear refinement
/// from `start`, physical parameters laid out as [`TfFit::params`].
pub fn fit_from(input: &FitInput, opts: &FitOptions, start: &[f64]) -> Result<TfFit, FitError> {
    let mut prep = prepare(input, opts)?;
    check_param_count(&prep, "start", start)?;
    if let Some((i, v)) = start.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(FitError::InvalidOption {
            option: "start",
            reason: format!("{} is not finite ({v})", prep.names[i]),
        });
    }
    let scaled = prep.scaling.to_scaled(&prep.problem.shape, start);
    refine_held(&mut prep, opts, scaled)
}

/// The most passes [`fit_with_transient`] makes, each with the transient's
/// columns rebuilt from the last pass's denominator; they stop sooner when
/// no parameter moved by [`TRANSIENT_SETTLED`] of its std.
const TRANSIENT_PASSES: usize = 8;
const TRANSIENT_SETTLED: f64 = 1e-3;

/// As [`fit`] (or from `start`, physical parameters laid out as
/// [`TfFit::params`]), with the record's transient fitted beside the model
/// ([`transient`]): `u` is the command's DFT at each bin of `input`, on any
/// common scale. The covariance is the model's marginal one.
pub fn fit_with_transient(
    input: &FitInput,
    u: &[Complex<f64>],
    opts: &FitOptions,
    start: Option<&[f64]>,
) -> Result<TfFit, FitError> {
    let mut prep = prepare(input, opts)?;
    if u.len() != input.freq_hz.len() {
        return Err(FitError::InvalidOption {
            option: "u",
            reason: format!(
                "needs the command's DFT at each of the {} bins, got {}",
                input.freq_hz.len(),
                u.len()
            ),
        });
    }
    if let Some((index, v)) = u
        .iter()
        .enumerate()
        .find(|(_, v)| !(v.re.is_finite() && v.im.is_finite()))
    {
        return Err(FitError::NonFinite {
            field: "u",
            index,
            value: InputValue::Complex(*v),
        });
    }
    let shape = prep.problem.shape;
    let first = match start {
        Some(start) => {
            check_param_count(&prep, "start", start)?;
            start.to_vec()
        }
        // The plain fit's optimum is the first pass's start and
        // denominator.
        None => fit(input, opts)?.params,
    };
    let mut theta = prep.scaling.to_scaled(&shape, &first);
    prep.transient = Some(TransientData { u: u.to_vec() });
    let mut last = None;
    let mut scale = 1.0;
    for _ in 0..TRANSIENT_PASSES {
        // The aliases at this pass's start, as the projector: a pass that
        // moves no parameter leaves both where they were.
        prep.follow_aliases(opts, &theta, scale);
        let data = prep.transient.as_ref().expect("set above");
        let q = data
            .projector(&prep, &theta)
            .ok_or_else(|| FitError::InvalidOption {
                option: "u",
                reason: "the command's DFT is zero at every bin".into(),
            })?;
        prep.problem.projector = Some(std::sync::Arc::new(q));
        let f = refine(&prep, opts, theta.clone())?;
        scale = f.reduced_chi2.sqrt();
        let next = prep.scaling.to_scaled(&shape, &f.params);
        let factors = prep.scaling.factors(&shape);
        let moved = (0..next.len())
            .map(|k| ((next[k] - theta[k]) * factors[k]).abs() / f.std[k])
            .fold(0.0, f64::max);
        theta = next;
        last = Some(f);
        if moved < TRANSIENT_SETTLED {
            break;
        }
    }
    Ok(last.expect("at least one pass"))
}

/// Covariance of least-squares parameters, (J^T J)^-1 * `scale`, for the
/// Jacobian J of weighted residuals (so J^T J = J_u^T W J_u).
///
/// Computed from the SVD of J with unit-norm columns, taken through its QR
/// factor R (the normal equations would square its condition number).
/// `fit` passes the reduced chi-square as `scale`: the weights 1/variance
/// then need to be right only up to a common factor, and when the model
/// cannot reproduce the data (chi2 per degree of freedom above 1) the
/// uncertainty grows with the misfit instead of claiming a precision the
/// residuals contradict.
pub fn covariance(jac: &DMatrix<f64>, scale: f64) -> Result<DMatrix<f64>, RankDeficient> {
    let factors = linear::ScaledFactors::of(jac.clone())?;
    Ok(assembled(&factors.norms, &factors.svd, scale))
}

/// As [`covariance`], from J given as row blocks (`blocks` hands its
/// argument each block in turn, the same blocks on every call), holding a
/// block and a p x p triangle, never J: the columns' norms from a first
/// pass, then the scaled J's R from a Householder QR of the triangle so far
/// stacked on each block. R is unique up to the signs of its rows, which
/// the covariance does not see; its bits are not [`covariance`]'s.
pub fn covariance_streamed(
    p: usize,
    blocks: impl Fn(&mut dyn FnMut(DMatrix<f64>)),
    scale: f64,
) -> Result<DMatrix<f64>, RankDeficient> {
    let mut squares = vec![0.0; p];
    let mut rows = 0;
    blocks(&mut |b| {
        rows += b.nrows();
        for (s, c) in squares.iter_mut().zip(b.column_iter()) {
            *s += c.norm_squared();
        }
    });
    let norms: Vec<f64> = squares.iter().map(|s| s.sqrt()).collect();
    if let Some(column) = norms.iter().position(|&n| n == 0.0 || !n.is_finite()) {
        return Err(RankDeficient { column, ratio: 0.0 });
    }
    if rows < p {
        return Err(RankDeficient {
            column: p - 1,
            ratio: 0.0,
        });
    }
    let mut r = DMatrix::<f64>::zeros(0, p);
    blocks(&mut |b| {
        let above = r.nrows();
        let stacked = DMatrix::from_fn(above + b.nrows(), p, |i, j| match i < above {
            true => r[(i, j)],
            false => b[(i - above, j)] / norms[j],
        });
        r = stacked.qr().r();
    });
    let svd = linear::rank_checked(r)?;
    Ok(assembled(&norms, &svd, scale))
}

/// The covariance from the scaled J's SVD and the columns' norms.
fn assembled(
    norms: &[f64],
    svd: &nalgebra::SVD<f64, nalgebra::Dyn, nalgebra::Dyn>,
    scale: f64,
) -> DMatrix<f64> {
    let v_t = svd.v_t.as_ref().expect("V^T was requested");
    let p = norms.len();
    let mut cov = DMatrix::zeros(p, p);
    for k in 0..p {
        let inv_s2 = 1.0 / (svd.singular_values[k] * svd.singular_values[k]);
        for i in 0..p {
            for j in 0..p {
                cov[(i, j)] += v_t[(k, i)] * v_t[(k, j)] * inv_s2;
            }
        }
    }
    for i in 0..p {
        for j in 0..p {
            cov[(i, j)] *= scale / (norms[i] * norms[j]);
        }
    }
    cov
}

/// The covariance of a weighted least-squares estimate whose bins' errors
/// correlate with their near neighbours: the sandwich A^-1 Omega A^-1 of
/// Newey & West (1987, Econometrica 55(3), 703-708) with A = J^T J and
/// Omega the long-run variance of the bins' scores J_i^T r_i.
///
/// Why: an FRF estimator whose bins share data (a window's spectral kernel,
/// or the local polynomial method's transient, taken from 2R + 1 bins
/// around each) makes each bin's noise correlate with the bins within
/// `reach` of it. Weighing them as independent, (J^T J)^-1 chi2/dof, states
/// a std too small where the correlation is positive (the LPM's: some 13 %
/// on records not at rest). The correlation's range is known, so Omega sums
/// the scores' cross products over exactly that range (a truncated kernel,
/// unbiased); should that sum not be positive definite, Bartlett's weights
/// 1 - d / (reach + 1), which always are (Newey & West's point).
///
/// `scores` has a row per bin, `position` each bin's group (a run's FRF)
/// and place in bins along it, ascending within a group; bins of different
/// groups are independent, and bins of group g correlate up to `reach[g]`
/// bins apart. `a_inv` is (J^T J)^-1 and `dof` the residuals' degrees of
/// freedom (rows - p), for the small-sample factor rows / dof.
pub fn correlated_covariance(
    scores: &DMatrix<f64>,
    position: &[(usize, f64)],
    reach: &[f64],
    a_inv: &DMatrix<f64>,
    rows: usize,
    dof: usize,
) -> DMatrix<f64> {
    let omega = |bartlett: bool| {
        let p = scores.ncols();
        let mut omega = DMatrix::<f64>::zeros(p, p);
        for i in 0..scores.nrows() {
            let si = scores.row(i);
            omega += si.transpose() * si;
            let (gi, fi) = position[i];
            let reach = reach[gi];
            for (j, &(gj, fj)) in position.iter().enumerate().skip(i + 1) {
                let d = fj - fi;
                if gj != gi || d > reach + 1e-9 {
                    break;
                }
                let w = if bartlett {
                    1.0 - d / (reach + 1.0)
                } else {
                    1.0
                };
                let cross = si.transpose() * scores.row(j);
                omega += (&cross + cross.transpose()) * w;
            }
        }
        omega
    };
    let mut om = omega(false);
    if om.clone().cholesky().is_none() {
        om = omega(true);
    }
    a_inv * om * a_inv * (rows as f64 / dof.max(1) as f64)
}

/// The largest condition number of the column-scaled normal matrix for
/// which [`covariance_from_normal`] answers. Inverting it loses about
/// log10 of that many digits of the 16 a double holds: at 1e8 the
/// covariance still has some eight right, far more than a standard
/// deviation is quoted with.
pub const NORMAL_CONDITION_MAX: f64 = 1e8;

/// [`covariance`] from the normal matrix A = J^T J alone, for a problem
/// that forms A without J (the joint fit's solver does, at every point it
/// visits). The columns are scaled to unit norm as [`covariance`] scales
/// J's, so that the scaled A is J_s^T J_s, whose eigenvalues are the
/// squares of J_s's singular values. `None` when the scaled A's condition
/// number is above [`NORMAL_CONDITION_MAX`] or A is not positive definite:
/// the caller then forms J and calls [`covariance`], whose rank test works
/// at J's own precision (its ratio of 1e-12 would be 1e-24 here, beyond
/// what squared numbers can resolve).
pub fn covariance_from_normal(a: &DMatrix<f64>, scale: f64) -> Option<DMatrix<f64>> {
    let p = a.nrows();
    let norms: Vec<f64> = (0..p).map(|i| a[(i, i)].sqrt()).collect();
    if !norms.iter().all(|n| n.is_finite() && *n > 0.0) {
        return None;
    }
    let scaled = DMatrix::from_fn(p, p, |i, j| a[(i, j)] / (norms[i] * norms[j]));
    // nalgebra's `symmetric_eigen` iterates without a bound: a non-finite
    // entry would never converge. LAPACK's 30 sweeps per
    // eigenvalue bound it.
    if scaled.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let eig = nalgebra::SymmetricEigen::try_new(scaled, f64::EPSILON, 30 * p.max(1))?;
    let lo = eig.eigenvalues.min();
    let hi = eig.eigenvalues.max();
    if !(lo > 0.0 && hi.is_finite() && hi <= NORMAL_CONDITION_MAX * lo) {
        return None;
    }
    let v = &eig.eigenvectors;
    let mut cov = DMatrix::zeros(p, p);
    for k in 0..p {
        let inv = 1.0 / eig.eigenvalues[k];
        for i in 0..p {
            for j in 0..p {
                cov[(i, j)] += v[(i, k)] * v[(j, k)] * inv;
            }
        }
    }
    for i in 0..p {
        for j in 0..p {
            cov[(i, j)] *= scale / (norms[i] * norms[j]);
        }
    }
    Some(cov)
}

/// The covariance a fit of `input`'s bins would state for a model whose
/// parameters are `params` (laid out as [`TfFit::params`]), were the data
/// that model plus noise of `input.variance`: (J' W J)^-1 at `params`, the
/// fit's own Jacobian and weights, without the scaling by the reduced chi2
/// (which is 1 in expectation when the variances are honest). `input.h`
/// only has to be finite. For planning: how precisely a run that has not
/// been made would be fitted.
pub fn predicted_covariance(
    input: &FitInput,
    opts: &FitOptions,
    params: &[f64],
) -> Result<DMatrix<f64>, FitError> {
    let mut prep = prepare(input, opts)?;
    let shape = prep.problem.shape;
    let p = shape.n_params();
    check_param_count(&prep, "params", params)?;
    let theta = prep.scaling.to_scaled(&shape, params);
    prep.follow_aliases(opts, &theta, 1.0);
    let jac = prep.problem.jacobian_matrix(&theta);
    let cov_scaled = covariance(&jac, 1.0)
        .map_err(|e| not_identifiable(&prep, e, "Jacobian at the planned model (J^T W J)"))?;
    let factors = prep.scaling.factors(&shape);
    Ok(DMatrix::from_fn(p, p, |i, j| {
        cov_scaled[(i, j)] * factors[i] * factors[j]
    }))
}

/// `values` has one value per parameter of the prepared model.
fn check_param_count(
    prep: &Prepared,
    option: &'static str,
    values: &[f64],
) -> Result<(), FitError> {
    let p = prep.problem.shape.n_params();
    if values.len() == p {
        return Ok(());
    }
    Err(FitError::InvalidOption {
        option,
        reason: format!(
            "needs {p} values ({}), got {}",
            prep.names.join(", "),
            values.len()
        ),
    })
}

/// Where Levenberg-Marquardt ended: its best parameters, why it stopped and
/// after how many iterations.
struct Solved {
    theta: Vec<f64>,
    reason: TerminationReason,
    iterations: u64,
}

/// Run `solver` on `problem` from `start` in argmin's executor.
/// The state is [`lm::LmState`] for a problem giving residuals and J, and
/// [`lm::LmNormalState`] for one giving its cost and normal equations.
fn solve<O, J, R>(
    problem: O,
    solver: LevenbergMarquardt,
    start: Vec<f64>,
    max_iterations: u64,
) -> Result<Solved, FitError>
where
    LevenbergMarquardt:
        argmin::core::Solver<O, argmin::core::IterState<DVector<f64>, (), J, (), R, f64>>,
    J: Clone,
    R: Clone,
{
    let result = Executor::new(problem, solver)
        .configure(|s| s.param(DVector::from_vec(start)).max_iters(max_iterations))
        .run()?;
    let state = result.state();
    let theta = state
        .get_best_param()
        .ok_or(FitError::NoSolution)?
        .iter()
        .copied()
        .collect();
    Ok(Solved {
        theta,
        reason: state.get_termination_reason().cloned().unwrap_or_default(),
        iterations: state.get_iter(),
    })
}

/// The most re-evaluations of the aliases [`refine_held`] makes after its
/// first fit; one or two settle them (module docs).
const ALIAS_PASSES: usize = 4;

/// The predicted reduction (chi-square units) below which a fit no
/// damping improves on has converged (`LevenbergMarquardt::with_settled_cost`):
/// a parameter 1e-3 of its std from the optimum.
pub const SETTLED_COST: f64 = 1e-6;

/// The aliases are followed while evaluating them at the estimate would
/// move some parameter by this fraction of its stated std or more
/// (`shift_in_stds`). Where their whole effect is below it (a high
/// sampling rate: the paper's 2048 Hz), the hold's continuous factor is the
/// model. On noise-free data the fit follows them to round-off, in as many
/// passes as allowed.
pub const ALIAS_SETTLED: f64 = 1e-2;

/// The aliases are read on every this many bins before they are evaluated
/// at every one: the change they make to the model is the images' sum,
/// G_d - G Z, which the band's resonances do not shape (its terms are the
/// plant's response a sampling rate away), so its projection onto the
/// Jacobian's columns over every 8th bin reads the whole.
pub const ALIAS_PROBE_STRIDE: usize = 8;

/// The largest move, in stated stds, of a least-squares optimum whose model
/// changes by d at some bins: with the weighted Jacobian's rows J_i and the
/// weighted changes d_i over every `1 / share`-th bin, a = sum J_i^T J_i
/// and b = sum J_i^T d_i, the Gauss-Newton step is a^-1 b and the
/// covariance scale^2 share a^-1 (a over the probe is `share` of the whole
/// one), so parameter j moves by |(a^-1 b)_j| / (scale sqrt(share
/// (a^-1)_jj)) stds. The change's part orthogonal to the Jacobian's columns
/// moves nothing (the force FRFs' aliases at 2048 Hz are mostly that).
/// Each parameter's; None for a singular a (a start that does not settle
/// every parameter: the aliases are read again at the optimum).
pub(crate) fn shift_in_stds(
    a: &DMatrix<f64>,
    b: &DVector<f64>,
    share: f64,
    scale: f64,
) -> Option<Vec<f64>> {
    let inv = covariance_from_normal(a, 1.0)?;
    let step = &inv * b;
    Some(
        (0..step.len())
            .map(|j| step[j].abs() / (scale * (share * inv[(j, j)]).sqrt()))
            .collect(),
    )
}

/// [`refine`] with the hold's aliases those of the model it finds (module
/// docs): evaluated at `start` (scaled), then at each optimum, and fitted
/// again from there while they would move it by [`ALIAS_SETTLED`] of its
/// stated std or more.
fn refine_held(prep: &mut Prepared, opts: &FitOptions, start: Vec<f64>) -> Result<TfFit, FitError> {
    prep.follow_aliases(opts, &start, 1.0);
    let mut fit = refine(prep, opts, start)?;
    for _ in 0..ALIAS_PASSES {
        let theta = prep.scaling.to_scaled(&prep.problem.shape, &fit.params);
        if !prep.follow_aliases(opts, &theta, fit.reduced_chi2.sqrt()) {
            break;
        }
        fit = refine(prep, opts, theta)?;
    }
    Ok(fit)
}

impl Prepared {
    /// The known factor at every `stride`-th bin for the model at `theta`
    /// (scaled): the hold and any fixed delay times the aliases of that
    /// model's sampled response ([`alias_factor`]). None without a hold,
    /// or for a model that is not a transfer function (non-finite
    /// coefficients).
    fn exact_known(
        &self,
        opts: &FitOptions,
        theta: &[f64],
        stride: usize,
    ) -> Option<Vec<Complex<f64>>> {
        if opts.intersample == Intersample::None {
            return None;
        }
        let params = self.scaling.to_physical(&self.problem.shape, theta);
        let (tf, _) = fitted_tf(self, &params).ok()?;
        let freq: Vec<f64> = self.freq_hz.iter().step_by(stride).copied().collect();
        let alias = alias_factor(opts.intersample, opts.sample_rate_hz, &tf, &freq);
        let held = self.held.iter().step_by(stride);
        Some(held.zip(alias).map(|(h, a)| h * a).collect())
    }

    /// Sets the known factors to the aliases at `theta` where they would
    /// move some parameter by [`ALIAS_SETTLED`] of its std or more
    /// ([`shift_in_stds`] on every [`ALIAS_PROBE_STRIDE`]-th bin, `scale`
    /// the root of the reduced chi-square; 1 before a fit). Whether it set
    /// them.
    fn follow_aliases(&mut self, opts: &FitOptions, theta: &[f64], scale: f64) -> bool {
        let Some(probe) = self.exact_known(opts, theta, ALIAS_PROBE_STRIDE) else {
            return false;
        };
        let p = &self.problem;
        let n = p.n_bins();
        let np = p.shape.n_params();
        let model = p.model_every(theta, ALIAS_PROBE_STRIDE);
        let jac = p.jacobian_matrix(theta);
        let mut a = DMatrix::zeros(np, np);
        let mut b = DVector::zeros(np);
        for (i, (m, new)) in (0..n)
            .step_by(ALIAS_PROBE_STRIDE)
            .zip(model.iter().zip(&probe))
        {
            let d = m * (new / p.known[i] - 1.0) * p.weight[i];
            for j in 0..np {
                let (re, im) = (jac[(i, j)], jac[(n + i, j)]);
                b[j] += re * d.re + im * d.im;
                for k in 0..np {
                    a[(j, k)] += re * jac[(i, k)] + im * jac[(n + i, k)];
                }
            }
        }
        let shift = shift_in_stds(&a, &b, probe.len() as f64 / n as f64, scale);
        if !shift.is_some_and(|z| z.iter().any(|&z| z >= ALIAS_SETTLED)) {
            return false;
        }
        match self.exact_known(opts, theta, 1) {
            Some(known) => {
                self.problem.known = known;
                self.problem.last = Default::default();
                self.aliased = true;
                true
            }
            None => false,
        }
    }
}

/// Levenberg-Marquardt from `start` (scaled), then the covariance and report.
fn refine(prep: &Prepared, opts: &FitOptions, start: Vec<f64>) -> Result<TfFit, FitError> {
    let problem = &prep.problem;
    let shape = problem.shape;
    let p = shape.n_params();
    let Solved {
        theta,
        reason,
        iterations,
    } = solve(
        problem.clone(),
        delay_bounded_solver(prep)?,
        start,
        opts.max_iterations,
    )?;
    let converged = reason == TerminationReason::SolverConverged;

    let (reduced_chi2, cov_scaled) = scaled_covariance(prep, opts, &theta)?;
    let factors = prep.scaling.factors(&shape);
    let covariance = DMatrix::from_fn(p, p, |i, j| cov_scaled[(i, j)] * factors[i] * factors[j]);
    let std: Vec<f64> = (0..p).map(|i| covariance[(i, i)].sqrt()).collect();
    let params = prep.scaling.to_physical(&shape, &theta);
    let (tf, tau_s) = fitted_tf(prep, &params)?;
    let transient = prep
        .transient
        .as_ref()
        .zip(problem.projector.as_ref())
        .map(|(t, q)| t.found(prep, q, &theta));
    let fit_percent = fit_percent(prep, &theta, transient.as_ref());

    let termination = reason.text().to_string();
    let mut warnings = Vec::new();
    if !converged {
        warnings.push(Warning::new(
            format!("the fit did not converge in {iterations} iterations"),
            format!(
                "the fit did not converge ({termination} after {iterations} iterations); the coefficients and their covariance are from the last accepted step"
            ),
        ));
    }
    let stable = tf.is_stable();
    if !stable {
        warnings.push(unstable_warning(&tf));
    }
    if let Some(w) = delay_bound_warning(prep, &theta, tau_s) {
        warnings.push(w);
    }
    Ok(TfFit {
        tf,
        shape,
        params,
        param_names: prep.names.clone(),
        covariance,
        std,
        fit_percent,
        reduced_chi2,
        iterations,
        termination,
        converged,
        stable,
        n_bins: problem.n_bins(),
        warnings,
        transient,
        aliases: prep.aliased,
    })
}

/// A Levenberg-Marquardt solver, its delay held to [0, max] (scaled) when
/// the delay is fitted.
fn delay_bounded_solver(prep: &Prepared) -> Result<LevenbergMarquardt, FitError> {
    let solver = LevenbergMarquardt::new().with_settled_cost(SETTLED_COST);
    let Some(max_s) = prep.max_delay_s else {
        return Ok(solver);
    };
    let p = prep.problem.shape.n_params();
    let mut lower = DVector::from_element(p, f64::NEG_INFINITY);
    let mut upper = DVector::from_element(p, f64::INFINITY);
    lower[p - 1] = 0.0;
    upper[p - 1] = max_s * prep.scaling.w0_rad_per_s;
    Ok(solver.with_bounds(lower, upper)?)
}

/// The reduced chi-square at the optimum `theta` (scaled) and the
/// covariance of the scaled parameters: (J^T W J)^-1 times it, or the
/// sandwich over the bins' shared data when they share it.
fn scaled_covariance(
    prep: &Prepared,
    opts: &FitOptions,
    theta: &[f64],
) -> Result<(f64, DMatrix<f64>), FitError> {
    let problem = &prep.problem;
    let p = problem.shape.n_params();
    let n = problem.n_bins();
    let jac = problem.jacobian_matrix(theta);
    let chi2 = problem.residuals(theta).norm_squared();
    // The transient's coefficients are parameters too (eliminated).
    let eliminated = problem.projector.as_ref().map_or(0, |q| q.rank());
    let dof = (2 * n).saturating_sub(p + eliminated).max(1);
    let reduced_chi2 = chi2 / dof as f64;
    let cov_scaled = covariance(&jac, reduced_chi2)
        .map_err(|e| not_identifiable(prep, e, "Jacobian at the optimum (J^T W J)"))?;
    if opts.independent_lag > 1 && reduced_chi2 > 0.0 {
        // Neighbouring bins share data: the sandwich over their range.
        let a_inv = &cov_scaled / reduced_chi2;
        let cov = shared_bins_covariance(problem, &jac, theta, opts.independent_lag, &a_inv, dof);
        return Ok((reduced_chi2, cov));
    }
    Ok((reduced_chi2, cov_scaled))
}

/// [`correlated_covariance`] for one FRF whose bins share data with those
/// fewer than `independent_lag` bins away: the scores from the Jacobian
/// `jac` and residuals at `theta`, each bin placed by its frequency in
/// bin steps. `a_inv` is (J^T J)^-1.
fn shared_bins_covariance(
    problem: &FrfProblem,
    jac: &DMatrix<f64>,
    theta: &[f64],
    independent_lag: usize,
    a_inv: &DMatrix<f64>,
    dof: usize,
) -> DMatrix<f64> {
    let n = problem.n_bins();
    let p = problem.shape.n_params();
    let r = problem.residuals(theta);
    let scores = DMatrix::from_fn(n, p, |i, k| jac[(i, k)] * r[i] + jac[(n + i, k)] * r[n + i]);
    let step = problem
        .s
        .windows(2)
        .map(|w| w[1].im - w[0].im)
        .filter(|d| *d > 0.0)
        .fold(f64::INFINITY, f64::min);
    let position: Vec<(usize, f64)> = problem.s.iter().map(|s| (0, s.im / step)).collect();
    correlated_covariance(
        &scores,
        &position,
        &[(independent_lag - 1) as f64],
        a_inv,
        2 * n,
        dof,
    )
}

/// The fitted plant from physical `params`: n(s) / d(s) with d monic, and
/// the delay (s), fitted or fixed.
fn fitted_tf(prep: &Prepared, params: &[f64]) -> Result<(TransferFunction, f64), FitError> {
    let shape = prep.problem.shape;
    let m = shape.numerator_order;
    let tau_s = if shape.fit_delay {
        params[shape.n_params() - 1]
    } else {
        prep.fixed_delay_s
    };
    let mut den = vec![1.0];
    den.extend_from_slice(&params[m + 1..shape.n_rational()]);
    let tf = TransferFunction::with_delay(&params[..=m], &den, tau_s)?;
    Ok((tf, tau_s))
}

/// [`TfFit::fit_percent`] of the model at `theta` (scaled), compared with
/// the measured response less the `transient` fitted beside it.
fn fit_percent(prep: &Prepared, theta: &[f64], transient: Option<&transient::Transient>) -> f64 {
    let problem = &prep.problem;
    let n = problem.n_bins();
    let w0 = prep.scaling.w0_rad_per_s;
    let h: Vec<Complex<f64>> = match transient {
        Some(t) => problem
            .h
            .iter()
            .zip(&prep.transient.as_ref().expect("with the transient").u)
            .zip(&problem.s)
            .map(|((h, u), s)| h - t.at(s.im * w0 / (2.0 * std::f64::consts::PI), *u))
            .collect(),
        None => problem.h.clone(),
    };
    let model = problem.model(theta);
    let mean = h.iter().sum::<Complex<f64>>() / n as f64;
    let err = h
        .iter()
        .zip(model.iter())
        .map(|(h, hm)| (h - hm).norm_sqr())
        .sum::<f64>()
        .sqrt();
    let spread = h.iter().map(|h| (h - mean).norm_sqr()).sum::<f64>().sqrt();
    100.0 * (1.0 - err / spread)
}

/// The warning for a model with a pole outside the open left half-plane.
fn unstable_warning(tf: &TransferFunction) -> Warning {
    let poles: Vec<String> = tf.poles().iter().map(|p| format!("{p:.4}")).collect();
    Warning::new(
        "the fitted model is unstable: a pole outside the open left half-plane",
        format!(
            "the fitted model is unstable: poles outside the open left half-plane among [{}] (rad/s)",
            poles.join(", ")
        ),
    )
}

/// The warning for a fitted delay `tau_s` at a bound of its range, where
/// its standard deviation no longer holds.
fn delay_bound_warning(prep: &Prepared, theta: &[f64], tau_s: f64) -> Option<Warning> {
    let max_s = prep.max_delay_s?;
    let tau_scaled = theta[prep.problem.shape.n_params() - 1];
    // Compared in scaled units, where the solver clamps exactly.
    let at_bound = tau_scaled <= 0.0 || tau_scaled >= max_s * prep.scaling.w0_rad_per_s;
    at_bound.then(|| {
        Warning::new(
            format!("the fitted delay {tau_s:.3e} s is at a bound of its range [0, {max_s}] s"),
            format!(
                "the fitted delay {tau_s} s is at a bound of [0, {max_s}] s; its standard deviation assumes an interior optimum"
            ),
        )
    })
}
