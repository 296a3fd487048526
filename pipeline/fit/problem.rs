//! The fitted model in scaled frequency and its residuals and analytic
//! Jacobian, as an argmin problem (`Operator` + `Jacobian`).
//!
//! With s' = s / w0 the model is
//! H(s') = N'(s') / D'(s') * exp(-s' tau') * K, where N' has free coefficients
//! b'_m .. b'_0, D' = s'^n + a'_{n-1} s'^{n-1} + ... + a'_0 is monic, tau' =
//! tau w0 is the delay in units of 1/w0 and K is the known factor at each bin
//! (the hold and any fixed delay). [`Scaling`] maps these to physical units.

use argmin::core::{Error as ArgminError, Jacobian, Operator};
use nalgebra::{Complex, DMatrix, DVector};

use super::settings::Intersample;
use crate::lti::TransferFunction;
use crate::poly;

/// Response of the command's intersample behaviour at `f_hz` (Hz).
///
/// `SampleAndHold`: a D/A converter holding each sample for T = 1/fs has the
/// impulse response 1/T on [0, T), whose transform is
/// Z(jw) = (1 - exp(-jwT)) / (jwT) = exp(-jwT/2) sin(wT/2) / (wT/2),
/// a half-sample delay times a sinc; written in the second form it has no
/// cancellation as w -> 0. `None`: Z = 1.
pub fn hold_response(intersample: Intersample, sample_rate_hz: f64, f_hz: f64) -> Complex<f64> {
    match intersample {
        Intersample::None => Complex::new(1.0, 0.0),
        Intersample::SampleAndHold => crate::lti::zoh_response(f_hz, sample_rate_hz),
    }
}

/// What a log of the command and of the output holds of the plant `tf`
/// (its delay included) at each of `freq_hz`: with a held command its
/// exact sampled response, aliases and all ([`crate::lti::ZohSampled`]),
/// of which `tf`'s response times [`hold_response`] is the first term;
/// without a hold, `tf`'s response.
pub fn sampled_response(
    intersample: Intersample,
    sample_rate_hz: f64,
    tf: &TransferFunction,
    freq_hz: &[f64],
) -> Vec<Complex<f64>> {
    match intersample {
        Intersample::None => freq_hz.iter().map(|&f| tf.freq_response(f)).collect(),
        Intersample::SampleAndHold => {
            crate::lti::ZohSampled::new(tf, sample_rate_hz).response(freq_hz)
        }
    }
}

/// The factor the aliases put on `tf`'s continuous model with the hold at
/// each of `freq_hz`: [`sampled_response`] over `tf`'s response times
/// [`hold_response`] ([`crate::lti::ZohSampled::over_hold`] over the
/// rational part). A fit models the hold as this factor on its rational
/// model, evaluated at its own estimate (`fit::refine_held`): the aliases
/// depend on the plant, but weakly, so a few re-evaluations reach the
/// model whose factor is its own. 1 without a hold, and where the ratio is
/// not finite (a continuous model that vanishes at a bin).
pub fn alias_factor(
    intersample: Intersample,
    sample_rate_hz: f64,
    tf: &TransferFunction,
    freq_hz: &[f64],
) -> Vec<Complex<f64>> {
    let one = Complex::new(1.0, 0.0);
    if intersample == Intersample::None {
        return vec![one; freq_hz.len()];
    }
    let sampled = crate::lti::ZohSampled::new(tf, sample_rate_hz);
    let mut work = Vec::new();
    freq_hz
        .iter()
        .map(|&f| {
            let s = Complex::new(0.0, 2.0 * std::f64::consts::PI * f);
            let a = sampled.over_hold(f, &mut work) * crate::poly::eval(&tf.den, s)
                / crate::poly::eval(&tf.num, s);
            if a.re.is_finite() && a.im.is_finite() {
                a
            } else {
                one
            }
        })
        .collect()
}

/// Orders of the fitted model and whether a delay is a parameter.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ModelShape {
    pub numerator_order: usize,
    pub denominator_order: usize,
    pub fit_delay: bool,
}

impl ModelShape {
    /// Number of free parameters: m + 1 numerator, n denominator, and tau.
    pub fn n_params(&self) -> usize {
        self.n_rational() + usize::from(self.fit_delay)
    }

    /// Number of rational-part parameters (numerator and denominator).
    pub fn n_rational(&self) -> usize {
        self.numerator_order + 1 + self.denominator_order
    }

