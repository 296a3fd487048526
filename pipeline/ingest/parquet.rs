//! Parquet logs, read by polars. Only the wanted columns are decoded; any
//! numeric column type is accepted and converted to f64. Places are 1-based
//! table rows.

use std::io::Cursor;
use std::path::Path;

use polars::prelude::{DataFrame, DataType, ParquetReader, SerReader};

use super::plan::{Column, LogPlan};
use super::{At, FormatProblem, IngestError, Raw, Wanted, list, raw_from_table, wanted};

/// What a damaged Parquet file declares that it does not hold: found by
/// servoid's checks before polars reads (and would reserve for) it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ParquetDamage {
    #[error("its footer declares {len} bytes of metadata in a file of {file} bytes")]
    MetadataLength { len: usize, file: usize },
    #[error(transparent)]
    FooterList(#[from] super::parquet_footer::OverlongList),
    #[error("polars failed reading its footer ({0})")]
    FooterPanicked(String),
    #[error("row group {group}, column {column}: {source}")]
    Column {
        group: usize,
        column: usize,
        #[source]
        source: Box<ParquetDamage>,
    },
    #[error(
        "its metadata puts {values} values in bytes {start} to {end} of a file of {file} bytes"
    )]
    ChunkRange {
        values: i64,
        start: u64,
        end: u64,
        file: usize,
    },
    #[error(
        "row group {group} declares {declared} rows where its columns hold at most {most} values"
    )]
    GroupRows {
        group: usize,
        declared: u64,
        most: i64,
    },
    #[error("its footer declares {declared} rows where its row groups hold {rows}")]
    FileRows { declared: i64, rows: u64 },
    /// The page header does not parse (the thrift parser's message).
    #[error("the page header at byte {pos} of its chunk does not read: {message}")]
    PageHeader { pos: usize, message: String },
    #[error(
        "a page at byte {pos} of its chunk declares {compressed} bytes (uncompressed {uncompressed}) where {room} remain"
    )]
    PageSize {
        pos: usize,
        compressed: i64,
        uncompressed: i32,
        room: i64,
    },
    #[error(
        "a page at byte {pos} of its chunk declares {what} {value} where its chunk has {values} values in {chunk} bytes"
    )]
    PageCount {
        pos: usize,
        what: &'static str,
        value: i32,
        values: i64,
        chunk: usize,
    },
    #[error("its chunk ends after pages of {seen} of its {values} values")]
    ChunkShort { seen: i64, values: i64 },
}

/// A Parquet log's column names.
pub(super) fn names(path: &Path, bytes: &[u8]) -> Result<Vec<String>, IngestError> {
    Ok(open(path, bytes)?.1)
}

/// A Parquet reader over a log's bytes.
type Reader<'a> = ParquetReader<Cursor<&'a [u8]>>;

/// The reader of a Parquet log, its footer checked, and its column names.
fn open<'a>(path: &Path, bytes: &'a [u8]) -> Result<(Reader<'a>, Vec<String>), IngestError> {
    let format = |problem| IngestError::format(path, problem);
    let mut reader = ParquetReader::new(Cursor::new(bytes));
    // A panic inside polars on damaged bytes (found by the Parquet fuzz
    // target) is reported as such, not a crash.
    let damaged =
        |p: super::ReaderPanic| format(FormatProblem::ParquetDamaged { message: p.message });
    check_footer(bytes).map_err(|source| format(FormatProblem::ParquetMetadata { source }))?;
    let schema = super::guard_reader(|| reader.schema())
        .map_err(damaged)?
        .map_err(|source| format(FormatProblem::ParquetUnreadable { source }))?;
    Ok((reader, schema.iter_names().map(|n| n.to_string()).collect()))
}

