//! A command whose spectrum is sparse lines (a periodic multisine or square
//! wave whose periods the record holds whole): the FRF at its excited lines
//! and its noise level from the lines it does not excite (`sparse_lines`,
//! `at_lines`).
//!
//! Between the lines U is zero, so there Y(k) = T(k) + V(k): the record's
//! transient, smooth in k, and the noise. At an excited line the transient
//! is interpolated by a local polynomial through the non-excited lines
//! around it, whose scatter about it is the noise level:
//! G(k) = (Y(k) - T^(k)) / U(k), with the variance
//! sigma_V^2(k) (1 + q(k)) / |U(k)|^2 (Pintelon, Barbe, Vandersteen & Van
//! Moer 2011). A record of whole steady periods has no transient: the
//! lines between hold the periods' spread alone, and G(k) = Y(k) / U(k)
//! with sigma_V^2(k) / |U(k)|^2. Why not the ETFE's local polynomials:
//! docs/methods.md, "Periodic commands: the excited lines".

use nalgebra::{Complex, Matrix3, Vector3};

use super::{ETFE_NOISE_SMOOTH_HALF_WIDTH, Frf, UNEXCITED_SHARE};

/// Non-excited lines taken on each side of an excited one, and how far
/// (bins) they are looked for: 2 x 6 bins leave 9 complex degrees of
/// freedom after the quadratic, pooled over the lines nearby (below).
const PER_SIDE: usize = 6;
/// The fewest non-excited lines a line's polynomial needs: two more than
/// its coefficients.
const MIN_NEIGHBOURS: usize = 5;
/// For whole steady periods, which fit nothing: 2 x 24 non-excited lines,
/// 48 complex degrees of freedom a line.
const STEADY_PER_SIDE: usize = 24;

/// Whether `frf`'s command is sparse lines over `band_hz`: at least half of
/// the band's bins hold no excitation (below [`UNEXCITED_SHARE`] of the
/// band's mean input power, as [`super::band_mask`] reads it), which a
/// sweep, noise or a multisine between rests (whose lines leak into every
/// bin) never leave. Only for a single record with the command's DFT kept.
pub fn sparse_lines(frf: &Frf, band_hz: (f64, f64)) -> bool {
    if frf.n_averages != 1 || frf.input_dft.is_none() {
        return false;
    }
    let in_band: Vec<f64> = frf
        .freq_hz
        .iter()
        .zip(&frf.suu)
        .filter(|(f, _)| **f >= band_hz.0 && **f <= band_hz.1)
        .map(|(_, p)| *p)
        .collect();
    if in_band.is_empty() {
        return false;
    }
    let floor = UNEXCITED_SHARE * in_band.iter().sum::<f64>() / in_band.len() as f64;
    let excited = in_band.iter().filter(|p| **p >= floor).count();
    2 * excited <= in_band.len()
}

