//! The nightly batch (`cargo bench --bench night`): a synthetic night of
//! logs, 120 s at 1 kHz each, written by `servoid simulate` and run by one
//! `servoid run` process, timed as a whole process the way a lab's cron job
//! runs it. For CSV and Parquet logs, without figures (`--figures none`)
//! and with the default figures (no `--figures`: the summary's, PNG), it
//! reports the wall time, logs/s, MB/s of log files, the CPU time (user +
//! system) over the wall time, the peak RSS, which GNU time
//! (`/usr/bin/time -v`) reads from the kernel, and what the job wrote (kB
//! a log); then the cached rerun into the same output folder. Criterion is not used: it
//! times closures in its own process, and neither the peak RSS nor a
//! process's start-up is visible from there.
//!
//! The night: one no-specimen run, a fifth springs (the paper's k1 and k2, a
//! stiffer one, then 60-160 kN/m), and the rest validation runs with SDOF specimens of varied mass, damping, stiffness and P gain
//! (a quadratic chirp 0.1-35 Hz of 118 s with a second of rest either side,
//! 18-bit I/O, LVDT and load-cell noise, the bundled default's
//! identification settings). The logs are generated once, outside the timed
//! part, into a scratch folder, and reused by later invocations while their
//! simulation manifest is unchanged (delete the folder to regenerate). They
//! are read from the page cache: MB/s is not a disk speed.
//!
//! Environment:
//! - `SERVOID_NIGHT_LOGS`: logs per night, or a comma-separated list
//!   (`100,500`) to see whether the peak RSS depends on it; default 500;
//! - `SERVOID_NIGHT_REPEATS`: runs of each measurement (default 3; the
//!   table gives medians and ranges);
//! - `SERVOID_NIGHT_FORMATS`: `csv,parquet` (the default) or either alone;
//! - `SERVOID_NIGHT_FIGURES`: the figure choices, `none,default` (the
//!   default), any of `none`, `default`, `summary`, `png`, `svg`, `all`;
//! - `SERVOID_NIGHT_JOBS`: passed as `--jobs` (default: servoid's, two
//!   workers per core);
//! - `SERVOID_NIGHT_MAX_OTHERS`: on a shared machine, measure a run again
//!   (up to 5 tries) when the rest of the machine used more than this many
//!   cores during it (read from /proc/stat; e.g. 0.1); unset, every run
//!   counts. The table always shows what the others used.
//! - `SERVOID_NIGHT_DIR`: the scratch folder (default
//!   `<target dir>/servoid-night`; 500 logs take 1.3 GB as Parquet and
//!   3.9 GB as CSV);
//! - `SERVOID_BIN`: the servoid binary to time. Without it the bench runs
//!   `cargo build --release --locked --bin servoid` first (a no-op when it
//!   is up to date) and times `<target dir>/release/servoid`, so the binary
//!   is never older than the sources.
//!
//! On two cores, 500 logs with three repeats take about 5 minutes, of
//! which the first generation of the logs is about 1 minute.
//!
//! The table goes to stdout and to `<scratch>/night.md`; progress goes to
//! stderr. A run that fails (a nonzero exit, or a signal) is reported as
//! such with the last line of its stderr, not hidden.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode, Stdio};
use std::time::Instant;

