//! A campaign's analysis in two passes over its runs, each in parallel
//! (results keep the manifest's order, so the output does not depend on the
//! thread count), holding one log per worker at a time:
//!
//! 1. every run that does not need the rig (no-specimen, spring and fit
//!    runs) is read, estimated and fitted, its figures drawn and its signals
//!    dropped; what the rig and its later figures need is kept;
//! 2. the rig is identified from them (Fig. 6, Eqs. 18-20) or taken as
//!    given; then the validation runs are read, predicted and validated,
//!    and the other runs get what depends on the rig.
//!
//! Then the sensitivity and the comparisons. A failed run is recorded and
//! the batch goes on; each run's output goes to the `sink` as it arrives.

use crate::warning::Warning;
use std::sync::Arc;
use std::time::Instant;

use rayon::prelude::*;

use super::scratch::Scratch;
use super::sink::{Done, Probed, Sink};
use super::step::{self, Output, RigOutcome};
use crate::analysis::RigError;
use crate::analysis::conclusions;
use crate::analysis::evidence::RigInput;
use crate::analysis::rig;
use crate::analysis::sensitivity::NoiseSource;
use crate::ingest::LogFile;
use crate::manifest::{Campaign, Role, RunPlan};
use crate::model::RigParams;
use crate::report::figures::catalogue::{self, OverlayRun};
use crate::report::{FigureFormats, PageFigure, WriteError};
use crate::results::{RESULTS_SCHEMA_VERSION, Results, RigResult, RunResult, Status};
use crate::validate::csi::Csi;

pub use crate::analysis::run_result::RunError;

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
    let sink = Sink {
        out_dir: None,
        files: None,
        choice: FigureFormats::None,
        intersample: campaign.identification.intersample,
        cache: None,
    };
    analyse_with(campaign, &sink, &Unobserved)
        .expect("nothing is written without figures or a cache")
        .results
}

/// Analyse a campaign, its figures, tables and cache going to `sink`.
pub(super) fn analyse_with(
    campaign: &Campaign,
    sink: &Sink<'_>,
    observer: &dyn Observer,
) -> Result<Analysed, WriteError> {
    observer.event(&Event::Started {
        runs: campaign.runs.len(),
    });
    // The identification runs' bins wait for the rig in a scratch file,
    // where the job has a folder (in memory where it has none).
    let scratch = sink.out_dir.and_then(Scratch::new);
    let mut first = first_passes(campaign, sink, observer, scratch.as_ref())?;
    // The workers' logs are freed beneath what the runs keep.
    super::allocator::give_back();

    // The first no-specimen run's noise, in manifest order.
    let noise = first.iter().find_map(|f| match f {
        FirstPass::Done(d) => d.kept.noise.clone(),
        FirstPass::Waiting(_) => None,
    });
    // What the manifest found (an unused log matched by the run table's
    // glob, say), then what the analysis finds.
    let mut warnings = campaign.warnings.clone();
    let rig = establish_rig(campaign, &mut first, &mut warnings);
    drop(scratch);
    let rig_for_runs = for_runs(campaign, &rig);
    // Each run's tracking waits for the set's files in another, once the
    // run's own are written: what the campaign holds then grows by a run's
    // summary, not by its tracking.
    let parked = sink.out_dir.and_then(Scratch::new);
    let second = second_passes(
        campaign,
        first,
        &rig_for_runs,
        sink,
        observer,
        parked.as_ref(),
    )?;
    // The workers' logs are freed beneath the runs' results again, before
    // the campaign's conclusions and its files are built.
    super::allocator::give_back();
    let runs = PerRun::of(second, &mut warnings);
    let (rig_result, rig_error) = match rig {
        Ok((_, r)) => (Some(r), None),
        Err(e) => (
            None,
            conclusions::needs_rig(campaign).then(|| e.to_string()),
        ),
    };
    let results = Results {
        schema_version: RESULTS_SCHEMA_VERSION,
        servoid_version: env!("CARGO_PKG_VERSION").to_string(),
        campaign: conclusions::summary(campaign),
        rig: rig_result,
        rig_error,
        runs: runs.results,
        ccf: Vec::new(),
        csi: runs.csi,
        comparisons: Vec::new(),
        sensitivity: None,
        drift: None,
        warnings,
        manifest: campaign.manifest.clone(),
    };
    let rig = rig_for_runs.ok().map(|(p, ..)| p);
    let (mut results, mut campaign_figures) =
        campaign_level(campaign, results, rig, noise.as_ref(), runs.overlay, sink)?;
    let drawn: Vec<&PageFigure> = runs
        .figures
        .iter()
        .flatten()
        .chain(&campaign_figures)
        .collect();
    let (numbered, numbered_warnings) =
        sink.numbered(&campaign.manifest.numbered_figures, &drawn)?;
    results.warnings.extend(numbered_warnings);
    campaign_figures.extend(numbered);
    sink.finish()?;
    Ok(Analysed {
        results,
        run_figures: runs.figures,
        campaign_figures,
        run_tables: runs.tables,
        seconds: runs.seconds,
        cached: runs.cached,
    })
}

