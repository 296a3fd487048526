//! `servoid design RESULTS|MANIFEST`: tomorrow night's identification
//! runs (`design::night`) from the rig and noise a campaign's results.json
//! states, or from a campaign manifest's nominal `rig.parameters` with the
//! noise and limits given, written as one output set: each run's command
//! as the controller's waveform generator plays it (`commands/<run>.csv`
//! and `.mat`, time_s and command_m at the DAQ's rate, rest to rest), the
//! next night's manifest for the logs to come (campaign.toml), a simulation
//! manifest that plays the commands on the rig planned at (check.toml, for
//! `servoid simulate --run` before the lab runs them), design.json and the
//! page to read first (design.html).

use std::path::{Path, PathBuf};

use crate::design::night::{self, DesignError, Limit, Limits, Night, NightPlan, Noise};
use crate::design::precision;
use crate::design::spectrum::RunModel;
use crate::manifest::{
    self, Campaign, DesignSettings, Loaded, Manifest, Role, Run, RunData, RunSource,
};
use crate::model::{RigParams, SpecimenModel};
use crate::report::{self, matlab};
use crate::results::{
    DesignBaseline, DesignLimits, DesignResult, DesignedParameter, DesignedRunResult, LimitUsed,
    LogInfo, Results, RunResult, Status,
};

use super::JobError;

mod questions;

/// What the design is asked beside its source: the limits, times, rate
/// and noise (each absent one taken from the campaign's `[design]`, then
/// from the results, or not applied), the rest around each command, the
/// seed of the detection lines.
#[derive(Debug, Clone, Default)]
pub struct DesignAsk {
    pub out: Option<PathBuf>,
    pub limits: DesignSettings,
    pub rest_s: f64,
    pub seed: u64,
    pub wait: Option<std::time::Duration>,
}

/// Why a design was not written.
#[derive(Debug, thiserror::Error)]
pub enum DesignJobError {
    #[error("{}: states no rig to design from ({why})", path.display())]
    NoRig { path: PathBuf, why: String },
    #[error("{}: no identification run (role no_specimen or spring) {why}", path.display())]
    NoRuns { path: PathBuf, why: &'static str },
    #[error("{}: a design from nominal values needs {}", path.display(), missing.join("; "))]
    Missing {
        path: PathBuf,
        missing: Vec<&'static str>,
    },
    #[error("{flag} {value}: {why}")]
    Flag {
        flag: &'static str,
        value: f64,
        why: String,
    },
    #[error("{}: {source}", path.display())]
    Design {
        path: PathBuf,
        #[source]
        source: DesignError,
    },
}

/// What `servoid design` wrote.
#[derive(Debug, Clone)]
pub struct Designed {
    pub out_dir: PathBuf,
    pub result: DesignResult,
}

/// What a design starts from: the rig, the identification runs it
/// repeats and, from results, what last night's logs measured.
struct Basis {
    /// The results.json or manifest designed from, and its SHA-256.
    path: PathBuf,
    sha256: String,
    /// The campaign's manifest: the next night keeps its channels and
    /// settings.
    manifest: Manifest,
    campaign: String,
    rig_name: String,
    rig: RigParams,
    /// Where the rig came from, in words.
    rig_from: &'static str,
    /// What the joint fit found beyond the paper's model, where the
    /// campaign uses it, with last night's stds of its parameters.
    extension: precision::Extension,
    extension_std: Vec<(String, f64)>,
    /// Last night's stated stds of beta1, a1b0, a2, a3 (from results).
    last_std: Option<[Option<f64>; 4]>,
    /// The identification runs the night repeats.
    runs: Vec<BasisRun>,
    /// Last night's validation runs with linear specimens: specimens and
    /// P gains the lab has.
    validation: Vec<BasisRun>,
    /// What last night's joint fit could not tell apart, and the
    /// experiments that would settle it.
    ambiguity: Option<String>,
    settle: Vec<crate::results::Settle>,
}

/// An identification run the night repeats.
struct BasisRun {
    id: String,
    role: Role,
    description: String,
    p_gain: f64,
    specimen: SpecimenModel,
    model: RunModel,
    /// Its log as the manifest names it (last night's, or expected).
    log_file: Option<String>,
    /// From results: what its log was, the noise it measured, its fit's
    /// band, and what it said of the rig's linearity where it said the
    /// rig is not linear.
    log: Option<LogInfo>,
    noise: Option<Noise>,
    fit_band_hz: Option<[f64; 2]>,
    nonlinear: Option<String>,
}

/// Designs tomorrow night from `from` (a results.json, the output folder
/// that holds one, or a campaign manifest) and writes it (see the
/// module's header).
pub fn design_night(from: &Path, ask: &DesignAsk) -> Result<Designed, JobError> {
    let basis = if from.extension().is_some_and(|e| e == "toml") {
        from_manifest(from)?
    } else if from.is_dir() {
        from_results(&from.join("results.json"))?
    } else {
        from_results(from)?
    };
    let ask = &DesignAsk {
        limits: ask.limits.clone().or(basis.manifest.design.as_ref()),
        ..ask.clone()
    };
    let (plan, limits, noise_from) = night_plan(&basis, ask)?;
    let designed = night::design(&plan, ask.limits.target_relative_std).map_err(|source| {
        DesignJobError::Design {
            path: basis.path.clone(),
            source,
        }
    })?;
    let mut result = design_result(&basis, &plan, &designed, limits, noise_from, ask);
    let mut commands: Vec<Vec<f64>> = designed.runs.iter().map(|r| r.command_m.clone()).collect();
    for added in questions::added(&basis, &plan, &designed, &result.runs) {
        commands.push(added.command);
        result.runs.push(added.run);
        result.questions.push(added.question);
    }
    let out_dir = ask
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("reports").join(format!("{}-design", basis.campaign)));
    let set = super::begin(&out_dir, ask.wait)?;
    write_design(set.dir(), &basis, &commands, &result).map_err(|e| set.relocate(e))?;
    set.commit()?;
    Ok(Designed { out_dir, result })
}

