//! End-to-end tests of the fit against independent truths: analytic
//! responses, an exactly discretised sampled plant, Monte Carlo coverage,
//! finite differences.

use approx::assert_relative_eq;
use nalgebra::{Complex, DMatrix, DVector};

use super::*;
use crate::model::{LinearSpecimen, tf_x1_u};
use crate::simulate::Draws;

/// The bins of a 2048 Hz log with 8192-sample segments (0.25 Hz apart) in
/// the paper's 0.5-30 Hz band.
fn band_bins() -> Vec<f64> {
    (0..119).map(|k| 0.5 + 0.25 * k as f64).collect()
}

/// The response of `tf` (delay included) as a log shows it: its own, or
/// with a command held at `fs` its exact sampled response
/// (`lti::ZohSampled`, checked there against partial fractions and the
/// alias sum).
fn analytic(tf: &TransferFunction, freq: &[f64], fs: Option<f64>) -> Vec<Complex<f64>> {
    match fs {
        None => freq.iter().map(|&f| tf.freq_response(f)).collect(),
        Some(fs) => crate::lti::ZohSampled::new(tf, fs).response(freq),
    }
}

fn truth_params(tf: &TransferFunction) -> Vec<f64> {
    let mut p = tf.num.clone();
    p.extend_from_slice(&tf.den[1..]);
    p
}

fn paper_exp1_fourth_order() -> TransferFunction {
    // Eq. 17 with the paper's identified rig (Table 3) and the Exp1 specimen
    // (Table 2): m = 3.8 kg, c = 5 N s/m, k = 129,400 N/m.
    let rig = crate::model::PAPER_RIG;
    let specimen = LinearSpecimen::Sdof {
        mass_kg: 3.8,
        damping_ns_per_m: 5.0,
        stiffness_n_per_m: 129_400.0,
    };
    tf_x1_u(&rig, &specimen).unwrap()
}

fn options(tf: &TransferFunction, intersample: Intersample, delay: DelayPlan) -> FitOptions {
    FitOptions {
        numerator_order: tf.num.len() - 1,
        denominator_order: tf.order(),
        intersample,
        sample_rate_hz: 1000.0,
        delay,
        max_iterations: 200,
        sk_iterations: 10,
        independent_lag: 1,
    }
}

#[test]
fn recovers_the_papers_models_exactly_from_noise_free_data() {
    let models = [
        (
            "no specimen (Eq. 36)",
            TransferFunction::new(&[3060.0], &[1.0, 267.0, 3060.0]).unwrap(),
        ),
        (
            "spring k1 (Eq. 37)",
            TransferFunction::new(&[2703.0], &[1.0, 263.4, 3337.0]).unwrap(),
        ),
        ("Exp1 4th order (Eq. 17)", paper_exp1_fourth_order()),
    ];
    let freq = band_bins();
    for (name, plant) in &models {
        let cases = [
            ("plain", Intersample::None, DelayPlan::None, 0.0),
            (
                "hold 1 kHz",
                Intersample::SampleAndHold,
                DelayPlan::None,
                0.0,
            ),
            (
                "hold + fixed 1.5 ms",
                Intersample::SampleAndHold,
                DelayPlan::Fixed { delay_s: 0.0015 },
                0.0015,
            ),
            (
                "hold + fitted delay",
                Intersample::SampleAndHold,
                DelayPlan::Fit { max_s: 0.005 },
                0.0015,
            ),
        ];
        for (case, intersample, delay, tau) in cases {
            let truth = TransferFunction::with_delay(&plant.num, &plant.den, tau).unwrap();
            let fs = (intersample == Intersample::SampleAndHold).then_some(1000.0);
            let h = analytic(&truth, &freq, fs);
            // Variances 1e-6 |h|^2: weights like a 0.1 % noise level.
            let variance: Vec<f64> = h.iter().map(|h| 1e-6 * h.norm_sqr()).collect();
            let input = FitInput {
                freq_hz: &freq,
                h: &h,
                variance: &variance,
            };
            let fit = fit(&input, &options(plant, intersample, delay)).unwrap();
            let mut want = truth_params(plant);
            if matches!(delay, DelayPlan::Fit { .. }) {
                want.push(tau);
            }
            assert_eq!(fit.params.len(), want.len(), "{name}, {case}");
            for (got, w) in fit.params.iter().zip(want.iter()) {
                assert!(
                    (got - w).abs() <= 1e-8 * w.abs(),
                    "{name}, {case}: {:?} vs {want:?}",
                    fit.params
                );
            }
            assert!(fit.converged, "{name}, {case}: {}", fit.termination);
            assert!(fit.stable);
            assert_relative_eq!(fit.tf.delay_s, tau, epsilon = 1e-12);
            assert_relative_eq!(fit.fit_percent, 100.0, epsilon = 1e-6);
            assert!(
                fit.warnings.is_empty(),
                "{name}, {case}: {:?}",
                fit.warnings
            );
        }
    }
}

