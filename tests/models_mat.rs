//! `models.mat` read back by two independent readers, every number
//! checked:
//! - `scipy.io.loadmat` (what Python users have): the transfer functions,
//!   their fits (band, parameters, stds, covariance) and the rig with its
//!   stds and covariance against results.json, a separate serialisation of
//!   the same results; each plant's A, B, C, D against Eq. 10 and Eqs.
//!   34-35 written out here from the rig and the specimen in results.json;
//!   and `ss(A, B, C, D)` against `tf(num, den)`: scipy.signal's `ss2tf` of
//!   the physical and canonical forms gives the run's x1/u. Then the
//!   README's Python lines, run as written.
//! - GNU Octave (MATLAB's language with its own MAT reader, which refused a
//!   layout scipy took): the README's MATLAB lines run as written, and the
//!   rig, its covariance and Exp1's canonical form printed to the last
//!   digit and checked.
//!
//! Where either is missing its part says SKIPPED with the install command,
//! unless `SERVOID_REQUIRE_SCIPY` / `SERVOID_REQUIRE_OCTAVE` is set
//! (`.ci/run` sets both and installs them).

use std::path::{Path, PathBuf};

use serde_json::Value;

use crate::util::{bundled_simulation, run_by_id, scratch, servoid_into, skip_unless_required};

const REQUIRE_SCIPY: &str = "SERVOID_REQUIRE_SCIPY";
const REQUIRE_OCTAVE: &str = "SERVOID_REQUIRE_OCTAVE";

/// GNU Octave (MATLAB's language, its own MAT reader) with the control
/// package, which has `tf`, `ss` and `step` as MATLAB's Control System
/// Toolbox does.
fn octave_with_control() -> Option<PathBuf> {
    let octave = PathBuf::from("octave-cli");
    std::process::Command::new(&octave)
        .args(["--no-gui", "-q", "--eval", "pkg load control"])
        .output()
        .is_ok_and(|o| o.status.success())
        .then_some(octave)
}

/// The README's MATLAB lines, run in Octave as written on this campaign's
/// models.mat (figures not shown), then what they loaded printed to the
/// last digit: the rig and its covariance against results.json, Exp1's
/// canonical form against Eqs. 34-35, and its step against the transfer
/// function's.
fn readme_matlab_runs_in_octave(octave: &Path, out: &Path, results: &Value) {
    let readme = std::fs::read_to_string(crate::util::root().join("README.md")).unwrap();
    let blocks = crate::docs::fenced_blocks(&readme, "matlab");
    let [block] = blocks.as_slice() else {
        panic!("the README has one MATLAB block, not {}", blocks.len());
    };
    let place = "reports/maghareh2018-synthetic/models.mat";
    assert!(
        block.contains(place),
        "the README loads the bundled default's models"
    );
    let script = format!(
        "pkg load control\nset(0, 'defaultfigurevisible', 'off');\n{}\n{}",
        block.replace(place, out.join("models.mat").to_str().unwrap()),
        r#"G = tf(exp1.tf.num, exp1.tf.den); P = ss(exp1.ccf.A, exp1.ccf.B, exp1.ccf.C(1,:), 0);
[y1, t] = step(G, 0.3); y2 = step(P, t);
printf("%.17g\n", numel(m.runs), max(abs(y1 - y2)), y1(end), m.rig.values, m.rig.covariance(:), exp1.ccf.A(:), exp1.p_gain);
"#
    );
    let o = std::process::Command::new(octave)
        .args(["--no-gui", "-q", "--eval", &script])
        .env_remove("DISPLAY")
        .output()
        .expect("octave runs");
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "the README's MATLAB lines fail in Octave:\n{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let got: Vec<f64> = stdout
        .lines()
        .map(|l| {
            l.trim()
                .parse()
                .unwrap_or_else(|_| panic!("{l:?} in\n{stdout}"))
        })
        .collect();
    assert_eq!(got.len(), 3 + 4 + 16 + 16 + 1, "{stdout}");
    assert_eq!(got[0], results["runs"].as_array().unwrap().len() as f64);
    let exp1 = run_by_id(results, "exp1");
    let gain = f(&exp1["tf"]["num"][0]) / f(exp1["tf"]["den"].as_array().unwrap().last().unwrap());
    assert!(got[1] < 1e-9 * gain, "ss and tf step apart by {}", got[1]);
    assert!(
        (got[2] - gain).abs() < 0.05 * gain,
        "x1 at 0.3 s {} vs DC gain {gain}",
        got[2]
    );
    let rig = &results["rig"];
    let names = ["beta1", "a1b0", "a2", "a3"];
    let values: Vec<f64> = names.iter().map(|n| f(&rig[n]["value"])).collect();
    close("Octave rig.values", &got[3..7], &values, 1e-15);
    // covariance(:) is column by column; it is symmetric up to rounding.
    let cov: Vec<f64> = (0..4)
        .flat_map(|j| (0..4).map(move |i| (i, j)))
        .map(|(i, j)| f(&rig["covariance"][i][j]))
        .collect();
    close("Octave rig.covariance", &got[7..23], &cov, 1e-15);
    let p = got[39];
    assert_eq!(p, f(&exp1["p_gain"]));
    let spec = &exp1["specimen"];
    let mck = (
        f(&spec["mass_kg"]),
        f(&spec["damping_ns_per_m"]),
        f(&spec["stiffness_n_per_m"]),
    );
    let rig_at_p = [
        values[0],
        values[1] * p / f(&rig["p_gain"]),
        values[2],
        values[3],
    ];
    let [a, ..] = eq35(rig_at_p, mck, true);
    let a_by_column: Vec<f64> = (0..4).flat_map(|j| a.iter().map(move |r| r[j])).collect();
    close("Octave exp1.ccf.A", &got[23..39], &a_by_column, 1e-12);
}

