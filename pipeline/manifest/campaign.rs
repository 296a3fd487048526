//! From the campaign manifest as written to a [`Campaign`] whose every value
//! is usable: positive masses, stiffnesses and gains, specimens that fit their
//! runs' roles, transfer functions that are proper, logs that exist,
//! references that name quantities the campaign computes. Every problem is
//! collected, with its key path, run and line. The runs of a `[run_table]`
//! (checked in `table`) follow those of `[[runs]]`.

use crate::warning::Warning;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use super::checks::{
    P_GAIN_RANGE, check_band, check_channels, check_date, check_nameplate, check_slug,
    check_specimen, plausible, positive,
};
use super::document::{Document, read};
use super::identification::check_identification;
use super::keypath::KeyPath;
use super::problem::{ManifestError, Problem, TablePlace};
use super::raw::{
    CampaignInfo, Channel, Channels as RawChannels, CompareMode, CompensatorSettings,
    DesignSettings, FigureFormats, History, Identification, JointSettings, Limits, Manifest,
    MonteCarloSettings, NumberedFigure, Reference, ReportSettings, Rig, Role, Run, RunData,
    RunTable, SCHEMA_VERSION, SensitivitySettings, manifest_schema,
};
use super::table::{CheckedTable, RowKey, RunTableInfo, TableRun, check_table};
use crate::drift::{MIN_HISTORY, Rule};
use crate::identify::IdentificationPlan;
use crate::ingest::{self, ChannelPlan, Channels, LogFormat, LogPlan, TimePlan};
use crate::lti::{LtiError, TransferFunction};
use crate::model::RigParams;
use crate::model::SpecimenModel;
use crate::units::TimeUnit;

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
    /// The `[[runs]]` runs, then the run table's in table order.
    pub runs: Vec<RunPlan>,
    pub references: Vec<ReferencePlan>,
    /// The manifest as read, echoed into results for provenance.
    pub manifest: Manifest,
    /// The run table's file, hash and rows, when the manifest names one.
    pub run_table: Option<RunTableInfo>,
    /// What is odd but not wrong (a log the run table's `logs` matched that
    /// no run uses); each names its file.
    pub warnings: Vec<Warning>,
    /// Where the rig's history is kept and when it raises an alarm.
    pub history: HistoryPlan,
    /// The stiffness sensitivity's sweep and target.
    pub sensitivity: SensitivityPlan,
    /// The compensator designed for each validation run.
    pub compensator: CompensatorSettings,
    /// The joint grey-box fit's settings (`[identification.joint]`): kept
    /// apart from `identification` so that changing them does not redo the
    /// runs' own fits.
    pub joint: JointSettings,
}

/// The stiffness sensitivity's checked settings.
#[derive(Debug, Clone, PartialEq)]
pub struct SensitivityPlan {
    pub range: StiffnessRange,
    pub points: usize,
    pub target_rel_std: f64,
    /// None: no Monte Carlo.
    pub monte_carlo: Option<MonteCarloSettings>,
}

/// The specimen stiffnesses the sensitivity sweeps (Sec. 2.3), which each
/// validation run's compensator is designed over too.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StiffnessRange {
    /// The manifest's `sensitivity.stiffness_range_n_per_m` (N/m).
    Given(f64, f64),
    /// From 0.01 to 10 times the identified rig's a2: the paper's springs
    /// sit near 0.1 a2, and the rig's response to the specimen changes
    /// most about a2 (Eq. 19).
    OfA2,
}

impl StiffnessRange {
    /// The range in N/m for a rig of `a2_n_per_m` (N/m).
    pub fn n_per_m(self, a2_n_per_m: f64) -> (f64, f64) {
        match self {
            StiffnessRange::Given(lo, hi) => (lo, hi),
            StiffnessRange::OfA2 => (0.01 * a2_n_per_m, 10.0 * a2_n_per_m),
        }
    }
}

/// The rig history's checked settings.
#[derive(Debug, Clone, PartialEq)]
pub struct HistoryPlan {
    /// The table, resolved against the manifest's folder; None keeps it in
    /// the output folder.
    pub file: Option<PathBuf>,
    pub rule: Rule,
}

impl Campaign {
    /// The figures the manifest asks for (`report.figures`), else the
    /// summary's, or every figure for a publication's campaign (one that
    /// numbers its figures): those numbers copy figures the summary leaves
    /// out, and a paper's reader wants SVG.
    pub fn figures(&self) -> FigureFormats {
        let asked = self.manifest.report.as_ref().and_then(|r| r.figures);
        asked.unwrap_or(match self.manifest.numbered_figures.is_empty() {
            true => FigureFormats::Summary,
            false => FigureFormats::All,
        })
    }

    /// Give `date` (normalised by [`crate::manifest::normalise_date`]) to every run the
    /// manifest and run table leave undated: the night a job records, for
    /// a nightly manifest that is the same every night. A run's own date
    /// stays.
    pub fn date_undated_runs(&mut self, date: &str) {
        for run in self.runs.iter_mut().filter(|r| r.date.is_none()) {
            run.date = Some(date.to_string());
        }
    }

