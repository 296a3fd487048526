//! The campaign's rig: identified from its no-specimen and spring runs by the
//! paper's procedure (Fig. 6, Eqs. 18-20) when it can be, else the
//! parameters the manifest gives.

use std::fmt;
use std::sync::Arc;

use super::acquire::AcquireError;
use super::evidence::RigInput;
use crate::identify::{self, Estimate, IdentifyError, SecondOrder, SpringRun, TfEstimate};
use crate::manifest::{Campaign, Role};
use crate::model::RigParams;
use crate::results::{RigEstimates, RigResult, RigSource, Spread};
use crate::simulate::specimen::SpecimenModel;

/// Why the campaign has no rig parameters.
#[derive(Debug, thiserror::Error)]
pub enum RigError {
    #[error(
        "the campaign neither gives [rig.parameters] nor has a no_specimen run and a spring run"
    )]
    Unavailable,
    #[error("identification runs failed: {}", join(.0))]
    RunsFailed(Vec<FailedRun>),
    #[error(transparent)]
    Identify(#[from] IdentifyError),
}

/// An identification run that gave no usable second-order model.
#[derive(Debug)]
pub enum FailedRun {
    /// The run itself failed.
    Failed {
        run: String,
        error: Arc<AcquireError>,
    },
    /// Its model is not the second-order form Eqs. 18-19 need.
    NotSecondOrder { run: String, error: IdentifyError },
}

impl fmt::Display for FailedRun {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FailedRun::Failed { run, error } => write!(f, "run {run} failed ({error})"),
            FailedRun::NotSecondOrder { run, error } => write!(f, "run {run}: {error}"),
        }
    }
}

fn join(failed: &[FailedRun]) -> String {
    failed
        .iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join("; ")
}

/// The rig: identified when the campaign can (Fig. 6), else given. A given
/// rig beside an identifying campaign is reported in `warnings`. `inputs`
/// follow the campaign's runs.
pub(super) fn establish<'a>(
    campaign: &Campaign,
    inputs: impl Iterator<Item = &'a RigInput>,
    warnings: &mut Vec<String>,
) -> Result<(RigParams, RigResult), RigError> {
    if !campaign.identifies_rig() {
        return match campaign.given_rig {
            Some(p) => Ok((p, given_result(&p))),
            None => Err(RigError::Unavailable),
        };
    }
    let mut no_spec = Vec::new();
    let mut springs = Vec::new();
    let mut failed = Vec::new();
    let mut evidence = Vec::new();
    let mut validation = Vec::new();
    for (plan, input) in campaign.runs.iter().zip(inputs) {
        if let RigInput::Validation(e) = input {
            validation.push((plan, e.as_ref()));
        }
        if !matches!(plan.role, Role::NoSpecimen | Role::Spring) {
            continue;
        }
        if let RigInput::Estimate(e) = input {
            evidence.push((plan, e.as_ref()));
        }
        let run = plan.id.clone();
        let estimate = match input {
            RigInput::Estimate(e) => match SecondOrder::from_tf(&e.tf) {
                Ok(so) => TfEstimate {
                    run,
                    p_gain: plan.p_gain,
                    tf: so,
                    cov: e.cov,
                },
                Err(error) => {
                    failed.push(FailedRun::NotSecondOrder { run, error });
                    continue;
                }
            },
            RigInput::Nothing | RigInput::Validation(_) => continue,
            RigInput::Failed(error) => {
                failed.push(FailedRun::Failed {
                    run,
                    error: error.clone(),
                });
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
        return Err(RigError::RunsFailed(failed));
    }
    let ident = identify::identify_rig(&no_spec, &springs)?;
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
    if ident.consistency.consistent == Some(false) {
        warnings.push(format!(
            "rig: {}; likely causes: {}",
            ident.consistency.note,
            ident.consistency.likely_causes.join("; ")
        ));
    }
    // A check that could not be made is said where the lab reads, not only
    // in results.json (issue 24): unless the springs are published
    // transfer functions, which carry no covariance by what they are.
    if let Some(why) = ident.consistency.untested
        && why != identify::consistency::Untested::NoCovariance
    {
        let runs: Vec<&str> = ident.per_spring.iter().map(|s| s.run.as_str()).collect();
        warnings.push(format!(
            "rig: the springs' agreement was not tested (spring runs {}): {}",
            runs.join(", "),
            ident.consistency.note
        ));
    }
    let sequential = RigEstimates {
        beta1: ident.beta1,
        a1b0: ident.a1b0,
        a2: ident.a2,
        a3: ident.a3,
        R1: ident.r1,
        covariance: ident.covariance,
    };
    let joint = super::joint::joint(
        campaign,
        &evidence,
        &validation,
        &ident.params(),
        &sequential,
        warnings,
    );
    let (source, chosen) = match joint.as_ref().and_then(super::joint::used_estimates) {
        Some(e) => (RigSource::Joint, e),
        None => (RigSource::Identified, sequential.clone()),
    };
    let params = RigParams {
        beta1_per_s: chosen.beta1.value,
        a1b0_n_per_m_s2: chosen.a1b0.value,
        a2_n_per_m: chosen.a2.value,
        a3_per_s: chosen.a3.value,
        p_gain: ident.p_gain,
    };
    let result = RigResult {
        source,
        p_gain: ident.p_gain,
        beta1: chosen.beta1,
        a1b0: chosen.a1b0,
        a2: chosen.a2,
        a3: chosen.a3,
        R1: chosen.R1,
        valve_time_constant_ms: time_constant(&chosen.beta1),
        per_spring: ident.per_spring,
        spread,
        consistency: Some(ident.consistency),
        covariance: chosen.covariance,
        sequential: Some(sequential),
        joint,
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
        consistency: None,
        covariance: None,
        sequential: None,
        joint: None,
    }
}