/// Read a Parquet log's wanted columns.
pub(super) fn read<'a>(
    path: &Path,
    bytes: &'a [u8],
    plan: &'a LogPlan,
) -> Result<Raw<'a>, IngestError> {
    let format = |problem| IngestError::format(path, problem);
    let damaged =
        |p: super::ReaderPanic| format(FormatProblem::ParquetDamaged { message: p.message });
    let (mut reader, names) = open(path, bytes)?;
    check_pages(bytes, &mut reader)
        .map_err(|source| format(FormatProblem::ParquetMetadata { source }))?;

    let want = wanted(plan);
    let index = column_indices(path, &want, &names)?;
    let mut projection = index.clone();
    projection.sort_unstable();
    projection.dedup();
    let df = super::guard_reader(|| reader.with_projection(Some(projection)).finish())
        .map_err(damaged)?
        .map_err(|source| format(FormatProblem::ParquetRead { source }))?;
    if df.height() == 0 {
        return Err(IngestError::HeaderOnly {
            path: path.to_path_buf(),
            what: "a schema but no rows".into(),
        });
    }
    let mut columns = Vec::with_capacity(want.len());
    for (w, &i) in want.iter().zip(&index) {
        columns.push(column_values(path, plan, w, &names[i], &df)?);
    }
    raw_from_table(path, plan, columns, Box::new(|i| At::Row(i + 1)))
}

