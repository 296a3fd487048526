//! Named columns as CSV or Parquet: the simulator's synthetic lab logs (for
//! `ingest` to read back), and through `frame_bytes` the runs' tables and the
//! rig's history. Every writer gives the same bytes for the same columns,
//! and writes atomically (temporary sibling, then rename). The simulator's
//! logs may also be MATLAB MAT-files (level 5 and v7.3), HDF5 or TDMS, as
//! labs' acquisition systems write them, so each reader is tried on a
//! campaign whose truth is known.

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

/// A table that could not be written as the output folder's error: a
/// write failure as it is, a malformed table as the table's.
impl From<ColumnWriteError> for WriteError {
    fn from(e: ColumnWriteError) -> Self {
        match e {
            ColumnWriteError::Write(w) => w,
            other => WriteError::Table(Box::new(other)),
        }
    }
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
    let mut digits = ryu::Buffer::new();
    for row in 0..n {
        for (j, (_, values)) in columns.iter().enumerate() {
            if j > 0 {
                s.push(',');
            }
            s.push_str(&shortest(&mut digits, values[row]));
        }
        s.push('\n');
    }
    Ok(s.into_bytes())
}

/// `x` in the shortest decimal form that parses back to `x`, as Rust's
/// `Display` writes it for 1e-5 <= |x| < 1e16 and zero (no exponent), and
/// `LowerExp` elsewhere (tiny and huge values). Ryu (Adams, PLDI 2018)
/// chooses the same digits and the same notation by the same decimal
/// exponent, with two differences put right here: it ends an integral
/// value with ".0", and where `x` lies exactly halfway between the two
/// closest shortest candidates it takes the even one, where Rust's takes
/// the one above.
fn shortest(buf: &mut ryu::Buffer, x: f64) -> std::borrow::Cow<'_, str> {
    let text = buf.format(x);
    let text = text.strip_suffix(".0").unwrap_or(text);
    match last_digit(text) {
        Some((at, k)) if halfway_rounded_down(x, k) => {
            let mut up = text.as_bytes().to_vec();
            // Ryu's choice at a tie is even, so adding one never carries.
            up[at] += 1;
            std::borrow::Cow::Owned(String::from_utf8(up).expect("ASCII digits"))
        }
        _ => std::borrow::Cow::Borrowed(text),
    }
}

/// The byte index of `text`'s last significant digit and its decimal
/// exponent k (the digit counts 10^k); None for text without digits.
fn last_digit(text: &str) -> Option<(usize, i32)> {
    let (mantissa, exp) = match text.split_once('e') {
        Some((m, e)) => (m, e.parse::<i32>().ok()?),
        None => (text, 0),
    };
    match mantissa.split_once('.') {
        Some((_, frac)) => Some((mantissa.len() - 1, exp - frac.len() as i32)),
        None => {
            let zeros = mantissa.len() - mantissa.trim_end_matches('0').len();
            let at = (mantissa.len() - 1).checked_sub(zeros)?;
            mantissa.as_bytes()[at]
                .is_ascii_digit()
                .then_some((at, exp + zeros as i32))
        }
    }
}

/// Whether `x` lies exactly halfway between the multiples of 10^k on each
/// side of it and the lower one is even (so that Ryu, rounding half to
/// even, wrote it): with |x| = M 2^E, M odd, that is k = E + 1, M
/// divisible by 5^k where k > 0, and M = 1 (mod 4) (|x| / 10^k =
/// (M 5^-k - 1) / 2 + 1/2, and 5 = 1 (mod 4)).
fn halfway_rounded_down(x: f64, k: i32) -> bool {
    let bits = x.to_bits();
    let exp = ((bits >> 52) & 0x7ff) as i32;
    let frac = bits & ((1 << 52) - 1);
    let (m, e) = match exp {
        0 => (frac, -1074),
        0x7ff => return false,
        _ => (frac | (1 << 52), exp - 1075),
    };
    if m == 0 {
        return false;
    }
    let tz = m.trailing_zeros();
    let (m, e) = (m >> tz, e + tz as i32);
    if k != e + 1 || m % 4 != 1 {
        return false;
    }
    k <= 0 || 5u64.checked_pow(k as u32).is_some_and(|p| m % p == 0)
}

/// Write `columns` as a Parquet file of f64 columns (zstd-compressed pages,
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

