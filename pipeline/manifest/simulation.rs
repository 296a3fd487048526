//! The simulation manifest: a rig with known (true) parameters, a test
//! program and an instrument chain, from which `servoid simulate` writes lab
//! logs, a truth file and an analysis manifest. Checked with the same
//! machinery as the analysis manifest (every problem at once, with key paths
//! and lines); `schemas/simulation.schema.json` is generated from these types.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::campaign::{check_numbered_figures, check_sensitivity};
use super::checks::{
    P_GAIN_RANGE, STIFFNESS_RANGE, check_nameplate, check_slug, check_specimen, plausible, positive,
};
use super::document::{Document, read};
use super::identification::check_identification;
use super::keypath::KeyPath;
use super::problem::{ManifestError, Problem};
use super::raw::{
    Identification, NumberedFigure, Reference, Role, SCHEMA_VERSION, SensitivitySettings, Specimen,
    SpecimenKind,
};
use crate::ingest::sha256_hex;
use crate::model::RigParams;
use crate::model::SpecimenModel;
use crate::simulate::excitation::{ChirpLaw, Excitation, Padding};
use crate::simulate::instrument::Sensor;
use crate::simulate::ode::Integrator;
use crate::simulate::plant::{self, ActuatorFriction, PlantSpec, Unmodelled, ValveMode};
use crate::units::UnitKind;

/// A simulated campaign: the truth, the test program and the instruments.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct SimulationManifest {
    /// Version of the manifest format (this servoid reads 1).
    pub schema_version: u32,
    pub simulation: SimulationInfo,
    pub rig: SimRig,
    /// The default excitation; a run may give its own.
    pub excitation: ExcitationSpec,
    pub instrument: Instrument,
    /// Identification options written into the generated analysis manifest.
    #[serde(default)]
    pub identification: Identification,
    /// The runs to simulate, each written as a log.
    pub runs: Vec<SimRun>,
    /// Published values copied into the generated analysis manifest.
    #[serde(default)]
    pub references: Vec<Reference>,
    /// The stiffness sensitivity's settings, written into the generated
    /// analysis manifest (checked here as it will check them).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensitivity: Option<SensitivitySettings>,
    /// A publication's figures by their numbers, copied into the generated
    /// analysis manifest.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub numbered_figures: Vec<NumberedFigure>,
}

/// Global settings of a simulation.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct SimulationInfo {
    /// Name of the simulated campaign (letters, digits, `.`, `_`, `-`); also
    /// the default output folder under `reports/`.
    pub name: String,
    /// Free-form description, shown on the report.
    #[serde(default)]
    pub description: String,
    /// Sampling rate of the logs and of the D/A converter (Hz).
    pub sample_rate_hz: f64,
    /// Seed of the sensor noise (an integer); the same seed gives the same bytes.
    pub seed: u64,
    /// Format of the written logs.
    #[serde(default)]
    pub log_format: OutputFormat,
    /// Integrator for nonlinear specimens (linear plants are simulated exactly).
    #[serde(default)]
    pub integrator: IntegratorSpec,
}

/// Log format written by the simulator.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum OutputFormat {
    #[default]
    Csv,
    Parquet,
    /// MATLAB level-5 MAT-file: each column an N x 1 double.
    Mat,
    /// MATLAB v7.3 MAT-file (HDF5): each column an N x 1 double.
    MatV73,
    /// HDF5: each column a dataset at the root, with its `units`.
    Hdf5,
    /// NI TDMS: each column a channel of group `servoid`, with its
    /// `unit_string` and `wf_increment`.
    Tdms,
}

impl OutputFormat {
    /// The extension of a log in this format.
    pub fn extension(self) -> &'static str {
        match self {
            OutputFormat::Csv => "csv",
            OutputFormat::Parquet => "parquet",
            OutputFormat::Mat | OutputFormat::MatV73 => "mat",
            OutputFormat::Hdf5 => "h5",
            OutputFormat::Tdms => "tdms",
        }
    }
}

/// Integrator for nonlinear plants.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct IntegratorSpec {
    #[serde(default)]
    pub method: IntegratorMethod,
    /// RK4 sub-steps per sample.
    #[serde(default = "default_substeps")]
    pub substeps: usize,
    /// Dormand-Prince relative and absolute tolerances.
    #[serde(default = "default_rtol")]
    pub rtol: f64,
    /// Absolute tolerance of the ODE integrator.
    #[serde(default = "default_atol")]
    pub atol: f64,
}

impl Default for IntegratorSpec {
    fn default() -> Self {
        Self {
            method: IntegratorMethod::default(),
            substeps: default_substeps(),
            rtol: default_rtol(),
            atol: default_atol(),
        }
    }
}

/// Integration method.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum IntegratorMethod {
    /// Fixed-step classical Runge-Kutta with `substeps` steps per sample.
    #[default]
    Rk4,
    /// Adaptive Dormand-Prince 5(4) with `rtol` and `atol`.
    DormandPrince,
}

/// The simulated rig: its true parameters and what the paper's model lacks.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct SimRig {
    /// The rig's name in the generated analysis manifest.
    pub name: String,
    /// Free-form notes.
    #[serde(default)]
    pub notes: String,
    /// The true parameters (Eq. 10), a1b0 at `p_gain`.
    pub parameters: RigParams,
    /// Dynamics a real rig has and the paper's model lacks; omit for a
    /// campaign that is exactly the paper's model ("clean").
    #[serde(default)]
    pub unmodelled: Option<UnmodelledSpec>,
    /// Supply pressure P_s (Pa), with `piston_area_m2`: the servo-valve's
    /// flow then falls with the load pressure, f' = -a2 x2 - a3 f + r
    /// sqrt(1 - sign(r) f / F_max) with F_max = A P_s (docs/model.md; Eq. 10 is
    /// its limit f << F_max). Give both or neither; truth.json records
    /// F_max as `max_force_n`.
    #[serde(default)]
    pub supply_pressure_pa: Option<f64>,
    /// Piston area A (m^2) of the flow-pressure law, with
    /// `supply_pressure_pa`.
    #[serde(default)]
    pub piston_area_m2: Option<f64>,
}

