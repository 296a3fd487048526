//! From the manifest as written to a [`Campaign`] whose every value is usable:
//! positive masses, stiffnesses and gains, specimens that fit their runs'
//! roles, transfer functions that are proper, logs that exist, references
//! that name quantities the campaign computes. Every problem is collected.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

use super::keypath::KeyPath;
use super::load::Problem;
use super::{
    CampaignInfo, Channel, Channels as RawChannels, Column, CompareMode, CsvOptions, DelayMode,
    Detrend, Estimator, Identification, Intersample, LogFormat, Manifest, Reference, Rig, Role,
    Run, SCHEMA_VERSION, Specimen, SpecimenKind, TimeUnit, Unit, UnitKind, Window,
};
use crate::lti::TransferFunction;
use crate::model::RigParams;

/// The sections that deserialized (a failed section is `None`; its problem is
/// already recorded).
#[derive(Debug, Default)]
pub(super) struct Partial {
    pub schema_version: Option<u32>,
    pub campaign: Option<CampaignInfo>,
    pub rig: Option<Rig>,
    pub channels: Option<RawChannels>,
    pub identification: Option<Identification>,
    pub runs: Vec<Option<Run>>,
    /// Ids and roles read straight from the document, so cross-run checks
    /// still see a run whose other keys failed to deserialize.
    pub raw_run_ids: Vec<Option<String>>,
    pub raw_run_roles: Vec<Option<Role>>,
    pub references: Vec<Option<Reference>>,
}

/// A checked campaign, ready to run.
#[derive(Debug, Clone)]
pub struct Campaign {
    /// The manifest file it came from.
    pub file: PathBuf,
    /// SHA-256 of the manifest's bytes (hex), for provenance.
    pub manifest_sha256: String,
    pub name: String,
    pub description: String,
    pub rig_name: String,
    pub rig_notes: String,
    /// Rig parameters given in the manifest (identified earlier).
    pub given_rig: Option<RigParams>,
    pub identification: IdentificationPlan,
    pub runs: Vec<RunPlan>,
    pub references: Vec<ReferencePlan>,
    /// The manifest as read, echoed into results for provenance.
    pub manifest: Manifest,
}

impl Campaign {
    /// Whether the campaign can identify the rig itself (Fig. 6, steps 3-5).
    pub fn identifies_rig(&self) -> bool {
        self.runs.iter().any(|r| r.role == Role::NoSpecimen)
            && self.runs.iter().any(|r| r.role == Role::Spring)
    }
}

/// Checked identification options.
#[derive(Debug, Clone, PartialEq)]
pub struct IdentificationPlan {
    pub band_hz: (f64, f64),
    pub coherence_min: f64,
    pub frf: FrfPlan,
    pub intersample: Intersample,
    pub delay: DelayPlan,
    pub numerator_order: usize,
    pub denominator_order: usize,
    pub trim_to_excitation: bool,
}

/// Checked FRF settings.
#[derive(Debug, Clone, PartialEq)]
pub struct FrfPlan {
    pub estimator: Estimator,
    pub segment_length: usize,
    pub overlap: f64,
    pub window: Window,
    pub detrend: Detrend,
}

/// How a pure delay enters the fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DelayPlan {
    None,
    Fixed { delay_s: f64 },
    Fit { max_s: f64 },
}

/// A checked run.
#[derive(Debug, Clone)]
pub struct RunPlan {
    /// Position in the manifest (results keep this order).
    pub index: usize,
    pub id: String,
    pub role: Role,
    pub description: String,
    pub p_gain: f64,
    pub specimen: SpecimenPlan,
    pub source: RunSource,
    pub band_hz: (f64, f64),
}

/// A checked specimen: the simulator's model of it, linear or not.
pub type SpecimenPlan = crate::simulate::specimen::SpecimenModel;

/// Where a run's transfer function comes from.
#[derive(Debug, Clone)]
pub enum RunSource {
    /// No data: the run is a prediction from the rig model only.
    None,
    /// A published transfer function.
    Published {
        tf: TransferFunction,
        source: String,
    },
    /// A log to ingest.
    Log(Box<LogPlan>),
}

/// A log to ingest, with its channels resolved.
#[derive(Debug, Clone, PartialEq)]
pub struct LogPlan {
    pub path: PathBuf,
    pub format: LogFormat,
    pub csv: CsvOptions,
    pub sha256: Option<String>,
    pub channels: Channels,
}