/// Where each wanted column is among the file's `names`, by name or index.
fn column_indices(
    path: &Path,
    want: &[Wanted<'_>],
    names: &[String],
) -> Result<Vec<usize>, IngestError> {
    let mut index = Vec::with_capacity(want.len());
    for w in want {
        let found = match w.column {
            Column::Name(n) => names.iter().position(|c| c == n),
            Column::Index(i) => (*i < names.len()).then_some(*i),
        };
        index.push(found.ok_or_else(|| IngestError::MissingColumn {
            path: path.to_path_buf(),
            channel: w.channel,
            column: w.column.to_string(),
            available: format!(
                "{} columns, indices 0 to {}: {}",
                names.len(),
                names.len().saturating_sub(1),
                list(names.iter().map(|n| format!("`{n}`")))
            ),
        })?);
    }
    Ok(index)
}

/// The wanted column `w` (named `name` in the file) of `df` as f64: any
/// numeric type converted, a logger's timestamps as seconds since the
/// first, a null refused.
fn column_values(
    path: &Path,
    plan: &LogPlan,
    w: &Wanted<'_>,
    name: &str,
    df: &DataFrame,
) -> Result<Vec<f64>, IngestError> {
    let format = |problem| IngestError::format(path, problem);
    let col = df.column(name).map_err(|source| {
        format(FormatProblem::ColumnLost {
            column: name.to_string(),
            source,
        })
    })?;
    let elapsed;
    let col = match (w.channel, col.dtype(), &plan.channels.time) {
        // A logger's timestamps (`timestamp[us]`): the time channel is
        // the seconds since the first sample, in the channel's unit.
        ("time", DataType::Datetime(unit, _), super::plan::TimePlan::Column { to_s, .. }) => {
            elapsed = seconds_since_first(col, *unit, *to_s).ok_or_else(|| {
                format(FormatProblem::NotNumeric {
                    column: name.to_string(),
                    channel: w.channel,
                    dtype: Box::new(col.dtype().clone()),
                })
            })?;
            &elapsed
        }
        _ => col,
    };
    if !col.dtype().is_primitive_numeric() {
        return Err(format(FormatProblem::NotNumeric {
            column: name.to_string(),
            channel: w.channel,
            dtype: Box::new(col.dtype().clone()),
        }));
    }
    let not_f64 = |source| {
        format(FormatProblem::NotF64 {
            column: name.to_string(),
            source,
        })
    };
    let col = col.cast(&DataType::Float64).map_err(not_f64)?;
    let ca = col.f64().map_err(not_f64)?;
    if ca.null_count() > 0 {
        let row = ca.iter().position(|v| v.is_none()).expect("a null exists");
        return Err(IngestError::MissingValue {
            path: path.to_path_buf(),
            at: At::Row(row + 1),
            channel: w.channel,
            column: w.column.to_string(),
            detail: "null".into(),
        });
    }
    let mut v = Vec::with_capacity(ca.len());
    for chunk in ca.downcast_iter() {
        v.extend_from_slice(chunk.values());
    }
    Ok(v)
}

/// Checks a Parquet file's footer before polars reads it: every length its
/// thrift metadata declares (of a string, of a list) must fit in the bytes
/// left, and the metadata in the file. polars 0.55 reserves what a list
/// declares before reading it, so a damaged footer declaring 10^11
/// elements aborted the process on a failed allocation (found by the
/// Parquet fuzz target; `fuzz/regressions/log_parquet/`), which no error
/// handling can catch. A file without the Parquet magic is left to polars
/// to refuse. [`check_pages`] checks what the footer points to, once polars
/// has parsed it.
///
/// The footer is `metadata | u32 length (little-endian) | "PAR1"`, the
/// metadata a thrift struct in the compact protocol (Apache Thrift,
/// `doc/specs/thrift-compact-protocol.md`).
pub(super) fn check_footer(bytes: &[u8]) -> Result<(), ParquetDamage> {
    let n = bytes.len();
    if n < 12 || &bytes[n - 4..] != b"PAR1" {
        return Ok(());
    }
    let len = u32::from_le_bytes([bytes[n - 8], bytes[n - 7], bytes[n - 6], bytes[n - 5]]) as usize;
    if len > n - 12 {
        return Err(ParquetDamage::MetadataLength { len, file: n });
    }
    // The footer as polars' own decoder reads it (see `parquet_footer`):
    // a generic walk by wire types, which this replaced, does not always
    // read it as polars does.
    Ok(super::parquet_footer::check(&bytes[n - 8 - len..n - 8])?)
}

/// Checks, on the metadata as polars parsed it (`reader` over `bytes`),
/// what it declares before polars decodes any page:
/// - each column chunk lies in the file and holds a count of values >= 0;
///   a row group has no more rows than its fullest column has values
///   (equal for flat columns), the file no more than its groups;
/// - each page header, read by the parser polars uses
///   (`polars_parquet_format`) in the order polars reads them, declares
///   sizes and counts between 0 and what its chunk holds.
///
/// A page declaring a negative count reached polars' decoder as about
/// 2^64 values, for which it reserved a validity bitmap of 2^61 bytes and
/// aborted (`fuzz/regressions/*/page-*.parquet`). The checks read polars'
/// own parse of the footer, not a parse of ours beside it: the fuzzer found
/// footers that two thrift readers read differently (a field of the wrong
/// wire type is skipped by a generic reader and read as its declared type
/// by polars').
pub(super) fn check_pages(
    bytes: &[u8],
    reader: &mut ParquetReader<Cursor<&[u8]>>,
) -> Result<(), ParquetDamage> {
    let meta = match super::guard_reader(|| reader.get_metadata().cloned()) {
        Ok(Ok(meta)) => meta,
        // polars refuses the footer: the read that follows says why.
        Ok(Err(_)) => return Ok(()),
        Err(panic) => return Err(ParquetDamage::FooterPanicked(panic.message)),
    };
    let mut rows = 0u64;
    for (g, group) in meta.row_groups.iter().enumerate() {
        let mut most = 0i64;
        for (c, column) in group.parquet_columns().iter().enumerate() {
            let at = |e: ParquetDamage| ParquetDamage::Column {
                group: g,
                column: c,
                source: Box::new(e),
            };
            let values = column.num_values();
            let range = column.byte_range();
            if values < 0 || range.start > range.end || range.end > bytes.len() as u64 {
                return Err(at(ParquetDamage::ChunkRange {
                    values,
                    start: range.start,
                    end: range.end,
                    file: bytes.len(),
                }));
            }
            chunk_pages(&bytes[range.start as usize..range.end as usize], values).map_err(at)?;
            most = most.max(values);
        }
        let declared = group.num_rows() as u64;
        if declared > most as u64 {
            return Err(ParquetDamage::GroupRows {
                group: g,
                declared,
                most,
            });
        }
        rows += declared;
    }
    if meta.num_rows as u64 > rows {
        return Err(ParquetDamage::FileRows {
            declared: meta.num_rows as i64,
            rows,
        });
    }
    Ok(())
}

/// The page headers of one column chunk of `values` values, as polars'
/// page reader walks them: from the chunk's start, header after header,
/// until the data pages' counts reach `values`.
pub(super) fn chunk_pages(chunk: &[u8], values: i64) -> Result<(), ParquetDamage> {
    use polars_parquet_format::thrift::protocol::TCompactInputProtocol;
    use polars_parquet_format::{PageHeader, PageType};

    let mut pos = 0usize;
    let mut seen = 0i64;
    while seen < values {
        let left = chunk.len() - pos;
        let mut cursor = std::io::Cursor::new(&chunk[pos..]);
        // The same generated parser polars runs, bounded by the bytes left
        // (polars runs it unbounded): what reads here reads there, and
        // allocates no more than the chunk holds.
        let mut prot = TCompactInputProtocol::new(&mut cursor, left);
        let page = PageHeader::read_from_in_protocol(&mut prot).map_err(|e| {
            ParquetDamage::PageHeader {
                pos,
                message: e.to_string(),
            }
        })?;
        let header_len = cursor.position() as usize;
        let compressed = i64::from(page.compressed_page_size);
        let room = (left - header_len) as i64;
        if page.uncompressed_page_size < 0 || !(0..=room).contains(&compressed) {
            return Err(ParquetDamage::PageSize {
                pos,
                compressed,
                uncompressed: page.uncompressed_page_size,
                room,
            });
        }
        let bad = |what: &'static str, v: i32, most: i64| {
            (!(0..=most).contains(&i64::from(v))).then_some(ParquetDamage::PageCount {
                pos,
                what,
                value: v,
                values,
                chunk: chunk.len(),
            })
        };
        let mut problems = Vec::new();
        if let Some(h) = &page.data_page_header {
            problems.extend(bad("a count of", h.num_values, values));
        }
        if let Some(h) = &page.dictionary_page_header {
            problems.extend(bad("a dictionary of", h.num_values, values));
        }
        if let Some(h) = &page.data_page_header_v2 {
            problems.extend(bad("a count of", h.num_values, values));
            problems.extend(bad("a null count of", h.num_nulls, values));
            problems.extend(bad("a row count of", h.num_rows, values));
            problems.extend(bad(
                "levels of",
                h.definition_levels_byte_length,
                compressed,
            ));
            problems.extend(bad(
                "levels of",
                h.repetition_levels_byte_length,
                compressed,
            ));
        }
        if let Some(p) = problems.into_iter().next() {
            return Err(p);
        }
        // What polars counts towards the chunk's values (its
        // `get_page_num_values`).
        seen += i64::from(match page.type_ {
            PageType::DATA_PAGE => page.data_page_header.as_ref().map_or(0, |h| h.num_values),
            PageType::DATA_PAGE_V2 => page
                .data_page_header_v2
                .as_ref()
                .map_or(0, |h| h.num_values),
            _ => 0,
        });
        pos += header_len + compressed as usize;
        if pos >= chunk.len() && seen < values {
            return Err(ParquetDamage::ChunkShort { seen, values });
        }
    }
    Ok(())
}

/// A timestamp column as the time since its first value, divided by `to_s`
/// (the time channel's unit in seconds), so that the channel's own scaling
/// gives seconds. Exact to the timestamp's unit: the differences are taken
/// in integers. None when the column does not read as timestamps; a null
/// stays null (the caller names its row).
fn seconds_since_first(
    col: &polars::prelude::Column,
    unit: polars::prelude::TimeUnit,
    to_s: f64,
) -> Option<polars::prelude::Column> {
    use polars::prelude::TimeUnit as Tu;
    let tick = match unit {
        Tu::Nanoseconds => 1e-9,
        Tu::Microseconds => 1e-6,
        Tu::Milliseconds => 1e-3,
    };
    let physical = col.to_physical_repr();
    let ca = physical.i64().ok()?;
    let first = ca.iter().flatten().next()?;
    let values: Vec<Option<f64>> = ca
        .iter()
        .map(|v| v.map(|v| (v.wrapping_sub(first)) as f64 * tick / to_s))
        .collect();
    Some(polars::prelude::Column::new(col.name().clone(), values))
}