/// The basis a campaign's results give: the rig they state and the
/// identification runs that fitted a log with a linear specimen.
fn from_results(path: &Path) -> Result<Basis, JobError> {
    let (bytes, results) = super::verify::read_results(path)?;
    let Results {
        campaign,
        manifest,
        rig,
        rig_error,
        runs,
        ..
    } = results;
    let rig_stated = rig.as_ref().ok_or_else(|| DesignJobError::NoRig {
        path: path.to_path_buf(),
        why: rig_error.unwrap_or_else(|| "rig is null".into()),
    })?;
    let rig = RigParams {
        beta1_per_s: rig_stated.beta1.value,
        a1b0_n_per_m_s2: rig_stated.a1b0.value,
        a2_n_per_m: rig_stated.a2.value,
        a3_per_s: rig_stated.a3.value,
        p_gain: rig_stated.p_gain,
    };
    let last_std = Some([
        rig_stated.beta1.std,
        rig_stated.a1b0.std,
        rig_stated.a2.std,
        rig_stated.a3.std,
    ]);
    let (ambiguity, settle) = rig_stated.joint.as_ref().map_or((None, Vec::new()), |j| {
        (j.ambiguity.clone(), j.settle.clone())
    });
    // A structure the data did not settle is not planned for: shaping the
    // night for one candidate tunes it away from the others.
    let (extension, extension_std) = rig_stated
        .joint
        .as_ref()
        .filter(|j| j.used && j.ambiguity.is_none())
        .map(extension_of)
        .unwrap_or_default();
    let all: Vec<BasisRun> = runs.into_iter().filter_map(basis_run).collect();
    let (runs, validation): (Vec<BasisRun>, Vec<BasisRun>) = all
        .into_iter()
        .filter(|r| r.role == Role::Validation || r.noise.is_some())
        .partition(|r| r.role != Role::Validation);
    if runs.is_empty() {
        return Err(DesignJobError::NoRuns {
            path: path.to_path_buf(),
            why: "has a fitted log whose noise the design could plan for",
        }
        .into());
    }
    Ok(Basis {
        path: path.to_path_buf(),
        sha256: crate::ingest::sha256_hex(&bytes),
        manifest,
        rig_name: campaign.rig_name,
        campaign: campaign.name,
        rig,
        rig_from: "the rig the results state",
        extension,
        extension_std,
        last_std,
        runs,
        validation,
        ambiguity,
        settle,
    })
}

/// What the joint fit `j` found beyond the paper's model (its delay,
/// mode and piston mass; not the seals' friction, whose describing
/// function depends on the amplitude), and each parameter's stated std.
fn extension_of(j: &crate::results::JointResult) -> (precision::Extension, Vec<(String, f64)>) {
    let value = |name: &str| {
        j.parameters
            .iter()
            .find(|p| p.name == name)
            .map(|p| p.value)
    };
    use crate::identify::joint::Place as Joint;
    let place = j.structure.and_then(|s| s.place()).map(|p| match p {
        Joint::Loop => precision::Place::Loop,
        Joint::Command => precision::Place::Command,
        Joint::Measurement => precision::Place::Measurement,
    });
    let (hz, damping) = match place {
        Some(precision::Place::Loop) => ("valve_hz", "valve_damping"),
        _ => ("mode_hz", "mode_damping"),
    };
    let extension = precision::Extension {
        delay_s: value("delay_s").filter(|t| *t > 0.0),
        mode: place.and_then(|place| {
            Some(precision::Mode {
                place,
                hz: value(hz)?,
                damping: value(damping)?,
            })
        }),
        piston_mass_kg: value("piston_mass_kg").filter(|m| *m > 0.0),
    };
    let stds = extension
        .values()
        .into_iter()
        .filter_map(|(name, _)| {
            let p = j.parameters.iter().find(|p| p.name == name)?;
            Some((name.to_string(), p.total_std))
        })
        .collect();
    (extension, stds)
}

