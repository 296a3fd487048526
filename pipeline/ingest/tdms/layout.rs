//! Where each channel's values lie in a TDMS file, found by walking its
//! segments as NI documents them ("TDMS File Format Internal Structure"):
//! each a 28-byte lead-in (tag `TDSm`, table of contents, version, the
//! segment's and its metadata's lengths), an object list (paths, raw-data
//! indices, properties) and raw data, in chunks that hold every listed
//! object's values in turn.
//!
//! A string, boolean or timestamp channel is passed over, and named when
//! asked for; a last segment cut short gives what its whole chunks hold,
//! with a warning; a count the segment cannot hold names the channel and
//! the bytes. Every offset is checked against the file before it is used:
//! a damaged file is an error in words, never a panic or an allocation it
//! declares. Why not a crate: docs/methods.md, "TDMS segments".

use std::collections::HashMap;

/// The file's channels, in the order they first appear, and what was left
/// out at its end.
pub(super) struct Layout {
    pub channels: Vec<Channel>,
    /// The recording's end as the file has it, when it was cut short.
    pub dropped: Option<String>,
}

/// One channel (`/'group'/'channel'`) with where its values lie.
pub(super) struct Channel {
    pub group: String,
    pub name: String,
    /// Its TDMS data type, when any segment gives it values.
    pub dtype: Option<u32>,
    /// Its values in file order: runs of `count` values `stride` bytes
    /// apart (stride is the value's size unless the data are interleaved).
    pub pieces: Vec<Piece>,
    pub len: usize,
    /// `wf_increment`: a waveform's sample interval, s.
    pub increment: Option<f64>,
    /// `unit_string`.
    pub unit: Option<String>,
}

#[derive(Debug, Clone, Copy)]
pub(super) struct Piece {
    pub start: usize,
    pub count: usize,
    pub stride: usize,
    pub big_endian: bool,
}

const LEAD_IN: usize = 28;
const TOC_META_DATA: u32 = 1 << 1;
const TOC_NEW_OBJ_LIST: u32 = 1 << 2;
const TOC_RAW_DATA: u32 = 1 << 3;
const TOC_INTERLEAVED: u32 = 1 << 5;
const TOC_BIG_ENDIAN: u32 = 1 << 6;
const TOC_DAQMX: u32 = 1 << 7;
const STRING: u32 = 0x20;

/// A data type's size in bytes, for those with a fixed size.
fn size_of(dtype: u32) -> Option<usize> {
    Some(match dtype {
        1 | 5 | 0x21 => 1,
        2 | 6 => 2,
        3 | 7 | 9 | 0x19 => 4,
        4 | 8 | 10 | 0x1A | 0x0008_000C => 8,
        11 | 0x1B | 0x44 | 0x0010_000D => 16,
        _ => return None,
    })
}

/// What a channel of a type that holds no real numbers holds, in words;
/// None for the numeric types.
pub(super) fn not_numeric(dtype: u32) -> Option<String> {
    Some(match dtype {
        1..=10 | 0x19 | 0x1A => return None,
        STRING => "a string channel".into(),
        0x21 => "a boolean channel".into(),
        0x44 => "a timestamp channel".into(),
        0x0008_000C | 0x0010_000D => "a complex channel (a log channel must be real)".into(),
        11 | 0x1B => "an 80-bit extended-float channel, which servoid does not read".into(),
        t => format!("a channel of TDMS data type {t:#x}, which servoid does not read"),
    })
}

/// Value `i` of `piece` (of type `dtype`) as f64, or None where the bytes
/// are not there.
pub(super) fn value(bytes: &[u8], dtype: u32, piece: &Piece, i: usize) -> Option<f64> {
    let size = size_of(dtype)?;
    let at = piece.start.checked_add(i.checked_mul(piece.stride)?)?;
    let b = bytes.get(at..at.checked_add(size)?)?;
    macro_rules! num {
        ($t:ty) => {{
            let a = b.try_into().ok()?;
            let v = if piece.big_endian {
                <$t>::from_be_bytes(a)
            } else {
                <$t>::from_le_bytes(a)
            };
            v as f64
        }};
    }
    Some(match dtype {
        1 => num!(i8),
        2 => num!(i16),
        3 => num!(i32),
        4 => num!(i64),
        5 => num!(u8),
        6 => num!(u16),
        7 => num!(u32),
        8 => num!(u64),
        9 | 0x19 => num!(f32),
        10 | 0x1A => num!(f64),
        _ => return None,
    })
}

