//! Side tables (a campaign's run table): CSV or Parquet read by polars into
//! named columns of text cells. The manifest checks the cells; this file only
//! reads them, so both formats give it the same shape: every cell as text,
//! an empty or null cell as `None`. Rows are the table's data rows in file
//! order as polars reads them: the header is not a row, and a blank line of
//! a CSV table is a row of empty cells (so that row N of a CSV table without
//! quoted line breaks is its line N + 1).

use std::io::Cursor;
use std::path::{Path, PathBuf};

use polars::prelude::{CsvReadOptions, DataFrame, DataType, ParquetReader, PolarsError, SerReader};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::sha256_hex;

/// Side-table file formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum TableFormat {
    /// Comma-separated text with a header line (`.csv`).
    Csv,
    /// Apache Parquet (`.parquet`, `.pq`).
    Parquet,
}

impl TableFormat {
    /// The format a file's extension names, if it names one.
    pub fn from_path(path: &Path) -> Option<Self> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "csv" => Some(TableFormat::Csv),
            "parquet" | "pq" => Some(TableFormat::Parquet),
            _ => None,
        }
    }
}

/// A side table as read: its columns' names and its rows of text cells.
#[derive(Debug, Clone, PartialEq)]
pub struct Table {
    pub path: PathBuf,
    /// SHA-256 of the file's bytes, lowercase hexadecimal.
    pub sha256: String,
    pub format: TableFormat,
    /// Column names, in file order.
    pub columns: Vec<String>,
    /// Data rows in file order, one cell per column; `None` where the cell
    /// is empty (or null), else its text without surrounding white space.
    pub rows: Vec<Vec<Option<String>>>,
    /// Whether its numbers are written with a decimal comma (a CSV table's,
    /// given or detected): the cells are as written, the reader of a number
    /// reads the comma as the point.
    pub decimal_comma: bool,
}

/// How a CSV table's text is split; None detects it where that is
/// unambiguous (see [`read_table_as`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TableText {
    pub delimiter: Option<u8>,
    pub decimal_comma: Option<bool>,
}

impl Table {
    /// The 0-based index of the column named `name`.
    pub fn column(&self, name: &str) -> Option<usize> {
        self.columns.iter().position(|c| c == name)
    }
}

/// Why a table cannot be read at all; the message names the file.
#[derive(Debug, thiserror::Error)]
#[error("{}: {problem}", path.display())]
pub struct TableError {
    pub path: PathBuf,
    #[source]
    pub problem: TableProblem,
}

/// What is wrong with a table file as a whole.
#[derive(Debug, thiserror::Error)]
pub enum TableProblem {
    #[error("cannot read: {source}")]
    Io {
        #[source]
        source: std::io::Error,
    },
    #[error("not a readable CSV table: {source}")]
    Csv {
        #[source]
        source: PolarsError,
    },
    #[error("not a readable Parquet table: {source}")]
    Parquet {
        #[source]
        source: PolarsError,
    },
    /// Its Parquet metadata or page headers declare what the file cannot
    /// hold (servoid's check before polars reads them).
    #[error("a damaged Parquet table: {source}")]
    Metadata {
        #[source]
        source: super::parquet::ParquetDamage,
    },
    /// The reader failed inside polars on damaged bytes.
    #[error("a damaged {format} table: polars failed reading it ({message})")]
    Damaged {
        format: &'static str,
        message: String,
    },
    /// A CSV header with more than one candidate delimiter in it.
    #[error("cannot tell the delimiter: the header line has {found}; give [run_table] delimiter")]
    AmbiguousDelimiter { found: String },
    /// A row that splits into more fields than the header (polars' own
    /// message advises an option servoid does not have).
    #[error(
        "a row has more fields than the header ({fields} against {header}, split on {delimiter:?}){hint}"
    )]
    Ragged {
        header: usize,
        fields: usize,
        delimiter: char,
        hint: &'static str,
    },
    /// A Parquet column of a type that has no text form (a list, a struct).
    #[error("column `{column}` holds {dtype}, which cannot be read as text")]
    NotText {
        column: String,
        /// Boxed, as in [`super::FormatProblem::NotNumeric`].
        dtype: Box<DataType>,
    },
}

