//! The campaign's rig: identified from its no-specimen and spring runs by the
//! paper's procedure (Fig. 6, Eqs. 18-20) when it can be, else the
//! parameters the manifest gives.

use crate::warning::Warning;
use std::fmt;
use std::sync::Arc;

use super::evidence::{Evidence, RigInput, ValidationEvidence};
use super::log_stage::LogStageError;
use super::log_stage::STIFFNESS_MISMATCH;
use crate::frf;
use crate::identify::bins::{Bins, Span};
use crate::identify::consistency::Consistency;
use crate::identify::{self, Estimate, IdentifyError, SecondOrder, SpringRun, TfEstimate};
use crate::manifest::{Campaign, Role, RunPlan};
use crate::model::RigParams;
use crate::model::SpecimenModel;
use crate::results::{RigEstimates, RigResult, RigSource, Spread};

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
        error: Arc<LogStageError>,
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
pub fn establish<'a>(
    campaign: &'a Campaign,
    inputs: impl Iterator<Item = &'a RigInput>,
    warnings: &mut Vec<Warning>,
) -> Result<(RigParams, RigResult), RigError> {
    if !campaign.identifies_rig() {
        return match campaign.given_rig {
            Some(p) => Ok((p, given_result(&p))),
            None => Err(RigError::Unavailable),
        };
    }
    let runs = Gathered::of(campaign, inputs)?;
    let mut ident = identify::identify_rig(&runs.no_spec, &runs.springs)?;
    let slow = slow_gain_pattern(&runs.evidence);
    if let Some(SlowGain::Load { text, largest }) = &slow {
        warnings.push(Warning::new(
            format!(
                "rig: a gain that depends on the load: slow gain {:+.2} % under load, none unloaded",
                100.0 * largest
            ),
            format!("rig: {text}"),
        ));
    }
    // What a run's own warnings already found wrong, named with the run;
    // a gain the load changes is the campaign's finding, not one run's.
    let run_cause = match &slow {
        Some(SlowGain::Load { .. }) => Some(LOAD_GAIN_CAUSE.to_string()),
        _ => runs
            .evidence
            .iter()
            .find_map(|(p, e)| e.cause.as_ref().map(|c| format!("run {}: {c}", p.id))),
    };
    let slow_name = match &slow {
        Some(SlowGain::Reading) => Some("a nonlinear reading (the unloaded run's warning)"),
        Some(SlowGain::Load { .. }) => Some("a gain that depends on the load"),
        None => None,
    };
    let cause_name = narrow_causes(
        &mut ident.consistency,
        &runs,
        run_cause.as_deref(),
        slow_name,
    );
    identification_warnings(campaign, &ident, cause_name.as_deref(), warnings);
    // What the joint fit's misfit, if any, is put down to.
    let known = run_cause.or_else(|| {
        (ident.consistency.consistent == Some(false)).then(|| {
            "the springs' disagreement (the warning above: a stiffness, a log or a unit the manifest gives)"
                .to_string()
        })
    });
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
        &runs.evidence,
        &runs.validation,
        &ident.params(),
        &sequential,
        known.as_deref(),
        matches!(slow, Some(SlowGain::Load { .. })),
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
        spread: spread(&ident.per_spring),
        per_spring: ident.per_spring,
        consistency: Some(ident.consistency),
        covariance: chosen.covariance,
        sequential: Some(sequential),
        joint,
        amplitude_series: amplitude_series(&runs.evidence, &params),
    };
    Ok((params, result))
}

/// Runs whose amplitudes differ by less than this factor repeat a run; they
/// do not make a series.
const SERIES_SPREAD: f64 = 1.2;

