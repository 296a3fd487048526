//! The record's transient, fitted beside a run's model. A record that does
//! not start and end at rest (a sweep cut while the rig still moves, a
//! multisine or noise run started from rest) has the DFT
//! Y(k) = G(k) U(k) + T(k) + V(k), T the leakage of the states at its ends.
//! Over the band T is a real polynomial of degree n + 1 over the model's own
//! denominator D (of order n), times the model's delay, and a drifting
//! sensor adds c fs / s: divided by U(k), n + 3 columns that enter H = Y/U
//! linearly with real coefficients (`weighted_columns`, `column_count`).
//!
//! The fit eliminates them at every step by separable least squares
//! (`Projector`: residuals and Jacobian projected onto the complement of
//! the columns), so the model's covariance is the marginal one; `Transient`
//! is what was taken out. The derivation (Pintelon & Schoukens 2012,
//! Sec. 6.3.2; Golub & Pereyra 2003): docs/methods.md, "The transient
//! fitted beside the model".

use nalgebra::{Complex, DMatrix, DVector};

/// The weighted transient columns of one pass, factored: projecting a
/// residual vector (stacked [Re; Im]) onto their complement, and the
/// columns' coefficients for a residual.
#[derive(Debug, Clone)]
pub struct Projector {
    /// Orthonormal basis of the columns' span (2n x r, r <= the columns).
    q: DMatrix<f64>,
    /// Coefficients of the unscaled columns from Q^T r (columns x r).
    coefficients_of: DMatrix<f64>,
}

/// Singular values below this share of the largest (columns scaled to unit
/// norm) are taken as a direction the columns do not span.
const RANK_TOL: f64 = 1e-10;

impl Projector {
    /// The projector of the weighted columns `b` (2n x m), or None when
    /// they span nothing.
    pub fn new(mut b: DMatrix<f64>) -> Option<Self> {
        let norms: Vec<f64> = b.column_iter().map(|c| c.norm()).collect();
        for (j, mut col) in b.column_iter_mut().enumerate() {
            if norms[j] > 0.0 && norms[j].is_finite() {
                col /= norms[j];
            } else {
                col.fill(0.0);
            }
        }
        let (rows, cols) = b.shape();
        let svd = b.svd(true, true);
        let (u, v_t) = (svd.u.as_ref()?, svd.v_t.as_ref()?);
        let sv = &svd.singular_values;
        let top = sv.iter().fold(0.0_f64, |m, &v| m.max(v));
        if !(top > 0.0 && top.is_finite()) {
            return None;
        }
        let kept: Vec<usize> = (0..sv.len()).filter(|&i| sv[i] > RANK_TOL * top).collect();
        let q = DMatrix::from_fn(rows, kept.len(), |i, j| u[(i, kept[j])]);
        // b_scaled = U S V^T, so the least-squares coefficients of the
        // scaled columns are V S^-1 U^T r; of the unscaled ones, those over
        // the norms.
        let coefficients_of = DMatrix::from_fn(cols, kept.len(), |i, j| {
            let k = kept[j];
            if norms[i] > 0.0 && norms[i].is_finite() {
                v_t[(k, i)] / sv[k] / norms[i]
            } else {
                0.0
            }
        });
        Some(Self { q, coefficients_of })
    }

    /// The directions the columns span (at most their number).
    pub fn rank(&self) -> usize {
        self.q.ncols()
    }

    /// `r` less its part in the columns' span.
    pub fn project(&self, r: &mut DVector<f64>) {
        let c = self.q.tr_mul(r);
        r.gemv(-1.0, &self.q, &c, 1.0);
    }

    /// Each column of `j` less its part in the columns' span.
    pub fn project_columns(&self, j: &mut DMatrix<f64>) {
        let c = self.q.tr_mul(j);
        j.gemm(-1.0, &self.q, &c, 1.0);
    }