/// A byte reader over one segment's metadata, in the segment's byte order.
struct Meta<'b> {
    bytes: &'b [u8],
    at: usize,
    big_endian: bool,
}

impl<'b> Meta<'b> {
    fn take(&mut self, n: usize) -> Result<&'b [u8], String> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len());
        let end = end.ok_or("the segment's metadata ends inside an entry")?;
        let b = &self.bytes[self.at..end];
        self.at = end;
        Ok(b)
    }

    fn u32(&mut self) -> Result<u32, String> {
        let a = self.take(4)?.try_into().expect("4 bytes");
        Ok(if self.big_endian {
            u32::from_be_bytes(a)
        } else {
            u32::from_le_bytes(a)
        })
    }

    fn u64(&mut self) -> Result<u64, String> {
        let a = self.take(8)?.try_into().expect("8 bytes");
        Ok(if self.big_endian {
            u64::from_be_bytes(a)
        } else {
            u64::from_le_bytes(a)
        })
    }

    fn string(&mut self) -> Result<String, String> {
        let n = self.u32()? as usize;
        Ok(String::from_utf8_lossy(self.take(n)?).into_owned())
    }

    /// A property's value: the two servoid uses kept, the rest passed over.
    fn property(&mut self) -> Result<Property, String> {
        let dtype = self.u32()?;
        Ok(match dtype {
            STRING => Property::Text(self.string()?),
            9 | 0x19 => Property::Number(f64::from(f32::from_bits(self.u32()?))),
            10 | 0x1A => Property::Number(f64::from_bits(self.u64()?)),
            t => {
                let n = size_of(t).ok_or(format!("a property of unknown type {t:#x}"))?;
                self.take(n)?;
                Property::Other
            }
        })
    }
}

enum Property {
    Text(String),
    Number(f64),
    Other,
}

/// An object's raw-data index: its type, values a chunk and bytes a chunk.
#[derive(Debug, Clone, Copy)]
struct Index {
    dtype: u32,
    count: u64,
    bytes: u64,
}

/// An object of the file (root, group or channel) as the segments so far
/// describe it.
struct Object {
    /// Its place in `channels`, for a channel.
    channel: Option<usize>,
    /// Its names joined by `/` (`log/x`), as messages give it.
    name: String,
    index: Option<Index>,
}

/// The walk's state: every object seen, and the list the current segment's
/// raw data follows (objects with the index they have in it).
#[derive(Default)]
struct Walk {
    objects: Vec<Object>,
    by_path: HashMap<String, usize>,
    active: Vec<(usize, Option<Index>)>,
    channels: Vec<Channel>,
}

