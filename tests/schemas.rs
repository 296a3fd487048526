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

/// docs/keys.md is `servoid keys` as the code stands: a key added, removed
/// or documented anew in a manifest type changes the schema and fails this
/// until the reference is regenerated.
#[test]
fn the_key_reference_is_current() {
    let dir = scratch();
    let o = servoid(dir.path(), &["keys"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    let committed = std::fs::read_to_string(root().join("docs/keys.md"))
        .expect("docs/keys.md exists; write it with `cargo run --release -- keys > docs/keys.md`");
    assert!(
        o.stdout == committed,
        "docs/keys.md is stale; regenerate it with `cargo run --release -- keys > docs/keys.md`"
    );
    // Every key the manifest's schema names at its top level is there.
    let schema: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(root().join("schemas/manifest.schema.json")).unwrap(),
    )
    .unwrap();
    for key in schema["properties"].as_object().unwrap().keys() {
        assert!(
            committed.contains(&format!("| `{key}` |")),
            "{key} is not in docs/keys.md"
        );
    }
}
