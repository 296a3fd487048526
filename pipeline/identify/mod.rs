//! Rig parameters from identified transfer functions (paper Sec. 2.3,
//! Eqs. 18-20, Fig. 6): beta1 and R1 from the no-specimen run, R2 and R3 from
//! each spring run, then a1b0, a2 and a3 per spring and their mean.
//!
//! Standard deviations are propagated to first order, sigma_out = J Sigma J^T,
//! from the covariance of each fitted (n0, d1, d0); the runs are independent
//! experiments, so their covariances form a block-diagonal Sigma, and the
//! shared no-specimen run correlates the springs (J is taken over everything).

pub mod amplitude;
pub mod bins;
pub mod consistency;
pub mod joint;
mod run_fit;
mod settings;

pub use run_fit::{FitData, RunTfError, UnstableCause, fit_options, fit_run};
pub use settings::IdentificationPlan;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::lti::TransferFunction;
use crate::model::RigParams;

/// A value with its standard deviation (null when the inputs had none, e.g.
/// published transfer functions).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Estimate {
    pub value: f64,
    pub std: Option<f64>,
}

impl Estimate {
    pub fn exact(value: f64) -> Self {
        Self { value, std: None }
    }
}

/// x1/u = n0 / (s^2 + d1 s + d0): the second-order form of Eqs. 11 and 13
/// with d2 normalised to 1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SecondOrder {
    pub n0: f64,
    pub d1: f64,
    pub d0: f64,
}

impl SecondOrder {
    /// From a transfer function that must be n0 / (d2 s^2 + d1 s + d0).
    pub fn from_tf(tf: &TransferFunction) -> Result<Self, IdentifyError> {
        if tf.den.len() != 3 || tf.num.len() != 1 {
            return Err(IdentifyError::NotSecondOrder {
                numerator: tf.num.len() - 1,
                denominator: tf.den.len() - 1,
            });
        }
        let d2 = tf.den[0];
        Ok(Self {
            n0: tf.num[0] / d2,
            d1: tf.den[1] / d2,
            d0: tf.den[2] / d2,
        })
    }

    fn as_array(&self) -> [f64; 3] {
        [self.n0, self.d1, self.d0]
    }
}

/// One identification run's fitted model and, when known, the 3x3 covariance
/// of (n0, d1, d0) in that order.
#[derive(Debug, Clone, PartialEq)]
pub struct TfEstimate {
    pub run: String,
    pub p_gain: f64,
    pub tf: SecondOrder,
    pub cov: Option<[[f64; 3]; 3]>,
}

/// A spring identification run: its stiffness and its fitted model.
#[derive(Debug, Clone, PartialEq)]
pub struct SpringRun {
    pub stiffness_n_per_m: f64,
    pub estimate: TfEstimate,
}

/// Per-spring results (Eqs. 19-20). a1b0 is stated at the rig's reference P.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[allow(non_snake_case)]
pub struct PerSpring {
    pub run: String,
    pub stiffness_n_per_m: f64,
    /// R2 = a1b0/a3 at this run's P gain (Eq. 19).
    pub R2: Estimate,
    /// R3 = 1/a1b0 at this run's P gain (Eq. 19).
    pub R3: Estimate,
    pub a1b0: Estimate,
    pub a2: Estimate,
    pub a3: Estimate,
}

/// The identified rig: Eq. 18 from the no-specimen run(s), Eq. 20 averaged
/// over the springs as the paper does.
#[derive(Debug, Clone, PartialEq)]
pub struct RigIdentification {
    /// P gain at which a1b0 and R1 are stated (the no-specimen run's).
    pub p_gain: f64,
    pub beta1: Estimate,
    pub r1: Estimate,
    pub a1b0: Estimate,
    pub a2: Estimate,
    pub a3: Estimate,
    pub per_spring: Vec<PerSpring>,
    /// Whether the springs agree within their propagated stds.
    pub consistency: consistency::Consistency,
    /// Covariance of (beta1, a1b0, a2, a3), a1b0 at `p_gain`, by
    /// first-order propagation; None without the runs' covariances.
    pub covariance: Option<[[f64; 4]; 4]>,
}

