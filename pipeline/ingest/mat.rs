//! MATLAB level-5 MAT-files (v5 and v7, compressed or not), parsed by the
//! `matfile` crate (which inflates miCOMPRESSED elements itself). v7.3 files
//! are HDF5 and are refused with a hint.
//!
//! How channels are addressed:
//! - `Column::Name("x1")`: the numeric vector variable `x1` (1 x N or N x 1).
//! - `Column::Name("data:2")`: channel 2 (0-based) of the 2-D variable `data`,
//!   used when no variable is literally named `data:2`.
//! - `Column::Index(2)`: channel 2 of the only 2-D (non-vector) numeric
//!   variable; an error when there is none or more than one.
//!
//! In a 2-D variable the channels are its columns (N x channels, as
//! `save('log.mat', 'data')` keeps a table of samples); a wide variable (fewer
//! rows than columns, as Simulink's To File block writes `[t; u; y]`) has its
//! channels in rows. `FromLog` time is the vector variable `t`, else `time`.
//! Integer and single-precision variables are widened to f64; complex ones are
//! refused. Places are 1-based element (sample) numbers.

use std::path::Path;

use matfile::{Array, MatFile, NumericData};

use super::plan::{Column, LogPlan, TimePlan};
use super::{
    At, FormatProblem, IngestError, MatVariable, Raw, RawTime, Wanted, dims, list, wanted,
};

/// Length of the level-5 header: 116 bytes of text, 8 of subsystem offset,
/// version (2) and endian indicator (2).
const HEADER_LEN: usize = 128;

/// Read a MAT log's wanted channels.
pub(super) fn read<'a>(
    path: &Path,
    bytes: &'a [u8],
    plan: &'a LogPlan,
) -> Result<Raw<'a>, IngestError> {
    let format = |problem| IngestError::format(path, problem);
    if bytes.starts_with(b"MATLAB 7.3") {
        return Err(format(FormatProblem::MatV73));
    }
    let endian = bytes.get(126..HEADER_LEN);
    if bytes.len() < HEADER_LEN || !matches!(endian, Some(b"IM" | b"MI")) {
        return Err(format(FormatProblem::NotMat));
    }
    if bytes.len() == HEADER_LEN {
        return Err(IngestError::HeaderOnly {
            path: path.to_path_buf(),
            what: "a MAT header and no variables".into(),
        });
    }
    check_elements(path, bytes)?;
    let mat =
        MatFile::parse(bytes).map_err(|source| format(FormatProblem::MatUnreadable { source }))?;
    if mat.arrays().is_empty() {
        return Err(IngestError::HeaderOnly {
            path: path.to_path_buf(),
            what: "no numeric variables".into(),
        });
    }
    let columns = wanted_columns(path, &mat, &wanted(plan))?;
    let mut it = columns.into_iter();
    let time = match &plan.channels.time {
        TimePlan::Column { column, to_s } => RawTime::Column {
            raw: it.next().expect("time wanted").1,
            to_s: *to_s,
            column: column.to_string(),
        },
        TimePlan::SampleRate { hz } => RawTime::Rate {
            hz: *hz,
            from: "manifest",
        },
        TimePlan::FromLog => {
            let a = mat
                .find_by_name("t")
                .or_else(|| mat.find_by_name("time"))
                .ok_or_else(|| {
                    format(FormatProblem::NoTimeBase {
                        variables: variables(&mat),
                    })
                })?;
            RawTime::Column {
                raw: vector(path, a, "time")?,
                to_s: 1.0,
                column: format!("`{}`", a.name()),
            }
        }
    };
    let rest: Vec<(&'static str, Vec<f64>)> = it.collect();
    let mut lengths = rest.iter().map(|(c, v)| (*c, v.len())).collect::<Vec<_>>();
    if let RawTime::Column { raw, .. } = &time {
        lengths.insert(0, ("time", raw.len()));
    }
    if lengths.iter().any(|(_, n)| *n != lengths[0].1) {
        return Err(format(FormatProblem::Lengths { lengths }));
    }
    let mut rest = rest.into_iter().map(|(_, v)| v);
    let command = rest.next().expect("command wanted");
    let displacement = rest.next().expect("displacement wanted");
    let force = rest.next();
    Ok(Raw {
        time,
        command,
        displacement,
        force,
        locate: Box::new(|i| At::Element(i + 1)),
        warnings: Vec::new(),
    })
}