/// Walk `bytes`' segments. Err: the file's damage in words.
pub(super) fn layout(bytes: &[u8]) -> Result<Layout, String> {
    let mut walk = Walk::default();
    let mut at = 0usize;
    let mut segment = 0usize;
    let mut dropped = None;
    while at < bytes.len() {
        segment += 1;
        let rest = bytes.len() - at;
        if rest < LEAD_IN {
            dropped = Some(format!(
                "the file ends {rest} byte(s) into segment {segment}'s lead-in; those bytes were dropped"
            ));
            break;
        }
        let lead = &bytes[at..at + LEAD_IN];
        if &lead[..4] != b"TDSm" {
            return Err(if segment == 1 {
                "it does not begin with a TDMS segment (tag `TDSm`)".into()
            } else {
                format!("segment {segment} (byte {at}) does not begin with the tag `TDSm`")
            });
        }
        let toc = u32::from_le_bytes(lead[4..8].try_into().expect("4 bytes"));
        let big_endian = toc & TOC_BIG_ENDIAN != 0;
        let mut m = Meta {
            bytes: &lead[8..],
            at: 0,
            big_endian,
        };
        let _version = m.u32()?;
        let next = m.u64()?;
        let raw_offset = m.u64()?;
        let body = at + LEAD_IN;
        let declared_end = usize::try_from(next).ok().and_then(|n| body.checked_add(n));
        let (end, cut) = match declared_end {
            Some(e) if e <= bytes.len() => (e, false),
            _ => (bytes.len(), true),
        };
        let raw_start = usize::try_from(raw_offset)
            .ok()
            .and_then(|n| body.checked_add(n))
            .filter(|&r| r <= end);
        let Some(raw_start) = raw_start else {
            if cut {
                dropped = Some(format!(
                    "the file ends inside segment {segment}'s metadata (byte {at}); the segment was dropped"
                ));
                break;
            }
            return Err(format!(
                "segment {segment} (byte {at}) declares {raw_offset} bytes of metadata in a segment of {next}"
            ));
        };
        let where_ = format!("segment {segment} (byte {at})");
        if toc & TOC_META_DATA != 0 {
            match walk.metadata(&bytes[body..raw_start], toc) {
                Ok(()) => {}
                Err(e) if cut => {
                    dropped = Some(format!(
                        "the file ends inside {where_}, whose metadata cannot be read ({e}); the segment was dropped"
                    ));
                    break;
                }
                Err(e) => return Err(format!("{where_}: {e}")),
            }
        }
        let chunks = if toc & TOC_RAW_DATA != 0 {
            walk.raw_data(toc, raw_start, end - raw_start, cut)
                .map_err(|e| format!("{where_}: {e}"))?
        } else {
            Chunks::default()
        };
        if cut {
            let declared = (next != u64::MAX).then(|| next.saturating_sub(raw_offset));
            dropped = Some(format!(
                "the file ends inside {where_}, {}: {} (a recording cut short)",
                match declared {
                    Some(_) => format!(
                        "which declares {next} bytes where {} are there",
                        bytes.len() - body
                    ),
                    None => "whose length was never written (a recording not closed)".into(),
                },
                chunks.what_was_dropped(declared)
            ));
            break;
        }
        at = end;
    }
    Ok(Layout {
        channels: walk.channels,
        dropped,
    })
}

/// How a segment's raw data divide into chunks.
#[derive(Default)]
struct Chunks {
    /// Whole chunks read.
    read: u64,
    /// Bytes after them.
    left: u64,
    /// Bytes a chunk.
    bytes: u64,
    /// Values of each channel a chunk, where every channel has as many.
    values: Option<u64>,
}

impl Chunks {
    /// What a segment cut short lost, in words, from the raw bytes it
    /// declares (None: its length was never written).
    fn what_was_dropped(&self, declared: Option<u64>) -> String {
        let read = match self.read {
            0 => String::new(),
            n => format!("its first {n} whole chunk(s) read; "),
        };
        let lost = match (declared, self.values) {
            _ if self.bytes == 0 => return "it holds no raw data".into(),
            (Some(d), Some(v)) => {
                let n = (d / self.bytes).saturating_sub(self.read) * v;
                format!("{n} value(s) of each channel dropped")
            }
            (None, Some(v)) if self.left > 0 => {
                format!("fewer than {v} value(s) of each channel dropped")
            }
            (None, _) if self.left == 0 => return "its whole chunks read".into(),
            _ => format!("the {} byte(s) after them dropped", self.left),
        };
        format!("{read}{lost}")
    }
}

impl Walk {
    /// One segment's metadata: its object list replaces or updates the
    /// list the raw data follow.
    fn metadata(&mut self, meta: &[u8], toc: u32) -> Result<(), String> {
        if toc & TOC_NEW_OBJ_LIST != 0 {
            self.active.clear();
        }
        self.objects_of(&mut Meta {
            bytes: meta,
            at: 0,
            big_endian: toc & TOC_BIG_ENDIAN != 0,
        })
    }