    /// Whether the campaign can identify the rig itself (Fig. 6, steps 3-5).
    pub fn identifies_rig(&self) -> bool {
        self.runs.iter().any(|r| r.role == Role::NoSpecimen)
            && self.runs.iter().any(|r| r.role == Role::Spring)
    }
}

/// A checked run.
#[derive(Debug, Clone)]
pub struct RunPlan {
    /// Position among the campaign's runs, `[[runs]]` first, then the run
    /// table's rows (results keep this order).
    pub index: usize,
    pub id: String,
    pub role: Role,
    pub description: String,
    /// When the run was made: ISO 8601 (`YYYY-MM-DD` or
    /// `YYYY-MM-DDTHH:MM:SS`, optionally ending in `Z`), normalised.
    pub date: Option<String>,
    pub p_gain: f64,
    /// The specimen as the simulator models it, linear or not.
    pub specimen: SpecimenModel,
    pub source: RunSource,
    pub band_hz: (f64, f64),
    /// A run table row's cells in the lab's own columns (a `notes`, an
    /// `operator`), by column: carried to results.json and the run's page.
    pub annotations: std::collections::BTreeMap<String, String>,
}

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

/// Read and check a campaign manifest file (`.json` is read as JSON,
/// anything else as TOML).
pub fn load(path: &Path) -> Result<Campaign, ManifestError> {
    let text = read(path)?;
    load_str(&text, path)
}

/// Check campaign-manifest text as if read from `path` (relative log paths
/// resolve against `path`'s folder).
pub fn load_str(text: &str, path: &Path) -> Result<Campaign, ManifestError> {
    let mut doc = Document::parse(text, path, manifest_schema())?;
    doc.check_top_level();
    // Each section, and each run and reference on its own, so that a type
    // error in one does not hide the problems in the others.
    let partial = Partial {
        schema_version: doc.section("schema_version"),
        campaign: doc.section::<CampaignInfo>("campaign"),
        rig: doc.section::<Rig>("rig"),
        channels: doc.section::<RawChannels>("channels"),
        identification: doc.section::<Identification>("identification"),
        runs: doc.array::<Run>("runs"),
        raw_run_ids: doc.raw("runs", "id"),
        raw_run_roles: doc.raw("runs", "role"),
        references: doc.array::<Reference>("references"),
        run_table: doc.section::<RunTable>("run_table"),
        run_table_given: doc.has("run_table"),
        history: doc.section::<History>("history"),
        sensitivity: doc.section::<SensitivitySettings>("sensitivity"),
        compensator: doc.section::<CompensatorSettings>("compensator"),
        limits: doc.section::<Limits>("limits"),
        report: doc.section::<ReportSettings>("report"),
        design: doc.section::<DesignSettings>("design"),
        numbered_figures: doc.array::<NumberedFigure>("numbered_figures"),
    };
    doc.begin_checks();
    let base_dir = path.parent().unwrap_or(Path::new(""));
    let campaign = validate(partial, path, text.as_bytes(), base_dir, &mut doc.problems);
    doc.finish(campaign)
}

/// The sections that deserialized (a failed section is `None`; its problem is
/// already recorded).
#[derive(Debug, Default)]
struct Partial {
    schema_version: Option<u32>,
    campaign: Option<CampaignInfo>,
    rig: Option<Rig>,
    channels: Option<RawChannels>,
    identification: Option<Identification>,
    runs: Vec<Option<Run>>,
    /// Ids and roles read straight from the document, so cross-run checks
    /// still see a run whose other keys failed to deserialize.
    raw_run_ids: Vec<Option<String>>,
    raw_run_roles: Vec<Option<Role>>,
    references: Vec<Option<Reference>>,
    run_table: Option<RunTable>,
    /// Whether the manifest has a `run_table` section, read or not.
    run_table_given: bool,
    history: Option<History>,
    sensitivity: Option<SensitivitySettings>,
    compensator: Option<CompensatorSettings>,
    limits: Option<Limits>,
    report: Option<ReportSettings>,
    design: Option<DesignSettings>,
    numbered_figures: Vec<Option<NumberedFigure>>,
}

/// What every run's checks share.
struct RunContext<'a> {
    default_channels: &'a RawChannels,
    ident: &'a IdentificationPlan,
    base_dir: &'a Path,
    /// `[limits] max_log_mib` in bytes.
    max_log_bytes: u64,
}

