//! What a log holds before a manifest says what to read: its columns (or
//! variables) with the units the file states and the rate it gives, for
//! `servoid init` to propose channels from.

use std::path::Path;

use super::plan::LogFormat;
use super::{IngestError, LogColumn, LogFile};

/// A log's columns, as `servoid init` sees them.
#[derive(Debug, Clone, PartialEq)]
pub struct Inspected {
    pub format: LogFormat,
    pub columns: Vec<LogColumn>,
    /// The sampling rate the file states (DAQ text header, TDMS
    /// `wf_increment`), when it states one (Hz).
    pub rate_hz: Option<f64>,
    /// A CSV log's delimiter, as its header splits best.
    pub csv_delimiter: Option<char>,
    /// Whether a CSV log's numbers use a decimal comma (a European
    /// export's `0,000762939453` with fields delimited by `;`).
    pub csv_decimal_comma: bool,
}

/// Inspect the log at `path` in `format` (at most `max_bytes`).
pub fn inspect(path: &Path, format: LogFormat, max_bytes: u64) -> Result<Inspected, IngestError> {
    let file = LogFile::read(path, max_bytes)?;
    inspect_bytes(path, &file.bytes, format)
}

/// [`inspect`] of a log's bytes already read (`path` names it in errors).
pub fn inspect_bytes(
    path: &Path,
    bytes: &[u8],
    format: LogFormat,
) -> Result<Inspected, IngestError> {
    if bytes.iter().all(u8::is_ascii_whitespace) {
        return Err(IngestError::Empty {
            path: path.to_path_buf(),
        });
    }
    let named = |names: Vec<String>| -> Vec<LogColumn> {
        names
            .into_iter()
            .map(|name| LogColumn { name, unit: None })
            .collect()
    };
    let mut csv_delimiter = None;
    let mut csv_decimal_comma = false;
    let (columns, rate_hz) = match format {
        LogFormat::Csv => {
            let (names, sep) = csv_header(path, bytes)?;
            csv_delimiter = Some(char::from(sep));
            csv_decimal_comma = sep != b',' && decimal_comma(bytes, sep);
            (named(names), None)
        }
        LogFormat::Parquet => (named(super::parquet::names(path, bytes)?), None),
        LogFormat::DaqText => super::daq::columns(path, bytes)?,
        LogFormat::Mat => (super::mat::columns(path, bytes)?, None),
        LogFormat::Hdf5 => (super::hdf5::columns(path, bytes, false)?, None),
        LogFormat::Tdms => super::tdms::columns(path, bytes)?,
    };
    Ok(Inspected {
        format,
        columns,
        rate_hz,
        csv_delimiter,
        csv_decimal_comma,
    })
}

/// The data lines a CSV log's decimal mark is read from.
const DECIMAL_LINES: usize = 20;

/// Whether the numbers of a CSV log delimited by `sep` (not a comma) are
/// written with a decimal comma: among the first [`DECIMAL_LINES`] lines
/// after the header, some field is digits, one comma and digits, and none
/// is digits, a point and digits.
fn decimal_comma(bytes: &[u8], sep: u8) -> bool {
    let text = String::from_utf8_lossy(&bytes[..bytes.len().min(1 << 16)]);
    let lines = text.lines().filter(|l| !l.trim().is_empty()).skip(1);
    let (mut comma, mut point) = (false, false);
    for line in lines.take(DECIMAL_LINES) {
        for field in line.split(char::from(sep)) {
            let f = field.trim().trim_start_matches(['-', '+']);
            let number_with = |mark: char| {
                f.split_once(mark).is_some_and(|(a, b)| {
                    // Digits, and an exponent's letters and signs after them.
                    let digits = |s: &str| {
                        s.starts_with(|c: char| c.is_ascii_digit())
                            && s.chars().all(|c| c.is_ascii_digit() || "eE+-".contains(c))
                    };
                    digits(a) && digits(b)
                })
            };
            comma |= number_with(',');
            point |= number_with('.');
        }
    }
    comma && !point
}

/// The delimiters a CSV log may use, tried in turn: the first that splits
/// the header into the most fields is taken.
pub const CSV_DELIMITERS: [u8; 3] = [b',', b';', b'\t'];

/// A CSV log's header fields and the delimiter that gives the most.
fn csv_header(path: &Path, bytes: &[u8]) -> Result<(Vec<String>, u8), IngestError> {
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    let first = bytes
        .split(|&b| b == b'\n')
        .map(|l| l.strip_suffix(b"\r").unwrap_or(l))
        .find(|l| !String::from_utf8_lossy(l).trim().is_empty())
        .ok_or_else(|| IngestError::HeaderOnly {
            path: path.to_path_buf(),
            what: "only blank lines".into(),
        })?;
    let mut best: Option<(Vec<String>, u8)> = None;
    for sep in CSV_DELIMITERS {
        let mut f = super::fields::Fields::new(sep);
        let names: Vec<String> = f
            .split(first)
            .into_iter()
            .map(|s| s.trim().to_string())
            .collect();
        if best.as_ref().is_none_or(|(b, _)| names.len() > b.len()) {
            best = Some((names, sep));
        }
    }
    Ok(best.expect("three delimiters"))
}
