//! How well the actuator follows its command: the tracking
//! measures an RTHS lab reads of a run, each from the command and the
//! measured (or predicted) displacement alone, so that the same function
//! gives the measured tracking of a log and the tracking the identified
//! model predicts for its command.
//!
//! - the time delay by cross-correlation ([`delay::xcorr_delay`]) and by
//!   the slope of the FRF's phase ([`delay::phase_slope_delay`]);
//! - the frequency evaluation index ([`frequency_evaluation`]: Guo, Chen,
//!   Xu & Sanchez 2014), the amplitude and phase of the tracking at the
//!   frequencies the command has, and the delay they imply;
//! - the tracking indicator ([`tracking_indicator`]: Mercan & Ricles
//!   2007), the signed area of the synchronized subspace plot;
//! - the tracking error's normalised RMS and peak ([`tracking_errors`]:
//!   J2 and J3 of the RTHS benchmark, Silva et al. 2020).
//!
//! Pure: signals in, numbers or notes out. Displacements in m, times in
//! s. A positive delay is a displacement that lags its command.

pub mod compensator;
pub mod delay;

#[cfg(test)]
mod tests;

use nalgebra::Complex;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

pub use delay::{DelayNote, phase_slope_delay, xcorr_delay};

use crate::validate::{Window, window_range};

/// The longest delay the cross-correlation looks for (s): ten times a
/// servo-hydraulic actuator's usual 10-30 ms, and short against any
/// record's length.
pub const MAX_DELAY_S: f64 = 0.25;

/// The frequency evaluation index of Guo et al. (2014): the complex ratio
/// of the displacement's spectrum to the command's, averaged over
/// frequency with the command's power as weights,
///
/// `FEI = sum_j (X_m(f_j) / X_c(f_j)) |X_c(f_j)|^2 / sum_j |X_c(f_j)|^2
///      = sum_j X_m(f_j) conj(X_c(f_j)) / sum_j |X_c(f_j)|^2`,
///
/// so that it is the tracking at the frequencies the command has. Its
/// modulus is the amplitude ratio, its argument the phase, and with the
/// equivalent frequency `f_eq = sum_j f_j |X_c|^2 / sum_j |X_c|^2` the
/// delay is `-phase / (2 pi f_eq)`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct FrequencyEvaluation {
    /// |FEI|: displacement over command amplitude (1 is exact).
    pub amplitude: f64,
    /// arg FEI (degrees; negative when the displacement lags).
    pub phase_deg: f64,
    /// The command-power-weighted mean frequency (Hz).
    pub equivalent_frequency_hz: f64,
    /// -phase / (2 pi f_eq) (s).
    pub delay_s: f64,
}

/// Why the frequency evaluation index has no value.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FeiNote {
    #[error("the command is constant: it has no frequency to evaluate")]
    ConstantCommand,
    #[error("fewer than 8 samples")]
    TooShort,
}

/// A command prepared for the tracking measures of displacements against
/// it: its mean and the one-sided DFT of it less its mean, transformed
/// once. A run's measured, predicted and compensated displacements are
/// measured against the same command, and the cross-correlation and the
/// frequency evaluation index both read its transform.
#[derive(Debug, Clone)]
pub struct Reference<'a> {
    samples: &'a [f64],
    mean: f64,
    spectrum: Vec<Complex<f64>>,
}

impl<'a> Reference<'a> {
    pub fn new(command: &'a [f64]) -> Self {
        let mean = mean(command);
        Self {
            samples: command,
            mean,
            spectrum: centred_spectrum(command, mean),
        }
    }

    /// The command's samples.
    pub fn samples(&self) -> &'a [f64] {
        self.samples
    }

    /// The same command cut to its first `n` samples, transformed again
    /// when that is fewer than it has (a displacement shorter than its
    /// command is measured against as much of it).
    fn first(&self, n: usize) -> std::borrow::Cow<'_, Reference<'a>> {
        if n >= self.samples.len() {
            std::borrow::Cow::Borrowed(self)
        } else {
            std::borrow::Cow::Owned(Reference::new(&self.samples[..n]))
        }
    }
}