/// Every check of the sections, the runs and what ties them together; the
/// campaign when none found a problem.
fn validate(
    partial: Partial,
    file: &Path,
    bytes: &[u8],
    base_dir: &Path,
    problems: &mut Vec<Problem>,
) -> Option<Campaign> {
    // The run table first: its problems name the table, not a key.
    let table = match &partial.run_table {
        Some(spec) => check_table(spec, base_dir, &run_logs(&partial.runs, base_dir), problems),
        None => CheckedTable::default(),
    };
    let root = KeyPath::root();
    let mut bad = |path: KeyPath, msg: String| problems.push(Problem::new(path, msg));

    check_header(&partial, &mut bad);
    let history = check_history(partial.history.as_ref(), base_dir, &mut bad);
    let sensitivity = check_sensitivity(partial.sensitivity.as_ref(), &mut bad);
    let compensator = check_compensator(partial.compensator.as_ref(), &mut bad);
    check_design(partial.design.as_ref(), &mut bad);
    check_numbered_figures(&partial.numbered_figures, &mut bad);
    let channels = partial.channels.clone().unwrap_or_default();
    check_channels(&channels, &root.key("channels"), &mut bad);
    let identification = partial.identification.clone().unwrap_or_default();
    let ident_plan = check_identification(&identification, &root.key("identification"), &mut bad);

    // A run table that failed to read is already a problem: not also "no runs".
    let table_unread = partial.run_table_given && table.info.is_none();
    let mut table_problems = Vec::new();
    check_run_ids(
        &partial,
        &table.keys,
        table_unread,
        &mut bad,
        &mut table_problems,
    );
    let ctx = RunContext {
        default_channels: &channels,
        ident: &ident_plan,
        base_dir,
        max_log_bytes: check_limits(partial.limits.as_ref(), &mut bad),
    };
    let runs = check_runs(&partial.runs, &table.runs, &ctx, &mut bad);
    let given_rig = partial.rig.as_ref().and_then(|r| r.parameters);
    let references = check_across_runs(&partial, &table.keys, given_rig.is_some(), &mut bad);
    problems.extend(table_problems);

    if !problems.is_empty() {
        return None;
    }
    let checked = Checked {
        channels,
        identification,
        ident_plan,
        given_rig,
        runs,
        references,
        table,
        history,
        sensitivity,
        compensator,
    };
    campaign_of(partial, checked, file, bytes)
}

/// `[limits]`: at least one MiB a log. Returns `max_log_mib` in bytes.
fn check_limits(limits: Option<&Limits>, bad: &mut impl FnMut(KeyPath, String)) -> u64 {
    let limits = limits.cloned().unwrap_or_default();
    if limits.max_log_mib == 0 {
        bad(
            KeyPath::root().key("limits").key("max_log_mib"),
            "must be at least 1 (MiB)".into(),
        );
    }
    limits.max_log_mib.saturating_mul(1 << 20)
}

/// Each run's plan: the `[[runs]]` that read, then the run table's rows
/// that passed their checks, numbered after them.
fn check_runs(
    runs: &[Option<Run>],
    table_runs: &[TableRun],
    ctx: &RunContext<'_>,
    bad: &mut impl FnMut(KeyPath, String),
) -> Vec<RunPlan> {
    let root = KeyPath::root();
    let mut plans: Vec<RunPlan> = runs
        .iter()
        .enumerate()
        .filter_map(|(i, run)| {
            let run = run.as_ref()?;
            check_run(run, i, &root.key("runs").index(i), ctx, bad)
        })
        .collect();
    let first = runs.len();
    plans.extend(
        table_runs
            .iter()
            .enumerate()
            .filter_map(|(k, t)| table_run_plan(t, first + k, ctx, bad)),
    );
    plans
}

/// What the runs together must give: the rig's source, and a run of the
/// right kind for each reference. Returns the references' plans.
fn check_across_runs(
    partial: &Partial,
    rows: &[RowKey],
    given_rig: bool,
    bad: &mut impl FnMut(KeyPath, String),
) -> Vec<ReferencePlan> {
    let roles: Vec<Option<Role>> = (partial.raw_run_roles.iter().copied())
        .chain(rows.iter().map(|k| k.role))
        .collect();
    check_rig_source(&roles, given_rig, bad);
    // Runs listed but unread (a type error in them, already a problem):
    // a reference to one is not also "a run the campaign does not have".
    let listed: BTreeSet<&str> = partial
        .raw_run_ids
        .iter()
        .flatten()
        .map(String::as_str)
        .collect();
    check_references(
        &run_roles(&partial.runs, rows),
        &listed,
        &partial.references,
        bad,
    )
}

/// What the checks made of the sections, kept for the campaign.
struct Checked {
    /// The default channels, as the manifest gives them.
    channels: RawChannels,
    identification: Identification,
    ident_plan: IdentificationPlan,
    given_rig: Option<RigParams>,
    runs: Vec<RunPlan>,
    references: Vec<ReferencePlan>,
    table: CheckedTable,
    history: HistoryPlan,
    sensitivity: SensitivityPlan,
    compensator: CompensatorSettings,
}