/// The identification runs that repeat a specimen (the same role, specimen
/// and P gain) at amplitudes a fifth or more apart, each group's movement
/// with the amplitude against the rig `params` (`identify::amplitude`).
/// Only sweeps' bins carry the displacement's amplitude.
fn amplitude_series(
    evidence: &[(&RunPlan, &Evidence)],
    params: &RigParams,
) -> Vec<identify::amplitude::AmplitudeSeries> {
    // Each run's largest amplitude first, its bins read one run at a time:
    // only a series' runs are read together.
    let mut groups: Vec<Vec<(&RunPlan, Bins<'_>, f64)>> = Vec::new();
    for (p, e) in evidence {
        let Some((bins, ..)) = e.bins().filter(|(b, ..)| b.has_amplitudes()) else {
            continue;
        };
        let largest = bins
            .all()
            .amplitude_m
            .map_or(0.0, |x| identify::amplitude::largest(&x));
        let same =
            |q: &RunPlan| q.role == p.role && q.specimen == p.specimen && q.p_gain == p.p_gain;
        match groups.iter_mut().find(|g| same(g[0].0)) {
            Some(g) => g.push((p, bins, largest)),
            None => groups.push(vec![(p, bins, largest)]),
        }
    }
    groups
        .into_iter()
        .filter(|g| {
            let (lo, hi) = g.iter().fold((f64::INFINITY, 0.0_f64), |(l, h), r| {
                (l.min(r.2), h.max(r.2))
            });
            lo > 0.0 && hi >= SERIES_SPREAD * lo
        })
        .filter_map(|g| {
            let plan = g[0].0;
            let read: Vec<Span<'_>> = g.iter().map(|(_, bins, _)| bins.all()).collect();
            let runs: Vec<identify::amplitude::SeriesRun<'_>> = g
                .iter()
                .zip(&read)
                .filter_map(|((p, ..), d)| {
                    Some(identify::amplitude::SeriesRun {
                        id: &p.id,
                        freq_hz: &d.freq_hz,
                        h: &d.h,
                        variance: &d.variance,
                        amplitude_m: d.amplitude_m.as_deref()?,
                    })
                })
                .collect();
            identify::amplitude::series(
                &params.at_p_gain(plan.p_gain),
                &plan.specimen.linear()?,
                &runs,
            )
        })
        .collect()
}

/// What the identification runs give the rig, sorted by role.
struct Gathered<'a> {
    /// The no-specimen runs' second-order models.
    no_spec: Vec<TfEstimate>,
    /// The spring runs' models with their stiffness.
    springs: Vec<SpringRun>,
    /// Each identification run's model with what its fit was given (the
    /// joint fit's).
    evidence: Vec<(&'a RunPlan, &'a Evidence)>,
    /// The validation runs' FRFs the joint fit may include.
    validation: Vec<(&'a RunPlan, &'a ValidationEvidence)>,
}

impl<'a> Gathered<'a> {
    /// The runs' inputs, or every identification run that failed or gave no
    /// second-order model (Eqs. 18-19 need one).
    fn of(
        campaign: &'a Campaign,
        inputs: impl Iterator<Item = &'a RigInput>,
    ) -> Result<Self, RigError> {
        let mut g = Gathered {
            no_spec: Vec::new(),
            springs: Vec::new(),
            evidence: Vec::new(),
            validation: Vec::new(),
        };
        let mut failed = Vec::new();
        for (plan, input) in campaign.runs.iter().zip(inputs) {
            if let RigInput::Validation(e) = input {
                g.validation.push((plan, e.as_ref()));
            }
            if !matches!(plan.role, Role::NoSpecimen | Role::Spring) {
                continue;
            }
            let run = plan.id.clone();
            let e = match input {
                RigInput::Estimate(e) => e.as_ref(),
                RigInput::Nothing | RigInput::Validation(_) => continue,
                RigInput::Failed(error) => {
                    let error = error.clone();
                    failed.push(FailedRun::Failed { run, error });
                    continue;
                }
            };
            g.evidence.push((plan, e));
            let estimate = match SecondOrder::from_tf(&e.tf) {
                Ok(tf) => TfEstimate {
                    run,
                    p_gain: plan.p_gain,
                    tf,
                    cov: e.cov,
                },
                Err(error) => {
                    failed.push(FailedRun::NotSecondOrder { run, error });
                    continue;
                }
            };
            match plan.specimen {
                SpecimenModel::Spring { stiffness_n_per_m } => g.springs.push(SpringRun {
                    stiffness_n_per_m,
                    estimate,
                }),
                _ => g.no_spec.push(estimate),
            }
        }
        match failed.is_empty() {
            true => Ok(g),
            false => Err(RigError::RunsFailed(failed)),
        }
    }
}

