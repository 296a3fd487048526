//! The joint grey-box fit in the campaign against known truth:
//! campaigns simulated with what real rigs have and the paper's model
//! lacks (a servo-valve mode, a sensor delay, LVDT offset and drift),
//! identified with default settings (no delay and no structure named in
//! the manifest), compared with the parameters they were simulated from.
//! The simulator shares only the model's equations with the fit (docs/model.md;
//! the valve mode's state space is checked against the transfer function
//! in the unit tests of `identify::joint`).

use servoid::identify::amplitude::Movement;
use servoid::identify::joint::Structure;
use servoid::manifest::simulation::load_simulation_str;
use servoid::manifest::{Campaign, load};
use servoid::results::{JointResult, Results, RigSource};
use servoid::run::analyse;
use servoid::run::simulate::simulate_campaign;

use crate::util::scratch;

/// A rig and its springs.
struct Rig {
    beta1: f64,
    a1b0: f64,
    a2: f64,
    a3: f64,
    springs: &'static [f64],
}

const PAPER: Rig = Rig {
    beta1: 267.0,
    a1b0: 2.412e9,
    a2: 7.881e5,
    a3: 16.118,
    springs: &[116_640.0, 88_540.0],
};

const OTHER: Rig = Rig {
    beta1: 180.0,
    a1b0: 3.1e9,
    a2: 9.5e5,
    a3: 22.0,
    springs: &[150_000.0, 105_000.0, 60_000.0],
};

/// What the rig has besides the paper's model, and what a test changes
/// from the 120 s campaign.
#[derive(Default, Clone, Copy)]
struct Extras {
    fs: f64,
    /// A mode in the loop (Hz, damping), or none.
    valve: Option<(f64, f64)>,
    /// A mode in the command path, and one on the logged displacement.
    command: Option<(f64, f64)>,
    measurement: Option<(f64, f64)>,
    delay_samples: f64,
    /// LVDT offset (mm) and drift (mm/s).
    offset_mm: f64,
    drift_mm_per_s: f64,
    /// The springs' cubic stiffening: each spring k is simulated as the
    /// Duffing spring k x1 + k3 x1^3 with k3 = this * k / (4 mm)^2 (its
    /// secant stiffness that much higher at the chirp's 4 mm), and analysed
    /// as the linear k.
    spring_cubic: f64,
    /// Lines for `[rig.unmodelled]` beyond the modes above.
    unmodelled: &'static str,
    /// Lines for `[rig]` (the flow law's supply pressure and piston area).
    rig: &'static str,
    /// The inline table `identification.joint` holds, or "" for none.
    joint: &'static str,
    record: Record,
}

/// The record and its analysis, where a test departs from the campaign's.
#[derive(Clone, Copy)]
struct Record {
    duration_s: f64,
    f0_hz: f64,
    /// The command at rest this long before and after the chirp.
    lead_s: f64,
    /// LVDT noise RMS, mm.
    noise_mm: f64,
    /// The FRF estimator the manifest names, or "" for servoid's default.
    estimator: &'static str,
}

impl Default for Record {
    fn default() -> Self {
        Record {
            duration_s: 120.0,
            f0_hz: 0.1,
            lead_s: 1.0,
            noise_mm: 0.002,
            estimator: "etfe",
        }
    }
}

/// A 120 s campaign: a quadratic chirp 0.1-35 Hz of 4 mm, 18-bit
/// converters, 2 um of LVDT noise, a no-specimen run and the rig's
/// springs. `[identification]` names neither a delay nor a structure.
fn manifest(seed: u64, rig: &Rig, x: &Extras) -> String {
    let mut valve = String::new();
    for (key, mode) in [
        ("valve_mode", x.valve),
        ("command_mode", x.command),
        ("measurement_mode", x.measurement),
    ] {
        if let Some((hz, zeta)) = mode {
            valve +=
                &format!("{key} = {{ natural_frequency_hz = {hz}, damping_ratio = {zeta} }}\n");
        }
    }
    valve += x.unmodelled;
    if !valve.is_empty() {
        valve = format!("[rig.unmodelled]\n{valve}");
    }
    let joint = if x.joint.is_empty() {
        String::new()
    } else {
        format!("joint = {{ {} }}\n", x.joint)
    };
    let rec = &x.record;
    let mut runs = String::from("[[runs]]\nid = \"bare\"\nrole = \"no_specimen\"\np_gain = 1.0\n");
    for (i, k) in rig.springs.iter().enumerate() {
        let spring = if x.spring_cubic == 0.0 {
            format!("{{ stiffness_n_per_m = {k} }}")
        } else {
            let k3 = x.spring_cubic * k / (0.004f64 * 0.004);
            format!(
                "{{ model = \"duffing\", stiffness_n_per_m = {k}, cubic_stiffness_n_per_m3 = {k3:e} }}"
            )
        };
        runs += &format!(
            "\n[[runs]]\nid = \"k{}\"\nrole = \"spring\"\np_gain = 1.0\nspecimen = {spring}\n",
            i + 1
        );
    }
    format!(
        r#"
schema_version = 1

[simulation]
name = "joint"
sample_rate_hz = {fs}
seed = {seed}
log_format = "parquet"

[rig]
name = "a simulated rig"
{rig_lines}

[rig.parameters]
beta1_per_s = {beta1}
a1b0_n_per_m_s2 = {a1b0}
a2_n_per_m = {a2}
a3_per_s = {a3}

{valve}
[excitation]
kind = "chirp"
law = "quadratic"
f0_hz = {f0:?}
f1_hz = 35.0
duration_s = {duration:?}
amplitude_m = 0.004
lead_in_s = {lead:?}
lead_out_s = {lead:?}

[instrument.command]
unit = "mm"
quantization = {{ bits = 18, full_scale = 50.0 }}

[instrument.displacement]
unit = "mm"
noise_rms = {noise:?}
delay_s = {delay_s}
offset = {offset}
drift_per_s = {drift}
quantization = {{ bits = 18, full_scale = 50.0 }}

[instrument.force]
unit = "N"
noise_rms = 2.0
quantization = {{ bits = 18, full_scale = 5000.0 }}

[identification]
{joint}band_hz = [0.5, 30.0]
coherence_min = 0.8
command_intersample = "sample_and_hold"
{frf}

{runs}
"#,
        fs = x.fs,
        rig_lines = x.rig,
        beta1 = rig.beta1,
        a1b0 = rig.a1b0,
        a2 = rig.a2,
        a3 = rig.a3,
        delay_s = x.delay_samples / x.fs,
        offset = x.offset_mm,
        drift = x.drift_mm_per_s,
        f0 = rec.f0_hz,
        duration = rec.duration_s,
        lead = rec.lead_s,
        noise = rec.noise_mm,
        frf = if rec.estimator.is_empty() {
            String::new()
        } else {
            format!(
                "frf = {{ estimator = \"{}\", segment_length = 8192, overlap = 0.5, window = \"rectangular\", detrend = \"mean\" }}",
                rec.estimator
            )
        },
    )
}

fn identify(text: &str) -> Results {
    simulated(text).2
}

/// The campaign `text` simulates, analysed: the folder its logs are in,
/// the campaign and its results (every run without error).
fn simulated(text: &str) -> (tempfile::TempDir, Campaign, Results) {
    let dir = scratch();
    let plan = load_simulation_str(text, &dir.path().join("sim.toml")).expect("a valid simulation");
    let sim = simulate_campaign(&plan, dir.path()).expect("simulates");
    let campaign = load(&sim.manifest).expect("the generated manifest loads");
    let results = analyse(&campaign);
    for r in &results.runs {
        assert!(r.error.is_none(), "run {} failed: {:?}", r.id, r.error);
    }
    (dir, campaign, results)
}

/// `[rig.unmodelled]`'s lines for a piston of `mass_kg` with Coulomb
/// friction `force_n`, tanh(v / 2 mm/s).
fn friction_lines(mass_kg: f64, force_n: f64) -> &'static str {
    seal_lines(mass_kg, force_n, 0.0)
}

/// The same with the seals' viscous damping `viscous` (N s/m) beside the
/// friction.
fn seal_lines(mass_kg: f64, force_n: f64, viscous: f64) -> &'static str {
    Box::leak(
        format!(
            "piston_mass_kg = {mass_kg}\nactuator_friction = {{ coulomb_force_n = {force_n}, smoothing_velocity_m_per_s = 0.002, viscous_ns_per_m = {viscous} }}\n"
        )
        .into_boxed_str(),
    )
}

/// The seal-friction tests' campaign: the paper's rig with `unmodelled`,
/// the 120 s campaign with servoid's default FRF settings and `joint` in
/// `identification.joint`, seed `seed`, three SDOF validation runs;
/// analysed.
fn paper_friction_campaign(unmodelled: &'static str, joint: &'static str, seed: u64) -> Results {
    let x = Extras {
        unmodelled,
        joint,
        record: Record {
            estimator: "",
            ..Record::default()
        },
        ..base(None, None, None, 0.0, 0.0, 0.0)
    };
    identify(&(manifest(seed, &PAPER, &x) + &sdof_validation_runs([1.0; 3])))
}

/// The seals' friction the joint fit found, (value, std) in N.
fn friction_found(joint: &JointResult) -> Option<(f64, f64)> {
    joint_parameter(joint, "coulomb_friction_n")
}

/// The joint fit's parameter `name` with its total std (what results
/// state for it), where it was fitted.
fn joint_parameter(joint: &JointResult, name: &str) -> Option<(f64, f64)> {
    joint
        .parameters
        .iter()
        .find(|p| p.name == name)
        .map(|p| (p.value, p.total_std))
}

/// Prints a suite's table (its `header` row, then `rows`) and how many of
/// its parameters lie within 2 total stds; returns that fraction.
fn print_suite(name: &str, header: &str, rows: &[String], covered: usize, total: usize) -> f64 {
    eprintln!("{header}");
    for row in rows {
        eprintln!("{row}");
    }
    let coverage = covered as f64 / total as f64;
    eprintln!(
        "{name} coverage: {covered} of {total} within 2 total stds ({:.1} %)",
        100.0 * coverage
    );
    coverage
}

/// Relative errors of the rig the campaign uses, against `rig`.
fn errors(results: &Results, rig: &Rig) -> [f64; 4] {
    let r = results.rig.as_ref().expect("the rig is identified");
    [
        r.beta1.value / rig.beta1 - 1.0,
        r.a1b0.value / rig.a1b0 - 1.0,
        r.a2.value / rig.a2 - 1.0,
        r.a3.value / rig.a3 - 1.0,
    ]
}