/// A Python that imports scipy: the one on PATH, else Debian's (where
/// `apt-get install python3-scipy` puts it, when PATH leads to another).
fn python_with_scipy() -> Option<PathBuf> {
    ["python3", "/usr/bin/python3"]
        .iter()
        .map(PathBuf::from)
        .find(|p| {
            std::process::Command::new(p)
                .args(["-c", "import scipy.io, scipy.signal"])
                .output()
                .is_ok_and(|o| o.status.success())
        })
}

/// Reads models.mat and prints what it holds as JSON (NaN as null), with
/// scipy.signal's transfer function of each state space's first output.
const READ_BACK: &str = r#"
import json, math, sys
import numpy as np
from scipy.io import loadmat
from scipy import signal

m = loadmat(sys.argv[1], squeeze_me=False, struct_as_record=True, chars_as_strings=True)

def plain(v):
    # A MATLAB value as JSON: numbers as [rows][cols], text as a string,
    # structs as objects, cells as lists.
    if isinstance(v, np.ndarray) and v.dtype.names is not None:
        assert v.shape[0] == 1, v.shape
        out = [{n: plain(e[n]) for n in v.dtype.names} for e in v[0]]
        return out[0] if len(out) == 1 else out
    if isinstance(v, np.ndarray) and v.dtype == object:
        return [plain(e) for e in v.reshape(-1, order="F")]
    if isinstance(v, np.ndarray) and v.dtype.kind == "U":
        return "".join(v.reshape(-1))
    if isinstance(v, np.ndarray):
        return [[None if math.isnan(x) else float(x) for x in row] for row in v]
    raise TypeError(type(v))

def ss_tf(ss):
    a, b, c, d = (np.array(ss[k], dtype=float) for k in "ABCD")
    num, den = signal.ss2tf(a, b, c[0:1, :], d[0:1, :])
    return {"num": (num[0] / den[0]).tolist(), "den": (den / den[0]).tolist()}

def band_tracking(r, compensated):
    # The held plant x1/u (times the compensator) over the run's band, as
    # scipy.signal evaluates them: freqs for the plant, freqz for b/a, the
    # hold's sinc and half-sample delay, the phase unwrapped from a
    # hundred times below the band.
    c, tf = r["compensator"], r["tf"]
    b, a = np.array(c["b"][0]), np.array(c["a"][0])
    fs = c["fs"][0][0]
    lo, hi = c["band_hz"][0]
    num, den = np.array(tf["num"][0]), np.array(tf["den"][0])
    f = np.concatenate([lo * 0.01 ** (1 - np.arange(50) / 50), lo * (hi / lo) ** (np.arange(200) / 199)])
    _, g = signal.freqs(num, den, worN=2 * np.pi * f)
    g = g * np.exp(-2j * np.pi * f * tf["delay_s"][0][0])
    h = g * np.sinc(f / fs) * np.exp(-1j * np.pi * f / fs)
    if compensated:
        h = h * signal.freqz(b, a, worN=f, fs=fs)[1]
    delay = -np.unwrap(np.angle(h)) / (2 * np.pi * f) * fs
    return {
        "max_amplitude_error_pct": float(100 * np.abs(np.abs(h[50:]) - 1).max()),
        "delay_samples_min": float(delay[50:].min()),
        "delay_samples_max": float(delay[50:].max()),
    }

