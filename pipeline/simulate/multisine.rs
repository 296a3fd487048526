//! Random-odd multisines with a low crest factor: the periodic command that
//! separates a rig's noise from its nonlinear distortion (Pintelon &
//! Schoukens, "System Identification: A Frequency Domain Approach", 2nd
//! ed., Wiley 2012, Sec. 3.4 and 4.3).
//!
//! Flat amplitudes on the odd harmonics of 1/period in the band, one of each
//! group of [`GROUP`] left out at random: the even harmonics then show even
//! distortion and the odd ones left out odd distortion. The phases start as
//! Schroeder's; the crest factor is lowered by clipping the period and
//! restoring its spectrum (Van der Ouderaa, Schoukens & Renneboog 1988),
//! then by minimising the period's Lp norm for p rising to 512 (Guillaume et
//! al., IEEE Trans. Instrum. Meas. 40(6):982-989, 1991) with argmin's L-BFGS.
//! The derivation: docs/methods.md, "Random-odd multisines".

use argmin::core::{CostFunction, Error as ArgminError, Executor, Gradient};
use argmin::solver::linesearch::MoreThuenteLineSearch;
use argmin::solver::quasinewton::LBFGS;
use nalgebra::{Complex, DVector};
use rand::Rng;
use std::f64::consts::PI;

/// Consecutive odd harmonics of which one is left out to detect odd
/// distortion.
pub const GROUP: usize = 3;

/// Clipping passes: a start for the Lp norms far below Schroeder's phases,
/// which suit contiguous lines, not odd ones with gaps.
const PASSES: usize = 100;

/// The clipping level, as a share of the period's peak.
const CLIP: f64 = 0.85;

/// The Lp norms minimised in turn: a rising p weighs the peak more, the
/// last near the maximum norm the crest factor is.
const NORMS: [f64; 7] = [8.0, 16.0, 32.0, 64.0, 128.0, 256.0, 512.0];

/// L-BFGS iterations per norm.
const ITERATIONS: u64 = 100;

/// Samples per period of the highest line at least, where the phases are
/// optimised: the peak between samples is then within 1 % of the sampled
/// one, and a long period's optimisation works on far fewer samples.
const OVERSAMPLE: usize = 16;

/// One period of a random-odd multisine.
#[derive(Debug, Clone, PartialEq)]
pub struct OddMultisine {
    /// The period's samples, with root mean square exactly the one asked.
    pub period: Vec<f64>,
    /// The excited harmonics k (frequency k fs / period length).
    pub excited: Vec<usize>,
    /// The odd harmonics in the band left out: odd distortion shows there.
    pub detection: Vec<usize>,
    /// Peak over root mean square of the period.
    pub crest_factor: f64,
}

/// The odd harmonics k of fs / `len` in [`f_min_hz`, `f_max_hz`] (below
/// Nyquist), split into the excited ones and one of each [`GROUP`] left out,
/// chosen by `rng`.
pub fn lines(
    f_min_hz: f64,
    f_max_hz: f64,
    fs: f64,
    len: usize,
    rng: &mut impl Rng,
) -> (Vec<usize>, Vec<usize>) {
    let res = fs / len as f64;
    let odd: Vec<usize> = (1..len.div_ceil(2))
        .step_by(2)
        .filter(|&k| {
            let f = k as f64 * res;
            f >= f_min_hz * (1.0 - 1e-12) && f <= f_max_hz * (1.0 + 1e-12)
        })
        .collect();
    let (mut excited, mut detection) = (Vec::new(), Vec::new());
    for group in odd.chunks(GROUP) {
        // A group shorter than GROUP (the band's last) keeps its lines:
        // leaving one of one or two out would thin the band's top.
        let out = (group.len() == GROUP).then(|| rng.random_range(0..GROUP));
        for (i, &k) in group.iter().enumerate() {
            match out == Some(i) {
                true => detection.push(k),
                false => excited.push(k),
            }
        }
    }
    (excited, detection)
}

/// The period of length `len` with amplitudes `amps` and `phases` on the
/// `excited` harmonics, by an inverse real transform.
fn synthesise(len: usize, excited: &[usize], amps: &[f64], phases: &[f64]) -> Vec<f64> {
    let mut spectrum = vec![Complex::new(0.0, 0.0); len / 2 + 1];
    // x_j = sum_k A cos(2 pi k j / len + phi_k): the inverse transform of
    // A/2 e^(i phi) on each line, doubled by its mirror.
    for ((&k, &amp), &phi) in excited.iter().zip(amps).zip(phases) {
        spectrum[k] = Complex::from_polar(0.5 * amp, phi);
    }
    let mut x = vec![0.0; len];
    crate::fft::real_inverse(len)
        .process(&mut spectrum, &mut x)
        .expect("a half spectrum of len / 2 + 1 bins, imaginary parts zero at DC and Nyquist");
    x
}

