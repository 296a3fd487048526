//! The joint grey-box fit in the campaign: the identification
//! runs' FRFs to `identify::joint::select`, its outcome beside the sequential
//! estimate, and the decision which of the two the campaign uses.
//!
//! The joint estimate is used (with `identification.joint.rig = "auto"`)
//! when the chosen structure converged to a physical rig and is adequate:
//! it passes the cost test, or it explains the data about as well as the
//! sequential per-run fits do (a reduced chi-square within 10 % of theirs
//! pooled). The per-run fits have three free coefficients per run against
//! the joint fit's 4-7 shared parameters, so a joint fit that does as well
//! shows that the physical model is not what limits the fit: the noise
//! estimate or something neither model has is.

use super::evidence::{Evidence, ValidationEvidence};
use crate::fit::adequacy::Adequacy;
use crate::identify::bins::Bins;
use crate::identify::joint::{
    self, Candidate, Choice, JointFit, JointIdentification, JointOptions, JointRun, Output,
    P_SIGNIFICANT, Place, RunSpread, Selection, Structure, StructureSpread,
};
use crate::identify::{Estimate, FitData, IdentificationPlan};
use crate::manifest::{Campaign, JointRig, Role, RunPlan};
use crate::model::{RigExtras, RigParams, Seals};
use crate::results::{
    FTestResult, JointCandidate, JointParameter, JointResult, RigEstimates, RunAdequacy, Settle,
};
use crate::warning::Warning;

/// How much worse than the sequential fits' pooled reduced chi-square the
/// joint fit's may be and still count as adequate.
const AS_GOOD_AS_SEQUENTIAL: f64 = 1.1;

/// Where a structure's mode sits, in words; `split` when the force FRFs
/// tell the command path from the measurement path (without them the
/// command-path fit stands for both).
fn place(s: Structure, split: bool) -> Option<&'static str> {
    if s == Structure::DelayValvePiston {
        return Some("loop and actuator (piston mass)");
    }
    if s.piston() {
        return Some("actuator (piston mass)");
    }
    Some(match s.place()? {
        Place::Loop => "loop",
        Place::Command if split => "command path",
        Place::Command => "in series",
        Place::Measurement => "measurement path",
    })
}

/// A structure as the ambiguity warning names it.
fn described(s: Structure, split: bool) -> String {
    match place(s, split) {
        Some("loop") => format!("\"{}\" (a mode in the loop)", s.as_str()),
        Some(_) if s == Structure::DelayValvePiston => format!(
            "\"{}\" (a mode in the loop and the piston's mass)",
            s.as_str()
        ),
        Some("in series") => format!(
            "\"{}\" (a mode in series, in the command or the measurement path)",
            s.as_str()
        ),
        Some(_) if s.piston() => {
            format!("\"{}\" (the piston's mass on the oil column)", s.as_str())
        }
        Some(p) => format!("\"{}\" (a mode in the {p})", s.as_str()),
        None if s == Structure::Delay => "\"delay\" (a delay alone)".into(),
        None => format!("\"{}\" (the paper's model alone)", s.as_str()),
    }
}

/// Runs whose rates differ by less than this share are one DAQ's: a rate
/// fitted to jittered stamps differs from another log's in its last
/// digits, and the hold's response with it by less than a part in 1e6.
const SAME_RATE: f64 = 1e-6;