/// Read a side table: every column, every cell as text, a CSV table's
/// delimiter and decimal mark detected ([`read_table_as`]).
///
/// CSV cells are taken as written (polars reads every column as text, so
/// `007` stays `007`); Parquet numbers are printed in the shortest form that
/// reads back to the same value, integers in full; dates and timestamps as
/// ISO 8601.
pub fn read_table(path: &Path, format: TableFormat) -> Result<Table, TableError> {
    read_table_as(path, format, TableText::default())
}

/// [`read_table`] with a CSV table's delimiter and decimal mark as `text`
/// gives them. What it leaves out is detected where that is unambiguous: a
/// `.tsv` file is tab-delimited; otherwise the one of `,`, `;` and tab the
/// header line holds (outside quotes), a comma when it holds none, and a
/// problem when it holds several. Numbers have a decimal comma when the
/// delimiter is not a comma, some cell is digits with one comma between
/// them (`4,5`) and none is written with a point (`4.5`).
pub fn read_table_as(
    path: &Path,
    format: TableFormat,
    text: TableText,
) -> Result<Table, TableError> {
    let bytes = std::fs::read(path).map_err(|source| TableError {
        path: path.to_path_buf(),
        problem: TableProblem::Io { source },
    })?;
    table_from_bytes_as(path, bytes, format, text)
}

/// [`read_table`] of bytes already read (`path` names them in errors).
pub fn table_from_bytes(
    path: &Path,
    bytes: Vec<u8>,
    format: TableFormat,
) -> Result<Table, TableError> {
    table_from_bytes_as(path, bytes, format, TableText::default())
}

/// [`read_table_as`] of bytes already read.
pub fn table_from_bytes_as(
    path: &Path,
    bytes: Vec<u8>,
    format: TableFormat,
    text: TableText,
) -> Result<Table, TableError> {
    let fail = |problem| TableError {
        path: path.to_path_buf(),
        problem,
    };
    // A UTF-8 byte-order mark is not part of the first column's name.
    let body = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(&bytes);
    let (sep, decimal_comma) = match format {
        TableFormat::Csv => {
            let tsv = path
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("tsv"));
            let sep = match text.delimiter {
                Some(d) => d,
                None if tsv => b'\t',
                None => sniff_delimiter(body).map_err(fail)?,
            };
            let comma = text
                .decimal_comma
                .unwrap_or_else(|| sep != b',' && sniff_decimal_comma(body, sep));
            (sep, comma)
        }
        TableFormat::Parquet => (b',', false),
    };
    let read = || match format {
        TableFormat::Csv => CsvReadOptions::default()
            .with_has_header(true)
            // No inference: every column is text, read as written.
            .with_infer_schema_length(Some(0))
            .with_raise_if_empty(false)
            .with_parse_options(polars::prelude::CsvParseOptions::default().with_separator(sep))
            .into_reader_with_file_handle(Cursor::new(body))
            .finish()
            .map_err(|source| fail(csv_problem(source, body, sep))),
        TableFormat::Parquet => {
            let mut reader = ParquetReader::new(Cursor::new(bytes.as_slice()));
            super::parquet::check_pages(&bytes, &mut reader)
                .map_err(|source| fail(TableProblem::Metadata { source }))?;
            reader
                .finish()
                .map_err(|source| fail(TableProblem::Parquet { source }))
        }
    };
    // A panic inside polars on damaged bytes is the table's problem, not a
    // crash (found by the run-table fuzz target).
    if format == TableFormat::Parquet {
        super::parquet::check_footer(&bytes)
            .map_err(|source| fail(TableProblem::Metadata { source }))?;
    }
    let df = super::off_pool(|| super::guard_reader(read)).map_err(|p| {
        fail(TableProblem::Damaged {
            format: match format {
                TableFormat::Csv => "CSV",
                TableFormat::Parquet => "Parquet",
            },
            message: p.message,
        })
    })??;
    let (columns, rows) = text_cells(&df).map_err(fail)?;
    Ok(Table {
        path: path.to_path_buf(),
        sha256: sha256_hex(&bytes),
        format,
        columns,
        rows,
        decimal_comma,
    })
}

