//! MATLAB level-5 MAT files (`models.mat`), written by servoid itself: a
//! header and a list of tagged elements (MathWorks, "MAT-File Format",
//! R2024a, ch. 1), of which models.mat needs numeric matrices, text,
//! structs and cell arrays. The Rust MAT writers do not do: matrw 0.1
//! returns Ok when its write failed and writes text as UTF-8 bytes MATLAB
//! reads as another length; matio-rs needs cmake and libclang to build.
//! MATLAB, Octave and `scipy.io.loadmat` read these files.
//!
//! Layout (little-endian): a 128-byte header (116 bytes of text, 8 of
//! subsystem offset, version 0x0100, "IM"), then one `miMATRIX` element per
//! variable: array flags (class), dimensions, name, data. `miDOUBLE` values
//! are column-major; text is `miUINT16` UTF-16 code units; a struct has its
//! field-name length, the names and one unnamed `miMATRIX` per field (per
//! element, in turn, for a struct array); a cell array one unnamed
//! `miMATRIX` per element. Every element is padded to 8 bytes.

use std::io::{Seek, SeekFrom, Write};

/// A value in a MAT file.
#[derive(Debug, Clone, PartialEq)]
pub enum MatValue {
    /// A real matrix, `rows` x `cols`, its values column by column.
    Matrix {
        rows: usize,
        cols: usize,
        data: Vec<f64>,
    },
    /// A char row vector.
    Text(String),
    /// A 1 x 1 struct, its fields in order.
    Struct(Vec<(String, MatValue)>),
    /// A 1 x n struct array: every element has the same fields, named once;
    /// MATLAB's `s(i).field`.
    StructArray {
        fields: Vec<String>,
        elements: Vec<Vec<MatValue>>,
    },
    /// A 1 x n cell array.
    Cell(Vec<MatValue>),
}

impl MatValue {
    /// A scalar.
    pub fn scalar(v: f64) -> Self {
        Self::Matrix {
            rows: 1,
            cols: 1,
            data: vec![v],
        }
    }

    /// A row vector (1 x n), as MATLAB's `tf(num, den)` takes coefficients.
    pub fn row(v: &[f64]) -> Self {
        Self::Matrix {
            rows: 1,
            cols: v.len(),
            data: v.to_vec(),
        }
    }

    /// The empty matrix `[]`, for what a run does not have.
    pub fn empty() -> Self {
        Self::Matrix {
            rows: 0,
            cols: 0,
            data: Vec::new(),
        }
    }

    /// A column vector (n x 1).
    pub fn column(v: &[f64]) -> Self {
        Self::Matrix {
            rows: v.len(),
            cols: 1,
            data: v.to_vec(),
        }
    }

    /// A 1 x n cell array of text.
    pub fn texts<S: AsRef<str>>(items: &[S]) -> Self {
        Self::Cell(
            items
                .iter()
                .map(|s| Self::Text(s.as_ref().into()))
                .collect(),
        )
    }

    /// A matrix from its rows.
    pub fn from_rows<const C: usize>(rows: &[[f64; C]]) -> Self {
        let data = (0..C)
            .flat_map(|j| rows.iter().map(move |r| r[j]))
            .collect();
        Self::Matrix {
            rows: rows.len(),
            cols: C,
            data,
        }
    }
}

/// Why a MAT file could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MatWriteError {
    #[error(
        "`{name}` is not a MATLAB name (a letter, then letters, digits or underscores, at most {MAX_NAME} characters)"
    )]
    BadName { name: String },
    #[error("matrix `{name}` is {rows} x {cols} but holds {len} values")]
    Shape {
        name: String,
        rows: usize,
        cols: usize,
        len: usize,
    },
    #[error("element {element} of struct array `{name}` has {got} fields, not the {want} named")]
    Fields {
        name: String,
        element: usize,
        got: usize,
        want: usize,
    },
    #[error("`{name}` holds more than a MAT level-5 element can (2^31 bytes)")]
    TooLarge { name: String },
}

/// The longest variable or field name MATLAB takes (`namelengthmax`).
pub const MAX_NAME: usize = 63;

const MI_INT8: u32 = 1;
const MI_UINT16: u32 = 4;
const MI_INT32: u32 = 5;
const MI_UINT32: u32 = 6;
const MI_DOUBLE: u32 = 9;
const MI_MATRIX: u32 = 14;

const MX_CELL: u32 = 1;
const MX_STRUCT: u32 = 2;
const MX_CHAR: u32 = 4;
const MX_DOUBLE: u32 = 6;

