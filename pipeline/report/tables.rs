//! Each run's FRF and model as Parquet tables beside results.json, for users
//! who continue in polars or pandas: `tables/frf-<id>.parquet` (one row per
//! frequency bin up to the upper frequency the figures show: the band's upper
//! edge or 35 Hz, whichever is higher, since the force path's notch lies
//! below 35 Hz for the paper's specimens), with the fit's mask and the model
//! as the measurement sees it, and `tables/model-<id>.parquet` (one row per
//! coefficient). What a run's tables hold ([`RunTables::of`]) and how they are
//! written ([`RunTables::write`]) live here together. Same data, same bytes:
//! the writer stamps no time or host into the file.

use std::path::Path;

use nalgebra::Complex;
use polars::prelude::Column;

use super::columns::{ColumnWriteError, frame_bytes};
use super::figures::catalogue::model_response;
use super::{Measured, WriteError, write_artifact};
use crate::fit::Intersample;
use crate::lti::TransferFunction;
use crate::results::RunResult;

/// Highest frequency a table holds, unless the fit band reaches higher:
/// all the analysis keeps.
pub const TABLE_MAX_HZ: f64 = crate::frf::KEPT_MAX_HZ;

/// The files of one run's tables, relative to the output folder.
fn names(id: &str) -> [String; 2] {
    [
        format!("tables/frf-{id}.parquet"),
        format!("tables/model-{id}.parquet"),
    ]
}

/// A run's tables as computed: its FRF table (when it has a log) and its
/// model table (when it has a transfer function).
#[derive(Debug, Clone, PartialEq)]
pub struct RunTables {
    id: String,
    frf: Option<FrfTable>,
    model: Option<ModelTable>,
}

impl RunTables {
    /// The tables of `run`, with its log's FRFs when it has a log.
    pub fn of(run: &RunResult, measured: Option<&Measured<'_>>, intersample: Intersample) -> Self {
        Self {
            id: run.id.clone(),
            frf: measured.map(|m| frf_table(run, m, intersample)),
            model: model_table(run),
        }
    }

    /// Write the tables under `out_dir`; returns the files written,
    /// relative to it.
    pub fn write(&self, out_dir: &Path) -> Result<Vec<String>, WriteError> {
        let [frf_name, model_name] = names(&self.id);
        let mut written = Vec::new();
        let unwrap = WriteError::from;
        if let Some(t) = &self.frf {
            write_frf(&out_dir.join(&frf_name), t).map_err(unwrap)?;
            written.push(frf_name);
        }
        if let Some(t) = &self.model {
            write_model(&out_dir.join(&model_name), t).map_err(unwrap)?;
            written.push(model_name);
        }
        Ok(written)
    }
}

/// A run's measured FRF with what the fit and the model make of it.
#[derive(Debug, Clone, PartialEq)]
pub struct FrfTable {
    pub freq_hz: Vec<f64>,
    /// Command to displacement, measured.
    pub h: Vec<Complex<f64>>,
    pub coherence: Vec<f64>,
    /// Whether each bin entered the fit (band and coherence).
    pub in_fit: Vec<bool>,
    /// The model as the measurement sees it (with the command's hold and
    /// any delay): the fitted one, or the rig's prediction.
    pub model: Option<Vec<Complex<f64>>>,
    /// Command to force, measured, when the log has force.
    pub force: Option<(Vec<Complex<f64>>, Vec<f64>)>,
}

/// A run's transfer-function coefficients: fitted ones with their standard
/// deviations, or a model's without.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelTable {
    pub name: Vec<String>,
    pub value: Vec<f64>,
    pub std: Vec<Option<f64>>,
}

