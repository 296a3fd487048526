//! What `models.mat` holds: the campaign's identified models in the shapes
//! MATLAB's `tf(num, den)` and `ss(A, B, C, D)` (and `scipy.signal`) take,
//! so a lab designing a compensator starts from the numbers servoid found.
//! Built from the results alone (pure); `run` writes the bytes.
//!
//! Three variables, each a struct a MATLAB user reads by name:
//! - `servoid`: the version, campaign and manifest hash, and the units.
//! - `rig`: beta1, a1b0 (at the rig's `p_gain`), a2, a3, their stds and
//!   covariance, and R1.
//! - `runs`: a 1 x n struct array in manifest order: each run's x1/u
//!   (numerator, denominator, delay; a fitted one's band, parameters, stds,
//!   covariance); its plant as a state space, physical (Eq. 10) and, for an
//!   SDOF specimen, canonical (Eqs. 34-35) with Cn kept and dropped
//!   (Sec. 3.2.2); a validation run's compensator (`filter(b, a, x)` at
//!   `fs`). What a run does not have is `[]`.

use super::matlab::{MatValue, MatWriter};
use crate::model::SpecimenModel;
use crate::model::{self, CnTerm, LinearSdof, LinearSpecimen, RigParams};
use crate::results::{FitSummary, Results, RigResult, RunResult, Status, TfResult, TfSource};
use crate::tracking::compensator::CompensatorOutcome;
use std::io::{Seek, Write};

/// `models.mat` for `results`, written to `w` a run at a time. The header
/// names the servoid version and nothing that changes from one run to the
/// next (no date), so the same results give the same bytes.
pub fn write_models_mat<W: Write + Seek>(w: W, results: &Results) -> std::io::Result<()> {
    let head = format!(
        "MATLAB 5.0 MAT-file, Platform: servoid {}, identified models of campaign {}",
        results.servoid_version, results.campaign.name
    );
    let rig = results.rig.as_ref();
    let mut mat = MatWriter::new(w, &head)?;
    mat.var("servoid", &about(results))?;
    mat.var("rig", &rig.map_or_else(MatValue::empty, rig_value))?;
    mat.struct_array("runs", &RUN_FIELDS, results.runs.len(), |i| {
        run_value(&results.runs[i], rig)
    })
}

fn text(s: &str) -> MatValue {
    MatValue::Text(s.into())
}

fn about(results: &Results) -> MatValue {
    MatValue::Struct(vec![
        ("version".into(), text(&results.servoid_version)),
        ("campaign".into(), text(&results.campaign.name)),
        ("manifest".into(), text(&results.campaign.manifest)),
        (
            "manifest_sha256".into(),
            text(&results.campaign.manifest_sha256),
        ),
        (
            "units".into(),
            text(
                "SI throughout: displacement m, force N, time s, mass kg; transfer functions x1/u in m/m with the delay in s",
            ),
        ),
    ])
}

/// The rig's parameters in the order of its covariance.
const RIG_NAMES: [&str; 4] = ["beta1", "a1b0", "a2", "a3"];
const RIG_UNITS: [&str; 4] = ["1/s", "N/(m s^2)", "N/m", "1/s"];

fn rig_value(rig: &RigResult) -> MatValue {
    let est = [&rig.beta1, &rig.a1b0, &rig.a2, &rig.a3];
    let values: Vec<f64> = est.iter().map(|e| e.value).collect();
    // A given rig has no stds: NaN, as MATLAB marks a missing number.
    let std: Vec<f64> = est.iter().map(|e| e.std.unwrap_or(f64::NAN)).collect();
    let covariance = rig
        .covariance
        .map_or_else(MatValue::empty, |c| MatValue::from_rows(&c));
    let mut fields = vec![
        ("source".to_string(), text(rig_source(rig))),
        ("p_gain".into(), MatValue::scalar(rig.p_gain)),
        ("names".into(), MatValue::texts(&RIG_NAMES)),
        ("units".into(), MatValue::texts(&RIG_UNITS)),
        ("values".into(), MatValue::row(&values)),
        ("std".into(), MatValue::row(&std)),
        ("covariance".into(), covariance),
    ];
    for (name, e) in RIG_NAMES.iter().zip(est) {
        fields.push((name.to_string(), MatValue::scalar(e.value)));
    }
    fields.push(("R1".into(), MatValue::scalar(rig.R1.value)));
    fields.push((
        "R1_std".into(),
        MatValue::scalar(rig.R1.std.unwrap_or(f64::NAN)),
    ));
    MatValue::Struct(fields)
}

fn rig_source(rig: &RigResult) -> &'static str {
    use crate::results::RigSource;
    match rig.source {
        RigSource::Identified => "identified",
        RigSource::Joint => "joint",
        RigSource::Given => "given",
    }
}

