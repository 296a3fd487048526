//! The runs that settle what last night left open, each with what every
//! answer would mean: a run whose log said the rig is not linear is played
//! again at half its amplitude; structures the joint fit could not tell
//! apart (results.json's `rig.joint.settle`) get the run that parts them,
//! a P gain or a specimen last night's validation runs had (or a new one),
//! in the joint fit (`include_validation`), or the no-specimen run over a
//! wider band.

use crate::design::night::{self, Limits, Night, NightPlan};
use crate::design::spectrum::RunModel;
use crate::manifest::Role;
use crate::model::{LinearSpecimen, SpecimenModel};
use crate::results::{DesignQuestion, DesignedRunResult, Settle};

use super::{Basis, log_like, used};

/// A run added to settle a question, its command and the question.
pub(super) struct Added {
    pub run: DesignedRunResult,
    pub command: Vec<f64>,
    pub question: DesignQuestion,
}

/// Every run the night adds to settle a question. `designed` are the
/// night's own runs, as design.json states them.
pub(super) fn added(
    basis: &Basis,
    plan: &NightPlan,
    night: &Night,
    designed: &[DesignedRunResult],
) -> Vec<Added> {
    let mut added: Vec<Added> = basis
        .runs
        .iter()
        .enumerate()
        .filter_map(|(i, r)| {
            let said = r.nonlinear.as_ref()?;
            let question = format!("last night's run {}: {said}", r.id);
            Some(second_amplitude(
                &designed[i],
                &night.runs[i].command_m,
                question,
                &plan.limits,
            ))
        })
        .collect();
    added.extend(structure_questions(basis, plan, night));
    added
}

/// The share of its amplitude at which a run whose rig answered it
/// nonlinearly is played again.
const SECOND_AMPLITUDE: f64 = 0.5;

/// The run that plays `from`'s command again at [`SECOND_AMPLITUDE`] of
/// its amplitude, and the question it settles.
fn second_amplitude(
    from: &DesignedRunResult,
    command: &[f64],
    question: String,
    limits: &Limits,
) -> Added {
    let share = SECOND_AMPLITUDE;
    let id = format!("{}-half", from.id);
    let peaks = from.peaks.scaled(share);
    let run = DesignedRunResult {
        id: id.clone(),
        role: Role::Fit,
        description: format!(
            "{}'s command at {} of its amplitude: is the rig linear?",
            from.id, share
        ),
        p_gain: from.p_gain,
        specimen: from.specimen,
        command_csv: format!("commands/{id}.csv"),
        command_mat: format!("commands/{id}.mat"),
        log: log_like(&id, &from.log),
        crest_factor: from.crest_factor,
        rms_m: share * from.rms_m,
        peaks,
        bound_by: None,
        used: used(&peaks, limits),
        repeats: Some(from.id.clone()),
        amplitude_share: share,
        band_hz: None,
        command_log: super::command_log_file(&id, &from.log),
    };
    let answers = format!(
        "Run {id} plays {from}'s command at half its amplitude and is fitted on its own (role fit). Where the rig is linear its transfer function (results.json's runs[].fit) agrees with {from}'s within their stds, and its empty lines hold the noise floor. Seal friction lowers the gain at low frequencies, more at the lower amplitude (its describing function grows as the amplitude falls: docs/methods.md, \"Seal friction\"); a spring that stiffens is softer at the lower amplitude; the valve's flow law changes the gain with the velocity. Where the two agree, what last night saw was not the rig's amplitude.",
        from = from.id
    );
    Added {
        command: command.iter().map(|u| share * u).collect(),
        question: DesignQuestion {
            question,
            run: id,
            answers,
        },
        run,
    }
}