const TIME: &str = "/usr/bin/time";
const SAMPLE_RATE_HZ: f64 = 1000.0;
const LOG_SECONDS: f64 = 120.0;
/// The first spring tests of the night (N/m): the paper's k1 and k2 and a
/// stiffer one; the others spread over 60-160 kN/m.
const SPRINGS_N_PER_M: [f64; 3] = [116_640.0, 88_540.0, 150_000.0];
/// The project's targets for a night on two cores, without figures and
/// with the default figures, and what the default figures' night may
/// write a log (kB = 1,000 bytes).
const TARGET_LOGS_PER_S: f64 = 100.0;
const TARGET_FIGURES_LOGS_PER_S: f64 = 25.0;
const TARGET_KB_PER_LOG: f64 = 500.0;
const TARGET_PEAK_RSS_KB: u64 = 1_000_000;
/// The largest night's peak RSS over the smallest's, at most.
const TARGET_RSS_GROWTH: f64 = 1.25;
/// The figure choices the bench knows: `default` passes no `--figures`.
const FIGURES: [&str; 6] = ["none", "default", "summary", "png", "svg", "all"];
/// "Both cores busy": CPU time over wall time at least this share of the
/// cores.
const TARGET_CPU_SHARE: f64 = 0.9;
/// Tries of one measurement under `SERVOID_NIGHT_MAX_OTHERS`.
const MAX_ATTEMPTS: usize = 5;
/// The others' CPU time (s) below which a run is not measured again,
/// whatever its share: five ticks of /proc/stat.
const MIN_OTHERS_S: f64 = 0.05;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Format {
    Csv,
    Parquet,
}

impl Format {
    fn name(self) -> &'static str {
        match self {
            Format::Csv => "csv",
            Format::Parquet => "parquet",
        }
    }
}

struct Config {
    sizes: Vec<usize>,
    repeats: usize,
    formats: Vec<Format>,
    figures: Vec<&'static str>,
    jobs: Option<usize>,
    /// Measure a run again when the rest of the machine used more than
    /// this many cores meanwhile.
    max_others: Option<f64>,
    dir: PathBuf,
    bin: PathBuf,
}

/// One process, as GNU time saw it.
#[derive(Debug, Clone)]
struct Sample {
    wall_s: f64,
    user_s: f64,
    system_s: f64,
    peak_rss_kb: u64,
    /// CPU time the rest of the machine used meanwhile (s): other builds
    /// and benchmarks on the same cores; None where /proc/stat is missing.
    other_cpu_s: Option<f64>,
    /// Bytes in the output folder once the job is done.
    out_bytes: u64,
    /// None when the process exited with 0; else how it ended and the last
    /// line of its stderr.
    failure: Option<String>,
}

/// One row of the table: a night, a format, a figure choice, fresh or
/// cached.
struct Row {
    logs: usize,
    log_bytes: u64,
    format: Format,
    figures: &'static str,
    cached: bool,
    samples: Vec<Sample>,
    /// Runs measured again because the rest of the machine was busy.
    redone: usize,
}

fn main() -> ExitCode {
    // `cargo bench` passes --bench; `cargo test --benches` does not, and
    // tests never time.
    if !std::env::args().any(|a| a == "--bench") {
        println!("night: a benchmark of whole processes; run it with `cargo bench --bench night`");
        return ExitCode::SUCCESS;
    }
    if !Path::new(TIME).exists() {
        println!(
            "SKIPPED: {TIME} is missing; it measures the peak RSS (Debian: apt-get install -y time)"
        );
        return ExitCode::SUCCESS;
    }
    let config = match config() {
        Ok(c) => c,
        Err(e) => {
            eprintln!("night: {e}");
            return ExitCode::FAILURE;
        }
    };
    match night(&config) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("night: {e}");
            ExitCode::FAILURE
        }
    }
}

fn env_list<T: std::str::FromStr>(name: &str, default: &str) -> Result<Vec<T>, String> {
    let text = std::env::var(name).unwrap_or_else(|_| default.to_string());
    text.split(',')
        .map(|s| s.trim())
        .filter(|s| !s.is_empty())
        .map(|s| {
            s.parse()
                .map_err(|_| format!("{name}: cannot read `{s}` (got `{text}`)"))
        })
        .collect()
}