/// `rows` rows of `cols` as Parquet bytes (zstd pages, no time or host
/// stamped in): the one writer of the logs, the run tables and the history
/// (`path` only names the file in errors). zstd rather than Snappy: a
/// night's FRF tables take 10 % less (pyarrow, pandas and polars read
/// both).
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
            .with_compression(ParquetCompression::Zstd(None))
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

/// A simulated run's log in `format` (`path` only names it in errors).
pub fn log_bytes(
    format: crate::manifest::simulation::OutputFormat,
    path: &Path,
    s: &crate::analysis::simulated::RunSignals,
    dt_s: f64,
) -> Result<Vec<u8>, ColumnWriteError> {
    let with_units: Vec<UnitColumn<'_>> = s
        .columns
        .iter()
        .zip(&s.units)
        .map(|((n, v), u)| UnitColumn {
            name: n,
            unit: u,
            values: v,
        })
        .collect();
    columns_bytes(format, path, &with_units, dt_s)
}

/// Columns sampled every `dt_s` as a log in `format` (`path` only names
/// it in errors).
pub fn columns_bytes(
    format: crate::manifest::simulation::OutputFormat,
    path: &Path,
    with_units: &[UnitColumn<'_>],
    dt_s: f64,
) -> Result<Vec<u8>, ColumnWriteError> {
    let cols = names_and_values(with_units);
    use crate::manifest::simulation::OutputFormat;
    match format {
        OutputFormat::Csv => csv_bytes(path, &cols),
        OutputFormat::Parquet => parquet_bytes(path, &cols),
        OutputFormat::Mat => mat_bytes(path, with_units),
        OutputFormat::MatV73 => mat_v73_bytes(path, with_units),
        OutputFormat::Hdf5 => hdf5_bytes(path, with_units),
        OutputFormat::Tdms => tdms_bytes(
            path,
            with_units,
            crate::analysis::simulated::TDMS_GROUP,
            dt_s,
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// What Rust's formatter writes: `Display` without an exponent where
    /// it is short, `LowerExp` elsewhere.
    fn by_std(x: f64) -> String {
        let a = x.abs();
        if a == 0.0 || !a.is_finite() || (1e-5..1e16).contains(&a) {
            format!("{x}")
        } else {
            format!("{x:e}")
        }
    }

    /// Ryu's text is the standard formatter's, value by value: on random
    /// bit patterns (every exponent), on random values of a log's size, on
    /// integers, on the neighbours of each notation's bounds and of every
    /// power of ten, and on zeros, subnormals and the extremes.
    #[test]
    fn the_shortest_text_is_the_standard_formatters() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut values: Vec<f64> = (0..200_000)
            .map(|_| f64::from_bits(rng.random::<u64>()))
            .filter(|x| x.is_finite())
            .collect();
        values.extend((0..200_000).map(|_| rng.random_range(-0.05..0.05)));
        values.extend((0..2_000).map(|i| f64::from(i) - 1000.0));
        for e in -320..=308 {
            let p = format!("1e{e}").parse::<f64>().unwrap();
            let mut below = p;
            let mut above = p;
            for _ in 0..3 {
                below = below.next_down();
                above = above.next_up();
                values.extend([below, above, -below, -above]);
            }
            values.extend([p, -p, 0.5 * p, 3.0 * p]);
        }
        values.extend([
            0.0,
            -0.0,
            f64::MIN_POSITIVE,
            f64::MIN_POSITIVE.next_down(),
            f64::from_bits(1),
            f64::MAX,
            f64::MIN,
            f64::EPSILON,
            2f64.powi(53),
            2f64.powi(53) + 2.0,
        ]);
        // Halfway cases: M 2^E with few bits below the point, where the
        // shortest text's last digit can fall exactly on a tie.
        for e in -40..=40 {
            for bits in [53, 30, 12] {
                for _ in 0..300 {
                    let m = rng.random::<u64>() >> (64 - bits) | 1;
                    values.push(m as f64 * 2f64.powi(e));
                }
            }
        }
        // 2086845729129147.25 lies halfway between ...147.2 and ...147.3.
        values.push(2_086_845_729_129_147.0 + 0.25);
        let mut buf = ryu::Buffer::new();
        let mut ties = 0;
        for x in values {
            let text = shortest(&mut buf, x);
            ties += usize::from(matches!(text, std::borrow::Cow::Owned(_)));
            assert_eq!(text, by_std(x), "bits {:#x}", x.to_bits());
        }
        // Ryu's own text differs from the standard's at each of these.
        assert!(ties > 100, "{ties} halfway cases");
    }
}
