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
        poly::eval(&self.num, s) / poly::eval(&self.den, s) * poly::delay(s, self.delay_s)
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
/// `sinc(w T / 2) exp(-i w T / 2)`, the hold's continuous factor: `G(i w)`
/// times it is the first term (k = 0) of what a plant driven through the
/// hold and sampled at the same rate responds ([`ZohSampled`] has them
/// all). One sine and one cosine, the same bits as `from_polar(sinc, -w T
/// / 2)` (cosine even, sine odd).
pub fn zoh_response(f_hz: f64, sample_rate_hz: f64) -> Complex<f64> {
    let half = std::f64::consts::PI * f_hz / sample_rate_hz; // wT/2
    let (sin, cos) = (half.sin(), half.cos());
    let sinc = if half == 0.0 { 1.0 } else { sin / half };
    Complex::new(sinc * cos, -(sinc * sin))
}

/// A plant driven through a zero-order hold and read at the hold's own
/// instants, as the log of a rig whose command comes from a D/A converter
/// sees it: its exact sampled response G_d(e^{i w T}).
///
/// The held staircase has lines at w_k = w + k 2 pi fs, and sampling folds
/// each back onto w (Poisson summation):
///
///   G_d(e^{i w T}) = (1 - e^{-i w T}) sum_k G(i w_k) / (i w_k T),
///
/// of which `G(i w) zoh_response(f)` is the term k = 0 alone. The others,
/// the aliases, fall as (f / fs)^(r + 1) for a plant of relative degree r:
/// on the paper's no-specimen model (r = 2) sampled at 200 Hz they are
/// 0.6 % of the response at 30 Hz (nearly all in its phase), and a fit
/// without them put beta1 0.2 % (nine stds) high.
///
/// Computed from the state space rather than by summing: with Phi(t) =
/// e^{A t} and Gamma(t) = int_0^t e^{A s} ds B, x\[k+1\] = Phi(T) x\[k\] +
/// Gamma(T) u\[k\] holds exactly, and a delay tau = q T + eps (0 <= eps < T)
/// reads the state T - eps into the period q + 1 samples back (the
/// simulator's taps, `simulate::discrete`), so
///
///   G_d(z) = z^-q (c (zI - Phi)^-1 Gamma + d)                              eps = 0,
///   G_d(z) = z^-(q+1) (c Phi(T-eps) (zI - Phi)^-1 Gamma + c Gamma(T-eps) + d)   eps > 0
///
/// (Franklin, Powell & Workman, Digital Control of Dynamic Systems, Sec.
/// 4.3.3; the second is the modified z-transform's state-space form).
/// Phi is reduced to Hessenberg form once, so each frequency costs one
/// O(n^2) solve (Laub 1981, IEEE Trans. Autom. Control 26(2):407-408); no
/// eigen-decomposition is made, so repeated poles need no care.
#[derive(Debug, Clone)]
pub struct ZohSampled {
    /// Q^T Phi(T) Q, upper Hessenberg, row by row.
    h: Vec<f64>,
    /// Q^T Gamma(T).
    g: Vec<f64>,
    /// The output row through Q: Q^T c (or Q^T Phi(T - eps)^T c).
    c: Vec<f64>,
    /// The direct term: d, or c Gamma(T - eps) + d.
    d: f64,
    /// Whole samples of delay: q, or q + 1.
    shift: f64,
    /// What the whole samples exceed the delay by (s): 0, or T - eps.
    lead_s: f64,
    period_s: f64,
}

impl ZohSampled {
    /// `tf` (its delay included) held and sampled at `sample_rate_hz`.
    pub fn new(tf: &TransferFunction, sample_rate_hz: f64) -> Self {
        Self::of_state_space(&tf.to_state_space(), 0, tf.delay_s, sample_rate_hz)
    }

