//! Sensitivity of the identified rig parameters to the spring stiffness, the
//! analysis the paper recommends before choosing springs (Sec. 2.3, after
//! Eq. 19): for a spring of stiffness k, how much do the relative errors of
//! the fitted coefficients (n0, d1, d0) grow into a1b0, a2 and a3?
//!
//! R3 = (1/n0 - 1/R1)/k is a difference of two nearly equal numbers when k is
//! small against a2, so its relative error is about (k + a2)/k times that of
//! n0; R2 depends on d0/n0 - 1 = beta1 a3 k / a1b0, also small for soft
//! springs. Stiff springs break the massless, linearised model instead (the
//! paper, Sec. 3.1), which this analysis cannot show: it only bounds the soft
//! end.

pub mod draws;
pub mod montecarlo;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::fit::{DelayPlan, FitError, FitInput, FitOptions, predicted_covariance};
use crate::identify::{self, SecondOrder, SpringRun, TfEstimate};
use crate::model::{self, LinearSpecimen, RigParams};

/// Predicted relative standard deviations (fractions) of the rig parameters
/// identified from one no-specimen run and one spring of each stiffness.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct StiffnessSensitivity {
    /// The relative standard deviation assumed for every fitted coefficient,
    /// when no log's noise was known (null when the noise was measured).
    pub coefficient_rel_std: Option<f64>,
    pub stiffness_n_per_m: Vec<f64>,
    pub rel_std_beta1: Vec<f64>,
    pub rel_std_a1b0: Vec<f64>,
    pub rel_std_a2: Vec<f64>,
    pub rel_std_a3: Vec<f64>,
}

impl StiffnessSensitivity {
    /// No stiffnesses.
    pub fn empty() -> Self {
        Self {
            coefficient_rel_std: None,
            stiffness_n_per_m: Vec::new(),
            rel_std_beta1: Vec::new(),
            rel_std_a1b0: Vec::new(),
            rel_std_a2: Vec::new(),
            rel_std_a3: Vec::new(),
        }
    }
}

/// `points` (at least 2) stiffnesses log-spaced over `range_n_per_m`, both
/// ends included: the grid of the sweep and of the Monte Carlo.
pub fn log_grid(range_n_per_m: (f64, f64), points: usize) -> Vec<f64> {
    let (lo, hi) = range_n_per_m;
    let points = points.max(2);
    (0..points)
        .map(|i| lo * (hi / lo).powf(i as f64 / (points - 1) as f64))
        .collect()
}

/// What a campaign's logs say of their noise, for runs not yet made: the
/// no-specimen run's fitted bins (band and coherence), the variance of its
/// FRF at each, its sample rate and delay. A spring run recorded with the
/// same excitation and sensors has the same FRF variance (the output noise
/// over the same command spectrum).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoiseProfile {
    pub run: String,
    pub freq_hz: Vec<f64>,
    /// E|dH|^2 at each bin.
    pub variance: Vec<f64>,
    pub sample_rate_hz: f64,
    /// The fitted (or fixed) delay of the no-specimen model (s).
    pub delay_s: f64,
    /// The white displacement noise (m rms) that variance implies, and its
    /// whiteness (see [`montecarlo::white_noise`]); None when too few bins
    /// tell.
    pub white_noise: Option<(f64, f64)>,
    /// The displacement channel's quantisation step (m), when its samples
    /// sit on a grid.
    pub displacement_step_m: Option<f64>,
    /// SHA-256 of the log, whose command the Monte Carlo replays.
    pub log_sha256: String,
}

/// How the fitted coefficients of a planned run would scatter.
#[derive(Debug, Clone, Copy)]
pub enum CoefficientNoise<'a> {
    /// Each coefficient with this relative std, independently: the
    /// assumption when no log's noise is known.
    Relative(f64),
    /// The campaign's measured FRF noise through the fit's own Jacobian
    /// and weights, the fit set up as `opts` says (hold, delay, orders).
    Measured {
        profile: &'a NoiseProfile,
        opts: &'a FitOptions,
    },
}