impl SimRig {
    /// F_max = A P_s (N) when the rig has the flow-pressure law.
    pub fn max_force_n(&self) -> Option<f64> {
        Some(self.piston_area_m2? * self.supply_pressure_pa?)
    }
}

/// Unmodelled dynamics ("rich" campaigns).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct UnmodelledSpec {
    /// A second-order servo-valve mode in series with the first-order valve,
    /// inside the position loop.
    #[serde(default)]
    pub valve_mode: Option<ValveModeSpec>,
    /// Piston (and load-cell) mass moving with the actuator (kg).
    #[serde(default)]
    pub piston_mass_kg: Option<f64>,
    /// A second-order mode in the command path, ahead of the loop (a
    /// command filter or valve driver): x1 and the force both follow it.
    #[serde(default)]
    pub command_mode: Option<ValveModeSpec>,
    /// A second-order mode on the logged displacement only (a sensor or
    /// logging filter outside the loop): the force does not follow it.
    #[serde(default)]
    pub measurement_mode: Option<ValveModeSpec>,
    /// Coulomb friction on the piston, which the load cell does not read.
    #[serde(default)]
    pub actuator_friction: Option<ActuatorFrictionSpec>,
}

/// Coulomb friction on the piston: coulomb_force_n * tanh(x2 / smoothing_velocity_m_per_s).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct ActuatorFrictionSpec {
    /// Coulomb friction force of the actuator's seals (N).
    pub coulomb_force_n: f64,
    /// Velocity (m/s) over which the friction's sign is smoothed (tanh).
    pub smoothing_velocity_m_per_s: f64,
    /// Viscous damping of the seals (N s/m), beside the Coulomb force.
    #[serde(default)]
    pub viscous_ns_per_m: f64,
}

/// A second-order servo-valve mode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct ValveModeSpec {
    /// Natural frequency (Hz) of the second-order mode.
    pub natural_frequency_hz: f64,
    /// Damping ratio of the second-order mode.
    pub damping_ratio: f64,
}

/// A test signal for the command displacement.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct ExcitationSpec {
    pub kind: ExcitationKind,
    /// Chirp law (default quadratic, as the paper's).
    #[serde(default)]
    pub law: Option<ChirpLawSpec>,
    /// Chirp start frequency (Hz).
    #[serde(default)]
    pub f0_hz: Option<f64>,
    /// Chirp end frequency (Hz).
    #[serde(default)]
    pub f1_hz: Option<f64>,
    /// Lower edge of a multisine's or band-limited random signal's band (Hz).
    #[serde(default)]
    pub f_min_hz: Option<f64>,
    /// Upper edge of a multisine's or band-limited random signal's band (Hz).
    #[serde(default)]
    pub f_max_hz: Option<f64>,
    /// Length of the excitation (s), without lead-in and lead-out; a
    /// command file's is its own.
    #[serde(default)]
    pub duration_s: Option<f64>,
    /// A command file played as written (kind `file`): a log with a
    /// `time_s` column (s) and a `command_m` column (m) sampled at
    /// simulation.sample_rate_hz, in any log format, as `servoid design`
    /// writes it; relative to the manifest's folder.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub file: Option<PathBuf>,
    /// Peak amplitude of a chirp, or the levels +-amplitude_m of a square
    /// wave (m).
    #[serde(default)]
    pub amplitude_m: Option<f64>,
    /// A square wave's full period (s): it holds each level half a period,
    /// switching at the sample nearest each edge. An odd multisine's
    /// period (s): its lines are the odd harmonics of 1 / period_s.
    #[serde(default)]
    pub period_s: Option<f64>,
    /// RMS of a multisine or random signal (m).
    #[serde(default)]
    pub rms_m: Option<f64>,
    /// Tones of a multisine.
    #[serde(default)]
    pub n_tones: Option<usize>,
    /// Zeros before the excitation (s).
    #[serde(default)]
    pub lead_in_s: f64,
    /// Zeros after the excitation (s).
    #[serde(default)]
    pub lead_out_s: f64,
    /// The controller's command limit (m): the command is clamped to
    /// +-limit_m before it is logged and before the servo-valve sees it.
    #[serde(default)]
    pub limit_m: Option<f64>,
}

/// Kinds of excitation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum ExcitationKind {
    /// A swept sine: `law`, `f0_hz`, `f1_hz`, `amplitude_m`.
    Chirp,
    /// Equal tones with random phases: `f_min_hz`, `f_max_hz`, `n_tones`,
    /// `rms_m`.
    Multisine,
    /// Band-limited Gaussian noise: `f_min_hz`, `f_max_hz`, `rms_m`.
    RandomBand,
    /// A square wave (servo tuning): `amplitude_m`, `period_s`.
    Square,
    /// A random-odd multisine with a low crest factor, periodic: flat lines
    /// on the odd harmonics of 1 / `period_s` in `f_min_hz`-`f_max_hz`, one
    /// of each three left out (where odd distortion shows), `rms_m`;
    /// `duration_s` a whole number of periods, at least 3, the first
    /// fading in and the last out.
    OddMultisine,
    /// A command file (`file`), played sample by sample: a designed
    /// night's command checked before the lab runs it.
    File,
}

