//! Parquet logs, read by polars. Only the wanted columns are decoded; any
//! numeric column type is accepted and converted to f64. Places are 1-based
//! table rows.

use std::io::Cursor;
use std::path::Path;

use polars::prelude::{DataType, ParquetReader, SerReader};

use super::plan::{Column, LogPlan};
use super::{At, FormatProblem, IngestError, Raw, list, raw_from_table, wanted};

/// Read a Parquet log's wanted columns.
pub(super) fn read<'a>(
    path: &Path,
    bytes: &'a [u8],
    plan: &'a LogPlan,
) -> Result<Raw<'a>, IngestError> {
    let format = |problem| IngestError::format(path, problem);
    let mut reader = ParquetReader::new(Cursor::new(bytes));
    // A panic inside polars on damaged bytes (found by the Parquet fuzz
    // target) is reported as such, not a crash.
    let damaged = |message| format(FormatProblem::ParquetDamaged { message });
    check_footer(bytes).map_err(|message| format(FormatProblem::ParquetMetadata { message }))?;
    let schema = super::guard_polars(|| reader.schema())
        .map_err(damaged)?
        .map_err(|source| format(FormatProblem::ParquetUnreadable { source }))?;
    let names: Vec<String> = schema.iter_names().map(|n| n.to_string()).collect();

    let want = wanted(plan);
    let mut index = Vec::with_capacity(want.len());
    for w in &want {
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
    let mut projection = index.clone();
    projection.sort_unstable();
    projection.dedup();
    let df = super::guard_polars(|| reader.with_projection(Some(projection)).finish())
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
        let name = &names[i];
        let col = df.column(name).map_err(|source| {
            format(FormatProblem::ColumnLost {
                column: name.clone(),
                source,
            })
        })?;
        if !col.dtype().is_primitive_numeric() {
            return Err(format(FormatProblem::NotNumeric {
                column: name.clone(),
                channel: w.channel,
                dtype: Box::new(col.dtype().clone()),
            }));
        }
        let not_f64 = |source| {
            format(FormatProblem::NotF64 {
                column: name.clone(),
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
        columns.push(v);
    }
    raw_from_table(path, plan, columns, Box::new(|i| At::Row(i + 1)))
}

/// Checks a Parquet file's footer, and the page headers it points to,
/// before polars reads them.
///
/// - Every length the footer's thrift metadata declares (of a string, of a
///   list) must fit in the bytes left, and the metadata in the file. polars
///   0.55 reserves what a list declares before reading it, so a damaged
///   footer declaring 10^11 elements aborted the process on a failed
///   allocation (found by the Parquet fuzz target;
///   `fuzz/regressions/log_parquet/`), which no error handling can catch.
/// - Each column chunk's pages must lie in the file, and each page header
///   must declare sizes and value counts between 0 and what its chunk
///   holds. A page declaring a negative count reached polars as about
///   2^64 values, for which it reserved a validity bitmap of 2^61 bytes
///   (`fuzz/regressions/*/page-validity-count-alloc.parquet`).
///
/// A file without the Parquet magic is left to polars to refuse. The
/// footer is `metadata | u32 length (little-endian) | "PAR1"`, the metadata
/// a thrift struct (`FileMetaData`, `PageHeader`: parquet-format's
/// `parquet.thrift`) in the compact protocol (Apache Thrift,
/// `doc/specs/thrift-compact-protocol.md`).
pub(super) fn check_footer(bytes: &[u8]) -> Result<(), String> {
    let n = bytes.len();
    if n < 12 || &bytes[n - 4..] != b"PAR1" {
        return Ok(());
    }
    let len = u32::from_le_bytes([bytes[n - 8], bytes[n - 7], bytes[n - 6], bytes[n - 5]]) as usize;
    if len > n - 12 {
        return Err(format!(
            "its footer declares {len} bytes of metadata in a file of {n} bytes"
        ));
    }
    let mut r = Thrift {
        bytes: &bytes[n - 8 - len..n - 8],
        pos: 0,
        what: "its footer",
    };
    let meta = r.fields(0)?;
    let int = |fields: &[(i16, Tv)], id| match field(fields, id) {
        Some(Tv::Int(v)) => *v,
        _ => 0,
    };
    // FileMetaData: 3 num_rows, 4 row_groups; RowGroup: 1 columns, 3
    // num_rows; ColumnChunk: 3 meta_data (ColumnMetaData: 5 num_values).
    // A row group has no more rows than its fullest column has values
    // (equal for flat columns), and the file no more than its groups.
    let mut rows = 0i64;
    for (g, group) in structs(field(&meta, 4)).enumerate() {
        let mut most = 0i64;
        for (c, chunk) in structs(field(group, 1)).enumerate() {
            if let Some(Tv::Struct(cm)) = field(chunk, 3) {
                check_pages(bytes, n - 8 - len, cm)
                    .map_err(|e| format!("row group {g}, column {c}: {e}"))?;
                most = most.max(int(cm, 5));
            }
        }
        let declared = int(group, 3);
        if !(0..=most).contains(&declared) {
            return Err(format!(
                "row group {g} declares {declared} rows where its columns hold at most {most} values"
            ));
        }
        rows = rows.saturating_add(declared);
    }
    let declared = int(&meta, 3);
    if !(0..=rows).contains(&declared) {
        return Err(format!(
            "its footer declares {declared} rows where its row groups hold {rows}"
        ));
    }
    Ok(())
}

/// The page headers of one column chunk (`ColumnMetaData` `cm`: 5
/// num_values, 7 total_compressed_size, 9 data_page_offset, 11
/// dictionary_page_offset), in the file's first `end` bytes.
fn check_pages(bytes: &[u8], end: usize, cm: &[(i16, Tv)]) -> Result<(), String> {
    let int = |id| match field(cm, id) {
        Some(Tv::Int(v)) => Some(*v),
        _ => None,
    };
    let (Some(values), Some(size), Some(data)) = (int(5), int(7), int(9)) else {
        return Ok(());
    };
    // Some writers put 0 for "no dictionary page": a page starts after the
    // leading magic or not at all.
    let start = int(11).filter(|d| (4..data).contains(d)).unwrap_or(data);
    if values < 0 || size < 0 || start < 0 || start.saturating_add(size) > end as i64 {
        return Err(format!(
            "its metadata puts {values} values in bytes {start} to {} of a file of {end} bytes of data",
            start.saturating_add(size)
        ));
    }
    let (mut pos, stop) = (start as usize, (start + size) as usize);
    let mut seen = 0i64;
    while pos < stop && seen < values {
        let mut r = Thrift {
            bytes: &bytes[pos..stop],
            pos: 0,
            what: "a page header",
        };
        let page = r.fields(0)?;
        let at = |id| match field(&page, id) {
            Some(Tv::Int(v)) => *v,
            _ => 0,
        };
        let compressed = at(3);
        if at(2) < 0 || !(0..=(stop - pos - r.pos) as i64).contains(&compressed) {
            return Err(format!(
                "a page at byte {pos} declares {compressed} bytes (uncompressed {}) where {} remain in its column",
                at(2),
                stop - pos - r.pos
            ));
        }
        // DataPageHeader (5), DictionaryPageHeader (7) and DataPageHeaderV2
        // (8) each start with num_values; v2 adds num_nulls (2), num_rows
        // (3) and its levels' byte lengths (5, 6).
        for (kind, counts) in [(5, &[1][..]), (7, &[1]), (8, &[1, 2, 3, 5, 6])] {
            let Some(Tv::Struct(h)) = field(&page, kind) else {
                continue;
            };
            for id in counts {
                let v = match field(h, *id) {
                    Some(Tv::Int(v)) => *v,
                    _ => 0,
                };
                let most = if *id >= 5 { compressed } else { values };
                if !(0..=most).contains(&v) {
                    return Err(format!(
                        "a page at byte {pos} declares a count of {v} where its column has {values} values in {size} bytes"
                    ));
                }
            }
            if kind != 7 {
                seen = seen.saturating_add(match field(h, 1) {
                    Some(Tv::Int(v)) => *v,
                    _ => 0,
                });
            }
        }
        pos += r.pos + compressed as usize;
    }
    Ok(())
}

/// A thrift value as far as the checks need it.
enum Tv {
    Int(i64),
    Struct(Vec<(i16, Tv)>),
    List(Vec<Tv>),
    /// Strings, doubles, booleans and maps: checked and skipped.
    Other,
}

/// The value of field `id` in a struct's fields, if present.
fn field(fields: &[(i16, Tv)], id: i16) -> Option<&Tv> {
    fields.iter().find(|(i, _)| *i == id).map(|(_, v)| v)
}

/// The structs of a list value (none when it is not one).
fn structs(v: Option<&Tv>) -> impl Iterator<Item = &[(i16, Tv)]> {
    let items: &[Tv] = match v {
        Some(Tv::List(items)) => items,
        _ => &[],
    };
    items.iter().filter_map(|t| match t {
        Tv::Struct(f) => Some(f.as_slice()),
        _ => None,
    })
}

/// A reader of the thrift compact protocol that checks every declared
/// length against the bytes left.
struct Thrift<'a> {
    bytes: &'a [u8],
    pos: usize,
    /// What is read, for messages: "its footer", "a page header".
    what: &'static str,
}

/// Deeper nesting than Parquet's metadata has is damage (and would exhaust
/// the stack).
const MAX_THRIFT_DEPTH: usize = 32;

impl Thrift<'_> {
    fn left(&self) -> usize {
        self.bytes.len() - self.pos
    }

    fn byte(&mut self) -> Result<u8, String> {
        let b = *self
            .bytes
            .get(self.pos)
            .ok_or_else(|| format!("{}'s metadata ends early", self.what))?;
        self.pos += 1;
        Ok(b)
    }

    fn varint(&mut self) -> Result<u64, String> {
        let mut value = 0u64;
        for shift in (0..64).step_by(7) {
            let b = self.byte()?;
            value |= u64::from(b & 0x7f) << shift;
            if b & 0x80 == 0 {
                return Ok(value);
            }
        }
        Err(format!("{} holds a varint longer than 64 bits", self.what))
    }

    /// A zigzag-encoded integer (i16, i32, i64).
    fn int(&mut self) -> Result<i64, String> {
        let v = self.varint()?;
        Ok((v >> 1) as i64 ^ -((v & 1) as i64))
    }

    fn advance(&mut self, n: u64, what: &str) -> Result<(), String> {
        if n > self.left() as u64 {
            return Err(format!(
                "{} declares {what} of {n} bytes where {} remain",
                self.what,
                self.left()
            ));
        }
        self.pos += n as usize;
        Ok(())
    }

    /// A struct's fields, up to its stop byte.
    fn fields(&mut self, depth: usize) -> Result<Vec<(i16, Tv)>, String> {
        if depth > MAX_THRIFT_DEPTH {
            return Err(format!("{}'s metadata is nested too deep", self.what));
        }
        let mut fields = Vec::new();
        let mut id: i16 = 0;
        loop {
            let header = self.byte()?;
            if header == 0 {
                return Ok(fields);
            }
            id = match header >> 4 {
                // A long-form field id (zigzag i16) follows.
                0 => self.int()? as i16,
                delta => id.wrapping_add(i16::from(delta)),
            };
            // A field's booleans are in its header (types 1 and 2).
            let value = match header & 0x0f {
                1 | 2 => Tv::Other,
                ty => self.value(ty, depth)?,
            };
            fields.push((id, value));
        }
    }

    /// A value of compact type `ty` (booleans as a byte, as in lists).
    fn value(&mut self, ty: u8, depth: usize) -> Result<Tv, String> {
        Ok(match ty {
            1..=3 => {
                self.byte()?;
                Tv::Other
            }
            4..=6 => Tv::Int(self.int()?),
            7 => {
                self.advance(8, "a double")?;
                Tv::Other
            }
            8 => {
                let len = self.varint()?;
                self.advance(len, "a string")?;
                Tv::Other
            }
            9 | 10 => {
                let header = self.byte()?;
                let mut size = u64::from(header >> 4);
                if size == 15 {
                    size = self.varint()?;
                }
                // Every element takes at least a byte.
                if size > self.left() as u64 {
                    return Err(format!(
                        "{} declares a list of {size} elements where {} bytes remain",
                        self.what,
                        self.left()
                    ));
                }
                let items = (0..size)
                    .map(|_| self.value(header & 0x0f, depth + 1))
                    .collect::<Result<_, _>>()?;
                Tv::List(items)
            }
            11 => {
                let size = self.varint()?;
                if size == 0 {
                    return Ok(Tv::Other);
                }
                let types = self.byte()?;
                if size > self.left() as u64 {
                    return Err(format!(
                        "{} declares a map of {size} entries where {} bytes remain",
                        self.what,
                        self.left()
                    ));
                }
                for _ in 0..size {
                    self.value(types >> 4, depth + 1)?;
                    self.value(types & 0x0f, depth + 1)?;
                }
                Tv::Other
            }
            12 => Tv::Struct(self.fields(depth + 1)?),
            other => {
                return Err(format!(
                    "{}'s metadata has an unknown thrift type {other}",
                    self.what
                ));
            }
        })
    }
}
