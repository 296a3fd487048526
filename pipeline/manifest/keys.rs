//! The manifests' key reference (docs/keys.md), generated from their JSON
//! Schemas as the man page is from the command line's definition: every
//! key with its value, default and meaning, the meaning being the doc
//! comment of the field that reads it. `servoid keys` prints it.

use serde_json::{Map, Value};

/// The key reference of both manifests, as markdown.
pub fn key_reference() -> String {
    let mut out = String::from(
        "# Manifest keys\n\n\
         Every key of the two manifests, generated from their JSON Schemas \
         (`schemas/`) by `servoid keys > docs/keys.md`; a test fails when this \
         file and the code disagree. The guide to writing a manifest is \
         [manifest.md](manifest.md). A key under `runs[]` is a key of each \
         `[[runs]]` table. A value in quotes is one of the strings the key \
         accepts; a default of `null` means the key is optional and has no \
         value unless given.\n",
    );
    section(
        &mut out,
        "The campaign manifest (`servoid run`, `servoid check`)",
        &super::raw::manifest_schema(),
    );
    section(
        &mut out,
        "The simulation manifest (`servoid simulate`)",
        &super::simulation::simulation_schema(),
    );
    out
}

fn section(out: &mut String, title: &str, schema: &Value) {
    let defs = schema.get("$defs").and_then(Value::as_object);
    let empty = Map::new();
    let keys = Keys {
        defs: defs.unwrap_or(&empty),
    };
    out.push_str(&format!(
        "\n## {title}\n\n| key | value | default | meaning |\n|---|---|---|---|\n"
    ));
    let mut rows = Vec::new();
    keys.walk("", schema, &mut Vec::new(), &mut rows);
    for r in rows {
        out.push_str(&r);
        out.push('\n');
    }
}

struct Keys<'a> {
    defs: &'a Map<String, Value>,
}

