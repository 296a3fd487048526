//! `servoid simulate`: from a checked simulation manifest to lab logs, a truth
//! file and an analysis manifest ready for `servoid run` (a closed loop).
//! Everything is computed first and written only when every run succeeded,
//! each file atomically, so a failure leaves no half-written campaign.

use std::path::{Path, PathBuf};

use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::lti::TransferFunction;
use crate::manifest::simulation::{
    ChirpLawSpec, ExcitationKind, ExcitationSpec, IntegratorMethod, OutputFormat, SensorSpec,
    SimRunPlan, SimulationPlan, UnmodelledSpec,
};
use crate::manifest::{
    CampaignInfo, Channel, Channels, Column, Manifest, Reference, Rig, Role, Run, RunData,
    SCHEMA_VERSION, TimeChannel, TimeUnit,
};
use crate::model::{self, RigParams};
use crate::report;
use crate::simulate::{excitation, instrument, ode, plant};

/// Why a simulation failed.
#[derive(Debug, thiserror::Error)]
pub enum SimulateError {
    #[error("run {run}: {message}")]
    Run { run: String, message: String },
    #[error(transparent)]
    Write(#[from] report::WriteError),
    #[error("{}: {message}", path.display())]
    Log { path: PathBuf, message: String },
}

/// What `servoid simulate` wrote.
#[derive(Debug, Clone)]
pub struct Simulated {
    pub out_dir: PathBuf,
    pub manifest: PathBuf,
    pub truth: PathBuf,
    pub logs: Vec<PathBuf>,
}

/// truth.json: what the identification should find.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Truth {
    pub schema_version: u32,
    pub servoid_version: String,
    /// The simulation's name and its manifest's SHA-256.
    pub simulation: String,
    pub manifest_sha256: String,
    pub seed: u64,
    pub sample_rate_hz: f64,
    /// The true rig parameters (a1b0 at `rig.p_gain`).
    pub rig: RigParams,
    /// True when the plant is exactly the paper's model (no unmodelled dynamics).
    pub clean: bool,
    pub unmodelled: Option<UnmodelledSpec>,
    pub runs: Vec<TruthRun>,
}

/// One simulated run's truth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TruthRun {
    pub id: String,
    pub role: Role,
    pub p_gain: f64,
    /// The specimen as simulated.
    pub specimen: crate::simulate::specimen::SpecimenModel,
    /// a1b0 at this run's P gain.
    pub a1b0: f64,
    /// x1/u of the paper's model (Eqs. 12, 14, 17) at the true parameters;
    /// null for a nonlinear specimen.
    pub model_tf_x1_u: Option<TransferFunction>,
    /// x1/u of the simulated linear plant, unmodelled dynamics included;
    /// equal to `model_tf_x1_u` for a clean campaign.
    pub plant_tf_x1_u: Option<TransferFunction>,
    /// The log, relative to the output folder.
    pub log: String,
    pub log_sha256: String,
    pub n_samples: usize,
}

/// The simulated signals of one run, in the channels' units.
struct RunSignals {
    columns: Vec<(String, Vec<f64>)>,
    truth: TruthRun,
}

fn column_name(channel: &str, spec: &SensorSpec) -> String {
    format!("{channel}_{}", spec.unit.symbol().to_ascii_lowercase())
}

fn excitation_of(spec: &ExcitationSpec) -> excitation::Excitation {
    use excitation::{ChirpLaw, Excitation};
    match spec.kind {
        ExcitationKind::Chirp => Excitation::Chirp {
            law: match spec.law.unwrap_or_default() {
                ChirpLawSpec::Linear => ChirpLaw::Linear,
                ChirpLawSpec::Quadratic => ChirpLaw::Quadratic,
                ChirpLawSpec::Logarithmic => ChirpLaw::Logarithmic,
            },
            f0_hz: spec.f0_hz.unwrap_or_default(),
            f1_hz: spec.f1_hz.unwrap_or_default(),
            duration_s: spec.duration_s,
            amplitude_m: spec.amplitude_m.unwrap_or_default(),
        },
        ExcitationKind::Multisine => Excitation::Multisine {
            f_min_hz: spec.f_min_hz.unwrap_or_default(),
            f_max_hz: spec.f_max_hz.unwrap_or_default(),
            n_tones: spec.n_tones.unwrap_or(1),
            rms_m: spec.rms_m.unwrap_or_default(),
            duration_s: spec.duration_s,
            seed: 0,
        },
        ExcitationKind::RandomBand => Excitation::RandomBand {
            f_min_hz: spec.f_min_hz.unwrap_or_default(),
            f_max_hz: spec.f_max_hz.unwrap_or_default(),
            rms_m: spec.rms_m.unwrap_or_default(),
            duration_s: spec.duration_s,
            seed: 0,
        },
    }
}