/// The frequency evaluation index of `displacement` against the command
/// `reference`.
///
/// Each record's mean is removed first: Guo et al. take every bin from DC,
/// but a command resting away from zero (the UTFSM logs' -0.21 mm) would
/// then put most of the weight on the DC bin, whose ratio says nothing of
/// tracking. The one-sided spectra's factor of two cancels in the ratio.
/// The phase is taken with `atan2` (Guo et al.'s `atan` is right only
/// within +-90 degrees).
pub fn frequency_evaluation(
    reference: &Reference<'_>,
    displacement: &[f64],
    sample_rate_hz: f64,
) -> Result<FrequencyEvaluation, FeiNote> {
    let n = reference.samples.len().min(displacement.len());
    if n < 8 {
        return Err(FeiNote::TooShort);
    }
    let reference = reference.first(n);
    if constant(reference.samples) {
        return Err(FeiNote::ConstantCommand);
    }
    let x = &displacement[..n];
    let (uk, xk) = (&reference.spectrum, centred_spectrum(x, mean(x)));
    let (mut cross, mut power, mut weighted_f) = (Complex::new(0.0, 0.0), 0.0, 0.0);
    for (k, (u, x)) in uk.iter().zip(&xk).enumerate().skip(1) {
        let p = u.norm_sqr();
        cross += x * u.conj();
        power += p;
        weighted_f += p * k as f64 * sample_rate_hz / n as f64;
    }
    if power == 0.0 || !power.is_finite() {
        return Err(FeiNote::ConstantCommand);
    }
    let fei = cross / power;
    let f_eq = weighted_f / power;
    let phase = fei.arg();
    Ok(FrequencyEvaluation {
        amplitude: fei.norm(),
        phase_deg: phase.to_degrees(),
        equivalent_frequency_hz: f_eq,
        delay_s: -phase / (2.0 * std::f64::consts::PI * f_eq),
    })
}

/// Whether every value is the first (a record less its mean may then
/// hold rounding's residue, not zeros).
fn constant(x: &[f64]) -> bool {
    x.iter().all(|v| *v == x[0])
}

/// The mean of `x` (0 for none).
fn mean(x: &[f64]) -> f64 {
    if x.is_empty() {
        0.0
    } else {
        x.iter().sum::<f64>() / x.len() as f64
    }
}

/// The one-sided DFT of `x` less `mean` (none for no samples).
fn centred_spectrum(x: &[f64], mean: f64) -> Vec<Complex<f64>> {
    if x.is_empty() {
        return Vec::new();
    }
    let mut buf: Vec<f64> = x.iter().map(|v| v - mean).collect();
    let plan = crate::fft::real_forward(x.len());
    let mut out = plan.make_output_vec();
    plan.process(&mut buf, &mut out)
        .expect("lengths come from the plan");
    out
}

/// The tracking indicator of Mercan & Ricles (2007), as OpenFresco
/// computes it (`plotOutputDSpace.m`): with `x_c` the command and `x_m` the
/// displacement, by the trapezoidal rule,
///
/// `A = integral x_m dx_c`, `TA = integral x_c dx_m`, `TI = (A - TA) / 2`,
///
/// which is minus the area the synchronized subspace plot (`x_m` against
/// `x_c`) encloses, counted positive anticlockwise. A displacement that
/// lags its command traces the loop anticlockwise, so **TI falls while the
/// actuator lags and rises while it leads**; for `x_c = a sin(wt)`, `x_m =
/// b sin(wt - phi)` it falls by `pi a b sin(phi)` a cycle. Returned with
/// its value normalised by the square of the larger peak, in percent (as
/// OpenFresco's `plotOutputXPCtarget.m` shows it), which does not depend on
/// the unit.
pub fn tracking_indicator(command: &[f64], displacement: &[f64]) -> Option<(f64, f64)> {
    let n = command.len().min(displacement.len());
    if n < 2 {
        return None;
    }
    let (xc, xm) = (&command[..n], &displacement[..n]);
    let mut ti = 0.0;
    for i in 1..n {
        let a = 0.5 * (xm[i] + xm[i - 1]) * (xc[i] - xc[i - 1]);
        let ta = 0.5 * (xc[i] + xc[i - 1]) * (xm[i] - xm[i - 1]);
        ti += 0.5 * (a - ta);
    }
    let peak = xc.iter().chain(xm).fold(0.0_f64, |m, v| m.max(v.abs()));
    (peak > 0.0).then(|| (ti, ti / (peak * peak) * 100.0))
}

/// The tracking error's size, as the RTHS benchmark's J2 and J3 define it
/// (Silva, Gomez, Maghareh, Dyke & Spencer 2020, "Benchmark control problem
/// for real-time hybrid simulation", MSSP 135:106381, Sec. 3.5), with the
/// command as the target:
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TrackingErrors {
    /// J2 = sqrt(sum (x_m - x_c)^2 / sum x_c^2) * 100 (%).
    pub nrms_pct: f64,
    /// J3 = max|x_m - x_c| / max|x_c| * 100 (%).
    pub peak_pct: f64,
    /// max|x_m - x_c| (m).
    pub peak_error_m: f64,
}

