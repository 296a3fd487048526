//! A manifest document as parsed (TOML or JSON), read section by section
//! against its JSON Schema: unknown keys with suggestions, the first type
//! error of each section, required keys, and every problem's line and
//! column. Shared by every manifest kind servoid reads.

use std::ops::Range;
use std::path::Path;

use serde::de::DeserializeOwned;
use serde_json::Value;

use super::keypath::{KeyPath, Seg};
use super::problem::{MAX_MANIFEST_BYTES, ManifestError, Problem};

/// Read a manifest's text, naming the file when it cannot be read; at most
/// [`MAX_MANIFEST_BYTES`] of it.
pub(super) fn read(path: &Path) -> Result<String, ManifestError> {
    use std::io::Read;
    let failed = |source| ManifestError::Read {
        file: path.to_path_buf(),
        source,
    };
    let file = std::fs::File::open(path).map_err(failed)?;
    let mut bytes = Vec::new();
    file.take(MAX_MANIFEST_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(failed)?;
    if bytes.len() as u64 > MAX_MANIFEST_BYTES {
        return Err(ManifestError::TooLarge {
            file: path.to_path_buf(),
        });
    }
    if let Some(encoding) = utf16(&bytes) {
        return Err(failed(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("{encoding} text; servoid reads manifests as UTF-8: save it as UTF-8"),
        )));
    }
    String::from_utf8(bytes).map_err(|e| {
        failed(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!(
                "not UTF-8 text (first bad byte at offset {})",
                e.utf8_error().valid_up_to()
            ),
        ))
    })
}

/// The UTF-16 a manifest is in, in words, when it is: by its byte-order
/// mark, or without one (Windows editors offer both) by the zero bytes
/// its ASCII characters leave at every other place. Its UTF-16 without a
/// mark is valid UTF-8 full of NULs, which TOML reads as keys with no
/// value.
fn utf16(bytes: &[u8]) -> Option<&'static str> {
    match bytes {
        [0xff, 0xfe, ..] => return Some("UTF-16 (little-endian, with a byte-order mark)"),
        [0xfe, 0xff, ..] => return Some("UTF-16 (big-endian, with a byte-order mark)"),
        _ => {}
    }
    let head = &bytes[..bytes.len().min(4096) & !1];
    let pairs = head.len() / 2;
    let zero_at = |odd: usize| {
        head.iter()
            .skip(odd)
            .step_by(2)
            .filter(|&&b| b == 0)
            .count()
    };
    // Mostly ASCII text: one byte of each pair zero, the other not.
    if pairs >= 4 && zero_at(1) * 10 >= pairs * 9 && zero_at(0) * 10 < pairs {
        Some("UTF-16 (little-endian, without a byte-order mark)")
    } else if pairs >= 4 && zero_at(0) * 10 >= pairs * 9 && zero_at(1) * 10 < pairs {
        Some("UTF-16 (big-endian, without a byte-order mark)")
    } else {
        None
    }
}

/// Whether the manifest text has the top-level key `key`, read leniently:
/// text that does not parse has none.
pub(super) fn has_top_level_key(text: &str, path: &Path, key: &str) -> bool {
    if is_json(path) {
        serde_json::from_str::<Value>(text)
            .ok()
            .is_some_and(|v| v.get(key).is_some())
    } else {
        toml::from_str::<toml::Table>(text)
            .ok()
            .is_some_and(|t| t.contains_key(key))
    }
}

/// `.json` is read as JSON, anything else as TOML.
fn is_json(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"))
}

/// A parsed manifest document (TOML or JSON) and the problems found in it so
/// far; shared by every manifest kind servoid reads.
pub(super) struct Document<'a> {
    path: &'a Path,
    text: &'a str,
    value: Value,
    /// The TOML document with spans, for line and column.
    spans: Option<toml_edit::Document<&'a str>>,
    schema: Value,
    pub problems: Vec<Problem>,
    /// Whether a number was nan or infinite (replaced by 1 so that its
    /// section still reads; see [`Document::begin_checks`]).
    non_finite: bool,
    /// How many problems there were when the cross-key checks began.
    structural: Option<usize>,
    /// Values `servoid init` left for the lab to fill
    /// ([`super::scaffold::PLACEHOLDER`]): while there are any, they are
    /// the only problems reported (the rest follow from them).
    placeholders: Vec<Problem>,
}