/// The springs' likely causes of disagreement, narrowed to those the runs
/// allow: a run's own finding (FRF settings, a stiffness its force
/// contradicts, a rig not linear) first, and then the pattern's. Springs
/// whose load cells confirm their stated stiffnesses rule out a stiffness
/// typed wrong, a swapped log and a unit, which would each show in the
/// load cell; springs that disagree where their loads differ, with every
/// stiffness confirmed or harmonics of the command in their displacement,
/// point at a gain that depends on the load. The dynamics the model leaves
/// out are dropped where a run's finding explains the disagreement or
/// every spring run's own fit passes its adequacy tests (they would show
/// there as misfit).
fn narrow_causes(
    c: &mut Consistency,
    runs: &Gathered<'_>,
    run_cause: Option<&str>,
    slow_gain: Option<&str>,
) -> Option<String> {
    if c.consistent != Some(false) {
        return None;
    }
    let springs: Vec<Spring<'_>> = runs
        .evidence
        .iter()
        .filter_map(|(p, e)| match p.specimen {
            SpecimenModel::Spring { stiffness_n_per_m } => Some(Spring {
                id: &p.id,
                stated: stiffness_n_per_m,
                evidence: e,
            }),
            _ => None,
        })
        .collect();
    let confirmed = !springs.is_empty()
        && springs.iter().all(|s| {
            s.evidence
                .load_cell
                .is_some_and(|(k, _)| (k / s.stated - 1.0).abs() <= STIFFNESS_MISMATCH)
        });
    let harmonics: Vec<&str> = springs
        .iter()
        .filter(|s| s.evidence.friction_signature || s.evidence.spring_cubic_n_per_m3.is_some())
        .map(|s| s.id)
        .collect();
    let adequate = springs
        .iter()
        .all(|s| s.evidence.adequacy.as_ref().is_some_and(|a| a.passed()));
    let odd = c
        .likely_causes
        .iter()
        .find(|cause| cause.starts_with("spring run "))
        .cloned();
    // Each cause with its name in a few words, for the headline.
    let mut causes: Vec<(String, String)> = run_cause
        .map(|r| {
            let name = match (slow_gain, r.split_once(": ")) {
                (Some(slow), _) => slow.to_string(),
                (None, Some((run, _))) if run.starts_with("run ") => {
                    format!("what {run}'s warnings found")
                }
                _ => r.split(',').next().unwrap_or(r).to_string(),
            };
            (name, r.to_string())
        })
        .into_iter()
        .collect();
    causes.extend(odd.map(|o| ("one spring an outlier".to_string(), o)));
    // The slow parts of the sweeps have already told the load's gain from
    // the reading's (`slow_gain_pattern`).
    if slow_gain.is_none() && (confirmed || !harmonics.is_empty()) {
        causes.push((
            "a gain that depends on the load".to_string(),
            load_dependence(c, &springs, &harmonics),
        ));
    }
    if let Some(swap) = swapped(&springs) {
        causes.push(("stiffnesses or logs swapped".to_string(), swap));
    } else if confirmed {
        c.note += &format!(
            "; every spring's load cell confirms its stated stiffness within {:.0} %, which rules out the manifest's stiffnesses, the runs' logs and the force's unit",
            100.0 * STIFFNESS_MISMATCH
        );
    } else {
        causes.extend(identify::consistency::MANIFEST_CAUSES.iter().map(|s| {
            (
                "a stiffness, log or unit the manifest gives?".to_string(),
                s.to_string(),
            )
        }));
    }
    if run_cause.is_none() && !adequate {
        causes.push((
            "dynamics the model leaves out".to_string(),
            identify::consistency::DYNAMICS_CAUSE.to_string(),
        ));
    }
    let first = causes.first().map(|(name, _)| name.clone());
    c.likely_causes = causes.into_iter().map(|(_, text)| text).collect();
    first
}

/// What a misfit is put down to where the loaded runs' gain changes with
/// amplitude and the unloaded run's does not (`slow_gain_pattern`).
pub const LOAD_GAIN_CAUSE: &str =
    "a gain that depends on the load, which the slow parts of the sweeps show (the warning above)";

/// What the runs' slow stretches say of a gain that changes with amplitude
/// (`frf::slow_cubic`, read where the loop makes the rig follow its
/// command).
enum SlowGain {
    /// The unloaded run's changes: the reading, which every run shares.
    Reading,
    /// The unloaded run's does not, loaded runs' do: the load. The
    /// warning, and the largest change (a share).
    Load { text: String, largest: f64 },
}

