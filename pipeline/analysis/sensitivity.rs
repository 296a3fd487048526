//! The campaign's stiffness sensitivity (paper Sec. 2.3): the analytic
//! sweep from the campaign's own noise (or an assumed precision without a
//! log), the recommendation, and the Monte Carlo (`sensitivity::draws`)
//! compared with the sweep. The run caches the Monte Carlo.

use crate::analysis::log_stage::replayed_command;
use crate::frf::FrfPlan;
use crate::identify;
use crate::ingest::IngestError;
use crate::manifest::{Campaign, MonteCarloSettings, Role, RunSource};
use crate::model::{RigParams, SpecimenModel};
use crate::results::{AnalyticSensitivity, Results, SensitivityResult};
use crate::sensitivity::draws::{McInput, monte_carlo};
use crate::sensitivity::montecarlo::{MonteCarlo, compare};
use crate::sensitivity::{
    CoefficientNoise, NoiseProfile, StiffnessSensitivity, log_grid, recommend, stiffness_sweep,
};

/// A no-specimen run's FRF noise and the FRF settings that gave it: what
/// the stiffness sensitivity reads, and the settings the Monte Carlo's
/// draws get.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NoiseSource {
    pub profile: NoiseProfile,
    pub frf: FrfPlan,
}

/// The sensitivity of a campaign whose rig is `rig` over the stiffnesses
/// `range` (N/m); `noise` the first no-specimen run's FRF noise, and
/// `monte_carlo` gives the Monte Carlo when the manifest asks for one (Err:
/// why it could not run), called only where there is a sweep. None when
/// the rig allows no sweep.
pub fn sensitivity<E>(
    campaign: &Campaign,
    rig: &RigParams,
    results: &Results,
    noise: Option<&NoiseSource>,
    range: (f64, f64),
    monte_carlo: impl FnOnce() -> Result<Option<Result<MonteCarlo, String>>, E>,
) -> Result<Option<SensitivityResult>, E> {
    let springs: Vec<f64> = campaign
        .runs
        .iter()
        .filter_map(|r| match (r.role, r.specimen) {
            (Role::Spring, SpecimenModel::Spring { stiffness_n_per_m }) => Some(stiffness_n_per_m),
            _ => None,
        })
        .collect();
    let Some(analytic) = analytic(campaign, rig, results, noise, range) else {
        return Ok(None);
    };
    // The scatter between springs, relative, when there are two or more.
    let scatter = results.rig.as_ref().and_then(|r| {
        let s = r.spread.as_ref()?;
        Some([s.a2 / r.a2.value.abs(), s.a3 / r.a3.value.abs()])
    });
    let recommendation = recommend(
        &analytic.sweep,
        campaign.sensitivity.target_rel_std,
        &springs,
        scatter,
    );
    let (monte_carlo, monte_carlo_note) = match monte_carlo()? {
        None => (None, None),
        Some(Ok(m)) => (Some(m), None),
        Some(Err(why)) => (None, Some(why)),
    };
    Ok(Some(SensitivityResult {
        springs_n_per_m: springs,
        analytic,
        monte_carlo,
        monte_carlo_note,
        recommendation,
    }))
}

/// The analytic sweep over `range`: from the campaign's measured FRF
/// noise when a no-specimen log gave it, else assuming each coefficient is
/// as precise as the campaign's median fitted one, or 0.1 % when its models
/// carry no uncertainty (published transfer functions).
fn analytic(
    campaign: &Campaign,
    rig: &RigParams,
    results: &Results,
    noise: Option<&NoiseSource>,
    range: (f64, f64),
) -> Option<AnalyticSensitivity> {
    let points = campaign.sensitivity.points;
    // The campaign's own noise when a no-specimen log measured it: its
    // FRF variance through the fit's Jacobian (Sec. 2.3's analysis with
    // the lab's noise, not an assumed one).
    if let Some(NoiseSource { profile, frf }) = noise {
        let opts = identify::fit_options(&campaign.identification, frf, profile.sample_rate_hz);
        let measured = CoefficientNoise::Measured {
            profile,
            opts: &opts,
        };
        if let Ok(sweep) = stiffness_sweep(rig, range, points, measured) {
            let (f0, f1) = (
                profile.freq_hz.first().copied().unwrap_or(f64::NAN),
                profile.freq_hz.last().copied().unwrap_or(f64::NAN),
            );
            return Some(AnalyticSensitivity {
                basis: format!(
                    "the FRF noise run {} measured ({} bins, {f0:.3}-{f1:.2} Hz) through the fit's Jacobian, for runs with the same excitation and sensors",
                    profile.run,
                    profile.freq_hz.len()
                ),
                sweep,
            });
        }
    }
    let mut rel: Vec<f64> = results
        .runs
        .iter()
        .filter(|r| matches!(r.role, Role::NoSpecimen | Role::Spring))
        .filter_map(|r| r.tf.as_ref())
        .flat_map(|tf| tf.rel_std.clone().unwrap_or_default())
        .filter(|v| v.is_finite() && *v > 0.0)
        .collect();
    rel.sort_by(f64::total_cmp);
    let (eps, basis) = match rel.get(rel.len() / 2) {
        Some(&m) => (
            m,
            format!("median relative std of the campaign's fitted coefficients ({m:.2e}), each assumed independent"),
        ),
        None => (
            1e-3,
            "assumed 0.1 % relative std per coefficient (the campaign's models carry no uncertainty)".to_string(),
        ),
    };
    let sweep = stiffness_sweep(rig, range, points, CoefficientNoise::Relative(eps)).ok()?;
    Some(AnalyticSensitivity { basis, sweep })
}

