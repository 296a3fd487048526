//! A campaign's analysis: each run's first stage in parallel (results keep
//! the manifest's order, so the output does not depend on the thread
//! count), the rig, then each run's model, prediction and time-domain
//! validation, the canonical forms, the stiffness sensitivity and the
//! comparisons with published numbers. A failed run is recorded in its
//! result and the batch goes on. Pure apart from ingest reading the logs.

use std::sync::Arc;

use rayon::prelude::*;

use super::acquire::{AcquireError, Acquired, LogStage, acquire};
use super::compare::compare;
use super::rig::{self, RigError};
use crate::fit::TfFit;
use crate::ingest::Log;
use crate::manifest::{Campaign, Role, RunPlan, RunSource};
use crate::model::{self, CnTerm, LinearSdof, LinearSpecimen, RigParams};
use crate::results::{
    CampaignSummary, CcfResult, ComplexValue, FitSummary, LogInfo, RESULTS_SCHEMA_VERSION, Results,
    RunResult, SensitivityResult, Status, TfResult, TfSource,
};
use crate::simulate::specimen::SpecimenModel;
use crate::validate::{self, Record, TimeStage, ValidateError, ValidationMetrics};

/// Why one run failed; recorded in that run's result.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error(transparent)]
    Acquire(#[from] Arc<AcquireError>),
    #[error("the rig parameters are unavailable: {0}")]
    NoRig(Arc<RigError>),
    #[error("time-domain validation: {0}")]
    Validation(#[from] ValidateError),
}

impl From<Arc<RigError>> for RunError {
    fn from(e: Arc<RigError>) -> Self {
        RunError::NoRig(e)
    }
}

/// What a run leaves for the figures besides its result.
#[derive(Debug, Clone, Default)]
pub struct RunArtifacts {
    pub stage: Option<Box<LogStage>>,
    pub time: Option<TimeStage>,
}

/// A campaign's results and the signals behind them.
#[derive(Debug, Clone)]
pub struct Analysis {
    pub results: Results,
    /// One per run, in manifest order.
    pub artifacts: Vec<RunArtifacts>,
}

/// Analyse a campaign. Pure apart from the ingest stage reading the logs.
pub fn analyse(campaign: &Campaign) -> Results {
    analyse_full(campaign).results
}

/// Analyse a campaign and keep the signals for the figures.
pub fn analyse_full(campaign: &Campaign) -> Analysis {
    let acquired: Vec<Result<Acquired, Arc<AcquireError>>> = campaign
        .runs
        .par_iter()
        .map(|r| acquire(campaign, r).map_err(Arc::new))
        .collect();

    let mut warnings = Vec::new();
    let rig = rig::establish(campaign, &acquired, &mut warnings).map_err(Arc::new);
    let rig_params = rig.as_ref().ok().map(|(p, _)| *p);
    let rig_for_runs = rig.as_ref().map(|(p, _)| p).map_err(Arc::clone);

    let (mut runs, artifacts): (Vec<RunResult>, Vec<RunArtifacts>) = campaign
        .runs
        .par_iter()
        .zip(acquired)
        .map(|(plan, acq)| run_result(plan, acq, rig_for_runs.clone()))
        .collect::<Vec<_>>()
        .into_iter()
        .unzip();
    // Validation runs far worse than the others are flagged (the specimen
    // may differ from its log's behaviour).
    let mut validation: Vec<&mut ValidationMetrics> = runs
        .iter_mut()
        .filter(|r| r.role == Role::Validation)
        .filter_map(|r| r.validation.as_mut())
        .collect();
    validate::flag_outliers(&mut validation);

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
        campaign: CampaignSummary {
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
        },
        rig: rig_result,
        rig_error,
        runs,
        ccf,
        comparisons: Vec::new(),
        sensitivity: None,
        warnings,
        manifest: campaign.manifest.clone(),
    };
    results.sensitivity = rig_params.and_then(|rig| sensitivity(campaign, &rig, &results));
    results.comparisons = compare(campaign, &results);
    Analysis { results, artifacts }
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

/// One run's result from its first stage and the rig (or why there is none).
fn run_result(
    plan: &RunPlan,
    acq: Result<Acquired, Arc<AcquireError>>,
    rig: Result<&RigParams, Arc<RigError>>,
) -> (RunResult, RunArtifacts) {
    let specimen = plan.specimen;
    let rig_at_p = rig.as_ref().ok().map(|r| r.at_p_gain(plan.p_gain));
    let mut out = RunResult {
        id: plan.id.clone(),
        role: plan.role,
        description: plan.description.clone(),
        p_gain: plan.p_gain,
        status: Status::Ok,
        error: None,
        warnings: Vec::new(),
        specimen,
        natural_frequency_hz: specimen.natural_frequency_hz(),
        a1b0: rig_at_p.map(|r| r.a1b0_n_per_m_s2),
        tf: None,
        force_tf: None,
        fit: None,
        validation: None,
        log: None,
    };
    let acq = match acq {
        Ok(a) => a,
        Err(e) => return (failed(out, e.into()), RunArtifacts::default()),
    };
    out.warnings = acq.warnings.clone();
    if let (Some(st), RunSource::Log(lp)) = (&acq.stage, &plan.source) {
        out.log = Some(LogInfo {
            file: lp
                .path
                .file_name()
                .map(|f| f.to_string_lossy().into_owned())
                .unwrap_or_default(),
            sha256: st.log.sha256.clone(),
            sample_rate_hz: st.log.sample_rate_hz,
            n_samples: st.log.n_rows,
            duration_s: st.log.n_rows as f64 / st.log.sample_rate_hz,
        });
    }
    // The model's transfer functions exist for linear specimens only.
    let linear = specimen.linear();
    if let (Some(r), Some(lin)) = (&rig_at_p, &linear)
        && !matches!(lin, LinearSpecimen::None)
    {
        out.force_tf = Some(TfResult::new(&model::tf_f_u(r, lin), TfSource::Model));
    }
    match plan.role {
        Role::Validation => match (rig_at_p, rig) {
            (Some(r), _) => {
                out.tf =
                    linear.map(|lin| TfResult::new(&model::tf_x1_u(&r, &lin), TfSource::Model));
                predicted(out, &r, &specimen, acq.stage)
            }
            (None, Err(e)) => (failed(out, e.into()), RunArtifacts::default()),
            (None, Ok(_)) => unreachable!("rig_at_p is the rig at this run's P gain"),
        },
        _ => fitted(plan, out, acq),
    }
}

/// A run marked failed with its error.
fn failed(mut out: RunResult, e: RunError) -> RunResult {
    out.status = Status::Failed;
    out.error = Some(e.to_string());
    out
}

/// A validation run: the identified rig with its specimen, driven by its
/// measured command (Sec. 4).
fn predicted(
    mut out: RunResult,
    rig_at_p: &RigParams,
    specimen: &SpecimenModel,
    stage: Option<Box<LogStage>>,
) -> (RunResult, RunArtifacts) {
    let Some(st) = &stage else {
        return (out, RunArtifacts::default());
    };
    match validate::validation_run(rig_at_p, specimen, &record(&st.log)) {
        Ok(t) => {
            out.validation = Some(t.metrics.clone());
            (
                out,
                RunArtifacts {
                    stage,
                    time: Some(t),
                },
            )
        }
        Err(e) => (failed(out, e.into()), RunArtifacts { stage, time: None }),
    }
}

/// An identification or fit run: its published or fitted model with the
/// coefficients' uncertainty, and the fitted model in the time domain (Figs.
/// 9, 12, 14). A failure of the time-domain check is a warning: the fit
/// stands on its own.
fn fitted(plan: &RunPlan, mut out: RunResult, acq: Acquired) -> (RunResult, RunArtifacts) {
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
        out.fit = Some(fit_summary(plan, st, fit));
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
    (out, RunArtifacts { stage, time })
}

fn fit_summary(plan: &RunPlan, st: &LogStage, fit: &TfFit) -> FitSummary {
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
    }
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
    let poles = |cn| {
        model::ccf_linear_state_space(&rig, &sdof, cn)
            .eigenvalues()
            .into_iter()
            .map(ComplexValue::from)
            .collect()
    };
    let poles_without_cn: Vec<ComplexValue> = poles(CnTerm::Dropped);
    Some(CcfResult {
        stable_without_cn: poles_without_cn.iter().all(|p| p.re < 0.0),
        run: plan.id.clone(),
        p_gain: plan.p_gain,
        C1: c.C1,
        C2: c.C2,
        C3: c.C3,
        C4: c.C4,
        C5: c.C5,
        poles_with_cn: poles(CnTerm::Kept),
        poles_without_cn,
    })
}

