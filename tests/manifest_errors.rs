//! Bad manifests: each gives one clear message naming the file and the key
//! or run, exit code 2, and no output written.

use crate::util::{paper_tf_runs, scratch, servoid, write};

/// A small valid campaign: no specimen, one spring, one validation run.
const BASE: &str = concat!(
    r#"schema_version = 1

[campaign]
name = "tiny"

[rig]
name = "test rig"

"#,
    paper_tf_runs!(),
    r#"
[[runs]]
id = "exp1"
role = "validation"
p_gain = 1.0
specimen = { mass_kg = 3.8, damping_ns_per_m = 5.0, stiffness_n_per_m = 129400.0 }
"#
);

struct Checked {
    code: i32,
    stderr: String,
    wrote_output: bool,
}

fn check(text: &str) -> Checked {
    check_named(text, "campaign.toml")
}

fn check_named(text: &str, name: &str) -> Checked {
    let dir = scratch();
    let path = write(dir.path(), name, text);
    let out = dir.path().join("out");
    let o = servoid(
        dir.path(),
        &[
            "run",
            path.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ],
    );
    Checked {
        code: o.code,
        stderr: o.stderr,
        wrote_output: out.exists(),
    }
}

/// Assert a manifest error: exit 2, nothing written, and every fragment in the message.
fn assert_manifest_error(text: &str, fragments: &[&str]) {
    let c = check(text);
    assert_eq!(c.code, 2, "exit code; stderr:\n{}", c.stderr);
    assert!(!c.wrote_output, "a bad manifest must write nothing");
    assert!(
        c.stderr.contains("campaign.toml"),
        "names the file:\n{}",
        c.stderr
    );
    for f in fragments {
        assert!(c.stderr.contains(f), "missing {f:?} in:\n{}", c.stderr);
    }
}

#[test]
fn the_base_manifest_is_valid() {
    let c = check(BASE);
    assert_eq!(c.code, 0, "{}", c.stderr);
    assert!(c.wrote_output);
}

#[test]
fn syntax_error_names_line_and_column() {
    let text = BASE.replace(
        "p_gain = 1.0\nspecimen = { stiff",
        "p_gain = = 1.0\nspecimen = { stiff",
    );
    // The broken line is line 20 (k1's p_gain); the column points into it.
    assert_manifest_error(&text, &["campaign.toml:20:", "TOML syntax error"]);
}

#[test]
fn json_syntax_error_names_line_and_column() {
    let c = check_named(
        "{\n  \"schema_version\": 1,\n  \"campaign\": {,}\n}\n",
        "m.json",
    );
    assert_eq!(c.code, 2);
    assert!(c.stderr.contains("m.json:3:"), "{}", c.stderr);
}

#[test]
fn missing_key_is_named() {
    let text = BASE.replace(
        "id = \"k1\"\nrole = \"spring\"\np_gain = 1.0\n",
        "id = \"k1\"\nrole = \"spring\"\n",
    );
    assert_manifest_error(
        &text,
        &["runs[1].p_gain", "run \"k1\"", "required key is missing"],
    );
}

#[test]
fn missing_section_is_named() {
    let text = BASE.replace("[campaign]\nname = \"tiny\"\n", "");
    assert_manifest_error(
        &text,
        &["campaign: required section is missing: add a [campaign] table"],
    );
}

#[test]
fn mistyped_key_is_named_with_line() {
    let text = BASE.replace(
        "id = \"exp1\"\nrole = \"validation\"\np_gain = 1.0",
        "id = \"exp1\"\nrole = \"validation\"\np_gain = \"one\"",
    );
    assert_manifest_error(
        &text,
        &[
            "runs[2].p_gain",
            "run \"exp1\"",
            "must be a number, not the string \"one\"",
            "campaign.toml:29:1:",
        ],
    );
}