/// The joint fit of the identification runs in `evidence` (and the
/// validation runs' FRFs in `validation`, when the manifest includes them),
/// from the sequential rig `start`: what it found, and whether the campaign
/// uses it. Warnings (a failed or inadequate fit, a manifest structure the
/// data reject) go to `warnings`. None when no run has bins to fit
/// (published models only). `load_gain`: the loaded runs' slow gain shows
/// the load changing it, the servo-valve's flow-pressure law's signature,
/// where the law is tried.
#[allow(clippy::too_many_arguments)]
pub fn joint(
    campaign: &Campaign,
    evidence: &[(&RunPlan, &Evidence)],
    validation: &[(&RunPlan, &ValidationEvidence)],
    start: &RigParams,
    sequential: &RigEstimates,
    known: Option<&str>,
    load_gain: bool,
    warnings: &mut Vec<Warning>,
) -> Option<JointResult> {
    let (fitted, identification_frfs) = fitted_frfs(evidence, validation)?;
    let fs = fitted[0].3;
    if fitted.iter().any(|f| (f.3 / fs - 1.0).abs() > SAME_RATE) {
        warnings.push(Warning::new(
            "rig: no joint fit: the runs were logged at different sample rates",
            "rig: no joint fit: the runs it would fit were logged at different sample rates; the sequential estimate is used",
        ));
        return None;
    }
    let runs: Vec<JointRun<'_>> = fitted
        .iter()
        .map(|(p, output, (bins, bin_hz, lag), _, cubic)| JointRun {
            specimen: p.specimen.linear().expect("filtered"),
            p_gain: p.p_gain,
            output: *output,
            bins: *bins,
            bin_hz: *bin_hz,
            lag: *lag,
            spring_cubic_n_per_m3: *cubic,
        })
        .collect();
    let mut opts = campaign_options(campaign, evidence, start, fs, load_gain);
    let choice = campaign.joint.structure;
    let band_top = fitted.iter().map(|(p, ..)| p.band_hz.1).fold(0.0, f64::max);
    let mut ident = joint::identify(runs.clone(), start, &opts, choice, band_top);
    let plans: Vec<&RunPlan> = fitted.iter().map(|f| f.0).collect();
    let artifact = super::friction::law_artifact(campaign, &plans, &ident, &opts);
    if artifact.is_some() {
        opts.try_flow_law = false;
        ident = joint::identify(runs, start, &opts, choice, band_top);
    }
    if ident.stiffening_rejected {
        warnings.push(Warning::new(
            "rig: the springs' cubic term is not borne out by their FRFs; the stated k are used",
            STIFFENING_REJECTED,
        ));
    }
    let ids = frf_ids(&fitted);
    let seq_chi2 = sequential_chi2(evidence);
    let stiffening: Vec<(String, f64)> = ids
        .iter()
        .zip(&ident.runs)
        .filter_map(|(id, r)| Some((id.clone(), r.spring_cubic_n_per_m3?)))
        .collect();
    if let Some(note) = stiffening_note(&stiffening) {
        warnings.push(Warning::new(
            format!(
                "rig: not linear: {} stiffening spring(s) taken at their amplitude in the joint fit",
                stiffening.len()
            ),
            format!("rig: {note}"),
        ));
    }
    let mut result = describe(
        &ident, known, &ids, campaign, sequential, seq_chi2, warnings,
    );
    if let Some((data, simulated)) = artifact {
        result.explanation.push_str(&format!(
            "; the valve's flow law the F test took beside the friction (F_max = {data:.0} N) is left out: the rig simulated with its friction alone and fitted again reads a law as strong (F_max = {simulated:.0} N), so it is what the friction's describing function leaves, not the valve's"
        ));
    }
    if let Some(c) = super::friction::corrected(campaign, &plans, &ident, &opts) {
        super::friction::apply(c, &mut result, warnings);
    }
    if ids.len() > identification_frfs {
        result.explanation.push_str(&format!(
            "; the validation runs' FRFs are in the fit (identification.joint.include_validation: {}), so their validation is not independent of the rig",
            ids[identification_frfs..].join(", ")
        ));
    }
    Some(result)
}

/// Each fitted FRF's name: an identification run's id; a validation run's
/// two FRFs by what each measures.
fn frf_ids(fitted: &[Fitted<'_>]) -> Vec<String> {
    fitted
        .iter()
        .map(|(p, output, ..)| match (p.role, output) {
            (Role::Validation, Output::Displacement) => format!("{} x1/u", p.id),
            (Role::Validation, Output::Force) => format!("{} f/u", p.id),
            _ => p.id.clone(),
        })
        .collect()
}

/// An FRF the joint fit is given: its run, what it measures, its bins
/// (with their grid spacing and independent lag), the log's sample rate
/// and a stiffening spring's cubic term (N/m^3).
type Fitted<'a> = (
    &'a RunPlan,
    Output,
    (Bins<'a>, f64, usize),
    f64,
    Option<f64>,
);

/// Each FRF the joint fit is given, the identification runs' first, then
/// the validation runs' (their count is the second value). None when no
/// identification run has bins to fit.
fn fitted_frfs<'a>(
    evidence: &[(&'a RunPlan, &'a Evidence)],
    validation: &[(&'a RunPlan, &'a ValidationEvidence)],
) -> Option<(Vec<Fitted<'a>>, usize)> {
    let mut fitted: Vec<Fitted<'a>> = evidence
        .iter()
        .filter_map(|(p, e)| {
            Some((
                *p,
                Output::Displacement,
                e.bins()?,
                e.sample_rate_hz?,
                e.spring_cubic_n_per_m3,
            ))
        })
        .filter(|(p, ..)| p.specimen.linear().is_some())
        .collect();
    if fitted.is_empty() {
        return None;
    }
    let identification_frfs = fitted.len();
    for (p, v) in validation {
        if p.specimen.linear().is_none() {
            continue;
        }
        let held = |d: &'a FitData| (d.bins(), d.bin_hz, d.lag);
        fitted.push((
            p,
            Output::Displacement,
            held(&v.displacement),
            v.sample_rate_hz,
            None,
        ));
        if let Some(force) = &v.force {
            fitted.push((p, Output::Force, held(force), v.sample_rate_hz, None));
        }
    }
    Some((fitted, identification_frfs))
}

