//! Each run's FRF and model as Parquet tables beside results.json, for users
//! who continue in polars or pandas: `tables/frf-<id>.parquet` (one row per
//! frequency bin up to the figures' upper frequency) and
//! `tables/model-<id>.parquet` (one row per coefficient). Same data, same
//! bytes: the writer stamps no time or host into the file.

use std::path::Path;

use nalgebra::Complex;
use polars::prelude::Column;

use super::logs::{LogWriteError, frame_bytes};
use super::write_artifact;

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
pub fn write_frf(path: &Path, t: &FrfTable) -> Result<(), LogWriteError> {
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
pub fn write_model(path: &Path, t: &ModelTable) -> Result<(), LogWriteError> {
    let cols = vec![
        Column::new("name".into(), &t.name),
        Column::new("value".into(), &t.value),
        Column::new("std".into(), &t.std),
    ];
    write(path, t.name.len(), cols)
}

fn write(path: &Path, rows: usize, cols: Vec<Column>) -> Result<(), LogWriteError> {
    write_artifact(path, &frame_bytes(path, rows, cols)?)?;
    Ok(())
}