/// A run's channels, defaults and overrides merged, with SI conversion.
#[derive(Debug, Clone, PartialEq)]
pub struct Channels {
    pub time: TimePlan,
    pub command: ChannelPlan,
    pub displacement: ChannelPlan,
    pub force: Option<ChannelPlan>,
}

/// How to get the time base.
#[derive(Debug, Clone, PartialEq)]
pub enum TimePlan {
    Column {
        column: Column,
        to_s: f64,
    },
    SampleRate {
        hz: f64,
    },
    /// The log's own header gives the rate (DAQ text, MAT).
    FromLog,
}

/// One channel: SI value = raw * gain + offset.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelPlan {
    pub column: Column,
    /// The unit the manifest gave (reported back in results).
    pub unit: Unit,
    /// scale * unit-to-SI.
    pub gain: f64,
    /// offset * unit-to-SI.
    pub offset: f64,
}

/// A reference with its quantity parsed.
#[derive(Debug, Clone, PartialEq)]
pub struct ReferencePlan {
    pub quantity: Quantity,
    pub published: f64,
    pub source: String,
    pub compare: CompareMode,
    pub tolerance_pct: f64,
}

/// A quantity servoid computes and can compare: `<scope>.<name>`.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub enum Quantity {
    Rig(String),
    PerSpring { run: String, name: String },
    Run { run: String, name: String },
    Ccf { run: String, name: String },
}

impl std::fmt::Display for Quantity {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Quantity::Rig(n) => write!(f, "rig.{n}"),
            Quantity::PerSpring { run, name } => write!(f, "per_spring.{run}.{name}"),
            Quantity::Run { run, name } => write!(f, "runs.{run}.{name}"),
            Quantity::Ccf { run, name } => write!(f, "ccf.{run}.{name}"),
        }
    }
}

const RIG_QUANTITIES: &[&str] = &["beta1", "R1", "a1b0", "a2", "a3", "valve_time_constant_ms"];
const SPRING_QUANTITIES: &[&str] = &["R2", "R3", "a1b0", "a2", "a3"];
const RUN_QUANTITIES: &[&str] = &["a1b0", "natural_frequency_hz", "nrmse_pct", "nae_pct"];
const CCF_QUANTITIES: &[&str] = &["C1", "C2", "C3", "C4", "C5"];

