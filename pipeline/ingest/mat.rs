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

/// Whether `bytes` begin with a MATLAB level-4 matrix header: a type word
/// MOPT (machine 0-4, 0, precision 0-5, text/sparse 0-2) in either byte
/// order, non-negative rows and columns, an imaginary flag of 0 or 1, and
/// a name of `namlen` bytes that ends in a NUL.
pub(super) fn is_level4(bytes: &[u8]) -> bool {
    let Some(head) = bytes.get(..20) else {
        return false;
    };
    let word = |i: usize, be: bool| {
        let b: [u8; 4] = head[4 * i..4 * i + 4].try_into().expect("4 bytes");
        if be {
            i32::from_be_bytes(b)
        } else {
            i32::from_le_bytes(b)
        }
    };
    [false, true].into_iter().any(|be| {
        let mopt = word(0, be);
        let (m, o, p, t) = (mopt / 1000, mopt / 100 % 10, mopt / 10 % 10, mopt % 10);
        let namlen = word(4, be);
        (0..=4052).contains(&mopt)
            && m <= 4
            && o == 0
            && p <= 5
            && t <= 2
            && word(1, be) >= 0
            && word(2, be) >= 0
            && matches!(word(3, be), 0 | 1)
            && (2..=64).contains(&namlen)
            && bytes.get(20..20 + namlen as usize).is_some_and(|name| {
                name.last() == Some(&0)
                    && name[..name.len() - 1]
                        .iter()
                        .all(|c| c.is_ascii_alphanumeric() || *c == b'_')
            })
    })
}

fn open<'p>(path: &'p Path, bytes: &[u8]) -> Result<Level5<'p>, IngestError> {
    let format = |problem| IngestError::format(path, problem);
    let endian = bytes.get(126..HEADER_LEN);
    if bytes.len() < HEADER_LEN || !matches!(endian, Some(b"IM" | b"MI")) {
        return Err(format(
            super::other_kind(bytes, "a level-5 or v7.3 MAT-file").unwrap_or(FormatProblem::NotMat),
        ));
    }
    if bytes.len() == HEADER_LEN {
        return Err(IngestError::HeaderOnly {
            path: path.to_path_buf(),
            what: "a MAT header and no variables".into(),
        });
    }
    let unusable = check_elements(path, bytes)?;
    let mat = super::guard_reader(|| MatFile::parse(bytes))
        .map_err(|p| format(FormatProblem::MatReaderFailed { why: p.message }))?
        .map_err(|source| format(FormatProblem::MatUnreadable { source }))?;
    if mat.arrays().is_empty() && unusable.is_empty() {
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
        unusable,
    })
}

/// A parsed level-5 file's numeric variables.
struct Level5<'p> {
    path: &'p Path,
    mat: MatFile,
    variables: Vec<MatVariable>,
    /// The variables `matfile` passes over (text, cells, structs), named.
    unusable: Vec<arrays::Unusable>,
}

impl Arrays for Level5<'_> {
    fn variables(&self) -> &[MatVariable] {
        &self.variables
    }

    fn values(&self, name: &str, channel: &'static str) -> Result<Vec<f64>, IngestError> {
        let a = self.mat.find_by_name(name).expect("a listed variable");
        real_f64(self.path, a, channel)
    }

    fn unusable(&self) -> &[arrays::Unusable] {
        &self.unusable
    }
}

