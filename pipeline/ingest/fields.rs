//! A delimited line split into its fields as CSV quotes them (RFC 4180: a
//! field in double quotes may hold the delimiter, and `""` inside it is a
//! quote), by `csv-core`, the `csv` crate's parser, reused from line to line.
//! The CSV reader's fallback and its header use it; a quoted separator no
//! longer splits a field.

/// The splitter of one delimiter, with its buffers.
pub(super) struct Fields {
    reader: csv_core::Reader,
    out: Vec<u8>,
    ends: Vec<usize>,
}

impl Fields {
    pub(super) fn new(sep: u8) -> Self {
        Self {
            reader: csv_core::ReaderBuilder::new().delimiter(sep).build(),
            out: vec![0; 256],
            ends: vec![0; 16],
        }
    }

    /// The fields of `line` (one line, without its terminator), unquoted;
    /// bytes that are not UTF-8 make the field U+FFFD. An empty line has
    /// one empty field, as a split on the delimiter gives.
    pub(super) fn split(&mut self, line: &[u8]) -> Vec<&str> {
        use csv_core::ReadRecordResult as R;
        self.reader.reset();
        let (mut input, mut nout, mut nends) = (line, 0, 0);
        let mut eof = false;
        loop {
            let (res, read, wrote, ended) =
                self.reader
                    .read_record(input, &mut self.out[nout..], &mut self.ends[nends..]);
            input = &input[read..];
            (nout, nends) = (nout + wrote, nends + ended);
            match res {
                // The whole line is read: an empty input tells the parser
                // the record ends here.
                R::InputEmpty if !eof => eof = true,
                R::InputEmpty | R::Record | R::End => break,
                R::OutputFull => self.out.resize(2 * self.out.len(), 0),
                R::OutputEndsFull => self.ends.resize(2 * self.ends.len(), 0),
            }
            if eof {
                input = &[];
            }
        }
        if nends == 0 {
            return vec![""];
        }
        let mut start = 0;
        self.ends[..nends]
            .iter()
            .map(|&end| {
                let f = std::str::from_utf8(&self.out[start..end]).unwrap_or("\u{fffd}");
                start = end;
                f
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::Fields;

    #[test]
    fn quoted_fields_keep_their_delimiters_and_quotes() {
        let mut f = Fields::new(b',');
        assert_eq!(f.split(b"a,b,c"), ["a", "b", "c"]);
        assert_eq!(f.split(b"\"disp, mm\",2"), ["disp, mm", "2"]);
        assert_eq!(f.split(b"\"say \"\"hi\"\"\",x"), ["say \"hi\"", "x"]);
        assert_eq!(f.split(b"a,,"), ["a", "", ""]);
        assert_eq!(f.split(b""), [""]);
        // A quote inside a field is a character like any other.
        assert_eq!(f.split(b"1.5 \"x,2"), ["1.5 \"x", "2"]);
        let mut semi = Fields::new(b';');
        assert_eq!(semi.split(b"1,5;2,5"), ["1,5", "2,5"]);
        // Longer than the first buffers: they grow.
        let long = vec!["123456789"; 100].join(",");
        assert_eq!(f.split(long.as_bytes()).len(), 100);
        assert_eq!(f.split(b"\xff,ok"), ["\u{fffd}", "ok"]);
    }
}