impl RigIdentification {
    /// The point estimate as model parameters.
    pub fn params(&self) -> RigParams {
        RigParams {
            beta1_per_s: self.beta1.value,
            a1b0_n_per_m_s2: self.a1b0.value,
            a2_n_per_m: self.a2.value,
            a3_per_s: self.a3.value,
            p_gain: self.p_gain,
        }
    }
}

/// Why the algebra could not produce physical parameters.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IdentifyError {
    #[error("no no-specimen run to give beta1 and R1 (Eq. 18)")]
    NoNoSpecimenRun,
    #[error("no spring run to give R2 and R3 (Eq. 19)")]
    NoSpringRun,
    #[error(
        "the paper's procedure needs a second-order model n0/(s^2 + d1 s + d0); got numerator degree {numerator} and denominator degree {denominator}"
    )]
    NotSecondOrder {
        numerator: usize,
        denominator: usize,
    },
    #[error(
        "run {run}: {quantity} = {value:.6e} is not positive, so the rig parameters are not physical{hint}"
    )]
    NonPhysical {
        run: String,
        quantity: &'static str,
        value: f64,
        hint: &'static str,
    },
}

/// Outputs of [`compute`] in order: beta1, R1, a1b0, a2, a3, then per spring
/// R2, R3, a1b0, a2, a3.
const HEAD: usize = 5;
const PER_SPRING: usize = 5;

/// The whole algebra as one function of the stacked coefficients
/// theta = [no-specimen runs' (n0, d1, d0)..., springs' (n0, d1, d0)...], so
/// the Jacobian for the propagation covers every dependency.
fn compute(theta: &[f64], no_spec: &[TfEstimate], springs: &[SpringRun], p_ref: f64) -> Vec<f64> {
    let ns = no_spec.len();
    // Eq. 18 per no-specimen run (d2 = 1), R1 referred to the reference P.
    let mut beta1 = 0.0;
    let mut r1 = 0.0;
    for (i, run) in no_spec.iter().enumerate() {
        let (d1, d0) = (theta[3 * i + 1], theta[3 * i + 2]);
        beta1 += d1;
        r1 += d0 * p_ref / run.p_gain;
    }
    beta1 /= ns as f64;
    r1 /= ns as f64;

    let mut out = vec![0.0; HEAD + PER_SPRING * springs.len()];
    out[0] = beta1;
    out[1] = r1;
    let (mut s_a1b0, mut s_a2, mut s_a3) = (0.0, 0.0, 0.0);
    for (j, spring) in springs.iter().enumerate() {
        let base = 3 * (ns + j);
        let (n0, d0) = (theta[base], theta[base + 2]);
        let k = spring.stiffness_n_per_m;
        let p = spring.estimate.p_gain;
        // R1 at this run's P gain: R1 = a1b0/a2 is proportional to P.
        let r1_p = r1 * p / p_ref;
        // Eq. 19 with d2 = 1.
        let r2 = beta1 * k / (d0 / n0 - 1.0);
        let r3 = (1.0 / n0 - 1.0 / r1_p) / k;
        // Eq. 20, a1b0 referred back to the reference P.
        let a1b0 = (1.0 / r3) * p_ref / p;
        let a2 = 1.0 / (r3 * r1_p);
        let a3 = 1.0 / (r2 * r3);
        let o = HEAD + PER_SPRING * j;
        out[o..o + PER_SPRING].copy_from_slice(&[r2, r3, a1b0, a2, a3]);
        s_a1b0 += a1b0;
        s_a2 += a2;
        s_a3 += a3;
    }
    let n = springs.len() as f64;
    out[2] = s_a1b0 / n;
    out[3] = s_a2 / n;
    out[4] = s_a3 / n;
    out
}

