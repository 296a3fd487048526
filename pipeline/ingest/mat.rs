//! MATLAB level-5 MAT-files (v5 and v7, compressed or not), parsed by the
//! `matfile` crate (which inflates miCOMPRESSED elements itself); a v7.3
//! file (HDF5) goes to `hdf5`. Channels are found as in every array format
//! (`arrays`): `FromLog` time is the vector variable `t`, else `time`.
//! Integer and single-precision variables are widened to f64; complex ones
//! are refused.

use std::path::Path;

use matfile::{Array, MatFile, NumericData};

use super::arrays::{self, Arrays};
use super::plan::LogPlan;
use super::{FormatProblem, IngestError, MatVariable, Raw};

/// Length of the level-5 header: 116 bytes of text, 8 of subsystem offset,
/// version (2) and endian indicator (2).
const HEADER_LEN: usize = 128;

/// Read a MAT log's wanted channels.
pub(super) fn read<'a>(
    path: &Path,
    bytes: &[u8],
    plan: &'a LogPlan,
) -> Result<Raw<'a>, IngestError> {
    if is_v73(bytes) {
        return super::hdf5::read(path, bytes, plan, true);
    }
    arrays::read(path, &open(path, bytes)?, plan)
}

/// A MAT log's numeric variables.
pub(super) fn columns(path: &Path, bytes: &[u8]) -> Result<Vec<super::LogColumn>, IngestError> {
    if is_v73(bytes) {
        return super::hdf5::columns(path, bytes, true);
    }
    Ok(arrays::columns(&open(path, bytes)?))
}

/// MATLAB writes v7.3 files with this header text in the user block.
fn is_v73(bytes: &[u8]) -> bool {
    bytes.starts_with(b"MATLAB 7.3") || super::hdf5::is_hdf5(bytes)
}

fn open<'p>(path: &'p Path, bytes: &[u8]) -> Result<Level5<'p>, IngestError> {
    let format = |problem| IngestError::format(path, problem);
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
    Ok(Level5 {
        path,
        variables: mat
            .arrays()
            .iter()
            .map(|a| MatVariable {
                name: a.name().to_string(),
                size: a.size().clone(),
            })
            .collect(),
        mat,
    })
}

/// A parsed level-5 file's numeric variables.
struct Level5<'p> {
    path: &'p Path,
    mat: MatFile,
    variables: Vec<MatVariable>,
}

impl Arrays for Level5<'_> {
    fn variables(&self) -> &[MatVariable] {
        &self.variables
    }

    fn values(&self, name: &str, channel: &'static str) -> Result<Vec<f64>, IngestError> {
        let a = self.mat.find_by_name(name).expect("a listed variable");
        real_f64(self.path, a, channel)
    }
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
    Ok(values)
}
