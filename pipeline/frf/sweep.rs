//! The command's amplitude along a sweep, frequency by frequency. A slow
//! sweep holds one frequency at a time, so the displacement's amplitude
//! while it passed a frequency is the FRF's gain there times this; seal
//! friction's equivalent damping at a bin, 4 F / (pi V) with V the velocity
//! amplitude there (Gelb & Vander Velde 1968, Multiple-Input Describing
//! Functions, Ch. 2; docs/model.md, "Seal friction"), follows from it. The
//! gain comes from the FRF, not the displacement's envelope, which the
//! friction's own harmonics and the noise swell where the response is small.
//!
//! The command's analytic part (the Hilbert transform, by FFT) gives its
//! instantaneous frequency (the phase it advances in a window over the
//! window's length) and its envelope (the median of its modulus there).
//! Windows where the envelope is under [`ACTIVE`] of the sweep's are left
//! out; the rest, ordered by frequency, are read at a bin by linear
//! interpolation, and at the ends by the nearest.

use nalgebra::Complex;

use super::{Detrend, detrend};

/// Windows the record is cut into.
const WINDOWS: usize = 256;
/// The fewest samples in a window.
const MIN_WINDOW: usize = 8;
/// A window counts where the command's envelope is at least this share of
/// the largest window's.
pub const ACTIVE: f64 = 0.2;

/// The command's amplitude at the frequencies the sweep passed.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepAmplitude {
    /// Increasing.
    freq_hz: Vec<f64>,
    /// The command's amplitude at each (its unit's).
    amplitude: Vec<f64>,
}

impl SweepAmplitude {
    /// The amplitude at `freq_hz`: interpolated between the windows around
    /// it, the nearest window's beyond them.
    pub fn at(&self, freq_hz: f64) -> f64 {
        let (f, a) = (&self.freq_hz, &self.amplitude);
        let i = f.partition_point(|&x| x < freq_hz);
        if i == 0 {
            return a[0];
        }
        if i == f.len() {
            return a[f.len() - 1];
        }
        let t = (freq_hz - f[i - 1]) / (f[i] - f[i - 1]);
        if t.is_finite() {
            a[i - 1] + t * (a[i] - a[i - 1])
        } else {
            a[i]
        }
    }

    /// The frequencies (Hz) the sweep was read at, lowest first.
    pub fn freq_hz(&self) -> &[f64] {
        &self.freq_hz
    }
}

/// The amplitude of the sweep `u`, sampled at `sample_rate_hz`, along its
/// frequencies. None when the record is too short to cut into windows or
/// no window holds the sweep.
pub fn sweep_amplitude(u: &[f64], sample_rate_hz: f64) -> Option<SweepAmplitude> {
    let n = u.len();
    if n < WINDOWS * MIN_WINDOW || sample_rate_hz.is_nan() || sample_rate_hz <= 0.0 {
        return None;
    }
    let ua = analytic(&detrend(u, Detrend::Linear));
    let w = n / WINDOWS;
    let median = |v: &mut Vec<f64>| {
        let mid = v.len() / 2;
        *v.select_nth_unstable_by(mid, f64::total_cmp).1
    };
    let windows: Vec<(f64, f64)> = (0..WINDOWS)
        .map(|k| {
            let r = k * w..(k + 1) * w;
            let envelope = median(&mut ua[r.clone()].iter().map(|c| c.norm()).collect());
            // The phase advanced over the window, sample by sample (each
            // step well under half a turn below Nyquist).
            let turned: f64 = ua[r.start..r.end]
                .windows(2)
                .map(|p| (p[1] * p[0].conj()).arg())
                .sum();
            let freq = turned * sample_rate_hz / (2.0 * std::f64::consts::PI * (w - 1) as f64);
            (envelope, freq)
        })
        .collect();
    let loudest = windows.iter().map(|w| w.0).fold(0.0, f64::max);
    let mut kept: Vec<(f64, f64)> = windows
        .into_iter()
        .filter(|&(e, f)| e >= ACTIVE * loudest && e > 0.0 && f > 0.0)
        .map(|(e, f)| (f, e))
        .collect();
    if kept.is_empty() {
        return None;
    }
    kept.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (freq_hz, amplitude) = kept.into_iter().unzip();
    Some(SweepAmplitude { freq_hz, amplitude })
}

/// The analytic signal v + i H[v]: the spectrum's negative frequencies
/// removed and its positive ones doubled.
fn analytic(v: &[f64]) -> Vec<Complex<f64>> {
    let n = v.len();
    let mut z: Vec<Complex<f64>> = v.iter().map(|&r| Complex::new(r, 0.0)).collect();
    crate::fft::complex_forward(n).process(&mut z);
    let half = n.div_ceil(2);
    for (k, c) in z.iter_mut().enumerate() {
        let factor = if k == 0 || (n.is_multiple_of(2) && k == n / 2) {
            1.0
        } else if k < half {
            2.0
        } else {
            0.0
        };
        *c *= factor / n as f64;
    }
    crate::fft::complex_inverse(n).process(&mut z);
    z
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// A linear sweep 1 -> 20 Hz whose amplitude falls as 1 / (1 + f / 10),
    /// offset and drifting: the amplitude read at each frequency is that,
    /// known in closed form.
    #[test]
    fn the_amplitude_along_a_sweep_is_read_at_each_frequency() {
        let fs = 1000.0;
        let t_end = 60.0;
        let n = (t_end * fs) as usize;
        let (f0, f1) = (1.0, 20.0);
        let rate = (f1 - f0) / t_end;
        let freq = |t: f64| f0 + rate * t;
        let gain = |f: f64| 1.0 / (1.0 + f / 10.0);
        let phase = |t: f64| 2.0 * PI * (f0 * t + 0.5 * rate * t * t);
        let u: Vec<f64> = (0..n)
            .map(|i| {
                let t = i as f64 / fs;
                3.0 + 0.01 * t + 2e-3 * gain(freq(t)) * phase(t).sin()
            })
            .collect();
        let a = sweep_amplitude(&u, fs).expect("a sweep");
        for f in [2.0, 5.0, 10.0, 15.0, 19.0] {
            let want = 2e-3 * gain(f);
            assert!(
                (a.at(f) / want - 1.0).abs() < 0.01,
                "at {f} Hz: {} against {want}",
                a.at(f)
            );
        }
        // The windows' frequencies span the sweep.
        let fr = a.freq_hz();
        assert!(
            fr[0] < 1.3 && fr[fr.len() - 1] > 19.7,
            "{:?}",
            (fr[0], fr[fr.len() - 1])
        );
    }

    #[test]
    fn a_record_at_rest_or_too_short_has_no_sweep() {
        assert!(sweep_amplitude(&[0.0; 4096], 1000.0).is_none());
        assert!(sweep_amplitude(&[1.0; 4096], 1000.0).is_none());
        assert!(sweep_amplitude(&[1.0; 100], 1000.0).is_none());
    }
}