/// The campaign from sections that passed every check; None when a
/// required section is missing (its problem is already recorded).
fn campaign_of(partial: Partial, checked: Checked, file: &Path, bytes: &[u8]) -> Option<Campaign> {
    let campaign = partial.campaign?;
    let rig = partial.rig?;
    let ident = checked.identification;
    let manifest = Manifest {
        schema_version: partial.schema_version?,
        campaign: campaign.clone(),
        rig: rig.clone(),
        channels: checked.channels,
        identification: ident.clone(),
        runs: partial.runs.into_iter().flatten().collect(),
        references: partial.references.into_iter().flatten().collect(),
        run_table: partial.run_table,
        history: partial.history,
        sensitivity: partial.sensitivity,
        compensator: partial.compensator,
        limits: partial.limits,
        report: partial.report,
        design: partial.design,
        numbered_figures: partial.numbered_figures.into_iter().flatten().collect(),
    };
    let cutoff_warning = cutoff_below_band(&checked.compensator, checked.ident_plan.band_hz);
    Some(Campaign {
        file: file.to_path_buf(),
        manifest_sha256: ingest::sha256_hex(bytes),
        name: campaign.name,
        description: campaign.description,
        rig_name: rig.name,
        rig_notes: rig.notes,
        given_rig: checked.given_rig,
        identification: checked.ident_plan,
        runs: checked.runs,
        references: checked.references,
        manifest,
        run_table: checked.table.info,
        warnings: checked
            .table
            .warnings
            .into_iter()
            .chain(cutoff_warning)
            .collect(),
        history: checked.history,
        sensitivity: checked.sensitivity,
        compensator: checked.compensator,
        joint: ident.joint,
    })
}

/// `[[numbered_figures]]`: each number digits and an optional letter, once;
/// each with a figure or the reason it has none, not both; a figure named
/// as its file's stem (lowercase letters, digits and `-`).
pub(super) fn check_numbered_figures(
    figures: &[Option<NumberedFigure>],
    bad: &mut impl FnMut(KeyPath, String),
) {
    let mut seen: Vec<&str> = Vec::new();
    for (i, f) in figures.iter().enumerate() {
        let Some(f) = f else { continue };
        let path = KeyPath::root().key("numbered_figures").index(i);
        let digits = f.number.chars().take_while(char::is_ascii_digit).count();
        let rest = &f.number[digits..];
        if digits == 0 || rest.len() > 1 || !rest.chars().all(|c| c.is_ascii_lowercase()) {
            bad(
                path.key("number"),
                format!(
                    "must be digits and an optional lowercase letter (`8`, `16a`; got {:?})",
                    f.number
                ),
            );
        } else if seen.contains(&f.number.as_str()) {
            bad(path.key("number"), format!("{} is given twice", f.number));
        }
        seen.push(&f.number);
        match (&f.figure, &f.not_drawn) {
            (Some(id), None) => {
                if id.is_empty()
                    || !id
                        .chars()
                        .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-')
                {
                    bad(
                        path.key("figure"),
                        format!(
                            "must be a figure's file stem under figures/ (`frf-no-specimen`; got {id:?})"
                        ),
                    );
                }
            }
            (None, Some(_)) => {}
            _ => bad(
                path,
                "give `figure` (the campaign's figure that stands for it) or `not_drawn` (why none does), one of them".into(),
            ),
        }
    }
}

/// The sensitivity's settings: a range 0 < low < high, at least two
/// points, a positive target.
pub(super) fn check_sensitivity(
    s: Option<&SensitivitySettings>,
    bad: &mut impl FnMut(KeyPath, String),
) -> SensitivityPlan {
    let s = s.cloned().unwrap_or_default();
    let path = KeyPath::root().key("sensitivity");
    if let Some([lo, hi]) = s.stiffness_range_n_per_m
        && !(lo.is_finite() && hi.is_finite() && lo > 0.0 && hi > lo)
    {
        bad(
            path.key("stiffness_range_n_per_m"),
            format!("must be two stiffnesses 0 < low < high in N/m (got [{lo}, {hi}])"),
        );
    }
    if s.points < 2 {
        bad(
            path.key("points"),
            format!(
                "must be at least 2 (a sweep needs two stiffnesses; got {})",
                s.points
            ),
        );
    }
    if !(s.target_rel_std.is_finite() && s.target_rel_std > 0.0) {
        bad(
            path.key("target_rel_std"),
            format!(
                "must be a positive fraction, 0.01 for 1 % (got {})",
                s.target_rel_std
            ),
        );
    }
    if let Some(mc) = &s.monte_carlo {
        let path = path.key("monte_carlo");
        if mc.points < 2 {
            bad(
                path.key("points"),
                format!(
                    "must be at least 2 (the Monte Carlo needs two stiffnesses; got {})",
                    mc.points
                ),
            );
        }
        if mc.seeds == 0 {
            bad(
                path.key("seeds"),
                "must be at least 1 (the identifications per stiffness; 50 gives each std to about 10 %); got 0".into(),
            );
        }
    }
    SensitivityPlan {
        range: s
            .stiffness_range_n_per_m
            .map_or(StiffnessRange::OfA2, |[lo, hi]| {
                StiffnessRange::Given(lo, hi)
            }),
        points: s.points,
        target_rel_std: s.target_rel_std,
        monte_carlo: s.monte_carlo,
    }
}

