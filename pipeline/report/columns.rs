//! Named columns as CSV or Parquet: the simulator's synthetic lab logs (for
//! `ingest` to read back), and through `frame_bytes` the runs' tables and the
//! rig's history. Every writer gives the same bytes for the same columns,
//! and writes atomically (temporary sibling, then rename). The simulator's
//! logs may also be MATLAB MAT-files (level 5 and v7.3), HDF5 or TDMS, as
//! labs' acquisition systems write them, so each reader is tried on a
//! campaign whose truth is known.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use polars::prelude::{Column, DataFrame, ParquetCompression, ParquetWriter};

use super::{WriteError, write_artifact};

/// Why named columns could not be written.
#[derive(Debug, thiserror::Error)]
pub enum ColumnWriteError {
    #[error(transparent)]
    Write(#[from] WriteError),
    #[error("{}: no columns to write", path.display())]
    NoColumns { path: PathBuf },
    #[error("{}: column `{name}` has {len} values but `{first}` has {first_len}; columns must be equally long", path.display())]
    Ragged {
        path: PathBuf,
        name: String,
        len: usize,
        first: String,
        first_len: usize,
    },
    #[error("{}: column name {name:?} must be non-empty, unique and free of commas, quotes and line breaks", path.display())]
    BadName { path: PathBuf, name: String },
    #[error("{}: {format} encoding failed: {why}", path.display())]
    Encode {
        path: PathBuf,
        format: &'static str,
        why: String,
    },
    #[error("{}: Parquet encoding failed: {source}", path.display())]
    Parquet {
        path: PathBuf,
        #[source]
        source: polars::prelude::PolarsError,
    },
}

impl ColumnWriteError {
    /// This error with every path it names passed through `f`.
    pub fn map_paths(self, f: &dyn Fn(&Path) -> PathBuf) -> Self {
        match self {
            Self::Write(e) => Self::Write(e.map_paths(f)),
            Self::NoColumns { path } => Self::NoColumns { path: f(&path) },
            Self::Ragged {
                path,
                name,
                len,
                first,
                first_len,
            } => Self::Ragged {
                path: f(&path),
                name,
                len,
                first,
                first_len,
            },
            Self::BadName { path, name } => Self::BadName {
                path: f(&path),
                name,
            },
            Self::Parquet { path, source } => Self::Parquet {
                path: f(&path),
                source,
            },
            Self::Encode { path, format, why } => Self::Encode {
                path: f(&path),
                format,
                why,
            },
        }
    }
}

/// Write `columns` as CSV: a header line of the names, then one line per
/// row, fields separated by `,`, lines ended by `\n`. Each value is printed
/// in the shortest form that reads back to the same f64 (plain decimals for
/// magnitudes in \[1e-5, 1e16), else exponent form; `NaN`, `inf`, `-inf` for
/// non-finite values).
pub fn write_csv(path: &Path, columns: &[(&str, &[f64])]) -> Result<(), ColumnWriteError> {
    let bytes = csv_bytes(path, columns)?;
    write_artifact(path, &bytes)?;
    Ok(())
}

/// The bytes [`write_csv`] writes (`path` only names the file in errors).
pub fn csv_bytes(path: &Path, columns: &[(&str, &[f64])]) -> Result<Vec<u8>, ColumnWriteError> {
    let n = check(path, columns)?;
    // About 20 bytes per value is typical of shortest round-trip output.
    let mut s = String::with_capacity(20 * n * columns.len() + 64);
    let names: Vec<&str> = columns.iter().map(|(name, _)| *name).collect();
    s.push_str(&names.join(","));
    s.push('\n');
    for row in 0..n {
        for (j, (_, values)) in columns.iter().enumerate() {
            if j > 0 {
                s.push(',');
            }
            push_shortest(&mut s, values[row]);
        }
        s.push('\n');
    }
    Ok(s.into_bytes())
}

/// Append `x` in the shortest decimal form that parses back to `x`. Rust's
/// `Display` and `LowerExp` for f64 both print the shortest round-trip digits;
/// `Display` never uses an exponent, so tiny and huge values take `LowerExp`.
fn push_shortest(s: &mut String, x: f64) {
    let a = x.abs();
    if a == 0.0 || !a.is_finite() || (1e-5..1e16).contains(&a) {
        let _ = write!(s, "{x}");
    } else {
        let _ = write!(s, "{x:e}");
    }
}

/// Write `columns` as a Parquet file of f64 columns (Snappy-compressed pages,
/// one row group per 512^2 rows as polars chooses). The same columns give the
/// same bytes: the writer stamps no time or host into the file.
pub fn write_parquet(path: &Path, columns: &[(&str, &[f64])]) -> Result<(), ColumnWriteError> {
    let bytes = parquet_bytes(path, columns)?;
    write_artifact(path, &bytes)?;
    Ok(())
}

/// The bytes [`write_parquet`] writes (`path` only names the file in errors).
pub fn parquet_bytes(path: &Path, columns: &[(&str, &[f64])]) -> Result<Vec<u8>, ColumnWriteError> {
    let n = check(path, columns)?;
    let cols: Vec<Column> = columns
        .iter()
        .map(|(name, values)| Column::new((*name).into(), *values))
        .collect();
    frame_bytes(path, n, cols)
}

/// A column with the unit of its values, as the formats that hold units
/// (HDF5, TDMS) state it.
pub struct UnitColumn<'a> {
    pub name: &'a str,
    pub unit: &'a str,
    pub values: &'a [f64],
}

