//! Linear starting values in scaled frequency: Levy's least squares,
//! Sanathanan-Koerner re-weighting, and a grid over a fitted delay; plus the
//! rank-revealing least-squares solve they share with the covariance.
//!
//! References: E. C. Levy, "Complex-curve fitting", IRE Trans. Automatic
//! Control 4 (1959) 37-43; C. K. Sanathanan and J. Koerner, "Transfer function
//! synthesis as a ratio of two complex polynomials", IEEE Trans. Automatic
//! Control 8 (1963) 56-58.

use nalgebra::linalg::{QR, SVD};
use nalgebra::{Complex, DMatrix, DVector, Dyn, SMatrix, SVector};
use rayon::prelude::*;

use super::problem::FrfProblem;

/// Smallest over largest singular value of a column-normalised matrix below
/// which a parameter is declared not identifiable. Exact dependence gives
/// ~1e-16; 1e-12 leaves four digits of margin for round-off.
pub const RANK_TOL: f64 = 1e-12;

/// A least-squares matrix without full column rank.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RankDeficient {
    /// The column (parameter) with the largest weight in the null direction.
    pub column: usize,
    /// Smallest over largest singular value after column normalisation.
    pub ratio: f64,
}

/// A tall matrix with its columns scaled to unit norm (so units do not
/// count as ill-conditioning), factored once: Householder QR, and the SVD of
/// the small p x p triangle R. With A = Q R and Q's columns orthonormal, A
/// and R have the same singular values and right singular vectors, so the
/// rank check and the covariance need no SVD of the tall matrix itself.
#[derive(Debug)]
pub struct ScaledFactors {
    /// The norms the columns were divided by.
    pub norms: Vec<f64>,
    qr: QR<f64, Dyn, Dyn>,
    /// SVD of R (right singular vectors requested).
    pub svd: SVD<f64, Dyn, Dyn>,
}

/// The SVD of a column-scaled matrix's triangle R (right singular vectors
/// requested), after checking that it has full column rank: the right
/// singular vector of the smallest singular value is the direction the
/// data cannot see; its largest component names the parameter.
pub fn rank_checked(r: DMatrix<f64>) -> Result<SVD<f64, Dyn, Dyn>, RankDeficient> {
    let p = r.ncols();
    let svd = r.svd(false, true);
    let sv = &svd.singular_values;
    let (imin, smin) =
        sv.iter().enumerate().fold(
            (0, f64::INFINITY),
            |acc, (i, &v)| if v < acc.1 { (i, v) } else { acc },
        );
    let smax = sv.iter().fold(0.0_f64, |m, &v| m.max(v));
    let ratio = smin / smax;
    if ratio < RANK_TOL || !ratio.is_finite() {
        let v_t = svd.v_t.as_ref().expect("V^T was requested");
        let row = v_t.row(imin);
        let column = (0..p)
            .max_by(|&x, &y| row[x].abs().total_cmp(&row[y].abs()))
            .unwrap_or(0);
        return Err(RankDeficient { column, ratio });
    }
    Ok(svd)
}

impl ScaledFactors {
    /// Factors `a` after checking that it has full column rank: the right
    /// singular vector of the smallest singular value is the direction the
    /// data cannot see; its largest component names the parameter.
    pub fn of(mut a: DMatrix<f64>) -> Result<Self, RankDeficient> {
        let norms: Vec<f64> = a.column_iter().map(|c| c.norm()).collect();
        if let Some(column) = norms.iter().position(|&n| n == 0.0 || !n.is_finite()) {
            return Err(RankDeficient { column, ratio: 0.0 });
        }
        let p = a.ncols();
        if a.nrows() < p {
            return Err(RankDeficient {
                column: p - 1,
                ratio: 0.0,
            });
        }
        for (j, mut col) in a.column_iter_mut().enumerate() {
            col /= norms[j];
        }
        let qr = a.qr();
        let svd = rank_checked(qr.r())?;
        Ok(Self { norms, qr, svd })
    }

