//! Time-domain checks of a run with a log: the model driven by the measured
//! command (held between samples, as the D/A did), compared with the measured
//! displacement and force by the paper's Eqs. 47-48 over the whole record and
//! in the four windows of its figures. Linear models start at their
//! equilibrium under the first command sample (nonlinear specimens from
//! rest, as before). For a validation run the model is the
//! identified rig with the run's specimen, simulated in the physical form
//! (Eq. 10) and in the controllable canonical form with Cn (Eq. 34), which
//! must agree, and in the paper's simplified form (Cn dropped) side by side.
//! For an identification run it is the fitted transfer function (Figs. 9,
//! 12, 14).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::metrics::{self as validate, Errors, Window};
use crate::lti::{StateSpace, TransferFunction};
use crate::model::SpecimenModel;
use crate::model::{self, CnTerm, LinearSdof, RigExtras, RigParams, Seals};
use crate::simulate::SimError;
use crate::simulate::discrete::simulate_linear;
use crate::simulate::ode::Integrator;
use crate::simulate::plant::{self, ActuatorFriction, PlantSpec, Unmodelled};

/// A run's measured signals in SI, uniformly sampled, as the time-domain
/// checks read them.
#[derive(Debug, Clone, Copy)]
pub struct Record<'a> {
    pub sample_rate_hz: f64,
    /// Command displacement u (m).
    pub command_m: &'a [f64],
    /// Measured actuator displacement x1 (m).
    pub displacement_m: &'a [f64],
    /// Measured actuator force f (N), when logged.
    pub force_n: Option<&'a [f64]>,
}

/// Why a run cannot be checked in the time domain.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ValidateError {
    #[error(transparent)]
    Simulation(#[from] SimError),
    #[error("the measured displacement is identically zero")]
    ZeroDisplacement,
}

/// Errors in one of the paper's windows.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct WindowErrors {
    pub label: String,
    pub start_s: f64,
    pub end_s: f64,
    pub nrmse_pct: f64,
    pub nae_pct: f64,
}

/// Measured against simulated displacement (Eqs. 47-48) and what else the
/// run can be checked on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct ValidationMetrics {
    /// Over the whole record (Eq. 47).
    pub nrmse_pct: f64,
    /// Over the whole record (Eq. 48).
    pub nae_pct: f64,
    pub fit_pct: f64,
    /// What was simulated: "identified rig (Eq. 10)" or "fitted transfer function".
    pub model: String,
    /// The constant offset between measured and simulated displacement,
    /// removed before comparing (a sensor offset) (m).
    pub offset_removed_m: f64,
    /// The four windows of the paper's figures, where the sweep reaches them.
    pub windows: Vec<WindowErrors>,
    /// Measured against simulated force, when the log has force.
    pub force: Option<Errors>,
    /// The paper's simplified canonical form (Cn dropped), side by side;
    /// null for a specimen that is not a linear SDOF.
    pub simplified_ccf: Option<SimplifiedCcf>,
    /// max |x1(CCF with Cn) - x1(physical)| / max |x1(physical)|: the two
    /// forms are one model, so this is round-off.
    pub ccf_consistency: Option<f64>,
    /// Set when this run's errors are far above the campaign's other runs.
    pub outlier: bool,
    pub note: Option<String>,
    /// The seals' friction the joint fit found, which the prediction above
    /// carries, with the errors of the prediction without it; null when no
    /// friction was found.
    #[serde(default)]
    pub seals: Option<SealsPrediction>,
    /// The valve's flow-pressure law the joint fit found, which the
    /// prediction above carries (the rig at the run's load), with the
    /// errors of the zero-load rig's prediction; absent without the law.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub load: Option<LoadPrediction>,
}

/// A prediction with the valve's flow-pressure law: the rig at the load the
/// run reached, where the zero-load rig's valve passes more flow.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct LoadPrediction {
    /// F_max = A P_s (N) the prediction holds.
    pub max_force_n: f64,
    /// The largest force the prediction reaches (N), and its share of F_max.
    pub peak_force_n: f64,
    pub load_fraction: f64,
    /// Measured against the zero-load rig's linear prediction (Eqs. 47-48).
    pub zero_load: Errors,
    /// The command's amplitude (m, half its range) and the equivalent
    /// linear rig at the load the run's specimen takes there, fitted over
    /// the run's band (`model::flow::equivalent_rig`, a1b0 at the run's P
    /// gain): what its tracking prediction and compensator are built on.
    #[serde(default)]
    pub amplitude_m: Option<f64>,
    #[serde(default)]
    pub equivalent_rig: Option<RigParams>,
}

