//! The actuator's time delay, two ways:
//!
//! - [`xcorr_delay`]: the lag that maximises the cross-correlation of the
//!   command and the displacement, refined below a sample on the
//!   correlation's band-limited interpolant: the delay a pure time shift
//!   would have (Knapp & Carter 1976, IEEE Trans. ASSP 24(4):320-327, with
//!   unit weighting).
//! - [`phase_slope_delay`]: minus the slope of the FRF's unwrapped phase
//!   against angular frequency over the band, the group delay averaged
//!   over it.
//!
//! They agree for a pure delay and differ when the plant is not one, which
//! is why both are kept. Pure: signals in, numbers out. A positive delay is
//! a displacement that lags its command. Definitions: docs/tracking.md.

use nalgebra::Complex;

use super::Reference;

/// Why a delay could not be estimated: a note, not a number.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DelayNote {
    #[error("the command is constant: it has nothing to track")]
    ConstantCommand,
    #[error("the displacement is constant: the actuator did not move")]
    ConstantResponse,
    #[error("fewer than {needed} samples")]
    TooShort { needed: usize },
    #[error(
        "no clear delay: within +-{limit_s} s the command and the displacement correlate at most {rho:.2} (or at the end of that range): the delay is longer, or the displacement does not follow the command"
    )]
    Uncorrelated { rho: f64, limit_s: f64 },
    #[error("fewer than 3 FRF bins in the band with enough coherence")]
    TooFewBins,
}

/// The delay (s) by cross-correlation of `displacement` with the command
/// `reference`: the lag in +-`max_delay_s` at which
/// the normalised correlation `r(lag) / sqrt(E(lag))`, with
/// `r(lag) = sum_t x[t] u[t - lag]` and `E(lag) = sum_t u[t - lag]^2`, is
/// largest, each record less its mean and `t` over the same displacement
/// samples at every lag (those at least the search limit from either end),
/// refined between the samples next to the best integer lag.
///
/// Maximising `r / sqrt(E)` is least squares, min over (g, tau) of
/// `sum (x[t] - g u(t - tau))^2`, which a delayed copy meets exactly,
/// while `r` alone is pulled off the delay by the energy the window's ends
/// gain or lose as the command shifts (a 0.5-5 Hz multisine through a
/// 2 ms lag measured 1.5 ms).
///
/// The integer lags come from the command's transform and one transform of
/// the displacement (`integer_lags`). The refinement evaluates the same
/// sum with the command interpolated between its samples (16-point
/// Lagrange) and maximises it by golden-section search: the three-point
/// parabola, the usual refinement, is biased by a few hundredths of a
/// sample, and the correlation's own trigonometric interpolant by the
/// records' ends. Its sums are the integer lags' correlation
/// (`displacement_sums`) and the command's autocorrelation, formed once
/// for every displacement measured against it (`gram_row0`), each less
/// the few hundred products at the ends; where the lags it reads pass the
/// search limit (a delay within 8 samples of it), they are gathered
/// sample by sample (`refinement_sums`).
pub fn xcorr_delay(
    reference: &Reference<'_>,
    displacement: &[f64],
    sample_rate_hz: f64,
    max_delay_s: f64,
) -> Result<f64, DelayNote> {
    let n = reference.samples.len().min(displacement.len());
    if n < MIN_SAMPLES {
        return Err(DelayNote::TooShort {
            needed: MIN_SAMPLES,
        });
    }
    let reference = reference.first(n);
    let (u, x) = (reference.samples, &displacement[..n]);
    if super::constant(u) {
        return Err(DelayNote::ConstantCommand);
    }
    if super::constant(x) {
        return Err(DelayNote::ConstantResponse);
    }
    let (mu, mx) = (reference.mean, super::mean(x));
    let limit = ((max_delay_s * sample_rate_hz).round() as usize).clamp(1, n / 4);
    let (r, e, ex) = integer_lags(u, x, mu, mx, limit, &reference.spectrum);
    let lim = limit as i64;
    let at = |lag: i64| (lag + lim) as usize;
    let score = |lag: i64| r[at(lag)] / e[at(lag)].sqrt();
    let best = (-lim..=lim)
        .max_by(|a, b| score(*a).total_cmp(&score(*b)).then(b.abs().cmp(&a.abs())))
        .expect("a nonempty range");
    let rho = score(best) / ex.sqrt();
    if best.abs() == lim || rho.is_nan() || rho < MIN_CORRELATION {
        return Err(DelayNote::Uncorrelated {
            rho,
            limit_s: limit as f64 / sample_rate_hz,
        });
    }
    // Below a sample: the same normalised sum with the command between its
    // samples, interpolated through the 2K nearest (Lagrange). The kernel
    // reaches no further than `KERNEL_HALF` samples, inside the `limit`
    // kept clear at either end.
    let first = limit + KERNEL_HALF + 1;
    let last = n - limit - KERNEL_HALF - 1;
    let half = KERNEL_HALF as i64;
    let low = best - half;
    let (rl, gram) = if low >= -lim && low + 2 * half <= lim {
        let row0 = gram_row0(&reference, low, first..last);
        let rl = displacement_sums(
            &r[at(low)..=at(low + 2 * half)],
            u,
            x,
            (mu, mx),
            low,
            limit,
            first..last,
        );
        (rl, gram_from_row0(u, mu, low, first..last, row0))
    } else {
        refinement_sums(u, x, mu, mx, low, first..last)
    };
    let corr = |tau: f64| -> f64 {
        // tau = shift + frac: u(t - tau) = sum_j u[t - shift - j] L(j - frac),
        // j = 1 - K ..= K, the lag shift + j at offset shift + j - low.
        let shift = tau.floor().min(best as f64);
        let taps = lagrange_taps(tau - shift);
        let off = (shift as i64 + 1 - half - low) as usize;
        let r: f64 = taps.iter().enumerate().map(|(a, w)| w * rl[off + a]).sum();
        let mut e = 0.0;
        for (a, wa) in taps.iter().enumerate() {
            for (b, wb) in taps.iter().enumerate() {
                let (i, j) = (off + a.min(b), off + a.max(b));
                e += wa * wb * gram[i * LAGS + j];
            }
        }
        r / e.sqrt()
    };
    let tau = golden_max(&corr, best as f64 - 1.0, best as f64 + 1.0, 1e-5);
    Ok(tau / sample_rate_hz)
}

