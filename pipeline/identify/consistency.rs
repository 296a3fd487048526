//! Do the springs agree? Each spring run gives its own a1b0, a2 and a3
//! (Eqs. 19-20); the paper averages them. If the model holds and the
//! manifest is right, their spread is what their propagated standard
//! deviations predict. A stiffness typed wrong, two logs swapped, a channel
//! in the wrong unit or dynamics the model leaves out make the springs
//! disagree far beyond it, while each spring's own fit, and the validation
//! of the averaged rig, can look fine.
//!
//! The test, per parameter: with the springs' values x (n of them) and
//! their joint covariance S (first-order propagation through Eqs. 18-20,
//! which keeps the correlation the shared no-specimen run gives them), the
//! generalised-least-squares mean m = (1' S^-1 x) / (1' S^-1 1) and
//! chi2 = (x - m 1)' S^-1 (x - m 1), which follows a chi-square law with
//! n - 1 degrees of freedom when the springs agree. A p-value below
//! [`ALPHA`] flags the campaign.

use nalgebra::{DMatrix, DVector};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use statrs::distribution::{ChiSquared, ContinuousCDF};

/// The test's significance level: one campaign in a thousand whose springs
/// do agree is flagged.
pub const ALPHA: f64 = 1e-3;

/// The parameters compared, in the order of [`PerSpringValues`].
pub const PARAMETERS: [&str; 3] = ["a1b0", "a2", "a3"];

/// One spring's values of a1b0, a2 and a3 (a1b0 at the rig's reference P).
#[derive(Debug, Clone, PartialEq)]
pub struct PerSpringValues {
    pub run: String,
    pub values: [f64; 3],
}

/// The springs' agreement, as results.json states it (`rig.consistency`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Consistency {
    /// Spring runs compared.
    pub springs: usize,
    /// Significance level of each parameter's test.
    pub alpha: f64,
    /// One test per parameter (a1b0, a2, a3); empty when none can be made.
    pub checks: Vec<ConsistencyCheck>,
    /// Whether the springs agree; null when the check cannot be made (a
    /// single spring, or fits without a covariance).
    pub consistent: Option<bool>,
    /// What was found, or why nothing could be, in words.
    pub note: String,
    /// With two or more springs: the rig from all springs but one, for
    /// each spring left out (the paper's average of the others).
    pub leave_one_out: Vec<LeaveOneOut>,
    /// When the springs disagree: what usually makes them.
    pub likely_causes: Vec<String>,
    /// Why the test could not be made, when it could not (not in
    /// results.json: `note` says it in words).
    #[serde(skip)]
    pub untested: Option<Untested>,
}

/// Why the springs' agreement could not be tested.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Untested {
    /// One spring run: the campaign's design (a second spring makes the
    /// test possible).
    OneSpring,
    /// Published transfer functions: no covariance, by what they are.
    NoCovariance,
    /// The springs' covariance is not positive definite: something in the
    /// data or the specimens' values (a stiffness of 1e-300) is wrong.
    NotPositiveDefinite,
}

/// One parameter's chi-square test across the springs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct ConsistencyCheck {
    pub parameter: String,
    /// The generalised-least-squares mean over the springs.
    pub weighted_mean: f64,
    pub chi2: f64,
    /// Degrees of freedom: springs - 1.
    pub dof: usize,
    /// Probability of a chi2 this large or larger if the springs agree.
    pub p_value: f64,
    pub consistent: bool,
}

/// The rig from every spring but one.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct LeaveOneOut {
    /// The spring run left out.
    pub left_out: String,
    pub a1b0: f64,
    pub a2: f64,
    pub a3: f64,
    /// Whether the springs that remain agree (null with fewer than two, or
    /// without covariances).
    pub rest_consistent: Option<bool>,
}