pub(super) fn validate(
    partial: Partial,
    file: &Path,
    bytes: &[u8],
    base_dir: &Path,
    problems: &mut Vec<Problem>,
) -> Option<Campaign> {
    let root = KeyPath::root();
    let mut bad = |path: KeyPath, msg: String| problems.push(Problem::new(path, msg));

    if let Some(v) = partial.schema_version
        && v != SCHEMA_VERSION
    {
        bad(
            root.key("schema_version"),
            format!("unsupported schema_version {v}; this servoid reads {SCHEMA_VERSION}"),
        );
    }
    if let Some(c) = &partial.campaign {
        check_slug(&c.name, &root.key("campaign").key("name"), &mut bad);
    }
    let given_rig = partial.rig.as_ref().and_then(|r| r.parameters);
    if let Some(rig) = &partial.rig {
        if rig.name.trim().is_empty() {
            bad(root.key("rig").key("name"), "must not be empty".into());
        }
        if let Some(p) = &rig.parameters {
            let base = root.key("rig").key("parameters");
            for (k, v) in [
                ("beta1_per_s", p.beta1_per_s),
                ("a1b0_n_per_m_s2", p.a1b0_n_per_m_s2),
                ("a2_n_per_m", p.a2_n_per_m),
                ("a3_per_s", p.a3_per_s),
                ("p_gain", p.p_gain),
            ] {
                positive(v, &base.key(k), &mut bad);
            }
        }
    }
    let default_channels = partial.channels.clone().unwrap_or_default();
    check_channels(&default_channels, &root.key("channels"), &mut bad);
    let ident = partial.identification.clone().unwrap_or_default();
    let ident_plan = check_identification(&ident, &root.key("identification"), &mut bad);

    // Runs.
    if partial.runs.is_empty() && partial.raw_run_ids.is_empty() {
        bad(root.key("runs"), "the campaign has no runs".into());
    }
    let mut first_seen: BTreeMap<&str, usize> = BTreeMap::new();
    for (i, id) in partial.raw_run_ids.iter().enumerate() {
        if let Some(id) = id {
            if let Some(&j) = first_seen.get(id.as_str()) {
                bad(
                    root.key("runs").index(i).key("id"),
                    format!("duplicate run id `{id}` (first used by runs[{j}])"),
                );
            } else {
                first_seen.insert(id, i);
            }
        }
    }
    let mut runs = Vec::new();
    for (i, run) in partial.runs.iter().enumerate() {
        let Some(run) = run else { continue };
        let base = root.key("runs").index(i);
        if let Some(plan) = check_run(
            run,
            i,
            &base,
            &default_channels,
            &ident_plan,
            base_dir,
            &mut bad,
        ) {
            runs.push(plan);
        }
    }

    // A campaign with validation runs needs the rig: given, or identified.
    let roles: Vec<Role> = partial.raw_run_roles.iter().flatten().copied().collect();
    let has_ns = roles.contains(&Role::NoSpecimen);
    let has_spring = roles.contains(&Role::Spring);
    if roles.contains(&Role::Validation) && given_rig.is_none() && !(has_ns && has_spring) {
        let missing = match (has_ns, has_spring) {
            (false, false) => "has neither a no_specimen run nor a spring run",
            (false, true) => "has no no_specimen run",
            _ => "has no spring run",
        };
        bad(
            root.key("rig").key("parameters"),
            format!(
                "the validation runs need rig parameters, but the campaign gives no [rig.parameters] and {missing} to identify them from (Eqs. 18-20)"
            ),
        );
    }
    if has_spring && !has_ns && given_rig.is_none() {
        bad(
            root.key("runs"),
            "spring runs need a no_specimen run (beta1 and R1, Eq. 18) to identify the rig".into(),
        );
    }

    // References.
    let run_roles: BTreeMap<&str, (Role, bool)> = partial
        .runs
        .iter()
        .flatten()
        .map(|r| {
            let has_mass = r.specimen.as_ref().is_some_and(|s| s.mass_kg.is_some());
            (r.id.as_str(), (r.role, has_mass))
        })
        .collect();
    let mut references = Vec::new();
    for (i, r) in partial.references.iter().enumerate() {
        let Some(r) = r else { continue };
        let base = root.key("references").index(i);
        if let Some(plan) = check_reference(r, &base, &run_roles, &mut bad) {
            references.push(plan);
        }
    }

    if !problems.is_empty() {
        return None;
    }
    let campaign = partial.campaign?;
    let rig = partial.rig?;
    let manifest = Manifest {
        schema_version: partial.schema_version?,
        campaign: campaign.clone(),
        rig: rig.clone(),
        channels: default_channels,
        identification: ident,
        runs: partial.runs.into_iter().flatten().collect(),
        references: partial.references.into_iter().flatten().collect(),
    };
    Some(Campaign {
        file: file.to_path_buf(),
        manifest_sha256: hex(&Sha256::digest(bytes)),
        name: campaign.name,
        description: campaign.description,
        rig_name: rig.name,
        rig_notes: rig.notes,
        given_rig,
        identification: ident_plan,
        runs,
        references,
        manifest,
    })
}

pub fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

pub(super) fn check_slug(s: &str, path: &KeyPath, bad: &mut impl FnMut(KeyPath, String)) {
    if s.is_empty() {
        bad(path.clone(), "must not be empty".into());
    } else if !s
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-'))
        || s.starts_with('.')
    {
        bad(
            path.clone(),
            format!(
                "`{s}` may hold only letters, digits, `.`, `_` and `-` (it names files and folders)"
            ),
        );
    }
}

fn positive(v: f64, path: &KeyPath, bad: &mut impl FnMut(KeyPath, String)) -> bool {
    if v.is_finite() && v > 0.0 {
        true
    } else {
        bad(path.clone(), format!("must be positive (got {v})"));
        false
    }
}

fn check_channel(
    ch: &Channel,
    kind: UnitKind,
    path: &KeyPath,
    bad: &mut impl FnMut(KeyPath, String),
) {
    if ch.unit.kind() != kind {
        let need = match kind {
            UnitKind::Length => "m, cm, mm or in",
            UnitKind::Force => "N, kN or lbf",
        };
        bad(
            path.key("unit"),
            format!(
                "`{}` does not fit this channel; use {need}",
                ch.unit.symbol()
            ),
        );
    }
    if !(ch.scale.is_finite() && ch.scale != 0.0) {
        bad(
            path.key("scale"),
            format!("must be finite and non-zero (got {})", ch.scale),
        );
    }
    if !ch.offset.is_finite() {
        bad(path.key("offset"), "must be finite".into());
    }
    if let Column::Name(n) = &ch.column
        && n.is_empty()
    {
        bad(path.key("column"), "must not be empty".into());
    }
}