/// What every evaluation of the refinement needs, for the 2K + 1 integer
/// lags `low ..= low + 2K` (K = [`KERNEL_HALF`]) over the displacement's
/// samples `t` in `ts`, each record less its mean: the displacement's
/// products with the lagged command, `rl[a] = sum_t x[t] u[t - low - a]`,
/// and the lagged command's with itself, `gram[a][b] = sum_t u[t - low - a]
/// u[t - low - b]` (upper triangle, row-major). Then `r(tau) = w . rl` and
/// `E(tau) = w' gram w` for the taps `w` of `tau`: the same sums as
/// interpolating the command sample by sample.
///
/// The Gram matrix is Toeplitz but for the ends: entry (a, a + d) is
/// `sum_s c_d(s)` with `c_d(s) = u[s] u[s - d]` over `s` in `ts` moved back
/// by `low + a`, so each of the 2K + 1 differences `d` is summed once over
/// the samples of row 0, and row `a` is row `a - 1` less the product that
/// leaves the range at its end and plus the one that enters at its start.
/// That is 2(2K + 1) products a sample, where forming each entry sample by
/// sample took (2K + 1)(2K + 2)/2 = 153.
fn refinement_sums(
    u: &[f64],
    x: &[f64],
    mu: f64,
    mx: f64,
    low: i64,
    ts: std::ops::Range<usize>,
) -> (Vec<f64>, Vec<f64>) {
    // Command sample s = t - low - a, a in 0..LAGS, and t in ts.
    let at = |t: usize, a: usize| (t as i64 - low - a as i64) as usize;
    let (mut rl, mut row0) = ([0.0; LAGS], [0.0; LAGS]);
    for t in ts.clone() {
        let xt = x[t] - mx;
        let s0 = at(t, 0);
        // u[s0 - a] is window[LAGS - 1 - a]: one bounds check a sample.
        let window: &[f64; LAGS] = u[s0 + 1 - LAGS..=s0]
            .try_into()
            .expect("a window of LAGS samples");
        let u0 = window[LAGS - 1] - mu;
        for a in 0..LAGS {
            let ua = window[LAGS - 1 - a] - mu;
            rl[a] += xt * ua;
            row0[a] += u0 * ua;
        }
    }
    (rl.to_vec(), gram_from_row0(u, mu, low, ts, row0))
}

