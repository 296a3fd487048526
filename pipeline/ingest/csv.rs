//! Delimited text logs, parsed by polars.
//!
//! polars does the fast parse; this file finds the header itself (to resolve
//! columns and list the available ones), forces the wanted columns to f64 and,
//! when polars refuses a value, rescans the lines to name the line and column
//! at fault. Line numbers count every line of the file, 1-based, with the
//! lines polars skips: the first `skip_lines`, comment lines and blank lines.

use std::io::Cursor;
use std::path::Path;

use polars::prelude::{
    CsvParseOptions, CsvReadOptions, DataType, Field, Schema, SchemaRef, SerReader,
};

use super::{At, IngestError, Raw, Wanted, list, raw_from_table, wanted};
use crate::manifest::{Column, LogPlan};

/// Read a CSV log's wanted columns.
pub(super) fn read<'a>(
    path: &Path,
    bytes: &'a [u8],
    plan: &'a LogPlan,
) -> Result<Raw<'a>, IngestError> {
    let opts = Layout::new(path, plan)?;
    let mut lines = opts.data_lines(bytes);
    let Some((first_no, first)) = lines.next() else {
        return Err(IngestError::HeaderOnly {
            path: path.to_path_buf(),
            what: "only skipped, comment or blank lines".into(),
        });
    };
    let first_fields: Vec<String> = split(first, opts.sep)
        .map(|f| unquote(f).to_string())
        .collect();
    let names = plan.csv.header.then_some(&first_fields);
    if names.is_some() && lines.next().is_none() {
        return Err(IngestError::HeaderOnly {
            path: path.to_path_buf(),
            what: format!("a header at line {first_no} and nothing after it"),
        });
    }

    let want = wanted(plan);
    let mut index = Vec::with_capacity(want.len());
    for w in &want {
        index.push(resolve(path, w, names, first_fields.len())?);
    }
    let polars_name = |i: usize| match names {
        Some(n) => n[i].clone(),
        None => format!("column_{}", i + 1),
    };
    let mut projection = index.clone();
    projection.sort_unstable();
    projection.dedup();
    let schema: Schema = projection
        .iter()
        .map(|&i| Field::new(polars_name(i).into(), DataType::Float64))
        .collect();

    let mut parse = CsvParseOptions::default().with_separator(opts.sep);
    if let Some(p) = &plan.csv.comment_prefix {
        parse = parse.with_comment_prefix(Some(p.as_str()));
    }
    // polars reads a blank line as a row of nulls; blank lines are skipped
    // here, as in the other text format, by handing polars a copy without
    // them (only when there are any).
    let cleaned = without_blank_lines(bytes, plan.csv.skip_lines);
    let df = CsvReadOptions::default()
        .with_has_header(plan.csv.header)
        .with_skip_lines(plan.csv.skip_lines)
        .with_projection(Some(projection.clone().into()))
        .with_schema_overwrite(Some(SchemaRef::new(schema)))
        .with_raise_if_empty(false)
        .with_parse_options(parse)
        .into_reader_with_file_handle(Cursor::new(cleaned.as_deref().unwrap_or(bytes)))
        .finish()
        .map_err(|e| {
            diagnose(path, bytes, &opts, plan.csv.header, &want, &index).unwrap_or_else(|| {
                IngestError::Format {
                    path: path.to_path_buf(),
                    message: format!("polars cannot read it as CSV: {e}"),
                }
            })
        })?;
    if df.height() == 0 {
        return Err(IngestError::HeaderOnly {
            path: path.to_path_buf(),
            what: "no line parses as a data row".into(),
        });
    }

    let mut columns = Vec::with_capacity(want.len());
    for (w, &i) in want.iter().zip(&index) {
        let name = polars_name(i);
        let internal = |message: String| IngestError::Format {
            path: path.to_path_buf(),
            message,
        };
        let col = df
            .column(&name)
            .map_err(|e| internal(format!("column `{name}` lost in parsing: {e}")))?;
        let col = col
            .cast(&DataType::Float64)
            .map_err(|e| internal(format!("column `{name}` is not numeric: {e}")))?;
        let ca = col
            .f64()
            .map_err(|e| internal(format!("column `{name}` is not numeric: {e}")))?;
        if ca.null_count() > 0 {
            let row = ca.iter().position(|v| v.is_none()).expect("a null exists");
            let (line_no, line) = opts
                .data_lines(bytes)
                .nth(row + usize::from(plan.csv.header))
                .expect("polars' rows are data lines");
            return Err(IngestError::MissingValue {
                path: path.to_path_buf(),
                at: At::Line(line_no),
                channel: w.channel,
                column: w.column.to_string(),
                detail: field_detail(line, opts.sep, i),
            });
        }
        columns.push(ca.into_no_null_iter().collect::<Vec<f64>>());
    }

    let skip_header = usize::from(plan.csv.header);
    let locate = Box::new(move |row: usize| {
        let (line_no, _) = opts
            .data_lines(bytes)
            .nth(row + skip_header)
            .expect("polars' rows are data lines");
        At::Line(line_no)
    });
    raw_from_table(path, plan, columns, locate)
}