/// The response a sampled system really has when its input is held: the
/// plant discretised exactly under a zero-order hold (Franklin, Powell &
/// Workman, Digital Control, Sec. 4.3.3): [[Ad, Bd], [0, 1]] =
/// expm([[A, B], [0, 0]] T), then Gd(z) = C (zI - Ad)^-1 Bd + D at
/// z = exp(jwT). Aliasing is included, nothing is approximated.
fn zoh_sampled_response(tf: &TransferFunction, fs: f64, freq: &[f64]) -> Vec<Complex<f64>> {
    let ss = tf.to_state_space();
    let n = ss.order();
    let t = 1.0 / fs;
    let mut aug = DMatrix::<f64>::zeros(n + 1, n + 1);
    aug.view_mut((0, 0), (n, n)).copy_from(&(&ss.a * t));
    aug.view_mut((0, n), (n, 1)).copy_from(&(&ss.b * t));
    let e = aug.exp();
    let ad = e.view((0, 0), (n, n)).map(|v| Complex::new(v, 0.0));
    let bd: DVector<Complex<f64>> = e
        .view((0, n), (n, 1))
        .column(0)
        .map(|v| Complex::new(v, 0.0));
    freq.iter()
        .map(|&f| {
            let z = Complex::from_polar(1.0, 2.0 * std::f64::consts::PI * f * t);
            let m = DMatrix::<Complex<f64>>::identity(n, n) * z - &ad;
            let x = m.lu().solve(&bd).unwrap();
            let mut y = Complex::new(ss.d[0], 0.0);
            for j in 0..n {
                y += x[j] * ss.c[(0, j)];
            }
            y
        })
        .collect()
}

#[test]
fn ignoring_the_hold_biases_d1_and_modelling_it_removes_the_bias() {
    // At 1 kHz and at 200 Hz, where the aliases are 0.6 % of the response
    // at 30 Hz: the hold with its aliases gives the plant back exactly.
    let plant = TransferFunction::new(&[3060.0], &[1.0, 267.0, 3060.0]).unwrap();
    let freq = band_bins();
    for fs in [1000.0, 200.0] {
        let h = zoh_sampled_response(&plant, fs, &freq);
        let variance: Vec<f64> = h.iter().map(|h| 1e-6 * h.norm_sqr()).collect();
        let input = FitInput {
            freq_hz: &freq,
            h: &h,
            variance: &variance,
        };
        let mut opts = FitOptions::new(0, 2, fs);
        opts.intersample = Intersample::None;
        let naive = fit(&input, &opts).unwrap();
        let bias = naive.params[1] / 267.0 - 1.0;
        assert!(
            bias.abs() > 0.02,
            "{fs} Hz: d1 bias without the hold: {bias}"
        );

        opts.intersample = Intersample::SampleAndHold;
        let held = fit(&input, &opts).unwrap();
        for (got, want) in held.params.iter().zip([3060.0, 267.0, 3060.0]) {
            assert_relative_eq!(*got, want, max_relative = 1e-9);
        }
    }
}