/// The refinement's Gram matrix (see `refinement_sums`) from its row 0:
/// each next row by the products that leave and enter at its ends.
fn gram_from_row0(
    u: &[f64],
    mu: f64,
    low: i64,
    ts: std::ops::Range<usize>,
    row0: [f64; LAGS],
) -> Vec<f64> {
    let at = |t: usize, a: usize| (t as i64 - low - a as i64) as usize;
    let uc = |s: usize| u[s] - mu;
    let mut gram = vec![0.0; LAGS * LAGS];
    for d in 0..LAGS {
        // Row 0 of difference d, then each next row by its ends.
        let mut sum = row0[d];
        gram[d] = sum;
        for a in 1..LAGS - d {
            let leaving = at(ts.end - 1, a - 1);
            let entering = at(ts.start, a);
            sum += uc(entering) * uc(entering - d) - uc(leaving) * uc(leaving - d);
            gram[a * LAGS + a + d] = sum;
        }
    }
    gram
}

/// Row 0 of the refinement's Gram matrix, `sum_t u[t - low] u[t - low - d]`
/// over `t` in `ts` (each less the command's mean), from the command's
/// autocorrelation over the whole record less the products outside `ts`:
/// a few hundred products at either end, where summing over `ts` took
/// LAGS a sample. `low` is at least the search limit below `ts.start`.
fn gram_row0(reference: &Reference<'_>, low: i64, ts: std::ops::Range<usize>) -> [f64; LAGS] {
    let (u, mu) = (reference.samples, reference.mean);
    let (head, tail) = (
        (ts.start as i64 - low) as usize,
        (ts.end as i64 - low) as usize,
    );
    let mut row0 = *reference.autocorrelation();
    for (d, sum) in row0.iter_mut().enumerate() {
        // The record's s in d..n, less s in d..head and in tail..n.
        let outside: f64 = (d..head)
            .chain(tail..u.len())
            .map(|s| (u[s] - mu) * (u[s - d] - mu))
            .sum();
        *sum -= outside;
    }
    row0
}

/// The refinement's `rl[a] = sum_t x[t] u[t - low - a]` over `t` in `ts`
/// (each less its mean) from the integer lags' correlation `r` over `t` in
/// [limit, n - limit) at the lags `low ..= low + 2K`, less the products of
/// the samples between those ranges' ends.
fn displacement_sums(
    r: &[f64],
    u: &[f64],
    x: &[f64],
    (mu, mx): (f64, f64),
    low: i64,
    limit: usize,
    ts: std::ops::Range<usize>,
) -> Vec<f64> {
    let n = u.len();
    r.iter()
        .enumerate()
        .map(|(a, r)| {
            let outside: f64 = (limit..ts.start)
                .chain(ts.end..n - limit)
                .map(|t| (x[t] - mx) * (u[(t as i64 - low - a as i64) as usize] - mu))
                .sum();
            r - outside
        })
        .collect()
}

