//! The rig history as a Parquet table, one row per campaign (see
//! `servoid::drift`), for the next campaign and for anyone who plots a
//! rig's life in polars or pandas. Units: beta1 and a3 in 1/s, a1b0 in
//! N/(m s^2) at the row's p_gain, a2 in N/m, the delay in s. Same entries,
//! same bytes.

use std::path::Path;

use polars::prelude::Column;

use super::columns::{ColumnWriteError, frame_bytes};
use super::write_atomic;
use crate::drift::Entry;

/// Write the history atomically: readers see the old table or the new.
/// `extra` are columns of the lab's own (name, a cell per entry), written
/// after servoid's as text. `before`, the bytes the table holds now, is
/// first kept in `previous` when the update changes them (so the previous
/// copy is the last table that differs, not the one a rerun rewrote
/// unchanged).
pub fn write(
    path: &Path,
    previous: &Path,
    before: Option<&[u8]>,
    entries: &[Entry],
    extra: &[(String, Vec<Option<String>>)],
) -> Result<(), ColumnWriteError> {
    let text = |f: fn(&Entry) -> &str| entries.iter().map(f).map(String::from).collect::<Vec<_>>();
    let num = |f: fn(&Entry) -> f64| entries.iter().map(f).collect::<Vec<f64>>();
    let opt = |f: fn(&Entry) -> Option<f64>| entries.iter().map(f).collect::<Vec<Option<f64>>>();
    let n = entries.len();
    let mut cols = vec![
        Column::new("rig".into(), text(|e| &e.rig)),
        Column::new("campaign".into(), text(|e| &e.campaign)),
        Column::new(
            "date".into(),
            entries.iter().map(|e| e.date.clone()).collect::<Vec<_>>(),
        ),
        Column::new("inputs_sha256".into(), text(|e| &e.inputs_sha256)),
        Column::new("results_sha256".into(), text(|e| &e.results_sha256)),
        Column::new("p_gain".into(), num(|e| e.p_gain)),
        Column::new("beta1".into(), num(|e| e.beta1)),
        Column::new("beta1_std".into(), opt(|e| e.beta1_std)),
        Column::new("a1b0".into(), num(|e| e.a1b0)),
        Column::new("a1b0_std".into(), opt(|e| e.a1b0_std)),
        Column::new("a2".into(), num(|e| e.a2)),
        Column::new("a2_std".into(), opt(|e| e.a2_std)),
        Column::new("a3".into(), num(|e| e.a3)),
        Column::new("a3_std".into(), opt(|e| e.a3_std)),
        Column::new("servoid_version".into(), text(|e| &e.servoid_version)),
        Column::new("delay_s".into(), opt(|e| e.delay_s)),
        Column::new(
            "logs_sha256".into(),
            entries
                .iter()
                .map(|e| e.logs_sha256.clone())
                .collect::<Vec<_>>(),
        ),
    ];
    cols.extend(
        extra
            .iter()
            .map(|(name, cells)| Column::new(name.as_str().into(), cells.clone())),
    );
    let bytes = frame_bytes(path, n, cols)?;
    if let Some(before) = before.filter(|b| *b != &bytes[..])
        && std::fs::read(previous).ok().as_deref() != Some(before)
    {
        write_atomic(previous, before)?;
    }
    write_atomic(path, &bytes)?;
    Ok(())
}

/// Append `records` (one JSON object each) to the history's audit file
/// `path`, JSON lines: what a correction replaced and what a removal took
/// out, so no row leaves the history unrecorded. Written whole and
/// atomically, as the history is.
pub fn append_audit(path: &Path, records: &[serde_json::Value]) -> Result<(), ColumnWriteError> {
    if records.is_empty() {
        return Ok(());
    }
    let mut bytes = std::fs::read(path).unwrap_or_default();
    for r in records {
        bytes.extend_from_slice(r.to_string().as_bytes());
        bytes.push(b'\n');
    }
    write_atomic(path, &bytes)?;
    Ok(())
}
