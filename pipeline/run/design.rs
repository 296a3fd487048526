//! `servoid design RESULTS`: tomorrow night's identification runs from the
//! rig and noise a campaign's results.json states (`design::night`),
//! written as one output set: each run's command as the controller's
//! waveform generator plays it (`commands/<run>.csv` and `.mat`, time_s and
//! command_m at the DAQ's rate, rest to rest), the next night's manifest
//! for the logs to come (campaign.toml), a simulation manifest that plays
//! the commands on the identified rig with the noise measured (check.toml,
//! for `servoid simulate --run` before the lab runs them), design.json and
//! the page to read first (design.html).

use std::path::{Path, PathBuf};

use crate::design::night::{self, DesignError, Limit, Limits, Night, NightPlan, Noise};
use crate::design::precision;
use crate::design::spectrum::RunModel;
use crate::manifest::{DesignSettings, Manifest, Role, Run, RunData};
use crate::model::RigParams;
use crate::report::{self, matlab};
use crate::results::{
    DesignBaseline, DesignLimits, DesignQuestion, DesignResult, DesignedParameter,
    DesignedRunResult, LimitUsed, Results, RunResult, Status,
};

use super::JobError;

/// What the design is asked beside the results: the limits and times
/// (each absent one taken from the campaign's `[design]`, then from the
/// results, or not applied), the rate (default: the logs'), the rest
/// around each command, the seed of the detection lines.
#[derive(Debug, Clone, Default)]
pub struct DesignAsk {
    pub out: Option<PathBuf>,
    pub limits: DesignSettings,
    pub sample_rate_hz: Option<f64>,
    pub rest_s: f64,
    pub seed: u64,
    pub wait: Option<std::time::Duration>,
}

/// Why a design was not written.
#[derive(Debug, thiserror::Error)]
pub enum DesignJobError {
    #[error("{}: the results state no rig to design from ({why})", path.display())]
    NoRig { path: PathBuf, why: String },
    #[error(
        "{}: no identification run (role no_specimen or spring) has a fitted log whose noise the design could plan for",
        path.display()
    )]
    NoRuns { path: PathBuf },
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

/// Last night's identification run a designed run repeats: its result,
/// the noise it measured and its model.
struct LastRun<'a> {
    result: &'a RunResult,
    noise: &'a Noise,
    model: RunModel,
}

/// Designs tomorrow night from `results_path` and writes it (see the
/// module's header).
pub fn design_night(results_path: &Path, ask: &DesignAsk) -> Result<Designed, JobError> {
    let (bytes, results) = super::verify::read_results(results_path)?;
    let ask = &DesignAsk {
        limits: ask.limits.clone().or(results.manifest.design.as_ref()),
        ..ask.clone()
    };
    let last = last_runs(&results);
    let (plan, limits) = night_plan(results_path, &results, &last, ask)?;
    let designed = night::design(&plan, ask.limits.target_relative_std).map_err(|source| {
        DesignJobError::Design {
            path: results_path.to_path_buf(),
            source,
        }
    })?;
    let source = Source {
        path: results_path.display().to_string(),
        sha256: crate::ingest::sha256_hex(&bytes),
    };
    let mut result = design_result(&results, &plan, &designed, &last, limits, ask, &source);
    let mut commands: Vec<Vec<f64>> = designed.runs.iter().map(|r| r.command_m.clone()).collect();
    for (from, question) in nonlinear_questions(&last) {
        let (run, q) = second_amplitude(&result.runs[from], question, &plan.limits);
        commands.push(
            commands[from]
                .iter()
                .map(|u| run.amplitude_share * u)
                .collect(),
        );
        result.runs.push(run);
        result.questions.push(q);
    }
    let out_dir = ask.out.clone().unwrap_or_else(|| {
        PathBuf::from("reports").join(format!("{}-design", results.campaign.name))
    });
    let set = super::begin(&out_dir, ask.wait)?;
    write_design(set.dir(), &results, &commands, &result, &last).map_err(|e| set.relocate(e))?;
    set.commit()?;
    Ok(Designed { out_dir, result })
}