/// Every run's first pass, in parallel, in manifest order; an
/// identification run's bins go to `scratch` as its pass ends.
fn first_passes(
    campaign: &Campaign,
    sink: &Sink<'_>,
    observer: &dyn Observer,
    scratch: Option<&Arc<Scratch>>,
) -> Result<Vec<FirstPass>, WriteError> {
    // One run per task: rayon otherwise hands each thread a block of runs
    // it works through alone once started, so a block of slow runs (spring
    // runs with their delay test) holds one core while the other has
    // nothing left to take.
    campaign
        .runs
        .par_iter()
        .with_max_len(1)
        .map(|plan| {
            let mut first = first_pass(campaign, plan, sink, observer);
            if let (Ok(FirstPass::Done(d)), Some(scratch)) = (&mut first, scratch)
                && let Some(e) = d.kept.estimate.as_mut()
            {
                e.move_bins(|data| scratch.keep(data).ok());
            }
            first.map_err(|e| e.in_run(&plan.id))
        })
        .collect()
}

/// Every run's second pass, in parallel (one run per task, as the first),
/// in manifest order; each run's tracking goes to `parked` once the run's
/// own files are written.
fn second_passes(
    campaign: &Campaign,
    first: Vec<FirstPass>,
    rig: &RigOutcome,
    sink: &Sink<'_>,
    observer: &dyn Observer,
    parked: Option<&Arc<Scratch>>,
) -> Result<Vec<Done>, WriteError> {
    campaign
        .runs
        .par_iter()
        .zip(first)
        .with_max_len(1)
        .map(|(plan, first)| {
            let mut done = second_pass(campaign, plan, first, rig, sink, observer)
                .map_err(|e| e.in_run(&plan.id))?;
            if let (Some(parked), Some(tracking)) = (parked, &mut done.kept.result.tracking) {
                tracking.park(|bytes| parked.keep_part(bytes).ok());
            }
            Ok(done)
        })
        .collect()
}

/// The rig from what the first pass's runs give it (their estimates move
/// there and are freed with its fit).
fn establish_rig(
    campaign: &Campaign,
    first: &mut [FirstPass],
    warnings: &mut Vec<Warning>,
) -> Result<(RigParams, RigResult), Arc<RigError>> {
    let inputs: Vec<RigInput> = first.iter_mut().map(FirstPass::rig_input).collect();
    let rig = rig::establish(campaign, inputs.iter(), warnings).map_err(Arc::new);
    drop(inputs);
    // The rig's fit and the FRFs it read are freed beneath the runs' results.
    super::allocator::give_back();
    rig
}

/// What each run's second pass reads of the rig: its parameters, their
/// covariance and what the prediction carries beyond them (the seals).
fn for_runs(
    campaign: &Campaign,
    rig: &Result<(RigParams, RigResult), Arc<RigError>>,
) -> RigOutcome {
    rig.as_ref()
        .map(|(p, r)| {
            let smoothing = campaign.joint.friction_smoothing_m_per_s;
            let extras = r
                .joint
                .as_ref()
                .map(|j| crate::analysis::joint::extras(j, smoothing))
                .unwrap_or_default();
            (*p, r.covariance, extras)
        })
        .map_err(Arc::clone)
}