/// The first line of `body` that is not blank.
fn header_line(body: &[u8]) -> &[u8] {
    body.split(|&b| b == b'\n')
        .map(|l| l.strip_suffix(b"\r").unwrap_or(l))
        .find(|l| !l.iter().all(u8::is_ascii_whitespace))
        .unwrap_or_default()
}

/// The delimiter the header line holds outside quotes: `,`, `;` or tab,
/// a comma when it holds none of them (a one-column table).
fn sniff_delimiter(body: &[u8]) -> Result<u8, TableProblem> {
    let mut quoted = false;
    let mut found = Vec::new();
    for &b in header_line(body) {
        match b {
            b'"' => quoted = !quoted,
            b',' | b';' | b'\t' if !quoted && !found.contains(&b) => found.push(b),
            _ => {}
        }
    }
    match found.as_slice() {
        [] => Ok(b','),
        [one] => Ok(*one),
        several => Err(TableProblem::AmbiguousDelimiter {
            found: several
                .iter()
                .map(|&b| match b {
                    b'\t' => "tabs".to_string(),
                    b => format!("`{}`", b as char),
                })
                .collect::<Vec<_>>()
                .join(" and "),
        }),
    }
}

/// Whether the table's numbers are written with a decimal comma: some cell
/// (split on `sep`, which is not a comma) is digits, one comma, digits, and
/// none is a number with a point.
fn sniff_decimal_comma(body: &[u8], sep: u8) -> bool {
    let number = |cell: &[u8], mark: u8| {
        let cell = cell.trim_ascii();
        let cell = cell
            .strip_prefix(b"-")
            .or(cell.strip_prefix(b"+"))
            .unwrap_or(cell);
        let mut parts = cell.splitn(2, |&b| b == mark);
        let (int, frac) = (parts.next().unwrap_or_default(), parts.next());
        frac.is_some_and(|f| !f.is_empty() && f.iter().all(u8::is_ascii_digit))
            && int.iter().all(u8::is_ascii_digit)
    };
    let cells = || {
        body.split(|&b| b == b'\n')
            .skip(1)
            .flat_map(move |l| l.split(move |&b| b == sep))
    };
    cells().any(|c| number(c, b',')) && !cells().any(|c| number(c, b'.'))
}

/// A CSV table polars refused, in servoid's words where polars' would
/// advise one of its own options.
fn csv_problem(source: PolarsError, body: &[u8], sep: u8) -> TableProblem {
    if !source.to_string().contains("truncate_ragged_lines") {
        return TableProblem::Csv { source };
    }
    let header = header_line(body).split(|&b| b == sep).count();
    let fields = body
        .split(|&b| b == b'\n')
        .map(|l| l.split(|&b| b == sep).count())
        .max()
        .unwrap_or(header);
    TableProblem::Ragged {
        header,
        fields,
        delimiter: sep as char,
        hint: if sep == b',' {
            "; a table whose numbers have decimal commas is delimited by `;`: give [run_table] delimiter = \";\" (and decimal = \",\")"
        } else {
            ""
        },
    }
}

/// One row's (or column's) cells: text, or None where empty.
type Cells = Vec<Option<String>>;

/// The frame's column names and its rows of trimmed, non-empty text cells.
fn text_cells(df: &DataFrame) -> Result<(Vec<String>, Vec<Cells>), TableProblem> {
    let names: Vec<String> = df.columns().iter().map(|c| c.name().to_string()).collect();
    let mut rows = vec![Vec::with_capacity(names.len()); df.height()];
    for (name, col) in names.iter().zip(df.columns()) {
        let cells = column_text(name, col)?;
        for (row, cell) in rows.iter_mut().zip(cells) {
            row.push(cell.map(|s| s.trim().to_string()).filter(|s| !s.is_empty()));
        }
    }
    Ok((names, rows))
}