/// The campaign's joint-fit options: [`options`] with the friction and the
/// flow law tried as the runs' evidence says, and the manifest's nameplate
/// and friction width.
fn campaign_options(
    campaign: &Campaign,
    evidence: &[(&RunPlan, &Evidence)],
    start: &RigParams,
    fs: f64,
    load_gain: bool,
) -> JointOptions {
    let mut opts = options(&campaign.identification, start, fs);
    // Harmonics in the loaded runs alone, of springs that do not stiffen,
    // are the flow law's: it is tried, and no friction is fitted for them.
    // Where the unloaded run has them too the friction is fitted, and the
    // law, whose harmonics the friction's hide, is tried beside it.
    let stiffening = evidence
        .iter()
        .any(|(_, e)| e.spring_cubic_n_per_m3.is_some());
    let under_load = !stiffening && super::evidence::harmonics_under_load_only(evidence);
    opts.friction = evidence.iter().any(|(_, e)| e.friction_signature) && !under_load;
    opts.try_flow_law = load_gain || under_load || (opts.friction && !stiffening);
    opts.max_force_nameplate_n = campaign.manifest.rig.max_force_n();
    opts.friction_smoothing_m_per_s = campaign.joint.friction_smoothing_m_per_s;
    opts
}

/// The joint fit's options from the campaign's identification settings,
/// the sequential rig `start` and the runs' sample rate.
fn options(ident: &IdentificationPlan, start: &RigParams, fs: f64) -> JointOptions {
    JointOptions {
        structure: Structure::Plain,
        intersample: ident.intersample,
        sample_rate_hz: fs,
        p_ref: start.p_gain,
        max_iterations: crate::fit::RUN_MAX_ITERATIONS,
        valve_start: (0.0, 0.0),
        piston_start_kg: 1.0,
        delay_start_s: 0.0,
        force_delay_start_s: 0.0,
        max_delay_s: ident.max_delay_s,
        friction: false,
        friction_start_n: 0.0,
        friction_smoothing_m_per_s: None,
        seal_damping: false,
        command_gain: false,
        command_gain_start: 1.0,
        flow_law: false,
        try_flow_law: false,
        max_force_start_n: f64::INFINITY,
        max_force_nameplate_n: None,
        flow_law_held: false,
    }
}

/// The per-run fits' pooled reduced chi-square (their costs over their
/// degrees of freedom), which the joint fit is compared with.
fn sequential_chi2(evidence: &[(&RunPlan, &Evidence)]) -> Option<f64> {
    let seq_adequacy: Vec<&Adequacy> = evidence
        .iter()
        .filter_map(|(_, e)| e.adequacy.as_ref())
        .collect();
    (!seq_adequacy.is_empty()).then(|| {
        seq_adequacy.iter().map(|a| a.cost).sum::<f64>()
            / seq_adequacy.iter().map(|a| a.dof).sum::<usize>() as f64
    })
}

/// The table row of one candidate, with its Schwarz weight.
fn row(
    c: &Candidate,
    chosen: Option<Structure>,
    split: bool,
    weight: Option<f64>,
) -> JointCandidate {
    let fit = c.fit.as_ref().ok();
    JointCandidate {
        structure: c.structure,
        place: place(c.structure, split).map(String::from),
        parameters: fit.map_or(c.structure.names().len(), |f| f.params.len()),
        cost: fit.map(|f| f.cost),
        dof: fit.map(|f| f.dof),
        reduced_chi2: fit.map(|f| f.cost / f.dof as f64),
        cost_z: fit.map(|f| f.adequacy.cost_z),
        bic: c.bic(),
        f_test: c.f_test.map(|t| FTestResult {
            against: t.against,
            f: t.f,
            p_value: t.p_value,
            significant: t.p_value < P_SIGNIFICANT,
        }),
        weight,
        converged: fit.map(|f| f.converged),
        unusable: c.unusable.clone(),
        error: c.fit.as_ref().err().map(ToString::to_string),
        chosen: chosen == Some(c.structure),
    }
}

/// Why the data choose what they choose, in a sentence.
fn explain(sel: &Selection) -> String {
    let Some(auto) = sel.auto else {
        return "no structure gave a usable fit".into();
    };
    let mut parts = Vec::new();
    for c in &sel.candidates {
        let Some(t) = c.f_test else { continue };
        parts.push(format!(
            "{} against {}: F = {:.3e}, p = {:.2e} ({})",
            c.structure.as_str(),
            t.against.as_str(),
            t.f,
            t.p_value,
            if t.p_value < P_SIGNIFICANT {
                "its extra parameters explain more than the residual scatter"
            } else {
                "not significant at p < 0.001"
            }
        ));
    }
    let tests = if parts.is_empty() {
        String::from("the only usable structure")
    } else {
        parts.join("; ")
    };
    let gain = sel.fit().and_then(command_gain_note).unwrap_or_default();
    format!(
        "the data choose \"{}\" by extra-sum-of-squares F tests between nested structures and, among the modes the tests take at different places (the same parameter count), the lowest weighted cost: {tests}{gain}",
        auto.as_str()
    )
}

