//! A campaign's analysis in two passes over its runs, each in parallel
//! (results keep the manifest's order, so the output does not depend on the
//! thread count), holding one log per worker at a time:
//!
//! 1. every run that does not need the rig (no-specimen, spring and fit
//!    runs) is read, estimated, fitted and checked in the time domain, its
//!    figures drawn, and its signals dropped; what the rig needs (the fitted
//!    model and covariance) and what its later figure needs (the force FRF's
//!    plotted bins) are kept;
//! 2. the rig is identified from them (Fig. 6, Eqs. 18-20) or taken as
//!    given; then the validation runs are read, predicted and validated,
//!    their figures drawn and their signals dropped, and the other runs get
//!    what depends on the rig (a1b0 at their P gain, the force model and its
//!    figure).
//!
//! Then the canonical forms, outliers, the stiffness sensitivity and the
//! comparisons with published numbers. A failed run is recorded in its
//! result and the batch goes on. Pure apart from ingest reading the logs and
//! the figures going to their files.

use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use rayon::prelude::*;

use super::acquire::fit_options;
use super::acquire::{AcquireError, Acquired, FitData, LogStage, acquire_with};
use super::cache::{self, Cache, Probe};
use super::compare::compare;
use super::figures::{self, ForceBins, OverlayRun};
use super::rig::{self, Evidence, RigError, RigInput, ValidationEvidence};
use super::tables;
use crate::fit::adequacy::{self, Adequacy, Residuals};
use crate::fit::{self, DelayPlan, TfFit};
use crate::frf::{self, Frf};
use crate::ingest::{IngestError, Log};
use crate::manifest::{Campaign, IdentificationPlan, Role, RunPlan, RunSource};
use crate::model::{self, CnTerm, LinearSdof, LinearSpecimen, RigParams};
use crate::report::{FigureFiles, FigureFormats, FigureSpec, PageFigure, WriteError};
use crate::results::{
    CampaignSummary, CcfResult, ComplexValue, DelayTestResult, FitSummary, LogInfo,
    RESULTS_SCHEMA_VERSION, Results, RunResult, Status, TfResult, TfSource,
};
use crate::sensitivity::NoiseProfile;
use crate::simulate::specimen::SpecimenModel;
use crate::validate::csi::Csi;
use crate::validate::{self, Record, ValidateError, ValidationMetrics};

/// Below this fit percent (MATLAB tfest's FitPercent, [`crate::fit::TfFit`])
/// a run's model gets a warning naming the log's mapping.
const POOR_FIT_PERCENT: f64 = 50.0;

/// Why one run failed; recorded in that run's result.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error(transparent)]
    Acquire(#[from] Arc<AcquireError>),
    #[error("the rig parameters are unavailable: {0}")]
    NoRig(Arc<RigError>),
    #[error("time-domain validation: {0}")]
    Validation(#[from] ValidateError),
    /// The rig with the run's specimen and P gain gives a model beyond
    /// f64's range (finite but extreme manifest numbers, issue 24).
    #[error(
        "the model of the rig (beta1 {beta1:.4e} 1/s, a1b0 {a1b0:.4e} N/(m s^2) at p_gain = {p_gain}, a2 {a2:.4e} N/m, a3 {a3:.4e} 1/s) with the specimen (mass_kg = {m}, damping_ns_per_m = {c}, stiffness_n_per_m = {k}) leaves f64's range ({source}): check this run's specimen and p_gain, and the identification runs' published or measured data"
    )]
    Model {
        beta1: f64,
        a1b0: f64,
        a2: f64,
        a3: f64,
        p_gain: f64,
        m: f64,
        c: f64,
        k: f64,
        source: crate::lti::LtiError,
    },
}

impl RunError {
    /// [`RunError::Model`] for `rig` (at the run's P gain) and `specimen`.
    fn model(rig: &RigParams, specimen: &LinearSpecimen, source: crate::lti::LtiError) -> Self {
        let (m, c, k) = specimen.mck();
        RunError::Model {
            beta1: rig.beta1_per_s,
            a1b0: rig.a1b0_n_per_m_s2,
            a2: rig.a2_n_per_m,
            a3: rig.a3_per_s,
            p_gain: rig.p_gain,
            m,
            c,
            k,
            source,
        }
    }
}

impl From<Arc<RigError>> for RunError {
    fn from(e: Arc<RigError>) -> Self {
        RunError::NoRig(e)
    }
}

