//! A run's transfer function from its FRF: the bins the fit is given, the
//! fit's options from the campaign's settings, and the fit itself, refused
//! where `servoid run` refuses it (too few bins, no convergence, unstable).
//! With `auto`'s plan the record's transient and the bins' noise level are
//! fitted first (`fit::transient`), then the model on what they leave.

use crate::fit::{self, DelayPlan, FitError, FitInput, FitOptions, TfFit};
use crate::frf::{self, Frf, FrfError, FrfPlan};

use super::IdentificationPlan;

/// What the fit is given from an FRF: the bins of `mask` whose variance is
/// defined, their frequencies, estimates and E|dH|^2.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FitData {
    pub freq_hz: Vec<f64>,
    #[serde(with = "crate::lti::complex_vec")]
    pub h: Vec<nalgebra::Complex<f64>>,
    pub variance: Vec<f64>,
    /// The input's one-sided auto-spectral density at those bins
    /// (unit^2/Hz), which turns the variance into a noise level.
    pub suu: Vec<f64>,
    /// The FRF's grid spacing (Hz).
    pub bin_hz: f64,
    /// The lag in bins from which the FRF's errors are independent
    /// (`FrfPlan::independent_lag` of the run's settings).
    pub lag: usize,
    /// The displacement's amplitude at those bins along a sweep
    /// (`Self::with_amplitude`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub amplitude_m: Option<Vec<f64>>,
}

impl FitData {
    /// The bins of `mask`, of an FRF `plan` made.
    pub fn of(h: &Frf, mask: &[bool], plan: &FrfPlan) -> Self {
        let (bins, variance) = Self::usable(h, mask);
        Self::at(h, &bins, variance, plan)
    }

    /// For a command of sparse lines over `band_hz` (`frf::sparse_lines`),
    /// the excited lines of `mask` with the transient taken out of `h` there
    /// and the variances the lines it does not excite give
    /// (`frf::at_lines`). None for any other command, or where no line has
    /// the neighbours its noise level needs.
    pub fn at_lines(
        h: &mut Frf,
        mask: &[bool],
        band_hz: (f64, f64),
        plan: &FrfPlan,
    ) -> Option<Self> {
        if !frf::sparse_lines(h, band_hz) {
            return None;
        }
        let (bins, variance) = frf::at_lines(h, mask, band_hz, plan.steady_periods())?;
        Some(Self::at(h, &bins, variance, plan))
    }

    /// The bins of `mask` whose variance is defined, and E|dH|^2 there.
    fn usable(h: &Frf, mask: &[bool]) -> (Vec<usize>, Vec<f64>) {
        let masked: Vec<usize> = (0..h.freq_hz.len()).filter(|&i| mask[i]).collect();
        // frf gives the variance of Re(H) and of Im(H) each; fit wants
        // E|dH|^2, their sum. A bin whose variance is undefined (no noise
        // information around it) carries no weight and is left out.
        masked
            .iter()
            .zip(frf::h_variance_at(h, &masked))
            .filter(|(_, v)| v.is_finite())
            .map(|(&i, v)| (i, 2.0 * v))
            .unzip()
    }

    /// `h` at `bins`, with their variances.
    fn at(h: &Frf, bins: &[usize], variance: Vec<f64>, plan: &FrfPlan) -> Self {
        Self {
            freq_hz: bins.iter().map(|&i| h.freq_hz[i]).collect(),
            h: bins.iter().map(|&i| h.h[i]).collect(),
            variance,
            suu: bins.iter().map(|&i| h.suu[i]).collect(),
            bin_hz: h.resolution_hz,
            lag: plan.independent_lag(),
            amplitude_m: None,
        }
    }

    /// The bins as the rig's identification reads them: without the
    /// input's spectrum (`suu` left empty), which only the run's own noise
    /// level reads, a sixth of what a bin holds: 17 MB of a 3,000-log
    /// night's 600 spring FRFs, held until the rig is fitted.
    pub fn for_rig(self) -> Self {
        Self {
            suu: Vec::new(),
            ..self
        }
    }

    /// With the displacement's amplitude at each bin: the FRF's gain there
    /// times the command's amplitude `sweep` gives.
    pub fn with_amplitude(mut self, sweep: &frf::SweepAmplitude) -> Self {
        self.amplitude_m = Some(
            self.freq_hz
                .iter()
                .zip(&self.h)
                .map(|(&f, h)| h.norm() * sweep.at(f))
                .collect(),
        );
        self
    }