/// The logged command's gain where the fit took it, in words.
fn command_gain_note(fit: &JointFit) -> Option<String> {
    let g = fit.command_gain?;
    let k = fit.names.iter().position(|n| *n == joint::COMMAND_GAIN)?;
    Some(format!(
        "; the logged command's gain, fitted because the F test takes it over the 1 the rig has at rest (p < 0.001), is {g:.6} +- {:.6}: the logged command reads {:+.4} % from the command the loop follows (another converter's or calibration's scale, or a command of few levels, each level quantised)",
        fit.std[k],
        100.0 * (1.0 / g - 1.0)
    ))
}

/// The valve's flow law as the chosen fit has it: held at the nameplate's
/// F_max (in `result`, said in its explanation), or fitted (a warning).
fn report_flow_law(fit: &JointFit, result: &mut JointResult, warnings: &mut Vec<Warning>) {
    result.flow_law_held_n = fit
        .max_force_n
        .filter(|_| !fit.names.contains(&joint::FLOW_LAW));
    if let Some(f) = result.flow_law_held_n {
        result.explanation.push_str(&format!(
            " The valve's flow law is held at the nameplate's F_max = A P_s = {f:.0} N, which the runs do not determine (the F test does not take it freed, or its std is not below it): the rig is the zero-load one."
        ));
    }
    if let Some(note) = flow_law_note(fit) {
        warnings.push(Warning::new(
            format!(
                "rig: the valve's flow falls with the load: F_max = {:.0} N fitted; the rig is the zero-load one",
                fit.max_force_n.unwrap_or(f64::NAN)
            ),
            format!("rig: {note}"),
        ));
    }
}

/// The flow-pressure law the fit found, in words: F_max with its std, and
/// what it means for the rig at a run's load.
fn flow_law_note(fit: &JointFit) -> Option<String> {
    let fmax = fit.max_force_n?;
    let k = fit.names.iter().position(|n| *n == joint::FLOW_LAW)?;
    Some(format!(
        "the rig is not linear at this amplitude: the servo-valve's flow falls with the load pressure (Merritt's orifice law, r sqrt(1 - sign(r) f / F_max)), which the F test takes over the linear valve (p < 0.001): the joint fit models it by its describing function at each bin's force amplitude, F_max = A P_s = {fmax:.0} +- {:.0} N. The rig's parameters are the zero-load ones; at a run's load its equivalent linear rig differs (the valve's gain falls and its phase moves by about 4 / (3 pi) of the force over F_max), more where the force is a larger share of F_max",
        fit.std[k]
    ))
}

/// What a fit with the valve's flow-pressure law leaves unexplained: on the
/// paper's night at 8-16 % of F_max the residuals of the loaded runs alone
/// correlate (r 0.07-0.14, their costs 0.92-0.96 of their dof), the
/// unloaded run's not (docs/accuracy.md).
const FLOW_LAW_HARMONICS: &str = "the valve flow law's harmonics of the command in the loaded runs, which their FRFs' variances count as noise, and the sweep's amplitude read window by window (the law itself is fitted by its describing function)";

/// What a fit with the piston's friction leaves unexplained.
const FRICTION_HARMONICS: &str = "the seal friction's harmonics of the command, which the FRFs' variances count as noise (the friction itself is fitted)";

/// The friction the fit found, in words: its force with its std, and what
/// that means for the rig at other amplitudes.
fn friction_note(fit: &JointFit, ids: &[String]) -> Option<String> {
    let f = fit.friction_n?;
    let k = fit.names.iter().position(|n| *n == joint::FRICTION)?;
    let unresolved = if fit.structure.piston() {
        ""
    } else {
        UNRESOLVED_PISTON
    };
    let damping = fit
        .seal_damping_ns_per_m
        .zip(fit.names.iter().position(|n| *n == joint::SEAL_DAMPING))
        .map_or(String::new(), |(c, k)| {
            // Taken before the flow law, the damping may have stood in for
            // the law's leakage, and be nil beside it.
            let taken = if fit.max_force_n.is_some() && c.abs() < 2.0 * fit.std[k] {
                "which the data took before the valve's flow law and which, beside it, is nil within its std"
            } else {
                "which the data take"
            };
            format!(
                ", with the seals' viscous damping, {taken}: c_v = {c:.1} +- {:.1} N s/m",
                fit.std[k]
            )
        });
    Some(format!(
        "seal friction: the rig is not linear at this amplitude, its displacement holding odd harmonics of the command (friction's signature), so the joint fit models the piston seals' Coulomb friction by its describing function at each bin's amplitude, over {}: F = {:.3} +- {:.3} N{damping}. The rig's parameters are the actuator's with that friction; its linear response at another amplitude differs (the friction acts as a damper 4 F / (pi V) at velocity amplitude V), and a small command is tracked worse than the model without friction predicts{unresolved}",
        ids.join(", "),
        f,
        fit.std[k]
    ))
}