/// Test the springs: `springs` their values, `cov[p]` the joint covariance
/// of parameter p's values over the springs (None when the fits carry no
/// covariance).
pub fn check(springs: &[PerSpringValues], cov: Option<&[DMatrix<f64>; 3]>) -> Consistency {
    let n = springs.len();
    let mut out = Consistency {
        springs: n,
        alpha: ALPHA,
        checks: Vec::new(),
        consistent: None,
        note: String::new(),
        leave_one_out: Vec::new(),
        likely_causes: Vec::new(),
        untested: None,
    };
    if n < 2 {
        out.untested = Some(Untested::OneSpring);
        out.note = "one spring run: the springs' agreement cannot be checked (a second spring of another stiffness makes the check possible)".into();
        return out;
    }
    let rest = cov.filter(|_| n >= 3).map(|c| rest_consistent(springs, c));
    out.leave_one_out = (0..n)
        .map(|left| {
            let keep: Vec<usize> = (0..n).filter(|&j| j != left).collect();
            let mean = |p: usize| {
                keep.iter().map(|&j| springs[j].values[p]).sum::<f64>() / keep.len() as f64
            };
            let rest_consistent = rest.as_ref().and_then(|r| r[left]);
            LeaveOneOut {
                left_out: springs[left].run.clone(),
                a1b0: mean(0),
                a2: mean(1),
                a3: mean(2),
                rest_consistent,
            }
        })
        .collect();
    let Some(cov) = cov else {
        out.untested = Some(Untested::NoCovariance);
        out.note = "the spring runs' fits carry no covariance (published transfer functions), so their agreement cannot be tested; the leave-one-out values show their spread".into();
        return out;
    };
    let all: Vec<usize> = (0..n).collect();
    let Some(checks) = tests(springs, cov, &all) else {
        out.untested = Some(Untested::NotPositiveDefinite);
        out.note = "the springs' propagated covariance is not positive definite, so their agreement cannot be tested".into();
        return out;
    };
    let bad: Vec<&ConsistencyCheck> = checks.iter().filter(|c| !c.consistent).collect();
    out.consistent = Some(bad.is_empty());
    if bad.is_empty() {
        out.note = format!(
            "the {n} springs agree: a1b0, a2 and a3 scatter as their propagated standard deviations predict (chi-square, p >= {ALPHA})"
        );
    } else {
        let what: Vec<String> = bad
            .iter()
            .map(|c| {
                format!(
                    "{} (chi2 = {:.3e} on {} dof, p = {:.1e})",
                    c.parameter, c.chi2, c.dof, c.p_value
                )
            })
            .collect();
        out.note = format!(
            "the {n} springs disagree far beyond their standard deviations: {}. The averaged rig and its stated std are not to be trusted until the cause is found",
            what.join(", ")
        );
        out.likely_causes = causes(&out.leave_one_out);
    }
    out.checks = checks;
    out
}

/// For each spring left out, whether the others agree (None where a
/// covariance is not positive definite). With S's inverse P, the rest's
/// precision is the Schur complement of P_jj, so each quadratic form of
/// the rest is the whole one less (P v)_j (P w)_j / P_jj: O(1) a spring
/// after one inverse, where a Cholesky of each rest costs O(n^4) in all.
/// The values are centred on their mean first, which changes no test and
/// keeps the forms from cancelling.
fn rest_consistent(springs: &[PerSpringValues], cov: &[DMatrix<f64>; 3]) -> Vec<Option<bool>> {
    let n = springs.len();
    let Some(chi2) = rest_chi2(springs, cov) else {
        return (0..n).map(|j| rest_by_cholesky(springs, cov, j)).collect();
    };
    let law = ChiSquared::new((n - 2) as f64).expect("n >= 3");
    chi2.iter()
        .map(|c| Some(c.iter().all(|&c| law.sf(c) >= ALPHA)))
        .collect()
}