/// The bytes of a MAT file holding `vars` in order; `text` heads the file
/// (truncated to 116 bytes), as MATLAB's own "MATLAB 5.0 MAT-file, ...".
pub fn mat_bytes(text: &str, vars: &[(String, MatValue)]) -> Result<Vec<u8>, MatWriteError> {
    let mut out = Vec::with_capacity(4096);
    out.extend_from_slice(&header(text));
    for (name, value) in vars {
        out.extend(variable(name, value)?);
    }
    Ok(out)
}

/// A top-level variable's `miMATRIX` element, its name checked.
fn variable(name: &str, value: &MatValue) -> Result<Vec<u8>, MatWriteError> {
    check_name(name)?;
    matrix(name, value)
}

/// The file's 128-byte header: `text` in 116 bytes, no subsystem data,
/// version 0x0100, little-endian.
fn header(text: &str) -> [u8; 128] {
    let mut head = [b' '; 128];
    for (h, b) in head.iter_mut().zip(text.bytes().take(116)) {
        *h = b;
    }
    head[116..124].fill(0);
    head[124..126].copy_from_slice(&0x0100_u16.to_le_bytes());
    head[126..].copy_from_slice(b"IM");
    head
}

/// A MAT file written as its variables come, the same bytes as
/// [`mat_bytes`]: a struct array's elements are made and written one at a
/// time ([`Self::struct_array`]), so a night's 3,000 runs are never whole
/// in memory (34 MB at the night's end, models.mat being 20 MB).
pub struct MatWriter<W> {
    w: W,
}

impl<W: Write + Seek> MatWriter<W> {
    /// The file's header, `text` as in [`mat_bytes`].
    pub fn new(mut w: W, text: &str) -> std::io::Result<Self> {
        w.write_all(&header(text))?;
        Ok(Self { w })
    }

    /// A whole variable.
    pub fn var(&mut self, name: &str, value: &MatValue) -> std::io::Result<()> {
        let bytes = variable(name, value).map_err(std::io::Error::other)?;
        self.w.write_all(&bytes)
    }

    /// A 1 x `n` struct array of `fields`, element `i`'s values
    /// `element(i)` in the fields' order. Its tag's byte count, which
    /// comes before the elements, is written once they are.
    pub fn struct_array(
        &mut self,
        name: &str,
        fields: &[&str],
        n: usize,
        mut element: impl FnMut(usize) -> Vec<MatValue>,
    ) -> std::io::Result<()> {
        let fail = std::io::Error::other;
        check_name(name).map_err(fail)?;
        let mut head = Vec::new();
        array_head(&mut head, name, MX_STRUCT, [1, n]).map_err(fail)?;
        field_names(&mut head, fields).map_err(fail)?;
        let tag = self.w.stream_position()?;
        self.w.write_all(&MI_MATRIX.to_le_bytes())?;
        self.w.write_all(&0_u32.to_le_bytes())?;
        self.w.write_all(&head)?;
        let mut len = head.len();
        for i in 0..n {
            let bytes = struct_element(name, i, &element(i), fields.len()).map_err(fail)?;
            self.w.write_all(&bytes)?;
            len += bytes.len();
        }
        // Every element is padded to 8 bytes, so the body is too.
        let len = body_len(name, len).map_err(fail)?;
        let end = self.w.stream_position()?;
        self.w.seek(SeekFrom::Start(tag + 4))?;
        self.w.write_all(&len.to_le_bytes())?;
        self.w.seek(SeekFrom::Start(end))?;
        Ok(())
    }

    /// The writer, after the last variable.
    pub fn into_inner(self) -> W {
        self.w
    }
}

fn check_name(name: &str) -> Result<(), MatWriteError> {
    let mut chars = name.chars();
    let ok = chars.next().is_some_and(|c| c.is_ascii_alphabetic())
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
        && name.len() <= MAX_NAME;
    match ok {
        true => Ok(()),
        false => Err(MatWriteError::BadName { name: name.into() }),
    }
}

/// One tagged element: type, byte count, data, padding to 8 bytes.
fn element(out: &mut Vec<u8>, ty: u32, data: &[u8]) {
    out.extend_from_slice(&ty.to_le_bytes());
    out.extend_from_slice(&(data.len() as u32).to_le_bytes());
    out.extend_from_slice(data);
    out.resize(out.len().next_multiple_of(8), 0);
}