#[test]
fn unknown_key_is_rejected_with_its_path_and_a_suggestion() {
    let text = BASE.replace(
        "{ stiffness_n_per_m = 116640.0 }",
        "{ stifness_n_per_m = 116640.0 }",
    );
    assert_manifest_error(
        &text,
        &[
            "runs[1].specimen.stifness_n_per_m",
            "unknown key",
            "did you mean `stiffness_n_per_m`",
        ],
    );
}

#[test]
fn unknown_top_level_key_is_rejected() {
    let text = format!("{BASE}\n[extras]\nfoo = 1\n");
    assert_manifest_error(&text, &["extras: unknown key `extras`"]);
}

#[test]
fn zero_or_negative_mass_stiffness_and_p_gain_are_rejected() {
    let text = BASE
        .replace("mass_kg = 3.8", "mass_kg = -3.8")
        .replace(
            "{ stiffness_n_per_m = 116640.0 }",
            "{ stiffness_n_per_m = 0.0 }",
        )
        .replace(
            "id = \"ns\"\nrole = \"no_specimen\"\np_gain = 1.0",
            "id = \"ns\"\nrole = \"no_specimen\"\np_gain = 0.0",
        );
    let c = check(&text);
    assert_eq!(c.code, 2);
    // Every problem at once, each with its run.
    for f in [
        "runs[2].specimen.mass_kg (run \"exp1\"): must be positive (got -3.8)",
        "runs[1].specimen.stiffness_n_per_m (run \"k1\"): must be positive (got 0)",
        "runs[0].p_gain (run \"ns\"): must be positive (got 0)",
        "3 problems",
    ] {
        assert!(c.stderr.contains(f), "missing {f:?} in:\n{}", c.stderr);
    }
}

#[test]
fn spring_run_without_stiffness() {
    let text = BASE.replace("specimen = { stiffness_n_per_m = 116640.0 }\n", "");
    assert_manifest_error(
        &text,
        &[
            "runs[1].specimen.stiffness_n_per_m",
            "run \"k1\"",
            "needs the spring's stiffness",
        ],
    );
}

#[test]
fn validation_campaign_without_rig_parameters_or_identification_runs() {
    // Drop the spring run: nothing gives R2 and R3, and no [rig.parameters].
    let start = BASE.find("[[runs]]\nid = \"k1\"").unwrap();
    let end = BASE.find("[[runs]]\nid = \"exp1\"").unwrap();
    let text = format!("{}{}", &BASE[..start], &BASE[end..]);
    assert_manifest_error(&text, &["rig.parameters", "has no spring run"]);
}

#[test]
fn given_rig_parameters_suffice_for_validation() {
    let exp = &BASE[BASE.find("[[runs]]\nid = \"exp1\"").unwrap()..];
    let text = format!(
        "schema_version = 1\n[campaign]\nname = \"given\"\n[rig]\nname = \"r\"\n[rig.parameters]\nbeta1_per_s = 267.0\na1b0_n_per_m_s2 = 2.412e9\na2_n_per_m = 7.881e5\na3_per_s = 16.118\n\n{exp}"
    );
    let c = check(&text);
    assert_eq!(c.code, 0, "{}", c.stderr);
}

#[test]
fn duplicate_run_ids() {
    let text = BASE.replace("id = \"k1\"", "id = \"ns\"");
    assert_manifest_error(
        &text,
        &[
            "runs[1].id",
            "duplicate run id `ns` (first used by runs[0])",
        ],
    );
}

#[test]
fn zero_leading_denominator() {
    let text = BASE.replace("den = [1.0, 263.4, 3337.0]", "den = [0.0, 263.4, 3337.0]");
    assert_manifest_error(
        &text,
        &[
            "runs[1].data.transfer_function.den",
            "run \"k1\"",
            "leading denominator coefficient is zero",
        ],
    );
}

#[test]
fn identification_runs_need_second_order_models() {
    let text = BASE.replace(
        "den = [1.0, 267.0, 3060.0]",
        "den = [1.0, 267.0, 3060.0, 5.0]",
    );
    assert_manifest_error(&text, &["runs[0].data.transfer_function", "second-order"]);
}

