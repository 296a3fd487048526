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

use crate::identify::{self, SecondOrder, SpringRun, TfEstimate};
use crate::model::{self, LinearSpecimen, RigParams};

/// Predicted relative standard deviations (fractions) of the rig parameters
/// identified from one no-specimen run and one spring of each stiffness.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct StiffnessSensitivity {
    /// The relative standard deviation assumed for every fitted coefficient.
    pub coefficient_rel_std: f64,
    pub stiffness_n_per_m: Vec<f64>,
    pub rel_std_a1b0: Vec<f64>,
    pub rel_std_a2: Vec<f64>,
    pub rel_std_a3: Vec<f64>,
}

/// Why the analysis could not run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
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
}

/// Sweep `points` log-spaced stiffnesses over `range_n_per_m`, assuming each
/// fitted coefficient has relative standard deviation `coefficient_rel_std`
/// and independent errors.
pub fn stiffness_sweep(
    rig: &RigParams,
    range_n_per_m: (f64, f64),
    points: usize,
    coefficient_rel_std: f64,
) -> Result<StiffnessSensitivity, SensitivityError> {
    let (lo, hi) = range_n_per_m;
    if !(lo > 0.0 && hi > lo && hi.is_finite()) {
        return Err(SensitivityError::Range(lo, hi));
    }
    if !(coefficient_rel_std > 0.0 && coefficient_rel_std.is_finite()) {
        return Err(SensitivityError::Noise(coefficient_rel_std));
    }
    if !rig.is_physical() {
        return Err(SensitivityError::Rig(*rig));
    }
    let points = points.max(2);
    let estimate = |run: &str, spec: &LinearSpecimen| {
        let tf = SecondOrder::from_tf(&model::tf_x1_u(rig, spec))
            .expect("Eqs. 12 and 14 are second order");
        let var = |x: f64| (coefficient_rel_std * x).powi(2);
        TfEstimate {
            run: run.to_string(),
            p_gain: rig.p_gain,
            tf,
            cov: Some([
                [var(tf.n0), 0.0, 0.0],
                [0.0, var(tf.d1), 0.0],
                [0.0, 0.0, var(tf.d0)],
            ]),
        }
    };
    let no_spec = vec![estimate("no-specimen", &LinearSpecimen::None)];
    let mut out = StiffnessSensitivity {
        coefficient_rel_std,
        stiffness_n_per_m: Vec::with_capacity(points),
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
            ),
        };
        let id = identify::identify_rig(&no_spec, std::slice::from_ref(&spring))
            .map_err(|source| SensitivityError::Identify { k, source })?;
        let rel = |e: &identify::Estimate| e.std.unwrap_or(f64::NAN) / e.value.abs();
        out.stiffness_n_per_m.push(k);
        out.rel_std_a1b0.push(rel(&id.a1b0));
        out.rel_std_a2.push(rel(&id.a2));
        out.rel_std_a3.push(rel(&id.a3));
    }
    Ok(out)
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
        let s = stiffness_sweep(&r, (1e4, 1e7), 25, eps).unwrap();
        for (k, got) in s.stiffness_n_per_m.iter().zip(&s.rel_std_a1b0) {
            let a2 = r.a2_n_per_m;
            let want = eps * ((k + a2).powi(2) + a2 * a2).sqrt() / k;
            assert_relative_eq!(*got, want, max_relative = 1e-4);
        }
    }

    #[test]
    fn soft_springs_amplify_noise() {
        let s = stiffness_sweep(&crate::model::PAPER_RIG, (1e3, 1e7), 40, 1e-3).unwrap();
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
            stiffness_sweep(&crate::model::PAPER_RIG, (0.0, 1e5), 10, 1e-3),
            Err(SensitivityError::Range(..))
        ));
        assert!(matches!(
            stiffness_sweep(&crate::model::PAPER_RIG, (1e3, 1e5), 10, 0.0),
            Err(SensitivityError::Noise(_))
        ));
    }
}
