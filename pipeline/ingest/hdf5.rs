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

fn open<'p, 'b>(
    path: &'p Path,
    bytes: &'b [u8],
    matlab: bool,
) -> Result<Hdf5<'p, 'b>, IngestError> {
    if !is_hdf5(bytes)
        && let Some(problem) = super::other_kind(bytes, "an HDF5 file")
    {
        return Err(IngestError::format(path, problem));
    }
    let mut owned = bytes.to_vec();
    let links = skip_v1_links(&mut owned);
    let file = File::from_bytes(owned).map_err(|e| unreadable(path, matlab, &e))?;
    let mut h = Hdf5 {
        path,
        raw: bytes,
        file,
        matlab,
        variables: Vec::new(),
        datasets: Vec::new(),
        unusable: Vec::new(),
        links,
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

struct Hdf5<'p, 'b> {
    path: &'p Path,
    /// The file's bytes, as given (before the link pass).
    raw: &'b [u8],
    file: File,
    matlab: bool,
    variables: Vec<MatVariable>,
    /// Each variable's dataset path in the file, and whether its values are
    /// row-major (a plain 2-D dataset) and must be put column-major.
    datasets: Vec<(String, bool)>,
    /// The datasets that are not numeric arrays, with what they are.
    unusable: Vec<arrays::Unusable>,
    /// How many soft links the file's old-style groups hold (skipped).
    links: usize,
}

impl Hdf5<'_, '_> {
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
        let dtype = ds.dtype().map_err(bad)?;
        let attrs = ds.attrs().map_err(bad)?;
        let class = attrs.get("MATLAB_class").and_then(AttrValue::as_str);
        // MATLAB text is uint16 with class "char"; an empty variable stores
        // its dimensions as its data.
        let what = match (class, &dtype) {
            (Some("char"), _) => Some("a MATLAB char array (text)".to_string()),
            (Some("cell"), _) => Some("a MATLAB cell array".to_string()),
            (Some("struct"), _) => Some("an empty MATLAB struct".to_string()),
            _ if attrs.contains_key("MATLAB_empty") => Some("empty".to_string()),
            // MATLAB keeps a struct array's field as references to each
            // element's value.
            (None, DType::ObjectReference) if self.matlab => Some(
                "a field of a MATLAB struct array (a value per element; servoid reads a single struct's fields: save the run's signals as variables, or as a 1 x 1 struct)".to_string(),
            ),
            _ => not_numeric(&dtype),
        };
        if let Some(what) = what {
            self.unusable.push(arrays::Unusable {
                name: self.name_of(full),
                what,
            });
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
        let name = self.name_of(full);
        self.variables.push(MatVariable { name, size });
        self.datasets.push((full.to_string(), row_major));
        Ok(())
    }

    /// A dataset's name as a plan gives it: its path, or for MATLAB its
    /// struct fields joined by dots.
    fn name_of(&self, full: &str) -> String {
        match self.matlab {
            true => full.replace('/', "."),
            false => full.to_string(),
        }
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

impl Arrays for Hdf5<'_, '_> {
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
        let most = self.raw.len().saturating_mul(1032) / 8;
        if declared.is_none_or(|n| n > most) {
            return Err(unreadable(
                self.path,
                self.matlab,
                &format!(
                    "dataset `{name}` declares {} values, more than a file of {} bytes can hold even compressed",
                    super::dims(&v.size),
                    self.raw.len()
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

    fn unusable(&self) -> &[arrays::Unusable] {
        &self.unusable
    }

    fn skipped(&self) -> Option<String> {
        (self.links > 0).then(|| {
            format!(
                "{} soft link(s), which servoid does not follow: name the dataset a link points to",
                self.links
            )
        })
    }

    fn link(&self, name: &str) -> Option<String> {
        link_named(self.raw, name.rsplit(['/', '.']).next().unwrap_or(name))
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

/// What a dataset of type `dtype` is when it is not a real number array:
/// h5py writes complex numbers as a compound of two floats, booleans as an
/// enum of FALSE and TRUE, and text as strings.
fn not_numeric(dtype: &DType) -> Option<String> {
    let float = |d: &DType| matches!(d, DType::F32 | DType::F64);
    Some(match dtype {
        DType::F32
        | DType::F64
        | DType::I8
        | DType::I16
        | DType::I32
        | DType::I64
        | DType::U8
        | DType::U16
        | DType::U32
        | DType::U64 => return None,
        DType::Compound(fields) if fields.len() == 2 && fields.iter().all(|(_, d)| float(d)) => {
            "complex".to_string()
        }
        DType::Enum(names)
            if names.len() == 2 && names.iter().all(|n| matches!(n.as_str(), "FALSE" | "TRUE")) =>
        {
            "boolean".to_string()
        }
        DType::String | DType::VariableLengthString => "text (strings)".to_string(),
        other => format!("of HDF5 type {other}"),
    })
}

/// What a link named `name` in a new-style group is (a link message,
/// version 1, in an object header or a dense group's heap), found in the
/// file's bytes: hdf5-pure lists a new-style group's hard links only, so a
/// channel named as a soft or external link would be "not there". The
/// message's header is tried at every length its flags allow (name-length
/// size, creation order, character set, link type) before each place the
/// name occurs; only a soft (1) or external (64) link whose target reads
/// is taken.
fn link_named(bytes: &[u8], name: &str) -> Option<String> {
    let key = name.as_bytes();
    if key.is_empty() || key.len() > 255 {
        return None;
    }
    for at in memchr::memmem::find_iter(bytes, key) {
        for flags in 0u8..32 {
            if flags & 0x08 == 0 {
                // Without a link-type field the link is hard.
                continue;
            }
            let len_size = 1usize << (flags & 3);
            let head =
                2 + 1 + usize::from(flags & 4 != 0) * 8 + usize::from(flags & 0x10 != 0) + len_size;
            let Some(start) = at.checked_sub(head) else {
                continue;
            };
            let h = &bytes[start..at];
            let len_at = head - len_size;
            let mut len = 0usize;
            for (k, b) in h[len_at..].iter().enumerate() {
                len |= usize::from(*b) << (8 * k);
            }
            if h[0] != 1 || h[1] != flags || len != key.len() {
                continue;
            }
            let target = &bytes[at + key.len()..];
            let Some(n) = target
                .get(..2)
                .map(|b| usize::from(u16::from_le_bytes([b[0], b[1]])))
            else {
                continue;
            };
            let Some(info) = target.get(2..2 + n) else {
                continue;
            };
            let text = |b: &[u8]| {
                std::str::from_utf8(b)
                    .ok()
                    .filter(|t| !t.is_empty() && !t.contains(char::is_control))
                    .map(str::to_string)
            };
            match h[2] {
                1 => {
                    if let Some(to) = text(info) {
                        return Some(format!(
                            "a soft link to `{to}`, which servoid does not follow: name that dataset"
                        ));
                    }
                }
                64 => {
                    let mut parts = info.get(1..)?.split(|&b| b == 0);
                    if let (Some(file), Some(object)) =
                        (parts.next().and_then(text), parts.next().and_then(text))
                    {
                        return Some(format!(
                            "an external link to `{object}` in {file}, which servoid does not follow: give that file as the run's log"
                        ));
                    }
                }
                _ => {}
            }
        }
    }
    None
}

/// Drop the soft links from `bytes`' old-style groups, returning how many.
///
/// An old-style (version 1) group lists its members in symbol-table nodes
/// (`SNOD`), where a soft link is an entry of cache type 2 with no object
/// header (its address undefined). hdf5-pure parses every member's object
/// header to list a group, so one such link, used or not, makes the group
/// unreadable ("unexpected EOF: need 18446744073709551615 bytes"). servoid
/// does not follow links: each node's link entries are removed and the
/// rest moved up, the node's count lowered. A node is taken as one only
/// when its version, count and every entry's cache type (0-2) are as the
/// format has them, and only a link entry is removed, so data bytes that
/// happen to spell `SNOD` are left alone.
pub(super) fn skip_v1_links(bytes: &mut [u8]) -> usize {
    let Some(offsets) = offset_size(bytes) else {
        return 0;
    };
    let entry = 2 * offsets + 24;
    let mut skipped = 0;
    let mut at = 0;
    while let Some(found) = memchr::memmem::find(&bytes[at..], b"SNOD") {
        let node = at + found;
        at = node + 4;
        let Some(head) = bytes.get(node..node + 8) else {
            break;
        };
        let count = usize::from(u16::from_le_bytes([head[6], head[7]]));
        let body = node + 8;
        if head[4] != 1 || body + count * entry > bytes.len() {
            continue;
        }
        let cache = |b: &[u8], i: usize| {
            let c = body + i * entry + 2 * offsets;
            u32::from_le_bytes([b[c], b[c + 1], b[c + 2], b[c + 3]])
        };
        let address_undefined = |b: &[u8], i: usize| {
            let a = body + i * entry + offsets;
            b[a..a + offsets].iter().all(|&x| x == 0xff)
        };
        if (0..count).any(|i| cache(bytes, i) > 2) {
            continue;
        }
        let keep: Vec<usize> = (0..count)
            .filter(|&i| !(cache(bytes, i) == 2 && address_undefined(bytes, i)))
            .collect();
        if keep.len() == count {
            continue;
        }
        // Each kept entry moves up to its new place (j <= i).
        for (j, &i) in keep.iter().enumerate() {
            bytes.copy_within(body + i * entry..body + (i + 1) * entry, body + j * entry);
        }
        bytes[body + keep.len() * entry..body + count * entry].fill(0);
        let n = u16::try_from(keep.len()).expect("fewer than count");
        bytes[node + 6..node + 8].copy_from_slice(&n.to_le_bytes());
        skipped += count - keep.len();
        at = body + count * entry;
    }
    skipped
}

/// The superblock's size of offsets (bytes), where the file has a
/// superblock servoid knows (versions 0-3, at 0 or behind a user block).
fn offset_size(bytes: &[u8]) -> Option<usize> {
    const SIGNATURE: &[u8; 8] = b"\x89HDF\r\n\x1a\n";
    let at = (0..)
        .map(|k| if k == 0 { 0 } else { 512usize << (k - 1) })
        .take_while(|&at| at + 16 <= bytes.len())
        .find(|&at| &bytes[at..at + 8] == SIGNATURE)?;
    let size = match bytes[at + 8] {
        0 | 1 => bytes[at + 13],
        2 | 3 => bytes[at + 9],
        _ => return None,
    };
    matches!(size, 2 | 4 | 8).then_some(usize::from(size))
}