/// A prediction with the seals' friction.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct SealsPrediction {
    /// F (N), as the joint fit found it.
    pub coulomb_friction_n: f64,
    /// v0 (m/s): the simulation's friction is F tanh(x2 / v0).
    pub smoothing_velocity_m_per_s: f64,
    /// The piston's mass simulated with it (kg), when the fit resolved one.
    pub piston_mass_kg: Option<f64>,
    /// Measured against the prediction of the rig without the friction
    /// (Eqs. 47-48).
    pub without_friction: Errors,
}

/// Why a validation run's prediction leaves the seals' friction out.
const MASSLESS_SEALS: &str = "the seals' friction the joint fit found is not in this prediction: with a massless specimen and no piston mass resolved, nothing moves under the friction's force balance (the prediction is the linear rig's)";

/// The paper's simplified canonical form (Cn dropped "for a linear
/// specimen", Sec. 3) checked on a validation run. Dropping Cn moves the
/// poles (docs/model.md); at some rig parameters it moves the specimen's pair into
/// the right half-plane, and a simulation of it then grows without bound, so
/// it is only simulated when stable and otherwise says so.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct SimplifiedCcf {
    /// Every pole of the simplified form has a negative real part.
    pub stable: bool,
    /// The largest real part among its poles (1/s); positive when unstable.
    pub max_pole_real_per_s: f64,
    /// Measured against simulated displacement (Eqs. 47-48); null when the
    /// form is unstable and was not simulated.
    pub errors: Option<Errors>,
    pub note: String,
}

/// The simulated signals kept for the figures.
#[derive(Debug, Clone)]
pub struct TimeStage {
    pub metrics: ValidationMetrics,
    pub windows: Vec<Window>,
    /// Measured displacement, offset removed (m).
    pub x1_measured: Vec<f64>,
    pub x1_simulated: Vec<f64>,
    pub x1_simplified: Option<Vec<f64>>,
}

/// The linear model's response to the log's command, starting at its
/// equilibrium under the first command sample: a rig settles at its rest
/// command long before the log begins, and a real command need not rest at
/// zero (the UTFSM logs rest at -0.21 mm). Simulated as the response to
/// u - u[0] from rest plus the steady output G(0) u[0] (D u[0] when A is
/// singular; `compare` removes a constant offset anyway).
fn simulate(ss: &StateSpace, rec: &Record<'_>, delay_s: f64) -> Result<Vec<Vec<f64>>, SimError> {
    let outputs = ss.c.nrows();
    let u0 = rec.command_m.first().copied().unwrap_or(0.0);
    let u: Vec<f64> = rec.command_m.iter().map(|v| v - u0).collect();
    let mut out = simulate_linear(ss, &u, 1.0 / rec.sample_rate_hz, &vec![delay_s; outputs])?;
    for (i, y) in out.iter_mut().enumerate() {
        let dc = ss.eval(i, nalgebra::Complex::new(0.0, 0.0)).re;
        if dc.is_finite() {
            y.iter_mut().for_each(|v| *v += dc * u0);
        }
    }
    Ok(out)
}

/// Compare with the offset between the records removed.
fn compare(
    measured: &[f64],
    simulated: &[f64],
    sample_rate_hz: f64,
    windows: &[Window],
) -> Option<(Errors, Vec<WindowErrors>, f64, Vec<f64>)> {
    let n = measured.len().min(simulated.len());
    let offset = (0..n).map(|k| measured[k] - simulated[k]).sum::<f64>() / n.max(1) as f64;
    let centred: Vec<f64> = measured[..n].iter().map(|v| v - offset).collect();
    let whole = validate::errors(&centred, &simulated[..n])?;
    let per_window = windows
        .iter()
        .filter_map(|w| {
            let r = validate::window_range(w, sample_rate_hz, n);
            let e = validate::errors(&centred[r.clone()], &simulated[r])?;
            Some(WindowErrors {
                label: w.label.clone(),
                start_s: w.start_s,
                end_s: w.end_s,
                nrmse_pct: e.nrmse_pct,
                nae_pct: e.nae_pct,
            })
        })
        .collect();
    Some((whole, per_window, offset, centred))
}