/// Chirp laws (MATLAB `chirp` conventions).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum ChirpLawSpec {
    Linear,
    #[default]
    Quadratic,
    Logarithmic,
}

/// The instrument chain of each logged channel.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct Instrument {
    /// The command as logged (the D/A's input).
    pub command: Sensor,
    /// The displacement sensor (e.g. the actuator's LVDT).
    pub displacement: Sensor,
    /// The load cell.
    pub force: Sensor,
}

/// One simulated run.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct SimRun {
    /// Unique id (letters, digits, `.`, `_` and `-`); the log's file name.
    pub id: String,
    pub role: Role,
    /// Free-form description.
    #[serde(default)]
    pub description: String,
    /// Proportional gain of the analog controller in this run: the
    /// servo-valve's drive per unit of position error (mA/m in the paper's
    /// Table 1). Only ratios between runs matter: a1b0 is proportional to
    /// it (Eq. 10), and results give a1b0 at the rig's P gain.
    pub p_gain: f64,
    #[serde(default)]
    pub specimen: Option<Specimen>,
    /// This run's excitation, replacing the default.
    #[serde(default)]
    pub excitation: Option<ExcitationSpec>,
}

fn default_substeps() -> usize {
    8
}
fn default_rtol() -> f64 {
    1e-8
}
fn default_atol() -> f64 {
    1e-12
}

/// The simulation manifest's JSON Schema (cached, as the campaign
/// manifest's).
pub fn simulation_schema() -> Value {
    static CACHE: OnceLock<Value> = OnceLock::new();
    CACHE
        .get_or_init(|| {
            serde_json::to_value(schemars::schema_for!(SimulationManifest))
                .expect("schema serialises")
        })
        .clone()
}

/// A checked simulation: the manifest as read (the truth file and the
/// generated analysis manifest echo it) and the simulator's own settings.
#[derive(Debug, Clone)]
pub struct SimulationPlan {
    pub file: PathBuf,
    pub manifest_sha256: String,
    pub manifest: SimulationManifest,
    /// The integrator for nonlinear plants.
    pub integrator: Integrator,
    /// The dynamics the paper's model lacks (none for a clean campaign).
    pub unmodelled: Unmodelled,
    pub runs: Vec<SimRunPlan>,
}

/// A run's command signal.
#[derive(Debug, Clone, PartialEq)]
pub enum Command {
    /// Generated by the simulator; multisine and random phases are drawn
    /// per run from the campaign seed when the run is simulated.
    Generated(Excitation),
    /// Played from a command file, its path resolved against the
    /// manifest's folder; ingest reads it when the run is simulated.
    File(PathBuf),
}

/// A checked simulated run.
#[derive(Debug, Clone)]
pub struct SimRunPlan {
    pub id: String,
    pub role: Role,
    pub p_gain: f64,
    pub specimen: SpecimenModel,
    /// The command's signal.
    pub excitation: Command,
    pub padding: Padding,
    /// The controller's command limit (m), if any.
    pub limit_m: Option<f64>,
}

/// Read and check a simulation manifest.
pub fn load_simulation(path: &Path) -> Result<SimulationPlan, ManifestError> {
    let text = read(path)?;
    load_simulation_str(&text, path)
}

/// The sections that deserialized (a failed one is `None`, its problem
/// recorded).
struct Sections {
    schema_version: Option<u32>,
    info: Option<SimulationInfo>,
    rig: Option<SimRig>,
    excitation: Option<ExcitationSpec>,
    instrument: Option<Instrument>,
    identification: Option<Identification>,
    runs: Vec<Option<SimRun>>,
    raw_ids: Vec<Option<String>>,
    references: Vec<Option<Reference>>,
    sensitivity: Option<SensitivitySettings>,
    numbered_figures: Vec<Option<NumberedFigure>>,
}

/// Check simulation-manifest text as if read from `path`.
pub fn load_simulation_str(text: &str, path: &Path) -> Result<SimulationPlan, ManifestError> {
    let mut doc = Document::parse(text, path, simulation_schema())?;
    doc.check_top_level();
    let s = Sections {
        schema_version: doc.section("schema_version"),
        info: doc.section("simulation"),
        rig: doc.section("rig"),
        excitation: doc.section("excitation"),
        instrument: doc.section("instrument"),
        identification: doc.section("identification"),
        runs: doc.array("runs"),
        raw_ids: doc.raw("runs", "id"),
        references: doc.array("references"),
        sensitivity: doc.section("sensitivity"),
        numbered_figures: doc.array("numbered_figures"),
    };
    doc.begin_checks();
    let problems = &mut doc.problems;
    let mut bad = |path: KeyPath, msg: String| problems.push(Problem::new(path, msg));
    let fs = s.info.as_ref().map(|i| i.sample_rate_hz);
    check_header(&s, &mut bad);
    if let Some(r) = &s.rig {
        check_rig(r, &mut bad);
    }
    if let Some(e) = &s.excitation {
        check_excitation(e, &KeyPath::root().key("excitation"), fs, &mut bad);
    }
    if let Some(ins) = &s.instrument {
        check_instrument(ins, &mut bad);
    }
    let ident = s.identification.clone().unwrap_or_default();
    check_simulated_identification(&ident, fs, &mut bad);
    if let Some(sens) = &s.sensitivity {
        check_sensitivity(Some(sens), &mut bad);
    }
    check_numbered_figures(&s.numbered_figures, &mut bad);
    let plan_dir = path.parent().unwrap_or(Path::new(""));
    let runs = check_runs(&s, plan_dir, &mut bad);
    for (i, r) in s.references.iter().enumerate() {
        if let Some(r) = r
            && !(r.published.is_finite() && r.published != 0.0)
        {
            bad(
                KeyPath::root().key("references").index(i).key("published"),
                "must be a finite, non-zero number".into(),
            );
        }
    }
    let result = assemble(s, ident, runs, text, path);
    doc.finish(result)
}