#[test]
fn standard_deviations_are_honest_in_monte_carlo() {
    // 200 seeded repetitions of H_true + circular complex Gaussian noise with
    // a known per-bin variance (3 % of |H| in standard deviation). If the
    // covariance is right, |estimate - truth| < 2 std in ~95 % of runs and
    // the mean reported std matches the spread of the estimates.
    let plant = TransferFunction::new(&[3060.0], &[1.0, 267.0, 3060.0]).unwrap();
    let truth = [3060.0, 267.0, 3060.0];
    let fs = 2048.0;
    let freq = band_bins();
    let clean = analytic(&plant, &freq, Some(fs));
    let variance: Vec<f64> = clean.iter().map(|h| (0.03 * h.norm()).powi(2)).collect();
    let opts = FitOptions::new(0, 2, fs);
    let mut rng = Draws::new(20_180_398, "fit tests");
    let reps = 200;
    let mut estimates = vec![Vec::new(); 3];
    let mut stds = vec![Vec::new(); 3];
    let mut inside = [0_usize; 3];
    let mut chi2 = 0.0;
    for _ in 0..reps {
        let h: Vec<Complex<f64>> = clean
            .iter()
            .zip(variance.iter())
            .map(|(h, &v)| h + rng.complex_normal(v))
            .collect();
        let input = FitInput {
            freq_hz: &freq,
            h: &h,
            variance: &variance,
        };
        let f = fit(&input, &opts).unwrap();
        assert!(f.converged, "{}", f.termination);
        let cov = f.second_order_cov().unwrap();
        for k in 0..3 {
            assert_relative_eq!(cov[k][k].sqrt(), f.std[k], max_relative = 1e-12);
            estimates[k].push(f.params[k]);
            stds[k].push(f.std[k]);
            if (f.params[k] - truth[k]).abs() < 2.0 * f.std[k] {
                inside[k] += 1;
            }
        }
        chi2 += f.reduced_chi2;
    }
    // With the right variances chi2/(2N - p) averages 1 (its sd per run is
    // sqrt(2/235) = 0.09, so 0.05 over 200 runs is a loose bound).
    assert_relative_eq!(chi2 / reps as f64, 1.0, epsilon = 0.05);
    for k in 0..3 {
        let coverage = inside[k] as f64 / reps as f64;
        assert!(
            (0.90..=0.99).contains(&coverage),
            "parameter {k}: coverage {coverage}"
        );
        let mean = estimates[k].iter().sum::<f64>() / reps as f64;
        let empirical = (estimates[k].iter().map(|e| (e - mean).powi(2)).sum::<f64>()
            / (reps - 1) as f64)
            .sqrt();
        let reported = stds[k].iter().sum::<f64>() / reps as f64;
        assert_relative_eq!(reported, empirical, max_relative = 0.15);
        // The covariance predicted for this plan before any data (the
        // clean response at the truth, the same variances) is that spread
        // too: what the stiffness sensitivity relies on.
        let planned = predicted_covariance(
            &FitInput {
                freq_hz: &freq,
                h: &clean,
                variance: &variance,
            },
            &opts,
            &truth,
        )
        .unwrap();
        assert_relative_eq!(planned[(k, k)].sqrt(), empirical, max_relative = 0.15);
    }
}

#[test]
fn analytic_jacobian_matches_central_differences() {
    let mut rng = Draws::new(7, "fit tests");
    let shapes = [(0, 2, true), (1, 3, true), (0, 4, false), (2, 2, true)];
    for (m, n, fit_delay) in shapes {
        let shape = ModelShape {
            numerator_order: m,
            denominator_order: n,
            fit_delay,
        };
        let nb = 12;
        let problem = FrfProblem {
            shape,
            s: (0..nb)
                .map(|i| Complex::new(0.0, 0.1 + 0.4 * i as f64))
                .collect(),
            h: (0..nb).map(|_| rng.complex_normal(1.0)).collect(),
            known: (0..nb)
                .map(|_| Complex::from_polar(0.5 + rng.uniform(), -rng.uniform()))
                .collect(),
            weight: (0..nb).map(|_| 0.5 + rng.uniform()).collect(),
            projector: None,
            last: Default::default(),
        };
        for _ in 0..20 {
            let mut theta: Vec<f64> = (0..shape.n_rational())
                .map(|_| 0.5 + 2.0 * rng.uniform())
                .collect();
            if fit_delay {
                theta.push(2.0 * rng.uniform());
            }
            let jac = problem.jacobian_matrix(&theta);
            for k in 0..theta.len() {
                let step = 1e-6 * theta[k].abs().max(1.0);
                let (mut up, mut down) = (theta.clone(), theta.clone());
                up[k] += step;
                down[k] -= step;
                let fd = (problem.residuals(&up) - problem.residuals(&down)) / (2.0 * step);
                let scale = fd.amax().max(1e-3);
                for i in 0..fd.len() {
                    assert!(
                        (jac[(i, k)] - fd[i]).abs() <= 1e-6 * scale,
                        "shape {m}/{n} delay {fit_delay}, param {k}, row {i}: {} vs {}",
                        jac[(i, k)],
                        fd[i]
                    );
                }
            }
        }
    }
}