/// The rig as the model takes it, a1b0 at the rig's own P gain.
fn rig_params(rig: &RigResult) -> RigParams {
    RigParams {
        beta1_per_s: rig.beta1.value,
        a1b0_n_per_m_s2: rig.a1b0.value,
        a2_n_per_m: rig.a2.value,
        a3_per_s: rig.a3.value,
        p_gain: rig.p_gain,
    }
}

const RUN_FIELDS: [&str; 11] = [
    "id",
    "role",
    "status",
    "p_gain",
    "specimen",
    "tf",
    "physical",
    "ccf",
    "ccf_simplified",
    "compensator",
    "error",
];

fn run_value(run: &RunResult, rig: Option<&RigResult>) -> Vec<MatValue> {
    let rig_at_p = rig.map(|r| rig_params(r).at_p_gain(run.p_gain));
    let linear = run.specimen.linear();
    let physical = match (rig_at_p, linear) {
        (Some(rig), Some(lin)) => physical(&rig, &lin),
        _ => MatValue::empty(),
    };
    let sdof = match run.specimen {
        SpecimenModel::LinearSdof {
            mass_kg,
            damping_ns_per_m,
            stiffness_n_per_m,
        } => Some(LinearSdof {
            mass_kg,
            damping_ns_per_m,
            stiffness_n_per_m,
        }),
        _ => None,
    };
    let (ccf, simplified) = match (rig_at_p, sdof) {
        (Some(rig), Some(sdof)) => (
            canonical(&rig, &sdof, CnTerm::Kept),
            canonical(&rig, &sdof, CnTerm::Dropped),
        ),
        _ => (MatValue::empty(), MatValue::empty()),
    };
    let status = match run.status {
        Status::Ok => "ok",
        Status::Failed => "failed",
    };
    vec![
        text(&run.id),
        text(run.role.as_str()),
        text(status),
        MatValue::scalar(run.p_gain),
        specimen(&run.specimen),
        run.tf
            .as_ref()
            .map_or_else(MatValue::empty, |tf| tf_value(tf, run.fit.as_deref())),
        physical,
        ccf,
        simplified,
        run.tracking
            .as_ref()
            .map(|t| t.get())
            .as_deref()
            .and_then(|t| t.compensator.as_ref())
            .map_or_else(MatValue::empty, compensator),
        text(run.error.as_deref().unwrap_or("")),
    ]
}

/// The run's compensator as `filter(b, a, x)` runs it at `fs`, with its
/// continuous design `tf(num_s, den_s)` before the lead; `[]` without one.
fn compensator(c: &CompensatorOutcome) -> MatValue {
    let Some(d) = &c.design else {
        return MatValue::empty();
    };
    MatValue::Struct(vec![
        ("b".into(), MatValue::row(&d.b)),
        ("a".into(), MatValue::row(&d.a)),
        ("fs".into(), MatValue::scalar(d.sample_rate_hz)),
        ("cutoff_hz".into(), MatValue::scalar(d.cutoff_hz)),
        ("order".into(), MatValue::scalar(d.order as f64)),
        ("lead_s".into(), MatValue::scalar(d.lead_s)),
        ("num_s".into(), MatValue::row(&d.num_s)),
        ("den_s".into(), MatValue::row(&d.den_s)),
        ("band_hz".into(), MatValue::row(&c.band_hz)),
    ])
}

/// The specimen: its kind, its m, c, k (`[]` for what it does not have),
/// then every other parameter its kind has (a Duffing spring's cubic
/// stiffness, Bouc-Wen's, friction's), named as in results.json.
fn specimen(s: &SpecimenModel) -> MatValue {
    const MCK: [&str; 3] = ["mass_kg", "damping_ns_per_m", "stiffness_n_per_m"];
    // results.json's serialisation: one source for the names and values.
    let fields = match serde_json::to_value(s) {
        Ok(serde_json::Value::Object(map)) => map,
        _ => serde_json::Map::new(),
    };
    let num = |v: Option<f64>| v.map_or_else(MatValue::empty, MatValue::scalar);
    let mut out = vec![("kind".to_string(), text(s.name()))];
    out.extend(
        MCK.iter()
            .map(|&k| (k.to_string(), num(fields.get(k).and_then(|v| v.as_f64())))),
    );
    out.extend(
        fields
            .iter()
            .filter(|(k, _)| !MCK.contains(&k.as_str()))
            .filter_map(|(k, v)| Some((k.clone(), MatValue::scalar(v.as_f64()?)))),
    );
    MatValue::Struct(out)
}

