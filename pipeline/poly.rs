//! Real polynomials with coefficients stored highest power first (the order
//! results.json uses), and their roots.
//!
//! Roots come from the eigenvalues of the companion matrix, then each is
//! polished by a few Newton steps on the polynomial itself: the companion
//! eigenvalues are backward stable but lose digits when the coefficients span
//! many decades, as the plant's do (s^4 ... 1e9).

use nalgebra::{Complex, DMatrix};

/// Evaluate a real polynomial (highest power first) at a complex point (Horner).
pub fn eval(coeffs: &[f64], s: Complex<f64>) -> Complex<f64> {
    coeffs
        .iter()
        .fold(Complex::new(0.0, 0.0), |acc, &c| acc * s + c)
}

/// Evaluate a monic polynomial at `s`: `rest` are its coefficients after
/// the leading 1 (highest power first), as the fits store a denominator.
pub fn eval_monic(rest: &[f64], s: Complex<f64>) -> Complex<f64> {
    rest.iter()
        .fold(Complex::new(1.0, 0.0), |acc, &c| acc * s + c)
}

/// A pure delay's response exp(-s tau); exactly 1 where there is none.
pub fn delay(s: Complex<f64>, tau: f64) -> Complex<f64> {
    if tau == 0.0 {
        Complex::new(1.0, 0.0)
    } else {
        (-s * tau).exp()
    }
}

/// Evaluate a real polynomial (highest power first) at a real point.
pub fn eval_real(coeffs: &[f64], x: f64) -> f64 {
    coeffs.iter().fold(0.0, |acc, &c| acc * x + c)
}

/// Derivative coefficients (highest power first).
pub fn derivative(coeffs: &[f64]) -> Vec<f64> {
    let n = coeffs.len();
    if n <= 1 {
        return vec![0.0];
    }
    coeffs[..n - 1]
        .iter()
        .enumerate()
        .map(|(i, &c)| c * (n - 1 - i) as f64)
        .collect()
}

/// Product of two polynomials (highest power first).
pub fn mul(a: &[f64], b: &[f64]) -> Vec<f64> {
    if a.is_empty() || b.is_empty() {
        return Vec::new();
    }
    let mut out = vec![0.0; a.len() + b.len() - 1];
    for (i, &x) in a.iter().enumerate() {
        for (j, &y) in b.iter().enumerate() {
            out[i + j] += x * y;
        }
    }
    out
}

/// Sum of two polynomials (highest power first), aligned at the constant term.
pub fn add(a: &[f64], b: &[f64]) -> Vec<f64> {
    let n = a.len().max(b.len());
    let mut out = vec![0.0; n];
    for (k, &x) in a.iter().rev().enumerate() {
        out[n - 1 - k] += x;
    }
    for (k, &y) in b.iter().rev().enumerate() {
        out[n - 1 - k] += y;
    }
    out
}

/// Drop leading zero coefficients (keeps at least one coefficient).
pub fn trim_leading_zeros(coeffs: &[f64]) -> Vec<f64> {
    let first = coeffs.iter().position(|&c| c != 0.0);
    match first {
        Some(i) => coeffs[i..].to_vec(),
        None => vec![0.0],
    }
}

/// Monic polynomial with the given roots (complex roots must come in conjugate
/// pairs for the result to be real; the imaginary residue is discarded).
pub fn from_roots(roots: &[Complex<f64>]) -> Vec<f64> {
    let mut acc: Vec<Complex<f64>> = vec![Complex::new(1.0, 0.0)];
    for &r in roots {
        let mut next = vec![Complex::new(0.0, 0.0); acc.len() + 1];
        for (i, &c) in acc.iter().enumerate() {
            next[i] += c;
            next[i + 1] -= c * r;
        }
        acc = next;
    }
    acc.iter().map(|c| c.re).collect()
}

/// Roots of a real polynomial (highest power first), sorted by real part then
/// imaginary part so the order is reproducible.
///
/// Returns an empty vector for constants. Leading zeros are ignored.
pub fn roots(coeffs: &[f64]) -> Vec<Complex<f64>> {
    let p = trim_leading_zeros(coeffs);
    let n = p.len() - 1;
    if n == 0 {
        return Vec::new();
    }
    let lead = p[0];
    let monic: Vec<f64> = p.iter().map(|c| c / lead).collect();
    let mut out: Vec<Complex<f64>> = if n == 1 {
        vec![Complex::new(-monic[1], 0.0)]
    } else if n == 2 {
        quadratic_roots(monic[1], monic[2]).to_vec()
    } else {
        // Companion matrix in the form whose characteristic polynomial is `monic`.
        let mut c = DMatrix::<f64>::zeros(n, n);
        for j in 0..n {
            c[(0, j)] = -monic[j + 1];
        }
        for i in 1..n {
            c[(i, i - 1)] = 1.0;
        }
        // Roots that cannot be found (a coefficient so large the QR
        // iteration overflows) are NaN: not stable, and not a hang.
        eigenvalues(&c).unwrap_or_else(|| vec![Complex::new(f64::NAN, f64::NAN); n])
    };
    let dp = derivative(&monic);
    for r in out.iter_mut() {
        *r = polish(&monic, &dp, *r);
    }
    // Force exact conjugate symmetry and real roots to be real where the
    // imaginary part is round-off.
    for r in out.iter_mut() {
        if r.im.abs() <= 1e-12 * r.norm().max(1.0) {
            r.im = 0.0;
        }
    }
    out.sort_by(|a, b| a.re.total_cmp(&b.re).then(a.im.total_cmp(&b.im)));
    out
}