/// The pattern of the identification runs' slow gains, when one is
/// significant (`frf::SlowCubic::significant`). Without an unloaded run
/// whose slow gain was read, or with a spring whose load cell finds it
/// stiffening, or with friction's harmonics in a displacement (harmonics
/// in the loaded runs alone are the load's,
/// `evidence::harmonics_under_load_only`),
/// a change has no single cause here and None is given (its own fit names
/// what it found).
fn slow_gain_pattern(evidence: &[(&RunPlan, &Evidence)]) -> Option<SlowGain> {
    let (unloaded, loaded): (Vec<_>, Vec<_>) = evidence
        .iter()
        .filter(|(_, e)| e.slow.is_some())
        .partition(|(p, _)| !p.specimen.loads());
    // Friction changes the slow gain as well, loaded or not.
    if evidence.iter().any(|(_, e)| e.friction_signature)
        && !super::evidence::harmonics_under_load_only(evidence)
    {
        return None;
    }
    if unloaded
        .iter()
        .any(|(_, e)| e.slow.is_some_and(|s| s.significant()))
    {
        return Some(SlowGain::Reading);
    }
    let changed: Vec<(&RunPlan, frf::SlowCubic)> = loaded
        .iter()
        .filter_map(|(p, e)| e.slow.filter(|s| s.significant()).map(|s| (*p, s)))
        .collect();
    let stiffening = evidence
        .iter()
        .any(|(_, e)| e.spring_cubic_n_per_m3.is_some());
    if unloaded.is_empty() || changed.is_empty() || stiffening {
        return None;
    }
    let describe = |s: &frf::SlowCubic| {
        format!(
            "{:+.2} % at {} mm (t = {:.0})",
            100.0 * s.share,
            crate::units::format_number(1e3 * s.amplitude_m, 2),
            s.t.abs()
        )
    };
    let runs: Vec<String> = changed
        .iter()
        .map(|(p, s)| format!("{}'s {}", p.id, describe(s)))
        .collect();
    let (p, s) = unloaded[0];
    let reference = s.slow.map(|s| describe(&s)).unwrap_or_default();
    let falls = changed.iter().all(|(_, s)| s.share < 0.0);
    let why = if falls {
        "the servo-valve's flow falling with the load pressure (its flow-pressure law, Q ~ sqrt(1 - F / F_max)) or a load-dependent leakage: each run's rig is an equivalent linear one at its own load, and the rig's parameters hold near the loads they were identified at"
    } else {
        "each run's rig is an equivalent linear one at its own load, and the rig's parameters hold near the loads they were identified at"
    };
    let largest = changed
        .iter()
        .map(|(_, s)| s.share)
        .max_by(|a, b| a.abs().total_cmp(&b.abs()))
        .unwrap_or(0.0);
    Some(SlowGain::Load {
        largest,
        text: format!(
            "a gain that depends on the load: where the sweeps are below {} Hz the loaded runs' gain against the command changes with amplitude ({}) and the unloaded {}'s does not ({reference}): {why}",
            frf::linearity::SLOW_HZ,
            runs.join(", "),
            p.id,
        ),
    })
}

/// Springs whose load cells read another spring's stated stiffness (each
/// within [`STIFFNESS_MISMATCH`]), in words: the stiffnesses or the logs
/// swapped. None unless every spring whose load cell contradicts its own
/// stiffness reads another's.
fn swapped(springs: &[Spring<'_>]) -> Option<String> {
    let near = |k: f64, stated: f64| (k / stated - 1.0).abs() <= STIFFNESS_MISMATCH;
    let mut pairs = Vec::new();
    for (i, s) in springs.iter().enumerate() {
        let (k, _) = s.evidence.load_cell?;
        if near(k, s.stated) {
            continue;
        }
        let other = springs
            .iter()
            .enumerate()
            .find(|(j, o)| *j != i && near(k, o.stated))?;
        pairs.push(format!(
            "{}'s load cell reads {} N/m, {}'s stated stiffness",
            s.id,
            crate::units::format_number(k, 5),
            other.1.id
        ));
    }
    (!pairs.is_empty()).then(|| {
        format!(
            "{}: the stiffnesses swapped in the manifest or the run table (stiffness_n_per_m), or the runs' logs (each run's log = ...)",
            pairs.join(", ")
        )
    })
}

/// A spring run as the springs' causes read it.
struct Spring<'a> {
    id: &'a str,
    stated: f64,
    evidence: &'a Evidence,
}