fn noisy_second_order(seed: u64, fs: f64) -> (Vec<f64>, Vec<Complex<f64>>, Vec<f64>) {
    let plant = TransferFunction::new(&[2703.0], &[1.0, 263.4, 3337.0]).unwrap();
    let freq = band_bins();
    let clean = analytic(&plant, &freq, Some(fs));
    let variance: Vec<f64> = clean.iter().map(|h| (0.02 * h.norm()).powi(2)).collect();
    let mut rng = Draws::new(seed, "fit tests");
    let h = clean
        .iter()
        .zip(variance.iter())
        .map(|(h, &v)| h + rng.complex_normal(v))
        .collect();
    (freq, h, variance)
}

#[test]
fn far_start_reaches_the_same_optimum_and_one_iteration_is_reported() {
    let fs = 2048.0;
    let (freq, h, variance) = noisy_second_order(11, fs);
    let input = FitInput {
        freq_hz: &freq,
        h: &h,
        variance: &variance,
    };
    let opts = FitOptions::new(0, 2, fs);
    let near = fit(&input, &opts).unwrap();
    assert!(near.converged);
    // Coefficients off by a factor of 3 either way.
    let far_start = [
        near.params[0] * 3.0,
        near.params[1] / 3.0,
        near.params[2] * 3.0,
    ];
    let far = fit_from(&input, &opts, &far_start).unwrap();
    assert!(far.converged, "{}", far.termination);
    assert_eq!(far.termination, "Solver converged");
    // The same optimum: apart by a negligible fraction of the uncertainty.
    for k in 0..3 {
        let gap = (far.params[k] - near.params[k]).abs();
        assert!(
            gap < 1e-3 * near.std[k],
            "{}: {} vs {} (std {})",
            near.param_names[k],
            far.params[k],
            near.params[k],
            near.std[k]
        );
    }
    // fit_percent as defined, recomputed from the fitted tf and the hold.
    let model = analytic(&far.tf, &freq, Some(fs));
    let mean = h.iter().sum::<Complex<f64>>() / h.len() as f64;
    let err: f64 = h.iter().zip(&model).map(|(a, b)| (a - b).norm_sqr()).sum();
    let spread: f64 = h.iter().map(|a| (a - mean).norm_sqr()).sum();
    assert_relative_eq!(
        far.fit_percent,
        100.0 * (1.0 - (err / spread).sqrt()),
        max_relative = 1e-9
    );

    let mut one = opts.clone();
    one.max_iterations = 1;
    let stopped = fit_from(&input, &one, &far_start).unwrap();
    assert!(!stopped.converged);
    assert_eq!(stopped.iterations, 1);
    assert_eq!(stopped.termination, "Maximum number of iterations reached");
    assert!(
        stopped
            .warnings
            .iter()
            .any(|w| w.contains("did not converge")),
        "{:?}",
        stopped.warnings
    );
}

