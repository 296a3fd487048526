//! The local polynomial method with its transient term (Pintelon,
//! Schoukens, Vandersteen & Barbe 2010, MSSP 24(3), 573-595), for the ETFE
//! of a record that does not start and end at rest, or whose sensor
//! drifts: Y(k) = G(k) U(k) + T(k) + E(k), the transient T smooth in k.
//!
//! Around each bin k, over 2R + 1 bins (R = `HALF_WIDTH`), G and T are
//! local quadratics fitted by complex least squares. The estimate is
//! H(k) = (Y(k) - t_0) / U(k): the transient out, the bin's own noise kept,
//! with the variance sigma^2 (1 - 2 Re c_k + sum_j |c_j|^2) that t_0's
//! weights c give it. The noise level sigma^2 is the local residuals' mean
//! square, averaged over 2S + 1 bins (S = `SMOOTH_HALF_WIDTH`) less the
//! windows that hold bin k. The derivation: docs/methods.md, "The local
//! polynomial method".

use nalgebra::{Complex, SMatrix, SVector};
use rayon::prelude::*;

use super::{Frf, Method};

/// The polynomials' degree: quadratic, as the ETFE's noise estimate.
const DEGREE: usize = 2;
const P: usize = DEGREE + 1;
/// Unknowns per window: G's and T's coefficients.
const UNKNOWNS: usize = 2 * P;
/// Half width R of the local window (2R + 1 = 9 bins, 3 complex dof; the
/// noise level's average over 2S + 1 bins makes up the few dof). The
/// local quadratics' bias grows as R^3: with R = 7 the joint fit's beta1
/// and a3 came out +0.27 and -0.39 std off on average over 400 campaigns
/// not at rest, with R = 4 +0.12 and -0.14 (`tests/joint.rs`). Bins up to
/// 2R apart share a window, so their errors correlate: the fits take
/// that range from `FrfPlan::independent_lag` (2R + 1) for their
/// sandwich covariance.
pub const HALF_WIDTH: usize = 4;
const WIDTH: usize = 2 * HALF_WIDTH + 1;
/// Half width S of the noise level's average.
pub const SMOOTH_HALF_WIDTH: usize = 60;
/// Local fits per rayon task.
const PAR_MIN_FITS: usize = 256;

/// One bin's local fit.
#[derive(Debug, Clone, Copy)]
struct Local {
    /// The transient at the bin, t_0.
    transient: Complex<f64>,
    /// The residuals' mean square per complex degree of freedom: the noise
    /// level of Y there.
    sigma2: f64,
    /// 1 - 2 Re c_k + sum |c_j|^2: the estimate's noise over E(k)'s.
    share: f64,
    /// The window's first bin.
    first: usize,
}

fn local_fit(u: &[Complex<f64>], y: &[Complex<f64>], k: usize) -> Option<Local> {
    if k == 0 {
        return None;
    }
    let first = super::local_window(k, u.len(), HALF_WIDTH)?.start;
    let width = WIDTH;
    // U's columns scaled by the window's RMS |U|, so both halves of the
    // normal matrix are of a size.
    let scale = (u[first..first + width]
        .iter()
        .map(|v| v.norm_sqr())
        .sum::<f64>()
        / width as f64)
        .sqrt();
    if !(scale > 0.0 && scale.is_finite()) {
        return None;
    }
    // The local design K (2R + 1 rows: U(j) x^p / scale, then x^p) solved
    // through its QR factor rather than the normal equations, which would
    // square its condition: near a sweep's ends U's phase turns slowly and
    // the U and T columns come close to collinear.
    let mut k_mat = SMatrix::<Complex<f64>, WIDTH, UNKNOWNS>::zeros();
    for (row, j) in (first..first + width).enumerate() {
        let x = (j as f64 - k as f64) / HALF_WIDTH as f64;
        let mut power = 1.0;
        for p in 0..P {
            k_mat[(row, p)] = u[j] * (power / scale);
            k_mat[(row, P + p)] = Complex::new(power, 0.0);
            power *= x;
        }
    }
    let y_w =
        SVector::<Complex<f64>, WIDTH>::from_iterator(y[first..first + width].iter().copied());
    let qr = k_mat.qr();
    let (q, r) = (qr.q(), qr.r());
    let r_inv = r.try_inverse()?;
    // theta = R^-1 Q^H y; t_0 = sum_j c_j Y(j) with c = row P of R^-1 Q^H.
    let qh_y = q.adjoint() * y_w;
    let theta = r_inv * qh_y;
    let fitted = k_mat * theta;
    let rss: f64 = (0..WIDTH).map(|i| (y_w[i] - fitted[i]).norm_sqr()).sum();
    let (mut own, mut sum_c2) = (Complex::new(0.0, 0.0), 0.0);
    for i in 0..WIDTH {
        let c: Complex<f64> = (0..UNKNOWNS)
            .map(|m| r_inv[(P, m)] * q[(i, m)].conj())
            .sum();
        sum_c2 += c.norm_sqr();
        if first + i == k {
            own = c;
        }
    }
    let sigma2 = rss / (width - UNKNOWNS) as f64;
    sigma2.is_finite().then_some(Local {
        transient: theta[P],
        sigma2,
        share: 1.0 - 2.0 * own.re + sum_c2,
        first,
    })
}

/// `frf` (an ETFE) with its estimate and variance from the transforms `u`
/// and `y` by the local polynomial method (module docs).
pub(super) fn take_out_transient(mut frf: Frf, u: &[Complex<f64>], y: &[Complex<f64>]) -> Frf {
    let nb = frf.h.len().min(u.len()).min(y.len());
    let local: Vec<Option<Local>> = (0..nb)
        .into_par_iter()
        .with_min_len(PAR_MIN_FITS)
        .map(|k| local_fit(u, y, k))
        .collect();
    let (h, variance): (Vec<Complex<f64>>, Vec<f64>) = (0..nb)
        .into_par_iter()
        .with_min_len(PAR_MIN_FITS)
        .map(|k| {
            let (Some(own), true) = (local[k], u[k].norm_sqr() > 0.0) else {
                return (frf.h[k], f64::INFINITY);
            };
            // The noise level around k, less the windows that hold k.
            let (mut sum, mut n) = (0.0, 0usize);
            let lo = k.saturating_sub(SMOOTH_HALF_WIDTH);
            let hi = (k + SMOOTH_HALF_WIDTH + 1).min(nb);
            for l in local[lo..hi].iter().flatten() {
                if !(l.first..l.first + WIDTH).contains(&k) {
                    sum += l.sigma2;
                    n += 1;
                }
            }
            if n == 0 {
                return (frf.h[k], f64::INFINITY);
            }
            let sigma2 = sum / n as f64;
            let h = (y[k] - own.transient) / u[k];
            // Per component, half the complex variance.
            (h, 0.5 * sigma2 * own.share / u[k].norm_sqr())
        })
        .unzip();
    frf.h[..nb].copy_from_slice(&h);
    let mut v = vec![f64::INFINITY; frf.h.len()];
    v[..nb].copy_from_slice(&variance);
    frf.variance = Some(v);
    frf.method = Method::Lpm;
    frf
}
