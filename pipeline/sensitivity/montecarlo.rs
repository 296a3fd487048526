//! The Monte Carlo side of the stiffness sensitivity (paper Sec. 2.3): what
//! the simulated identifications gave at each stiffness, the white noise
//! level they were drawn with, and how their spread compares with the
//! first-order (analytic) prediction. The simulations themselves are
//! `draws`'; this module is the pure arithmetic on their outcomes.

use std::collections::BTreeMap;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use statrs::distribution::{ChiSquared, ContinuousCDF};

use super::StiffnessSensitivity;

/// One value for each of beta1, a1b0, a2 and a3.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct PerParameter {
    pub beta1: f64,
    pub a1b0: f64,
    pub a2: f64,
    pub a3: f64,
}

impl PerParameter {
    pub const NAMES: [&'static str; 4] = ["beta1", "a1b0", "a2", "a3"];

    pub fn from_array(v: [f64; 4]) -> Self {
        Self {
            beta1: v[0],
            a1b0: v[1],
            a2: v[2],
            a3: v[3],
        }
    }

    pub fn to_array(self) -> [f64; 4] {
        [self.beta1, self.a1b0, self.a2, self.a3]
    }
}

/// The identifications at one stiffness over the seeds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct MonteCarloPoint {
    pub stiffness_n_per_m: f64,
    /// Seeds whose no-specimen and spring runs both identified.
    pub identified: usize,
    /// Seeds that did not, counted as `servoid run` would have failed the
    /// run: too few bins, a fit that did not converge or is unstable, Eqs.
    /// 18-20 without a physical solution.
    pub failed: usize,
    /// Why, with how many seeds each.
    pub failures: BTreeMap<String, usize>,
    /// mean / true - 1 over the identified seeds (null below two).
    pub rel_bias: Option<PerParameter>,
    /// Sample standard deviation / true value (null below two).
    pub rel_std: Option<PerParameter>,
    /// The first-order prediction at this stiffness, from the campaign's
    /// measured FRF noise.
    pub analytic_rel_std: Option<PerParameter>,
    /// rel_std / analytic_rel_std.
    pub ratio: Option<PerParameter>,
    /// Whether every ratio lies in the sampling band (null without an
    /// analytic prediction).
    pub agrees: Option<bool>,
    /// Why not, where it does not.
    pub note: Option<String>,
}

/// The Monte Carlo of a campaign: what it simulated and what it found.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct MonteCarlo {
    /// What was simulated, in words.
    pub basis: String,
    /// The no-specimen run whose command and noise it replays.
    pub excitation_run: String,
    /// The white displacement noise drawn (m rms).
    pub noise_rms_m: f64,
    /// How white the measured noise is: 90th over 10th percentile of its
    /// per-bin level (as an rms ratio), 1 for white noise.
    pub noise_whiteness: f64,
    /// The converter grid each simulated reading is rounded to (m).
    pub displacement_step_m: Option<f64>,
    /// The simulated command-to-displacement delay (s).
    pub delay_s: f64,
    pub sample_rate_hz: f64,
    /// Length of each simulated run (s).
    pub record_s: f64,
    pub seeds: u64,
    pub seed: u64,
    pub points: Vec<MonteCarloPoint>,
    pub agreement: Agreement,
}

/// The Monte Carlo against the analytic prediction.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Agreement {
    /// The 99 % band of a sample std over the true one for the seeds drawn
    /// (chi-square with seeds - 1 degrees of freedom): a point agrees when
    /// each of its four ratios lies inside.
    pub sampling_band: [f64; 2],
    /// Points where the noise is small: every analytic relative std below
    /// `SMALL_NOISE` (5 %), where first-order propagation holds.
    pub small_noise_points: usize,
    /// sqrt of the pooled variance ratio over those points, per parameter.
    pub pooled_ratio: Option<PerParameter>,
    /// The pooled ratio's own relative standard error from sampling,
    /// 1 / sqrt(2 sum(n - 1)).
    pub pooled_rel_error: Option<f64>,
    /// Whether every pooled ratio is within 10 % of 1.
    pub within_10_percent: Option<bool>,
    /// Points outside the sampling band, and how many chance alone gives.
    pub disagreeing_points: usize,
    pub expected_by_chance: f64,
    pub summary: String,
}