/// Each parameter's chi2 over the springs but j, for each j; None when a
/// covariance is not positive definite.
fn rest_chi2(springs: &[PerSpringValues], cov: &[DMatrix<f64>; 3]) -> Option<Vec<[f64; 3]>> {
    let n = springs.len();
    let mut rest = vec![[0.0; 3]; n];
    for (p, s) in cov.iter().enumerate() {
        let inv = s.clone().cholesky()?.inverse();
        let mean = springs.iter().map(|s| s.values[p]).sum::<f64>() / n as f64;
        let y = DVector::from_iterator(n, springs.iter().map(|s| s.values[p] - mean));
        let ones = DVector::from_element(n, 1.0);
        let (py, p1) = (&inv * &y, &inv * &ones);
        let (a, b, c) = (y.dot(&py), ones.dot(&py), ones.dot(&p1));
        for (j, r) in rest.iter_mut().enumerate() {
            let d = inv[(j, j)];
            let yy = a - py[j] * py[j] / d;
            let oy = b - p1[j] * py[j] / d;
            let oo = c - p1[j] * p1[j] / d;
            r[p] = (yy - oy * oy / oo).max(0.0);
        }
    }
    Some(rest)
}

/// Whether the springs but `left` agree, the rest's covariance factored on
/// its own: where the whole one is not positive definite.
fn rest_by_cholesky(
    springs: &[PerSpringValues],
    cov: &[DMatrix<f64>; 3],
    left: usize,
) -> Option<bool> {
    let keep: Vec<usize> = (0..springs.len()).filter(|&j| j != left).collect();
    tests(springs, cov, &keep).map(|t| t.iter().all(|c| c.consistent))
}

/// Each parameter's test over the springs `keep`; None when a covariance
/// is not positive definite.
fn tests(
    springs: &[PerSpringValues],
    cov: &[DMatrix<f64>; 3],
    keep: &[usize],
) -> Option<Vec<ConsistencyCheck>> {
    let n = keep.len();
    PARAMETERS
        .iter()
        .enumerate()
        .map(|(p, name)| {
            let x = DVector::from_iterator(n, keep.iter().map(|&j| springs[j].values[p]));
            let s = DMatrix::from_fn(n, n, |a, b| cov[p][(keep[a], keep[b])]);
            let chol = s.cholesky()?;
            let ones = DVector::from_element(n, 1.0);
            let si_x = chol.solve(&x);
            let si_1 = chol.solve(&ones);
            let mean = ones.dot(&si_x) / ones.dot(&si_1);
            let r = &x - &ones * mean;
            let chi2 = r.dot(&chol.solve(&r)).max(0.0);
            let dof = n - 1;
            let p_value = ChiSquared::new(dof as f64).ok()?.sf(chi2);
            Some(ConsistencyCheck {
                parameter: (*name).to_string(),
                weighted_mean: mean,
                chi2,
                dof,
                p_value,
                consistent: p_value >= ALPHA,
            })
        })
        .collect()
}

/// What makes springs disagree, the odd one first when leaving one spring
/// out makes the rest agree.
fn causes(loo: &[LeaveOneOut]) -> Vec<String> {
    let mut out = Vec::new();
    let odd: Vec<&str> = loo
        .iter()
        .filter(|l| l.rest_consistent == Some(true))
        .map(|l| l.left_out.as_str())
        .collect();
    if let [one] = odd.as_slice() {
        out.push(format!(
            "spring run {one} is the odd one out: without it the other springs agree"
        ));
    }
    out.extend(MANIFEST_CAUSES.iter().map(|s| s.to_string()));
    out.push(DYNAMICS_CAUSE.to_string());
    out
}

/// What makes springs disagree that the manifest or the logs it names
/// would be to blame for: each shows in a spring's load cell, where it has
/// one.
pub const MANIFEST_CAUSES: [&str; 3] = [
    "a spring's stiffness typed wrong in the manifest or the run table (stiffness_n_per_m)",
    "the logs of two runs swapped (each run's log = ... names the file it analyses)",
    "a channel in the wrong unit or scale in one run (its [channels] or the DAQ's range)",
];