    /// Parameter names in the order of the parameter vector:
    /// n_m .. n_0, d_{n-1} .. d_0 (the paper's n0, d1, d0 for a 0/2 model),
    /// then `tau_s`.
    pub fn names(&self) -> Vec<String> {
        let m = self.numerator_order;
        let n = self.denominator_order;
        let mut names: Vec<String> = (0..=m).rev().map(|k| format!("n{k}")).collect();
        names.extend((0..n).rev().map(|k| format!("d{k}")));
        if self.fit_delay {
            names.push("tau_s".to_string());
        }
        names
    }

    /// Power of s' that parameter `index` multiplies (numerator or
    /// denominator), or `None` for the delay.
    fn power(&self, index: usize) -> Option<usize> {
        let m = self.numerator_order;
        let n = self.denominator_order;
        if index <= m {
            Some(m - index)
        } else if index < self.n_rational() {
            Some(n - 1 - (index - m - 1))
        } else {
            None
        }
    }
}

/// Frequency scaling s' = s / w0 and its effect on the parameters.
///
/// N(s)/D(s) with D monic of order n equals N'(s')/D'(s') when every
/// coefficient of s^k (numerator or denominator) is divided by w0^(n-k):
/// D(s) = w0^n D'(s'), N(s) = w0^n N'(s'). The map is diagonal, so the
/// covariance transforms exactly as S C S with S = diag(w0^(n-k), ..., 1/w0).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scaling {
    /// w0 (rad/s).
    pub w0_rad_per_s: f64,
}

impl Scaling {
    /// w0 = sqrt(w_min w_max), the geometric mean of the band's edge angular
    /// frequencies, so |s'| spans [1/r, r] symmetrically in log: the powers
    /// s'^k in the normal equations then stay near 1 instead of spanning
    /// 1 .. w^2n (1 .. 1e9 for the plant).
    pub fn for_band(freq_hz: &[f64]) -> Self {
        let (lo, hi) = freq_hz
            .iter()
            .fold((f64::INFINITY, 0.0_f64), |(lo, hi), &f| {
                (lo.min(f), hi.max(f))
            });
        Self {
            w0_rad_per_s: 2.0 * std::f64::consts::PI * (lo * hi).sqrt(),
        }
    }

    /// Factors S with physical = S * scaled, per parameter.
    pub fn factors(&self, shape: &ModelShape) -> Vec<f64> {
        let n = shape.denominator_order as i32;
        (0..shape.n_params())
            .map(|i| match shape.power(i) {
                Some(k) => self.w0_rad_per_s.powi(n - k as i32),
                None => 1.0 / self.w0_rad_per_s,
            })
            .collect()
    }

    /// Scaled parameters to physical ones (coefficients, tau in s).
    pub fn to_physical(&self, shape: &ModelShape, scaled: &[f64]) -> Vec<f64> {
        scaled
            .iter()
            .zip(self.factors(shape))
            .map(|(x, f)| x * f)
            .collect()
    }

    /// Physical parameters to scaled ones.
    pub fn to_scaled(&self, shape: &ModelShape, physical: &[f64]) -> Vec<f64> {
        physical
            .iter()
            .zip(self.factors(shape))
            .map(|(x, f)| x / f)
            .collect()
    }

    /// s' = j w / w0 at `f_hz`.
    pub fn s(&self, f_hz: f64) -> Complex<f64> {
        Complex::new(0.0, 2.0 * std::f64::consts::PI * f_hz / self.w0_rad_per_s)
    }
}

/// Weighted least-squares problem: residuals e_i = (h_i - H(s'_i)) w_i with
/// w_i = sqrt(2 / variance_i), stacked [Re e; Im e].
///
/// For circular complex noise of variance v, the real and imaginary parts
/// each have variance v/2, so with these weights the sum of squares is a
/// chi-square with 2N degrees of freedom at the true parameters.
#[derive(Debug, Clone)]
pub struct FrfProblem {
    pub shape: ModelShape,
    /// s' at each bin.
    pub s: Vec<Complex<f64>>,
    /// Measured response.
    pub h: Vec<Complex<f64>>,
    /// Known factor K at each bin: the hold, its aliases at the model
    /// they were evaluated for ([`alias_factor`]) and any fixed delay.
    pub known: Vec<Complex<f64>>,
    /// sqrt(2 / variance) at each bin.
    pub weight: Vec<f64>,
    /// The record's transient columns, projected out of the residuals and
    /// the Jacobian (`fit::transient`); None for a plain fit.
    pub projector: Option<std::sync::Arc<super::transient::Projector>>,
    /// The last evaluation, kept for the next call at the same point: it
    /// depends on `shape`, `s` and `known`, which do not change once a
    /// problem is evaluated (a changed problem is a new one).
    pub last: LastEval,
}