/// Why the analysis could not run.
#[derive(Debug, thiserror::Error)]
pub enum SensitivityError {
    #[error("the stiffness range must satisfy 0 < low < high (got {0} .. {1} N/m)")]
    Range(f64, f64),
    #[error("the coefficient relative std must be positive (got {0})")]
    Noise(f64),
    #[error("the rig parameters are not physical: {0:?}")]
    Rig(RigParams),
    #[error("at k = {k} N/m: {source}")]
    Identify {
        k: f64,
        #[source]
        source: identify::IdentifyError,
    },
    #[error("at k = {k} N/m, the planned fit: {source}")]
    Fit {
        k: f64,
        #[source]
        source: FitError,
    },
    #[error("at k = {k} N/m, the rig's model (Eq. 14) leaves f64's range: {source}")]
    Model {
        k: f64,
        #[source]
        source: crate::lti::LtiError,
    },
}

/// Sweep `points` log-spaced stiffnesses over `range_n_per_m`: the stds of
/// beta1, a1b0, a2 and a3 that one no-specimen run and one spring of each
/// stiffness would give (Eqs. 18-20, first-order propagation), their
/// coefficients scattering as `noise` says.
pub fn stiffness_sweep(
    rig: &RigParams,
    range_n_per_m: (f64, f64),
    points: usize,
    noise: CoefficientNoise<'_>,
) -> Result<StiffnessSensitivity, SensitivityError> {
    let (lo, hi) = range_n_per_m;
    if !(lo > 0.0 && hi > lo && hi.is_finite()) {
        return Err(SensitivityError::Range(lo, hi));
    }
    if let CoefficientNoise::Relative(eps) = noise
        && !(eps > 0.0 && eps.is_finite())
    {
        return Err(SensitivityError::Noise(eps));
    }
    if !rig.is_physical() {
        return Err(SensitivityError::Rig(*rig));
    }
    let estimate = |run: &str, spec: &LinearSpecimen, k: f64| {
        let tf =
            model::tf_x1_u(rig, spec).map_err(|source| SensitivityError::Model { k, source })?;
        let tf = SecondOrder::from_tf(&tf).expect("Eqs. 12 and 14 are second order");
        let cov =
            coefficient_cov(&tf, noise).map_err(|source| SensitivityError::Fit { k, source })?;
        Ok(TfEstimate {
            run: run.to_string(),
            p_gain: rig.p_gain,
            tf,
            cov: Some(cov),
        })
    };
    let no_spec = vec![estimate("no-specimen", &LinearSpecimen::None, 0.0)?];
    let mut out = StiffnessSensitivity {
        coefficient_rel_std: match noise {
            CoefficientNoise::Relative(eps) => Some(eps),
            CoefficientNoise::Measured { .. } => None,
        },
        ..StiffnessSensitivity::empty()
    };
    for k in log_grid(range_n_per_m, points) {
        let spring = SpringRun {
            stiffness_n_per_m: k,
            estimate: estimate(
                "spring",
                &LinearSpecimen::Spring {
                    stiffness_n_per_m: k,
                },
                k,
            )?,
        };
        let id = identify::identify_rig(&no_spec, std::slice::from_ref(&spring))
            .map_err(|source| SensitivityError::Identify { k, source })?;
        let rel = |e: &identify::Estimate| e.std.unwrap_or(f64::NAN) / e.value.abs();
        out.stiffness_n_per_m.push(k);
        out.rel_std_beta1.push(rel(&id.beta1));
        out.rel_std_a1b0.push(rel(&id.a1b0));
        out.rel_std_a2.push(rel(&id.a2));
        out.rel_std_a3.push(rel(&id.a3));
    }
    Ok(out)
}