    /// The columns' least-squares coefficients for the residual `r`.
    pub fn coefficients(&self, r: &DVector<f64>) -> DVector<f64> {
        &self.coefficients_of * self.q.tr_mul(r)
    }
}

/// The transient a fit found, T(k)/U(k) at any bin: what the fit took out
/// of the FRF beside its model.
#[derive(Debug, Clone, PartialEq)]
pub struct Transient {
    /// The frequency scaling of the fit (rad/s): s' = j w / w0.
    pub w0_rad_per_s: f64,
    /// The model's monic denominator in s' after its leading 1.
    pub den: Vec<f64>,
    /// The model's delay (s), fixed and fitted.
    pub delay_s: f64,
    /// The real coefficients of s'^0 .. s'^(n+1) over D(s'), then the
    /// drift's over s'.
    pub coefficients: Vec<f64>,
}

impl Transient {
    /// T/U at `f_hz` (positive) for the command's DFT `u` there, in the
    /// FRF's units; zero where U is zero.
    pub fn at(&self, f_hz: f64, u: Complex<f64>) -> Complex<f64> {
        let s = Complex::new(0.0, 2.0 * std::f64::consts::PI * f_hz / self.w0_rad_per_s);
        let columns = columns_at(s, u, &self.den, self.delay_s * self.w0_rad_per_s);
        columns
            .iter()
            .zip(&self.coefficients)
            .map(|(c, k)| c * *k)
            .sum()
    }
}

/// The number of transient columns beside a model whose denominator has
/// order `n`: s'^0 .. s'^(n+1) over D, and the drift's.
pub fn column_count(n: usize) -> usize {
    n + 3
}

/// The transient's columns at one bin, unweighted: s'^j exp(-s' tau') /
/// (D(s') U) for j = 0 ..= n + 1, and 1 / (s' U). Zero where U is zero.
fn columns_at(s: Complex<f64>, u: Complex<f64>, den: &[f64], tau: f64) -> Vec<Complex<f64>> {
    let n = den.len();
    let mut out = Vec::with_capacity(column_count(n));
    if u.norm_sqr() == 0.0 {
        out.resize(column_count(n), Complex::new(0.0, 0.0));
        return out;
    }
    let d = crate::poly::eval_monic(den, s);
    let base = crate::poly::delay(s, tau) / (d * u);
    let mut power = Complex::new(1.0, 0.0);
    for _ in 0..n + 2 {
        out.push(base * power);
        power *= s;
    }
    out.push(Complex::new(1.0, 0.0) / (s * u));
    out
}