fn check_channels(ch: &RawChannels, path: &KeyPath, bad: &mut impl FnMut(KeyPath, String)) {
    if let Some(t) = &ch.time {
        let p = path.key("time");
        match (&t.column, t.sample_rate_hz) {
            (Some(_), Some(_)) => bad(
                p.clone(),
                "give either `column` or `sample_rate_hz`, not both".into(),
            ),
            (None, Some(hz)) => {
                positive(hz, &p.key("sample_rate_hz"), bad);
            }
            (None, None) => bad(p.clone(), "give `column` or `sample_rate_hz`".into()),
            (Some(_), None) => {}
        }
        if t.unit.is_some() && t.column.is_none() {
            bad(p.key("unit"), "applies only to a time `column`".into());
        }
    }
    if let Some(c) = &ch.command {
        check_channel(c, UnitKind::Length, &path.key("command"), bad);
    }
    if let Some(c) = &ch.displacement {
        check_channel(c, UnitKind::Length, &path.key("displacement"), bad);
    }
    if let Some(c) = &ch.force {
        check_channel(c, UnitKind::Force, &path.key("force"), bad);
    }
}

fn check_band(band: [f64; 2], path: &KeyPath, bad: &mut impl FnMut(KeyPath, String)) {
    let [lo, hi] = band;
    if !(lo.is_finite() && hi.is_finite() && lo >= 0.0 && hi > lo) {
        bad(
            path.clone(),
            format!("must be [low, high] with 0 <= low < high (got [{lo}, {hi}])"),
        );
    }
}

pub(super) fn check_identification(
    id: &Identification,
    path: &KeyPath,
    bad: &mut impl FnMut(KeyPath, String),
) -> IdentificationPlan {
    check_band(id.band_hz, &path.key("band_hz"), bad);
    if !(0.0..1.0).contains(&id.coherence_min) {
        bad(
            path.key("coherence_min"),
            format!("must be in [0, 1) (got {})", id.coherence_min),
        );
    }
    let frf = path.key("frf");
    if id.frf.segment_length < 16 {
        bad(
            frf.key("segment_length"),
            format!(
                "must be at least 16 samples (got {})",
                id.frf.segment_length
            ),
        );
    }
    if !(0.0..1.0).contains(&id.frf.overlap) {
        bad(
            frf.key("overlap"),
            format!("must be in [0, 1) (got {})", id.frf.overlap),
        );
    }
    let d = &id.delay;
    let delay = match d.mode {
        DelayMode::None => DelayPlan::None,
        DelayMode::Fixed => {
            if !(d.value_s.is_finite() && d.value_s >= 0.0) {
                bad(
                    path.key("delay").key("value_s"),
                    format!("must be a non-negative delay (got {})", d.value_s),
                );
            }
            DelayPlan::Fixed { delay_s: d.value_s }
        }
        DelayMode::Fit => {
            positive(d.max_s, &path.key("delay").key("max_s"), bad);
            DelayPlan::Fit { max_s: d.max_s }
        }
    };
    if id.model.denominator == 0 || id.model.numerator > id.model.denominator {
        bad(
            path.key("model"),
            format!(
                "needs 1 <= denominator and numerator <= denominator (got {}/{})",
                id.model.numerator, id.model.denominator
            ),
        );
    }
    IdentificationPlan {
        band_hz: (id.band_hz[0], id.band_hz[1]),
        coherence_min: id.coherence_min,
        frf: FrfPlan {
            estimator: id.frf.estimator,
            segment_length: id.frf.segment_length,
            overlap: id.frf.overlap,
            window: id.frf.window,
            detrend: id.frf.detrend,
        },
        intersample: id.command_intersample,
        delay,
        numerator_order: id.model.numerator,
        denominator_order: id.model.denominator,
        trim_to_excitation: id.trim_to_excitation,
    }
}