fn names_and_values<'a>(columns: &[UnitColumn<'a>]) -> Vec<(&'a str, &'a [f64])> {
    columns.iter().map(|c| (c.name, c.values)).collect()
}

fn encode_error<'p>(
    path: &'p Path,
    format: &'static str,
) -> impl Fn(String) -> ColumnWriteError + 'p {
    move |why| ColumnWriteError::Encode {
        path: path.to_path_buf(),
        format,
        why,
    }
}

/// The columns as a MATLAB level-5 MAT-file, each an N x 1 double variable
/// named as the column.
pub fn mat_bytes(path: &Path, columns: &[UnitColumn<'_>]) -> Result<Vec<u8>, ColumnWriteError> {
    check(path, &names_and_values(columns))?;
    let vars: Vec<(String, super::matlab::MatValue)> = columns
        .iter()
        .map(|c| {
            (
                c.name.to_string(),
                super::matlab::MatValue::column(c.values),
            )
        })
        .collect();
    super::matlab::mat_bytes(
        "MATLAB 5.0 MAT-file, Platform: servoid, a synthetic log",
        &vars,
    )
    .map_err(|e| encode_error(path, "MAT")(e.to_string()))
}

/// The columns as a MATLAB v7.3 MAT-file (HDF5 behind MATLAB's 512-byte
/// header), each an N x 1 double variable, written by hdf5-pure's MATLAB
/// writer.
pub fn mat_v73_bytes(path: &Path, columns: &[UnitColumn<'_>]) -> Result<Vec<u8>, ColumnWriteError> {
    check(path, &names_and_values(columns))?;
    let bad = encode_error(path, "MAT v7.3");
    let mut mat = hdf5_pure::mat::MatBuilder::new(hdf5_pure::mat::Options::default());
    for c in columns {
        mat.write_f64(c.name, &[c.values.len(), 1], c.values)
            .map_err(|e| bad(e.to_string()))?;
    }
    mat.finish().map_err(|e| bad(e.to_string()))
}

/// The columns as HDF5, each a 1-D f64 dataset at the root, chunked and
/// deflated as loggers write them, with a `units` attribute.
pub fn hdf5_bytes(path: &Path, columns: &[UnitColumn<'_>]) -> Result<Vec<u8>, ColumnWriteError> {
    let n = check(path, &names_and_values(columns))?;
    let mut file = hdf5_pure::FileBuilder::new();
    let chunk = (n as u64).clamp(1, 65_536);
    for c in columns {
        file.create_dataset(c.name)
            .with_f64_data(c.values)
            .with_shape(&[n as u64])
            .with_chunks(&[chunk])
            .with_shuffle()
            .with_deflate(4)
            .set_attr("units", hdf5_pure::AttrValue::String(c.unit.to_string()));
    }
    file.finish()
        .map_err(|e| encode_error(path, "HDF5")(e.to_string()))
}

/// The columns as TDMS: group `group`, each a channel with its
/// `unit_string` and, as a waveform, its sample interval `wf_increment`.
pub fn tdms_bytes(
    path: &Path,
    columns: &[UnitColumn<'_>],
    group: &str,
    dt_s: f64,
) -> Result<Vec<u8>, ColumnWriteError> {
    use tedium::{ChannelPath, DataLayout, PropertyPath, PropertyValue, TdmsFile};
    check(path, &names_and_values(columns))?;
    let bad = encode_error(path, "TDMS");
    let mut bytes = Vec::new();
    {
        let mut file =
            TdmsFile::new(std::io::Cursor::new(&mut bytes)).map_err(|e| bad(e.to_string()))?;
        let mut w = file.writer().map_err(|e| bad(e.to_string()))?;
        for c in columns {
            w.write_properties(
                &PropertyPath::channel(group, c.name),
                &[
                    ("unit_string", PropertyValue::String(c.unit.to_string())),
                    ("wf_increment", PropertyValue::DoubleFloat(dt_s)),
                    ("wf_start_offset", PropertyValue::DoubleFloat(0.0)),
                ],
            )
            .map_err(|e| bad(e.to_string()))?;
        }
        for c in columns {
            w.write_channels(
                &[ChannelPath::new(group, c.name)],
                c.values,
                DataLayout::Contigious,
            )
            .map_err(|e| bad(e.to_string()))?;
        }
    }
    Ok(bytes)
}

/// `rows` rows of `cols` as Parquet bytes (Snappy pages, no time or host
/// stamped in): the one writer of the logs, the run tables and the history
/// (`path` only names the file in errors).
pub(super) fn frame_bytes(
    path: &Path,
    rows: usize,
    cols: Vec<Column>,
) -> Result<Vec<u8>, ColumnWriteError> {
    let parquet = |source| ColumnWriteError::Parquet {
        path: path.to_path_buf(),
        source,
    };
    let mut df = DataFrame::new(rows, cols).map_err(parquet)?;
    let mut buf = Vec::new();
    // Off the caller's rayon pool: see `ingest::off_pool`.
    crate::ingest::off_pool(|| {
        ParquetWriter::new(&mut buf)
            .with_compression(ParquetCompression::Snappy)
            .finish(&mut df)
    })
    .map_err(parquet)?;
    Ok(buf)
}

/// Common checks; returns the row count.
fn check(path: &Path, columns: &[(&str, &[f64])]) -> Result<usize, ColumnWriteError> {
    let Some((first, first_values)) = columns.first() else {
        return Err(ColumnWriteError::NoColumns {
            path: path.to_path_buf(),
        });
    };
    for (j, (name, values)) in columns.iter().enumerate() {
        let bad_char = name.contains([',', '"', '\n', '\r']);
        let duplicate = columns[..j].iter().any(|(other, _)| other == name);
        if name.is_empty() || bad_char || duplicate {
            return Err(ColumnWriteError::BadName {
                path: path.to_path_buf(),
                name: name.to_string(),
            });
        }
        if values.len() != first_values.len() {
            return Err(ColumnWriteError::Ragged {
                path: path.to_path_buf(),
                name: name.to_string(),
                len: values.len(),
                first: first.to_string(),
                first_len: first_values.len(),
            });
        }
    }
    Ok(first_values.len())
}
