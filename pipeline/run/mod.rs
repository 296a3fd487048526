//! The campaign runner: the one module that knows every stage. It takes a
//! checked [`Campaign`], runs each run's stages in parallel (results keep the
//! manifest's order, so the output does not depend on the thread count),
//! identifies the rig, predicts and validates, and compares with the
//! published numbers. A failed run is recorded in its result and the batch
//! goes on.

pub mod acquire;
pub mod figures;
pub mod simulate;
pub mod timedomain;

use rayon::prelude::*;

use crate::identify::{self, Estimate, SecondOrder, SpringRun, TfEstimate};
use crate::lti::TransferFunction;
use crate::manifest::{Campaign, CompareMode, Quantity, Role, RunPlan, RunSource};
use crate::model::{self, CnTerm, LinearSdof, LinearSpecimen, RigParams};
use crate::results::{
    CampaignSummary, CcfResult, Comparison, ComparisonStatus, ComplexValue, FitSummary, LogInfo,
    RESULTS_SCHEMA_VERSION, Results, RigResult, RigSource, RunResult, Spread, Status, TfResult,
    TfSource,
};
use crate::simulate::specimen::SpecimenModel;
use acquire::LogStage;
use timedomain::TimeStage;

/// Why one run failed; recorded in that run's result.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RunError {
    #[error(transparent)]
    Acquire(#[from] acquire::AcquireError),
    #[error("the rig parameters are unavailable: {0}")]
    NoRig(String),
    #[error("time-domain validation: {0}")]
    Validation(String),
}

/// What the first stage gives for each run: its own transfer function, and
/// the log's signals and spectra when it has a log.
#[derive(Debug, Clone)]
struct Acquired {
    tf: Option<TransferFunction>,
    /// Covariance of (n0, d1, d0) for a second-order fit.
    cov: Option<[[f64; 3]; 3]>,
    source: TfSource,
    warnings: Vec<String>,
    stage: Option<Box<LogStage>>,
}