/// The identified rig with a linear specimen and what the prediction
/// carries beyond Eq. 10 (the seals' friction, the valve's flow law): the
/// nonlinear plant (docs/model.md) driven by u - u[0] from rest, plus the
/// linear model's steady output under u[0] (as [`simulate`] does), so the
/// nonlinearity's transient at the start is the rig's own. Outputs x1 and
/// the load cell's force.
fn simulate_nonlinear(
    rig_at_p: &RigParams,
    specimen: &SpecimenModel,
    (seals, max_force_n): (Option<&Seals>, Option<f64>),
    ss: &StateSpace,
    rec: &Record<'_>,
) -> Result<(Vec<f64>, Vec<f64>), SimError> {
    let spec = PlantSpec {
        rig: *rig_at_p,
        specimen: *specimen,
        unmodelled: Unmodelled {
            piston_mass_kg: seals.and_then(|s| s.piston_mass_kg),
            actuator_friction: seals.map(|seals| ActuatorFriction {
                coulomb_force_n: seals.coulomb_friction_n,
                smoothing_velocity_m_per_s: seals.smoothing(),
                // A damping fitted below zero within its noise is none.
                viscous_ns_per_m: seals.seal_damping_ns_per_m.unwrap_or(0.0).max(0.0),
            }),
            max_force_n,
            ..Unmodelled::default()
        },
    };
    let u0 = rec.command_m.first().copied().unwrap_or(0.0);
    let u: Vec<f64> = rec.command_m.iter().map(|v| v - u0).collect();
    let r = plant::simulate(
        &spec,
        &u,
        rec.sample_rate_hz,
        [0.0, 0.0],
        Integrator::default(),
    )?;
    let dc = |i: usize| {
        let g = ss.eval(i, nalgebra::Complex::new(0.0, 0.0)).re;
        if g.is_finite() { g * u0 } else { 0.0 }
    };
    let (x_dc, f_dc) = (dc(model::OUT_X1), dc(model::OUT_FORCE));
    Ok((
        r.x1_m.iter().map(|v| v + x_dc).collect(),
        r.force_n.iter().map(|v| v + f_dc).collect(),
    ))
}

/// The identified rig's x1 and force with the run's specimen: its linear
/// model, or a nonlinear specimen's simulation.
fn rig_response(
    rig_at_p: &RigParams,
    specimen: &SpecimenModel,
    rec: &Record<'_>,
) -> Result<(Vec<f64>, Vec<f64>), SimError> {
    match specimen.linear() {
        Some(lin) => {
            let mut out = simulate(&model::state_space(rig_at_p, &lin), rec, 0.0)?;
            let f = out.pop().expect("two outputs");
            Ok((out.pop().expect("two outputs"), f))
        }
        None => {
            let spec = PlantSpec {
                rig: *rig_at_p,
                specimen: *specimen,
                unmodelled: Unmodelled::default(),
            };
            let r = plant::simulate(
                &spec,
                rec.command_m,
                rec.sample_rate_hz,
                [0.0, 0.0],
                Integrator::Rk4 { substeps: 8 },
            )?;
            Ok((r.x1_m, r.force_n))
        }
    }
}

/// A prediction with what the rig carries beyond Eq. 10: x1, the force and
/// what it records beside them.
struct Beyond {
    x1: Vec<f64>,
    force: Vec<f64>,
    seals: Option<SealsPrediction>,
    load: Option<LoadPrediction>,
}

/// The prediction with the seals' friction and the valve's flow law, where
/// there is one to make (a linear specimen and either found), with the
/// errors of the linear prediction `linear_x1` beside it, and a note where
/// one is left out: the friction on a run with nothing to move under it,
/// the law where the prediction's force reaches F_max.
fn nonlinear_response(
    rig_at_p: &RigParams,
    specimen: &SpecimenModel,
    extras: &RigExtras,
    linear_x1: &[f64],
    rec: &Record<'_>,
) -> Result<(Option<Beyond>, Option<String>), ValidateError> {
    let Some(lin) = specimen.linear() else {
        return Ok((None, None));
    };
    // The friction's force balance needs a moving mass: the specimen's or
    // the piston's.
    let (seals, note) = match &extras.seals {
        Some(s) if lin.mck().0 + s.piston_mass_kg.unwrap_or(0.0) <= 0.0 => {
            (None, Some(MASSLESS_SEALS.to_string()))
        }
        other => (other.as_ref(), None),
    };
    if seals.is_none() && extras.max_force_n.is_none() {
        return Ok((None, note));
    }
    let ss = model::state_space(rig_at_p, &lin);
    let (x1, force) = match simulate_nonlinear(
        rig_at_p,
        specimen,
        (seals, extras.max_force_n),
        &ss,
        rec,
    ) {
        Ok(r) => r,
        Err(SimError::BeyondSupply {
            force_n,
            max_force_n,
            t_s,
        }) => {
            return Ok((
                None,
                Some(format!(
                    "the valve's flow law is not in this prediction: with it the force reaches {force_n:.0} N at {t_s:.3} s, F_max = {max_force_n:.0} N, where the valve passes no flow against the load (the prediction is the zero-load rig's)"
                )),
            ));
        }
        Err(e) => return Err(e.into()),
    };
    let zero = compare(rec.displacement_m, linear_x1, rec.sample_rate_hz, &[])
        .ok_or(ValidateError::ZeroDisplacement)?
        .0;
    let seals = seals.map(|seals| SealsPrediction {
        coulomb_friction_n: seals.coulomb_friction_n,
        smoothing_velocity_m_per_s: seals.smoothing(),
        piston_mass_kg: seals.piston_mass_kg,
        without_friction: zero,
    });
    let load = extras.max_force_n.map(|max_force_n| {
        let peak = force.iter().fold(0.0_f64, |m, f| m.max(f.abs()));
        LoadPrediction {
            max_force_n,
            peak_force_n: peak,
            load_fraction: peak / max_force_n,
            zero_load: zero,
            amplitude_m: None,
            equivalent_rig: None,
        }
    });
    Ok((
        Some(Beyond {
            x1,
            force,
            seals,
            load,
        }),
        note,
    ))
}