/// Write a run's FRF table to `path` (under the output folder).
pub fn write_frf(path: &Path, t: &FrfTable) -> Result<(), ColumnWriteError> {
    let re = |v: &[Complex<f64>]| v.iter().map(|c| c.re).collect::<Vec<f64>>();
    let im = |v: &[Complex<f64>]| v.iter().map(|c| c.im).collect::<Vec<f64>>();
    let mut cols = vec![
        Column::new("freq_hz".into(), &t.freq_hz),
        Column::new("h_re".into(), re(&t.h)),
        Column::new("h_im".into(), im(&t.h)),
        Column::new("coherence".into(), &t.coherence),
        Column::new("in_fit".into(), &t.in_fit),
    ];
    if let Some(m) = &t.model {
        cols.push(Column::new("model_re".into(), re(m)));
        cols.push(Column::new("model_im".into(), im(m)));
    }
    if let Some((f, coh)) = &t.force {
        cols.push(Column::new("force_re".into(), re(f)));
        cols.push(Column::new("force_im".into(), im(f)));
        cols.push(Column::new("force_coherence".into(), coh));
    }
    write(path, t.freq_hz.len(), cols)
}

/// Write a run's model table to `path`.
pub fn write_model(path: &Path, t: &ModelTable) -> Result<(), ColumnWriteError> {
    let cols = vec![
        Column::new("name".into(), &t.name),
        Column::new("value".into(), &t.value),
        Column::new("std".into(), &t.std),
    ];
    write(path, t.name.len(), cols)
}

fn write(path: &Path, rows: usize, cols: Vec<Column>) -> Result<(), ColumnWriteError> {
    write_artifact(path, &frame_bytes(path, rows, cols)?)?;
    Ok(())
}

fn frf_table(run: &RunResult, st: &Measured<'_>, intersample: Intersample) -> FrfTable {
    let f_max = TABLE_MAX_HZ.max(run.fit.as_ref().map_or(0.0, |f| f.band_hz[1]));
    let bins: Vec<usize> = (0..st.frf.freq_hz.len())
        .filter(|&i| st.frf.freq_hz[i] > 0.0 && st.frf.freq_hz[i] <= f_max)
        .collect();
    let freq_hz: Vec<f64> = bins.iter().map(|&i| st.frf.freq_hz[i]).collect();
    let fs = st.sample_rate_hz;
    // A fitted model as its fit compared it with the log, a predicted one
    // with the hold's continuous factor (`model_response`).
    let model = match st.fit {
        Some(fit) => Some(fit.as_logged(intersample, fs, &freq_hz)),
        None => run.tf.as_ref().map(|t| {
            let tf = TransferFunction {
                num: t.num.clone(),
                den: t.den.clone(),
                delay_s: t.delay_s,
            };
            model_response(&tf, intersample, fs, &freq_hz)
        }),
    };
    FrfTable {
        h: bins.iter().map(|&i| st.frf.h[i]).collect(),
        coherence: bins.iter().map(|&i| st.frf.coherence[i]).collect(),
        in_fit: bins.iter().map(|&i| st.mask[i]).collect(),
        model,
        force: st.force_frf.map(|ff| {
            (
                bins.iter().map(|&i| ff.h[i]).collect(),
                bins.iter().map(|&i| ff.coherence[i]).collect(),
            )
        }),
        freq_hz,
    }
}

/// The fitted parameters with their standard deviations, else the model's
/// coefficients (`num[k]`, `den[k]`, highest power first).
fn model_table(run: &RunResult) -> Option<ModelTable> {
    if let Some(fit) = &run.fit {
        return Some(ModelTable {
            name: fit.param_names.clone(),
            value: fit.params.clone(),
            std: fit.std.iter().map(|s| Some(*s)).collect(),
        });
    }
    let tf = run.tf.as_ref()?;
    let mut t = ModelTable {
        name: Vec::new(),
        value: Vec::new(),
        std: Vec::new(),
    };
    for (part, coeffs) in [("num", &tf.num), ("den", &tf.den)] {
        for (k, c) in coeffs.iter().enumerate() {
            t.name.push(format!("{part}[{k}]"));
            t.value.push(*c);
            t.std.push(None);
        }
    }
    Some(t)
}

/// The campaign's tracking table, `tables/tracking.parquet`, relative to the
/// output folder.
pub const TRACKING_TABLE: &str = "tables/tracking.parquet";

