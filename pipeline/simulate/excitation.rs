//! Command signals u(t) for simulated tests: swept sines (linear, quadratic
//! after MATLAB's `chirp`, logarithmic), random-phase multisines,
//! band-limited Gaussian noise and square waves (servo tuning), sampled at
//! t_k = k / fs with zero lead-in and lead-out, and the controller's command
//! limit ([`limit`]).
//!
//! The excitation itself has N = round(duration_s * fs) samples. Multisines
//! and random-band noise are periodic over those N samples (period N / fs,
//! frequencies on the grid k fs / N), so their spectrum is exact: energy only
//! in the requested bins, nothing leaks.

use nalgebra::Complex;
use rand::Rng;
use rand_distr::StandardNormal;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

use super::{fft, seeded_rng};

/// How a chirp's instantaneous frequency moves from f0 to f1 over t1.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum ChirpLaw {
    /// f(t) = f0 + (f1 - f0) t / t1.
    Linear,
    /// f(t) = f0 + (f1 - f0) (t / t1)^2, as MATLAB's `chirp(t, f0, t1, f1,
    /// 'quadratic')`; the paper's command (0.1 -> 35 Hz over about 170 s).
    Quadratic,
    /// f(t) = f0 (f1 / f0)^(t / t1) (exponential sweep; f0, f1 > 0).
    Logarithmic,
}

/// A command signal, in metres of command displacement.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Excitation {
    /// u(t) = amplitude sin(phase(t)), phase(0) = 0.
    Chirp {
        law: ChirpLaw,
        f0_hz: f64,
        f1_hz: f64,
        duration_s: f64,
        amplitude_m: f64,
    },
    /// `n_tones` equal-amplitude sines on distinct bins of the k fs / N grid,
    /// linearly spaced over [f_min_hz, f_max_hz], with random phases;
    /// periodic over the duration, rms exactly `rms_m`.
    Multisine {
        f_min_hz: f64,
        f_max_hz: f64,
        n_tones: usize,
        rms_m: f64,
        duration_s: f64,
        seed: u64,
    },
    /// Gaussian noise shaped in the frequency domain: independent complex
    /// Gaussian coefficients on every bin of the k fs / N grid inside
    /// [f_min_hz, f_max_hz] (DC excluded), zero elsewhere; periodic over the
    /// duration, scaled to rms exactly `rms_m`.
    RandomBand {
        f_min_hz: f64,
        f_max_hz: f64,
        rms_m: f64,
        duration_s: f64,
        seed: u64,
    },
    /// +amplitude for the first half of each period, -amplitude for the
    /// second; each edge (at multiples of period_s / 2) moved to the sample
    /// nearest it, halfway between two samples to the later one, so the
    /// sampled command holds exact plateaus.
    Square {
        amplitude_m: f64,
        period_s: f64,
        duration_s: f64,
    },
    /// A random-odd multisine (`multisine::odd_multisine`): flat lines on
    /// the odd harmonics of 1 / period_s in [f_min_hz, f_max_hz], one of
    /// each three left out to detect odd distortion, its crest factor
    /// lowered; the period repeated over duration_s (a whole number of
    /// periods, at least three), faded in over the first period and out
    /// over the last, so that the command starts and ends at rest. rms_m
    /// is a whole period's.
    OddMultisine {
        f_min_hz: f64,
        f_max_hz: f64,
        rms_m: f64,
        period_s: f64,
        duration_s: f64,
        seed: u64,
    },
}

/// Zeros before and after the excitation (s).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct Padding {
    pub lead_in_s: f64,
    pub lead_out_s: f64,
}

/// Why an excitation cannot be generated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ExcitationError {
    #[error("{name} must be positive and finite (got {value})")]
    NotPositive { name: &'static str, value: f64 },
    #[error("{name} must be finite and non-negative (got {value})")]
    Negative { name: &'static str, value: f64 },
    #[error(
        "{name} = {value_hz} Hz is at or above the Nyquist frequency {nyquist_hz} Hz (sample_rate_hz = {sample_rate_hz})"
    )]
    AboveNyquist {
        name: &'static str,
        value_hz: f64,
        nyquist_hz: f64,
        sample_rate_hz: f64,
    },
    #[error("f_min_hz ({f_min_hz} Hz) must be below f_max_hz ({f_max_hz} Hz)")]
    BandOrder { f_min_hz: f64, f_max_hz: f64 },
    #[error("n_tones must be at least 1 (got 0)")]
    NoTones,
    #[error(
        "period_s = {period_s} s at sample_rate_hz = {sample_rate_hz} spans {samples} sample(s); a square wave needs at least 2"
    )]
    PeriodTooShort {
        period_s: f64,
        sample_rate_hz: f64,
        samples: f64,
    },
    #[error(
        "a logarithmic chirp needs f0_hz > 0 and f1_hz > 0 (got f0_hz = {f0_hz}, f1_hz = {f1_hz})"
    )]
    LogChirpFrequency { f0_hz: f64, f1_hz: f64 },
    #[error(
        "duration_s = {duration_s} s at sample_rate_hz = {sample_rate_hz} gives {samples} sample(s); at least 2 are needed"
    )]
    TooShort {
        duration_s: f64,
        sample_rate_hz: f64,
        samples: usize,
    },
    #[error(
        "the band {f_min_hz}-{f_max_hz} Hz holds {available} bin(s) of the {resolution_hz} Hz grid (1/duration_s) but n_tones = {n_tones}"
    )]
    TooManyTones {
        f_min_hz: f64,
        f_max_hz: f64,
        n_tones: usize,
        available: usize,
        resolution_hz: f64,
    },
    #[error(
        "duration_s = {duration_s} s is {periods} periods of period_s = {period_s} s; an odd multisine needs a whole number of periods, at least 3 (one fading in, one at least steady, one fading out)"
    )]
    Periods {
        duration_s: f64,
        period_s: f64,
        periods: f64,
    },
    #[error(
        "the band {f_min_hz}-{f_max_hz} Hz holds no odd harmonic of 1/period_s = {resolution_hz} Hz; lengthen period_s or widen the band"
    )]
    NoOddLine {
        f_min_hz: f64,
        f_max_hz: f64,
        resolution_hz: f64,
    },
    #[error(
        "the band {f_min_hz}-{f_max_hz} Hz contains no bin of the {resolution_hz} Hz grid (1/duration_s) above DC; lengthen duration_s or widen the band"
    )]
    EmptyBand {
        f_min_hz: f64,
        f_max_hz: f64,
        resolution_hz: f64,
    },
}

