//! `servoid init` on the bundled default's logs: the manifest it proposes
//! finds the channels and the roles, `servoid check` names every
//! placeholder by key, and once they are filled with what the lab knows
//! (the values of the hand-written manifest `servoid simulate` made) the
//! campaign gives the same rig, to the last digit, as that manifest. On the
//! same logs renamed `log1.csv`... the channels are still found and the
//! roles are left to fill.

use std::path::Path;

use serde_json::Value;

use crate::util::{bundled_simulation, scratch, servoid, servoid_into};

fn toml_of(path: &Path) -> toml::Table {
    toml::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn rig_of(results: &Path) -> Value {
    let v: Value = serde_json::from_slice(&std::fs::read(results).unwrap()).unwrap();
    v["rig"].clone()
}

fn runs(t: &toml::Table) -> &Vec<toml::Value> {
    t["runs"].as_array().unwrap()
}

/// The bundled default simulated into `dir/sim` (and run there with
/// `run`): the folder and its hand-written manifest, the reference.
fn simulated(dir: &Path, run: bool) -> (std::path::PathBuf, toml::Table) {
    let sim = bundled_simulation(dir, false);
    let out = dir.join("sim");
    let args: &[&str] = if run { &["--run"] } else { &[] };
    let o = servoid_into(dir, "simulate", &sim, &out, args);
    assert_eq!(o.code, 0, "{}", o.stderr);
    let reference = toml_of(&out.join("campaign.toml"));
    (out, reference)
}

/// What the lab fills in a proposed manifest besides its runs: the rig's
/// name, and the identification settings it chose (init writes the
/// defaults).
fn fill_rig(t: &mut toml::Table, reference: &toml::Table) {
    t["rig"]["name"] = reference["rig"]["name"].clone();
    t.insert("identification".into(), reference["identification"].clone());
}

#[test]
fn init_proposes_a_manifest_that_reproduces_the_bundled_rig_once_filled() {
    let dir = scratch();
    let (out, reference) = simulated(dir.path(), true);

    let proposed = dir.path().join("proposed.toml");
    let o = servoid(
        dir.path(),
        &["init", "sim/logs", "--out", proposed.to_str().unwrap()],
    );
    assert_eq!(o.code, 0, "{}", o.stderr);
    assert!(o.stdout.contains("7 log(s)"), "{}", o.stdout);
    // Writing over it is refused.
    let again = servoid(
        dir.path(),
        &["init", "sim/logs", "--out", proposed.to_str().unwrap()],
    );
    assert_eq!(again.code, 2);
    assert!(again.stderr.contains("already exists"), "{}", again.stderr);

    let mut t = toml_of(&proposed);
    // The channels as the hand-written manifest has them.
    for ch in ["time", "command", "displacement", "force"] {
        assert_eq!(
            t["channels"][ch]["column"], reference["channels"][ch]["column"],
            "{ch}"
        );
        assert_eq!(
            t["channels"][ch]["unit"], reference["channels"][ch]["unit"],
            "{ch}"
        );
    }
    // The roles from the files' names.
    for r in runs(&t) {
        let id = r["id"].as_str().unwrap();
        let want = runs(&reference)
            .iter()
            .find(|x| x["id"].as_str() == Some(id))
            .unwrap_or_else(|| panic!("run {id} in the reference"));
        assert_eq!(r["role"], want["role"], "{id}");
        assert!(r["p_gain"].as_str().unwrap().starts_with("FILL:"), "{id}");
    }
    // check names every placeholder by key.
    let o = servoid(dir.path(), &["check", "proposed.toml"]);
    assert_eq!(o.code, 2);
    assert!(
        o.stderr
            .contains("runs[0].p_gain (run \"exp1\"): a placeholder to fill"),
        "{}",
        o.stderr
    );
    assert!(
        o.stderr.contains("rig.name: a placeholder to fill"),
        "{}",
        o.stderr
    );
    let named = o.stderr.matches("a placeholder to fill").count();
    assert_eq!(named, 1 + 7 + 2 + 4 * 3, "{}", o.stderr);

    // Filled as the lab would: the rig's name, each run's P gain and
    // specimen, and the identification settings it chose.
    fill_rig(&mut t, &reference);
    let reference_runs = runs(&reference).clone();
    for r in t["runs"].as_array_mut().unwrap() {
        let id = r["id"].as_str().unwrap().to_string();
        let want = reference_runs
            .iter()
            .find(|x| x["id"].as_str() == Some(id.as_str()))
            .unwrap();
        let r = r.as_table_mut().unwrap();
        r.insert("p_gain".into(), want["p_gain"].clone());
        match want.get("specimen") {
            Some(s) => {
                r.insert("specimen".into(), s.clone());
            }
            None => assert!(r.get("specimen").is_none(), "{id}"),
        }
    }
    std::fs::write(&proposed, toml::to_string(&t).unwrap()).unwrap();
    let o = servoid(dir.path(), &["check", "proposed.toml"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    let o = servoid(dir.path(), &["run", "proposed.toml", "--out", "filled"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    let rig = rig_of(&dir.path().join("filled/results.json"));
    assert!(rig["beta1"]["value"].is_f64());
    assert_eq!(
        rig,
        rig_of(&out.join("results.json")),
        "the same rig as the hand-written manifest"
    );
}

/// The campaign is named after the folder its manifest goes into: the
/// current one, or the one `--out` names, whether or not it exists yet
/// (the name a lab reads in `reports/<name>/`), each character other than
/// a letter, digit, `.`, `_` or `-` written `-`.
#[test]
fn init_names_the_campaign_after_the_manifests_folder() {
    let dir = scratch();
    let (out, _) = simulated(dir.path(), false);
    let logs = out.join("logs");
    let logs = logs.to_str().unwrap();
    for (manifest, name) in [
        ("frame-a/campaign.toml", "frame-a"),
        ("Frame B (2026)/campaign.toml", "Frame-B--2026-"),
    ] {
        let folder = dir.path().join(manifest).parent().unwrap().to_path_buf();
        assert!(!folder.exists());
        let o = servoid(dir.path(), &["init", logs, "--out", manifest]);
        assert_eq!(o.code, 0, "{manifest}: {}", o.stderr);
        let t = toml_of(&dir.path().join(manifest));
        assert_eq!(t["campaign"]["name"].as_str(), Some(name), "{manifest}");
    }
}

#[test]
fn init_on_unnamed_logs_finds_the_channels_and_leaves_the_roles_to_fill() {
    let dir = scratch();
    let (out, _) = simulated(dir.path(), false);
    let logs = dir.path().join("unnamed");
    std::fs::create_dir(&logs).unwrap();
    let mut names: Vec<_> = std::fs::read_dir(out.join("logs"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    names.sort();
    for (i, p) in names.iter().enumerate() {
        std::fs::copy(p, logs.join(format!("log{}.csv", i + 1))).unwrap();
    }
    let o = servoid(
        dir.path(),
        &["init", "unnamed/*.csv", "--out", "unnamed.toml"],
    );
    assert_eq!(o.code, 0, "{}", o.stderr);
    let t = toml_of(&dir.path().join("unnamed.toml"));
    assert_eq!(
        t["channels"]["displacement"]["column"].as_str(),
        Some("displacement_mm")
    );
    assert_eq!(t["channels"]["force"]["unit"].as_str(), Some("kN"));
    assert_eq!(runs(&t).len(), 7);
    for r in runs(&t) {
        assert!(r["role"].as_str().unwrap().starts_with("FILL:"), "{r}");
    }
    let o = servoid(dir.path(), &["check", "unnamed.toml"]);
    assert_eq!(o.code, 2);
    assert!(o.stderr.contains("runs[6].role (run \"log7\"): a placeholder to fill: no_specimen, spring, validation or fit"), "{}", o.stderr);
}

/// The real MTS logs (DAQ text, anonymous `CHANNEL0`-`CHANNEL2`): the rate
/// comes from their header, the channels, their units and the roles are
/// left to fill; filled from the example manifest
/// (experiments/utfsm-mts-mrdamper/campaign.toml: its channels with their
/// scale factors, roles, P gains and identification), the runs' fits are
/// the example's to the last digit.
#[test]
fn init_on_the_mts_logs_leaves_their_anonymous_channels_to_fill() {
    let Some(data) = crate::util::mts_data() else {
        return;
    };
    let dir = scratch();
    let o = servoid(
        dir.path(),
        &["init", data.to_str().unwrap(), "--out", "mts.toml"],
    );
    assert_eq!(o.code, 0, "{}", o.stderr);
    let text = std::fs::read_to_string(dir.path().join("mts.toml")).unwrap();
    assert!(text.contains("the file states its rate, 1000 Hz"), "{text}");
    let o = servoid(dir.path(), &["check", "mts.toml"]);
    assert_eq!(o.code, 2);
    for key in [
        "channels.command.column",
        "channels.displacement.unit",
        "runs[0].role (run \"0A\")",
        "runs[1].p_gain (run \"1A\")",
    ] {
        assert!(
            o.stderr.contains(&format!("{key}: a placeholder to fill")),
            "{key}: {}",
            o.stderr
        );
    }
    let example_path = crate::util::root().join("experiments/utfsm-mts-mrdamper/campaign.toml");
    let example = toml_of(&example_path);
    let mut t: toml::Table = toml::from_str(&text).unwrap();
    t["rig"]["name"] = example["rig"]["name"].clone();
    t.insert("channels".into(), example["channels"].clone());
    t.insert("identification".into(), example["identification"].clone());
    for r in t["runs"].as_array_mut().unwrap() {
        let id = r["id"].as_str().unwrap().to_string();
        let want = runs(&example)
            .iter()
            .find(|x| x["id"].as_str() == Some(id.as_str()))
            .unwrap()
            .clone();
        let r = r.as_table_mut().unwrap();
        r.insert("role".into(), want["role"].clone());
        r.insert("p_gain".into(), want["p_gain"].clone());
    }
    std::fs::write(dir.path().join("mts.toml"), toml::to_string(&t).unwrap()).unwrap();
    let o = servoid(dir.path(), &["run", "mts.toml", "--out", "filled"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    let mine: Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("filled/results.json")).unwrap())
            .unwrap();
    // The example, run on the same logs where they are.
    let example_text = std::fs::read_to_string(&example_path).unwrap().replace(
        "../../../shared/data/utfsm-mts-mrdamper",
        data.to_str().unwrap(),
    );
    std::fs::write(dir.path().join("example.toml"), example_text).unwrap();
    let o = servoid(dir.path(), &["run", "example.toml", "--out", "example"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    let theirs: Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("example/results.json")).unwrap())
            .unwrap();
    for (a, b) in mine["runs"]
        .as_array()
        .unwrap()
        .iter()
        .zip(theirs["runs"].as_array().unwrap())
    {
        assert_eq!(a["id"], b["id"]);
        assert!(a["tf"]["num"].is_array(), "{}", a["id"]);
        assert_eq!(
            (&a["tf"], &a["fit"]),
            (&b["tf"], &b["fit"]),
            "run {}",
            a["id"]
        );
    }
}

/// The reference's runs as a run table (CSV), in its order, with the
/// lab's own `operator` column.
fn table_of(reference: &toml::Table) -> String {
    let mut out = String::from(
        "id,role,p_gain,mass_kg,damping_ns_per_m,stiffness_n_per_m,description,operator\n",
    );
    for r in runs(reference) {
        let s = r.get("specimen");
        let cell = |k: &str| {
            s.and_then(|s| s.get(k))
                .map(|v| v.to_string())
                .unwrap_or_default()
        };
        out.push_str(&format!(
            "{},{},{},{},{},{},\"{}\",ana\n",
            r["id"].as_str().unwrap(),
            r["role"].as_str().unwrap(),
            r["p_gain"],
            cell("mass_kg"),
            cell("damping_ns_per_m"),
            cell("stiffness_n_per_m"),
            r.get("description")
                .and_then(|d| d.as_str())
                .unwrap_or_default()
        ));
    }
    out
}

/// A night folder as a nightly batch keeps it: its run table
/// (`specimens.csv`, with the lab's own column) beside a `logs/` folder,
/// and the same with the table among the logs. `init` names the table as
/// the manifest's `[run_table]` and the logs' folder, leaves only the rig's
/// name to fill, and the filled manifest gives the hand-written
/// manifest's rig to the last digit.
#[test]
fn init_on_a_night_folder_names_its_run_table() {
    let dir = scratch();
    let (out, reference) = simulated(dir.path(), true);
    let table = table_of(&reference);
    let logs = out.join("logs");
    for (night, log_dir) in [("night", "night/logs"), ("flat", "flat")] {
        let d = dir.path().join(log_dir);
        std::fs::create_dir_all(&d).unwrap();
        for e in std::fs::read_dir(&logs).unwrap() {
            let p = e.unwrap().path();
            std::fs::copy(&p, d.join(p.file_name().unwrap())).unwrap();
        }
        std::fs::write(dir.path().join(night).join("specimens.csv"), &table).unwrap();

        let manifest = format!("{night}.toml");
        let o = servoid(dir.path(), &["init", night, "--out", &manifest]);
        assert_eq!(o.code, 0, "{night}: {}", o.stderr);
        assert!(
            o.stdout.contains(&format!(
                "7 log(s) (runs from the table {night}/specimens.csv)"
            )),
            "{night}: {}",
            o.stdout
        );
        let mut t = toml_of(&dir.path().join(&manifest));
        assert!(
            t.get("runs").is_none(),
            "{night}: no [[runs]] beside the table"
        );
        assert_eq!(
            t["run_table"]["file"].as_str(),
            Some(format!("{night}/specimens.csv").as_str())
        );
        assert_eq!(t["run_table"]["logs"].as_str(), Some(log_dir));
        let text = std::fs::read_to_string(dir.path().join(&manifest)).unwrap();
        assert!(
            text.contains(&format!(
                "{night}/specimens.csv: 7 row(s); 7 of the 7 with an id find their log among the 7 found"
            )),
            "{text}"
        );
        // Only the rig's name is left: the table holds the rest.
        let o = servoid(dir.path(), &["check", &manifest]);
        assert_eq!(o.code, 2);
        assert_eq!(
            o.stderr.matches("a placeholder to fill").count(),
            1,
            "{}",
            o.stderr
        );
        assert!(o.stderr.contains("rig.name: a placeholder to fill"));

        fill_rig(&mut t, &reference);
        std::fs::write(dir.path().join(&manifest), toml::to_string(&t).unwrap()).unwrap();
        let o = servoid(dir.path(), &["check", &manifest]);
        assert_eq!(o.code, 0, "{night}: {}", o.stderr);
        // The table is not one of its own logs, in a folder of CSV logs.
        assert!(
            !o.stderr.contains("no run uses it"),
            "{night}: {}",
            o.stderr
        );
        let results = format!("{night}-out");
        let o = servoid(dir.path(), &["run", &manifest, "--out", &results]);
        assert_eq!(o.code, 0, "{night}: {}", o.stderr);
        assert_eq!(
            rig_of(&dir.path().join(&results).join("results.json")),
            rig_of(&out.join("results.json")),
            "{night}: the same rig as the hand-written manifest"
        );
    }
    // A log no row uses is still a warning: the table alone is left out.
    std::fs::copy(logs.join("exp1.csv"), dir.path().join("flat/extra.csv")).unwrap();
    let o = servoid(dir.path(), &["check", "flat.toml"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    assert!(
        o.stderr
            .contains("flat/extra.csv: matched by [run_table] logs = \"flat\", but no run uses it"),
        "{}",
        o.stderr
    );
    assert!(!o.stderr.contains("specimens.csv"), "{}", o.stderr);
}

/// A night of logs without a run table: `init --table` writes one, a row
/// per log, whose cells the lab must give are placeholders `servoid check`
/// names by row and column; filled in from the hand-written manifest, the
/// campaign gives its rig to the last digit.
#[test]
fn init_writes_a_run_table_to_fill_for_a_night_without_one() {
    let dir = scratch();
    let (out, reference) = simulated(dir.path(), true);

    let o = servoid(
        dir.path(),
        &[
            "init",
            "sim/logs",
            "--table",
            "night/runs.csv",
            "--out",
            "night.toml",
        ],
    );
    assert_eq!(o.code, 0, "{}", o.stderr);
    // 1 rig name, 7 P gains, 2 springs' and 4 specimens' 3 cells.
    assert!(o.stdout.contains("22 placeholder(s)"), "{}", o.stdout);
    let o = servoid(dir.path(), &["check", "night.toml"]);
    assert_eq!(o.code, 2);
    assert_eq!(
        o.stderr.matches("a placeholder to fill").count(),
        22,
        "{}",
        o.stderr
    );
    assert!(
        o.stderr.contains(
            "night/runs.csv: row 6 (run \"spring-k1\"), column stiffness_n_per_m: a placeholder to fill: the spring's stiffness in N/m"
        ),
        "{}",
        o.stderr
    );
    // Writing over the table is refused, as over the manifest.
    let again = servoid(
        dir.path(),
        &[
            "init",
            "sim/logs",
            "--table",
            "night/runs.csv",
            "--out",
            "other.toml",
        ],
    );
    assert_eq!(again.code, 2);
    assert!(
        again.stderr.contains("night/runs.csv: already exists"),
        "{}",
        again.stderr
    );

    // The lab fills the table (as a spreadsheet would: every cell it
    // knows, the proposed `log` cell kept) and the rig's name.
    let text = std::fs::read_to_string(dir.path().join("night/runs.csv")).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(
        header,
        [
            "id",
            "role",
            "p_gain",
            "mass_kg",
            "damping_ns_per_m",
            "stiffness_n_per_m",
            "log"
        ]
    );
    let mut filled = header.join(",") + "\n";
    for line in lines {
        let id = line.split(',').next().unwrap();
        let log = line.rsplit(',').next().unwrap();
        assert_eq!(log, format!("../sim/logs/{id}.csv"));
        let want = runs(&reference)
            .iter()
            .find(|x| x["id"].as_str() == Some(id))
            .unwrap_or_else(|| panic!("{id} in the reference"));
        let s = want.get("specimen");
        let cell = |k: &str| {
            s.and_then(|s| s.get(k))
                .map(|v| v.to_string())
                .unwrap_or_default()
        };
        filled += &format!(
            "{id},{},{},{},{},{},{log}\n",
            want["role"].as_str().unwrap(),
            want["p_gain"],
            cell("mass_kg"),
            cell("damping_ns_per_m"),
            cell("stiffness_n_per_m")
        );
    }
    std::fs::write(dir.path().join("night/runs.csv"), filled).unwrap();
    let mut t = toml_of(&dir.path().join("night.toml"));
    fill_rig(&mut t, &reference);
    std::fs::write(dir.path().join("night.toml"), toml::to_string(&t).unwrap()).unwrap();
    let o = servoid(dir.path(), &["run", "night.toml", "--out", "filled"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    assert_eq!(
        rig_of(&dir.path().join("filled/results.json")),
        rig_of(&out.join("results.json")),
        "the same rig as the hand-written manifest"
    );
}

/// `init` on a folder as a lab's disk holds it: one spring log exported
/// with German column names and units in other forms, the no-specimen log
/// kept again as a `.tsv` export (the same run id twice), a name that is
/// not UTF-8, a symbolic link to nothing and an empty file. Each skipped
/// file and the renamed runs are warned, naming them; the German log gets
/// its own channels; filled as the lab would (the second export dropped
/// once warned), the campaign gives the hand-written manifest's rig to the
/// last digit.
#[test]
fn init_on_a_real_folder_warns_what_it_skipped_and_renamed() {
    use std::os::unix::ffi::OsStrExt;
    let dir = scratch();
    let (out, reference) = simulated(dir.path(), true);
    let disk = dir.path().join("disk");
    std::fs::create_dir(&disk).unwrap();
    for e in std::fs::read_dir(out.join("logs")).unwrap() {
        let p = e.unwrap().path();
        std::fs::copy(&p, disk.join(p.file_name().unwrap())).unwrap();
    }
    let role_of = |r: &toml::Value| r["role"].as_str().unwrap().to_string();
    let id_of = |r: &toml::Value| r["id"].as_str().unwrap().to_string();
    let spring = runs(&reference)
        .iter()
        .find(|r| role_of(r) == "spring")
        .map(id_of)
        .unwrap();
    let bare = runs(&reference)
        .iter()
        .find(|r| role_of(r) == "no_specimen")
        .map(id_of)
        .unwrap();
    // The spring log's header in German.
    let german = [
        ("time", "Zeit [s]"),
        ("command", "Soll [mm]"),
        ("displacement", "Weg [mm]"),
        ("force", "Kraft/kN"),
    ];
    let path = disk.join(format!("{spring}.csv"));
    let text = std::fs::read_to_string(&path).unwrap();
    let (header, body) = text.split_once('\n').unwrap();
    let mut header = header.to_string();
    for (ch, name) in german {
        let column = reference["channels"][ch]["column"].as_str().unwrap();
        header = header.replace(column, name);
    }
    std::fs::write(&path, format!("{header}\n{body}")).unwrap();
    // The no-specimen log again as a tab-delimited export.
    let text = std::fs::read_to_string(disk.join(format!("{bare}.csv"))).unwrap();
    std::fs::write(disk.join(format!("{bare}.tsv")), text.replace(',', "\t")).unwrap();
    // A name in Latin-1, a link to nothing, an empty file.
    let latin1 = std::ffi::OsStr::from_bytes(b"exp\xe9.csv");
    std::fs::copy(disk.join(format!("{bare}.csv")), disk.join(latin1)).unwrap();
    std::os::unix::fs::symlink("/nonexistent/k9.csv", disk.join("k9.csv")).unwrap();
    std::fs::write(disk.join("empty.csv"), "").unwrap();

    let o = servoid(dir.path(), &["init", "disk", "--out", "proposed.toml"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    for said in [
        "warning: skipped disk/k9.csv: a symbolic link to /nonexistent/k9.csv, which is not there"
            .to_string(),
        "its name is not UTF-8 (bytes \"exp\\xe9.csv\")".to_string(),
        "warning: skipped disk/empty.csv".to_string(),
        format!("disk/{bare}.csv as `{bare}_csv`, disk/{bare}.tsv as `{bare}_tsv`"),
        format!("1 log(s) have other columns than the campaign's [channels]: disk/{spring}.csv"),
    ] {
        assert!(o.stderr.contains(&said), "{said}\n{}", o.stderr);
    }
    let mut t = toml_of(&dir.path().join("proposed.toml"));
    assert_eq!(runs(&t).len(), 8);
    let own = runs(&t).iter().find(|r| id_of(r) == spring).unwrap()["channels"].clone();
    for (ch, name) in german {
        assert_eq!(own[ch]["column"].as_str(), Some(name), "{ch}");
        assert_eq!(own[ch]["unit"], reference["channels"][ch]["unit"], "{ch}");
    }

    // Filled: the second export dropped, the first given its id back.
    fill_rig(&mut t, &reference);
    let reference_runs = runs(&reference).clone();
    let filled: Vec<toml::Value> = runs(&t)
        .iter()
        .filter(|r| id_of(r) != format!("{bare}_tsv"))
        .map(|r| {
            let mut r = r.as_table().unwrap().clone();
            let id = id_of(&toml::Value::Table(r.clone())).replace(&format!("{bare}_csv"), &bare);
            let want = reference_runs.iter().find(|x| id_of(x) == id).unwrap();
            r.insert("id".into(), id.into());
            r.insert("p_gain".into(), want["p_gain"].clone());
            if let Some(s) = want.get("specimen") {
                r.insert("specimen".into(), s.clone());
            }
            toml::Value::Table(r)
        })
        .collect();
    t.insert("runs".into(), toml::Value::Array(filled));
    std::fs::write(
        dir.path().join("proposed.toml"),
        toml::to_string(&t).unwrap(),
    )
    .unwrap();
    let o = servoid(dir.path(), &["check", "proposed.toml"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    let o = servoid(dir.path(), &["run", "proposed.toml", "--out", "filled"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    assert_eq!(
        rig_of(&dir.path().join("filled/results.json")),
        rig_of(&out.join("results.json")),
        "the same rig as the hand-written manifest"
    );
}

/// A European spreadsheet's export of a night's logs: fields delimited by
/// `;`, numbers with a decimal comma, columns named in German and Spanish
/// (`Zeit [s]`, `Consigna [mm]`, `Weg [mm]`, `Kraft [kN]`). init finds the
/// channels and writes the delimiter and the decimal mark, and the filled
/// manifest gives the same rig, to the last digit, as the logs written
/// with points and commas.
#[test]
fn init_reads_a_european_export_with_its_decimal_comma() {
    use crate::util::PaperSweep;
    let dir = scratch();
    let text = PaperSweep {
        duration_s: 20.0,
        log_format: "csv",
        ..PaperSweep::default()
    }
    .text();
    let sim = crate::util::write(dir.path(), "sim.toml", &text);
    let o = servoid_into(
        dir.path(),
        "simulate",
        &sim,
        &dir.path().join("sim"),
        &["--run"],
    );
    assert_eq!(o.code, 0, "{}", o.stderr);
    let reference = toml_of(&dir.path().join("sim/campaign.toml"));
    let logs = dir.path().join("export");
    std::fs::create_dir(&logs).unwrap();
    for entry in std::fs::read_dir(dir.path().join("sim/logs")).unwrap() {
        let p = entry.unwrap().path();
        let body = std::fs::read_to_string(&p).unwrap();
        let mut lines = body.lines();
        assert_eq!(
            lines.next(),
            Some("time_s,command_mm,displacement_mm,force_kn")
        );
        let mut out = String::from("Zeit [s];Consigna [mm];Weg [mm];Kraft [kN]\n");
        for l in lines {
            out.push_str(&l.replace(',', ";").replace('.', ","));
            out.push('\n');
        }
        std::fs::write(logs.join(p.file_name().unwrap()), out).unwrap();
    }

    let o = servoid(dir.path(), &["init", "export", "--out", "export.toml"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    let mut t = toml_of(&dir.path().join("export.toml"));
    for (ch, column, unit) in [
        ("time", "Zeit [s]", "s"),
        ("command", "Consigna [mm]", "mm"),
        ("displacement", "Weg [mm]", "mm"),
        ("force", "Kraft [kN]", "kN"),
    ] {
        assert_eq!(t["channels"][ch]["column"].as_str(), Some(column), "{ch}");
        assert_eq!(t["channels"][ch]["unit"].as_str(), Some(unit), "{ch}");
    }
    for r in runs(&t) {
        let csv = &r["data"]["csv"];
        assert_eq!(csv["delimiter"].as_str(), Some(";"), "{r}");
        assert_eq!(csv["decimal"].as_str(), Some(","), "{r}");
    }
    fill_rig(&mut t, &reference);
    let reference_runs = runs(&reference).clone();
    for r in t["runs"].as_array_mut().unwrap() {
        let id = r["id"].as_str().unwrap().to_string();
        let want = reference_runs
            .iter()
            .find(|x| x["id"].as_str() == Some(id.as_str()))
            .unwrap();
        let r = r.as_table_mut().unwrap();
        r.insert("p_gain".into(), want["p_gain"].clone());
        if let Some(s) = want.get("specimen") {
            r.insert("specimen".into(), s.clone());
        }
    }
    std::fs::write(dir.path().join("export.toml"), toml::to_string(&t).unwrap()).unwrap();
    let o = servoid(dir.path(), &["check", "export.toml"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    let o = servoid(dir.path(), &["run", "export.toml", "--out", "filled"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    assert_eq!(
        rig_of(&dir.path().join("filled/results.json")),
        rig_of(&dir.path().join("sim/results.json")),
        "the same rig as the logs with decimal points"
    );
}