/// D', the delay's phasor and the model H at one bin.
#[derive(Debug, Clone, Copy)]
struct BinEval {
    den: Complex<f64>,
    delay: Complex<f64>,
    model: Complex<f64>,
}

/// The bins' evaluations at the last parameters a problem was evaluated
/// at: Levenberg-Marquardt asks for the residuals at a trial point and,
/// when it accepts it, for the Jacobian at the same point, whose every bin
/// needs the same polynomials and delay phasor. A clone starts empty.
#[derive(Debug, Default)]
pub struct LastEval(std::sync::Mutex<Option<Evaluated>>);

/// Parameters and every bin's evaluation there.
type Evaluated = (Vec<f64>, std::sync::Arc<Vec<BinEval>>);

impl Clone for LastEval {
    fn clone(&self) -> Self {
        Self::default()
    }
}

impl FrfProblem {
    /// Number of bins.
    pub fn n_bins(&self) -> usize {
        self.s.len()
    }

    fn split<'a>(&self, theta: &'a [f64]) -> (&'a [f64], &'a [f64], f64) {
        let m = self.shape.numerator_order;
        let num = &theta[..=m];
        let den = &theta[m + 1..self.shape.n_rational()];
        let tau = if self.shape.fit_delay {
            theta[self.shape.n_rational()]
        } else {
            0.0
        };
        (num, den, tau)
    }

    fn eval_bin(&self, i: usize, num: &[f64], den: &[f64], tau: f64) -> BinEval {
        let s = self.s[i];
        let n_val = poly::eval(num, s);
        let d_val = poly::eval_monic(den, s);
        let delay = poly::delay(s, tau);
        BinEval {
            den: d_val,
            delay,
            model: n_val / d_val * delay * self.known[i],
        }
    }

    /// Every bin's evaluation at `theta`: the last one's when `theta` is the
    /// same bits.
    fn eval_bins(&self, theta: &[f64]) -> std::sync::Arc<Vec<BinEval>> {
        let mut last = self.last.0.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((at, bins)) = last.as_ref()
            && at.len() == theta.len()
            && at
                .iter()
                .zip(theta)
                .all(|(a, b)| a.to_bits() == b.to_bits())
        {
            return bins.clone();
        }
        let (num, den, tau) = self.split(theta);
        let bins = std::sync::Arc::new(
            (0..self.n_bins())
                .map(|i| self.eval_bin(i, num, den, tau))
                .collect::<Vec<_>>(),
        );
        *last = Some((theta.to_vec(), bins.clone()));
        bins
    }

    /// Model response H(s'_i) at every bin (known factors included).
    pub fn model(&self, theta: &[f64]) -> Vec<Complex<f64>> {
        self.eval_bins(theta).iter().map(|b| b.model).collect()
    }

    /// Model response at every `stride`-th bin (known factors included).
    pub fn model_every(&self, theta: &[f64], stride: usize) -> Vec<Complex<f64>> {
        let (num, den, tau) = self.split(theta);
        (0..self.n_bins())
            .step_by(stride)
            .map(|i| self.eval_bin(i, num, den, tau).model)
            .collect()
    }

    /// Weighted residuals stacked [Re; Im].
    pub fn residuals(&self, theta: &[f64]) -> DVector<f64> {
        let n = self.n_bins();
        let mut r = DVector::zeros(2 * n);
        for (i, hm) in self.model(theta).into_iter().enumerate() {
            let e = (self.h[i] - hm) * self.weight[i];
            r[i] = e.re;
            r[n + i] = e.im;
        }
        if let Some(p) = &self.projector {
            p.project(&mut r);
        }
        r
    }

    /// Analytic Jacobian of [`FrfProblem::residuals`]:
    /// dH/db'_k = s'^k / D' * E K, dH/da'_k = -H s'^k / D', dH/dtau' = -s' H,
    /// and de/dtheta = -w dH/dtheta.
    pub fn jacobian_matrix(&self, theta: &[f64]) -> DMatrix<f64> {
        let n = self.n_bins();
        let p = self.shape.n_params();
        let m = self.shape.numerator_order;
        let tau = self.split(theta).2;
        let bins = self.eval_bins(theta);
        let mut jac = DMatrix::zeros(2 * n, p);
        let max_pow = self.shape.denominator_order.max(m);
        let mut pow = vec![Complex::new(1.0, 0.0); max_pow + 1];
        for i in 0..n {
            let s = self.s[i];
            for k in 1..=max_pow {
                pow[k] = pow[k - 1] * s;
            }
            let b = &bins[i];
            // E K / D' = H / N' without dividing by a possibly zero N'.
            let ek_over_d = if tau == 0.0 {
                self.known[i] / b.den
            } else {
                b.delay * self.known[i] / b.den
            };
            let w = self.weight[i];
            for j in 0..p {
                let dh = match self.shape.power(j) {
                    Some(k) if j <= m => pow[k] * ek_over_d,
                    Some(k) => -b.model * pow[k] / b.den,
                    None => -s * b.model,
                };
                jac[(i, j)] = -dh.re * w;
                jac[(n + i, j)] = -dh.im * w;
            }
        }
        if let Some(p) = &self.projector {
            p.project_columns(&mut jac);
        }
        jac
    }
}