/// The compensator's settings: a positive, finite cut-off when given (each
/// log's rate bounds it further, run by run).
fn check_compensator(
    c: Option<&CompensatorSettings>,
    bad: &mut impl FnMut(KeyPath, String),
) -> CompensatorSettings {
    let c = c.cloned().unwrap_or_default();
    if let Some(fc) = c.cutoff_hz
        && !(fc.is_finite() && fc > 0.0)
    {
        bad(
            KeyPath::root().key("compensator").key("cutoff_hz"),
            format!("must be a positive frequency in Hz (got {fc})"),
        );
    }
    c
}

/// `[design]`: every limit and time positive, the band rising from
/// above 0.
fn check_design(d: Option<&DesignSettings>, bad: &mut impl FnMut(KeyPath, String)) {
    let Some(d) = d else {
        return;
    };
    let key = |k: &str| KeyPath::root().key("design").key(k);
    for (name, v) in [
        ("command_m", d.command_m),
        ("stroke_m", d.stroke_m),
        ("velocity_m_per_s", d.velocity_m_per_s),
        ("force_n", d.force_n),
        ("run_s", d.run_s),
        ("night_s", d.night_s),
        ("target_relative_std", d.target_relative_std),
        ("sample_rate_hz", d.sample_rate_hz),
        ("displacement_noise_m", d.displacement_noise_m),
    ] {
        if let Some(v) = v
            && !(v.is_finite() && v > 0.0)
        {
            bad(key(name), format!("must be a positive number (got {v})"));
        }
    }
    if let Some([lo, hi]) = d.band_hz
        && !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo < hi)
    {
        bad(
            key("band_hz"),
            format!("must be [low, high] with 0 < low < high (got [{lo}, {hi}])"),
        );
    }
}

/// A stated cut-off below the identification band's top: the
/// compensator's low-pass then removes the band it is to track, and its
/// design succeeds all the same.
fn cutoff_below_band(c: &CompensatorSettings, band_hz: (f64, f64)) -> Option<Warning> {
    let fc = c.cutoff_hz.filter(|&fc| fc < band_hz.1)?;
    let headline = format!(
        "compensator.cutoff_hz = {fc} Hz is below the band's top ({} Hz)",
        band_hz.1
    );
    Some(Warning::new(
        headline,
        format!(
            "compensator.cutoff_hz = {fc} Hz is below the identification band's top ({} Hz): the compensator's low-pass removes the band it is to track. Leave it out for {} times the band's top",
            band_hz.1,
            crate::tracking::compensator::CUTOFF_PER_BAND
        ),
    ))
}

/// The history's settings: a window the rule can use and a positive
/// threshold.
fn check_history(
    h: Option<&History>,
    base_dir: &Path,
    bad: &mut impl FnMut(KeyPath, String),
) -> HistoryPlan {
    let h = h.cloned().unwrap_or_default();
    let path = KeyPath::root().key("history");
    if h.window < MIN_HISTORY {
        bad(
            path.key("window"),
            format!(
                "must be at least {MIN_HISTORY} (the median of fewer entries says little; got {})",
                h.window
            ),
        );
    }
    positive(h.threshold, &path.key("threshold"), bad);
    if let Some(f) = &h.file {
        if f.trim().is_empty() {
            bad(path.key("file"), "must not be empty".into());
        } else if let Some(why) = not_a_file_path(&base_dir.join(f), f) {
            // /dev/null, `.` or a folder took every night's entry without
            // a word, and the drift alarm was off for good.
            bad(path.key("file"), why);
        }
    }
    HistoryPlan {
        file: h.file.as_ref().map(|f| base_dir.join(f)),
        rule: Rule {
            window: h.window,
            threshold: h.threshold,
        },
    }
}

/// Why `path` (given as `given`) cannot hold the rig history: a name that
/// is a folder's (`.`, `..`, a trailing `/`), or something that exists and
/// is not a regular file (a folder, /dev/null). None when it is, or is yet
/// to be, a regular file.
fn not_a_file_path(path: &Path, given: &str) -> Option<String> {
    use std::path::Component;
    let names_a_folder = given.ends_with('/')
        || !matches!(
            Path::new(given).components().next_back(),
            Some(Component::Normal(_))
        );
    if names_a_folder {
        return Some(format!(
            "`{given}` names a folder: give the history's file, such as `{}history.parquet`",
            if given.ends_with('/') {
                given.to_string()
            } else {
                format!("{given}/")
            }
        ));
    }
    match std::fs::metadata(path) {
        Ok(m) if m.is_dir() => Some(format!(
            "`{given}` is a folder: give the history's file, such as `{given}/history.parquet`"
        )),
        Ok(m) if !m.is_file() => Some(format!(
            "`{given}` is not a regular file (a device or a pipe takes every entry and gives none back): give a file path, such as `history.parquet`"
        )),
        _ => None,
    }
}

/// The logs the `[[runs]]` name, as paths from the manifest's folder.
fn run_logs(runs: &[Option<Run>], base_dir: &Path) -> Vec<PathBuf> {
    runs.iter()
        .flatten()
        .filter_map(|r| r.data.as_ref()?.log.as_ref())
        .map(|log| base_dir.join(log))
        .collect()
}