    /// With the displacement's amplitude at each bin read from `x1_u`, the
    /// displacement's FRF on the same grid, times the command's amplitude
    /// `sweep` gives: what a force FRF's bins need, since the friction's
    /// describing function depends on the displacement's amplitude.
    pub fn with_displacement_amplitude(mut self, x1_u: &Frf, sweep: &frf::SweepAmplitude) -> Self {
        self.amplitude_m = Some(
            self.freq_hz
                .iter()
                .map(|&f| {
                    let i = x1_u.freq_hz.partition_point(|&g| g < f);
                    let gain = match x1_u.freq_hz.get(i) {
                        Some(&g) if g == f => x1_u.h[i].norm(),
                        _ => 0.0,
                    };
                    gain * sweep.at(f)
                })
                .collect(),
        );
        self
    }

    pub fn input(&self) -> FitInput<'_> {
        FitInput {
            freq_hz: &self.freq_hz,
            h: &self.h,
            variance: &self.variance,
        }
    }
}

/// The fewest band bins a fit may use: one per parameter, at least three
/// (each bin gives two real equations, a margin over the bare minimum).
fn bins_needed(ident: &IdentificationPlan) -> usize {
    let n_params = ident.numerator_order
        + 1
        + ident.denominator_order
        + usize::from(matches!(ident.delay, DelayPlan::Fit { .. }));
    n_params.max(3)
}

/// The fit options of a campaign's identification settings for a run
/// whose FRF was made by `plan` from a log sampled at `sample_rate_hz`.
pub fn fit_options(ident: &IdentificationPlan, plan: &FrfPlan, sample_rate_hz: f64) -> FitOptions {
    let mut opts = FitOptions::new(
        ident.numerator_order,
        ident.denominator_order,
        sample_rate_hz,
    );
    opts.intersample = ident.intersample;
    opts.delay = ident.delay;
    opts.max_iterations = fit::RUN_MAX_ITERATIONS;
    opts.independent_lag = plan.independent_lag();
    opts
}

/// Why a run's FRF gives no transfer function: the one refusal `servoid
/// run` and the Monte Carlo's simulated runs share.
#[derive(Debug, thiserror::Error)]
pub enum RunTfError {
    #[error("FRF: {0}")]
    Frf(#[from] FrfError),
    #[error("the command has no energy in the fit band {lo}-{hi} Hz ({fraction:.2e} of its power)")]
    NoExcitation { lo: f64, hi: f64, fraction: f64 },
    #[error(
        "only {n} bins in {lo}-{hi} Hz have coherence >= {coherence_min}; the fit needs at least {need} (lower identification.coherence_min or widen the band)"
    )]
    TooFewBins {
        n: usize,
        need: usize,
        lo: f64,
        hi: f64,
        coherence_min: f64,
    },
    #[error("transfer-function fit: {0}")]
    Fit(#[from] FitError),
    #[error("the fit did not converge ({termination}); refusing a model that is not an optimum")]
    NotConverged { termination: String },
    #[error("the fitted model is unstable (poles {poles}); refusing it. {cause}")]
    Unstable { poles: String, cause: UnstableCause },
}

/// What the data say an unstable fit comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UnstableCause {
    /// The measured FRF leads its command over most of the band, as the
    /// inverse of an actuator's lag does: displacement read as command.
    Swapped,
    /// The fit has a delay: a delay and a pole can trade phase (the lag of
    /// e^(-s tau) against a pole's), and the band does not set both.
    DelayTradeOff,
    /// Neither: the band's bins do not fix a stable model of this order.
    Underdetermined,
}

impl std::fmt::Display for UnstableCause {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            UnstableCause::Swapped => {
                "The measured response leads its command over most of the band, as swapped command and displacement columns give: check the channels' columns"
            }
            UnstableCause::DelayTradeOff => {
                "The fitted delay trades phase with a pole, and the band does not set both: fit without the delay (identification.delay = { mode = \"none\" })"
            }
            UnstableCause::Underdetermined => {
                "The response lags its command, so the columns are not swapped: the band's bins do not fix a stable model of this order; narrow identification.band_hz to where the coherence is high"
            }
        })
    }
}

impl UnstableCause {
    /// The cause the fitted bins `h` and the unstable fit's delay point
    /// to: a lead over most of the bins (median phase above zero) is the
    /// inverse of an actuator's lag; else a fitted delay; else the bins.
    fn of(h: &[nalgebra::Complex<f64>], delay_s: f64) -> Self {
        let mut phase: Vec<f64> = h.iter().map(|h| h.arg()).collect();
        phase.sort_by(f64::total_cmp);
        let median = phase.get(phase.len() / 2).copied().unwrap_or(0.0);
        if median > 0.0 {
            UnstableCause::Swapped
        } else if delay_s > 0.0 {
            UnstableCause::DelayTradeOff
        } else {
            UnstableCause::Underdetermined
        }
    }
}

