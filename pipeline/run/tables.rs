//! A run's FRF and model as the tables `report::tables` writes: the bins up
//! to the upper frequency the figures show (the band's upper edge or 35 Hz,
//! whichever is higher: the force path's notch lies below 35 Hz for the
//! paper's specimens), with the fit's mask and the model as the measurement
//! sees it.

use std::path::Path;

use super::acquire::LogStage;
use super::figures::model_response;
use crate::fit::Intersample;
use crate::lti::TransferFunction;
use crate::report::tables::{self, FrfTable, ModelTable};
use crate::report::{WriteError, logs::LogWriteError};
use crate::results::RunResult;

/// Highest frequency a table holds, unless the fit band reaches higher.
pub(super) const TABLE_MAX_HZ: f64 = 35.0;

/// The files of one run's tables, relative to the output folder.
pub(super) fn names(id: &str) -> [String; 2] {
    [
        format!("tables/frf-{id}.parquet"),
        format!("tables/model-{id}.parquet"),
    ]
}

/// Write a run's FRF table (when it has a log) and model table (when it has
/// a transfer function) under `out_dir`; returns the files written.
pub(super) fn write(
    out_dir: &Path,
    run: &RunResult,
    stage: Option<&LogStage>,
    intersample: Intersample,
) -> Result<Vec<String>, WriteError> {
    let [frf_name, model_name] = names(&run.id);
    let mut written = Vec::new();
    let unwrap = |e: LogWriteError| match e {
        LogWriteError::Write(w) => w,
        other => WriteError::Table(Box::new(other)),
    };
    if let Some(st) = stage {
        tables::write_frf(&out_dir.join(&frf_name), &frf_table(run, st, intersample))
            .map_err(unwrap)?;
        written.push(frf_name);
    }
    if let Some(t) = model_table(run) {
        tables::write_model(&out_dir.join(&model_name), &t).map_err(unwrap)?;
        written.push(model_name);
    }
    Ok(written)
}

fn frf_table(run: &RunResult, st: &LogStage, intersample: Intersample) -> FrfTable {
    let f_max = TABLE_MAX_HZ.max(run.fit.as_ref().map_or(0.0, |f| f.band_hz[1]));
    let bins: Vec<usize> = (0..st.frf.freq_hz.len())
        .filter(|&i| st.frf.freq_hz[i] > 0.0 && st.frf.freq_hz[i] <= f_max)
        .collect();
    let freq_hz: Vec<f64> = bins.iter().map(|&i| st.frf.freq_hz[i]).collect();
    let fs = st.log.sample_rate_hz;
    let model_tf = match &st.fit {
        Some(fit) => Some(fit.tf.clone()),
        None => run.tf.as_ref().map(|t| TransferFunction {
            num: t.num.clone(),
            den: t.den.clone(),
            delay_s: t.delay_s,
        }),
    };
    FrfTable {
        h: bins.iter().map(|&i| st.frf.h[i]).collect(),
        coherence: bins.iter().map(|&i| st.frf.coherence[i]).collect(),
        in_fit: bins.iter().map(|&i| st.mask[i]).collect(),
        model: model_tf.map(|tf| model_response(&tf, intersample, fs, &freq_hz)),
        force: st.force_frf.as_ref().map(|ff| {
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
