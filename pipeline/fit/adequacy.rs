//! Whether a fitted model explains its FRF: three one-sided tests on the
//! weighted residuals e_k = (h_k - h_model,k) / sqrt(E|dH_k|^2 / 2), whose
//! real and imaginary parts each have unit variance when the model is
//! right and the variances are honest:
//!
//! 1. the cost against its chi-square mean and spread (2N - p dof);
//! 2. the correlation of residuals the estimator's kernel apart;
//! 3. a phase residual that grows linearly with frequency (a missing delay).
//!
//! Each fails beyond [`Z_LIMIT`] std. A cost or a neighbouring correlation
//! as far BELOW its expectation says the variances overstate the noise
//! ([`Adequacy::overstated`]). The derivations: docs/methods.md, "The
//! adequacy tests".

use nalgebra::Complex;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Standard deviations beyond which a test fails.
pub const Z_LIMIT: f64 = 4.0;

/// What a test compares, bin by bin.
#[derive(Debug, Clone, Copy)]
pub struct Residuals<'a> {
    pub freq_hz: &'a [f64],
    pub h: &'a [Complex<f64>],
    pub model: &'a [Complex<f64>],
    /// E|dH|^2 at each bin.
    pub variance: &'a [f64],
}

/// The three tests' outcomes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Adequacy {
    /// The weighted cost and its degrees of freedom (2 bins - parameters).
    pub cost: f64,
    pub dof: usize,
    /// (cost - dof) / sqrt(2 dof).
    pub cost_z: f64,
    /// Correlation of the normalised residuals `lag_bins` bins apart, when
    /// there are pairs.
    pub correlation: Option<Correlation>,
    /// The phase residual's linear trend, as a delay.
    pub phase_slope: Option<PhaseSlope>,
}

/// Correlation of the normalised residuals at the estimator's bandwidth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Correlation {
    pub lag_bins: usize,
    pub pairs: usize,
    pub r: f64,
    /// r sqrt(2 pairs).
    pub z: f64,
}

/// The delay a linear phase residual implies.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct PhaseSlope {
    pub delay_s: f64,
    pub std_s: f64,
    /// delay / std.
    pub z: f64,
}

/// A failed test.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Failure {
    Cost,
    Correlation,
    LinearPhase,
}

impl Adequacy {
    /// The tests that failed, in the order above.
    pub fn failures(&self) -> Vec<Failure> {
        let mut out = Vec::new();
        if self.cost_z > Z_LIMIT {
            out.push(Failure::Cost);
        }
        if self.correlation.as_ref().is_some_and(|c| c.z > Z_LIMIT) {
            out.push(Failure::Correlation);
        }
        if self.phase_slope.as_ref().is_some_and(|p| p.z > Z_LIMIT) {
            out.push(Failure::LinearPhase);
        }
        out
    }

    pub fn passed(&self) -> bool {
        self.failures().is_empty()
    }

    /// A failed fit's finding in a few words: the test that failed most,
    /// with its number.
    pub fn failure_headline(&self) -> String {
        let phase = self.phase_slope.as_ref().filter(|p| p.z > Z_LIMIT);
        let correlated = self.correlation.as_ref().filter(|c| c.z > Z_LIMIT);
        if self.cost_z > Z_LIMIT {
            format!(
                "chi-square {:.2}, {:.0} std above noise",
                self.reduced_chi2(),
                self.cost_z
            )
        } else if let Some(p) = phase {
            format!(
                "phase lags as a {:.3} ms delay ({:.0} std)",
                1e3 * p.delay_s,
                p.z
            )
        } else if let Some(c) = correlated {
            format!("residuals correlate (r = {:.2}, {:.0} std)", c.r, c.z)
        } else {
            "the fit passes its adequacy tests".to_string()
        }
    }

    /// An overstated noise's finding in a line.
    pub fn overstated_headline(&self) -> String {
        format!(
            "stds too wide: chi-square {:.3}, {:.0} std below noise",
            self.reduced_chi2(),
            -self.cost_z
        )
    }