/// Identify the rig from the no-specimen run(s) and the spring runs.
///
/// Several no-specimen runs are averaged (repeat tests); runs at different P
/// gains are referred to the first no-specimen run's P gain.
pub fn identify_rig(
    no_spec: &[TfEstimate],
    springs: &[SpringRun],
) -> Result<RigIdentification, IdentifyError> {
    let first = no_spec.first().ok_or(IdentifyError::NoNoSpecimenRun)?;
    if springs.is_empty() {
        return Err(IdentifyError::NoSpringRun);
    }
    let p_ref = first.p_gain;
    let theta: Vec<f64> = no_spec
        .iter()
        .map(|e| e.tf.as_array())
        .chain(springs.iter().map(|s| s.estimate.tf.as_array()))
        .flatten()
        .collect();
    let values = compute(&theta, no_spec, springs, p_ref);
    check_physical(no_spec, springs, &values)?;

    // The algebra's Jacobian and the runs' covariances, once: every std and
    // covariance below is first-order propagation through them (None when
    // a run has no covariance).
    let propagation = run_covariances(no_spec, springs)
        .map(|covs| (jacobian(&theta, no_spec, springs, p_ref), covs));
    let stds = propagation
        .as_ref()
        .map(|(jac, covs)| propagate(jac, covs, values.len()));
    let consistency = consistency::check(
        &(springs.iter().enumerate())
            .map(|(j, s)| consistency::PerSpringValues {
                run: s.estimate.run.clone(),
                values: [2, 3, 4].map(|i| values[HEAD + PER_SPRING * j + i]),
            })
            .collect::<Vec<_>>(),
        propagation
            .as_ref()
            .map(|(jac, covs)| spring_covariances(jac, covs, springs.len()))
            .as_ref(),
    );
    let covariance = propagation.as_ref().map(|(jac, covs)| {
        let c = propagated(jac, covs, &[0, 2, 3, 4]);
        std::array::from_fn(|i| std::array::from_fn(|j| c[(i, j)]))
    });
    let est = |i: usize| Estimate {
        value: values[i],
        std: stds.as_ref().map(|s| s[i]),
    };
    Ok(RigIdentification {
        p_gain: p_ref,
        beta1: est(0),
        r1: est(1),
        a1b0: est(2),
        a2: est(3),
        a3: est(4),
        per_spring: per_spring(springs, &est),
        consistency,
        covariance,
    })
}

/// Physical checks of the runs' coefficients and of [`compute`]'s
/// `values`, naming the run responsible: each no-specimen run's beta1 and
/// R1, each spring's R2, R3, a1b0, a2 and a3 positive.
fn check_physical(
    no_spec: &[TfEstimate],
    springs: &[SpringRun],
    values: &[f64],
) -> Result<(), IdentifyError> {
    for run in no_spec {
        for (q, v) in [("beta1 = d1/d2", run.tf.d1), ("R1 = d0/d2", run.tf.d0)] {
            if v.is_nan() || v <= 0.0 {
                return Err(IdentifyError::NonPhysical {
                    run: run.run.clone(),
                    quantity: q,
                    value: v,
                    hint: "",
                });
            }
        }
    }
    for (j, spring) in springs.iter().enumerate() {
        let o = HEAD + PER_SPRING * j;
        let names = ["R2", "R3", "a1b0", "a2", "a3"];
        for (i, name) in names.iter().enumerate() {
            let v = values[o + i];
            if !(v.is_finite() && v > 0.0) {
                return Err(IdentifyError::NonPhysical {
                    run: spring.estimate.run.clone(),
                    quantity: name,
                    value: v,
                    hint: " (Eq. 19 needs d0/n0 > 1 and 1/n0 > 1/R1: the spring must lower the static gain and the high-frequency gain; a too soft spring or noisy fit breaks this)",
                });
            }
        }
    }
    Ok(())
}

/// Each spring run's own R2, R3, a1b0, a2 and a3, `est` giving the output
/// of [`compute`] at an index.
fn per_spring(springs: &[SpringRun], est: &dyn Fn(usize) -> Estimate) -> Vec<PerSpring> {
    springs
        .iter()
        .enumerate()
        .map(|(j, s)| {
            let o = HEAD + PER_SPRING * j;
            PerSpring {
                run: s.estimate.run.clone(),
                stiffness_n_per_m: s.stiffness_n_per_m,
                R2: est(o),
                R3: est(o + 1),
                a1b0: est(o + 2),
                a2: est(o + 3),
                a3: est(o + 4),
            }
        })
        .collect()
}

/// The Jacobian of [`compute`] by rows, each input's row holding only the
/// outputs it moves, in ascending order, as (output, derivative): a
/// spring's outputs do not depend on another spring's fit, so with n
/// springs a row holds O(1) entries but the no-specimen runs', and the
/// propagation below costs O(n^2), not O(n^3).
type Jacobian = Vec<Vec<(usize, f64)>>;

