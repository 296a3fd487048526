//! How well the actuator follows its command: the tracking measures an RTHS
//! lab reads of a run, each from the command and the measured (or
//! predicted) displacement alone, so that one function gives a log's
//! measured tracking and the tracking the identified model predicts.
//!
//! - the delay by cross-correlation ([`delay::xcorr_delay`]) and by the
//!   slope of the FRF's phase ([`delay::phase_slope_delay`]);
//! - the frequency evaluation index ([`frequency_evaluation`]: Guo, Chen,
//!   Xu & Sanchez 2014);
//! - the tracking indicator ([`tracking_indicator`]: Mercan & Ricles 2007);
//! - the tracking error's normalised RMS and peak ([`tracking_errors`]: J2
//!   and J3 of the RTHS benchmark, Silva et al. 2020).
//!
//! Pure. Displacements in m, times in s; a positive delay is a displacement
//! that lags its command. Definitions: docs/tracking.md, "The measures".

pub mod compensator;
pub mod delay;

#[cfg(test)]
mod tests;

use std::ops::Range;
use std::sync::{Arc, Mutex, OnceLock};

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
/// measured against the same command, so what every measure reads of the
/// command alone is formed here, once, when first read: its Hilbert
/// transform and power (the frequency evaluation index), its
/// autocorrelation at the refinement's lags (the cross-correlation's
/// refinement), and the same for each window of it a measure asks for.
#[derive(Debug)]
pub struct Reference<'a> {
    samples: &'a [f64],
    mean: f64,
    spectrum: std::borrow::Cow<'a, [Complex<f64>]>,
    fei: OnceLock<FeiTerms>,
    autocorrelation: OnceLock<[f64; delay::LAGS]>,
    parts: Mutex<Vec<(Range<usize>, Arc<Reference<'a>>)>>,
}

/// What the frequency evaluation index reads of the command alone.
#[derive(Debug)]
struct FeiTerms {
    /// The command's discrete Hilbert transform: the inverse DFT of
    /// `-i sgn(k) U_k`, DC and Nyquist zero, `U` the one-sided DFT of the
    /// command less its mean.
    hilbert: Vec<f64>,
    /// `sum_k |U_k|^2` over the one-sided bins but DC.
    power: f64,
    /// `sum_k k |U_k|^2` over the same bins.
    weighted_bin: f64,
}

impl<'a> Reference<'a> {
    pub fn new(command: &'a [f64]) -> Self {
        let mean = mean(command);
        Self::of(command, mean, centred_spectrum(command, mean).into())
    }

    /// The command with its mean and its spectrum less the mean, nothing
    /// else made yet.
    fn of(samples: &'a [f64], mean: f64, spectrum: std::borrow::Cow<'a, [Complex<f64>]>) -> Self {
        Self {
            samples,
            mean,
            spectrum,
            fei: OnceLock::new(),
            autocorrelation: OnceLock::new(),
            parts: Mutex::new(Vec::new()),
        }
    }

    /// As [`Self::new`], with the command's one-sided DFT less its mean
    /// already made (the whole-record FRF's, `frf::estimate_sharing`):
    /// the same transform, its mean summed in another order, so the
    /// measures may differ in their last bits. A `spectrum` of another
    /// length than the command's is not it, and the command is
    /// transformed here.
    pub fn with_spectrum(command: &'a [f64], spectrum: &'a [Complex<f64>]) -> Self {
        if spectrum.len() != command.len() / 2 + 1 || command.is_empty() {
            return Self::new(command);
        }
        Self::of(command, mean(command), spectrum.into())
    }