/// The excited lines of `mask` (the fit's bins) with the transient
/// interpolated from the non-excited lines taken out of `frf` there, and
/// E|dH|^2 at each: the bins the fit is given and their variances. A line
/// with too few non-excited lines around it is left out. None where the
/// command's DFT is not kept. With `steady` (the record whole steady
/// periods, `frf::periodic`), no transient is fitted: the non-excited
/// lines' mean power is the noise density.
pub fn at_lines(
    frf: &mut Frf,
    mask: &[bool],
    band_hz: (f64, f64),
    steady: bool,
) -> Option<(Vec<usize>, Vec<f64>)> {
    let per_side = if steady { STEADY_PER_SIDE } else { PER_SIDE };
    let u = frf.input_dft.clone()?;
    let nb = frf.h.len().min(u.len()).min(mask.len());
    let (sum, n) = frf
        .freq_hz
        .iter()
        .zip(&frf.suu)
        .filter(|(f, _)| **f >= band_hz.0 && **f <= band_hz.1)
        .fold((0.0, 0usize), |(s, n), (_, p)| (s + p, n + 1));
    let floor = UNEXCITED_SHARE * sum / n.max(1) as f64;
    let finite = |h: Complex<f64>| h.re.is_finite() && h.im.is_finite();
    // A non-excited line whose output is known: Y = H U where U is not
    // exactly zero.
    let quiet = |j: usize| j > 0 && frf.suu[j] < floor && u[j].norm_sqr() > 0.0 && finite(frf.h[j]);
    // Per line: (bin, T^, noise density of Y, q).
    let mut found: Vec<(usize, Complex<f64>, f64, f64)> = Vec::new();
    for k in (1..nb).filter(|&k| mask[k] && frf.suu[k] >= floor) {
        let mut near = Vec::with_capacity(2 * per_side);
        let mut below = 0;
        let mut above = 0;
        for d in 1..=4 * per_side {
            if below < per_side && k > d && quiet(k - d) {
                near.push(k - d);
                below += 1;
            }
            if above < per_side && k + d < nb && quiet(k + d) {
                near.push(k + d);
                above += 1;
            }
        }
        if near.len() < MIN_NEIGHBOURS {
            continue;
        }
        if steady {
            let power: f64 = near.iter().map(|&j| (frf.h[j] * u[j]).norm_sqr()).sum();
            found.push((k, Complex::new(0.0, 0.0), power / near.len() as f64, 0.0));
            continue;
        }
        let scale = near.iter().map(|&j| j.abs_diff(k)).max().unwrap_or(1) as f64;
        let powers = |j: usize| {
            let x = (j as f64 - k as f64) / scale;
            Vector3::new(1.0, x, x * x)
        };
        let mut a = Matrix3::<f64>::zeros();
        let mut b = [Complex::new(0.0, 0.0); 3];
        for &j in &near {
            let p = powers(j);
            a += p * p.transpose();
            let y = frf.h[j] * u[j];
            for (r, br) in b.iter_mut().enumerate() {
                *br += y * p[r];
            }
        }
        let Some(inv) = a.try_inverse() else {
            continue;
        };
        let c: [Complex<f64>; 3] =
            std::array::from_fn(|r| (0..3).map(|s| b[s] * inv[(r, s)]).sum());
        let rss: f64 = near
            .iter()
            .map(|&j| {
                let p = powers(j);
                let fitted = c[0] + c[1] * p[1] + c[2] * p[2];
                (frf.h[j] * u[j] - fitted).norm_sqr()
            })
            .sum();
        found.push((k, c[0], rss / (near.len() - 3) as f64, inv[(0, 0)]));
    }
    // The noise density pooled over the lines within S bins, as the ETFE's
    // is ([`ETFE_NOISE_SMOOTH_HALF_WIDTH`]): weights drawn from one line's 9
    // degrees of freedom would make the fit's stds optimistic.
    let mut bins = Vec::with_capacity(found.len());
    let mut variance = Vec::with_capacity(found.len());
    for &(k, t, _, q) in &found {
        let (s, m) = found
            .iter()
            .filter(|(j, ..)| j.abs_diff(k) <= ETFE_NOISE_SMOOTH_HALF_WIDTH)
            .fold((0.0, 0usize), |(s, m), (_, _, d, _)| (s + d, m + 1));
        let density = s / m as f64;
        let uk = u[k];
        frf.h[k] = (frf.h[k] * uk - t) / uk;
        // Suy = s conj(U) Y and Suu = s |U|^2, as in `Frf::without_transient`.
        frf.suy[k] -= t / uk * frf.suu[k];
        frf.syy[k] = frf.suy[k].norm_sqr() / frf.suu[k];
        bins.push(k);
        variance.push(density * (1.0 + q) / uk.norm_sqr());
    }
    Some((bins, variance))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frf::{FrfRequest, band_mask, estimate_one};
    use crate::simulate::Draws;

    /// One period of a 58-tone multisine (every 18th bin of a 30 s record
    /// at 1 kHz, 0.1 to 34.3 Hz) through a 5 Hz first-order lag that
    /// starts from rest, with white noise: the lines' FRF comes back within
    /// the stated variance of the lag's own response (the mean of |dH|^2 /
    /// var near 1, no line beyond 5 of its stds), where the raw ETFE at the
    /// lines, its transient left in, is off by many times that.
    #[test]
    fn a_multisine_from_rest_gives_its_lines_within_their_variance() {
        let (fs, n) = (1000.0, 30_000usize);
        let lines: Vec<usize> = (3..=1030).step_by(18).collect();
        let mut rng = Draws::new(60, "sparse lines");
        let phase: Vec<f64> = lines
            .iter()
            .map(|_| 2.0 * std::f64::consts::PI * rng.uniform())
            .collect();
        let u: Vec<f64> = (0..n)
            .map(|t| {
                lines
                    .iter()
                    .zip(&phase)
                    .map(|(&k, p)| {
                        (2.0 * std::f64::consts::PI * (k * t) as f64 / n as f64 + p).cos()
                    })
                    .sum::<f64>()
                    * 1e-4
            })
            .collect();
        let a = (-2.0 * std::f64::consts::PI * 5.0 / fs).exp();
        let mut state = 0.0;
        let y: Vec<f64> = u
            .iter()
            .map(|&v| {
                state = a * state + (1.0 - a) * v;
                state + 2e-6 * rng.normal()
            })
            .collect();
        let truth = |k: usize| {
            let w = 2.0 * std::f64::consts::PI * k as f64 / n as f64;
            Complex::new(1.0 - a, 0.0) / (Complex::new(1.0, 0.0) - Complex::from_polar(a, -w))
        };
        let band = (0.5, 30.0);
        let plan = FrfRequest::default()
            .resolve(&u, &y, fs, band)
            .unwrap()
            .plan;
        let mut h = estimate_one(&u, &y, fs, &plan).unwrap();
        assert!(sparse_lines(&h, band));
        let raw = h.h.clone();
        let mask = band_mask(&h, band, 0.0);
        let (bins, var) = at_lines(&mut h, &mask, band, false).unwrap();
        assert!(bins.len() > 40, "{}", bins.len());
        let z2: Vec<f64> = bins
            .iter()
            .zip(&var)
            .map(|(&k, v)| (h.h[k] - truth(k)).norm_sqr() / v)
            .collect();
        let mean = z2.iter().sum::<f64>() / z2.len() as f64;
        assert!((0.6..1.6).contains(&mean), "{mean}");
        assert!(z2.iter().all(|z| *z < 25.0), "{z2:?}");
        let raw_mean = bins
            .iter()
            .zip(&var)
            .map(|(&k, v)| (raw[k] - truth(k)).norm_sqr() / v)
            .sum::<f64>()
            / bins.len() as f64;
        assert!(raw_mean > 10.0 * mean, "{raw_mean} against {mean}");
    }
}