/// `bytes` without the blank lines that follow the first `skip_lines`
/// lines, or `None` when there are none.
fn without_blank_lines(bytes: &[u8], skip_lines: usize) -> Option<Vec<u8>> {
    let mut start = 0;
    for _ in 0..skip_lines {
        match bytes[start..].iter().position(|&b| b == b'\n') {
            Some(k) => start += k + 1,
            None => return None,
        }
    }
    let body = &bytes[start..];
    let blank = |l: &[u8]| l.is_empty() || l == b"\r";
    // A blank line is one ended by '\n' with nothing (or only '\r') before
    // it; what follows the final '\n' is not a line.
    let mut line_start = 0;
    let mut any = false;
    for (i, &b) in body.iter().enumerate() {
        if b == b'\n' {
            if blank(&body[line_start..i]) {
                any = true;
                break;
            }
            line_start = i + 1;
        }
    }
    if !any {
        return None;
    }
    let mut out = Vec::with_capacity(bytes.len());
    out.extend_from_slice(&bytes[..start]);
    for l in body.split(|&b| b == b'\n').filter(|l| !blank(l)) {
        out.extend_from_slice(l);
        out.push(b'\n');
    }
    Some(out)
}

/// How lines are told apart: the options polars gets, for the rescans.
struct Layout<'p> {
    sep: u8,
    skip_lines: usize,
    comment: Option<&'p [u8]>,
}

impl<'p> Layout<'p> {
    fn new(path: &Path, plan: &'p LogPlan) -> Result<Self, IngestError> {
        let d = plan.csv.delimiter.as_bytes();
        if d.len() != 1 {
            return Err(IngestError::Format {
                path: path.to_path_buf(),
                message: format!(
                    "the CSV delimiter must be one ASCII character (got {:?})",
                    plan.csv.delimiter
                ),
            });
        }
        Ok(Layout {
            sep: d[0],
            skip_lines: plan.csv.skip_lines,
            comment: plan
                .csv
                .comment_prefix
                .as_deref()
                .filter(|p| !p.is_empty())
                .map(str::as_bytes),
        })
    }

    /// Header (if any) and data lines with their 1-based line numbers.
    fn data_lines<'b>(
        &self,
        bytes: &'b [u8],
    ) -> impl Iterator<Item = (usize, &'b [u8])> + use<'b, 'p> {
        let comment = self.comment;
        bytes
            .split(|&b| b == b'\n')
            .enumerate()
            .skip(self.skip_lines)
            .map(|(i, l)| (i + 1, l.strip_suffix(b"\r").unwrap_or(l)))
            .filter(move |(_, l)| !l.is_empty() && !comment.is_some_and(|c| l.starts_with(c)))
    }
}