fn positive(name: &'static str, value: f64) -> Result<(), ExcitationError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(ExcitationError::NotPositive { name, value })
    }
}

fn non_negative(name: &'static str, value: f64) -> Result<(), ExcitationError> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(ExcitationError::Negative { name, value })
    }
}

fn below_nyquist(name: &'static str, value_hz: f64, fs: f64) -> Result<(), ExcitationError> {
    if value_hz < fs / 2.0 {
        Ok(())
    } else {
        Err(ExcitationError::AboveNyquist {
            name,
            value_hz,
            nyquist_hz: fs / 2.0,
            sample_rate_hz: fs,
        })
    }
}

impl Excitation {
    /// Duration of the excitation itself (s), without padding.
    pub fn duration_s(&self) -> f64 {
        match *self {
            Excitation::Chirp { duration_s, .. }
            | Excitation::Multisine { duration_s, .. }
            | Excitation::RandomBand { duration_s, .. }
            | Excitation::Square { duration_s, .. }
            | Excitation::OddMultisine { duration_s, .. } => duration_s,
        }
    }

    /// Checks the parameters against the sample rate (Hz).
    pub fn validate(&self, sample_rate_hz: f64) -> Result<(), ExcitationError> {
        positive("sample_rate_hz", sample_rate_hz)?;
        let fs = sample_rate_hz;
        let duration_s = self.duration_s();
        positive("duration_s", duration_s)?;
        let samples = excitation_len(duration_s, fs);
        if samples < 2 {
            return Err(ExcitationError::TooShort {
                duration_s,
                sample_rate_hz: fs,
                samples,
            });
        }
        match *self {
            Excitation::Chirp {
                law,
                f0_hz,
                f1_hz,
                amplitude_m,
                ..
            } => {
                if law == ChirpLaw::Logarithmic && !(f0_hz > 0.0 && f1_hz > 0.0) {
                    return Err(ExcitationError::LogChirpFrequency { f0_hz, f1_hz });
                }
                non_negative("f0_hz", f0_hz)?;
                positive("f1_hz", f1_hz)?;
                below_nyquist("f0_hz", f0_hz, fs)?;
                below_nyquist("f1_hz", f1_hz, fs)?;
                positive("amplitude_m", amplitude_m)?;
            }
            Excitation::Multisine {
                f_min_hz,
                f_max_hz,
                n_tones,
                rms_m,
                ..
            } => {
                band(f_min_hz, f_max_hz, fs)?;
                positive("rms_m", rms_m)?;
                if n_tones == 0 {
                    return Err(ExcitationError::NoTones);
                }
                let bins = band_bins(f_min_hz, f_max_hz, fs, samples)?;
                let available = bins.end - bins.start;
                if n_tones > available {
                    return Err(ExcitationError::TooManyTones {
                        f_min_hz,
                        f_max_hz,
                        n_tones,
                        available,
                        resolution_hz: fs / samples as f64,
                    });
                }
            }
            Excitation::RandomBand {
                f_min_hz,
                f_max_hz,
                rms_m,
                ..
            } => {
                band(f_min_hz, f_max_hz, fs)?;
                positive("rms_m", rms_m)?;
                band_bins(f_min_hz, f_max_hz, fs, samples)?;
            }
            Excitation::Square {
                amplitude_m,
                period_s,
                ..
            } => {
                positive("amplitude_m", amplitude_m)?;
                positive("period_s", period_s)?;
                // Two samples a period: one per level at the least.
                if period_s * fs < 2.0 {
                    return Err(ExcitationError::PeriodTooShort {
                        period_s,
                        sample_rate_hz: fs,
                        samples: period_s * fs,
                    });
                }
            }
            Excitation::OddMultisine {
                f_min_hz,
                f_max_hz,
                rms_m,
                period_s,
                duration_s,
                ..
            } => odd_multisine_fits(f_min_hz, f_max_hz, rms_m, period_s, duration_s, fs)?,
        }
        Ok(())
    }
}

/// Whether `duration_s` holds a whole number of periods of `period_s`, at
/// least three: an odd multisine's first fades in, its last fades out, and
/// one at least between them is steady.
pub fn whole_periods(duration_s: f64, period_s: f64) -> bool {
    let periods = duration_s / period_s;
    (periods - periods.round()).abs() <= 1e-9 * periods && periods.round() >= 3.0
}