/// What the campaign learns once every run is done
/// (`analysis::campaign`), with the stiffness sensitivity and the
/// campaign's own figures.
fn campaign_level(
    campaign: &Campaign,
    mut results: Results,
    rig: Option<RigParams>,
    noise: Option<&NoiseSource>,
    overlay: Vec<OverlayRun>,
    sink: &Sink<'_>,
) -> Result<(Results, Vec<PageFigure>), WriteError> {
    conclusions::compare_runs(campaign, &mut results, rig.as_ref());
    if let Some(rig) = &rig {
        results.sensitivity =
            super::sensitivity::sensitivity(campaign, rig, &results, noise, sink.cache)?;
    }
    conclusions::conclude(campaign, &mut results);
    let specs = catalogue::campaign_figures(overlay, results.sensitivity.as_ref());
    let (figures, figure_warnings) = sink.figures(&specs)?;
    results.warnings.extend(figure_warnings);
    Ok((results, figures))
}

/// The runs' outcomes gathered in manifest order.
struct PerRun {
    results: Vec<RunResult>,
    figures: Vec<Vec<PageFigure>>,
    tables: Vec<Vec<String>>,
    seconds: Vec<f64>,
    cached: Vec<bool>,
    overlay: Vec<OverlayRun>,
    csi: Vec<Csi>,
}

impl PerRun {
    /// Gather `done`; their figures' warnings go to `warnings`.
    fn of(done: Vec<Done>, warnings: &mut Vec<Warning>) -> Self {
        let n = done.len();
        let mut all = PerRun {
            results: Vec::with_capacity(n),
            figures: Vec::with_capacity(n),
            tables: Vec::with_capacity(n),
            seconds: Vec::with_capacity(n),
            cached: Vec::with_capacity(n),
            overlay: Vec::new(),
            csi: Vec::new(),
        };
        for d in done {
            all.csi.extend(d.kept.csi);
            all.overlay.extend(d.kept.overlay);
            all.results.push(d.kept.result);
            all.figures.push(d.figures);
            all.tables.push(d.tables);
            warnings.extend(d.figure_warnings);
            all.seconds.push(d.seconds);
            all.cached.push(d.cached);
        }
        all
    }
}

/// What a run is after the first pass.
enum FirstPass {
    /// A validation run waits for the rig, with what the joint fit read of
    /// its log.
    Waiting(RigInput),
    /// A run done without the rig.
    Done(Box<Done>),
}

impl FirstPass {
    /// What the run gives the rig's identification: its estimate moves
    /// there (nothing after the rig reads it; the cache has stored it), so
    /// the identification runs' FRFs are held once.
    fn rig_input(&mut self) -> RigInput {
        match self {
            FirstPass::Waiting(read) => read.clone(),
            FirstPass::Done(d) => match (&d.log_error, d.kept.estimate.take()) {
                (Some(e), _) => RigInput::Failed(e.clone()),
                (None, Some(e)) => RigInput::Estimate(e),
                (None, None) => RigInput::Nothing,
            },
        }
    }
}

/// The first pass of one run: everything that does not need the rig.
fn first_pass(
    campaign: &Campaign,
    plan: &RunPlan,
    sink: &Sink<'_>,
    observer: &dyn Observer,
) -> Result<FirstPass, WriteError> {
    if plan.role == Role::Validation {
        let read = campaign.joint.include_validation && campaign.identifies_rig();
        return Ok(FirstPass::Waiting(match read {
            true => crate::analysis::run_result::validation_evidence(campaign, plan),
            false => RigInput::Nothing,
        }));
    }
    let parts: [&dyn std::fmt::Debug; 2] = [&"first pass", &campaign.identification];
    let wants = sink.wants();
    run_once(campaign, plan, sink, observer, Some(&parts), |file| {
        step::without_rig(campaign, plan, file, wants)
    })
    .map(|d| FirstPass::Done(Box::new(d)))
}

