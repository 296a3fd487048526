//! Delimited text logs, parsed by polars, with a line parser behind it.
//!
//! This file finds the header itself (to resolve columns by name or index and
//! list the available ones), then has polars parse the wanted columns as f64.
//! When polars refuses the file (spaces around values, a value that is not a
//! number), a line-by-line parser reads the wanted fields trimmed, and either
//! copes or names the line and column at fault. Both the header and that
//! parser split a line as CSV quotes it (`fields`, csv-core): a quoted field
//! may hold the delimiter. Both skip the first
//! `skip_lines` lines, comment lines and blank lines. Line numbers count every
//! line of the file, 1-based.

use std::io::Cursor;
use std::path::Path;

use polars::prelude::{
    CsvParseOptions, CsvReadOptions, DataType, Field, Schema, SchemaRef, SerReader,
};

use super::fields::Fields;
use super::plan::{Column, LogPlan};
use super::{At, FormatProblem, IngestError, Raw, Wanted, list, raw_from_table, wanted};

/// Read a CSV log's wanted columns.
pub(super) fn read<'a>(
    path: &Path,
    bytes: &'a [u8],
    plan: &'a LogPlan,
) -> Result<Raw<'a>, IngestError> {
    // A UTF-8 byte-order mark is not part of the first column's name.
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    let opts = Layout::new(path, plan)?;
    let mut lines = opts.data_lines(bytes);
    let Some((first_no, first)) = lines.next() else {
        return Err(IngestError::HeaderOnly {
            path: path.to_path_buf(),
            what: "only skipped, comment or blank lines".into(),
        });
    };
    let mut header_fields = Fields::new(opts.sep);
    let first_fields: Vec<&str> = header_fields.split(first);
    let names = plan.csv.header.then_some(first_fields.as_slice());
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
    let header = plan.csv.header;
    let columns = match by_polars(path, bytes, plan, &opts, names, &want, &index) {
        Some(result) => result?,
        None => by_hand(path, bytes, &opts, header, &want, &index)?,
    };
    if columns[0].is_empty() {
        return Err(IngestError::HeaderOnly {
            path: path.to_path_buf(),
            what: "no line parses as a data row".into(),
        });
    }
    let locate = Box::new(move |row: usize| {
        let (line_no, _) = opts
            .data_lines(bytes)
            .nth(row + usize::from(header))
            .expect("every row is a data line");
        At::Line(line_no)
    });
    raw_from_table(path, plan, columns, locate)
}