    /// When the variances overstate the noise: the cost, or the
    /// correlation of residuals at the estimator's bandwidth, more than
    /// [`Z_LIMIT`] std below its expectation. What it says in one line,
    /// with the likely cause and the estimator that removes it; None
    /// otherwise. A finding beside [`Self::diagnosis`], not a failure: the
    /// model may be right, its stds are too wide where the overstatement
    /// sits.
    /// `cause` is the likely cause with its remedy, which depends on the
    /// FRF estimator (`Estimator::overstated_noise` says it per estimator).
    pub fn overstated(&self, cause: &str) -> Option<String> {
        self.overstated_because(cause, None)
    }

    /// [`Self::overstated`], with the cause already `known` (a run's FRF
    /// settings the log contradicts, a rig found not linear) said in place
    /// of `cause`.
    pub fn overstated_because(&self, cause: &str, known: Option<&str>) -> Option<String> {
        let cause = known.unwrap_or(cause);
        let mut parts = Vec::new();
        if self.cost_z < -Z_LIMIT {
            parts.push(format!(
                "weighted cost {:.4e} against {} +- {:.0} expected (reduced chi-square {:.3}, {:.1} std below)",
                self.cost,
                self.dof,
                (2.0 * self.dof as f64).sqrt(),
                self.reduced_chi2(),
                -self.cost_z
            ));
        }
        if let Some(c) = self.correlation.as_ref().filter(|c| c.z < -Z_LIMIT) {
            parts.push(format!(
                "residuals {} bins apart anticorrelate (r = {:.3}, {:.1} std below 0)",
                c.lag_bins, c.r, -c.z
            ));
        }
        (!parts.is_empty()).then(|| {
            format!(
                "{}: the variances overstate the noise, and the stds are wider than the data need; likely cause: {cause}",
                parts.join("; ")
            )
        })
    }

    /// The reduced chi-square, cost / dof.
    pub fn reduced_chi2(&self) -> f64 {
        self.cost / self.dof.max(1) as f64
    }

    /// What the failures say, in one line, naming the manifest keys that
    /// would address them; None when every test passed. `add_delay` is
    /// what would add a delay to the model (None when it has one);
    /// `noise_cause` the likely cause of a noise the variances understate,
    /// which depends on the FRF estimator (`Estimator::understated_noise`).
    pub fn diagnosis(&self, add_delay: Option<&str>, noise_cause: &str) -> Option<String> {
        self.diagnosis_because(add_delay, noise_cause, None)
    }

    /// [`Self::diagnosis`], with the cause already `known` (a run's FRF
    /// settings the log contradicts, a rig found not linear) said in place
    /// of the one the failures would point at.
    pub fn diagnosis_because(
        &self,
        add_delay: Option<&str>,
        noise_cause: &str,
        known: Option<&str>,
    ) -> Option<String> {
        let failures = self.failures();
        if failures.is_empty() {
            return None;
        }
        let mut parts = Vec::new();
        if failures.contains(&Failure::Cost) {
            parts.push(format!(
                "weighted cost {:.4e} against {} +- {:.0} expected (reduced chi-square {:.2}, {:.1} std above)",
                self.cost,
                self.dof,
                (2.0 * self.dof as f64).sqrt(),
                self.reduced_chi2(),
                self.cost_z
            ));
        }
        if let (true, Some(c)) = (failures.contains(&Failure::Correlation), &self.correlation) {
            parts.push(format!(
                "residuals {} bins apart correlate (r = {:.3}, {:.1} std): structure the model lacks",
                c.lag_bins, c.r, c.z
            ));
        }
        if let (true, Some(p)) = (failures.contains(&Failure::LinearPhase), &self.phase_slope) {
            parts.push(format!(
                "the phase residual grows linearly with frequency, as a delay of {:.3} ms would ({:.1} std)",
                1e3 * p.delay_s,
                p.z
            ));
        }
        let cause = if let Some(known) = known {
            format!("likely cause: {known}")
        } else if failures.contains(&Failure::LinearPhase) {
            match add_delay {
                None => "likely cause: a delay beyond the fitted one's bound; widen identification.delay.max_s".to_string(),
                Some(key) => format!("likely cause: a delay the model lacks; {key}"),
            }
        } else if failures.contains(&Failure::Correlation) {
            "likely cause: dynamics the model lacks (a servo-valve mode, a resonance) within the band; the joint fit's identification.joint.structure = \"delay_valve\" (or \"auto\") models a valve mode, or narrow identification.band_hz".to_string()
        } else {
            format!("likely cause: {noise_cause}")
        };
        Some(format!("{}; {cause}", parts.join("; ")))
    }
}