impl RunTfError {
    /// What kind of refusal this is, in a few words: how the Monte Carlo
    /// counts its failed draws.
    pub fn kind(&self) -> &'static str {
        match self {
            RunTfError::Frf(_) => "the FRF failed",
            RunTfError::NoExcitation { .. } => "no excitation in the band",
            RunTfError::TooFewBins { .. } => "too few bins pass the coherence limit",
            RunTfError::Fit(_) => "the fit failed",
            RunTfError::NotConverged { .. } => "a fit that did not converge",
            RunTfError::Unstable { .. } => "an unstable fit",
        }
    }
}

/// A run's transfer function fitted to its FRF `h` (made by `plan`) on the
/// bins of `mask` (the band's, coherent enough), refused as `servoid run`
/// refuses a run: too few bins for the model, a fit that fails, is
/// unstable or did not converge. The fit's own warnings are in
/// `TfFit::warnings`.
///
/// With `plan.transient()` the record's transient is fitted beside the model
/// (`fit::transient`) and taken out of `h`; the bins' variances are then
/// estimated again from `h` without it (the ETFE's local noise level
/// counts a transient as noise) and the model fitted once more with them.
///
/// With `start` (parameters laid out as [`TfFit::params`] of this fit's
/// model: another reading's fit of the same plant) the first fit starts
/// there instead of at the linear least-squares start; the optimum is the
/// same, found in fewer steps.
pub fn fit_run(
    h: &mut Frf,
    mask: &[bool],
    band_hz: (f64, f64),
    ident: &IdentificationPlan,
    plan: &FrfPlan,
    sample_rate_hz: f64,
    start: Option<&[f64]>,
) -> Result<(TfFit, FitData), RunTfError> {
    let used = mask.iter().filter(|m| **m).count();
    let need = bins_needed(ident);
    if used < need {
        return Err(RunTfError::TooFewBins {
            n: used,
            need,
            lo: band_hz.0,
            hi: band_hz.1,
            coherence_min: ident.coherence_min,
        });
    }
    let opts = fit_options(ident, plan, sample_rate_hz);
    let (fit, data) = if plan.model_noise() {
        refined_fit(h, mask, band_hz, plan, &opts, ident.max_delay_s, start)?
    } else {
        let data = FitData::of(h, mask, plan);
        let fit = match start {
            Some(start) => fit::fit_from(&data.input(), &opts, start)?,
            None => fit::fit(&data.input(), &opts)?,
        };
        (fit, data)
    };
    if !fit.stable {
        let poles = fit
            .tf
            .poles()
            .iter()
            .map(|p| format!("{:.4}{:+.4}j", p.re, p.im))
            .collect::<Vec<_>>()
            .join(", ");
        return Err(RunTfError::Unstable {
            cause: UnstableCause::of(&data.h, fit.tf.delay_s),
            poles,
        });
    }
    if !fit.converged {
        return Err(RunTfError::NotConverged {
            termination: fit.termination.clone(),
        });
    }
    Ok((fit, data))
}

/// [`fit_run`]'s fit as `auto` makes it (`plan.model_noise()`). For a
/// command of sparse lines over `band_hz` (`frf::sparse_lines`), the FRF
/// and its variance at the excited lines from the non-excited ones
/// (`frf::at_lines`), and the model fitted there. Otherwise, first what
/// is not the model: the record's transient (when `plan.transient()`) and
/// the bins' noise level, from a fit of the model with a delay (up to
/// `max_delay_s`, whatever the manifest's delay: a sensor's delay the
/// model lacks would leave the transient's columns wrong and its misfit
/// in the noise); the transient is taken out of `h` and the noise level
/// read from what that fit leaves. Then the manifest's model, fitted to
/// `h` on those variances. The data returned are `h` at its bins with the
/// variances the model was weighted by, so that its cost is theirs. The
/// first fit starts from `start` when given.
fn refined_fit(
    h: &mut Frf,
    mask: &[bool],
    band_hz: (f64, f64),
    plan: &FrfPlan,
    opts: &FitOptions,
    max_delay_s: f64,
    start: Option<&[f64]>,
) -> Result<(TfFit, FitData), FitError> {
    if let Some(data) = FitData::at_lines(h, mask, band_hz, plan) {
        // A periodic command's lines: the transient and the noise level
        // from the lines it does not excite, the model fitted at the
        // excited ones alone.
        let fit = match start {
            Some(start) => fit::fit_from(&data.input(), opts, start)?,
            None => fit::fit(&data.input(), opts)?,
        };
        return Ok((fit, data));
    }
    let u = h.input_dft.clone().filter(|_| plan.transient().is_some());
    let (bins, variance) = FitData::usable(h, mask);
    let data = FitData::at(h, &bins, variance, plan);
    let first = if opts.delay == DelayPlan::None {
        // The delay from 0, the rest from the fit without it or the
        // transient: a delay of a few ms is well inside the band's phase,
        // where the search needs no grid.
        let nuisance = FitOptions {
            delay: DelayPlan::Fit { max_s: max_delay_s },
            ..opts.clone()
        };
        let mut start = match start {
            Some(start) => start.to_vec(),
            None => fit::fit(&data.input(), opts)?.params,
        };
        start.push(0.0);
        fit_at(&data, &bins, u.as_deref(), &nuisance, Some(&start))?
    } else {
        fit_at(&data, &bins, u.as_deref(), opts, start)?
    };
    if let Some(t) = &first.transient {
        h.without_transient(|f, u| t.at(f, u));
    }
    let (bins, variance) = residual_noise(h, mask, &first, opts);
    let data = FitData::at(h, &bins, variance, plan);
    let start = &first.params[..first.shape.n_rational()];
    let start: Vec<f64> = match opts.delay {
        DelayPlan::Fit { .. } => first.params.clone(),
        _ => start.to_vec(),
    };
    let fit = fit::fit_from(&data.input(), opts, &start)?;
    Ok((fit, data))
}