#[test]
fn every_problem_is_reported_at_once() {
    // A type error in one run does not hide problems elsewhere.
    let text = BASE
        .replace(
            "p_gain = 1.0\n[runs.data.transfer_function]\nnum = [3060.0]",
            "p_gain = \"x\"\n[runs.data.transfer_function]\nnum = [3060.0]",
        )
        .replace(
            "{ stiffness_n_per_m = 116640.0 }",
            "{ stiffness_n_per_m = -1.0 }",
        )
        .replace("mass_kg = 3.8", "mass_kg = 0.0")
        .replace(
            "name = \"test rig\"",
            "name = \"test rig\"\ncolour = \"red\"",
        );
    let c = check(&text);
    assert_eq!(c.code, 2);
    for f in [
        "4 problems",
        "runs[0].p_gain",
        "runs[1].specimen.stiffness_n_per_m",
        "runs[2].specimen.mass_kg",
        "rig.colour",
    ] {
        assert!(c.stderr.contains(f), "missing {f:?} in:\n{}", c.stderr);
    }
}

#[test]
fn unreadable_manifest_names_the_file() {
    let dir = scratch();
    let o = servoid(dir.path(), &["run", "nowhere.toml"]);
    assert_eq!(o.code, 2);
    assert!(o.stderr.contains("nowhere.toml"), "{}", o.stderr);
}

#[test]
fn unknown_reference_quantity_and_run() {
    let text = format!(
        "{BASE}\n[[references]]\nquantity = \"rig.a9\"\npublished = 1.0\n\n[[references]]\nquantity = \"ccf.nope.C1\"\npublished = 1.0\n"
    );
    assert_manifest_error(
        &text,
        &[
            "references[0].quantity",
            "unknown quantity `rig.a9`",
            "references[1].quantity",
            "run `nope`",
        ],
    );
}

#[test]
fn usage_errors_exit_2() {
    let dir = scratch();
    assert_eq!(servoid(dir.path(), &["frobnicate"]).code, 2);
    assert_eq!(servoid(dir.path(), &["run"]).code, 2);
    assert_eq!(servoid(dir.path(), &["--help"]).code, 0);
}

#[test]
fn a_failed_run_exits_1_and_the_others_complete() {
    // A spring whose fitted model raises the static gain (d0/n0 < 1) gives a
    // non-physical R2: identification fails, the validation run cannot be
    // predicted, and both are recorded in results.json.
    let text = BASE.replace("den = [1.0, 263.4, 3337.0]", "den = [1.0, 263.4, 2600.0]");
    let dir = scratch();
    let path = write(dir.path(), "campaign.toml", &text);
    let out = dir.path().join("out");
    let o = servoid(
        dir.path(),
        &[
            "run",
            path.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ],
    );
    assert_eq!(o.code, 1, "{}", o.stderr);
    let r: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("results.json")).unwrap()).unwrap();
    assert!(r["rig"].is_null());
    assert!(
        r["rig_error"].as_str().unwrap().contains("k1"),
        "{}",
        r["rig_error"]
    );
    let exp1 = &r["runs"][2];
    assert_eq!(exp1["status"], "failed");
    assert!(
        exp1["error"]
            .as_str()
            .unwrap()
            .contains("rig parameters are unavailable")
    );
    // The identification runs themselves completed.
    assert_eq!(r["runs"][0]["status"], "ok");
    assert!(o.stderr.contains("run exp1"), "{}", o.stderr);
}