fn config() -> Result<Config, String> {
    let sizes: Vec<usize> = env_list("SERVOID_NIGHT_LOGS", "500")?;
    if sizes.is_empty() || sizes.iter().any(|&n| n < SPRINGS_N_PER_M.len() + 2) {
        return Err(format!(
            "SERVOID_NIGHT_LOGS: each night needs at least {} logs",
            SPRINGS_N_PER_M.len() + 2
        ));
    }
    let repeats = env_list::<usize>("SERVOID_NIGHT_REPEATS", "3")?
        .first()
        .copied()
        .filter(|&r| r > 0)
        .ok_or("SERVOID_NIGHT_REPEATS: at least 1")?;
    let formats = env_list::<String>("SERVOID_NIGHT_FORMATS", "csv,parquet")?
        .iter()
        .map(|f| match f.as_str() {
            "csv" => Ok(Format::Csv),
            "parquet" => Ok(Format::Parquet),
            other => Err(format!(
                "SERVOID_NIGHT_FORMATS: `{other}` is not csv or parquet"
            )),
        })
        .collect::<Result<Vec<_>, _>>()?;
    let figures = env_list::<String>("SERVOID_NIGHT_FIGURES", "none,default")?
        .iter()
        .map(|f| {
            FIGURES.iter().copied().find(|k| k == f).ok_or(format!(
                "SERVOID_NIGHT_FIGURES: `{f}` is not one of {}",
                FIGURES.join(", ")
            ))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let jobs = env_list::<usize>("SERVOID_NIGHT_JOBS", "")?
        .first()
        .copied();
    let max_others = env_list::<f64>("SERVOID_NIGHT_MAX_OTHERS", "")?
        .first()
        .copied();

    // This binary is <target>/release/deps/night-<hash>.
    let exe = std::env::current_exe().map_err(|e| format!("where am I: {e}"))?;
    let target = exe
        .ancestors()
        .nth(3)
        .ok_or("cannot find the target folder from the bench's path")?
        .to_path_buf();
    let dir = std::env::var_os("SERVOID_NIGHT_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| target.join("servoid-night"));
    let bin = match std::env::var_os("SERVOID_BIN") {
        Some(b) => PathBuf::from(b),
        None => build_servoid(&target)?,
    };
    if !bin.is_file() {
        return Err(format!("no servoid binary at {}", bin.display()));
    }
    Ok(Config {
        sizes,
        repeats,
        formats,
        figures,
        jobs,
        max_others,
        dir,
        bin,
    })
}

/// `cargo bench` builds the benches, not always the binary: build it (a
/// no-op when it is up to date) in the same target folder.
fn build_servoid(target: &Path) -> Result<PathBuf, String> {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR")).join("Cargo.toml");
    eprintln!("night: cargo build --release --locked --bin servoid");
    let status = Command::new(cargo)
        .args(["build", "--release", "--locked", "--bin", "servoid"])
        .arg("--manifest-path")
        .arg(&manifest)
        .env("CARGO_TARGET_DIR", target)
        .status()
        .map_err(|e| format!("cannot run cargo: {e}"))?;
    if !status.success() {
        return Err(format!("cargo build failed ({status})"));
    }
    Ok(target
        .join("release")
        .join(format!("servoid{}", std::env::consts::EXE_SUFFIX)))
}

/// The simulation manifest of a night of `n` logs.
fn simulation_manifest(n: usize, format: Format) -> String {
    let lead_s = 1.0;
    let mut t = format!(
        r#"# A synthetic night for `cargo bench --bench night`: {n} logs of {LOG_SECONDS} s
# at {SAMPLE_RATE_HZ} Hz. Written by benches/night.rs; SYNTHETIC logs.
schema_version = 1

[simulation]
name = "night-{n}-{fmt}"
description = "A synthetic night of {n} logs for the nightly-batch benchmark"
sample_rate_hz = {SAMPLE_RATE_HZ:?}
seed = 2018
log_format = "{fmt}"

[rig]
name = "Simulated rig at the paper's parameters"

[rig.parameters]
beta1_per_s = 267.0
a1b0_n_per_m_s2 = 2.412e9
a2_n_per_m = 7.881e5
a3_per_s = 16.118
p_gain = 1.0

[excitation]
kind = "chirp"
law = "quadratic"
f0_hz = 0.1
f1_hz = 35.0
duration_s = {chirp_s:?}
amplitude_m = 0.004
lead_in_s = {lead_s:?}
lead_out_s = {lead_s:?}

[instrument.command]
unit = "mm"
quantization = {{ bits = 18, full_scale = 50.0 }}

[instrument.displacement]
unit = "mm"
noise_rms = 0.002
quantization = {{ bits = 18, full_scale = 50.0 }}

[instrument.force]
unit = "kN"
noise_rms = 0.001
quantization = {{ bits = 18, full_scale = 5.0 }}

[identification]
band_hz = [0.5, 30.0]
coherence_min = 0.8
command_intersample = "sample_and_hold"
frf = {{ estimator = "etfe", segment_length = 8192, overlap = 0.5, window = "rectangular", detrend = "mean" }}

[[runs]]
id = "no-specimen"
role = "no_specimen"
p_gain = 1.0
"#,
        fmt = format.name(),
        chirp_s = LOG_SECONDS - 2.0 * lead_s,
    );
    for i in 0..springs(n) {
        let k = SPRINGS_N_PER_M
            .get(i)
            .copied()
            .unwrap_or(60_000.0 + 1_000.0 * ((i * 37) % 101) as f64);
        let _ = write!(
            t,
            "\n[[runs]]\nid = \"spring-k{}\"\nrole = \"spring\"\np_gain = 1.0\nspecimen = {{ stiffness_n_per_m = {k:?} }}\n",
            i + 1
        );
    }
    // Specimens spread over 2-6 kg, 2-20 N s/m and 60-160 kN/m (natural
    // frequencies about 16-45 Hz), half of them at P = 2, in an order that
    // mixes them.
    for j in 0..n - 1 - springs(n) {
        let mass_kg = 2.0 + 0.1 * ((j * 17) % 41) as f64;
        let damping = 2.0 + 0.5 * ((j * 7) % 37) as f64;
        let stiffness = 60_000.0 + 1_000.0 * ((j * 53) % 101) as f64;
        let p_gain = if j % 2 == 0 { 1.0 } else { 2.0 };
        let _ = write!(
            t,
            "\n[[runs]]\nid = \"sdof-{:04}\"\nrole = \"validation\"\np_gain = {p_gain:?}\nspecimen = {{ mass_kg = {mass_kg:.1}, damping_ns_per_m = {damping:.1}, stiffness_n_per_m = {stiffness:?} }}\n",
            j + 1
        );
    }
    t
}

/// The spring runs of a night of `n` logs: a fifth, at least the three of
/// [`SPRINGS_N_PER_M`].
fn springs(n: usize) -> usize {
    (n / 5).max(SPRINGS_N_PER_M.len())
}

/// A night's logs and analysis manifest, generated by `servoid simulate`
/// unless the folder already holds them for the same simulation manifest.
/// Returns the campaign manifest and the logs' total size.
fn generate(config: &Config, n: usize, format: Format) -> Result<(PathBuf, u64), String> {
    let dir = config.dir.join(format!("{}-{n}", format.name()));
    let sim_path = dir.join("simulation.toml");
    let campaign = dir.join("campaign.toml");
    let text = simulation_manifest(n, format);
    let same = std::fs::read_to_string(&sim_path).is_ok_and(|old| old == text);
    if same && campaign.is_file() {
        eprintln!(
            "night: reusing the {n} {} logs in {}",
            format.name(),
            dir.display()
        );
    } else {
        if dir.exists() {
            std::fs::remove_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        }
        std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        // `simulate` writes campaign.toml last: an interrupted generation
        // has none and is redone.
        std::fs::write(&sim_path, &text).map_err(|e| format!("{}: {e}", sim_path.display()))?;
        eprintln!(
            "night: simulating {n} {} logs into {}",
            format.name(),
            dir.display()
        );
        let start = Instant::now();
        let status = Command::new(&config.bin)
            .arg("simulate")
            .arg(&sim_path)
            .arg("--out")
            .arg(&dir)
            .arg("--quiet")
            .status()
            .map_err(|e| format!("cannot run {}: {e}", config.bin.display()))?;
        if !status.success() {
            return Err(format!("servoid simulate failed ({status})"));
        }
        eprintln!(
            "night: simulated in {:.1} s (not part of the measurements)",
            start.elapsed().as_secs_f64()
        );
    }
    let mut bytes = 0;
    let mut count = 0;
    for entry in std::fs::read_dir(dir.join("logs")).map_err(|e| format!("logs: {e}"))? {
        let meta = entry
            .and_then(|e| e.metadata())
            .map_err(|e| e.to_string())?;
        bytes += meta.len();
        count += 1;
    }
    if count != n {
        return Err(format!("{}: {count} logs, expected {n}", dir.display()));
    }
    Ok((campaign, bytes))
}

/// One `servoid run` under GNU time.
fn measure(config: &Config, campaign: &Path, out: &Path, figures: &str) -> Result<Sample, String> {
    let report = out.with_extension("time.txt");
    let stderr = out.with_extension("stderr.txt");
    let mut cmd = Command::new(TIME);
    cmd.arg("-v")
        .arg("-o")
        .arg(&report)
        .arg(&config.bin)
        .arg("run")
        .arg(campaign)
        .arg("--out")
        .arg(out)
        .arg("--quiet");
    if figures != "default" {
        cmd.args(["--figures", figures]);
    }
    if let Some(j) = config.jobs {
        cmd.args(["--jobs", &j.to_string()]);
    }
    let err_file = std::fs::File::create(&stderr).map_err(|e| format!("{e}"))?;
    let busy_before = busy_cpu_s();
    let start = Instant::now();
    let _ = cmd
        .stdout(Stdio::null())
        .stderr(err_file)
        .status()
        .map_err(|e| format!("cannot run {TIME}: {e}"))?;
    let wall_s = start.elapsed().as_secs_f64();
    let busy_after = busy_cpu_s();
    let text =
        std::fs::read_to_string(&report).map_err(|e| format!("{}: {e}", report.display()))?;
    let field = |key: &str| -> Option<&str> {
        text.lines()
            .find_map(|l| l.trim().strip_prefix(key))
            .map(str::trim)
    };
    let number = |key: &str| -> Result<f64, String> {
        field(key)
            .and_then(|v| v.parse().ok())
            .ok_or_else(|| format!("{}: no `{key}`", report.display()))
    };
    let exit = field("Exit status:").unwrap_or("?");
    let signal = field("Command terminated by signal");
    let failure = if signal.is_some() || exit != "0" {
        let how = match signal {
            Some(s) => format!("signal {s}"),
            None => format!("exit {exit}"),
        };
        let last = std::fs::read_to_string(&stderr)
            .unwrap_or_default()
            .lines()
            .rev()
            .find(|l| !l.trim().is_empty())
            .unwrap_or("")
            .trim()
            .to_string();
        Some(format!("{how}: {last}"))
    } else {
        None
    };
    let (user_s, system_s) = (
        number("User time (seconds):")?,
        number("System time (seconds):")?,
    );
    Ok(Sample {
        wall_s,
        user_s,
        system_s,
        peak_rss_kb: number("Maximum resident set size (kbytes):")? as u64,
        other_cpu_s: busy_before
            .zip(busy_after)
            .map(|(a, b)| (b - a - user_s - system_s).max(0.0)),
        out_bytes: folder_bytes(out),
        failure,
    })
}

/// The bytes of the files under `dir`, its subfolders (the cache) included.
fn folder_bytes(dir: &Path) -> u64 {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return 0;
    };
    entries
        .flatten()
        .map(|e| match e.file_type() {
            Ok(t) if t.is_dir() => folder_bytes(&e.path()),
            Ok(_) => e.metadata().map_or(0, |m| m.len()),
            Err(_) => 0,
        })
        .sum()
}

/// CPU time every core of the machine has spent busy since boot (s), from
/// /proc/stat: user, nice, system, irq, softirq and steal, not idle or
/// iowait. Its unit is USER_HZ, 100 on every Linux architecture servoid
/// builds for.
fn busy_cpu_s() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/stat").ok()?;
    let line = stat.lines().find(|l| l.starts_with("cpu "))?;
    let ticks: Vec<u64> = line
        .split_whitespace()
        .skip(1)
        .map(|v| v.parse().ok())
        .collect::<Option<_>>()?;
    // user nice system idle iowait irq softirq steal ...
    let busy: u64 = [0, 1, 2, 5, 6, 7]
        .iter()
        .filter_map(|&i| ticks.get(i))
        .sum();
    Some(busy as f64 / 100.0)
}

fn night(config: &Config) -> Result<(), String> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut rows = Vec::new();
    let total = Instant::now();
    for &n in &config.sizes {
        for &format in &config.formats {
            let (campaign, log_bytes) = generate(config, n, format)?;
            let base = campaign.parent().expect("a folder");
            let mut these: Vec<Row> = (config.figures.iter())
                .flat_map(|&figures| {
                    [false, true].map(|cached| Row {
                        logs: n,
                        log_bytes,
                        format,
                        figures,
                        cached,
                        samples: Vec::new(),
                        redone: 0,
                    })
                })
                .collect();
            // Repeats interleaved, so a drift of the machine's speed
            // spreads over every row instead of biasing one.
            for r in 0..config.repeats {
                for row in these.iter_mut() {
                    let out = base.join(format!("out-{}", row.figures));
                    for attempt in 1.. {
                        if !row.cached && out.exists() {
                            std::fs::remove_dir_all(&out)
                                .map_err(|e| format!("{}: {e}", out.display()))?;
                        }
                        let s = measure(config, &campaign, &out, row.figures)?;
                        let others = s.other_cpu_s.map_or(0.0, |o| o / s.wall_s);
                        eprintln!(
                            "night: {n} {} logs, figures {}, {} run {}/{}: {:.2} s, peak RSS {} kB, others' CPU/wall {others:.2}{}",
                            format.name(),
                            row.figures,
                            row.run(),
                            r + 1,
                            config.repeats,
                            s.wall_s,
                            s.peak_rss_kb,
                            s.failure
                                .as_deref()
                                .map(|f| format!(", FAILED ({f})"))
                                .unwrap_or_default()
                        );
                        // /proc/stat counts in 10 ms ticks: a few of them
                        // on a short run are noise, not a neighbour.
                        let busy = config.max_others.is_some_and(|m| {
                            others > m && s.other_cpu_s.unwrap_or(0.0) > MIN_OTHERS_S
                        });
                        if busy && attempt < MAX_ATTEMPTS {
                            row.redone += 1;
                            continue;
                        }
                        row.samples.push(s);
                        break;
                    }
                }
            }
            rows.extend(these);
        }
    }
    let table = table(config, &rows, cores, total.elapsed().as_secs_f64());
    print!("{table}");
    let path = config.dir.join("night.md");
    std::fs::write(&path, &table).map_err(|e| format!("{}: {e}", path.display()))?;
    eprintln!("night: written to {}", path.display());
    Ok(())
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len().is_multiple_of(2) {
        (v[m - 1] + v[m]) / 2.0
    } else {
        v[m]
    }
}