/// The wanted columns, parsed by polars; `None` when polars cannot parse
/// them (the caller then parses by hand, which either copes, e.g. with
/// spaces around values, or names the line at fault).
fn by_polars(
    path: &Path,
    bytes: &[u8],
    plan: &LogPlan,
    opts: &Layout<'_>,
    names: Option<&[&str]>,
    want: &[Wanted<'_>],
    index: &[usize],
) -> Option<Result<Vec<Vec<f64>>, IngestError>> {
    let polars_name = |i: usize| match names {
        Some(n) => n[i].to_string(),
        None => format!("column_{}", i + 1),
    };
    let mut projection = index.to_vec();
    projection.sort_unstable();
    projection.dedup();
    let schema: Schema = projection
        .iter()
        .map(|&i| Field::new(polars_name(i).into(), DataType::Float64))
        .collect();
    let mut parse = CsvParseOptions::default()
        .with_separator(opts.sep)
        .with_decimal_comma(opts.decimal_comma);
    if let Some(p) = opts.comment {
        parse = parse.with_comment_prefix(Some(p));
    }
    // polars reads a blank line as a row of nulls; blank lines are skipped
    // here, as in the other text format, by handing polars a copy without
    // them (only when there are any).
    let cleaned = without_blank_lines(bytes, plan.csv.skip_lines);
    // A panic inside polars (damaged input) is a refusal like its errors:
    // the line parser then reads the file or names what is wrong with it.
    let df = super::guard_reader(|| {
        CsvReadOptions::default()
            .with_has_header(plan.csv.header)
            .with_skip_lines(plan.csv.skip_lines)
            .with_projection(Some(projection.into()))
            .with_schema_overwrite(Some(SchemaRef::new(schema)))
            .with_raise_if_empty(false)
            .with_parse_options(parse)
            .into_reader_with_file_handle(Cursor::new(cleaned.as_deref().unwrap_or(bytes)))
            .finish()
    })
    .ok()?
    .ok()?;

    let mut df = df;
    let mut columns = Vec::with_capacity(want.len());
    for (k, (w, &i)) in want.iter().zip(index).enumerate() {
        // A column no later channel reads is taken out of the frame, and
        // freed once copied, rather than kept to the end.
        let col = if index[k + 1..].contains(&i) {
            df.column(&polars_name(i)).ok()?.clone()
        } else {
            df.drop_in_place(&polars_name(i)).ok()?
        };
        let col = col.cast(&DataType::Float64).ok()?;
        let ca = col.f64().ok()?;
        if ca.null_count() > 0 {
            let row = ca.iter().position(|v| v.is_none()).expect("a null exists");
            let (line_no, line) = opts
                .data_lines(bytes)
                .nth(row + usize::from(plan.csv.header))?;
            return Some(Err(IngestError::MissingValue {
                path: path.to_path_buf(),
                at: At::Line(line_no),
                channel: w.channel,
                column: w.column.to_string(),
                detail: field_detail(line, opts.sep, i),
            }));
        }
        columns.push(ca.into_no_null_iter().collect::<Vec<f64>>());
    }
    Some(Ok(columns))
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
    // it; what follows the final '\n' is not a line. So there is one where
    // the body starts with "\n" or "\r\n" or holds "\n\n" or "\n\r\n":
    // found at memory speed, where a byte-by-byte walk was a tenth of
    // reading the file.
    let any = body.starts_with(b"\n")
        || body.starts_with(b"\r\n")
        || memchr::memmem::find(body, b"\n\n").is_some()
        || memchr::memmem::find(body, b"\n\r\n").is_some();
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
    /// Whether numbers are written with a decimal comma.
    decimal_comma: bool,
    skip_lines: usize,
    comment: Option<&'p str>,
}

impl<'p> Layout<'p> {
    fn new(path: &Path, plan: &'p LogPlan) -> Result<Self, IngestError> {
        let d = plan.csv.delimiter.as_bytes();
        if d.len() != 1 {
            return Err(IngestError::format(
                path,
                FormatProblem::Delimiter {
                    delimiter: plan.csv.delimiter.clone(),
                },
            ));
        }
        // A `.tsv` file is tab-delimited unless its options say otherwise
        // (the default delimiter, a comma, is not what a .tsv holds).
        let tsv = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("tsv"));
        Ok(Layout {
            sep: if tsv && d == b"," { b'\t' } else { d[0] },
            decimal_comma: plan.csv.decimal == ",",
            skip_lines: plan.csv.skip_lines,
            comment: plan.csv.comment_prefix.as_deref().filter(|p| !p.is_empty()),
        })
    }

    /// Header (if any) and data lines with their 1-based line numbers.
    fn data_lines<'b>(
        &self,
        bytes: &'b [u8],
    ) -> impl Iterator<Item = (usize, &'b [u8])> + use<'b, 'p> {
        let comment = self.comment.map(str::as_bytes);
        bytes
            .split(|&b| b == b'\n')
            .enumerate()
            .skip(self.skip_lines)
            .map(|(i, l)| (i + 1, l.strip_suffix(b"\r").unwrap_or(l)))
            .filter(move |(_, l)| !l.is_empty() && !comment.is_some_and(|c| l.starts_with(c)))
    }
}

/// When the header reads as one field holding `;` or a tab, the file is
/// delimited by that instead: say how to read it.
fn delimiter_hint(names: &[&str]) -> String {
    match names {
        [one] if one.contains(';') => "; the header is one field with `;` in it: for a semicolon-delimited export give data.csv = { delimiter = \";\" }, and decimal = \",\" if its numbers use decimal commas".into(),
        [one] if one.contains('\t') => "; the header is one field with tabs in it: give data.csv = { delimiter = \"\\t\" }".into(),
        _ => String::new(),
    }
}

/// A field without one pair of surrounding double quotes: CSV quoting
/// unquotes a field only where the quote opens it, and a value padded with
/// spaces (` "1.5" `) is quoted inside them.
fn unquote(f: &str) -> &str {
    f.strip_prefix('"')
        .and_then(|s| s.strip_suffix('"'))
        .unwrap_or(f)
}