/// One column's cells as text. Floats are printed by Rust, whose shortest
/// round-trip form reads back to the same f64, so a number written to
/// Parquet is checked as the value it is.
fn column_text(name: &str, col: &polars::prelude::Column) -> Result<Cells, TableProblem> {
    let dtype = col.dtype();
    let not_text = || TableProblem::NotText {
        column: name.to_string(),
        dtype: Box::new(dtype.clone()),
    };
    if dtype.is_float() {
        let col = col.cast(&DataType::Float64).map_err(|_| not_text())?;
        let ca = col.f64().map_err(|_| not_text())?;
        return Ok(ca.iter().map(|v| v.map(|x| x.to_string())).collect());
    }
    // A timestamp (a `date` column written by pandas or a logger): ISO 8601
    // as the manifest's dates are written, `Z` for an instant in UTC (a
    // time zone's instants are stored in UTC). Polars' own text has a space
    // for the `T` and no zone.
    if let DataType::Datetime(unit, zone) = dtype {
        let physical = col.to_physical_repr();
        let ca = physical.i64().map_err(|_| not_text())?;
        return Ok(ca
            .iter()
            .map(|v| v.map(|v| iso_datetime(v, *unit, zone.is_some())))
            .collect());
    }
    let col = col.cast(&DataType::String).map_err(|_| not_text())?;
    let ca = col.str().map_err(|_| not_text())?;
    Ok(ca.iter().map(|v| v.map(str::to_string)).collect())
}