    /// min ||A x - b|| from the factors: x = S^-1 R^-1 Q^T b, S the column
    /// scaling (the normal equations would square the condition number).
    pub fn solve(&self, mut b: DVector<f64>) -> Result<DVector<f64>, RankDeficient> {
        let p = self.norms.len();
        self.qr.q_tr_mul(&mut b);
        let rhs = b.rows(0, p).into_owned();
        let y = self
            .qr
            .r()
            .solve_upper_triangular(&rhs)
            .ok_or(RankDeficient {
                column: p - 1,
                ratio: 0.0,
            })?;
        Ok(DVector::from_iterator(
            p,
            y.iter().zip(self.norms.iter()).map(|(v, n)| v / n),
        ))
    }
}

/// Levy's linear least squares: minimise sum_i w_i |N'(s_i) - G_i D'(s_i)|^2
/// over the numerator b'_m .. b'_0 and the monic denominator's a'_{n-1} ..
/// a'_0 (returned in that order). The error N - G D is linear in the
/// coefficients; it is the output error H - N/D multiplied by D, so Levy
/// alone over-weights the bins where |D| is large.
pub fn levy(
    s: &[Complex<f64>],
    g: &[Complex<f64>],
    w: &[f64],
    numerator_order: usize,
    denominator_order: usize,
) -> Result<Vec<f64>, RankDeficient> {
    let (m, n) = (numerator_order, denominator_order);
    let p = m + 1 + n;
    let nb = s.len();
    let mut a = DMatrix::zeros(2 * nb, p);
    let mut b = DVector::zeros(2 * nb);
    let mut pow = vec![Complex::new(1.0, 0.0); m.max(n) + 1];
    for i in 0..nb {
        for k in 1..pow.len() {
            pow[k] = pow[k - 1] * s[i];
        }
        let sw = w[i].sqrt();
        // Unknowns: b'_k multiplies s^k; a'_k multiplies -G s^k; G s^n moves right.
        for j in 0..=m {
            let c = pow[m - j] * sw;
            a[(i, j)] = c.re;
            a[(nb + i, j)] = c.im;
        }
        for j in 0..n {
            let c = -g[i] * pow[n - 1 - j] * sw;
            a[(i, m + 1 + j)] = c.re;
            a[(nb + i, m + 1 + j)] = c.im;
        }
        let rhs = g[i] * pow[n] * sw;
        b[i] = rhs.re;
        b[nb + i] = rhs.im;
    }
    Ok(ScaledFactors::of(a)?.solve(b)?.iter().copied().collect())
}

/// Result of [`sanathanan_koerner`].
#[derive(Debug, Clone, PartialEq)]
pub struct SkResult {
    /// Scaled coefficients, ordered as in [`levy`].
    pub theta: Vec<f64>,
    /// Re-weighted solves performed after the first Levy solve.
    pub iterations: usize,
}

/// Sanathanan-Koerner iterations: Levy re-weighted by 1/|D'_prev(s_i)|^2, so
/// that at a fixed point the error (N - G D)/D_prev approximates the output
/// error N/D - G. Stops after `max_iterations` or when the coefficients
/// change by less than 1e-12 relative (vector norm).
pub fn sanathanan_koerner(
    s: &[Complex<f64>],
    g: &[Complex<f64>],
    w: &[f64],
    numerator_order: usize,
    denominator_order: usize,
    max_iterations: usize,
) -> Result<SkResult, RankDeficient> {
    let m = numerator_order;
    let first = levy(s, g, w, m, denominator_order)?;
    let (theta, iterations) = iterate_sk(s, w, m, max_iterations, first, |wk| {
        levy(s, g, wk, m, denominator_order)
    })?;
    Ok(SkResult { theta, iterations })
}

