//! DAQ text exports (`.txt`), parsed by hand: the data lines are ragged,
//! which polars refuses. A header of `key: value` lines (`Sampling Rate`,
//! `Sampling Interval`, `Sample Count`, ...), then a line without a colon
//! naming the columns (`Sample Number, Date/Time, CHANNEL0, ..., Events`),
//! then one line per sample.
//!
//! Columns are addressed by name (`CHANNEL0`) or by 0-based index into the
//! column-name line; fields after the last wanted one are never looked at,
//! so the Events field may be absent or hold commas. The time base is the
//! header's `Sampling Rate` (or 1 / `Sampling Interval`) for `FromLog`, the
//! manifest's rate, or a named column; the `Sample Number` column must count
//! up by one (a skipped number is a dropped sample). The date/time stamps
//! are not used. Places are 1-based line numbers. A whole example:
//! docs/methods.md, "DAQ text exports".

use crate::warning::Warning;
use std::path::Path;

use super::plan::{Column, LogPlan, TimePlan};
use super::{At, FormatProblem, IngestError, Raw, RawTime, Wanted, list, wanted};

/// Header values used (others are ignored).
#[derive(Default)]
struct Header {
    header_size: Option<usize>,
    rate_hz: Option<f64>,
    interval_s: Option<f64>,
    sample_count: Option<usize>,
}

/// Columns that hold text.
const TEXT_COLUMNS: [&str; 2] = ["Date/Time", "Events"];

/// Read a DAQ text log's wanted columns.
pub(super) fn read<'a>(
    path: &Path,
    bytes: &'a [u8],
    plan: &'a LogPlan,
) -> Result<Raw<'a>, IngestError> {
    let mut lines = Lines {
        bytes,
        pos: 0,
        no: 0,
    };
    let (header, names) = read_header(path, &mut lines)?;
    let names_line = lines.no;
    let mut warnings = Vec::new();
    if let Some(size) = header.header_size
        && size != names_line
    {
        warnings.push(Warning::new(
            format!("the header's size ({size}) is not the column names' line ({names_line})"),
            format!(
                "{}: the header says `Header Size: {size}` but the column names are on line {names_line}",
                path.display()
            ),
        ));
    }
    let want = wanted(plan);
    let index = resolve_columns(path, &want, &names, names_line)?;
    let check_samples = names
        .first()
        .is_some_and(|n| n.eq_ignore_ascii_case("Sample Number"));
    let data = read_rows(path, &mut lines, &want, &index, &names, check_samples)?;
    if data.rows == 0 {
        return Err(IngestError::HeaderOnly {
            path: path.to_path_buf(),
            what: format!("nothing after the column names on line {names_line}"),
        });
    }
    if let Some(count) = header.sample_count
        && count != data.rows
    {
        let truncated = if data.rows < count {
            " (truncated?)"
        } else {
            ""
        };
        warnings.push(Warning::new(
            format!(
                "the header says {count} samples, the file has {}{truncated}",
                data.rows
            ),
            format!(
                "{}: the header says `Sample Count: {count}` but the file has {} data lines{truncated}",
                path.display(),
                data.rows,
            ),
        ));
    }
    let header_hz = header_rate(&header, path, &mut warnings);
    let mut it = data.columns.into_iter();
    let time = time_base(plan, &mut it, header_hz, path, &mut warnings)?;
    let command = it.next().expect("command wanted");
    let displacement = it.next().expect("displacement wanted");
    let force = it.next();
    Ok(Raw {
        time,
        command,
        displacement,
        force,
        locate: line_locator(data.first_line, data.blanks),
        warnings,
    })
}

/// The rate the header gives: its `Sampling Rate`, else 1 / its `Sampling
/// Interval`; a warning when it gives both and they disagree.
fn header_rate(header: &Header, path: &Path, warnings: &mut Vec<Warning>) -> Option<f64> {
    match (header.rate_hz, header.interval_s) {
        (Some(hz), Some(dt)) => {
            if ((hz * dt) - 1.0).abs() > 1e-9 {
                warnings.push(Warning::new(
                    "the header's sampling rate and interval disagree; the rate is used",
                    format!(
                        "{}: the header's `Sampling Rate: {hz}` and `Sampling Interval: {dt}` disagree; the rate is used",
                        path.display()
                    ),
                ));
            }
            Some(hz)
        }
        (Some(hz), None) => Some(hz),
        (None, Some(dt)) => Some(1.0 / dt),
        (None, None) => None,
    }
}