/// The weighted columns at the fit's bins (s' and weights as the fit has
/// them), stacked [Re; Im] like its residuals: 2n x (order + 3).
pub fn weighted_columns(
    s: &[Complex<f64>],
    u: &[Complex<f64>],
    weight: &[f64],
    den: &[f64],
    tau: f64,
) -> DMatrix<f64> {
    let n = s.len();
    let m = column_count(den.len());
    let mut b = DMatrix::zeros(2 * n, m);
    for i in 0..n {
        for (j, c) in columns_at(s[i], u[i], den, tau).into_iter().enumerate() {
            b[(i, j)] = c.re * weight[i];
            b[(n + i, j)] = c.im * weight[i];
        }
    }
    b
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A residual made of the columns is taken out whole, and its
    /// coefficients come back; one orthogonal to them is left as it is.
    #[test]
    fn the_projector_removes_the_columns_span_and_recovers_coefficients() {
        let n = 40;
        let s: Vec<Complex<f64>> = (1..=n)
            .map(|k| Complex::new(0.0, 0.05 * k as f64))
            .collect();
        // A command whose phase turns quickly from bin to bin, as a sweep's.
        let u: Vec<Complex<f64>> = (0..n)
            .map(|k| Complex::from_polar(1.0 + 0.1 * k as f64, 2.3 * (k * k) as f64))
            .collect();
        let weight: Vec<f64> = (0..n).map(|k| 1.0 + 0.01 * k as f64).collect();
        let den = [1.3, 0.4];
        let b = weighted_columns(&s, &u, &weight, &den, 0.2);
        let p = Projector::new(b.clone()).unwrap();
        assert_eq!(p.rank(), 5);
        let truth = DVector::from_vec(vec![0.5, -1.0, 2.0, 0.25, -0.75]);
        let mut r = &b * &truth;
        let c = p.coefficients(&r);
        for k in 0..5 {
            assert!(
                (c[k] - truth[k]).abs() < 1e-9,
                "{k}: {} vs {}",
                c[k],
                truth[k]
            );
        }
        p.project(&mut r);
        assert!(r.norm() < 1e-9 * truth.norm());
        // The transient at a bin, as the fit's columns give it unweighted.
        let t = Transient {
            w0_rad_per_s: 1.0,
            den: den.to_vec(),
            delay_s: 0.2,
            coefficients: truth.iter().copied().collect(),
        };
        let k = 7;
        let want = Complex::new(
            (&b * &truth)[k] / weight[k],
            (&b * &truth)[n + k] / weight[k],
        );
        let got = t.at(s[k].im / (2.0 * std::f64::consts::PI), u[k]);
        assert!((got - want).norm() < 1e-12 * want.norm());
        // A vector orthogonal to the span keeps its length.
        let mut other = DVector::from_fn(2 * n, |i, _| ((i * 7919) % 13) as f64 - 6.0);
        let mut copy = other.clone();
        p.project(&mut copy);
        let removed = &other - &copy;
        // What was removed lies in the span: projecting it again leaves nothing.
        other.copy_from(&removed);
        p.project(&mut other);
        assert!(other.norm() < 1e-9 * removed.norm().max(1.0));
    }

    /// The transient of a record is the model's denominator over a
    /// polynomial: the exact discrete-time leakage of a first-order system
    /// cut in motion is matched by the columns to the order the module
    /// states, over a band well below the sampling rate.
    #[test]
    fn the_columns_span_a_discrete_systems_leakage() {
        // y(t+1) = a y(t) + b u(t), a = exp(p / fs): the DFT of a record
        // of N samples obeys Y (1 - a/z) = b U/z + (y(0) - y(N)) (with
        // z^N = 1), so T = (y0 - yN) / (1 - a/z).
        let fs = 1000.0;
        let pole: f64 = -40.0;
        let a = (pole / fs).exp();
        let n = 200;
        let w0 = 2.0 * std::f64::consts::PI * 10.0;
        let freq: Vec<f64> = (1..=n).map(|k| 0.15 * k as f64).collect();
        let s: Vec<Complex<f64>> = freq
            .iter()
            .map(|f| Complex::new(0.0, 2.0 * std::f64::consts::PI * f / w0))
            .collect();
        let u: Vec<Complex<f64>> = (0..n)
            .map(|k| Complex::from_polar(1.0, 0.7 * (k * k) as f64))
            .collect();
        let leak: Vec<Complex<f64>> = freq
            .iter()
            .zip(&u)
            .map(|(f, uk)| {
                let z = Complex::from_polar(1.0, 2.0 * std::f64::consts::PI * f / fs);
                Complex::new(1.0, 0.0) / (Complex::new(1.0, 0.0) - a / z) / uk
            })
            .collect();
        let weight = vec![1.0; n];
        let den = [-pole / w0];
        let b = weighted_columns(&s, &u, &weight, &den, 0.0);
        let p = Projector::new(b).unwrap();
        let mut r = DVector::from_fn(
            2 * n,
            |i, _| {
                if i < n { leak[i].re } else { leak[i - n].im }
            },
        );
        let before = r.norm();
        p.project(&mut r);
        // O((w/fs)^3) at 30 Hz and 1 kHz: about 1e-5 of the leakage.
        assert!(r.norm() < 1e-4 * before, "{} of {before}", r.norm());
    }
}