pub(super) fn check_specimen(
    role: Role,
    spec: Option<&Specimen>,
    path: &KeyPath,
    bad: &mut impl FnMut(KeyPath, String),
) -> Option<SpecimenPlan> {
    use crate::simulate::specimen::{BoucWen, Duffing, Friction, SpecimenModel as M};
    let s = spec.cloned().unwrap_or_default();
    let mut ok = true;
    for (k, v) in [
        ("mass_kg", s.mass_kg),
        ("stiffness_n_per_m", s.stiffness_n_per_m),
    ] {
        if let Some(v) = v {
            ok &= positive(v, &path.key(k), bad);
        }
    }
    if let Some(c) = s.damping_ns_per_m
        && !(c.is_finite() && c >= 0.0)
    {
        bad(
            path.key("damping_ns_per_m"),
            format!("must be zero or positive (got {c})"),
        );
        ok = false;
    }
    // Keys that belong to one nonlinear model only.
    let model_keys: [(&str, bool, SpecimenKind); 4] = [
        (
            "cubic_stiffness_n_per_m3",
            s.cubic_stiffness_n_per_m3.is_some(),
            SpecimenKind::Duffing,
        ),
        (
            "coulomb_force_n",
            s.coulomb_force_n.is_some(),
            SpecimenKind::Friction,
        ),
        (
            "smoothing_velocity_m_per_s",
            s.smoothing_velocity_m_per_s.is_some(),
            SpecimenKind::Friction,
        ),
        ("bouc_wen", s.bouc_wen.is_some(), SpecimenKind::BoucWen),
    ];
    for (key, given, owner) in model_keys {
        if given && s.model != owner {
            let name = serde_json::to_value(owner)
                .ok()
                .and_then(|v| v.as_str().map(str::to_string))
                .unwrap_or_default();
            bad(path.key(key), format!("applies only to model = \"{name}\""));
            ok = false;
        }
    }
    let given: Vec<&str> = [
        ("mass_kg", s.mass_kg.is_some()),
        ("damping_ns_per_m", s.damping_ns_per_m.is_some()),
        ("stiffness_n_per_m", s.stiffness_n_per_m.is_some()),
    ]
    .iter()
    .filter(|(_, g)| *g)
    .map(|(k, _)| *k)
    .collect();
    if s.model != SpecimenKind::Linear && matches!(role, Role::NoSpecimen | Role::Spring) {
        bad(
            path.key("model"),
            format!(
                "a {} run identifies the rig with a linear specimen (Eqs. 18-19); nonlinear specimens are for validation and fit runs",
                role.as_str()
            ),
        );
        return None;
    }
    match role {
        Role::NoSpecimen => {
            if !given.is_empty() {
                bad(
                    path.clone(),
                    format!(
                        "a no_specimen run has no specimen; remove {}",
                        given.join(", ")
                    ),
                );
                return None;
            }
            Some(M::None)
        }
        Role::Spring => {
            let Some(k) = s.stiffness_n_per_m else {
                bad(
                    path.key("stiffness_n_per_m"),
                    "a spring run needs the spring's stiffness".into(),
                );
                return None;
            };
            if s.mass_kg.is_some() || s.damping_ns_per_m.is_some() {
                bad(
                    path.clone(),
                    "a spring run is massless and undamped in the paper's model (Sec. 3.1); give only stiffness_n_per_m, or use role `validation` for a specimen with mass".into(),
                );
                return None;
            }
            ok.then_some(M::Spring {
                stiffness_n_per_m: k,
            })
        }
        Role::Validation | Role::Fit if s.model == SpecimenKind::Linear => {
            let lin = match (s.mass_kg, s.damping_ns_per_m, s.stiffness_n_per_m) {
                (None, None, None) => M::None,
                (None, None, Some(k)) => M::Spring {
                    stiffness_n_per_m: k,
                },
                (Some(m), c, Some(k)) => M::LinearSdof {
                    mass_kg: m,
                    damping_ns_per_m: c.unwrap_or(0.0),
                    stiffness_n_per_m: k,
                },
                (Some(_), _, None) => {
                    bad(
                        path.key("stiffness_n_per_m"),
                        "an SDOF specimen needs its stiffness".into(),
                    );
                    return None;
                }
                (None, Some(_), _) => {
                    bad(
                        path.key("mass_kg"),
                        "a damped specimen needs its mass (the paper's massless model has no damping)".into(),
                    );
                    return None;
                }
            };
            ok.then_some(lin)
        }
        Role::Validation | Role::Fit => {
            // A nonlinear specimen: every parameter of its model is required.
            let mut need = |key: &str, v: Option<f64>| -> f64 {
                v.unwrap_or_else(|| {
                    bad(
                        path.key(key),
                        format!("a {} specimen needs `{key}`", model_name(s.model)),
                    );
                    ok = false;
                    f64::NAN
                })
            };
            let m = need("mass_kg", s.mass_kg);
            let k = need("stiffness_n_per_m", s.stiffness_n_per_m);
            let c = s.damping_ns_per_m.unwrap_or(0.0);
            let model = match s.model {
                SpecimenKind::Duffing => M::Duffing(Duffing {
                    mass_kg: m,
                    damping_ns_per_m: c,
                    stiffness_n_per_m: k,
                    cubic_stiffness_n_per_m3: need(
                        "cubic_stiffness_n_per_m3",
                        s.cubic_stiffness_n_per_m3,
                    ),
                }),
                SpecimenKind::Friction => M::Friction(Friction {
                    mass_kg: m,
                    damping_ns_per_m: c,
                    stiffness_n_per_m: k,
                    coulomb_force_n: need("coulomb_force_n", s.coulomb_force_n),
                    smoothing_velocity_m_per_s: need(
                        "smoothing_velocity_m_per_s",
                        s.smoothing_velocity_m_per_s,
                    ),
                }),
                SpecimenKind::BoucWen => match &s.bouc_wen {
                    Some(bw) => M::BoucWen(BoucWen {
                        mass_kg: m,
                        damping_ns_per_m: c,
                        stiffness_n_per_m: k,
                        alpha: bw.alpha,
                        a: bw.a,
                        beta_per_m_pow_n: bw.beta_per_m_pow_n,
                        gamma_per_m_pow_n: bw.gamma_per_m_pow_n,
                        n: bw.n,
                    }),
                    None => {
                        bad(
                            path.key("bouc_wen"),
                            "a bouc_wen specimen needs its `bouc_wen` table (alpha, a, beta_per_m_pow_n, gamma_per_m_pow_n, n)".into(),
                        );
                        return None;
                    }
                },
                SpecimenKind::Linear => unreachable!("handled above"),
            };
            if !ok {
                return None;
            }
            // Signs and ranges, by the simulator's own checks (they name the parameter).
            match model.validate() {
                Ok(()) => Some(model),
                Err(e) => {
                    bad(path.clone(), e.to_string());
                    None
                }
            }
        }
    }
}