/// What happens as a campaign runs, for whoever watches it (a progress bar,
/// an event log). Called from the worker threads.
pub trait Observer: Sync {
    fn event(&self, event: &Event<'_>);
}

/// One thing that happened.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Event<'a> {
    /// The campaign starts with this many runs.
    Started { runs: usize },
    /// A run's log work starts.
    RunStarted { id: &'a str },
    /// A run's log work is done (or it failed, with its error), after
    /// `seconds`.
    RunFinished {
        id: &'a str,
        status: Status,
        error: Option<&'a str>,
        seconds: f64,
    },
    /// A run's outcome came from the cache, after `seconds`.
    RunCached { id: &'a str, seconds: f64 },
}

/// An observer that watches nothing.
pub struct Unobserved;

impl Observer for Unobserved {
    fn event(&self, _: &Event<'_>) {}
}

/// A campaign analysed, with the figures written for it.
#[derive(Debug, Clone)]
pub struct Analysed {
    pub results: Results,
    /// Each run's figures as written, in manifest order.
    pub run_figures: Vec<Vec<PageFigure>>,
    /// The campaign's own figures as written.
    pub campaign_figures: Vec<PageFigure>,
    /// Each run's tables as written (relative to the output folder), in
    /// manifest order.
    pub run_tables: Vec<Vec<String>>,
    /// Each run's log work (s), in manifest order: for run.jsonl, never
    /// results.json.
    pub seconds: Vec<f64>,
    /// Whether each run's outcome came from the cache.
    pub cached: Vec<bool>,
}

/// Analyse a campaign without drawing figures or caching.
pub fn analyse(campaign: &Campaign) -> Results {
    let draw = Drawer {
        out_dir: None,
        files: None,
        choice: FigureFormats::None,
        intersample: campaign.identification.intersample,
        cache: None,
    };
    analyse_with(campaign, &draw, &Unobserved)
        .expect("nothing is written without figures or a cache")
        .results
}

/// Analyse a campaign, its figures and cache as `draw` says.
pub(super) fn analyse_with(
    campaign: &Campaign,
    draw: &Drawer<'_>,
    observer: &dyn Observer,
) -> Result<Analysed, WriteError> {
    observer.event(&Event::Started {
        runs: campaign.runs.len(),
    });
    let first: Vec<FirstPass> = campaign
        .runs
        .par_iter()
        .map(|plan| first_pass(campaign, plan, draw, observer).map_err(|e| e.in_run(&plan.id)))
        .collect::<Result<_, _>>()?;

    // What the manifest found (an unused log matched by the run table's
    // glob, say), then what the analysis finds.
    // The first no-specimen run's noise, in manifest order.
    let noise = first.iter().find_map(|f| f.noise.clone());
    let mut warnings = campaign.warnings.clone();
    let rig = rig::establish(campaign, first.iter().map(|f| &f.rig_input), &mut warnings)
        .map_err(Arc::new);
    let rig_params = rig.as_ref().ok().map(|(p, _)| *p);
    let rig_for_runs = rig
        .as_ref()
        .map(|(p, r)| (*p, r.covariance))
        .map_err(Arc::clone);

    let second: Vec<Done> = campaign
        .runs
        .par_iter()
        .zip(first)
        .map(|(plan, first)| {
            second_pass(campaign, plan, first, &rig_for_runs, draw, observer)
                .map_err(|e| e.in_run(&plan.id))
        })
        .collect::<Result<_, _>>()?;

    let mut runs = Vec::with_capacity(second.len());
    let mut run_figures = Vec::with_capacity(second.len());
    let mut run_tables = Vec::with_capacity(second.len());
    let mut seconds = Vec::with_capacity(second.len());
    let mut cached = Vec::with_capacity(second.len());
    let mut overlay = Vec::new();
    let mut csi = Vec::new();
    for done in second {
        csi.extend(done.csi);
        runs.push(done.result);
        run_figures.push(done.figures);
        run_tables.push(done.tables);
        warnings.extend(done.figure_warnings);
        seconds.push(done.seconds);
        cached.push(done.cached);
        overlay.extend(done.overlay);
    }
    flag_outliers(&mut runs);

    let ccf = match &rig_params {
        Some(rig) => campaign
            .runs
            .iter()
            .filter_map(|r| ccf_result(rig, r))
            .collect(),
        None => Vec::new(),
    };
    let needs_rig = campaign.runs.iter().any(|r| r.role == Role::Validation)
        || campaign.identifies_rig()
        || campaign.given_rig.is_some();
    let (rig_result, rig_error) = match rig {
        Ok((_, r)) => (Some(r), None),
        Err(e) => (None, needs_rig.then(|| e.to_string())),
    };
    let mut results = Results {
        schema_version: RESULTS_SCHEMA_VERSION,
        servoid_version: env!("CARGO_PKG_VERSION").to_string(),
        campaign: summary(campaign),
        rig: rig_result,
        rig_error,
        runs,
        ccf,
        csi,
        comparisons: Vec::new(),
        sensitivity: None,
        drift: None,
        warnings,
        manifest: campaign.manifest.clone(),
    };
    results.sensitivity = match rig_params {
        Some(rig) => {
            super::sensitivity::sensitivity(campaign, &rig, &results, noise.as_ref(), draw.cache)?
        }
        None => None,
    };
    if let Some(note) = results
        .sensitivity
        .as_ref()
        .and_then(|s| s.monte_carlo_note.as_ref())
    {
        results
            .warnings
            .push(format!("sensitivity.monte_carlo: not run: {note}"));
    }
    results.comparisons = compare(campaign, &results);
    let specs = figures::campaign_figures(&overlay, results.sensitivity.as_ref());
    let (campaign_figures, figure_warnings) = draw.write(&specs)?;
    results.warnings.extend(figure_warnings);
    if let Some(cache) = draw.cache {
        cache.finish()?;
    }
    Ok(Analysed {
        results,
        run_figures,
        campaign_figures,
        run_tables,
        seconds,
        cached,
    })
}

fn summary(campaign: &Campaign) -> CampaignSummary {
    CampaignSummary {
        name: campaign.name.clone(),
        description: campaign.description.clone(),
        rig_name: campaign.rig_name.clone(),
        rig_notes: campaign.rig_notes.clone(),
        manifest: campaign
            .file
            .file_name()
            .map(|f| f.to_string_lossy().into_owned())
            .unwrap_or_default(),
        manifest_sha256: campaign.manifest_sha256.clone(),
        manifest_path: None,
        run_table: campaign.run_table.clone(),
    }
}

/// Validation runs far worse than the others are flagged (the specimen may
/// differ from its log's behaviour).
fn flag_outliers(runs: &mut [RunResult]) {
    let mut validation: Vec<&mut ValidationMetrics> = runs
        .iter_mut()
        .filter(|r| r.role == Role::Validation)
        .filter_map(|r| r.validation.as_mut())
        .collect();
    validate::flag_outliers(&mut validation);
}

/// How a campaign's runs are done: where their figures go (nowhere when the
/// campaign draws none) and the cache they are kept in, if any.
pub(super) struct Drawer<'a> {
    /// The output folder, for the runs' tables; None writes none.
    pub out_dir: Option<&'a Path>,
    pub files: Option<&'a FigureFiles<'a>>,
    pub choice: FigureFormats,
    pub intersample: crate::fit::Intersample,
    pub cache: Option<&'a Cache>,
}

impl Drawer<'_> {
    fn write(&self, specs: &[FigureSpec]) -> Result<(Vec<PageFigure>, Vec<String>), WriteError> {
        match self.files {
            Some(files) if !specs.is_empty() => files.write(specs),
            _ => Ok((Vec::new(), Vec::new())),
        }
    }

    fn enabled(&self) -> bool {
        self.files.is_some()
    }

    /// Write a run's tables, when there is an output folder.
    fn tables(&self, run: &RunResult, stage: Option<&LogStage>) -> Result<Vec<String>, WriteError> {
        match self.out_dir {
            Some(dir) => tables::write(dir, run, stage, self.intersample),
            None => Ok(Vec::new()),
        }
    }

    /// The size of a file under the output folder, None when it is not
    /// there.
    fn size_of(&self, name: &str) -> Option<u64> {
        let dir = self.out_dir?;
        std::fs::metadata(dir.join(name)).ok().map(|m| m.len())
    }

    /// Whether every file `stored` wrote (figures, tables) is still there,
    /// as it was written.
    fn still_there(&self, stored: &Stored) -> bool {
        stored
            .files
            .iter()
            .all(|(name, size)| self.size_of(name) == Some(*size))
    }

    /// Each file a run wrote (its figures and tables), with its size.
    fn sizes(&self, figures: &[PageFigure], tables: &[String]) -> Vec<(String, u64)> {
        figures
            .iter()
            .flat_map(|f| [&f.png_file, &f.svg_file])
            .flatten()
            .chain(tables)
            .filter_map(|name| self.size_of(name).map(|size| (name.clone(), size)))
            .collect()
    }
}

/// A run's outcome as the cache keeps it: everything the campaign needs of
/// it once its log is dropped.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
struct Stored {
    result: RunResult,
    /// What the rig is identified from.
    estimate: Option<Evidence>,
    force: Option<ForceBins>,
    overlay: Option<OverlayRun>,
    /// A validation run's control-structure interaction.
    #[serde(default)]
    csi: Option<Csi>,
    /// A no-specimen run's FRF noise.
    #[serde(default)]
    noise: Option<NoiseProfile>,
    figures: Vec<PageFigure>,
    figure_warnings: Vec<String>,
    /// The figure and table files with their sizes, to tell they are still
    /// there.
    files: Vec<(String, u64)>,
}

/// What a run keeps from the first pass: everything but its signals.
struct FirstPass {
    /// None for a validation run, which waits for the rig.
    result: Option<RunResult>,
    rig_input: RigInput,
    /// Whether the log was read and analysed (the rig's force model then
    /// applies to it).
    acquired: bool,
    force: Option<ForceBins>,
    overlay: Option<OverlayRun>,
    /// A no-specimen run's FRF noise, for the stiffness sensitivity.
    noise: Option<NoiseProfile>,
    figures: Vec<PageFigure>,
    figure_warnings: Vec<String>,
    /// The run's tables as written (relative to the output folder).
    tables: Vec<String>,
    seconds: f64,
    cached: bool,
}

/// Covariance of (beta1, a1b0, a2, a3).
type Cov4 = [[f64; 4]; 4];

/// A run done.
struct Done {
    result: RunResult,
    csi: Option<Csi>,
    figures: Vec<PageFigure>,
    figure_warnings: Vec<String>,
    /// The run's tables as written (relative to the output folder).
    tables: Vec<String>,
    overlay: Option<OverlayRun>,
    seconds: f64,
    cached: bool,
}

/// A run's result before anything is known of it.
fn new_result(plan: &RunPlan) -> RunResult {
    RunResult {
        id: plan.id.clone(),
        role: plan.role,
        description: plan.description.clone(),
        p_gain: plan.p_gain,
        status: Status::Ok,
        error: None,
        warnings: Vec::new(),
        specimen: plan.specimen,
        natural_frequency_hz: plan.specimen.natural_frequency_hz(),
        a1b0: None,
        tf: None,
        force_tf: None,
        fit: None,
        validation: None,
        log: None,
        annotations: plan.annotations.clone(),
    }
}

/// The cache's verdict on a run: its stored outcome, or the key to store
/// the new one under and its log's bytes when they were read on the way.
fn probe(
    draw: &Drawer<'_>,
    campaign: &Campaign,
    plan: &RunPlan,
    parts: &[&dyn std::fmt::Debug],
) -> (
    Option<Stored>,
    Option<String>,
    Option<crate::ingest::LogFile>,
) {
    let (Some(cache), RunSource::Log(lp)) = (draw.cache, &plan.source) else {
        return (None, None, None);
    };
    // The plan as the manifest states it: its log relative to the
    // manifest's folder, so the key does not depend on the folder the job
    // ran from (shards on other machines find each other's runs).
    // A run's description and the lab's notes do not change what it
    // computes: they are left out of the key and put in a stored outcome
    // as the manifest says them now, so editing a note redoes no work.
    let mut keyed = plan.clone();
    keyed.description.clear();
    keyed.annotations.clear();
    if let (RunSource::Log(kp), Some(base)) = (&mut keyed.source, campaign.file.parent()) {
        kp.path = kp.path.strip_prefix(base).unwrap_or(&kp.path).to_path_buf();
    }
    let key = |sha: &str| {
        let mut all: Vec<&dyn std::fmt::Debug> = parts.to_vec();
        all.extend([&keyed as &dyn std::fmt::Debug, &draw.choice, &sha]);
        cache::key(&all)
    };
    match cache.probe(&lp.path, lp.max_bytes, key, |s: &Stored| {
        draw.still_there(s)
    }) {
        Probe::Hit(mut stored) => {
            stored.result.description = plan.description.clone();
            stored.result.annotations = plan.annotations.clone();
            (Some(stored), None, None)
        }
        Probe::Miss { key, file } => (None, Some(key), file),
    }
}

/// The first pass of one run: everything that does not need the rig.
fn first_pass(
    campaign: &Campaign,
    plan: &RunPlan,
    draw: &Drawer<'_>,
    observer: &dyn Observer,
) -> Result<FirstPass, WriteError> {
    let mut pass = FirstPass {
        result: None,
        rig_input: RigInput::Nothing,
        acquired: false,
        force: None,
        overlay: None,
        noise: None,
        figures: Vec::new(),
        figure_warnings: Vec::new(),
        tables: Vec::new(),
        seconds: 0.0,
        cached: false,
    };
    if plan.role == Role::Validation {
        if campaign.joint.include_validation && campaign.identifies_rig() {
            pass.rig_input = validation_evidence(campaign, plan);
        }
        return Ok(pass);
    }
    observer.event(&Event::RunStarted { id: &plan.id });
    let start = Instant::now();
    let (stored, key, file) = probe(
        draw,
        campaign,
        plan,
        &[&"first pass", &campaign.identification],
    );
    if let Some(s) = stored {
        pass.seconds = start.elapsed().as_secs_f64();
        observer.event(&Event::RunCached {
            id: &plan.id,
            seconds: pass.seconds,
        });
        pass.rig_input = match s.estimate {
            Some(e) => RigInput::Estimate(Box::new(e)),
            None => RigInput::Nothing,
        };
        pass.result = Some(s.result);
        pass.acquired = true;
        (pass.force, pass.overlay, pass.noise) = (s.force, s.overlay, s.noise);
        (pass.figures, pass.figure_warnings) = (s.figures, s.figure_warnings);
        pass.tables = table_files(&s.files);
        pass.cached = true;
        return Ok(pass);
    }
    let mut out = new_result(plan);
    match acquire_with(campaign, plan, file) {
        Err(e) => {
            let e = Arc::new(e);
            pass.rig_input = RigInput::Failed(e.clone());
            out = failed(out, e.into());
        }
        Ok(acq) => {
            pass.acquired = true;
            let (tf, cov) = (acq.tf.clone(), acq.cov);
            let (result, stage, time) = fitted(&campaign.identification, plan, out, acq);
            out = result;
            // What the rig's identification needs of the run: its model,
            // and for the joint fit the bins its fit was given.
            let estimate = tf.map(|tf| Evidence {
                tf,
                cov,
                data: stage.as_ref().and_then(|st| st.fit_data.clone()),
                adequacy: out.fit.as_ref().and_then(|f| f.adequacy.clone()),
                sample_rate_hz: stage.as_ref().map(|st| st.log.sample_rate_hz),
            });
            pass.rig_input = match &estimate {
                Some(e) => RigInput::Estimate(Box::new(e.clone())),
                None => RigInput::Nothing,
            };
            if let Some(st) = &stage {
                pass.force = ForceBins::of(st);
                if plan.role == Role::NoSpecimen {
                    pass.noise = noise_profile(plan, st);
                }
                if draw.enabled() {
                    let (specs, overlay) =
                        figures::log_figures(&out, st, time.as_ref(), draw.intersample, None);
                    (pass.figures, pass.figure_warnings) = draw.write(&specs)?;
                    pass.overlay = overlay;
                }
            }
            let tables = draw.tables(&out, stage.as_deref())?;
            if let (Some(cache), Some(key)) = (draw.cache, &key) {
                cache.store(
                    key,
                    &Stored {
                        result: out.clone(),
                        estimate,
                        force: pass.force.clone(),
                        overlay: pass.overlay.clone(),
                        csi: None,
                        noise: pass.noise.clone(),
                        files: draw.sizes(&pass.figures, &tables),
                        figures: pass.figures.clone(),
                        figure_warnings: pass.figure_warnings.clone(),
                    },
                )?;
            }
            pass.tables = tables;
        }
    }
    pass.seconds = start.elapsed().as_secs_f64();
    observer.event(&Event::RunFinished {
        id: &plan.id,
        status: out.status,
        error: out.error.as_deref(),
        seconds: pass.seconds,
    });
    pass.result = Some(out);
    Ok(pass)
}

/// A validation run's FRFs for the joint fit, read ahead of the rig
/// (`identification.joint.include_validation`): the band's bins with the
/// coherence the identification runs need. Nothing when the run has no log
/// or its log fails here: the second pass reads it again and reports why.
fn validation_evidence(campaign: &Campaign, plan: &RunPlan) -> RigInput {
    if !matches!(plan.source, RunSource::Log(_)) {
        return RigInput::Nothing;
    }
    let Ok(Some(st)) = acquire_with(campaign, plan, None).map(|a| a.stage) else {
        return RigInput::Nothing;
    };
    let coherence_min = campaign.identification.coherence_min;
    let data = |h: &Frf| FitData::of(h, &frf::band_mask(h, plan.band_hz, coherence_min));
    RigInput::Validation(Box::new(ValidationEvidence {
        displacement: data(&st.frf),
        force: st.force_frf.as_ref().map(data),
        sample_rate_hz: st.log.sample_rate_hz,
        sha256: st.log.sha256.clone(),
    }))
}

/// The second pass of one run: a validation run's whole work, and for the
/// others what depends on the rig.
fn second_pass(
    campaign: &Campaign,
    plan: &RunPlan,
    first: FirstPass,
    rig: &Result<(RigParams, Option<Cov4>), Arc<RigError>>,
    draw: &Drawer<'_>,
    observer: &dyn Observer,
) -> Result<Done, WriteError> {
    let rig_at_p = rig.as_ref().ok().map(|(r, _)| r.at_p_gain(plan.p_gain));
    let Some(mut out) = first.result else {
        let fitted = match &first.rig_input {
            RigInput::Validation(e) => Some(e.sha256.as_str()),
            _ => None,
        };
        return validation_run(campaign, plan, rig, fitted, draw, observer);
    };
    out.a1b0 = rig_at_p.map(|r| r.a1b0_n_per_m_s2);
    let mut figures = first.figures;
    let mut figure_warnings = first.figure_warnings;
    if first.acquired {
        // The run's own fit stands without the force model: its absence is
        // a warning, not the run's failure.
        out.force_tf = match rig_at_p.map(|r| models(&r, &plan.specimen)) {
            Some(Ok((_, f))) => f,
            Some(Err(e)) => {
                out.warnings.push(format!("no force model (Eq. 45): {e}"));
                None
            }
            None => None,
        };
        if let (Some(bins), Some(model)) = (&first.force, &out.force_tf) {
            let spec = figures::force_figure(&out, bins, model, draw.intersample, None);
            let (f, w) = draw.write(std::slice::from_ref(&spec))?;
            // Figs. 16-17 come right after the run's FRF, as on the page.
            let at = figures.len().min(1);
            figures.splice(at..at, f);
            figure_warnings.extend(w);
        }
    }
    Ok(Done {
        result: out,
        csi: None,
        figures,
        figure_warnings,
        tables: first.tables,
        overlay: first.overlay,
        seconds: first.seconds,
        cached: first.cached,
    })
}

/// What run `plan`'s log says of its FRF noise: the bins its fit used and
/// their variance, the white noise level that implies, the displacement's
/// quantisation step and the log's hash (for the Monte Carlo, which
/// replays its command).
fn noise_profile(plan: &RunPlan, st: &LogStage) -> Option<NoiseProfile> {
    let (fit, data) = (st.fit.as_ref()?, st.fit_data.as_ref()?);
    let fs = st.log.sample_rate_hz;
    (!data.freq_hz.is_empty()).then(|| NoiseProfile {
        run: plan.id.clone(),
        white_noise: crate::sensitivity::montecarlo::white_noise(&data.variance, &data.suu, fs),
        freq_hz: data.freq_hz.clone(),
        variance: data.variance.clone(),
        sample_rate_hz: fs,
        delay_s: fit.tf.delay_s,
        displacement_step_m: crate::ingest::quantum_step(&st.log.displacement_m),
        log_sha256: st.log.sha256.clone(),
    })
}

/// The model's x1/u (Eq. 17) and force path f/u (Eq. 45) for a linear
/// specimen (f/u None without one), or the error that names why the rig
/// and the specimen give no model in f64.
#[allow(clippy::type_complexity)]
fn models(
    rig_at_p: &RigParams,
    specimen: &SpecimenModel,
) -> Result<(Option<TfResult>, Option<TfResult>), RunError> {
    let Some(lin) = specimen.linear() else {
        return Ok((None, None));
    };
    let err = |e| RunError::model(rig_at_p, &lin, e);
    let x = model::tf_x1_u(rig_at_p, &lin).map_err(err)?;
    let f = match lin {
        LinearSpecimen::None => None,
        _ => Some(model::tf_f_u(rig_at_p, &lin).map_err(err)?),
    };
    Ok((
        Some(TfResult::new(&x, TfSource::Model)),
        f.map(|f| TfResult::new(&f, TfSource::Model)),
    ))
}

/// A validation run: the identified rig with its specimen, driven by its
/// measured command (Sec. 4), or the model's prediction alone without a log.
/// `fitted` is the SHA-256 of the log as the joint fit read it, when it did.
fn validation_run(
    campaign: &Campaign,
    plan: &RunPlan,
    rig: &Result<(RigParams, Option<Cov4>), Arc<RigError>>,
    fitted: Option<&str>,
    draw: &Drawer<'_>,
    observer: &dyn Observer,
) -> Result<Done, WriteError> {
    observer.event(&Event::RunStarted { id: &plan.id });
    let start = Instant::now();
    // The key holds the rig at this run's P gain: a new rig redoes the run.
    let (stored, key, file) = match rig {
        Ok((r, cov)) => probe(
            draw,
            campaign,
            plan,
            &[
                &"validation",
                &campaign.identification,
                &r.at_p_gain(plan.p_gain),
                cov,
            ],
        ),
        Err(_) => (None, None, None),
    };
    if let Some(s) = stored {
        let seconds = start.elapsed().as_secs_f64();
        observer.event(&Event::RunCached {
            id: &plan.id,
            seconds,
        });
        return Ok(Done {
            tables: table_files(&s.files),
            result: s.result,
            csi: s.csi,
            figures: s.figures,
            figure_warnings: s.figure_warnings,
            overlay: None,
            seconds,
            cached: true,
        });
    }
    let mut out = new_result(plan);
    let figures = (Vec::new(), Vec::new());
    // The log's own failure comes first; a good log without a rig still
    // records what it is.
    let acq = acquire_with(campaign, plan, file).and_then(|a| match (fitted, &a.stage) {
        // The rig was fitted to the log's bytes as they were: a log that
        // has changed since is not what the rig says it validates.
        (Some(before), Some(st)) if st.log.sha256 != before => {
            Err(AcquireError::Ingest(IngestError::Changed {
                path: st.log.path.clone(),
                before: format!("SHA-256 {before} when the joint fit read it"),
                after: format!("SHA-256 {} when its run was validated", st.log.sha256),
            }))
        }
        _ => Ok(a),
    });
    let acq = match acq {
        Ok(a) => a,
        Err(e) => {
            out.a1b0 = rig
                .as_ref()
                .ok()
                .map(|(r, _)| r.at_p_gain(plan.p_gain).a1b0_n_per_m_s2);
            out = failed(out, Arc::new(e).into());
            return Ok(finish(plan, out, figures, start, observer));
        }
    };
    out.warnings = acq.warnings.clone();
    out.log = log_info(plan, acq.stage.as_deref());
    // The rig and its covariance at this run's P gain: a1b0 scales with P,
    // and its row and column of the covariance with it.
    let (rig_at_p, rig_cov) = match rig {
        Ok((r, cov)) => {
            let f = [1.0, plan.p_gain / r.p_gain, 1.0, 1.0];
            let at_p = cov.map(|c| -> Cov4 {
                std::array::from_fn(|i| std::array::from_fn(|j| c[i][j] * f[i] * f[j]))
            });
            (r.at_p_gain(plan.p_gain), at_p)
        }
        Err(e) => {
            // The measured FRF is still worth seeing.
            out = failed(out, e.clone().into());
            let figures = match (&acq.stage, draw.enabled()) {
                (Some(st), true) => {
                    draw.write(&figures::log_figures(&out, st, None, draw.intersample, None).0)?
                }
                _ => figures,
            };
            return Ok(finish(plan, out, figures, start, observer));
        }
    };
    out.a1b0 = Some(rig_at_p.a1b0_n_per_m_s2);
    let specimen = plan.specimen;
    let linear = specimen.linear();
    match models(&rig_at_p, &specimen) {
        Ok((tf, force_tf)) => (out.tf, out.force_tf) = (tf, force_tf),
        Err(e) => {
            out = failed(out, e);
            let figures = match (&acq.stage, draw.enabled()) {
                (Some(st), true) => {
                    draw.write(&figures::log_figures(&out, st, None, draw.intersample, None).0)?
                }
                _ => figures,
            };
            return Ok(finish(plan, out, figures, start, observer));
        }
    }
    let Some(st) = &acq.stage else {
        let tables = draw.tables(&out, None)?;
        return Ok(Done {
            tables,
            ..finish(plan, out, figures, start, observer)
        });
    };
    let time = match validate::validation_run(&rig_at_p, &specimen, &record(&st.log)) {
        Ok(t) => {
            out.validation = Some(t.metrics.clone());
            Some(t)
        }
        Err(e) => {
            out = failed(out, e.into());
            None
        }
    };
    let bins = ForceBins::of(st);
    let csi = linear.and_then(|lin| {
        validate::csi::csi(
            &plan.id,
            &rig_at_p,
            &lin,
            bins.as_ref().map(ForceBins::bins),
        )
    });
    let figures = if draw.enabled() {
        // The prediction's band, from the rig's covariance.
        let prediction = match (rig_cov, linear) {
            (Some(cov), Some(specimen)) => Some(figures::Prediction {
                rig: rig_at_p,
                cov,
                specimen,
            }),
            _ => None,
        };
        let (mut specs, _) = figures::log_figures(
            &out,
            st,
            time.as_ref(),
            draw.intersample,
            prediction.as_ref(),
        );
        if let (Some(bins), Some(model)) = (&bins, &out.force_tf) {
            specs.insert(
                1,
                figures::force_figure(&out, bins, model, draw.intersample, csi.as_ref()),
            );
        }
        draw.write(&specs)?
    } else {
        figures
    };
    let tables = draw.tables(&out, Some(st))?;
    if let (Some(cache), Some(key)) = (draw.cache, &key) {
        cache.store(
            key,
            &Stored {
                result: out.clone(),
                estimate: None,
                force: None,
                overlay: None,
                csi: csi.clone(),
                noise: None,
                files: draw.sizes(&figures.0, &tables),
                figures: figures.0.clone(),
                figure_warnings: figures.1.clone(),
            },
        )?;
    }
    Ok(Done {
        csi,
        tables,
        ..finish(plan, out, figures, start, observer)
    })
}

/// A validation run done: its log work timed and reported.
fn finish(
    plan: &RunPlan,
    result: RunResult,
    (figures, figure_warnings): (Vec<PageFigure>, Vec<String>),
    start: Instant,
    observer: &dyn Observer,
) -> Done {
    let seconds = start.elapsed().as_secs_f64();
    observer.event(&Event::RunFinished {
        id: &plan.id,
        status: result.status,
        error: result.error.as_deref(),
        seconds,
    });
    Done {
        result,
        csi: None,
        figures,
        figure_warnings,
        tables: Vec::new(),
        overlay: None,
        seconds,
        cached: false,
    }
}

/// The tables among the files a stored run wrote.
fn table_files(files: &[(String, u64)]) -> Vec<String> {
    files
        .iter()
        .map(|(name, _)| name)
        .filter(|name| name.starts_with("tables/"))
        .cloned()
        .collect()
}

/// A log's signals as the time-domain checks read them.
fn record(log: &Log) -> Record<'_> {
    Record {
        sample_rate_hz: log.sample_rate_hz,
        command_m: &log.command_m,
        displacement_m: &log.displacement_m,
        force_n: log.force_n.as_deref(),
    }
}