/// The plan, when every section deserialized (problems found by the checks
/// are reported by the caller either way).
fn assemble(
    s: Sections,
    identification: Identification,
    runs: Vec<SimRunPlan>,
    text: &str,
    path: &Path,
) -> Option<SimulationPlan> {
    let info = s.info?;
    let rig = s.rig?;
    let integrator = match info.integrator.method {
        IntegratorMethod::Rk4 => Integrator::Rk4 {
            substeps: info.integrator.substeps,
        },
        IntegratorMethod::DormandPrince => Integrator::DormandPrince {
            rtol: info.integrator.rtol,
            atol: info.integrator.atol,
        },
    };
    Some(SimulationPlan {
        file: path.to_path_buf(),
        manifest_sha256: sha256_hex(text.as_bytes()),
        integrator,
        unmodelled: unmodelled(&rig),
        manifest: SimulationManifest {
            schema_version: s.schema_version?,
            simulation: info,
            rig,
            excitation: s.excitation?,
            instrument: s.instrument?,
            identification,
            runs: s.runs.into_iter().collect::<Option<Vec<_>>>()?,
            references: s.references.into_iter().collect::<Option<Vec<_>>>()?,
            sensitivity: s.sensitivity,
            numbered_figures: s.numbered_figures.into_iter().collect::<Option<Vec<_>>>()?,
        },
        runs,
    })
}

/// The format version and the `[simulation]` table.
fn check_header(s: &Sections, bad: &mut impl FnMut(KeyPath, String)) {
    let root = KeyPath::root();
    if let Some(v) = s.schema_version
        && v != SCHEMA_VERSION
    {
        bad(
            root.key("schema_version"),
            format!("unsupported schema_version {v}; this servoid reads {SCHEMA_VERSION}"),
        );
    }
    let Some(i) = &s.info else { return };
    let p = root.key("simulation");
    check_slug(&i.name, &p.key("name"), bad);
    positive(i.sample_rate_hz, &p.key("sample_rate_hz"), bad);
    let ip = p.key("integrator");
    if i.integrator.substeps == 0 {
        bad(ip.key("substeps"), "must be at least 1".into());
    }
    for (k, v) in [("rtol", i.integrator.rtol), ("atol", i.integrator.atol)] {
        positive(v, &ip.key(k), bad);
    }
}

/// The true rig: the paper's parameters must be physical, and unmodelled
/// dynamics stable and positive.
fn check_rig(r: &SimRig, bad: &mut impl FnMut(KeyPath, String)) {
    let root = KeyPath::root();
    let p = root.key("rig").key("parameters");
    let par = &r.parameters;
    for (k, v) in [
        ("beta1_per_s", par.beta1_per_s),
        ("a1b0_n_per_m_s2", par.a1b0_n_per_m_s2),
        ("a2_n_per_m", par.a2_n_per_m),
        ("a3_per_s", par.a3_per_s),
        ("p_gain", par.p_gain),
    ] {
        if !(v.is_finite() && v > 0.0) {
            bad(
                p.key(k),
                format!(
                    "must be positive (got {v}); the true plant would not be the paper's stable rig"
                ),
            );
        }
    }
    check_nameplate(
        r.supply_pressure_pa,
        r.piston_area_m2,
        &root.key("rig"),
        bad,
    );
    let Some(u) = &r.unmodelled else { return };
    let up = root.key("rig").key("unmodelled");
    for (key, mode) in [
        ("valve_mode", &u.valve_mode),
        ("command_mode", &u.command_mode),
        ("measurement_mode", &u.measurement_mode),
    ] {
        let Some(v) = mode else { continue };
        let vp = up.key(key);
        positive(v.natural_frequency_hz, &vp.key("natural_frequency_hz"), bad);
        if !(v.damping_ratio.is_finite() && v.damping_ratio > 0.0) {
            bad(
                vp.key("damping_ratio"),
                format!(
                    "must be positive (got {}); an undamped or negatively damped mode is unstable",
                    v.damping_ratio
                ),
            );
        }
    }
    if let Some(fr) = &u.actuator_friction {
        let fp = up.key("actuator_friction");
        positive(fr.coulomb_force_n, &fp.key("coulomb_force_n"), bad);
        positive(
            fr.smoothing_velocity_m_per_s,
            &fp.key("smoothing_velocity_m_per_s"),
            bad,
        );
        if !(fr.viscous_ns_per_m.is_finite() && fr.viscous_ns_per_m >= 0.0) {
            bad(
                fp.key("viscous_ns_per_m"),
                format!("must be zero or positive (got {})", fr.viscous_ns_per_m),
            );
        }
    }
    if let Some(m) = u.piston_mass_kg {
        positive(m, &up.key("piston_mass_kg"), bad);
    }
}

/// Each channel's sensor fits its channel.
fn check_instrument(ins: &Instrument, bad: &mut impl FnMut(KeyPath, String)) {
    let p = KeyPath::root().key("instrument");
    for (name, s, kind) in [
        ("command", &ins.command, UnitKind::Length),
        ("displacement", &ins.displacement, UnitKind::Length),
        ("force", &ins.force, UnitKind::Force),
    ] {
        check_sensor(s, kind, &p.key(name), bad);
    }
}