/// A run of last night's as the design may repeat it: one with a linear
/// specimen; an identification run's noise only where it fitted.
fn basis_run(r: RunResult) -> Option<BasisRun> {
    let model = RunModel {
        specimen: r.specimen.linear()?,
        p_gain: r.p_gain,
    };
    let nonlinear = match (&r.linearity, &r.periodic) {
        (Some(lin), _) if !lin.linear => Some(lin.note.clone()),
        (_, Some(p)) if p.distorts => Some(format!(
            "the lines its periodic command left empty held {:.3} times the noise floor",
            p.distortion_to_noise
        )),
        _ => None,
    };
    let identifies = matches!(r.role, Role::NoSpecimen | Role::Spring) && r.status == Status::Ok;
    Some(BasisRun {
        log_file: r.log.as_ref().map(|l| l.file.clone()),
        fit_band_hz: r.fit.as_ref().map(|f| f.band_hz),
        noise: r.noise.filter(|_| identifies),
        id: r.id,
        role: r.role,
        description: r.description,
        p_gain: r.p_gain,
        specimen: r.specimen,
        model,
        log: r.log,
        nonlinear,
    })
}

/// The basis a campaign manifest gives: its nominal `rig.parameters` and
/// its identification runs with linear specimens.
fn from_manifest(path: &Path) -> Result<Basis, JobError> {
    let c: Campaign = match manifest::load_any(path)? {
        Loaded::Campaign(c) => *c,
        Loaded::Simulation(_) => {
            return Err(JobError::WrongKind {
                file: path.to_path_buf(),
                found: "simulation",
                hint: "run it (`servoid simulate MANIFEST --run`) and design from its results, or design from a campaign manifest with nominal [rig.parameters]".into(),
            });
        }
    };
    let rig = c.given_rig.ok_or_else(|| DesignJobError::NoRig {
        path: path.to_path_buf(),
        why: "a design from a manifest needs the rig's nominal values in [rig.parameters]; or design from a campaign's results.json".into(),
    })?;
    let runs: Vec<BasisRun> = c
        .runs
        .into_iter()
        .filter(|r| matches!(r.role, Role::NoSpecimen | Role::Spring))
        .filter_map(|r| {
            let model = RunModel {
                specimen: r.specimen.linear()?,
                p_gain: r.p_gain,
            };
            let log_file = match &r.source {
                RunSource::Log(plan) => Some(plan.path.display().to_string()),
                _ => None,
            };
            Some(BasisRun {
                id: r.id,
                role: r.role,
                description: r.description,
                p_gain: r.p_gain,
                specimen: r.specimen,
                model,
                log_file,
                log: None,
                noise: None,
                fit_band_hz: None,
                nonlinear: None,
            })
        })
        .collect();
    if runs.is_empty() {
        return Err(DesignJobError::NoRuns {
            path: path.to_path_buf(),
            why: "has a linear specimen the design could plan for",
        }
        .into());
    }
    Ok(Basis {
        path: path.to_path_buf(),
        sha256: c.manifest_sha256,
        manifest: c.manifest,
        campaign: c.name,
        rig_name: c.rig_name,
        rig,
        rig_from: "the manifest's nominal rig.parameters",
        extension: precision::Extension::default(),
        extension_std: Vec::new(),
        last_std: None,
        runs,
        validation: Vec::new(),
        ambiguity: None,
        settle: Vec::new(),
    })
}