/// What friction leaves unbounded where the data resolve no piston mass: a
/// light piston sticks at each reversal, which the describing function
/// (a sinusoidal velocity) does not hold, and how far it sticks depends on
/// the mass the data cannot see (docs/accuracy.md, "The nonlinear suite").
const UNRESOLVED_PISTON: &str = ". The data resolve no piston mass (its mode lies above the band), and a light piston sticks at each reversal, which the describing function does not hold: on simulated rigs with a 0.05 kg piston the rig's parameters came out 0.2-0.3 % off with friction of 2 % of the springs' force and up to 1.3 % with 5 %, beyond their stds, and simulating the identified rig with 0.005, 0.05 or 0.2 kg of piston moves that error from -2.4 % to +0.03 % (docs/accuracy.md). Take the stds as a lower bound here; a sweep of larger amplitude makes the friction weigh less";

/// Where the springs' forces show a cubic term the FRFs do not bear out.
const STIFFENING_REJECTED: &str = "rig: the springs' force against their displacement shows a cubic term (the spring runs' warnings), but the joint fit holds better with each stated k than with the springs stiffening, so it takes the stated k: a delay between the load cell and the LVDT, or the rig's own dynamics in the force, can mimic a cubic term; a spring that truly stiffens shows it in its FRF too";

/// How the joint fit took the springs that stiffen, (run, k3) each.
fn stiffening_note(springs: &[(String, f64)]) -> Option<String> {
    if springs.is_empty() {
        return None;
    }
    let each: Vec<String> = springs
        .iter()
        .map(|(id, k3)| format!("{id} (k3 = {k3:.4e} N/m^3)"))
        .collect();
    Some(format!(
        "stiffening springs: the rig is not linear at this amplitude, its springs stiffening, so the joint fit takes each of {} at its describing function k + 3/4 k3 X^2 at each bin's amplitude X, k3 from its force against its displacement: the joint rig holds their stiffening, while the sequential estimate (Eqs. 18-20) takes each stated k as exact",
        each.join(", ")
    ))
}

/// Why no candidate structure could be used, each in a few words: its
/// fit's error, or why the fit it made is not a rig.
fn no_usable_structure(sel: &Selection) -> String {
    let each: Vec<String> = sel
        .candidates
        .iter()
        .map(|c| {
            let why = match (&c.fit, &c.unusable) {
                (Err(e), _) => e.to_string(),
                (Ok(_), Some(why)) => why.clone(),
                (Ok(_), None) => "usable, not chosen".to_string(),
            };
            format!("\"{}\": {why}", c.structure.as_str())
        })
        .collect();
    format!(
        "no candidate structure gave a usable rig: {}",
        each.join("; ")
    )
}

/// The result table and the use decision.
/// `known` is what the runs' own warnings or the springs' agreement already
/// found wrong, which the misfit is put down to.
fn describe(
    ident: &JointIdentification<'_>,
    known: Option<&str>,
    ids: &[String],
    campaign: &Campaign,
    sequential: &RigEstimates,
    seq_chi2: Option<f64>,
    warnings: &mut Vec<Warning>,
) -> JointResult {
    let (sel, misfit) = (&ident.selection, ident.misfit.as_ref());
    let split = sel.candidate(Structure::DelayMeasurement).is_some();
    let spread = sel.spread();
    let mut result = table(sel, spread.as_ref(), split, warnings);
    let chosen = sel.chosen.and_then(|s| sel.candidate(s));
    let Some(fit) = chosen.and_then(|c| c.fit.as_ref().ok()) else {
        let why = match chosen.map(|c| &c.fit) {
            Some(Err(e)) => e.to_string(),
            _ => no_usable_structure(sel),
        };
        result.use_note = format!("the sequential estimate is used: the joint fit failed ({why})");
        warnings.push(Warning::new(
            "rig: the joint fit failed; the sequential estimate is used",
            format!("rig: the joint fit failed ({why}); the sequential estimate is used"),
        ));
        return result;
    };
    let cov = ident.rig_covariance().expect("a structure is chosen");
    result.parameters = parameters(fit, sequential, spread.as_ref(), misfit);
    report_flow_law(fit, &mut result, warnings);
    // With the friction or the flow law fitted, what its describing
    // function leaves out is what remains unexplained.
    let known = if let Some(note) = friction_note(fit, ids) {
        warnings.push(Warning::new(
            format!(
                "{}: F = {:.1} N fitted",
                super::friction::FRICTION_HEADLINE,
                fit.friction_n.unwrap_or(f64::NAN)
            ),
            format!("rig: {note}"),
        ));
        Some(FRICTION_HARMONICS)
    } else if fit.max_force_n.is_some() {
        Some(FLOW_LAW_HARMONICS)
    } else {
        known
    };
    if let Some(m) = misfit {
        let text = misfit_note(fit, m, known);
        let likely = super::log_stage::likely(known);
        warnings.push(Warning::new(
            format!(
                "rig: no structure fits: {}{likely}",
                fit.adequacy.failure_headline()
            ),
            format!("rig: {text}"),
        ));
        result.misfit = Some(text);
    }
    result.r1 = ident.r1();
    result.covariance = Some(cov);
    result.structure_covariance = spread.as_ref().map(|s| s.covariance);
    if let Some((text, settle)) = spread
        .as_ref()
        .and_then(|s| ambiguity(fit, s, &sel.candidates, split))
    {
        result.settle = settle;
        warnings.push(Warning::new(
            "rig: the data cannot tell two structures apart; the stds include the spread",
            format!("rig: {text}"),
        ));
        result.ambiguity = Some(text);
    }
    result.adequacy = Some(fit.adequacy.clone());
    result.per_run = ids
        .iter()
        .zip(&fit.per_run)
        .map(|(id, a)| RunAdequacy {
            run: id.to_string(),
            adequacy: a.clone(),
        })
        .collect();
    adequacy_warnings(fit, campaign, known, warnings);
    // `select` has judged convergence and physical sense already.
    let unusable = chosen.and_then(|c| c.unusable.clone());
    (result.used, result.use_note) = use_decision(fit, campaign, unusable, seq_chi2, warnings);
    result
}