/// The identification options written into the analysis manifest. The logs
/// will be sampled at simulation.sample_rate_hz: a band reaching Nyquist
/// would fit bins that hold no information (and the hold's half-sample
/// delay is exact only below Nyquist).
fn check_simulated_identification(
    ident: &Identification,
    fs: Option<f64>,
    bad: &mut impl FnMut(KeyPath, String),
) {
    let path = KeyPath::root().key("identification");
    let plan = check_identification(ident, &path, bad);
    if let Some(ny) = fs.filter(|f| f.is_finite() && *f > 0.0).map(|f| 0.5 * f)
        && plan.band_hz.1 >= ny
    {
        bad(
            path.key("band_hz"),
            format!(
                "the band's upper edge {} Hz is at or above the Nyquist frequency ({ny} Hz at simulation.sample_rate_hz = {})",
                plan.band_hz.1,
                2.0 * ny
            ),
        );
    }
}

/// Every run: a unique name, a positive gain, a specimen its role allows,
/// an excitation, and a true plant that is stable (Eq. 10 at this P gain
/// with the specimen and any unmodelled dynamics: eigenvalues, or those of
/// the linearisation at rest).
fn check_runs(
    s: &Sections,
    plan_dir: &Path,
    bad: &mut impl FnMut(KeyPath, String),
) -> Vec<SimRunPlan> {
    let root = KeyPath::root();
    let mut first_seen = std::collections::BTreeMap::new();
    for (i, id) in s.raw_ids.iter().enumerate() {
        if let Some(id) = id {
            if let Some(j) = first_seen.get(id.as_str()) {
                bad(
                    root.key("runs").index(i).key("id"),
                    format!("duplicate run id `{id}` (first used by runs[{j}])"),
                );
            } else {
                first_seen.insert(id.as_str(), i);
            }
        }
    }
    if s.runs.is_empty() {
        bad(root.key("runs"), "the simulation has no runs".into());
    }
    let fs = s.info.as_ref().map(|i| i.sample_rate_hz);
    let mut plans = Vec::new();
    for (i, run) in s.runs.iter().enumerate() {
        let Some(run) = run else { continue };
        let p = root.key("runs").index(i);
        check_slug(&run.id, &p.key("id"), bad);
        if positive(run.p_gain, &p.key("p_gain"), bad) {
            plausible(run.p_gain, P_GAIN_RANGE, &p.key("p_gain"), bad);
        }
        let spec = match run.specimen.as_ref() {
            Some(sp) if run.role == Role::Spring && sp.model == SpecimenKind::Duffing => {
                check_duffing_spring(sp, &p.key("specimen"), bad)
            }
            sp => check_specimen(run.role, sp, &p.key("specimen"), bad),
        };
        if let Some(e) = &run.excitation {
            check_excitation(e, &p.key("excitation"), fs, bad);
        }
        if let (Some(spec), Some(r)) = (&spec, &s.rig)
            && r.parameters.is_physical()
        {
            let plant = PlantSpec {
                rig: r.parameters.at_p_gain(run.p_gain),
                specimen: *spec,
                unmodelled: unmodelled(r),
            };
            if let Err(e) = plant::validate(&plant) {
                bad(
                    p.clone(),
                    format!("the true plant of this run cannot be simulated: {e}"),
                );
            }
        }
        let exc = run.excitation.as_ref().or(s.excitation.as_ref());
        if let (Some(spec), Some(exc)) = (spec, exc) {
            plans.push(SimRunPlan {
                id: run.id.clone(),
                role: run.role,
                p_gain: run.p_gain,
                specimen: spec,
                excitation: command(exc, plan_dir),
                padding: Padding {
                    lead_in_s: exc.lead_in_s,
                    lead_out_s: exc.lead_out_s,
                },
                limit_m: exc.limit_m,
            });
        }
    }
    plans
}

/// A spring run's true spring when it is mildly nonlinear: the lab analyses
/// it as the linear spring `stiffness_n_per_m` (its stiffness at rest), the
/// simulator adds `cubic_stiffness_n_per_m3` x1^3 (a mismatch the paper's
/// Eqs. 18-19 do not contain). Massless and undamped, as any spring run.
fn check_duffing_spring(
    s: &Specimen,
    path: &KeyPath,
    bad: &mut impl FnMut(KeyPath, String),
) -> Option<SpecimenModel> {
    let mut ok = true;
    for (key, given) in [
        ("mass_kg", s.mass_kg.is_some()),
        ("damping_ns_per_m", s.damping_ns_per_m.is_some()),
        ("coulomb_force_n", s.coulomb_force_n.is_some()),
        (
            "smoothing_velocity_m_per_s",
            s.smoothing_velocity_m_per_s.is_some(),
        ),
        ("bouc_wen", s.bouc_wen.is_some()),
    ] {
        if given {
            bad(
                path.key(key),
                "a spring run's duffing spring is massless and undamped: give only stiffness_n_per_m and cubic_stiffness_n_per_m3".into(),
            );
            ok = false;
        }
    }
    let mut need = |key: &str, v: Option<f64>| match v {
        Some(v) if v.is_finite() => v,
        _ => {
            bad(
                path.key(key),
                format!("a spring run's duffing spring needs a finite `{key}`"),
            );
            ok = false;
            f64::NAN
        }
    };
    let k = need("stiffness_n_per_m", s.stiffness_n_per_m);
    let k3 = need("cubic_stiffness_n_per_m3", s.cubic_stiffness_n_per_m3);
    if ok
        && !(positive(k, &path.key("stiffness_n_per_m"), bad)
            && plausible(k, STIFFNESS_RANGE, &path.key("stiffness_n_per_m"), bad))
    {
        return None;
    }
    ok.then_some(SpecimenModel::Duffing(crate::model::Duffing {
        mass_kg: 0.0,
        damping_ns_per_m: 0.0,
        stiffness_n_per_m: k,
        cubic_stiffness_n_per_m3: k3,
    }))
}

