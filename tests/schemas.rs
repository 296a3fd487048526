//! The committed JSON Schemas are generated from the Rust types; this fails
//! when they are stale (regenerate with `cargo run --release -- schema`).

use crate::util::{root, scratch, servoid};

#[test]
fn committed_schemas_are_current() {
    let dir = scratch();
    let o = servoid(dir.path(), &["schema", "--out-dir", "fresh"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    for name in [
        "manifest.schema.json",
        "results.schema.json",
        "simulation.schema.json",
    ] {
        let fresh = std::fs::read_to_string(dir.path().join("fresh").join(name)).unwrap();
        let committed = std::fs::read_to_string(root().join("schemas").join(name))
            .unwrap_or_else(|_| panic!("schemas/{name} is missing; run `servoid schema`"));
        assert!(
            fresh == committed,
            "schemas/{name} is stale; regenerate it with `cargo run --release -- schema`"
        );
    }
}

#[test]
fn schemas_reject_unknown_keys() {
    let text = std::fs::read_to_string(root().join("schemas/manifest.schema.json")).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(v["additionalProperties"], false);
    assert_eq!(v["$defs"]["Run"]["additionalProperties"], false);
}
