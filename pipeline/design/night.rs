//! Tomorrow night's identification runs: each run's command a random-odd
//! multisine whose lines carry the A-optimal shares ([`super::spectrum`])
//! mixed with a flat share, repeated over the run's record (faded in over
//! the first period and out over the last, at rest before and after; the
//! analysis reads the periods after the second, in which the response
//! settles), and
//! scaled to the largest amplitude the rig's limits allow in the identified
//! plant's own prediction. Of the periods and mixes tried, the one whose
//! predicted sum of squared relative stds ([`super::precision`]) is the
//! smallest once the crest factor it reaches and the limits have scaled it.
//! The derivation: docs/methods.md, "Designed nights".

use rayon::prelude::*;

use super::precision::{self, Precision};
use super::spectrum::{self, RunModel};
use crate::fit::Intersample;
use crate::lti::TransferFunction;
use crate::model::{self, LinearSpecimen, RigParams};
use crate::simulate::excitation::{self, ChirpLaw, Excitation, Padding};
use crate::simulate::{discrete, multisine, seeded_rng};

/// The displacement's noise spectrum a run's FRF variance implies, which
/// a night is planned for: a bin of E|dH|^2 at an input density Suu holds
/// a noise density Suu E|dH|^2 (times a Welch estimate's degrees of
/// freedom), averaged over sixth-octave bands (results.json's
/// `runs[].noise`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
pub struct Noise {
    /// The bands' centres (Hz), rising.
    pub freq_hz: Vec<f64>,
    /// The one-sided power spectral density of the displacement's noise
    /// in each band (m^2/Hz): white noise of s m RMS at fs gives 2 s^2 / fs.
    pub psd_m2_per_hz: Vec<f64>,
}

impl Noise {
    /// The density at `f_hz` (m^2/Hz), interpolated log-log between the
    /// bands and held beyond the first and last.
    pub fn psd(&self, f_hz: f64) -> f64 {
        let (f, p) = (&self.freq_hz, &self.psd_m2_per_hz);
        let i = f.partition_point(|&g| g <= f_hz);
        match i {
            0 => p[0],
            i if i == f.len() => p[i - 1],
            i => {
                let x = (f_hz / f[i - 1]).ln() / (f[i] / f[i - 1]).ln();
                (p[i - 1].ln() * (1.0 - x) + p[i].ln() * x).exp()
            }
        }
    }

    /// The noise's variance per sample at `f_hz`, lambda = psd fs / 2: the
    /// level [`precision::etfe_variance`] takes.
    pub fn level(&self, f_hz: f64, sample_rate_hz: f64) -> f64 {
        0.5 * self.psd(f_hz) * sample_rate_hz
    }

    /// White noise of `rms_m` RMS sampled at `sample_rate_hz`: one band,
    /// held everywhere.
    pub fn white(rms_m: f64, sample_rate_hz: f64, band_hz: [f64; 2]) -> Noise {
        Noise {
            freq_hz: vec![(band_hz[0] * band_hz[1]).sqrt()],
            psd_m2_per_hz: vec![2.0 * rms_m * rms_m / sample_rate_hz],
        }
    }

    /// The mean of several runs' spectra, on the first one's bands.
    pub fn mean(all: &[Noise]) -> Option<Noise> {
        let first = all.first()?;
        let psd_m2_per_hz = first
            .freq_hz
            .iter()
            .map(|&f| all.iter().map(|n| n.psd(f)).sum::<f64>() / all.len() as f64)
            .collect();
        Some(Noise {
            freq_hz: first.freq_hz.clone(),
            psd_m2_per_hz,
        })
    }
}

/// What the rig may do: the command's peak, and where given the stroke,
/// the peak velocity and the peak force (actuator on specimen).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    pub command_m: f64,
    pub stroke_m: Option<f64>,
    pub velocity_m_per_s: Option<f64>,
    pub force_n: Option<f64>,
}

/// The limit that sets a run's amplitude, or stops a target.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Limit {
    Command,
    Stroke,
    Velocity,
    Force,
    RunTime,
}

