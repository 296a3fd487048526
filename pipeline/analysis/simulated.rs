//! A simulated campaign, pure: each run's command, plant response and
//! instrument chains from a checked simulation manifest (`SimulationPlan`),
//! the truth they were drawn from, and the analysis manifest that reads
//! their logs back. `run` writes the logs, truth.json and campaign.toml.

use std::path::PathBuf;

use sha2::{Digest, Sha256};

use crate::ingest::Column;
use crate::ingest::command::CommandFile;
use crate::manifest::simulation::{Command, OutputFormat, SimRunPlan, SimulationPlan};
use crate::manifest::{
    CampaignInfo, Channel, Channels, Manifest, Reference, Rig, Role, Run, RunData, SCHEMA_VERSION,
    Specimen, SpecimenKind, TimeChannel,
};
use crate::model;
use crate::results::{Truth, TruthRun};
use crate::simulate::excitation::{self, Excitation, ExcitationError};
use crate::simulate::instrument::{self, InstrumentError, Sensor};
use crate::simulate::{SimError, plant};
use crate::units::{TimeUnit, format_number};

/// Why one simulated run failed.
#[derive(Debug, thiserror::Error)]
pub enum SimRunError {
    #[error("run {run}: {source}")]
    Excitation {
        run: String,
        #[source]
        source: ExcitationError,
    },
    #[error("run {run}: {source}")]
    Plant {
        run: String,
        #[source]
        source: SimError,
    },
    #[error("run {run}: {source}")]
    Instrument {
        run: String,
        #[source]
        source: InstrumentError,
    },
    #[error(
        "run {run}: the command file {} is sampled at {} Hz, but simulation.sample_rate_hz is {} Hz: a waveform generator plays one sample per tick, so write the command at the simulation's rate",
        path.display(), format_number(*file_hz, 9), format_number(*sample_rate_hz, 9)
    )]
    CommandRate {
        run: String,
        path: PathBuf,
        file_hz: f64,
        sample_rate_hz: f64,
    },
    #[error("run {run}: the command file {} was not read before the run was simulated", path.display())]
    CommandNotRead { run: String, path: PathBuf },
    #[error("run {run}: the rig's model with its specimen leaves f64's range: {source}")]
    Model {
        run: String,
        #[source]
        source: crate::lti::LtiError,
    },
}

/// The simulated signals of one run, in the channels' units.
pub struct RunSignals {
    pub columns: Vec<(String, Vec<f64>)>,
    /// Each column's unit, as formats that state units write it.
    pub units: Vec<&'static str>,
    /// The run's truth; its log's name and hash are filled in once the log is made.
    pub truth: TruthRun,
}

fn column_name(channel: &str, sensor: &Sensor) -> String {
    format!("{channel}_{}", sensor.unit.symbol().to_ascii_lowercase())
}

/// The command a run plays before the controller's limit: generated, or
/// the command file `played` (read for a run whose command is a file) at
/// the simulation's rate, with the run's padding.
fn command_signal(
    plan: &SimulationPlan,
    run: &SimRunPlan,
    played: Option<&CommandFile>,
) -> Result<Vec<f64>, SimRunError> {
    let m = &plan.manifest;
    let fs = m.simulation.sample_rate_hz;
    let id = || run.id.clone();
    let exc = match (&run.excitation, played) {
        (Command::Generated(exc), _) => exc,
        (Command::File(path), None) => {
            return Err(SimRunError::CommandNotRead {
                run: id(),
                path: path.clone(),
            });
        }
        (Command::File(_), Some(file)) => {
            // A waveform generator plays one sample per tick of the DAQ's
            // clock: a file at another rate would play faster or slower.
            if (file.sample_rate_hz - fs).abs() > 1e-6 * fs {
                return Err(SimRunError::CommandRate {
                    run: id(),
                    path: file.path.clone(),
                    file_hz: file.sample_rate_hz,
                    sample_rate_hz: fs,
                });
            }
            return excitation::padded(file.command_m.clone(), fs, run.padding)
                .map_err(|source| SimRunError::Excitation { run: id(), source });
        }
    };
    let mut exc = exc.clone();
    // Multisine phases and random bands draw from the campaign seed, per run.
    let exc_seed = seed_for(m.simulation.seed, &format!("excitation/{}", run.id));
    match &mut exc {
        Excitation::Multisine { seed, .. }
        | Excitation::RandomBand { seed, .. }
        | Excitation::OddMultisine { seed, .. } => *seed = exc_seed,
        Excitation::Chirp { .. } | Excitation::Square { .. } => {}
    }
    excitation::generate(&exc, fs, run.padding)
        .map_err(|source| SimRunError::Excitation { run: id(), source })
}