fn model_name(k: SpecimenKind) -> &'static str {
    match k {
        SpecimenKind::Linear => "linear",
        SpecimenKind::Duffing => "duffing",
        SpecimenKind::BoucWen => "bouc_wen",
        SpecimenKind::Friction => "friction",
    }
}

fn merge_channels(defaults: &RawChannels, over: Option<&RawChannels>) -> RawChannels {
    let mut out = defaults.clone();
    if let Some(o) = over {
        if o.time.is_some() {
            out.time = o.time.clone();
        }
        if o.command.is_some() {
            out.command = o.command.clone();
        }
        if o.displacement.is_some() {
            out.displacement = o.displacement.clone();
        }
        if o.force.is_some() {
            out.force = o.force.clone();
        }
    }
    out
}

fn plan_channel(c: &Channel) -> ChannelPlan {
    let si = c.unit.to_si();
    ChannelPlan {
        column: c.column.clone(),
        unit: c.unit,
        gain: c.scale * si,
        offset: c.offset * si,
    }
}

fn infer_format(path: &Path) -> Option<LogFormat> {
    let ext = path.extension()?.to_str()?.to_ascii_lowercase();
    match ext.as_str() {
        "csv" | "tsv" => Some(LogFormat::Csv),
        "parquet" | "pq" => Some(LogFormat::Parquet),
        "mat" => Some(LogFormat::Mat),
        "txt" => Some(LogFormat::DaqText),
        _ => None,
    }
}