impl Limit {
    /// The limit as the design page and its errors name it, with the flag
    /// and the manifest key that set it.
    pub fn describe(self) -> &'static str {
        match self {
            Limit::Command => "the peak command (--command-mm, [design] command_m)",
            Limit::Stroke => "the stroke (--stroke-mm, [design] stroke_m)",
            Limit::Velocity => "the peak velocity (--velocity-mm-s, [design] velocity_m_per_s)",
            Limit::Force => "the peak force (--force-n, [design] force_n)",
            Limit::RunTime => "the time per run (--run-s, [design] run_s)",
        }
    }
}

/// The night to design: the rig identified, its runs, and what bounds
/// them.
#[derive(Debug, Clone, PartialEq)]
pub struct NightPlan {
    /// The rig, a1b0 at its own P gain, and what the joint fit found
    /// beyond the paper's model (estimated beside it).
    pub rig: RigParams,
    pub extension: precision::Extension,
    pub runs: Vec<RunModel>,
    pub noise: Noise,
    pub band_hz: [f64; 2],
    pub sample_rate_hz: f64,
    /// Each run's record, its rest included (s).
    pub record_s: f64,
    /// Rest before and after each command (s).
    pub rest_s: f64,
    pub intersample: Intersample,
    pub limits: Limits,
    /// The random choice of the lines left out for detection.
    pub seed: u64,
}

/// A run's predicted peaks over its whole command.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Peaks {
    pub command_m: f64,
    pub displacement_m: f64,
    pub velocity_m_per_s: f64,
    /// The force on the specimen; None without one.
    pub force_n: Option<f64>,
}

impl Peaks {
    /// The peaks of the same command scaled by `a`: the plant is linear.
    pub fn scaled(&self, a: f64) -> Peaks {
        Peaks {
            command_m: a * self.command_m,
            displacement_m: a * self.displacement_m,
            velocity_m_per_s: a * self.velocity_m_per_s,
            force_n: self.force_n.map(|f| a * f),
        }
    }

    /// The largest scale inside `limits`, and the limit that sets it.
    pub fn largest_scale(&self, limits: &Limits) -> (f64, Limit) {
        let mut best = (limits.command_m / self.command_m, Limit::Command);
        let others = [
            (limits.stroke_m, Some(self.displacement_m), Limit::Stroke),
            (
                limits.velocity_m_per_s,
                Some(self.velocity_m_per_s),
                Limit::Velocity,
            ),
            (limits.force_n, self.force_n, Limit::Force),
        ];
        for (limit, peak, which) in others {
            if let (Some(limit), Some(peak)) = (limit, peak)
                && peak > 0.0
                && limit / peak < best.0
            {
                best = (limit / peak, which);
            }
        }
        best
    }
}

/// One run of the designed night.
#[derive(Debug, Clone, PartialEq)]
pub struct DesignedRun {
    /// Each excited line's share of the command's mean square.
    pub shares: Vec<f64>,
    /// The command, rest to rest, at the plan's rate (m).
    pub command_m: Vec<f64>,
    /// The period's peak over its RMS.
    pub crest_factor: f64,
    /// The steady periods' RMS (m).
    pub rms_m: f64,
    pub peaks: Peaks,
    /// The limit its amplitude reaches.
    pub bound_by: Limit,
}

/// A period and mix tried, and the sum of squared relative stds it
/// predicts (None where it cannot determine the rig).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Tried {
    pub period_s: f64,
    pub optimal_share: f64,
    /// The draw of the detection lines (`Night::draw`).
    pub draw: u64,
    pub largest_crest_factor: f64,
    pub criterion: Option<f64>,
}

/// The night designed.
#[derive(Debug, Clone, PartialEq)]
pub struct Night {
    pub period_s: f64,
    /// Periods per run, the first fading in and the last out.
    pub periods: usize,
    /// The A-optimal shares' part of each line's share (the rest flat).
    pub optimal_share: f64,
    /// Which draw of the detection lines (from the plan's seed).
    pub draw: u64,
    /// The excited lines, and the odd ones left out (Hz).
    pub lines_hz: Vec<f64>,
    pub detection_hz: Vec<f64>,
    pub runs: Vec<DesignedRun>,
    pub precision: Precision,
    /// Each run's record, its rest included (s).
    pub record_s: f64,
    pub tried: Vec<Tried>,
}