/// The candidates' table with why the data choose what they choose; the
/// chosen fit's numbers are filled in by `describe`. A manifest structure
/// the data reject is a warning.
fn table(
    sel: &Selection,
    spread: Option<&StructureSpread>,
    split: bool,
    warnings: &mut Vec<Warning>,
) -> JointResult {
    let candidates: Vec<JointCandidate> = sel
        .candidates
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let weight = spread
                .map(|s| s.weights[i])
                .filter(|_| c.usable().is_some());
            row(c, sel.chosen, split, weight)
        })
        .collect();
    let mut explanation = explain(sel);
    if let Choice::Fixed(s) = sel.choice {
        explanation = format!(
            "identification.joint.structure = \"{}\" fixes it; {explanation}",
            s.as_str()
        );
        if let Some(auto) = sel.auto.filter(|a| *a != s) {
            warnings.push(Warning::new(
                format!(
                    "rig: the data reject joint.structure = \"{}\"; they choose \"{}\"",
                    s.as_str(),
                    auto.as_str()
                ),
                format!(
                    "rig: identification.joint.structure = \"{}\" is kept, but the data reject it: they choose \"{}\" (F tests in the report); remove the key to let the data choose",
                    s.as_str(),
                    auto.as_str()
                ),
            ));
        }
    }
    let fit = sel
        .chosen
        .and_then(|s| sel.candidate(s))
        .and_then(|c| c.fit.as_ref().ok());
    JointResult {
        structure: fit.map(|f| f.structure),
        chosen_by: match sel.choice {
            Choice::Auto => "data".into(),
            Choice::Fixed(_) => "manifest".into(),
        },
        data_choose: sel.auto,
        explanation,
        candidates,
        parameters: Vec::new(),
        r1: None,
        covariance: None,
        structure_covariance: None,
        ambiguity: None,
        settle: Vec::new(),
        misfit: None,
        adequacy: None,
        per_run: Vec::new(),
        used: false,
        use_note: String::new(),
        flow_law_held_n: None,
        friction_correction: None,
    }
}

/// The chosen fit's adequacy, said where the lab reads: residuals the
/// model does not explain, or noise the FRF's variance overstates.
fn adequacy_warnings(
    fit: &JointFit,
    campaign: &Campaign,
    known: Option<&str>,
    warnings: &mut Vec<Warning>,
) {
    let structure = fit.structure.as_str();
    let estimator = campaign.identification.frf.estimator;
    if let Some(d) = fit.adequacy.diagnosis_because(
        (fit.structure == Structure::Plain)
            .then_some("set identification.joint.structure = \"auto\" (or \"delay\")"),
        estimator.understated_noise(),
        known,
    ) {
        let likely = super::log_stage::likely(known);
        warnings.push(Warning::new(
            format!(
                "rig: joint fit misses: {}{likely}",
                fit.adequacy.failure_headline()
            ),
            format!("rig: the joint fit (structure \"{structure}\"): {d}"),
        ));
    }
    if let Some(o) = fit
        .adequacy
        .overstated_because(estimator.overstated_noise(), known)
    {
        warnings.push(Warning::new(
            format!("rig: the joint fit: {}", fit.adequacy.overstated_headline()),
            format!("rig: the joint fit (structure \"{structure}\"): {o}"),
        ));
    }
}