/// For every integer lag in +-`limit`, `r(lag) = sum_t x[t] u[t - lag]` and
/// `E(lag) = sum_t u[t - lag]^2` over `t` in [limit, n - limit), each
/// record less its mean (`mu`, `mx`), and `sum_t x[t]^2` over the same
/// `t`; `u_spectrum` is the one-sided DFT of `u - mu`.
///
/// The correlation is one transform of the displacement, zero outside
/// [limit, n - limit), against the command's: for lags within +-limit the
/// circular correlation of n points never wraps (t - lag stays in [0, n)),
/// so it is the sum itself, `r(lag) = (1/n) sum_k X_k conj(U_k)
/// e^{2 pi i k lag / n}`.
fn integer_lags(
    u: &[f64],
    x: &[f64],
    mu: f64,
    mx: f64,
    limit: usize,
    u_spectrum: &[Complex<f64>],
) -> (Vec<f64>, Vec<f64>, f64) {
    let n = u.len();
    let lags = 2 * limit + 1;
    let (start, end) = (limit, n - limit);
    let forward = crate::fft::real_forward(n);
    let inverse = crate::fft::real_inverse(n);
    let mut xb = vec![0.0; n];
    let mut ex = 0.0;
    for t in start..end {
        let v = x[t] - mx;
        xb[t] = v;
        ex += v * v;
    }
    let mut xs = forward.make_output_vec();
    forward
        .process(&mut xb, &mut xs)
        .expect("lengths come from the plan");
    for (a, c) in xs.iter_mut().zip(u_spectrum) {
        *a *= c.conj();
    }
    // The bins whose imaginary parts a real signal's transform cannot
    // have: DC, and Nyquist for an even length.
    xs[0].im = 0.0;
    if n.is_multiple_of(2) {
        let last = xs.len() - 1;
        xs[last].im = 0.0;
    }
    let mut c = xb;
    inverse
        .process(&mut xs, &mut c)
        .expect("lengths come from the plan");
    let r = (0..lags)
        .map(|i| {
            let lag = i as i64 - limit as i64;
            c[lag.rem_euclid(n as i64) as usize] / n as f64
        })
        .collect();
    // E(lag) = sum over s in [start - lag, end - lag) of (u[s] - mu)^2: the
    // sum over [start, end) corrected at either end, where the samples a lag
    // adds or drops lie within `limit` of `start` and of `end` (prefix sums
    // over those two stretches).
    let sq = |s: usize| (u[s] - mu) * (u[s] - mu);
    let prefix = |from: usize, len: usize| -> Vec<f64> {
        let mut p = Vec::with_capacity(len + 1);
        let mut acc = 0.0;
        p.push(0.0);
        for s in from..from + len {
            acc += sq(s);
            p.push(acc);
        }
        p
    };
    let head = prefix(start - limit, 2 * limit);
    let tail = prefix(end - limit, 2 * limit);
    let over = |p: &[f64], from: usize, a: usize, b: usize| p[b - from] - p[a - from];
    let base: f64 = (start..end).map(sq).sum();
    let e = (0..lags)
        .map(|i| {
            let lag = i as i64 - limit as i64;
            let k = lag.unsigned_abs() as usize;
            if lag >= 0 {
                base + over(&head, start - limit, start - k, start)
                    - over(&tail, end - limit, end - k, end)
            } else {
                base - over(&head, start - limit, start, start + k)
                    + over(&tail, end - limit, end, end + k)
            }
        })
        .collect();
    (r, e, ex)
}

/// The fewest samples the cross-correlation takes: the lags searched and
/// the interpolation kernel must leave samples to sum over.
pub const MIN_SAMPLES: usize = 64;

/// The least correlation coefficient a delay is reported at: below it the
/// displacement does not follow the command closely enough for its peak to
/// be its delay.
pub const MIN_CORRELATION: f64 = 0.5;

/// The samples each side of a point that interpolate the command there.
const KERNEL_HALF: usize = 8;

/// The integer lags the refinement reads: `KERNEL_HALF` each side of the
/// best one, and it.
pub(super) const LAGS: usize = 2 * KERNEL_HALF + 1;

/// The weights of Lagrange interpolation through the 2K samples at offsets
/// j = 1 - K ..= K (K = [`KERNEL_HALF`]) of the point `frac` in [0, 1)
/// before the sample at j = 0: `w_j = prod_{m != j} (m - frac) / (m - j)`,
/// with `u(base - frac) = sum_j w_j u[base - j]`. Exact for polynomials up
/// to degree 2K - 1, so its gain at low frequency is 1 and its delay is
/// `frac` to within its error, about `(w/2)^(2K) / (2K)!`-small for
/// content below a quarter of the sampling rate. (A Lanczos kernel of the
/// same width, whose weights do not sum to 1, put a pure delay of 2.37
/// samples at 2.366.)
fn lagrange_taps(frac: f64) -> Vec<f64> {
    let half = KERNEL_HALF as i64;
    (1 - half..=half)
        .map(|j| {
            (1 - half..=half)
                .filter(|&m| m != j)
                .map(|m| (m as f64 - frac) / (m - j) as f64)
                .product()
        })
        .collect()
}

