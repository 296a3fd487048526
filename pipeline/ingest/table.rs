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
    #[error("a damaged Parquet table: {message}")]
    Metadata { message: String },
    /// The reader failed inside polars on damaged bytes.
    #[error("a damaged {format} table: polars failed reading it ({message})")]
    Damaged {
        format: &'static str,
        message: String,
    },
    /// A Parquet column of a type that has no text form (a list, a struct).
    #[error("column `{column}` holds {dtype}, which cannot be read as text")]
    NotText {
        column: String,
        /// Boxed, as in [`super::FormatProblem::NotNumeric`].
        dtype: Box<DataType>,
    },
}

/// Read a side table: every column, every cell as text.
///
/// CSV cells are taken as written (polars reads every column as text, so
/// `007` stays `007`); Parquet numbers are printed in the shortest form that
/// reads back to the same value, integers in full.
pub fn read_table(path: &Path, format: TableFormat) -> Result<Table, TableError> {
    let bytes = std::fs::read(path).map_err(|source| TableError {
        path: path.to_path_buf(),
        problem: TableProblem::Io { source },
    })?;
    table_from_bytes(path, bytes, format)
}

/// [`read_table`] of bytes already read (`path` names them in errors).
pub fn table_from_bytes(
    path: &Path,
    bytes: Vec<u8>,
    format: TableFormat,
) -> Result<Table, TableError> {
    let fail = |problem| TableError {
        path: path.to_path_buf(),
        problem,
    };
    let read = || match format {
        TableFormat::Csv => {
            // A UTF-8 byte-order mark is not part of the first column's name.
            let text = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(&bytes);
            CsvReadOptions::default()
                .with_has_header(true)
                // No inference: every column is text, read as written.
                .with_infer_schema_length(Some(0))
                .with_raise_if_empty(false)
                .into_reader_with_file_handle(Cursor::new(text))
                .finish()
                .map_err(|source| fail(TableProblem::Csv { source }))
        }
        TableFormat::Parquet => {
            let mut reader = ParquetReader::new(Cursor::new(bytes.as_slice()));
            super::parquet::check_pages(&bytes, &mut reader)
                .map_err(|message| fail(TableProblem::Metadata { message }))?;
            reader
                .finish()
                .map_err(|source| fail(TableProblem::Parquet { source }))
        }
    };
    // A panic inside polars on damaged bytes is the table's problem, not a
    // crash (found by the run-table fuzz target).
    if format == TableFormat::Parquet {
        super::parquet::check_footer(&bytes)
            .map_err(|message| fail(TableProblem::Metadata { message }))?;
    }
    let df = super::off_pool(|| super::guard_polars(read)).map_err(|message| {
        fail(TableProblem::Damaged {
            format: match format {
                TableFormat::Csv => "CSV",
                TableFormat::Parquet => "Parquet",
            },
            message,
        })
    })??;
    let (columns, rows) = text_cells(&df).map_err(fail)?;
    Ok(Table {
        path: path.to_path_buf(),
        sha256: sha256_hex(&bytes),
        format,
        columns,
        rows,
    })
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
    let col = col.cast(&DataType::String).map_err(|_| not_text())?;
    let ca = col.str().map_err(|_| not_text())?;
    Ok(ca.iter().map(|v| v.map(str::to_string)).collect())
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