/// The covariance of (n0, d1, d0) a run of model `tf` would be fitted with.
fn coefficient_cov(
    tf: &SecondOrder,
    noise: CoefficientNoise<'_>,
) -> Result<[[f64; 3]; 3], FitError> {
    match noise {
        CoefficientNoise::Relative(eps) => {
            let var = |x: f64| (eps * x).powi(2);
            Ok([
                [var(tf.n0), 0.0, 0.0],
                [0.0, var(tf.d1), 0.0],
                [0.0, 0.0, var(tf.d0)],
            ])
        }
        CoefficientNoise::Measured { profile, opts } => {
            // The planned model as the fit states it: (n0, d1, d0) and the
            // delay when it is fitted; the response only has to be finite.
            let mut params = vec![tf.n0, tf.d1, tf.d0];
            if matches!(opts.delay, DelayPlan::Fit { .. }) {
                params.push(profile.delay_s);
            }
            let plant = crate::lti::TransferFunction::new(&[tf.n0], &[1.0, tf.d1, tf.d0])
                .expect("a finite second-order model");
            let h: Vec<_> = profile
                .freq_hz
                .iter()
                .map(|&f| plant.freq_response(f))
                .collect();
            let input = FitInput {
                freq_hz: &profile.freq_hz,
                h: &h,
                variance: &profile.variance,
            };
            let c = predicted_covariance(&input, opts, &params)?;
            Ok(std::array::from_fn(|i| std::array::from_fn(|j| c[(i, j)])))
        }
    }
}

/// What a lab can act on: where each parameter's predicted relative std
/// is within the target, and how many spring tests a precision needs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Recommendation {
    /// The relative std aimed at (fraction).
    pub target_rel_std: f64,
    /// Per parameter, the stiffnesses of the sweep where it is within the
    /// target.
    pub ranges: Vec<StiffnessRange>,
    /// Spring tests for +-2 % on a2 and a3 at 95 % confidence.
    pub spring_tests: Vec<SpringTests>,
    /// A paragraph for the lab engineer.
    pub summary: String,
}

/// Where one parameter meets the target: from `low` to `high` (N/m), each
/// null where the sweep's own end is reached (the soft end then meets the
/// target already; the stiff end is the sweep's top, beyond which the
/// massless-spring model is not trusted anyway).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct StiffnessRange {
    pub parameter: String,
    /// False when no stiffness of the sweep meets the target.
    pub reachable: bool,
    pub low_n_per_m: Option<f64>,
    pub high_n_per_m: Option<f64>,
}

/// How many spring tests, averaged as the paper does, give a parameter to
/// `half_width_rel` at 95 % confidence: n = (1.96 s / half width)^2 with s
/// the relative std of one test.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct SpringTests {
    pub parameter: String,
    pub half_width_rel: f64,
    /// The stiffness the tests are planned at: the geometric mean of the
    /// campaign's springs.
    pub stiffness_n_per_m: f64,
    /// One test's relative std: the larger of the predicted one and the
    /// scatter between the campaign's springs.
    pub rel_std_per_test: f64,
    /// What set `rel_std_per_test`: "predicted" or "scatter between springs".
    pub basis: String,
    pub tests: u64,
}

/// Two-sided 95 % normal quantile.
const Z95: f64 = 1.959_963_984_540_054;
/// The precision the paper's users ask of a2 and a3.
const SPRING_TEST_HALF_WIDTH: f64 = 0.02;

