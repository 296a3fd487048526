//! The designed night against independent truths: a sine's steady
//! response for the predicted peaks, the limits over random rigs, the
//! square-root law for a target, and the paper's chirps for the bar the
//! night must clear.

use super::*;
use crate::simulate::seeded_rng;
use rand::Rng;
use std::f64::consts::PI;

const FS: f64 = 1000.0;

/// White displacement noise of `rms` m at `fs`: a flat density 2 rms^2 / fs.
fn white(rms: f64, fs: f64) -> Noise {
    Noise {
        freq_hz: vec![1.0, 10.0],
        psd_m2_per_hz: vec![2.0 * rms * rms / fs; 2],
    }
}

fn spring(k: f64) -> LinearSpecimen {
    LinearSpecimen::Spring {
        stiffness_n_per_m: k,
    }
}

/// The paper's three identification runs at P = 1.
fn paper_runs() -> Vec<RunModel> {
    [LinearSpecimen::None, spring(116_640.0), spring(88_540.0)]
        .into_iter()
        .map(|specimen| RunModel {
            specimen,
            p_gain: 1.0,
        })
        .collect()
}

fn plan(rig: RigParams, limits: Limits, record_s: f64) -> NightPlan {
    NightPlan {
        extension: Default::default(),
        rig,
        runs: paper_runs(),
        noise: white(2e-6, FS),
        band_hz: [0.5, 30.0],
        sample_rate_hz: FS,
        record_s,
        rest_s: 1.0,
        intersample: Intersample::SampleAndHold,
        limits,
        seed: 1,
    }
}

fn command_only(command_m: f64) -> Limits {
    Limits {
        command_m,
        stroke_m: None,
        velocity_m_per_s: None,
        force_n: None,
    }
}

/// White noise's level per sample is its variance, at any frequency.
#[test]
fn white_noise_has_its_variance_as_level() {
    let n = white(3e-6, 2048.0);
    for f in [0.1, 1.0, 5.0, 100.0] {
        assert!((n.level(f, 2048.0) / 9e-12 - 1.0).abs() < 1e-12);
    }
}

/// A 5 Hz sine of 2 mm faded in over 2 s on spring k1: the predicted
/// peaks are the plant's gain there (x1/u, s x1/u and f/u = k x1/u of
/// Eq. 10 evaluated at 5 Hz) times 2 mm, to 0.5 %.
#[test]
fn the_peaks_of_a_sine_are_its_steady_amplitudes() {
    let rig = crate::model::PAPER_RIG;
    let (f, a, k) = (5.0, 0.002, 116_640.0);
    let u: Vec<f64> = (0..20_000)
        .map(|j| {
            let t = j as f64 / FS;
            let ramp = if t < 2.0 {
                0.5 * (1.0 - (PI * t / 2.0).cos())
            } else {
                1.0
            };
            a * ramp * (2.0 * PI * f * t).sin()
        })
        .collect();
    let run = RunModel {
        specimen: spring(k),
        p_gain: 1.0,
    };
    let p = peaks(&rig, &run, &u, FS).unwrap();
    let s = nalgebra::Complex::new(0.0, 2.0 * PI * f);
    let (b1, a1b0, a2, a3) = (
        rig.beta1_per_s,
        rig.a1b0_n_per_m_s2,
        rig.a2_n_per_m,
        rig.a3_per_s,
    );
    // Eq. 10 with a spring: a1b0 / ((s + b1)((s + a3) k + s a2) + a1b0).
    let h = a1b0 / ((s + b1) * ((s + a3) * k + s * a2) + a1b0);
    let close = |got: f64, want: f64| (got / want - 1.0).abs() < 5e-3;
    assert!(close(p.command_m, a), "command {}", p.command_m);
    assert!(close(p.displacement_m, h.norm() * a), "x1 {p:?}");
    assert!(
        close(p.velocity_m_per_s, 2.0 * PI * f * h.norm() * a),
        "velocity {p:?}"
    );
    assert!(close(p.force_n.unwrap(), k * h.norm() * a), "force {p:?}");
}

