//! Exact simulation of linear plants driven through a sample-and-hold D/A
//! converter: zero-order-hold discretisation and a non-allocating sample
//! loop, with each output sampled at an exact (possibly fractional) delay.
//!
//! With u held constant over [t_k, t_k + T), x(t_k + tau) = Phi(tau) x_k +
//! Gamma(tau) u_k with Phi(tau) = exp(A tau) and Gamma(tau) = int_0^tau
//! exp(A s) ds B, both read off exp([[A, B], [0, 0]] tau) (Van Loan 1978,
//! "Computing integrals involving the matrix exponential"). No step-size
//! error: the only errors are round-off.

use nalgebra::{DMatrix, DVector, SMatrix, SVector};

use super::SimError;
use crate::lti::{StateSpace, phi_gamma, split_delay};

/// A state space discretised with a zero-order hold:
/// `x[k+1] = ad x[k] + bd u[k]`, `y[k] = c x[k] + d u[k]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Discretized {
    pub ad: DMatrix<f64>,
    pub bd: DVector<f64>,
    pub c: DMatrix<f64>,
    pub d: DVector<f64>,
    /// Sample period T (s).
    pub dt_s: f64,
}

/// Zero-order-hold discretisation over `dt_s` (s), through
/// [`crate::lti::phi_gamma`] (a balanced matrix exponential: the plant's A
/// mixes 1/m ~ 0.3 with a1b0 ~ 2.4e9).
pub fn zoh(ss: &StateSpace, dt_s: f64) -> Discretized {
    let (phi, gamma) = phi_gamma(&ss.a, &ss.b, dt_s);
    Discretized {
        ad: phi,
        bd: gamma,
        c: ss.c.clone(),
        d: ss.d.clone(),
        dt_s,
    }
}

/// How one output is read: `y[k + shift] = row . x[k] + gain u[k]`.
struct Tap {
    shift: usize,
    row: DVector<f64>,
    gain: f64,
}

/// Simulates `ss` from rest with the command `u` held over each sample period
/// `dt_s` (s); returns one vector per output row of C, output i sampled at
/// `t_k - output_delay_s[i]` exactly (zero before t = 0).
///
/// A delay of q whole samples reads `C x[k-q] + D u[k-q]`. A delay of q
/// samples plus a fraction eps reads the state T - eps after sample
/// k - q - 1, with that sample's command held:
/// `C Phi(T - eps) x[k-q-1] + (C Gamma(T - eps) + D) u[k-q-1]`. Orders up to
/// 8 run on fixed-size matrices; the sample loop never allocates.
pub fn simulate_linear(
    ss: &StateSpace,
    u: &[f64],
    dt_s: f64,
    output_delay_s: &[f64],
) -> Result<Vec<Vec<f64>>, SimError> {
    let n = ss.order();
    let outputs = ss.c.nrows();
    if ss.a.ncols() != n || ss.b.len() != n || ss.c.ncols() != n || ss.d.len() != outputs {
        return Err(SimError::Dimensions {
            a_rows: ss.a.nrows(),
            a_cols: ss.a.ncols(),
            b_rows: ss.b.len(),
            c_rows: ss.c.nrows(),
            c_cols: ss.c.ncols(),
            d_rows: ss.d.len(),
        });
    }
    if output_delay_s.len() != outputs {
        return Err(SimError::OutputDelays {
            delays: output_delay_s.len(),
            outputs,
        });
    }
    super::require_positive("linear simulation", "dt_s", dt_s)?;
    for &delay in output_delay_s {
        super::require_non_negative("linear simulation", "output_delay_s", delay)?;
    }
    if let Some((index, &value)) = u.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(SimError::NonFiniteCommand {
            index,
            t_s: index as f64 * dt_s,
            value,
        });
    }
    if [&ss.a, &ss.c]
        .iter()
        .any(|m| m.iter().any(|v| !v.is_finite()))
        || ss.b.iter().chain(ss.d.iter()).any(|v| !v.is_finite())
    {
        return Err(SimError::NonFiniteModel);
    }
    let disc = zoh(ss, dt_s);
    let taps: Vec<Tap> = (0..outputs)
        .map(|i| {
            let c_row = ss.c.row(i).transpose();
            match split_delay(output_delay_s[i], dt_s) {
                (q, None) => Tap {
                    shift: q,
                    row: c_row,
                    gain: ss.d[i],
                },
                (q, Some(eps)) => {
                    let (phi, gamma) = phi_gamma(&ss.a, &ss.b, dt_s - eps);
                    Tap {
                        shift: q + 1,
                        row: phi.transpose() * &c_row,
                        gain: c_row.dot(&gamma) + ss.d[i],
                    }
                }
            }
        })
        .collect();
    let mut out = vec![vec![0.0; u.len()]; outputs];
    match n {
        1 => run_fixed::<1>(&disc, &taps, u, &mut out),
        2 => run_fixed::<2>(&disc, &taps, u, &mut out),
        3 => run_fixed::<3>(&disc, &taps, u, &mut out),
        4 => run_fixed::<4>(&disc, &taps, u, &mut out),
        5 => run_fixed::<5>(&disc, &taps, u, &mut out),
        6 => run_fixed::<6>(&disc, &taps, u, &mut out),
        7 => run_fixed::<7>(&disc, &taps, u, &mut out),
        8 => run_fixed::<8>(&disc, &taps, u, &mut out),
        _ => run_dynamic(&disc, &taps, u, &mut out),
    }
    Ok(out)
}

