//! The predicted precision against what the joint fit does: the spread of
//! its estimates over noisy FRFs drawn at the predicted variance, the
//! truth computed another way (the simulator's state space, held and
//! sampled as a log holds it), and the ETFE variance of a sine by hand.

use rand_distr::{Distribution, StandardNormal};

use super::*;
use crate::identify::bins::Bins;
use crate::identify::joint::{JointOptions, JointRun, Output, Structure, joint_fit};
use crate::model::SpecimenModel;
use crate::simulate::plant::{PlantSpec, Unmodelled, linear_state_space};
use crate::simulate::seeded_rng;

const FS: f64 = 1000.0;

fn options() -> JointOptions {
    JointOptions {
        structure: Structure::Plain,
        intersample: Intersample::SampleAndHold,
        sample_rate_hz: FS,
        p_ref: 1.0,
        max_iterations: 200,
        valve_start: (150.0, 0.5),
        piston_start_kg: 1.0,
        delay_start_s: 0.0,
        max_delay_s: 0.05,
        force_delay_start_s: 0.0,
        friction: false,
        friction_start_n: 0.0,
        friction_smoothing_m_per_s: None,
        seal_damping: false,
        command_gain: false,
        command_gain_start: 1.0,
        flow_law: false,
        try_flow_law: false,
        max_force_start_n: f64::INFINITY,
        max_force_nameplate_n: None,
        flow_law_held: false,
    }
}

/// x1/u of `specimen` from the simulator's state space, held and sampled.
fn truth(rig: &RigParams, specimen: SpecimenModel, f: &[f64]) -> Vec<Complex<f64>> {
    let ss = linear_state_space(&PlantSpec {
        rig: *rig,
        specimen,
        unmodelled: Unmodelled::default(),
    })
    .unwrap();
    crate::lti::ZohSampled::of_state_space(&ss, 0, 0.0, FS).response(f)
}

/// The paper's three identification runs and a validation run at P = 2,
/// on bins of 0.5-30 Hz every 0.05 Hz, each bin's variance a percent of
/// |H|^2 rising with frequency: 1,000 noisy nights fitted jointly scatter
/// as predicted, each parameter's std within 10 % (the sample std of 1,000
/// draws is itself uncertain by 2.2 %; the ratios were 0.99-1.02).
#[test]
fn the_joint_fits_spread_is_the_predicted_one() {
    let rig = crate::model::PAPER_RIG;
    let f: Vec<f64> = (10..=600).map(|i| i as f64 * 0.05).collect();
    let specimens = [
        (SpecimenModel::None, 1.0),
        (
            SpecimenModel::Spring {
                stiffness_n_per_m: 116_640.0,
            },
            1.0,
        ),
        (
            SpecimenModel::Spring {
                stiffness_n_per_m: 88_540.0,
            },
            1.0,
        ),
        (
            SpecimenModel::LinearSdof {
                mass_kg: 3.8,
                damping_ns_per_m: 5.0,
                stiffness_n_per_m: 129_400.0,
            },
            2.0,
        ),
    ];
    let clean: Vec<Vec<Complex<f64>>> = specimens
        .iter()
        .map(|(s, p)| truth(&rig.at_p_gain(*p), *s, &f))
        .collect();
    let variance: Vec<Vec<f64>> = clean
        .iter()
        .map(|h| {
            h.iter()
                .zip(&f)
                .map(|(h, f)| 1e-4 * h.norm_sqr() * (1.0 + f / 10.0))
                .collect()
        })
        .collect();
    let planned: Vec<PlannedRun> = specimens
        .iter()
        .zip(&variance)
        .map(|((s, p), v)| PlannedRun {
            specimen: s.linear().unwrap(),
            p_gain: *p,
            freq_hz: f.clone(),
            variance: v.clone(),
        })
        .collect();
    let predicted = predict(&rig, &planned, Intersample::SampleAndHold, FS)
        .expect("four runs determine the rig")
        .std();

    let mut rng = seeded_rng(2, "design/precision/tests");
    let draws = 1000;
    let mut estimates = Vec::with_capacity(draws);
    for _ in 0..draws {
        let noisy: Vec<Vec<Complex<f64>>> = clean
            .iter()
            .zip(&variance)
            .map(|(h, v)| {
                h.iter()
                    .zip(v)
                    .map(|(h, v)| {
                        let s = (v / 2.0).sqrt();
                        let re: f64 = StandardNormal.sample(&mut rng);
                        let im: f64 = StandardNormal.sample(&mut rng);
                        h + Complex::new(re * s, im * s)
                    })
                    .collect()
            })
            .collect();
        let runs: Vec<JointRun<'_>> = noisy
            .iter()
            .zip(&variance)
            .zip(&planned)
            .map(|((h, v), p)| JointRun {
                specimen: p.specimen,
                p_gain: p.p_gain,
                output: Output::Displacement,
                bins: Bins::held(&f, h, v, None),
                bin_hz: 0.05,
                lag: 1,
                spring_cubic_n_per_m3: None,
            })
            .collect();
        let fit = joint_fit(&runs, &rig, &options()).expect("the joint fit converges");
        estimates.push([fit.params[0], fit.params[1], fit.params[2], fit.params[3]]);
    }
    for (j, name) in NAMES.iter().enumerate() {
        let mean = estimates.iter().map(|e| e[j]).sum::<f64>() / draws as f64;
        let var = estimates.iter().map(|e| (e[j] - mean).powi(2)).sum::<f64>() / (draws - 1) as f64;
        let ratio = var.sqrt() / predicted[j];
        assert!(
            (0.9..1.1).contains(&ratio),
            "{name}: spread {} against predicted {} (ratio {ratio})",
            var.sqrt(),
            predicted[j]
        );
    }
}