/// A `miMATRIX` element named `name` ("" inside a struct or cell).
fn matrix(name: &str, value: &MatValue) -> Result<Vec<u8>, MatWriteError> {
    let mut body = Vec::new();
    let (class, dims): (u32, [usize; 2]) = match value {
        MatValue::Matrix { rows, cols, data } => {
            if rows * cols != data.len() {
                return Err(MatWriteError::Shape {
                    name: name.into(),
                    rows: *rows,
                    cols: *cols,
                    len: data.len(),
                });
            }
            (MX_DOUBLE, [*rows, *cols])
        }
        MatValue::Text(s) => (MX_CHAR, [1, s.encode_utf16().count()]),
        MatValue::Struct(_) => (MX_STRUCT, [1, 1]),
        MatValue::StructArray { elements, .. } => (MX_STRUCT, [1, elements.len()]),
        MatValue::Cell(items) => (MX_CELL, [1, items.len()]),
    };
    array_head(&mut body, name, class, dims)?;
    match value {
        MatValue::Matrix { data, .. } => {
            let bytes: Vec<u8> = data.iter().flat_map(|v| v.to_le_bytes()).collect();
            element(&mut body, MI_DOUBLE, &bytes);
        }
        MatValue::Text(s) => {
            let bytes: Vec<u8> = s.encode_utf16().flat_map(|u| u.to_le_bytes()).collect();
            element(&mut body, MI_UINT16, &bytes);
        }
        MatValue::Struct(fields) => {
            let names: Vec<&str> = fields.iter().map(|(n, _)| n.as_str()).collect();
            field_names(&mut body, &names)?;
            for (_, v) in fields {
                body.extend(matrix("", v)?);
            }
        }
        MatValue::StructArray { fields, elements } => {
            let names: Vec<&str> = fields.iter().map(String::as_str).collect();
            field_names(&mut body, &names)?;
            // Element after element (column-major over the 1 x n array),
            // each element's fields in the order named.
            for (i, values) in elements.iter().enumerate() {
                body.extend(struct_element(name, i, values, fields.len())?);
            }
        }
        MatValue::Cell(items) => {
            for v in items {
                body.extend(matrix("", v)?);
            }
        }
    }
    body_len(name, body.len())?;
    let mut out = Vec::with_capacity(body.len() + 8);
    element(&mut out, MI_MATRIX, &body);
    Ok(out)
}

/// Element `i` (from 0) of struct array `name`: one unnamed matrix for each
/// of its `values`, which must be one for each of the `fields` named.
fn struct_element(
    name: &str,
    i: usize,
    values: &[MatValue],
    fields: usize,
) -> Result<Vec<u8>, MatWriteError> {
    if values.len() != fields {
        return Err(MatWriteError::Fields {
            name: name.into(),
            element: i + 1,
            got: values.len(),
            want: fields,
        });
    }
    let mut out = Vec::new();
    for v in values {
        out.extend(matrix("", v)?);
    }
    Ok(out)
}

/// The byte count a `miMATRIX` tag holds for a body of `len` bytes, which
/// MATLAB reads as a signed 32-bit count.
fn body_len(name: &str, len: usize) -> Result<u32, MatWriteError> {
    u32::try_from(len)
        .ok()
        .filter(|&l| l <= i32::MAX as u32)
        .ok_or_else(|| MatWriteError::TooLarge { name: name.into() })
}

/// A `miMATRIX` element's array flags (`class`), dimensions and name.
fn array_head(
    body: &mut Vec<u8>,
    name: &str,
    class: u32,
    dims: [usize; 2],
) -> Result<(), MatWriteError> {
    let mut flags = Vec::with_capacity(8);
    flags.extend_from_slice(&class.to_le_bytes());
    flags.extend_from_slice(&0_u32.to_le_bytes());
    element(body, MI_UINT32, &flags);
    let dim_bytes: Vec<u8> = dims
        .iter()
        .map(|&d| i32::try_from(d).map_err(|_| MatWriteError::TooLarge { name: name.into() }))
        .collect::<Result<Vec<i32>, _>>()?
        .iter()
        .flat_map(|d| d.to_le_bytes())
        .collect();
    element(body, MI_INT32, &dim_bytes);
    element(body, MI_INT8, name.as_bytes());
    Ok(())
}