/// The night to design from the basis's rig and runs, within what `ask`
/// gives and, where it is silent, what last night's logs did; the limits
/// as design.json states them; and where the noise came from.
fn night_plan(
    basis: &Basis,
    ask: &DesignAsk,
) -> Result<(NightPlan, DesignLimits, String), DesignJobError> {
    let given = &ask.limits;
    let logs: Vec<&LogInfo> = basis.runs.iter().filter_map(|r| r.log.as_ref()).collect();
    let largest = |v: Vec<f64>| v.into_iter().reduce(f64::max);
    let band_hz = given
        .band_hz
        .unwrap_or(basis.manifest.identification.band_hz);
    let fs = given
        .sample_rate_hz
        .or_else(|| logs.first().map(|l| l.sample_rate_hz))
        .or(basis
            .manifest
            .channels
            .time
            .as_ref()
            .and_then(|t| t.sample_rate_hz));
    let command = match given.command_m {
        Some(c) => Some((c, "given (--command-mm or [design] command_m)".to_string())),
        None => largest(logs.iter().filter_map(|l| l.command_peak_m).collect()).map(|c| {
            (
                c,
                "the largest command of last night's identification logs".to_string(),
            )
        }),
    };
    let n = basis.runs.len();
    let mut run = match given.run_s {
        Some(s) => Some((s, "given (--run-s or [design] run_s)".to_string())),
        None => largest(logs.iter().map(|l| l.duration_s).collect()).map(|s| {
            (
                s,
                "the longest of last night's identification logs".to_string(),
            )
        }),
    };
    if let Some(night_s) = given.night_s
        && run.as_ref().is_none_or(|(s, _)| night_s / n as f64 <= *s)
    {
        run = Some((
            night_s / n as f64,
            format!("--night-s {night_s} shared by {n} runs"),
        ));
    }
    let noise = planned_noise(basis, given.displacement_noise_m, fs, band_hz);
    let lacking = (command.is_none(), run.is_none());
    let (
        Some(fs),
        Some((command_m, command_from)),
        Some((run_s, run_from)),
        Some((noise, noise_from)),
    ) = (fs, command, run, noise)
    else {
        return Err(missing(basis, fs, lacking.0, lacking.1, given));
    };
    check_asked(ask, fs, band_hz, command_m, run_s)?;
    let plan = NightPlan {
        rig: basis.rig,
        extension: basis.extension,
        runs: basis.runs.iter().map(|r| r.model).collect(),
        noise,
        band_hz,
        sample_rate_hz: fs,
        record_s: run_s,
        rest_s: ask.rest_s,
        intersample: basis.manifest.identification.command_intersample,
        limits: Limits {
            command_m,
            stroke_m: given.stroke_m,
            velocity_m_per_s: given.velocity_m_per_s,
            force_n: given.force_n,
        },
        seed: ask.seed,
    };
    let limits = DesignLimits {
        command_m,
        command_from,
        stroke_m: given.stroke_m,
        velocity_m_per_s: given.velocity_m_per_s,
        force_n: given.force_n,
        run_s,
        run_from,
    };
    Ok((plan, limits, noise_from))
}

/// The noise to plan for, and where it came from: white at the level
/// given, else the mean of what last night's runs measured.
fn planned_noise(
    basis: &Basis,
    rms_m: Option<f64>,
    fs: Option<f64>,
    band_hz: [f64; 2],
) -> Option<(Noise, String)> {
    if let (Some(rms), Some(fs)) = (rms_m, fs) {
        return Some((
            Noise::white(rms, fs, band_hz),
            format!(
                "given: white displacement noise of {} mm RMS at {fs} Hz (--noise-mm or [design] displacement_noise_m)",
                rms * 1e3
            ),
        ));
    }
    let measured: Vec<Noise> = basis.runs.iter().filter_map(|r| r.noise.clone()).collect();
    Noise::mean(&measured).map(|n| {
        (
            n,
            "the mean of last night's identification logs' noise spectra".to_string(),
        )
    })
}

/// What a design from nominal values lacks, every piece at once with its
/// flag and key.
fn missing(
    basis: &Basis,
    fs: Option<f64>,
    no_command: bool,
    no_run: bool,
    given: &DesignSettings,
) -> DesignJobError {
    let mut missing = Vec::new();
    if no_command {
        missing.push("the command's peak (--command-mm or [design] command_m)");
    }
    if no_run {
        missing.push("the time per run (--run-s or [design] run_s) or for the night (--night-s or [design] night_s)");
    }
    if fs.is_none() {
        missing.push(
            "the DAQ's rate (--rate-hz, [design] sample_rate_hz or [channels.time] sample_rate_hz)",
        );
    }
    if given.displacement_noise_m.is_none() && basis.runs.iter().all(|r| r.noise.is_none()) {
        missing.push("the displacement's noise (--noise-mm or [design] displacement_noise_m, m RMS at the rate)");
    }
    DesignJobError::Missing {
        path: basis.path.clone(),
        missing,
    }
}

/// Refuses what no design can meet, naming the flag (or, for a value
/// taken from the results, what it was taken from).
fn check_asked(
    ask: &DesignAsk,
    fs: f64,
    band_hz: [f64; 2],
    command_m: f64,
    run_s: f64,
) -> Result<(), DesignJobError> {
    let bad = |flag: &'static str, value: f64, why: &str| DesignJobError::Flag {
        flag,
        value,
        why: why.to_string(),
    };
    let positive = |flag, v: Option<f64>| match v {
        Some(v) if !(v.is_finite() && v > 0.0) => Err(bad(flag, v, "must be a positive number")),
        _ => Ok(()),
    };
    positive("--stroke-mm", ask.limits.stroke_m.map(|v| v * 1e3))?;
    positive(
        "--velocity-mm-s",
        ask.limits.velocity_m_per_s.map(|v| v * 1e3),
    )?;
    positive("--force-n", ask.limits.force_n)?;
    positive("--rate-hz", Some(fs))?;
    positive("--command-mm", Some(command_m * 1e3))?;
    positive("--run-s", Some(run_s))?;
    positive("--target-std", ask.limits.target_relative_std)?;
    positive(
        "--noise-mm",
        ask.limits.displacement_noise_m.map(|v| v * 1e3),
    )?;
    if !(ask.rest_s.is_finite() && ask.rest_s >= 0.0) {
        return Err(bad("--rest-s", ask.rest_s, "must be zero or more"));
    }
    if !(band_hz[0] > 0.0 && band_hz[0] < band_hz[1] && band_hz[1] < 0.5 * fs) {
        return Err(bad(
            "--band-hz",
            band_hz[1],
            &format!(
                "the band {}-{} Hz must rise from above 0 to below half the rate ({} Hz)",
                band_hz[0],
                band_hz[1],
                0.5 * fs
            ),
        ));
    }
    Ok(())
}