/// First-order propagation holds where every parameter's predicted
/// relative std is below this.
pub const SMALL_NOISE: f64 = 0.05;
/// The coverage of the per-point sampling band.
const BAND_COVERAGE: f64 = 0.99;
/// Noise whose level varies across the band by more than this factor
/// (90th over 10th percentile of the per-bin estimates) is not white.
pub const COLOURED: f64 = 3.0;

/// The white output noise a log's FRF variance implies, and how white it
/// is. A white noise of variance s^2 on y adds E|dH|^2 = 2 s^2 / (fs Suu)
/// to each ETFE or H1 bin (Suu one-sided, in unit^2/Hz), so each fitted bin
/// gives s^2 = fs Suu E|dH|^2 / 2. Returns the median of those (robust to
/// the few bins a resonance or the band's edges disturb) as an rms, and the
/// ratio of their 90th to 10th percentiles, 1 for white noise.
pub fn white_noise(variance: &[f64], suu: &[f64], sample_rate_hz: f64) -> Option<(f64, f64)> {
    let mut s2: Vec<f64> = variance
        .iter()
        .zip(suu)
        .map(|(v, s)| 0.5 * sample_rate_hz * s * v)
        .filter(|v| v.is_finite() && *v > 0.0)
        .collect();
    if s2.len() < 10 {
        return None;
    }
    s2.sort_by(f64::total_cmp);
    let q = |p: f64| s2[((s2.len() - 1) as f64 * p).round() as usize];
    Some((q(0.5).sqrt(), (q(0.9) / q(0.1)).sqrt()))
}

/// The statistics of one stiffness's identifications: `truth` the rig
/// they were simulated from.
pub fn point(
    stiffness_n_per_m: f64,
    outcomes: &[Result<[f64; 4], &str>],
    truth: [f64; 4],
) -> MonteCarloPoint {
    let got: Vec<[f64; 4]> = outcomes.iter().filter_map(|o| o.ok()).collect();
    let mut failures = BTreeMap::new();
    for e in outcomes.iter().filter_map(|o| o.err()) {
        *failures.entry(e.to_string()).or_insert(0) += 1;
    }
    let n = got.len() as f64;
    let (rel_bias, rel_std) = if got.len() >= 2 {
        let stat = |p: usize| {
            let mean = got.iter().map(|g| g[p]).sum::<f64>() / n;
            let var = got.iter().map(|g| (g[p] - mean).powi(2)).sum::<f64>() / (n - 1.0);
            (mean / truth[p] - 1.0, var.sqrt() / truth[p].abs())
        };
        let s: [(f64, f64); 4] = std::array::from_fn(stat);
        (
            Some(PerParameter::from_array(s.map(|x| x.0))),
            Some(PerParameter::from_array(s.map(|x| x.1))),
        )
    } else {
        (None, None)
    };
    MonteCarloPoint {
        stiffness_n_per_m,
        identified: got.len(),
        failed: outcomes.len() - got.len(),
        failures,
        rel_bias,
        rel_std,
        analytic_rel_std: None,
        ratio: None,
        agrees: None,
        note: None,
    }
}