/// The 0-based field index of a wanted column.
fn resolve(
    path: &Path,
    w: &Wanted<'_>,
    names: Option<&[&str]>,
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
            let hits: Vec<usize> = (0..names.len())
                .filter(|&i| unquote(names[i].trim()) == n.trim())
                .collect();
            match hits.as_slice() {
                [i] => Ok(*i),
                [] => Err(missing(format!(
                    "columns: {}{}",
                    list(names.iter().map(|n| format!("`{n}`"))),
                    delimiter_hint(names)
                ))),
                _ => Err(IngestError::format(
                    path,
                    FormatProblem::DuplicateColumn {
                        name: n.clone(),
                        channel: w.channel,
                        fields: hits,
                    },
                )),
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

/// The wanted columns, parsed line by line: slower than polars, but it
/// trims spaces around values and names the first line whose wanted field is
/// missing or not a number.
fn by_hand(
    path: &Path,
    bytes: &[u8],
    opts: &Layout<'_>,
    header: bool,
    want: &[Wanted<'_>],
    index: &[usize],
) -> Result<Vec<Vec<f64>>, IngestError> {
    let mut columns = vec![Vec::new(); want.len()];
    let mut splitter = Fields::new(opts.sep);
    for (line_no, line) in opts.data_lines(bytes).skip(usize::from(header)) {
        let fields = splitter.split(line);
        for ((w, &i), col) in want.iter().zip(index).zip(&mut columns) {
            let missing = |detail: String| IngestError::MissingValue {
                path: path.to_path_buf(),
                at: At::Line(line_no),
                channel: w.channel,
                column: w.column.to_string(),
                detail,
            };
            let Some(field) = fields.get(i) else {
                return Err(missing(fields_detail(fields.len())));
            };
            let value = unquote(field.trim()).trim();
            if value.is_empty() {
                return Err(missing(format!("field {i} is empty")));
            }
            let parsed = if opts.decimal_comma {
                value.replacen(',', ".", 1).parse::<f64>()
            } else {
                value.parse::<f64>()
            };
            col.push(parsed.map_err(|_| IngestError::BadValue {
                path: path.to_path_buf(),
                at: At::Line(line_no),
                channel: w.channel,
                column: w.column.to_string(),
                value: value.to_string(),
            })?);
        }
    }
    Ok(columns)
}

/// Why field `i` of `line` gave no value.
fn field_detail(line: &[u8], sep: u8, i: usize) -> String {
    let n = Fields::new(sep).split(line).len();
    if i < n {
        format!("field {i} is empty")
    } else {
        fields_detail(n)
    }
}

fn fields_detail(n: usize) -> String {
    format!("the line has {n} field{}", if n == 1 { "" } else { "s" })
}

#[cfg(test)]
mod tests {
    use super::without_blank_lines;

    /// The lines of `bytes` after the first `skip` by a walk over its
    /// bytes, those blank (empty or a lone '\r', ended by '\n') left out:
    /// `None` when there is none to leave out.
    fn walked(bytes: &[u8], skip: usize) -> Option<Vec<u8>> {
        let mut lines: Vec<&[u8]> = bytes.split(|&b| b == b'\n').collect();
        // What follows the final '\n' is not a line.
        let tail = lines.pop().unwrap_or_default();
        let (head, body) = lines.split_at(skip.min(lines.len()));
        if lines.len() < skip {
            return None;
        }
        let blank = |l: &&[u8]| l.is_empty() || *l == b"\r";
        if !body.iter().any(blank) {
            return None;
        }
        let mut out = Vec::new();
        for l in head.iter().chain(body.iter().filter(|l| !blank(l))) {
            out.extend_from_slice(l);
            out.push(b'\n');
        }
        // The rest after the last '\n' is kept as a line unless blank.
        if !blank(&tail) {
            out.extend_from_slice(tail);
            out.push(b'\n');
        }
        Some(out)
    }

    #[test]
    fn blank_lines_are_found_where_a_walk_over_the_lines_finds_them() {
        let cases: [&[u8]; 14] = [
            b"a,b\n\n1,2",
            b"a,b\n\n1,2\n\r",
            b"a,b\n1,2\n",
            b"a,b\n\n1,2\n",
            b"\na,b\n1,2\n",
            b"\r\na,b\n1,2\n",
            b"a,b\r\n\r\n1,2\r\n",
            b"a,b\n1,2",
            b"a,b\n1,2\n\r",
            b"a,b\n1,2\n\n",
            b"a,b\r\n1,2\r\n",
            b"# x\n\na,b\n1,2\n",
            b"a\rb\n1,2\n",
            b"",
        ];
        for case in cases {
            for skip in [0, 1] {
                assert_eq!(
                    without_blank_lines(case, skip),
                    walked(case, skip),
                    "{:?}, skip {skip}",
                    String::from_utf8_lossy(case)
                );
            }
        }
    }
}
