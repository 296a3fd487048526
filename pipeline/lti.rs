//! Linear time-invariant models: continuous-time transfer functions (with an
//! optional pure delay) and single-input state-space models, with the
//! conversions and frequency responses the stages share.

use nalgebra::{Complex, DMatrix, DVector};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::poly;

/// Why a transfer function is not acceptable.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LtiError {
    #[error("the denominator is empty")]
    EmptyDenominator,
    #[error("the numerator is empty")]
    EmptyNumerator,
    #[error("the leading denominator coefficient is zero")]
    ZeroLeadingDenominator,
    #[error("coefficient {index} of the {which} is not finite ({value})")]
    NonFinite {
        which: &'static str,
        index: usize,
        value: f64,
    },
    #[error("the numerator has a higher degree ({num}) than the denominator ({den})")]
    Improper { num: usize, den: usize },
    #[error("the delay must be finite and non-negative (got {0} s)")]
    BadDelay(f64),
}

/// A continuous-time transfer function num(s)/den(s) * exp(-s delay_s).
///
/// Coefficients are stored highest power first. After [`TransferFunction::new`]
/// the denominator's leading coefficient is 1 (the form results.json promises).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TransferFunction {
    /// Numerator coefficients, highest power of s first.
    pub num: Vec<f64>,
    /// Denominator coefficients, highest power of s first; `den[0] == 1`.
    pub den: Vec<f64>,
    /// Pure time delay (s).
    pub delay_s: f64,
}

impl TransferFunction {
    /// Checks the coefficients and normalises the denominator to `den[0] == 1`.
    pub fn new(num: &[f64], den: &[f64]) -> Result<Self, LtiError> {
        Self::with_delay(num, den, 0.0)
    }

    /// As [`TransferFunction::new`] with a pure delay (s).
    pub fn with_delay(num: &[f64], den: &[f64], delay_s: f64) -> Result<Self, LtiError> {
        if den.is_empty() {
            return Err(LtiError::EmptyDenominator);
        }
        if num.is_empty() {
            return Err(LtiError::EmptyNumerator);
        }
        for (which, coeffs) in [("numerator", num), ("denominator", den)] {
            if let Some((index, &value)) = coeffs.iter().enumerate().find(|(_, c)| !c.is_finite()) {
                return Err(LtiError::NonFinite {
                    which,
                    index,
                    value,
                });
            }
        }
        if den[0] == 0.0 {
            return Err(LtiError::ZeroLeadingDenominator);
        }
        if !(delay_s.is_finite() && delay_s >= 0.0) {
            return Err(LtiError::BadDelay(delay_s));
        }
        let num = poly::trim_leading_zeros(num);
        if num.len() > den.len() {
            return Err(LtiError::Improper {
                num: num.len() - 1,
                den: den.len() - 1,
            });
        }
        let lead = den[0];
        Ok(Self {
            num: num.iter().map(|c| c / lead).collect(),
            den: den.iter().map(|c| c / lead).collect(),
            delay_s,
        })
    }

    /// Order of the denominator.
    pub fn order(&self) -> usize {
        self.den.len() - 1
    }

    /// H(s), the delay included.
    pub fn eval(&self, s: Complex<f64>) -> Complex<f64> {
        let rational = poly::eval(&self.num, s) / poly::eval(&self.den, s);
        if self.delay_s == 0.0 {
            rational
        } else {
            rational * (-s * self.delay_s).exp()
        }
    }

    /// Frequency response H(j 2 pi f) at `f_hz` (Hz).
    pub fn freq_response(&self, f_hz: f64) -> Complex<f64> {
        self.eval(Complex::new(0.0, 2.0 * std::f64::consts::PI * f_hz))
    }

    /// Static gain H(0).
    pub fn dc_gain(&self) -> f64 {
        poly::eval_real(&self.num, 0.0) / poly::eval_real(&self.den, 0.0)
    }

    /// Poles [rad/s], sorted by real then imaginary part.
    pub fn poles(&self) -> Vec<Complex<f64>> {
        poly::roots(&self.den)
    }

    /// Zeros [rad/s], sorted by real then imaginary part.
    pub fn zeros(&self) -> Vec<Complex<f64>> {
        poly::roots(&self.num)
    }

    /// True when every pole has a negative real part.
    pub fn is_stable(&self) -> bool {
        self.poles().iter().all(|p| p.re < 0.0)
    }