/// "median (min-max)" of a quantity over the samples, "-" for none.
fn spread<'a>(
    samples: impl IntoIterator<Item = &'a Sample>,
    f: impl Fn(&Sample) -> f64,
    digits: usize,
) -> String {
    let v: Vec<f64> = samples.into_iter().map(f).collect();
    if v.is_empty() {
        return "-".to_string();
    }
    let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if v.len() == 1 {
        format!("{:.digits$}", v[0])
    } else {
        format!("{:.digits$} ({lo:.digits$}-{hi:.digits$})", median(v))
    }
}

impl Row {
    /// The runs that exited with 0: throughput means nothing for the
    /// others.
    fn ok(&self) -> impl Iterator<Item = &Sample> {
        self.samples.iter().filter(|s| s.failure.is_none())
    }

    fn failures(&self) -> Vec<&str> {
        self.samples
            .iter()
            .filter_map(|s| s.failure.as_deref())
            .collect()
    }

    fn run(&self) -> &'static str {
        if self.cached { "cached rerun" } else { "fresh" }
    }
}

fn cpu_share(s: &Sample) -> f64 {
    (s.user_s + s.system_s) / s.wall_s
}

fn table(config: &Config, rows: &[Row], cores: usize, total_s: f64) -> String {
    let mut t = String::new();
    let sizes: Vec<String> = config.sizes.iter().map(|n| n.to_string()).collect();
    let _ = writeln!(
        t,
        "\n## servoid night: {} logs of {LOG_SECONDS} s at {SAMPLE_RATE_HZ} Hz, {cores} cores, {} runs each: median (min-max)\n",
        sizes.join(" and "),
        config.repeats,
    );
    let _ = writeln!(
        t,
        "| logs | format | MB of logs | figures | run | wall s | logs/s | MB/s of logs | CPU/wall | peak RSS kB | kB written a log | others' CPU/wall | failed |"
    );
    let _ = writeln!(t, "|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    let mut redone = 0;
    for row in rows {
        let n = row.logs as f64;
        let mb = row.log_bytes as f64 / 1e6;
        let failures = row.failures();
        let _ = writeln!(
            t,
            "| {} | {} | {mb:.0} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            row.logs,
            row.format.name(),
            row.figures,
            row.run(),
            spread(&row.samples, |s| s.wall_s, 2),
            spread(row.ok(), |s| n / s.wall_s, 0),
            // A cached rerun reads no log (their sizes and times match).
            if row.cached {
                "-".to_string()
            } else {
                spread(row.ok(), |s| mb / s.wall_s, 0)
            },
            spread(&row.samples, cpu_share, 2),
            spread(&row.samples, |s| s.peak_rss_kb as f64, 0),
            spread(&row.samples, |s| s.out_bytes as f64 / 1e3 / n, 0),
            if row.samples.iter().all(|s| s.other_cpu_s.is_some()) {
                spread(&row.samples, |s| s.other_cpu_s.unwrap_or(0.0) / s.wall_s, 2)
            } else {
                "-".to_string()
            },
            match failures.first() {
                None => "0".to_string(),
                Some(f) => format!("{} of {}: {f}", failures.len(), row.samples.len()),
            },
        );
        redone += row.redone;
    }
    let _ = writeln!(
        t,
        "\nCPU/wall: user + system CPU time over wall time, in cores. Others' CPU/wall: the CPU time the rest of the machine used meanwhile, in cores; above about 0.1 the run shared its cores and its times are pessimistic. Throughput is over the runs that succeeded; the wall time, CPU and RSS of a failed run are up to its failure."
    );
    if let Some(m) = config.max_others {
        let _ = writeln!(
            t,
            "\n{redone} runs were measured again because the others used more than {m} cores meanwhile (SERVOID_NIGHT_MAX_OTHERS; up to {MAX_ATTEMPTS} tries, the last kept)."
        );
    }
    if rows
        .iter()
        .flat_map(|r| r.failures())
        .any(|f| f.contains("stack overflow"))
    {
        let _ = writeln!(
            t,
            "\nA stack overflow: a worker thread ran out of its stack (2 MiB by default). To measure past it, RUST_MIN_STACK (bytes, e.g. 268435456) in the bench's environment reaches servoid's threads."
        );
    }

    // The targets.
    let _ = writeln!(
        t,
        "\n### Targets ({cores} cores)\n\nParquet at least {TARGET_LOGS_PER_S} logs/s without figures and {TARGET_FIGURES_LOGS_PER_S} with the default figures, writing at most {TARGET_KB_PER_LOG} kB a log, with CPU/wall at least {:.1}; peak RSS under {TARGET_PEAK_RSS_KB} kB, and the largest night's at most {TARGET_RSS_GROWTH} times the smallest's.\n",
        TARGET_CPU_SHARE * cores as f64
    );
    for row in rows
        .iter()
        .filter(|r| r.format == Format::Parquet && !r.cached)
    {
        let target = if row.figures == "none" {
            TARGET_LOGS_PER_S
        } else {
            TARGET_FIGURES_LOGS_PER_S
        };
        let failures = row.failures();
        let verdict = if !failures.is_empty() {
            format!(
                "NOT met: {} of {} failed",
                failures.len(),
                row.samples.len()
            )
        } else {
            let logs_s = median(row.ok().map(|s| row.logs as f64 / s.wall_s).collect());
            let cpu = median(row.ok().map(cpu_share).collect());
            let kb = median(
                row.ok()
                    .map(|s| s.out_bytes as f64 / 1e3 / row.logs as f64)
                    .collect(),
            );
            let small = row.figures == "none" || kb <= TARGET_KB_PER_LOG;
            let ok = logs_s >= target && cpu >= TARGET_CPU_SHARE * cores as f64 && small;
            format!(
                "{logs_s:.0} logs/s, CPU/wall {cpu:.2}, {kb:.0} kB written a log: {}",
                if ok { "met" } else { "NOT met" }
            )
        };
        let _ = writeln!(
            t,
            "- {} Parquet logs, figures {}: {verdict}",
            row.logs, row.figures
        );
    }
    for row in rows {
        let worst = row.samples.iter().map(|s| s.peak_rss_kb).max().unwrap_or(0);
        if worst >= TARGET_PEAK_RSS_KB {
            let _ = writeln!(
                t,
                "- peak RSS NOT met: {worst} kB ({} {} logs, figures {}, {})",
                row.logs,
                row.format.name(),
                row.figures,
                row.run()
            );
        }
    }
    if config.sizes.len() > 1 {
        for &format in &config.formats {
            for &figures in &config.figures {
                let kb_at = |n: usize| {
                    let r = rows.iter().find(|r| {
                        r.logs == n && r.format == format && r.figures == figures && !r.cached
                    })?;
                    Some(median(
                        r.samples.iter().map(|s| s.peak_rss_kb as f64).collect(),
                    ))
                };
                let (first, last) = (config.sizes[0], config.sizes[config.sizes.len() - 1]);
                if let (Some(a), Some(b)) = (kb_at(first), kb_at(last)) {
                    let growth = b / a;
                    let _ = writeln!(
                        t,
                        "- peak RSS at {last} logs over {first}, {} figures {figures}: {growth:.2}: {}",
                        format.name(),
                        if growth <= TARGET_RSS_GROWTH {
                            "met"
                        } else {
                            "NOT met"
                        }
                    );
                }
                let per_size: Vec<String> = config
                    .sizes
                    .iter()
                    .filter_map(|&n| {
                        let r = rows.iter().find(|r| {
                            r.logs == n && r.format == format && r.figures == figures && !r.cached
                        })?;
                        let kb = median(r.samples.iter().map(|s| s.peak_rss_kb as f64).collect());
                        Some(format!("{kb:.0} kB at {n} logs"))
                    })
                    .collect();
                let _ = writeln!(
                    t,
                    "- peak RSS by the night's size, {} figures {figures}, fresh: {}",
                    format.name(),
                    per_size.join(", ")
                );
            }
        }
    }
    let _ = writeln!(
        t,
        "\nservoid: {}; {:.0} s in all, log generation included.",
        config.bin.display(),
        total_s
    );
    t
}