/// Why no night could be designed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DesignError {
    #[error(
        "no period of {periods:?} s over the band {lo_hz}-{hi_hz} Hz fits a record of {record_s} s with {rest_s} s of rest at each end often enough to determine the rig (three periods unread: the fades and the one the response settles in; then {cycles} cycles of the band's low edge); lengthen the record (--run-s) or raise the band's low edge (--band-hz)",
        periods = .periods_s,
        lo_hz = .band_hz[0],
        hi_hz = .band_hz[1],
        cycles = crate::frf::MIN_PERIODS
    )]
    Undetermined {
        periods_s: Vec<f64>,
        band_hz: [f64; 2],
        record_s: f64,
        rest_s: f64,
    },
    #[error(
        "a worst relative std of {target} needs {needed_s:.1} s per run, and {} allows {available_s:.1} s (the best reached there is {reached:.4}); the runs' amplitudes are set by {bounds}",
        Limit::RunTime.describe()
    )]
    TargetOutOfReach {
        target: f64,
        reached: f64,
        needed_s: f64,
        available_s: f64,
        bounds: String,
    },
}

/// Periods of a run the analysis does not read: the fade-in, the period
/// the response settles in, and the fade-out.
pub const UNREAD: usize = 3;

/// The periods tried, in units of 1 / the band's low edge: odd multiples,
/// so that the edge itself is an odd harmonic and the lowest line there.
const PERIODS: [f64; 3] = [1.0, 3.0, 5.0];

/// The A-optimal shares' parts tried, the rest spread flat: a flatter
/// spectrum reaches a lower crest factor (all optimal, or half, did worse
/// on the paper's night at every period).
const MIXES: [f64; 2] = [0.9, 0.75];

/// The draws of the lines left out for detection tried: which of each
/// three odd lines is left out moves the night's criterion by some 10 %.
const DRAWS: u64 = 4;

/// Designs the night: every period and mix tried at the plan's record,
/// the best kept; with `target` (a worst relative std), the record it
/// needs, no longer than the plan's.
pub fn design(plan: &NightPlan, target: Option<f64>) -> Result<Night, DesignError> {
    let grid: Vec<(f64, f64, u64)> = PERIODS
        .iter()
        .flat_map(|k| MIXES.map(|mix| (k / plan.band_hz[0], mix)))
        .flat_map(|(period_s, mix)| (0..DRAWS).map(move |draw| (period_s, mix, draw)))
        .collect();
    // Each candidate on its own thread; kept in the grid's order, so the
    // choice is the same on any number of threads.
    let nights: Vec<Option<Night>> = grid
        .par_iter()
        .map(|&(period_s, mix, draw)| candidate(plan, period_s, mix, draw, plan.record_s))
        .collect();
    let mut tried = Vec::new();
    let mut best: Option<(f64, Night)> = None;
    for ((period_s, mix, draw), night) in grid.into_iter().zip(nights) {
        let criterion = night.as_ref().map(|n| criterion_of(plan, n));
        tried.push(Tried {
            period_s,
            optimal_share: mix,
            draw,
            largest_crest_factor: night.as_ref().map_or(f64::NAN, |n| {
                n.runs.iter().map(|r| r.crest_factor).fold(0.0, f64::max)
            }),
            criterion,
        });
        if let (Some(night), Some(c)) = (night, criterion)
            && best.as_ref().is_none_or(|(b, _)| c < *b)
        {
            best = Some((c, night));
        }
    }
    let Some((_, mut best)) = best else {
        return Err(DesignError::Undetermined {
            periods_s: PERIODS.iter().map(|k| k / plan.band_hz[0]).collect(),
            band_hz: plan.band_hz,
            record_s: plan.record_s,
            rest_s: plan.rest_s,
        });
    };
    if let Some(target) = target {
        best = to_target(plan, best, target)?;
    }
    best.tried = tried;
    Ok(best)
}

