//! Scale-out on a real Slurm cluster: scripts/slurm-shards.sh starts
//! munge, slurmctld and slurmd as a one-node cluster, runs the bundled
//! default as an array job of three `servoid run --shard i/3` tasks
//! (`sbatch --wait --array`), merges them and compares the merge with one
//! run. Here the comparison is made again, file by file, independently of
//! the script's `diff -r`.
//!
//! It needs Debian's slurm-wlm and munge and root. Where they are missing
//! the test says SKIPPED with the install command, unless
//! `SERVOID_REQUIRE_SLURM` is set (`.ci/run` installs them and sets it).

use std::process::Command;

use crate::shards::campaign;
use crate::util::{outputs, root, scratch, skip_unless_required};

const REQUIRE_SLURM: &str = "SERVOID_REQUIRE_SLURM";
const SHARDS: usize = 3;

/// Why this machine cannot run the cluster, if it cannot.
fn missing() -> Option<String> {
    let absent: Vec<&str> = ["munged", "slurmctld", "slurmd", "sbatch", "sinfo"]
        .into_iter()
        .filter(|cmd| {
            !Command::new("sh")
                .args(["-c", &format!("command -v {cmd}")])
                .output()
                .is_ok_and(|o| o.status.success())
        })
        .collect();
    if !absent.is_empty() {
        return Some(format!(
            "{} missing (apt-get install -y slurm-wlm munge)",
            absent.join(", ")
        ));
    }
    let uid = Command::new("id").arg("-u").output().ok()?;
    (String::from_utf8_lossy(&uid.stdout).trim() != "0")
        .then(|| "needs root to start slurmd".to_string())
}

#[test]
fn an_array_job_on_a_slurm_cluster_merges_to_the_single_run() {
    if let Some(why) = missing() {
        return skip_unless_required("slurm", REQUIRE_SLURM, &why);
    }
    let dir = scratch();
    let manifest = campaign(dir.path());
    let work = dir.path().join("work");
    let out = Command::new(root().join("scripts/slurm-shards.sh"))
        .arg(env!("CARGO_BIN_EXE_servoid"))
        .arg(&manifest)
        .arg(SHARDS.to_string())
        .arg(&work)
        .output()
        .expect("scripts/slurm-shards.sh runs");
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert!(
        out.status.success(),
        "slurm-shards.sh failed ({}):\n{stdout}\n{stderr}",
        out.status
    );

    // Each array task ran under Slurm and wrote its own share.
    for i in 0..SHARDS {
        let shard: serde_json::Value = serde_json::from_slice(
            &std::fs::read(work.join(format!("shard-{i}/shard.json"))).unwrap(),
        )
        .unwrap();
        assert_eq!(shard["shard"]["index"], i, "shard-{i}/shard.json");
        assert_eq!(shard["shard"]["count"], SHARDS, "shard-{i}/shard.json");
    }
    // slurmctld saw every task of the array finish with exit status 0.
    let log = std::fs::read_to_string(work.join("cluster/slurmctld.log")).unwrap();
    for i in 0..SHARDS {
        assert!(
            log.lines()
                .any(|l| l.contains(&format!("_{i}(")) && l.contains("WEXITSTATUS 0")),
            "slurmctld.log shows no successful array task {i}:\n{log}"
        );
    }

    let (single, merged) = (outputs(&work.join("single")), outputs(&work.join("merged")));
    let names = |v: &[(String, Vec<u8>)]| v.iter().map(|(n, _)| n.clone()).collect::<Vec<_>>();
    assert_eq!(names(&single), names(&merged), "the same files");
    assert!(single.iter().any(|(n, _)| n == "results.json"));
    for ((name, a), (_, b)) in single.iter().zip(&merged) {
        assert!(a == b, "{name} differs between the merge and one run");
    }
}