impl Operator for FrfProblem {
    type Param = DVector<f64>;
    type Output = DVector<f64>;

    fn apply(&self, param: &Self::Param) -> Result<Self::Output, ArgminError> {
        Ok(self.residuals(param.as_slice()))
    }
}

impl Jacobian for FrfProblem {
    type Param = DVector<f64>;
    type Jacobian = DMatrix<f64>;

    fn jacobian(&self, param: &Self::Param) -> Result<Self::Jacobian, ArgminError> {
        Ok(self.jacobian_matrix(param.as_slice()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn hold_matches_its_defining_formula() {
        // Z = (1 - exp(-jwT)) / (jwT), evaluated directly (the implementation
        // uses the sinc form), at frequencies from near DC to Nyquist. The
        // direct form cancels as wT -> 0 and is itself good only to about
        // eps / (wT); the tolerance allows for that.
        let fs = 1000.0;
        let t = 1.0 / fs;
        for f in [0.01, 0.5, 7.0, 30.0, 123.4, 499.0, 500.0] {
            let wt = 2.0 * std::f64::consts::PI * f * t;
            let jwt = Complex::new(0.0, wt);
            let want = (Complex::new(1.0, 0.0) - (-jwt).exp()) / jwt;
            let got = hold_response(Intersample::SampleAndHold, fs, f);
            let tol = 1e-15 + 4.0 * f64::EPSILON / wt;
            assert!((got - want).norm() < tol, "f = {f}: {got} vs {want}");
        }
        // At DC the hold passes unchanged; at Nyquist |Z| = sin(pi/2)/(pi/2) = 2/pi.
        let z0 = hold_response(Intersample::SampleAndHold, fs, 0.0);
        assert_relative_eq!(z0.re, 1.0);
        assert_relative_eq!(z0.im, 0.0);
        assert_relative_eq!(
            hold_response(Intersample::SampleAndHold, fs, 500.0).norm(),
            2.0 / std::f64::consts::PI,
            max_relative = 1e-14
        );
        let none = hold_response(Intersample::None, fs, 123.0);
        assert_relative_eq!(none.re, 1.0);
        assert_relative_eq!(none.im, 0.0);
    }

    #[test]
    fn scaled_model_equals_the_physical_transfer_function() {
        // (2 s + 3e4) / (s^3 + 300 s^2 + 4e4 s + 5e6) * exp(-0.002 s), evaluated
        // by lti::TransferFunction in physical units, against the scaled model.
        let shape = ModelShape {
            numerator_order: 1,
            denominator_order: 3,
            fit_delay: true,
        };
        let phys = [2.0, 3e4, 300.0, 4e4, 5e6, 0.002];
        let tf = TransferFunction::with_delay(&[2.0, 3e4], &[1.0, 300.0, 4e4, 5e6], 0.002).unwrap();
        let freq = [0.5, 3.0, 12.0, 30.0];
        let scaling = Scaling::for_band(&freq);
        assert_relative_eq!(
            scaling.w0_rad_per_s,
            2.0 * std::f64::consts::PI * 15.0_f64.sqrt(),
            max_relative = 1e-15
        );
        let scaled = scaling.to_scaled(&shape, &phys);
        let back = scaling.to_physical(&shape, &scaled);
        for (a, b) in back.iter().zip(phys.iter()) {
            assert_relative_eq!(a, b, max_relative = 1e-15);
        }
        let problem = FrfProblem {
            shape,
            s: freq.iter().map(|&f| scaling.s(f)).collect(),
            h: vec![Complex::new(0.0, 0.0); freq.len()],
            known: vec![Complex::new(1.0, 0.0); freq.len()],
            weight: vec![1.0; freq.len()],
            projector: None,
            last: Default::default(),
        };
        for (hm, &f) in problem.model(&scaled).iter().zip(freq.iter()) {
            let want = tf.freq_response(f);
            assert!((hm - want).norm() < 1e-13 * want.norm(), "{hm} vs {want}");
        }
        assert_eq!(
            shape.names(),
            ["n1", "n0", "d2", "d1", "d0", "tau_s"].map(String::from)
        );
    }
}