    /// A state-space realisation in controllable canonical form (the delay is
    /// not part of it).
    pub fn to_state_space(&self) -> StateSpace {
        let n = self.order();
        // Pad the numerator to the denominator's length; a direct feedthrough
        // appears when they have the same degree.
        let mut num = vec![0.0; n + 1 - self.num.len()];
        num.extend_from_slice(&self.num);
        let d = num[0];
        // num(s) = d den(s) + rest(s), rest of degree < n.
        let rest: Vec<f64> = (1..=n).map(|i| num[i] - d * self.den[i]).collect();
        let mut a = DMatrix::zeros(n, n);
        let mut b = DVector::zeros(n);
        let mut c = DMatrix::zeros(1, n);
        if n > 0 {
            for i in 0..n - 1 {
                a[(i, i + 1)] = 1.0;
            }
            for j in 0..n {
                // Last row: x_n' = -a0 x1 - a1 x2 - ... ; den = [1, a_{n-1}, ..., a0].
                a[(n - 1, j)] = -self.den[n - j];
                c[(0, j)] = rest[n - 1 - j];
            }
            b[n - 1] = 1.0;
        }
        StateSpace {
            a,
            b,
            c,
            d: DVector::from_element(1, d),
        }
    }
}

/// A single-input, multi-output state-space model x' = A x + B u, y = C x + D u.
#[derive(Debug, Clone, PartialEq)]
pub struct StateSpace {
    pub a: DMatrix<f64>,
    pub b: DVector<f64>,
    pub c: DMatrix<f64>,
    pub d: DVector<f64>,
}

impl StateSpace {
    /// Number of states.
    pub fn order(&self) -> usize {
        self.a.nrows()
    }

    /// Eigenvalues of A [rad/s], sorted by real then imaginary part.
    ///
    /// A is balanced first: the plant's A mixes 1/m ~ 0.3 with a1b0 ~ 1e9,
    /// and an unbalanced Schur decomposition loses five digits on it. None
    /// as [`crate::poly::eigenvalues`] says (a non-finite entry, or no
    /// convergence).
    pub fn eigenvalues(&self) -> Option<Vec<Complex<f64>>> {
        let mut e = crate::poly::eigenvalues(&balance(&self.a))?;
        e.sort_by(|a, b| a.re.total_cmp(&b.re).then(a.im.total_cmp(&b.im)));
        Some(e)
    }

    /// Frequency response of output `output` at complex frequency s, by solving
    /// (sI - A) x = B directly (independent of any polynomial form).
    pub fn eval(&self, output: usize, s: Complex<f64>) -> Complex<f64> {
        let n = self.order();
        let mut m = DMatrix::<Complex<f64>>::zeros(n, n);
        for i in 0..n {
            for j in 0..n {
                m[(i, j)] = Complex::new(-self.a[(i, j)], 0.0);
            }
            m[(i, i)] += s;
        }
        let b = self.b.map(|v| Complex::new(v, 0.0));
        let x = m.lu().solve(&b).unwrap_or_else(|| DVector::zeros(n));
        let mut y = Complex::new(self.d[output], 0.0);
        for j in 0..n {
            y += x[j] * self.c[(output, j)];
        }
        y
    }

    /// The transfer function of output `output`: den = det(sI - A) and, for a
    /// single input, C adj(sI - A) B = det(sI - A + B C) - det(sI - A).
    pub fn transfer_function(&self, output: usize) -> TransferFunction {
        let den = characteristic_polynomial(&self.a);
        let c_row = self.c.row(output).transpose();
        let bc = &self.b * c_row.transpose();
        let closed = characteristic_polynomial(&(&self.a - bc));
        let mut num: Vec<f64> = closed.iter().zip(den.iter()).map(|(x, y)| x - y).collect();
        let d = self.d[output];
        for (k, v) in num.iter_mut().enumerate() {
            *v += d * den[k];
        }
        // Strip the exactly-cancelled leading terms, and round-off relative to
        // the largest coefficient.
        let scale = num.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        let first = num
            .iter()
            .position(|v| v.abs() > 1e-13 * scale)
            .unwrap_or(num.len() - 1);
        TransferFunction {
            num: num[first..].to_vec(),
            den,
            delay_s: 0.0,
        }
    }
}