/// The likely cause of springs that disagree which the model, not the
/// manifest, would be to blame for.
pub const DYNAMICS_CAUSE: &str = "dynamics the model leaves out: a spring's own mass or a stiff spring beyond the paper's massless, linearised assumption, friction, the servo-valve's higher modes";

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn spring(run: &str, a1b0: f64, a2: f64, a3: f64) -> PerSpringValues {
        PerSpringValues {
            run: run.into(),
            values: [a1b0, a2, a3],
        }
    }

    /// Independent springs with stds sd: chi2 = sum ((x - mean) / sd)^2 with
    /// the inverse-variance mean; for two springs of equal sd it is
    /// (x1 - x2)^2 / (2 sd^2). p-values from the chi-square law by hand:
    /// for 1 dof, P(chi2 > 4) = erfc(sqrt 2) = 0.0455003, and for 2 dof
    /// P(chi2 > x) = exp(-x / 2).
    #[test]
    fn chi_square_by_hand() {
        let sd = [10.0, 1000.0, 0.1];
        let diag = |n: usize| -> [DMatrix<f64>; 3] {
            [0, 1, 2].map(|p| DMatrix::from_diagonal_element(n, n, sd[p] * sd[p]))
        };
        // Two springs, 2 sd apart in every parameter: chi2 = 2, p = 0.1573.
        let two = [
            spring("k1", 100.0, 5000.0, 1.0),
            spring("k2", 100.0 + 20.0, 7000.0, 1.2),
        ];
        let c = check(&two, Some(&diag(2)));
        assert_eq!(c.consistent, Some(true));
        for t in &c.checks {
            assert_relative_eq!(t.chi2, 2.0, max_relative = 1e-12);
            assert_eq!(t.dof, 1);
            assert_relative_eq!(t.p_value, 0.157_299_207_050_285_1, max_relative = 1e-9);
        }
        assert_relative_eq!(c.checks[0].weighted_mean, 110.0, max_relative = 1e-12);

        // Three springs, x = mean + (-2, 0, 2) sd in a2: chi2 = 8, 2 dof,
        // p = exp(-4) = 0.0183; a3 off by 20 sd in one spring: flagged.
        let three = [
            spring("k1", 100.0, 3000.0, 1.0),
            spring("k2", 100.0, 5000.0, 1.0),
            spring("k3", 100.0, 7000.0, 3.0),
        ];
        let c = check(&three, Some(&diag(3)));
        assert_relative_eq!(c.checks[1].chi2, 8.0, max_relative = 1e-12);
        assert_relative_eq!(c.checks[1].p_value, (-4.0f64).exp(), max_relative = 1e-9);
        assert!(c.checks[1].consistent);
        // a3: mean 5/3, residuals (-2/3, -2/3, 4/3) / 0.1 -> chi2 = 266.67.
        assert_relative_eq!(c.checks[2].chi2, 800.0 / 3.0, max_relative = 1e-12);
        assert!(!c.checks[2].consistent);
        assert_eq!(c.consistent, Some(false));
        // Without k3 the others agree: it is named first.
        assert_eq!(c.leave_one_out[2].rest_consistent, Some(true));
        assert_eq!(c.leave_one_out[0].rest_consistent, Some(false));
        assert!(
            c.likely_causes[0].starts_with("spring run k3 is the odd one out"),
            "{:?}",
            c.likely_causes
        );
        assert!(
            c.likely_causes
                .iter()
                .any(|s| s.contains("stiffness typed wrong"))
        );
        assert!(c.likely_causes.iter().any(|s| s.contains("swapped")));
        assert!(c.likely_causes.iter().any(|s| s.contains("unit")));
        assert!(c.likely_causes.iter().any(|s| s.contains("leaves out")));
        // Leave-one-out values: the plain mean of the others.
        assert_relative_eq!(c.leave_one_out[0].a2, 6000.0, max_relative = 1e-12);
    }

    /// Correlated values: with S = sd^2 [[1, r], [r, 1]] the two-spring
    /// chi2 is (x1 - x2)^2 / (2 sd^2 (1 - r)): a common error that both
    /// springs share does not count as disagreement.
    #[test]
    fn a_shared_error_is_not_disagreement() {
        let (sd, r) = (2.0, 0.9);
        let s = DMatrix::from_row_slice(2, 2, &[sd * sd, r * sd * sd, r * sd * sd, sd * sd]);
        let cov = [s.clone(), s.clone(), s];
        let two = [spring("a", 10.0, 10.0, 10.0), spring("b", 12.0, 12.0, 12.0)];
        let c = check(&two, Some(&cov));
        assert_relative_eq!(
            c.checks[0].chi2,
            4.0 / (2.0 * 4.0 * 0.1),
            max_relative = 1e-12
        );
        assert_relative_eq!(c.checks[0].weighted_mean, 11.0, max_relative = 1e-12);
    }

    #[test]
    fn one_spring_or_no_covariance_says_why_not() {
        let c = check(&[spring("k1", 1.0, 2.0, 3.0)], None);
        assert_eq!(c.consistent, None);
        assert!(c.note.starts_with("one spring run"), "{}", c.note);
        assert!(c.leave_one_out.is_empty());
        let c = check(
            &[spring("k1", 1.0, 2.0, 3.0), spring("k2", 1.5, 2.0, 3.0)],
            None,
        );
        assert_eq!(c.consistent, None);
        assert!(c.note.contains("no covariance"), "{}", c.note);
        assert_eq!(c.leave_one_out.len(), 2);
        // Exact: with two springs, leaving one out leaves the other's value.
        assert_eq!(c.leave_one_out[0].a1b0, 1.5);
    }
    /// The rest's chi2 from the whole covariance's inverse against a
    /// Cholesky of each rest's own covariance, on springs that share a
    /// strong common error (as the no-specimen run gives them), values a
    /// million times their spread from zero, and one spring far off.
    #[test]
    fn the_rest_s_chi2_from_the_whole_inverse_is_each_rest_s_own() {
        let n = 9;
        let shared = [4.0e2, 9.0e6, 2.5e-1];
        let own = |j: usize, p: usize| (1.0 + 0.3 * j as f64) * [1.0, 3.0e3, 2.0e-3][p];
        let cov: [DMatrix<f64>; 3] = [0, 1, 2].map(|p| {
            DMatrix::from_fn(n, n, |a, b| {
                let w = |j: usize| 1.0 + 0.05 * (j as f64).sin();
                shared[p] * w(a) * w(b) + if a == b { own(a, p).powi(2) } else { 0.0 }
            })
        });
        let springs: Vec<PerSpringValues> = (0..n)
            .map(|j| {
                let wiggle = |p: usize| own(j, p) * ((j * (p + 2)) as f64).cos();
                let off = if j == 4 { 30.0 } else { 0.0 };
                spring(
                    &format!("k{j}"),
                    1.0e6 + wiggle(0) + off * own(j, 0),
                    1.0e9 + wiggle(1),
                    1.0e5 + wiggle(2),
                )
            })
            .collect();
        let fast = rest_chi2(&springs, &cov).expect("positive definite");
        for (left, chi2) in fast.iter().enumerate() {
            let keep: Vec<usize> = (0..n).filter(|&j| j != left).collect();
            let direct = tests(&springs, &cov, &keep).expect("positive definite");
            for p in 0..3 {
                assert_relative_eq!(chi2[p], direct[p].chi2, max_relative = 1e-7, epsilon = 1e-9);
            }
        }
        // Spring 4 is 30 sds off in a1b0: the rest agree only without it.
        let rest = rest_consistent(&springs, &cov);
        assert_eq!(rest[4], Some(true));
        assert!(
            rest.iter()
                .enumerate()
                .all(|(j, r)| j == 4 || *r == Some(false))
        );
    }
}