/// The products a * c * b of two rows' entries at the outputs both hold,
/// in ascending output order.
fn common<'a>(
    a: &'a [(usize, f64)],
    b: &'a [(usize, f64)],
    c: f64,
) -> impl Iterator<Item = (usize, f64)> + 'a {
    let mut j = 0;
    a.iter().filter_map(move |&(o, x)| {
        while j < b.len() && b[j].0 < o {
            j += 1;
        }
        (j < b.len() && b[j].0 == o).then(|| (o, x * c * b[j].1))
    })
}

/// Standard deviations of the `m` outputs of [`compute`] by first-order
/// propagation through its Jacobian `jac` of the runs' covariances `covs`.
fn propagate(jac: &Jacobian, covs: &[[[f64; 3]; 3]], m: usize) -> Vec<f64> {
    let mut var = vec![0.0; m];
    for (b, cov) in covs.iter().enumerate() {
        for p in 0..3 {
            for q in 0..3 {
                let c = cov[p][q];
                if c == 0.0 {
                    continue;
                }
                for (o, v) in common(&jac[3 * b + p], &jac[3 * b + q], c) {
                    var[o] += v;
                }
            }
        }
    }
    var.into_iter().map(|v| v.max(0.0).sqrt()).collect()
}

/// The runs' coefficient covariances in theta's order; None when any run
/// lacks one.
fn run_covariances(no_spec: &[TfEstimate], springs: &[SpringRun]) -> Option<Vec<[[f64; 3]; 3]>> {
    no_spec
        .iter()
        .map(|e| e.cov)
        .chain(springs.iter().map(|s| s.estimate.cov))
        .collect()
}

/// jac[i] = d out / d theta_i of [`compute`], by central differences, the
/// outputs theta_i leaves exactly unchanged left out.
fn jacobian(theta: &[f64], no_spec: &[TfEstimate], springs: &[SpringRun], p_ref: f64) -> Jacobian {
    let mut jac = Vec::with_capacity(theta.len());
    let mut t = theta.to_vec();
    for i in 0..theta.len() {
        let h = 1e-6 * theta[i].abs().max(1e-12);
        t[i] = theta[i] + h;
        let plus = compute(&t, no_spec, springs, p_ref);
        t[i] = theta[i] - h;
        let minus = compute(&t, no_spec, springs, p_ref);
        t[i] = theta[i];
        jac.push(
            (plus.iter().zip(&minus).enumerate())
                .filter(|(_, (p, m))| p != m)
                .map(|(o, (p, m))| (o, (p - m) / (2.0 * h)))
                .collect(),
        );
    }
    jac
}

/// J C J' restricted to the outputs `at`, C block-diagonal by run. Each
/// entry sums its runs' terms in their order; the terms of a run that
/// moves neither output are zero, and left out.
fn propagated(jac: &Jacobian, covs: &[[[f64; 3]; 3]], at: &[usize]) -> nalgebra::DMatrix<f64> {
    let mut place = std::collections::HashMap::new();
    for (k, &o) in at.iter().enumerate() {
        place.insert(o, k);
    }
    let mut c = nalgebra::DMatrix::zeros(at.len(), at.len());
    let mut rows: [Vec<(usize, f64)>; 3] = Default::default();
    for (r, cov) in covs.iter().enumerate() {
        // Run r's rows at the outputs asked for, by their place in `at`.
        for (p, row) in rows.iter_mut().enumerate() {
            row.clear();
            row.extend(
                jac[3 * r + p]
                    .iter()
                    .filter_map(|&(o, v)| Some((*place.get(&o)?, v))),
            );
        }
        for p in 0..3 {
            for q in 0..3 {
                for &(a, x) in &rows[p] {
                    for &(b, y) in &rows[q] {
                        c[(a, b)] += x * cov[p][q] * y;
                    }
                }
            }
        }
    }
    c
}

