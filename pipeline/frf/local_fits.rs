//! The ETFE's noise level by local polynomials (see [`super::h_variance_at`]),
//! and the memo of their normal matrices.
//!
//! A bin's local fit is weighted least squares over its window, weighted by
//! the command's Suu. Its normal matrix, and so its inverse, depend on Suu
//! and the window alone, not on the estimate being fitted: an FRF's noise
//! level is read twice in a fit (on the estimate and on what the model
//! leaves of it) and the Monte Carlo's thousand readings of one command
//! share one Suu. [`LocalFits`] keeps the inverses of the first reading for
//! the others: the same numbers from the same operations, so the same bits.

use std::sync::{Arc, OnceLock};

use nalgebra::{Complex, SMatrix};
use rayon::prelude::*;

use super::{ETFE_LOCAL_DEGREE, ETFE_LOCAL_HALF_WIDTH, Frf, PAR_MIN_LOCAL_FITS, local_window};

/// Coefficients of the local polynomial.
const P: usize = ETFE_LOCAL_DEGREE + 1;
/// Bins of a local window.
const WIDTH: usize = 2 * ETFE_LOCAL_HALF_WIDTH + 1;

/// The inverted normal matrices of an ETFE's local fits, made on first use
/// and shared by the FRF's clones and heads (and, through
/// `EtfeSynthesis`, by every reading of one command). Each is checked
/// against the FRF it serves before use: the same window, the same Suu over
/// it, and every excited bin's estimate finite; a fit that fails the check
/// is made afresh. It is not part of the FRF's value: two FRFs compare
/// equal whatever their memos hold.
#[derive(Clone, Default)]
pub struct LocalFits(Arc<OnceLock<Table>>);

impl PartialEq for LocalFits {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl std::fmt::Debug for LocalFits {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("LocalFits")
    }
}

/// The inverses for the bins `start..start + fits.len()`.
struct Table {
    start: usize,
    fits: Vec<Option<Inverse>>,
}

/// One bin's inverted normal matrix, with what it was made from.
struct Inverse {
    /// The window's first bin.
    first: usize,
    /// Suu over the window.
    suu: [f64; WIDTH],
    inv: SMatrix<f64, P, P>,
}

/// A window's usable bins (excited, finite): the offset x = (j - k) / R,
/// scaled so that the normal matrix is well conditioned, the weight and
/// the estimate.
struct Gathered {
    xs: [f64; WIDTH],
    ws: [f64; WIDTH],
    hs: [Complex<f64>; WIDTH],
    used: usize,
    /// Whether every excited bin's estimate was finite: then the usable
    /// bins are Suu's alone.
    all_finite: bool,
}

impl Gathered {
    fn of(
        suu: &[f64],
        h: Option<&[Complex<f64>]>,
        window: std::ops::Range<usize>,
        k: usize,
    ) -> Self {
        let mut g = Gathered {
            xs: [0.0; WIDTH],
            ws: [0.0; WIDTH],
            hs: [Complex::new(0.0, 0.0); WIDTH],
            used: 0,
            all_finite: true,
        };
        let r_half = ETFE_LOCAL_HALF_WIDTH as f64;
        let finite = |h: &Complex<f64>| h.re.is_finite() && h.im.is_finite();
        // Every bin usable (as in the band): copied straight, in the order
        // and with the offsets the general walk below would give them.
        if window.len() == WIDTH
            && suu[window.clone()].iter().all(|&w| w > 0.0)
            && h.is_none_or(|h| h.iter().all(finite))
        {
            for (i, j) in window.enumerate() {
                g.xs[i] = (j as f64 - k as f64) / r_half;
                g.ws[i] = suu[j];
                g.hs[i] = h.map_or(Complex::new(0.0, 0.0), |h| h[i]);
            }
            g.used = WIDTH;
            return g;
        }
        for (i, j) in window.enumerate() {
            let w = suu[j];
            // A NaN Suu excites nothing either.
            if w.is_nan() || w <= 0.0 {
                continue;
            }
            let hj = h.map_or(Complex::new(0.0, 0.0), |h| h[i]);
            if !finite(&hj) {
                g.all_finite = false;
                continue;
            }
            g.xs[g.used] = (j as f64 - k as f64) / r_half;
            g.ws[g.used] = w;
            g.hs[g.used] = hj;
            g.used += 1;
        }
        g
    }

