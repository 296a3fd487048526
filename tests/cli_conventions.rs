//! The command line's conventions: shell completions and
//! a man page generated from the clap definitions, `--version` naming the
//! commit, and `NO_COLOR` honoured.

use std::process::{Command, Stdio};

use crate::util::{root, servoid};

const SUBCOMMANDS: [&str; 8] = [
    "run",
    "simulate",
    "merge",
    "verify",
    "check",
    "schema",
    "completions",
    "man",
];

/// Each shell's script names every subcommand; bash's parses (`bash -n`).
#[test]
fn completions_for_bash_zsh_and_fish_name_every_subcommand() {
    for (shell, opening) in [
        ("bash", "_servoid()"),
        ("zsh", "#compdef servoid"),
        ("fish", "complete -c servoid"),
    ] {
        let o = servoid(&root(), &["completions", shell]);
        assert_eq!(o.code, 0, "{shell}: {}", o.stderr);
        assert!(o.stdout.contains(opening), "{shell}: no {opening:?}");
        for sub in SUBCOMMANDS {
            assert!(o.stdout.contains(sub), "{shell}: no `{sub}`");
        }
        if shell == "bash" {
            let dir = crate::util::scratch();
            let script = dir.path().join("servoid.bash");
            std::fs::write(&script, &o.stdout).unwrap();
            let check = Command::new("bash").arg("-n").arg(&script).output();
            if let Ok(c) = check {
                assert!(
                    c.status.success(),
                    "bash -n: {}",
                    String::from_utf8_lossy(&c.stderr)
                );
            }
        }
    }
    let o = servoid(&root(), &["completions", "tcsh"]);
    assert_eq!(o.code, 2, "an unknown shell is a usage error");
    assert!(
        o.stderr.contains("bash") && o.stderr.contains("zsh"),
        "{}",
        o.stderr
    );
}

/// Each subcommand's `--help` opens with what that command does (the
/// words below, written from what each command is for): a description
/// attached to the wrong command shows here.
#[test]
fn each_subcommands_help_opens_with_its_own_description() {
    for (sub, opening) in [
        (&["run"][..], "Run a campaign"),
        (&["simulate"], "Simulate a campaign"),
        (&["merge"], "Merge the folders of `servoid run --shard"),
        (&["verify"], "Rerun the analysis a results.json records"),
        (&["history"], "Edit a rig history"),
        (
            &["history", "remove"],
            "Remove the entries of one date from a history",
        ),
        (&["init"], "Propose a campaign manifest from a lab's logs"),
        (&["check"], "Check a manifest"),
        (&["schema"], "Write the JSON Schemas"),
        (&["completions"], "Print a shell's completion script"),
        (&["man"], "Print servoid's man page"),
        (&["keys"], "Print the manifests' key reference"),
    ] {
        let mut args = sub.to_vec();
        args.push("--help");
        let o = servoid(&root(), &args);
        assert_eq!(o.code, 0, "{sub:?}: {}", o.stderr);
        assert!(
            o.stdout.starts_with(opening),
            "`servoid {} --help` opens:\n{}",
            sub.join(" "),
            o.stdout.lines().next().unwrap_or_default()
        );
    }
}

/// The man page is roff with the title, name and every subcommand.
#[test]
fn the_man_page_is_roff_naming_every_subcommand() {
    let o = servoid(&root(), &["man"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    assert!(
        o.stdout.contains(".TH servoid 1"),
        "{}",
        &o.stdout[..200.min(o.stdout.len())]
    );
    assert!(o.stdout.contains(".SH NAME"));
    assert!(o.stdout.contains(".SH SUBCOMMANDS"));
    for sub in SUBCOMMANDS {
        assert!(o.stdout.contains(&format!("servoid\\-{sub}")), "no `{sub}`");
    }
}

/// A reader that closes the pipe early (`| head -1`) ends the output
/// quietly: no panic, exit 0.
#[test]
fn a_closed_pipe_ends_the_output_quietly() {
    for args in [&["completions", "bash"][..], &["man"][..]] {
        let mut child = Command::new(env!("CARGO_BIN_EXE_servoid"))
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        drop(child.stdout.take());
        let out = child.wait_with_output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
        assert!(
            out.status.code() == Some(0),
            "{args:?}: {:?} {stderr}",
            out.status
        );
    }
}

/// `--version` names the commit the binary was built from, as git says it
/// independently (with "+modified" when the sources differ from it), or
/// "unknown" outside a checkout.
#[test]
fn the_version_names_the_commit() {
    let o = servoid(&root(), &["--version"]);
    assert_eq!(o.code, 0);
    let git = |args: &[&str]| {
        Command::new("git")
            .args(args)
            .current_dir(root())
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
    };
    let version = env!("CARGO_PKG_VERSION");
    match git(&["rev-parse", "--short=12", "HEAD"]) {
        Some(commit) => {
            let clean = format!("servoid {version} (commit {commit})\n");
            let modified = format!("servoid {version} (commit {commit}+modified)\n");
            assert!(
                o.stdout == clean || o.stdout == modified,
                "{:?} is neither {clean:?} nor {modified:?}",
                o.stdout
            );
        }
        None => assert_eq!(o.stdout, format!("servoid {version} (commit unknown)\n")),
    }
}

/// Colour on demand (`CLICOLOR_FORCE=1`) shows in a usage error; `NO_COLOR`
/// takes it away again (no-color.org), whatever else asks for colour.
#[test]
fn no_color_is_honoured() {
    let run = |env: &[(&str, &str)]| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_servoid"));
        c.args(["run", "--no-such-flag"]).env_remove("NO_COLOR");
        for (k, v) in env {
            c.env(k, v);
        }
        let out = c.output().unwrap();
        assert_eq!(out.status.code(), Some(2));
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let forced = run(&[("CLICOLOR_FORCE", "1")]);
    assert!(
        forced.contains('\u{1b}'),
        "CLICOLOR_FORCE=1 gives colour: {forced:?}"
    );
    let plain = run(&[("CLICOLOR_FORCE", "1"), ("NO_COLOR", "1")]);
    assert!(!plain.contains('\u{1b}'), "NO_COLOR=1: {plain:?}");
    assert!(plain.contains("--no-such-flag"), "{plain}");
}