/// Simulate one run: command, plant, instruments. `played` is the run's
/// command file, read, where its command is one.
pub fn simulate_run(
    plan: &SimulationPlan,
    run: &SimRunPlan,
    played: Option<&CommandFile>,
) -> Result<RunSignals, SimRunError> {
    let m = &plan.manifest;
    let fs = m.simulation.sample_rate_hz;
    let id = || run.id.clone();
    let rig = m.rig.parameters.at_p_gain(run.p_gain);
    let spec = plant::PlantSpec {
        rig,
        specimen: run.specimen,
        unmodelled: plan.unmodelled,
    };
    let mut u = command_signal(plan, run, played)?;
    if let Some(limit_m) = run.limit_m {
        excitation::limit(&mut u, limit_m)
            .map_err(|source| SimRunError::Excitation { run: id(), source })?;
    }
    let ins = &m.instrument;
    let response = plant::simulate(
        &spec,
        &u,
        fs,
        [ins.displacement.delay_s, ins.force.delay_s],
        plan.integrator,
    )
    .map_err(|source| SimRunError::Plant { run: id(), source })?;

    // Into the channels' units, then through each sensor chain with its own
    // reproducible random stream.
    let seed = m.simulation.seed;
    let logged = |name: &str, sensor: &Sensor, si: &[f64]| -> Result<Vec<f64>, SimRunError> {
        let to_unit = 1.0 / sensor.unit.to_si();
        let raw: Vec<f64> = si.iter().map(|v| v * to_unit).collect();
        let mut rng = instrument::channel_rng(seed, &format!("{}/{name}", run.id));
        instrument::apply(&raw, sensor, fs, &mut rng)
            .map_err(|source| SimRunError::Instrument { run: id(), source })
    };
    let n = u.len();
    let time: Vec<f64> = (0..n).map(|k| k as f64 / fs).collect();
    let columns = vec![
        ("time_s".to_string(), time),
        (
            column_name("command", &ins.command),
            logged("command", &ins.command, &u)?,
        ),
        (
            column_name("displacement", &ins.displacement),
            logged("displacement", &ins.displacement, &response.x1_m)?,
        ),
        (
            column_name("force", &ins.force),
            logged("force", &ins.force, &response.force_n)?,
        ),
    ];
    let model_tf = run
        .specimen
        .linear()
        .map(|lin| model::tf_x1_u(&rig, &lin))
        .transpose()
        .map_err(|source| SimRunError::Model { run: id(), source })?;
    let plant_tf = plant::linear_state_space(&spec).map(|ss| ss.transfer_function(model::OUT_X1));
    let units = vec![
        "s",
        ins.command.unit.symbol(),
        ins.displacement.unit.symbol(),
        ins.force.unit.symbol(),
    ];
    Ok(RunSignals {
        columns,
        units,
        truth: TruthRun {
            id: run.id.clone(),
            role: run.role,
            p_gain: run.p_gain,
            specimen: spec.specimen,
            a1b0: rig.a1b0_n_per_m_s2,
            model_tf_x1_u: model_tf,
            plant_tf_x1_u: plant_tf,
            log: String::new(),
            log_sha256: String::new(),
            n_samples: n,
            command_sha256: played.map(|f| f.sha256.clone()),
        },
    })
}

/// A seed for one purpose, derived from the campaign seed (SHA-256 of both),
/// so streams are independent and reproducible.
fn seed_for(seed: u64, purpose: &str) -> u64 {
    let mut h = Sha256::new();
    h.update(seed.to_le_bytes());
    h.update(purpose.as_bytes());
    let d = h.finalize();
    u64::from_le_bytes(d[..8].try_into().expect("8 bytes"))
}

/// The TDMS group the simulator's channels sit in.
pub const TDMS_GROUP: &str = "servoid";

/// How the analysis manifest names a logged column: in TDMS by its group.
fn column_in_log(format: OutputFormat, name: &str) -> String {
    match format {
        OutputFormat::Tdms => format!("{TDMS_GROUP}/{name}"),
        _ => name.to_string(),
    }
}

/// The campaign's truth: the rig and each run's, as `runs` carry them.
pub fn truth(plan: &SimulationPlan, runs: Vec<TruthRun>) -> Truth {
    let m = &plan.manifest;
    Truth {
        schema_version: 1,
        servoid_version: env!("CARGO_PKG_VERSION").to_string(),
        simulation: m.simulation.name.clone(),
        manifest_sha256: plan.manifest_sha256.clone(),
        seed: m.simulation.seed,
        sample_rate_hz: m.simulation.sample_rate_hz,
        rig: m.rig.parameters,
        clean: m.rig.unmodelled.is_none() && m.rig.max_force_n().is_none(),
        unmodelled: m.rig.unmodelled.clone(),
        max_force_n: m.rig.max_force_n(),
        runs,
    }
}

/// The analysis manifest's text: a header saying the logs are synthetic
/// and where they came from, then the manifest.
pub fn manifest_text(plan: &SimulationPlan, truth: &Truth) -> String {
    let mut text = format!(
        "# Generated by `servoid simulate` from {} (SHA-256 {}).\n# The logs are SYNTHETIC: simulated from known rig parameters (truth.json).\n\n",
        plan.file
            .file_name()
            .map(|f| f.to_string_lossy().into_owned())
            .unwrap_or_default(),
        plan.manifest_sha256
    );
    text.push_str(
        &toml::to_string(&analysis_manifest(plan, truth)).expect("the manifest serialises to TOML"),
    );
    text
}