/// Each run's role and whether it has a specimen mass, by id, from
/// `[[runs]]` and the run table alike: what references may name.
fn run_roles<'a>(runs: &'a [Option<Run>], rows: &'a [RowKey]) -> BTreeMap<&'a str, (Role, bool)> {
    let listed = runs.iter().flatten().map(|r| {
        let has_mass = r.specimen.as_ref().is_some_and(|s| s.mass_kg.is_some());
        (r.id.as_str(), (r.role, has_mass))
    });
    let tabled = rows
        .iter()
        .filter_map(|k| Some((k.id.as_deref()?, (k.role?, k.has_mass))));
    listed.chain(tabled).collect()
}

/// A run of the run table as the stages run it: the campaign's channels and
/// identification settings, its log read as its extension says.
fn table_run_plan(
    t: &TableRun,
    index: usize,
    ctx: &RunContext<'_>,
    bad: &mut impl FnMut(KeyPath, String),
) -> Option<RunPlan> {
    let source = match &t.log {
        None => RunSource::None,
        Some((path, format)) => {
            let ch_path = KeyPath::root().key("channels");
            let channels =
                plan_channels(ctx.default_channels, Some(*format), &ch_path, false, bad)?;
            RunSource::Log(Box::new(LogPlan {
                path: path.clone(),
                format: *format,
                csv: Default::default(),
                sha256: None,
                channels,
                max_bytes: ctx.max_log_bytes,
            }))
        }
    };
    Some(RunPlan {
        index,
        id: t.id.clone(),
        role: t.role,
        description: t.description.clone(),
        date: t.date.clone(),
        p_gain: t.p_gain,
        specimen: t.specimen,
        source,
        band_hz: ctx.ident.band_hz,
        annotations: t.annotations.clone(),
    })
}

/// The format version, the campaign's name and the rig.
fn check_header(partial: &Partial, bad: &mut impl FnMut(KeyPath, String)) {
    let root = KeyPath::root();
    if let Some(v) = partial.schema_version
        && v != SCHEMA_VERSION
    {
        bad(
            root.key("schema_version"),
            format!("unsupported schema_version {v}; this servoid reads {SCHEMA_VERSION}"),
        );
    }
    if let Some(c) = &partial.campaign {
        check_slug(&c.name, &root.key("campaign").key("name"), bad);
    }
    if let Some(rig) = &partial.rig {
        if rig.name.trim().is_empty() {
            bad(root.key("rig").key("name"), "must not be empty".into());
        }
        check_nameplate(
            rig.supply_pressure_pa,
            rig.piston_area_m2,
            &root.key("rig"),
            bad,
        );
        if let Some(p) = &rig.parameters {
            let base = root.key("rig").key("parameters");
            for (k, v) in [
                ("beta1_per_s", p.beta1_per_s),
                ("a1b0_n_per_m_s2", p.a1b0_n_per_m_s2),
                ("a2_n_per_m", p.a2_n_per_m),
                ("a3_per_s", p.a3_per_s),
                ("p_gain", p.p_gain),
            ] {
                positive(v, &base.key(k), bad);
            }
        }
    }
}

/// Run ids are unique across `[[runs]]` and the run table, also when
/// letter case is ignored (`K1` and `k1` name one file on a
/// case-insensitive disk), and the campaign has runs. A duplicate in the table is a problem of its row (in
/// `table_problems`), naming where the id was first used.
fn check_run_ids(
    partial: &Partial,
    rows: &[RowKey],
    table_unread: bool,
    bad: &mut impl FnMut(KeyPath, String),
    table_problems: &mut Vec<Problem>,
) {
    let root = KeyPath::root();
    if partial.runs.is_empty() && partial.raw_run_ids.is_empty() && rows.is_empty() && !table_unread
    {
        bad(
            root.key("runs"),
            "the campaign has no runs: give [[runs]] tables or a [run_table] with rows".into(),
        );
    }
    // By the id in lower case: the id as first written, and where.
    let mut first_seen: BTreeMap<String, (&str, String)> = BTreeMap::new();
    let clash = |id: &str, (first_id, first): &(&str, String)| {
        if id == *first_id {
            format!("duplicate run id `{id}` (first used by {first})")
        } else {
            format!(
                "run id `{id}` differs from `{first_id}` (used by {first}) only in letter case: on a case-insensitive disk (macOS, Windows) their files would be one; rename one"
            )
        }
    };
    for (i, id) in partial.raw_run_ids.iter().enumerate() {
        if let Some(id) = id {
            if let Some(first) = first_seen.get(&id.to_ascii_lowercase()) {
                bad(root.key("runs").index(i).key("id"), clash(id, first));
            } else {
                first_seen.insert(id.to_ascii_lowercase(), (id, format!("runs[{i}]")));
            }
        }
    }
    let file = partial.run_table.as_ref().map_or("", |t| t.file.as_str());
    for key in rows {
        let Some(id) = key.id.as_deref() else {
            continue;
        };
        if let Some(first) = first_seen.get(&id.to_ascii_lowercase()) {
            let place = TablePlace {
                file: file.to_string(),
                row: Some(key.row),
                column: Some("id".into()),
            };
            table_problems.push(Problem::in_table(
                place,
                Some(id.to_string()),
                clash(id, first),
            ));
        } else {
            first_seen.insert(
                id.to_ascii_lowercase(),
                (id, format!("row {} of {file}", key.row)),
            );
        }
    }
}

