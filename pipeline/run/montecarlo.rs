//! The stiffness sensitivity by Monte Carlo (paper Sec. 2.3, issue 13
//! part 2): at each stiffness, a no-specimen run and a spring run simulated
//! from the identified rig (Eq. 10, exactly: zero-order hold and the
//! campaign's delay, `simulate::discrete`), driven by the campaign's own
//! measured command, their displacement read with white noise of the level
//! the campaign's FRF variance implies and rounded to its converter's grid;
//! each pair identified with the campaign's own FRF and fit settings,
//! refused as `servoid run` refuses a run (too few bins, unstable, not
//! converged), and Eqs. 18-20. The bias and spread of beta1, a1b0, a2 and
//! a3 against k.
//!
//! Deterministic whatever the thread count: each (stiffness, seed) draws
//! its noise from its own ChaCha stream, and the results are gathered in
//! grid order. The noiseless responses are simulated once per stiffness
//! (and once for the no-specimen run) and shared by the seeds: the noise is
//! all that differs between draws.

use rand_distr::{Distribution, Normal};
use rayon::prelude::*;

use super::acquire::{FitData, bins_needed, fit_options};
use crate::fit::fit;
use crate::frf;
use crate::identify::{SecondOrder, SpringRun, TfEstimate, identify_rig};
use crate::manifest::IdentificationPlan;
use crate::model::{LinearSpecimen, RigParams, tf_x1_u};
use crate::sensitivity::montecarlo::{MonteCarloPoint, point};
use crate::simulate::{discrete::simulate_linear, seeded_rng};

/// What the simulated runs are made of.
pub struct McInput<'a> {
    pub rig: RigParams,
    /// The command (m) every simulated run is driven by.
    pub command_m: &'a [f64],
    pub sample_rate_hz: f64,
    /// Std of the displacement noise (m), white.
    pub noise_rms_m: f64,
    /// The displacement converter's step (m): each simulated reading,
    /// noise included, is rounded to a multiple of it. None: not rounded.
    pub step_m: Option<f64>,
    /// Pure delay from command to displacement (s), as the campaign's
    /// no-specimen fit found it.
    pub delay_s: f64,
    /// The campaign's FRF and fit settings, band and coherence limit.
    pub ident: &'a IdentificationPlan,
    /// Base seed of every draw.
    pub seed: u64,
}

/// The Monte Carlo over `stiffnesses` with `seeds` seeds each.
pub fn monte_carlo(input: &McInput<'_>, stiffnesses: &[f64], seeds: u64) -> Vec<MonteCarloPoint> {
    let truth = [
        input.rig.beta1_per_s,
        input.rig.a1b0_n_per_m_s2,
        input.rig.a2_n_per_m,
        input.rig.a3_per_s,
    ];
    let clean_none = clean(input, &LinearSpecimen::None);
    stiffnesses
        .iter()
        .enumerate()
        .map(|(i, &k)| {
            let clean_k = clean(
                input,
                &LinearSpecimen::Spring {
                    stiffness_n_per_m: k,
                },
            );
            let outcomes: Vec<Result<[f64; 4], String>> = (0..seeds)
                .into_par_iter()
                .map(|s| match (&clean_none, &clean_k) {
                    (Ok(none), Ok(spring)) => identify_once(input, none, spring, k, i, s),
                    (Err(e), _) | (_, Err(e)) => Err(e.clone()),
                })
                .collect();
            point(k, &outcomes, truth)
        })
        .collect()
}

/// The noiseless displacement of the rig with `spec`.
fn clean(input: &McInput<'_>, spec: &LinearSpecimen) -> Result<Vec<f64>, String> {
    let ss = tf_x1_u(&input.rig, spec)
        .map_err(|e| format!("the rig's model leaves f64's range: {e}"))?
        .to_state_space();
    simulate_linear(
        &ss,
        input.command_m,
        1.0 / input.sample_rate_hz,
        &[input.delay_s.max(0.0)],
    )
    .map(|mut y| y.remove(0))
    .map_err(|e| format!("the simulation failed: {e}"))
}

