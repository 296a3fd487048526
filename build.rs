//! The commit `servoid --version` names: `git rev-parse --short=12 HEAD` at
//! build time, with "+modified" when the sources differ from it, or
//! "unknown" outside a git checkout (a source tarball). The build script
//! reruns when the checkout moves (a commit or a checkout changes
//! `logs/HEAD`) or a source changes.

use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    let out = Command::new("git").args(args).output().ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

fn main() {
    for path in ["pipeline", "Cargo.toml", "Cargo.lock", "build.rs"] {
        println!("cargo:rerun-if-changed={path}");
    }
    let commit = match git(&["rev-parse", "--short=12", "HEAD"]) {
        Some(c) if !c.is_empty() => {
            if let Some(dir) = git(&["rev-parse", "--absolute-git-dir"]) {
                println!("cargo:rerun-if-changed={dir}/logs/HEAD");
                println!("cargo:rerun-if-changed={dir}/HEAD");
            }
            let clean = Command::new("git")
                .args([
                    "diff",
                    "--quiet",
                    "HEAD",
                    "--",
                    "pipeline",
                    "Cargo.toml",
                    "Cargo.lock",
                    "build.rs",
                ])
                .status()
                .is_ok_and(|s| s.success());
            if clean { c } else { format!("{c}+modified") }
        }
        _ => "unknown".to_string(),
    };
    println!("cargo:rustc-env=SERVOID_COMMIT={commit}");
}
