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
    let points = points.max(2);
    let estimate = |run: &str, spec: &LinearSpecimen, k: f64| {
        let tf = SecondOrder::from_tf(&model::tf_x1_u(rig, spec))
            .expect("Eqs. 12 and 14 are second order");
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
        stiffness_n_per_m: Vec::with_capacity(points),
        rel_std_beta1: Vec::with_capacity(points),
        rel_std_a1b0: Vec::with_capacity(points),
        rel_std_a2: Vec::with_capacity(points),
        rel_std_a3: Vec::with_capacity(points),
    };
    for i in 0..points {
        let k = lo * (hi / lo).powf(i as f64 / (points - 1) as f64);
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

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

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