/// The runs that part the structures last night's joint fit could not
/// tell apart, one per experiment its ambiguity names (a run that serves
/// two answers both).
fn structure_questions(basis: &Basis, plan: &NightPlan, night: &Night) -> Vec<Added> {
    let Some(ambiguity) = &basis.ambiguity else {
        return Vec::new();
    };
    let said = ambiguity
        .split("; the rig's stds include")
        .next()
        .unwrap_or(ambiguity);
    let question = format!("last night's joint fit: {said}");
    let base = basis
        .runs
        .iter()
        .position(|r| r.role == Role::NoSpecimen)
        .unwrap_or(0);
    let mut added: Vec<Added> = Vec::new();
    for &settle in &basis.settle {
        let made = match settle {
            Settle::PGain | Settle::Specimen | Settle::LoadCell => {
                in_the_fit(basis, plan, night, base, settle)
            }
            Settle::WiderBand => wider_band(basis, plan, base),
            Settle::Longer => None,
        };
        let Some((run, command)) = made else {
            continue;
        };
        let answer = answer(settle, &run);
        if let Some(a) = added.iter_mut().find(|a| a.run.id == run.id) {
            a.question.answers.push(' ');
            a.question.answers.push_str(&answer);
            continue;
        }
        added.push(Added {
            question: DesignQuestion {
                question: question.clone(),
                run: run.id.clone(),
                answers: answer,
            },
            run,
            command,
        });
    }
    added
}

/// A run in the joint fit with a P gain, a specimen or a load cell the
/// identification runs lack: last night's validation run that has it,
/// else the no-specimen run at half its P gain, or a spring about as
/// stiff as the oil column (a2). The base run's command, scaled to the
/// largest amplitude inside the limits on the run's own plant.
fn in_the_fit(
    basis: &Basis,
    plan: &NightPlan,
    night: &Night,
    base: usize,
    settle: Settle,
) -> Option<(DesignedRunResult, Vec<f64>)> {
    let ident = &basis.runs;
    let differs = |v: &&super::BasisRun| match settle {
        Settle::PGain => ident.iter().all(|r| r.p_gain != v.p_gain),
        Settle::Specimen => ident.iter().all(|r| r.specimen != v.specimen),
        _ => true,
    };
    let from = &ident[base];
    let (id, role, p_gain, specimen, log, why) = if let Some(v) =
        basis.validation.iter().find(differs)
    {
        (
            v.id.clone(),
            Role::Validation,
            v.p_gain,
            v.specimen,
            v.log_file.clone(),
            "last night's validation run",
        )
    } else {
        match settle {
            Settle::PGain => (
                format!("{}-p{}", from.id, 0.5 * from.p_gain),
                Role::Validation,
                0.5 * from.p_gain,
                from.specimen,
                from.log_file.clone(),
                "half the P gain",
            ),
            Settle::Specimen => {
                let k = two_digits(plan.rig.a2_n_per_m);
                (
                    format!("spring-{k}"),
                    Role::Spring,
                    from.p_gain,
                    SpecimenModel::Spring {
                        stiffness_n_per_m: k,
                    },
                    from.log_file.clone(),
                    "a spring about as stiff as the oil column (a2); state the stiffness of the one mounted",
                )
            }
            _ => return None,
        }
    };
    let model = RunModel {
        specimen: specimen.linear()?,
        p_gain,
    };
    let fs = plan.sample_rate_hz;
    let played = &night.runs[base];
    let (a, command, peaks, bound_by) =
        night::replayed(&plan.rig, &model, &played.command_m, fs, &plan.limits)?;
    let mut run = DesignedRunResult {
        description: format!(
            "{}'s command with {} ({why}), in the joint fit: which structure is the rig's?",
            from.id,
            specimen_words(&model.specimen, p_gain)
        ),
        command_csv: format!("commands/{id}.csv"),
        command_mat: format!("commands/{id}.mat"),
        log: log_like(&id, log.as_deref().unwrap_or("")),
        id,
        role,
        p_gain,
        specimen,
        crest_factor: played.crest_factor,
        rms_m: a * played.rms_m,
        used: used(&peaks, &plan.limits),
        peaks,
        bound_by: Some(bound_by),
        repeats: None,
        amplitude_share: 1.0,
        band_hz: None,
        command_log: None,
    };
    run.command_log = super::command_log_file(&run.id, &run.log);
    Some((run, command))
}