/// The three tests on `res` for a model of `n_params` parameters; bins are
/// `bin_hz` apart on the FRF's grid and pairs are taken `lag` bins apart.
pub fn assess(res: &Residuals<'_>, n_params: usize, bin_hz: f64, lag: usize) -> Adequacy {
    let mut sums = Sums::default();
    sums.add(res, bin_hz, lag);
    sums.finish(n_params, lag)
}

/// The sums the three tests are made of: additive over bins and runs, so
/// a joint fit's tests pool its runs' sums.
#[derive(Debug, Clone, Copy, Default)]
pub struct Sums {
    cost: f64,
    bins: usize,
    /// sum Re(e_k conj e_{k+L}), sum |e_k|^2, sum |e_{k+L}|^2 over pairs.
    sxy: f64,
    sxx: f64,
    syy: f64,
    pairs: usize,
    /// sum w phi / var and sum w^2 / var.
    swx: f64,
    sww: f64,
}

impl Sums {
    /// Add the bins of `res` (one FRF: pairs are not formed across FRFs).
    pub fn add(&mut self, res: &Residuals<'_>, bin_hz: f64, lag: usize) {
        let n = res.h.len();
        let e: Vec<Complex<f64>> = (0..n)
            .map(|k| (res.h[k] - res.model[k]) / (res.variance[k] / 2.0).sqrt())
            .collect();
        self.cost += e.iter().map(|v| v.norm_sqr()).sum::<f64>();
        self.bins += n;
        if bin_hz > 0.0 && lag > 0 {
            let index = |f: f64| (f / bin_hz).round() as i64;
            let mut j = 0;
            for i in 0..n {
                let want = index(res.freq_hz[i]) + lag as i64;
                while j < n && index(res.freq_hz[j]) < want {
                    j += 1;
                }
                if j == n {
                    break;
                }
                if index(res.freq_hz[j]) == want {
                    self.sxy += (e[i] * e[j].conj()).re;
                    self.sxx += e[i].norm_sqr();
                    self.syy += e[j].norm_sqr();
                    self.pairs += 1;
                }
            }
        }
        for k in 0..n {
            let m = res.model[k];
            if m.norm_sqr() == 0.0 {
                continue;
            }
            // phi = -w tau, of variance (E|dH|^2 / 2) / |model|^2.
            let phi = ((res.h[k] - m) / m).im;
            let var = res.variance[k] / 2.0 / m.norm_sqr();
            let w = 2.0 * std::f64::consts::PI * res.freq_hz[k];
            self.swx += w * phi / var;
            self.sww += w * w / var;
        }
    }

    /// The tests over what was added, for a model of `n_params` parameters
    /// (its share of them, for one run of a joint fit).
    pub fn finish(&self, n_params: usize, lag: usize) -> Adequacy {
        let dof = (2 * self.bins).saturating_sub(n_params).max(1);
        let correlation = (self.pairs >= 10 && self.sxx > 0.0 && self.syy > 0.0).then(|| {
            let r = self.sxy / (self.sxx * self.syy).sqrt();
            Correlation {
                lag_bins: lag,
                pairs: self.pairs,
                r,
                z: r * (2.0 * self.pairs as f64).sqrt(),
            }
        });
        let phase_slope = (self.sww > 0.0 && self.sww.is_finite()).then(|| {
            let delay_s = -self.swx / self.sww;
            let std_s = 1.0 / self.sww.sqrt();
            PhaseSlope {
                delay_s,
                std_s,
                z: delay_s / std_s,
            }
        });
        Adequacy {
            cost: self.cost,
            dof,
            cost_z: (self.cost - dof as f64) / (2.0 * dof as f64).sqrt(),
            correlation,
            phase_slope,
        }
    }

    /// The bins added.
    pub fn bins(&self) -> usize {
        self.bins
    }
}

