//! Time-domain checks of a run with a log: the model driven by the measured
//! command (held between samples, as the D/A did), compared with the measured
//! displacement and force by the paper's Eqs. 47-48 over the whole record and
//! in the four windows of its figures. For a validation run the model is the
//! identified rig with the run's specimen, simulated in the physical form
//! (Eq. 10) and in the controllable canonical form with Cn (Eq. 34), which
//! must agree, and in the paper's simplified form (Cn dropped) side by side.
//! For an identification run it is the fitted transfer function (Figs. 9,
//! 12, 14).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::ingest::Log;
use crate::lti::{StateSpace, TransferFunction};
use crate::model::{self, CnTerm, LinearSdof, RigParams};
use crate::simulate::discrete::simulate_linear;
use crate::simulate::ode::Integrator;
use crate::simulate::plant::{self, PlantSpec, Unmodelled};
use crate::simulate::specimen::SpecimenModel;
use crate::validate::{self, Errors, Window};

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
    /// The paper's simplified canonical form (Cn dropped) against the measured displacement.
    pub simplified_ccf: Option<Errors>,
    /// max |x1(CCF with Cn) - x1(physical)| / max |x1(physical)|: the two
    /// forms are one model, so this is round-off.
    pub ccf_consistency: Option<f64>,
    /// Set when this run's errors are far above the campaign's other runs.
    pub outlier: bool,
    pub note: Option<String>,
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

fn simulate(ss: &StateSpace, log: &Log, delay_s: f64) -> Result<Vec<Vec<f64>>, String> {
    let outputs = ss.c.nrows();
    simulate_linear(
        ss,
        &log.command_m,
        1.0 / log.sample_rate_hz,
        &vec![delay_s; outputs],
    )
    .map_err(|e| e.to_string())
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

/// A validation run: the identified rig at the run's P gain with its specimen.
pub fn validation_run(
    rig_at_p: &RigParams,
    specimen: &SpecimenModel,
    log: &Log,
) -> Result<TimeStage, String> {
    let fs = log.sample_rate_hz;
    let windows = validate::locate_windows(&log.command_m, fs);
    let (x1, force) = match specimen.linear() {
        Some(lin) => {
            let mut out = simulate(&model::state_space(rig_at_p, &lin), log, 0.0)?;
            let f = out.pop().expect("two outputs");
            (out.pop().expect("two outputs"), f)
        }
        None => {
            let spec = PlantSpec {
                rig: *rig_at_p,
                specimen: *specimen,
                unmodelled: Unmodelled::default(),
            };
            let r = plant::simulate(
                &spec,
                &log.command_m,
                fs,
                [0.0, 0.0],
                Integrator::Rk4 { substeps: 8 },
            )
            .map_err(|e| e.to_string())?;
            (r.x1_m, r.force_n)
        }
    };
    let (whole, per_window, offset, centred) = compare(&log.displacement_m, &x1, fs, &windows)
        .ok_or("the measured displacement is identically zero")?;
    let force_errors = log.force_n.as_ref().and_then(|f| {
        let n = f.len().min(force.len());
        let offset = (0..n).map(|k| f[k] - force[k]).sum::<f64>() / n.max(1) as f64;
        let centred: Vec<f64> = f[..n].iter().map(|v| v - offset).collect();
        validate::errors(&centred, &force[..n])
    });
    let (mut simplified, mut simplified_errors, mut consistency) = (None, None, None);
    if let SpecimenModel::LinearSdof {
        mass_kg,
        damping_ns_per_m,
        stiffness_n_per_m,
    } = *specimen
    {
        let sdof = LinearSdof {
            mass_kg,
            damping_ns_per_m,
            stiffness_n_per_m,
        };
        let kept = simulate(
            &model::ccf_linear_state_space(rig_at_p, &sdof, CnTerm::Kept),
            log,
            0.0,
        )?;
        let peak = x1.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        let diff = kept[0]
            .iter()
            .zip(&x1)
            .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
        consistency = (peak > 0.0).then(|| diff / peak);
        let dropped = simulate(
            &model::ccf_linear_state_space(rig_at_p, &sdof, CnTerm::Dropped),
            log,
            0.0,
        )?;
        let x_dropped = dropped.into_iter().next().expect("x1 output");
        simplified_errors = compare(&log.displacement_m, &x_dropped, fs, &[]).map(|c| c.0);
        simplified = Some(x_dropped);
    }
    Ok(TimeStage {
        metrics: ValidationMetrics {
            nrmse_pct: whole.nrmse_pct,
            nae_pct: whole.nae_pct,
            fit_pct: whole.fit_pct,
            model: "identified rig with the run's specimen (Eq. 10)".into(),
            offset_removed_m: offset,
            windows: per_window,
            force: force_errors,
            simplified_ccf: simplified_errors,
            ccf_consistency: consistency,
            outlier: false,
            note: None,
        },
        windows,
        x1_measured: centred,
        x1_simulated: x1,
        x1_simplified: simplified,
    })
}

/// An identification run: its fitted transfer function (hold exact, delay
/// as fitted) driven by the measured command (the paper's Figs. 9, 12, 14).
pub fn fitted_run(tf: &TransferFunction, log: &Log) -> Result<TimeStage, String> {
    let fs = log.sample_rate_hz;
    let windows = validate::locate_windows(&log.command_m, fs);
    let out = simulate(&tf.to_state_space(), log, tf.delay_s)?;
    let x1 = out.into_iter().next().expect("one output");
    let (whole, per_window, offset, centred) = compare(&log.displacement_m, &x1, fs, &windows)
        .ok_or("the measured displacement is identically zero")?;
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
        },
        windows,
        x1_measured: centred,
        x1_simulated: x1,
        x1_simplified: None,
    })
}

/// Flag validation runs whose NRMSE is far above the others': more than three
/// times the median of the other runs and above 5 %, the sign of a specimen
/// that is not what the manifest says (or a log of another run).
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
        if m.nrmse_pct > 3.0 * median && m.nrmse_pct > 5.0 {
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
        }
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
        // Uniformly poor runs are not outliers of each other.
        let mut m: Vec<ValidationMetrics> = [30.0, 28.0, 33.0].map(metrics).to_vec();
        let mut refs: Vec<&mut ValidationMetrics> = m.iter_mut().collect();
        flag_outliers(&mut refs);
        assert!(m.iter().all(|x| !x.outlier));
    }
}