/// Provenance of a run's log, when it has one.
fn log_info(plan: &RunPlan, stage: Option<&LogStage>) -> Option<LogInfo> {
    let (st, RunSource::Log(lp)) = (stage?, &plan.source) else {
        return None;
    };
    Some(LogInfo {
        file: lp
            .path
            .file_name()
            .map(|f| f.to_string_lossy().into_owned())
            .unwrap_or_default(),
        sha256: st.log.sha256.clone(),
        sample_rate_hz: st.log.sample_rate_hz,
        n_samples: st.log.n_rows,
        duration_s: st.log.n_rows as f64 / st.log.sample_rate_hz,
    })
}

/// A run marked failed with its error.
fn failed(mut out: RunResult, e: RunError) -> RunResult {
    out.status = Status::Failed;
    out.error = Some(e.to_string());
    out
}

/// An identification or fit run: its published or fitted model with the
/// coefficients' uncertainty, and the fitted model in the time domain (Figs.
/// 9, 12, 14). A failure of the time-domain check is a warning: the fit
/// stands on its own. Returns the result, the log stage and the
/// time-domain check for the figures.
fn fitted(
    ident: &IdentificationPlan,
    plan: &RunPlan,
    mut out: RunResult,
    acq: Acquired,
) -> (
    RunResult,
    Option<Box<LogStage>>,
    Option<validate::TimeStage>,
) {
    out.warnings = acq.warnings.clone();
    out.log = log_info(plan, acq.stage.as_deref());
    let stage = acq.stage;
    let fit = stage.as_ref().and_then(|s| s.fit.as_ref());
    out.tf = acq.tf.as_ref().map(|tf| {
        let mut t = TfResult::new(tf, acq.source);
        if let Some(fit) = fit {
            t.std = Some(fit.std.clone());
            t.rel_std = Some(
                fit.std
                    .iter()
                    .zip(&fit.params)
                    .map(|(s, p)| s / p.abs())
                    .collect(),
            );
        }
        t
    });
    let mut time = None;
    if let Some(st) = &stage
        && let Some(fit) = &st.fit
    {
        let summary = fit_summary(ident, plan, st, fit);
        if let Some(t) = summary.delay_test.as_ref().filter(|t| t.supported) {
            out.warnings.push(format!(
                "the run's own fit: {}; with a delay of {:.3} ms its reduced chi-square is {:.3} (without, {:.3}); set identification.delay = {{ mode = \"fit\" }}",
                t.note,
                1e3 * t.delay_s.unwrap_or(f64::NAN),
                t.reduced_chi2.unwrap_or(f64::NAN),
                summary.reduced_chi2
            ));
        }
        if let Some(d) = summary.adequacy.as_ref().and_then(|a| {
            a.diagnosis(
                (!fit.shape.fit_delay).then_some("set identification.delay = \"fit\""),
                ident.frf.estimator.understated_noise(),
            )
        }) {
            out.warnings.push(format!("the run's own fit: {d}"));
        }
        if let Some(o) = summary
            .adequacy
            .as_ref()
            .and_then(|a| a.overstated(ident.frf.estimator.overstated_noise()))
        {
            out.warnings.push(format!("the run's own fit: {o}"));
        }
        // A model that explains under half of the measured response is not
        // a rig's: the likely causes are in the log's mapping, not in the
        // model (swapped command and displacement columns measured 31 %).
        if summary.fit_percent < POOR_FIT_PERCENT {
            out.warnings.push(format!(
                "the model explains only {:.0} % of the measured response (fit percent below {POOR_FIT_PERCENT:.0}); likely cause: the channels' columns (command and displacement swapped, or another run's log)",
                summary.fit_percent
            ));
        }
        out.fit = Some(summary);
        match validate::fitted_run(&fit.tf, &record(&st.log)) {
            Ok(t) => {
                out.validation = Some(t.metrics.clone());
                time = Some(t);
            }
            Err(e) => out
                .warnings
                .push(format!("time-domain check of the fitted model: {e}")),
        }
    }
    (out, stage, time)
}