/// The SK iterations from Levy's coefficients `theta`: the weights `w`
/// divided by |D'_prev(s_i)|^2, solved again by `solve`, until
/// `max_iterations` or a change below 1e-12 of the coefficients' norm.
/// Returns the coefficients and the solves made.
fn iterate_sk<T: AsRef<[f64]>, E>(
    s: &[Complex<f64>],
    w: &[f64],
    numerator_order: usize,
    max_iterations: usize,
    mut theta: T,
    mut solve: impl FnMut(&[f64]) -> Result<T, E>,
) -> Result<(T, usize), E> {
    let mut wk = vec![0.0; s.len()];
    let mut iterations = 0;
    for _ in 0..max_iterations {
        let den = &theta.as_ref()[numerator_order + 1..];
        for ((wk, &si), &wi) in wk.iter_mut().zip(s).zip(w) {
            let d = den
                .iter()
                .fold(Complex::new(1.0, 0.0), |acc, &c| acc * si + c);
            *wk = wi / d.norm_sqr();
        }
        let next = solve(&wk)?;
        iterations += 1;
        let change = next
            .as_ref()
            .iter()
            .zip(theta.as_ref())
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            .sqrt();
        let size = next.as_ref().iter().map(|a| a * a).sum::<f64>().sqrt();
        theta = next;
        if change <= 1e-12 * size {
            break;
        }
    }
    Ok((theta, iterations))
}

/// Levy + SK on the data divided by the known factors and by exp(-s' tau')
/// (the grid's trial delay; 0 when no delay is fitted). Returns the rational
/// coefficients only.
pub fn linear_start(
    problem: &FrfProblem,
    tau_scaled: f64,
    sk_iterations: usize,
) -> Result<SkResult, RankDeficient> {
    let (g, w) = delayed_data(problem, tau_scaled);
    sanathanan_koerner(
        &problem.s,
        &g,
        &w,
        problem.shape.numerator_order,
        problem.shape.denominator_order,
        sk_iterations,
    )
}

/// The data Levy fits at the trial delay `tau_scaled`: h divided by the
/// known factor K exp(-s' tau'), and the weights |K|^2 w^2 (dividing h by K
/// divides its noise by |K|).
fn delayed_data(problem: &FrfProblem, tau_scaled: f64) -> (Vec<Complex<f64>>, Vec<f64>) {
    let known: Vec<Complex<f64>> = problem
        .known
        .iter()
        .zip(problem.s.iter())
        .map(|(&k, &s)| {
            if tau_scaled == 0.0 {
                k
            } else {
                k * (-s * tau_scaled).exp()
            }
        })
        .collect();
    let g = problem
        .h
        .iter()
        .zip(known.iter())
        .map(|(h, k)| h / k)
        .collect();
    let w = known
        .iter()
        .zip(problem.weight.iter())
        .map(|(k, wt)| k.norm_sqr() * wt * wt)
        .collect();
    (g, w)
}

/// Number of points of the delay grid: a step small enough that the phase
/// at the highest bin moves by at most 0.2 rad between points (the nonlinear
/// refinement then starts inside the right phase basin), from 2 to 201.
pub fn delay_grid_points(problem: &FrfProblem, max_tau_scaled: f64) -> usize {
    let s_max = problem.s.iter().fold(0.0_f64, |m, s| m.max(s.norm()));
    let steps = (s_max * max_tau_scaled / 0.2).ceil();
    (steps as usize + 1).clamp(2, 201)
}

