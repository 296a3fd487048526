//! The simulation manifest: a rig with known (true) parameters, a test
//! program and an instrument chain, from which `servoid simulate` writes lab
//! logs, a truth file and an analysis manifest. Checked with the same
//! machinery as the analysis manifest (every problem at once, with key paths
//! and lines); `schemas/simulation.schema.json` is generated from these types.

use std::path::{Path, PathBuf};

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use super::keypath::KeyPath;
use super::load::{Document, ManifestError, Problem, read};
use super::validate::{
    IdentificationPlan, SpecimenPlan, check_identification, check_specimen, hex,
};
use super::{Identification, Reference, Role, SCHEMA_VERSION, Specimen, Unit, UnitKind};
use crate::model::RigParams;

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
    pub runs: Vec<SimRun>,
    /// Published values copied into the generated analysis manifest.
    #[serde(default)]
    pub references: Vec<Reference>,
}

/// Global settings of a simulation.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct SimulationInfo {
    /// Name of the simulated campaign (letters, digits, `.`, `_`, `-`); also
    /// the default output folder under `reports/`.
    pub name: String,
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
    pub name: String,
    #[serde(default)]
    pub notes: String,
    /// The true parameters (Eq. 10), a1b0 at `p_gain`.
    pub parameters: RigParams,
    /// Dynamics a real rig has and the paper's model lacks; omit for a
    /// campaign that is exactly the paper's model ("clean").
    #[serde(default)]
    pub unmodelled: Option<UnmodelledSpec>,
}

/// Unmodelled dynamics ("rich" campaigns).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct UnmodelledSpec {
    /// A second-order servo-valve mode in series with the first-order valve.
    #[serde(default)]
    pub valve_mode: Option<ValveModeSpec>,
    /// Piston (and load-cell) mass moving with the actuator (kg).
    #[serde(default)]
    pub piston_mass_kg: Option<f64>,
}

/// A second-order servo-valve mode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct ValveModeSpec {
    pub natural_frequency_hz: f64,
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
    /// Chirp start and end frequencies (Hz).
    #[serde(default)]
    pub f0_hz: Option<f64>,
    #[serde(default)]
    pub f1_hz: Option<f64>,
    /// Band of a multisine or band-limited random signal (Hz).
    #[serde(default)]
    pub f_min_hz: Option<f64>,
    #[serde(default)]
    pub f_max_hz: Option<f64>,
    /// Length of the excitation (s), without lead-in and lead-out.
    pub duration_s: f64,
    /// Peak amplitude of a chirp (m).
    #[serde(default)]
    pub amplitude_m: Option<f64>,
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
}

/// Kinds of excitation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum ExcitationKind {
    Chirp,
    Multisine,
    RandomBand,
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
    pub command: SensorSpec,
    /// The displacement sensor (e.g. the actuator's LVDT).
    pub displacement: SensorSpec,
    /// The load cell.
    pub force: SensorSpec,
}

/// One channel's sensor and conditioning, in the channel's own unit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct SensorSpec {
    /// The unit the log records this channel in.
    pub unit: Unit,
    /// White noise RMS (in `unit`).
    #[serde(default)]
    pub noise_rms: f64,
    /// Sensor and conditioning delay (s).
    #[serde(default)]
    pub delay_s: f64,
    /// Constant offset (in `unit`).
    #[serde(default)]
    pub offset: f64,
    /// Slow linear drift (`unit` per second).
    #[serde(default)]
    pub drift_per_s: f64,
    /// ADC quantisation.
    #[serde(default)]
    pub quantization: Option<QuantizationSpec>,
}

/// ADC quantisation: `bits` over the symmetric range +/- `full_scale` (in the
/// channel's unit), values beyond it clipped.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct QuantizationSpec {
    pub bits: u32,
    pub full_scale: f64,
}

/// One simulated run.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct SimRun {
    pub id: String,
    pub role: Role,
    #[serde(default)]
    pub description: String,
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

/// A checked simulation.
#[derive(Debug, Clone)]
pub struct SimulationPlan {
    pub file: PathBuf,
    pub manifest_sha256: String,
    pub manifest: SimulationManifest,
    pub identification: IdentificationPlan,
    pub runs: Vec<SimRunPlan>,
}

/// A checked simulated run.
#[derive(Debug, Clone)]
pub struct SimRunPlan {
    pub id: String,
    pub role: Role,
    pub p_gain: f64,
    pub specimen: SpecimenPlan,
    pub excitation: ExcitationSpec,
}

/// Read and check a simulation manifest.
pub fn load_simulation(path: &Path) -> Result<SimulationPlan, ManifestError> {
    let text = read(path)?;
    load_simulation_str(&text, path)
}

