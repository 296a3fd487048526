//! The stiffness sensitivity's Monte Carlo draws (paper Sec. 2.3): at each
//! stiffness, a no-specimen run and a spring run simulated from the
//! identified rig (Eq. 10 exactly: zero-order hold and the campaign's
//! delay), driven by the campaign's measured command, read with white noise
//! of the level its FRF variance implies and rounded to its converter's
//! grid; each pair identified as `servoid run` identifies a run
//! (`identify::fit_run`), then Eqs. 18-20. `monte_carlo` gives the bias and
//! spread of beta1, a1b0, a2 and a3 against k.
//!
//! Where the FRF settings allow (`McInput::in_frequency_domain`) a reading
//! is drawn in the frequency domain (`frf::synthesis`); elsewhere it is
//! simulated sample by sample. Each (stiffness, seed) has its own ChaCha
//! stream: the same bits whatever the thread count. What it does:
//! docs/methods.md, "What it does", step 7; the draws: "The Monte Carlo's
//! draws".

use rand_distr::{Distribution, Normal, StandardNormal};
use rayon::prelude::*;

use super::montecarlo::{MonteCarloPoint, point};
use crate::frf::{self, EtfeSpectra, EtfeSynthesis, Frf, FrfPlan};
use crate::identify::{
    self, IdentificationPlan, RunTfError, SecondOrder, SpringRun, TfEstimate, fit_run, identify_rig,
};
use crate::lti::LtiError;
use crate::model::{LinearSpecimen, RigParams, tf_x1_u};
use crate::simulate::{SimError, discrete::simulate_linear, seeded_rng};

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
    /// The campaign's fit settings, band and coherence limit.
    pub ident: &'a IdentificationPlan,
    /// The FRF settings of the run whose command is replayed.
    pub frf: &'a FrfPlan,
    /// Base seed of every draw.
    pub seed: u64,
}