/// Each command is given the other kind of manifest: one message that says
/// which kind it is and the command that takes it, exit 2, nothing written.
#[test]
fn a_manifest_of_the_other_kind_names_the_command_that_takes_it() {
    let dir = scratch();
    let campaign = write(dir.path(), "campaign.toml", BASE);
    let sim = crate::util::root().join("experiments/maghareh2018/simulation.toml");
    let out = dir.path().join("out");
    let o = crate::util::servoid_into(dir.path(), "run", &sim, &out, &[]);
    assert_eq!(o.code, 2, "{}", o.stderr);
    assert!(
        o.stderr.contains("simulation.toml: this is a simulation manifest; simulate it and run the campaign it writes with `servoid simulate"),
        "{}",
        o.stderr
    );
    let o = crate::util::servoid_into(dir.path(), "simulate", &campaign, &out, &[]);
    assert_eq!(o.code, 2, "{}", o.stderr);
    assert!(
        o.stderr.contains("campaign.toml: this is a campaign manifest; a simulation manifest has a [simulation] table; run a campaign with `servoid run"),
        "{}",
        o.stderr
    );
    assert!(!out.exists(), "nothing written");
}

/// The nameplate's flow law needs both its numbers, each positive: the
/// key named is the one missing or wrong.
#[test]
fn a_nameplate_without_its_area_or_with_a_pressure_not_positive() {
    for (lines, want) in [
        (
            "supply_pressure_pa = 2.07e7\n",
            "rig.piston_area_m2: the flow-pressure law needs the piston area beside `supply_pressure_pa` (F_max = A P_s)",
        ),
        (
            "supply_pressure_pa = -1.0\npiston_area_m2 = 2.387e-4\n",
            "rig.supply_pressure_pa: must be positive (got -1)",
        ),
    ] {
        let text = BASE.replacen(
            "[rig]\nname = \"test rig\"\n",
            &format!("[rig]\nname = \"test rig\"\n{lines}"),
            1,
        );
        assert_ne!(text, BASE);
        let c = check(&text);
        assert_eq!(c.code, 2, "{}", c.stderr);
        assert!(
            c.stderr.contains(want),
            "missing {want:?} in:\n{}",
            c.stderr
        );
        assert!(!c.wrote_output);
    }
}

#[test]
fn a_history_window_too_short_and_a_threshold_not_positive() {
    let text = format!("{BASE}\n[history]\nwindow = 2\nthreshold = 0.0\nfile = \"\"\n");
    let c = check(&text);
    assert_eq!(c.code, 2);
    for f in [
        "history.window: must be at least 3 (the median of fewer entries says little; got 2)",
        "history.threshold: must be positive (got 0)",
        "history.file: must not be empty",
        "3 problems",
    ] {
        assert!(c.stderr.contains(f), "missing {f:?} in:\n{}", c.stderr);
    }
    assert!(!c.wrote_output);
}

#[test]
fn a_bad_sensitivity_range_too_few_points_and_a_target_not_positive() {
    let text = format!(
        "{BASE}\n[sensitivity]\nstiffness_range_n_per_m = [0.0, 1e6]\npoints = 1\ntarget_rel_std = -0.01\n"
    );
    let c = check(&text);
    assert_eq!(c.code, 2);
    for f in [
        "sensitivity.stiffness_range_n_per_m: must be two stiffnesses 0 < low < high in N/m (got [0, 1000000])",
        "sensitivity.points: must be at least 2 (a sweep needs two stiffnesses; got 1)",
        "sensitivity.target_rel_std: must be a positive fraction, 0.01 for 1 % (got -0.01)",
        "3 problems",
    ] {
        assert!(c.stderr.contains(f), "missing {f:?} in:\n{}", c.stderr);
    }
    assert!(!c.wrote_output);
    // A range high below low is as wrong; a good section passes.
    let c = check(&format!(
        "{BASE}\n[sensitivity]\nstiffness_range_n_per_m = [1e6, 1e5]\n"
    ));
    assert!(c.stderr.contains("(got [1000000, 100000])"), "{}", c.stderr);
    let c = check(&format!(
        "{BASE}\n[sensitivity]\nstiffness_range_n_per_m = [1e4, 1e7]\npoints = 21\ntarget_rel_std = 0.02\n"
    ));
    assert_eq!(c.code, 0, "{}", c.stderr);
}