/// A validation run: the identified rig at the run's P gain with its
/// specimen, and with the seals' friction and the valve's flow law when the
/// joint fit found them.
pub fn validation_run(
    rig_at_p: &RigParams,
    specimen: &SpecimenModel,
    extras: &RigExtras,
    rec: &Record<'_>,
) -> Result<TimeStage, ValidateError> {
    let fs = rec.sample_rate_hz;
    let windows = validate::locate_windows(rec.command_m, fs);
    // With the friction or the law the prediction is the nonlinear plant's;
    // the linear one stays for the canonical forms' check and the
    // comparison.
    let (linear_x1, linear_force) = rig_response(rig_at_p, specimen, rec)?;
    let (beyond, note) = nonlinear_response(rig_at_p, specimen, extras, &linear_x1, rec)?;
    let (x1, force) = match &beyond {
        Some(b) => (b.x1.as_slice(), b.force.as_slice()),
        None => (linear_x1.as_slice(), linear_force.as_slice()),
    };
    let (whole, per_window, offset, centred) =
        compare(rec.displacement_m, x1, fs, &windows).ok_or(ValidateError::ZeroDisplacement)?;
    let force_errors = rec.force_n.and_then(|f| {
        let n = f.len().min(force.len());
        let offset = (0..n).map(|k| f[k] - force[k]).sum::<f64>() / n.max(1) as f64;
        let centred: Vec<f64> = f[..n].iter().map(|v| v - offset).collect();
        validate::errors(&centred, &force[..n])
    });
    let canonical = match *specimen {
        SpecimenModel::LinearSdof {
            mass_kg,
            damping_ns_per_m,
            stiffness_n_per_m,
        } => {
            let sdof = LinearSdof {
                mass_kg,
                damping_ns_per_m,
                stiffness_n_per_m,
            };
            Some(canonical_forms(rig_at_p, &sdof, rec, &linear_x1)?)
        }
        _ => None,
    };
    let (simplified_check, consistency, simplified) = match canonical {
        Some(c) => (Some(c.check), c.consistency, c.x1_simplified),
        None => (None, None, None),
    };
    let (x1, seals, load) = match beyond {
        Some(b) => (b.x1, b.seals, b.load),
        None => (linear_x1, None, None),
    };
    Ok(TimeStage {
        metrics: ValidationMetrics {
            nrmse_pct: whole.nrmse_pct,
            nae_pct: whole.nae_pct,
            fit_pct: whole.fit_pct,
            model: prediction_model(seals.is_some(), load.is_some()).into(),
            offset_removed_m: offset,
            windows: per_window,
            force: force_errors,
            simplified_ccf: simplified_check,
            ccf_consistency: consistency,
            outlier: false,
            note,
            seals,
            load,
        },
        windows,
        x1_measured: centred,
        x1_simulated: x1,
        x1_simplified: simplified,
    })
}

/// What a validation run's prediction simulated, in words.
fn prediction_model(seals: bool, load: bool) -> &'static str {
    match (seals, load) {
        (false, false) => "identified rig with the run's specimen (Eq. 10)",
        (true, false) => {
            "identified rig with the run's specimen and the seals' friction (Eq. 10, friction F tanh(x2 / v0) on the piston)"
        }
        (false, true) => {
            "identified rig with the run's specimen at its load (Eq. 10, the valve's flow r sqrt(1 - sign(r) f / F_max))"
        }
        (true, true) => {
            "identified rig with the run's specimen at its load and the seals' friction (Eq. 10, the valve's flow r sqrt(1 - sign(r) f / F_max), friction F tanh(x2 / v0) on the piston)"
        }
    }
}