/// A zero-order hold's response at `f_hz` for samples at `sample_rate_hz`:
/// `sinc(w T / 2) exp(-i w T / 2)`, what a plant driven through a hold
/// and sampled at the same rate adds to its own response. One sine and one
/// cosine, the same bits as `from_polar(sinc, -w T / 2)` (cosine even, sine
/// odd).
pub fn zoh_response(f_hz: f64, sample_rate_hz: f64) -> Complex<f64> {
    let half = std::f64::consts::PI * f_hz / sample_rate_hz; // wT/2
    let (sin, cos) = (half.sin(), half.cos());
    let sinc = if half == 0.0 { 1.0 } else { sin / half };
    Complex::new(sinc * cos, -(sinc * sin))
}

/// First-order standard deviations of a response's magnitude, 20 log10 |G|
/// (dB), and phase, arg G (rad), from the gradient of ln G with respect to
/// parameters of covariance `cov(i, j)`: Re and Im of d ln G are the
/// gradients of ln |G| and arg G, so each variance is g' C g.
pub fn log_response_std(grad: &[Complex<f64>], cov: impl Fn(usize, usize) -> f64) -> (f64, f64) {
    let db = 20.0 / std::f64::consts::LN_10;
    let var = |part: &dyn Fn(Complex<f64>) -> f64| {
        let mut v = 0.0;
        for (i, gi) in grad.iter().enumerate() {
            for (j, gj) in grad.iter().enumerate() {
                v += part(*gi) * cov(i, j) * part(*gj);
            }
        }
        v.max(0.0).sqrt()
    };
    (var(&|z| db * z.re), var(&|z| z.im))
}

/// Parlett-Reinsch balancing: a diagonal similarity D^-1 A D with powers of
/// two (exact in floating point) that makes each row and column norm alike,
/// which keeps eigenvalues of badly scaled matrices accurate.
pub fn balance(a: &DMatrix<f64>) -> DMatrix<f64> {
    let d = balancing_diagonal(a);
    let n = a.nrows();
    DMatrix::from_fn(n, n, |i, j| a[(i, j)] * d[j] / d[i])
}

/// The diagonal D of [`balance`], powers of two, such that D^-1 A D has
/// comparable row and column norms (Parlett & Reinsch 1969, as LAPACK's
/// dgebal). A row or column whose norm is not finite is left alone: an
/// infinite norm has no balancing power (dividing it by 4 never ends: a
/// hang on finite but extreme manifest numbers).
pub fn balancing_diagonal(a: &DMatrix<f64>) -> Vec<f64> {
    let n = a.nrows();
    let mut b = a.clone();
    let mut d = vec![1.0; n];
    let radix = 2.0_f64;
    for _sweep in 0..100 {
        let mut converged = true;
        for i in 0..n {
            let (mut c, mut r) = (0.0, 0.0);
            for j in 0..n {
                if j != i {
                    c += b[(j, i)].abs();
                    r += b[(i, j)].abs();
                }
            }
            if c == 0.0 || r == 0.0 || !c.is_finite() || !r.is_finite() {
                continue;
            }
            let s = c + r;
            let mut f = 1.0;
            let mut c2 = c;
            while c2 < r / radix {
                c2 *= radix * radix;
                f *= radix;
            }
            while c2 >= r * radix {
                c2 /= radix * radix;
                f /= radix;
            }
            if c * f + r / f < 0.95 * s {
                converged = false;
                d[i] *= f;
                for j in 0..n {
                    b[(i, j)] /= f;
                    b[(j, i)] *= f;
                }
            }
        }
        if converged {
            break;
        }
    }
    d
}

/// Monic characteristic polynomial det(sI - A), highest power first
/// (Faddeev-LeVerrier; exact in exact arithmetic, well behaved for the small
/// matrices of the plant).
pub fn characteristic_polynomial(a: &DMatrix<f64>) -> Vec<f64> {
    let n = a.nrows();
    let mut coeffs = vec![0.0; n + 1];
    coeffs[0] = 1.0;
    let eye = DMatrix::<f64>::identity(n, n);
    let mut m = DMatrix::<f64>::zeros(n, n);
    for k in 1..=n {
        m = a * &m + &eye * coeffs[k - 1];
        let am = a * &m;
        coeffs[k] = -am.trace() / k as f64;
    }
    coeffs
}