impl<'a> Document<'a> {
    /// Parse the text; a syntax error names line and column.
    pub fn parse(text: &'a str, path: &'a Path, schema: Value) -> Result<Self, ManifestError> {
        let syntax = |format, (line, column), message: String| ManifestError::Syntax {
            file: path.to_path_buf(),
            format,
            line,
            column,
            message,
        };
        let (value, spans) = if is_json(path) {
            let v: Value = serde_json::from_str(text).map_err(|e| {
                let at = (e.line(), e.column());
                syntax("JSON", at, json_message(&e, text, at))
            })?;
            (v, None)
        } else {
            // JSON text under another extension reads as broken TOML: say so.
            let hint = if text.trim_start().starts_with('{') {
                " (the file looks like JSON: a manifest is read as JSON only when its name ends in .json)"
            } else {
                ""
            };
            // The toml crate first: toml_edit 0.23 panics on some documents
            // the toml crate refuses ("all items have spans", found by the
            // manifest fuzz target; fuzz/regressions/manifest_toml/), and
            // the spans are only wanted for a document that parses.
            let mut v: Value = toml::from_str(text).map_err(|e| {
                let at = e.span().map(|s| line_col(text, s.start)).unwrap_or((1, 1));
                syntax("TOML", at, format!("{}{hint}", e.message().trim_end()))
            })?;
            let doc = toml_edit::Document::parse(text).map_err(|e| {
                let at = e.span().map(|s| line_col(text, s.start)).unwrap_or((1, 1));
                syntax("TOML", at, format!("{}{hint}", e.message().trim_end()))
            })?;
            datetimes_as_text(&mut v);
            (v, Some(doc))
        };
        let mut doc = Self {
            path,
            text,
            value,
            spans,
            schema,
            problems: Vec::new(),
            non_finite: false,
            structural: None,
            placeholders: Vec::new(),
        };
        doc.non_finite_numbers();
        doc.find_placeholders();
        Ok(doc)
    }

    /// TOML allows nan and inf (JSON does not: its parser refuses them as
    /// syntax); converted for reading they become nulls, which would give
    /// "invalid type: null" or a missing key, and a whole section failing
    /// for one number (one bad channel `scale` then brought a false
    /// "needs a time base" for every run). Each is a problem naming the key
    /// and its text, and the value is read as 1 so that the rest of its
    /// section is still checked.
    fn non_finite_numbers(&mut self) {
        fn walk(v: &mut Value, path: KeyPath, found: &mut Vec<KeyPath>) {
            match v {
                Value::Null => {
                    *v = Value::from(1.0);
                    found.push(path);
                }
                Value::Object(map) => {
                    for (k, x) in map.iter_mut() {
                        walk(x, path.key(k), found);
                    }
                }
                Value::Array(items) => {
                    for (i, x) in items.iter_mut().enumerate() {
                        walk(x, path.index(i), found);
                    }
                }
                _ => {}
            }
        }
        if self.spans.is_none() {
            // JSON: a null is the manifest's own, judged by its key's type.
            return;
        }
        let mut found = Vec::new();
        walk(&mut self.value, KeyPath::root(), &mut found);
        // The number as written, from the TOML itself.
        let toml: Option<toml::Value> = toml::from_str(self.text).ok();
        for path in found {
            let raw = toml
                .as_ref()
                .and_then(|t| toml_at(t, &path))
                .and_then(toml::Value::as_float)
                .map_or("nan or inf".to_string(), |x| {
                    if x.is_nan() {
                        "nan".to_string()
                    } else {
                        x.to_string()
                    }
                });
            self.problems.push(Problem::new(
                path,
                format!("{raw} is not a finite number: give a finite value"),
            ));
            self.non_finite = true;
        }
    }