/// A timestamp as ISO 8601, `YYYY-MM-DDTHH:MM:SS` with the fraction only
/// when there is one, `Z` when `utc`; outside 1970-9999, the count and its
/// unit (which the date check then refuses by name).
fn iso_datetime(v: i64, unit: polars::prelude::TimeUnit, utc: bool) -> String {
    use polars::prelude::TimeUnit as Tu;
    use std::fmt::Write;
    use std::time::{Duration, UNIX_EPOCH};
    let per_s: i64 = match unit {
        Tu::Nanoseconds => 1_000_000_000,
        Tu::Microseconds => 1_000_000,
        Tu::Milliseconds => 1_000,
    };
    let (secs, sub) = (v.div_euclid(per_s), v.rem_euclid(per_s));
    let nanos = (sub * (1_000_000_000 / per_s)) as u32;
    let mut text = String::new();
    let written = (0..253_402_300_800).contains(&secs) && {
        let t = UNIX_EPOCH + Duration::new(secs as u64, nanos);
        let ts = if nanos == 0 {
            humantime::format_rfc3339_seconds(t)
        } else {
            humantime::format_rfc3339_nanos(t)
        };
        write!(text, "{ts}").is_ok()
    };
    if !written {
        return format!("{v} {unit} since 1970");
    }
    if !utc {
        text.pop();
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;
    use polars::prelude::{Column, DataFrame, ParquetWriter};

    fn cells(rows: &[&[Option<&str>]]) -> Vec<Vec<Option<String>>> {
        rows.iter()
            .map(|r| r.iter().map(|c| c.map(str::to_string)).collect())
            .collect()
    }

    #[test]
    fn csv_cells_are_text_as_written_and_empty_cells_are_none() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.csv");
        let text = "\u{feff}id,p_gain,date,note\nk1, 1.50 ,2024-05-01,\"a, b\"\n007,,,\n";
        std::fs::write(&path, text).unwrap();
        let t = read_table(&path, TableFormat::Csv).unwrap();
        assert_eq!(t.columns, ["id", "p_gain", "date", "note"]);
        assert_eq!(
            t.rows,
            cells(&[
                &[Some("k1"), Some("1.50"), Some("2024-05-01"), Some("a, b")],
                &[Some("007"), None, None, None],
            ])
        );
        assert_eq!(t.sha256, sha256_hex(text.as_bytes()));
        assert_eq!(t.column("date"), Some(2));
        assert_eq!(t.column("mass_kg"), None);
    }

    #[test]
    fn parquet_numbers_read_back_exactly_and_nulls_are_none() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.parquet");
        let mut df = DataFrame::new_infer_height(vec![
            Column::new("id".into(), ["a", "b"]),
            Column::new("k".into(), [Some(116640.0_f64), None]),
            Column::new("n".into(), [7_i64, -3]),
            Column::new("x".into(), [0.1_f64 + 0.2, 1e-9]),
        ])
        .unwrap();
        let mut file = std::fs::File::create(&path).unwrap();
        ParquetWriter::new(&mut file).finish(&mut df).unwrap();
        let t = read_table(&path, TableFormat::Parquet).unwrap();
        assert_eq!(t.columns, ["id", "k", "n", "x"]);
        assert_eq!(t.rows[0][1].as_deref(), Some("116640"));
        assert_eq!(t.rows[1][1], None);
        assert_eq!(t.rows[1][2].as_deref(), Some("-3"));
        let x: f64 = t.rows[0][3].as_deref().unwrap().parse().unwrap();
        assert_eq!(x.to_bits(), (0.1_f64 + 0.2).to_bits());
        assert_eq!(t.rows[1][3].as_deref(), Some("0.000000001"));
    }

    /// Dates, timestamps and decimals as pandas and loggers write them
    /// (refused as damaged or unreadable): dates and timestamps
    /// as ISO 8601 text, decimals as their digits. The expected texts are
    /// written by hand from the values.
    #[test]
    fn parquet_dates_timestamps_and_decimals_read_as_text() {
        use polars::prelude::{NamedFrom, Series, TimeUnit as Tu};
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.parquet");
        // 2024-05-01 is day 19844 since 1970-01-01; 09:30:00 is 34,200 s.
        let at = 19_844_i64 * 86_400 + 34_200;
        let date = Series::new("date".into(), [19_844_i32, 0])
            .cast(&DataType::Date)
            .unwrap();
        let naive = Series::new("naive".into(), [at * 1000, at * 1000 + 250])
            .cast(&DataType::Datetime(Tu::Milliseconds, None))
            .unwrap();
        let micro = Series::new("micro".into(), [at * 1_000_000, -1])
            .cast(&DataType::Datetime(Tu::Microseconds, None))
            .unwrap();
        let dec = Series::new("p_gain".into(), ["1.25", "100000.5"])
            .cast(&DataType::Decimal(9, 2))
            .unwrap();
        let mut df =
            DataFrame::new_infer_height(vec![date.into(), naive.into(), micro.into(), dec.into()])
                .unwrap();
        ParquetWriter::new(std::fs::File::create(&path).unwrap())
            .finish(&mut df)
            .unwrap();
        let t = read_table(&path, TableFormat::Parquet).unwrap();
        assert_eq!(
            t.rows,
            cells(&[
                &[
                    Some("2024-05-01"),
                    Some("2024-05-01T09:30:00"),
                    Some("2024-05-01T09:30:00"),
                    Some("1.25")
                ],
                &[
                    Some("1970-01-01"),
                    Some("2024-05-01T09:30:00.250000000"),
                    Some("-1 μs since 1970"),
                    Some("100000.50")
                ],
            ])
        );
        // An instant with a time zone is stored in UTC, and said so (a
        // table pyarrow writes with tz="UTC" or "Europe/Berlin").
        assert_eq!(
            iso_datetime(at * 1000, Tu::Milliseconds, true),
            "2024-05-01T09:30:00Z"
        );
        assert_eq!(
            iso_datetime(253_402_300_800_000, Tu::Milliseconds, false),
            "253402300800000 ms since 1970"
        );
    }

    #[test]
    fn unreadable_tables_name_the_file_and_the_cause() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("none.csv");
        let e = read_table(&missing, TableFormat::Csv).unwrap_err();
        assert!(matches!(e.problem, TableProblem::Io { .. }));
        assert!(
            e.to_string()
                .starts_with(&format!("{}: cannot read: ", missing.display()))
        );
        let fake = dir.path().join("fake.parquet");
        std::fs::write(&fake, "id,role\nk1,spring\n").unwrap();
        let e = read_table(&fake, TableFormat::Parquet).unwrap_err();
        assert!(matches!(e.problem, TableProblem::Parquet { .. }), "{e}");
        assert!(
            e.to_string().contains("not a readable Parquet table"),
            "{e}"
        );
    }

    #[test]
    fn formats_by_extension() {
        assert_eq!(
            TableFormat::from_path(Path::new("a/b.CSV")),
            Some(TableFormat::Csv)
        );
        assert_eq!(
            TableFormat::from_path(Path::new("b.pq")),
            Some(TableFormat::Parquet)
        );
        assert_eq!(
            TableFormat::from_path(Path::new("b.parquet")),
            Some(TableFormat::Parquet)
        );
        assert_eq!(TableFormat::from_path(Path::new("b.xlsx")), None);
        assert_eq!(TableFormat::from_path(Path::new("b")), None);
    }
}