/// The phases of `x`'s `excited` harmonics.
fn phases_of(x: &[f64], excited: &[usize]) -> Vec<f64> {
    let spectrum = crate::fft::real_spectrum(x);
    excited.iter().map(|&k| spectrum[k].arg()).collect()
}

/// log ||x||_p of the period the phases make, with its gradient over the
/// phases: for x_j = sum_k A_k cos(w_k j + phi_k) and g_j = |x_j|^(p-1)
/// sign(x_j), d/dphi_k sum_j |x_j|^p = -p A_k Im(conj(G_k) e^(i phi_k)),
/// G the transform of g. Scaled by the peak so that |x / peak|^p stays in
/// range.
struct LpNorm<'a> {
    len: usize,
    excited: &'a [usize],
    amps: &'a [f64],
    p: f64,
}

impl LpNorm<'_> {
    /// The period, its peak, and sum_j |x_j / peak|^p.
    fn sums(&self, phases: &DVector<f64>) -> (Vec<f64>, f64, f64) {
        let x = synthesise(self.len, self.excited, self.amps, phases.as_slice());
        let peak = peak(&x);
        let s = x.iter().map(|v| (v.abs() / peak).powf(self.p)).sum();
        (x, peak, s)
    }
}

impl CostFunction for LpNorm<'_> {
    type Param = DVector<f64>;
    type Output = f64;
    fn cost(&self, phases: &Self::Param) -> Result<f64, ArgminError> {
        let (_, peak, s) = self.sums(phases);
        Ok(peak.ln() + s.ln() / self.p)
    }
}

impl Gradient for LpNorm<'_> {
    type Param = DVector<f64>;
    type Gradient = DVector<f64>;
    fn gradient(&self, phases: &Self::Param) -> Result<Self::Gradient, ArgminError> {
        let (x, peak, s) = self.sums(phases);
        let mut g: Vec<f64> = x
            .iter()
            .map(|v| (v.abs() / peak).powf(self.p - 1.0) * v.signum())
            .collect();
        let fwd = crate::fft::real_forward(self.len);
        let mut spectrum = fwd.make_output_vec();
        fwd.process(&mut g, &mut spectrum)
            .expect("a buffer of the transform's length");
        Ok(DVector::from_iterator(
            self.excited.len(),
            self.excited
                .iter()
                .zip(self.amps)
                .zip(phases.iter())
                .map(|((&k, &amp), &phi)| {
                    -amp * (spectrum[k].conj() * Complex::from_polar(1.0, phi)).im / (s * peak)
                }),
        ))
    }
}

/// The largest magnitude of `x`.
fn peak(x: &[f64]) -> f64 {
    x.iter().fold(0.0_f64, |m, v| m.max(v.abs()))
}