#[allow(clippy::too_many_arguments)]
fn check_run(
    run: &Run,
    index: usize,
    base: &KeyPath,
    default_channels: &RawChannels,
    ident: &IdentificationPlan,
    base_dir: &Path,
    bad: &mut impl FnMut(KeyPath, String),
) -> Option<RunPlan> {
    check_slug(&run.id, &base.key("id"), bad);
    let p_ok = positive(run.p_gain, &base.key("p_gain"), bad);
    let specimen = check_specimen(run.role, run.specimen.as_ref(), &base.key("specimen"), bad);
    if let Some(b) = run.band_hz {
        check_band(b, &base.key("band_hz"), bad);
    }
    if let Some(ch) = &run.channels {
        check_channels(ch, &base.key("channels"), bad);
    }
    let identification_role = matches!(run.role, Role::NoSpecimen | Role::Spring);
    let data = run.data.clone().unwrap_or_default();
    let dpath = base.key("data");
    let source = match (&data.log, &data.transfer_function) {
        (Some(_), Some(_)) => {
            bad(
                dpath.clone(),
                "give either `log` or `transfer_function`, not both".into(),
            );
            None
        }
        (None, None) => {
            if identification_role || run.role == Role::Fit {
                bad(
                    dpath.clone(),
                    format!(
                        "a {} run needs data: a `log` file or a published `transfer_function`",
                        run.role.as_str()
                    ),
                );
                None
            } else {
                Some(RunSource::None)
            }
        }
        (None, Some(tf)) => {
            let tpath = dpath.key("transfer_function");
            match TransferFunction::with_delay(&tf.num, &tf.den, tf.delay_s) {
                Err(e) => {
                    let key = match e {
                        crate::lti::LtiError::BadDelay(_) => "delay_s",
                        crate::lti::LtiError::EmptyNumerator => "num",
                        crate::lti::LtiError::NonFinite {
                            which: "numerator", ..
                        } => "num",
                        _ => "den",
                    };
                    bad(tpath.key(key), e.to_string());
                    None
                }
                Ok(t) => {
                    if identification_role && (t.num.len() != 1 || t.den.len() != 3) {
                        bad(
                            tpath.clone(),
                            format!(
                                "the paper's procedure needs a second-order model n0/(s^2 + d1 s + d0); got numerator degree {} and denominator degree {}",
                                t.num.len() - 1,
                                t.den.len() - 1
                            ),
                        );
                        None
                    } else if run.role == Role::Validation {
                        bad(
                            tpath.clone(),
                            "a validation run is checked against a log; published transfer functions are for identification (no_specimen, spring) and fit runs".into(),
                        );
                        None
                    } else {
                        Some(RunSource::Published {
                            tf: t,
                            source: tf.source.clone(),
                        })
                    }
                }
            }
        }
        (Some(log), None) => check_log(
            log,
            &data,
            &dpath,
            default_channels,
            run.channels.as_ref(),
            base,
            base_dir,
            bad,
        ),
    };
    if data.log.is_none() {
        for (k, given) in [
            ("format", data.format.is_some()),
            ("csv", data.csv.is_some()),
            ("sha256", data.sha256.is_some()),
        ] {
            if given {
                bad(dpath.key(k), "applies only to a `log`".into());
            }
        }
    }
    let band = run.band_hz.unwrap_or([ident.band_hz.0, ident.band_hz.1]);
    Some(RunPlan {
        index,
        id: run.id.clone(),
        role: run.role,
        description: run.description.clone(),
        p_gain: run.p_gain,
        specimen: specimen?,
        source: source?,
        band_hz: (band[0], band[1]),
    })
    .filter(|_| p_ok)
}

#[allow(clippy::too_many_arguments)]
fn check_log(
    log: &str,
    data: &super::RunData,
    dpath: &KeyPath,
    default_channels: &RawChannels,
    overrides: Option<&RawChannels>,
    base: &KeyPath,
    base_dir: &Path,
    bad: &mut impl FnMut(KeyPath, String),
) -> Option<RunSource> {
    let path = base_dir.join(log);
    let mut ok = true;
    if !path.is_file() {
        bad(
            dpath.key("log"),
            format!("log file not found: {}", path.display()),
        );
        ok = false;
    }
    let format = data.format.or_else(|| infer_format(&path));
    if format.is_none() {
        bad(
            dpath.key("format"),
            format!(
                "cannot tell the format of `{log}` from its extension; give format = \"csv\", \"parquet\", \"mat\" or \"daq_text\""
            ),
        );
        ok = false;
    }
    let csv = data.csv.clone().unwrap_or(CsvOptions {
        delimiter: ",".into(),
        skip_lines: 0,
        comment_prefix: None,
        header: true,
    });
    if csv.delimiter.chars().count() != 1 {
        bad(
            dpath.key("csv").key("delimiter"),
            format!("must be one character (got {:?})", csv.delimiter),
        );
        ok = false;
    }
    if let Some(h) = &data.sha256
        && (h.len() != 64 || !h.chars().all(|c| c.is_ascii_hexdigit()))
    {
        bad(dpath.key("sha256"), "must be 64 hexadecimal digits".into());
        ok = false;
    }
    let merged = merge_channels(default_channels, overrides);
    let ch_path = base.key("channels");
    let mut need = |c: &Option<Channel>, name: &str| -> Option<ChannelPlan> {
        match c {
            Some(c) => Some(plan_channel(c)),
            None => {
                bad(
                    ch_path.key(name),
                    format!(
                        "the log needs a `{name}` channel (set [channels.{name}] or this run's channels.{name})"
                    ),
                );
                None
            }
        }
    };
    let command = need(&merged.command, "command");
    let displacement = need(&merged.displacement, "displacement");
    let time = match &merged.time {
        Some(t) => match (&t.column, t.sample_rate_hz) {
            (Some(c), _) => TimePlan::Column {
                column: c.clone(),
                to_s: t.unit.unwrap_or(TimeUnit::Second).to_si(),
            },
            (None, Some(hz)) => TimePlan::SampleRate { hz },
            (None, None) => TimePlan::FromLog,
        },
        None => {
            if matches!(format, Some(LogFormat::DaqText | LogFormat::Mat)) {
                TimePlan::FromLog
            } else {
                bad(
                    ch_path.key("time"),
                    "the log needs a time base: [channels.time] with `column` or `sample_rate_hz`"
                        .into(),
                );
                ok = false;
                TimePlan::FromLog
            }
        }
    };
    let channels = Channels {
        time,
        command: command?,
        displacement: displacement?,
        force: merged.force.as_ref().map(plan_channel),
    };
    ok.then(|| {
        RunSource::Log(Box::new(LogPlan {
            path,
            format: format.expect("checked above"),
            csv,
            sha256: data.sha256.as_ref().map(|s| s.to_ascii_lowercase()),
            channels,
        }))
    })
}