/// Roots of s^2 + b s + c without cancellation (the smaller root from the
/// product of the roots).
fn quadratic_roots(b: f64, c: f64) -> [Complex<f64>; 2] {
    let disc = b * b - 4.0 * c;
    if disc >= 0.0 {
        let q = -0.5 * (b + b.signum() * disc.sqrt());
        if q == 0.0 {
            return [Complex::new(0.0, 0.0), Complex::new(0.0, 0.0)];
        }
        [Complex::new(q, 0.0), Complex::new(c / q, 0.0)]
    } else {
        let re = -0.5 * b;
        let im = 0.5 * (-disc).sqrt();
        [Complex::new(re, -im), Complex::new(re, im)]
    }
}

/// Newton steps on p(s) from an eigenvalue estimate; keeps the estimate when a
/// step does not reduce |p|.
fn polish(p: &[f64], dp: &[f64], mut s: Complex<f64>) -> Complex<f64> {
    let mut val = eval(p, s).norm();
    for _ in 0..8 {
        let d = eval(dp, s);
        if d.norm() == 0.0 {
            break;
        }
        let next = s - eval(p, s) / d;
        let next_val = eval(p, next).norm();
        if next_val.is_nan() || next_val >= val {
            break;
        }
        s = next;
        val = next_val;
    }
    s
}

/// The QR sweeps [`eigenvalues`] allows per eigenvalue: LAPACK's dhseqr
/// allows 30 per eigenvalue; a matrix of the plant's scale converges in
/// a handful.
pub const SCHUR_SWEEPS_PER_EIGENVALUE: usize = 30;

/// The eigenvalues of a square matrix (real Schur form), or None when an
/// entry is not finite or the QR iteration does not converge within
/// [`SCHUR_SWEEPS_PER_EIGENVALUE`] sweeps per eigenvalue, or gives a
/// non-finite value. nalgebra's `complex_eigenvalues` iterates without a
/// bound, and on a matrix with an infinite entry (finite but extreme
/// manifest numbers overflow a model's coefficients) never returned.
pub fn eigenvalues(m: &DMatrix<f64>) -> Option<Vec<Complex<f64>>> {
    if m.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let n = m.nrows();
    let schur = nalgebra::Schur::try_new(
        m.clone(),
        f64::EPSILON,
        SCHUR_SWEEPS_PER_EIGENVALUE * n.max(1),
    )?;
    let e: Vec<Complex<f64>> = schur.complex_eigenvalues().iter().copied().collect();
    e.iter()
        .all(|z| z.re.is_finite() && z.im.is_finite())
        .then_some(e)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn roots_of_known_factors() {
        // (s + 1)(s + 10)(s^2 + 2 s + 5): roots -1, -10, -1 +/- 2i.
        let p = mul(&mul(&[1.0, 1.0], &[1.0, 10.0]), &[1.0, 2.0, 5.0]);
        let r = roots(&p);
        assert_eq!(r.len(), 4);
        let expected = [
            Complex::new(-10.0, 0.0),
            Complex::new(-1.0, -2.0),
            Complex::new(-1.0, 0.0),
            Complex::new(-1.0, 2.0),
        ];
        for (got, want) in r.iter().zip(expected.iter()) {
            assert_relative_eq!(got.re, want.re, epsilon = 1e-12);
            assert_relative_eq!(got.im, want.im, epsilon = 1e-12);
        }
    }

    #[test]
    fn from_roots_inverts_roots_over_wide_scales() {
        // Scales like the plant's: poles from ~10 to ~300 rad/s.
        let want = [
            Complex::new(-283.0, 0.0),
            Complex::new(-12.5, -180.0),
            Complex::new(-12.5, 180.0),
            Complex::new(-16.0, 0.0),
        ];
        let p = from_roots(&want);
        let got = roots(&p);
        let mut want_sorted = want.to_vec();
        want_sorted.sort_by(|a, b| a.re.total_cmp(&b.re).then(a.im.total_cmp(&b.im)));
        for (g, w) in got.iter().zip(want_sorted.iter()) {
            assert!((g - w).norm() < 1e-9 * w.norm(), "{g} vs {w}");
        }
    }

    #[test]
    fn quadratic_without_cancellation() {
        // s^2 + 1e8 s + 1: roots -1e-8 and -1e8; the naive formula loses the small one.
        let r = roots(&[1.0, 1e8, 1.0]);
        assert_relative_eq!(r[1].re, -1e-8, max_relative = 1e-12);
        assert_relative_eq!(r[0].re, -1e8, max_relative = 1e-12);
    }

    #[test]
    fn add_aligns_constant_terms() {
        // Exact: sums and products of small integers.
        assert_eq!(add(&[1.0, 2.0, 3.0], &[10.0]), vec![1.0, 2.0, 13.0]);
        assert_eq!(derivative(&[3.0, 2.0, 1.0]), vec![6.0, 2.0]);
        assert_relative_eq!(eval_real(&[1.0, 0.0, -4.0], 2.0), 0.0);
    }
}