/// Complex numbers as [re, im] pairs, for serde (`#[serde(with =
/// "complex_vec")]`): the run cache keeps FRF bins this way.
pub mod complex_vec {
    use nalgebra::Complex;
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &[Complex<f64>], s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(v.iter().map(|c| [c.re, c.im]))
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<Complex<f64>>, D::Error> {
        let pairs = Vec::<[f64; 2]>::deserialize(d)?;
        Ok(pairs
            .into_iter()
            .map(|[re, im]| Complex::new(re, im))
            .collect())
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn balancing_a_matrix_with_an_infinite_norm_ends_and_leaves_it() {
        // Row 1's column norm is infinite: the old loop divided it by 4
        // forever. Both rows are left unscaled.
        let a = DMatrix::from_row_slice(2, 2, &[0.0, f64::INFINITY, 1.0, 0.0]);
        // Exact: an unscaled row keeps the factor 1.
        assert_eq!(balancing_diagonal(&a), vec![1.0, 1.0]);
        // And a finite, badly scaled one is balanced to within a factor of
        // two, rows against columns.
        let b = DMatrix::from_row_slice(2, 2, &[0.0, 1e8, 1.0, 0.0]);
        let d = balancing_diagonal(&b);
        let bal = balance(&b);
        assert!((bal[(0, 1)] / bal[(1, 0)]).abs() < 4.0, "{bal}");
        // Exact: balancing scales by powers of two, which multiply exactly.
        assert_eq!(bal[(0, 1)], 1e8 * d[1] / d[0]);
    }

    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn new_normalises_and_rejects_bad_coefficients() {
        let tf = TransferFunction::new(&[6.0], &[2.0, 4.0, 6.0]).unwrap();
        // Exact: small integers divided by 2.
        assert_eq!(tf.den, vec![1.0, 2.0, 3.0]);
        assert_eq!(tf.num, vec![3.0]);
        assert_eq!(
            TransferFunction::new(&[1.0], &[0.0, 1.0, 2.0]),
            Err(LtiError::ZeroLeadingDenominator)
        );
        assert!(matches!(
            TransferFunction::new(&[1.0, 0.0, 0.0], &[1.0, 2.0]),
            Err(LtiError::Improper { .. })
        ));
        assert!(matches!(
            TransferFunction::new(&[f64::NAN], &[1.0, 2.0]),
            Err(LtiError::NonFinite { .. })
        ));
    }

    #[test]
    fn first_order_response_matches_closed_form() {
        // H = a/(s + a): |H(j w)| = a/sqrt(w^2 + a^2), phase = -atan(w/a).
        let a = 50.0;
        let tf = TransferFunction::new(&[a], &[1.0, a]).unwrap();
        let f = 7.0;
        let w = 2.0 * std::f64::consts::PI * f;
        let h = tf.freq_response(f);
        assert_relative_eq!(h.norm(), a / (w * w + a * a).sqrt(), max_relative = 1e-14);
        assert_relative_eq!(h.arg(), -(w / a).atan(), max_relative = 1e-14);
    }

    #[test]
    fn delay_rotates_phase_only() {
        let tf = TransferFunction::with_delay(&[1.0], &[1.0, 10.0], 0.002).unwrap();
        let plain = TransferFunction::new(&[1.0], &[1.0, 10.0]).unwrap();
        let f = 20.0;
        let ratio = tf.freq_response(f) / plain.freq_response(f);
        assert_relative_eq!(ratio.norm(), 1.0, max_relative = 1e-14);
        assert_relative_eq!(
            ratio.arg(),
            -2.0 * std::f64::consts::PI * f * 0.002,
            max_relative = 1e-12
        );
    }

    #[test]
    fn realisation_round_trips() {
        let tf = TransferFunction::new(&[2.0, 3.0, 5.0], &[1.0, 4.0, 6.0, 8.0]).unwrap();
        let ss = tf.to_state_space();
        let back = ss.transfer_function(0);
        assert_eq!(back.den.len(), tf.den.len());
        for (x, y) in back.den.iter().zip(tf.den.iter()) {
            assert_relative_eq!(x, y, max_relative = 1e-12);
        }
        for (x, y) in back.num.iter().zip(tf.num.iter()) {
            assert_relative_eq!(x, y, max_relative = 1e-12);
        }
        for f in [0.1, 1.0, 10.0] {
            let s = Complex::new(0.0, 2.0 * std::f64::consts::PI * f);
            assert!((ss.eval(0, s) - tf.eval(s)).norm() < 1e-12 * tf.eval(s).norm());
        }
    }

    #[test]
    fn biproper_realisation_has_feedthrough() {
        let tf = TransferFunction::new(&[2.0, 1.0], &[1.0, 3.0]).unwrap();
        let ss = tf.to_state_space();
        assert_relative_eq!(ss.d[0], 2.0);
        let s = Complex::new(0.3, 1.7);
        assert!((ss.eval(0, s) - tf.eval(s)).norm() < 1e-13);
    }
}