/// The night to design from the results' rig and `last` night's runs,
/// within what `ask` gives and, where it is silent, what last night's
/// logs did; and the limits as design.json states them.
fn night_plan(
    results_path: &Path,
    results: &Results,
    last: &[LastRun],
    ask: &DesignAsk,
) -> Result<(NightPlan, DesignLimits), DesignJobError> {
    let rig = rig_of(results).ok_or_else(|| DesignJobError::NoRig {
        path: results_path.to_path_buf(),
        why: results
            .rig_error
            .clone()
            .unwrap_or_else(|| "rig is null".into()),
    })?;
    let Some(first) = last.first() else {
        return Err(DesignJobError::NoRuns {
            path: results_path.to_path_buf(),
        });
    };
    let log = |r: &LastRun| r.result.log.clone();
    let fs = ask
        .sample_rate_hz
        .or_else(|| log(first).map(|l| l.sample_rate_hz))
        .unwrap_or(1000.0);
    let band_hz = ask
        .limits
        .band_hz
        .unwrap_or(results.manifest.identification.band_hz);
    let (command_m, command_from) = match ask.limits.command_m {
        Some(c) => (c, "given (--command-mm or [design] command_m)".to_string()),
        None => (
            last.iter()
                .filter_map(|r| log(r)?.command_peak_m)
                .fold(0.0, f64::max),
            "the largest command of last night's identification logs".to_string(),
        ),
    };
    let longest = last
        .iter()
        .filter_map(|r| log(r).map(|l| l.duration_s))
        .fold(0.0, f64::max);
    let (mut run_s, mut run_from) = match ask.limits.run_s {
        Some(s) => (s, "given (--run-s or [design] run_s)".to_string()),
        None => (
            longest,
            "the longest of last night's identification logs".to_string(),
        ),
    };
    if let Some(night_s) = ask.limits.night_s
        && night_s / last.len() as f64 <= run_s
    {
        run_s = night_s / last.len() as f64;
        run_from = format!("--night-s {night_s} shared by {} runs", last.len());
    }
    check_asked(ask, fs, band_hz, command_m, run_s)?;
    let noise = Noise::mean(&last.iter().map(|r| r.noise.clone()).collect::<Vec<_>>())
        .expect("at least one run");
    let plan = NightPlan {
        rig,
        runs: last.iter().map(|r| r.model).collect(),
        noise,
        band_hz,
        sample_rate_hz: fs,
        record_s: run_s,
        rest_s: ask.rest_s,
        intersample: results.manifest.identification.command_intersample,
        limits: Limits {
            command_m,
            stroke_m: ask.limits.stroke_m,
            velocity_m_per_s: ask.limits.velocity_m_per_s,
            force_n: ask.limits.force_n,
        },
        seed: ask.seed,
    };
    let limits = DesignLimits {
        command_m,
        command_from,
        stroke_m: ask.limits.stroke_m,
        velocity_m_per_s: ask.limits.velocity_m_per_s,
        force_n: ask.limits.force_n,
        run_s,
        run_from,
    };
    Ok((plan, limits))
}

/// The results.json designed from.
struct Source {
    path: String,
    sha256: String,
}

/// The rig the results state, a1b0 at its P gain.
fn rig_of(results: &Results) -> Option<RigParams> {
    let r = results.rig.as_ref()?;
    Some(RigParams {
        beta1_per_s: r.beta1.value,
        a1b0_n_per_m_s2: r.a1b0.value,
        a2_n_per_m: r.a2.value,
        a3_per_s: r.a3.value,
        p_gain: r.p_gain,
    })
}

/// The identification runs that fitted a log with a linear specimen, in
/// the results' order: what the night repeats.
fn last_runs(results: &Results) -> Vec<LastRun<'_>> {
    results
        .runs
        .iter()
        .filter(|r| matches!(r.role, Role::NoSpecimen | Role::Spring) && r.status == Status::Ok)
        .filter_map(|r| {
            let noise = r.noise.as_ref()?;
            Some(LastRun {
                result: r,
                noise,
                model: RunModel {
                    specimen: r.specimen.linear()?,
                    p_gain: r.p_gain,
                },
            })
        })
        .collect()
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
    results: &Results,
    plan: &NightPlan,
    night: &Night,
    last: &[LastRun],
    limits: DesignLimits,
    ask: &DesignAsk,
    source: &Source,
) -> DesignResult {
    let (parameters, baseline) = precision_table(results, plan, night);
    DesignResult {
        servoid_version: env!("CARGO_PKG_VERSION").to_string(),
        source: source.path.clone(),
        source_sha256: source.sha256.clone(),
        campaign: results.campaign.name.clone(),
        rig_name: results.campaign.rig_name.clone(),
        rig: plan.rig,
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
        runs: designed_runs(night, last, &plan.limits),
        questions: Vec::new(),
        noise: plan.noise.clone(),
        tried: night.tried.clone(),
    }
}