/// Why one draw of the Monte Carlo gave no rig: each is counted by its
/// [`DrawError::kind`] in the point's failures.
#[derive(Debug, thiserror::Error)]
pub enum DrawError {
    #[error("the rig's model leaves f64's range: {0}")]
    Model(#[from] LtiError),
    #[error("the simulation failed: {0}")]
    Simulation(#[from] SimError),
    #[error("the noise level: {0}")]
    Noise(#[from] rand_distr::NormalError),
    #[error("the {run} run: {source}")]
    Run {
        run: &'static str,
        #[source]
        source: RunTfError,
    },
    #[error("the {run} run's fit is not second order: {source}")]
    NotSecondOrder {
        run: &'static str,
        #[source]
        source: identify::IdentifyError,
    },
    #[error("Eqs. 18-20 have no physical solution: {0}")]
    Rig(identify::IdentifyError),
}

impl DrawError {
    /// What kind of failure this is, in a few words.
    pub fn kind(&self) -> &'static str {
        match self {
            DrawError::Model(_) => "the rig's model leaves f64's range",
            DrawError::Simulation(_) => "the simulation failed",
            DrawError::Noise(_) => "the noise level",
            DrawError::Run { source, .. } => source.kind(),
            DrawError::NotSecondOrder { .. } => "a fit that is not second order",
            DrawError::Rig(_) => "Eqs. 18-20 have no physical solution",
        }
    }
}

/// How the simulated runs' FRFs are made: in the frequency domain where
/// that is exact for the campaign's estimator (the ETFE with a rectangular
/// window; see `frf::synthesis`), else by simulating each reading in time.
enum Reading {
    /// The command's transforms, and the std of the white noise a reading
    /// adds (the converter's rounding counted as white noise of q^2/12).
    Spectra {
        synthesis: EtfeSynthesis,
        sigma: f64,
    },
    Samples,
}

impl McInput<'_> {
    /// Whether the draws are read in the frequency domain, where that is
    /// exact: a plan `EtfeSynthesis::check_plan` accepts (the ETFE with a
    /// rectangular window and the mean or nothing taken out), and a
    /// converter step no coarser than
    /// the noise. Rounding to a step q is then white noise of variance
    /// q^2/12 uncorrelated with the signal (Widrow & Kollar, *Quantization
    /// Noise*, 2008, Ch. 4-5: with Gaussian noise of std sigma >= q ahead
    /// of the quantiser, the rounding error departs from that model by
    /// terms of order exp(-2 pi^2 sigma^2 / q^2) < 1e-8).
    pub fn in_frequency_domain(&self) -> bool {
        EtfeSynthesis::check_plan(self.frf).is_ok()
            && self.step_m.is_none_or(|q| self.noise_rms_m >= q)
    }
}

impl Reading {
    fn of(input: &McInput<'_>) -> Self {
        if !input.in_frequency_domain() {
            return Reading::Samples;
        }
        let sigma = input.noise_rms_m;
        match EtfeSynthesis::new(
            input.command_m,
            input.sample_rate_hz,
            input.frf,
            input.ident.band_hz.1,
        ) {
            Ok(synthesis) => Reading::Spectra {
                synthesis,
                sigma: (sigma * sigma + input.step_m.map_or(0.0, |q| q * q / 12.0)).sqrt(),
            },
            // What the synthesis refuses (a record shorter than a segment),
            // the time-domain FRF refuses too, draw by draw, with its reason.
            Err(_) => Reading::Samples,
        }
    }
}

/// A noiseless response: its samples, and its transforms when the draws
/// read it in the frequency domain.
struct Clean {
    samples: Vec<f64>,
    spectra: Option<EtfeSpectra>,
}

/// The Monte Carlo over `stiffnesses` with `seeds` seeds each.
pub fn monte_carlo(input: &McInput<'_>, stiffnesses: &[f64], seeds: u64) -> Vec<MonteCarloPoint> {
    monte_carlo_reading(input, &Reading::of(input), stiffnesses, seeds)
}

/// The Monte Carlo with its runs read as `reading` says.
fn monte_carlo_reading(
    input: &McInput<'_>,
    reading: &Reading,
    stiffnesses: &[f64],
    seeds: u64,
) -> Vec<MonteCarloPoint> {
    let truth = [
        input.rig.beta1_per_s,
        input.rig.a1b0_n_per_m_s2,
        input.rig.a2_n_per_m,
        input.rig.a3_per_s,
    ];
    let clean_none = clean(input, reading, &LinearSpecimen::None);
    // The stiffnesses side by side too: each one's noiseless response is
    // simulated and transformed once, while other stiffnesses' draws run.
    stiffnesses
        .par_iter()
        .enumerate()
        .with_max_len(1)
        .map(|(i, &k)| {
            let spring = LinearSpecimen::Spring {
                stiffness_n_per_m: k,
            };
            let kinds: Vec<Result<[f64; 4], &'static str>> =
                match (&clean_none, &clean(input, reading, &spring)) {
                    (Ok(none), Ok(spring)) => seeds_at(input, reading, (none, spring), k, i, seeds),
                    (Err(e), _) | (_, Err(e)) => vec![Err(e.kind()); seeds as usize],
                };
            point(k, &kinds, truth)
        })
        .collect()
}

/// The noiseless displacement of the rig with `spec`, as `reading` reads it.
fn clean(
    input: &McInput<'_>,
    reading: &Reading,
    spec: &LinearSpecimen,
) -> Result<Clean, DrawError> {
    let ss = tf_x1_u(&input.rig, spec)?.to_state_space();
    let samples = simulate_linear(
        &ss,
        input.command_m,
        1.0 / input.sample_rate_hz,
        &[input.delay_s.max(0.0)],
    )?
    .remove(0);
    let spectra = match reading {
        Reading::Spectra { synthesis, .. } => {
            Some(synthesis.spectra_of(&samples).map_err(|e| DrawError::Run {
                run: "noiseless",
                source: RunTfError::Frf(e),
            })?)
        }
        Reading::Samples => None,
    };
    Ok(Clean { samples, spectra })
}

/// The identifications of `seeds` seeds at the stiffness `k` (the `i`-th).
/// Seed 0's fits start from the linear least-squares start, as a run's do;
/// every other seed's start from seed 0's fit of the same run, which is
/// within the noise's spread of its own optimum: the same optimum in fewer
/// steps. Seed 0 runs first, so each seed's result does not depend on the
/// thread count.
fn seeds_at(
    input: &McInput<'_>,
    reading: &Reading,
    clean: (&Clean, &Clean),
    k: f64,
    i: usize,
    seeds: u64,
) -> Vec<Result<[f64; 4], &'static str>> {
    if seeds == 0 {
        return Vec::new();
    }
    let first = identify_once(input, reading, clean, k, (i, 0), None);
    let starts = first.as_ref().ok().map(|d| d.params.clone());
    let rest: Vec<_> = (1..seeds)
        .into_par_iter()
        .map(|s| identify_once(input, reading, clean, k, (i, s), starts.as_ref()))
        .collect();
    std::iter::once(first)
        .chain(rest)
        .map(|d| d.map(|d| d.rig).map_err(|e| e.kind()))
        .collect()
}