    /// Every string that is a placeholder `servoid init` wrote, by key.
    fn find_placeholders(&mut self) {
        fn walk(v: &Value, path: KeyPath, found: &mut Vec<Problem>) {
            match v {
                Value::String(text) => {
                    if let Some(rest) = text.strip_prefix(super::scaffold::PLACEHOLDER) {
                        let what = rest.trim_start();
                        found.push(Problem {
                            placeholder: true,
                            ..Problem::new(path, format!("a placeholder to fill: {what}"))
                        });
                    }
                }
                Value::Object(map) => {
                    for (k, x) in map {
                        walk(x, path.key(k), found);
                    }
                }
                Value::Array(items) => {
                    for (i, x) in items.iter().enumerate() {
                        walk(x, path.index(i), found);
                    }
                }
                _ => {}
            }
        }
        walk(&self.value, KeyPath::root(), &mut self.placeholders);
    }

    /// Marks where the checks across keys begin (ranges, one key against
    /// another, logs on disk). When a number was nan or inf, the problems
    /// those checks find are dropped: they would judge the stand-in value,
    /// not the manifest's. They run again once the numbers are finite.
    pub fn begin_checks(&mut self) {
        self.structural = Some(self.problems.len());
    }

    /// Required top-level keys are present and no unknown ones are.
    pub fn check_top_level(&mut self) {
        let root = KeyPath::root();
        let Some(obj) = self.value.as_object() else {
            self.problems.push(Problem::new(
                root,
                "the manifest must be a table of sections",
            ));
            return;
        };
        for key in required_keys(&self.schema) {
            if !obj.contains_key(&key) {
                let what = match key.as_str() {
                    "schema_version" => "required key is missing: add schema_version = 1".into(),
                    "runs" => "required runs are missing: add [[runs]] tables".into(),
                    _ => format!("required section is missing: add a [{key}] table"),
                };
                self.problems.push(Problem::new(root.key(&key), what));
            }
        }
        let known = known_keys(&self.schema, &root);
        for key in obj.keys() {
            if !known.contains(key) {
                self.problems.push(unknown_key(&self.schema, &root, key));
            }
        }
    }

    /// Whether the document has the top-level key `key`, whatever its value.
    pub fn has(&self, key: &str) -> bool {
        self.value.get(key).is_some()
    }

    /// A top-level section; None when absent or when it failed (the problem is recorded).
    pub fn section<T: DeserializeOwned>(&mut self, key: &str) -> Option<T> {
        let v = self.value.get(key)?.clone();
        section(
            &v,
            &KeyPath::root().key(key),
            &self.schema,
            &mut self.problems,
        )
    }

    /// A top-level array of tables, each element deserialized on its own.
    pub fn array<T: DeserializeOwned>(&mut self, key: &str) -> Vec<Option<T>> {
        let path = KeyPath::root().key(key);
        let Some(v) = self.value.get(key).cloned() else {
            return Vec::new();
        };
        let Some(items) = v.as_array() else {
            self.problems.push(Problem::new(
                path,
                format!("must be an array of tables ([[{key}]])"),
            ));
            return Vec::new();
        };
        items
            .iter()
            .enumerate()
            .map(|(i, item)| section(item, &path.index(i), &self.schema, &mut self.problems))
            .collect()
    }

    /// One field of every element of a top-level array, read leniently (None
    /// where absent or of another type), for cross-element checks.
    pub fn raw<T: DeserializeOwned>(&self, array: &str, field: &str) -> Vec<Option<T>> {
        self.value
            .get(array)
            .and_then(Value::as_array)
            .map(|items| {
                items
                    .iter()
                    .map(|r| {
                        r.get(field)
                            .and_then(|x| serde_json::from_value(x.clone()).ok())
                    })
                    .collect()
            })
            .unwrap_or_default()
    }