out = {
    "header": m["__header__"].decode(),
    "servoid": plain(m["servoid"]),
    "rig": plain(m["rig"]),
    "runs": [],
}
runs = m["runs"]
assert runs.shape[0] == 1
for i in range(runs.shape[1]):
    r = {n: plain(runs[0, i][n]) for n in runs.dtype.names}
    for form in ("physical", "ccf", "ccf_simplified"):
        if isinstance(r[form], dict):
            r[form]["ss2tf"] = ss_tf(r[form])
    if isinstance(r["compensator"], dict):
        r["scipy_band"] = {"uncompensated": band_tracking(r, False), "compensated": band_tracking(r, True)}
    out["runs"].append(r)
print(json.dumps(out))
"#;

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("a number, not {v}"))
}

/// A MATLAB matrix as read back: rows of numbers (NaN read as null).
fn matrix(v: &Value) -> Vec<Vec<f64>> {
    v.as_array()
        .unwrap_or_else(|| panic!("a matrix, not {v}"))
        .iter()
        .map(|row| {
            row.as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap_or(f64::NAN))
                .collect()
        })
        .collect()
}

/// A row vector (1 x n) as read back.
fn row(v: &Value) -> Vec<f64> {
    let m = matrix(v);
    assert_eq!(m.len(), 1, "a row vector, not {v}");
    m.into_iter().next().unwrap()
}

fn scalar(v: &Value) -> f64 {
    let r = row(v);
    assert_eq!(r.len(), 1, "a scalar, not {v}");
    r[0]
}

fn numbers(v: &Value) -> Vec<f64> {
    v.as_array().unwrap().iter().map(f).collect()
}

fn close(what: &str, got: &[f64], want: &[f64], rel: f64) {
    assert_eq!(got.len(), want.len(), "{what}: {got:?} vs {want:?}");
    let scale = want.iter().fold(0.0_f64, |m, w| m.max(w.abs()));
    for (g, w) in got.iter().zip(want) {
        assert!(
            (g - w).abs() <= rel * scale.max(f64::MIN_POSITIVE),
            "{what}: {got:?} vs {want:?}"
        );
    }
}

fn close_matrix(what: &str, got: &[Vec<f64>], want: &[Vec<f64>], rel: f64) {
    assert_eq!(got.len(), want.len(), "{what}: rows");
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        close(&format!("{what} row {}", i + 1), g, w, rel);
    }
}

/// Eq. 10 at a1b0 for the run's P gain: states [x1, x2, f, r] for an SDOF
/// specimen, outputs [x1, f].
fn eq10_sdof(rig: [f64; 4], (m, c, k): (f64, f64, f64)) -> [Vec<Vec<f64>>; 4] {
    let [b1, a1b0, a2, a3] = rig;
    [
        vec![
            vec![0.0, 1.0, 0.0, 0.0],
            vec![-k / m, -c / m, 1.0 / m, 0.0],
            vec![0.0, -a2, -a3, 1.0],
            vec![-a1b0, 0.0, 0.0, -b1],
        ],
        vec![vec![0.0], vec![0.0], vec![0.0], vec![a1b0]],
        vec![vec![1.0, 0.0, 0.0, 0.0], vec![0.0, 0.0, 1.0, 0.0]],
        vec![vec![0.0], vec![0.0]],
    ]
}

