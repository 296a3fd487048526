//! JSON Schemas generated from the Rust types: the manifest (input) and
//! results.json (output). The committed files under `schemas/` are written by
//! `servoid schema` and a test fails when they are stale; never edit them.

use std::sync::OnceLock;

use serde_json::Value;

use crate::manifest::Manifest;
use crate::manifest::simulation::SimulationManifest;
use crate::results::Results;

/// File names under `schemas/`, with their generators.
pub fn all() -> Vec<(&'static str, Value)> {
    vec![
        ("manifest.schema.json", manifest_schema()),
        ("results.schema.json", results_schema()),
        ("simulation.schema.json", simulation_schema()),
    ]
}

/// The manifest schema (cached: the loader consults it for key suggestions).
pub fn manifest_schema() -> Value {
    static CACHE: OnceLock<Value> = OnceLock::new();
    CACHE
        .get_or_init(|| {
            serde_json::to_value(schemars::schema_for!(Manifest)).expect("schema serialises")
        })
        .clone()
}

/// The simulation manifest schema (cached, as the manifest's).
pub fn simulation_schema() -> Value {
    static CACHE: OnceLock<Value> = OnceLock::new();
    CACHE
        .get_or_init(|| {
            serde_json::to_value(schemars::schema_for!(SimulationManifest))
                .expect("schema serialises")
        })
        .clone()
}

/// The results.json schema.
pub fn results_schema() -> Value {
    serde_json::to_value(schemars::schema_for!(Results)).expect("schema serialises")
}

/// Pretty JSON with a trailing newline, as committed.
pub fn render(v: &Value) -> String {
    let mut s = serde_json::to_string_pretty(v).expect("JSON value serialises");
    s.push('\n');
    s
}