    /// The result when there is no problem; else every problem, with run ids,
    /// lines and columns, in file order.
    pub fn finish<R>(mut self, result: Option<R>) -> Result<R, ManifestError> {
        // While `servoid init`'s placeholders are left (the manifest's, and
        // a run table's cells), they are the problems, with the table's
        // cells' own (an empty id, a number that does not read), which no
        // placeholder causes: the rest follow from them.
        let placeholder_cells = self.problems.iter().any(|p| p.placeholder);
        if !self.placeholders.is_empty() || placeholder_cells {
            let cells: Vec<Problem> = self
                .problems
                .iter()
                .filter(|p| {
                    p.placeholder
                        || p.table
                            .as_ref()
                            .is_some_and(|t| t.row.is_some() && t.column.is_some())
                })
                .cloned()
                .collect();
            self.problems = std::mem::take(&mut self.placeholders);
            self.problems.extend(cells);
        }
        if let (true, Some(r)) = (self.problems.is_empty(), result) {
            return Ok(r);
        }
        if let (true, Some(n)) = (self.non_finite, self.structural) {
            self.problems.truncate(n);
        }
        // A misspelt key also leaves the key it meant missing: the
        // unknown key's suggestion says it all, so the missing key's own
        // problem (required, or needed by the run's role) is dropped.
        let meant: Vec<KeyPath> = self
            .problems
            .iter()
            .filter_map(|p| p.meant.clone())
            .collect();
        self.problems.retain(|p| !meant.contains(&p.path));
        for p in self.problems.iter_mut() {
            if p.run.is_none()
                && let Some(i) = p.path.run_index()
            {
                p.run = self
                    .value
                    .get("runs")
                    .and_then(|r| r.get(i))
                    .and_then(|r| r.get("id"))
                    .and_then(|id| id.as_str())
                    .map(str::to_string);
            }
            if let Some(doc) = &self.spans {
                p.line_col = span_of(doc, &p.path).map(|s| line_col(self.text, s.start));
            }
        }
        let mut problems = self.problems;
        problems.sort_by(|a, b| {
            a.line_col
                .unwrap_or((usize::MAX, 0))
                .cmp(&b.line_col.unwrap_or((usize::MAX, 0)))
                .then(a.path.cmp(&b.path))
                // A run table's problems by row, each row's by column.
                .then(a.table.cmp(&b.table))
        });
        problems.dedup();
        if problems.is_empty() {
            // Validation produced nothing yet no result: never expected, but say so.
            problems.push(Problem::new(KeyPath::root(), "the manifest is incomplete"));
        }
        Err(ManifestError::Invalid {
            file: self.path.to_path_buf(),
            problems,
        })
    }
}

/// serde_json's message without its own "at line L column C" (the place
/// is given once, before it), and what to do where the text is a number
/// JSON does not have.
fn json_message(e: &serde_json::Error, text: &str, (line, column): (usize, usize)) -> String {
    let full = e.to_string();
    let suffix = format!(" at line {line} column {column}");
    let message = full.strip_suffix(&suffix).unwrap_or(&full).to_string();
    let here = text
        .lines()
        .nth(line.saturating_sub(1))
        .and_then(|l| l.get(column.saturating_sub(1)..))
        .unwrap_or("");
    for word in ["NaN", "Infinity", "-Infinity", "nan", "inf", "-inf"] {
        if here.starts_with(word) {
            return format!("{message}: {word} is not a JSON number; give a finite value");
        }
    }
    message
}

/// The TOML value at `path`.
fn toml_at<'t>(root: &'t toml::Value, path: &KeyPath) -> Option<&'t toml::Value> {
    path.0.iter().try_fold(root, |v, seg| match seg {
        Seg::Key(k) => v.get(k.as_str()),
        Seg::Index(i) => v.get(*i),
    })
}

/// How the toml crate hands a TOML date or time to serde: a map with this
/// one key, whose value is the date's text.
const TOML_DATETIME: &str = "$__toml_private_datetime";

/// Every TOML date and time (`date = 2024-05-01`, unquoted) as its text, as
/// if quoted: the manifest reads dates as strings and checks them itself.
fn datetimes_as_text(v: &mut Value) {
    match v {
        Value::Object(map) => {
            if map.len() == 1
                && let Some(Value::String(text)) = map.get(TOML_DATETIME)
            {
                *v = Value::String(text.clone());
                return;
            }
            map.values_mut().for_each(datetimes_as_text);
        }
        Value::Array(items) => items.iter_mut().for_each(datetimes_as_text),
        _ => {}
    }
}