    /// The inverse of the weighted normal matrix; None where it is
    /// singular or the window has too few usable bins.
    fn normal_inverse(&self) -> Option<SMatrix<f64, P, P>> {
        if self.used <= P {
            return None;
        }
        let mut a = SMatrix::<f64, P, P>::zeros();
        for (&x, &w) in self.xs.iter().zip(&self.ws).take(self.used) {
            let powers = powers(x);
            for p in 0..P {
                for q in 0..P {
                    a[(p, q)] += w * powers[p] * powers[q];
                }
            }
        }
        a.try_inverse()
    }

    /// The weighted residual sum of squares per degree of freedom of the
    /// fit whose normal matrix's inverse is `inv`.
    fn density(&self, inv: &SMatrix<f64, P, P>) -> f64 {
        let mut b = [Complex::new(0.0, 0.0); P];
        for ((&x, &w), &h) in self.xs.iter().zip(&self.ws).zip(&self.hs).take(self.used) {
            let powers = powers(x);
            for p in 0..P {
                b[p] += h * (w * powers[p]);
            }
        }
        // On the stack: a heap vector per bin was a tenth of the cost.
        let c: [Complex<f64>; P] =
            std::array::from_fn(|p| (0..P).map(|q| b[q] * inv[(p, q)]).sum());
        let mut rss = 0.0;
        for ((&x, &w), &h) in self.xs.iter().zip(&self.ws).zip(&self.hs).take(self.used) {
            let fitted = c
                .iter()
                .rev()
                .fold(Complex::new(0.0, 0.0), |acc, cp| acc * x + cp);
            rss += w * (h - fitted).norm_sqr();
        }
        rss / (self.used - P) as f64
    }
}

fn powers(x: f64) -> [f64; P] {
    let mut powers = [1.0; P];
    for p in 1..P {
        powers[p] = powers[p - 1] * x;
    }
    powers
}

impl Table {
    /// The inverses of the bins `span` of a spectrum of `nb` bins with
    /// input density `suu`, the fits side by side (the same bits on any
    /// thread count).
    fn of(suu: &[f64], nb: usize, span: std::ops::Range<usize>) -> Self {
        let fits = span
            .clone()
            .into_par_iter()
            .with_min_len(PAR_MIN_LOCAL_FITS)
            .map(|k| {
                let window = local_window(k, nb, ETFE_LOCAL_HALF_WIDTH).filter(|_| k > 0)?;
                let g = Gathered::of(suu, None, window.clone(), k);
                Some(Inverse {
                    first: window.start,
                    suu: suu[window].try_into().expect("a window is WIDTH bins"),
                    inv: g.normal_inverse()?,
                })
            })
            .collect();
        Table {
            start: span.start,
            fits,
        }
    }

    /// Bin `k`'s inverse, where it was made from `window` and `suu` there.
    fn at(
        &self,
        k: usize,
        window: &std::ops::Range<usize>,
        suu: &[f64],
    ) -> Option<&SMatrix<f64, P, P>> {
        let fit = self.fits.get(k.checked_sub(self.start)?)?.as_ref()?;
        (fit.first == window.start && fit.suu[..] == suu[window.clone()]).then_some(&fit.inv)
    }
}

/// The local noise densities of `frf` over the bins `span`, the fits side
/// by side (the same bits on any thread count); the normal matrices from
/// the FRF's memo where it holds them.
pub(super) fn etfe_local_noise_densities(frf: &Frf, span: std::ops::Range<usize>) -> Vec<f64> {
    let nb = frf.h.len();
    let table = frf
        .local_fits
        .0
        .get_or_init(|| Table::of(&frf.suu, nb, span.clone()));
    span.into_par_iter()
        .with_min_len(PAR_MIN_LOCAL_FITS)
        .map(|k| etfe_local_noise_density(frf, k, Some(table)))
        .collect()
}