/// The simulator's form of what the rig has beyond the paper's model.
fn unmodelled(rig: &SimRig) -> Unmodelled {
    let max_force_n = rig.max_force_n();
    let Some(u) = &rig.unmodelled else {
        return Unmodelled {
            max_force_n,
            ..Unmodelled::default()
        };
    };
    let mode = |m: &Option<ValveModeSpec>| {
        m.as_ref().map(|v| ValveMode {
            natural_frequency_hz: v.natural_frequency_hz,
            damping_ratio: v.damping_ratio,
        })
    };
    Unmodelled {
        valve_mode: mode(&u.valve_mode),
        piston_mass_kg: u.piston_mass_kg,
        command_mode: mode(&u.command_mode),
        measurement_mode: mode(&u.measurement_mode),
        actuator_friction: u.actuator_friction.as_ref().map(|f| ActuatorFriction {
            coulomb_force_n: f.coulomb_force_n,
            smoothing_velocity_m_per_s: f.smoothing_velocity_m_per_s,
            viscous_ns_per_m: f.viscous_ns_per_m,
        }),
        max_force_n,
    }
}

/// The simulator's form of a checked excitation (its keys are known to be
/// there; the seed is set per run when it is simulated).
fn command(spec: &ExcitationSpec, plan_dir: &Path) -> Command {
    let duration_s = spec.duration_s.unwrap_or_default();
    Command::Generated(match spec.kind {
        ExcitationKind::File => {
            return Command::File(plan_dir.join(spec.file.as_deref().unwrap_or(Path::new(""))));
        }
        ExcitationKind::Chirp => Excitation::Chirp {
            law: match spec.law.unwrap_or_default() {
                ChirpLawSpec::Linear => ChirpLaw::Linear,
                ChirpLawSpec::Quadratic => ChirpLaw::Quadratic,
                ChirpLawSpec::Logarithmic => ChirpLaw::Logarithmic,
            },
            f0_hz: spec.f0_hz.unwrap_or_default(),
            f1_hz: spec.f1_hz.unwrap_or_default(),
            duration_s,
            amplitude_m: spec.amplitude_m.unwrap_or_default(),
        },
        ExcitationKind::Multisine => Excitation::Multisine {
            f_min_hz: spec.f_min_hz.unwrap_or_default(),
            f_max_hz: spec.f_max_hz.unwrap_or_default(),
            n_tones: spec.n_tones.unwrap_or(1),
            rms_m: spec.rms_m.unwrap_or_default(),
            duration_s,
            seed: 0,
        },
        ExcitationKind::RandomBand => Excitation::RandomBand {
            f_min_hz: spec.f_min_hz.unwrap_or_default(),
            f_max_hz: spec.f_max_hz.unwrap_or_default(),
            rms_m: spec.rms_m.unwrap_or_default(),
            duration_s,
            seed: 0,
        },
        ExcitationKind::Square => Excitation::Square {
            amplitude_m: spec.amplitude_m.unwrap_or_default(),
            period_s: spec.period_s.unwrap_or_default(),
            duration_s,
        },
        ExcitationKind::OddMultisine => Excitation::OddMultisine {
            f_min_hz: spec.f_min_hz.unwrap_or_default(),
            f_max_hz: spec.f_max_hz.unwrap_or_default(),
            rms_m: spec.rms_m.unwrap_or_default(),
            period_s: spec.period_s.unwrap_or_default(),
            duration_s,
            seed: 0,
        },
    })
}

/// A required positive key of an excitation: its value, or None with the
/// problem reported.
fn needed(
    e: &ExcitationSpec,
    p: &KeyPath,
    key: &str,
    v: Option<f64>,
    bad: &mut impl FnMut(KeyPath, String),
) -> Option<f64> {
    match v {
        None => {
            bad(
                p.key(key),
                format!("a {} excitation needs `{key}`", kind_name(e.kind)),
            );
            None
        }
        Some(x) if !(x.is_finite() && x > 0.0) => {
            bad(p.key(key), format!("must be positive (got {x})"));
            None
        }
        Some(x) => Some(x),
    }
}

/// The band a kind sweeps or fills (its two keys and their values), each
/// key the kind needs checked.
type Band = Option<(&'static str, &'static str, Option<f64>, Option<f64>)>;