/// Whether the campaign uses the joint estimate, and the note that says why
/// (`unusable`: what `select` found wrong with the chosen fit).
fn use_decision(
    fit: &JointFit,
    campaign: &Campaign,
    unusable: Option<String>,
    seq_chi2: Option<f64>,
    warnings: &mut Vec<Warning>,
) -> (bool, String) {
    let structure = fit.structure.as_str();
    let reduced = fit.cost / fit.dof as f64;
    let as_good = seq_chi2.is_some_and(|s| reduced <= AS_GOOD_AS_SEQUENTIAL * s);
    match (campaign.joint.rig, &unusable) {
        (JointRig::Sequential, _) => (
            false,
            "the sequential estimate is used: identification.joint.rig = \"sequential\""
                .to_string(),
        ),
        (_, Some(why)) => {
            warnings.push(Warning::new(
                "rig: the joint fit is not usable; the sequential estimate is used",
                format!(
                    "rig: the joint fit (structure \"{structure}\") is not used: {why}; the sequential estimate is used (identification.joint)"
                ),
            ));
            (
                false,
                format!("the sequential estimate is used: the joint fit {why}"),
            )
        }
        (JointRig::Joint, None) => (
            true,
            "the joint estimate is used: identification.joint.rig = \"joint\"".to_string(),
        ),
        (JointRig::Auto, None) if fit.adequacy.passed() => (
            true,
            "the joint estimate is used: it passes its adequacy tests".to_string(),
        ),
        (JointRig::Auto, None) if as_good => (
            true,
            format!(
                "the joint estimate is used: it explains the data as well as the per-run fits do (reduced chi-square {reduced:.3} against their {:.3})",
                seq_chi2.expect("as_good")
            ),
        ),
        (JointRig::Auto, None) => {
            warnings.push(Warning::new(
                format!(
                    "rig: the joint fit is not adequate (reduced chi-square {reduced:.2}); the sequential rig is used"
                ),
                format!(
                    "rig: the joint fit (structure \"{structure}\") is not adequate (reduced chi-square {reduced:.3}, the per-run fits' {}); the sequential estimate is used; identification.joint.rig = \"joint\" would use it anyway",
                    seq_chi2.map_or("unknown".into(), |s| format!("{s:.3}"))
                ),
            ));
            (
                false,
                "the sequential estimate is used: the joint fit is not adequate".to_string(),
            )
        }
    }
}

/// The warning when structures the data cannot tell apart move the rig:
/// which, by how much, and what would settle it (in words and as the
/// experiments).
fn ambiguity(
    fit: &JointFit,
    spread: &StructureSpread,
    candidates: &[Candidate],
    split: bool,
) -> Option<(String, Vec<Settle>)> {
    if spread.rivals.is_empty() {
        return None;
    }
    const NAMES: [&str; 4] = ["beta1", "a1b0", "a2", "a3"];
    let weight = |s: Structure| {
        candidates
            .iter()
            .position(|c| c.structure == s)
            .map_or(0.0, |i| spread.weights[i])
    };
    let mut text = format!(
        "the data cannot tell {} (Schwarz weight {:.2}) from ",
        described(fit.structure, split),
        weight(fit.structure)
    );
    let rivals: Vec<String> = spread
        .rivals
        .iter()
        .map(|r| {
            let moved: Vec<String> = r
                .moved
                .iter()
                .map(|m| {
                    format!(
                        "{} by {:+.2} % ({:+.1} combined stds)",
                        NAMES[m.parameter],
                        100.0 * m.relative,
                        m.z
                    )
                })
                .collect();
            format!(
                "{} (weight {:.2}), which moves {}",
                described(r.structure, split),
                r.weight,
                moved.join(", ")
            )
        })
        .collect();
    text.push_str(&rivals.join("; and from "));
    text.push_str(
        "; the rig's stds include that spread (the structure std; results.json keeps the statistical, structure and total stds). To settle it: ",
    );
    let settle = settle(fit, spread);
    let words: Vec<&str> = settle.iter().map(|s| s.text()).collect();
    text.push_str(&words.join("; or "));
    Some((text, settle))
}

/// What would settle which of the structures `fit` and `spread`'s rivals is
/// the rig's: the experiments that tell their places apart.
fn settle(fit: &JointFit, spread: &StructureSpread) -> Vec<Settle> {
    let mut settle = Vec::new();
    let places: Vec<Option<Place>> = std::iter::once(fit.structure)
        .chain(spread.rivals.iter().map(|r| r.structure))
        .map(Structure::place)
        .collect();
    let has = |p: Option<Place>| places.contains(&p);
    if has(Some(Place::Loop)) && places.iter().any(|p| *p != Some(Place::Loop)) {
        settle.push(Settle::PGain);
    }
    let delay_only = std::iter::once(fit.structure)
        .chain(spread.rivals.iter().map(|r| r.structure))
        .any(|s| matches!(s, Structure::Plain | Structure::Delay));
    if delay_only && places.iter().any(Option::is_some) {
        settle.push(Settle::WiderBand);
    }
    let piston = std::iter::once(fit.structure)
        .chain(spread.rivals.iter().map(|r| r.structure))
        .any(Structure::piston);
    if piston {
        settle.push(Settle::Specimen);
    }
    if has(Some(Place::Command)) && has(Some(Place::Measurement)) {
        settle.push(Settle::LoadCell);
    }
    if settle.is_empty() {
        settle.push(Settle::Longer);
    }
    settle
}