/// The joint covariance over the springs of each of a1b0, a2 and a3 (Eq.
/// 20) for `n` springs, by first-order propagation: the springs share the
/// no-specimen run, so their values are correlated.
fn spring_covariances(
    jac: &Jacobian,
    covs: &[[[f64; 3]; 3]],
    n: usize,
) -> [nalgebra::DMatrix<f64>; 3] {
    [2, 3, 4].map(|i| {
        let at: Vec<usize> = (0..n).map(|j| HEAD + PER_SPRING * j + i).collect();
        propagated(jac, covs, &at)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{LinearSpecimen, tf_x1_u};
    use approx::assert_relative_eq;

    fn est(run: &str, p: f64, num: f64, den: [f64; 3]) -> TfEstimate {
        let tf = TransferFunction::new(&[num], &den).unwrap();
        TfEstimate {
            run: run.into(),
            p_gain: p,
            tf: SecondOrder::from_tf(&tf).unwrap(),
            cov: None,
        }
    }

    /// The published transfer functions, Eqs. 36-38.
    fn paper_inputs() -> (Vec<TfEstimate>, Vec<SpringRun>) {
        (
            vec![est("no-specimen", 1.0, 3060.0, [1.0, 267.0, 3060.0])],
            vec![
                SpringRun {
                    stiffness_n_per_m: 116_640.0,
                    estimate: est("k1", 1.0, 2703.0, [1.0, 263.4, 3337.0]),
                },
                SpringRun {
                    stiffness_n_per_m: 88_540.0,
                    estimate: est("k2", 1.0, 2714.0, [1.0, 262.4, 3073.0]),
                },
            ],
        )
    }

    #[test]
    fn paper_values_from_published_transfer_functions() {
        // Paper Sec. 3.1: beta1 = 267, R1 = 3060, a2 = 8.83e5 / 6.95e5,
        // a3 = 20.35 / 11.89, means a1b0 = 2.412e9, a2 = 7.881e5, a3 = 16.118.
        let (ns, springs) = paper_inputs();
        let rig = identify_rig(&ns, &springs).unwrap();
        assert_relative_eq!(rig.beta1.value, 267.0, max_relative = 1e-12);
        assert_relative_eq!(rig.r1.value, 3060.0, max_relative = 1e-12);
        assert_relative_eq!(rig.per_spring[0].a2.value, 8.83e5, max_relative = 5e-3);
        assert_relative_eq!(rig.per_spring[1].a2.value, 6.95e5, max_relative = 5e-3);
        assert_relative_eq!(rig.per_spring[0].a3.value, 20.35, max_relative = 5e-3);
        assert_relative_eq!(rig.per_spring[1].a3.value, 11.89, max_relative = 5e-3);
        assert_relative_eq!(rig.a1b0.value, 2.412e9, max_relative = 5e-3);
        assert_relative_eq!(rig.a2.value, 7.881e5, max_relative = 5e-3);
        assert_relative_eq!(rig.a3.value, 16.118, max_relative = 5e-3);
        assert!(rig.a1b0.std.is_none());
    }

    #[test]
    fn exact_round_trip_from_the_model() {
        // Transfer functions generated by Eqs. 12 and 14 from known parameters
        // must give those parameters back exactly (up to round-off).
        let truth = RigParams {
            beta1_per_s: 180.0,
            a1b0_n_per_m_s2: 3.1e9,
            a2_n_per_m: 9.5e5,
            a3_per_s: 25.0,
            p_gain: 1.0,
        };
        let to_est = |run: &str, spec: &LinearSpecimen, p: f64| {
            let tf = tf_x1_u(&truth.at_p_gain(p), spec).unwrap();
            TfEstimate {
                run: run.into(),
                p_gain: p,
                tf: SecondOrder::from_tf(&tf).unwrap(),
                cov: None,
            }
        };
        let ns = vec![to_est("ns", &LinearSpecimen::None, 1.0)];
        // A spring at a different P gain exercises the P scaling of R1.
        let springs: Vec<SpringRun> = [(60_000.0, 1.0), (150_000.0, 1.5)]
            .iter()
            .map(|&(k, p)| SpringRun {
                stiffness_n_per_m: k,
                estimate: to_est(
                    "k",
                    &LinearSpecimen::Spring {
                        stiffness_n_per_m: k,
                    },
                    p,
                ),
            })
            .collect();
        let rig = identify_rig(&ns, &springs).unwrap();
        assert_relative_eq!(rig.beta1.value, 180.0, max_relative = 1e-12);
        assert_relative_eq!(rig.a1b0.value, 3.1e9, max_relative = 1e-9);
        assert_relative_eq!(rig.a2.value, 9.5e5, max_relative = 1e-9);
        assert_relative_eq!(rig.a3.value, 25.0, max_relative = 1e-9);
        for s in &rig.per_spring {
            assert_relative_eq!(s.a3.value, 25.0, max_relative = 1e-9);
        }
    }

    #[test]
    fn the_rig_covariance_holds_the_stated_stds() {
        let (no_spec, springs) = paper_inputs();
        let with_cov = |e: &TfEstimate| TfEstimate {
            cov: Some([
                [1e-6 * e.tf.n0 * e.tf.n0, 0.0, 0.0],
                [0.0, 4e-6 * e.tf.d1 * e.tf.d1, 1e-7 * e.tf.d1 * e.tf.d0],
                [0.0, 1e-7 * e.tf.d1 * e.tf.d0, 9e-6 * e.tf.d0 * e.tf.d0],
            ]),
            ..e.clone()
        };
        let no_spec: Vec<TfEstimate> = no_spec.iter().map(with_cov).collect();
        let springs: Vec<SpringRun> = springs
            .iter()
            .map(|s| SpringRun {
                estimate: with_cov(&s.estimate),
                ..s.clone()
            })
            .collect();
        let rig = identify_rig(&no_spec, &springs).unwrap();
        let c = rig.covariance.unwrap();
        for (i, e) in [rig.beta1, rig.a1b0, rig.a2, rig.a3].iter().enumerate() {
            assert_relative_eq!(c[i][i].sqrt(), e.std.unwrap(), max_relative = 1e-12);
        }
        // Symmetric, and beta1 (from the no-specimen run alone) correlates
        // with a3 through R2 = beta1 k / (d0/n0 - 1).
        assert_relative_eq!(c[0][3], c[3][0], max_relative = 1e-12);
        assert!(c[0][3] != 0.0);
    }

    #[test]
    fn propagated_std_matches_a_monte_carlo_of_the_algebra() {
        // Independent check of the propagation: perturb the inputs with a
        // deterministic low-discrepancy sequence of standard normals and
        // compare the sample std of a3 with the linearised one.
        let (mut ns, mut springs) = paper_inputs();
        let rel = 1e-4;
        let cov_of = |t: &SecondOrder| {
            let v = [t.n0, t.d1, t.d0].map(|x| (rel * x).powi(2));
            [[v[0], 0.0, 0.0], [0.0, v[1], 0.0], [0.0, 0.0, v[2]]]
        };
        ns[0].cov = Some(cov_of(&ns[0].tf));
        for s in springs.iter_mut() {
            s.estimate.cov = Some(cov_of(&s.estimate.tf));
        }
        let rig = identify_rig(&ns, &springs).unwrap();
        let lin = rig.a3.std.unwrap();

        let n_samples = 4000;
        let mut draws = crate::simulate::Draws::new(2018, "identify tests");
        let mut normal = move || draws.normal();
        let mut samples = Vec::with_capacity(n_samples);
        for _ in 0..n_samples {
            let mut jitter = |t: &SecondOrder| SecondOrder {
                n0: t.n0 * (1.0 + rel * normal()),
                d1: t.d1 * (1.0 + rel * normal()),
                d0: t.d0 * (1.0 + rel * normal()),
            };
            let mut ns_i = ns.clone();
            ns_i[0].tf = jitter(&ns[0].tf);
            let mut sp_i = springs.clone();
            for (j, s) in sp_i.iter_mut().enumerate() {
                s.estimate.tf = jitter(&springs[j].estimate.tf);
            }
            samples.push(identify_rig(&ns_i, &sp_i).unwrap().a3.value);
        }
        let mean = samples.iter().sum::<f64>() / n_samples as f64;
        let sd = (samples.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n_samples - 1) as f64)
            .sqrt();
        // 4000 samples estimate a std to about 1.1 %; linearisation adds little at 1e-4.
        assert_relative_eq!(lin, sd, max_relative = 0.05);
    }

    #[test]
    fn a_spring_that_does_not_lower_the_gain_is_rejected() {
        let (ns, mut springs) = paper_inputs();
        // d0/n0 < 1: R2 would be negative.
        springs[0].estimate.tf.d0 = 0.9 * springs[0].estimate.tf.n0;
        let err = identify_rig(&ns, &springs).unwrap_err();
        assert!(
            matches!(&err, IdentifyError::NonPhysical { run, quantity, .. } if run == "k1" && *quantity == "R2"),
            "{err}"
        );
    }
}
