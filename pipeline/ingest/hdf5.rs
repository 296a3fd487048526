//! HDF5 logs, read by the pure-Rust `hdf5-pure` crate (no C library to
//! install; see Cargo.toml for why this crate): plain HDF5 files, each
//! channel a dataset addressed by its path (`x1`, `run1/x1`), and MATLAB
//! v7.3 MAT-files, which are HDF5 behind a 512-byte user block with
//! MATLAB's conventions (a struct is a group, addressed `log.x1`; every
//! variable carries its `MATLAB_class`).
//!
//! Channels are found as in every array format (`arrays`). Sizes are as
//! MATLAB shows them: a v7.3 file stores an N x C MATLAB matrix as HDF5
//! dimensions [C, N] in row-major order, which is MATLAB's column-major
//! order of N x C, so its dimensions are read reversed and its values as
//! they lie; a plain HDF5 dataset of dimensions [N, C] (h5py, row-major)
//! is N x C and its values are put column-major. A dataset's `units` or
//! `unit` attribute, where there is one, is checked against the manifest's
//! unit.

use std::path::Path;

use hdf5_pure::{AttrValue, DType, File};

use super::arrays::{self, Arrays};
use super::plan::LogPlan;
use super::{FormatProblem, IngestError, MatVariable, Raw};

/// The deepest group path walked, and the most datasets listed: a damaged
/// or hostile file can link a group into itself.
const MAX_DEPTH: usize = 8;
const MAX_DATASETS: usize = 10_000;

/// MATLAB's hidden groups in a v7.3 file (cell contents, class objects):
/// not log variables.
const MATLAB_HIDDEN: [&str; 2] = ["#refs#", "#subsystem#"];

/// Read an HDF5 log (`matlab`: a MAT v7.3 file) as `plan` describes it.
pub(super) fn read<'a>(
    path: &Path,
    bytes: &[u8],
    plan: &'a LogPlan,
    matlab: bool,
) -> Result<Raw<'a>, IngestError> {
    guarded(path, matlab, || {
        arrays::read(path, &open(path, bytes, matlab)?, plan)
    })
}

/// `f`, with a panic inside hdf5-pure on damaged bytes reported as the
/// file's damage.
fn guarded<R>(
    path: &Path,
    matlab: bool,
    f: impl FnOnce() -> Result<R, IngestError>,
) -> Result<R, IngestError> {
    super::guard_reader(f).unwrap_or_else(|p| {
        Err(unreadable(
            path,
            matlab,
            &format!("the HDF5 reader failed on damaged bytes ({p})"),
        ))
    })
}

/// The numeric datasets of an HDF5 log, with the units they state.
pub(super) fn columns(
    path: &Path,
    bytes: &[u8],
    matlab: bool,
) -> Result<Vec<super::LogColumn>, IngestError> {
    guarded(path, matlab, || {
        Ok(arrays::columns(&open(path, bytes, matlab)?))
    })
}

fn open<'p>(path: &'p Path, bytes: &[u8], matlab: bool) -> Result<Hdf5<'p>, IngestError> {
    let file = File::from_bytes(bytes.to_vec()).map_err(|e| unreadable(path, matlab, &e))?;
    let mut h = Hdf5 {
        path,
        bytes: bytes.len(),
        file,
        matlab,
        variables: Vec::new(),
        datasets: Vec::new(),
    };
    h.walk("", 0)?;
    if h.variables.is_empty() {
        return Err(IngestError::HeaderOnly {
            path: path.to_path_buf(),
            what: "no numeric datasets".into(),
        });
    }
    Ok(h)
}

fn unreadable(path: &Path, matlab: bool, e: &dyn std::fmt::Display) -> IngestError {
    IngestError::format(
        path,
        FormatProblem::Hdf5Unreadable {
            what: if matlab { "MAT v7.3 (HDF5)" } else { "HDF5" },
            why: e.to_string(),
        },
    )
}

struct Hdf5<'p> {
    path: &'p Path,
    /// The file's length in bytes.
    bytes: usize,
    file: File,
    matlab: bool,
    variables: Vec<MatVariable>,
    /// Each variable's dataset path in the file, and whether its values are
    /// row-major (a plain 2-D dataset) and must be put column-major.
    datasets: Vec<(String, bool)>,
}