/// Deserialize one section, collecting its unknown keys and its first type error.
fn section<T: DeserializeOwned>(
    value: &Value,
    base: &KeyPath,
    schema: &Value,
    problems: &mut Vec<Problem>,
) -> Option<T> {
    let mut unknown: Vec<KeyPath> = Vec::new();
    let result: Result<T, _> = {
        let mut record = |p: serde_ignored::Path<'_>| unknown.push(from_ignored(&p));
        let de = serde_ignored::Deserializer::new(value.clone(), &mut record);
        serde_path_to_error::deserialize(de)
    };
    for u in unknown {
        let full = base.join(&u);
        let parent = full.parent();
        let name = match full.0.last() {
            Some(Seg::Key(k)) => k.clone(),
            _ => String::new(),
        };
        problems.push(unknown_key(schema, &parent, &name));
    }
    match result {
        Ok(v) => Some(v),
        Err(e) => {
            let mut path = base.join(&from_error_path(e.path()));
            let raw = e.inner().to_string();
            let message = if let Some(field) = raw
                .strip_prefix("missing field `")
                .and_then(|r| r.strip_suffix('`'))
            {
                path = path.key(field);
                "required key is missing".to_string()
            } else if raw.contains("untagged enum Column") {
                "expected a column name (string) or a 0-based column index (integer)".to_string()
            } else {
                plain_type_error(&raw).unwrap_or(raw)
            };
            problems.push(Problem::new(path, message));
            None
        }
    }
}

/// serde's "invalid type: string \"one\", expected f64" said as a lab
/// engineer would: "must be a number, not the string \"one\"".
fn plain_type_error(raw: &str) -> Option<String> {
    let rest = raw
        .strip_prefix("invalid type: ")
        .or_else(|| raw.strip_prefix("invalid value: "))?;
    let (got, expected) = rest.split_once(", expected ")?;
    let wanted = match expected {
        "f64" | "f32" => "a number",
        "u8" | "u16" | "u32" | "u64" | "usize" => "a whole number, 0 or more",
        "i8" | "i16" | "i32" | "i64" | "isize" => "a whole number",
        "a boolean" => "true or false",
        "a string" => "text in quotes",
        "a sequence" => "an array [...]",
        _ => return None,
    };
    Some(format!("must be {wanted}, not the {got}"))
}

fn unknown_key(schema: &Value, parent: &KeyPath, name: &str) -> Problem {
    let known = known_keys(schema, parent);
    let hint = suggest(&known, name);
    let mut p = Problem::new(parent.key(name), format!("unknown key `{name}`{hint}"));
    p.meant = closest(&known, name).map(|k| parent.key(k));
    p
}

/// The one of `known` closest to `name`, if any is close.
pub(super) fn closest<'k>(known: &'k [impl AsRef<str>], name: &str) -> Option<&'k str> {
    known
        .iter()
        .map(|k| (strsim::jaro_winkler(k.as_ref(), name), k.as_ref()))
        .filter(|(score, _)| *score > 0.85)
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, k)| k)
}

/// What to say after an unknown `name`: the closest of `known`
/// (`; did you mean `x`?`), else the list of them, else nothing.
pub(super) fn suggest(known: &[impl AsRef<str>], name: &str) -> String {
    match closest(known, name) {
        Some(k) => format!("; did you mean `{k}`?"),
        None if !known.is_empty() => {
            let names: Vec<&str> = known.iter().map(AsRef::as_ref).collect();
            format!("; expected one of: {}", names.join(", "))
        }
        None => String::new(),
    }
}

fn from_ignored(p: &serde_ignored::Path<'_>) -> KeyPath {
    use serde_ignored::Path as P;
    match p {
        P::Root => KeyPath::root(),
        P::Seq { parent, index } => from_ignored(parent).index(*index),
        P::Map { parent, key } => from_ignored(parent).key(key),
        P::Some { parent } | P::NewtypeStruct { parent } | P::NewtypeVariant { parent } => {
            from_ignored(parent)
        }
    }
}

fn from_error_path(p: &serde_path_to_error::Path) -> KeyPath {
    use serde_path_to_error::Segment;
    let mut out = KeyPath::root();
    for seg in p.iter() {
        out = match seg {
            Segment::Seq { index } => out.index(*index),
            Segment::Map { key } => out.key(key),
            Segment::Enum { variant } => out.key(variant),
            Segment::Unknown => out,
        };
    }
    out
}