/// The time base the plan asks for: the next of `columns` (the time
/// column, when it is wanted), the manifest's rate (a warning when it
/// overrides the header's) or the header's rate.
fn time_base(
    plan: &LogPlan,
    columns: &mut impl Iterator<Item = Vec<f64>>,
    header_hz: Option<f64>,
    path: &Path,
    warnings: &mut Vec<Warning>,
) -> Result<RawTime, IngestError> {
    Ok(match &plan.channels.time {
        TimePlan::Column { column, to_s } => RawTime::Column {
            raw: columns.next().expect("time wanted"),
            to_s: *to_s,
            column: column.to_string(),
        },
        TimePlan::SampleRate { hz } => {
            if let Some(h) = header_hz
                && ((h - hz) / hz).abs() > 1e-9
            {
                warnings.push(Warning::new(
                    format!("the manifest's sampling rate {hz} Hz overrides the header's {h} Hz"),
                    format!(
                        "{}: the manifest's sampling rate {hz} Hz overrides the header's {h} Hz",
                        path.display()
                    ),
                ));
            }
            RawTime::Rate {
                hz: *hz,
                from: "manifest",
            }
        }
        TimePlan::FromLog => RawTime::Rate {
            hz: header_hz.ok_or_else(|| IngestError::format(path, FormatProblem::NoHeaderRate))?,
            from: "DAQ header",
        },
    })
}

/// Where sample `i` sits: its data line, counting the blank lines skipped
/// before it (`blanks`: rows read before each run of blanks, and how many).
fn line_locator(first_line: usize, blanks: Vec<(usize, usize)>) -> Box<dyn Fn(usize) -> At + Send> {
    Box::new(move |i: usize| {
        let skipped: usize = blanks
            .iter()
            .take_while(|(r, _)| *r <= i)
            .map(|(_, k)| k)
            .sum();
        At::Line(first_line + i + skipped)
    })
}

/// The header block, up to the column-name line, and the column names.
/// A DAQ text export's numeric columns and the rate its header gives.
pub(super) fn columns(
    path: &Path,
    bytes: &[u8],
) -> Result<(Vec<super::LogColumn>, Option<f64>), IngestError> {
    let mut lines = Lines {
        bytes,
        pos: 0,
        no: 0,
    };
    let (header, names) = read_header(path, &mut lines)?;
    let rate = header
        .rate_hz
        .or(header.interval_s.map(|dt| 1.0 / dt))
        .filter(|r| r.is_finite() && *r > 0.0);
    let columns = names
        .iter()
        .filter(|n| !TEXT_COLUMNS.contains(n) && **n != "Sample Number")
        .map(|n| super::LogColumn {
            name: n.to_string(),
            unit: None,
        })
        .collect();
    Ok((columns, rate))
}

fn read_header<'a>(
    path: &Path,
    lines: &mut Lines<'a>,
) -> Result<(Header, Vec<&'a str>), IngestError> {
    let mut header = Header::default();
    let names: Vec<&str> = loop {
        let Some(line) = lines.next() else {
            return Err(IngestError::HeaderOnly {
                path: path.to_path_buf(),
                what: "a header block but no column-name line (`Sample Number, Date/Time, CHANNEL0, ...`)".into(),
            });
        };
        let text = utf8(line).trim();
        if text.is_empty() {
            continue;
        }
        let Some((key, value)) = text.split_once(':') else {
            break text.split(',').map(str::trim).collect();
        };
        let (key, value) = (key.trim(), value.trim());
        let bad = || {
            IngestError::format(
                path,
                FormatProblem::HeaderValue {
                    line: lines.no,
                    key: key.to_string(),
                    value: value.to_string(),
                },
            )
        };
        let positive = |v: f64| v.is_finite() && v > 0.0;
        match key {
            "Header Size" => header.header_size = Some(value.parse().map_err(|_| bad())?),
            "Sample Count" => header.sample_count = Some(value.parse().map_err(|_| bad())?),
            "Sampling Rate" => {
                let v = value
                    .parse()
                    .ok()
                    .filter(|&v| positive(v))
                    .ok_or_else(bad)?;
                header.rate_hz = Some(v);
            }
            "Sampling Interval" => {
                let v = value
                    .parse()
                    .ok()
                    .filter(|&v| positive(v))
                    .ok_or_else(bad)?;
                header.interval_s = Some(v);
            }
            _ => {}
        }
    };
    Ok((header, names))
}