fn kind_keys(
    e: &ExcitationSpec,
    p: &KeyPath,
    fs: Option<f64>,
    bad: &mut impl FnMut(KeyPath, String),
) -> Band {
    let mut need = |key: &str, v: Option<f64>| needed(e, p, key, v, bad);
    match e.kind {
        ExcitationKind::Chirp => {
            need("amplitude_m", e.amplitude_m);
            Some((
                "f0_hz",
                "f1_hz",
                need("f0_hz", e.f0_hz),
                need("f1_hz", e.f1_hz),
            ))
        }
        ExcitationKind::Multisine | ExcitationKind::RandomBand => {
            need("rms_m", e.rms_m);
            let band = Some((
                "f_min_hz",
                "f_max_hz",
                need("f_min_hz", e.f_min_hz),
                need("f_max_hz", e.f_max_hz),
            ));
            if e.kind == ExcitationKind::Multisine && e.n_tones.is_none_or(|n| n == 0) {
                bad(p.key("n_tones"), "a multisine needs `n_tones` >= 1".into());
            }
            band
        }
        ExcitationKind::OddMultisine => {
            need("rms_m", e.rms_m);
            let period = need("period_s", e.period_s);
            let band = Some((
                "f_min_hz",
                "f_max_hz",
                need("f_min_hz", e.f_min_hz),
                need("f_max_hz", e.f_max_hz),
            ));
            // Whole periods, one fading in, one at least steady, one
            // fading out.
            if let Some(period) = period
                && let Some(duration_s) = e.duration_s.filter(|d| d.is_finite() && *d > 0.0)
                && !crate::simulate::excitation::whole_periods(duration_s, period)
            {
                let periods = duration_s / period;
                bad(
                    p.key("duration_s"),
                    format!(
                        "{duration_s} s is {periods} periods of period_s = {period} s; an odd multisine needs a whole number of periods, at least 3 (one fading in, one steady, one fading out)"
                    ),
                );
            }
            band
        }
        ExcitationKind::File => {
            if e.file.is_none() {
                bad(
                    p.key("file"),
                    "a file excitation needs `file`: a command log with columns time_s and command_m"
                        .into(),
                );
            }
            if let Some(d) = e.duration_s {
                bad(
                    p.key("duration_s"),
                    format!("a command file's length is its own (got {d} s): leave duration_s out"),
                );
            }
            None
        }
        ExcitationKind::Square => {
            need("amplitude_m", e.amplitude_m);
            // Two samples a period: one per level at the least.
            if let Some(period) = need("period_s", e.period_s)
                && let Some(fs) = fs.filter(|f| f.is_finite() && *f > 0.0)
                && period * fs < 2.0
            {
                bad(
                    p.key("period_s"),
                    format!(
                        "{period} s spans {} sample(s) at simulation.sample_rate_hz = {fs}; a square wave needs at least 2",
                        period * fs
                    ),
                );
            }
            None
        }
    }
}

fn check_excitation(
    e: &ExcitationSpec,
    p: &KeyPath,
    fs: Option<f64>,
    bad: &mut impl FnMut(KeyPath, String),
) {
    let nyquist = fs.filter(|f| f.is_finite() && *f > 0.0).map(|f| 0.5 * f);
    let band = kind_keys(e, p, fs, bad);
    if let Some((lo_key, hi_key, lo, hi)) = band {
        if let (Some(lo), Some(hi)) = (lo, hi)
            && e.kind != ExcitationKind::Chirp
            && lo >= hi
        {
            bad(
                p.key(lo_key),
                format!("must be below {hi_key} ({lo} >= {hi})"),
            );
        }
        if let Some(ny) = nyquist {
            for (key, v) in [(lo_key, lo), (hi_key, hi)] {
                if let Some(v) = v
                    && v >= ny
                {
                    bad(
                        p.key(key),
                        format!(
                            "{v} Hz is at or above the Nyquist frequency ({ny} Hz at simulation.sample_rate_hz = {})",
                            2.0 * ny
                        ),
                    );
                }
            }
        }
    }
    match e.duration_s {
        None if e.kind != ExcitationKind::File => bad(
            p.key("duration_s"),
            format!("a {} excitation needs `duration_s`", kind_name(e.kind)),
        ),
        Some(d) if !(d.is_finite() && d > 0.0) => {
            bad(p.key("duration_s"), format!("must be positive (got {d})"))
        }
        _ => {}
    }
    if e.kind != ExcitationKind::File && e.file.is_some() {
        bad(p.key("file"), "applies only to a file excitation".into());
    }
    for (key, v) in [("lead_in_s", e.lead_in_s), ("lead_out_s", e.lead_out_s)] {
        if !(v.is_finite() && v >= 0.0) {
            bad(p.key(key), format!("must be zero or positive (got {v})"));
        }
    }
    if e.kind != ExcitationKind::Chirp && e.law.is_some() {
        bad(p.key("law"), "applies only to a chirp".into());
    }
    if !matches!(
        e.kind,
        ExcitationKind::Square | ExcitationKind::OddMultisine
    ) && e.period_s.is_some()
    {
        bad(
            p.key("period_s"),
            "applies only to a square wave or an odd multisine".into(),
        );
    }
    if let Some(l) = e.limit_m
        && !(l.is_finite() && l > 0.0)
    {
        bad(p.key("limit_m"), format!("must be positive (got {l})"));
    }
}

fn kind_name(k: ExcitationKind) -> &'static str {
    match k {
        ExcitationKind::Chirp => "chirp",
        ExcitationKind::Multisine => "multisine",
        ExcitationKind::RandomBand => "random_band",
        ExcitationKind::Square => "square",
        ExcitationKind::OddMultisine => "odd_multisine",
        ExcitationKind::File => "file",
    }
}