/// design.json's content.
fn design_result(
    basis: &Basis,
    plan: &NightPlan,
    night: &Night,
    limits: DesignLimits,
    noise_from: String,
    ask: &DesignAsk,
) -> DesignResult {
    let (parameters, baseline) = precision_table(basis, plan, night);
    DesignResult {
        servoid_version: env!("CARGO_PKG_VERSION").to_string(),
        source: basis.path.display().to_string(),
        source_sha256: basis.sha256.clone(),
        campaign: basis.campaign.clone(),
        rig_name: basis.rig_name.clone(),
        rig: plan.rig,
        rig_from: basis.rig_from.to_string(),
        sample_rate_hz: plan.sample_rate_hz,
        band_hz: plan.band_hz,
        record_s: night.record_s,
        rest_s: plan.rest_s,
        period_s: night.period_s,
        periods: night.periods,
        optimal_share: night.optimal_share,
        draw: night.draw,
        lines_excited: night.lines_hz.len(),
        lines_detection: night.detection_hz.len(),
        limits,
        target_relative_std: ask.limits.target_relative_std,
        parameters,
        baseline,
        runs: designed_runs(night, &basis.runs, &plan.limits),
        questions: Vec::new(),
        noise: plan.noise.clone(),
        noise_from,
        noise_spread: {
            let psd = &plan.noise.psd_m2_per_hz;
            psd.iter().fold(0.0, |m: f64, &p| m.max(p))
                / psd.iter().fold(f64::INFINITY, |m, &p| m.min(p))
        },
        lines: night::line_levels(plan, night),
        tried: night.tried.clone(),
    }
}

/// Each rig parameter's std: last night's stated, the designed night's
/// predicted and the paper's chirps' at the same record and peak; and
/// the night against the chirps.
fn precision_table(
    basis: &Basis,
    plan: &NightPlan,
    night: &Night,
) -> (Vec<DesignedParameter>, Option<DesignBaseline>) {
    let (rig, last_std) = (&plan.rig, basis.last_std);
    let std = night.precision.std();
    let relative = night.precision.relative_std(rig);
    let chirps = night::chirp_baseline(plan, night.record_s);
    let chirp_std = chirps.as_ref().map(|c| c.std());
    let fs = plan.sample_rate_hz;
    let white = Noise::white(check_noise_rms_m(&plan.noise, fs), fs, plan.band_hz);
    let check = night::precision_under(plan, night, &white);
    let check_std = check.as_ref().map(|c| c.std());
    let values = precision::values(rig);
    let mut parameters: Vec<DesignedParameter> = precision::NAMES
        .iter()
        .enumerate()
        .map(|(j, name)| DesignedParameter {
            name: name.to_string(),
            value: values[j],
            last_std: last_std.and_then(|s| s[j]),
            std: std[j],
            relative_std: relative[j],
            chirp_std: chirp_std.map(|c| c[j]),
            check_std: check_std.map(|c| c[j]),
        })
        .collect();
    // The extension's parameters, estimated beside the rig's.
    for (k, &(name, value, std)) in night.precision.extension.iter().enumerate() {
        parameters.push(DesignedParameter {
            name: name.to_string(),
            value,
            last_std: basis
                .extension_std
                .iter()
                .find(|(n, _)| n == name)
                .map(|(_, s)| *s),
            std,
            relative_std: std / value.abs(),
            chirp_std: chirps.as_ref().and_then(|c| Some(c.extension.get(k)?.2)),
            check_std: check.as_ref().and_then(|c| Some(c.extension.get(k)?.2)),
        });
    }
    let baseline = chirps.map(|c| {
        let theirs = c.relative_std(rig);
        let max = |r: [f64; 4]| r.into_iter().fold(0.0, f64::max);
        let squares = |r: [f64; 4]| r.iter().map(|r| r * r).sum::<f64>();
        let [f0, f1] = night::chirp_band_hz(plan);
        DesignBaseline {
            description: format!(
                "the paper's quadratic chirp from {f0} to {f1} Hz (Sec. 3.2.2) over the same record at the same peak command, read as an ETFE"
            ),
            worst_ratio: max(theirs) / max(relative),
            squares_ratio: squares(theirs) / squares(relative),
        }
    });
    (parameters, baseline)
}