/// The argument of the largest value of `f` on [a, b] by golden-section
/// search, to within `tol` (`f` unimodal there: the correlation next to its
/// highest sample).
fn golden_max(f: &impl Fn(f64) -> f64, mut a: f64, mut b: f64, tol: f64) -> f64 {
    let g = (5.0_f64.sqrt() - 1.0) / 2.0;
    let mut c = b - g * (b - a);
    let mut d = a + g * (b - a);
    let (mut fc, mut fd) = (f(c), f(d));
    while b - a > tol {
        if fc >= fd {
            b = d;
            d = c;
            fd = fc;
            c = b - g * (b - a);
            fc = f(c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + g * (b - a);
            fd = f(d);
        }
    }
    (a + b) / 2.0
}

/// The delay (s) from the slope of the FRF's phase: the least-squares line
/// through the unwrapped phase of `h` against `2 pi f` over the bins in
/// `keep` (the band, where the coherence is enough), its slope negated.
/// For a pure delay the phase is `-2 pi f tau` and this is `tau` exactly;
/// for a plant with dynamics it is the group delay averaged over the band.
pub fn phase_slope_delay(
    freq_hz: &[f64],
    h: &[Complex<f64>],
    keep: &[bool],
) -> Result<f64, DelayNote> {
    let bins: Vec<usize> = (0..freq_hz.len())
        .filter(|&i| keep.get(i).copied().unwrap_or(false) && h[i].norm() > 0.0)
        .collect();
    if bins.len() < 3 {
        return Err(DelayNote::TooFewBins);
    }
    // Unwrapped along the kept bins, in frequency order: a gap in them
    // (bins of low coherence) is bridged as if the phase moved less than
    // half a turn across it, as it does for delays below half the gap's
    // period.
    let mut phase = Vec::with_capacity(bins.len());
    let mut prev: Option<f64> = None;
    for &i in &bins {
        let p = h[i].arg();
        let p = match prev {
            None => p,
            Some(q) => {
                let two_pi = 2.0 * std::f64::consts::PI;
                p + two_pi * ((q - p) / two_pi).round()
            }
        };
        phase.push(p);
        prev = Some(p);
    }
    let w: Vec<f64> = bins
        .iter()
        .map(|&i| 2.0 * std::f64::consts::PI * freq_hz[i])
        .collect();
    let k = w.len() as f64;
    let (mw, mp) = (w.iter().sum::<f64>() / k, phase.iter().sum::<f64>() / k);
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for (a, p) in w.iter().zip(&phase) {
        sxy += (a - mw) * (p - mp);
        sxx += (a - mw) * (a - mw);
    }
    if sxx == 0.0 {
        return Err(DelayNote::TooFewBins);
    }
    Ok(-sxy / sxx)
}

#[cfg(test)]
mod tests {
    use super::{
        KERNEL_HALF, LAGS, displacement_sums, gram_from_row0, gram_row0, integer_lags,
        refinement_sums,
    };
    use crate::tracking::tests::record;
    use crate::tracking::{Reference, centred_spectrum};

    /// The sums [`integer_lags`] defines, term by term.
    fn naive(u: &[f64], x: &[f64], mu: f64, mx: f64, limit: usize) -> (Vec<f64>, Vec<f64>, f64) {
        let (start, end) = (limit, u.len() - limit);
        let mut r = Vec::new();
        let mut e = Vec::new();
        for lag in -(limit as i64)..=limit as i64 {
            let at = |t: usize| (t as i64 - lag) as usize;
            r.push((start..end).map(|t| (x[t] - mx) * (u[at(t)] - mu)).sum());
            e.push((start..end).map(|t| (u[at(t)] - mu).powi(2)).sum());
        }
        let ex = (start..end).map(|t| (x[t] - mx).powi(2)).sum();
        (r, e, ex)
    }

    /// The refinement's sums against forming each entry sample by sample,
    /// at a lag far from zero either way and at zero.
    #[test]
    fn the_refinement_sums_are_the_sums_they_define() {
        let n = 5_000;
        let u = record(n, 3, 0.4);
        let x = record(n, 11, -0.7);
        let (mu, mx) = (0.35, -0.65);
        for low in [-40_i64, -8, 0, 25] {
            let ts = 60..n - 60;
            let (rl, gram) = refinement_sums(&u, &x, mu, mx, low, ts.clone());
            let lagged = |t: usize, a: usize| u[(t as i64 - low - a as i64) as usize] - mu;
            for a in 0..LAGS {
                let r: f64 = ts.clone().map(|t| (x[t] - mx) * lagged(t, a)).sum();
                assert!(
                    (rl[a] - r).abs() < 1e-9,
                    "low {low}, rl[{a}]: {} vs {r}",
                    rl[a]
                );
                for b in a..LAGS {
                    let g: f64 = ts.clone().map(|t| lagged(t, a) * lagged(t, b)).sum();
                    let got = gram[a * LAGS + b];
                    assert!(
                        (got - g).abs() < 1e-9,
                        "low {low}, gram[{a}][{b}]: {got} vs {g}"
                    );
                }
            }
        }
    }

    /// The refinement's sums from the integer lags' correlation and the
    /// command's autocorrelation, as `xcorr_delay` forms them, against the
    /// same sums gathered sample by sample (`refinement_sums`, itself
    /// checked term by term above), over the lags the shortcut serves.
    #[test]
    fn the_refinement_sums_from_the_correlations_are_the_sums_gathered() {
        for n in [2_000, 4_099, 30_000] {
            let u = record(n, 5 + n as u64, 0.6);
            let x = record(n, 9 + n as u64, -0.2);
            let reference = Reference::new(&u);
            let (mu, mx) = (reference.mean, -0.15);
            let limit = 60;
            let (r, _, _) = integer_lags(&u, &x, mu, mx, limit, &reference.spectrum);
            let ts = limit + KERNEL_HALF + 1..n - limit - KERNEL_HALF - 1;
            let lim = limit as i64;
            for low in [-lim, -31, -8, 0, 17, lim - 2 * KERNEL_HALF as i64] {
                let (want_rl, want_gram) = refinement_sums(&u, &x, mu, mx, low, ts.clone());
                let at = (low + lim) as usize;
                let rl =
                    displacement_sums(&r[at..at + LAGS], &u, &x, (mu, mx), low, limit, ts.clone());
                let row0 = gram_row0(&reference, low, ts.clone());
                let gram = gram_from_row0(&u, mu, low, ts.clone(), row0);
                let tol = 1e-11 * n as f64;
                for a in 0..LAGS {
                    assert!(
                        (rl[a] - want_rl[a]).abs() < tol,
                        "n {n}, low {low}, rl[{a}]: {} vs {}",
                        rl[a],
                        want_rl[a]
                    );
                    for b in a..LAGS {
                        let (got, want) = (gram[a * LAGS + b], want_gram[a * LAGS + b]);
                        assert!(
                            (got - want).abs() < tol,
                            "n {n}, low {low}, gram[{a}][{b}]: {got} vs {want}"
                        );
                    }
                }
            }
        }
    }

    /// The transforms' correlation against the sums themselves, over even,
    /// odd and prime lengths, and lags from none to many.
    #[test]
    fn the_transforms_correlation_is_the_sum_it_defines() {
        for n in [200, 4_099, 65_536, 65_573, 132_072] {
            for limit in [0, 1, 7, 60] {
                let u = record(n, 1 + n as u64, 0.3);
                let x = record(n, 7 + limit as u64, -1.2);
                let (mu, mx) = (0.25, -1.1);
                let (r, e, ex) = integer_lags(&u, &x, mu, mx, limit, &centred_spectrum(&u, mu));
                let (rn, en, exn) = naive(&u, &x, mu, mx, limit);
                // Each sum's terms are O(1) and there are about n of them:
                // the FFT's rounding is some 1e-12 of n.
                let tol = 1e-9 * n as f64;
                assert_eq!(r.len(), 2 * limit + 1);
                for (k, (a, b)) in r.iter().zip(&rn).enumerate() {
                    assert!(
                        (a - b).abs() < tol,
                        "n {n}, limit {limit}, r[{k}]: {a} vs {b}"
                    );
                }
                for (k, (a, b)) in e.iter().zip(&en).enumerate() {
                    assert!(
                        (a - b).abs() < tol,
                        "n {n}, limit {limit}, E[{k}]: {a} vs {b}"
                    );
                }
                assert!(
                    (ex - exn).abs() < tol,
                    "n {n}, limit {limit}: {ex} vs {exn}"
                );
            }
        }
    }
}
