//! Parquet logs, read by polars. Only the wanted columns are decoded; any
//! numeric column type is accepted and converted to f64. Places are 1-based
//! table rows.

use std::io::Cursor;
use std::path::Path;

use polars::prelude::{DataType, ParquetReader, SerReader};

use super::plan::{Column, LogPlan};
use super::{At, FormatProblem, IngestError, Raw, list, raw_from_table, wanted};

/// Read a Parquet log's wanted columns.
pub(super) fn read<'a>(
    path: &Path,
    bytes: &'a [u8],
    plan: &'a LogPlan,
) -> Result<Raw<'a>, IngestError> {
    let format = |problem| IngestError::format(path, problem);
    let mut reader = ParquetReader::new(Cursor::new(bytes));
    // A panic inside polars on damaged bytes (found by the Parquet fuzz
    // target) is reported as such, not a crash.
    let damaged = |message| format(FormatProblem::ParquetDamaged { message });
    let schema = super::guard_polars(|| reader.schema())
        .map_err(damaged)?
        .map_err(|source| format(FormatProblem::ParquetUnreadable { source }))?;
    let names: Vec<String> = schema.iter_names().map(|n| n.to_string()).collect();

    let want = wanted(plan);
    let mut index = Vec::with_capacity(want.len());
    for w in &want {
        let found = match w.column {
            Column::Name(n) => names.iter().position(|c| c == n),
            Column::Index(i) => (*i < names.len()).then_some(*i),
        };
        index.push(found.ok_or_else(|| IngestError::MissingColumn {
            path: path.to_path_buf(),
            channel: w.channel,
            column: w.column.to_string(),
            available: format!(
                "{} columns, indices 0 to {}: {}",
                names.len(),
                names.len().saturating_sub(1),
                list(names.iter().map(|n| format!("`{n}`")))
            ),
        })?);
    }
    let mut projection = index.clone();
    projection.sort_unstable();
    projection.dedup();
    let df = super::guard_polars(|| reader.with_projection(Some(projection)).finish())
        .map_err(damaged)?
        .map_err(|source| format(FormatProblem::ParquetRead { source }))?;
    if df.height() == 0 {
        return Err(IngestError::HeaderOnly {
            path: path.to_path_buf(),
            what: "a schema but no rows".into(),
        });
    }

    let mut columns = Vec::with_capacity(want.len());
    for (w, &i) in want.iter().zip(&index) {
        let name = &names[i];
        let col = df.column(name).map_err(|source| {
            format(FormatProblem::ColumnLost {
                column: name.clone(),
                source,
            })
        })?;
        if !col.dtype().is_primitive_numeric() {
            return Err(format(FormatProblem::NotNumeric {
                column: name.clone(),
                channel: w.channel,
                dtype: Box::new(col.dtype().clone()),
            }));
        }
        let not_f64 = |source| {
            format(FormatProblem::NotF64 {
                column: name.clone(),
                source,
            })
        };
        let col = col.cast(&DataType::Float64).map_err(not_f64)?;
        let ca = col.f64().map_err(not_f64)?;
        if ca.null_count() > 0 {
            let row = ca.iter().position(|v| v.is_none()).expect("a null exists");
            return Err(IngestError::MissingValue {
                path: path.to_path_buf(),
                at: At::Row(row + 1),
                channel: w.channel,
                column: w.column.to_string(),
                detail: "null".into(),
            });
        }
        let mut v = Vec::with_capacity(ca.len());
        for chunk in ca.downcast_iter() {
            v.extend_from_slice(chunk.values());
        }
        columns.push(v);
    }
    raw_from_table(path, plan, columns, Box::new(|i| At::Row(i + 1)))
}