/// Eqs. 34-35 (signs checked in docs/model.md) with f = m x3 + c x2 + k x1 substituted
/// and Cn = h'' = -(c x4 + k x3)/m (h = -(c x2 + k x1)/m) kept or dropped.
fn eq35(rig: [f64; 4], (m, c, k): (f64, f64, f64), cn: bool) -> [Vec<Vec<f64>>; 4] {
    let [b1, a1b0, a2, a3] = rig;
    let (dh1, dh2) = (-k / m, -c / m);
    let c1 = a1b0 / m;
    let c2 = -b1 * a2 / m + (b1 + a3) * dh1;
    let c3 = (b1 + a3) * dh2 - a2 / m;
    let c4 = -(b1 + a3);
    let c5 = -b1 * a3 / m;
    let (n3, n4) = if cn { (dh1, dh2) } else { (0.0, 0.0) };
    [
        vec![
            vec![0.0, 1.0, 0.0, 0.0],
            vec![0.0, 0.0, 1.0, 0.0],
            vec![0.0, 0.0, 0.0, 1.0],
            vec![-c1 + c5 * k, c2 + c5 * c, c3 + c5 * m + n3, c4 + n4],
        ],
        vec![vec![0.0], vec![0.0], vec![0.0], vec![c1]],
        vec![vec![1.0, 0.0, 0.0, 0.0], vec![k, c, m, 0.0]],
        vec![vec![0.0], vec![0.0]],
    ]
}

fn check_state_space(what: &str, got: &Value, want: &[Vec<Vec<f64>>; 4]) {
    for (name, w) in ["A", "B", "C", "D"].iter().zip(want) {
        close_matrix(&format!("{what}.{name}"), &matrix(&got[name]), w, 1e-12);
    }
}