/// The recommendation from a sweep: `springs` the campaign's spring
/// stiffnesses, `scatter` the relative sample std of the per-spring a2
/// and a3 when there are two springs or more.
pub fn recommend(
    sweep: &StiffnessSensitivity,
    target_rel_std: f64,
    springs: &[f64],
    scatter: Option<[f64; 2]>,
) -> Recommendation {
    let ks = &sweep.stiffness_n_per_m;
    let series: [(&str, &Vec<f64>); 4] = [
        ("beta1", &sweep.rel_std_beta1),
        ("a1b0", &sweep.rel_std_a1b0),
        ("a2", &sweep.rel_std_a2),
        ("a3", &sweep.rel_std_a3),
    ];
    let ranges: Vec<StiffnessRange> = series
        .iter()
        .map(|(name, rel)| within(name, ks, rel, target_rel_std))
        .collect();
    let k_plan = if springs.is_empty() {
        None
    } else {
        Some((springs.iter().map(|k| k.ln()).sum::<f64>() / springs.len() as f64).exp())
    };
    let spring_tests: Vec<SpringTests> = match k_plan {
        Some(k) => [("a2", &sweep.rel_std_a2, 0), ("a3", &sweep.rel_std_a3, 1)]
            .iter()
            .map(|(name, rel, j)| {
                let predicted = log_interp(ks, rel, k);
                let seen = scatter.map(|s| s[*j]).unwrap_or(0.0);
                let (s, basis) = if seen > predicted {
                    (seen, "scatter between springs")
                } else {
                    (predicted, "predicted")
                };
                SpringTests {
                    parameter: name.to_string(),
                    half_width_rel: SPRING_TEST_HALF_WIDTH,
                    stiffness_n_per_m: k,
                    rel_std_per_test: s,
                    basis: basis.into(),
                    tests: ((Z95 * s / SPRING_TEST_HALF_WIDTH).powi(2).ceil() as u64).max(1),
                }
            })
            .collect(),
        None => Vec::new(),
    };
    let summary = summary(
        &ranges,
        &spring_tests,
        target_rel_std,
        springs,
        ks,
        sweep.coefficient_rel_std,
    );
    Recommendation {
        target_rel_std,
        ranges,
        spring_tests,
        summary,
    }
}

/// The part of the sweep where `rel <= target`, its ends interpolated in
/// log k and log rel between the grid points that straddle them.
fn within(name: &str, ks: &[f64], rel: &[f64], target: f64) -> StiffnessRange {
    let ok: Vec<bool> = rel.iter().map(|r| *r <= target).collect();
    let Some(first) = ok.iter().position(|o| *o) else {
        return StiffnessRange {
            parameter: name.into(),
            reachable: false,
            low_n_per_m: None,
            high_n_per_m: None,
        };
    };
    let last = ok.iter().rposition(|o| *o).unwrap_or(first);
    let cross = |i: usize, j: usize| {
        // rel crosses target between grid points i and j.
        let t = (target / rel[i]).ln() / (rel[j] / rel[i]).ln();
        (ks[i].ln() + t * (ks[j] / ks[i]).ln()).exp()
    };
    StiffnessRange {
        parameter: name.into(),
        reachable: true,
        low_n_per_m: (first > 0).then(|| cross(first - 1, first)),
        high_n_per_m: (last + 1 < ks.len()).then(|| cross(last, last + 1)),
    }
}

/// `ys` at `x` by linear interpolation in log x and log y (clamped to the
/// grid's ends).
fn log_interp(xs: &[f64], ys: &[f64], x: f64) -> f64 {
    if x <= xs[0] {
        return ys[0];
    }
    let Some(i) = xs.windows(2).position(|w| x <= w[1]) else {
        return ys[ys.len() - 1];
    };
    let t = (x / xs[i]).ln() / (xs[i + 1] / xs[i]).ln();
    (ys[i].ln() + t * (ys[i + 1] / ys[i]).ln()).exp()
}