/// x1/u with, for a fitted one, what the fit says of it.
fn tf_value(tf: &TfResult, fit: Option<&FitSummary>) -> MatValue {
    let source = match tf.source {
        TfSource::Published => "published",
        TfSource::Fitted => "fitted",
        TfSource::Model => "model",
    };
    let fit = fit.filter(|_| tf.source == TfSource::Fitted);
    let or_empty = |v: Option<MatValue>| v.unwrap_or_else(MatValue::empty);
    let covariance = fit.and_then(|f| f.covariance.as_ref()).map(|c| {
        let n = c.len();
        MatValue::Matrix {
            rows: n,
            cols: n,
            // Column by column; the matrix is symmetric, but say it as
            // the format wants it.
            data: (0..n).flat_map(|j| c.iter().map(move |r| r[j])).collect(),
        }
    });
    MatValue::Struct(vec![
        ("num".into(), MatValue::row(&tf.num)),
        ("den".into(), MatValue::row(&tf.den)),
        ("delay_s".into(), MatValue::scalar(tf.delay_s)),
        ("source".into(), text(source)),
        (
            "band_hz".into(),
            or_empty(fit.map(|f| MatValue::row(&f.band_hz))),
        ),
        (
            "param_names".into(),
            or_empty(fit.map(|f| MatValue::texts(&f.param_names))),
        ),
        (
            "params".into(),
            or_empty(fit.map(|f| MatValue::row(&f.params))),
        ),
        ("std".into(), or_empty(fit.map(|f| MatValue::row(&f.std)))),
        ("covariance".into(), or_empty(covariance)),
    ])
}

/// A state space's four matrices with its states and outputs named.
fn state_space(
    ss: &crate::lti::StateSpace,
    states: &[&str],
    note: &str,
) -> Vec<(String, MatValue)> {
    let matrix = |m: &nalgebra::DMatrix<f64>| MatValue::Matrix {
        rows: m.nrows(),
        cols: m.ncols(),
        // nalgebra stores column-major, as MAT files do.
        data: m.as_slice().to_vec(),
    };
    vec![
        ("A".into(), matrix(&ss.a)),
        ("B".into(), MatValue::column(ss.b.as_slice())),
        ("C".into(), matrix(&ss.c)),
        ("D".into(), MatValue::column(ss.d.as_slice())),
        ("states".into(), MatValue::texts(states)),
        ("outputs".into(), MatValue::texts(&["x1 (m)", "f (N)"])),
        ("note".into(), text(note)),
    ]
}

/// Eq. 10 as a state space; for a massless specimen the x2 row is gone
/// (`model::state_space`).
fn physical(rig: &RigParams, lin: &LinearSpecimen) -> MatValue {
    let ss = model::state_space(rig, lin);
    let (states, note): (&[&str], &str) = match lin {
        LinearSpecimen::Sdof { .. } => (
            &["x1 (m)", "x2 = dx1/dt (m/s)", "f (N)", "r (N/s)"],
            "Eq. 10: x1' = x2, m x2' = f - c x2 - k x1, f' = -a2 x2 - a3 f + r, r' = -beta1 r + a1b0 (u - x1)",
        ),
        _ => (
            &["x1 (m)", "r (N/s)"],
            "Eq. 10 with a massless specimen (f = k x1): x1' = (r - a3 k x1) / (k + a2), r' = -beta1 r + a1b0 (u - x1)",
        ),
    };
    MatValue::Struct(state_space(&ss, states, note))
}

/// Eqs. 34-35 with Cn kept (the plant exactly) or dropped (the paper's
/// simplified model), with C1-C5.
fn canonical(rig: &RigParams, sdof: &LinearSdof, cn: CnTerm) -> MatValue {
    let ss = model::ccf_linear_state_space(rig, sdof, cn);
    let c = model::ccf_coefficients(rig, sdof, 0.0, 0.0);
    let note = match cn {
        CnTerm::Kept => {
            "Eqs. 34-35 with Cn = h'' kept: the plant of Eq. 10 exactly; f = m x3 + c x2 + k x1"
        }
        CnTerm::Dropped => {
            "Eqs. 34-35 with Cn dropped, as the paper simplifies for a linear specimen (Sec. 3.2.2): a different model, whose poles differ"
        }
    };
    let mut fields = state_space(
        &ss,
        &[
            "x1 (m)",
            "x2 = dx1/dt (m/s)",
            "x3 = d2x1/dt2 (m/s^2)",
            "x4 = d3x1/dt3 (m/s^3)",
        ],
        note,
    );
    for (name, v) in [
        ("C1", c.C1),
        ("C2", c.C2),
        ("C3", c.C3),
        ("C4", c.C4),
        ("C5", c.C5),
    ] {
        fields.push((name.into(), MatValue::scalar(v)));
    }
    MatValue::Struct(fields)
}