/// A struct's field names: the slot length (the longest name plus one),
/// then each name null-terminated in its slot.
fn field_names(body: &mut Vec<u8>, fields: &[&str]) -> Result<(), MatWriteError> {
    let slot = fields.iter().map(|n| n.len()).max().unwrap_or(0) + 1;
    // The slot length in the small data element format (type and byte
    // count in one word, then the value), as MATLAB writes it: Octave's
    // reader takes no other form here.
    body.extend_from_slice(&((4_u32 << 16) | MI_INT32).to_le_bytes());
    body.extend_from_slice(&(slot as i32).to_le_bytes());
    let mut names = Vec::with_capacity(slot * fields.len());
    for n in fields {
        check_name(n)?;
        names.extend_from_slice(n.as_bytes());
        names.resize(names.len().next_multiple_of(slot).max(names.len() + 1), 0);
    }
    element(body, MI_INT8, &names);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Numbers written here read back through the `matfile` crate (an
    /// independent level-5 reader, the one `ingest` uses): names, shapes and
    /// every value to the bit, column-major.
    #[test]
    fn numeric_variables_read_back_through_the_matfile_crate() {
        let a = MatValue::from_rows(&[[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
        let num = MatValue::row(&[3060.0]);
        let den = MatValue::row(&[1.0, 267.0, 3060.0]);
        let tiny = MatValue::scalar(f64::MIN_POSITIVE);
        let vars = vec![
            ("A".to_string(), a),
            ("num".to_string(), num),
            ("den".to_string(), den),
            ("tiny".to_string(), tiny),
            ("label".to_string(), MatValue::Text("x1/u".into())),
        ];
        let bytes = mat_bytes("MATLAB 5.0 MAT-file, written by servoid tests", &vars).unwrap();
        assert_eq!(bytes.len() % 8, 0);
        let mat = matfile::MatFile::parse(bytes.as_slice()).unwrap();
        let get = |name: &str| -> (Vec<usize>, Vec<f64>) {
            let a = mat.find_by_name(name).unwrap_or_else(|| panic!("{name}"));
            match a.data() {
                matfile::NumericData::Double { real, imag: None } => {
                    (a.size().to_vec(), real.clone())
                }
                other => panic!("{name}: {other:?}"),
            }
        };
        // Exact: the values written, read back bit for bit.
        assert_eq!(get("A"), (vec![2, 3], vec![1.0, 4.0, 2.0, 5.0, 3.0, 6.0]));
        assert_eq!(get("num"), (vec![1, 1], vec![3060.0]));
        assert_eq!(get("den"), (vec![1, 3], vec![1.0, 267.0, 3060.0]));
        assert_eq!(get("tiny").1[0].to_bits(), f64::MIN_POSITIVE.to_bits());
    }

    #[test]
    fn names_and_shapes_are_checked() {
        let bad = |name: &str| mat_bytes("", &[(name.to_string(), MatValue::scalar(1.0))]);
        for name in ["", "1a", "a-b", "a b", &"a".repeat(64)] {
            assert!(
                matches!(bad(name), Err(MatWriteError::BadName { .. })),
                "{name:?}"
            );
        }
        assert!(bad("a_1").is_ok());
        let shape = MatValue::Matrix {
            rows: 2,
            cols: 2,
            data: vec![1.0; 3],
        };
        assert_eq!(
            mat_bytes("", &[("m".into(), shape)])
                .unwrap_err()
                .to_string(),
            "matrix `m` is 2 x 2 but holds 3 values"
        );
        let field = MatValue::Struct(vec![
            ("ok".into(), MatValue::scalar(1.0)),
            ("no good".into(), MatValue::scalar(2.0)),
        ]);
        assert!(matches!(
            mat_bytes("", &[("s".into(), field)]),
            Err(MatWriteError::BadName { .. })
        ));
    }

    /// A struct array written element by element is the same bytes as
    /// the whole array (the tag's count patched in once the elements are
    /// written), and a wrong element is refused as the whole one is.
    #[test]
    fn a_struct_array_streamed_is_the_whole_arrays_bytes() {
        let fields = ["id", "k"];
        let element = |i: usize| {
            vec![
                MatValue::Text(format!("run{i}")),
                MatValue::row(&[i as f64; 3]),
            ]
        };
        let whole = MatValue::StructArray {
            fields: fields.iter().map(|f| f.to_string()).collect(),
            elements: (0..3).map(element).collect(),
        };
        let head = "MATLAB 5.0 MAT-file, written by servoid tests";
        let about = MatValue::scalar(1.5);
        let bytes = mat_bytes(
            head,
            &[("about".into(), about.clone()), ("runs".into(), whole)],
        )
        .unwrap();
        let mut w = MatWriter::new(std::io::Cursor::new(Vec::new()), head).unwrap();
        w.var("about", &about).unwrap();
        w.struct_array("runs", &fields, 3, element).unwrap();
        assert_eq!(w.into_inner().into_inner(), bytes);

        let mut w = MatWriter::new(std::io::Cursor::new(Vec::new()), head).unwrap();
        let err = w
            .struct_array("runs", &fields, 2, |_| vec![MatValue::scalar(1.0)])
            .unwrap_err();
        assert_eq!(
            err.to_string(),
            "element 1 of struct array `runs` has 1 fields, not the 2 named"
        );
    }

    /// The struct layout by hand, from the format's description: the field
    /// name length (longest name + 1), the names in slots of that length,
    /// then one unnamed matrix per field.
    #[test]
    fn a_struct_is_laid_out_as_the_format_says() {
        let s = MatValue::Struct(vec![
            ("k".into(), MatValue::scalar(2.5)),
            ("name".into(), MatValue::Text("ab".into())),
        ]);
        let bytes = mat_bytes("", &[("s".into(), s)]).unwrap();
        let u32_at = |i: usize| u32::from_le_bytes(bytes[i..i + 4].try_into().unwrap());
        assert_eq!(&bytes[124..128], &[0x00, 0x01, b'I', b'M']);
        assert_eq!(u32_at(128), 14, "miMATRIX");
        assert_eq!(u32_at(128 + 4) as usize, bytes.len() - 136);
        // flags: class 2 (struct)
        assert_eq!((u32_at(136), u32_at(140), u32_at(144)), (6, 8, 2));
        // dims 1 x 1
        assert_eq!(
            (u32_at(152), u32_at(156), u32_at(160), u32_at(164)),
            (5, 8, 1, 1)
        );
        // name "s"
        assert_eq!((u32_at(168), u32_at(172), bytes[176]), (1, 1, b's'));
        // field name length 5 ("name" + 1), a small element (4 bytes of
        // miINT32 in the tag's word), as MATLAB writes it and Octave needs
        assert_eq!((u32_at(184), u32_at(188)), ((4 << 16) | 5, 5));
        // names: "k\0\0\0\0name\0" in 10 bytes
        assert_eq!((u32_at(192), u32_at(196)), (1, 10));
        assert_eq!(&bytes[200..210], b"k\0\0\0\0name\0");
        // then the first field's matrix, unnamed
        assert_eq!(u32_at(216), 14);
    }

    /// A 1 x 2 struct array: dims 1 x 2, the names once, then element 1's
    /// fields and element 2's, each an unnamed matrix; an element without
    /// every field is refused, naming it.
    #[test]
    fn a_struct_array_names_its_fields_once_then_each_element() {
        let runs = MatValue::StructArray {
            fields: vec!["id".into(), "k".into()],
            elements: vec![
                vec![MatValue::Text("a".into()), MatValue::scalar(1.0)],
                vec![MatValue::Text("b".into()), MatValue::empty()],
            ],
        };
        let bytes = mat_bytes("", &[("runs".into(), runs)]).unwrap();
        let u32_at = |i: usize| u32::from_le_bytes(bytes[i..i + 4].try_into().unwrap());
        assert_eq!((u32_at(144), u32_at(160), u32_at(164)), (2, 1, 2));
        // name "runs", then the slot length 3 as a small element
        assert_eq!(&bytes[176..180], b"runs");
        assert_eq!((u32_at(184), u32_at(188)), ((4 << 16) | 5, 3));
        assert_eq!((u32_at(192), u32_at(196)), (1, 6));
        assert_eq!(&bytes[200..206], b"id\0k\0\0");
        // Four unnamed matrices follow, in element order: "a", 1, "b", [].
        let mut at = 208;
        let mut classes = Vec::new();
        while at < bytes.len() {
            assert_eq!(u32_at(at), 14);
            classes.push((u32_at(at + 16), u32_at(at + 32), u32_at(at + 36)));
            at += 8 + u32_at(at + 4) as usize;
        }
        assert_eq!(classes, [(4, 1, 1), (6, 1, 1), (4, 1, 1), (6, 0, 0)]);
        let short = MatValue::StructArray {
            fields: vec!["id".into(), "k".into()],
            elements: vec![vec![MatValue::scalar(1.0)]],
        };
        assert_eq!(
            mat_bytes("", &[("runs".into(), short)])
                .unwrap_err()
                .to_string(),
            "element 1 of struct array `runs` has 1 fields, not the 2 named"
        );
    }
}