/// The designed identification runs as design.json states them.
fn designed_runs(night: &Night, runs: &[BasisRun], limits: &Limits) -> Vec<DesignedRunResult> {
    runs.iter()
        .zip(&night.runs)
        .map(|(l, d)| {
            let id = &l.id;
            DesignedRunResult {
                id: id.clone(),
                role: l.role,
                description: l.description.clone(),
                p_gain: l.p_gain,
                specimen: l.specimen,
                command_csv: format!("commands/{id}.csv"),
                command_mat: format!("commands/{id}.mat"),
                log: log_like(id, l.log_file.as_deref().unwrap_or("")),
                crest_factor: d.crest_factor,
                rms_m: d.rms_m,
                peaks: d.peaks,
                bound_by: Some(d.bound_by),
                used: used(&d.peaks, limits),
                repeats: None,
                amplitude_share: 1.0,
                band_hz: None,
                command_log: command_log_file(id, l.log_file.as_deref().unwrap_or("")),
            }
        })
        .collect()
}

/// Each limit given, with the run's predicted peak against it.
fn used(p: &night::Peaks, limits: &Limits) -> Vec<LimitUsed> {
    let all = [
        (Limit::Command, Some(p.command_m), Some(limits.command_m)),
        (Limit::Stroke, Some(p.displacement_m), limits.stroke_m),
        (
            Limit::Velocity,
            Some(p.velocity_m_per_s),
            limits.velocity_m_per_s,
        ),
        (Limit::Force, p.force_n, limits.force_n),
    ];
    all.into_iter()
        .filter_map(|(limit, peak, value)| {
            let (peak, value) = (peak?, value?);
            Some(LimitUsed {
                limit,
                peak,
                value,
                share: peak / value,
            })
        })
        .collect()
}

/// The log the next night's manifest expects for run `id`: `logs/<id>`
/// with the extension of `like`, a log of last night's (the DAQ writes
/// the same format), CSV where it has none.
fn log_like(id: &str, like: &str) -> String {
    let ext = Path::new(like)
        .extension()
        .map_or("csv".into(), |e| e.to_string_lossy());
    format!("logs/{id}.{ext}")
}

/// Writes the design's files into `dir` (the output set's work folder).
fn write_design(
    dir: &Path,
    basis: &Basis,
    commands: &[Vec<f64>],
    result: &DesignResult,
) -> Result<(), report::WriteError> {
    let fs = result.sample_rate_hz;
    for (run, command) in result.runs.iter().zip(commands) {
        report::write_artifact(
            &dir.join(&run.command_csv),
            command_csv(command, fs).as_bytes(),
        )?;
        report::write_artifact(
            &dir.join(&run.command_mat),
            &command_mat(command, fs, &run.id),
        )?;
        if let Some(file) = &run.command_log {
            let path = dir.join(file);
            let bytes = command_log(command, fs, &path)
                .map_err(|e| report::WriteError::Table(Box::new(e)))?;
            report::write_artifact(&path, &bytes)?;
        }
    }
    report::write_artifact(
        &dir.join("campaign.toml"),
        next_manifest(basis, result).as_bytes(),
    )?;
    report::write_artifact(
        &dir.join("check.toml"),
        check_manifest(basis, result).as_bytes(),
    )?;
    report::write_artifact(&dir.join("design.json"), &report::json_bytes(result))?;
    let files = report::FigureFiles::new(dir, report::FigureFormats::All)
        .expect("all formats draw figures");
    let (figures, notes) = files.write(&[report::figures::catalogue::design_figure(result)])?;
    report::write_artifact(
        &dir.join("design.html"),
        report::design_page(result, &figures, &notes)?.as_bytes(),
    )?;
    report::settle(dir)
}

/// A command as CSV: time_s (s) and command_m (m), a row per sample,
/// each number in the fewest digits that read back to the same double.
fn command_csv(u: &[f64], fs: f64) -> String {
    let mut text = String::with_capacity(u.len() * 32);
    text.push_str("time_s,command_m\n");
    for (j, v) in u.iter().enumerate() {
        text.push_str(&format!("{},{}\n", j as f64 / fs, v));
    }
    text
}

/// The format of last night's logs where the design writes the commands
/// in it too (CSV and MAT 5 it writes for every run).
fn log_format(log: &str) -> Option<crate::manifest::simulation::OutputFormat> {
    use crate::manifest::simulation::OutputFormat;
    match Path::new(log).extension()?.to_str()? {
        "parquet" => Some(OutputFormat::Parquet),
        "h5" | "hdf5" => Some(OutputFormat::Hdf5),
        "tdms" => Some(OutputFormat::Tdms),
        _ => None,
    }
}