/// The no-specimen run's odd multisine over a band four times as wide at
/// the top (at most a fifth of the rate), fitted over it: as the night
/// designed over that band would play it (one run alone does not
/// determine the rig its shares are optimal for).
fn wider_band(
    basis: &Basis,
    plan: &NightPlan,
    base: usize,
) -> Option<(DesignedRunResult, Vec<f64>)> {
    let [lo, hi] = plan.band_hz;
    let top = (4.0 * hi).min(0.2 * plan.sample_rate_hz);
    if top < 1.5 * hi {
        return None;
    }
    let wide = NightPlan {
        band_hz: [lo, top],
        ..plan.clone()
    };
    let mut designed = night::design(&wide, None).ok()?;
    let r = designed.runs.swap_remove(base);
    let from = &basis.runs[base];
    let id = format!("{}-wide", from.id);
    let mut run = DesignedRunResult {
        description: format!(
            "{}'s specimen and P gain over {lo}-{top} Hz: a delay or a mode?",
            from.id
        ),
        command_csv: format!("commands/{id}.csv"),
        command_mat: format!("commands/{id}.mat"),
        log: log_like(&id, from.log_file.as_deref().unwrap_or("")),
        id,
        role: from.role,
        p_gain: from.p_gain,
        specimen: from.specimen,
        crest_factor: r.crest_factor,
        rms_m: r.rms_m,
        used: used(&r.peaks, &plan.limits),
        peaks: r.peaks,
        bound_by: Some(r.bound_by),
        repeats: Some(from.id.clone()),
        amplitude_share: 1.0,
        band_hz: Some([lo, top]),
        command_log: None,
    };
    run.command_log = super::command_log_file(&run.id, &run.log);
    Some((run, r.command_m))
}

/// What each answer of `settle`'s run would mean.
fn answer(settle: Settle, run: &DesignedRunResult) -> String {
    let id = &run.id;
    match settle {
        Settle::PGain => format!(
            "Run {id} (P = {}) enters the joint fit (campaign.toml sets identification.joint.include_validation). A mode in the loop changes x1/u with the P gain, one outside the loop does not: the structure that holds at both gains then takes the Schwarz weight and the rig's structure std falls. Where the rivals still share it, the mode sits too far above the band to matter at either gain.",
            run.p_gain
        ),
        Settle::Specimen => format!(
            "Run {id} enters the joint fit (as an identification run, or through identification.joint.include_validation). The piston's mode on the oil column moves with the specimen's stiffness and mass, a mode in the valve or the command path does not: where the piston's structure then takes the weight the piston's mass is real, where it loses it the mode is the valve's."
        ),
        Settle::LoadCell => format!(
            "Run {id} measures the force and enters the joint fit (identification.joint.include_validation): a mode in the command path reaches the force, one on the displacement channel does not."
        ),
        Settle::WiderBand => format!(
            "Run {id} is fitted over {}-{} Hz (its band_hz in campaign.toml): a delay's phase lag keeps growing in proportion to frequency, a mode's gain falls off above it, so over the wider band the structures part and the one the fit then weights is the rig's. Where they still share the weight, neither reaches the band the rig is used in.",
            run.band_hz.map_or(0.0, |b| b[0]),
            run.band_hz.map_or(0.0, |b| b[1])
        ),
        Settle::Longer => String::new(),
    }
}

/// A specimen and P gain in words.
fn specimen_words(s: &LinearSpecimen, p_gain: f64) -> String {
    let what = match *s {
        LinearSpecimen::None => "no specimen".to_string(),
        LinearSpecimen::Spring { stiffness_n_per_m } => {
            format!("a spring of {stiffness_n_per_m} N/m")
        }
        LinearSpecimen::Sdof {
            mass_kg,
            damping_ns_per_m,
            stiffness_n_per_m,
        } => format!(
            "an SDOF specimen ({mass_kg} kg, {damping_ns_per_m} N s/m, {stiffness_n_per_m} N/m)"
        ),
    };
    format!("{what} at P = {p_gain}")
}

/// `x` to two significant digits: a stiffness a lab can find.
fn two_digits(x: f64) -> f64 {
    let step = 10f64.powi(x.abs().log10().floor() as i32 - 1);
    (x / step).round() * step
}