/// Six rich campaigns over the issue's range: valve modes 70-200 Hz with
/// damping 0.3-0.8, sensor delays 0-3 samples, offsets and drift, 1 and
/// 2 kHz, two rigs with two and three springs. With default settings the
/// campaign uses the joint estimate and all four parameters are within 1 %
/// of the truth; the sequential estimate beside it is not (the issue's
/// 2-50 %), which is what makes the case.
#[test]
fn rich_campaigns_give_the_rig_within_one_percent() {
    let cases = [
        (&PAPER, 1000.0, Some((70.0, 0.3)), 2.0),
        (&PAPER, 2000.0, Some((200.0, 0.8)), 3.0),
        (&OTHER, 1000.0, Some((100.0, 0.5)), 0.0),
        (&OTHER, 2000.0, Some((130.0, 0.6)), 1.0),
        (&PAPER, 1000.0, Some((200.0, 0.3)), 3.0),
        (&OTHER, 2000.0, Some((70.0, 0.8)), 0.0),
    ];
    let mut worst_sequential: f64 = 0.0;
    for (i, (rig, fs, valve, delay)) in cases.into_iter().enumerate() {
        let x = Extras {
            fs,
            valve,
            delay_samples: delay,
            offset_mm: 0.15,
            drift_mm_per_s: 4e-4,
            ..Extras::default()
        };
        let results = identify(&manifest(100 + i as u64, rig, &x));
        let r = results.rig.as_ref().unwrap();
        let joint = r.joint.as_ref().expect("a joint fit");
        let err = errors(&results, rig);
        eprintln!(
            "case {i}: {fs} Hz, valve {valve:?}, delay {delay} samples: structure {:?}, used {}, errors {:+.3?} %; {}",
            joint.structure,
            joint.used,
            err.map(|e| 100.0 * e),
            joint.explanation
        );
        assert_eq!(r.source, RigSource::Joint, "case {i}: {}", joint.use_note);
        for (name, e) in ["beta1", "a1b0", "a2", "a3"].iter().zip(err) {
            assert!(e.abs() < 0.01, "case {i}: {name} {:.3} % off", 100.0 * e);
        }
        let seq = r.sequential.as_ref().unwrap();
        let seq_err = (seq.a1b0.value / rig.a1b0 - 1.0)
            .abs()
            .max((seq.beta1.value / rig.beta1 - 1.0).abs());
        worst_sequential = worst_sequential.max(seq_err);
        // The model-error term says the two estimates differ by more than
        // statistics where the sequential one is off by more than 1 %.
        if seq_err > 0.01 {
            assert!(
                joint
                    .parameters
                    .iter()
                    .any(|p| p.dominant.as_deref() == Some("model error")),
                "case {i}"
            );
        }
    }
    assert!(
        worst_sequential > 0.02,
        "the sequential estimate was within {worst_sequential}: the cases do not test the joint fit"
    );
}

/// A clean campaign (the paper's model exactly, no delay, no offsets) at
/// 2 kHz: the joint estimate within 0.1 % and the data choose the plain
/// structure, which passes its adequacy tests; no warning about the rig.
#[test]
fn a_clean_campaign_gives_the_rig_within_a_tenth_of_a_percent() {
    let x = Extras {
        fs: 2000.0,
        valve: None,
        delay_samples: 0.0,
        offset_mm: 0.0,
        drift_mm_per_s: 0.0,
        ..Extras::default()
    };
    let results = identify(&manifest(7, &PAPER, &x));
    let r = results.rig.as_ref().unwrap();
    let joint = r.joint.as_ref().unwrap();
    assert_eq!(
        joint.structure,
        Some(Structure::Plain),
        "{}",
        joint.explanation
    );
    assert!(joint.adequacy.as_ref().unwrap().passed());
    assert_eq!(r.source, RigSource::Joint);
    for (name, e) in ["beta1", "a1b0", "a2", "a3"]
        .iter()
        .zip(errors(&results, &PAPER))
    {
        assert!(e.abs() < 0.001, "{name} {:.4} % off", 100.0 * e);
    }
    assert!(
        !results
            .warnings
            .iter()
            .any(|w| w.detail.starts_with("rig:")),
        "{:?}",
        results.warnings
    );
}

/// The validation runs in the joint fit (`include_validation`): a rich
/// campaign (1 kHz, a 100 Hz valve mode of damping 0.5, a 2-sample delay,
/// offset and drift) with the paper's Exp1 and Exp2 specimens (Table 2;
/// Exp2 at P = 2) as validation runs, fitted with and without them. With
/// them each run adds its x1/u (Eq. 17) and f/u (Eq. 45): the fit lists
/// all seven FRFs, the rig is within 1 % of the truth, every rig
/// parameter's std is smaller than without them (four more FRFs of the
/// same parameters), and the validation runs are still validated. The
/// LVDT's delay is not the load cell's (the simulator delays only the
/// displacement): the force FRFs' own delay is found at 0, the LVDT's at
/// its 2 samples. One delay for both put beta1 1.04 % off.
#[test]
fn validation_runs_join_the_fit_when_the_manifest_says() {
    let x = Extras {
        fs: 1000.0,
        valve: Some((100.0, 0.5)),
        delay_samples: 2.0,
        offset_mm: 0.15,
        drift_mm_per_s: 4e-4,
        ..Extras::default()
    };
    let exps = r#"
[[runs]]
id = "exp1"
role = "validation"
p_gain = 1.0
specimen = { mass_kg = 3.8, damping_ns_per_m = 5.0, stiffness_n_per_m = 129400.0 }

[[runs]]
id = "exp2"
role = "validation"
p_gain = 2.0
specimen = { mass_kg = 3.8, damping_ns_per_m = 5.0, stiffness_n_per_m = 129400.0 }
"#;
    let with_exps = manifest(21, &PAPER, &x) + exps;
    let included = manifest(
        21,
        &PAPER,
        &Extras {
            joint: "include_validation = true",
            ..x
        },
    ) + exps;
    let without = identify(&with_exps);
    let with = identify(&included);
    let (jw, jo) = (
        with.rig.as_ref().unwrap().joint.as_ref().unwrap(),
        without.rig.as_ref().unwrap().joint.as_ref().unwrap(),
    );
    let ids = |j: &servoid::results::JointResult| {
        j.per_run.iter().map(|r| r.run.clone()).collect::<Vec<_>>()
    };
    assert_eq!(ids(jo), ["bare", "k1", "k2"]);
    assert_eq!(
        ids(jw),
        [
            "bare",
            "k1",
            "k2",
            "exp1 x1/u",
            "exp1 f/u",
            "exp2 x1/u",
            "exp2 f/u"
        ]
    );
    assert!(jw.explanation.contains("not independent of the rig"));
    assert_eq!(jw.structure, Some(Structure::DelayValve));
    assert_eq!(with.rig.as_ref().unwrap().source, RigSource::Joint);
    for (name, e) in ["beta1", "a1b0", "a2", "a3"]
        .iter()
        .zip(errors(&with, &PAPER))
    {
        assert!(e.abs() < 0.01, "{name} {:.3} % off", 100.0 * e);
    }
    let param = |name: &str| jw.parameters.iter().find(|p| p.name == name).unwrap();
    assert!(
        (param("delay_s").value * 1000.0 - 2.0).abs() < 0.1,
        "{:?}",
        param("delay_s")
    );
    assert!(
        param("force_delay_s").value * 1000.0 < 0.1,
        "{:?}",
        param("force_delay_s")
    );
    for (a, b) in jw.parameters.iter().zip(&jo.parameters).take(4) {
        eprintln!(
            "{}: std {:.3e} with the validation runs, {:.3e} without",
            a.name, a.std, b.std
        );
        assert!(a.std < b.std, "{}: {} against {}", a.name, a.std, b.std);
    }
    for id in ["exp1", "exp2"] {
        let run = with.runs.iter().find(|r| r.id == id).unwrap();
        assert!(run.validation.is_some(), "{id} is validated");
    }
}

/// A structure fixed in the manifest that the data reject is kept and
/// flagged: "none" on a rig with a 3-sample delay and a valve mode, where
/// the data put a mode in the loop. The
/// warnings name the key, and the adequacy tests say what is missing.
#[test]
fn a_fixed_structure_the_data_reject_is_kept_and_flagged() {
    let x = Extras {
        fs: 1000.0,
        valve: Some((100.0, 0.5)),
        delay_samples: 3.0,
        offset_mm: 0.0,
        drift_mm_per_s: 0.0,
        ..Extras::default()
    };
    let text = manifest(
        3,
        &PAPER,
        &Extras {
            joint: "structure = \"none\"",
            ..x
        },
    );
    let results = identify(&text);
    let r = results.rig.as_ref().unwrap();
    let joint = r.joint.as_ref().unwrap();
    assert_eq!(joint.structure, Some(Structure::Plain));
    assert_eq!(joint.chosen_by, "manifest");
    // A mode in the loop: the valve's alone, or with the piston's mass
    // (on this record the two differ by a cost of 131 in 23,000).
    assert_eq!(
        joint.data_choose.and_then(|s| s.place()),
        Some(servoid::identify::joint::Place::Loop),
        "{:?}",
        joint.data_choose
    );
    eprintln!("{:#?}", results.warnings);
    let flagged = |needle: &str| results.warnings.iter().any(|w| w.contains(needle));
    assert!(
        flagged("identification.joint.structure = \"none\" is kept, but the data reject it"),
        "{:?}",
        results.warnings
    );
    // The adequacy tests say what is missing.
    assert!(
        flagged("phase residual grows linearly"),
        "{:?}",
        results.warnings
    );
}