/// The sum of the four squared relative stds a night predicts.
fn criterion_of(plan: &NightPlan, night: &Night) -> f64 {
    night
        .precision
        .relative_std(&plan.rig)
        .iter()
        .map(|r| r * r)
        .sum()
}

/// The worst relative std a night predicts.
pub fn worst(night: &Night, rig: &RigParams) -> f64 {
    night
        .precision
        .relative_std(rig)
        .into_iter()
        .fold(0.0, f64::max)
}

/// `best` with as many periods as bring its worst relative std to
/// `target` (stds fall as the square root of the steady periods), or the
/// limit that stops it.
fn to_target(plan: &NightPlan, best: Night, target: f64) -> Result<Night, DesignError> {
    let reached = worst(&best, &plan.rig);
    let steady = (best.periods - UNREAD) as f64;
    // A part in 1e9 off the ceiling: the square-root law met exactly is
    // met, whatever the last bit of the ratio.
    let needed = (steady * (reached / target).powi(2) * (1.0 - 1e-9))
        .ceil()
        .max(1.0);
    // No fewer than the FRF stage needs of the band's lowest line.
    let fewest = (crate::frf::MIN_PERIODS / (plan.band_hz[0] * best.period_s) - 1e-9).ceil();
    let needed = needed.max(fewest);
    let needed_s = (needed + UNREAD as f64) * best.period_s + 2.0 * plan.rest_s;
    if needed_s > plan.record_s * (1.0 + 1e-12) {
        let mut bounds: Vec<&str> = best.runs.iter().map(|r| r.bound_by.describe()).collect();
        bounds.dedup();
        return Err(DesignError::TargetOutOfReach {
            target,
            reached,
            needed_s,
            available_s: plan.record_s,
            bounds: bounds.join(", "),
        });
    }
    Ok(candidate(plan, best.period_s, best.optimal_share, best.draw, needed_s).unwrap_or(best))
}

/// The night of odd multisines of `period_s` with `mix` of the A-optimal
/// shares and the `draw`-th detection lines, over records of `record_s`;
/// None where it cannot be made or does not determine the rig.
fn candidate(plan: &NightPlan, period_s: f64, mix: f64, draw: u64, record_s: f64) -> Option<Night> {
    let fs = plan.sample_rate_hz;
    let len = (period_s * fs).round() as usize;
    let rest = (plan.rest_s * fs).round() as usize;
    let total = (record_s * fs).round() as usize;
    let periods = total.checked_sub(2 * rest)? / len;
    // The periods read must hold the band's lowest line MIN_PERIODS times,
    // as the FRF stage asks of any record.
    let read_s = periods.saturating_sub(UNREAD) as f64 * len as f64 / fs;
    if periods <= UNREAD || len < 4 || read_s * plan.band_hz[0] < crate::frf::MIN_PERIODS {
        return None;
    }
    let mut rng = seeded_rng(plan.seed, &format!("design/night/{draw}"));
    let (excited, detection) =
        multisine::lines(plan.band_hz[0], plan.band_hz[1], fs, len, &mut rng);
    let hz = |k: &usize| *k as f64 * fs / len as f64;
    let lines_hz: Vec<f64> = excited.iter().map(hz).collect();
    if lines_hz.len() < 2 {
        return None;
    }
    let noise = |f: f64| plan.noise.level(f, fs);
    let optimal = spectrum::a_optimal(
        &plan.rig,
        &plan.extension,
        &plan.runs,
        &vec![1.0; plan.runs.len()],
        &lines_hz,
        noise,
        plan.intersample,
        fs,
    )?;
    let flat = 1.0 / lines_hz.len() as f64;
    // The periods the analysis reads: not the fades, nor the period after
    // the fade-in, in which the response settles (`analysis::log_stage`).
    let steady = ((periods - UNREAD) * len) as f64;
    let mut runs = Vec::new();
    for (model, w) in plan.runs.iter().zip(&optimal) {
        let shares: Vec<f64> = w.iter().map(|w| mix * w + (1.0 - mix) * flat).collect();
        let amps = shares.iter().map(|w| (2.0 * w).sqrt()).collect();
        let unit = multisine::low_crest(len, excited.clone(), detection.clone(), amps);
        let body = excitation::faded(&unit.period, periods * len);
        let padding = Padding {
            lead_in_s: plan.rest_s,
            lead_out_s: plan.rest_s,
        };
        let unit_command = excitation::padded(body, fs, padding).ok()?;
        let at_unit = peaks(&plan.rig, model, &unit_command, fs)?;
        let (scale, bound_by) = at_unit.largest_scale(&plan.limits);
        // A part in 1e9 below the limit, so that rounding never crosses it.
        let a = scale * (1.0 - 1e-9);
        runs.push(DesignedRun {
            shares,
            command_m: unit_command.iter().map(|u| a * u).collect(),
            crest_factor: unit.crest_factor,
            rms_m: a,
            peaks: at_unit.scaled(a),
            bound_by,
        });
    }
    let precision = predicted(plan, &runs, &lines_hz, steady, noise)?;
    Some(Night {
        period_s: len as f64 / fs,
        periods,
        optimal_share: mix,
        draw,
        detection_hz: detection.iter().map(hz).collect(),
        lines_hz,
        runs,
        precision,
        record_s: (periods * len + 2 * rest) as f64 / fs,
        tried: Vec::new(),
    })
}