/// The first stage of one run: its measured or published transfer function.
fn acquire(campaign: &Campaign, run: &RunPlan) -> Result<Acquired, RunError> {
    match &run.source {
        RunSource::None => Ok(Acquired {
            tf: None,
            cov: None,
            source: TfSource::Model,
            warnings: Vec::new(),
            stage: None,
        }),
        RunSource::Published { tf, .. } => Ok(Acquired {
            tf: Some(tf.clone()),
            cov: None,
            source: TfSource::Published,
            warnings: Vec::new(),
            stage: None,
        }),
        RunSource::Log(plan) => {
            let stage = acquire::log_stage(run, plan, &campaign.identification)?;
            let fit = stage.fit.as_ref();
            Ok(Acquired {
                tf: fit.map(|f| f.tf.clone()),
                cov: fit.and_then(|f| f.second_order_cov()),
                source: TfSource::Fitted,
                warnings: stage.warnings.clone(),
                stage: Some(Box::new(stage)),
            })
        }
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
    let acquired: Vec<Result<Acquired, RunError>> = campaign
        .runs
        .par_iter()
        .map(|r| acquire(campaign, r))
        .collect();

    let mut warnings = Vec::new();
    let rig = establish_rig(campaign, &acquired, &mut warnings);
    let rig_params = rig.as_ref().ok().map(|(p, _)| *p);

    let (mut runs, artifacts): (Vec<RunResult>, Vec<RunArtifacts>) = campaign
        .runs
        .par_iter()
        .zip(acquired)
        .map(|(plan, acq)| run_result(plan, acq, rig_params.as_ref(), rig.as_ref().err()))
        .collect::<Vec<_>>()
        .into_iter()
        .unzip();
    // Validation runs far worse than the others are flagged (the specimen
    // may differ from its log's behaviour).
    let mut validation: Vec<&mut timedomain::ValidationMetrics> = runs
        .iter_mut()
        .filter(|r| r.role == Role::Validation)
        .filter_map(|r| r.validation.as_mut())
        .collect();
    timedomain::flag_outliers(&mut validation);

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
        Err(e) => (None, needs_rig.then_some(e)),
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

/// The rig: identified when the campaign can (Fig. 6), else given.
fn establish_rig(
    campaign: &Campaign,
    acquired: &[Result<Acquired, RunError>],
    warnings: &mut Vec<String>,
) -> Result<(RigParams, RigResult), String> {
    if !campaign.identifies_rig() {
        return match campaign.given_rig {
            Some(p) => Ok((p, given_result(&p))),
            None => Err("the campaign neither gives [rig.parameters] nor has a no_specimen run and a spring run".into()),
        };
    }
    let mut no_spec = Vec::new();
    let mut springs = Vec::new();
    let mut failed = Vec::new();
    for (plan, acq) in campaign.runs.iter().zip(acquired) {
        if !matches!(plan.role, Role::NoSpecimen | Role::Spring) {
            continue;
        }
        let estimate = match acq {
            Ok(Acquired {
                tf: Some(tf), cov, ..
            }) => match SecondOrder::from_tf(tf) {
                Ok(so) => TfEstimate {
                    run: plan.id.clone(),
                    p_gain: plan.p_gain,
                    tf: so,
                    cov: *cov,
                },
                Err(e) => {
                    failed.push(format!("run {}: {e}", plan.id));
                    continue;
                }
            },
            Ok(_) => continue,
            Err(e) => {
                failed.push(format!("run {} failed ({e})", plan.id));
                continue;
            }
        };
        match plan.specimen {
            SpecimenModel::Spring { stiffness_n_per_m } => springs.push(SpringRun {
                stiffness_n_per_m,
                estimate,
            }),
            _ => no_spec.push(estimate),
        }
    }
    if !failed.is_empty() {
        return Err(format!("identification runs failed: {}", failed.join("; ")));
    }
    let ident = identify::identify_rig(&no_spec, &springs).map_err(|e| e.to_string())?;
    if let Some(given) = &campaign.given_rig {
        warnings.push(format!(
            "the manifest gives [rig.parameters] and the campaign identifies the rig; the identified parameters are used (given: beta1 = {:.6e}, a1b0 = {:.6e} at P = {}, a2 = {:.6e}, a3 = {:.6e})",
            given.beta1_per_s, given.a1b0_n_per_m_s2, given.p_gain, given.a2_n_per_m, given.a3_per_s
        ));
    }
    let spread = (ident.per_spring.len() >= 2).then(|| {
        let sd = |f: &dyn Fn(&identify::PerSpring) -> f64| {
            let v: Vec<f64> = ident.per_spring.iter().map(f).collect();
            let mean = v.iter().sum::<f64>() / v.len() as f64;
            (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
        };
        Spread {
            a1b0: sd(&|s| s.a1b0.value),
            a2: sd(&|s| s.a2.value),
            a3: sd(&|s| s.a3.value),
        }
    });
    let params = ident.params();
    let result = RigResult {
        source: RigSource::Identified,
        p_gain: ident.p_gain,
        beta1: ident.beta1,
        a1b0: ident.a1b0,
        a2: ident.a2,
        a3: ident.a3,
        R1: ident.r1,
        valve_time_constant_ms: time_constant(&ident.beta1),
        per_spring: ident.per_spring,
        spread,
    };
    Ok((params, result))
}

/// 1/beta1 in ms, with its propagated std.
fn time_constant(beta1: &Estimate) -> Estimate {
    Estimate {
        value: 1e3 / beta1.value,
        std: beta1.std.map(|s| 1e3 * s / (beta1.value * beta1.value)),
    }
}

fn given_result(p: &RigParams) -> RigResult {
    let beta1 = Estimate::exact(p.beta1_per_s);
    RigResult {
        source: RigSource::Given,
        p_gain: p.p_gain,
        beta1,
        a1b0: Estimate::exact(p.a1b0_n_per_m_s2),
        a2: Estimate::exact(p.a2_n_per_m),
        a3: Estimate::exact(p.a3_per_s),
        R1: Estimate::exact(p.r1()),
        valve_time_constant_ms: time_constant(&beta1),
        per_spring: Vec::new(),
        spread: None,
    }
}

fn run_result(
    plan: &RunPlan,
    acq: Result<Acquired, RunError>,
    rig: Option<&RigParams>,
    rig_error: Option<&String>,
) -> (RunResult, RunArtifacts) {
    let specimen = plan.specimen;
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
        a1b0: rig.map(|r| r.at_p_gain(plan.p_gain).a1b0_n_per_m_s2),
        tf: None,
        force_tf: None,
        fit: None,
        validation: None,
        log: None,
    };
    let acq = match acq {
        Ok(a) => a,
        Err(e) => {
            out.status = Status::Failed;
            out.error = Some(e.to_string());
            return (out, RunArtifacts::default());
        }
    };
    out.warnings = acq.warnings.clone();
    let stage = acq.stage;
    if let (Some(st), RunSource::Log(lp)) = (&stage, &plan.source) {
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
    let rig_at_p = rig.map(|r| r.at_p_gain(plan.p_gain));
    // The model's transfer functions exist for linear specimens only.
    let linear = specimen.linear();
    if let (Some(r), Some(lin)) = (&rig_at_p, &linear)
        && !matches!(lin, LinearSpecimen::None)
    {
        out.force_tf = Some(TfResult::new(&model::tf_f_u(r, lin), TfSource::Model));
    }
    let mut time = None;
    match plan.role {
        Role::Validation => match &rig_at_p {
            Some(r) => {
                out.tf = linear.map(|lin| TfResult::new(&model::tf_x1_u(r, &lin), TfSource::Model));
                if let Some(st) = &stage {
                    match timedomain::validation_run(r, &specimen, &st.log) {
                        Ok(t) => {
                            out.validation = Some(t.metrics.clone());
                            time = Some(t);
                        }
                        Err(e) => {
                            out.status = Status::Failed;
                            out.error = Some(RunError::Validation(e).to_string());
                        }
                    }
                }
            }
            None => {
                out.status = Status::Failed;
                out.error =
                    Some(RunError::NoRig(rig_error.cloned().unwrap_or_default()).to_string());
            }
        },
        _ => {
            out.tf = acq.tf.as_ref().map(|tf| {
                let mut t = TfResult::new(tf, acq.source);
                if let Some(fit) = stage.as_ref().and_then(|s| s.fit.as_ref()) {
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
            if let Some(st) = &stage
                && let Some(fit) = &st.fit
            {
                out.fit = Some(fit_summary(plan, st, fit));
                // The fitted model in the time domain (Figs. 9, 12, 14); a
                // failure here is a warning, the fit stands on its own.
                match timedomain::fitted_run(&fit.tf, &st.log) {
                    Ok(t) => {
                        out.validation = Some(t.metrics.clone());
                        time = Some(t);
                    }
                    Err(e) => out
                        .warnings
                        .push(format!("time-domain check of the fitted model: {e}")),
                }
            }
        }
    }
    (out, RunArtifacts { stage, time })
}

fn fit_summary(plan: &RunPlan, st: &LogStage, fit: &crate::fit::TfFit) -> FitSummary {
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
) -> Option<crate::results::SensitivityResult> {
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
    Some(crate::results::SensitivityResult {
        basis,
        sweep,
        springs_n_per_m: springs,
    })
}

/// The value of a quantity, read back from the results being written (so the
/// comparison is of what a reader sees).
fn lookup(q: &Quantity, r: &Results) -> Option<f64> {
    match q {
        Quantity::Rig(name) => {
            let rig = r.rig.as_ref()?;
            Some(match name.as_str() {
                "beta1" => rig.beta1.value,
                "R1" => rig.R1.value,
                "a1b0" => rig.a1b0.value,
                "a2" => rig.a2.value,
                "a3" => rig.a3.value,
                "valve_time_constant_ms" => rig.valve_time_constant_ms.value,
                _ => return None,
            })
        }
        Quantity::PerSpring { run, name } => {
            let s = r.rig.as_ref()?.per_spring.iter().find(|s| &s.run == run)?;
            Some(match name.as_str() {
                "R2" => s.R2.value,
                "R3" => s.R3.value,
                "a1b0" => s.a1b0.value,
                "a2" => s.a2.value,
                "a3" => s.a3.value,
                _ => return None,
            })
        }
        Quantity::Run { run, name } => {
            let rr = r.runs.iter().find(|x| &x.id == run)?;
            match name.as_str() {
                "a1b0" => rr.a1b0,
                "natural_frequency_hz" => rr.natural_frequency_hz,
                "nrmse_pct" => rr.validation.as_ref().map(|v| v.nrmse_pct),
                "nae_pct" => rr.validation.as_ref().map(|v| v.nae_pct),
                _ => None,
            }
        }
        Quantity::Ccf { run, name } => {
            let c = r.ccf.iter().find(|c| &c.run == run)?;
            Some(match name.as_str() {
                "C1" => c.C1,
                "C2" => c.C2,
                "C3" => c.C3,
                "C4" => c.C4,
                "C5" => c.C5,
                _ => return None,
            })
        }
    }
}

fn compare(campaign: &Campaign, results: &Results) -> Vec<Comparison> {
    campaign
        .references
        .iter()
        .map(|refp| {
            let computed = lookup(&refp.quantity, results);
            let rel_diff = computed.map(|c| {
                let c = match refp.compare {
                    CompareMode::Signed => c,
                    CompareMode::Magnitude => c.abs(),
                };
                (c - refp.published) / refp.published.abs()
            });
            let flag = rel_diff.is_some_and(|d| d.abs() * 100.0 > refp.tolerance_pct);
            let status = match rel_diff {
                None => ComparisonStatus::NotComputed,
                Some(_) if flag => ComparisonStatus::Differs,
                Some(_) => ComparisonStatus::Agrees,
            };
            Comparison {
                quantity: refp.quantity.to_string(),
                published: refp.published,
                computed,
                rel_diff,
                flag,
                compare: refp.compare,
                tolerance_pct: refp.tolerance_pct,
                source: refp.source.clone(),
                status,
            }
        })
        .collect()
}

/// Whether any run failed.
pub fn any_failed(results: &Results) -> bool {
    results.runs.iter().any(|r| r.status == Status::Failed)
}