/// An odd multisine's settings checked: its band, a whole number of
/// periods (at least three) and an odd harmonic of 1 / period_s in the band.
fn odd_multisine_fits(
    f_min_hz: f64,
    f_max_hz: f64,
    rms_m: f64,
    period_s: f64,
    duration_s: f64,
    fs: f64,
) -> Result<(), ExcitationError> {
    band(f_min_hz, f_max_hz, fs)?;
    positive("rms_m", rms_m)?;
    positive("period_s", period_s)?;
    if !whole_periods(duration_s, period_s) {
        let periods = duration_s / period_s;
        return Err(ExcitationError::Periods {
            duration_s,
            period_s,
            periods,
        });
    }
    let res = 1.0 / period_s;
    // The first odd harmonic at or above f_min_hz.
    let k = ((f_min_hz / res) * (1.0 - 1e-12)).ceil().max(1.0) as usize;
    if (k | 1) as f64 * res > f_max_hz * (1.0 + 1e-12) {
        return Err(ExcitationError::NoOddLine {
            f_min_hz,
            f_max_hz,
            resolution_hz: res,
        });
    }
    Ok(())
}

fn band(f_min_hz: f64, f_max_hz: f64, fs: f64) -> Result<(), ExcitationError> {
    non_negative("f_min_hz", f_min_hz)?;
    positive("f_max_hz", f_max_hz)?;
    if f_min_hz >= f_max_hz {
        return Err(ExcitationError::BandOrder { f_min_hz, f_max_hz });
    }
    below_nyquist("f_max_hz", f_max_hz, fs)
}

/// Number of samples of the excitation itself.
fn excitation_len(duration_s: f64, fs: f64) -> usize {
    (duration_s * fs).round() as usize
}

/// Bins k (frequency k fs / N) inside [f_min, f_max], above DC and below
/// Nyquist. A small relative slack keeps a band edge that is exactly on the
/// grid (e.g. 1 Hz with a 0.5 Hz resolution) inside despite round-off.
fn band_bins(
    f_min_hz: f64,
    f_max_hz: f64,
    fs: f64,
    n: usize,
) -> Result<std::ops::Range<usize>, ExcitationError> {
    let res = fs / n as f64;
    let lo = ((f_min_hz / res) * (1.0 - 1e-12)).ceil().max(1.0) as usize;
    let hi_nyquist = (n - 1) / 2; // largest k with k < N/2
    let hi = (((f_max_hz / res) * (1.0 + 1e-12)).floor() as usize).min(hi_nyquist);
    if hi < lo {
        return Err(ExcitationError::EmptyBand {
            f_min_hz,
            f_max_hz,
            resolution_hz: res,
        });
    }
    Ok(lo..hi + 1)
}