/// A sine of amplitude A on bin k of N samples has |U_k| = N A / 2, so
/// white noise of variance s^2 gives E|dH_k|^2 = 4 s^2 / (N A^2).
#[test]
fn a_sines_etfe_variance_is_four_s2_over_n_a2() {
    let (n, k, a, s2) = (4000usize, 37usize, 0.002, 1e-12);
    let u: Vec<f64> = (0..n)
        .map(|j| a * (2.0 * std::f64::consts::PI * (k * j) as f64 / n as f64 + 0.3).sin())
        .collect();
    let (f, v) = etfe_variance(&u, FS, [0.5, 30.0], |_| s2);
    let at = f
        .iter()
        .position(|x| (x - k as f64 * FS / n as f64).abs() < 1e-9)
        .expect("the sine's bin");
    let expected = 4.0 * s2 / (n as f64 * a * a);
    assert!(
        (v[at] / expected - 1.0).abs() < 1e-9,
        "{} vs {expected}",
        v[at]
    );
    // The other bins hold rounding only: their variance is far larger.
    assert!(
        v.iter()
            .enumerate()
            .all(|(i, x)| i == at || *x > 1e6 * expected)
    );
}

/// With no extension, the extended x1/u is the paper's (Eq. 17 through
/// model::tf_x1_u) for each kind of specimen, to 1e-12; a delay rotates
/// it by -w tau and keeps its magnitude.
#[test]
fn the_extended_x1_u_without_extension_is_the_papers() {
    let rig = crate::model::PAPER_RIG.at_p_gain(2.0);
    let specimens = [
        LinearSpecimen::None,
        LinearSpecimen::Spring {
            stiffness_n_per_m: 116_640.0,
        },
        LinearSpecimen::Sdof {
            mass_kg: 3.8,
            damping_ns_per_m: 5.0,
            stiffness_n_per_m: 129_400.0,
        },
    ];
    for s in specimens {
        let tf = model::tf_x1_u(&rig, &s).unwrap();
        for f in [0.3, 2.0, 17.0, 60.0] {
            let paper = tf.freq_response(f);
            let ours = x1_u(&rig, &Extension::default(), s, f);
            assert!((ours / paper - 1.0).norm() < 1e-12, "{s:?} at {f} Hz");
            let tau = 6e-4;
            let delayed = x1_u(
                &rig,
                &Extension {
                    delay_s: Some(tau),
                    ..Extension::default()
                },
                s,
                f,
            );
            let turn = delayed / paper;
            assert!((turn.norm() - 1.0).abs() < 1e-12);
            assert!((turn.arg() + 2.0 * std::f64::consts::PI * f * tau).abs() < 1e-9);
        }
    }
}