/// One fit of `data` (at the FRF's `bins`), with the record's transient
/// when the command's DFT `u` is given, from `start` when given.
fn fit_at(
    data: &FitData,
    bins: &[usize],
    u: Option<&[nalgebra::Complex<f64>]>,
    opts: &FitOptions,
    start: Option<&[f64]>,
) -> Result<TfFit, FitError> {
    match (u, start) {
        (Some(u), _) => {
            let at: Vec<_> = bins.iter().map(|&k| u[k]).collect();
            fit::fit_with_transient(&data.input(), &at, opts, start)
        }
        (None, Some(start)) => fit::fit_from(&data.input(), opts, start),
        (None, None) => fit::fit(&data.input(), opts),
    }
}

/// The bins of `mask` with a defined noise level and E|dH|^2 there, read
/// (as the ETFE reads it, `frf::h_variance_at`) from `h` less `fit`'s model
/// with the hold: the local polynomials then only follow the model's
/// misfit, which is smooth, where on `h` itself they must follow the
/// plant's curvature.
fn residual_noise(
    h: &Frf,
    mask: &[bool],
    fit: &TfFit,
    opts: &FitOptions,
) -> (Vec<usize>, Vec<f64>) {
    // The bins the mask holds and the noise estimate's reach beyond them.
    let top = h
        .freq_hz
        .iter()
        .zip(mask)
        .filter(|(_, m)| **m)
        .map(|(f, _)| *f)
        .fold(0.0, f64::max);
    let mut residual = h.head(top, frf::VARIANCE_REACH_BINS);
    let n = residual.h.len();
    let model = fit.as_logged(opts.intersample, opts.sample_rate_hz, &h.freq_hz[..n]);
    for ((hk, &f), m) in residual.h.iter_mut().zip(&h.freq_hz).zip(model) {
        if f > 0.0 {
            *hk -= m;
        }
    }
    FitData::usable(&residual, &mask[..residual.h.len()])
}

#[cfg(test)]
mod tests {
    use super::UnstableCause;
    use nalgebra::Complex;

    /// The paper's no-specimen x1/u, 3060 / (s^2 + 267 s + 3060) (Sec. 3.1),
    /// at 0.5-30 Hz.
    fn actuator() -> Vec<Complex<f64>> {
        (1..=60)
            .map(|k| {
                let s = Complex::new(0.0, 2.0 * std::f64::consts::PI * 0.5 * k as f64);
                Complex::new(3060.0, 0.0) / (s * s + s * 267.0 + 3060.0)
            })
            .collect()
    }

    /// An unstable fit is put down to swapped columns only where the
    /// response leads its command (the inverse of the actuator's lag);
    /// with the actuator's own lag, to a fitted delay where there is one,
    /// else to the bins; and the message says so.
    #[test]
    fn an_unstable_fit_is_put_down_to_what_the_response_shows() {
        let lag = actuator();
        let lead: Vec<Complex<f64>> = lag.iter().map(|h| h.inv()).collect();
        assert_eq!(UnstableCause::of(&lead, 0.0), UnstableCause::Swapped);
        assert_eq!(UnstableCause::of(&lead, 3e-3), UnstableCause::Swapped);
        assert_eq!(UnstableCause::of(&lag, 3e-3), UnstableCause::DelayTradeOff);
        assert_eq!(UnstableCause::of(&lag, 0.0), UnstableCause::Underdetermined);
        for cause in [UnstableCause::DelayTradeOff, UnstableCause::Underdetermined] {
            assert!(!cause.to_string().contains("swapped command"), "{cause}");
        }
        assert!(
            UnstableCause::DelayTradeOff
                .to_string()
                .contains("identification.delay")
        );
        assert!(
            UnstableCause::Swapped
                .to_string()
                .contains("swapped command and displacement")
        );
    }
}