    /// The command's samples.
    pub fn samples(&self) -> &'a [f64] {
        self.samples
    }

    /// The command's samples `range`, prepared once however many measures
    /// read them.
    fn part(&self, range: Range<usize>) -> Arc<Reference<'a>> {
        let mut parts = self.parts.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((_, r)) = parts.iter().find(|(r, _)| *r == range) {
            return Arc::clone(r);
        }
        let part = Arc::new(Reference::new(&self.samples[range.clone()]));
        parts.push((range, Arc::clone(&part)));
        part
    }

    /// The same command cut to its first `n` samples (a displacement
    /// shorter than its command is measured against as much of it).
    fn first(&self, n: usize) -> MaybeOwned<'_, 'a> {
        if n >= self.samples.len() {
            MaybeOwned::Borrowed(self)
        } else {
            MaybeOwned::Owned(Box::new(Reference::new(&self.samples[..n])))
        }
    }

    fn fei_terms(&self) -> &FeiTerms {
        self.fei.get_or_init(|| {
            let n = self.samples.len();
            let even = n.is_multiple_of(2);
            let last = self.spectrum.len().saturating_sub(1);
            let (mut power, mut weighted_bin) = (0.0, 0.0);
            for (k, u) in self.spectrum.iter().enumerate().skip(1) {
                let p = u.norm_sqr();
                power += p;
                weighted_bin += p * k as f64;
            }
            let mut y: Vec<Complex<f64>> = self
                .spectrum
                .iter()
                .enumerate()
                .map(|(k, u)| {
                    if k == 0 || (even && k == last) {
                        Complex::new(0.0, 0.0)
                    } else {
                        Complex::new(u.im, -u.re)
                    }
                })
                .collect();
            let mut hilbert = vec![0.0; n];
            if n > 0 {
                crate::fft::real_inverse(n)
                    .process(&mut y, &mut hilbert)
                    .expect("lengths come from the plan");
            }
            for h in &mut hilbert {
                *h /= n as f64;
            }
            FeiTerms {
                hilbert,
                power,
                weighted_bin,
            }
        })
    }

    /// `A[d] = sum_s (u[s] - mean)(u[s - d] - mean)` over `s` in `d..n`,
    /// for `d` below the refinement's lag count.
    fn autocorrelation(&self) -> &[f64; delay::LAGS] {
        self.autocorrelation.get_or_init(|| {
            const L: usize = delay::LAGS;
            let c: Vec<f64> = self.samples.iter().map(|v| v - self.mean).collect();
            let mut a = [0.0; L];
            for s in 0..c.len().min(L - 1) {
                for d in 0..=s {
                    a[d] += c[s] * c[s - d];
                }
            }
            for s in L - 1..c.len() {
                // c[s - d] is window[L - 1 - d]: one bounds check a sample.
                let window: &[f64; L] = c[s + 1 - L..=s].try_into().expect("L samples");
                for d in 0..L {
                    a[d] += window[L - 1] * window[L - 1 - d];
                }
            }
            a
        })
    }
}