/// J2 and J3 of the displacement against its command; None for a command
/// that is zero throughout (nothing to normalise by).
pub fn tracking_errors(command: &[f64], displacement: &[f64]) -> Option<TrackingErrors> {
    let n = command.len().min(displacement.len());
    let (mut se, mut sc, mut pe, mut pc) = (0.0, 0.0, 0.0_f64, 0.0_f64);
    for (c, m) in command[..n].iter().zip(&displacement[..n]) {
        let e = m - c;
        se += e * e;
        sc += c * c;
        pe = pe.max(e.abs());
        pc = pc.max(c.abs());
    }
    (sc > 0.0 && pc > 0.0).then(|| TrackingErrors {
        nrms_pct: (se / sc).sqrt() * 100.0,
        peak_pct: pe / pc * 100.0,
        peak_error_m: pe,
    })
}

/// The tracking measures of one displacement record against its command.
/// A measure the records cannot give is absent, with its reason in
/// `notes`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Tracking {
    /// The delay by cross-correlation, refined below a sample (s).
    pub delay_xcorr_s: Option<f64>,
    /// The same in samples of the log.
    pub delay_xcorr_samples: Option<f64>,
    /// The delay from the slope of the FRF's phase over the fitted band
    /// (s): the group delay averaged over it. It differs from the
    /// cross-correlation's when the plant is not a pure delay.
    pub delay_phase_slope_s: Option<f64>,
    /// The frequency evaluation index (Guo et al. 2014).
    pub fei: Option<FrequencyEvaluation>,
    /// The tracking indicator TI of Mercan & Ricles (2007) at the end of
    /// the record (m^2): negative when the displacement lagged overall.
    pub tracking_indicator_m2: Option<f64>,
    /// TI over the square of the larger peak of the two records (%).
    pub tracking_indicator_pct: Option<f64>,
    /// J2 and J3 of the RTHS benchmark (Silva et al. 2020).
    pub errors: Option<TrackingErrors>,
    /// The same in the paper's windows of a sweep (Figs. 9, 12, 14, 19-22),
    /// where the command's frequency is about one: the amplitude and phase
    /// of the tracking at that frequency.
    pub windows: Vec<WindowTracking>,
    /// Why a measure is absent, each naming it.
    pub notes: Vec<String>,
}

/// The tracking in one window of the record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct WindowTracking {
    pub label: String,
    pub start_s: f64,
    pub end_s: f64,
    pub fei: Option<FrequencyEvaluation>,
    pub errors: Option<TrackingErrors>,
}

/// An FRF's bins as the phase slope takes them: frequencies (Hz), the
/// estimate at each, and which to use (the fitted band, where the
/// coherence is enough).
#[derive(Debug, Clone, Copy)]
pub struct FrfBins<'a> {
    pub freq_hz: &'a [f64],
    pub h: &'a [Complex<f64>],
    pub keep: &'a [bool],
}

/// Every tracking measure of `displacement` against the command
/// `reference` (m, sampled at `sample_rate_hz`), with the phase slope from
/// `frf` when given, over the whole record and in each of `windows`.
pub fn measure(
    reference: &Reference<'_>,
    displacement: &[f64],
    sample_rate_hz: f64,
    frf: Option<FrfBins<'_>>,
    windows: &[Window],
) -> Tracking {
    let command = reference.samples;
    let n = command.len().min(displacement.len());
    let windows = windows
        .iter()
        .map(|w| {
            let r = window_range(w, sample_rate_hz, n);
            let (c, d) = (&command[r.clone()], &displacement[r]);
            WindowTracking {
                label: w.label.clone(),
                start_s: w.start_s,
                end_s: w.end_s,
                fei: frequency_evaluation(&Reference::new(c), d, sample_rate_hz).ok(),
                errors: tracking_errors(c, d),
            }
        })
        .collect();
    let mut notes = Vec::new();
    let xcorr = xcorr_delay(reference, displacement, sample_rate_hz, MAX_DELAY_S)
        .map_err(|e| notes.push(format!("delay by cross-correlation: {e}")))
        .ok();
    let slope = match frf {
        Some(b) => phase_slope_delay(b.freq_hz, b.h, b.keep)
            .map_err(|e| notes.push(format!("delay from the FRF's phase: {e}")))
            .ok(),
        None => None,
    };
    let fei = frequency_evaluation(reference, displacement, sample_rate_hz)
        .map_err(|e| notes.push(format!("frequency evaluation index: {e}")))
        .ok();
    let ti = tracking_indicator(command, displacement);
    let errors = tracking_errors(command, displacement);
    if errors.is_none() {
        notes.push("tracking errors: the command is zero throughout".into());
    }
    Tracking {
        delay_xcorr_s: xcorr,
        delay_xcorr_samples: xcorr.map(|d| d * sample_rate_hz),
        delay_phase_slope_s: slope,
        fei,
        tracking_indicator_m2: ti.map(|t| t.0),
        tracking_indicator_pct: ti.map(|t| t.1),
        errors,
        windows,
        notes,
    }
}