/// Command `u` played on `model`: scaled to the largest amplitude inside
/// `limits`, with the scale, its peaks and the limit that sets them.
pub fn replayed(
    rig: &RigParams,
    model: &RunModel,
    u: &[f64],
    fs: f64,
    limits: &Limits,
) -> Option<(f64, Vec<f64>, Peaks, Limit)> {
    let at = peaks(rig, model, u, fs)?;
    let (scale, bound_by) = at.largest_scale(limits);
    // A part in 1e9 below the limit, as `candidate` keeps it.
    let a = scale * (1.0 - 1e-9);
    Some((a, u.iter().map(|v| a * v).collect(), at.scaled(a), bound_by))
}

/// The night's predicted precision with `noise` in place of the plan's:
/// what a check that plays other noise should state.
pub fn precision_under(plan: &NightPlan, night: &Night, noise: &Noise) -> Option<Precision> {
    let fs = plan.sample_rate_hz;
    let steady = night.periods.saturating_sub(UNREAD) as f64 * (night.period_s * fs).round();
    predicted(plan, &night.runs, &night.lines_hz, steady, |f| {
        noise.level(f, fs)
    })
}

/// The predicted precision of designed `runs` whose lines `lines_hz` are
/// read over `steady` samples, the noise's level per sample `noise(f)`.
fn predicted(
    plan: &NightPlan,
    runs: &[DesignedRun],
    lines_hz: &[f64],
    steady: f64,
    noise: impl Fn(f64) -> f64,
) -> Option<Precision> {
    let scale: Vec<f64> = runs.iter().map(|r| steady * r.rms_m * r.rms_m).collect();
    let shares: Vec<Vec<f64>> = runs.iter().map(|r| r.shares.clone()).collect();
    let planned = spectrum::planned(&plan.runs, &scale, lines_hz, &shares, noise);
    precision::predict_extended(
        &plan.rig,
        &plan.extension,
        &planned,
        plan.intersample,
        plan.sample_rate_hz,
    )
}

/// What each run's displacement holds at the night's excited lines, and
/// the noise it has to clear there: the page's figure.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LineLevels {
    /// The excited lines (Hz).
    pub freq_hz: Vec<f64>,
    /// Per run, the displacement's amplitude at each line (m): the
    /// command's, rms sqrt(2 share), through |x1/u| (Eq. 17).
    pub displacement_m: Vec<Vec<f64>>,
    /// The noise's amplitude at a line of the periods read (m), sqrt(2
    /// psd / T) for T s read: a line at this amplitude is read with a
    /// signal-to-noise ratio of 1.
    pub noise_m: Vec<f64>,
}