/// The stiffness sweep over 0.01 a2 .. 10 a2 (the paper's springs sit near
/// 0.1 a2), assuming each coefficient is as precise as the campaign's
/// median fitted one, or 0.1 % when the campaign's models carry no
/// uncertainty (published transfer functions).
fn sensitivity(
    campaign: &Campaign,
    rig: &RigParams,
    results: &Results,
) -> Option<SensitivityResult> {
    let springs: Vec<f64> = campaign
        .runs
        .iter()
        .filter_map(|r| match (r.role, r.specimen) {
            (Role::Spring, SpecimenModel::Spring { stiffness_n_per_m }) => Some(stiffness_n_per_m),
            _ => None,
        })
        .collect();
    let mut rel: Vec<f64> = results
        .runs
        .iter()
        .filter(|r| matches!(r.role, Role::NoSpecimen | Role::Spring))
        .filter_map(|r| r.tf.as_ref())
        .flat_map(|tf| tf.rel_std.clone().unwrap_or_default())
        .filter(|v| v.is_finite() && *v > 0.0)
        .collect();
    rel.sort_by(f64::total_cmp);
    let (eps, basis) = match rel.get(rel.len() / 2) {
        Some(&m) if !rel.is_empty() => (
            m,
            format!("median relative std of the campaign's fitted coefficients ({m:.2e})"),
        ),
        _ => (
            1e-3,
            "assumed 0.1 % relative std per coefficient (the campaign's models carry no uncertainty)".to_string(),
        ),
    };
    let a2 = rig.a2_n_per_m;
    let sweep = crate::sensitivity::stiffness_sweep(rig, (0.01 * a2, 10.0 * a2), 61, eps).ok()?;
    Some(SensitivityResult {
        basis,
        sweep,
        springs_n_per_m: springs,
    })
}

/// Whether any run failed.
pub fn any_failed(results: &Results) -> bool {
    results.runs.iter().any(|r| r.status == Status::Failed)
}