fn check_reference(
    r: &Reference,
    base: &KeyPath,
    runs: &BTreeMap<&str, (Role, bool)>,
    bad: &mut impl FnMut(KeyPath, String),
) -> Option<ReferencePlan> {
    let qpath = base.key("quantity");
    if !(r.published.is_finite() && r.published != 0.0) {
        bad(
            base.key("published"),
            "must be a finite, non-zero number (differences are relative to it)".into(),
        );
    }
    if !(r.tolerance_pct.is_finite() && r.tolerance_pct > 0.0) {
        bad(
            base.key("tolerance_pct"),
            format!("must be positive (got {})", r.tolerance_pct),
        );
    }
    let parts: Vec<&str> = r.quantity.split('.').collect();
    let pick = |list: &[&str], name: &str| list.contains(&name);
    let run_must = |run: &str, bad: &mut dyn FnMut(KeyPath, String)| -> Option<(Role, bool)> {
        let found = runs.get(run).copied();
        if found.is_none() {
            bad(
                qpath.clone(),
                format!(
                    "`{}` names run `{run}`, which the campaign does not have",
                    r.quantity
                ),
            );
        }
        found
    };
    let q = match parts.as_slice() {
        ["rig", name] if pick(RIG_QUANTITIES, name) => Some(Quantity::Rig(name.to_string())),
        ["per_spring", run, name] if pick(SPRING_QUANTITIES, name) => match run_must(run, bad) {
            Some((Role::Spring, _)) => Some(Quantity::PerSpring {
                run: run.to_string(),
                name: name.to_string(),
            }),
            Some(_) => {
                bad(qpath.clone(), format!("run `{run}` is not a spring run"));
                None
            }
            None => None,
        },
        ["runs", run, name] if pick(RUN_QUANTITIES, name) => {
            run_must(run, bad).map(|_| Quantity::Run {
                run: run.to_string(),
                name: name.to_string(),
            })
        }
        ["ccf", run, name] if pick(CCF_QUANTITIES, name) => match run_must(run, bad) {
            Some((_, true)) => Some(Quantity::Ccf {
                run: run.to_string(),
                name: name.to_string(),
            }),
            Some(_) => {
                bad(
                    qpath.clone(),
                    format!(
                        "run `{run}` has no specimen mass, so it has no controllable canonical form (Eq. 35 divides by m)"
                    ),
                );
                None
            }
            None => None,
        },
        _ => {
            bad(
                qpath.clone(),
                format!(
                    "unknown quantity `{}`; use rig.{{{}}}, per_spring.<run>.{{{}}}, runs.<run>.{{{}}} or ccf.<run>.{{{}}}",
                    r.quantity,
                    RIG_QUANTITIES.join(","),
                    SPRING_QUANTITIES.join(","),
                    RUN_QUANTITIES.join(","),
                    CCF_QUANTITIES.join(",")
                ),
            );
            None
        }
    };
    Some(ReferencePlan {
        quantity: q?,
        published: r.published,
        source: r.source.clone(),
        compare: r.compare,
        tolerance_pct: r.tolerance_pct,
    })
}