/// The campaign's models.mat, read back.
fn read_back(python: &Path, out: &Path) -> Value {
    let o = std::process::Command::new(python)
        .args(["-c", READ_BACK])
        .arg(out.join("models.mat"))
        .output()
        .expect("python runs");
    assert!(
        o.status.success(),
        "scipy could not read models.mat:\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_slice(&o.stdout).expect("the reader's JSON")
}

#[test]
fn models_mat_reads_back_in_scipy_and_octave() {
    let test = "models_mat_reads_back_in_scipy_and_octave";
    let python = python_with_scipy();
    let octave = octave_with_control();
    if python.is_none() {
        skip_unless_required(
            &format!("{test} (scipy)"),
            REQUIRE_SCIPY,
            "needs Python with scipy (apt-get install -y python3-scipy, or pip install scipy)",
        );
    }
    if octave.is_none() {
        skip_unless_required(
            &format!("{test} (Octave)"),
            REQUIRE_OCTAVE,
            "needs GNU Octave with its control package (apt-get install -y octave octave-control)",
        );
    }
    if python.is_none() && octave.is_none() {
        return;
    }
    let dir = scratch();
    let sim = bundled_simulation(dir.path(), false);
    let out = dir.path().join("out");
    let o = servoid_into(dir.path(), "simulate", &sim, &out, &["--run"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    let record = std::fs::read_to_string(out.join("outputs.sha256")).unwrap();
    assert!(
        record.lines().any(|l| l.ends_with("  models.mat")),
        "the set's record lists models.mat"
    );
    let results: Value =
        serde_json::from_slice(&std::fs::read(out.join("results.json")).unwrap()).unwrap();
    if let Some(octave) = octave {
        readme_matlab_runs_in_octave(&octave, &out, &results);
    }
    if let Some(python) = python {
        every_number_in_scipy(&python, &out, &results);
    }
}

/// Everything in models.mat, read back by scipy, against results.json and
/// the paper's equations.
fn every_number_in_scipy(python: &Path, out: &Path, results: &Value) {
    let mat = read_back(python, out);

    assert!(
        mat["header"]
            .as_str()
            .unwrap()
            .starts_with("MATLAB 5.0 MAT-file"),
        "{}",
        mat["header"]
    );
    assert_eq!(mat["servoid"]["campaign"], results["campaign"]["name"]);
    assert_eq!(
        mat["servoid"]["manifest_sha256"],
        results["campaign"]["manifest_sha256"]
    );

    // The rig, with its stds and covariance.
    let rig = &results["rig"];
    let names = ["beta1", "a1b0", "a2", "a3"];
    let values: Vec<f64> = names.iter().map(|n| f(&rig[n]["value"])).collect();
    let stds: Vec<f64> = names.iter().map(|n| f(&rig[n]["std"])).collect();
    close("rig.values", &row(&mat["rig"]["values"]), &values, 1e-15);
    close("rig.std", &row(&mat["rig"]["std"]), &stds, 1e-15);
    for (n, v) in names.iter().zip(&values) {
        close(&format!("rig.{n}"), &[scalar(&mat["rig"][n])], &[*v], 1e-15);
    }
    assert_eq!(mat["rig"]["names"], serde_json::json!(names));
    let cov: Vec<Vec<f64>> = rig["covariance"]
        .as_array()
        .unwrap()
        .iter()
        .map(numbers)
        .collect();
    close_matrix(
        "rig.covariance",
        &matrix(&mat["rig"]["covariance"]),
        &cov,
        1e-15,
    );
    close(
        "rig.R1",
        &[scalar(&mat["rig"]["R1"])],
        &[f(&rig["R1"]["value"])],
        1e-15,
    );
    let rig_p = f(&rig["p_gain"]);

    let runs = mat["runs"].as_array().unwrap();
    let want_runs = results["runs"].as_array().unwrap();
    assert_eq!(runs.len(), want_runs.len(), "one entry per run");
    let mut canonical = 0;
    for (got, want) in runs.iter().zip(want_runs) {
        let id = want["id"].as_str().unwrap();
        assert_eq!(got["id"], want["id"]);
        assert_eq!(got["role"], want["role"], "{id}");
        close(
            &format!("{id} p_gain"),
            &[scalar(&got["p_gain"])],
            &[f(&want["p_gain"])],
            0.0,
        );
        let tf = &got["tf"];
        let wtf = &want["tf"];
        close(
            &format!("{id} num"),
            &row(&tf["num"]),
            &numbers(&wtf["num"]),
            1e-15,
        );
        close(
            &format!("{id} den"),
            &row(&tf["den"]),
            &numbers(&wtf["den"]),
            1e-15,
        );
        close(
            &format!("{id} delay"),
            &[scalar(&tf["delay_s"])],
            &[f(&wtf["delay_s"])],
            0.0,
        );
        assert_eq!(tf["source"], wtf["source"], "{id}");
        if wtf["source"] == "fitted" {
            let fit = &want["fit"];
            close(
                &format!("{id} band"),
                &row(&tf["band_hz"]),
                &numbers(&fit["band_hz"]),
                0.0,
            );
            close(
                &format!("{id} params"),
                &row(&tf["params"]),
                &numbers(&fit["params"]),
                1e-15,
            );
            let std = numbers(&fit["std"]);
            close(&format!("{id} std"), &row(&tf["std"]), &std, 1e-15);
            assert_eq!(tf["param_names"], fit["param_names"], "{id}");
            // As results.json has it, and its diagonal is the stds squared
            // (the fit states its stds as the root of it).
            let c = matrix(&tf["covariance"]);
            let want_c: Vec<Vec<f64>> = fit["covariance"]
                .as_array()
                .unwrap()
                .iter()
                .map(numbers)
                .collect();
            assert_eq!(c.len(), std.len(), "{id}: covariance is p x p");
            close_matrix(&format!("{id} covariance"), &c, &want_c, 1e-15);
            for (i, s) in std.iter().enumerate() {
                let diagonal = [c[i][i].sqrt()];
                close(
                    &format!("{id} covariance diagonal"),
                    &diagonal,
                    &[*s],
                    1e-12,
                );
                for j in 0..i {
                    let scale = (c[i][i] * c[j][j]).sqrt();
                    assert!((c[i][j] - c[j][i]).abs() <= 1e-9 * scale, "{id}: symmetric");
                }
            }
        }
        // The plant as a state space, from the rig at this run's P gain.
        let p = f(&want["p_gain"]);
        let rig_at_p = [values[0], values[1] * p / rig_p, values[2], values[3]];
        let spec = &want["specimen"];
        if spec["kind"] == "linear_sdof" {
            let mck = (
                f(&spec["mass_kg"]),
                f(&spec["damping_ns_per_m"]),
                f(&spec["stiffness_n_per_m"]),
            );
            check_state_space(
                &format!("{id} physical"),
                &got["physical"],
                &eq10_sdof(rig_at_p, mck),
            );
            check_state_space(
                &format!("{id} ccf"),
                &got["ccf"],
                &eq35(rig_at_p, mck, true),
            );
            check_state_space(
                &format!("{id} ccf_simplified"),
                &got["ccf_simplified"],
                &eq35(rig_at_p, mck, false),
            );
            // ss(A, B, C, D) of either exact form is the run's x1/u
            // (Eq. 17, the model's, in results.json); the simplified one
            // is not (its poles differ, Sec. 3.2.2).
            for form in ["physical", "ccf"] {
                let t = &got[form]["ss2tf"];
                close(
                    &format!("{id} {form} den"),
                    &numbers(&t["den"]),
                    &numbers(&wtf["den"]),
                    1e-9,
                );
                let num = numbers(&t["num"]);
                let lead = num.len() - wtf["num"].as_array().unwrap().len();
                close(
                    &format!("{id} {form} num"),
                    &num[lead..],
                    &numbers(&wtf["num"]),
                    1e-9,
                );
                assert!(
                    num[..lead].iter().all(|x| x.abs() < 1e-6 * num[lead].abs()),
                    "{id} {form}: {num:?}"
                );
            }
            let simplified = numbers(&got["ccf_simplified"]["ss2tf"]["den"]);
            let wden = numbers(&wtf["den"]);
            assert!(
                simplified
                    .iter()
                    .zip(&wden)
                    .any(|(a, b)| (a - b).abs() > 1e-6 * b.abs()),
                "{id}: the simplified form differs from the plant"
            );
            let ccf = results["ccf"]
                .as_array()
                .unwrap()
                .iter()
                .find(|c| c["run"] == id)
                .unwrap();
            for name in ["C1", "C2", "C3", "C4", "C5"] {
                close(
                    &format!("{id} {name}"),
                    &[scalar(&got["ccf"][name])],
                    &[f(&ccf[name])],
                    1e-15,
                );
            }
            canonical += 1;
        } else {
            assert_eq!(
                got["ccf"],
                serde_json::json!([]),
                "{id}: no CCF without a mass"
            );
        }
    }
    assert_eq!(canonical, 4, "Exp1-Exp4 have their plants in both forms");
    compensators_in_scipy(runs, want_runs);
    // The no-specimen run's physical form is Eq. 10 with f = 0: two states.
    let ns = runs.iter().find(|r| r["id"] == "no-specimen").unwrap();
    let (b1, a1b0) = (values[0], values[1]);
    close_matrix(
        "no-specimen physical.A",
        &matrix(&ns["physical"]["A"]),
        &[vec![0.0, 1.0 / values[2]], vec![-a1b0, -b1]],
        1e-12,
    );
    assert_eq!(run_by_id(results, "no-specimen")["role"], "no_specimen");

    readme_python_runs(python, out);
}

/// Each validation run's compensator as models.mat gives it, evaluated by
/// scipy.signal on the plant x1/u it was designed for: the tracking over
/// the band results.json states, and the compensator's targets on the bundled
/// default (delay under one sample, amplitude within 1 %), which the plant
/// alone misses by far.
fn compensators_in_scipy(runs: &[Value], want_runs: &[Value]) {
    let mut compensated = 0;
    for (got, want) in runs.iter().zip(want_runs) {
        let id = want["id"].as_str().unwrap();
        let stated = &want["tracking"]["compensator"];
        if want["role"] != "validation" {
            assert_eq!(got["compensator"], serde_json::json!([]), "{id}");
            continue;
        }
        let d = &stated["design"];
        close(
            &format!("{id} b"),
            &row(&got["compensator"]["b"]),
            &numbers(&d["b"]),
            1e-15,
        );
        close(
            &format!("{id} a"),
            &row(&got["compensator"]["a"]),
            &numbers(&d["a"]),
            1e-15,
        );
        for side in ["uncompensated", "compensated"] {
            for key in [
                "max_amplitude_error_pct",
                "delay_samples_min",
                "delay_samples_max",
            ] {
                let (g, w) = (f(&got["scipy_band"][side][key]), f(&stated[side][key]));
                assert!(
                    (g - w).abs() < 1e-6 * w.abs().max(1.0),
                    "{id} {side} {key}: scipy {g}, results.json {w}"
                );
            }
        }
        let c = &got["scipy_band"]["compensated"];
        let worst_delay = f(&c["delay_samples_min"])
            .abs()
            .max(f(&c["delay_samples_max"]).abs());
        assert!(f(&c["max_amplitude_error_pct"]) < 1.0, "{id}: {c}");
        assert!(worst_delay < 1.0, "{id}: {c}");
        assert!(
            f(&got["scipy_band"]["uncompensated"]["delay_samples_min"]) > 10.0,
            "{id}"
        );
        assert_eq!(stated["meets_target"], true, "{id}");
        compensated += 1;
    }
    assert_eq!(compensated, 4, "Exp1-Exp4 each have a compensator");
}

/// The README's Python lines, run as written on this campaign's models.mat:
/// Exp1's canonical form stepped, which must settle at x1/u's DC gain and
/// match the transfer function's step.
fn readme_python_runs(python: &Path, out: &Path) {
    let readme = std::fs::read_to_string(crate::util::root().join("README.md")).unwrap();
    let blocks = crate::docs::fenced_blocks(&readme, "python");
    let [block] = blocks.as_slice() else {
        panic!("the README has one Python block, not {}", blocks.len());
    };
    let place = "reports/maghareh2018-synthetic/models.mat";
    assert!(
        block.contains(place),
        "the README loads the bundled default's models"
    );
    let script = format!(
        "{}\n{}",
        block.replace(place, out.join("models.mat").to_str().unwrap()),
        r#"import numpy as np
gain = exp1.tf.num / exp1.tf.den[-1]
y = signal.step(signal.TransferFunction(exp1.tf.num, exp1.tf.den), T=t)[1]
assert np.all(np.isfinite(x1)) and len(x1) > 10, x1
assert abs(x1[-1] - gain) < 1e-3 * abs(gain), (x1[-1], gain)
assert np.abs(y - x1).max() < 1e-9 * abs(gain), np.abs(y - x1).max()
"#
    );
    let o = std::process::Command::new(python)
        .args(["-c", &script])
        .output()
        .expect("python runs");
    assert!(
        o.status.success(),
        "the README's Python lines fail:\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
}

/// A nonlinear specimen in models.mat: Exp4 made a Duffing specimen
/// (k3 = 1e9 N/m^3). Its mass, damping and stiffness were `[]` and its
/// cubic stiffness missing; now every parameter results.json gives it is
/// in the run's `specimen` struct, read back by scipy, with its kind.
#[test]
fn a_nonlinear_specimen_keeps_every_parameter_in_models_mat() {
    let Some(python) = python_with_scipy() else {
        skip_unless_required(
            "a_nonlinear_specimen_keeps_every_parameter_in_models_mat",
            REQUIRE_SCIPY,
            "needs Python with scipy (apt-get install -y python3-scipy, or pip install scipy)",
        );
        return;
    };
    let dir = scratch();
    let sim = bundled_simulation(dir.path(), false);
    let text = std::fs::read_to_string(&sim).unwrap();
    let exp4 = "p_gain = 2.0\nspecimen = { mass_kg = 3.8, damping_ns_per_m = 5.0, stiffness_n_per_m = 84340.0 }";
    assert!(text.contains(exp4), "Exp4 as the bundled default has it");
    std::fs::write(
        &sim,
        text.replace(
            exp4,
            "p_gain = 2.0\nspecimen = { model = \"duffing\", mass_kg = 3.8, damping_ns_per_m = 5.0, stiffness_n_per_m = 84340.0, cubic_stiffness_n_per_m3 = 1e9 }",
        ),
    )
    .unwrap();
    let out = dir.path().join("out");
    let o = servoid_into(dir.path(), "simulate", &sim, &out, &["--run"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    let results: Value =
        serde_json::from_slice(&std::fs::read(out.join("results.json")).unwrap()).unwrap();
    let want = &run_by_id(&results, "exp4")["specimen"];
    assert_eq!(want["kind"], "duffing", "{want}");
    let back = read_back(&python, &out);
    let got = back["runs"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["id"] == "exp4")
        .expect("exp4 in models.mat");
    let spec = &got["specimen"];
    assert_eq!(spec["kind"], "duffing specimen", "{spec}");
    let fields = want.as_object().unwrap();
    assert_eq!(fields.len(), 5, "kind and four parameters: {want}");
    for (name, value) in fields.iter().filter(|(n, _)| *n != "kind") {
        assert_eq!(scalar(&spec[name]), f(value), "{name}");
    }
}