/// The object schemas a schema node stands for, following `$ref` and
/// `anyOf`/`oneOf`/`allOf` (Option<T> is `anyOf [T, null]`).
fn resolve<'a>(root: &'a Value, node: &'a Value, out: &mut Vec<&'a Value>) {
    if let Some(r) = node.get("$ref").and_then(Value::as_str) {
        let name = r.trim_start_matches("#/$defs/");
        if let Some(target) = root.get("$defs").and_then(|d| d.get(name)) {
            resolve(root, target, out);
        }
        return;
    }
    let mut branched = false;
    for key in ["anyOf", "oneOf", "allOf"] {
        if let Some(list) = node.get(key).and_then(Value::as_array) {
            branched = true;
            for n in list {
                resolve(root, n, out);
            }
        }
    }
    if !branched || node.get("properties").is_some() || node.get("items").is_some() {
        out.push(node);
    }
}

/// The keys the schema allows at `path`.
fn known_keys(schema: &Value, path: &KeyPath) -> Vec<String> {
    let mut nodes = Vec::new();
    resolve(schema, schema, &mut nodes);
    for seg in &path.0 {
        let mut next = Vec::new();
        for n in &nodes {
            let child = match seg {
                Seg::Key(k) => n.get("properties").and_then(|p| p.get(k)),
                Seg::Index(_) => n.get("items"),
            };
            if let Some(c) = child {
                resolve(schema, c, &mut next);
            }
        }
        nodes = next;
    }
    let mut keys: Vec<String> = nodes
        .iter()
        .filter_map(|n| n.get("properties").and_then(Value::as_object))
        .flat_map(|p| p.keys().cloned())
        .collect();
    keys.sort();
    keys.dedup();
    keys
}

fn required_keys(schema: &Value) -> Vec<String> {
    schema
        .get("required")
        .and_then(Value::as_array)
        .map(|a| {
            a.iter()
                .filter_map(|v| v.as_str().map(str::to_string))
                .collect()
        })
        .unwrap_or_default()
}

/// Byte span of the key (or, failing that, the nearest enclosing item) a path
/// points at.
fn span_of(doc: &toml_edit::Document<&str>, path: &KeyPath) -> Option<Range<usize>> {
    use toml_edit::{Item, Value as TV};
    let mut item: &Item = doc.as_item();
    let mut best: Option<Range<usize>> = None;
    for (i, seg) in path.0.iter().enumerate() {
        let last = i + 1 == path.0.len();
        let next = match seg {
            Seg::Key(k) => {
                let kv = match item {
                    Item::Table(t) => t.get_key_value(k),
                    Item::Value(TV::InlineTable(t)) => t.get_key_value(k),
                    _ => None,
                };
                match kv {
                    Some((key, it)) => {
                        let key_span = key.span();
                        best = if last {
                            key_span.or_else(|| it.span()).or(best)
                        } else {
                            it.span().or(key_span).or(best)
                        };
                        it
                    }
                    None => return best,
                }
            }
            Seg::Index(n) => match item.get(*n) {
                Some(it) => {
                    best = it.span().or(best);
                    it
                }
                None => return best,
            },
        };
        item = next;
    }
    best
}

/// 1-based line and column of a byte offset.
fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let offset = offset.min(text.len());
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let col = before.rfind('\n').map_or(before.chars().count(), |nl| {
        before[nl + 1..].chars().count()
    }) + 1;
    (line, col)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_col_counts_from_one() {
        let t = "a = 1\nbb = 2\n";
        assert_eq!(line_col(t, 0), (1, 1));
        assert_eq!(line_col(t, 6), (2, 1));
        assert_eq!(line_col(t, 9), (2, 4));
    }

    #[test]
    fn schema_knows_the_keys_of_a_run_specimen() {
        let schema = super::super::raw::manifest_schema();
        let keys = known_keys(&schema, &KeyPath::parse("runs[0].specimen"));
        assert!(keys.contains(&"stiffness_n_per_m".to_string()), "{keys:?}");
        assert!(keys.contains(&"mass_kg".to_string()));
        let top = known_keys(&schema, &KeyPath::root());
        assert!(top.contains(&"runs".to_string()));
    }
}