/// A compensator's cut-off that is not a positive frequency, and a key the
/// table does not take, each named by its key; a good table passes.
#[test]
fn a_compensator_cutoff_not_positive_or_an_unknown_key() {
    for (bad, why) in [
        ("-240.0", "must be a positive frequency in Hz (got -240)"),
        ("0.0", "must be a positive frequency in Hz (got 0)"),
        ("nan", "nan is not a finite number"),
    ] {
        let c = check(&format!("{BASE}\n[compensator]\ncutoff_hz = {bad}\n"));
        assert_eq!(c.code, 2, "{bad}: {}", c.stderr);
        assert!(
            c.stderr.contains(&format!("compensator.cutoff_hz: {why}")),
            "{bad}: {}",
            c.stderr
        );
        assert!(!c.wrote_output);
    }
    let c = check(&format!("{BASE}\n[compensator]\ncutoff = 240.0\n"));
    assert_eq!(c.code, 2);
    assert!(c.stderr.contains("compensator.cutoff"), "{}", c.stderr);
    assert!(
        c.stderr.contains("cutoff_hz"),
        "names the key it takes: {}",
        c.stderr
    );
    let c = check(&format!(
        "{BASE}\n[compensator]\ncutoff_hz = 200.0\nlead = false\n"
    ));
    assert_eq!(c.code, 0, "{}", c.stderr);
}

/// The Monte Carlo's zero seeds and one stiffness, each named by its key;
/// an unknown key in its table is named with the ones it takes.
#[test]
fn a_monte_carlo_with_zero_seeds_or_one_point() {
    let c = check(&format!(
        "{BASE}\n[sensitivity]\nmonte_carlo = {{ points = 1, seeds = 0 }}\n"
    ));
    assert_eq!(c.code, 2);
    for f in [
        "sensitivity.monte_carlo.points: must be at least 2 (the Monte Carlo needs two stiffnesses; got 1)",
        "sensitivity.monte_carlo.seeds: must be at least 1",
        "2 problems",
    ] {
        assert!(c.stderr.contains(f), "missing {f:?} in:\n{}", c.stderr);
    }
    assert!(!c.wrote_output);
    let c = check(&format!(
        "{BASE}\n[sensitivity]\nmonte_carlo = {{ seeds = 5, seedz = 3 }}\n"
    ));
    assert_eq!(c.code, 2);
    assert!(
        c.stderr.contains("sensitivity.monte_carlo.seedz"),
        "{}",
        c.stderr
    );
    let c = check(&format!(
        "{BASE}\n[sensitivity]\nmonte_carlo = {{ points = 4, seeds = 3, seed = 7 }}\n"
    ));
    assert_eq!(c.code, 0, "{}", c.stderr);
}

/// A simulation manifest checks the sensitivity it passes on, naming the
/// key, before it simulates anything.
#[test]
fn a_simulation_checks_the_sensitivity_it_passes_on() {
    let dir = scratch();
    let text = std::fs::read_to_string(
        crate::util::root().join("experiments/maghareh2018/simulation.toml"),
    )
    .unwrap()
    .replace(
        "monte_carlo = { points = 20, seeds = 50 }",
        "monte_carlo = { points = 20, seeds = 0 }\ntarget_rel_std = 0.0",
    );
    assert!(text.contains("seeds = 0"));
    let sim = write(dir.path(), "simulation.toml", &text);
    let out = dir.path().join("out");
    let o = crate::util::servoid_into(dir.path(), "simulate", &sim, &out, &[]);
    assert_eq!(o.code, 2, "{}", o.stderr);
    for f in [
        "sensitivity.monte_carlo.seeds: must be at least 1",
        "sensitivity.target_rel_std: must be a positive fraction",
    ] {
        assert!(o.stderr.contains(f), "missing {f:?} in:\n{}", o.stderr);
    }
    assert!(!out.exists(), "nothing written");
}

