//! A walk of a Parquet footer that reads it exactly as polars 0.55's own
//! decoder does (`polars-parquet`, `handwritten_thrift/file_metadata_thrift.rs`
//! and `parquet_thrift.rs`), to find the lists that decoder would reserve
//! memory for before reading them.
//!
//! polars reads each field it knows as the type parquet.thrift declares,
//! whatever its wire type, and sizes a `Vec` from a list's declared count
//! before reading the elements: one footer can make it reserve tens of
//! gigabytes and abort. This walk follows polars field by field and refuses
//! a list that declares more elements than bytes remain (`OverlongList`);
//! where polars would stop with an error, it stops and leaves the refusal
//! to polars. It mirrors polars-parquet 0.55.2: `Cargo.toml` pins it, a test
//! fails on another in Cargo.lock, and the fuzz targets replay footers the
//! two walks read differently. Why not a generic thrift walk:
//! docs/methods.md, "The Parquet footer".

/// A list in the footer that declares more elements than the footer has
/// bytes left: polars would reserve for all of them first.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("its footer declares {size} {what} where {left} bytes remain")]
pub struct OverlongList {
    pub size: i32,
    pub what: &'static str,
    pub left: usize,
}

/// Why the walk stopped early.
enum Stop {
    /// A list declares more elements than the footer has bytes left.
    Refuse(OverlongList),
    /// polars' decoder errs (or panics, which is caught) here, before it
    /// reserves anything more.
    PolarsErrs,
}

type Step<T = ()> = Result<T, Stop>;

/// polars' `FieldType`: the wire types a field header may carry.
const STOP: u8 = 0;
const BOOL_TRUE: u8 = 1;
const BOOL_FALSE: u8 = 2;
const LIST: u8 = 9;
const SET: u8 = 10;
const MAP: u8 = 11;
const STRUCT: u8 = 12;

/// Refuse what polars would over-reserve for in the footer's metadata
/// `meta`; Ok where polars reads it or refuses it without reserving more.
pub(super) fn check(meta: &[u8]) -> Result<(), OverlongList> {
    let mut w = Walk { buf: meta, pos: 0 };
    match w.file_metadata() {
        Ok(()) | Err(Stop::PolarsErrs) => Ok(()),
        Err(Stop::Refuse(why)) => Err(why),
    }
}

struct Walk<'a> {
    buf: &'a [u8],
    pos: usize,
}

/// One field header: its id, wire type and, for a boolean, its value.
struct Field {
    id: i16,
    ty: u8,
    bool_val: Option<bool>,
}