/// Start for a fitted delay: Levy + SK at each delay of a uniform grid on
/// [0, `max_tau_scaled`], keeping the one whose output-error cost
/// (the weighted residuals of `problem`) is smallest, the first on a tie.
/// Returns the rational coefficients followed by tau'.
///
/// Every point is first screened (`screened_cost`: the same SK
/// iterations solved by their normal equations, a few times cheaper than
/// the QR). Only the points whose screened cost is within
/// `SCREEN_MARGIN` (1e-3) of the lowest, and those the screen cannot vouch for,
/// are then solved by QR as the grid defines them, and the choice is made
/// among those. The screen's costs are within about 1e-8 of the QR's where
/// it vouches for them (a condition number below 1e5), so no point it
/// leaves out could have won: the start, and any rank error, are those of
/// the grid solved by QR throughout (checked against it in the tests).
///
/// The points are independent and solved side by side, and the choice is
/// made afterwards in grid order, so the start is the same on any thread
/// count.
pub fn delay_grid_start(
    problem: &FrfProblem,
    max_tau_scaled: f64,
    sk_iterations: usize,
) -> Result<Vec<f64>, RankDeficient> {
    debug_assert!(problem.shape.fit_delay);
    let points = delay_grid_points(problem, max_tau_scaled);
    let tau = |k: usize| max_tau_scaled * k as f64 / (points - 1) as f64;
    let screened: Vec<Option<f64>> = (0..points)
        .into_par_iter()
        .map(|k| screened_cost(problem, tau(k), sk_iterations))
        .collect();
    let lowest = screened
        .iter()
        .flatten()
        .copied()
        .filter(|c| c.is_finite())
        .fold(f64::INFINITY, f64::min);
    let candidates: Vec<usize> = (0..points)
        .filter(|&k| match screened[k] {
            Some(c) => !(c.is_finite() && c > lowest * (1.0 + SCREEN_MARGIN)),
            None => true,
        })
        .collect();
    let solved: Vec<Result<(f64, Vec<f64>), RankDeficient>> = candidates
        .par_iter()
        .map(|&k| {
            let mut theta = linear_start(problem, tau(k), sk_iterations)?.theta;
            theta.push(tau(k));
            Ok((problem.residuals(&theta).norm_squared(), theta))
        })
        .collect();
    let mut best: Option<(f64, Vec<f64>)> = None;
    for point in solved {
        let (cost, theta) = point?;
        let better = match &best {
            None => true,
            Some((c, _)) => cost.is_finite() && (cost < *c || !c.is_finite()),
        };
        if better {
            best = Some((cost, theta));
        }
    }
    Ok(best.expect("the lowest screened point is a candidate").1)
}

/// Relative distance from the lowest screened cost within which a grid
/// point is solved by QR: a hundred thousand times the screen's error.
const SCREEN_MARGIN: f64 = 1e-3;

/// Smallest lower bound on a column-normalised Levy matrix's smallest over
/// largest singular value for which the screen solves its normal
/// equations: their error grows as the condition number squared, 1e10
/// times the rounding here, about 1e-6 of the coefficients at worst. It
/// is far above [`RANK_TOL`], so a matrix the QR path would call
/// rank-deficient is never screened.
const SCREEN_RATIO: f64 = 1e-5;

/// The grid point's output-error cost with Levy + SK solved by the normal
/// equations ([`levy_normal`]); `None` where a solve's conditioning is not
/// vouched for or the model has more than eight coefficients, and the point
/// must be solved by QR.
fn screened_cost(problem: &FrfProblem, tau_scaled: f64, sk_iterations: usize) -> Option<f64> {
    let shape = problem.shape;
    let mut theta = match shape.n_rational() {
        2 => screened_sk::<2>(problem, tau_scaled, sk_iterations)?.to_vec(),
        3 => screened_sk::<3>(problem, tau_scaled, sk_iterations)?.to_vec(),
        4 => screened_sk::<4>(problem, tau_scaled, sk_iterations)?.to_vec(),
        5 => screened_sk::<5>(problem, tau_scaled, sk_iterations)?.to_vec(),
        6 => screened_sk::<6>(problem, tau_scaled, sk_iterations)?.to_vec(),
        7 => screened_sk::<7>(problem, tau_scaled, sk_iterations)?.to_vec(),
        8 => screened_sk::<8>(problem, tau_scaled, sk_iterations)?.to_vec(),
        _ => return None,
    };
    theta.push(tau_scaled);
    Some(problem.residuals(&theta).norm_squared())
}

/// [`sanathanan_koerner`] on the grid point's data with each solve by
/// [`levy_normal`]: the same weights and the same stopping rule.
fn screened_sk<const P: usize>(
    problem: &FrfProblem,
    tau_scaled: f64,
    sk_iterations: usize,
) -> Option<[f64; P]> {
    let m = problem.shape.numerator_order;
    let n = problem.shape.denominator_order;
    let s = &problem.s;
    let (g, w) = delayed_data(problem, tau_scaled);
    let first = levy_normal::<P>(s, &g, &w, m, n)?;
    iterate_sk(s, &w, m, sk_iterations, first, |wk| {
        levy_normal::<P>(s, &g, wk, m, n).ok_or(())
    })
    .ok()
    .map(|(theta, _)| theta)
}