/// One identification: the two noiseless responses read with noise from
/// stream (i, seed), fitted, and Eqs. 18-20.
fn identify_once(
    input: &McInput<'_>,
    clean_none: &[f64],
    clean_spring: &[f64],
    k: f64,
    i: usize,
    seed: u64,
) -> Result<[f64; 4], String> {
    let fs = input.sample_rate_hz;
    let ident = input.ident;
    let run = |clean: &[f64], label: &str| -> Result<TfEstimate, String> {
        let mut rng = seeded_rng(input.seed, &format!("mc/{i}/{seed}/{label}"));
        let noise =
            Normal::new(0.0, input.noise_rms_m).map_err(|e| format!("the noise level: {e}"))?;
        let y: Vec<f64> = clean
            .iter()
            .map(|v| {
                let read = v + noise.sample(&mut rng);
                match input.step_m {
                    Some(q) => (read / q).round() * q,
                    None => read,
                }
            })
            .collect();
        let h = frf::estimate(input.command_m, &y, fs, &ident.frf)
            .map_err(|e| format!("the FRF failed: {e}"))?;
        let mask = frf::band_mask(&h, ident.band_hz, ident.coherence_min);
        let data = FitData::of(&h, &mask);
        let opts = fit_options(ident, fs);
        // As acquire refuses a run: too few bins for the model.
        if mask.iter().filter(|m| **m).count() < bins_needed(ident) {
            return Err("too few bins pass the coherence limit".into());
        }
        let f = fit(&data.input(), &opts).map_err(|_| "the fit failed".to_string())?;
        if !f.stable {
            return Err("an unstable fit".into());
        }
        if !f.converged {
            return Err("a fit that did not converge".into());
        }
        Ok(TfEstimate {
            run: label.to_string(),
            p_gain: input.rig.p_gain,
            tf: SecondOrder::from_tf(&f.tf).map_err(|_| "a fit that is not second order")?,
            cov: f.second_order_cov(),
        })
    };
    let no_spec = run(clean_none, "no-specimen")?;
    let spring = run(clean_spring, "spring")?;
    let id = identify_rig(
        &[no_spec],
        &[SpringRun {
            stiffness_n_per_m: k,
            estimate: spring,
        }],
    )
    .map_err(|_| "Eqs. 18-20 have no physical solution".to_string())?;
    Ok([id.beta1.value, id.a1b0.value, id.a2.value, id.a3.value])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::{DelayPlan, Intersample};
    use crate::frf::{Detrend, Estimator, FrfPlan, Window};
    use crate::sensitivity::{CoefficientNoise, NoiseProfile, stiffness_sweep};

    /// A linear chirp 0.5-40 Hz over 20 s at 1 kHz, 3 mm, with a second of
    /// rest either side (so the record holds the whole response: no
    /// transient leaks into the FRF).
    fn chirp() -> Vec<f64> {
        let fs = 1000.0;
        let (f0, f1, t1) = (0.5, 40.0, 20.0);
        let rest = vec![0.0; 1000];
        let sweep = (0..20_000).map(|i| {
            let t = i as f64 / fs;
            0.003 * (2.0 * std::f64::consts::PI * (f0 * t + 0.5 * (f1 - f0) / t1 * t * t)).sin()
        });
        rest.iter()
            .copied()
            .chain(sweep)
            .chain(rest.iter().copied())
            .collect()
    }

    /// The paper's rig driven by `u` at 1 kHz with 2 um of noise.
    fn paper_input<'a>(u: &'a [f64], ident: &'a IdentificationPlan) -> McInput<'a> {
        McInput {
            rig: crate::model::PAPER_RIG,
            command_m: u,
            sample_rate_hz: 1000.0,
            noise_rms_m: 2e-6,
            step_m: None,
            delay_s: 0.0,
            ident,
            seed: 0,
        }
    }

    fn ident() -> IdentificationPlan {
        IdentificationPlan {
            band_hz: (0.5, 30.0),
            coherence_min: 0.0,
            frf: FrfPlan {
                estimator: Estimator::Etfe,
                segment_length: 4096,
                overlap: 0.5,
                window: Window::Rectangular,
                detrend: Detrend::Mean,
            },
            intersample: Intersample::SampleAndHold,
            delay: DelayPlan::None,
            numerator_order: 0,
            denominator_order: 2,
            trim_to_excitation: false,
        }
    }

    /// Where the noise is small, the spread of 400 seeds' identifications
    /// is what the analytic sweep predicts from one noisy run's FRF
    /// variance: within 10 % (the sample std of 400 has a 3.5 % error of
    /// its own), and the bias is well inside the spread.
    #[test]
    fn the_spread_is_the_analytic_prediction_where_noise_is_small() {
        let u = chirp();
        let ident = ident();
        let input = paper_input(&u, &ident);
        let rig = input.rig;
        let ks = [5e4, 1.2e5, 5e5];
        let mc = monte_carlo(&input, &ks, 400);

        // The analytic side: the FRF variance of one noisy no-specimen run.
        let ss = tf_x1_u(&rig, &LinearSpecimen::None)
            .unwrap()
            .to_state_space();
        let mut y = simulate_linear(&ss, &u, 1e-3, &[0.0]).unwrap().remove(0);
        let mut rng = seeded_rng(99, "profile");
        let noise = Normal::new(0.0, 2e-6).unwrap();
        for v in &mut y {
            *v += noise.sample(&mut rng);
        }
        let h = frf::estimate(&u, &y, 1000.0, &ident.frf).unwrap();
        let data = FitData::of(&h, &frf::band_mask(&h, ident.band_hz, 0.0));
        let profile = NoiseProfile {
            run: "no-specimen".into(),
            freq_hz: data.freq_hz,
            variance: data.variance,
            sample_rate_hz: 1000.0,
            delay_s: 0.0,
            white_noise: None,
            displacement_step_m: None,
            log_sha256: String::new(),
        };
        let opts = fit_options(&ident, 1000.0);
        for p in &mc {
            let k = p.stiffness_n_per_m;
            let sweep = stiffness_sweep(
                &rig,
                (k, 1.0001 * k),
                2,
                CoefficientNoise::Measured {
                    profile: &profile,
                    opts: &opts,
                },
            )
            .unwrap();
            let analytic = [
                sweep.rel_std_beta1[0],
                sweep.rel_std_a1b0[0],
                sweep.rel_std_a2[0],
                sweep.rel_std_a3[0],
            ];
            assert_eq!(p.failed, 0);
            let names = ["beta1", "a1b0", "a2", "a3"];
            for (j, (name, an)) in names.iter().zip(analytic).enumerate() {
                let (std, bias) = (
                    p.rel_std.unwrap().to_array()[j],
                    p.rel_bias.unwrap().to_array()[j],
                );
                assert!(
                    (std / an - 1.0).abs() < 0.10,
                    "k = {k}, {name}: MC {std:.3e} vs analytic {an:.3e}"
                );
                assert!(
                    bias.abs() < 0.5 * std + 1e-4,
                    "k = {k}, {name}: bias {bias:.2e}"
                );
            }
        }
    }

    /// The same numbers on one thread as on four.
    #[test]
    fn the_thread_count_changes_nothing() {
        let u = chirp();
        let ident = ident();
        let input = paper_input(&u, &ident);
        let run = |threads| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| monte_carlo(&input, &[8e4, 2e5], 6))
        };
        assert_eq!(run(1), run(4));
    }
}
