//! A disk that fills up during a night: the run stops with an error that
//! names the run and the file it could not write, leaves no temporary file
//! behind, and the previous night's results.json and report.html keep
//! their bytes (documents are replaced only after everything they refer
//! to was written).
//!
//! The output folder is a small tmpfs mounted in a private mount
//! namespace (`unshare -m`, util-linux), as root or in a user namespace.
//! Where neither can be made the test says SKIPPED, unless
//! `SERVOID_REQUIRE_NAMESPACES` is set (`.ci/run` sets it).

use std::path::Path;
use std::process::Command;

use crate::shards::campaign;
use crate::util::{scratch, servoid_into, skip_unless_required};

const REQUIRE: &str = "SERVOID_REQUIRE_NAMESPACES";

/// The `unshare` arguments that give a private mount namespace here.
fn namespace() -> Option<&'static [&'static str]> {
    [&["-m"][..], &["-r", "-m"][..]].into_iter().find(|args| {
        Command::new("unshare")
            .args(*args)
            .args(["sh", "-c", "mount -t tmpfs -o size=64k none /mnt"])
            .output()
            .is_ok_and(|o| o.status.success())
    })
}

/// Kilobytes a folder takes (`du -sk`).
fn kb(dir: &Path) -> u64 {
    let o = Command::new("du").arg("-sk").arg(dir).output().unwrap();
    String::from_utf8_lossy(&o.stdout)
        .split_whitespace()
        .next()
        .and_then(|v| v.parse().ok())
        .unwrap()
}

#[test]
fn a_full_disk_fails_the_night_and_keeps_the_previous_report() {
    let Some(unshare) = namespace() else {
        return skip_unless_required(
            "disk full",
            REQUIRE,
            "no private mount namespace to mount a tmpfs in (unshare -m, as root)",
        );
    };
    let dir = scratch();
    let manifest = campaign(dir.path());
    // How much the night writes without figures and with them, measured
    // on the scratch disk: the tmpfs holds the first and not the second.
    let sizes: Vec<u64> = ["none", "all"]
        .iter()
        .map(|figures| {
            let out = dir.path().join(format!("size-{figures}"));
            let o = servoid_into(
                dir.path(),
                "run",
                &manifest,
                &out,
                &["--figures", figures, "--quiet"],
            );
            assert_eq!(o.code, 0, "{}", o.stderr);
            kb(&out)
        })
        .collect();
    assert!(sizes[1] > sizes[0] + 1024, "{sizes:?}");
    let size_kb = (sizes[0] + sizes[1]) / 2;

    let (mnt, save) = (dir.path().join("mnt"), dir.path().join("save"));
    std::fs::create_dir_all(&mnt).unwrap();
    std::fs::create_dir_all(&save).unwrap();
    let servoid = env!("CARGO_BIN_EXE_servoid");
    let m = manifest.display();
    let (mn, sv) = (mnt.display(), save.display());
    let script = format!(
        r#"set -u
mount -t tmpfs -o size={size_kb}k none "{mn}" || exit 99
"{servoid}" run "{m}" --out "{mn}/out" --figures none --quiet; echo $? > "{sv}/first.code"
cp -a "{mn}/out" "{sv}/first"
"{servoid}" run "{m}" --out "{mn}/out" --force --quiet 2> "{sv}/second.err"; echo $? > "{sv}/second.code"
cp -a "{mn}/out" "{sv}/second"
"#
    );
    let o = Command::new("unshare")
        .args(unshare)
        .args(["sh", "-c", &script])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let read = |name: &str| std::fs::read_to_string(save.join(name)).unwrap();
    assert_eq!(read("first.code").trim(), "0", "the first night fits");
    assert_eq!(read("second.code").trim(), "1", "{}", read("second.err"));

    // The error says what could not be written, for which run, and why.
    let err = read("second.err");
    assert!(
        err.starts_with("error: cannot write the outputs: run "),
        "{err}"
    );
    assert!(err.contains(&format!("{}/out/", mnt.display())), "{err}");
    assert!(err.contains("No space left on device"), "{err}");

    // The previous night's documents are the bytes they were.
    for doc in ["results.json", "report.html", "history.parquet"] {
        assert!(
            std::fs::read(save.join("first").join(doc)).unwrap()
                == std::fs::read(save.join("second").join(doc)).unwrap(),
            "{doc} changed"
        );
    }
    // No temporary file is left behind.
    let mut stray = Vec::new();
    let mut stack = vec![save.join("second")];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(d).unwrap().flatten() {
            if e.path().is_dir() {
                stack.push(e.path());
            } else if e.file_name().to_string_lossy().contains(".tmp-") {
                stray.push(e.path());
            }
        }
    }
    assert!(stray.is_empty(), "{stray:?}");
}