impl Walk<'_> {
    fn left(&self) -> usize {
        self.buf.len() - self.pos
    }

    fn byte(&mut self) -> Step<u8> {
        let b = *self.buf.get(self.pos).ok_or(Stop::PolarsErrs)?;
        self.pos += 1;
        Ok(b)
    }

    /// `read_vlq`: no limit on its length, as in polars.
    fn vlq(&mut self) -> Step<u64> {
        let mut v = 0u64;
        let mut shift = 0u32;
        loop {
            let b = self.byte()?;
            v |= u64::from(b & 0x7f).wrapping_shl(shift);
            if b & 0x80 == 0 {
                return Ok(v);
            }
            shift += 7;
        }
    }

    fn zigzag(&mut self) -> Step<i64> {
        let v = self.vlq()?;
        Ok((v >> 1) as i64 ^ -((v & 1) as i64))
    }

    fn skip_vlq(&mut self) -> Step {
        while self.byte()? & 0x80 != 0 {}
        Ok(())
    }

    fn skip_bytes(&mut self, n: usize) -> Step {
        if n > self.left() {
            return Err(Stop::PolarsErrs);
        }
        self.pos += n;
        Ok(())
    }

    fn skip_binary(&mut self) -> Step {
        let n = self.vlq()? as usize;
        self.skip_bytes(n)
    }

    /// `read_string`: the bytes, which must be UTF-8.
    fn string(&mut self) -> Step {
        let n = self.vlq()? as usize;
        let start = self.pos;
        self.skip_bytes(n)?;
        std::str::from_utf8(&self.buf[start..start + n]).map_err(|_| Stop::PolarsErrs)?;
        Ok(())
    }

    /// `read_list_begin`: the element type (checked as polars checks it)
    /// and the declared count.
    fn list_begin(&mut self) -> Step<(u8, i32)> {
        let header = self.byte()?;
        let count = header >> 4;
        let ty = match header & 0x0f {
            // fastparquet's empty list, a bare 0x00.
            0 if count == 0 => 3,
            n @ 1..=12 => n,
            _ => return Err(Stop::PolarsErrs),
        };
        let size = if count != 15 {
            i32::from(count)
        } else {
            self.vlq()? as i32
        };
        Ok((ty, size))
    }

    /// `read_list` of structs: polars reserves the declared count first.
    fn list(&mut self, what: &'static str, mut element: impl FnMut(&mut Self) -> Step) -> Step {
        let (_, size) = self.list_begin()?;
        if size.max(0) as usize > self.left() {
            return Err(Stop::Refuse(OverlongList {
                size,
                what,
                left: self.left(),
            }));
        }
        for _ in 0..size {
            element(self)?;
        }
        Ok(())
    }

    /// `read_field_begin`; None at the stop byte.
    fn field(&mut self, last: i16) -> Step<Option<Field>> {
        let header = self.byte()?;
        let delta = header >> 4;
        let ty = header & 0x0f;
        if ty > STRUCT {
            return Err(Stop::PolarsErrs);
        }
        if ty == STOP {
            return Ok(None);
        }
        let bool_val = match ty {
            BOOL_TRUE => Some(true),
            BOOL_FALSE => Some(false),
            _ => None,
        };
        let id = if delta != 0 {
            last.checked_add(i16::from(delta)).ok_or(Stop::PolarsErrs)?
        } else {
            self.zigzag()? as i16
        };
        Ok(Some(Field { id, ty, bool_val }))
    }

    /// `read_struct_fields!`: each field to `arm`, which returns false for
    /// an id it does not know (then skipped by its wire type).
    fn fields(&mut self, mut arm: impl FnMut(&mut Self, &Field) -> Step<bool>) -> Step {
        let mut last = 0i16;
        while let Some(f) = self.field(last)? {
            if !arm(self, &f)? {
                self.skip(f.ty, 64)?;
            }
            last = f.id;
        }
        Ok(())
    }

    /// `skip_till_depth`.
    fn skip(&mut self, ty: u8, depth: i8) -> Step {
        if depth == 0 {
            return Err(Stop::PolarsErrs);
        }
        match ty {
            BOOL_TRUE | BOOL_FALSE => Ok(()),
            3 => self.byte().map(|_| ()),
            4..=6 => self.skip_vlq(),
            7 => self.skip_bytes(8),
            8 => self.skip_binary(),
            STRUCT => {
                let mut last = 0i16;
                while let Some(f) = self.field(last)? {
                    self.skip(f.ty, depth - 1)?;
                    last = f.id;
                }
                Ok(())
            }
            LIST => {
                let (elem, size) = self.list_begin()?;
                for _ in 0..size {
                    // An element type converts to a field type as in
                    // polars: a boolean element as BooleanTrue (no bytes),
                    // sets and maps not at all.
                    let as_field = match elem {
                        1 | 2 => BOOL_TRUE,
                        SET | MAP => return Err(Stop::PolarsErrs),
                        t => t,
                    };
                    self.skip(as_field, depth - 1)?;
                }
                Ok(())
            }
            _ => Err(Stop::PolarsErrs),
        }
    }

    /// A boolean field polars reads from its header (`bool_val.expect`,
    /// which panics otherwise).
    fn flag(f: &Field) -> Step<bool> {
        f.bool_val.map(|_| true).ok_or(Stop::PolarsErrs)
    }

    fn int(&mut self) -> Step<bool> {
        self.zigzag().map(|_| true)
    }

    fn file_metadata(&mut self) -> Step {
        self.fields(|w, f| match f.id {
            1 | 3 => w.int(),
            2 => w
                .list("schema elements", Self::schema_element)
                .map(|_| true),
            4 => w.list("row groups", Self::row_group).map(|_| true),
            5 => w.list("key-value pairs", Self::key_value).map(|_| true),
            6 => w.string().map(|_| true),
            7 => w.list("column orders", Self::column_order).map(|_| true),
            _ => Ok(false),
        })
    }

    fn schema_element(&mut self) -> Step {
        self.fields(|w, f| match f.id {
            1..=3 | 5..=9 => w.int(),
            4 => w.string().map(|_| true),
            10 => w.logical_type().map(|_| true),
            _ => Ok(false),
        })
    }

    fn row_group(&mut self) -> Step {
        self.fields(|w, f| match f.id {
            1 => w.list("column chunks", Self::column_chunk).map(|_| true),
            2 | 3 => w.int(),
            4 => w
                .list("sorting columns", Self::sorting_column)
                .map(|_| true),
            5..=7 => w.skip_vlq().map(|_| true),
            _ => Ok(false),
        })
    }

    fn column_chunk(&mut self) -> Step {
        self.fields(|w, f| match f.id {
            1 => w.skip_binary().map(|_| true),
            2 => w.skip_vlq().map(|_| true),
            3 => w.column_meta_data().map(|_| true),
            4..=7 => w.int(),
            _ => Ok(false),
        })
    }

    fn column_meta_data(&mut self) -> Step {
        self.fields(|w, f| match f.id {
            1 => w.skip_vlq().map(|_| true),
            2 => {
                let (_, size) = w.list_begin()?;
                for _ in 0..size.max(0) {
                    w.skip_vlq()?;
                }
                Ok(true)
            }
            3 => {
                let (_, size) = w.list_begin()?;
                for _ in 0..size.max(0) {
                    w.skip_binary()?;
                }
                Ok(true)
            }
            4..=7 | 9..=11 | 14 | 15 => w.int(),
            12 => w.statistics().map(|_| true),
            _ => Ok(false),
        })
    }

    fn statistics(&mut self) -> Step {
        self.fields(|w, f| match f.id {
            1 | 2 => w.skip_binary().map(|_| true),
            3 | 4 => w.int(),
            // The length is read as a u32 before the bytes are skipped.
            5 | 6 => {
                let n = w.vlq()? as u32;
                w.skip_bytes(n as usize).map(|_| true)
            }
            7 | 8 => Self::flag(f),
            _ => Ok(false),
        })
    }

    fn key_value(&mut self) -> Step {
        self.fields(|w, f| match f.id {
            1 | 2 => w.string().map(|_| true),
            _ => Ok(false),
        })
    }

    fn sorting_column(&mut self) -> Step {
        self.fields(|w, f| match f.id {
            1 => w.int(),
            2 | 3 => Self::flag(f),
            _ => Ok(false),
        })
    }

    fn column_order(&mut self) -> Step {
        self.fields(|w, f| match f.id {
            1 | 2 => w.empty_struct().map(|_| true),
            _ => Ok(false),
        })
    }

    /// `read_empty_struct`: every field skipped by its wire type.
    fn empty_struct(&mut self) -> Step {
        self.fields(|_, _| Ok(false))
    }

    fn logical_type(&mut self) -> Step {
        self.fields(|w, f| match f.id {
            1..=4 | 6 | 11..=15 => w.empty_struct().map(|_| true),
            5 => w
                .fields(|w, f| match f.id {
                    1 | 2 => w.int(),
                    _ => Ok(false),
                })
                .map(|_| true),
            7 | 8 => w
                .fields(|w, f| match f.id {
                    1 => Self::flag(f),
                    2 => w.time_unit().map(|_| true),
                    _ => Ok(false),
                })
                .map(|_| true),
            10 => w
                .fields(|w, f| match f.id {
                    1 => w.byte().map(|_| true),
                    2 => Self::flag(f),
                    _ => Ok(false),
                })
                .map(|_| true),
            _ => Ok(false),
        })
    }

    fn time_unit(&mut self) -> Step {
        self.fields(|w, f| match f.id {
            1..=3 => w.empty_struct().map(|_| true),
            _ => Ok(false),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_field_of_another_wire_type_is_read_as_polars_reads_it() {
        // FileMetaData: field 1 (delta 1) with the wire type of a boolean
        // (0x11), which polars reads as an i32 varint anyway: the next
        // byte, 0x00. Then field 4 (delta 3, wire type i32: 0x35), read as
        // a list: header 0xFC (count 15, a varint follows; structs), count
        // 2^31 - 1. A walk by wire types reads 0x00 as the stop byte and
        // sees nothing.
        let meta = [0x11, 0x00, 0x35, 0xFC, 0xFF, 0xFF, 0xFF, 0xFF, 0x07, 0x00];
        assert_eq!(
            check(&meta).map_err(|e| e.to_string()),
            Err("its footer declares 2147483647 row groups where 1 bytes remain".into())
        );
        // The same footer with a list of one row group with no fields.
        let meta = [0x11, 0x00, 0x35, 0x1C, 0x00, 0x00];
        assert_eq!(check(&meta), Ok(()));
    }

    #[test]
    fn where_polars_errs_the_walk_leaves_the_refusal_to_polars() {
        // Wire type 13 does not exist; an unterminated struct ends early.
        assert_eq!(check(&[0x1D]), Ok(()));
        assert_eq!(check(&[0x15]), Ok(()));
    }

    /// Cargo.lock holds the polars-parquet this walk mirrors, and no other:
    /// an upgrade of polars fails here until the walk is checked against
    /// the new decoder and the constant moved.
    #[test]
    fn cargo_lock_holds_the_polars_the_walk_mirrors() {
        let lock = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/Cargo.lock"))
            .expect("Cargo.lock beside Cargo.toml");
        let versions: Vec<&str> = lock
            .split("[[package]]")
            .filter(|p| p.contains("\nname = \"polars-parquet\"\n"))
            .filter_map(|p| p.lines().find_map(|l| l.strip_prefix("version = ")))
            .map(|v| v.trim_matches('"'))
            .collect();
        assert_eq!(versions, vec!["0.55.2"], "{versions:?}");
    }
}