/// The noise density at bin `k` by the local polynomial method (see
/// [`super::h_variance_at`]); infinite where the window has too few excited
/// bins. The window is shifted, not shortened, at the ends of the
/// spectrum, and DC (which detrending empties) is left out. The normal
/// matrix's inverse comes from `table` where it holds this window's.
fn etfe_local_noise_density(frf: &Frf, k: usize, table: Option<&Table>) -> f64 {
    let nb = frf.h.len();
    if frf.suu[k] <= 0.0 || k == 0 {
        return f64::INFINITY;
    }
    let Some(window) = local_window(k, nb, ETFE_LOCAL_HALF_WIDTH) else {
        return f64::INFINITY;
    };
    let g = Gathered::of(&frf.suu, Some(&frf.h[window.clone()]), window.clone(), k);
    if g.used <= P {
        return f64::INFINITY;
    }
    let memo = table
        .filter(|_| g.all_finite)
        .and_then(|t| t.at(k, &window, &frf.suu));
    let inv = match memo {
        Some(inv) => *inv,
        None => match g.normal_inverse() {
            Some(inv) => inv,
            None => return f64::INFINITY,
        },
    };
    g.density(&inv)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The memo's densities are the fresh fits' to the bit, on an FRF
    /// whose estimate differs from the one the memo was made on (a second
    /// reading of the same command), on one with a non-finite bin and on a
    /// head whose top windows shift.
    #[test]
    fn the_memo_gives_the_fresh_fits_bits() {
        let nb = 400;
        // Suu with zeros (unexcited bins) and a smooth rise; two estimates.
        let suu: Vec<f64> = (0..nb)
            .map(|k| {
                if k % 37 == 5 {
                    0.0
                } else {
                    1.0 + (k as f64 * 0.013).sin().powi(2)
                }
            })
            .collect();
        let h_of = |seed: f64| -> Vec<Complex<f64>> {
            (0..nb)
                .map(|k| {
                    let x = k as f64;
                    Complex::new(
                        (x * 0.05 + seed).cos() + (x * 1.7 * seed).sin() * 1e-2,
                        (x * 0.03).sin(),
                    )
                })
                .collect()
        };
        let frf = |h: Vec<Complex<f64>>| Frf {
            freq_hz: (0..nb).map(|k| k as f64 * 0.1).collect(),
            coherence: vec![1.0; nb],
            suu: suu.clone(),
            syy: vec![1.0; nb],
            suy: vec![Complex::new(0.0, 0.0); nb],
            h,
            n_averages: 1,
            effective_averages: 1.0,
            method: super::super::Method::Etfe,
            resolution_hz: 0.1,
            variance: None,
            input_dft: None,
            local_fits: LocalFits::default(),
        };
        let first = frf(h_of(0.3));
        let _ = etfe_local_noise_densities(&first, 0..nb);
        let mut second = frf(h_of(0.7));
        second.local_fits = first.local_fits.clone();
        second.h[200] = Complex::new(f64::NAN, 0.0);
        // Every bin's density through the memo, and each made afresh.
        let memo_is_fresh = |f: &Frf| {
            let bits = |d: Vec<f64>| d.into_iter().map(f64::to_bits).collect::<Vec<_>>();
            let fresh = (0..f.h.len())
                .map(|k| etfe_local_noise_density(f, k, None))
                .collect();
            assert_eq!(
                bits(etfe_local_noise_densities(f, 0..f.h.len())),
                bits(fresh)
            );
        };
        memo_is_fresh(&second);
        // The bins next to the non-finite one and the head's top are
        // made afresh; the rest come from the memo.
        let table = first.local_fits.0.get().expect("made on first use");
        assert!(table.at(100, &(93..108), &second.suu).is_some());
        let head = second.head(30.0, 0);
        assert!(head.h.len() < nb);
        memo_is_fresh(&head);
        let top = head.h.len() - 1;
        let window = local_window(top, head.h.len(), ETFE_LOCAL_HALF_WIDTH).unwrap();
        assert!(
            table.at(top, &window, &head.suu).is_none(),
            "the head's last window shifts"
        );
        // A changed Suu is not served from the memo.
        let mut third = frf(h_of(0.3));
        third.local_fits = first.local_fits.clone();
        third.suu[100] *= 2.0;
        assert!(table.at(100, &(93..108), &third.suu).is_none());
        memo_is_fresh(&third);
    }
}