/// Coverage: over 2,000 seeds of a short clean campaign
/// (30 s sweeps at 1 kHz, 10 um of LVDT noise, so that noise dominates
/// every other error), the fraction of the joint estimate's four rig
/// parameters within 1 and 2 of their stds of the truth, and the same for
/// the sequential estimate; the issue's band is 95 +- 1 % within 2 std.
///
/// The joint estimate is checked against its stated (total) std: the
/// statistical std and the structure std, which on clean
/// campaigns adds little. Measured (2,000 seeds from 5000; 8,000 checks
/// each): joint 68.0 % within 1 total std and 95.2 %
/// within 2, sequential 68.5 % and 95.2 %; the scaled errors' RMS 1.004,
/// 1.007, 1.010, 1.016 (joint) and 1.007, 1.002, 1.002, 1.001 (sequential)
/// for beta1, a1b0, a2, a3, asserted within 0.97-1.03 (the issue's target
/// is 0.98-1.02; 2,000 seeds' own sampling std is 0.016). With the ETFE's
/// former noise estimate, which averaged windows holding the bin's own
/// noise, the joint stds were some 4 % optimistic (94.5 % within 2 std,
/// RMS 1.034-1.044; docs/accuracy.md, "Accuracy against known truth").
/// Fewer seeds are not enough: a campaign's four parameters share its
/// noise, and 300 seeds leave the fraction about a percent from its
/// expectation.
#[test]
#[ignore = "statistical, 2,000 campaigns: .ci/run runs it by name (docs/developers.md)"]
fn the_joint_stds_are_honest_across_seeds() {
    use rayon::prelude::*;
    let seeds = COVERAGE_SEEDS;
    assert!(seeds >= 2000, "the bands below are set for 2,000 seeds");
    let x = Extras {
        fs: 1000.0,
        valve: None,
        delay_samples: 0.0,
        offset_mm: 0.0,
        drift_mm_per_s: 0.0,
        record: Record {
            duration_s: 30.0,
            f0_hz: 0.5,
            noise_mm: 0.01,
            ..Record::default()
        },
        ..Extras::default()
    };
    let z: Vec<([f64; 4], [f64; 4])> = (0..seeds)
        .into_par_iter()
        .map(|seed| {
            let text = manifest(5000 + seed, &OTHER, &x);
            let results = identify(&text);
            let r = results.rig.as_ref().unwrap();
            let truth = [OTHER.beta1, OTHER.a1b0, OTHER.a2, OTHER.a3];
            let j = &r.joint.as_ref().unwrap().parameters;
            let s = r.sequential.as_ref().unwrap();
            let seq = [s.beta1, s.a1b0, s.a2, s.a3];
            (
                std::array::from_fn(|i| ((j[i].value - truth[i]) / j[i].total_std).abs()),
                std::array::from_fn(|i| ((seq[i].value - truth[i]) / seq[i].std.unwrap()).abs()),
            )
        })
        .collect();
    // Fractions within k stds: of the joint (false) or sequential (true) z.
    let within = |sequential: bool, k: f64| {
        let all: Vec<f64> = z
            .iter()
            .flat_map(|p| if sequential { p.1 } else { p.0 })
            .collect();
        all.iter().filter(|v| **v <= k).count() as f64 / all.len() as f64
    };
    let (j1, j2) = (within(false, 1.0), within(false, 2.0));
    let (s1, s2) = (within(true, 1.0), within(true, 2.0));
    for (i, name) in ["beta1", "a1b0", "a2", "a3"].iter().enumerate() {
        let f = |k: f64| z.iter().filter(|p| p.0[i] <= k).count() as f64 / z.len() as f64;
        // The scaled errors' RMS (a standard normal's is 1; over 2,000
        // seeds its own sampling std is about 0.016).
        let rms = |seq: bool| {
            (z.iter()
                .map(|p| if seq { p.1[i] } else { p.0[i] }.powi(2))
                .sum::<f64>()
                / z.len() as f64)
                .sqrt()
        };
        let (rj, rs) = (rms(false), rms(true));
        eprintln!(
            "  joint {name}: {:.1} % within 1 std, {:.1} % within 2; scaled errors' RMS joint {rj:.3}, sequential {rs:.3}",
            100.0 * f(1.0),
            100.0 * f(2.0)
        );
        assert!((0.97..=1.03).contains(&rj), "joint {name}: RMS {rj}");
        assert!((0.97..=1.03).contains(&rs), "sequential {name}: RMS {rs}");
    }
    eprintln!(
        "coverage over {seeds} seeds: joint {:.1} % within 1 std, {:.1} % within 2; sequential {:.1} %, {:.1} %",
        100.0 * j1,
        100.0 * j2,
        100.0 * s1,
        100.0 * s2
    );
    // The issue's band; within 1 std a Gaussian's 68.3 % with about the
    // same relative margin.
    assert!((0.94..=0.96).contains(&j2), "joint within 2 std: {j2}");
    assert!((0.655..=0.71).contains(&j1), "joint within 1 std: {j1}");
    assert!((0.94..=0.96).contains(&s2), "sequential within 2 std: {s2}");
    assert!(
        (0.655..=0.71).contains(&s1),
        "sequential within 1 std: {s1}"
    );
}

/// The campaigns the coverage test draws: enough that the fraction within
/// 2 std is within a percent of its expectation.
const COVERAGE_SEEDS: u64 = 2000;

/// Three SDOF validation runs (the paper's Exp1 specimen and two others)
/// at the given P gains, as `[[runs]]` tables.
fn sdof_validation_runs(p_gains: [f64; 3]) -> String {
    let specimens = [
        (3.8, 5.0, 129_400.0),
        (6.0, 12.0, 80_000.0),
        (2.5, 8.0, 180_000.0),
    ];
    let mut runs = String::new();
    for (i, ((m, c, k), p)) in specimens.iter().zip(p_gains).enumerate() {
        runs += &format!(
            "\n[[runs]]\nid = \"sdof{}\"\nrole = \"validation\"\np_gain = {p}\nspecimen = {{ mass_kg = {m}, damping_ns_per_m = {c}, stiffness_n_per_m = {k} }}\n",
            i + 1
        );
    }
    runs
}

/// Where the extra dynamics sit: the issue's rig, a 110 Hz mode
/// of damping 0.6 with a 2-sample sensor delay, offset and drift, three
/// springs and three SDOF validation runs, default settings, with the mode
/// in the loop and outside it (command path; on x1/u the measurement path
/// is the same product). Before the structures named their place the
/// command-path rig came out beta1 +2.6 %, a1b0 +2.5 % with stds of 0.09 %,
/// unwarned. Now each rig parameter must be within 0.5 % (in the loop, as
/// before) or, outside the loop, within 1 % or within 2 total stds with a
/// warning that names the structures the data cannot tell apart.
#[test]
fn a_mode_outside_the_loop_is_placed_there_or_warned() {
    for (i, (valve, command)) in [(Some((110.0, 0.6)), None), (None, Some((110.0, 0.6)))]
        .into_iter()
        .enumerate()
    {
        let x = Extras {
            fs: 1000.0,
            valve,
            command,
            delay_samples: 2.0,
            offset_mm: 0.15,
            drift_mm_per_s: 4e-4,
            ..Extras::default()
        };
        let text = manifest(230 + i as u64, &OTHER, &x) + &sdof_validation_runs([1.0; 3]);
        let results = identify(&text);
        let r = results.rig.as_ref().unwrap();
        let joint = r.joint.as_ref().unwrap();
        let err = errors(&results, &OTHER);
        let stds = [&r.beta1, &r.a1b0, &r.a2, &r.a3].map(|e| e.std.unwrap());
        let truth = [OTHER.beta1, OTHER.a1b0, OTHER.a2, OTHER.a3];
        let z: [f64; 4] = std::array::from_fn(|k| err[k] * truth[k] / stds[k]);
        eprintln!(
            "mode {}: structure {:?}, errors {:+.3?} %, in total stds {:+.2?}; candidates {:?}; ambiguity {:?}",
            if valve.is_some() {
                "in the loop"
            } else {
                "in the command path"
            },
            joint.structure,
            err.map(|e| 100.0 * e),
            z,
            joint
                .candidates
                .iter()
                .map(|c| (c.structure, c.place.clone(), c.reduced_chi2, c.weight))
                .collect::<Vec<_>>(),
            joint.ambiguity
        );
        assert_eq!(r.source, RigSource::Joint, "{}", joint.use_note);
        if valve.is_some() {
            assert_eq!(joint.structure, Some(Structure::DelayValve));
            for (name, e) in ["beta1", "a1b0", "a2", "a3"].iter().zip(err) {
                assert!(
                    e.abs() < 0.005,
                    "in the loop: {name} {:.3} % off",
                    100.0 * e
                );
            }
            continue;
        }
        let warned = joint.ambiguity.is_some()
            && results
                .warnings
                .iter()
                .any(|w| w.contains("the data cannot tell"));
        for (k, name) in ["beta1", "a1b0", "a2", "a3"].iter().enumerate() {
            assert!(
                err[k].abs() < 0.01 || (z[k].abs() < 2.0 && warned),
                "command path: {name} {:.3} % off, {:.2} total stds, warned {warned}",
                100.0 * err[k],
                z[k]
            );
        }
        let place = joint
            .candidates
            .iter()
            .find(|c| c.chosen)
            .and_then(|c| c.place.clone());
        assert_eq!(place.as_deref(), Some("in series"), "{}", joint.explanation);
    }
}

/// A rig of the mismatch suite: its name and what the simulation manifest
/// gives it besides the paper's model.
struct Mismatch {
    name: &'static str,
    extras: Extras,
}

/// What one campaign of a rig gave: its docs/accuracy.md row, the rig's errors in
/// total stds, and whether a structure warning was given.
struct Outcome {
    row: String,
    err: [f64; 4],
    z: [f64; 4],
    warned: bool,
    /// The seals' friction the joint fit gave, with its std (N).
    friction: Option<(f64, f64)>,
    /// The seals' viscous damping it gave, with its std (N s/m).
    damping: Option<(f64, f64)>,
    /// Whether the springs were taken as stiffening.
    stiffening: bool,
    /// The flow law's F_max the joint fit gave, with its std (N).
    max_force: Option<(f64, f64)>,
    /// Each validation run's peak force over F_max and NRMSE (%) predicted
    /// at its load and at zero load, where it was predicted with the law.
    at_load: Vec<(f64, f64, f64)>,
    warnings: Vec<String>,
}

fn run_mismatch(rig: &Mismatch, seed: u64) -> Outcome {
    let text = manifest(seed, &OTHER, &rig.extras) + &sdof_validation_runs([1.0; 3]);
    let results = identify(&text);
    let r = results.rig.as_ref().unwrap();
    let err = errors(&results, &OTHER);
    let truth = [OTHER.beta1, OTHER.a1b0, OTHER.a2, OTHER.a3];
    let std = [&r.beta1, &r.a1b0, &r.a2, &r.a3].map(|e| e.std.unwrap());
    let z: [f64; 4] = std::array::from_fn(|k| err[k] * truth[k] / std[k]);
    let joint = r.joint.as_ref();
    let warned = joint.is_some_and(|j| j.ambiguity.is_some() || j.misfit.is_some());
    let structure = joint
        .and_then(|j| j.candidates.iter().find(|c| c.chosen))
        .map_or("none".to_string(), |c| {
            format!(
                "{}{}",
                c.structure.as_str(),
                c.place
                    .as_ref()
                    .map_or(String::new(), |p| format!(" ({p})"))
            )
        });
    let row = format!(
        "| {} | {} | {}{} | {} | {} | {} |",
        rig.name,
        seed,
        structure,
        if r.source == RigSource::Joint {
            ""
        } else {
            " (sequential used)"
        },
        err.map(|e| format!("{:+.3}", 100.0 * e)).join(", "),
        z.map(|v| format!("{v:+.2}")).join(", "),
        if warned { "yes" } else { "no" }
    );
    eprintln!("{row}");
    if let Some(j) = joint {
        for note in j.ambiguity.iter().chain(&j.misfit) {
            eprintln!("    {note}");
        }
    }
    let friction = joint.and_then(friction_found);
    let damping = joint.and_then(|j| joint_parameter(j, "seal_damping_ns_per_m"));
    let stiffening = results
        .warnings
        .iter()
        .any(|w| w.contains("stiffening springs"));
    let at_load = results
        .runs
        .iter()
        .filter_map(|r| r.validation.as_ref())
        .filter_map(|v| {
            let load = v.load.as_ref()?;
            Some((load.load_fraction, v.nrmse_pct, load.zero_load.nrmse_pct))
        })
        .collect();
    Outcome {
        row,
        err,
        z,
        warned,
        friction,
        damping,
        stiffening,
        max_force: joint.and_then(|j| joint_parameter(j, "max_force_n")),
        at_load,
        warnings: results.warnings.iter().map(|w| w.detail.clone()).collect(),
    }
}

fn base(
    valve: Option<(f64, f64)>,
    command: Option<(f64, f64)>,
    measurement: Option<(f64, f64)>,
    delay_samples: f64,
    offset_mm: f64,
    drift_mm_per_s: f64,
) -> Extras {
    Extras {
        fs: 1000.0,
        valve,
        command,
        measurement,
        delay_samples,
        offset_mm,
        drift_mm_per_s,
        ..Extras::default()
    }
}