    /// Output `output` of `ss`, read `delay_s` late, held and sampled at
    /// `sample_rate_hz`.
    pub fn of_state_space(
        ss: &StateSpace,
        output: usize,
        delay_s: f64,
        sample_rate_hz: f64,
    ) -> Self {
        let t = 1.0 / sample_rate_hz;
        let n = ss.order();
        // Balanced (a power-of-two similarity, exact): the plant's
        // coefficients span ten decades and Phi's small entries would
        // otherwise lose digits. B then carries the scaling's range, which
        // the exponential's own balancing cannot take out of [[A, B], [0,
        // 0]] (its last row is zero) and which would set its squarings: B
        // is scaled to a largest entry of 1 and C the other way.
        let scale = balancing_diagonal(&ss.a);
        let a = DMatrix::from_fn(n, n, |i, j| ss.a[(i, j)] * scale[j] / scale[i]);
        let b = DVector::from_fn(n, |i, _| ss.b[i] / scale[i]);
        let size = match b.amax() {
            m if m > 0.0 && m.is_finite() => m,
            _ => 1.0,
        };
        let b = b / size;
        let c = DVector::from_fn(n, |j, _| ss.c[(output, j)] * scale[j] * size);
        let (phi, gamma) = phi_gamma(&a, &b, t);
        let (whole, eps) = split_delay(delay_s, t);
        let (c, d, shift) = match eps {
            None => (c, ss.d[output], whole),
            Some(eps) => {
                let (phi_e, gamma_e) = phi_gamma(&a, &b, t - eps);
                (
                    phi_e.transpose() * &c,
                    c.dot(&gamma_e) + ss.d[output],
                    whole + 1,
                )
            }
        };
        let (q, h) = if n == 0 {
            (phi.clone(), phi)
        } else {
            nalgebra::linalg::Hessenberg::new(phi).unpack()
        };
        Self {
            h: (0..n * n).map(|k| h[(k / n, k % n)]).collect(),
            g: (q.transpose() * gamma).iter().copied().collect(),
            c: (q.transpose() * c).iter().copied().collect(),
            d,
            shift: shift as f64,
            lead_s: shift as f64 * t - delay_s,
            period_s: t,
        }
    }

    /// G_d(e^{i w T}) at `f_hz` (Hz); `work` is scratch of any length.
    pub fn at(&self, f_hz: f64, work: &mut Vec<Complex<f64>>) -> Complex<f64> {
        let wt = 2.0 * std::f64::consts::PI * f_hz * self.period_s;
        self.solve(Complex::from_polar(1.0, wt), work) * Complex::from_polar(1.0, -wt * self.shift)
    }

    /// G_d(e^{i w T}) over the hold's continuous factor and the delay,
    /// G_d / (zoh_response(f) e^{-i w delay}), at `f_hz`: what multiplies a
    /// rational model's R(i w) in the sampled response, R itself and the
    /// aliases' factor (k = 0 alone would leave R). The whole samples'
    /// z^-shift less the delay leaves e^{i w lead}, so with e^{i w T / 2}
    /// from the hold one or two sines and cosines a frequency.
    pub fn over_hold(&self, f_hz: f64, work: &mut Vec<Complex<f64>>) -> Complex<f64> {
        let half = std::f64::consts::PI * f_hz * self.period_s; // w T / 2
        let (sin, cos) = half.sin_cos();
        let z = Complex::new(cos * cos - sin * sin, 2.0 * sin * cos);
        let inv_sinc = if half == 0.0 { 1.0 } else { half / sin };
        // G_d / (Z e^{-i w tau}) = y(z) e^{i w (T/2 - lead)} / sinc.
        let phase = if self.lead_s == 0.0 {
            Complex::new(cos, sin)
        } else {
            Complex::from_polar(1.0, half - 2.0 * std::f64::consts::PI * f_hz * self.lead_s)
        };
        self.solve(z, work) * (phase * inv_sinc)
    }

    /// c (zI - H)^-1 g + d by Gaussian elimination with partial pivoting:
    /// H has one subdiagonal, so each step pairs two rows.
    fn solve(&self, z: Complex<f64>, work: &mut Vec<Complex<f64>>) -> Complex<f64> {
        let n = self.g.len();
        // m is n x n, then the right-hand side.
        work.clear();
        work.extend(self.h.iter().map(|&v| Complex::new(-v, 0.0)));
        work.extend(self.g.iter().map(|&v| Complex::new(v, 0.0)));
        let (m, r) = work.split_at_mut(n * n);
        for k in 0..n {
            m[k * n + k] += z;
        }
        for k in 0..n.saturating_sub(1) {
            let (top, below) = (k * n, (k + 1) * n);
            if m[below + k].norm_sqr() > m[top + k].norm_sqr() {
                for j in k..n {
                    m.swap(top + j, below + j);
                }
                r.swap(k, k + 1);
            }
            let l = m[below + k] / m[top + k];
            for j in k + 1..n {
                let v = m[top + j];
                m[below + j] -= l * v;
            }
            let v = r[k];
            r[k + 1] -= l * v;
        }
        let mut y = Complex::new(self.d, 0.0);
        for i in (0..n).rev() {
            let mut v = r[i];
            for j in i + 1..n {
                v -= m[i * n + j] * r[j];
            }
            r[i] = v / m[i * n + i];
            y += r[i] * self.c[i];
        }
        y
    }