fn crest_factor(x: &[f64]) -> f64 {
    let rms = (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt();
    peak(x) / rms
}

/// A random-odd multisine of `len` samples at `fs` over [`f_min_hz`,
/// `f_max_hz`] with root mean square `rms_m`; `rng` picks the lines left
/// out. None when the band holds no odd harmonic of fs / `len`.
pub fn odd_multisine(
    f_min_hz: f64,
    f_max_hz: f64,
    fs: f64,
    len: usize,
    rms_m: f64,
    rng: &mut impl Rng,
) -> Option<OddMultisine> {
    let (excited, detection) = lines(f_min_hz, f_max_hz, fs, len, rng);
    if excited.is_empty() {
        return None;
    }
    let f = excited.len() as f64;
    // Each line's cosine has mean square A^2 / 2: the period's is F A^2 / 2.
    let amps = vec![rms_m * (2.0 / f).sqrt(); excited.len()];
    Some(low_crest(len, excited, detection, amps))
}

/// As [`odd_multisine`], each excited line's share of the mean square
/// `share(f_hz)` over their sum (a spectrum shaped for the rig): line k's
/// amplitude is rms_m sqrt(2 w_k / sum w).
pub fn shaped_odd_multisine(
    f_min_hz: f64,
    f_max_hz: f64,
    fs: f64,
    len: usize,
    rms_m: f64,
    share: impl Fn(f64) -> f64,
    rng: &mut impl Rng,
) -> Option<OddMultisine> {
    let (excited, detection) = lines(f_min_hz, f_max_hz, fs, len, rng);
    let w: Vec<f64> = excited
        .iter()
        .map(|&k| share(k as f64 * fs / len as f64).max(0.0))
        .collect();
    let total: f64 = w.iter().sum();
    if excited.is_empty() || !(total > 0.0 && total.is_finite()) {
        return None;
    }
    let amps = w.iter().map(|w| rms_m * (2.0 * w / total).sqrt()).collect();
    Some(low_crest(len, excited, detection, amps))
}

/// The period of `len` samples with `amps` on the `excited` lines, its
/// phases chosen for a low crest factor: Schroeder's, clipped, then the
/// Lp norms.
pub fn low_crest(
    len: usize,
    excited: Vec<usize>,
    detection: Vec<usize>,
    amps: Vec<f64>,
) -> OddMultisine {
    let f = excited.len() as f64;
    // Schroeder's phases, -pi i (i - 1) / F for the i-th of F lines.
    let mut phases: Vec<f64> = (1..=excited.len())
        .map(|i| -PI * (i * (i - 1)) as f64 / f)
        .collect();
    // The phases are optimised on a grid of `grid` samples a period, enough
    // for the highest line; the period is made at `len` from them.
    let top = excited.last().copied().unwrap_or(1);
    let grid = len.min((OVERSAMPLE * top).next_multiple_of(2).max(2 * top + 2));
    for _ in 0..PASSES {
        let x = synthesise(grid, &excited, &amps, &phases);
        let level = CLIP * peak(&x);
        let clipped: Vec<f64> = x.iter().map(|v| v.clamp(-level, level)).collect();
        phases = phases_of(&clipped, &excited);
    }
    for p in NORMS {
        let norm = LpNorm {
            len: grid,
            excited: &excited,
            amps: &amps,
            p,
        };
        let solver = LBFGS::new(MoreThuenteLineSearch::new(), 7);
        let start = DVector::from_vec(phases.clone());
        // A norm whose search fails keeps the phases it started from.
        if let Ok(done) = Executor::new(norm, solver)
            .configure(|state| state.param(start).max_iters(ITERATIONS))
            .run()
            && let Some(best) = done.state.best_param
        {
            phases = best.as_slice().to_vec();
        }
    }
    let best = synthesise(len, &excited, &amps, &phases);
    OddMultisine {
        crest_factor: crest_factor(&best),
        period: best,
        excited,
        detection,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::seeded_rng;

    /// The DFT of `x` at harmonic k by its definition: the independent truth.
    fn line(x: &[f64], k: usize) -> Complex<f64> {
        let n = x.len();
        x.iter()
            .enumerate()
            .map(|(j, v)| Complex::from_polar(*v, -2.0 * PI * ((j * k) % n) as f64 / n as f64))
            .sum()
    }

    /// 0.5-30 Hz over a 10 s period at 1 kHz: the odd harmonics of 0.1 Hz
    /// from 0.5 Hz, a third of them left out.
    fn designed(seed: u64) -> OddMultisine {
        let mut rng = seeded_rng(seed, "test");
        odd_multisine(0.5, 30.0, 1000.0, 10_000, 1e-3, &mut rng).expect("lines in the band")
    }

    /// The period's energy is on its excited lines only, flat, at the rms
    /// asked; the even harmonics and the detection lines are empty; one
    /// of each three odd harmonics is left out.
    #[test]
    fn energy_is_on_the_excited_odd_lines_only_and_flat() {
        let m = designed(1);
        let n = m.period.len();
        let rms = (m.period.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
        assert!((rms / 1e-3 - 1.0).abs() < 1e-12, "rms {rms}");
        assert!(m.excited.iter().all(|k| k % 2 == 1));
        assert_eq!(
            m.excited.len() + m.detection.len(),
            148,
            "odd harmonics 5..=299"
        );
        assert_eq!(m.detection.len(), 49);
        let amp = 1e-3 * (2.0 / m.excited.len() as f64).sqrt();
        for &k in &m.excited {
            let a = 2.0 * line(&m.period, k).norm() / n as f64;
            assert!((a / amp - 1.0).abs() < 1e-9, "line {k}: {a} against {amp}");
        }
        for k in m.detection.iter().copied().chain((2..400).step_by(2)) {
            let a = 2.0 * line(&m.period, k).norm() / n as f64;
            assert!(a < 1e-12 * amp.max(1.0), "line {k} holds {a}");
        }
    }

    /// At least 50 lines reach a crest factor of at most 1.6, stated as
    /// the period's own peak over its rms, for every seed tried.
    #[test]
    fn fifty_lines_or_more_reach_a_crest_factor_of_at_most_1_6() {
        for seed in 1..=5 {
            let m = designed(seed);
            assert!(m.excited.len() >= 50);
            assert!(
                (m.crest_factor - crest_factor(&m.period)).abs() < 1e-12,
                "the stated crest factor is the period's"
            );
            eprintln!("seed {seed}: crest factor {:.3}", m.crest_factor);
            assert!(m.crest_factor <= 1.6, "seed {seed}: {}", m.crest_factor);
        }
    }

    /// The lines left out depend on the seed, one in each group of three.
    #[test]
    fn the_detection_lines_are_drawn_one_per_group() {
        let (a, b) = (designed(1), designed(2));
        assert_ne!(a.detection, b.detection);
        let odd: Vec<usize> = (5..=299).step_by(2).collect();
        for group in odd.chunks(GROUP).filter(|g| g.len() == GROUP) {
            let out = group.iter().filter(|k| a.detection.contains(k)).count();
            assert_eq!(out, 1, "group {group:?}");
        }
    }
}