/// The mismatch suite: rigs with what the paper's model
/// lacks, at the places a lab's rig has it, two seeds each, default
/// settings, the issue's campaign (no-specimen run, three springs, three
/// SDOF validation runs; 120 s chirps at 1 kHz). For every rig parameter
/// the campaign reports: within 1 % of the truth, or within 2 total stds
/// of it with a structure warning. Across the suite at least 90 % of the
/// parameters lie within 2 total stds, and no rig (all linear) is given
/// friction, stiffening springs or a flow law. The table it prints is
/// docs/accuracy.md's.
#[test]
fn the_mismatch_suite_is_right_or_warned() {
    // The validation runs' x1/u and f/u join the fit where `include` says.
    let rig = |name, extras, unmodelled, include: bool| Mismatch {
        name,
        extras: Extras {
            unmodelled,
            joint: if include {
                "include_validation = true"
            } else {
                ""
            },
            ..extras
        },
    };
    let suite = [
        rig(
            "mode in the loop, 110 Hz, 0.6",
            base(Some((110.0, 0.6)), None, None, 2.0, 0.15, 4e-4),
            "",
            false,
        ),
        rig(
            "mode in the loop, 70 Hz, 0.3",
            base(Some((70.0, 0.3)), None, None, 3.0, 0.0, 0.0),
            "",
            false,
        ),
        rig(
            "mode in the command path, 110 Hz, 0.6",
            base(None, Some((110.0, 0.6)), None, 2.0, 0.15, 4e-4),
            "",
            false,
        ),
        rig(
            "mode in the command path, 60 Hz, 0.4",
            base(None, Some((60.0, 0.4)), None, 1.0, 0.0, 0.0),
            "",
            false,
        ),
        rig(
            "filter on the logged displacement, 80 Hz, 0.7",
            base(None, None, Some((80.0, 0.7)), 0.0, 0.15, 4e-4),
            "",
            false,
        ),
        rig(
            "the same, validation runs' force in the fit",
            base(None, None, Some((80.0, 0.7)), 0.0, 0.15, 4e-4),
            "",
            true,
        ),
        rig(
            "piston mass 3 kg",
            base(None, None, None, 1.0, 0.0, 0.0),
            "piston_mass_kg = 3.0\n",
            false,
        ),
        rig(
            "LVDT drift 2 um/s, offset 0.5 mm, loop mode 130 Hz",
            base(Some((130.0, 0.5)), None, None, 2.0, 0.5, 2e-3),
            "",
            false,
        ),
    ];
    let mut rows = Vec::new();
    let (mut covered, mut total) = (0, 0);
    let mut misses = Vec::new();
    for (i, rig) in suite.iter().enumerate() {
        for seed in 0..2u64 {
            let o = run_mismatch(rig, 300 + 10 * i as u64 + seed);
            assert!(
                o.friction.is_none() && !o.stiffening && o.max_force.is_none(),
                "{}: a linear rig given friction {:?}, stiffening springs ({}) or a flow law {:?}",
                rig.name,
                o.friction,
                o.stiffening,
                o.max_force
            );
            for k in 0..4 {
                total += 1;
                covered += usize::from(o.z[k].abs() <= 2.0);
                if !(o.err[k].abs() < 0.01 || (o.z[k].abs() < 2.0 && o.warned)) {
                    misses.push(format!(
                        "{} seed {seed}: {} {:+.3} % ({:+.2} total stds), warned {}",
                        rig.name,
                        ["beta1", "a1b0", "a2", "a3"][k],
                        100.0 * o.err[k],
                        o.z[k],
                        o.warned
                    ));
                }
            }
            rows.push(o.row);
        }
    }
    let coverage = print_suite(
        "suite",
        "| rig | seed | structure chosen | error % (beta1, a1b0, a2, a3) | error in total stds | warning |",
        &rows,
        covered,
        total,
    );
    assert!(misses.is_empty(), "{misses:#?}");
    assert!(coverage >= 0.9, "coverage {coverage}");
}

/// Beyond the candidates: a rig with what no structure holds, two modes at
/// once (in the loop and in the command path). Their errors are not covered by the stated stds (the
/// docs/accuracy.md's table says by how much); what the test asserts is that the
/// campaign says so: the chosen structure fails its adequacy tests and the
/// misfit warning names it.
#[test]
fn beyond_the_candidates_the_campaign_says_so() {
    let beyond = [Mismatch {
        name: "modes in the loop (150 Hz) and the command path (90 Hz)",
        extras: base(Some((150.0, 0.5)), Some((90.0, 0.6)), None, 1.0, 0.0, 0.0),
    }];
    for (i, rig) in beyond.iter().enumerate() {
        for seed in 0..2u64 {
            let o = run_mismatch(rig, 400 + 10 * i as u64 + seed);
            let worst = o.err.iter().fold(0.0f64, |m, e| m.max(e.abs()));
            assert!(
                worst < 0.01 || o.warned,
                "{}: {:.2} % off, unwarned",
                rig.name,
                100.0 * worst
            );
        }
    }
}

/// The experiment the ambiguity warning proposes settles it. A thin campaign (the no-specimen run and one spring, 10 s, 30
/// um of LVDT noise) on a rig with a 250 Hz mode (damping 0.5) in the loop,
/// eight times the band's top: no extension passes the F test against the
/// delay, and the data cannot tell the delay from the piston (Schwarz
/// weights 0.63 and 0.35), which moves beta1 by -1.3 % and a1b0 by -1.2 %.
/// The campaign says so, and proposes runs of other stiffness or mass in
/// the fit. The same campaign with its validation run (an SDOF specimen at
/// P = 2) in the fit (`include_validation`, as the warning says): the loop
/// is chosen with all the weight, no ambiguity, the rig within 0.5 % and 2
/// total stds. (Without the run a2 is 1.15 % off at 2.9 total stds: the
/// warning, not the std, is what tells the lab.)
#[test]
fn a_run_at_another_p_gain_settles_the_place() {
    let x = Extras {
        fs: 1000.0,
        valve: Some((250.0, 0.5)),
        delay_samples: 1.0,
        record: Record {
            duration_s: 10.0,
            noise_mm: 0.03,
            ..Record::default()
        },
        ..Extras::default()
    };
    let thin = Rig {
        springs: &[150_000.0],
        ..OTHER
    };
    let sdof = "\n[[runs]]\nid = \"sdof\"\nrole = \"validation\"\np_gain = 2.0\nspecimen = { mass_kg = 3.8, damping_ns_per_m = 5.0, stiffness_n_per_m = 129400.0 }\n";
    let text = manifest(77, &thin, &x) + sdof;
    let settled = manifest(
        77,
        &thin,
        &Extras {
            joint: "include_validation = true",
            ..x
        },
    ) + sdof;
    for (name, text) in [("default", &text), ("with the P = 2 run", &settled)] {
        let results = identify(text);
        let r = results.rig.as_ref().unwrap();
        let joint = r.joint.as_ref().unwrap();
        let err = errors(&results, &thin);
        let truth = [thin.beta1, thin.a1b0, thin.a2, thin.a3];
        let std = [&r.beta1, &r.a1b0, &r.a2, &r.a3].map(|e| e.std.unwrap());
        let z: [f64; 4] = std::array::from_fn(|k| err[k] * truth[k] / std[k]);
        eprintln!(
            "{name}: {:?}, errors {:+.3?} %, {:+.2?} total stds; weights {:?}; ambiguity {:?}",
            joint.structure,
            err.map(|e| 100.0 * e),
            z,
            joint
                .candidates
                .iter()
                .map(|c| (c.structure.as_str(), c.weight))
                .collect::<Vec<_>>(),
            joint.ambiguity
        );
        if name == "default" {
            let a = joint.ambiguity.as_deref().expect("an ambiguity");
            for needle in ["\"delay_piston\"", "include_validation"] {
                assert!(a.contains(needle), "{needle} not in {a}");
            }
            assert!(
                results
                    .warnings
                    .iter()
                    .any(|w| w.detail.starts_with("rig: the data cannot tell")),
                "{:?}",
                results.warnings
            );
            let moved = joint
                .parameters
                .iter()
                .take(4)
                .filter(|p| p.structure_std.is_some_and(|s| s > 0.5 * p.std))
                .count();
            assert!(moved >= 2, "{:?}", joint.parameters);
        } else {
            assert_eq!(joint.ambiguity, None);
            assert_eq!(joint.structure, Some(Structure::DelayValve));
            for k in 0..4 {
                assert!(
                    err[k].abs() < 0.005 && z[k].abs() < 2.0,
                    "{k}: {} %, {} total stds",
                    100.0 * err[k],
                    z[k]
                );
            }
        }
    }
}