/// [`levy`]'s least squares solved by its normal equations, A^T A x =
/// A^T b (P <= 8), with A's columns scaled to unit norm and a Cholesky
/// factor. `None` unless every s is on the imaginary axis, every pivot is
/// positive and the bound sigma_min / sigma_max >= 1 / sqrt(P trace((A^T
/// A)^-1)) (lambda_max <= trace = P, lambda_min >= 1 / trace of the
/// inverse) is at least [`SCREEN_RATIO`].
///
/// On the imaginary axis, s^p = w^p i^p, so each entry of A^T A and A^T b
/// is one of four weighted moments of the bins, sum w w^k, sum w w^k Re g,
/// sum w w^k Im g and sum w w^k |g|^2, times 0 or +-1 (Levy's own
/// formulation): four products a bin and power, where forming A's rows
/// took a complex product per column and P^2 / 2 products more.
fn levy_normal<const P: usize>(
    s: &[Complex<f64>],
    g: &[Complex<f64>],
    w: &[f64],
    m: usize,
    n: usize,
) -> Option<[f64; P]> {
    debug_assert!(P == m + 1 + n && P <= 8);
    if s.iter().any(|si| si.re != 0.0) {
        return None;
    }
    // Powers up to the largest sum of two columns' (or a column's and the
    // right-hand side's) powers: 2m, m + n and 2n - 1, at most 15.
    let top = (2 * m).max(m + n).max((2 * n).saturating_sub(1));
    let (mut sw, mut sre, mut sim, mut sgg) = ([0.0; 16], [0.0; 16], [0.0; 16], [0.0; 16]);
    for ((&si, &gi), &wi) in s.iter().zip(g).zip(w) {
        let (gg, mut wk) = (gi.norm_sqr(), wi);
        for k in 0..=top {
            sw[k] += wk;
            sre[k] += wk * gi.re;
            sim[k] += wk * gi.im;
            sgg[k] += wk * gg;
            wk *= si.im;
        }
    }
    // Re(i^d) and Re(i^d conj g) for d = p - q.
    let re_i = |d: isize| [1.0, 0.0, -1.0, 0.0][d.rem_euclid(4) as usize];
    let re_i_conj_g = |d: isize, k: usize| match d.rem_euclid(4) {
        0 => sre[k],
        1 => sim[k],
        2 => -sre[k],
        _ => -sim[k],
    };
    // Column j's power, and whether it is a denominator's (-g s^q) column.
    let column = |j: usize| {
        if j <= m {
            ((m - j) as isize, false)
        } else {
            ((m + n - j) as isize, true)
        }
    };
    let entry = |i: usize, j: usize| {
        let ((p, p_den), (q, q_den)) = (column(i), column(j));
        let k = (p + q) as usize;
        match (p_den, q_den) {
            (false, false) => re_i(p - q) * sw[k],
            (true, true) => re_i(p - q) * sgg[k],
            (false, true) => -re_i_conj_g(p - q, k),
            (true, false) => -re_i_conj_g(q - p, k),
        }
    };
    let rhs = |i: usize| {
        let ((p, p_den), n) = (column(i), n as isize);
        if p_den {
            -re_i(p - n) * sgg[(p + n) as usize]
        } else {
            re_i_conj_g(p - n, (p + n) as usize)
        }
    };
    // Unit columns: row and column i divided by the norm of A's column i.
    let norms = SVector::<f64, P>::from_fn(|i, _| entry(i, i).sqrt());
    if norms.iter().any(|v| !v.is_finite() || *v <= 0.0) {
        return None;
    }
    let scaled = SMatrix::<f64, P, P>::from_fn(|i, j| entry(i, j) / (norms[i] * norms[j]));
    let cholesky = scaled.cholesky()?;
    let trace = cholesky.inverse().trace();
    if trace.is_nan() || P as f64 * trace > 1.0 / (SCREEN_RATIO * SCREEN_RATIO) {
        return None;
    }
    let y = cholesky.solve(&SVector::<f64, P>::from_fn(|i, _| rhs(i) / norms[i]));
    let x: [f64; P] = y.component_div(&norms).into();
    x.iter().all(|v| v.is_finite()).then_some(x)
}