/// Walk the top-level elements' tags (type, byte count) and refuse a file
/// cut short: `matfile` stops quietly at an element it cannot parse, which
/// would lose the last variables without a word. Returns the variables
/// `matfile` leaves out (char, cell, struct, object and sparse arrays),
/// each with what it is.
fn check_elements(path: &Path, bytes: &[u8]) -> Result<Vec<arrays::Unusable>, IngestError> {
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
    let mut unusable = Vec::new();
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
        // A variable is an miMATRIX (14) or miCOMPRESSED (15) element;
        // matfile prints anything else to stdout, where a night's JSON log
        // lines go, before passing over it.
        if !matches!(word(pos), 14 | 15) {
            return Err(IngestError::format(
                path,
                FormatProblem::MatElement {
                    at_byte: pos,
                    kind: word(pos),
                },
            ));
        }
        let body = &bytes[pos + 8..pos + 8 + size];
        if let Some(head) = matrix_head(word(pos), body, big_endian) {
            if !head.dims_hold() {
                return Err(IngestError::format(
                    path,
                    FormatProblem::MatDimensions {
                        variable: head.name,
                        dims: head.dims,
                    },
                ));
            }
            unusable.extend(head.not_numeric());
        }
        // miCOMPRESSED (15) elements are not padded; others are padded to
        // 8 bytes (the last one may lack its padding).
        let padded = if word(pos) == 15 {
            size
        } else {
            size.div_ceil(8) * 8
        };
        pos = (pos + 8 + padded).min(bytes.len());
    }
    Ok(unusable)
}

/// What a top-level array element declares of itself: its class, its
/// dimensions and its name.
struct Head {
    class: u8,
    dims: Vec<i32>,
    name: String,
}

impl Head {
    /// What a variable of this class is, when `matfile` does not read it
    /// (char, cell, struct, object and sparse arrays).
    fn not_numeric(&self) -> Option<arrays::Unusable> {
        let what = match self.class {
            1 => "a MATLAB cell array",
            2 => {
                "a MATLAB struct (servoid reads a struct's fields in a v7.3 file: save with `-v7.3`, or save the fields as variables)"
            }
            3 => "a MATLAB object",
            4 => "a MATLAB char array (text)",
            5 => "a MATLAB sparse matrix",
            _ => return None,
        };
        Some(arrays::Unusable {
            name: self.name.clone(),
            what: what.to_string(),
        })
    }

    /// Whether its dimensions are ones a file can hold: none negative, and
    /// their product within MATLAB's 32-bit count (`matfile` multiplies
    /// them in i32).
    fn dims_hold(&self) -> bool {
        self.dims.iter().all(|&d| d >= 0)
            && self
                .dims
                .iter()
                .try_fold(1i32, |p, &d| p.checked_mul(d))
                .is_some()
    }
}

/// The head of a top-level element of type `kind`: an miMATRIX (14) read
/// from its array flags, dimensions and name sub-elements, an miCOMPRESSED
/// (15) one from the first bytes it inflates to; None for other elements
/// or where the head does not read (`matfile` then says why).
fn matrix_head(kind: u32, body: &[u8], big_endian: bool) -> Option<Head> {
    use std::io::Read as _;
    let inflated;
    let matrix = match kind {
        14 => body,
        15 => {
            let mut head = Vec::new();
            flate2::read::ZlibDecoder::new(body)
                .take(1024)
                .read_to_end(&mut head)
                .ok()?;
            inflated = head;
            // The inflated element's own tag: miMATRIX and its size.
            inflated.get(8..)?
        }
        _ => return None,
    };
    let word = |at: usize| -> Option<u32> {
        let b: [u8; 4] = matrix.get(at..at + 4)?.try_into().ok()?;
        Some(if big_endian {
            u32::from_be_bytes(b)
        } else {
            u32::from_le_bytes(b)
        })
    };
    // Array flags (tag, then the class in the low byte), then dimensions.
    let class = (word(8)? & 0xFF) as u8;
    let n = word(20)? as usize;
    let dims = (0..n / 4)
        .map(|k| word(24 + 4 * k).map(|d| d as i32))
        .collect::<Option<Vec<i32>>>()?;
    let at = 24 + n.div_ceil(8) * 8;
    let tag = word(at)?;
    // The name: a small element (its size in the tag's upper half) or a
    // normal one.
    let name = if tag >> 16 != 0 {
        matrix.get(at + 4..at + 4 + (tag >> 16) as usize)?
    } else {
        let n = word(at + 4)? as usize;
        matrix.get(at + 8..at + 8 + n)?
    };
    Some(Head {
        class,
        dims,
        name: String::from_utf8_lossy(name).into_owned(),
    })
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