/// A validation run whose log is another run's (exp1 given exp3's log, its
/// SHA-256 pin moved with it): the run completes, but its error is many
/// times the other runs', and the command line says so on its own line,
/// with why, rather than a bare "ok".
#[test]
fn an_outlier_validation_run_is_flagged_on_the_command_line() {
    let dir = scratch();
    let manifest = crate::shards::campaign(dir.path());
    let text = std::fs::read_to_string(&manifest).unwrap();
    let sha_of = |log: &str| {
        let at = text.find(&format!("log = \"{log}\"\nsha256 = \"")).unwrap();
        text[at..].lines().nth(1).unwrap().to_string()
    };
    let (exp1, exp3) = (sha_of("logs/exp1.csv"), sha_of("logs/exp3.csv"));
    let text = text.replace(
        &format!("log = \"logs/exp1.csv\"\n{exp1}"),
        &format!("log = \"logs/exp3.csv\"\n{exp3}"),
    );
    let swapped = write(manifest.parent().unwrap(), "swapped.toml", &text);
    let out = dir.path().join("out");
    let o = crate::util::servoid_into(dir.path(), "run", &swapped, &out, &["--figures", "none"]);
    let line = o
        .stdout
        .lines()
        .find(|l| l.trim_start().starts_with("run exp1 "))
        .unwrap_or_else(|| panic!("no line for exp1:\n{}", o.stdout));
    assert!(
        line.ends_with("ok (OUTLIER)"),
        "{line}\n{}\n{}",
        o.stdout,
        o.stderr
    );
    for other in ["exp2", "exp3", "exp4"] {
        let l = o
            .stdout
            .lines()
            .find(|l| l.trim_start().starts_with(&format!("run {other} ")))
            .unwrap();
        assert!(l.ends_with(" ok"), "{l}");
    }
    assert!(
        o.stdout.contains("      outlier: NRMSE ")
            && o.stdout.contains("the log belongs to another run"),
        "{}",
        o.stdout
    );
    let r: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("results.json")).unwrap()).unwrap();
    let v = &crate::util::run_by_id(&r, "exp1")["validation"];
    assert_eq!(v["outlier"], true);
}

/// `[[numbered_figures]]`: a number that is not digits and a letter, one
/// given twice, an entry with both a figure and a reason and one with
/// neither, and a figure that is no file stem are each named at their key.
#[test]
fn numbered_figures_are_checked_each_at_its_key() {
    let text = format!(
        "{BASE}\n{}",
        concat!(
            "[[numbered_figures]]\nnumber = \"8\"\nfigure = \"frf-ns\"\ncaption = \"a\"\n\n",
            "[[numbered_figures]]\nnumber = \"8\"\nfigure = \"frf-k1\"\ncaption = \"b\"\n\n",
            "[[numbered_figures]]\nnumber = \"Fig. 9\"\nfigure = \"frf-k1\"\ncaption = \"c\"\n\n",
            "[[numbered_figures]]\nnumber = \"10\"\nfigure = \"frf-k1\"\ncaption = \"d\"\nnot_drawn = \"a photo\"\n\n",
            "[[numbered_figures]]\nnumber = \"11\"\ncaption = \"e\"\n\n",
            "[[numbered_figures]]\nnumber = \"12\"\nfigure = \"figures/frf-k1.png\"\ncaption = \"f\"\n",
        )
    );
    let c = check(&text);
    assert_eq!(c.code, 2, "{}", c.stderr);
    for f in [
        "numbered_figures[1].number: 8 is given twice",
        "numbered_figures[2].number: must be digits and an optional lowercase letter",
        "numbered_figures[3]: give `figure`",
        "numbered_figures[4]: give `figure`",
        "numbered_figures[5].figure: must be a figure's file stem",
        "5 problems",
    ] {
        assert!(c.stderr.contains(f), "missing {f:?} in:\n{}", c.stderr);
    }
}