#[cfg(test)]
mod tests {
    use super::super::problem::{ModelShape, Scaling};
    use super::*;
    use approx::assert_relative_eq;

    fn bins() -> Vec<f64> {
        (0..119).map(|k| 0.5 + 0.25 * k as f64).collect()
    }

    /// Problem with data from the physical n0/(s^2 + d1 s + d0).
    fn second_order_problem(n0: f64, d1: f64, d0: f64, noise: &[Complex<f64>]) -> FrfProblem {
        let freq = bins();
        let scaling = Scaling::for_band(&freq);
        let s: Vec<Complex<f64>> = freq.iter().map(|&f| scaling.s(f)).collect();
        let h: Vec<Complex<f64>> = freq
            .iter()
            .enumerate()
            .map(|(i, &f)| {
                let jw = Complex::new(0.0, 2.0 * std::f64::consts::PI * f);
                n0 / (jw * jw + jw * d1 + d0) + noise.get(i).copied().unwrap_or_default()
            })
            .collect();
        FrfProblem {
            shape: ModelShape {
                numerator_order: 0,
                denominator_order: 2,
                fit_delay: false,
            },
            s,
            h,
            known: vec![Complex::new(1.0, 0.0); freq.len()],
            weight: vec![1.0; freq.len()],
            projector: None,
            last: Default::default(),
        }
    }

    #[test]
    fn levy_recovers_exact_data() {
        // Noise-free 3060/(s^2 + 267 s + 3060) (paper Eq. 36): N - G D = 0 at
        // the truth, so Levy's solution is exact whatever the weights.
        let p = second_order_problem(3060.0, 267.0, 3060.0, &[]);
        let w = vec![1.0; p.n_bins()];
        let theta = levy(&p.s, &p.h, &w, 0, 2).unwrap();
        let scaling = Scaling::for_band(&bins());
        let phys = scaling.to_physical(&p.shape, &theta);
        for (got, want) in phys.iter().zip([3060.0, 267.0, 3060.0]) {
            assert_relative_eq!(*got, want, max_relative = 1e-11);
        }
    }

    #[test]
    fn sk_lowers_the_output_error_that_levy_misweights() {
        // With noise, Levy minimises |D|^2 |N/D - G|^2, which over-weights the
        // high bins; SK's fixed point approximates the output error itself, so
        // its output-error cost must be lower than Levy's.
        let noise: Vec<Complex<f64>> = (0..119)
            .map(|i| {
                let x = (i as f64 * 12.9898).sin() * 43758.5453;
                let y = (i as f64 * 78.233).sin() * 12345.678;
                Complex::new(x.fract(), y.fract()) * 0.02
            })
            .collect();
        let p = second_order_problem(3060.0, 267.0, 3060.0, &noise);
        let w = vec![1.0; p.n_bins()];
        let levy_theta = levy(&p.s, &p.h, &w, 0, 2).unwrap();
        let sk = sanathanan_koerner(&p.s, &p.h, &w, 0, 2, 20).unwrap();
        assert!(sk.iterations >= 2);
        let cost_levy = p.residuals(&levy_theta).norm_squared();
        let cost_sk = p.residuals(&sk.theta).norm_squared();
        assert!(
            cost_sk < 0.9 * cost_levy,
            "SK {cost_sk} vs Levy {cost_levy}"
        );
    }

    /// Data from 3060/(s^2 + 267 s + 3060) exp(-s tau) (paper Eq. 36 with a
    /// delay) plus deterministic pseudo-random noise of relative size
    /// `noise`, fitted with a delay and a denominator of `denominator_order`.
    fn delayed_problem(tau_s: f64, noise: f64, denominator_order: usize) -> (FrfProblem, f64) {
        delayed_problem_of(tau_s, noise, (0, denominator_order))
    }