/// The adequacy tests of a run's own fit on the bins it was given, its
/// model with the hold and delay.
fn fit_adequacy(ident: &IdentificationPlan, st: &LogStage, fit: &TfFit) -> Option<Adequacy> {
    let data = st.fit_data.as_ref()?;
    let fs = st.log.sample_rate_hz;
    let model: Vec<_> = data
        .freq_hz
        .iter()
        .map(|&f| fit.tf.freq_response(f) * crate::fit::hold_response(ident.intersample, fs, f))
        .collect();
    Some(adequacy::assess(
        &Residuals {
            freq_hz: &data.freq_hz,
            h: &data.h,
            model: &model,
            variance: &data.variance,
        },
        fit.params.len(),
        st.frf.resolution_hz,
        ident.frf.independent_lag(),
    ))
}

fn fit_summary(
    ident: &IdentificationPlan,
    plan: &RunPlan,
    st: &LogStage,
    fit: &TfFit,
) -> FitSummary {
    let used: Vec<f64> = st
        .frf
        .coherence
        .iter()
        .zip(&st.mask)
        .filter(|(_, m)| **m)
        .map(|(c, _)| *c)
        .collect();
    FitSummary {
        fit_percent: fit.fit_percent,
        n_bins: fit.n_bins,
        band_hz: [plan.band_hz.0, plan.band_hz.1],
        coherence_mean: used.iter().sum::<f64>() / used.len().max(1) as f64,
        coherence_min: used.iter().copied().fold(f64::INFINITY, f64::min),
        reduced_chi2: fit.reduced_chi2,
        iterations: fit.iterations,
        termination: fit.termination.clone(),
        converged: fit.converged,
        stable: fit.stable,
        param_names: fit.param_names.clone(),
        params: fit.params.clone(),
        std: fit.std.clone(),
        frf_averages: st.frf.n_averages,
        frf_resolution_hz: st.frf.resolution_hz,
        adequacy: fit_adequacy(ident, st, fit),
        delay_test: delay_test(ident, st, fit),
    }
}