/// Every run's tracking in one table (one row per run, manifest order): the
/// measured measures, the model's prediction and the compensated
/// prediction (each `measured_`, `predicted_`, `compensated_` and the
/// measure: delays in s, FEI amplitude, phase in degrees and delay in s,
/// the tracking indicator in % of a 90-degree lag's area, J2 and J3 in %), the delay the
/// model lacks, and the compensator's design and target range. A measure a
/// run does not have is null. Built from the results alone, so a merged
/// campaign writes the same table as one run whole.
pub fn write_tracking(path: &Path, runs: &[RunResult]) -> Result<(), ColumnWriteError> {
    use crate::tracking::Tracking;
    type Measure = fn(&Tracking) -> Option<f64>;
    const MEASURES: [(&str, Measure); 8] = [
        ("delay_xcorr_s", |t| t.delay_xcorr_s),
        ("delay_phase_slope_s", |t| t.delay_phase_slope_s),
        ("fei_amplitude", |t| t.fei.as_ref().map(|f| f.amplitude)),
        ("fei_phase_deg", |t| t.fei.as_ref().map(|f| f.phase_deg)),
        ("fei_delay_s", |t| t.fei.as_ref().map(|f| f.delay_s)),
        ("tracking_indicator_pct", |t| t.tracking_indicator_pct),
        ("j2_pct", |t| t.errors.as_ref().map(|e| e.nrms_pct)),
        ("j3_pct", |t| t.errors.as_ref().map(|e| e.peak_pct)),
    ];
    const SOURCES: [&str; 3] = ["measured", "predicted", "compensated"];
    const AFTER: [&str; 3] = ["model_gap_s", "compensator_cutoff_hz", "compensator_lead_s"];
    // Each run's tracking is read once (it may be parked), its numbers
    // gathered by column.
    let n = runs.len();
    let mut numbers = vec![Vec::with_capacity(n); SOURCES.len() * MEASURES.len() + AFTER.len()];
    let mut meets: Vec<Option<bool>> = Vec::with_capacity(n);
    let mut targets = [Vec::with_capacity(n), Vec::with_capacity(n)];
    for r in runs {
        let tracking = r.tracking.as_ref().map(|t| t.get());
        let t = tracking.as_deref();
        let c = t.and_then(|t| t.compensator.as_ref());
        let design = c.and_then(|c| c.design.as_ref());
        let sources = [
            t.map(|t| &t.measured),
            t.and_then(|t| t.predicted.as_ref()),
            c.and_then(|c| c.predicted.as_ref()),
        ];
        let measured = sources
            .iter()
            .flat_map(|s| MEASURES.iter().map(move |(_, m)| s.and_then(m)));
        let after = [
            t.and_then(|t| t.model_gap_s),
            design.map(|d| d.cutoff_hz),
            design.map(|d| d.lead_s),
        ];
        for (column, v) in numbers.iter_mut().zip(measured.chain(after)) {
            column.push(v);
        }
        meets.push(c.and_then(|c| c.meets_target));
        let k = c.and_then(|c| c.target_stiffness_n_per_m);
        for (i, column) in targets.iter_mut().enumerate() {
            column.push(k.map(|k| k[i]));
        }
    }
    let names = SOURCES
        .iter()
        .flat_map(|s| MEASURES.iter().map(move |(m, _)| format!("{s}_{m}")))
        .chain(AFTER.map(String::from));
    let text = |f: &dyn Fn(&RunResult) -> String| runs.iter().map(f).collect::<Vec<String>>();
    let mut cols = vec![
        Column::new("run".into(), text(&|r| r.id.clone())),
        Column::new("role".into(), text(&|r| r.role.as_str().to_string())),
    ];
    cols.extend(
        names
            .zip(numbers)
            .map(|(name, v)| Column::new(name.into(), v)),
    );
    cols.push(Column::new("compensator_meets_target".into(), meets));
    for (name, v) in ["low", "high"].iter().zip(targets) {
        cols.push(Column::new(
            format!("compensator_target_k_{name}_n_per_m").into(),
            v,
        ));
    }
    write(path, runs.len(), cols)
}