#[test]
fn fitted_delay_from_noisy_data_is_within_its_uncertainty() {
    // A 2 ms sensor delay on top of the hold, fitted in [0, 10] ms.
    let fs = 2048.0;
    let plant = TransferFunction::with_delay(&[2703.0], &[1.0, 263.4, 3337.0], 0.002).unwrap();
    let freq = band_bins();
    let clean = analytic(&plant, &freq, Some(fs));
    let variance: Vec<f64> = clean.iter().map(|h| (0.01 * h.norm()).powi(2)).collect();
    let mut rng = Draws::new(3, "fit tests");
    let h: Vec<Complex<f64>> = clean
        .iter()
        .zip(variance.iter())
        .map(|(h, &v)| h + rng.complex_normal(v))
        .collect();
    let input = FitInput {
        freq_hz: &freq,
        h: &h,
        variance: &variance,
    };
    let mut opts = FitOptions::new(0, 2, fs);
    opts.delay = DelayPlan::Fit { max_s: 0.01 };
    let f = fit(&input, &opts).unwrap();
    assert!(f.converged);
    assert_eq!(f.param_names, ["n0", "d1", "d0", "tau_s"]);
    for (k, want) in [2703.0, 263.4, 3337.0, 0.002].iter().enumerate() {
        assert!(
            (f.params[k] - want).abs() < 4.0 * f.std[k],
            "{}: {} vs {want} (std {})",
            f.param_names[k],
            f.params[k],
            f.std[k]
        );
    }
    assert_relative_eq!(f.tf.delay_s, f.params[3]);
    // The marginal block is the leading 3x3 of the full covariance.
    let c = f.second_order_cov().unwrap();
    assert_relative_eq!(c[0][2], f.covariance[(0, 2)]);
}

#[test]
fn unstable_plant_is_fitted_and_flagged() {
    // 1/(s^2 - 10 s + 3000): poles 5 +/- j 54.5 rad/s.
    let plant = TransferFunction::new(&[1.0], &[1.0, -10.0, 3000.0]).unwrap();
    let freq = band_bins();
    let h = analytic(&plant, &freq, None);
    let variance: Vec<f64> = h.iter().map(|h| 1e-6 * h.norm_sqr()).collect();
    let input = FitInput {
        freq_hz: &freq,
        h: &h,
        variance: &variance,
    };
    let mut opts = FitOptions::new(0, 2, 1000.0);
    opts.intersample = Intersample::None;
    let f = fit(&input, &opts).unwrap();
    for (got, want) in f.params.iter().zip([1.0, -10.0, 3000.0]) {
        assert_relative_eq!(*got, want, max_relative = 1e-8);
    }
    assert!(!f.stable);
    assert!(
        f.warnings.iter().any(|w| w.contains("unstable")),
        "{:?}",
        f.warnings
    );
}

#[test]
fn second_order_cov_only_for_the_papers_orders() {
    let plant = TransferFunction::new(&[2.0, 3060.0], &[1.0, 267.0, 3060.0]).unwrap();
    let freq = band_bins();
    let h = analytic(&plant, &freq, None);
    let variance = vec![1e-6; freq.len()];
    let input = FitInput {
        freq_hz: &freq,
        h: &h,
        variance: &variance,
    };
    let mut opts = FitOptions::new(1, 2, 1000.0);
    opts.intersample = Intersample::None;
    let f = fit(&input, &opts).unwrap();
    assert_eq!(f.param_names, ["n1", "n0", "d1", "d0"]);
    assert!(f.second_order_cov().is_none());
}

fn err(freq: &[f64], h: &[Complex<f64>], variance: &[f64], opts: &FitOptions) -> String {
    let input = FitInput {
        freq_hz: freq,
        h,
        variance,
    };
    fit(&input, opts).unwrap_err().to_string()
}