/// Each wanted column's values: a vector variable by name, one column of
/// a 2-D variable as `name:index`, or by index the one 2-D table's column.
fn wanted_columns(
    path: &Path,
    mat: &MatFile,
    want: &[Wanted<'_>],
) -> Result<Vec<(&'static str, Vec<f64>)>, IngestError> {
    let format = |problem| IngestError::format(path, problem);
    let mut columns = Vec::with_capacity(want.len());
    for w in want {
        let missing = || IngestError::MissingColumn {
            path: path.to_path_buf(),
            channel: w.channel,
            column: w.column.to_string(),
            available: format!("variables: {}", list(variables(mat))),
        };
        let v = match w.column {
            Column::Name(n) => match mat.find_by_name(n) {
                Some(a) => vector(path, a, w.channel)?,
                None => {
                    let (var, ch) = n
                        .rsplit_once(':')
                        .and_then(|(v, c)| Some((v, c.trim().parse::<usize>().ok()?)))
                        .ok_or_else(missing)?;
                    let a = mat.find_by_name(var).ok_or_else(missing)?;
                    channel(path, a, ch, w.channel)?
                }
            },
            Column::Index(i) => {
                let tables: Vec<&Array> = mat.arrays().iter().filter(|a| !is_vector(a)).collect();
                match tables.as_slice() {
                    [a] => channel(path, a, *i, w.channel)?,
                    [] => {
                        return Err(format(FormatProblem::NoTable {
                            channel: w.channel,
                            index: *i,
                            variables: variables(mat),
                        }));
                    }
                    _ => {
                        return Err(format(FormatProblem::SeveralTables {
                            channel: w.channel,
                            index: *i,
                            tables: tables.iter().map(|a| a.name().to_string()).collect(),
                        }));
                    }
                }
            }
        };
        columns.push((w.channel, v));
    }
    Ok(columns)
}

/// The file's variables, for messages.
fn variables(mat: &MatFile) -> Vec<MatVariable> {
    mat.arrays()
        .iter()
        .map(|a| MatVariable {
            name: a.name().to_string(),
            size: a.size().clone(),
        })
        .collect()
}

/// Walk the top-level elements' tags (type, byte count) and refuse a file
/// cut short: `matfile` stops quietly at an element it cannot parse, which
/// would lose the last variables without a word.
fn check_elements(path: &Path, bytes: &[u8]) -> Result<(), IngestError> {
    let big_endian = &bytes[126..HEADER_LEN] == b"MI";
    let word = |at: usize| {
        let b: [u8; 4] = bytes[at..at + 4].try_into().expect("4 bytes");
        if big_endian {
            u32::from_be_bytes(b)
        } else {
            u32::from_le_bytes(b)
        }
    };
    let mut pos = HEADER_LEN;
    while pos < bytes.len() {
        let remain = bytes.len() - pos;
        let declared = if remain >= 8 {
            Some(word(pos + 4) as usize)
        } else {
            None
        };
        if declared.is_none_or(|size| size > remain - 8) {
            return Err(IngestError::format(
                path,
                FormatProblem::CutShort {
                    at_byte: pos,
                    needed: declared.map(|size| size + 8),
                    remain,
                },
            ));
        }
        let size = declared.unwrap_or(0);
        // miCOMPRESSED (15) elements are not padded; others are padded to
        // 8 bytes (the last one may lack its padding).
        let padded = if word(pos) == 15 {
            size
        } else {
            size.div_ceil(8) * 8
        };
        pos = (pos + 8 + padded).min(bytes.len());
    }
    Ok(())
}

/// A 1 x N or N x 1 array (an empty or scalar one counts too).
fn is_vector(a: &Array) -> bool {
    a.size().len() == 2 && a.size().iter().filter(|&&d| d > 1).count() <= 1
}

/// The real values of `a` as f64, column-major.
fn real_f64(path: &Path, a: &Array, channel: &'static str) -> Result<Vec<f64>, IngestError> {
    fn widen<T: Copy + Into<f64>>(v: &[T]) -> Vec<f64> {
        v.iter().map(|&x| x.into()).collect()
    }
    let complex = || {
        IngestError::format(
            path,
            FormatProblem::Complex {
                variable: a.name().to_string(),
                channel,
            },
        )
    };
    let values = match a.data() {
        NumericData::Double { real, imag: None } => real.clone(),
        NumericData::Single { real, imag: None } => widen(real),
        NumericData::Int8 { real, imag: None } => widen(real),
        NumericData::UInt8 { real, imag: None } => widen(real),
        NumericData::Int16 { real, imag: None } => widen(real),
        NumericData::UInt16 { real, imag: None } => widen(real),
        NumericData::Int32 { real, imag: None } => widen(real),
        NumericData::UInt32 { real, imag: None } => widen(real),
        // 64-bit integers beyond 2^53 lose digits; counts and codes do not
        // reach that.
        NumericData::Int64 { real, imag: None } => real.iter().map(|&x| x as f64).collect(),
        NumericData::UInt64 { real, imag: None } => real.iter().map(|&x| x as f64).collect(),
        _ => return Err(complex()),
    };
    // A damaged file can declare more elements than it holds (found by the
    // MAT fuzz target): indexing by the declared size would run off the end.
    let declared: usize = a.size().iter().product();
    if values.len() != declared {
        return Err(IngestError::format(
            path,
            FormatProblem::SizeMismatch {
                variable: a.name().to_string(),
                channel,
                size: a.size().clone(),
                held: values.len(),
            },
        ));
    }
    Ok(values)
}

/// A vector variable's values.
fn vector(path: &Path, a: &Array, channel: &'static str) -> Result<Vec<f64>, IngestError> {
    if !is_vector(a) {
        return Err(IngestError::format(
            path,
            FormatProblem::NotVector {
                variable: a.name().to_string(),
                channel,
                size: a.size().clone(),
            },
        ));
    }
    real_f64(path, a, channel)
}

/// Channel `j` of a 2-D variable: its column `j`, or its row `j` when the
/// variable is wide (fewer rows than columns).
fn channel(
    path: &Path,
    a: &Array,
    j: usize,
    channel: &'static str,
) -> Result<Vec<f64>, IngestError> {
    let size = a.size();
    if size.len() != 2 {
        return Err(IngestError::format(
            path,
            FormatProblem::NotTable {
                variable: a.name().to_string(),
                channel,
                size: size.clone(),
            },
        ));
    }
    let (rows, cols) = (size[0], size[1]);
    let wide = rows < cols;
    let n_channels = if wide { rows } else { cols };
    if j >= n_channels {
        return Err(IngestError::MissingColumn {
            path: path.to_path_buf(),
            channel,
            column: format!("`{}:{j}`", a.name()),
            available: format!(
                "`{}` is {} and holds channels 0 to {} in its {}",
                a.name(),
                dims(size),
                n_channels.saturating_sub(1),
                if wide { "rows" } else { "columns" }
            ),
        });
    }
    let all = real_f64(path, a, channel)?;
    // Column-major storage: element (r, c) sits at r + c * rows.
    Ok(if wide {
        (0..cols).map(|c| all[j + c * rows]).collect()
    } else {
        all[j * rows..(j + 1) * rows].to_vec()
    })
}