/// A reference borrowed, or made for a shorter displacement.
enum MaybeOwned<'r, 'a> {
    Borrowed(&'r Reference<'a>),
    Owned(Box<Reference<'a>>),
}

impl<'a> std::ops::Deref for MaybeOwned<'_, 'a> {
    type Target = Reference<'a>;
    fn deref(&self) -> &Reference<'a> {
        match self {
            MaybeOwned::Borrowed(r) => r,
            MaybeOwned::Owned(r) => r,
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
    let cross = fei_cross(&reference, x);
    let terms = reference.fei_terms();
    let (power, weighted_f) = (terms.power, terms.weighted_bin * sample_rate_hz / n as f64);
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

/// `sum_k X_k conj(U_k)` over the one-sided bins but DC, `X` and `U` the
/// DFTs of the displacement `x` and the command, each less its mean, by
/// Parseval from two sums over the samples instead of a transform of `x`.
/// With `S` the sum over `0 < k < n/2`:
///
/// - `sum_t x[t] u[t] = (X_0 U_0 + 2 Re S + X_N U_N) / n` (the Nyquist term
///   for even `n` only), and
/// - `sum_t x[t] h[t] = -2 Im S / n`, `h` the command's Hilbert transform
///   (the DFT `-i sgn(k) U_k`),
///
/// and the sum wanted is `S` plus the Nyquist bin's `X_N U_N`.
fn fei_cross(reference: &Reference<'_>, x: &[f64]) -> Complex<f64> {
    let n = x.len();
    let (u, mu, mx) = (reference.samples, reference.mean, mean(x));
    let h = &reference.fei_terms().hilbert;
    let (mut xu, mut xh, mut x0, mut xn) = (0.0, 0.0, 0.0, 0.0);
    for t in 0..n {
        let xt = x[t] - mx;
        xu += xt * (u[t] - mu);
        xh += xt * h[t];
        x0 += xt;
        xn += if t % 2 == 0 { xt } else { -xt };
    }
    let spectrum = &reference.spectrum;
    let u0 = spectrum[0].re;
    let nyquist = if n.is_multiple_of(2) {
        xn * spectrum[spectrum.len() - 1].re
    } else {
        0.0
    };
    let nf = n as f64;
    Complex::new((nf * xu - x0 * u0 + nyquist) / 2.0, -nf / 2.0 * xh)
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
/// b sin(wt - phi)` it falls by `pi a b sin(phi)` a cycle: TI at the end
/// of the record (m^2, as the records' unit). None for fewer than two
/// samples or records that are zero throughout; runs compare by
/// [`tracking_indicator_per_cycle`].
pub fn tracking_indicator(command: &[f64], displacement: &[f64]) -> Option<f64> {
    let n = command.len().min(displacement.len());
    let (xc, xm) = (&command[..n], &displacement[..n]);
    let moves = xc.iter().chain(xm).any(|v| *v != 0.0);
    (n >= 2 && moves).then(|| indicator_over(xc, xm))
}

/// TI over the samples given, by the trapezoidal rule.
fn indicator_over(xc: &[f64], xm: &[f64]) -> f64 {
    let mut ti = 0.0;
    for i in 1..xc.len().min(xm.len()) {
        let a = 0.5 * (xm[i] + xm[i - 1]) * (xc[i] - xc[i - 1]);
        let ta = 0.5 * (xc[i] + xc[i - 1]) * (xm[i] - xm[i - 1]);
        ti += 0.5 * (a - ta);
    }
    ti
}

/// TI over the command's whole cycles (from one upward zero crossing to
/// the next) as a percentage of the area a lag of 90 degrees would enclose
/// in them, pi a_k b_k a cycle with a_k and b_k half the command's and the
/// displacement's range in cycle k: -100 sin(phi) for a sine lagging by
/// phi, whatever its amplitude, frequency or length, so two runs compare.
/// None without a whole cycle.
pub fn tracking_indicator_per_cycle(command: &[f64], displacement: &[f64]) -> Option<f64> {
    let n = command.len().min(displacement.len());
    let up: Vec<usize> = (1..n)
        .filter(|&i| command[i - 1] < 0.0 && command[i] >= 0.0)
        .collect();
    let half_range = |x: &[f64]| {
        let (lo, hi) = x
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
                (l.min(v), h.max(v))
            });
        0.5 * (hi - lo)
    };
    let mut area = 0.0;
    for w in up.windows(2) {
        let (i, j) = (w[0], w[1]);
        area +=
            std::f64::consts::PI * half_range(&command[i..=j]) * half_range(&displacement[i..=j]);
    }
    let (&first, &last) = (up.first()?, up.last()?);
    (area > 0.0)
        .then(|| 100.0 * indicator_over(&command[first..=last], &displacement[first..=last]) / area)
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
    /// TI over the command's whole cycles as a percentage of the area a
    /// 90-degree lag would enclose in them (-100 sin(phi) for a sine
    /// lagging by phi).
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
            let (c, d) = (&command[r.clone()], &displacement[r.clone()]);
            WindowTracking {
                label: w.label.clone(),
                start_s: w.start_s,
                end_s: w.end_s,
                fei: frequency_evaluation(&reference.part(r), d, sample_rate_hz).ok(),
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
    let ti_per_cycle = tracking_indicator_per_cycle(command, displacement);
    let errors = tracking_errors(command, displacement);
    if errors.is_none() {
        notes.push("tracking errors: the command is zero throughout".into());
    }
    Tracking {
        delay_xcorr_s: xcorr,
        delay_xcorr_samples: xcorr.map(|d| d * sample_rate_hz),
        delay_phase_slope_s: slope,
        fei,
        tracking_indicator_m2: ti,
        tracking_indicator_pct: ti_per_cycle,
        errors,
        windows,
        notes,
    }
}
