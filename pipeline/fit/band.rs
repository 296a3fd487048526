//! How uncertain a fitted model's frequency response is: the standard
//! deviation of its magnitude (dB) and phase (rad) at each frequency, by
//! first-order propagation of the fit's parameter covariance. The Bode
//! figures shade +-2 of them around the model.
//!
//! With G(s) = N(s)/D(s) exp(-s tau), ln G = ln N - ln D - s tau, so at
//! s = jw: d lnG / d n_i = s^i / N, d lnG / d d_i = -s^i / D and
//! d lnG / d tau = -s. The magnitude in dB is (20 / ln 10) Re ln G and the
//! phase is Im ln G; each is a linear function g of the parameters to first
//! order, with variance g' C g.

use nalgebra::Complex;

use crate::lti::log_response_std;
use crate::poly;

use super::TfFit;

/// Standard deviations of a model's response, frequency by frequency.
#[derive(Debug, Clone, PartialEq)]
pub struct ResponseStd {
    pub magnitude_db: Vec<f64>,
    pub phase_rad: Vec<f64>,
}

/// The first-order standard deviations of `fit`'s response at `freq_hz`
/// (the command's hold has no parameter and changes neither).
pub fn response_std(fit: &TfFit, freq_hz: &[f64]) -> ResponseStd {
    let (m, n) = (fit.shape.numerator_order, fit.shape.denominator_order);
    let mut out = ResponseStd {
        magnitude_db: Vec::with_capacity(freq_hz.len()),
        phase_rad: Vec::with_capacity(freq_hz.len()),
    };
    let p = fit.params.len();
    for &f in freq_hz {
        let s = Complex::new(0.0, 2.0 * std::f64::consts::PI * f);
        let (num, den) = (poly::eval(&fit.tf.num, s), poly::eval(&fit.tf.den, s));
        // d ln G / d param, in the order of `params`.
        let mut grad: Vec<Complex<f64>> = Vec::with_capacity(p);
        // Numerator n_m .. n0: the coefficient of s^i.
        for i in (0..=m).rev() {
            grad.push(s.powu(i as u32) / num);
        }
        // Denominator after its leading 1: d_{n-1} .. d0.
        for i in (0..n).rev() {
            grad.push(-s.powu(i as u32) / den);
        }
        if fit.shape.fit_delay {
            grad.push(-s);
        }
        let (mag, phase) = log_response_std(&grad, |i, j| fit.covariance[(i, j)]);
        out.magnitude_db.push(mag);
        out.phase_rad.push(phase);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::ModelShape;
    use crate::lti::TransferFunction;
    use nalgebra::{DMatrix, DVector};
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};

    /// A fit of n0 / (s^2 + d1 s + d0) with a delay, as the solver states
    /// it, with a covariance that correlates the parameters.
    fn fit() -> TfFit {
        let (n0, d1, d0, tau) = (2.4e9 / 7.9e5, 267.0, 3060.0, 0.002);
        let params = vec![n0, d1, d0, tau];
        let sd = DVector::from_vec(vec![0.004 * n0, 0.003 * d1, 0.004 * d0, 1e-5]);
        let corr = DMatrix::from_row_slice(
            4,
            4,
            &[
                1.0, 0.3, 0.8, 0.1, //
                0.3, 1.0, 0.2, -0.4, //
                0.8, 0.2, 1.0, 0.0, //
                0.1, -0.4, 0.0, 1.0,
            ],
        );
        let covariance = DMatrix::from_fn(4, 4, |i, j| corr[(i, j)] * sd[i] * sd[j]);
        TfFit {
            tf: TransferFunction::with_delay(&[n0], &[1.0, d1, d0], tau).unwrap(),
            shape: ModelShape {
                numerator_order: 0,
                denominator_order: 2,
                fit_delay: true,
            },
            param_names: vec!["n0".into(), "d1".into(), "d0".into(), "tau_s".into()],
            std: sd.iter().copied().collect(),
            params,
            covariance,
            fit_percent: 99.0,
            reduced_chi2: 1.0,
            iterations: 5,
            termination: String::new(),
            converged: true,
            stable: true,
            n_bins: 100,
            warnings: Vec::new(),
            transient: None,
            aliases: false,
        }
    }

    /// Draws from the covariance (Cholesky factor times standard normals,
    /// a fixed seed), the response of each draw computed directly, and the
    /// sample std of its magnitude and phase: within 5 % of the first-order
    /// std at every frequency (20,000 draws: the sample std's own relative
    /// error is 0.5 %; the rest is the small curvature first order leaves
    /// out).
    #[test]
    fn first_order_matches_draws_from_the_covariance() {
        let f = fit();
        let freqs = [0.5, 2.0, 8.0, 20.0, 60.0];
        let std = response_std(&f, &freqs);
        let l = f.covariance.clone().cholesky().unwrap().l();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let draws = 20_000;
        let mut sums = vec![(0.0, 0.0, 0.0, 0.0); freqs.len()];
        for _ in 0..draws {
            let z = DVector::from_iterator(4, (0..4).map(|_| StandardNormal.sample(&mut rng)));
            let p = DVector::from_vec(f.params.clone()) + &l * z;
            for (k, &fr) in freqs.iter().enumerate() {
                let s = Complex::new(0.0, 2.0 * std::f64::consts::PI * fr);
                let g = p[0] / (s * s + s * p[1] + p[2]) * (-s * p[3]).exp();
                let g0 = f.tf.freq_response(fr);
                // Phase relative to the nominal one: no wrapping.
                let (mdb, ph) = (20.0 * g.norm().log10(), (g / g0).arg());
                let e = &mut sums[k];
                *e = (e.0 + mdb, e.1 + mdb * mdb, e.2 + ph, e.3 + ph * ph);
            }
        }
        for (k, e) in sums.iter().enumerate() {
            let n = draws as f64;
            let sd = |s: f64, s2: f64| ((s2 - s * s / n) / (n - 1.0)).sqrt();
            let (m, p) = (sd(e.0, e.1), sd(e.2, e.3));
            assert!(
                (m / std.magnitude_db[k] - 1.0).abs() < 0.05,
                "{} Hz: {m} vs {}",
                freqs[k],
                std.magnitude_db[k]
            );
            assert!(
                (p / std.phase_rad[k] - 1.0).abs() < 0.05,
                "{} Hz: {p} vs {}",
                freqs[k],
                std.phase_rad[k]
            );
        }
    }
}