/// Check simulation-manifest text as if read from `path`.
pub fn load_simulation_str(text: &str, path: &Path) -> Result<SimulationPlan, ManifestError> {
    let mut doc = Document::parse(text, path, crate::schema::simulation_schema())?;
    doc.check_top_level();
    let schema_version: Option<u32> = doc.section("schema_version");
    let info: Option<SimulationInfo> = doc.section("simulation");
    let rig: Option<SimRig> = doc.section("rig");
    let excitation: Option<ExcitationSpec> = doc.section("excitation");
    let instrument: Option<Instrument> = doc.section("instrument");
    let identification: Option<Identification> = doc.section("identification");
    let runs: Vec<Option<SimRun>> = doc.array("runs");
    let raw_ids: Vec<Option<String>> = doc.raw("runs", "id");
    let references: Vec<Option<Reference>> = doc.array("references");

    let problems = &mut doc.problems;
    let mut bad = |path: KeyPath, msg: String| problems.push(Problem::new(path, msg));
    let root = KeyPath::root();
    if let Some(v) = schema_version
        && v != SCHEMA_VERSION
    {
        bad(
            root.key("schema_version"),
            format!("unsupported schema_version {v}; this servoid reads {SCHEMA_VERSION}"),
        );
    }
    let fs = info.as_ref().map(|i| i.sample_rate_hz);
    if let Some(i) = &info {
        let p = root.key("simulation");
        super::validate::check_slug(&i.name, &p.key("name"), &mut bad);
        if !(i.sample_rate_hz.is_finite() && i.sample_rate_hz > 0.0) {
            bad(
                p.key("sample_rate_hz"),
                format!("must be positive (got {})", i.sample_rate_hz),
            );
        }
        let ip = p.key("integrator");
        if i.integrator.substeps == 0 {
            bad(ip.key("substeps"), "must be at least 1".into());
        }
        for (k, v) in [("rtol", i.integrator.rtol), ("atol", i.integrator.atol)] {
            if !(v.is_finite() && v > 0.0) {
                bad(ip.key(k), format!("must be positive (got {v})"));
            }
        }
    }
    if let Some(r) = &rig {
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
        if let Some(u) = &r.unmodelled {
            let up = root.key("rig").key("unmodelled");
            if let Some(v) = &u.valve_mode {
                let vp = up.key("valve_mode");
                if !(v.natural_frequency_hz.is_finite() && v.natural_frequency_hz > 0.0) {
                    bad(
                        vp.key("natural_frequency_hz"),
                        format!("must be positive (got {})", v.natural_frequency_hz),
                    );
                }
                if !(v.damping_ratio.is_finite() && v.damping_ratio > 0.0) {
                    bad(
                        vp.key("damping_ratio"),
                        format!(
                            "must be positive (got {}); an undamped or negatively damped valve mode is unstable",
                            v.damping_ratio
                        ),
                    );
                }
            }
            if let Some(m) = u.piston_mass_kg
                && !(m.is_finite() && m > 0.0)
            {
                bad(
                    up.key("piston_mass_kg"),
                    format!("must be positive (got {m})"),
                );
            }
        }
    }
    if let Some(e) = &excitation {
        check_excitation(e, &root.key("excitation"), fs, &mut bad);
    }
    if let Some(ins) = &instrument {
        let p = root.key("instrument");
        for (name, s, kind) in [
            ("command", &ins.command, UnitKind::Length),
            ("displacement", &ins.displacement, UnitKind::Length),
            ("force", &ins.force, UnitKind::Force),
        ] {
            check_sensor(s, kind, &p.key(name), &mut bad);
        }
    }
    let ident = identification.clone().unwrap_or_default();
    let ident_plan = check_identification(&ident, &root.key("identification"), &mut bad);
    // The logs will be sampled at simulation.sample_rate_hz: a band reaching
    // Nyquist would fit bins that hold no information (and the hold's
    // half-sample delay, exact only below Nyquist).
    if let Some(ny) = fs.filter(|f| f.is_finite() && *f > 0.0).map(|f| 0.5 * f)
        && ident_plan.band_hz.1 >= ny
    {
        bad(
            root.key("identification").key("band_hz"),
            format!(
                "the band's upper edge {} Hz is at or above the Nyquist frequency ({ny} Hz at simulation.sample_rate_hz = {})",
                ident_plan.band_hz.1,
                2.0 * ny
            ),
        );
    }

    let mut first_seen = std::collections::BTreeMap::new();
    for (i, id) in raw_ids.iter().enumerate() {
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
    if runs.is_empty() {
        bad(root.key("runs"), "the simulation has no runs".into());
    }
    let mut run_plans = Vec::new();
    for (i, run) in runs.iter().enumerate() {
        let Some(run) = run else { continue };
        let p = root.key("runs").index(i);
        super::validate::check_slug(&run.id, &p.key("id"), &mut bad);
        if !(run.p_gain.is_finite() && run.p_gain > 0.0) {
            bad(
                p.key("p_gain"),
                format!("must be positive (got {})", run.p_gain),
            );
        }
        let spec = check_specimen(
            run.role,
            run.specimen.as_ref(),
            &p.key("specimen"),
            &mut bad,
        );
        if let Some(e) = &run.excitation {
            check_excitation(e, &p.key("excitation"), fs, &mut bad);
        }
        let exc = run.excitation.clone().or_else(|| excitation.clone());
        // The true plant must be stable: Eq. 10 at this P gain with the
        // specimen and any unmodelled dynamics (eigenvalues, or those of the
        // linearisation at rest).
        if let (Some(spec), Some(r)) = (&spec, &rig)
            && r.parameters.is_physical()
        {
            let plant = crate::simulate::plant::PlantSpec {
                rig: r.parameters.at_p_gain(run.p_gain),
                specimen: *spec,
                unmodelled: unmodelled(r.unmodelled.as_ref()),
            };
            if let Err(e) = crate::simulate::plant::validate(&plant) {
                bad(
                    p.clone(),
                    format!("the true plant of this run cannot be simulated: {e}"),
                );
            }
        }
        if let (Some(spec), Some(exc)) = (spec, exc) {
            run_plans.push(SimRunPlan {
                id: run.id.clone(),
                role: run.role,
                p_gain: run.p_gain,
                specimen: spec,
                excitation: exc,
            });
        }
    }
    for (i, r) in references.iter().enumerate() {
        if let Some(r) = r
            && !(r.published.is_finite() && r.published != 0.0)
        {
            bad(
                root.key("references").index(i).key("published"),
                "must be a finite, non-zero number".into(),
            );
        }
    }

    let result = (|| {
        Some(SimulationPlan {
            file: path.to_path_buf(),
            manifest_sha256: hex(&Sha256::digest(text.as_bytes())),
            manifest: SimulationManifest {
                schema_version: schema_version?,
                simulation: info?,
                rig: rig?,
                excitation: excitation?,
                instrument: instrument?,
                identification: ident,
                runs: runs.into_iter().collect::<Option<Vec<_>>>()?,
                references: references.into_iter().collect::<Option<Vec<_>>>()?,
            },
            identification: ident_plan,
            runs: run_plans,
        })
    })();
    doc.finish(result)
}

/// The simulator's form of the unmodelled dynamics.
pub fn unmodelled(u: Option<&UnmodelledSpec>) -> crate::simulate::plant::Unmodelled {
    let Some(u) = u else {
        return crate::simulate::plant::Unmodelled::default();
    };
    crate::simulate::plant::Unmodelled {
        valve_mode: u
            .valve_mode
            .as_ref()
            .map(|v| crate::simulate::plant::ValveMode {
                natural_frequency_hz: v.natural_frequency_hz,
                damping_ratio: v.damping_ratio,
            }),
        piston_mass_kg: u.piston_mass_kg,
    }
}

fn check_excitation(
    e: &ExcitationSpec,
    p: &KeyPath,
    fs: Option<f64>,
    bad: &mut impl FnMut(KeyPath, String),
) {
    let nyquist = fs.filter(|f| f.is_finite() && *f > 0.0).map(|f| 0.5 * f);
    let need = |key: &str, v: Option<f64>, bad: &mut dyn FnMut(KeyPath, String)| -> Option<f64> {
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
    };
    let (lo_key, hi_key, lo, hi) = match e.kind {
        ExcitationKind::Chirp => {
            need("amplitude_m", e.amplitude_m, bad);
            (
                "f0_hz",
                "f1_hz",
                need("f0_hz", e.f0_hz, bad),
                need("f1_hz", e.f1_hz, bad),
            )
        }
        ExcitationKind::Multisine | ExcitationKind::RandomBand => {
            need("rms_m", e.rms_m, bad);
            if e.kind == ExcitationKind::Multisine && e.n_tones.is_none_or(|n| n == 0) {
                bad(p.key("n_tones"), "a multisine needs `n_tones` >= 1".into());
            }
            (
                "f_min_hz",
                "f_max_hz",
                need("f_min_hz", e.f_min_hz, bad),
                need("f_max_hz", e.f_max_hz, bad),
            )
        }
    };
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
    if !(e.duration_s.is_finite() && e.duration_s > 0.0) {
        bad(
            p.key("duration_s"),
            format!("must be positive (got {})", e.duration_s),
        );
    }
    for (key, v) in [("lead_in_s", e.lead_in_s), ("lead_out_s", e.lead_out_s)] {
        if !(v.is_finite() && v >= 0.0) {
            bad(p.key(key), format!("must be zero or positive (got {v})"));
        }
    }
    if e.kind != ExcitationKind::Chirp && e.law.is_some() {
        bad(p.key("law"), "applies only to a chirp".into());
    }
}

fn kind_name(k: ExcitationKind) -> &'static str {
    match k {
        ExcitationKind::Chirp => "chirp",
        ExcitationKind::Multisine => "multisine",
        ExcitationKind::RandomBand => "random_band",
    }
}

fn check_sensor(
    s: &SensorSpec,
    kind: UnitKind,
    p: &KeyPath,
    bad: &mut impl FnMut(KeyPath, String),
) {
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
        assert!(e.contains("expected u64"), "{e}");
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
    fn a_negative_rig_parameter_is_refused() {
        let e = problems(&BUNDLED.replace("a3_per_s = 16.118", "a3_per_s = -16.118"));
        assert!(
            e.contains("rig.parameters.a3_per_s: must be positive"),
            "{e}"
        );
    }
}