fn summary(
    ranges: &[StiffnessRange],
    tests: &[SpringTests],
    target: f64,
    springs: &[f64],
    ks: &[f64],
    assumed: Option<f64>,
) -> String {
    let kn = |k: f64| format!("{:.1} kN/m", k / 1e3);
    let mut out = String::new();
    let noise = match assumed {
        None => "this campaign's measured noise".to_string(),
        Some(e) => format!(
            "an assumed {} % relative std of each fitted coefficient (no log measured the noise)",
            100.0 * e
        ),
    };
    let parts: Vec<String> = ranges
        .iter()
        .map(|r| match (r.reachable, r.low_n_per_m, r.high_n_per_m) {
            (false, ..) => format!(
                "{} nowhere in {}-{}",
                r.parameter,
                kn(ks[0]),
                kn(ks[ks.len() - 1])
            ),
            (true, None, None) => format!("{} everywhere in the sweep", r.parameter),
            (true, Some(lo), None) => format!("{} above {}", r.parameter, kn(lo)),
            (true, None, Some(hi)) => format!("{} below {}", r.parameter, kn(hi)),
            (true, Some(lo), Some(hi)) => format!("{} from {} to {}", r.parameter, kn(lo), kn(hi)),
        })
        .collect();
    out.push_str(&format!(
        "With this rig and {noise}, one no-specimen run and one spring give each parameter within {} % (1 std) for springs: {}.",
        100.0 * target,
        parts.join("; ")
    ));
    if !springs.is_empty() {
        let soft: Vec<String> = springs
            .iter()
            .filter(|k| {
                ranges
                    .iter()
                    .any(|r| !r.reachable || r.low_n_per_m.is_some_and(|lo| **k < lo))
            })
            .map(|k| kn(*k))
            .collect();
        if soft.is_empty() {
            out.push_str(" The campaign's springs are all stiff enough.");
        } else {
            out.push_str(&format!(
                " Too soft for the target: {} (soft springs amplify the fit's error about (k + a2)/k times); choose a stiffer spring or repeat it.",
                soft.join(", ")
            ));
        }
    }
    for t in tests {
        out.push_str(&format!(
            " For +-{:.0} % on {} at 95 % confidence: {} spring test{} at {} (one test's relative std {:.2e}, {}).",
            100.0 * t.half_width_rel,
            t.parameter,
            t.tests,
            if t.tests == 1 { "" } else { "s" },
            kn(t.stiffness_n_per_m),
            t.rel_std_per_test,
            t.basis
        ));
    }
    if tests.iter().any(|t| t.basis != "predicted") {
        out.push_str(" The springs scatter more than their noise explains: more tests average it down only if that scatter is random; check the springs' consistency first.");
    }
    out.push_str(" What limits the stiff end is not noise but the paper's massless, linearised spring (Eq. 14): a spring whose own mass or attachment moves within the band, or a stiffness comparable to the actuator's oil column a2, is outside the model, which this analysis cannot see.");
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    /// A sweep whose relative stds fall as c/k (soft springs amplify):
    /// log-log linear, so the target's crossing interpolates exactly to
    /// k = c / target.
    fn falling(c: [f64; 4]) -> StiffnessSensitivity {
        let ks: Vec<f64> = (0..31).map(|i| 1e4 * 10f64.powf(i as f64 / 10.0)).collect();
        let rel = |c: f64| ks.iter().map(|k| c / k).collect::<Vec<_>>();
        StiffnessSensitivity {
            coefficient_rel_std: None,
            rel_std_beta1: vec![1e-4; ks.len()],
            rel_std_a1b0: rel(c[1]),
            rel_std_a2: rel(c[2]),
            rel_std_a3: rel(c[3]),
            stiffness_n_per_m: ks,
        }
    }

    #[test]
    fn ranges_cross_the_target_where_the_law_says() {
        // a1b0: 2000/k <= 0.01 from k = 2e5; a2 never below 1 % (1e6/k at
        // k <= 1e7 is >= 0.1); a3 within it everywhere (50/k <= 0.005).
        let r = recommend(&falling([0.0, 2000.0, 1e6, 50.0]), 0.01, &[1e5], None);
        let by = |p: &str| r.ranges.iter().find(|x| x.parameter == p).unwrap().clone();
        assert_relative_eq!(by("a1b0").low_n_per_m.unwrap(), 2e5, max_relative = 1e-9);
        assert_eq!(by("a1b0").high_n_per_m, None);
        assert!(!by("a2").reachable);
        assert!(by("a3").reachable && by("a3").low_n_per_m.is_none());
        assert!(r.summary.contains("a1b0 above 200.0 kN/m"), "{}", r.summary);
        assert!(
            r.summary.contains("Too soft for the target: 100.0 kN/m"),
            "{}",
            r.summary
        );
        assert!(r.summary.contains("massless"), "{}", r.summary);
    }

    /// n = ceil((1.96 s / 0.02)^2): s = 1 % needs 1 test (0.96), s = 5 %
    /// needs 25 (24.01); the scatter between springs counts when larger.
    #[test]
    fn spring_tests_follow_the_normal_law() {
        // At k = 1e5: a2's predicted rel std 1000/1e5 = 1 %, a3's 5000/1e5 = 5 %.
        let r = recommend(&falling([0.0, 1.0, 1000.0, 5000.0]), 0.01, &[1e5], None);
        assert_eq!(r.spring_tests[0].tests, 1);
        assert_eq!(r.spring_tests[1].tests, 25);
        assert_eq!(r.spring_tests[1].basis, "predicted");
        // Two springs around 1e5 (geometric mean 1e5) that scatter 10 % in a2.
        let r = recommend(
            &falling([0.0, 1.0, 1000.0, 5000.0]),
            0.01,
            &[5e4, 2e5],
            Some([0.1, 0.01]),
        );
        assert_relative_eq!(
            r.spring_tests[0].stiffness_n_per_m,
            1e5,
            max_relative = 1e-12
        );
        assert_eq!(r.spring_tests[0].basis, "scatter between springs");
        // (1.96 * 0.1 / 0.02)^2 = 96.04.
        assert_eq!(r.spring_tests[0].tests, 97);
        assert_eq!(r.spring_tests[1].tests, 25);
        assert!(
            r.summary.contains("check the springs' consistency"),
            "{}",
            r.summary
        );
    }

    #[test]
    fn a1b0_error_follows_the_closed_form_conditioning() {
        // a1b0 = 1/R3 with R3 = (1/n0_s - 1/R1)/k, R1 = d0_ns (d2 = 1). With
        // independent relative errors eps on n0_s and d0_ns, first-order
        // propagation by hand gives
        //   rel(a1b0)^2 = eps^2 [ (1/n0_s)^2 + (1/R1)^2 ] / (1/n0_s - 1/R1)^2
        // and 1/n0_s - 1/R1 = k/a1b0, 1/n0_s = (k + a2)/a1b0, 1/R1 = a2/a1b0:
        //   rel(a1b0) = eps sqrt((k + a2)^2 + a2^2) / k.
        let r = crate::model::PAPER_RIG;
        let eps = 1e-3;
        let s = stiffness_sweep(&r, (1e4, 1e7), 25, CoefficientNoise::Relative(eps)).unwrap();
        for (k, got) in s.stiffness_n_per_m.iter().zip(&s.rel_std_a1b0) {
            let a2 = r.a2_n_per_m;
            let want = eps * ((k + a2).powi(2) + a2 * a2).sqrt() / k;
            assert_relative_eq!(*got, want, max_relative = 1e-4);
        }
    }

    #[test]
    fn soft_springs_amplify_noise() {
        let s = stiffness_sweep(
            &crate::model::PAPER_RIG,
            (1e3, 1e7),
            40,
            CoefficientNoise::Relative(1e-3),
        )
        .unwrap();
        // Monotone improvement with stiffness over this range for a1b0 and a2.
        for w in s.rel_std_a1b0.windows(2) {
            assert!(w[1] < w[0]);
        }
        // At k = a2/100 the error is amplified more than a hundredfold.
        assert!(s.rel_std_a2[0] > 100.0 * 1e-3);
    }

    #[test]
    fn bad_ranges_are_rejected() {
        assert!(matches!(
            stiffness_sweep(
                &crate::model::PAPER_RIG,
                (0.0, 1e5),
                10,
                CoefficientNoise::Relative(1e-3)
            ),
            Err(SensitivityError::Range(..))
        ));
        assert!(matches!(
            stiffness_sweep(
                &crate::model::PAPER_RIG,
                (1e3, 1e5),
                10,
                CoefficientNoise::Relative(0.0)
            ),
            Err(SensitivityError::Noise(_))
        ));
    }
}
