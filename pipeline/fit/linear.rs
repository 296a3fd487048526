//! Linear starting values in scaled frequency: Levy's least squares,
//! Sanathanan-Koerner re-weighting, and a grid over a fitted delay; plus the
//! rank-revealing least-squares solve they share with the covariance.
//!
//! References: E. C. Levy, "Complex-curve fitting", IRE Trans. Automatic
//! Control 4 (1959) 37-43; C. K. Sanathanan and J. Koerner, "Transfer function
//! synthesis as a ratio of two complex polynomials", IEEE Trans. Automatic
//! Control 8 (1963) 56-58.

use nalgebra::linalg::{QR, SVD};
use nalgebra::{Complex, DMatrix, DVector, Dyn};
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
        let svd = qr.r().svd(false, true);
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
    let mut theta = levy(s, g, w, m, denominator_order)?;
    let mut iterations = 0;
    for _ in 0..max_iterations {
        let den = &theta[m + 1..];
        let wk: Vec<f64> = s
            .iter()
            .zip(w)
            .map(|(&si, &wi)| {
                let d = den
                    .iter()
                    .fold(Complex::new(1.0, 0.0), |acc, &c| acc * si + c);
                wi / d.norm_sqr()
            })
            .collect();
        let next = levy(s, g, &wk, m, denominator_order)?;
        iterations += 1;
        let change = next
            .iter()
            .zip(theta.iter())
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            .sqrt();
        let size = next.iter().map(|a| a * a).sum::<f64>().sqrt();
        theta = next;
        if change <= 1e-12 * size {
            break;
        }
    }
    Ok(SkResult { theta, iterations })
}

/// Levy + SK on the data divided by the known factors and by exp(-s' tau')
/// (the grid's trial delay; 0 when no delay is fitted). Returns the rational
/// coefficients only. The weights are |K|^2 w^2: dividing h by K divides its
/// noise by |K|.
pub fn linear_start(
    problem: &FrfProblem,
    tau_scaled: f64,
    sk_iterations: usize,
) -> Result<SkResult, RankDeficient> {
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
    let g: Vec<Complex<f64>> = problem
        .h
        .iter()
        .zip(known.iter())
        .map(|(h, k)| h / k)
        .collect();
    let w: Vec<f64> = known
        .iter()
        .zip(problem.weight.iter())
        .map(|(k, wt)| k.norm_sqr() * wt * wt)
        .collect();
    sanathanan_koerner(
        &problem.s,
        &g,
        &w,
        problem.shape.numerator_order,
        problem.shape.denominator_order,
        sk_iterations,
    )
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
/// The points are independent and solved side by side: a run's grid (up
/// to 201 points of ten SK solves) can be the longest task of a stage, and
/// would otherwise hold one core while the other has nothing left to do.
/// The choice is made afterwards in grid order, so the start is the same
/// on any thread count.
pub fn delay_grid_start(
    problem: &FrfProblem,
    max_tau_scaled: f64,
    sk_iterations: usize,
) -> Result<Vec<f64>, RankDeficient> {
    debug_assert!(problem.shape.fit_delay);
    let points = delay_grid_points(problem, max_tau_scaled);
    let solved: Vec<Result<(f64, Vec<f64>), RankDeficient>> = (0..points)
        .into_par_iter()
        .map(|k| {
            let tau = max_tau_scaled * k as f64 / (points - 1) as f64;
            let mut theta = linear_start(problem, tau, sk_iterations)?.theta;
            theta.push(tau);
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
    Ok(best.expect("the grid has at least two points").1)
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