#[test]
fn bad_inputs_give_errors_that_say_what_and_where() {
    let one = Complex::new(1.0, 0.0);
    let opts = FitOptions::new(0, 2, 1000.0);
    let f3 = [1.0, 2.0, 3.0];
    let h3 = [one; 3];
    let v3 = [1.0; 3];

    let mut o = opts.clone();
    o.denominator_order = 0;
    o.numerator_order = 0;
    assert_eq!(
        err(&f3, &h3, &v3, &o),
        "invalid fit option denominator_order: must be at least 1 (got 0)"
    );
    let mut o = opts.clone();
    o.numerator_order = 3;
    assert_eq!(
        err(&f3, &h3, &v3, &o),
        "invalid fit option numerator_order: must not exceed denominator_order (got 3 > 2)"
    );
    let mut o = opts.clone();
    o.sample_rate_hz = 0.0;
    assert_eq!(
        err(&f3, &h3, &v3, &o),
        "invalid fit option sample_rate_hz: must be positive for a sample-and-hold command (got 0 Hz)"
    );
    let mut o = opts.clone();
    o.delay = DelayPlan::Fit { max_s: -1.0 };
    assert_eq!(
        err(&f3, &h3, &v3, &o),
        "invalid fit option delay: the bound on a fitted delay must be positive (got -1 s)"
    );
    assert_eq!(
        err(&f3, &h3[..2], &v3, &opts),
        "input lengths differ: 3 frequencies, 2 responses, 3 variances"
    );
    assert_eq!(
        err(&f3, &[one, Complex::new(f64::NAN, 0.0), one], &v3, &opts),
        "h[1] is not finite (NaN+0i)"
    );
    assert_eq!(
        err(
            &f3,
            &[Complex::new(f64::INFINITY, -2.5), one, one],
            &v3,
            &opts
        ),
        "h[0] is not finite (inf-2.5i)"
    );
    assert_eq!(
        err(&[1.0, f64::INFINITY, 3.0], &h3, &v3, &opts),
        "freq_hz[1] is not finite (inf)"
    );
    assert_eq!(
        err(&f3, &h3, &[1.0, 1.0, f64::NEG_INFINITY], &opts),
        "variance[2] is not finite (-inf)"
    );
    assert_eq!(
        err(&[0.0, 2.0, 3.0], &h3, &v3, &opts),
        "freq_hz[0] must be positive (got 0 Hz)"
    );
    assert_eq!(
        err(&f3, &h3, &[1.0, 1.0, -1.0], &opts),
        "variance[2] must be positive (got -1)"
    );
    assert_eq!(
        err(&[1.0, 2.0, 600.0], &h3, &v3, &opts),
        "freq_hz[2] = 600 Hz is above the Nyquist frequency 500 Hz of the command's sample-and-hold"
    );
    assert_eq!(
        err(&[1.0], &[one], &[1.0], &opts),
        "1 bins give 2 real equations, which does not exceed the 3 parameters (n0, d1, d0); at least 2 bins are needed"
    );
    // Three bins at one frequency carry two real equations' worth of
    // information: three parameters cannot all be identified.
    let same = [5.0; 3];
    let h_same = [Complex::new(0.2, -0.7); 3];
    let msg = err(&same, &h_same, &v3, &opts);
    assert!(
        msg.starts_with("parameter ")
            && msg.contains(
                "is not identifiable from these 3 bins: the Levy least-squares matrix is singular"
            ),
        "{msg}"
    );

    // A start whose squared residuals overflow: the optimiser cannot begin.
    let input = FitInput {
        freq_hz: &f3,
        h: &h3,
        variance: &v3,
    };
    let msg = fit_from(&input, &opts, &[1e300, 1.0, 1.0])
        .unwrap_err()
        .to_string();
    assert!(
        msg.starts_with("the optimiser failed:") && msg.contains("cost at the starting point is"),
        "{msg}"
    );
    let msg = fit_from(&input, &opts, &[1.0, 0.0])
        .unwrap_err()
        .to_string();
    assert_eq!(
        msg,
        "invalid fit option start: needs 3 values (n0, d1, d0), got 2"
    );
}

#[test]
fn covariance_is_the_scaled_inverse_normal_matrix() {
    // Independent route: explicit inverse of J^T J, on a Jacobian whose
    // columns differ in scale by 1e6 (as unscaled coefficients would).
    let mut rng = Draws::new(99, "fit tests");
    let jac = DMatrix::from_fn(40, 3, |_, j| rng.normal() * 1e3_f64.powi(j as i32));
    let cov = covariance(&jac, 2.5).unwrap();
    let want = (jac.transpose() * &jac).try_inverse().unwrap() * 2.5;
    for i in 0..3 {
        for j in 0..3 {
            let scale = (want[(i, i)] * want[(j, j)]).sqrt();
            assert!((cov[(i, j)] - want[(i, j)]).abs() < 1e-10 * scale);
        }
    }
    // A column the residuals do not depend on is named.
    let mut singular = jac.clone();
    singular.column_mut(1).fill(0.0);
    assert_eq!(covariance(&singular, 1.0).unwrap_err().column, 1);
}