fn check_sensor(s: &Sensor, kind: UnitKind, p: &KeyPath, bad: &mut impl FnMut(KeyPath, String)) {
    if s.unit.kind() != kind {
        bad(
            p.key("unit"),
            format!("`{}` does not fit this channel", s.unit.symbol()),
        );
    }
    for (k, v) in [("noise_rms", s.noise_rms), ("delay_s", s.delay_s)] {
        if !(v.is_finite() && v >= 0.0) {
            bad(p.key(k), format!("must be zero or positive (got {v})"));
        }
    }
    for (k, v) in [("offset", s.offset), ("drift_per_s", s.drift_per_s)] {
        if !v.is_finite() {
            bad(p.key(k), format!("must be finite (got {v})"));
        }
    }
    if let Some(q) = &s.quantization {
        if !(2..=32).contains(&q.bits) {
            bad(
                p.key("quantization").key("bits"),
                format!("must be between 2 and 32 (got {})", q.bits),
            );
        }
        if !(q.full_scale.is_finite() && q.full_scale > 0.0) {
            bad(
                p.key("quantization").key("full_scale"),
                format!("must be positive (got {})", q.full_scale),
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const BUNDLED: &str = include_str!("../../experiments/maghareh2018/simulation.toml");

    fn problems(text: &str) -> String {
        match load_simulation_str(text, Path::new("sim.toml")) {
            Ok(_) => String::new(),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn the_bundled_default_is_valid() {
        let plan = load_simulation_str(BUNDLED, Path::new("simulation.toml")).unwrap();
        assert_eq!(plan.runs.len(), 7);
        assert_eq!(plan.manifest.simulation.seed, 2018);
    }

    #[test]
    fn band_above_nyquist_names_the_key() {
        let e = problems(&BUNDLED.replace("f1_hz = 35.0", "f1_hz = 1500.0"));
        assert!(e.contains("excitation.f1_hz"), "{e}");
        assert!(
            e.contains("at or above the Nyquist frequency (1024 Hz"),
            "{e}"
        );
    }

    #[test]
    fn an_identification_band_above_nyquist_names_the_key() {
        let e = problems(&BUNDLED.replace("band_hz = [0.5, 30.0]", "band_hz = [0.5, 1100.0]"));
        assert!(e.contains("identification.band_hz"), "{e}");
        assert!(
            e.contains("1100 Hz is at or above the Nyquist frequency (1024 Hz"),
            "{e}"
        );
    }

    #[test]
    fn non_positive_duration_and_sample_rate() {
        let e = problems(
            &BUNDLED
                .replace("duration_s = 170.0", "duration_s = 0.0")
                .replace("sample_rate_hz = 2048.0", "sample_rate_hz = -1.0"),
        );
        assert!(
            e.contains("excitation.duration_s: must be positive (got 0)"),
            "{e}"
        );
        assert!(
            e.contains("simulation.sample_rate_hz: must be positive (got -1)"),
            "{e}"
        );
    }

    #[test]
    fn a_seed_that_is_not_an_integer() {
        let e = problems(&BUNDLED.replace("seed = 2018", "seed = 20.18"));
        assert!(e.contains("simulation.seed"), "{e}");
        assert!(e.contains("must be a whole number, 0 or more"), "{e}");
        let e = problems(&BUNDLED.replace("seed = 2018", "seed = \"abc\""));
        assert!(e.contains("simulation.seed"), "{e}");
    }

    #[test]
    fn chirp_without_its_frequencies() {
        let e = problems(&BUNDLED.replace("f0_hz = 0.1\n", ""));
        assert!(
            e.contains("excitation.f0_hz: a chirp excitation needs `f0_hz`"),
            "{e}"
        );
    }

    #[test]
    fn square_waves_limits_and_the_supply_name_their_keys() {
        let chirp = "kind = \"chirp\"\nlaw = \"quadratic\"\nf0_hz = 0.1\nf1_hz = 35.0\n";
        assert!(BUNDLED.contains(chirp));
        let square = BUNDLED.replace(chirp, "kind = \"square\"\n");
        let e = problems(&square);
        assert!(
            e.contains("excitation.period_s: a square excitation needs `period_s`"),
            "{e}"
        );
        let e = problems(&square.replace("amplitude_m = 0.004", "period_s = 0.0005"));
        assert!(
            e.contains("excitation.amplitude_m: a square excitation needs `amplitude_m`"),
            "{e}"
        );
        assert!(
            e.contains("excitation.period_s: 0.0005 s spans 1.024 sample(s) at simulation.sample_rate_hz = 2048; a square wave needs at least 2"),
            "{e}"
        );
        let plan = load_simulation_str(
            &square.replace(
                "amplitude_m = 0.004",
                "amplitude_m = 0.004\nperiod_s = 2.0\nlimit_m = 0.003",
            ),
            Path::new("sim.toml"),
        )
        .unwrap();
        assert_eq!(
            plan.runs[0].excitation,
            Command::Generated(Excitation::Square {
                amplitude_m: 0.004,
                period_s: 2.0,
                duration_s: 170.0
            })
        );
        assert_eq!(plan.runs[0].limit_m, Some(0.003));
        let e = problems(&BUNDLED.replace(
            "amplitude_m = 0.004",
            "amplitude_m = 0.004\nperiod_s = 2.0\nlimit_m = 0.0",
        ));
        assert!(
            e.contains("excitation.period_s: applies only to a square wave"),
            "{e}"
        );
        assert!(
            e.contains("excitation.limit_m: must be positive (got 0)"),
            "{e}"
        );

        let supplied = |lines: &str| {
            BUNDLED.replace("[rig.parameters]", &format!("{lines}\n[rig.parameters]"))
        };
        let e = problems(&supplied("piston_area_m2 = 2.387e-4"));
        assert!(
            e.contains("rig.supply_pressure_pa: the flow-pressure law needs the supply pressure"),
            "{e}"
        );
        let e = problems(&supplied(
            "piston_area_m2 = 2.387e-4\nsupply_pressure_pa = -1.0",
        ));
        assert!(
            e.contains("rig.supply_pressure_pa: must be positive"),
            "{e}"
        );
        let plan = load_simulation_str(
            &supplied("piston_area_m2 = 2.387e-4\nsupply_pressure_pa = 2.07e7"),
            Path::new("sim.toml"),
        )
        .unwrap();
        assert_eq!(plan.unmodelled.max_force_n, Some(2.387e-4 * 2.07e7));
    }

    #[test]
    fn a_negative_rig_parameter_is_refused() {
        let e = problems(&BUNDLED.replace("a3_per_s = 16.118", "a3_per_s = -16.118"));
        assert!(
            e.contains("rig.parameters.a3_per_s: must be positive"),
            "{e}"
        );
    }
}