/// The command file for a run whose log is `log`, in the log's format,
/// where that is another than CSV and MAT.
fn command_log_file(id: &str, log: &str) -> Option<String> {
    log_format(log).map(|f| format!("commands/{id}.{}", f.extension()))
}

/// A command in the format `path`'s extension names: columns time_s (s)
/// and command_m (m).
fn command_log(
    u: &[f64],
    fs: f64,
    path: &Path,
) -> Result<Vec<u8>, report::columns::ColumnWriteError> {
    let time: Vec<f64> = (0..u.len()).map(|j| j as f64 / fs).collect();
    let format = log_format(&path.display().to_string())
        .expect("a command log is written only in a format log_format names");
    report::columns::columns_bytes(
        format,
        path,
        &[
            report::columns::UnitColumn {
                name: "time_s",
                unit: "s",
                values: &time,
            },
            report::columns::UnitColumn {
                name: "command_m",
                unit: "m",
                values: u,
            },
        ],
        1.0 / fs,
    )
}

/// A command as a MAT 5 file: column vectors time_s (s) and command_m (m).
fn command_mat(u: &[f64], fs: f64, id: &str) -> Vec<u8> {
    let column = |data: Vec<f64>| matlab::MatValue::Matrix {
        rows: data.len(),
        cols: 1,
        data,
    };
    let time: Vec<f64> = (0..u.len()).map(|j| j as f64 / fs).collect();
    matlab::mat_bytes(
        &format!("servoid design: run {id}'s command, time_s (s) and command_m (m)"),
        &[
            ("time_s".to_string(), column(time)),
            ("command_m".to_string(), column(u.to_vec())),
        ],
    )
    .expect("two plain column vectors with valid names")
}

/// The next night's manifest: last night's campaign (channels, settings)
/// with the designed runs, each expecting its log under logs/.
fn next_manifest(basis: &Basis, result: &DesignResult) -> String {
    let mut m: Manifest = basis.manifest.clone();
    m.campaign.synthetic = None;
    m.campaign.description = format!(
        "The identification runs servoid design made from {}: odd multisines of {} s, {} periods a run",
        result.source, result.period_s, result.periods
    );
    m.rig.parameters = None;
    m.runs = result
        .runs
        .iter()
        .map(|d| {
            // A run that settles a question has the specimen, channels and
            // band of the run it repeats.
            let like = d.repeats.as_deref().unwrap_or(&d.id);
            let stated = basis.manifest.runs.iter().find(|r| r.id == like);
            let l = basis.runs.iter().find(|l| l.id == like);
            Run {
                id: d.id.clone(),
                role: d.role,
                description: d.description.clone(),
                date: None,
                p_gain: d.p_gain,
                specimen: stated_specimen(&d.specimen),
                data: Some(RunData {
                    log: Some(d.log.clone()),
                    ..RunData::default()
                }),
                channels: stated.and_then(|r| r.channels.clone()),
                band_hz: d
                    .band_hz
                    .or(stated.and_then(|r| r.band_hz))
                    .or(l.and_then(|l| l.fit_band_hz)),
            }
        })
        .collect();
    m.identification = identification(basis, result);
    m.references.clear();
    m.numbered_figures.clear();
    m.run_table = None;
    m.history = None;
    let mut text = format!(
        "# Tomorrow night's identification runs, designed by `servoid design` from\n# {} (SHA-256 {}).\n# Play commands/<run>.csv (or .mat) on the controller, save each run's log\n# as the run's `log` below, then `servoid run campaign.toml`. Add your\n# nightly [history] as your own manifest has it.\n\n",
        result.source, result.source_sha256
    );
    text.push_str(&toml::to_string(&m).expect("the manifest serialises to TOML"));
    text
}

/// The white noise check.toml plays (m RMS at `fs`): the planned
/// density's mean over its bands.
fn check_noise_rms_m(noise: &Noise, fs: f64) -> f64 {
    let psd = &noise.psd_m2_per_hz;
    (psd.iter().sum::<f64>() / psd.len() as f64 * fs / 2.0).sqrt()
}

/// The extension's mode and piston as a simulation manifest's
/// `[rig.unmodelled]` gives them (its delay is the displacement's).
fn unmodelled(ext: &precision::Extension) -> toml::Table {
    use toml::Value;
    let mut t = toml::Table::new();
    if let Some(m) = ext.mode {
        let key = match m.place {
            precision::Place::Loop => "valve_mode",
            precision::Place::Command => "command_mode",
            precision::Place::Measurement => "measurement_mode",
        };
        let mut mode = toml::Table::new();
        mode.insert("natural_frequency_hz".into(), Value::Float(m.hz));
        mode.insert("damping_ratio".into(), Value::Float(m.damping));
        t.insert(key.into(), Value::Table(mode));
    }
    if let Some(mp) = ext.piston_mass_kg {
        t.insert("piston_mass_kg".into(), Value::Float(mp));
    }
    t
}