/// The simulated runs as the analysis manifest lists them: each with its
/// log and the log's hash.
fn analysis_runs(plan: &SimulationPlan, truth: &Truth) -> Vec<Run> {
    let m = &plan.manifest;
    plan.runs
        .iter()
        .zip(&truth.runs)
        .map(|(r, t)| {
            let stated = m.runs.iter().find(|x| x.id == r.id);
            Run {
                id: r.id.clone(),
                role: r.role,
                description: stated.map(|x| x.description.clone()).unwrap_or_default(),
                date: None,
                p_gain: r.p_gain,
                specimen: stated
                    .and_then(|x| x.specimen.clone())
                    .map(|s| analysed_as(r.role, s)),
                data: Some(RunData {
                    log: Some(t.log.clone()),
                    sha256: Some(t.log_sha256.clone()),
                    ..RunData::default()
                }),
                channels: None,
                band_hz: None,
            }
        })
        .collect()
}

/// The manifest's references with the true rig beside them, which the
/// analysis compares its identified rig with (within 0.5 % on an exact rig,
/// 3 % on one with dynamics the paper's model lacks).
fn truth_references(plan: &SimulationPlan, truth: &Truth) -> Vec<Reference> {
    let m = &plan.manifest;
    let tol = if truth.clean { 0.5 } else { 3.0 };
    let source = format!("simulation truth (seed {})", truth.seed);
    let mut references: Vec<Reference> = m.references.clone();
    let rig = &truth.rig;
    // The analysis states a1b0 at its no-specimen run's P gain.
    let p_ref = plan
        .runs
        .iter()
        .find(|r| r.role == Role::NoSpecimen)
        .map_or(rig.p_gain, |r| r.p_gain);
    for (q, v) in [
        ("rig.beta1", rig.beta1_per_s),
        ("rig.a1b0", rig.at_p_gain(p_ref).a1b0_n_per_m_s2),
        ("rig.a2", rig.a2_n_per_m),
        ("rig.a3", rig.a3_per_s),
    ] {
        references.push(Reference {
            quantity: q.to_string(),
            published: v,
            source: source.clone(),
            compare: Default::default(),
            tolerance_pct: tol,
        });
    }
    references
}

/// The analysis manifest for the simulated logs: the simulation's
/// identification options and references, the channels as logged, each log
/// pinned by its SHA-256, and the truth as references (0.5 % for a clean
/// campaign, 3 % when it has unmodelled dynamics).
fn analysis_manifest(plan: &SimulationPlan, truth: &Truth) -> Manifest {
    let m = &plan.manifest;
    let ins = &m.instrument;
    let channel = |name: &str, sensor: &Sensor| Channel {
        column: Column::Name(column_in_log(
            m.simulation.log_format,
            &column_name(name, sensor),
        )),
        unit: sensor.unit,
        scale: 1.0,
        offset: 0.0,
        range: None,
        repair: Default::default(),
    };
    Manifest {
        schema_version: SCHEMA_VERSION,
        campaign: CampaignInfo {
            name: m.simulation.name.clone(),
            description: m.simulation.description.clone(),
            synthetic: Some(format!(
                "These logs are synthetic: simulated by servoid {} from the simulation manifest {} (seed {}){}. truth.json holds the true parameters.",
                env!("CARGO_PKG_VERSION"),
                plan.file
                    .file_name()
                    .map(|f| f.to_string_lossy().into_owned())
                    .unwrap_or_default(),
                truth.seed,
                if truth.clean {
                    ", exactly the paper's model"
                } else {
                    ", with dynamics the paper's model lacks"
                }
            )),
        },
        rig: Rig {
            name: m.rig.name.clone(),
            notes: m.rig.notes.clone(),
            parameters: None,
            supply_pressure_pa: None,
            piston_area_m2: None,
        },
        channels: Channels {
            time: Some(TimeChannel {
                column: Some(Column::Name(column_in_log(
                    m.simulation.log_format,
                    "time_s",
                ))),
                unit: Some(TimeUnit::Second),
                sample_rate_hz: None,
            }),
            command: Some(channel("command", &ins.command)),
            displacement: Some(channel("displacement", &ins.displacement)),
            force: Some(channel("force", &ins.force)),
        },
        identification: m.identification.clone(),
        runs: analysis_runs(plan, truth),
        references: truth_references(plan, truth),
        run_table: None,
        history: None,
        sensitivity: m.sensitivity.clone(),
        compensator: None,
        limits: None,
        report: None,
        design: None,
        numbered_figures: m.numbered_figures.clone(),
    }
}

/// The specimen as the lab analyses it: a spring run's spring is linear in
/// the paper's model (Eqs. 18-19), so a simulated Duffing spring is handed
/// to the analysis as its stiffness at rest alone.
fn analysed_as(role: Role, s: Specimen) -> Specimen {
    if role == Role::Spring && s.model == SpecimenKind::Duffing {
        Specimen {
            stiffness_n_per_m: s.stiffness_n_per_m,
            ..Specimen::default()
        }
    } else {
        s
    }
}