/// One identification's outcome: beta1, a1b0, a2 and a3 (Eqs. 18-20), and
/// the fitted parameters of its no-specimen and spring runs.
struct Draw {
    rig: [f64; 4],
    params: [Vec<f64>; 2],
}

/// One identification: the two noiseless responses `(none, spring)` read
/// with noise from stream (i, seed), each identified as `servoid
/// run` identifies a run (`identify::fit_run`, from `starts` when given),
/// and Eqs. 18-20.
fn identify_once(
    input: &McInput<'_>,
    reading: &Reading,
    (clean_none, clean_spring): (&Clean, &Clean),
    k: f64,
    (i, seed): (usize, u64),
    starts: Option<&[Vec<f64>; 2]>,
) -> Result<Draw, DrawError> {
    let fs = input.sample_rate_hz;
    let ident = input.ident;
    let run = |clean: &Clean,
               label: &'static str,
               start: Option<&[f64]>|
     -> Result<(TfEstimate, Vec<f64>), DrawError> {
        let mut rng = seeded_rng(input.seed, &format!("mc/{i}/{seed}/{label}"));
        let mut h = read(input, reading, clean, &mut rng)?;
        let mask = frf::band_mask(&h, ident.band_hz, ident.coherence_min);
        let (f, _) = fit_run(&mut h, &mask, ident.band_hz, ident, input.frf, fs, start)
            .map_err(|source| DrawError::Run { run: label, source })?;
        Ok((
            TfEstimate {
                run: label.to_string(),
                p_gain: input.rig.p_gain,
                tf: SecondOrder::from_tf(&f.tf)
                    .map_err(|source| DrawError::NotSecondOrder { run: label, source })?,
                cov: f.second_order_cov(),
            },
            f.params,
        ))
    };
    let (no_spec, none_params) = run(clean_none, "no-specimen", starts.map(|s| &s[0][..]))?;
    let (spring, spring_params) = run(clean_spring, "spring", starts.map(|s| &s[1][..]))?;
    let id = identify_rig(
        &[no_spec],
        &[SpringRun {
            stiffness_n_per_m: k,
            estimate: spring,
        }],
    )
    .map_err(DrawError::Rig)?;
    Ok(Draw {
        rig: [id.beta1.value, id.a1b0.value, id.a2.value, id.a3.value],
        params: [none_params, spring_params],
    })
}