/// Why the Monte Carlo cannot run: recorded in the results as its note, not
/// a failure of the campaign.
#[derive(Debug, thiserror::Error)]
pub enum McUnavailable {
    #[error("run {run}: too few fitted bins to tell its noise level")]
    NoNoiseLevel { run: String },
    #[error("run {run}: no log to replay")]
    NoLog { run: String },
    #[error("run {run}: {source}")]
    Replay {
        run: String,
        #[source]
        source: Box<IngestError>,
    },
}

/// What the Monte Carlo did, in a sentence for results.json and the page.
fn basis(
    mc: &MonteCarloSettings,
    profile: &NoiseProfile,
    record_s: f64,
    noise_rms_m: f64,
    frequency_domain: bool,
) -> String {
    format!(
        "{} identifications per stiffness, each of a no-specimen run and a spring run simulated from the identified rig (Eq. 10 with the zero-order hold{}), driven by run {}'s logged command ({:.1} s at {} Hz), read with {:.3} um rms of white displacement noise (the level its FRF variance implies){}{}, and identified with the campaign's settings",
        mc.seeds,
        if profile.delay_s > 0.0 {
            format!(" and its {:.2} ms delay", 1e3 * profile.delay_s)
        } else {
            String::new()
        },
        profile.run,
        record_s,
        profile.sample_rate_hz,
        1e6 * noise_rms_m,
        match profile.displacement_step_m {
            Some(q) => format!(" on its converter's {:.3} um grid", 1e6 * q),
            None => String::new(),
        },
        if frequency_domain {
            " (drawn on the ETFE's bins, exact for white noise, the grid's rounding as white noise of step^2/12)"
        } else {
            ""
        },
    )
}

/// The Monte Carlo of `mc` over `range`: the rig identified again from
/// simulated runs driven by `source`'s logged command with its noise.
pub fn run_monte_carlo(
    campaign: &Campaign,
    rig: &RigParams,
    NoiseSource { profile, frf }: &NoiseSource,
    range: (f64, f64),
    mc: &MonteCarloSettings,
) -> Result<MonteCarlo, McUnavailable> {
    let run = || profile.run.clone();
    let Some((noise_rms_m, whiteness)) = profile.white_noise else {
        return Err(McUnavailable::NoNoiseLevel { run: run() });
    };
    let log_plan = campaign
        .runs
        .iter()
        .find(|r| r.id == profile.run)
        .and_then(|r| match &r.source {
            RunSource::Log(l) => Some(l),
            _ => None,
        })
        .ok_or_else(|| McUnavailable::NoLog { run: run() })?;
    let command = replayed_command(log_plan, &campaign.identification, &profile.log_sha256)
        .map_err(|e| McUnavailable::Replay {
            run: run(),
            source: Box::new(e),
        })?;
    let fs = profile.sample_rate_hz;
    let input = McInput {
        rig: *rig,
        command_m: &command,
        sample_rate_hz: fs,
        noise_rms_m,
        step_m: profile.displacement_step_m,
        delay_s: profile.delay_s,
        ident: &campaign.identification,
        frf,
        seed: mc.seed,
    };
    let ks = log_grid(range, mc.points);
    let frequency_domain = input.in_frequency_domain();
    let mut points = monte_carlo(&input, &ks, mc.seeds);
    // The analytic prediction at exactly these stiffnesses.
    let opts = identify::fit_options(&campaign.identification, frf, fs);
    let at_points = stiffness_sweep(
        rig,
        range,
        mc.points,
        CoefficientNoise::Measured {
            profile,
            opts: &opts,
        },
    )
    .unwrap_or_else(|_| StiffnessSensitivity::empty());
    let agreement = compare(&mut points, &at_points, mc.seeds, whiteness);
    Ok(MonteCarlo {
        basis: basis(
            mc,
            profile,
            command.len() as f64 / fs,
            noise_rms_m,
            frequency_domain,
        ),
        excitation_run: profile.run.clone(),
        noise_rms_m,
        noise_whiteness: whiteness,
        displacement_step_m: profile.displacement_step_m,
        delay_s: profile.delay_s,
        sample_rate_hz: fs,
        record_s: command.len() as f64 / fs,
        seeds: mc.seeds,
        seed: mc.seed,
        points,
        agreement,
    })
}