    /// Lay out one segment's `raw_len` bytes of raw data from `raw_start`
    /// in whole chunks: (chunks, bytes left after them). A chunk larger
    /// than a whole segment is a damaged count; in a segment the file cuts
    /// short (`cut`) it is what the recording did not finish.
    fn raw_data(
        &mut self,
        toc: u32,
        raw_start: usize,
        raw_len: usize,
        cut: bool,
    ) -> Result<Chunks, String> {
        let big_endian = toc & TOC_BIG_ENDIAN != 0;
        if toc & TOC_DAQMX != 0 {
            return Err("its raw data are DAQmx raw data, which servoid does not read; export the channels scaled".into());
        }
        let with_data: Vec<(usize, Index)> = self
            .active
            .iter()
            .filter_map(|&(o, i)| Some((o, i?)))
            .collect();
        let chunk = with_data
            .iter()
            .try_fold(0u64, |s, (_, i)| s.checked_add(i.bytes))
            .ok_or("its objects' sizes overflow")?;
        if chunk == 0 {
            return Ok(Chunks::default());
        }
        let chunks = raw_len as u64 / chunk;
        let left = raw_len as u64 % chunk;
        if chunks == 0 && !cut {
            let (o, i) = with_data
                .iter()
                .max_by_key(|(_, i)| i.bytes)
                .expect("a chunk of some bytes");
            return Err(format!(
                "`{}` declares {} values ({} bytes) but the segment holds {raw_len} bytes of data",
                self.objects[*o].name, i.count, i.bytes
            ));
        }
        let interleaved = toc & TOC_INTERLEAVED != 0;
        if interleaved
            && with_data
                .iter()
                .any(|(_, i)| i.count != with_data[0].1.count)
        {
            return Err("its interleaved channels declare different numbers of values".into());
        }
        for c in 0..chunks as usize {
            let mut off = raw_start + c * chunk as usize;
            for &(o, i) in &with_data {
                // The index fits in `chunk`, which fits in the segment.
                let count = i.count as usize;
                let piece = if interleaved {
                    let size = size_of(i.dtype)
                        .ok_or("interleaved data of a type without a fixed size")?;
                    let p = Piece {
                        start: off,
                        count,
                        stride: (chunk / i.count) as usize,
                        big_endian,
                    };
                    off += size;
                    p
                } else {
                    let p = Piece {
                        start: off,
                        count,
                        stride: size_of(i.dtype).unwrap_or(0),
                        big_endian,
                    };
                    off += i.bytes as usize;
                    p
                };
                if let Some(ch) = self.objects[o].channel {
                    let ch = &mut self.channels[ch];
                    ch.len = ch.len.saturating_add(count);
                    ch.pieces.push(piece);
                }
            }
        }
        let count = with_data[0].1.count;
        Ok(Chunks {
            read: chunks,
            left,
            bytes: chunk,
            values: with_data
                .iter()
                .all(|(_, i)| i.count == count)
                .then_some(count),
        })
    }

    /// The object list of one segment's metadata: each object's raw-data
    /// index and properties, merged into what the file said before.
    fn objects_of(&mut self, m: &mut Meta<'_>) -> Result<(), String> {
        let n = m.u32()?;
        for _ in 0..n {
            let path = m.string()?;
            let o = self.object(&path)?;
            let path = self.objects[o].name.clone();
            let header = m.u32()?;
            let index = match header {
                0xFFFF_FFFF => None,
                0 => Some(self.objects[o].index.ok_or_else(|| {
                    format!("`{path}` repeats a raw-data index it was never given")
                })?),
                0x6912_0000..=0x6913_FFFF => {
                    return Err(format!(
                        "`{path}` holds DAQmx raw data, which servoid does not read; export the channels scaled"
                    ));
                }
                _ => Some(index(m, &path)?),
            };
            if let Some(i) = index {
                self.objects[o].index = Some(i);
                if let Some(ch) = self.objects[o].channel {
                    let ch = &mut self.channels[ch];
                    match ch.dtype {
                        Some(t) if t != i.dtype => {
                            return Err(format!(
                                "`{path}` changes its data type from {t:#x} to {:#x}",
                                i.dtype
                            ));
                        }
                        _ => ch.dtype = Some(i.dtype),
                    }
                }
            }
            match self.active.iter_mut().find(|(a, _)| *a == o) {
                Some(entry) => entry.1 = index,
                None => self.active.push((o, index)),
            }
            let properties = m.u32()?;
            for _ in 0..properties {
                let name = m.string()?;
                let value = m.property()?;
                if let Some(ch) = self.objects[o].channel {
                    let ch = &mut self.channels[ch];
                    match (name.as_str(), value) {
                        ("wf_increment", Property::Number(v)) => ch.increment = Some(v),
                        ("unit_string", Property::Text(t)) => ch.unit = Some(t),
                        _ => {}
                    }
                }
            }
        }
        Ok(())
    }