/// The field index of each wanted column; text columns cannot be channels.
fn resolve_columns(
    path: &Path,
    want: &[Wanted<'_>],
    names: &[&str],
    names_line: usize,
) -> Result<Vec<usize>, IngestError> {
    let mut index = Vec::with_capacity(want.len());
    for w in want {
        let found = match w.column {
            Column::Name(n) => names.iter().position(|c| c == n),
            Column::Index(i) => (*i < names.len()).then_some(*i),
        };
        let Some(i) = found else {
            return Err(IngestError::MissingColumn {
                path: path.to_path_buf(),
                channel: w.channel,
                column: w.column.to_string(),
                available: format!(
                    "line {names_line} names {} columns, indices 0 to {}: {}",
                    names.len(),
                    names.len().saturating_sub(1),
                    list(names.iter().map(|n| format!("`{n}`")))
                ),
            });
        };
        if TEXT_COLUMNS.contains(&names[i]) {
            return Err(IngestError::format(
                path,
                FormatProblem::TextColumn {
                    name: names[i].to_string(),
                    index: i,
                    channel: w.channel,
                },
            ));
        }
        index.push(i);
    }
    Ok(index)
}

/// The data lines: the wanted columns' values, with where blank lines
/// fell (for naming a sample's line later).
struct Rows {
    columns: Vec<Vec<f64>>,
    rows: usize,
    /// Line number of the first data line.
    first_line: usize,
    /// (rows read before it, blank lines skipped) for blank lines among data.
    blanks: Vec<(usize, usize)>,
}

/// Read the data lines: each wanted field a number, sample numbers (when
/// the first column holds them) consecutive.
fn read_rows(
    path: &Path,
    lines: &mut Lines<'_>,
    want: &[Wanted<'_>],
    index: &[usize],
    names: &[&str],
    check_samples: bool,
) -> Result<Rows, IngestError> {
    let last_field = index.iter().copied().max().unwrap_or(0);
    let expect_rows = lines.bytes.len() / 64;
    let mut columns: Vec<Vec<f64>> = want
        .iter()
        .map(|_| Vec::with_capacity(expect_rows))
        .collect();
    let mut fields: Vec<&[u8]> = Vec::with_capacity(last_field + 2);
    let mut first_line = 0;
    let mut blanks: Vec<(usize, usize)> = Vec::new();
    let mut prev_sample: Option<u64> = None;
    let mut rows = 0usize;
    while let Some(line) = lines.next() {
        if line.iter().all(u8::is_ascii_whitespace) {
            if rows > 0 {
                match blanks.last_mut() {
                    Some((r, k)) if *r == rows => *k += 1,
                    _ => blanks.push((rows, 1)),
                }
            }
            continue;
        }
        if rows == 0 {
            first_line = lines.no;
        }
        let at = At::Line(lines.no);
        fields.clear();
        fields.extend(line.splitn(last_field + 2, |&b| b == b','));
        if check_samples {
            let field = fields[0].trim_ascii();
            let n: u64 = utf8(field).parse().map_err(|_| IngestError::BadValue {
                path: path.to_path_buf(),
                at,
                channel: "sample number",
                column: format!("`{}`", names[0]),
                value: String::from_utf8_lossy(field).into_owned(),
            })?;
            if let Some(p) = prev_sample
                && p.checked_add(1) != Some(n)
            {
                return Err(IngestError::SampleGap {
                    path: path.to_path_buf(),
                    at,
                    prev: p,
                    next: n,
                });
            }
            prev_sample = Some(n);
        }
        for ((w, &i), col) in want.iter().zip(index).zip(&mut columns) {
            let Some(field) = fields.get(i) else {
                return Err(IngestError::MissingValue {
                    path: path.to_path_buf(),
                    at,
                    channel: w.channel,
                    column: w.column.to_string(),
                    detail: format!("the line has {} fields", fields.len()),
                });
            };
            let field = field.trim_ascii();
            match utf8(field).parse::<f64>() {
                Ok(v) => col.push(v),
                Err(_) if field.is_empty() => {
                    return Err(IngestError::MissingValue {
                        path: path.to_path_buf(),
                        at,
                        channel: w.channel,
                        column: w.column.to_string(),
                        detail: format!("field {i} is empty"),
                    });
                }
                Err(_) => {
                    return Err(IngestError::BadValue {
                        path: path.to_path_buf(),
                        at,
                        channel: w.channel,
                        column: w.column.to_string(),
                        value: String::from_utf8_lossy(field).into_owned(),
                    });
                }
            }
        }
        rows += 1;
    }
    Ok(Rows {
        columns,
        rows,
        first_line,
        blanks,
    })
}

/// Lines without their `\n` or `\r\n`, counted from 1.
struct Lines<'a> {
    bytes: &'a [u8],
    pos: usize,
    /// Number of the line last returned.
    no: usize,
}

impl<'a> Iterator for Lines<'a> {
    type Item = &'a [u8];

    fn next(&mut self) -> Option<&'a [u8]> {
        let rest = &self.bytes[self.pos..];
        if rest.is_empty() {
            return None;
        }
        let (line, advance) = match rest.iter().position(|&b| b == b'\n') {
            Some(k) => (&rest[..k], k + 1),
            None => (rest, rest.len()),
        };
        self.pos += advance;
        self.no += 1;
        Some(line.strip_suffix(b"\r").unwrap_or(line))
    }
}

/// Text of a field; invalid UTF-8 becomes a string that parses as nothing.
fn utf8(b: &[u8]) -> &str {
    std::str::from_utf8(b).unwrap_or("\u{fffd}")
}