/// A campaign with validation runs needs the rig: given, or identified from
/// a no-specimen run and springs (Eqs. 18-20).
fn check_rig_source(
    raw_roles: &[Option<Role>],
    given_rig: bool,
    bad: &mut impl FnMut(KeyPath, String),
) {
    let root = KeyPath::root();
    let roles: Vec<Role> = raw_roles.iter().flatten().copied().collect();
    let has_ns = roles.contains(&Role::NoSpecimen);
    let has_spring = roles.contains(&Role::Spring);
    if roles.contains(&Role::Validation) && !given_rig && !(has_ns && has_spring) {
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
    if has_spring && !has_ns && !given_rig {
        bad(
            root.key("runs"),
            "spring runs need a no_specimen run (beta1 and R1, Eq. 18) to identify the rig".into(),
        );
    }
}

fn check_run(
    run: &Run,
    index: usize,
    base: &KeyPath,
    ctx: &RunContext<'_>,
    bad: &mut impl FnMut(KeyPath, String),
) -> Option<RunPlan> {
    check_slug(&run.id, &base.key("id"), bad);
    let p_ok = positive(run.p_gain, &base.key("p_gain"), bad)
        && plausible(run.p_gain, P_GAIN_RANGE, &base.key("p_gain"), bad);
    let specimen = check_specimen(run.role, run.specimen.as_ref(), &base.key("specimen"), bad);
    if let Some(b) = run.band_hz {
        check_band(b, &base.key("band_hz"), bad);
    }
    if let Some(ch) = &run.channels {
        check_channels(ch, &base.key("channels"), bad);
    }
    let source = check_source(run, base, ctx, bad);
    let date = run
        .date
        .as_ref()
        .map(|d| check_date(d, &base.key("date"), bad));
    let band = run
        .band_hz
        .unwrap_or([ctx.ident.band_hz.0, ctx.ident.band_hz.1]);
    Some(RunPlan {
        index,
        id: run.id.clone(),
        role: run.role,
        description: run.description.clone(),
        date: date.flatten(),
        p_gain: run.p_gain,
        specimen: specimen?,
        source: source?,
        band_hz: (band[0], band[1]),
        annotations: Default::default(),
    })
    .filter(|_| p_ok)
}

/// A run's data: nothing (a prediction), a published transfer function or a
/// log, as its role allows.
fn check_source(
    run: &Run,
    base: &KeyPath,
    ctx: &RunContext<'_>,
    bad: &mut impl FnMut(KeyPath, String),
) -> Option<RunSource> {
    let identification_role = matches!(run.role, Role::NoSpecimen | Role::Spring);
    let data = run.data.clone().unwrap_or_default();
    let dpath = base.key("data");
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
    match (&data.log, &data.transfer_function) {
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
        (None, Some(tf)) => check_published(run.role, tf, &dpath.key("transfer_function"), bad),
        (Some(log), None) => check_log(log, &data, run, base, ctx, bad),
    }
}

/// A published transfer function: proper, and second order where the
/// paper's procedure needs it.
fn check_published(
    role: Role,
    tf: &super::raw::PublishedTf,
    tpath: &KeyPath,
    bad: &mut impl FnMut(KeyPath, String),
) -> Option<RunSource> {
    let t = match TransferFunction::with_delay(&tf.num, &tf.den, tf.delay_s) {
        Ok(t) => t,
        Err(e) => {
            let key = match e {
                LtiError::BadDelay(_) => "delay_s",
                LtiError::EmptyNumerator => "num",
                LtiError::NonFinite {
                    which: "numerator", ..
                } => "num",
                _ => "den",
            };
            bad(tpath.key(key), e.to_string());
            return None;
        }
    };
    if matches!(role, Role::NoSpecimen | Role::Spring) && (t.num.len() != 1 || t.den.len() != 3) {
        bad(
            tpath.clone(),
            format!(
                "the paper's procedure needs a second-order model n0/(s^2 + d1 s + d0); got numerator degree {} and denominator degree {}",
                t.num.len() - 1,
                t.den.len() - 1
            ),
        );
        None
    } else if role == Role::Validation {
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

/// A run's log: the file exists, its format is known, its CSV options and
/// hash are well formed, and its channels (defaults merged with the run's
/// overrides) are all there, each with its conversion to SI.
fn check_log(
    log: &str,
    data: &RunData,
    run: &Run,
    base: &KeyPath,
    ctx: &RunContext<'_>,
    bad: &mut impl FnMut(KeyPath, String),
) -> Option<RunSource> {
    let dpath = base.key("data");
    let path = ctx.base_dir.join(log);
    let mut ok = true;
    // A log that is not there (yet) fails its run alone when the run reads
    // it, as a run table's rows do: one missing log must not refuse a
    // night's campaign. A folder, device or pipe in its place is a mistake
    // in the manifest.
    if let Ok(m) = std::fs::metadata(&path)
        && !m.is_file()
    {
        let what = if m.is_dir() {
            "the log is a folder, not a file"
        } else {
            "the log is not a regular file (a device, pipe or socket)"
        };
        bad(dpath.key("log"), format!("{what}: {}", path.display()));
        ok = false;
    }
    let format = data.format.or_else(|| LogFormat::from_path(&path));
    // A log that is not there has no format to tell yet: one problem, not two.
    if format.is_none() && ok {
        bad(
            dpath.key("format"),
            format!(
                "cannot tell the format of `{log}` from its extension; give format = \"csv\", \"parquet\", \"mat\", \"daq_text\", \"hdf5\" or \"tdms\""
            ),
        );
        ok = false;
    }
    let csv = data.csv.clone().unwrap_or_default();
    if csv.delimiter.chars().count() != 1 {
        bad(
            dpath.key("csv").key("delimiter"),
            format!("must be one character (got {:?})", csv.delimiter),
        );
        ok = false;
    }
    if csv.decimal != "." && csv.decimal != "," {
        bad(
            dpath.key("csv").key("decimal"),
            format!("must be \".\" or \",\" (got {:?})", csv.decimal),
        );
        ok = false;
    } else if csv.decimal == "," && csv.delimiter == "," {
        bad(
            dpath.key("csv").key("decimal"),
            "a decimal comma needs another field delimiter: give delimiter = \";\" (or the export's own)".into(),
        );
        ok = false;
    }
    if let Some(h) = &data.sha256
        && (h.len() != 64 || !h.chars().all(|c| c.is_ascii_hexdigit()))
    {
        bad(dpath.key("sha256"), "must be 64 hexadecimal digits".into());
        ok = false;
    }
    let merged = merge_channels(ctx.default_channels, run.channels.as_ref());
    let channels = plan_channels(&merged, format, &base.key("channels"), true, bad);
    let (channels, format) = (channels?, format?);
    ok.then(|| {
        RunSource::Log(Box::new(LogPlan {
            path,
            format,
            csv,
            sha256: data.sha256.as_ref().map(|s| s.to_ascii_lowercase()),
            channels,
            max_bytes: ctx.max_log_bytes,
        }))
    })
}

/// The resolved channels of a log: command and displacement are required,
/// and the time base comes from a column, a rate, or (DAQ text, MAT) the
/// log's own header. `per_run` says whether the run may override a channel
/// (a `[[runs]]` run may, a run-table row may not), for the hint.
fn plan_channels(
    merged: &RawChannels,
    format: Option<LogFormat>,
    ch_path: &KeyPath,
    per_run: bool,
    bad: &mut impl FnMut(KeyPath, String),
) -> Option<Channels> {
    let mut need = |c: &Option<Channel>, name: &str| -> Option<ChannelPlan> {
        match c {
            Some(c) => Some(plan_channel(c)),
            None => {
                let hint = if per_run {
                    format!("set [channels.{name}] or this run's channels.{name}")
                } else {
                    format!(
                        "set [channels.{name}]; the run table's runs use the campaign's channels"
                    )
                };
                bad(
                    ch_path.key(name),
                    format!("the log needs a `{name}` channel ({hint})"),
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
        None if matches!(
            format,
            Some(LogFormat::DaqText | LogFormat::Mat | LogFormat::Hdf5 | LogFormat::Tdms)
        ) =>
        {
            TimePlan::FromLog
        }
        None => {
            bad(
                ch_path.key("time"),
                "the log needs a time base: [channels.time] with `column` or `sample_rate_hz`"
                    .into(),
            );
            return None;
        }
    };
    Some(Channels {
        time,
        command: command?,
        displacement: displacement?,
        force: merged.force.as_ref().map(plan_channel),
    })
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

/// A channel's conversion to SI, decided once here and applied at ingest.
fn plan_channel(c: &Channel) -> ChannelPlan {
    let si = c.unit.to_si();
    ChannelPlan {
        column: c.column.clone(),
        unit: c.unit,
        gain: c.scale * si,
        offset: c.offset * si,
        range: c.range.map(|[lo, hi]| (lo * si, hi * si)),
        repair: c.repair,
    }
}

/// Every reference names a quantity the campaign computes; `run_roles` has
/// each run's role and whether it has a specimen mass.
fn check_references(
    run_roles: &BTreeMap<&str, (Role, bool)>,
    listed: &BTreeSet<&str>,
    references: &[Option<Reference>],
    bad: &mut impl FnMut(KeyPath, String),
) -> Vec<ReferencePlan> {
    references
        .iter()
        .enumerate()
        .filter_map(|(i, r)| {
            let base = KeyPath::root().key("references").index(i);
            check_reference(r.as_ref()?, &base, run_roles, listed, bad)
        })
        .collect()
}

fn check_reference(
    r: &Reference,
    base: &KeyPath,
    runs: &BTreeMap<&str, (Role, bool)>,
    listed: &BTreeSet<&str>,
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
        if found.is_none() && !listed.contains(run) {
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
