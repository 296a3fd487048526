//! What a campaign learns from its runs together, once each is done: the
//! validation runs far worse than the others, each SDOF run's canonical
//! form (Eqs. 34-35) with and without the c_n term, the notes the runs
//! share, and the comparisons with published numbers.

use crate::analysis::compare::compare;
use crate::manifest::{Campaign, Role, RunPlan};
use crate::model::{self, CnTerm, LinearSdof, RigParams, SpecimenModel};
use crate::results::{CampaignSummary, CcfResult, ComplexValue, Results, RunResult};
use crate::tracking::compensator::CompensatorOutcome;
use crate::validate::{self, ValidationMetrics};
use crate::warning::Warning;

/// The runs judged against each other: outliers flagged, and with a rig
/// each SDOF validation run's canonical form.
pub fn compare_runs(campaign: &Campaign, results: &mut Results, rig: Option<&RigParams>) {
    flag_outliers(&mut results.runs);
    if let Some(rig) = rig {
        results.ccf = campaign
            .runs
            .iter()
            .filter_map(|r| ccf_result(rig, r))
            .collect();
    }
}

/// The campaign's closing notes (a Monte Carlo not run, a stated cutoff no
/// compensator could use) and its comparisons with published numbers.
pub fn conclude(campaign: &Campaign, results: &mut Results) {
    if let Some(note) = results
        .sensitivity
        .as_ref()
        .and_then(|s| s.monte_carlo_note.as_ref())
    {
        results.warnings.push(Warning::new(
            "sensitivity.monte_carlo: not run",
            format!("sensitivity.monte_carlo: not run: {note}"),
        ));
    }
    if let Some(w) = stated_cutoff_unused(campaign, results) {
        results.warnings.push(w);
    }
    results.comparisons = compare(campaign, results);
}

/// Whether a missing rig is worth an error in results.json: the campaign
/// validates, identifies or gives one.
pub fn needs_rig(campaign: &Campaign) -> bool {
    campaign.runs.iter().any(|r| r.role == Role::Validation)
        || campaign.identifies_rig()
        || campaign.given_rig.is_some()
}

/// A stated `compensator.cutoff_hz` no run's compensator could be designed
/// with: each run's note says why, and the campaign says it once, naming
/// the key.
fn stated_cutoff_unused(campaign: &Campaign, results: &Results) -> Option<Warning> {
    let fc = campaign.compensator.cutoff_hz?;
    // Each run's compensator: whether it was designed, and why not.
    let outcomes: Vec<(&str, bool, Option<String>)> = results
        .runs
        .iter()
        .filter_map(|r| {
            let tracking = r.tracking.as_ref()?.get();
            let c: &CompensatorOutcome = tracking.compensator.as_ref()?;
            Some((r.id.as_str(), c.design.is_some(), c.note.clone()))
        })
        .collect();
    if outcomes.iter().any(|(_, designed, _)| *designed) {
        return None;
    }
    let notes: Vec<(&str, &str)> = outcomes
        .iter()
        .filter_map(|(id, _, note)| Some((*id, note.as_deref()?)))
        .collect();
    let (_, why) = notes.first()?;
    let headline = format!("compensator.cutoff_hz = {fc} Hz: no compensator could be designed");
    Some(Warning::new(
        headline,
        format!(
            "compensator.cutoff_hz = {fc} Hz: no compensator was designed ({why}, for {})",
            notes
                .iter()
                .map(|(id, _)| format!("run {id}"))
                .collect::<Vec<_>>()
                .join(", ")
        ),
    ))
}

/// The campaign as results.json names it.
pub fn summary(campaign: &Campaign) -> CampaignSummary {
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