    /// G_d at each of `freq_hz`.
    pub fn response(&self, freq_hz: &[f64]) -> Vec<Complex<f64>> {
        let mut work = Vec::new();
        freq_hz.iter().map(|&f| self.at(f, &mut work)).collect()
    }
}

/// Phi(t) = e^{A t} and Gamma(t) = int_0^t e^{A s} ds B, both read off
/// exp([[A, B], [0, 0]] t) (Van Loan 1978, "Computing integrals involving
/// the matrix exponential").
pub fn phi_gamma(a: &DMatrix<f64>, b: &DVector<f64>, t: f64) -> (DMatrix<f64>, DVector<f64>) {
    let n = a.nrows();
    let mut m = DMatrix::<f64>::zeros(n + 1, n + 1);
    m.view_mut((0, 0), (n, n)).copy_from(&(a * t));
    m.view_mut((0, n), (n, 1)).copy_from(&(b * t));
    let e = expm_balanced(&m);
    let phi = e.view((0, 0), (n, n)).into_owned();
    let gamma = e.view((0, n), (n, 1)).column(0).into_owned();
    (phi, gamma)
}

/// exp(M) through a power-of-two diagonal similarity; NaN throughout for
/// an M with a non-finite entry, or whose balanced 1-norm is above
/// [`EXPM_NORM_MAX`] (nalgebra's scaling and squaring would square
/// u64::MAX times: a hang).
///
/// exp() is nalgebra's Pade scaling-and-squaring (Al-Mohy & Higham 2009),
/// applied after the balancing: the plant's A mixes 1/m ~ 0.3 with a1b0 ~
/// 2.4e9, so ||A T|| ~ 1e6 while its eigenvalues times T are below 1.
/// Unbalanced, that costs about twenty squarings and the small entries of
/// Phi lose digits; balanced, the norm is that of the eigenvalues.
/// exp(D^-1 M D) = D^-1 exp(M) D exactly, and powers of two make the
/// scaling exact in floating point.
pub fn expm_balanced(m: &DMatrix<f64>) -> DMatrix<f64> {
    if m.iter().any(|v| !v.is_finite()) {
        return DMatrix::from_element(m.nrows(), m.ncols(), f64::NAN);
    }
    let d = balancing_diagonal(m);
    let n = m.nrows();
    let balanced = DMatrix::from_fn(n, n, |i, j| m[(i, j)] * d[j] / d[i]);
    let norm = (0..n)
        .map(|j| balanced.column(j).iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0, f64::max);
    if norm > EXPM_NORM_MAX {
        return DMatrix::from_element(n, n, f64::NAN);
    }
    let e = balanced.exp();
    DMatrix::from_fn(n, n, |i, j| e[(i, j)] * d[i] / d[j])
}

/// The largest 1-norm [`expm_balanced`] takes: nalgebra's exp reads its
/// scaling from norms of M^10, which overflow from about 1e30 and then ask
/// for u64::MAX squarings. A plant's A T is below 1e3 or so; 1e20 is a
/// model's parameters gone far out (a mode at 1e20 rad/s), whose
/// exponential nothing reads.
pub const EXPM_NORM_MAX: f64 = 1e20;

