//! Helpers for the integration tests: run the binary, scratch folders.

use std::path::{Path, PathBuf};
use std::process::Command;

/// Output of one `servoid` invocation.
pub struct Output {
    pub code: i32,
    pub stdout: String,
    pub stderr: String,
}

/// Run the servoid binary with `args` in `cwd`.
pub fn servoid(cwd: &Path, args: &[&str]) -> Output {
    let out = Command::new(env!("CARGO_BIN_EXE_servoid"))
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("the servoid binary runs");
    Output {
        code: out.status.code().unwrap_or(-1),
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

/// `servoid COMMAND MANIFEST --out OUT EXTRA...` in `cwd`.
pub fn servoid_into(
    cwd: &Path,
    command: &str,
    manifest: &Path,
    out: &Path,
    extra: &[&str],
) -> Output {
    let mut args = vec![
        command,
        manifest.to_str().expect("a UTF-8 path"),
        "--out",
        out.to_str().expect("a UTF-8 path"),
    ];
    args.extend_from_slice(extra);
    servoid(cwd, &args)
}

/// The repository root.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The bundled default's simulation manifest, copied into `dir`; without
/// its Monte Carlo unless `monte_carlo` (tests/sensitivity.rs checks the
/// Monte Carlo, the shards test that it merges and the browser test its
/// page; it costs about 15 s of two cores, which the other tests of the
/// bundled campaign, about other things, do not spend).
pub fn bundled_simulation(dir: &Path, monte_carlo: bool) -> PathBuf {
    let text = std::fs::read_to_string(root().join("experiments/maghareh2018/simulation.toml"))
        .expect("the bundled default");
    let line = "monte_carlo = { points = 20, seeds = 50 }\n";
    assert!(
        text.contains(line),
        "the bundled default runs its Monte Carlo"
    );
    let text = if monte_carlo {
        text
    } else {
        text.replace(line, "")
    };
    write(dir, "simulation.toml", &text)
}

/// Every file under `dir` with its bytes, by path relative to `dir`.
pub fn tree(dir: &Path) -> std::collections::BTreeMap<String, Vec<u8>> {
    let mut out = std::collections::BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if e.file_type().unwrap().is_dir() {
                stack.push(p);
            } else {
                let rel = p.strip_prefix(dir).unwrap().display().to_string();
                out.insert(rel, std::fs::read(&p).unwrap());
            }
        }
    }
    out
}

/// A scratch folder, removed when dropped.
pub fn scratch() -> tempfile::TempDir {
    tempfile::tempdir().expect("a temporary folder")
}

/// The entry of `doc["runs"]` (results.json or truth.json) whose `id` is
/// `id`; panics naming the id when there is none.
pub fn run_by_id<'a>(doc: &'a serde_json::Value, id: &str) -> &'a serde_json::Value {
    doc["runs"]
        .as_array()
        .unwrap_or_else(|| panic!("no runs array looking for run {id}"))
        .iter()
        .find(|r| r["id"] == id)
        .unwrap_or_else(|| panic!("no run {id}"))
}

/// Write `text` to `dir/name` and return the path.
pub fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).expect("write a test file");
    p
}

#[path = "support/mts_data.rs"]
mod mts_data;

/// The shared folder of real MTS logs (see `support/mts_data.rs`, which the
/// unit tests include too), or None after a SKIPPED line.
pub fn mts_data() -> Option<PathBuf> {
    mts_data::mts_data_in(&root())
}

/// The paper's identification runs as its published transfer functions: no
/// specimen, 3060/(s^2 + 267 s + 3060), and spring k1 = 116,640 N/m,
/// 2703/(s^2 + 263.4 s + 3337) (Eqs. 36-37), as manifest `[[runs]]` tables:
/// a rig identified without logs. A macro so that `concat!` builds `const`
/// manifests around it.
macro_rules! paper_tf_runs {
    () => {
        r#"[[runs]]
id = "ns"
role = "no_specimen"
p_gain = 1.0
[runs.data.transfer_function]
num = [3060.0]
den = [1.0, 267.0, 3060.0]

[[runs]]
id = "k1"
role = "spring"
p_gain = 1.0
specimen = { stiffness_n_per_m = 116640.0 }
[runs.data.transfer_function]
num = [2703.0]
den = [1.0, 263.4, 3337.0]
"#
    };
}
pub(crate) use paper_tf_runs;