/// The next night's identification settings: last night's, with the
/// validation runs in the joint fit where a run added to settle a
/// structure is one.
fn identification(basis: &Basis, result: &DesignResult) -> manifest::Identification {
    let mut ident = basis.manifest.identification.clone();
    if result.runs.iter().any(|r| r.role == Role::Validation) {
        ident.joint.include_validation = true;
    }
    ident
}

/// A designed run's linear specimen as a manifest states it; None for no
/// specimen.
fn stated_specimen(specimen: &SpecimenModel) -> Option<manifest::Specimen> {
    let (m, c, k) = specimen.linear_mck()?;
    let given = |v: f64| (v != 0.0).then_some(v);
    (k != 0.0 || m != 0.0).then(|| manifest::Specimen {
        mass_kg: given(m),
        damping_ns_per_m: given(c),
        stiffness_n_per_m: given(k),
        ..manifest::Specimen::default()
    })
}

/// A simulation manifest that plays the designed commands on the rig
/// planned at, with white displacement noise at the level measured
/// (the mean over the band of the noise planned for).
fn check_manifest(basis: &Basis, result: &DesignResult) -> String {
    use toml::{Table, Value};
    let fs = result.sample_rate_hz;
    let rms_mm = check_noise_rms_m(&result.noise, fs) * 1e3;
    let table = |pairs: Vec<(&str, Value)>| -> Value {
        Value::Table(pairs.into_iter().map(|(k, v)| (k.to_string(), v)).collect())
    };
    let s = |v: &str| Value::String(v.to_string());
    let file =
        |run: &DesignedRunResult| table(vec![("kind", s("file")), ("file", s(&run.command_csv))]);
    let mut doc = Table::new();
    doc.insert("schema_version".into(), Value::Integer(1));
    doc.insert(
        "simulation".into(),
        table(vec![
            ("name", s(&format!("{}-design-check", result.campaign))),
            (
                "description",
                s("SYNTHETIC: the designed commands played on the rig servoid identified, with the displacement noise it measured"),
            ),
            ("sample_rate_hz", Value::Float(fs)),
            ("seed", Value::Integer(1)),
            ("log_format", s("csv")),
        ]),
    );
    let mut rig = vec![
        ("name", s(&result.rig_name)),
        (
            "parameters",
            Value::try_from(result.rig).expect("the rig serialises"),
        ),
    ];
    let unmodelled = unmodelled(&basis.extension);
    if !unmodelled.is_empty() {
        rig.push(("unmodelled", Value::Table(unmodelled)));
    }
    doc.insert("rig".into(), table(rig));
    doc.insert("excitation".into(), file(&result.runs[0]));
    let ext = &basis.extension;
    let mut displacement = vec![("unit", s("mm")), ("noise_rms", Value::Float(rms_mm))];
    if let Some(tau) = ext.delay_s {
        displacement.push(("delay_s", Value::Float(tau)));
    }
    doc.insert(
        "instrument".into(),
        table(vec![
            ("command", table(vec![("unit", s("mm"))])),
            ("displacement", table(displacement)),
            ("force", table(vec![("unit", s("kN"))])),
        ]),
    );
    doc.insert(
        "identification".into(),
        Value::try_from(identification(basis, result)).expect("the settings serialise"),
    );
    let runs = result
        .runs
        .iter()
        .map(|r| {
            let mut run = Table::new();
            run.insert("id".into(), s(&r.id));
            run.insert(
                "role".into(),
                Value::try_from(r.role).expect("a role serialises"),
            );
            run.insert("p_gain".into(), Value::Float(r.p_gain));
            if let Some(spec) = stated_specimen(&r.specimen) {
                run.insert(
                    "specimen".into(),
                    Value::try_from(spec).expect("a specimen serialises"),
                );
            }
            run.insert("excitation".into(), file(r));
            Value::Table(run)
        })
        .collect();
    doc.insert("runs".into(), Value::Array(runs));
    let mut text = format!(
        "# Checks the design before the lab runs it: `servoid simulate check.toml --run`\n# plays commands/<run>.csv on the rig {} states, with {rms_mm:.3e} mm RMS of\n# white displacement noise (the level it measured). The logs are SYNTHETIC.\n",
        result.source
    );
    if result.noise_spread > 2.0 {
        text.push_str(&format!(
            "# The noise planned for is not white (its density spans {:.1} times over the\n# band): this white noise at its mean level is more at some lines and less at\n# others, so the stds this check states are design.json's check_std, not its\n# std (what the measured noise gives).\n",
            result.noise_spread
        ));
    }
    text.push('\n');
    text.push_str(&toml::to_string(&doc).expect("the check serialises to TOML"));
    text
}