/// The warning when the chosen structure fails its adequacy tests and the
/// runs pull the rig apart: put down to `known` when the runs found it,
/// else to what no candidate holds.
fn misfit_note(fit: &JointFit, m: &RunSpread, known: Option<&str>) -> String {
    const NAMES: [&str; 4] = ["beta1", "a1b0", "a2", "a3"];
    let spread: Vec<String> = (0..4)
        .map(|k| {
            format!(
                "{} {:.2} %",
                NAMES[k],
                100.0 * m.jackknife_std[k] / fit.params[k].abs()
            )
        })
        .collect();
    let cause = match known {
        Some(known) => format!("the likely cause is {known}"),
        None => "the rig has something none of the structures holds (friction, a nonlinear specimen, two modes at once)".to_string(),
    };
    format!(
        "no candidate structure explains the data: the chosen \"{}\" fails its adequacy tests, so {cause}, and its parameters carry an error no std here bounds. Refitted without {} in turn the rig moves by (jackknife std) {}; the stds include what of that spread statistics do not explain (misfit_std in results.json), but not an error every run shares, which on simulated rigs with piston friction or two modes was 5 to 18 times larger (docs/accuracy.md). Use the rig as approximate: the difference from the sequential estimate (the model-error term) shows its scale, and the per-run adequacy table shows which runs the misfit weighs on",
        fit.structure.as_str(),
        if m.refits == m.frfs {
            format!("each of the {} FRFs", m.frfs)
        } else {
            format!("each of {} groups of its {} FRFs", m.refits, m.frfs)
        },
        spread.join(", ")
    )
}

/// The chosen fit's parameters beside the sequential estimate, with the
/// structure std of the rig's four.
fn parameters(
    fit: &JointFit,
    seq: &RigEstimates,
    spread: Option<&StructureSpread>,
    misfit: Option<&RunSpread>,
) -> Vec<JointParameter> {
    let seq_est = [seq.beta1, seq.a1b0, seq.a2, seq.a3];
    // The rig's four by the names the rest of results.json gives them.
    let short = |name: &'static str| match name {
        "beta1_per_s" => "beta1",
        "a1b0_n_per_m_s2" => "a1b0",
        "a2_n_per_m" => "a2",
        "a3_per_s" => "a3",
        other => other,
    };
    fit.params
        .iter()
        .zip(&fit.std)
        .enumerate()
        .map(|(i, (&value, &std))| {
            let sequential: Option<Estimate> = seq_est.get(i).copied();
            let diff = sequential.map(|s| value - s.value);
            let combined = sequential
                .and_then(|s| s.std)
                .map(|s| (s * s + std * std).sqrt());
            let difference_std = diff.zip(combined).map(|(d, c)| d / c);
            let structure_std = spread.and_then(|s| s.std.get(i).copied());
            let misfit_std = misfit.and_then(|m| m.std.get(i).copied());
            JointParameter {
                name: short(fit.names[i]).into(),
                value,
                std,
                structure_std,
                misfit_std,
                total_std: (std * std
                    + structure_std.unwrap_or(0.0).powi(2)
                    + misfit_std.unwrap_or(0.0).powi(2))
                .sqrt(),
                sequential,
                difference_std,
                model_error: diff.map(f64::abs),
                dominant: difference_std.map(|z| {
                    if z.abs() > 2.0 {
                        "model error".into()
                    } else {
                        "statistical".into()
                    }
                }),
                correction_std: None,
            }
        })
        .collect()
}

/// The joint estimate as the rig's estimates (a1b0 at the reference P
/// gain), when the campaign uses it.
pub fn used_estimates(r: &JointResult) -> Option<RigEstimates> {
    if !r.used {
        return None;
    }
    let est = |i: usize| {
        r.parameters.get(i).map(|p| Estimate {
            value: p.value,
            std: Some(p.total_std),
        })
    };
    Some(RigEstimates {
        beta1: est(0)?,
        a1b0: est(1)?,
        a2: est(2)?,
        a3: est(3)?,
        R1: r.r1?,
        covariance: r.covariance,
    })
}

/// What a validation run's prediction carries besides the rig, when the
/// campaign uses the joint estimate: the seals' friction (`seals`) and the
/// flow law's F_max, fitted or held at the nameplate's.
pub fn extras(r: &JointResult, smoothing: Option<f64>) -> RigExtras {
    let fitted = r
        .parameters
        .iter()
        .find(|p| p.name == joint::FLOW_LAW)
        .map(|p| p.value);
    RigExtras {
        seals: seals(r, smoothing),
        max_force_n: r.used.then_some(fitted.or(r.flow_law_held_n)).flatten(),
    }
}

/// The seals' friction (and the piston's mass with it) the joint fit found,
/// when the campaign uses the joint estimate, with the zero-crossing width
/// `smoothing` the manifest states.
fn seals(r: &JointResult, smoothing: Option<f64>) -> Option<Seals> {
    if !r.used {
        return None;
    }
    let value = |name: &str| {
        r.parameters
            .iter()
            .find(|p| p.name == name)
            .map(|p| p.value)
    };
    Some(Seals {
        coulomb_friction_n: value(joint::FRICTION)?,
        piston_mass_kg: value("piston_mass_kg"),
        smoothing_velocity_m_per_s: smoothing,
        seal_damping_ns_per_m: value(joint::SEAL_DAMPING),
    })
}