/// The night's line levels (see [`LineLevels`]).
pub fn line_levels(plan: &NightPlan, night: &Night) -> LineLevels {
    let read_s = night.periods.saturating_sub(UNREAD) as f64 * night.period_s;
    let displacement_m = plan
        .runs
        .iter()
        .zip(&night.runs)
        .map(|(model, run)| {
            let x1 = model::tf_x1_u(&plan.rig.at_p_gain(model.p_gain), &model.specimen).ok();
            night
                .lines_hz
                .iter()
                .zip(&run.shares)
                .map(|(&f, &w)| {
                    let gain = x1.as_ref().map_or(f64::NAN, |h| h.freq_response(f).norm());
                    gain * run.rms_m * (2.0 * w).sqrt()
                })
                .collect()
        })
        .collect();
    LineLevels {
        noise_m: night
            .lines_hz
            .iter()
            .map(|&f| (2.0 * plan.noise.psd(f) / read_s).sqrt())
            .collect(),
        freq_hz: night.lines_hz.clone(),
        displacement_m,
    }
}

/// The peaks of command `u`, and of the displacement, velocity and force
/// the rig at `model`'s P gain and specimen answers it with (the command
/// held over each sample, from rest).
pub fn peaks(rig: &RigParams, model: &RunModel, u: &[f64], fs: f64) -> Option<Peaks> {
    let at = rig.at_p_gain(model.p_gain);
    let x1 = model::tf_x1_u(&at, &model.specimen).ok()?;
    let velocity = TransferFunction::new(&crate::poly::mul(&x1.num, &[1.0, 0.0]), &x1.den).ok()?;
    let peak_of = |tf: &TransferFunction| -> Option<f64> {
        let y = discrete::simulate_linear(&tf.to_state_space(), u, 1.0 / fs, &[0.0]).ok()?;
        Some(y[0].iter().fold(0.0, |m, v| m.max(v.abs())))
    };
    let force_n = match model.specimen {
        LinearSpecimen::None => None,
        s => Some(peak_of(&model::tf_f_u(&at, &s).ok()?)?),
    };
    Some(Peaks {
        command_m: u.iter().fold(0.0, |m, v| m.max(v.abs())),
        displacement_m: peak_of(&x1)?,
        velocity_m_per_s: peak_of(&velocity)?,
        force_n,
    })
}

/// The baseline chirp's start and end (Hz): a fifth of the band's low
/// edge and 7/6 of its top, below 0.45 of the rate.
pub fn chirp_band_hz(plan: &NightPlan) -> [f64; 2] {
    [
        plan.band_hz[0] / 5.0,
        (plan.band_hz[1] * 7.0 / 6.0).min(0.45 * plan.sample_rate_hz),
    ]
}

/// The paper's command over the same records at the same peak command:
/// a quadratic chirp from a fifth of the band's low edge to 7/6 of its
/// high one (0.1-35 Hz for 0.5-30 Hz, Sec. 3.2.2), each run an ETFE over
/// its whole record, for the night to be compared with.
pub fn chirp_baseline(plan: &NightPlan, record_s: f64) -> Option<Precision> {
    let fs = plan.sample_rate_hz;
    let [f0_hz, f1_hz] = chirp_band_hz(plan);
    let chirp = Excitation::Chirp {
        law: ChirpLaw::Quadratic,
        f0_hz,
        f1_hz,
        duration_s: record_s - 2.0 * plan.rest_s,
        amplitude_m: plan.limits.command_m,
    };
    let padding = Padding {
        lead_in_s: plan.rest_s,
        lead_out_s: plan.rest_s,
    };
    let u = excitation::generate(&chirp, fs, padding).ok()?;
    let (freq_hz, variance) =
        precision::etfe_variance(&u, fs, plan.band_hz, |f| plan.noise.level(f, fs));
    let runs: Vec<precision::PlannedRun> = plan
        .runs
        .iter()
        .map(|r| precision::PlannedRun {
            specimen: r.specimen,
            p_gain: r.p_gain,
            freq_hz: freq_hz.clone(),
            variance: variance.clone(),
        })
        .collect();
    precision::predict_extended(&plan.rig, &plan.extension, &runs, plan.intersample, fs)
}

#[cfg(test)]
mod tests;