    /// The object at `path`, added (and, for a channel, listed) when new.
    fn object(&mut self, path: &str) -> Result<usize, String> {
        if let Some(&o) = self.by_path.get(path) {
            return Ok(o);
        }
        let parts =
            components(path).ok_or_else(|| format!("`{path}` is not a TDMS object path"))?;
        let channel = match parts.as_slice() {
            [group, name] => {
                self.channels.push(Channel {
                    group: group.clone(),
                    name: name.clone(),
                    dtype: None,
                    pieces: Vec::new(),
                    len: 0,
                    increment: None,
                    unit: None,
                });
                Some(self.channels.len() - 1)
            }
            _ => None,
        };
        self.objects.push(Object {
            channel,
            name: if parts.is_empty() {
                "/".into()
            } else {
                parts.join("/")
            },
            index: None,
        });
        let o = self.objects.len() - 1;
        self.by_path.insert(path.to_string(), o);
        Ok(o)
    }
}

/// A raw-data index after its length word: type, dimension (always 1),
/// number of values and, for strings, their bytes.
fn index(m: &mut Meta<'_>, path: &str) -> Result<Index, String> {
    let dtype = m.u32()?;
    let dims = m.u32()?;
    if dims != 1 {
        return Err(format!(
            "`{path}` declares {dims} dimensions (TDMS allows 1)"
        ));
    }
    let count = m.u64()?;
    let bytes = if dtype == STRING {
        m.u64()?
    } else {
        let size = size_of(dtype).unwrap_or(0) as u64;
        count
            .checked_mul(size)
            .ok_or_else(|| format!("`{path}` declares {count} values, more than any file holds"))?
    };
    Ok(Index {
        dtype,
        count,
        bytes,
    })
}