/// The FRF of one noisy reading of `clean`, the noise drawn from `rng`.
fn read(
    input: &McInput<'_>,
    reading: &Reading,
    clean: &Clean,
    rng: &mut impl rand::Rng,
) -> Result<Frf, DrawError> {
    if let (Reading::Spectra { synthesis, sigma }, Some(c)) = (reading, &clean.spectra) {
        let noise = synthesis.white_noise(*sigma, || StandardNormal.sample(rng));
        return Ok(synthesis.frf(c, &noise));
    }
    let noise = Normal::new(0.0, input.noise_rms_m)?;
    let y: Vec<f64> = clean
        .samples
        .iter()
        .map(|v| {
            let read = v + noise.sample(rng);
            match input.step_m {
                Some(q) => (read / q).round() * q,
                None => read,
            }
        })
        .collect();
    frf::estimate_one(input.command_m, &y, input.sample_rate_hz, input.frf).map_err(|e| {
        DrawError::Run {
            run: "simulated",
            source: RunTfError::Frf(e),
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::{DelayPlan, Intersample};
    use crate::frf::{Detrend, FrfPlan, Method, Window};
    use crate::identify::{FitData, fit_options};
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
    fn paper_input<'a>(
        u: &'a [f64],
        ident: &'a IdentificationPlan,
        frf: &'a FrfPlan,
    ) -> McInput<'a> {
        McInput {
            rig: crate::model::PAPER_RIG,
            command_m: u,
            sample_rate_hz: 1000.0,
            noise_rms_m: 2e-6,
            step_m: None,
            delay_s: 0.0,
            ident,
            frf,
            seed: 0,
        }
    }

    /// The ETFE with a rectangular window, as the bundled default states it.
    fn etfe() -> FrfPlan {
        FrfPlan::new(Method::Etfe, 4096, 0.5, Window::Rectangular, Detrend::Mean).unwrap()
    }

    fn ident() -> IdentificationPlan {
        IdentificationPlan {
            band_hz: (0.5, 30.0),
            coherence_min: 0.0,
            frf: etfe().into(),
            intersample: Intersample::SampleAndHold,
            delay: DelayPlan::None,
            max_delay_s: 0.02,
            numerator_order: 0,
            denominator_order: 2,
            trim_to_excitation: false,
        }
    }

    /// Where the noise is small, the spread of 1,000 seeds' identifications
    /// is what the analytic sweep predicts from one noisy run's FRF
    /// variance: within 10 % (the sample std of 1,000 has a 2.2 % error of
    /// its own), and the bias is well inside the spread.
    #[test]
    fn the_spread_is_the_analytic_prediction_where_noise_is_small() {
        let u = chirp();
        let (ident, frf) = (ident(), etfe());
        let input = paper_input(&u, &ident, &frf);
        let rig = input.rig;
        let ks = [5e4, 1.2e5, 5e5];
        let mc = monte_carlo(&input, &ks, 1000);

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
        let h = frf::estimate_one(&u, &y, 1000.0, &frf).unwrap();
        let data = FitData::of(&h, &frf::band_mask(&h, ident.band_hz, 0.0), &frf);
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
        let opts = fit_options(&ident, &frf, 1000.0);
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

    /// The frequency-domain draws are the time-domain ones' equal: the same
    /// bias and spread of every parameter, within their Monte Carlo error,
    /// on a rig read noisily enough that the coherence limit (0.8) drops
    /// bins at the top of the band (2e-5 m of noise, 10 times the paper's,
    /// on a 1e-5 m converter grid, so the rounding's white-noise model is
    /// exercised too). 150 seeds each way: a mean differs by less than
    /// 4 of its combined standard errors, a std by less than 30 % (the
    /// ratio of two sample stds of 150 scatters by 8 %).
    #[test]
    fn the_frequency_domain_draws_match_the_time_domain_ones() {
        let u = chirp();
        let mut ident = ident();
        ident.coherence_min = 0.8;
        let frf = etfe();
        let mut input = paper_input(&u, &ident, &frf);
        input.noise_rms_m = 2e-5;
        input.step_m = Some(1e-5);
        let reading = Reading::of(&input);
        assert!(matches!(reading, Reading::Spectra { .. }));
        let ks = [5e4, 5e5];
        let seeds = 150;
        let fast = monte_carlo_reading(&input, &reading, &ks, seeds);
        let slow = monte_carlo_reading(&input, &Reading::Samples, &ks, seeds);
        let n = seeds as f64;
        for (f, s) in fast.iter().zip(&slow) {
            let k = f.stiffness_n_per_m;
            assert_eq!((f.identified, s.identified), (150, 150), "k = {k}");
            let (fb, fs) = (
                f.rel_bias.unwrap().to_array(),
                f.rel_std.unwrap().to_array(),
            );
            let (sb, ss) = (
                s.rel_bias.unwrap().to_array(),
                s.rel_std.unwrap().to_array(),
            );
            for j in 0..4 {
                let se = ((fs[j] * fs[j] + ss[j] * ss[j]) / n).sqrt();
                assert!(
                    (fb[j] - sb[j]).abs() < 4.0 * se,
                    "k = {k}, parameter {j}: bias {:.3e} vs {:.3e} (se {se:.1e})",
                    fb[j],
                    sb[j]
                );
                assert!(
                    (fs[j] / ss[j] - 1.0).abs() < 0.3,
                    "k = {k}, parameter {j}: std {:.3e} vs {:.3e}",
                    fs[j],
                    ss[j]
                );
            }
        }
    }

    /// A converter step coarser than the noise is not white noise: those
    /// draws are read sample by sample in time, as are the estimators whose
    /// transforms are not linear bin by bin.
    #[test]
    fn coarse_steps_and_other_estimators_are_read_in_time() {
        let u = chirp();
        let (ident, frf) = (ident(), etfe());
        let mut input = paper_input(&u, &ident, &frf);
        input.step_m = Some(4e-6);
        assert!(matches!(Reading::of(&input), Reading::Samples));
        input.step_m = Some(1e-6);
        assert!(matches!(Reading::of(&input), Reading::Spectra { .. }));
        let welch =
            FrfPlan::new(Method::H1, 4096, 0.5, Window::Rectangular, Detrend::Mean).unwrap();
        let input = paper_input(&u, &ident, &welch);
        assert!(matches!(Reading::of(&input), Reading::Samples));
    }

    /// The same numbers on one thread as on four.
    #[test]
    fn the_thread_count_changes_nothing() {
        let u = chirp();
        let (ident, frf) = (ident(), etfe());
        let input = paper_input(&u, &ident, &frf);
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