fn chain_of(spec: &SensorSpec) -> instrument::SensorChain {
    instrument::SensorChain {
        noise_rms: spec.noise_rms,
        offset: spec.offset,
        drift_per_s: spec.drift_per_s,
        quantization: spec
            .quantization
            .as_ref()
            .map(|q| instrument::Quantization {
                bits: q.bits,
                full_scale: q.full_scale,
            }),
    }
}

/// Simulate one run: command, plant, instruments.
fn simulate_run(plan: &SimulationPlan, run: &SimRunPlan) -> Result<RunSignals, SimulateError> {
    let m = &plan.manifest;
    let fs = m.simulation.sample_rate_hz;
    let fail = |message: String| SimulateError::Run {
        run: run.id.clone(),
        message,
    };
    let rig = m.rig.parameters.at_p_gain(run.p_gain);
    let spec = plant::PlantSpec {
        rig,
        specimen: run.specimen,
        unmodelled: crate::manifest::simulation::unmodelled(m.rig.unmodelled.as_ref()),
    };
    let mut exc = excitation_of(&run.excitation);
    // Multisine phases and random bands draw from the campaign seed, per run.
    let exc_seed = seed_for(m.simulation.seed, &format!("excitation/{}", run.id));
    match &mut exc {
        excitation::Excitation::Multisine { seed, .. }
        | excitation::Excitation::RandomBand { seed, .. } => *seed = exc_seed,
        excitation::Excitation::Chirp { .. } => {}
    }
    let u = excitation::generate(
        &exc,
        fs,
        excitation::Padding {
            lead_in_s: run.excitation.lead_in_s,
            lead_out_s: run.excitation.lead_out_s,
        },
    )
    .map_err(|e| fail(e.to_string()))?;
    let integ = match m.simulation.integrator.method {
        IntegratorMethod::Rk4 => ode::Integrator::Rk4 {
            substeps: m.simulation.integrator.substeps,
        },
        IntegratorMethod::DormandPrince => ode::Integrator::DormandPrince {
            rtol: m.simulation.integrator.rtol,
            atol: m.simulation.integrator.atol,
        },
    };
    let ins = &m.instrument;
    let response = plant::simulate(
        &spec,
        &u,
        fs,
        [ins.displacement.delay_s, ins.force.delay_s],
        integ,
    )
    .map_err(|e| fail(e.to_string()))?;

    // Into the channels' units, then through each sensor chain with its own
    // reproducible random stream.
    let seed = m.simulation.seed;
    let logged = |name: &str, spec: &SensorSpec, si: &[f64]| -> Result<Vec<f64>, SimulateError> {
        let to_unit = 1.0 / spec.unit.to_si();
        let raw: Vec<f64> = si.iter().map(|v| v * to_unit).collect();
        let mut rng = instrument::channel_rng(seed, &format!("{}/{name}", run.id));
        instrument::apply(&raw, &chain_of(spec), fs, &mut rng).map_err(|e| fail(e.to_string()))
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
    let model_tf = run.specimen.linear().map(|lin| model::tf_x1_u(&rig, &lin));
    let plant_tf = plant::linear_state_space(&spec).map(|ss| ss.transfer_function(model::OUT_X1));
    Ok(RunSignals {
        columns,
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

/// Simulate every run and write the campaign into `out_dir`.
pub fn simulate_campaign(
    plan: &SimulationPlan,
    out_dir: &Path,
) -> Result<Simulated, SimulateError> {
    let signals: Vec<RunSignals> = plan
        .runs
        .par_iter()
        .map(|run| simulate_run(plan, run))
        .collect::<Result<_, _>>()?;

    let m = &plan.manifest;
    let ext = match m.simulation.log_format {
        OutputFormat::Csv => "csv",
        OutputFormat::Parquet => "parquet",
    };
    let mut logs = Vec::new();
    let mut truth_runs = Vec::new();
    for s in signals {
        let rel = format!("logs/{}.{ext}", s.truth.id);
        let path = out_dir.join(&rel);
        let cols: Vec<(&str, &[f64])> = s
            .columns
            .iter()
            .map(|(n, v)| (n.as_str(), v.as_slice()))
            .collect();
        let bytes = match m.simulation.log_format {
            OutputFormat::Csv => report::logs::csv_bytes(&path, &cols),
            OutputFormat::Parquet => report::logs::parquet_bytes(&path, &cols),
        }
        .map_err(|e| SimulateError::Log {
            path: path.clone(),
            message: e.to_string(),
        })?;
        report::write_atomic(&path, &bytes)?;
        let mut t = s.truth;
        t.log = rel;
        t.log_sha256 = crate::manifest::hex(&Sha256::digest(&bytes));
        truth_runs.push(t);
        logs.push(path);
    }

    let truth = Truth {
        schema_version: 1,
        servoid_version: env!("CARGO_PKG_VERSION").to_string(),
        simulation: m.simulation.name.clone(),
        manifest_sha256: plan.manifest_sha256.clone(),
        seed: m.simulation.seed,
        sample_rate_hz: m.simulation.sample_rate_hz,
        rig: m.rig.parameters,
        clean: m.rig.unmodelled.is_none(),
        unmodelled: m.rig.unmodelled.clone(),
        runs: truth_runs,
    };
    let truth_path = out_dir.join("truth.json");
    let mut truth_json = serde_json::to_string_pretty(&truth).expect("truth serialises");
    truth_json.push('\n');
    report::write_atomic(&truth_path, truth_json.as_bytes())?;

    let manifest = analysis_manifest(plan, &truth);
    let mut text = format!(
        "# Generated by `servoid simulate` from {} (SHA-256 {}).\n# The logs are SYNTHETIC: simulated from known rig parameters (truth.json).\n\n",
        plan.file
            .file_name()
            .map(|f| f.to_string_lossy().into_owned())
            .unwrap_or_default(),
        plan.manifest_sha256
    );
    text.push_str(&toml::to_string(&manifest).expect("the manifest serialises to TOML"));
    let manifest_path = out_dir.join("campaign.toml");
    report::write_atomic(&manifest_path, text.as_bytes())?;
    Ok(Simulated {
        out_dir: out_dir.to_path_buf(),
        manifest: manifest_path,
        truth: truth_path,
        logs,
    })
}

/// The analysis manifest for the simulated logs: the simulation's
/// identification options and references, the channels as logged, each log
/// pinned by its SHA-256, and the truth as references (0.5 % for a clean
/// campaign, 3 % when it has unmodelled dynamics).
fn analysis_manifest(plan: &SimulationPlan, truth: &Truth) -> Manifest {
    let m = &plan.manifest;
    let ins = &m.instrument;
    let channel = |name: &str, spec: &SensorSpec| Channel {
        column: Column::Name(column_name(name, spec)),
        unit: spec.unit,
        scale: 1.0,
        offset: 0.0,
    };
    let runs = plan
        .runs
        .iter()
        .zip(&truth.runs)
        .map(|(r, t)| Run {
            id: r.id.clone(),
            role: r.role,
            description: m
                .runs
                .iter()
                .find(|x| x.id == r.id)
                .map(|x| x.description.clone())
                .unwrap_or_default(),
            p_gain: r.p_gain,
            specimen: m
                .runs
                .iter()
                .find(|x| x.id == r.id)
                .and_then(|x| x.specimen.clone()),
            data: Some(RunData {
                log: Some(t.log.clone()),
                sha256: Some(t.log_sha256.clone()),
                ..RunData::default()
            }),
            channels: None,
            band_hz: None,
        })
        .collect();
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
        },
        channels: Channels {
            time: Some(TimeChannel {
                column: Some(Column::Name("time_s".into())),
                unit: Some(TimeUnit::Second),
                sample_rate_hz: None,
            }),
            command: Some(channel("command", &ins.command)),
            displacement: Some(channel("displacement", &ins.displacement)),
            force: Some(channel("force", &ins.force)),
        },
        identification: m.identification.clone(),
        runs,
        references,
    }
}