/// For a fit made without a delay (`identification.delay` none): the same
/// fit with one, up to the default bound, and whether the data support it.
fn delay_test(ident: &IdentificationPlan, st: &LogStage, fit: &TfFit) -> Option<DelayTestResult> {
    if ident.delay != DelayPlan::None {
        return None;
    }
    let data = st.fit_data.as_ref()?;
    let opts = fit_options(ident, st.log.sample_rate_hz);
    let t = fit::delay_test::delay_test(&data.input(), &opts, fit, ident.max_delay_s);
    let with = t.with_delay.as_ref().ok();
    let converged = with.filter(|w| w.converged && w.stable);
    let note = match (&t.with_delay, t.f_test) {
        (Err(e), _) => format!("the fit with a delay failed: {e}"),
        (Ok(w), None) if !w.converged => format!(
            "the fit with a delay did not converge ({}); likely cause: the delay trades off against the model's poles in this band",
            w.termination
        ),
        (Ok(_), None) => "the fit with a delay is unstable".into(),
        (Ok(_), Some((f, p))) if t.supported() => {
            format!("the data support a delay: F = {f:.4e}, p = {p:.2e} (p < 0.001)")
        }
        (Ok(_), Some((f, p))) => {
            format!("the data do not support a delay: F = {f:.4e}, p = {p:.2e}")
        }
    };
    Some(DelayTestResult {
        delay_s: converged.and_then(|w| w.params.last().copied()),
        reduced_chi2: converged.map(|w| w.reduced_chi2),
        f: t.f_test.map(|(f, _)| f),
        p_value: t.f_test.map(|(_, p)| p),
        supported: t.supported(),
        note,
    })
}