/// The sample loop on stack-allocated N x N matrices.
fn run_fixed<const N: usize>(disc: &Discretized, taps: &[Tap], u: &[f64], out: &mut [Vec<f64>]) {
    let ad = SMatrix::<f64, N, N>::from_fn(|i, j| disc.ad[(i, j)]);
    let bd = SVector::<f64, N>::from_fn(|i, _| disc.bd[i]);
    let rows: Vec<(usize, SVector<f64, N>, f64)> = taps
        .iter()
        .map(|t| (t.shift, SVector::<f64, N>::from_fn(|i, _| t.row[i]), t.gain))
        .collect();
    let len = u.len();
    let mut x = SVector::<f64, N>::zeros();
    for (k, &uk) in u.iter().enumerate() {
        for ((shift, row, gain), y) in rows.iter().zip(out.iter_mut()) {
            let j = k + shift;
            if j < len {
                y[j] = row.dot(&x) + gain * uk;
            }
        }
        x = ad * x + bd * uk;
    }
}

/// The sample loop for larger orders, on preallocated buffers.
fn run_dynamic(disc: &Discretized, taps: &[Tap], u: &[f64], out: &mut [Vec<f64>]) {
    let n = disc.ad.nrows();
    let len = u.len();
    let mut x = DVector::<f64>::zeros(n);
    let mut next = DVector::<f64>::zeros(n);
    for (k, &uk) in u.iter().enumerate() {
        for (tap, y) in taps.iter().zip(out.iter_mut()) {
            let j = k + tap.shift;
            if j < len {
                y[j] = tap.row.dot(&x) + tap.gain * uk;
            }
        }
        disc.ad.mul_to(&x, &mut next);
        next.axpy(uk, &disc.bd, 1.0);
        std::mem::swap(&mut x, &mut next);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lti::TransferFunction;
    use crate::model::{self, LinearSpecimen};
    use approx::assert_relative_eq;
    use nalgebra::Complex;
    use std::f64::consts::PI;

    fn exp1() -> LinearSpecimen {
        LinearSpecimen::Sdof {
            mass_kg: 3.8,
            damping_ns_per_m: 5.0,
            stiffness_n_per_m: 129_400.0,
        }
    }

    fn max_abs(v: &[f64]) -> f64 {
        v.iter().fold(0.0, |m, x| m.max(x.abs()))
    }

    #[test]
    fn first_order_step_response_is_exact() {
        // a/(s + a) from rest, unit step: y(t) = 1 - exp(-a t).
        let a = 37.0;
        let ss = TransferFunction::new(&[a], &[1.0, a])
            .unwrap()
            .to_state_space();
        let dt = 1e-3;
        let u = vec![1.0; 400];
        let y = simulate_linear(&ss, &u, dt, &[0.0]).unwrap();
        for (k, v) in y[0].iter().enumerate() {
            let t = k as f64 * dt;
            let want = 1.0 - (-a * t).exp();
            assert!(
                (v - want).abs() <= 1e-12 * want.abs().max(1e-3),
                "k = {k}: {v} vs {want}"
            );
        }
    }

    #[test]
    fn second_order_step_response_is_exact() {
        // wn^2 / (s^2 + 2 zeta wn s + wn^2): y = 1 - exp(-zeta wn t) (cos wd t
        // + zeta / sqrt(1 - zeta^2) sin wd t), wd = wn sqrt(1 - zeta^2).
        let (wn, zeta) = (2.0 * PI * 12.0, 0.15);
        let ss = TransferFunction::new(&[wn * wn], &[1.0, 2.0 * zeta * wn, wn * wn])
            .unwrap()
            .to_state_space();
        let dt = 1.0 / 1024.0;
        let u = vec![1.0; 1024];
        let y = simulate_linear(&ss, &u, dt, &[0.0]).unwrap();
        let wd = wn * (1.0 - zeta * zeta).sqrt();
        for (k, v) in y[0].iter().enumerate() {
            let t = k as f64 * dt;
            let want = 1.0
                - (-zeta * wn * t).exp()
                    * ((wd * t).cos() + zeta / (1.0 - zeta * zeta).sqrt() * (wd * t).sin());
            assert!(
                (v - want).abs() <= 1e-9 * want.abs().max(1e-3),
                "k = {k}: {v} vs {want}"
            );
        }
    }

    #[test]
    fn fractional_output_delay_is_exact() {
        // First-order step read 2.3 samples late: 1 - exp(-a (t - tau)) for
        // t > tau, 0 before; a whole-sample delay shifts the samples.
        let a = 80.0;
        let ss = TransferFunction::new(&[a], &[1.0, a])
            .unwrap()
            .to_state_space();
        let dt = 1e-3;
        let tau = 2.3e-3;
        let mut u = vec![1.0; 300];
        u[0] = 1.0;
        let ss2 = StateSpace {
            c: DMatrix::from_row_slice(3, 1, &[ss.c[(0, 0)], ss.c[(0, 0)], ss.c[(0, 0)]]),
            d: DVector::from_element(3, 0.0),
            ..ss.clone()
        };
        let y = simulate_linear(&ss2, &u, dt, &[tau, 4.0 * dt, 0.0]).unwrap();
        for k in 0..u.len() {
            let t = k as f64 * dt;
            let want = if t > tau {
                1.0 - (-a * (t - tau)).exp()
            } else {
                0.0
            };
            assert!(
                (y[0][k] - want).abs() <= 1e-12,
                "k = {k}: {} vs {want}",
                y[0][k]
            );
            let want4 = if k >= 4 { y[2][k - 4] } else { 0.0 };
            assert!((y[1][k] - want4).abs() <= 1e-15);
        }
    }

    #[test]
    fn feedthrough_is_delayed_with_the_held_command() {
        // y = u (D = 1, no dynamics but one decoupled state): a delay of 1.5
        // samples reads the command held at t_k - 1.5 T, i.e. u[k - 2].
        let ss = StateSpace {
            a: DMatrix::from_element(1, 1, -1.0),
            b: DVector::from_element(1, 0.0),
            c: DMatrix::from_element(1, 1, 0.0),
            d: DVector::from_element(1, 1.0),
        };
        let u: Vec<f64> = (0..10).map(|k| k as f64 + 1.0).collect();
        let y = simulate_linear(&ss, &u, 0.01, &[0.015]).unwrap();
        let want = [0.0, 0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0];
        for (g, w) in y[0].iter().zip(want.iter()) {
            assert_relative_eq!(g, w, max_relative = 1e-15);
        }
    }

    /// Step response of a transfer function by partial fractions over its
    /// (distinct) poles: y(t) = H(0) + sum_i N(p_i) / (p_i D'(p_i)) e^{p_i t}.
    fn step_by_partial_fractions(tf: &TransferFunction, t: f64) -> f64 {
        let poles = tf.poles();
        let mut y = Complex::new(tf.dc_gain(), 0.0);
        for (i, p) in poles.iter().enumerate() {
            let mut dprime = Complex::new(1.0, 0.0);
            for (j, q) in poles.iter().enumerate() {
                if i != j {
                    dprime *= p - q;
                }
            }
            let num = crate::poly::eval(&tf.num, *p);
            y += num / (p * dprime) * (p * t).exp();
        }
        y.re
    }

    #[test]
    fn paper_plant_step_matches_partial_fractions() {
        // Exp1 (Eq. 17's x1/u and Eq. 45's f/u) against the closed-form step
        // response from the transfer functions' poles: independent of exp().
        let rig = model::PAPER_RIG;
        let ss = model::state_space(&rig, &exp1());
        let tfs = [
            model::tf_x1_u(&rig, &exp1()).unwrap(),
            model::tf_f_u(&rig, &exp1()).unwrap(),
        ];
        let dt = 1.0 / 2048.0;
        let u = vec![1e-3; 2048];
        let y = simulate_linear(&ss, &u, dt, &[0.0, 0.0]).unwrap();
        for (out, tf) in tfs.iter().enumerate() {
            let want: Vec<f64> = (0..u.len())
                .map(|k| 1e-3 * step_by_partial_fractions(tf, k as f64 * dt))
                .collect();
            let peak = max_abs(&want);
            for k in 0..u.len() {
                assert!(
                    (y[out][k] - want[k]).abs() <= 1e-9 * peak,
                    "output {out} k = {k}: {} vs {}",
                    y[out][k],
                    want[k]
                );
            }
        }
    }

    #[test]
    fn zoh_is_accurate_entrywise_on_the_badly_scaled_plant() {
        // exp([[A, B], [0, 0]] T) for Exp1 at 2048 Hz against its Taylor
        // series by definition, sum_j M^j / j! to 60 terms. A diagonal
        // power-of-two similarity changes no rounding in a product, so the
        // series computed on M carries the accuracy it has on the balanced
        // matrix, whose norm here is 0.72: about eps per entry. Pade with
        // scaling and squaring on the unbalanced M (norm 1.7e6, ~21 squarings)
        // was measured 3e-10 off in the x1 row; balanced, it is within 1e-15.
        let rig = model::PAPER_RIG;
        let ss = model::state_space(&rig, &exp1());
        let dt = 1.0 / 2048.0;
        let n = 4;
        let mut m = DMatrix::<f64>::zeros(n + 1, n + 1);
        m.view_mut((0, 0), (n, n)).copy_from(&(&ss.a * dt));
        m.view_mut((0, n), (n, 1)).copy_from(&(&ss.b * dt));
        let mut term = DMatrix::<f64>::identity(n + 1, n + 1);
        let mut taylor = term.clone();
        for j in 1..60 {
            term = &term * &m / j as f64;
            taylor += &term;
        }
        let disc = zoh(&ss, dt);
        for i in 0..n {
            for j in 0..=n {
                let got = if j < n { disc.ad[(i, j)] } else { disc.bd[i] };
                let want = taylor[(i, j)];
                assert!(
                    (got - want).abs() <= 1e-13 * want.abs(),
                    "({i}, {j}): {got:e} vs {want:e}"
                );
            }
        }
    }

    #[test]
    fn balanced_exp_matches_sylvesters_formula() {
        // exp(B T) for the balanced Exp1 matrix B by Sylvester's formula over
        // its distinct eigenvalues: sum_i e^{l_i T} prod_{j != i} (B - l_j) /
        // (l_i - l_j). The eigen-decomposition route, independent of Pade.
        let rig = model::PAPER_RIG;
        let a = crate::lti::balance(&model::state_space(&rig, &exp1()).a);
        let t = 1.0 / 2048.0;
        let ss = StateSpace {
            a: a.clone(),
            b: DVector::zeros(4),
            c: DMatrix::zeros(1, 4),
            d: DVector::zeros(1),
        };
        let got = zoh(&ss, t).ad;
        let eig = ss.eigenvalues().unwrap();
        let ac = a.map(|v| Complex::new(v, 0.0));
        let eye = DMatrix::<Complex<f64>>::identity(4, 4);
        let mut want = DMatrix::<Complex<f64>>::zeros(4, 4);
        for (i, li) in eig.iter().enumerate() {
            let mut p = eye.clone();
            for (j, lj) in eig.iter().enumerate() {
                if i != j {
                    p = p * (&ac - &eye * *lj) / (li - lj);
                }
            }
            want += p * (li * t).exp();
        }
        let scale = want.iter().fold(0.0_f64, |m, v| m.max(v.norm()));
        for i in 0..4 {
            for j in 0..4 {
                assert!(want[(i, j)].im.abs() < 1e-10 * scale);
                assert!(
                    (got[(i, j)] - want[(i, j)].re).abs() < 1e-10 * scale,
                    "({i}, {j}): {} vs {}",
                    got[(i, j)],
                    want[(i, j)].re
                );
            }
        }
    }

    #[test]
    fn sine_through_the_plant_has_the_sampled_frequency_response() {
        // Steady state of the sampled response to u[k] = sin(w t_k) through
        // the hold. The held staircase has lines at w_m = w + m ws with weights
        // sinc(w_m T / 2) exp(-j w_m T / 2), and sampling folds them all back
        // onto w (Poisson summation), so y[k] = Im(G e^{j w t_k}) with
        // G = sum_m H(j w_m) sinc(w_m T/2) exp(-j w_m T/2), H from the
        // closed-form transfer functions (Eqs. 17 and 45). For x1 (relative
        // degree 4) the m = 0 term alone is within 1e-11; the force path
        // (relative degree 2) aliases about 1e-8, so the sum is taken to
        // |m| = 4000 (tail ~ 1/m^2, below 1e-13).
        let rig = model::PAPER_RIG;
        let spec = exp1();
        let ss = model::state_space(&rig, &spec);
        let fs = 2048.0;
        let dt = 1.0 / fs;
        let ws = 2.0 * PI * fs;
        for (f_hz, out, tf) in [
            (2.0, 0, model::tf_x1_u(&rig, &spec).unwrap()),
            (2.0, 1, model::tf_f_u(&rig, &spec).unwrap()),
            (16.0, 0, model::tf_x1_u(&rig, &spec).unwrap()),
            (64.0, 1, model::tf_f_u(&rig, &spec).unwrap()),
        ] {
            let w = 2.0 * PI * f_hz;
            let n = 8 * 2048; // 8 s; the slowest pole (-6.5 rad/s) leaves e^{-39}
            let u: Vec<f64> = (0..n).map(|k| (w * k as f64 * dt).sin()).collect();
            let y = simulate_linear(&ss, &u, dt, &[0.0, 0.0]).unwrap();
            // Fourier coefficients over the last 2 s (an integer number of periods).
            let start = n - 2 * 2048;
            let (mut s, mut c) = (0.0, 0.0);
            for (k, v) in y[out].iter().enumerate().skip(start) {
                let t = k as f64 * dt;
                s += v * (w * t).sin();
                c += v * (w * t).cos();
            }
            let m = (n - start) as f64 / 2.0;
            // y = |G| sin(wt + arg G) = Re(G) sin + Im(G) cos.
            let got = Complex::new(s / m, c / m);
            let hold = |wm: f64| {
                let x = wm * dt / 2.0;
                Complex::from_polar(x.sin() / x, -x)
            };
            let mut want = Complex::new(0.0, 0.0);
            for mm in (-4000..=4000).rev() {
                let wm = w + mm as f64 * ws;
                want += tf.eval(Complex::new(0.0, wm)) * hold(wm);
            }
            let plain = tf.eval(Complex::new(0.0, w)) * hold(w);
            assert_relative_eq!(got.norm(), want.norm(), max_relative = 1e-9);
            assert!(
                (got.arg() - want.arg()).abs() < 1e-9,
                "{f_hz} Hz: {} vs {}",
                got.arg(),
                want.arg()
            );
            if out == 0 {
                assert_relative_eq!(got.norm(), plain.norm(), max_relative = 1e-9);
            }
        }
    }

    #[test]
    fn orders_above_eight_use_the_dynamic_loop_with_the_same_result() {
        // A 10th-order chain of first-order lags; the same chain truncated to
        // the fixed-size path via a block-diagonal copy would be circular, so
        // compare with its closed form: the step response of 1/(tau s + 1)^n
        // at the sample instants is 1 - e^{-t/tau} sum_{j<n} (t/tau)^j / j!.
        let n = 10;
        let tau = 0.01;
        let mut a = DMatrix::<f64>::zeros(n, n);
        for i in 0..n {
            a[(i, i)] = -1.0 / tau;
            if i > 0 {
                a[(i, i - 1)] = 1.0 / tau;
            }
        }
        let mut b = DVector::<f64>::zeros(n);
        b[0] = 1.0 / tau;
        let mut c = DMatrix::<f64>::zeros(1, n);
        c[(0, n - 1)] = 1.0;
        let ss = StateSpace {
            a,
            b,
            c,
            d: DVector::zeros(1),
        };
        let dt = 1e-3;
        let y = simulate_linear(&ss, &vec![1.0; 500], dt, &[0.0]).unwrap();
        for (k, v) in y[0].iter().enumerate() {
            let x = k as f64 * dt / tau;
            let mut sum = 0.0;
            let mut term = 1.0;
            for j in 0..n {
                if j > 0 {
                    term *= x / j as f64;
                }
                sum += term;
            }
            let want = 1.0 - (-x).exp() * sum;
            assert!((v - want).abs() < 1e-12, "k = {k}: {v} vs {want}");
        }
    }

    #[test]
    fn rejects_bad_inputs_with_their_numbers() {
        let ss = TransferFunction::new(&[1.0], &[1.0, 1.0])
            .unwrap()
            .to_state_space();
        let e = simulate_linear(&ss, &[0.0, f64::NAN], 0.5, &[0.0]).unwrap_err();
        assert_eq!(
            e.to_string(),
            "command sample 1 (t = 0.5 s) is not finite (NaN)"
        );
        let e = simulate_linear(&ss, &[0.0], 0.5, &[0.0, 0.0]).unwrap_err();
        assert_eq!(
            e.to_string(),
            "state-space dimensions disagree: 2 output delay(s) for 1 output(s)"
        );
        let mut wide = ss.clone();
        wide.d = DVector::zeros(2);
        let e = simulate_linear(&wide, &[0.0], 0.5, &[0.0]).unwrap_err();
        assert_eq!(
            e.to_string(),
            "state-space dimensions disagree: A is 1x1, B has 1 rows, C is 1x1, D has 2 rows"
        );
        let e = simulate_linear(&ss, &[0.0], 0.0, &[0.0]).unwrap_err();
        assert_eq!(
            e.to_string(),
            "linear simulation: dt_s must be positive and finite (got 0)"
        );
        let e = simulate_linear(&ss, &[0.0], 0.1, &[-1e-3]).unwrap_err();
        assert_eq!(
            e.to_string(),
            "linear simulation: output_delay_s must be non-negative and finite (got -0.001)"
        );
    }
}