/// The springs' disagreement put down to a gain that depends on the load,
/// with what shows it: the parameters that disagree at each spring's load
/// (its load cell's stiffness times its displacement's amplitude), and the
/// runs whose displacement holds harmonics of the command.
fn load_dependence(c: &Consistency, springs: &[Spring<'_>], harmonics: &[&str]) -> String {
    let mut by_load: Vec<(&Spring<'_>, Option<f64>)> = springs
        .iter()
        .map(|s| (s, s.evidence.load_cell.map(|(k, a)| k * a)))
        .collect();
    by_load.sort_by(|a, b| a.1.unwrap_or(0.0).total_cmp(&b.1.unwrap_or(0.0)));
    let loads: Vec<String> = by_load
        .iter()
        .map(|(s, load)| match load {
            Some(f) => format!("{} at {} N", s.id, crate::units::format_number(*f, 3)),
            None => s.id.to_string(),
        })
        .collect();
    let which: Vec<&str> = c
        .checks
        .iter()
        .filter(|t| !t.consistent)
        .map(|t| t.parameter.as_str())
        .collect();
    let mut text = format!(
        "a gain that depends on the load: {} differ between springs loaded differently ({})",
        which.join(", "),
        loads.join(", ")
    );
    if !harmonics.is_empty() {
        text += &format!(
            ", and {} hold harmonics of the command (the rig is not linear at their amplitude)",
            harmonics.join(", ")
        );
    }
    text + ": the servo-valve's flow falling with the load pressure, seal friction, or a spring that stiffens; each spring's rig is an equivalent linear one at its own load"
}

/// What the lab reads of the sequential identification: a given rig the
/// identified one replaces, springs that disagree, and an agreement that
/// could not be tested.
fn identification_warnings(
    campaign: &Campaign,
    ident: &identify::RigIdentification,
    cause_name: Option<&str>,
    warnings: &mut Vec<Warning>,
) {
    if let Some(given) = &campaign.given_rig {
        warnings.push(Warning::new(
            "the identified rig replaces the manifest's [rig.parameters]",
            format!(
                "the manifest gives [rig.parameters] and the campaign identifies the rig; the identified parameters are used (given: beta1 = {:.6e}, a1b0 = {:.6e} at P = {}, a2 = {:.6e}, a3 = {:.6e})",
                given.beta1_per_s, given.a1b0_n_per_m_s2, given.p_gain, given.a2_n_per_m, given.a3_per_s
            ),
        ));
    }
    if ident.consistency.consistent == Some(false) {
        let worst = ident
            .consistency
            .checks
            .iter()
            .filter(|t| !t.consistent)
            .min_by(|a, b| a.p_value.total_cmp(&b.p_value));
        let shown = worst.map_or(String::new(), |t| {
            format!(" ({} p = {:.0e})", t.parameter, t.p_value)
        });
        warnings.push(Warning::new(
            format!(
                "rig: the springs disagree{shown}; likely: {}",
                cause_name.unwrap_or("see the detail")
            ),
            format!(
                "rig: {}; likely causes: {}",
                ident.consistency.note,
                ident.consistency.likely_causes.join("; ")
            ),
        ));
    }
    // A check that could not be made is said where the lab reads, not only
    // in results.json: unless the springs are published
    // transfer functions, which carry no covariance by what they are.
    if let Some(why) = ident.consistency.untested
        && why != identify::consistency::Untested::NoCovariance
    {
        let runs: Vec<&str> = ident.per_spring.iter().map(|s| s.run.as_str()).collect();
        let n = runs.len();
        warnings.push(Warning::new(
            format!(
                "rig: the springs' agreement was not tested ({n} spring run{})",
                if n == 1 { "" } else { "s" }
            ),
            format!(
                "rig: the springs' agreement was not tested (spring runs {}): {}",
                runs.join(", "),
                ident.consistency.note
            ),
        ));
    }
}

/// The spread of the springs' a1b0, a2 and a3 (sample std), with two
/// springs or more.
fn spread(per_spring: &[identify::PerSpring]) -> Option<Spread> {
    (per_spring.len() >= 2).then(|| {
        let sd = |f: &dyn Fn(&identify::PerSpring) -> f64| {
            let v: Vec<f64> = per_spring.iter().map(f).collect();
            let mean = v.iter().sum::<f64>() / v.len() as f64;
            (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
        };
        Spread {
            a1b0: sd(&|s| s.a1b0.value),
            a2: sd(&|s| s.a2.value),
            a3: sd(&|s| s.a3.value),
        }
    })
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
        amplitude_series: Vec::new(),
    }
}