/// The sampled command u(k / fs) with `padding` zeros around the excitation.
pub fn generate(
    exc: &Excitation,
    sample_rate_hz: f64,
    padding: Padding,
) -> Result<Vec<f64>, ExcitationError> {
    exc.validate(sample_rate_hz)?;
    non_negative("lead_in_s", padding.lead_in_s)?;
    non_negative("lead_out_s", padding.lead_out_s)?;
    let fs = sample_rate_hz;
    let n = excitation_len(exc.duration_s(), fs);
    let body = match *exc {
        Excitation::Chirp { amplitude_m, .. } => (0..n)
            .map(|k| amplitude_m * chirp_phase(exc, k as f64 / fs).sin())
            .collect(),
        Excitation::Multisine {
            f_min_hz,
            f_max_hz,
            n_tones,
            rms_m,
            seed,
            ..
        } => {
            let bins = band_bins(f_min_hz, f_max_hz, fs, n)?;
            let mut rng = seeded_rng(seed, "excitation/multisine");
            // Equal amplitudes A on distinct bins strictly between DC and
            // Nyquist: mean square over one period is n_tones A^2 / 2 exactly.
            let amp = rms_m * (2.0 / n_tones as f64).sqrt();
            let mut spectrum = vec![Complex::new(0.0, 0.0); n];
            for k in tone_bins(&bins, n_tones) {
                let phase = 2.0 * PI * rng.random::<f64>();
                spectrum[k] = Complex::from_polar(amp, phase);
            }
            fft::inverse_dft(&spectrum).iter().map(|c| c.re).collect()
        }
        Excitation::RandomBand {
            f_min_hz,
            f_max_hz,
            rms_m,
            seed,
            ..
        } => {
            let bins = band_bins(f_min_hz, f_max_hz, fs, n)?;
            let mut rng = seeded_rng(seed, "excitation/random_band");
            let mut spectrum = vec![Complex::new(0.0, 0.0); n];
            for k in bins {
                let re: f64 = rng.sample(StandardNormal);
                let im: f64 = rng.sample(StandardNormal);
                spectrum[k] = Complex::new(re, im);
            }
            // Real part of the one-sided synthesis: a real signal whose DFT is
            // (X_k + conj(X_{N-k})) / 2, still zero outside the band.
            let mut x: Vec<f64> = fft::inverse_dft(&spectrum).iter().map(|c| c.re).collect();
            let rms = (x.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
            for v in &mut x {
                *v *= rms_m / rms;
            }
            x
        }
        Excitation::Square {
            amplitude_m,
            period_s,
            ..
        } => square(amplitude_m, period_s, fs, n),
        Excitation::OddMultisine {
            f_min_hz,
            f_max_hz,
            rms_m,
            period_s,
            seed,
            ..
        } => {
            let len = (period_s * fs).round() as usize;
            let mut rng = seeded_rng(seed, "excitation/odd_multisine");
            let m = super::multisine::odd_multisine(f_min_hz, f_max_hz, fs, len, rms_m, &mut rng)
                .ok_or(ExcitationError::NoOddLine {
                f_min_hz,
                f_max_hz,
                resolution_hz: 1.0 / period_s,
            })?;
            faded(&m.period, n)
        }
    };
    Ok(pad(body, fs, padding))
}

/// A command `body` sampled at `sample_rate_hz` (a command file's) with
/// `padding` zeros around it.
pub fn padded(
    body: Vec<f64>,
    sample_rate_hz: f64,
    padding: Padding,
) -> Result<Vec<f64>, ExcitationError> {
    positive("sample_rate_hz", sample_rate_hz)?;
    non_negative("lead_in_s", padding.lead_in_s)?;
    non_negative("lead_out_s", padding.lead_out_s)?;
    Ok(pad(body, sample_rate_hz, padding))
}

fn pad(body: Vec<f64>, fs: f64, padding: Padding) -> Vec<f64> {
    let lead_in = (padding.lead_in_s * fs).round() as usize;
    let lead_out = (padding.lead_out_s * fs).round() as usize;
    let mut u = vec![0.0; lead_in];
    u.reserve(body.len() + lead_out);
    u.extend(body);
    u.resize(u.len() + lead_out, 0.0);
    u
}

/// `n` samples of a square wave of levels +-`amplitude_m` and period
/// `period_s` at `fs`.
fn square(amplitude_m: f64, period_s: f64, fs: f64, n: usize) -> Vec<f64> {
    // Edge j (at j period_s / 2) falls on sample round(j half); f64::round
    // takes a tie away from zero, to the later sample.
    let half = 0.5 * period_s * fs;
    let mut body = Vec::with_capacity(n);
    let mut level = amplitude_m;
    let mut j = 1usize;
    let mut next = half.round() as usize;
    for k in 0..n {
        while k >= next {
            level = -level;
            j += 1;
            next = (j as f64 * half).round() as usize;
        }
        body.push(level);
    }
    body
}

/// `period` repeated over `n` samples, faded in over the first period and
/// out over the last by a raised cosine, so that the command leaves rest
/// and returns to it smoothly.
pub fn faded(period: &[f64], n: usize) -> Vec<f64> {
    let p = period.len();
    (0..n)
        .map(|j| {
            let ramp = |i: usize| 0.5 * (1.0 - (PI * i as f64 / p as f64).cos());
            let w = if j < p {
                ramp(j)
            } else if j >= n - p {
                ramp(n - j)
            } else {
                1.0
            };
            w * period[j % p]
        })
        .collect()
}

/// Clamps the command to +-`limit_m`, as a controller's command limit does
/// before the servo-valve: the command the plant sees and the log records
/// is the clamped one.
pub fn limit(u: &mut [f64], limit_m: f64) -> Result<(), ExcitationError> {
    positive("limit_m", limit_m)?;
    for v in u {
        *v = v.clamp(-limit_m, limit_m);
    }
    Ok(())
}

/// `n_tones` distinct bins linearly spaced over `bins` (which holds at least
/// `n_tones`): k_i = lo + round(i (hi - lo) / (n_tones - 1)); the spacing is
/// at least one bin, so rounding keeps them distinct.
fn tone_bins(bins: &std::ops::Range<usize>, n_tones: usize) -> Vec<usize> {
    let lo = bins.start;
    let span = (bins.end - 1 - lo) as f64;
    if n_tones == 1 {
        return vec![lo];
    }
    (0..n_tones)
        .map(|i| lo + (i as f64 * span / (n_tones - 1) as f64).round() as usize)
        .collect()
}

/// The chirp's phase (rad) at t from its start.
fn chirp_phase(exc: &Excitation, t: f64) -> f64 {
    let Excitation::Chirp {
        law,
        f0_hz: f0,
        f1_hz: f1,
        duration_s: t1,
        ..
    } = *exc
    else {
        return 0.0;
    };
    let cycles = match law {
        ChirpLaw::Linear => f0 * t + (f1 - f0) * t * t / (2.0 * t1),
        ChirpLaw::Quadratic => f0 * t + (f1 - f0) * t * t * t / (3.0 * t1 * t1),
        ChirpLaw::Logarithmic => {
            let r = (f1 / f0).ln();
            if r.abs() < 1e-12 {
                f0 * t
            } else {
                // Integral of f0 exp(r t / t1): f0 t1 / r (exp(r t / t1) - 1).
                f0 * t1 / r * (r * t / t1).exp_m1()
            }
        }
    };
    2.0 * PI * cycles
}

/// A chirp's instantaneous frequency (Hz) at `t_s` from its start; `None` for
/// other excitations or outside [0, duration_s].
pub fn instantaneous_frequency_hz(exc: &Excitation, t_s: f64) -> Option<f64> {
    let Excitation::Chirp {
        law,
        f0_hz: f0,
        f1_hz: f1,
        duration_s: t1,
        ..
    } = *exc
    else {
        return None;
    };
    if !(0.0..=t1).contains(&t_s) {
        return None;
    }
    let x = t_s / t1;
    Some(match law {
        ChirpLaw::Linear => f0 + (f1 - f0) * x,
        ChirpLaw::Quadratic => f0 + (f1 - f0) * x * x,
        ChirpLaw::Logarithmic => f0 * (f1 / f0).powf(x),
    })
}

/// The time (s from the chirp's start) at which a chirp passes `f_hz`; `None`
/// for other excitations, for a frequency the sweep never reaches, or for a
/// constant-frequency "sweep".
pub fn time_at_frequency_s(exc: &Excitation, f_hz: f64) -> Option<f64> {
    let Excitation::Chirp {
        law,
        f0_hz: f0,
        f1_hz: f1,
        duration_s: t1,
        ..
    } = *exc
    else {
        return None;
    };
    // A relative slack of 1e-12 accepts the end frequencies as computed by
    // `instantaneous_frequency_hz` despite round-off.
    let (lo, hi) = (f0.min(f1), f0.max(f1));
    if f0 == f1 || f_hz < lo * (1.0 - 1e-12) || f_hz > hi * (1.0 + 1e-12) {
        return None;
    }
    let f_hz = f_hz.clamp(lo, hi);
    let frac = (f_hz - f0) / (f1 - f0);
    let x = match law {
        ChirpLaw::Linear => frac,
        ChirpLaw::Quadratic => frac.sqrt(),
        ChirpLaw::Logarithmic => (f_hz / f0).ln() / (f1 / f0).ln(),
    };
    Some(x * t1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn paper_chirp() -> Excitation {
        Excitation::Chirp {
            law: ChirpLaw::Quadratic,
            f0_hz: 0.1,
            f1_hz: 35.0,
            duration_s: 170.0,
            amplitude_m: 2e-3,
        }
    }

    #[test]
    fn quadratic_chirp_follows_the_papers_time_frequency_map() {
        let c = paper_chirp();
        let f = |t| instantaneous_frequency_hz(&c, t).unwrap();
        // MATLAB's law by hand: f(t) = 0.1 + 34.9 (t / 170)^2.
        assert_relative_eq!(
            f(15.0),
            0.1 + 34.9 * (15.0_f64 / 170.0).powi(2),
            max_relative = 1e-14
        );
        // The paper's figures: < 0.5 Hz near 10-20 s (f(18 s) = 0.49 Hz;
        // f(20 s) = 0.58 Hz), about 2.5 Hz near 40-50 s, 18 Hz near
        // 120-122 s, 35 Hz at 170 s.
        assert!(f(10.0) < 0.5 && f(15.0) < 0.5 && f(18.0) < 0.5);
        assert!((2.0..3.2).contains(&f(40.0)) && (2.0..3.2).contains(&f(50.0)));
        assert!((f(45.0) - 2.5).abs() < 0.1, "{}", f(45.0));
        assert!((17.4..18.1).contains(&f(120.0)) && (17.4..18.1).contains(&f(122.0)));
        assert_relative_eq!(f(170.0), 35.0, max_relative = 1e-14);
        // The inverse: 18 Hz is reached at 170 sqrt(17.9 / 34.9) = 121.75 s.
        let t18 = time_at_frequency_s(&c, 18.0).unwrap();
        assert_relative_eq!(t18, 170.0 * (17.9_f64 / 34.9).sqrt(), max_relative = 1e-14);
        assert!((120.0..122.0).contains(&t18));
        assert_eq!(time_at_frequency_s(&c, 40.0), None);
        assert_eq!(instantaneous_frequency_hz(&c, 171.0), None);
    }

    #[test]
    fn generated_chirps_cross_zero_at_their_instantaneous_frequency() {
        // Independent of the phase formula: count zero crossings of the
        // generated samples in a 1 s window (2 per cycle) and compare with the
        // frequency law at the window's centre.
        let fs = 2048.0;
        let lead_in = 1.0;
        let padding = Padding {
            lead_in_s: lead_in,
            lead_out_s: 0.5,
        };
        for law in [ChirpLaw::Linear, ChirpLaw::Quadratic, ChirpLaw::Logarithmic] {
            let c = Excitation::Chirp {
                law,
                f0_hz: 0.5,
                f1_hz: 40.0,
                duration_s: 60.0,
                amplitude_m: 1e-3,
            };
            let u = generate(&c, fs, padding).unwrap();
            assert_eq!(u.len(), (61.5 * fs) as usize);
            assert!(u[..2048].iter().all(|v| *v == 0.0));
            assert!(u[u.len() - 1024..].iter().all(|v| *v == 0.0));
            for centre in [20.0, 45.0, 55.0] {
                let f = instantaneous_frequency_hz(&c, centre).unwrap();
                let a = ((lead_in + centre - 0.5) * fs) as usize;
                let b = ((lead_in + centre + 0.5) * fs) as usize;
                let crossings = u[a..b]
                    .windows(2)
                    .filter(|w| (w[0] < 0.0) != (w[1] < 0.0))
                    .count() as f64;
                // Over 1 s the frequency changes by at most f'(t), and a
                // crossing count is off by at most one.
                assert!(
                    (crossings / 2.0 - f).abs() < 0.6,
                    "{law:?} at {centre} s: {crossings} vs {f}"
                );
            }
            assert!(u.iter().all(|v| v.abs() <= 1e-3));
        }
    }

    #[test]
    fn time_at_frequency_inverts_the_frequency_law() {
        for law in [ChirpLaw::Linear, ChirpLaw::Quadratic, ChirpLaw::Logarithmic] {
            for (f0, f1) in [(0.2, 30.0), (30.0, 0.2)] {
                let c = Excitation::Chirp {
                    law,
                    f0_hz: f0,
                    f1_hz: f1,
                    duration_s: 100.0,
                    amplitude_m: 1.0,
                };
                for t in [0.0, 12.5, 50.0, 99.0, 100.0] {
                    let f = instantaneous_frequency_hz(&c, t).unwrap();
                    let back = time_at_frequency_s(&c, f).unwrap();
                    assert!((back - t).abs() < 1e-9, "{law:?} {f0}->{f1}: {t} vs {back}");
                }
            }
        }
        // Logarithmic law: geometric mean frequency at mid-sweep.
        let c = Excitation::Chirp {
            law: ChirpLaw::Logarithmic,
            f0_hz: 1.0,
            f1_hz: 100.0,
            duration_s: 10.0,
            amplitude_m: 1.0,
        };
        assert_relative_eq!(
            instantaneous_frequency_hz(&c, 5.0).unwrap(),
            10.0,
            max_relative = 1e-14
        );
    }

    /// |X_k|^2 of a real signal by the DFT's definition (the independent check
    /// of the FFT-based synthesis).
    fn naive_power(x: &[f64]) -> Vec<f64> {
        let n = x.len();
        (0..=n / 2)
            .map(|k| {
                let (mut re, mut im) = (0.0, 0.0);
                for (j, v) in x.iter().enumerate() {
                    let a = -2.0 * PI * ((j * k) % n) as f64 / n as f64;
                    re += v * a.cos();
                    im += v * a.sin();
                }
                re * re + im * im
            })
            .collect()
    }

    #[test]
    fn multisine_has_its_rms_and_energy_only_on_its_tones() {
        let fs = 200.0;
        let exc = Excitation::Multisine {
            f_min_hz: 2.0,
            f_max_hz: 30.0,
            n_tones: 15,
            rms_m: 1.5e-3,
            duration_s: 5.0,
            seed: 7,
        };
        let u = generate(&exc, fs, Padding::default()).unwrap();
        assert_eq!(u.len(), 1000);
        let rms = (u.iter().map(|v| v * v).sum::<f64>() / u.len() as f64).sqrt();
        assert_relative_eq!(rms, 1.5e-3, max_relative = 1e-12);
        let p = naive_power(&u);
        let total: f64 = p.iter().sum();
        // Resolution 0.2 Hz: band bins 10..=150; 15 tones, spacing 10 bins.
        let tones: Vec<usize> = (0..p.len()).filter(|&k| p[k] > 1e-20 * total).collect();
        let want: Vec<usize> = (0..15).map(|i| 10 + 10 * i).collect();
        assert_eq!(tones, want);
        // Equal amplitudes: each tone holds 1/15 of the power.
        for k in want {
            assert_relative_eq!(p[k], total / 15.0, max_relative = 1e-9);
        }
    }

    #[test]
    fn random_band_has_no_energy_outside_its_band() {
        let fs = 100.0;
        // N = 777 (odd, not a power of two: the Bluestein path).
        let exc = Excitation::RandomBand {
            f_min_hz: 5.0,
            f_max_hz: 20.0,
            rms_m: 2e-3,
            duration_s: 7.77,
            seed: 3,
        };
        let u = generate(&exc, fs, Padding::default()).unwrap();
        assert_eq!(u.len(), 777);
        let rms = (u.iter().map(|v| v * v).sum::<f64>() / u.len() as f64).sqrt();
        assert_relative_eq!(rms, 2e-3, max_relative = 1e-12);
        let p = naive_power(&u);
        let res = fs / 777.0;
        let (mut inside, mut outside) = (0.0, 0.0);
        for (k, v) in p.iter().enumerate() {
            let f = k as f64 * res;
            if (5.0..=20.0).contains(&f) {
                inside += v;
            } else {
                outside += v;
            }
        }
        // Round-off of two O(N log N) transforms and the naive DFT.
        assert!(
            outside < 1e-24 * inside,
            "outside/inside = {}",
            outside / inside
        );
        // Every in-band bin has energy (Gaussian coefficients are never zero).
        let lo = (5.0 / res).ceil() as usize;
        let hi = (20.0 / res).floor() as usize;
        assert!((lo..=hi).all(|k| p[k] > 1e-12 * inside / (hi - lo + 1) as f64));
    }

    #[test]
    fn same_seed_same_signal_other_seed_other_signal() {
        let make = |seed| Excitation::RandomBand {
            f_min_hz: 1.0,
            f_max_hz: 10.0,
            rms_m: 1.0,
            duration_s: 4.0,
            seed,
        };
        let a = generate(&make(1), 64.0, Padding::default()).unwrap();
        let b = generate(&make(1), 64.0, Padding::default()).unwrap();
        let c = generate(&make(2), 64.0, Padding::default()).unwrap();
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&a), bits(&b));
        let diff = a
            .iter()
            .zip(c.iter())
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max);
        assert!(diff > 0.1, "{diff}");
    }

    #[test]
    fn a_square_wave_holds_its_levels_and_switches_at_the_nearest_sample() {
        // 51.2 samples a half period: the edges at 51.2, 102.4, 153.6, 204.8
        // and 256 samples fall, rounded to the nearest, on samples 51, 102,
        // 154, 205 and 256 (by hand). Sample k lies in half period
        // floor((k + 1/2) / 51.2) counted from the nearest-sample edges
        // (no k + 1/2 is a multiple of 51.2, so no edge is a tie here).
        let (fs, period, amp) = (1024.0, 0.1, 2e-3);
        let exc = Excitation::Square {
            amplitude_m: amp,
            period_s: period,
            duration_s: 1.0,
        };
        let padding = Padding {
            lead_in_s: 0.25,
            lead_out_s: 0.125,
        };
        let u = generate(&exc, fs, padding).unwrap();
        assert_eq!(u.len(), 256 + 1024 + 128);
        assert!(u[..256].iter().chain(&u[256 + 1024..]).all(|v| *v == 0.0));
        let body = &u[256..256 + 1024];
        for (k, v) in body.iter().enumerate() {
            let half = ((k as f64 + 0.5) / (0.5 * period * fs)).floor() as usize;
            let want = if half.is_multiple_of(2) { amp } else { -amp };
            assert_eq!(*v, want, "sample {k}");
        }
        let edges: Vec<usize> = (1..body.len())
            .filter(|&k| body[k] != body[k - 1])
            .collect();
        assert_eq!(edges[..5], [51, 102, 154, 205, 256]);
        assert_eq!(edges.len(), 19);

        // 2.5 samples a half period (exact in binary): the edges at 2.5 and
        // 7.5 are ties and go to the later sample (3 and 8), those at 5 and
        // 10 are on samples.
        let tie = Excitation::Square {
            amplitude_m: 1.0,
            period_s: 5.0 / 1024.0,
            duration_s: 12.0 / 1024.0,
        };
        let u = generate(&tie, 1024.0, Padding::default()).unwrap();
        assert_eq!(
            u,
            [
                1.0, 1.0, 1.0, -1.0, -1.0, 1.0, 1.0, 1.0, -1.0, -1.0, 1.0, 1.0
            ]
        );
    }

    #[test]
    fn the_limit_clamps_the_command_and_nothing_else() {
        // A square wave above the limit sits at +-limit; a chirp reads
        // clamp(A sin(phase(t_k)), -L, L) with MATLAB's quadratic phase
        // 2 pi (f0 t + (f1 - f0) t^3 / (3 t1^2)) written out here.
        let fs = 1000.0;
        let padding = Padding {
            lead_in_s: 0.1,
            lead_out_s: 0.1,
        };
        let square = Excitation::Square {
            amplitude_m: 2e-3,
            period_s: 0.05,
            duration_s: 1.0,
        };
        let mut u = generate(&square, fs, padding).unwrap();
        limit(&mut u, 1.5e-3).unwrap();
        assert!(u[..100].iter().chain(&u[1100..]).all(|v| *v == 0.0));
        assert!(u[100..1100].iter().all(|v| v.abs() == 1.5e-3));
        let (f0, f1, t1, amp, lim) = (0.5, 20.0, 4.0, 3e-3, 2e-3);
        let chirp = Excitation::Chirp {
            law: ChirpLaw::Quadratic,
            f0_hz: f0,
            f1_hz: f1,
            duration_s: t1,
            amplitude_m: amp,
        };
        let mut u = generate(&chirp, fs, padding).unwrap();
        limit(&mut u, lim).unwrap();
        for (k, v) in u[100..4100].iter().enumerate() {
            let t = k as f64 / fs;
            let phase = 2.0 * PI * (f0 * t + (f1 - f0) * t.powi(3) / (3.0 * t1 * t1));
            let want = (amp * phase.sin()).clamp(-lim, lim);
            assert!((v - want).abs() <= 1e-15, "sample {k}: {v} vs {want}");
        }
        assert!(u.iter().any(|v| v.abs() == lim));
        for bad in [0.0, -1e-3, f64::NAN, f64::INFINITY] {
            assert_eq!(
                limit(&mut u, bad).unwrap_err().to_string(),
                format!("limit_m must be positive and finite (got {bad})")
            );
        }
    }

    /// An odd multisine starts and ends at rest, fading in over its first
    /// period and out over its last; between them every period is the
    /// same samples, at the rms asked; and a duration that is not a whole
    /// number of periods, at least three, is refused by its numbers.
    #[test]
    fn an_odd_multisine_repeats_its_period_between_rests() {
        let fs = 1000.0;
        let exc = Excitation::OddMultisine {
            f_min_hz: 0.5,
            f_max_hz: 30.0,
            rms_m: 2e-3,
            period_s: 4.0,
            duration_s: 20.0,
            seed: 7,
        };
        let u = generate(&exc, fs, Padding::default()).unwrap();
        let p = 4000;
        assert_eq!(u.len(), 5 * p);
        assert_eq!(u[0], 0.0);
        assert!(u[u.len() - 1].abs() < 1e-5 * 2e-3, "{}", u[u.len() - 1]);
        for j in 0..p {
            assert_eq!(u[p + j], u[2 * p + j], "sample {j}");
            assert_eq!(u[p + j], u[3 * p + j], "sample {j}");
        }
        let steady = &u[p..2 * p];
        let rms = (steady.iter().map(|v| v * v).sum::<f64>() / p as f64).sqrt();
        assert!((rms / 2e-3 - 1.0).abs() < 1e-12, "rms {rms}");
        let odd = |duration_s, period_s| Excitation::OddMultisine {
            f_min_hz: 0.5,
            f_max_hz: 30.0,
            rms_m: 2e-3,
            period_s,
            duration_s,
            seed: 7,
        };
        for (duration_s, period_s) in [(10.0, 4.0), (8.0, 4.0)] {
            assert!(matches!(
                odd(duration_s, period_s).validate(fs),
                Err(ExcitationError::Periods { .. })
            ));
        }
        let narrow = Excitation::OddMultisine {
            f_min_hz: 0.55,
            f_max_hz: 0.7,
            rms_m: 2e-3,
            period_s: 4.0,
            duration_s: 12.0,
            seed: 7,
        };
        // 0.25 Hz apart: 0.5 and 0.75 Hz are outside, 0.25 k for k odd.
        assert!(matches!(
            narrow.validate(fs),
            Err(ExcitationError::NoOddLine { .. })
        ));
    }

    #[test]
    fn every_invalid_setting_is_named_with_its_numbers() {
        let fs = 1000.0;
        let none = Padding::default();
        let chirp = |law, f0, f1, d, a| Excitation::Chirp {
            law,
            f0_hz: f0,
            f1_hz: f1,
            duration_s: d,
            amplitude_m: a,
        };
        let msg = |e: &Excitation, fs: f64| generate(e, fs, none).unwrap_err().to_string();
        assert_eq!(
            msg(&chirp(ChirpLaw::Linear, 1.0, 600.0, 10.0, 1e-3), fs),
            "f1_hz = 600 Hz is at or above the Nyquist frequency 500 Hz (sample_rate_hz = 1000)"
        );
        assert_eq!(
            msg(&chirp(ChirpLaw::Linear, 1.0, 50.0, 0.0, 1e-3), fs),
            "duration_s must be positive and finite (got 0)"
        );
        assert_eq!(
            msg(&chirp(ChirpLaw::Linear, 1.0, 50.0, 10.0, 1e-3), -5.0),
            "sample_rate_hz must be positive and finite (got -5)"
        );
        assert_eq!(
            msg(&chirp(ChirpLaw::Quadratic, 1.0, 50.0, 10.0, 0.0), fs),
            "amplitude_m must be positive and finite (got 0)"
        );
        assert_eq!(
            msg(&chirp(ChirpLaw::Logarithmic, 0.0, 50.0, 10.0, 1e-3), fs),
            "a logarithmic chirp needs f0_hz > 0 and f1_hz > 0 (got f0_hz = 0, f1_hz = 50)"
        );
        assert_eq!(
            msg(&chirp(ChirpLaw::Linear, -1.0, 50.0, 10.0, 1e-3), fs),
            "f0_hz must be finite and non-negative (got -1)"
        );
        assert_eq!(
            msg(&chirp(ChirpLaw::Linear, 1.0, 50.0, 1e-3, 1e-3), fs),
            "duration_s = 0.001 s at sample_rate_hz = 1000 gives 1 sample(s); at least 2 are needed"
        );
        let ms = |lo, hi, n| Excitation::Multisine {
            f_min_hz: lo,
            f_max_hz: hi,
            n_tones: n,
            rms_m: 1e-3,
            duration_s: 2.0,
            seed: 0,
        };
        assert_eq!(
            msg(&ms(20.0, 10.0, 5), fs),
            "f_min_hz (20 Hz) must be below f_max_hz (10 Hz)"
        );
        assert_eq!(
            msg(&ms(1.0, 10.0, 0), fs),
            "n_tones must be at least 1 (got 0)"
        );
        assert_eq!(
            msg(&ms(1.0, 3.0, 10), fs),
            "the band 1-3 Hz holds 5 bin(s) of the 0.5 Hz grid (1/duration_s) but n_tones = 10"
        );
        assert_eq!(
            msg(&ms(1.0, 500.0, 10), fs),
            "f_max_hz = 500 Hz is at or above the Nyquist frequency 500 Hz (sample_rate_hz = 1000)"
        );
        let square = |amplitude_m, period_s| Excitation::Square {
            amplitude_m,
            period_s,
            duration_s: 2.0,
        };
        assert_eq!(
            msg(&square(1e-3, 1.5e-3), fs),
            "period_s = 0.0015 s at sample_rate_hz = 1000 spans 1.5 sample(s); a square wave needs at least 2"
        );
        assert_eq!(
            msg(&square(1e-3, f64::NAN), fs),
            "period_s must be positive and finite (got NaN)"
        );
        assert_eq!(
            msg(&square(-1e-3, 0.1), fs),
            "amplitude_m must be positive and finite (got -0.001)"
        );
        generate(&square(1e-3, 2e-3), fs, none).unwrap();
        let rb = Excitation::RandomBand {
            f_min_hz: 1.1,
            f_max_hz: 1.4,
            rms_m: 1.0,
            duration_s: 2.0,
            seed: 0,
        };
        assert_eq!(
            msg(&rb, fs),
            "the band 1.1-1.4 Hz contains no bin of the 0.5 Hz grid (1/duration_s) above DC; lengthen duration_s or widen the band"
        );
        let err = generate(
            &chirp(ChirpLaw::Linear, 1.0, 50.0, 10.0, 1e-3),
            fs,
            Padding {
                lead_in_s: -1.0,
                lead_out_s: 0.0,
            },
        )
        .unwrap_err();
        assert_eq!(
            err.to_string(),
            "lead_in_s must be finite and non-negative (got -1)"
        );
    }
}