/// The second pass of one run: a validation run's whole work, and for the
/// others what depends on the rig.
fn second_pass(
    campaign: &Campaign,
    plan: &RunPlan,
    first: FirstPass,
    rig: &RigOutcome,
    sink: &Sink<'_>,
    observer: &dyn Observer,
) -> Result<Done, WriteError> {
    let wants = sink.wants();
    let mut done = match first {
        FirstPass::Waiting(read) => {
            let fitted = match &read {
                RigInput::Validation(e) => Some(e.sha256.as_str()),
                _ => None,
            };
            // The key holds the rig at this run's P gain and what the
            // prediction carries beyond it: a new rig redoes the run.
            let keyed = rig
                .as_ref()
                .ok()
                .map(|(r, cov, seals)| (r.at_p_gain(plan.p_gain), *cov, *seals));
            // The compensator's settings and the stiffnesses it is swept
            // over decide the outcome too.
            let sweep = (
                &campaign.compensator,
                campaign.sensitivity.range,
                campaign.sensitivity.points,
            );
            let parts = keyed
                .as_ref()
                .map(|(r, cov, seals)| -> [&dyn std::fmt::Debug; 6] {
                    [
                        &"validation",
                        &campaign.identification,
                        r,
                        cov,
                        seals,
                        &sweep,
                    ]
                });
            return run_once(
                campaign,
                plan,
                sink,
                observer,
                parts.as_ref().map(|p| &p[..]),
                |file| step::validation(campaign, plan, rig, fitted, file, wants),
            );
        }
        FirstPass::Done(done) => *done,
    };
    let rig_at_p = rig.as_ref().ok().map(|(r, ..)| r.at_p_gain(plan.p_gain));
    if done.log_error.is_some() {
        done.kept.result.a1b0 = rig_at_p.map(|r| r.a1b0_n_per_m_s2);
    } else if let Some(spec) = step::with_rig(&mut done.kept, plan, rig_at_p.as_ref(), wants) {
        let (f, w) = sink.figures(std::slice::from_ref(&spec))?;
        // Figs. 16-17 come right after the run's FRF, as on the page.
        let at = done.figures.len().min(1);
        done.figures.splice(at..at, f);
        done.figure_warnings.extend(w);
    }
    Ok(done)
}

/// One run through the cache, timed and reported to `observer`: its stored
/// outcome when there is one (`parts` decide its key besides its plan and
/// log; None caches nothing), else its `step` computed and its output
/// written.
fn run_once(
    campaign: &Campaign,
    plan: &RunPlan,
    sink: &Sink<'_>,
    observer: &dyn Observer,
    parts: Option<&[&dyn std::fmt::Debug]>,
    step: impl FnOnce(Option<LogFile>) -> Output,
) -> Result<Done, WriteError> {
    observer.event(&Event::RunStarted { id: &plan.id });
    let start = Instant::now();
    let mut done = match sink.probe(campaign, plan, parts) {
        Probed::Hit(stored) => Done::from_stored(*stored),
        Probed::Miss { key, file } => sink.keep(key.as_deref(), step(file))?,
    };
    done.seconds = start.elapsed().as_secs_f64();
    let (id, seconds) = (plan.id.as_str(), done.seconds);
    observer.event(&match done.cached {
        true => Event::RunCached { id, seconds },
        false => Event::RunFinished {
            id,
            status: done.kept.result.status,
            error: done.kept.result.error.as_deref(),
            seconds,
        },
    });
    Ok(done)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::results::Parked;

    /// A campaign whose runs' tracking waits in the scratch file gives the
    /// results.json the same campaign gives with it held, byte for byte.
    #[test]
    fn parked_tracking_gives_the_results_held_tracking_gives() {
        let dir = tempfile::tempdir().unwrap();
        let text = include_str!("../../tests/fixtures/small-simulation.toml");
        let campaign = crate::run::simulate::simulated(text, dir.path());
        let held = analyse(&campaign);
        let work = tempfile::tempdir().unwrap();
        let sink = Sink {
            out_dir: Some(work.path()),
            files: None,
            choice: FigureFormats::None,
            intersample: campaign.identification.intersample,
            cache: None,
        };
        let parked = analyse_with(&campaign, &sink, &Unobserved).unwrap().results;
        let stored = |r: &Results| {
            (r.runs.iter())
                .filter(|r| r.tracking.as_ref().is_some_and(Parked::is_stored))
                .count()
        };
        assert!(
            stored(&parked) >= 2,
            "the validation runs' tracking is parked"
        );
        assert_eq!(stored(&held), 0);
        assert!(
            held.runs
                .iter()
                .any(|r| (r.tracking.as_ref()).is_some_and(|t| t.get().compensator.is_some()))
        );
        assert_eq!(
            serde_json::to_string(&parked).unwrap(),
            serde_json::to_string(&held).unwrap()
        );
        assert_eq!(parked, held);
    }
}