/// Records that do not start and end at rest: clean
/// campaigns of the test's second rig whose 60 s quadratic chirp (0.1-35
/// Hz, 1 kHz, 2 um of LVDT noise) runs over the whole record, cut while the
/// rig still moves, identified with default settings but the FRF
/// estimator: the ETFE, and the ETFE with the local polynomial method's
/// transient taken out (`estimator = "lpm"`). Per rig parameter the scaled
/// errors (error / stated total std of the rig the campaign uses) over the
/// seeds. The ETFE's stds are 4 to 7 times too large (the transient's
/// leakage counted as noise), and every ETFE campaign's runs say so (the
/// command is not at rest at the record's end); the LPM's are right: over
/// 400 campaigns (the test at 400 seeds, LPM only) 94.8 % of the parameters within 2
/// stds, spreads 0.957, 1.007, 1.008, 1.035 for beta1, a1b0, a2, a3, means
/// +0.12, -0.02, -0.05, -0.14. That needs the LPM's window narrow (2R + 1
/// = 9 bins: a 15-bin one biased beta1 and a3 by +0.27 and -0.39 std) and
/// the fits' covariance a sandwich over the bins that share a window (the
/// errors of bins up to 2R apart correlate; weighted as independent the
/// stds were 4 to 13 % small). Asserted at 96 seeds (a spread's own
/// sampling std is about 0.07 there, a mean's 0.1): the LPM's spreads
/// within 0.85-1.15 and means within 0.3, the ETFE's spreads below 0.3.
#[test]
fn records_not_at_rest_are_calibrated_with_the_lpm() {
    use rayon::prelude::*;
    let seeds: u64 = 96;
    let x = Extras {
        fs: 1000.0,
        ..Extras::default()
    };
    let truth = [OTHER.beta1, OTHER.a1b0, OTHER.a2, OTHER.a3];
    let mut summary = Vec::new();
    for estimator in ["etfe", "lpm"].into_iter() {
        let z: Vec<[f64; 4]> = (0..seeds)
            .into_par_iter()
            .map(|seed| {
                let x = Extras {
                    record: Record {
                        duration_s: 60.0,
                        lead_s: 0.0,
                        estimator,
                        ..Record::default()
                    },
                    ..x
                };
                let text = manifest(7000 + seed, &OTHER, &x);
                let results = identify(&text);
                let told = results.runs.iter().all(|run| {
                    run.warnings
                        .iter()
                        .any(|w| w.contains("is not at rest at the record's"))
                });
                assert_eq!(told, estimator == "etfe", "seed {seed}, {estimator}");
                let r = results.rig.as_ref().unwrap();
                let est = [&r.beta1, &r.a1b0, &r.a2, &r.a3];
                std::array::from_fn(|k| (est[k].value - truth[k]) / est[k].std.unwrap())
            })
            .collect();
        let n = z.len() as f64;
        let stats: [(f64, f64); 4] = std::array::from_fn(|k| {
            let mean = z.iter().map(|v| v[k]).sum::<f64>() / n;
            let sd = (z.iter().map(|v| (v[k] - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
            (sd, mean)
        });
        let within2 = z.iter().flatten().filter(|v| v.abs() <= 2.0).count() as f64 / (4.0 * n);
        eprintln!(
            "{estimator}, {seeds} campaigns not at rest: {:.1} % within 2 stds; scaled errors' spread (mean) beta1 {:.3} ({:+.2}), a1b0 {:.3} ({:+.2}), a2 {:.3} ({:+.2}), a3 {:.3} ({:+.2})",
            100.0 * within2,
            stats[0].0,
            stats[0].1,
            stats[1].0,
            stats[1].1,
            stats[2].0,
            stats[2].1,
            stats[3].0,
            stats[3].1
        );
        summary.push(stats);
    }
    if seeds < 96 {
        return;
    }
    for (k, name) in ["beta1", "a1b0", "a2", "a3"].iter().enumerate() {
        let (sd, mean) = summary[1][k];
        assert!((0.85..=1.15).contains(&sd), "lpm {name}: spread {sd}");
        assert!(mean.abs() < 0.3, "lpm {name}: mean {mean}");
        assert!(
            summary[0][k].0 < 0.3,
            "etfe {name}: spread {}",
            summary[0][k].0
        );
    }
}

/// The paper's rig with 0.5 kg of piston and 8 N of Coulomb seal friction
/// (tanh(v / 2 mm/s)), the 120 s campaign at 1 kHz with servoid's default
/// FRF settings: the joint fit finds the friction from the displacement's
/// harmonics, fits it with the rig, and gives every rig parameter within
/// 1 % and the friction within 10 % of the 8 N it was simulated with (a
/// linear model's fit is 4.7 % off, docs/accuracy.md). Its SDOF validation
/// runs are predicted with that friction, which matches their logs (made
/// with the true friction) at under half the NRMSE of the rig without it
/// (0.08-0.10 % against 0.37-0.40 %), and their compensators say what the
/// friction leaves, more as the amplitude falls. The same campaign on the
/// rig without friction is given none.
#[test]
fn seal_friction_is_fitted_with_the_rig() {
    for (unmodelled, friction) in [
        (friction_lines(0.5, 8.0), true),
        ("piston_mass_kg = 0.5\n", false),
    ] {
        for seed in 0..2u64 {
            let results = paper_friction_campaign(unmodelled, "", 700 + seed);
            let r = results.rig.as_ref().unwrap();
            let joint = r.joint.as_ref().unwrap();
            let err = errors(&results, &PAPER);
            let found = friction_found(joint);
            eprintln!(
                "friction {friction}, seed {seed}: {:?}, errors {:+.3?} %, friction {found:?}",
                joint.structure,
                err.map(|e| 100.0 * e),
            );
            assert_eq!(r.source, RigSource::Joint, "{}", joint.use_note);
            for (name, e) in ["beta1", "a1b0", "a2", "a3"].iter().zip(err) {
                assert!(e.abs() < 0.01, "{name} {:+.3} % off", 100.0 * e);
            }
            let validation: Vec<_> = results
                .runs
                .iter()
                .filter(|r| r.role == servoid::manifest::Role::Validation)
                .collect();
            assert_eq!(validation.len(), 3);
            // The validation runs' prediction carries the friction found,
            // and the compensator says what the friction leaves of its
            // tracking as the amplitude falls.
            for run in &validation {
                let v = run.validation.as_ref().expect("validated");
                let t = run.tracking.as_ref().expect("tracking").get();
                let c = t.compensator.as_ref().expect("a compensator");
                let left: Vec<(f64, f64)> = c
                    .seals
                    .iter()
                    .map(|s| (s.amplitude_m, s.compensated.max_amplitude_error_pct))
                    .collect();
                eprintln!(
                    "  {}: NRMSE {:.3} %, without friction {:?}; compensated amplitude error with friction {left:?}",
                    run.id,
                    v.nrmse_pct,
                    v.seals.as_ref().map(|s| s.without_friction.nrmse_pct),
                );
                let Some(seals) = &v.seals else {
                    assert!(!friction, "{}: no friction in the prediction", run.id);
                    assert!(left.is_empty());
                    continue;
                };
                assert!(
                    friction,
                    "{}: a rig without friction predicted with it",
                    run.id
                );
                assert!(
                    v.nrmse_pct < 0.5 * seals.without_friction.nrmse_pct,
                    "{}: NRMSE {} with the friction, {} without",
                    run.id,
                    v.nrmse_pct,
                    seals.without_friction.nrmse_pct
                );
                assert_eq!(left.len(), 3);
                assert!(
                    left.windows(2).all(|w| w[1].0 < w[0].0 && w[1].1 > w[0].1),
                    "{}: the friction should leave more as the amplitude falls: {left:?}",
                    run.id
                );
            }
            if !friction {
                assert!(found.is_none(), "a rig without friction given {found:?}");
                continue;
            }
            let (f, _) = found.expect("the friction is fitted");
            assert!((f / 8.0 - 1.0).abs() < 0.1, "friction {f} N");
            assert!(
                results.warnings.iter().any(|w| w.contains("seal friction")),
                "{:#?}",
                results.warnings
            );
        }
    }
    // Another rig, a heavier piston and more friction (20 N on 2 kg,
    // tanh(v / 1 mm/s)), three springs: every rig parameter within 1 %, the
    // friction within 2 of its total stds, and no flow law (the F test
    // takes one, F_max 86 kN, from what the friction's describing function
    // leaves; a simulation of the rig with its friction alone reads one as
    // strong, so it is left out).
    let heavy = Mismatch {
        name: "piston 2 kg with 20 N Coulomb friction",
        extras: Extras {
            unmodelled: "piston_mass_kg = 2.0\nactuator_friction = { coulomb_force_n = 20.0, smoothing_velocity_m_per_s = 0.001 }\n",
            ..base(None, None, None, 0.0, 0.0, 0.0)
        },
    };
    for seed in 0..2u64 {
        let o = run_mismatch(&heavy, 400 + seed);
        eprintln!(
            "{} seed {seed}: friction {:?}, F_max {:?}, errors {:+.3?} %",
            heavy.name,
            o.friction,
            o.max_force,
            o.err.map(|e| 100.0 * e)
        );
        for (name, e) in ["beta1", "a1b0", "a2", "a3"].iter().zip(o.err) {
            assert!(
                e.abs() < 0.01,
                "{}: {name} {:+.3} % off",
                heavy.name,
                100.0 * e
            );
        }
        let (f, sd) = o.friction.expect("the friction is fitted");
        assert!((f - 20.0).abs() < 2.0 * sd, "friction {f} +- {sd} N");
        assert!(
            o.max_force.is_none() && !o.warnings.iter().any(|w| w.contains("flow falls")),
            "a rig without the law given one: {:?}",
            o.max_force
        );
    }
}

/// The friction rig of `seal_friction_is_fitted_with_the_rig` whose seals
/// also damp viscously (c_v = 300 N s/m beside the 8 N), default settings:
/// the undamped choice takes the loop's mode for the damping
/// (`delay_valve`, a2 1.1 % off), the damping freed on it is taken, and
/// the structures chosen again with it come out `delay_piston` with c_v
/// within 2 stds or 3 % and every rig parameter within 0.5 %. The rig
/// without viscous damping is given none, its rig as before.
#[test]
fn the_seals_viscous_damping_is_found_where_it_is() {
    for (viscous, seed) in [(300.0, 710u64), (0.0, 700)] {
        let lines = seal_lines(0.5, 8.0, viscous);
        let x = Extras {
            unmodelled: lines,
            record: Record {
                estimator: "",
                ..Record::default()
            },
            ..base(None, None, None, 0.0, 0.0, 0.0)
        };
        let text = manifest(seed, &PAPER, &x) + &sdof_validation_runs([1.0; 3]);
        let results = identify(&text);
        let r = results.rig.as_ref().unwrap();
        let joint = r.joint.as_ref().unwrap();
        let err = errors(&results, &PAPER);
        let value = |name: &str| {
            joint
                .parameters
                .iter()
                .find(|p| p.name == name)
                .map(|p| (p.value, p.std))
        };
        let damping = value("seal_damping_ns_per_m");
        eprintln!(
            "c_v {viscous}: {:?}, errors {:+.3?} %, friction {:?}, damping {damping:?}",
            joint.structure,
            err.map(|e| 100.0 * e),
            value("coulomb_friction_n")
        );
        for (name, e) in ["beta1", "a1b0", "a2", "a3"].iter().zip(err) {
            assert!(
                e.abs() < 0.005,
                "c_v {viscous}: {name} {:+.3} % off",
                100.0 * e
            );
        }
        assert_eq!(
            joint.structure,
            Some(Structure::DelayPiston),
            "c_v {viscous}"
        );
        if viscous == 0.0 {
            assert!(damping.is_none(), "a rig without damping given {damping:?}");
        } else {
            let (c, std) = damping.expect("the damping is taken");
            assert!(
                results
                    .warnings
                    .iter()
                    .any(|w| w.contains("seal friction") && w.contains("viscous damping")),
                "the friction's warning names the damping: {:#?}",
                results.warnings
            );
            assert!(
                (c - viscous).abs() < 2.0 * std.max(0.015 * viscous),
                "damping {c} +- {std} N s/m"
            );
        }
    }
}

/// The friction rig of `seal_friction_is_fitted_with_the_rig` (tanh(v /
/// 2 mm/s)) with that width stated (`friction_smoothing_m_per_s`): the
/// describing function is then the tanh law's and the bias is corrected at
/// that width alone, and the friction found moves toward the 8 N simulated
/// (seeds 700 and 701: 8.29 +- 0.29 N over the three widths, 7.99 +- 0.09
/// at the stated one), the rig within 1 % either way (beta1 -0.35 to
/// -0.32 %, a2 -0.06 %). The sweep's
/// velocity amplitude is 10-100 times v0 over most of the band, where the
/// two laws' describing functions differ by 0.1-1 %.
#[test]
fn a_stated_zero_crossing_width_is_the_frictions() {
    for seed in 0..2u64 {
        let mut friction = Vec::new();
        for joint in ["", "friction_smoothing_m_per_s = 0.002"] {
            let results = paper_friction_campaign(friction_lines(0.5, 8.0), joint, 700 + seed);
            let r = results.rig.as_ref().unwrap();
            let joint_result = r.joint.as_ref().unwrap();
            let err = errors(&results, &PAPER);
            let found = friction_found(joint_result);
            eprintln!(
                "seed {seed} [{joint}]: {:?}, errors {:+.3?} %, friction {found:?}",
                joint_result.structure,
                err.map(|e| 100.0 * e)
            );
            for (name, e) in ["beta1", "a1b0", "a2", "a3"].iter().zip(err) {
                assert!(e.abs() < 0.01, "[{joint}] {name} {:+.3} % off", 100.0 * e);
            }
            friction.push(found.expect("the friction is fitted").0);
        }
        assert!(
            (friction[1] - 8.0).abs() < (friction[0] - 8.0).abs(),
            "seed {seed}: friction {friction:?} N, stated width last"
        );
    }
}

/// The friction rig of `seal_friction_is_fitted_with_the_rig` with its SDOF
/// validation runs in the joint fit (`include_validation`): their bins carry
/// the displacement's amplitude too, so the friction's describing function
/// acts on them as on the identification runs', and the rig and friction
/// stay about as close as without them: every rig parameter within 1 %, the
/// friction within 10 % (seed 700: -0.48, -0.64, -0.10, -0.17 % and 7.37 N;
/// when the validation runs' bins had no amplitude, and so no friction,
/// +4.1, +3.3, -0.6, -1.2 % and 0.59 N).
#[test]
fn validation_runs_in_the_fit_carry_the_friction() {
    let results =
        paper_friction_campaign(friction_lines(0.5, 8.0), "include_validation = true", 700);
    let r = results.rig.as_ref().unwrap();
    let joint = r.joint.as_ref().unwrap();
    let err = errors(&results, &PAPER);
    let found = friction_found(joint);
    eprintln!(
        "with the validation runs: {:?}, errors {:+.3?} %, friction {found:?}; {}",
        joint.structure,
        err.map(|e| 100.0 * e),
        joint.explanation
    );
    assert_eq!(r.source, RigSource::Joint, "{}", joint.use_note);
    for (name, e) in ["beta1", "a1b0", "a2", "a3"].iter().zip(err) {
        assert!(e.abs() < 0.01, "{name} {:+.3} % off", 100.0 * e);
    }
    let (f, _) = found.expect("the friction is fitted");
    assert!((f / 8.0 - 1.0).abs() < 0.1, "friction {f} N");
}

/// The nonlinear suite: rigs the linear model does not hold, the other rig
/// of the mismatch suite (three springs, forces 240-600 N at the chirp's
/// 4 mm, 420 N on average) and its campaign, default settings, two seeds
/// each. Seal friction of 2, 8 and 20 N (0.5, 1.9 and 4.8 % of the springs'
/// mean force; tanh(v / 2 mm/s)) on a 0.5 kg piston, on a 0.05 kg one (the
/// simulator needs a moving mass under friction: this is the piston the
/// paper's model neglects), and on the 0.5 kg piston with a 110 Hz mode in
/// the loop; 8 N with 300 N s/m of viscous damping in the seals, with and
/// without that mode; springs 2 and 5 % stiffer at 4 mm than the k the
/// manifest states, with that mode; the valve's flow-pressure law at F_max
/// 8, 4 and 2 kN (the springs at 3-30 % of it), and at 4 kN beside 8 N of
/// friction; and three linear rigs. No linear rig is given friction,
/// stiffening or a flow law, no rig without the law is given one, no rig
/// without viscous damping is given any (beside the law, nil within 2 stds
/// is none), and every nonlinear one is named in a warning. F_max is within
/// 10 % where the springs reach 10 % of it, and each validation run above
/// 10 % of F_max is predicted at its load closer to its log than at zero
/// load. For every rig
/// parameter: within 1 % of the truth, or within 2 total stds (the bar),
/// each friction within 10 % and each damping within 10 % or 2 stds;
/// except on the light piston, where the describing function falls short
/// (the piston sticks at each reversal: docs/accuracy.md): there within
/// 1.5 %, its errors beyond its stds at 8 and 20 N. Every parameter beyond 3 total stds
/// is warned: by the structure's ambiguity or misfit, or, where no piston
/// mass is resolved, by the friction warning's saying the stds are a lower
/// bound; at most 5 % lie unwarned between 2 and 3, as chance leaves them.
/// At least 90 % of the parameters are within 2 total stds (95 %), and
/// 99 % within 1 % or 2 total stds. Where the piston is resolved, the
/// friction (corrected for the describing function's bias by simulating
/// the fitted rig, `analysis::friction`) is within 2 of its total stds on
/// at least 80 % of the rigs (16 of 18) and within 3.5 on all (the 20 N on
/// 0.5 kg at 3.1). The table it prints is docs/accuracy.md's.
#[test]
fn the_nonlinear_suite_is_right_or_warned() {
    struct Case {
        name: &'static str,
        extras: Extras,
        /// The friction it was simulated with (N), if any.
        friction_n: Option<f64>,
        /// The seals' viscous damping it was simulated with (N s/m).
        viscous: f64,
        /// Where the describing function falls short (a light piston).
        short: bool,
        /// The flow law's F_max it was simulated with (N), if any.
        max_force_n: Option<f64>,
    }
    let seals = |name, mass: f64, force: f64, viscous: f64, valve| Case {
        name,
        extras: Extras {
            unmodelled: seal_lines(mass, force, viscous),
            ..base(valve, None, None, 1.0, 0.0, 0.0)
        },
        friction_n: Some(force),
        viscous,
        short: mass < 0.1,
        max_force_n: None,
    };
    // The valve's flow law at A P_s: 20.7 MPa on the area that gives F_max.
    // No LVDT delay: the validation runs' predictions leave a sensor delay
    // out, and its error (about 1 % NRMSE) would hide what the law's is.
    let flow = |name, rig: &'static str, max_force_n: f64, friction: Option<f64>| Case {
        name,
        extras: Extras {
            rig,
            unmodelled: if friction.is_some() {
                friction_lines(0.5, 8.0)
            } else {
                ""
            },
            ..base(None, None, None, 0.0, 0.0, 0.0)
        },
        friction_n: friction,
        viscous: 0.0,
        short: false,
        max_force_n: Some(max_force_n),
    };
    let friction = |name, mass, force, valve| seals(name, mass, force, 0.0, valve);
    let loop_mode = Some((110.0, 0.6));
    let springs = |name, cubic| Case {
        name,
        extras: Extras {
            spring_cubic: cubic,
            ..base(loop_mode, None, None, 1.0, 0.0, 0.0)
        },
        friction_n: None,
        viscous: 0.0,
        short: false,
        max_force_n: None,
    };
    let suite = [
        friction("friction 2 N, piston 0.5 kg", 0.5, 2.0, None),
        friction("friction 8 N, piston 0.5 kg", 0.5, 8.0, None),
        friction("friction 20 N, piston 0.5 kg", 0.5, 20.0, None),
        friction("friction 2 N, piston 0.05 kg", 0.05, 2.0, None),
        friction("friction 8 N, piston 0.05 kg", 0.05, 8.0, None),
        friction("friction 20 N, piston 0.05 kg", 0.05, 20.0, None),
        friction(
            "friction 2 N, piston 0.5 kg, loop mode 110 Hz",
            0.5,
            2.0,
            loop_mode,
        ),
        friction(
            "friction 8 N, piston 0.5 kg, loop mode 110 Hz",
            0.5,
            8.0,
            loop_mode,
        ),
        friction(
            "friction 20 N, piston 0.5 kg, loop mode 110 Hz",
            0.5,
            20.0,
            loop_mode,
        ),
        seals(
            "friction 8 N and damping 300 N s/m, piston 0.5 kg",
            0.5,
            8.0,
            300.0,
            None,
        ),
        seals(
            "friction 8 N and damping 300 N s/m, piston 0.5 kg, loop mode 110 Hz",
            0.5,
            8.0,
            300.0,
            loop_mode,
        ),
        springs("springs 2 % stiffer at 4 mm, loop mode 110 Hz", 0.02),
        springs("springs 5 % stiffer at 4 mm, loop mode 110 Hz", 0.05),
        flow(
            "flow law, F_max 8 kN",
            "supply_pressure_pa = 2.07e7\npiston_area_m2 = 3.8647e-4",
            8000.0,
            None,
        ),
        flow(
            "flow law, F_max 4 kN",
            "supply_pressure_pa = 2.07e7\npiston_area_m2 = 1.93237e-4",
            4000.0,
            None,
        ),
        flow(
            "flow law, F_max 2 kN",
            "supply_pressure_pa = 2.07e7\npiston_area_m2 = 9.6618e-5",
            2000.0,
            None,
        ),
        flow(
            "flow law, F_max 4 kN, friction 8 N, piston 0.5 kg",
            "supply_pressure_pa = 2.07e7\npiston_area_m2 = 1.93237e-4",
            4000.0,
            Some(8.0),
        ),
        Case {
            name: "linear: piston 0.5 kg",
            extras: Extras {
                unmodelled: "piston_mass_kg = 0.5\n",
                ..base(None, None, None, 1.0, 0.0, 0.0)
            },
            friction_n: None,
            viscous: 0.0,
            short: false,
            max_force_n: None,
        },
        Case {
            name: "linear: piston 0.5 kg, loop mode 110 Hz",
            extras: Extras {
                unmodelled: "piston_mass_kg = 0.5\n",
                ..base(loop_mode, None, None, 1.0, 0.0, 0.0)
            },
            friction_n: None,
            viscous: 0.0,
            short: false,
            max_force_n: None,
        },
        Case {
            name: "linear: loop mode 110 Hz",
            extras: base(loop_mode, None, None, 1.0, 0.0, 0.0),
            friction_n: None,
            viscous: 0.0,
            short: false,
            max_force_n: None,
        },
    ];
    let mut rows = Vec::new();
    let (mut covered, mut total) = (0, 0);
    let (mut friction_covered, mut friction_total) = (0, 0);
    let mut misses = Vec::new();
    let mut chance = 0;
    for (i, case) in suite.iter().enumerate() {
        let nonlinear = case.friction_n.is_some()
            || case.extras.spring_cubic > 0.0
            || case.max_force_n.is_some();
        for seed in 0..2u64 {
            let rig = Mismatch {
                name: case.name,
                extras: case.extras,
            };
            let o = run_mismatch(&rig, 500 + 10 * i as u64 + seed);
            let named = o.warnings.iter().any(|w| {
                w.contains("seal friction")
                    || w.contains("stiffening springs")
                    || w.contains("flow falls with the load")
            });
            // The friction warning where no piston mass is resolved says
            // the stds are a lower bound there.
            let lower_bound = o
                .warnings
                .iter()
                .any(|w| w.contains("Take the stds as a lower bound"));
            rows.push(format!(
                "{} {} | {} | {} | {} | {} | {} | {} |",
                o.row,
                if lower_bound { "yes" } else { "no" },
                o.friction
                    .map_or("none".into(), |(f, s)| format!("{f:.2} +- {s:.2}")),
                case.friction_n.map_or("none".into(), |f| format!("{f}")),
                o.damping
                    .map_or("none".into(), |(c, s)| format!("{c:.0} +- {s:.0}")),
                if case.viscous > 0.0 {
                    format!("{}", case.viscous)
                } else {
                    "none".into()
                },
                o.max_force
                    .map_or("none".into(), |(f, s)| format!("{f:.0} +- {s:.0}")),
                case.max_force_n
                    .map_or("none".into(), |f| format!("{f:.0}")),
            ));
            // F_max is found where the springs reach 10 % of it (600 N),
            // and given to no rig without the law.
            match (case.max_force_n, o.max_force) {
                (None, None) => {}
                (Some(truth), _) if 600.0 < 0.1 * truth => {}
                (Some(truth), Some((f, _))) if (f / truth - 1.0).abs() < 0.1 => {}
                (_, found) => misses.push(format!("{} seed {seed}: F_max {found:?} N", case.name)),
            }
            // A run predicted at a load above 10 % of F_max is closer to
            // its log than at zero load.
            for &(fraction, at, zero) in &o.at_load {
                eprintln!(
                    "    validation at {:.1} % of F_max: NRMSE {at:.3} % at its load, {zero:.3} % at zero load",
                    100.0 * fraction
                );
                if fraction > 0.1 && at >= zero {
                    misses.push(format!(
                        "{} seed {seed}: at {fraction:.3} of F_max NRMSE {at} against {zero} at zero load",
                        case.name
                    ));
                }
            }
            // The viscous damping is found where the seals have it (within
            // 10 % or 2 stds) and given to no rig without it; with the flow
            // law, which comes after it, nil within 2 stds is none.
            match (case.viscous > 0.0, o.damping) {
                (false, None) => {}
                (false, Some((c, sd))) if case.max_force_n.is_some() && c.abs() < 2.0 * sd => {}
                (true, Some((c, sd)))
                    if (c / case.viscous - 1.0).abs() < 0.1
                        || (c - case.viscous).abs() < 2.0 * sd => {}
                (_, found) => misses.push(format!(
                    "{} seed {seed}: seal damping {found:?} N s/m",
                    case.name
                )),
            }
            if !nonlinear && (o.friction.is_some() || o.stiffening) {
                misses.push(format!(
                    "{} seed {seed}: a linear rig given friction {:?} or stiffening ({})",
                    case.name, o.friction, o.stiffening
                ));
            }
            if nonlinear != named {
                misses.push(format!(
                    "{} seed {seed}: named in a warning {named}",
                    case.name
                ));
            }
            if let (Some(truth), false) = (case.friction_n, case.short) {
                let (found, sd) = o.friction.unwrap_or((0.0, 0.0));
                if (found / truth - 1.0).abs() > 0.1 {
                    misses.push(format!("{} seed {seed}: friction {found} N", case.name));
                }
                // The friction's stated (total) std covers it where the
                // data resolve the piston (docs/accuracy.md, "Coverage of
                // the friction's std").
                friction_total += 1;
                friction_covered += usize::from((found - truth).abs() <= 2.0 * sd);
                if (found - truth).abs() > 3.5 * sd {
                    misses.push(format!(
                        "{} seed {seed}: friction {found} +- {sd} N, {:.1} stds from {truth}",
                        case.name,
                        (found - truth) / sd
                    ));
                }
            }
            for k in 0..4 {
                total += 1;
                covered += usize::from(o.z[k].abs() <= 2.0);
                let right = if case.short {
                    o.err[k].abs() < 0.015
                } else {
                    o.err[k].abs() < 0.01 || o.z[k].abs() <= 2.0
                };
                let warned = o.warned || lower_bound;
                // A calibrated std leaves 5 % of parameters beyond 2 stds
                // and 0.3 % beyond 3 by chance: unwarned, those beyond 2
                // are counted, those beyond 3 are misses.
                let unwarned = o.z[k].abs() > 2.0 && !warned;
                chance += usize::from(unwarned && o.z[k].abs() <= 3.0);
                if !right || (unwarned && o.z[k].abs() > 3.0) {
                    misses.push(format!(
                        "{} seed {seed}: {} {:+.3} % ({:+.2} total stds), friction or springs named {named}, warned {warned}",
                        case.name,
                        ["beta1", "a1b0", "a2", "a3"][k],
                        100.0 * o.err[k],
                        o.z[k],
                    ));
                }
            }
        }
    }
    let coverage = print_suite(
        "nonlinear suite",
        "| rig | seed | structure chosen | error % (beta1, a1b0, a2, a3) | error in total stds | structure warning | stds a lower bound | friction found (N) | truth (N) | damping found (N s/m) | truth (N s/m) | F_max found (N) | truth (N) |",
        &rows,
        covered,
        total,
    );
    eprintln!("unwarned beyond 2 total stds (within 3): {chance} of {total}");
    eprintln!(
        "friction within 2 total stds: {friction_covered} of {friction_total} (the piston resolved)"
    );
    assert!(misses.is_empty(), "{misses:#?}");
    assert!(
        10 * friction_covered >= 8 * friction_total,
        "friction coverage {friction_covered} of {friction_total}"
    );
    assert!(20 * chance <= total, "{chance} unwarned beyond 2 stds");
    assert!(coverage >= 0.9, "coverage {coverage}");
}

/// The two routes for a rig with seal friction, compared on the same
/// campaigns (docs/accuracy.md, "Seal friction: two routes"): the paper's
/// rig with 0.5 kg and 8 N, 0.5 kg and 20 N, and 0.05 kg and 8 N of piston
/// and friction (tanh(v / 2 mm/s)), seed 700, default settings. The
/// describing function is what servoid ships; the time-domain fit of the
/// nonlinear model's simulation (`time_domain.rs`) starts from it. Each
/// simulation of the campaign's three runs takes 1.5-1.8 s on this
/// project's 2-core machine, and the fit runs 80 to 260 of them: the test
/// takes about 40 minutes, so it runs by name only
/// (`cargo test --release --test integration -- --ignored friction_routes`).
/// It asserts what the comparison found where both converge: the
/// time-domain fit within 0.1 % and its friction within 1 % on the first
/// rig, where the describing function is 0.5 % and 7 % off.
#[test]
#[ignore = "about 40 minutes: the time-domain route's cost is what it measures"]
fn friction_routes_compared() {
    use crate::time_domain::{TimeRun, TimeStart, time_domain_fit};
    use servoid::manifest::RunSource;
    for (mass, force) in [(0.5, 8.0), (0.5, 20.0), (0.05, 8.0)] {
        let x = Extras {
            unmodelled: friction_lines(mass, force),
            record: Record {
                estimator: "",
                ..Record::default()
            },
            ..base(None, None, None, 0.0, 0.0, 0.0)
        };
        let text = manifest(700, &PAPER, &x) + &sdof_validation_runs([1.0; 3]);
        // The folder stays while the logs are read again below.
        let (_dir, campaign, results) = simulated(&text);
        let r = results.rig.as_ref().unwrap();
        let joint = r.joint.as_ref().unwrap();
        let get = |n: &str| {
            joint
                .parameters
                .iter()
                .find(|p| p.name == n)
                .map(|p| p.value)
        };
        let fd = errors(&results, &PAPER);
        eprintln!(
            "{mass} kg, {force} N: describing function {:?}, errors {:+.3?} %, friction {:?}, piston {:?}",
            joint.structure,
            fd.map(|e| 100.0 * e),
            get("coulomb_friction_n"),
            get("piston_mass_kg")
        );
        let logs: Vec<_> = campaign
            .runs
            .iter()
            .filter(|p| p.role != servoid::manifest::Role::Validation)
            .filter_map(|p| match &p.source {
                RunSource::Log(l) => Some((p, servoid::ingest::read_log(l).unwrap())),
                _ => None,
            })
            .collect();
        let runs: Vec<TimeRun> = logs
            .iter()
            .map(|(p, l)| TimeRun {
                command_m: &l.command_m,
                displacement_m: &l.displacement_m,
                specimen: p.specimen.linear().unwrap(),
                p_gain: p.p_gain,
            })
            .collect();
        // Where the describing function put no piston, the time-domain fit
        // starts from 0.1 kg.
        let start = TimeStart {
            rig: servoid::model::RigParams {
                beta1_per_s: get("beta1").unwrap(),
                a1b0_n_per_m_s2: get("a1b0").unwrap(),
                a2_n_per_m: get("a2").unwrap(),
                a3_per_s: get("a3").unwrap(),
                p_gain: 1.0,
            },
            piston_mass_kg: get("piston_mass_kg").unwrap_or(0.1).max(0.02),
            friction_n: get("coulomb_friction_n").unwrap_or(1.0),
            smoothing_m_per_s: 0.001,
            delay_s: get("delay_s").unwrap_or(0.0),
        };
        let fit = time_domain_fit(&runs, logs[0].1.sample_rate_hz, &start, 30).unwrap();
        let truth = [PAPER.beta1, PAPER.a1b0, PAPER.a2, PAPER.a3];
        let td: [f64; 4] = std::array::from_fn(|k| fit.values[k] / truth[k] - 1.0);
        eprintln!(
            "  time domain ({} simulations, {} iterations, converged {}): errors {:+.3?} %, in its stds {:+.2?}, piston {:.4} +- {:.4} kg, friction {:.3} +- {:.3} N, v0 {:.5} m/s, residual rms {:.3e} m",
            fit.simulations,
            fit.iterations,
            fit.converged,
            td.map(|e| 100.0 * e),
            (0..4)
                .map(|k| (fit.values[k] - truth[k]) / fit.stds[k])
                .collect::<Vec<_>>(),
            fit.values[4],
            fit.stds[4],
            fit.values[5],
            fit.stds[5],
            fit.values[6],
            fit.residual_rms_m
        );
        if (mass, force) == (0.5, 8.0) {
            assert!(fit.converged);
            assert!(td.iter().all(|e| e.abs() < 0.001), "{td:?}");
            assert!((fit.values[5] / force - 1.0).abs() < 0.01);
            assert!(fd.iter().any(|e| e.abs() > 0.003), "{fd:?}");
        }
    }
}

/// Three rigs of the mismatch suite whose LVDT is not the load cell's twin
/// (3 samples late with a 70 Hz loop mode; an 80 Hz filter on the logged
/// displacement; 2 samples late, offset 0.5 mm and drifting 2 um/s), with
/// linear springs: no spring run says its spring stiffens, and the rig
/// needs no word on a cubic term the FRFs do not bear out. Fitted over the
/// whole record at once, the force against the displacement read these as
/// springs 0.6-1.0 % stiffer or softer at 3.5 mm, at t = 11 to 74.
#[test]
fn a_sensor_that_lags_or_drifts_is_not_a_stiffening_spring() {
    let cases = [
        (
            "LVDT 3 samples late, loop mode 70 Hz",
            base(Some((70.0, 0.3)), None, None, 3.0, 0.0, 0.0),
        ),
        (
            "80 Hz filter on the LVDT",
            base(None, None, Some((80.0, 0.7)), 0.0, 0.15, 4e-4),
        ),
        (
            "LVDT 2 samples late, offset and drift",
            base(Some((130.0, 0.5)), None, None, 2.0, 0.5, 2e-3),
        ),
    ];
    for (name, extras) in cases {
        let text = manifest(5000, &OTHER, &extras) + &sdof_validation_runs([1.0; 3]);
        let results = identify(&text);
        for r in &results.runs {
            assert!(
                !r.warnings.iter().any(|w| w.contains("grows faster")),
                "{name}: run {} says its spring stiffens: {:#?}",
                r.id,
                r.warnings
            );
        }
        assert!(
            !results
                .warnings
                .iter()
                .any(|w| w.contains("mimic") || w.contains("stiffening springs")),
            "{name}: {:#?}",
            results.warnings
        );
    }
}

/// The servo-valve's flow-pressure law on the paper's night (its two
/// springs and Exp1 as a validation run, a 4 mm chirp) at the ShoreWestern
/// actuator's F_max (2.387e-4 m^2 at 20.7 MPa, 4.94 kN) and at half of it
/// (the springs' forces then some 8 and 16 % of F_max): the joint fit
/// takes the law, F_max within 10 % of the truth, and the rig it states,
/// the zero-load one, within 1 % or 3 of its stds.
#[test]
fn the_flow_law_is_fitted_and_the_rig_is_the_zero_load_one() {
    let cases = [
        (
            "supply_pressure_pa = 2.07e7\npiston_area_m2 = 2.387e-4",
            2.387e-4 * 2.07e7,
            1,
        ),
        (
            "supply_pressure_pa = 2.07e7\npiston_area_m2 = 1.2077e-4",
            1.2077e-4 * 2.07e7,
            2,
        ),
    ];
    for (rig, fmax, seed) in cases {
        let results = identify(&law_night(rig, seed));
        let r = results.rig.as_ref().expect("the rig is identified");
        let joint = r.joint.as_ref().expect("a joint fit");
        let found = joint_parameter(joint, "max_force_n");
        eprintln!(
            "F_max {fmax:.0} N: {:?} ({}), F_max found {found:?}",
            joint.structure, joint.use_note
        );
        let (value, _) = found.unwrap_or_else(|| panic!("no flow law: {:?}", results.warnings));
        assert!(
            (value / fmax - 1.0).abs() < 0.1,
            "F_max {value} against {fmax}"
        );
        for ((name, truth), est) in crate::util::PAPER_TRUTH
            .iter()
            .zip([&r.beta1, &r.a1b0, &r.a2, &r.a3])
        {
            let std = est.std.expect("a std");
            let (e, z) = (est.value / truth - 1.0, (est.value - truth) / std);
            eprintln!("  {name}: {:+.3} %, {z:+.2} stds", 100.0 * e);
            assert!(e.abs() < 0.01 || z.abs() < 3.0, "{name}: {e}, {z}");
        }
        closer_at_its_load(&results, "exp1");
    }
}

/// The paper's night (its springs, Exp1 as a validation run) on a rig
/// with the `[rig]` lines `rig` (the flow law's supply pressure and piston
/// area): the simulation manifest.
fn law_night(rig: &'static str, seed: u64) -> String {
    crate::util::PaperSweep {
        rig,
        seed,
        validation: true,
        ..crate::util::PaperSweep::default()
    }
    .text()
}

/// A validation run predicted at its load (the rig with the flow law) is
/// closer to its log than the zero-load rig's prediction.
fn closer_at_its_load(results: &Results, id: &str) {
    let run = results.runs.iter().find(|r| r.id == id).expect("the run");
    let v = run.validation.as_ref().expect("validated");
    let load = v.load.as_ref().expect("predicted at its load");
    eprintln!(
        "  {id} at {:.1} % of F_max: NRMSE {:.3} % at its load, {:.3} % at zero load",
        100.0 * load.load_fraction,
        v.nrmse_pct,
        load.zero_load.nrmse_pct
    );
    assert!(
        v.nrmse_pct < load.zero_load.nrmse_pct,
        "{id}: {} against {}",
        v.nrmse_pct,
        load.zero_load.nrmse_pct
    );
}

/// The nameplate's F_max (`rig.supply_pressure_pa`, `rig.piston_area_m2`
/// in the analysis manifest) on the paper's night, its springs at 4 mm, at
/// 20.7 MPa on 9.662 cm^2 (20 kN: the springs reach 2.3 % of it, Exp1
/// some 2 %), on 96.62 cm^2 (200 kN, 0.23 %) and on 966.2 cm^2 (2 MN,
/// 0.023 %). The same logs are read without the nameplate and with it.
/// With it every rig parameter is within 1 % or 3 total stds, the law is
/// fitted within 10 % of the nameplate's F_max (20 and 200 kN) or held at
/// it where the runs do not determine it (2 MN), and Exp1 is predicted at
/// its load no further from its log than at zero load.
#[test]
fn the_nameplate_starts_the_flow_law_or_holds_it() {
    for (rig, area, seed, held) in [
        (
            "supply_pressure_pa = 2.07e7\npiston_area_m2 = 9.662e-4",
            9.662e-4,
            3,
            false,
        ),
        (
            "supply_pressure_pa = 2.07e7\npiston_area_m2 = 9.662e-3",
            9.662e-3,
            4,
            false,
        ),
        (
            "supply_pressure_pa = 2.07e7\npiston_area_m2 = 9.662e-2",
            9.662e-2,
            5,
            true,
        ),
    ] {
        let ps = 2.07e7;
        let dir = scratch();
        let plan = load_simulation_str(&law_night(rig, seed), &dir.path().join("sim.toml"))
            .expect("a valid simulation");
        let sim = simulate_campaign(&plan, dir.path()).expect("simulates");
        let blind = analyse(&load(&sim.manifest).expect("loads"));
        let generated = std::fs::read_to_string(&sim.manifest).expect("the manifest");
        let with = generated.replacen(
            "[rig]\n",
            &format!("[rig]\nsupply_pressure_pa = {ps:?}\npiston_area_m2 = {area:?}\n"),
            1,
        );
        assert_ne!(with, generated, "the nameplate is written");
        let named = dir.path().join("nameplate.toml");
        std::fs::write(&named, with).expect("writes");
        let results = analyse(&load(&named).expect("the nameplate's manifest loads"));
        let fmax = ps * area;
        eprintln!("F_max {fmax:.0} N:");
        for (label, res) in [("  without the nameplate", &blind), ("  with it", &results)] {
            let r = res.rig.as_ref().expect("the rig");
            let errors: Vec<String> = crate::util::PAPER_TRUTH
                .iter()
                .zip([&r.beta1, &r.a1b0, &r.a2, &r.a3])
                .map(|((name, truth), est)| {
                    let z = (est.value - truth) / est.std.unwrap_or(f64::NAN);
                    format!(
                        "{name} {:+.3} % ({z:+.2})",
                        100.0 * (est.value / truth - 1.0)
                    )
                })
                .collect();
            eprintln!("{label}: {}", errors.join(", "));
        }
        let r = results.rig.as_ref().expect("the rig");
        let joint = r.joint.as_ref().expect("a joint fit");
        match (joint_parameter(joint, "max_force_n"), joint.flow_law_held_n) {
            (Some((value, std)), None) if !held => {
                eprintln!("  F_max fitted {value:.0} +- {std:.0} N");
                assert!((value / fmax - 1.0).abs() < 0.1, "F_max {value}");
            }
            (None, Some(f)) if held => {
                eprintln!("  F_max held at {f:.0} N");
                assert!((f - fmax).abs() < 1e-6 * fmax, "held at {f}");
                assert!(joint.explanation.contains("held at the nameplate"));
            }
            other => panic!("F_max {fmax}: {other:?}"),
        }
        for ((name, truth), est) in crate::util::PAPER_TRUTH
            .iter()
            .zip([&r.beta1, &r.a1b0, &r.a2, &r.a3])
        {
            let (e, z) = (
                est.value / truth - 1.0,
                (est.value - truth) / est.std.expect("a std"),
            );
            assert!(e.abs() < 0.01 || z.abs() < 3.0, "{name}: {e}, {z}");
        }
        let v = results.runs.iter().find(|r| r.id == "exp1").expect("exp1");
        let v = v.validation.as_ref().expect("validated");
        let load = v.load.as_ref().expect("predicted at its load");
        eprintln!(
            "  exp1 at {:.2} % of F_max: NRMSE {:.4} % at its load, {:.4} % at zero load",
            100.0 * load.load_fraction,
            v.nrmse_pct,
            load.zero_load.nrmse_pct
        );
        assert!(v.nrmse_pct <= load.zero_load.nrmse_pct * 1.001);
    }
}

/// The amplitude series: the paper's rig (its two springs, the no-specimen
/// run) with the no-specimen run and the first spring repeated at 1 mm
/// beside the 4 mm of the campaign, on four rigs: linear; with the seals'
/// 8 N of friction (tanh(v / 2 mm/s), a 0.5 kg piston); with the flow law
/// at F_max = 4 kN (the spring's 4 mm reach 11.7 % of it, its 1 mm
/// 2.9 %); with springs that stiffen 2 % at 4 mm. Each series must name the
/// candidate the rig holds, and none on the linear rig or for the law
/// without a specimen (no force for it to act on). F_max and k3 come out
/// within 1 % (4,025 +- 41 N, 1.443e8 +- 4.4e6 N/m^3 against 1.458e8;
/// asserted within 3 stds or 2 %). The friction comes out 7.2-7.3 N, 8-10 %
/// low, and its std (0.02 N) does not cover it: the describing function's
/// bias in the closed loop, which the joint fit's friction shares
/// (docs/accuracy.md); asserted within 15 %.
#[test]
fn an_amplitude_series_names_what_moves_the_rig() {
    let small = |id: &str, role: &str, specimen: &str| {
        format!(
            "\n[[runs]]\nid = \"{id}\"\nrole = \"{role}\"\np_gain = 1.0\n{specimen}excitation = {{ kind = \"chirp\", law = \"quadratic\", f0_hz = 0.1, f1_hz = 35.0, duration_s = 120.0, amplitude_m = 0.001, lead_in_s = 1.0, lead_out_s = 1.0 }}\n"
        )
    };
    let k1 = PAPER.springs[0];
    let cubic = 0.02;
    type Truth = [(Option<Movement>, Option<f64>); 2];
    let cases: [(&str, Extras, Truth); 4] = [
        (
            "linear",
            base(None, None, None, 0.0, 0.0, 0.0),
            [(None, None), (None, None)],
        ),
        (
            "friction 8 N",
            Extras {
                unmodelled: friction_lines(0.5, 8.0),
                ..base(None, None, None, 0.0, 0.0, 0.0)
            },
            [
                (Some(Movement::SealFriction), Some(8.0)),
                (Some(Movement::SealFriction), Some(8.0)),
            ],
        ),
        (
            "flow law F_max 4 kN",
            Extras {
                rig: "supply_pressure_pa = 2.07e7\npiston_area_m2 = 1.93237e-4",
                ..base(None, None, None, 0.0, 0.0, 0.0)
            },
            [(None, None), (Some(Movement::FlowLaw), Some(4000.0))],
        ),
        (
            "springs stiffening 2 % at 4 mm",
            Extras {
                spring_cubic: cubic,
                ..base(None, None, None, 0.0, 0.0, 0.0)
            },
            [
                (None, None),
                (
                    Some(Movement::Stiffening),
                    Some(cubic * k1 / 0.004f64.powi(2)),
                ),
            ],
        ),
    ];
    for (name, x, truth) in cases {
        let spring = if x.spring_cubic == 0.0 {
            format!("specimen = {{ stiffness_n_per_m = {k1} }}\n")
        } else {
            format!(
                "specimen = {{ model = \"duffing\", stiffness_n_per_m = {k1}, cubic_stiffness_n_per_m3 = {:e} }}\n",
                x.spring_cubic * k1 / (0.004f64 * 0.004)
            )
        };
        let text = manifest(900, &PAPER, &x)
            + &small("bare-1mm", "no_specimen", "")
            + &small("k1-1mm", "spring", &spring);
        let results = identify(&text);
        let series = &results.rig.as_ref().unwrap().amplitude_series;
        assert_eq!(series.len(), 2, "{name}: {series:#?}");
        for (s, (fits, value)) in series.iter().zip(truth) {
            eprintln!("{name}: {}", s.finding);
            assert_eq!(s.fits, fits, "{name}: {}", s.finding);
            if let (Some(f), Some(v)) = (fits, value) {
                let c = s.candidates.iter().find(|c| c.candidate == f).unwrap();
                let (got, std) = (c.value.unwrap(), c.std.unwrap());
                let ok = match f {
                    Movement::SealFriction => (got / v - 1.0).abs() < 0.15,
                    _ => (got - v).abs() < 3.0 * std || (got / v - 1.0).abs() < 0.02,
                };
                assert!(ok, "{name}: {got} +- {std} against {v}");
            }
        }
    }
}