/// Set each point's analytic prediction (`analytic`, a sweep at exactly
/// the points' stiffnesses), ratio, agreement and note; `noise_spread` is
/// the measured noise's whiteness (see [`white_noise`]).
pub fn compare(
    points: &mut [MonteCarloPoint],
    analytic: &StiffnessSensitivity,
    seeds: u64,
    noise_spread: f64,
) -> Agreement {
    let dof = seeds.saturating_sub(1).max(1) as f64;
    let band = ChiSquared::new(dof)
        .map(|c| {
            let tail = 0.5 * (1.0 - BAND_COVERAGE);
            [
                (c.inverse_cdf(tail) / dof).sqrt(),
                (c.inverse_cdf(1.0 - tail) / dof).sqrt(),
            ]
        })
        .unwrap_or([0.0, f64::INFINITY]);
    let mut pooled = [0.0; 4];
    let mut pooled_dof = 0.0;
    let mut small = 0;
    let mut compared = 0;
    let mut disagreeing = 0;
    for (i, p) in points.iter_mut().enumerate() {
        let Some(&k) = analytic.stiffness_n_per_m.get(i) else {
            continue;
        };
        // The sweep was asked for these stiffnesses; anything else is a
        // caller's mistake, and comparing at the wrong k would mislead.
        if (k / p.stiffness_n_per_m - 1.0).abs() > 1e-9 {
            continue;
        }
        let an = [
            analytic.rel_std_beta1[i],
            analytic.rel_std_a1b0[i],
            analytic.rel_std_a2[i],
            analytic.rel_std_a3[i],
        ];
        if !an.iter().all(|v| v.is_finite() && *v > 0.0) {
            continue;
        }
        p.analytic_rel_std = Some(PerParameter::from_array(an));
        let Some(mc) = p.rel_std else {
            p.note = Some(format!(
                "{} of {seeds} identifications failed ({}): no spread to compare",
                p.failed,
                reasons(&p.failures)
            ));
            continue;
        };
        let mc = mc.to_array();
        let ratio: [f64; 4] = std::array::from_fn(|j| mc[j] / an[j]);
        p.ratio = Some(PerParameter::from_array(ratio));
        compared += 1;
        let inside = ratio.iter().all(|r| (band[0]..=band[1]).contains(r));
        p.agrees = Some(inside);
        let is_small = an.iter().all(|v| *v < SMALL_NOISE);
        if is_small && p.failed == 0 {
            small += 1;
            let n1 = (p.identified - 1) as f64;
            for j in 0..4 {
                pooled[j] += n1 * ratio[j] * ratio[j];
            }
            pooled_dof += n1;
        }
        if !inside {
            disagreeing += 1;
            p.note = Some(why(p, &an, &ratio, band, is_small, noise_spread));
        }
    }
    let expected = compared as f64 * 4.0 * (1.0 - BAND_COVERAGE);
    let (pooled_ratio, pooled_rel_error, within) = if pooled_dof > 0.0 {
        let r = pooled.map(|v| (v / pooled_dof).sqrt());
        (
            Some(PerParameter::from_array(r)),
            Some(1.0 / (2.0 * pooled_dof).sqrt()),
            Some(r.iter().all(|v| (v - 1.0).abs() <= 0.10)),
        )
    } else {
        (None, None, None)
    };
    let summary = agreement_summary(
        points.len(),
        small,
        pooled_ratio,
        pooled_rel_error,
        within,
        disagreeing,
        expected,
        noise_spread,
    );
    Agreement {
        sampling_band: band,
        small_noise_points: small,
        pooled_ratio,
        pooled_rel_error,
        within_10_percent: within,
        disagreeing_points: disagreeing,
        expected_by_chance: expected,
        summary,
    }
}

fn reasons(failures: &BTreeMap<String, usize>) -> String {
    failures
        .iter()
        .map(|(why, n)| format!("{n} {why}"))
        .collect::<Vec<_>>()
        .join("; ")
}

/// Why a point's spread is not the first-order prediction, from what can
/// be seen: failed draws, noise too large for first order (then a bias
/// shows too), coloured noise, or, failing those, chance.
fn why(
    p: &MonteCarloPoint,
    an: &[f64; 4],
    ratio: &[f64; 4],
    band: [f64; 2],
    is_small: bool,
    noise_spread: f64,
) -> String {
    let worst = (0..4)
        .max_by(|&a, &b| {
            let off = |j: usize| ratio[j].ln().abs();
            off(a).total_cmp(&off(b))
        })
        .unwrap_or(0);
    let name = PerParameter::NAMES[worst];
    let mut text = format!(
        "{name}: Monte Carlo std {:.3} of the analytic one (99 % sampling band {:.2}-{:.2})",
        ratio[worst], band[0], band[1]
    );
    let mut causes = Vec::new();
    if p.failed > 0 {
        causes.push(format!(
            "{} of {} draws failed ({}), and the spread is of the rest",
            p.failed,
            p.failed + p.identified,
            reasons(&p.failures)
        ));
    }
    if !is_small {
        let big = an.iter().copied().fold(0.0, f64::max);
        causes.push(format!(
            "the noise is not small here (a predicted relative std of {:.1} %): Eqs. 18-20 are nonlinear in the fitted coefficients and first-order propagation no longer holds",
            100.0 * big
        ));
    }
    if let Some(b) = p.rel_bias {
        let b = b.to_array()[worst];
        let se = ratio[worst] * an[worst] / (p.identified as f64).sqrt();
        if b.abs() > 4.0 * se {
            causes.push(format!(
                "the estimates are biased by {:+.2} %, which a first-order analysis does not have",
                100.0 * b
            ));
        }
    }
    if noise_spread > COLOURED {
        causes.push(format!(
            "the measured noise is not white (its level varies {noise_spread:.1}-fold across the band): the analytic side uses it bin by bin, the Monte Carlo draws white noise at its median"
        ));
    }
    if causes.is_empty() {
        causes.push(
            "nothing the analysis can see: at 99 % coverage about one comparison in a hundred falls outside by chance".into(),
        );
    }
    text.push_str(": ");
    text.push_str(&causes.join("; "));
    text
}