#[test]
fn covariance_from_the_normal_matrix_is_that_of_j_where_it_answers() {
    // The same 1e6-spread columns: J^T J alone gives the covariance QR of J
    // gives, to 1e-10 of the stds' scale.
    let mut rng = Draws::new(7, "fit tests");
    let jac = DMatrix::from_fn(40, 3, |_, j| rng.normal() * 1e3_f64.powi(j as i32));
    let a = jac.transpose() * &jac;
    let from_normal = covariance_from_normal(&a, 2.5).unwrap();
    let from_j = covariance(&jac, 2.5).unwrap();
    for i in 0..3 {
        for j in 0..3 {
            let scale = (from_j[(i, i)] * from_j[(j, j)]).sqrt();
            assert!((from_normal[(i, j)] - from_j[(i, j)]).abs() < 1e-10 * scale);
        }
    }
    // Column 1 replaced by column 0 turned 1e-5 towards a fresh random
    // direction: the scaled J's condition number is some 1e5, which QR of
    // J still resolves, but J^T J's is some 1e10, past
    // NORMAL_CONDITION_MAX: the normal matrix declines, so the caller
    // forms J.
    let mut close = jac.clone();
    let c0 = close.column(0).clone_owned();
    let fresh = DVector::from_fn(40, |_, _| rng.normal());
    close.set_column(1, &(&c0 + &fresh * (1e-5 * c0.norm() / fresh.norm())));
    assert!(covariance(&close, 1.0).is_ok());
    assert!(covariance_from_normal(&(close.transpose() * &close), 1.0).is_none());
    // A column the residuals do not depend on: not positive definite.
    let mut singular = a.clone();
    singular.row_mut(1).fill(0.0);
    singular.column_mut(1).fill(0.0);
    assert!(covariance_from_normal(&singular, 1.0).is_none());
}

#[test]
fn unidentifiable_parameter_at_the_optimum_is_named() {
    // fit_from skips Levy, so three bins at one frequency reach the
    // Jacobian check: damped steps still run, but J^T W J is singular there.
    let opts = FitOptions::new(0, 2, 1000.0);
    let same = [5.0; 3];
    let h = [Complex::new(0.2, -0.7); 3];
    let v = [1.0; 3];
    let input = FitInput {
        freq_hz: &same,
        h: &h,
        variance: &v,
    };
    let msg = fit_from(&input, &opts, &[3000.0, 250.0, 3000.0])
        .unwrap_err()
        .to_string();
    assert!(
        msg.starts_with("parameter ")
            && msg.contains("is not identifiable from these 3 bins: the Jacobian at the optimum (J^T W J) is singular"),
        "{msg}"
    );
}

#[test]
fn a_delay_fitted_at_its_bound_is_reported() {
    // No delay in the data: the best delay in [0, 5] ms is 0, on the bound.
    let plant = TransferFunction::new(&[3060.0], &[1.0, 267.0, 3060.0]).unwrap();
    let freq = band_bins();
    let h = analytic(&plant, &freq, Some(1000.0));
    let variance: Vec<f64> = h.iter().map(|h| 1e-6 * h.norm_sqr()).collect();
    let input = FitInput {
        freq_hz: &freq,
        h: &h,
        variance: &variance,
    };
    let mut opts = FitOptions::new(0, 2, 1000.0);
    opts.delay = DelayPlan::Fit { max_s: 0.005 };
    let f = fit(&input, &opts).unwrap();
    assert!(f.params[3].abs() < 1e-12, "tau = {}", f.params[3]);
    for (got, want) in f.params.iter().zip([3060.0, 267.0, 3060.0]) {
        assert_relative_eq!(*got, want, max_relative = 1e-8);
    }
    assert!(
        f.warnings
            .iter()
            .any(|w| w.contains("at a bound of [0, 0.005] s")),
        "{:?}",
        f.warnings
    );
}