/// Say on the terminal that a test is skipped and why.
pub fn skipped(why: &str) {
    note(&format!("SKIPPED: {why}"));
}

/// A test that needs what this machine may lack (`why` it cannot run):
/// SKIPPED, unless the environment variable `require` is set (to anything
/// but `0`, as `.ci/run` does), when the absence is a failure.
pub fn skip_unless_required(test: &str, require: &str, why: &str) {
    if std::env::var_os(require).is_none_or(|v| v == "0") {
        skipped(&format!(
            "{test}: {why}; set {require}=1 to make this a failure"
        ));
    } else {
        panic!("{require} is set but {test} cannot run here: {why}");
    }
}

/// A line on the terminal, written to stderr directly, not through
/// `eprintln!`, which the test harness captures and shows only for failing
/// tests.
pub fn note(line: &str) {
    use std::io::Write;
    let _ = writeln!(std::io::stderr(), "{line}");
}

/// Every file under `dir` but the run cache and run.jsonl (timings), with
/// its bytes, by path.
pub fn outputs(dir: &Path) -> Vec<(String, Vec<u8>)> {
    fn walk(base: &Path, dir: &Path, out: &mut Vec<(String, Vec<u8>)>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            let rel = p.strip_prefix(base).unwrap().to_string_lossy().into_owned();
            if rel.starts_with(".cache") || rel == "run.jsonl" {
                continue;
            }
            if p.is_dir() {
                walk(base, &p, out);
            } else {
                out.push((rel, std::fs::read(&p).unwrap()));
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out);
    out.sort_by(|a, b| a.0.cmp(&b.0));
    out
}

/// A simulated campaign of the paper's rig (Table 3) as a lab's first night
/// would log it: a no-specimen run and its two springs (116,640 and
/// 88,540 N/m), a quadratic chirp 0.1-35 Hz of 4 mm, 2 um of LVDT noise,
/// 18-bit converters, the band 0.5-30 Hz and no other identification
/// setting. What a test changes is in the fields.
pub struct PaperSweep {
    pub duration_s: f64,
    /// A second of rest before and after the sweep, or the sweep filling
    /// the record (cut in motion at 35 Hz).
    pub at_rest: bool,
    pub sample_rate_hz: f64,
    pub seed: u64,
    pub log_format: &'static str,
    /// Lines of `[rig.unmodelled]`.
    pub unmodelled: &'static str,
    /// Lines added to `[instrument.displacement]`.
    pub sensor: &'static str,
    /// The springs' `specimen = ...` tables.
    pub springs: [&'static str; 2],
    /// The `[excitation]` table's lines in place of the chirp (its
    /// duration and rests are then theirs).
    pub excitation: Option<&'static str>,
    /// The chirp's amplitude (m).
    pub amplitude_m: f64,
    /// The converters' bits (command, displacement, force).
    pub bits: u32,
    /// Paper's Exp1 as a validation run after the springs.
    pub validation: bool,
    /// Lines of the `[rig]` table (the flow law's supply pressure and
    /// piston area).
    pub rig: &'static str,
}

impl Default for PaperSweep {
    fn default() -> Self {
        Self {
            duration_s: 60.0,
            at_rest: true,
            sample_rate_hz: 1000.0,
            seed: 2026,
            log_format: "parquet",
            unmodelled: "",
            sensor: "",
            springs: [
                "{ stiffness_n_per_m = 116640.0 }",
                "{ stiffness_n_per_m = 88540.0 }",
            ],
            excitation: None,
            amplitude_m: 0.004,
            bits: 18,
            validation: false,
            rig: "",
        }
    }
}

/// The paper's rig, Table 3, as [`PaperSweep`] simulates it.
pub const PAPER_TRUTH: [(&str, f64); 4] = [
    ("beta1", 267.0),
    ("a1b0", 2.412e9),
    ("a2", 7.881e5),
    ("a3", 16.118),
];

impl PaperSweep {
    /// The simulation manifest.
    pub fn text(&self) -> String {
        let (lead, body) = if self.at_rest {
            (1.0, self.duration_s - 2.0)
        } else {
            (0.0, self.duration_s)
        };
        let unmodelled = if self.unmodelled.is_empty() {
            String::new()
        } else {
            format!("[rig.unmodelled]\n{}\n", self.unmodelled)
        };
        let [k1, k2] = self.springs;
        let excitation = match self.excitation {
            Some(lines) => lines.to_string(),
            None => format!(
                "kind = \"chirp\"\nlaw = \"quadratic\"\nf0_hz = 0.1\nf1_hz = 35.0\nduration_s = {body:?}\namplitude_m = {:?}\nlead_in_s = {lead:?}\nlead_out_s = {lead:?}",
                self.amplitude_m
            ),
        };
        let validation = if self.validation {
            "\n[[runs]]\nid = \"exp1\"\nrole = \"validation\"\np_gain = 1.0\nspecimen = { mass_kg = 3.8, damping_ns_per_m = 5.0, stiffness_n_per_m = 129400.0 }\n"
        } else {
            ""
        };
        format!(
            r#"schema_version = 1

[simulation]
name = "first-night"
sample_rate_hz = {fs:?}
seed = {seed}
log_format = "{format}"

[rig]
name = "the paper's rig, simulated"
{rig}

[rig.parameters]
beta1_per_s = 267.0
a1b0_n_per_m_s2 = 2.412e9
a2_n_per_m = 7.881e5
a3_per_s = 16.118

{unmodelled}
[excitation]
{excitation}

[instrument.command]
unit = "mm"
quantization = {{ bits = {bits}, full_scale = 50.0 }}

[instrument.displacement]
unit = "mm"
noise_rms = 0.002
{sensor}quantization = {{ bits = {bits}, full_scale = 50.0 }}

[instrument.force]
unit = "kN"
noise_rms = 0.001
quantization = {{ bits = {bits}, full_scale = 5.0 }}

[identification]
band_hz = [0.5, 30.0]

[[runs]]
id = "no-specimen"
role = "no_specimen"
p_gain = 1.0

[[runs]]
id = "spring-k1"
role = "spring"
p_gain = 1.0
specimen = {k1}

[[runs]]
id = "spring-k2"
role = "spring"
p_gain = 1.0
specimen = {k2}
{validation}"#,
            bits = self.bits,
            fs = self.sample_rate_hz,
            seed = self.seed,
            format = self.log_format,
            sensor = self.sensor,
            rig = self.rig,
        )
    }
}

/// `sweep` (a simulation manifest) simulated in a scratch folder, its logs
/// touched by `logs`, and analysed as the generated manifest has it, less
/// the logs' SHA-256 (a touched log would fail that check first) and with
/// `edit` applied: the results.
pub fn analysed_simulation(
    sweep: &str,
    logs: impl FnOnce(&Path),
    edit: impl FnOnce(String) -> String,
) -> servoid::results::Results {
    use servoid::manifest::{load, simulation::load_simulation_str};
    let dir = scratch();
    let sim = load_simulation_str(sweep, &dir.path().join("sim.toml")).expect("a valid simulation");
    let out = servoid::run::simulate::simulate_campaign(&sim, dir.path()).expect("simulates");
    logs(&dir.path().join("logs"));
    let text: String = std::fs::read_to_string(&out.manifest)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with("sha256 = "))
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(&out.manifest, edit(text)).unwrap();
    servoid::run::analyse(&load(&out.manifest).expect("the analysis manifest loads"))
}

/// Column `col` of the CSV log `path` (a header line, then samples)
/// rewritten by `f(sample, field)`.
pub fn rewrite_column(path: &Path, col: usize, f: impl Fn(usize, &str) -> String) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut out = String::with_capacity(text.len());
    for (i, line) in text.lines().enumerate() {
        if i == 0 {
            out.push_str(line);
        } else {
            let mut fields: Vec<String> = line.split(',').map(String::from).collect();
            fields[col] = f(i - 1, &fields[col]);
            out.push_str(&fields.join(","));
        }
        out.push('\n');
    }
    std::fs::write(path, out).unwrap();
}

/// Every `.rs` file under `dir`, into `out`.
pub fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("the folder is readable") {
        let path = entry.expect("a directory entry").path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}