impl Hdf5<'_> {
    /// List the numeric datasets under group `prefix` (`""`: the root).
    fn walk(&mut self, prefix: &str, depth: usize) -> Result<(), IngestError> {
        let (path, matlab) = (self.path, self.matlab);
        let bad = |e: hdf5_pure::Error| unreadable(path, matlab, &e);
        let group = match prefix {
            "" => self.file.root(),
            p => self.file.group(p).map_err(bad)?,
        };
        let mut names = group.datasets().map_err(bad)?;
        names.sort();
        for name in names {
            if self.datasets.len() >= MAX_DATASETS {
                break;
            }
            let full = format!("{prefix}{name}");
            self.add(&full)?;
        }
        if depth >= MAX_DEPTH {
            return Ok(());
        }
        let mut groups = group.groups().map_err(bad)?;
        groups.sort();
        for g in groups {
            if prefix.is_empty() && self.matlab && MATLAB_HIDDEN.contains(&g.as_str()) {
                continue;
            }
            self.walk(&format!("{prefix}{g}/"), depth + 1)?;
        }
        Ok(())
    }

    /// List dataset `full` when it is numeric.
    fn add(&mut self, full: &str) -> Result<(), IngestError> {
        let bad = |e: hdf5_pure::Error| unreadable(self.path, self.matlab, &e);
        let ds = self.file.dataset(full).map_err(bad)?;
        let numeric = matches!(
            ds.dtype().map_err(bad)?,
            DType::F32
                | DType::F64
                | DType::I8
                | DType::I16
                | DType::I32
                | DType::I64
                | DType::U8
                | DType::U16
                | DType::U32
                | DType::U64
        );
        let attrs = ds.attrs().map_err(bad)?;
        let class = attrs.get("MATLAB_class").and_then(AttrValue::as_str);
        // MATLAB text is uint16 with class "char"; an empty variable stores
        // its dimensions as its data.
        let text = class.is_some_and(|c| matches!(c, "char" | "cell" | "struct"));
        if !numeric || text || attrs.contains_key("MATLAB_empty") {
            return Ok(());
        }
        let shape: Vec<usize> = ds
            .shape()
            .map_err(bad)?
            .iter()
            .map(|&d| usize::try_from(d).unwrap_or(usize::MAX))
            .collect();
        let (size, row_major) = match (self.matlab, shape.as_slice()) {
            (_, []) => (vec![1, 1], false),
            (_, [n]) => (vec![*n, 1], false),
            (true, s) => (s.iter().rev().copied().collect(), false),
            (false, s) => (s.to_vec(), s.len() == 2),
        };
        let name = match self.matlab {
            true => full.replace('/', "."),
            false => full.to_string(),
        };
        self.variables.push(MatVariable { name, size });
        self.datasets.push((full.to_string(), row_major));
        Ok(())
    }

    fn dataset_of(&self, name: &str) -> (&str, bool, &MatVariable) {
        let i = self
            .variables
            .iter()
            .position(|v| v.name == name)
            .expect("a listed variable");
        let (path, row_major) = &self.datasets[i];
        (path, *row_major, &self.variables[i])
    }
}

impl Arrays for Hdf5<'_> {
    fn variables(&self) -> &[MatVariable] {
        &self.variables
    }

    fn values(&self, name: &str, _channel: &'static str) -> Result<Vec<f64>, IngestError> {
        let (full, row_major, v) = self.dataset_of(name);
        let bad = |e: hdf5_pure::Error| unreadable(self.path, self.matlab, &e);
        // A damaged or hostile file can declare a shape its bytes cannot
        // hold, and the reader reserves for it before reading (found by the
        // log_hdf5 fuzz target: hundreds of GB). Deflate packs at most
        // about 1032 bytes into one, so no dataset of this file can hold
        // more values than that many bytes' worth.
        let declared = v.size.iter().try_fold(1usize, |a, &d| a.checked_mul(d));
        let most = self.bytes.saturating_mul(1032) / 8;
        if declared.is_none_or(|n| n > most) {
            return Err(unreadable(
                self.path,
                self.matlab,
                &format!(
                    "dataset `{name}` declares {} values, more than a file of {} bytes can hold even compressed",
                    super::dims(&v.size),
                    self.bytes
                ),
            ));
        }
        let values = self
            .file
            .dataset(full)
            .and_then(|ds| ds.read_f64())
            .map_err(bad)?;
        let (rows, cols) = (v.size[0], v.size[1]);
        if !row_major || values.len() != rows.saturating_mul(cols) {
            // The size check that follows names a short dataset.
            return Ok(values);
        }
        // Row-major [rows, cols] to column-major: (r, c) from r * cols + c.
        Ok((0..cols)
            .flat_map(|c| (0..rows).map(move |r| r * cols + c))
            .map(|i| values[i])
            .collect())
    }

    fn stated_unit(&self, name: &str) -> Option<String> {
        let (full, ..) = self.dataset_of(name);
        let attrs = self.file.dataset(full).ok()?.attrs().ok()?;
        ["units", "unit"].iter().find_map(|k| {
            attrs
                .get(*k)
                .and_then(AttrValue::as_str)
                .map(str::to_string)
        })
    }
}

/// Whether `bytes` are an HDF5 file: the signature at 0 or behind a user
/// block (512, 1024, ... bytes, as MATLAB v7.3 puts it at 512).
pub(super) fn is_hdf5(bytes: &[u8]) -> bool {
    const SIGNATURE: &[u8; 8] = b"\x89HDF\r\n\x1a\n";
    (0..)
        .map(|k| if k == 0 { 0 } else { 512usize << (k - 1) })
        .take_while(|&at| at + 8 <= bytes.len())
        .any(|at| &bytes[at..at + 8] == SIGNATURE)
}