    /// [`delayed_problem`] fitted with numerator and denominator orders
    /// `(m, n)`.
    fn delayed_problem_of(tau_s: f64, noise: f64, (m, n): (usize, usize)) -> (FrfProblem, f64) {
        let freq = bins();
        let scaling = Scaling::for_band(&freq);
        let h = freq
            .iter()
            .enumerate()
            .map(|(i, &f)| {
                let jw = Complex::new(0.0, 2.0 * std::f64::consts::PI * f);
                let x = (i as f64 * 12.9898 + noise).sin() * 43758.5453;
                let y = (i as f64 * 78.233 + noise).sin() * 12345.678;
                let model = 3060.0 / (jw * jw + jw * 267.0 + 3060.0) * (-jw * tau_s).exp();
                model * (1.0 + Complex::new(x.fract(), y.fract()) * noise)
            })
            .collect();
        let problem = FrfProblem {
            shape: ModelShape {
                numerator_order: m,
                denominator_order: n,
                fit_delay: true,
            },
            s: freq.iter().map(|&f| scaling.s(f)).collect(),
            h,
            known: vec![Complex::new(1.0, 0.0); freq.len()],
            weight: vec![1.0; freq.len()],
            projector: None,
            last: Default::default(),
        };
        (problem, 0.02 * scaling.w0_rad_per_s)
    }

    /// The grid by its definition: every point solved by QR.
    fn qr_grid(problem: &FrfProblem, max_tau: f64, sk: usize) -> Result<Vec<f64>, RankDeficient> {
        let points = delay_grid_points(problem, max_tau);
        let mut best: Option<(f64, Vec<f64>)> = None;
        for k in 0..points {
            let tau = max_tau * k as f64 / (points - 1) as f64;
            let mut theta = linear_start(problem, tau, sk)?.theta;
            theta.push(tau);
            let cost = problem.residuals(&theta).norm_squared();
            if best
                .as_ref()
                .is_none_or(|(c, _)| cost.is_finite() && (cost < *c || !c.is_finite()))
            {
                best = Some((cost, theta));
            }
        }
        Ok(best.unwrap().1)
    }

    #[test]
    fn the_screened_grid_starts_where_the_qr_grid_does() {
        // Clean, noisy and over-parameterised (a third-order denominator on
        // second-order data, where neighbouring points' costs are close):
        // the start must be the QR grid's to the bit, and the screen must
        // have left most points out, or it saved nothing.
        for (tau_s, noise, order) in [
            (0.004, 0.0, 2),
            (0.011, 0.05, 2),
            (0.007, 0.2, 2),
            (0.004, 0.0, 3),
            (0.009, 0.1, 3),
            (0.002, 0.3, 3),
        ] {
            let (p, max_tau) = delayed_problem(tau_s, noise, order);
            let got = delay_grid_start(&p, max_tau, 10).unwrap();
            let want = qr_grid(&p, max_tau, 10).unwrap();
            assert_eq!(got, want, "tau {tau_s} noise {noise} order {order}");
            let points = delay_grid_points(&p, max_tau);
            let screened: Vec<f64> = (0..points)
                .filter_map(|k| screened_cost(&p, max_tau * k as f64 / (points - 1) as f64, 10))
                .collect();
            let lowest = screened.iter().copied().fold(f64::INFINITY, f64::min);
            let kept = screened
                .iter()
                .filter(|&&c| c <= lowest * (1.0 + SCREEN_MARGIN))
                .count();
            assert_eq!(screened.len(), points, "every point vouched for");
            assert!(kept * 4 < points, "{kept} of {points} points solved by QR");
        }
    }