impl std::ops::AddAssign for Sums {
    fn add_assign(&mut self, o: Self) {
        self.cost += o.cost;
        self.bins += o.bins;
        self.sxy += o.sxy;
        self.sxx += o.sxx;
        self.syy += o.syy;
        self.pairs += o.pairs;
        self.swx += o.swx;
        self.sww += o.sww;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// A first-order model over 2,000 bins at 0.05 Hz, with complex noise of
    /// known variance; `distort` changes the truth the data come from.
    fn case(seed: u64, distort: impl Fn(f64) -> Complex<f64>) -> Adequacy {
        let n = 2000;
        let bin = 0.05;
        let freq: Vec<f64> = (1..=n).map(|k| k as f64 * bin).collect();
        let model: Vec<Complex<f64>> = freq
            .iter()
            .map(|f| Complex::new(1.0, 0.0) / Complex::new(1.0, f / 20.0))
            .collect();
        let var = 1e-4;
        let normal = Normal::new(0.0, (var / 2.0_f64).sqrt()).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let h: Vec<Complex<f64>> = freq
            .iter()
            .zip(&model)
            .map(|(f, m)| {
                m * distort(*f) + Complex::new(normal.sample(&mut rng), normal.sample(&mut rng))
            })
            .collect();
        let variance = vec![var; n];
        assess(
            &Residuals {
                freq_hz: &freq,
                h: &h,
                model: &model,
                variance: &variance,
            },
            0,
            bin,
            1,
        )
    }

    #[test]
    fn the_right_model_passes_every_test_across_seeds() {
        // 40 seeds: each z is N(0, 1), so |z| stays below 4 (a 3e-5 event
        // per test); the mean of cost_z over seeds is within 4 / sqrt(40).
        let mut mean_z = 0.0;
        for seed in 0..40 {
            let a = case(seed, |_| Complex::new(1.0, 0.0));
            assert!(a.passed(), "seed {seed}: {a:?}");
            assert_eq!(a.overstated(""), None, "seed {seed}: {a:?}");
            assert_eq!(a.dof, 4000);
            assert_eq!(a.correlation.as_ref().unwrap().pairs, 1999);
            mean_z += a.cost_z / 40.0;
        }
        assert!(mean_z.abs() < 4.0 / 40f64.sqrt(), "mean cost z {mean_z}");
    }

    #[test]
    fn a_missing_delay_shows_as_a_linear_phase_and_its_size_is_recovered() {
        // 0.4 ms: 2 pi f tau is at most 0.25 rad at 100 Hz, so the small-angle
        // phase is within 1 % of linear in the mean.
        let tau = 4e-4;
        let a = case(7, |f| {
            Complex::from_polar(1.0, -2.0 * std::f64::consts::PI * f * tau)
        });
        assert!(a.failures().contains(&Failure::LinearPhase), "{a:?}");
        let p = a.phase_slope.as_ref().unwrap();
        assert!((p.delay_s / tau - 1.0).abs() < 0.02, "{p:?}");
        let d = a
            .diagnosis(Some("set identification.delay = \"fit\""), "noise")
            .unwrap();
        assert!(
            d.contains("a delay the model lacks; set identification.delay"),
            "{d}"
        );
    }

    #[test]
    fn a_smooth_gain_error_shows_as_cost_and_correlation_not_as_a_delay() {
        // A 2 % gain ripple over 20 Hz: smooth, so neighbours correlate.
        let a = case(3, |f| {
            Complex::new(
                1.0 + 0.02 * (2.0 * std::f64::consts::PI * f / 20.0).sin(),
                0.0,
            )
        });
        let failures = a.failures();
        assert!(failures.contains(&Failure::Cost), "{a:?}");
        assert!(failures.contains(&Failure::Correlation), "{a:?}");
        assert!(!failures.contains(&Failure::LinearPhase), "{a:?}");
        assert!(a.diagnosis(None, "noise").unwrap().contains("delay_valve"));
    }

    /// The three tests on bins 0.05 Hz apart, each of stated variance
    /// 1e-4, a model without parameters, pairs one bin apart.
    fn judge_flat(freq: &[f64], h: &[Complex<f64>], model: &[Complex<f64>]) -> Adequacy {
        assess(
            &Residuals {
                freq_hz: freq,
                h,
                model,
                variance: &vec![1e-4; h.len()],
            },
            0,
            0.05,
            1,
        )
    }

    #[test]
    fn understated_noise_fails_the_cost_alone() {
        // Noise 1.5 times what the variance says, white: cost 2.25 dof.
        let n = 2000;
        let freq: Vec<f64> = (1..=n).map(|k| k as f64 * 0.05).collect();
        let model = vec![Complex::new(1.0, 0.0); n];
        let normal = Normal::new(0.0, 1.5 * 0.01 / 2f64.sqrt()).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let h: Vec<Complex<f64>> = model
            .iter()
            .map(|m| m + Complex::new(normal.sample(&mut rng), normal.sample(&mut rng)))
            .collect();
        let a = judge_flat(&freq, &h, &model);
        assert_eq!(a.failures(), vec![Failure::Cost]);
        assert!((a.reduced_chi2() / 2.25 - 1.0).abs() < 0.1, "{a:?}");
        // The cause is the one the estimator's variance would miss.
        let d = a.diagnosis(None, "the cause").unwrap();
        assert!(d.ends_with("likely cause: the cause"), "{d}");
    }

    #[test]
    fn overstated_noise_is_a_finding_not_a_failure() {
        // Noise 0.9 of what the variance says, white: cost 0.81 dof, 4000
        // dof, so z = -0.19 * 4000 / sqrt(8000) = -8.5: the finding, and
        // no failure. Then noise that is a bin's own minus a share of its
        // neighbour's, e_k = a_k - 0.35 a_{k-1} (scaled to the stated
        // variance): each e has the stated variance, neighbours correlate
        // at -0.35 / (1 + 0.35^2) = -0.31, z = -0.31 sqrt(2 * 1999) = -20.
        let n = 2000;
        let freq: Vec<f64> = (1..=n).map(|k| k as f64 * 0.05).collect();
        let model = vec![Complex::new(1.0, 0.0); n];
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
        let unit = Normal::new(0.0, 0.01 / 2f64.sqrt()).unwrap();
        let a: Vec<Complex<f64>> = (0..=n)
            .map(|_| Complex::new(unit.sample(&mut rng), unit.sample(&mut rng)))
            .collect();
        let judge = |h: Vec<Complex<f64>>| judge_flat(&freq, &h, &model);
        let low = judge((0..n).map(|k| model[k] + a[k + 1] * 0.9).collect());
        assert!(low.passed(), "{low:?}");
        assert!((low.reduced_chi2() / 0.81 - 1.0).abs() < 0.05, "{low:?}");
        let said = low.overstated("the cause").expect("a finding");
        assert!(
            said.contains("std below") && said.ends_with("likely cause: the cause"),
            "{said}"
        );
        let scale = 1.0 / (1.0 + 0.35f64 * 0.35).sqrt();
        let anti = judge(
            (0..n)
                .map(|k| model[k] + (a[k + 1] - a[k] * 0.35) * scale)
                .collect(),
        );
        assert!(anti.passed(), "{anti:?}");
        let c = anti.correlation.as_ref().unwrap();
        assert!((c.r + 0.31).abs() < 0.05, "{c:?}");
        assert!(anti.overstated("").unwrap().contains("anticorrelate"));
    }

    #[test]
    fn pairs_skip_gaps_in_the_bins() {
        let pairs = |freq: &[f64], lag: usize| {
            let n = freq.len();
            let ones = vec![Complex::new(1.0, 0.0); n];
            let zeros = vec![Complex::new(0.5, 0.0); n];
            assess(
                &Residuals {
                    freq_hz: freq,
                    h: &ones,
                    model: &zeros,
                    variance: &vec![1.0; n],
                },
                0,
                1.0,
                lag,
            )
            .correlation
            .map(|c| c.pairs)
        };
        // Pairs one bin apart: (1, 2) and (4, 5) only; under 10: none.
        assert_eq!(pairs(&[1.0, 2.0, 4.0, 5.0, 7.0], 1), None);
        let even: Vec<f64> = (0..30).map(|k| (2 * k) as f64).collect();
        assert_eq!(pairs(&even, 1), None);
        assert_eq!(pairs(&even, 2), Some(29));
    }
}