fn ccf_result(rig: &RigParams, plan: &RunPlan) -> Option<CcfResult> {
    let SpecimenModel::LinearSdof {
        mass_kg,
        damping_ns_per_m,
        stiffness_n_per_m,
    } = plan.specimen
    else {
        return None;
    };
    let rig = rig.at_p_gain(plan.p_gain);
    let sdof = LinearSdof {
        mass_kg,
        damping_ns_per_m,
        stiffness_n_per_m,
    };
    let c = model::ccf_coefficients(&rig, &sdof, 0.0, 0.0);
    // No poles where the eigenvalues cannot be computed (the run's model
    // error says why); then the simplified form is not called stable.
    let poles = |cn| -> Option<Vec<ComplexValue>> {
        let e = model::ccf_linear_state_space(&rig, &sdof, cn).eigenvalues()?;
        Some(e.into_iter().map(ComplexValue::from).collect())
    };
    let dropped = poles(CnTerm::Dropped);
    let stable_without_cn = dropped
        .as_ref()
        .is_some_and(|p| p.iter().all(|p| p.re < 0.0));
    let poles_without_cn: Vec<ComplexValue> = dropped.unwrap_or_default();
    Some(CcfResult {
        stable_without_cn,
        run: plan.id.clone(),
        p_gain: plan.p_gain,
        C1: c.C1,
        C2: c.C2,
        C3: c.C3,
        C4: c.C4,
        C5: c.C5,
        poles_with_cn: poles(CnTerm::Kept).unwrap_or_default(),
        poles_without_cn,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::manifest::load;
    use crate::manifest::simulation::load_simulation_str;
    use crate::run::simulate::simulate_campaign;

    /// A 30 s campaign at 1 kHz: a no-specimen run, a spring and the
    /// paper's Exp1 as a validation run, the joint fit including it.
    const CAMPAIGN: &str = r#"
schema_version = 1

[simulation]
name = "changed"
sample_rate_hz = 1000.0
seed = 3
log_format = "csv"

[rig]
name = "a simulated rig"

[rig.parameters]
beta1_per_s = 267.0
a1b0_n_per_m_s2 = 2.412e9
a2_n_per_m = 7.881e5
a3_per_s = 16.118

[excitation]
kind = "chirp"
law = "quadratic"
f0_hz = 0.1
f1_hz = 35.0
duration_s = 30.0
amplitude_m = 0.004
lead_in_s = 1.0
lead_out_s = 1.0

[instrument.command]
unit = "mm"

[instrument.displacement]
unit = "mm"
noise_rms = 0.002

[instrument.force]
unit = "N"
noise_rms = 2.0

[identification]
band_hz = [0.5, 30.0]
coherence_min = 0.8
frf = { estimator = "etfe", segment_length = 8192, overlap = 0.5, window = "rectangular", detrend = "mean" }
joint = { include_validation = true }

[[runs]]
id = "bare"
role = "no_specimen"
p_gain = 1.0

[[runs]]
id = "k1"
role = "spring"
p_gain = 1.0
specimen = { stiffness_n_per_m = 116640.0 }

[[runs]]
id = "exp1"
role = "validation"
p_gain = 1.0
specimen = { mass_kg = 3.8, damping_ns_per_m = 5.0, stiffness_n_per_m = 129400.0 }
"#;

    /// The joint fit read a validation run's log; the second pass finds
    /// other bytes there (here: told the fit read other ones). The run
    /// fails with an error naming the file and both hashes, rather than
    /// validating a rig against a log it was not fitted to; with the hash
    /// the fit read, the same run validates.
    #[test]
    fn a_validation_log_changed_since_the_joint_fit_read_it_fails_its_run() {
        let dir = tempfile::tempdir().unwrap();
        let sim =
            load_simulation_str(CAMPAIGN, &dir.path().join("sim.toml")).expect("a simulation");
        let out = simulate_campaign(&sim, dir.path()).expect("simulates");
        let campaign = load(&out.manifest).expect("the manifest loads");
        let plan = campaign.runs.iter().find(|r| r.id == "exp1").unwrap();
        let RigInput::Validation(read) = validation_evidence(&campaign, plan) else {
            panic!("the joint fit reads the validation run");
        };
        assert!(read.force.is_some() && !read.displacement.freq_hz.is_empty());
        let rig = Ok((crate::model::PAPER_RIG, None));
        let draw = Drawer {
            out_dir: None,
            files: None,
            choice: FigureFormats::None,
            intersample: campaign.identification.intersample,
            cache: None,
        };
        let other = "0".repeat(64);
        let done = validation_run(&campaign, plan, &rig, Some(&other), &draw, &Unobserved).unwrap();
        let error = done.result.error.expect("the run fails");
        let RunSource::Log(log) = &plan.source else {
            unreachable!()
        };
        for needle in [
            log.path.display().to_string(),
            format!("SHA-256 {other} when the joint fit read it"),
            format!("SHA-256 {} when its run was validated", read.sha256),
        ] {
            assert!(error.contains(&needle), "{needle:?} not in {error:?}");
        }
        let done = validation_run(
            &campaign,
            plan,
            &rig,
            Some(&read.sha256),
            &draw,
            &Unobserved,
        )
        .unwrap();
        assert!(done.result.error.is_none(), "{:?}", done.result.error);
        assert!(done.result.validation.is_some());
    }
}