/// The canonical forms of a linear SDOF validation run (Eqs. 34-35).
struct CanonicalForms {
    check: SimplifiedCcf,
    /// max |x1(CCF with Cn) - x1(physical)| / max |x1(physical)|.
    consistency: Option<f64>,
    /// x1 of the simplified form, when it was stable enough to simulate.
    x1_simplified: Option<Vec<f64>>,
}

/// The form with Cn kept must reproduce the physical form's `x1` (one model,
/// so the difference is round-off); the paper's simplified form (Cn
/// dropped) is simulated beside it only when its poles are stable, and
/// otherwise says which poles are not.
fn canonical_forms(
    rig_at_p: &RigParams,
    sdof: &LinearSdof,
    rec: &Record<'_>,
    x1: &[f64],
) -> Result<CanonicalForms, ValidateError> {
    let kept = simulate(
        &model::ccf_linear_state_space(rig_at_p, sdof, CnTerm::Kept),
        rec,
        0.0,
    )?;
    let peak = x1.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    let diff = kept[0]
        .iter()
        .zip(x1)
        .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
    let consistency = (peak > 0.0).then(|| diff / peak);
    let dropped_ss = model::ccf_linear_state_space(rig_at_p, sdof, CnTerm::Dropped);
    let poles = dropped_ss.eigenvalues().ok_or(SimError::NoEigenvalues {
        what: "simplified canonical form",
    })?;
    let max_re = poles.iter().map(|p| p.re).fold(f64::NEG_INFINITY, f64::max);
    if max_re < 0.0 {
        let dropped = simulate(&dropped_ss, rec, 0.0)?;
        let x_dropped = dropped.into_iter().next().expect("x1 output");
        let errors = compare(rec.displacement_m, &x_dropped, rec.sample_rate_hz, &[]).map(|c| c.0);
        return Ok(CanonicalForms {
            check: SimplifiedCcf {
                stable: true,
                max_pole_real_per_s: max_re,
                errors,
                note: "stable; simulated beside the full form".into(),
            },
            consistency,
            x1_simplified: Some(x_dropped),
        });
    }
    let worst = poles
        .iter()
        .filter(|p| p.re >= 0.0)
        .map(|p| {
            format!(
                "{:.1} {} {:.1}j",
                p.re,
                if p.im < 0.0 { '-' } else { '+' },
                p.im.abs()
            )
        })
        .collect::<Vec<_>>()
        .join(", ");
    Ok(CanonicalForms {
        check: SimplifiedCcf {
            stable: false,
            max_pole_real_per_s: max_re,
            errors: None,
            note: format!(
                "unstable with Cn dropped (poles {worst} rad/s), so not simulated: at these rig parameters the paper's simplification does not describe the plant; the form with Cn kept does"
            ),
        },
        consistency,
        x1_simplified: None,
    })
}

/// An identification run: its fitted transfer function (hold exact, delay
/// as fitted) driven by the measured command (the paper's Figs. 9, 12, 14).
pub fn fitted_run(tf: &TransferFunction, rec: &Record<'_>) -> Result<TimeStage, ValidateError> {
    let fs = rec.sample_rate_hz;
    let windows = validate::locate_windows(rec.command_m, fs);
    let out = simulate(&tf.to_state_space(), rec, tf.delay_s)?;
    let x1 = out.into_iter().next().expect("one output");
    let (whole, per_window, offset, centred) =
        compare(rec.displacement_m, &x1, fs, &windows).ok_or(ValidateError::ZeroDisplacement)?;
    Ok(TimeStage {
        metrics: ValidationMetrics {
            nrmse_pct: whole.nrmse_pct,
            nae_pct: whole.nae_pct,
            fit_pct: whole.fit_pct,
            model: "fitted transfer function".into(),
            offset_removed_m: offset,
            windows: per_window,
            force: None,
            simplified_ccf: None,
            ccf_consistency: None,
            outlier: false,
            note: None,
            seals: None,
            load: None,
        },
        windows,
        x1_measured: centred,
        x1_simulated: x1,
        x1_simplified: None,
    })
}