/// An object path's names: `/` is the root, `/'g'` a group, `/'g'/'c'` a
/// channel, a quote inside a name doubled.
fn components(path: &str) -> Option<Vec<String>> {
    let mut out = Vec::new();
    let mut rest = path.strip_prefix('/')?;
    while !rest.is_empty() {
        let mut chars = rest.strip_prefix('\'')?.char_indices().peekable();
        let mut name = String::new();
        let end = loop {
            let (i, c) = chars.next()?;
            if c == '\'' {
                if chars.peek().is_some_and(|&(_, c)| c == '\'') {
                    chars.next();
                    name.push('\'');
                } else {
                    break i + 2;
                }
            } else {
                name.push(c);
            }
        };
        out.push(name);
        rest = &rest[end..];
        if !rest.is_empty() {
            rest = rest.strip_prefix('/')?;
        }
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn object_paths_split_into_names_with_doubled_quotes_undone() {
        assert_eq!(components("/"), Some(vec![]));
        assert_eq!(components("/'log'"), Some(vec!["log".to_string()]));
        assert_eq!(
            components("/'log'/'it''s x'"),
            Some(vec!["log".to_string(), "it's x".to_string()])
        );
        assert_eq!(
            components("/'a/b'/'c'"),
            Some(vec!["a/b".to_string(), "c".to_string()])
        );
        assert_eq!(components("/'log"), None);
        assert_eq!(components("log"), None);
        assert_eq!(components("/'a'x"), None);
    }

    /// A TDMS file written here by NI's description, big-endian and
    /// interleaved: segment 1 lists `g/a` (i16, unit mm) and `g/b` (f64,
    /// wf_increment 1 ms) with three rows; segment 2 has no metadata and
    /// reuses the list; segment 3 repeats both indexes (`0`) and the file
    /// ends 5 bytes into its rows.
    fn big_endian_interleaved() -> Vec<u8> {
        let u32b = |v: u32| v.to_be_bytes().to_vec();
        let string = |s: &str| [u32b(s.len() as u32), s.as_bytes().to_vec()].concat();
        let rows = |from: i16| -> Vec<u8> {
            (from..from + 3)
                .flat_map(|k| {
                    [
                        k.to_be_bytes().to_vec(),
                        (f64::from(k) * 0.5).to_be_bytes().to_vec(),
                    ]
                    .concat()
                })
                .collect()
        };
        let segment = |toc: u32, meta: Vec<u8>, raw: Vec<u8>| -> Vec<u8> {
            let mut out = b"TDSm".to_vec();
            out.extend(toc.to_le_bytes());
            out.extend(u32b(4713));
            out.extend(((meta.len() + raw.len()) as u64).to_be_bytes());
            out.extend((meta.len() as u64).to_be_bytes());
            [out, meta, raw].concat()
        };
        let index =
            |dtype: u32| [u32b(20), u32b(dtype), u32b(1), 3u64.to_be_bytes().to_vec()].concat();
        let meta1 = [
            u32b(4),
            string("/"),
            u32b(0xFFFF_FFFF),
            u32b(0),
            string("/'g'"),
            u32b(0xFFFF_FFFF),
            u32b(0),
            string("/'g'/'a'"),
            index(2),
            u32b(1),
            string("unit_string"),
            u32b(0x20),
            string("mm"),
            string("/'g'/'b'"),
            index(10),
            u32b(1),
            string("wf_increment"),
            u32b(10),
            0.001f64.to_be_bytes().to_vec(),
        ]
        .concat();
        let meta3 = [
            u32b(2),
            string("/'g'/'a'"),
            u32b(0),
            u32b(0),
            string("/'g'/'b'"),
            u32b(0),
            u32b(0),
        ]
        .concat();
        let all =
            TOC_META_DATA | TOC_NEW_OBJ_LIST | TOC_RAW_DATA | TOC_INTERLEAVED | TOC_BIG_ENDIAN;
        let mut file = segment(all, meta1, rows(0));
        file.extend(segment(
            TOC_RAW_DATA | TOC_INTERLEAVED | TOC_BIG_ENDIAN,
            vec![],
            rows(3),
        ));
        file.extend(segment(all & !TOC_NEW_OBJ_LIST, meta3, rows(6)));
        file.truncate(file.len() - 25);
        file
    }

    #[test]
    fn interleaved_big_endian_segments_read_to_the_cut() {
        let bytes = big_endian_interleaved();
        let l = layout(&bytes).unwrap();
        let names: Vec<String> = l
            .channels
            .iter()
            .map(|c| format!("{}/{}", c.group, c.name))
            .collect();
        assert_eq!(names, ["g/a", "g/b"]);
        let read = |c: &Channel| -> Vec<f64> {
            c.pieces
                .iter()
                .flat_map(|p| (0..p.count).map(|i| value(&bytes, c.dtype.unwrap(), p, i).unwrap()))
                .collect()
        };
        assert_eq!(read(&l.channels[0]), [0.0, 1.0, 2.0, 3.0, 4.0, 5.0]);
        assert_eq!(read(&l.channels[1]), [0.0, 0.5, 1.0, 1.5, 2.0, 2.5]);
        assert_eq!(l.channels[0].unit.as_deref(), Some("mm"));
        assert_eq!(l.channels[1].increment, Some(0.001));
        let dropped = l.dropped.unwrap();
        assert!(
            dropped.contains("segment 3") && dropped.contains("3 value(s) of each channel dropped"),
            "{dropped}"
        );
    }

    #[test]
    fn a_damaged_file_is_an_error_in_words_at_every_length() {
        // Every prefix of a valid file, and every byte of it flipped, is
        // read or refused; none panics or reads past its end.
        let bytes = big_endian_interleaved();
        for n in 0..bytes.len() {
            if let Ok(l) = layout(&bytes[..n]) {
                for c in &l.channels {
                    for p in &c.pieces {
                        assert!(
                            p.count == 0
                                || value(&bytes[..n], c.dtype.unwrap(), p, p.count - 1).is_some()
                        );
                    }
                }
            }
        }
        for i in 0..bytes.len() {
            let mut b = bytes.clone();
            b[i] ^= 0xFF;
            let _ = layout(&b);
        }
    }
}