/// Each rig parameter's std: last night's stated, the designed night's
/// predicted and the paper's chirps' at the same record and peak; and
/// the night against the chirps.
fn precision_table(
    results: &Results,
    plan: &NightPlan,
    night: &Night,
) -> (Vec<DesignedParameter>, Option<DesignBaseline>) {
    let rig = &plan.rig;
    let std = night.precision.std();
    let relative = night.precision.relative_std(rig);
    let chirps = night::chirp_baseline(plan, night.record_s);
    let chirp_std = chirps.map(|c| c.std());
    let last_std = results
        .rig
        .as_ref()
        .map(|r| [r.beta1.std, r.a1b0.std, r.a2.std, r.a3.std]);
    let values = precision::values(rig);
    let parameters = precision::NAMES
        .iter()
        .enumerate()
        .map(|(j, name)| DesignedParameter {
            name: name.to_string(),
            value: values[j],
            last_std: last_std.and_then(|s| s[j]),
            std: std[j],
            relative_std: relative[j],
            chirp_std: chirp_std.map(|c| c[j]),
        })
        .collect();
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
fn designed_runs(night: &Night, last: &[LastRun], limits: &Limits) -> Vec<DesignedRunResult> {
    last.iter()
        .zip(&night.runs)
        .map(|(l, d)| {
            let id = &l.result.id;
            DesignedRunResult {
                id: id.clone(),
                role: l.result.role,
                description: l.result.description.clone(),
                p_gain: l.result.p_gain,
                specimen: l.result.specimen,
                command_csv: format!("commands/{id}.csv"),
                command_mat: format!("commands/{id}.mat"),
                log: log_like(id, l.result.log.as_ref().map_or("", |g| &g.file)),
                crest_factor: d.crest_factor,
                rms_m: d.rms_m,
                peaks: d.peaks,
                bound_by: Some(d.bound_by),
                used: used(&d.peaks, limits),
                repeats: None,
                amplitude_share: 1.0,
            }
        })
        .collect()
}

/// The share of its amplitude at which a run whose rig answered it
/// nonlinearly is played again.
const SECOND_AMPLITUDE: f64 = 0.5;

/// The identification runs (by index) whose logs said the rig is not
/// linear at their amplitude, with what they said: harmonics of a
/// sweep's command, or a periodic command's empty lines above the noise.
fn nonlinear_questions(last: &[LastRun]) -> Vec<(usize, String)> {
    last.iter()
        .enumerate()
        .filter_map(|(i, l)| {
            let r = l.result;
            let said = match (&r.linearity, &r.periodic) {
                (Some(lin), _) if !lin.linear => lin.note.clone(),
                (_, Some(p)) if p.distorts => format!(
                    "the lines its periodic command left empty held {:.3} times the noise floor",
                    p.distortion_to_noise
                ),
                _ => return None,
            };
            Some((i, format!("last night's run {}: {said}", r.id)))
        })
        .collect()
}

/// The run that plays `from`'s command again at [`SECOND_AMPLITUDE`] of
/// its amplitude, and the question it settles.
fn second_amplitude(
    from: &DesignedRunResult,
    question: String,
    limits: &Limits,
) -> (DesignedRunResult, DesignQuestion) {
    let share = SECOND_AMPLITUDE;
    let id = format!("{}-half", from.id);
    let peaks = from.peaks.scaled(share);
    let run = DesignedRunResult {
        id: id.clone(),
        role: Role::Fit,
        description: format!(
            "{}'s command at {} of its amplitude: is the rig linear?",
            from.id, share
        ),
        p_gain: from.p_gain,
        specimen: from.specimen,
        command_csv: format!("commands/{id}.csv"),
        command_mat: format!("commands/{id}.mat"),
        log: log_like(&id, &from.log),
        crest_factor: from.crest_factor,
        rms_m: share * from.rms_m,
        peaks,
        bound_by: None,
        used: used(&peaks, limits),
        repeats: Some(from.id.clone()),
        amplitude_share: share,
    };
    let answers = format!(
        "Run {id} plays {from}'s command at half its amplitude and is fitted on its own (role fit). Where the rig is linear its transfer function (results.json's runs[].fit) agrees with {from}'s within their stds, and its empty lines hold the noise floor. Seal friction lowers the gain at low frequencies, more at the lower amplitude (its describing function grows as the amplitude falls: docs/methods.md, \"Seal friction\"); a spring that stiffens is softer at the lower amplitude; the valve's flow law changes the gain with the velocity. Where the two agree, what last night saw was not the rig's amplitude.",
        from = from.id
    );
    (
        run,
        DesignQuestion {
            question,
            run: id,
            answers,
        },
    )
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
    results: &Results,
    commands: &[Vec<f64>],
    result: &DesignResult,
    last: &[LastRun],
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
    }
    report::write_artifact(
        &dir.join("campaign.toml"),
        next_manifest(results, result, last).as_bytes(),
    )?;
    report::write_artifact(
        &dir.join("check.toml"),
        check_manifest(results, result).as_bytes(),
    )?;
    report::write_artifact(&dir.join("design.json"), &report::json_bytes(result))?;
    report::write_artifact(
        &dir.join("design.html"),
        report::design_page(result)?.as_bytes(),
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
fn next_manifest(results: &Results, result: &DesignResult, last: &[LastRun]) -> String {
    let mut m: Manifest = results.manifest.clone();
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
            let stated = results.manifest.runs.iter().find(|r| r.id == like);
            let l = last.iter().find(|l| l.result.id == like);
            Run {
                id: d.id.clone(),
                role: d.role,
                description: d.description.clone(),
                date: None,
                p_gain: d.p_gain,
                specimen: stated.and_then(|r| r.specimen.clone()),
                data: Some(RunData {
                    log: Some(d.log.clone()),
                    ..RunData::default()
                }),
                channels: stated.and_then(|r| r.channels.clone()),
                band_hz: stated
                    .and_then(|r| r.band_hz)
                    .or(l.and_then(|l| l.result.fit.as_ref()).map(|f| f.band_hz)),
            }
        })
        .collect();
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

/// A simulation manifest that plays the designed commands on the rig the
/// results state, with white displacement noise at the level measured
/// (the mean over the band of the noise planned for).
fn check_manifest(results: &Results, result: &DesignResult) -> String {
    use toml::{Table, Value};
    let fs = result.sample_rate_hz;
    let psd = &result.noise.psd_m2_per_hz;
    let rms_mm = (psd.iter().sum::<f64>() / psd.len() as f64 * fs / 2.0).sqrt() * 1e3;
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
    doc.insert(
        "rig".into(),
        table(vec![
            ("name", s(&result.rig_name)),
            (
                "parameters",
                Value::try_from(result.rig).expect("the rig serialises"),
            ),
        ]),
    );
    doc.insert("excitation".into(), file(&result.runs[0]));
    doc.insert(
        "instrument".into(),
        table(vec![
            ("command", table(vec![("unit", s("mm"))])),
            (
                "displacement",
                table(vec![("unit", s("mm")), ("noise_rms", Value::Float(rms_mm))]),
            ),
            ("force", table(vec![("unit", s("kN"))])),
        ]),
    );
    doc.insert(
        "identification".into(),
        Value::try_from(&results.manifest.identification).expect("the settings serialise"),
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
            let like = r.repeats.as_deref().unwrap_or(&r.id);
            if let Some(spec) = results
                .manifest
                .runs
                .iter()
                .find(|x| x.id == like)
                .and_then(|x| x.specimen.clone())
            {
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
        "# Checks the design before the lab runs it: `servoid simulate check.toml --run`\n# plays commands/<run>.csv on the rig {} states, with {rms_mm:.3e} mm RMS of\n# white displacement noise (the level it measured). The logs are SYNTHETIC.\n\n",
        result.source
    );
    text.push_str(&toml::to_string(&doc).expect("the check serialises to TOML"));
    text
}