#[test]
fn the_sandwich_covers_the_mean_of_correlated_errors() {
    // y_i = mu + e_i, e_i = a_i + 0.6 a_{i-1} (an MA(1), a_i ~ N(0, 1)),
    // 400 values in each of 2,000 series. The mean's variance is
    // (1 + 0.6)^2 / n to O(1/n^2); the plain least-squares variance
    // (1 + 0.6^2) / n is 1.37 times too small in std. The sandwich over one
    // lag (reach 1) must state the right std: the scaled errors of the
    // 2,000 means spread 1 (within 0.05, 2.2 standard errors) and 95 %
    // (within 1.5 %) fall within 2 stds.
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    let (n, theta) = (400, 0.6);
    let normal = Normal::new(0.0, 1.0).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let position: Vec<(usize, f64)> = (0..n).map(|i| (0, i as f64)).collect();
    let a_inv = DMatrix::from_element(1, 1, 1.0 / n as f64);
    let (mut z, mut plain) = (Vec::new(), Vec::new());
    for _ in 0..2000 {
        let a: Vec<f64> = (0..=n).map(|_| normal.sample(&mut rng)).collect();
        let y: Vec<f64> = (0..n).map(|i| a[i + 1] + theta * a[i]).collect();
        let mean = y.iter().sum::<f64>() / n as f64;
        let scores = DMatrix::from_fn(n, 1, |i, _| y[i] - mean);
        let cov = correlated_covariance(&scores, &position, &[1.0], &a_inv, n, n - 1);
        let s2 = y.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
        z.push(mean / cov[(0, 0)].sqrt());
        plain.push(mean / (s2 / n as f64).sqrt());
    }
    let spread = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    let within = z.iter().filter(|v| v.abs() <= 2.0).count() as f64 / z.len() as f64;
    assert!(
        (spread(&z) - 1.0).abs() < 0.05,
        "sandwich spread {}",
        spread(&z)
    );
    assert!((within - 0.95).abs() < 0.015, "within 2 stds {within}");
    let ratio = spread(&plain) / spread(&z);
    assert!((ratio - 1.6 / 1.36f64.sqrt()).abs() < 0.06, "plain {ratio}");
}

/// The covariance from J's row blocks, each stacked on the triangle so
/// far, against J factored whole: a tall J with columns of scales 1e-6 to
/// 1e6, in blocks of uneven sizes (the first smaller than its columns);
/// and a J with a column of zeros, named as the whole J names it.
#[test]
fn the_covariance_from_blocks_is_the_whole_jacobian_s() {
    let (n, p) = (997, 5);
    let scales = [1e-6, 1.0, 3e2, 1e6, 0.5];
    let jac = DMatrix::from_fn(n, p, |i, j| {
        let t = (i * 7 + j * 13) as f64;
        scales[j] * ((0.37 * t).sin() + 0.2 * (1.3 * t * (j + 1) as f64).cos())
    });
    let cuts = [0, 3, 200, 201, 640, n];
    let blocks = |jac: &DMatrix<f64>| {
        let jac = jac.clone();
        move |emit: &mut dyn FnMut(DMatrix<f64>)| {
            for w in cuts.windows(2) {
                emit(jac.rows(w[0], w[1] - w[0]).into_owned());
            }
        }
    };
    let whole = covariance(&jac, 2.5).unwrap();
    let streamed = covariance_streamed(p, blocks(&jac), 2.5).unwrap();
    for i in 0..p {
        for j in 0..p {
            let scale = (whole[(i, i)] * whole[(j, j)]).sqrt();
            assert!(
                (streamed[(i, j)] - whole[(i, j)]).abs() <= 1e-10 * scale,
                "({i}, {j}): {} against {}",
                streamed[(i, j)],
                whole[(i, j)]
            );
        }
    }
    let mut flat = jac.clone();
    flat.column_mut(3).fill(0.0);
    assert_eq!(
        covariance_streamed(p, blocks(&flat), 1.0)
            .unwrap_err()
            .column,
        covariance(&flat, 1.0).unwrap_err().column
    );
}