/// Flag validation runs whose NRMSE is far above the others': more than three
/// times the median of the other runs and more than 2 percentage points
/// above it, the sign of a specimen that is not what the manifest says (or a
/// log of another run). The margin keeps runs that are all near the noise
/// floor from flagging each other, and the ratio keeps a campaign like the
/// paper's (Table 4: 2.7-3.1 %) quiet unless one run passes about 8 %.
pub fn flag_outliers(metrics: &mut [&mut ValidationMetrics]) {
    let all: Vec<f64> = metrics.iter().map(|m| m.nrmse_pct).collect();
    for (i, m) in metrics.iter_mut().enumerate() {
        let mut others: Vec<f64> = all
            .iter()
            .enumerate()
            .filter(|(j, _)| *j != i)
            .map(|(_, v)| *v)
            .collect();
        if others.is_empty() {
            continue;
        }
        others.sort_by(f64::total_cmp);
        let median = others[others.len() / 2];
        if m.nrmse_pct > 3.0 * median && m.nrmse_pct > median + 2.0 {
            m.outlier = true;
            m.note = Some(format!(
                "NRMSE {:.1} % is {:.1} times the other runs' median ({:.2} %): the specimen may not be what the manifest says, or the log belongs to another run",
                m.nrmse_pct,
                m.nrmse_pct / median,
                median
            ));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn metrics(nrmse: f64) -> ValidationMetrics {
        ValidationMetrics {
            nrmse_pct: nrmse,
            nae_pct: 0.0,
            fit_pct: 0.0,
            model: String::new(),
            offset_removed_m: 0.0,
            windows: Vec::new(),
            force: None,
            simplified_ccf: None,
            ccf_consistency: None,
            outlier: false,
            note: None,
            seals: None,
            load: None,
        }
    }

    /// Command, displacement and force (1 kHz, 20 s chirp) of the model's
    /// own noise-free response.
    fn signals_of(rig: &RigParams, specimen: &SpecimenModel) -> [Vec<f64>; 3] {
        let fs = 1000.0;
        let n = 20_000;
        let u: Vec<f64> = (0..n)
            .map(|k| {
                let t = k as f64 / fs;
                let phase = 2.0 * std::f64::consts::PI * (0.5 * t + 0.5 * (29.5 / 20.0) * t * t);
                2e-3 * phase.sin()
            })
            .collect();
        let lin = specimen.linear().expect("linear");
        let mut y = simulate_linear(&model::state_space(rig, &lin), &u, 1.0 / fs, &[0.0, 0.0])
            .expect("simulates");
        let f = y.pop().expect("force");
        [u, y.pop().expect("x1"), f]
    }

    fn with(seals: Seals) -> RigExtras {
        RigExtras {
            seals: Some(seals),
            max_force_n: None,
        }
    }

    /// With the valve's flow law a spring's run is predicted at its load:
    /// the prediction states the force it reached, below the zero-load
    /// rig's (the valve passes less flow against the load; at some 18 % of
    /// F_max by a few %), and departs from the zero-load rig's own log.
    /// Where the law's force would reach F_max the prediction is the
    /// zero-load rig's, and says so.
    #[test]
    fn a_run_is_predicted_at_its_load_or_says_why_not() {
        let rig = model::PAPER_RIG;
        let specimen = SpecimenModel::Spring {
            stiffness_n_per_m: 116_640.0,
        };
        let signals = signals_of(&rig, &specimen);
        let law = |max_force_n| RigExtras {
            seals: None,
            max_force_n: Some(max_force_n),
        };
        let stage = validation_run(&rig, &specimen, &law(1000.0), &record(&signals)).unwrap();
        let m = &stage.metrics;
        let load = m.load.as_ref().expect("predicted at its load");
        // The zero-load rig's own force (its log) peaks higher: against
        // the load the valve passes less flow.
        let zero_load_peak = signals[2].iter().fold(0.0_f64, |p, f| p.max(f.abs()));
        let ratio = load.peak_force_n / zero_load_peak;
        assert!(ratio < 1.0 && ratio > 0.9, "{ratio}");
        assert!((load.load_fraction - load.peak_force_n / 1000.0).abs() < 1e-12);
        assert!(load.zero_load.nrmse_pct < 1e-6);
        assert!(m.nrmse_pct > 0.1, "{}", m.nrmse_pct);
        assert!(m.model.contains("at its load"), "{}", m.model);
        // A 50 kg mass's inertia drives the chamber's force past a 300 N
        // F_max against the flow (simulate::plant's test of the same).
        let heavy = SpecimenModel::LinearSdof {
            mass_kg: 50.0,
            damping_ns_per_m: 5.0,
            stiffness_n_per_m: 129_400.0,
        };
        let signals = signals_of(&rig, &heavy);
        let stage = validation_run(&rig, &heavy, &law(300.0), &record(&signals)).unwrap();
        let m = &stage.metrics;
        assert!(m.load.is_none());
        assert!(m.nrmse_pct < 1e-6, "{}", m.nrmse_pct);
        assert!(
            m.note
                .as_deref()
                .is_some_and(|n| n.contains("F_max = 300 N")),
            "{:?}",
            m.note
        );
    }

    fn record(s: &[Vec<f64>; 3]) -> Record<'_> {
        Record {
            sample_rate_hz: 1000.0,
            command_m: &s[0],
            displacement_m: &s[1],
            force_n: Some(&s[2]),
        }
    }

    /// Exp1 of Table 2 at the paper's rig: with Cn dropped the canonical
    /// form's characteristic polynomial is s^4 - C4 s^3 - (C3 + C5 m) s^2 -
    /// (C2 + C5 c) s + (C1 - C5 k). Its roots, computed separately with
    /// numpy.roots from Table 3's parameters (C1..C5 by Eq. 35 with the signs checked),
    /// are -290.85, -12.52 and 10.125 +/- 463.11j rad/s: unstable. The run
    /// must say so and not report errors of a diverging simulation, while
    /// the full model reproduces its own noise-free log.
    /// With the seals' friction a spring's validation run has nothing to
    /// move under it unless a piston mass was resolved: the prediction is
    /// the linear rig's, which its own noise-free log matches, and the note
    /// says why the friction is left out. With a piston mass the friction
    /// is simulated, and the prediction departs from the linear log.
    #[test]
    fn a_massless_run_is_predicted_without_the_seals_and_says_so() {
        let rig = model::PAPER_RIG;
        let specimen = SpecimenModel::Spring {
            stiffness_n_per_m: 116_640.0,
        };
        let signals = signals_of(&rig, &specimen);
        let mut seals = Seals {
            coulomb_friction_n: 8.0,
            piston_mass_kg: None,
            smoothing_velocity_m_per_s: None,
            seal_damping_ns_per_m: None,
        };
        let stage = validation_run(&rig, &specimen, &with(seals), &record(&signals)).unwrap();
        let m = &stage.metrics;
        assert!(m.seals.is_none());
        assert!(m.nrmse_pct < 1e-6, "{}", m.nrmse_pct);
        assert!(
            m.note.as_deref().is_some_and(|n| n.contains("massless")),
            "{:?}",
            m.note
        );
        seals.piston_mass_kg = Some(0.5);
        let stage = validation_run(&rig, &specimen, &with(seals), &record(&signals)).unwrap();
        let m = &stage.metrics;
        let with = m.seals.as_ref().expect("simulated with the friction");
        assert_eq!(
            with.smoothing_velocity_m_per_s,
            model::SEAL_SMOOTHING_M_PER_S
        );
        assert!(with.without_friction.nrmse_pct < 1e-6);
        assert!(m.nrmse_pct > 0.1, "{}", m.nrmse_pct);
        assert!(m.note.is_none());
    }

    #[test]
    fn the_simplified_ccf_is_reported_unstable_at_the_papers_exp1() {
        let rig = model::PAPER_RIG;
        let specimen = SpecimenModel::LinearSdof {
            mass_kg: 3.8,
            damping_ns_per_m: 5.0,
            stiffness_n_per_m: 129_400.0,
        };
        let signals = signals_of(&rig, &specimen);
        let stage =
            validation_run(&rig, &specimen, &RigExtras::default(), &record(&signals)).unwrap();
        let m = &stage.metrics;
        assert!(m.nrmse_pct < 1e-6, "full model NRMSE {}", m.nrmse_pct);
        assert!(m.ccf_consistency.unwrap() < 1e-9);
        let s = m.simplified_ccf.as_ref().expect("linear SDOF is checked");
        assert!(!s.stable);
        assert!(
            (s.max_pole_real_per_s - 10.125).abs() < 0.01,
            "{}",
            s.max_pole_real_per_s
        );
        assert!(s.errors.is_none());
        assert!(
            s.note.contains("unstable") && s.note.contains("463.1j"),
            "{}",
            s.note
        );
        assert!(stage.x1_simplified.is_none());
    }

    /// With c = 500 N s/m the same rig's simplified form is stable (numpy
    /// roots of the quartic above: largest real part -6.32 rad/s), so it is
    /// simulated beside the full model. Dropping Cn is a model error, so its
    /// NRMSE on the full model's own log is clearly above zero.
    #[test]
    fn a_stable_simplified_ccf_is_validated_side_by_side() {
        let rig = model::PAPER_RIG;
        let specimen = SpecimenModel::LinearSdof {
            mass_kg: 3.8,
            damping_ns_per_m: 500.0,
            stiffness_n_per_m: 129_400.0,
        };
        let signals = signals_of(&rig, &specimen);
        let stage =
            validation_run(&rig, &specimen, &RigExtras::default(), &record(&signals)).unwrap();
        let s = stage.metrics.simplified_ccf.as_ref().unwrap();
        assert!(s.stable);
        assert!(
            (s.max_pole_real_per_s + 6.317).abs() < 0.01,
            "{}",
            s.max_pole_real_per_s
        );
        let e = s.errors.as_ref().expect("simulated");
        assert!(
            e.nrmse_pct > 0.1 && e.nrmse_pct.is_finite(),
            "{}",
            e.nrmse_pct
        );
        assert!(stage.metrics.nrmse_pct < 1e-6);
        assert_eq!(stage.x1_simplified.as_ref().unwrap().len(), 20_000);
    }

    #[test]
    fn an_outlier_is_flagged_and_the_others_are_not() {
        let mut m: Vec<ValidationMetrics> = [3.1, 2.8, 2.7, 40.0].map(metrics).to_vec();
        let mut refs: Vec<&mut ValidationMetrics> = m.iter_mut().collect();
        flag_outliers(&mut refs);
        assert_eq!(
            m.iter().map(|x| x.outlier).collect::<Vec<_>>(),
            [false, false, false, true]
        );
        assert!(m[3].note.as_ref().unwrap().contains("40.0 %"));
        // A wrong specimen among runs at the noise floor.
        let mut m: Vec<ValidationMetrics> = [0.09, 0.08, 3.9, 0.08].map(metrics).to_vec();
        let mut refs: Vec<&mut ValidationMetrics> = m.iter_mut().collect();
        flag_outliers(&mut refs);
        assert_eq!(
            m.iter().map(|x| x.outlier).collect::<Vec<_>>(),
            [false, false, true, false]
        );
        // Runs near the noise floor do not flag each other, nor do the
        // paper's Table 4 values.
        for v in [[0.09, 0.08, 0.3, 0.08], [3.1, 2.8, 2.7, 2.8]] {
            let mut m: Vec<ValidationMetrics> = v.map(metrics).to_vec();
            let mut refs: Vec<&mut ValidationMetrics> = m.iter_mut().collect();
            flag_outliers(&mut refs);
            assert!(m.iter().all(|x| !x.outlier), "{v:?}");
        }
        // Uniformly poor runs are not outliers of each other.
        let mut m: Vec<ValidationMetrics> = [30.0, 28.0, 33.0].map(metrics).to_vec();
        let mut refs: Vec<&mut ValidationMetrics> = m.iter_mut().collect();
        flag_outliers(&mut refs);
        assert!(m.iter().all(|x| !x.outlier));
    }

    /// Regression (the UTFSM MTS logs): a real command rests at a non-zero
    /// level (-0.21 mm) before the sweep. Simulated from zero state, the
    /// model answered that level with a step response the actuator never
    /// made (it had settled there long before the log began), which put
    /// NAE at 12.3 % on the UTFSM 0A log (8.9 % from equilibrium). The plant
    /// here is a first-order lag at rest at its equilibrium under the first command, then driven by a
    /// step; the measured record is its exact held-input response, so the
    /// comparison must be exact to round-off.
    #[test]
    fn a_command_resting_off_zero_starts_the_model_at_equilibrium() {
        let fs = 1000.0;
        let dt = 1.0 / fs;
        let a = 50.0; // pole (rad/s); G = a/(s + a), DC gain 1
        let tf = TransferFunction::new(&[a], &[1.0, a]).unwrap();
        let (rest, step) = (-2.1e-4, 1.5e-3);
        let n = 2000;
        let u: Vec<f64> = (0..n)
            .map(|k| if k < 500 { rest } else { rest + step })
            .collect();
        // Exact zero-order-hold response from equilibrium x = rest:
        // y[k + 1] = e^(-a T) y[k] + (1 - e^(-a T)) u[k].
        let phi = (-a * dt).exp();
        let mut y = vec![rest; n];
        for k in 0..n - 1 {
            y[k + 1] = phi * y[k] + (1.0 - phi) * u[k];
        }
        let rec = Record {
            sample_rate_hz: fs,
            command_m: &u,
            displacement_m: &y,
            force_n: None,
        };
        let t = fitted_run(&tf, &rec).unwrap();
        assert!(t.metrics.nae_pct < 1e-8, "NAE {} %", t.metrics.nae_pct);
        assert!(t.metrics.offset_removed_m.abs() < 1e-12);
    }
}