    #[test]
    fn the_screen_agrees_with_the_qr_solve() {
        // The normal equations against the QR on the same grid point: the
        // SK coefficients and the cost to 1e-8, at every point of a noisy
        // grid.
        let (p, max_tau) = delayed_problem(0.009, 0.1, 3);
        let points = delay_grid_points(&p, max_tau);
        for k in 0..points {
            let tau = max_tau * k as f64 / (points - 1) as f64;
            let mut exact = linear_start(&p, tau, 10).unwrap().theta;
            exact.push(tau);
            let want = p.residuals(&exact).norm_squared();
            let got = screened_cost(&p, tau, 10).expect("well conditioned");
            assert_relative_eq!(got, want, max_relative = 1e-8);
        }
        // One Levy solve against the QR, for numerators and denominators
        // of several orders (every sign of i^d in the moments' entries).
        for (m, n) in [(0, 3), (1, 2), (2, 3), (1, 4), (3, 3)] {
            let (p, max_tau) = delayed_problem_of(0.009, 0.1, (m, n));
            let (g, w) = delayed_data(&p, 0.3 * max_tau);
            let qr = levy(&p.s, &g, &w, m, n).unwrap();
            let normal = match m + 1 + n {
                4 => levy_normal::<4>(&p.s, &g, &w, m, n).map(|x| x.to_vec()),
                6 => levy_normal::<6>(&p.s, &g, &w, m, n).map(|x| x.to_vec()),
                7 => levy_normal::<7>(&p.s, &g, &w, m, n).map(|x| x.to_vec()),
                other => unreachable!("{other} coefficients"),
            };
            let normal = normal.unwrap_or_else(|| panic!("orders ({m}, {n}) refused"));
            for (a, b) in normal.iter().zip(&qr) {
                assert_relative_eq!(*a, *b, max_relative = 1e-7);
            }
        }
    }

    #[test]
    fn the_screen_leaves_a_rank_deficient_grid_to_the_qr() {
        // Zero weights make every column zero: the QR path names the first
        // parameter; the screen must not hide that.
        let (mut p, max_tau) = delayed_problem(0.004, 0.0, 2);
        p.weight.iter_mut().for_each(|w| *w = 0.0);
        assert_eq!(screened_cost(&p, 0.0, 10), None);
        assert_eq!(
            delay_grid_start(&p, max_tau, 10).unwrap_err(),
            qr_grid(&p, max_tau, 10).unwrap_err()
        );
    }

    #[test]
    fn rank_check_names_a_dependent_column() {
        // Column 2 = column 0 + column 1: rank 2. Every column takes part in
        // the null direction, so any of them is a fair answer; check that the
        // ratio is ~0, then break the dependence and see the check pass.
        let mut a = DMatrix::from_fn(6, 3, |i, j| ((i * 7 + j * 3) % 5) as f64 + 1.0);
        for i in 0..6 {
            a[(i, 2)] = a[(i, 0)] + a[(i, 1)];
        }
        let err = ScaledFactors::of(a.clone()).unwrap_err();
        assert!(err.column < 3);
        assert!(err.ratio < 1e-14);
        a[(0, 2)] += 1.0;
        assert!(ScaledFactors::of(a).is_ok());
        // A zero column is named exactly.
        let mut z = DMatrix::from_fn(4, 2, |i, j| (i + j) as f64 + 1.0);
        z.column_mut(1).fill(0.0);
        assert_eq!(ScaledFactors::of(z).unwrap_err().column, 1);
    }

    #[test]
    fn qr_solve_matches_the_normal_equations_on_a_well_posed_problem() {
        // Independent route: solve (A^T A) x = A^T b by explicit inverse.
        let a = DMatrix::from_fn(8, 3, |i, j| ((i + 1) as f64).powi(j as i32));
        let b = DVector::from_fn(8, |i, _| (i as f64 * 0.7).cos());
        let x = ScaledFactors::of(a.clone())
            .unwrap()
            .solve(b.clone())
            .unwrap();
        let ata = a.transpose() * &a;
        let want = ata.try_inverse().unwrap() * a.transpose() * &b;
        for (g, w) in x.iter().zip(want.iter()) {
            assert_relative_eq!(*g, *w, max_relative = 1e-10);
        }
    }
}