#[allow(clippy::too_many_arguments)]
fn agreement_summary(
    points: usize,
    small: usize,
    pooled: Option<PerParameter>,
    pooled_err: Option<f64>,
    within: Option<bool>,
    disagreeing: usize,
    expected: f64,
    noise_spread: f64,
) -> String {
    let mut s = String::new();
    match (pooled, pooled_err, within) {
        (Some(r), Some(e), Some(w)) => {
            let r = r.to_array();
            s.push_str(&format!(
                "Where the noise is small ({small} of {points} stiffnesses), the Monte Carlo spread is {} the analytic prediction: pooled ratios beta1 {:.3}, a1b0 {:.3}, a2 {:.3}, a3 {:.3} (each +-{:.1} % from sampling alone).",
                if w { "within 10 % of" } else { "NOT within 10 % of" },
                r[0], r[1], r[2], r[3],
                100.0 * e
            ));
            if !w && noise_spread > COLOURED {
                s.push_str(&format!(
                    " The measured noise is not white (its level varies {noise_spread:.1}-fold across the band), which the Monte Carlo's white noise does not reproduce."
                ));
            }
        }
        _ => s.push_str(&format!(
            "No stiffness has noise small enough for first-order propagation (every predicted relative std below {:.0} %) with every draw identified, so the two are not compared there.",
            100.0 * SMALL_NOISE
        )),
    }
    s.push_str(&format!(
        " {disagreeing} of {points} stiffnesses fall outside the 99 % sampling band ({expected:.1} expected by chance); each says why."
    ));
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// White noise of known variance through the ETFE: the per-bin
    /// variance the local-polynomial method measures gives the noise back.
    /// Independent: the noise is drawn here, its rms known.
    #[test]
    fn the_frf_variance_gives_the_white_noise_level_back() {
        use crate::frf::{self, Detrend, FrfPlan, Method, Window};
        use rand_distr::{Distribution, Normal};
        let fs = 1000.0;
        let n = 60_000;
        let mut rng = crate::simulate::seeded_rng(3, "white");
        let unit = Normal::new(0.0, 1.0).unwrap();
        // A broadband command, and y = a smooth system's response + noise.
        let u: Vec<f64> = (0..n).map(|_| unit.sample(&mut rng)).collect();
        let sigma = 0.05;
        let y: Vec<f64> = (0..n)
            .map(|i| {
                let prev = if i > 0 { u[i - 1] } else { 0.0 };
                0.5 * u[i] + 0.3 * prev + sigma * unit.sample(&mut rng)
            })
            .collect();
        let plan =
            FrfPlan::new(Method::Etfe, 4096, 0.5, Window::Rectangular, Detrend::Mean).unwrap();
        let h = frf::estimate_one(&u, &y, fs, &plan).unwrap();
        let bins: Vec<usize> = (0..h.freq_hz.len())
            .filter(|&i| h.freq_hz[i] > 5.0 && h.freq_hz[i] < 400.0)
            .collect();
        let var = frf::h_variance_at(&h, &bins);
        // frf gives var(Re) and var(Im) each: E|dH|^2 is twice.
        let var: Vec<f64> = var.iter().map(|v| 2.0 * v).collect();
        let suu: Vec<f64> = bins.iter().map(|&i| h.suu[i]).collect();
        let (rms, spread) = white_noise(&var, &suu, fs).unwrap();
        assert!((rms / sigma - 1.0).abs() < 0.05, "{rms} vs {sigma}");
        assert!(spread < 1.5, "{spread}");
    }

    /// The band for 50 seeds from the chi-square quantiles, checked
    /// against the Wilson-Hilferty approximation by hand.
    #[test]
    fn the_sampling_band_is_the_chi_square_one() {
        let ks = vec![1e5];
        let sweep = StiffnessSensitivity {
            coefficient_rel_std: None,
            stiffness_n_per_m: ks.clone(),
            rel_std_beta1: vec![0.01],
            rel_std_a1b0: vec![0.01],
            rel_std_a2: vec![0.01],
            rel_std_a3: vec![0.01],
        };
        let mut pts = vec![point(1e5, &[Ok([1.0; 4]), Ok([1.0; 4])], [1.0; 4])];
        let a = compare(&mut pts, &sweep, 50, 1.0);
        // Wilson-Hilferty: chi2_q(v) ~ v (1 - 2/(9v) + z sqrt(2/(9v)))^3.
        let v = 49.0_f64;
        let wh = |z: f64| (1.0 - 2.0 / (9.0 * v) + z * (2.0 / (9.0 * v)).sqrt()).powi(3);
        let z = 2.575_829;
        assert!((a.sampling_band[0] - wh(-z).sqrt()).abs() < 0.005);
        assert!((a.sampling_band[1] - wh(z).sqrt()).abs() < 0.005);
    }

    /// Pooling: of two points with spreads 1.08 and 0.9 of the prediction,
    /// only the one without a failed draw pools; a failed seed's reason is
    /// counted; a point outside the band says why.
    #[test]
    fn points_pool_and_say_why() {
        let truth = [1.0, 2.0, 3.0, 4.0];
        // Two seeds each: std of {x - d, x + d} is d sqrt(2).
        let draws = |d: f64| -> Vec<Result<[f64; 4], &str>> {
            vec![
                Ok(truth.map(|t| t * (1.0 - d / 2f64.sqrt()))),
                Ok(truth.map(|t| t * (1.0 + d / 2f64.sqrt()))),
            ]
        };
        let mut pts = vec![point(1e4, &draws(0.0108), truth), {
            let mut o = draws(0.009);
            o.push(Err("an unstable fit"));
            point(1e5, &o, truth)
        }];
        assert_eq!(pts[1].failures.get("an unstable fit"), Some(&1));
        let rs = pts[0].rel_std.unwrap().to_array();
        for r in rs {
            assert!((r - 0.0108).abs() < 1e-12, "{r}");
        }
        let sweep = StiffnessSensitivity {
            coefficient_rel_std: None,
            stiffness_n_per_m: vec![1e4, 1e5],
            rel_std_beta1: vec![0.01, 0.01],
            rel_std_a1b0: vec![0.01, 0.01],
            rel_std_a2: vec![0.01, 0.01],
            rel_std_a3: vec![0.01, 0.01],
        };
        // Two seeds: the 99 % band is wide ([0.006, 2.8]); both agree.
        let a = compare(&mut pts, &sweep, 3, 1.0);
        assert_eq!(pts[0].agrees, Some(true));
        // Only the first pools: the second had a failed draw.
        assert_eq!(a.small_noise_points, 1);
        let p = a.pooled_ratio.unwrap().to_array();
        for r in p {
            assert!((r - 1.08).abs() < 1e-9, "{r}");
        }
        assert_eq!(a.within_10_percent, Some(true));

        // A spread 5 times the prediction with 50 "seeds" is outside.
        let sweep = StiffnessSensitivity {
            rel_std_a2: vec![0.00216, 0.01],
            ..sweep
        };
        let a = compare(&mut pts, &sweep, 50, 1.0);
        assert_eq!(pts[0].agrees, Some(false));
        let note = pts[0].note.as_deref().unwrap();
        assert!(note.starts_with("a2: Monte Carlo std 5.0"), "{note}");
        assert!(note.contains("chance"), "{note}");
        assert_eq!(pts[1].agrees, Some(true));
        assert_eq!(a.disagreeing_points, 1);
    }
}