/// Splits a delay into whole samples and a fraction: (q, Some(eps)) with
/// delay = q T + eps, 0 < eps < T, or (q, None) when the delay is a whole
/// number of samples to within 1e-9 of a sample.
pub fn split_delay(delay_s: f64, dt_s: f64) -> (usize, Option<f64>) {
    let q = delay_s / dt_s;
    let whole = q.round();
    if (q - whole).abs() < 1e-9 {
        (whole as usize, None)
    } else {
        let qf = q.floor();
        (qf as usize, Some(delay_s - qf * dt_s))
    }
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

    /// G_d by partial fractions, independently of the state space: with
    /// G(s)/s = sum_i c_i / (s - p_i) (the hold's pole p = 0 among them),
    /// sum_k e^{-i k ws eps} / (a + i k ws) = T e^{a eps} / (e^{a T} - 1)
    /// for 0 <= eps < T (the Fourier series of e^{-a t} on [0, T)) turns
    /// the alias sum into
    /// G_d = (1 - z^-1) z^-q sum_i c_i e^{-p_i eps} / (e^{(i w - p_i) T} - 1)
    /// for a strictly proper G with distinct poles.
    fn partial_fractions(tf: &TransferFunction, fs: f64, f: f64) -> Complex<f64> {
        let t = 1.0 / fs;
        let w = 2.0 * std::f64::consts::PI * f;
        let (q, eps) = split_delay(tf.delay_s, t);
        let eps = eps.unwrap_or(0.0);
        let dden = poly::derivative(&tf.den);
        let mut poles = vec![(Complex::new(0.0, 0.0), Complex::new(tf.dc_gain(), 0.0))];
        for p in tf.poles() {
            let c = poly::eval(&tf.num, p) / (p * poly::eval(&dden, p));
            poles.push((p, c));
        }
        let iw = Complex::new(0.0, w);
        let sum: Complex<f64> = poles
            .iter()
            .map(|&(p, c)| c * (-p * eps).exp() / (((iw - p) * t).exp() - 1.0))
            .sum();
        let one = Complex::new(1.0, 0.0);
        (one - Complex::from_polar(1.0, -w * t)) * Complex::from_polar(1.0, -w * t * q as f64) * sum
    }

    /// G_d as the alias sum itself, sum_k G(i w_k) e^{-i w_k tau} Z(i w_k),
    /// to |k| = 40,000: the terms fall as 1 / k^(r + 1), so what is left
    /// out is below 1e-12 of the response for r >= 2.
    fn alias_sum(tf: &TransferFunction, fs: f64, f: f64) -> Complex<f64> {
        let ws = 2.0 * std::f64::consts::PI * fs;
        (-40_000..=40_000)
            .rev()
            .map(|k| {
                let wk = 2.0 * std::f64::consts::PI * f + k as f64 * ws;
                tf.freq_response(wk / (2.0 * std::f64::consts::PI)) * zoh_response(wk / ws * fs, fs)
            })
            .sum()
    }

    #[test]
    fn zoh_sampled_response_is_the_alias_sum() {
        // The paper's no-specimen model (Eq. 36, r = 2) and Exp1's x1/u
        // (Eq. 17, r = 4) at 200 Hz, undelayed, 2 samples late and 1.37
        // samples late: the state space's G_d against the partial
        // fractions' to 1e-10, and against the alias sum to 1e-10.
        let fs = 200.0;
        let t = 1.0 / fs;
        let exp1 = crate::model::tf_x1_u(
            &crate::model::PAPER_RIG,
            &crate::model::LinearSpecimen::Sdof {
                mass_kg: 3.8,
                damping_ns_per_m: 5.0,
                stiffness_n_per_m: 129_400.0,
            },
        )
        .unwrap();
        let no_specimen = TransferFunction::new(&[3060.0], &[1.0, 267.0, 3060.0]).unwrap();
        let freq = [0.5, 7.0, 29.4, 30.0, 99.0];
        for plant in [&no_specimen, &exp1] {
            for delay in [0.0, 2.0 * t, 1.37 * t] {
                let tf = TransferFunction::with_delay(&plant.num, &plant.den, delay).unwrap();
                let sampled = ZohSampled::new(&tf, fs);
                let got = sampled.response(&freq);
                let mut work = Vec::new();
                for (&f, g) in freq.iter().zip(&got) {
                    // over_hold is G_d less the hold and the delay.
                    let back = sampled.over_hold(f, &mut work)
                        * zoh_response(f, fs)
                        * Complex::from_polar(1.0, -2.0 * std::f64::consts::PI * f * delay);
                    assert!(
                        (back - g).norm() < 1e-12 * g.norm(),
                        "{f} Hz: {back} vs {g}"
                    );
                    let want = partial_fractions(&tf, fs, f);
                    let sum = alias_sum(&tf, fs, f);
                    assert!(
                        (g - want).norm() < 1e-10 * want.norm(),
                        "order {}, delay {delay}, {f} Hz: {g} vs {want}",
                        tf.order()
                    );
                    assert!(
                        (g - sum).norm() < 1e-10 * sum.norm(),
                        "order {}, delay {delay}, {f} Hz: {g} vs {sum}",
                        tf.order()
                    );
                }
                // The aliases are what the continuous factor leaves out:
                // 0.6 % of the no-specimen model's response at 30 Hz.
                if plant.order() == 2 && delay == 0.0 {
                    let k0 = tf.freq_response(30.0) * zoh_response(30.0, fs);
                    let share = (got[3] - k0).norm() / got[3].norm();
                    assert!((5e-3..8e-3).contains(&share), "{share}");
                }
            }
        }
    }

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