impl<'a> Keys<'a> {
    /// `v` with a `$ref` followed.
    fn resolve(&self, v: &'a Value) -> &'a Value {
        match v.get("$ref").and_then(Value::as_str) {
            Some(r) => self.defs.get(r.trim_start_matches("#/$defs/")).unwrap_or(v),
            None => v,
        }
    }

    /// `v` without the `null` an optional key also accepts, resolved.
    fn value(&self, v: &'a Value) -> &'a Value {
        if let Some(any) = v.get("anyOf").and_then(Value::as_array) {
            let some: Vec<&Value> = any.iter().filter(|a| a["type"] != "null").collect();
            if let [only] = some[..] {
                return self.resolve(only);
            }
        }
        self.resolve(v)
    }

    /// One row per key of `schema`'s tables under `prefix`, depth first;
    /// `seen` holds the definitions being walked (a type that contains
    /// itself is listed once).
    fn walk(
        &self,
        prefix: &str,
        schema: &'a Value,
        seen: &mut Vec<&'a str>,
        rows: &mut Vec<String>,
    ) {
        let Some(props) = schema.get("properties").and_then(Value::as_object) else {
            return;
        };
        let required: Vec<&str> = schema
            .get("required")
            .and_then(Value::as_array)
            .map(|r| r.iter().filter_map(Value::as_str).collect())
            .unwrap_or_default();
        for (name, prop) in props {
            let key = if prefix.is_empty() {
                name.clone()
            } else {
                format!("{prefix}.{name}")
            };
            let target = self.value(prop);
            let (inner, table_key) = match target.get("items") {
                Some(items) if target["type"] == "array" => (self.value(items), format!("{key}[]")),
                _ => (target, key.clone()),
            };
            rows.push(self.row(&key, prop, target, required.contains(&name.as_str())));
            let def = self
                .def_name(prop)
                .or_else(|| target.get("items").and_then(|i| self.def_name(i)));
            if inner.get("properties").is_some() && !def.is_some_and(|d| seen.contains(&d)) {
                seen.extend(def);
                self.walk(&table_key, inner, seen, rows);
                if def.is_some() {
                    seen.pop();
                }
            }
        }
    }

    /// The definition a property refers to, directly or as an option.
    fn def_name(&self, v: &'a Value) -> Option<&'a str> {
        let r = v.get("$ref").or_else(|| {
            v.get("anyOf")?
                .as_array()?
                .iter()
                .find_map(|a| a.get("$ref"))
        })?;
        r.as_str().map(|r| r.trim_start_matches("#/$defs/"))
    }

    fn row(&self, key: &str, prop: &Value, target: &Value, required: bool) -> String {
        let kind = self.kind(target);
        let default = match prop.get("default") {
            // A table's defaults are its keys'.
            Some(_) if kind == "table" => String::new(),
            Some(d) => format!("`{}`", serde_json::to_string(d).unwrap_or_default()),
            None if required => "required".to_string(),
            None => String::new(),
        };
        let mut meaning = text(
            prop.get("description")
                .or_else(|| target.get("description")),
        );
        let choices = self.choices(target);
        if choices.iter().any(|(_, d)| !d.is_empty()) {
            let said: Vec<String> = choices
                .iter()
                .map(|(v, d)| {
                    if d.is_empty() {
                        format!("`{v}`")
                    } else {
                        format!("`{v}`: {}", d.trim_end_matches('.'))
                    }
                })
                .collect();
            meaning = format!("{meaning} Values: {}.", said.join("; "));
        }
        format!(
            "| `{key}` | {} | {default} | {} |",
            cell(&kind),
            cell(meaning.trim())
        )
    }

    /// The strings a key accepts, with what each means, when it is one of
    /// a list.
    fn choices(&self, v: &Value) -> Vec<(String, String)> {
        let v = self.resolve(v);
        if let Some(e) = v.get("enum").and_then(Value::as_array) {
            return e
                .iter()
                .map(|c| (c.as_str().unwrap_or_default().to_string(), String::new()))
                .collect();
        }
        if let Some(c) = v.get("const") {
            return vec![(
                c.as_str().unwrap_or_default().to_string(),
                text(v.get("description")),
            )];
        }
        let alternatives = v
            .get("oneOf")
            .or_else(|| v.get("anyOf"))
            .and_then(Value::as_array);
        match alternatives {
            Some(alts) => {
                let each: Vec<Vec<(String, String)>> = alts
                    .iter()
                    .filter(|a| a["type"] != "null")
                    .map(|a| self.choices(a))
                    .collect();
                if each.iter().all(|c| !c.is_empty()) {
                    each.into_iter().flatten().collect()
                } else {
                    Vec::new()
                }
            }
            None => Vec::new(),
        }
    }

    /// What a key's value is, in a few words.
    fn kind(&self, v: &Value) -> String {
        let v = self.resolve(v);
        let choices = self.choices(v);
        if !choices.is_empty() {
            return choices
                .iter()
                .map(|(c, _)| format!("\"{c}\""))
                .collect::<Vec<_>>()
                .join(" or ");
        }
        if let Some(alts) = v
            .get("oneOf")
            .or_else(|| v.get("anyOf"))
            .and_then(Value::as_array)
        {
            return alts
                .iter()
                .filter(|a| a["type"] != "null")
                .map(|a| self.kind(a))
                .collect::<Vec<_>>()
                .join(" or ");
        }
        let ty = match v.get("type") {
            Some(Value::Array(types)) => types
                .iter()
                .filter_map(Value::as_str)
                .find(|t| *t != "null")
                .unwrap_or("any"),
            Some(Value::String(t)) => t.as_str(),
            _ => "any",
        };
        match ty {
            "array" => {
                let item = v
                    .get("items")
                    .map_or("any".to_string(), |i| self.kind(self.value(i)));
                match (v.get("minItems"), v.get("maxItems")) {
                    (Some(a), Some(b)) if a == b => {
                        let n = a.as_u64().unwrap_or(0) as usize;
                        format!("[{}]", vec![item; n].join(", "))
                    }
                    _ => format!("array of {item}"),
                }
            }
            "object" if v.get("properties").is_some() => "table".to_string(),
            "object" => match v.get("additionalProperties") {
                Some(a) if a.is_object() => format!("table of {}", self.kind(self.value(a))),
                _ => "table".to_string(),
            },
            "integer" if v.get("minimum") == Some(&Value::from(0)) => "integer >= 0".to_string(),
            t => t.to_string(),
        }
    }
}

/// A doc comment's text on one line.
fn text(v: Option<&Value>) -> String {
    v.and_then(Value::as_str)
        .unwrap_or_default()
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
}

/// Text safe inside a markdown table cell.
fn cell(s: &str) -> String {
    s.replace('|', "\\|")
}