fn split(line: &[u8], sep: u8) -> impl Iterator<Item = &str> {
    line.split(move |&b| b == sep)
        .map(|f| std::str::from_utf8(f).unwrap_or("\u{fffd}"))
}

/// A field without one pair of surrounding double quotes.
fn unquote(f: &str) -> &str {
    f.strip_prefix('"')
        .and_then(|s| s.strip_suffix('"'))
        .unwrap_or(f)
}

/// The 0-based field index of a wanted column.
fn resolve(
    path: &Path,
    w: &Wanted<'_>,
    names: Option<&Vec<String>>,
    n_fields: usize,
) -> Result<usize, IngestError> {
    let missing = |available: String| IngestError::MissingColumn {
        path: path.to_path_buf(),
        channel: w.channel,
        column: w.column.to_string(),
        available,
    };
    match (w.column, names) {
        (Column::Name(n), Some(names)) => {
            let hits: Vec<usize> = (0..names.len()).filter(|&i| &names[i] == n).collect();
            match hits.as_slice() {
                [i] => Ok(*i),
                [] => Err(missing(format!(
                    "columns: {}",
                    list(names.iter().map(|n| format!("`{n}`")))
                ))),
                _ => Err(IngestError::Format {
                    path: path.to_path_buf(),
                    message: format!(
                        "column `{n}` ({} channel) appears {} times in the header (fields {}); rename one or address it by index",
                        w.channel,
                        hits.len(),
                        list(&hits)
                    ),
                }),
            }
        }
        (Column::Name(_), None) => Err(missing(format!(
            "the file has no header line (csv.header = false), so address columns by index 0 to {}",
            n_fields.saturating_sub(1)
        ))),
        (Column::Index(i), names) => {
            if *i < n_fields {
                Ok(*i)
            } else {
                Err(missing(match names {
                    Some(names) => format!(
                        "{n_fields} columns, indices 0 to {}: {}",
                        n_fields - 1,
                        list(names.iter().map(|n| format!("`{n}`")))
                    ),
                    None => format!(
                        "the first data line has {n_fields} fields, indices 0 to {}",
                        n_fields.saturating_sub(1)
                    ),
                }))
            }
        }
    }
}

/// After polars refused the file: the first line whose wanted field is
/// missing or not a number, as an error naming it; `None` if every wanted
/// field parses (the trouble is elsewhere, and polars' message stands).
fn diagnose(
    path: &Path,
    bytes: &[u8],
    opts: &Layout<'_>,
    header: bool,
    want: &[Wanted<'_>],
    index: &[usize],
) -> Option<IngestError> {
    for (line_no, line) in opts.data_lines(bytes).skip(usize::from(header)) {
        let fields: Vec<&str> = split(line, opts.sep).collect();
        for (w, &i) in want.iter().zip(index) {
            let at = At::Line(line_no);
            let Some(field) = fields.get(i) else {
                return Some(IngestError::MissingValue {
                    path: path.to_path_buf(),
                    at,
                    channel: w.channel,
                    column: w.column.to_string(),
                    detail: fields_detail(fields.len()),
                });
            };
            let value = unquote(field);
            if value.is_empty() {
                return Some(IngestError::MissingValue {
                    path: path.to_path_buf(),
                    at,
                    channel: w.channel,
                    column: w.column.to_string(),
                    detail: format!("field {i} is empty"),
                });
            }
            if value.parse::<f64>().is_err() {
                return Some(IngestError::BadValue {
                    path: path.to_path_buf(),
                    at,
                    channel: w.channel,
                    column: w.column.to_string(),
                    value: value.to_string(),
                });
            }
        }
    }
    None
}

/// Why field `i` of `line` gave no value.
fn field_detail(line: &[u8], sep: u8, i: usize) -> String {
    let n = split(line, sep).count();
    if i < n {
        format!("field {i} is empty")
    } else {
        fields_detail(n)
    }
}

fn fields_detail(n: usize) -> String {
    format!("the line has {n} field{}", if n == 1 { "" } else { "s" })
}