/// Over random rigs (each parameter the paper's times 0.5-2) and random
/// limits (some absent), every designed run's predicted peaks are inside
/// every limit, the limit that bounds it is reached to a part in 1e6, and
/// the command written peaks at the peak predicted.
#[test]
fn a_design_never_exceeds_a_limit_over_random_rigs() {
    let mut rng = seeded_rng(7, "design/night/tests");
    for draw in 0..8 {
        let mut factor = || 2f64.powf(rng.random_range(-1.0..1.0));
        let base = crate::model::PAPER_RIG;
        let rig = RigParams {
            beta1_per_s: base.beta1_per_s * factor(),
            a1b0_n_per_m_s2: base.a1b0_n_per_m_s2 * factor(),
            a2_n_per_m: base.a2_n_per_m * factor(),
            a3_per_s: base.a3_per_s * factor(),
            ..base
        };
        let limits = Limits {
            command_m: rng.random_range(1e-3..1e-2),
            stroke_m: rng.random_bool(0.7).then(|| rng.random_range(5e-4..5e-3)),
            velocity_m_per_s: rng.random_bool(0.7).then(|| rng.random_range(0.01..0.3)),
            force_n: rng.random_bool(0.7).then(|| rng.random_range(50.0..500.0)),
        };
        let night = design(&plan(rig, limits, 30.0), None).unwrap();
        for (r, run) in night.runs.iter().enumerate() {
            let p = run.peaks;
            let within = |peak: f64, limit: Option<f64>| limit.is_none_or(|l| peak <= l);
            assert!(
                p.command_m <= limits.command_m,
                "draw {draw} run {r}: {p:?}"
            );
            assert!(
                within(p.displacement_m, limits.stroke_m),
                "draw {draw} run {r}"
            );
            assert!(
                within(p.velocity_m_per_s, limits.velocity_m_per_s),
                "draw {draw} run {r}"
            );
            assert!(
                p.force_n.is_none_or(|f| within(f, limits.force_n)),
                "draw {draw} run {r}"
            );
            let (peak, limit) = match run.bound_by {
                Limit::Command => (p.command_m, Some(limits.command_m)),
                Limit::Stroke => (p.displacement_m, limits.stroke_m),
                Limit::Velocity => (p.velocity_m_per_s, limits.velocity_m_per_s),
                Limit::Force => (p.force_n.unwrap(), limits.force_n),
                Limit::RunTime => unreachable!("a run's amplitude is not bounded by time"),
            };
            assert!(
                (peak / limit.unwrap() - 1.0).abs() < 1e-6,
                "draw {draw} run {r}: bounded by {:?} at {peak}",
                run.bound_by
            );
            let written = run.command_m.iter().fold(0.0_f64, |m, u| m.max(u.abs()));
            assert!((written / p.command_m - 1.0).abs() < 1e-12);
            assert_eq!(run.command_m[0], 0.0, "at rest at the start");
            assert_eq!(*run.command_m.last().unwrap(), 0.0, "at rest at the end");
        }
    }
}

/// With a target, the night is as long as the square-root law says it
/// must be: its worst relative std is at the target, and a period less
/// would miss it. A target the time per run cannot reach is refused,
/// naming that limit and the one that sets the amplitudes.
#[test]
fn a_target_sets_the_record_or_names_the_limit_that_stops_it() {
    let rig = crate::model::PAPER_RIG;
    let short = design(&plan(rig, command_only(0.004), 40.0), None).unwrap();
    let target = worst(&short, &rig) / 1.5;
    let night = design(&plan(rig, command_only(0.004), 120.0), Some(target)).unwrap();
    let reached = worst(&night, &rig);
    let steady = (night.periods - UNREAD) as f64;
    assert!(
        reached <= target * (1.0 + 1e-9),
        "{reached} against {target}"
    );
    assert!(
        reached * (steady / (steady - 1.0)).sqrt() > target,
        "a period fewer would do: {reached}, {steady} steady periods"
    );
    assert!(night.record_s < 120.0);
    let err = design(&plan(rig, command_only(0.004), 40.0), Some(target / 10.0)).unwrap_err();
    let text = err.to_string();
    assert!(
        text.contains("--run-s")
            && text.contains("the peak command (--command-mm, [design] command_m)"),
        "{text}"
    );
    let DesignError::TargetOutOfReach { needed_s, .. } = err else {
        panic!("{err:?}");
    };
    assert!(needed_s > 40.0);
}

/// The paper's night (its three identification runs, 172 s each at
/// 2,048 Hz, 4 mm peak, 2 um of LVDT noise): the designed commands give
/// the worst-determined parameter a std at least 1.3 times smaller than
/// the paper's quadratic chirps at the same record and peak, and the sum
/// of the squared relative stds at least 2 times smaller (the issue's
/// bar), each odd multisine of at least 50 lines at a crest factor of at
/// most 1.6.
#[test]
fn the_designed_night_clears_the_paper_chirps() {
    let rig = crate::model::PAPER_RIG;
    let mut plan = plan(rig, command_only(0.004), 172.0);
    plan.sample_rate_hz = 2048.0;
    plan.noise = white(2e-6, 2048.0);
    let night = design(&plan, None).unwrap();
    let chirps = chirp_baseline(&plan, 172.0).unwrap().relative_std(&rig);
    let ours = night.precision.relative_std(&rig);
    let max = |r: [f64; 4]| r.into_iter().fold(0.0, f64::max);
    let squares = |r: [f64; 4]| r.iter().map(|r| r * r).sum::<f64>();
    let (w, s) = (max(chirps) / max(ours), squares(chirps) / squares(ours));
    eprintln!(
        "period {} s x {}, share {}: worst {w:.2}, squares {s:.2}",
        night.period_s, night.periods, night.optimal_share
    );

    assert!(w >= 1.3 && s >= 2.0, "worst {w}, squares {s}");
    for run in &night.runs {
        if night.lines_hz.len() >= 50 {
            assert!(run.crest_factor <= 1.6, "crest {}", run.crest_factor);
        }
        assert!(run.peaks.command_m <= 0.004);
    }
}
