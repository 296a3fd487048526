//! Rendering cost of a seven-run campaign's figures (paper Figs. 8-22 plus
//! residuals): 3 identification Bode figures with coherence, 1 overlay of the
//! 3 identification runs, 4 command-to-force FRFs, 7 four-window time figures
//! and 7 residual figures from 348,160-sample records, rendered in parallel
//! with rayon: as PNG and SVG, and as PNG, SVG and the page's preview.
//!
//! `cargo bench --bench figures`. With SERVOID_FIGURE_EXAMPLES=<dir> the PNG,
//! SVG and preview of one figure of each kind are also written there
//! (outside the timed loop).

use std::f64::consts::PI;
use std::hint::black_box;
use std::sync::Arc;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use nalgebra::Complex;
use servoid::model::{LinearSpecimen, PAPER_RIG, tf_f_u, tf_x1_u};
use servoid::report::figures::{
    BodeFigure, BodeSeries, FULL_WIDTH, Figure, Formats, LinesFigure, PanelsFigure, TimePanel,
    TimeSeries, Trace, XySeries, render_many,
};

const FS_HZ: f64 = 2000.0;
const N: usize = 348_160; // 174 s at 2 kHz
const DF_HZ: f64 = 0.25;
const BINS: usize = 4097;

/// Deterministic noise in [-0.5, 0.5).
struct Noise(u64);
impl Noise {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    }
}

fn freqs() -> Vec<f64> {
    (0..BINS).map(|k| k as f64 * DF_HZ).collect()
}

/// "Measured" FRF: the model with 3 % complex noise, a 0.25 ms extra delay
/// and coherence that drops at low frequency where the chirp is slow.
fn measured_frf(model: &[Complex<f64>], f: &[f64], seed: u64) -> (Vec<Complex<f64>>, Vec<f64>) {
    let mut n = Noise(seed);
    let h = model
        .iter()
        .zip(f)
        .map(|(h, &fk)| {
            let delay = Complex::from_polar(1.0, -2.0 * PI * fk * 2.5e-4);
            h * delay * Complex::new(1.0 + 0.06 * n.next(), 0.06 * n.next())
        })
        .collect();
    let coh = f
        .iter()
        .map(|&fk| (1.0 - 0.6 * (-fk / 0.8).exp() - 0.04 * (n.next() + 0.5)).clamp(0.0, 1.0))
        .collect();
    (h, coh)
}

fn model_frf(tf: &servoid::lti::TransferFunction, f: &[f64]) -> Vec<Complex<f64>> {
    f.iter().map(|&fk| tf.freq_response(fk)).collect()
}

/// Quadratic chirp 0.1 -> 35 Hz over the record, 0.5 cm.
fn command_cm() -> Vec<f64> {
    let t_end = N as f64 / FS_HZ;
    (0..N)
        .map(|i| {
            let t = i as f64 / FS_HZ;
            let phase = 2.0 * PI * (0.1 * t + 34.9 * t.powi(3) / (3.0 * t_end * t_end));
            0.5 * phase.sin()
        })
        .collect()
}

/// x1 for x1/u = wn2 / (s^2 + d1 s + wn2), semi-implicit Euler.
fn respond(u: &[f64], d1: f64, wn2: f64) -> Vec<f64> {
    let dt = 1.0 / FS_HZ;
    let (mut x, mut v) = (0.0, 0.0);
    u.iter()
        .map(|&uk| {
            v += dt * (wn2 * (uk - x) - d1 * v);
            x += dt * v;
            x
        })
        .collect()
}

fn campaign() -> Vec<(Figure, (u32, u32))> {
    let rig = PAPER_RIG;
    let f = freqs();
    let mut figs = Vec::new();

    // Identification runs: no specimen, springs k1 and k2 (Eqs. 36-38).
    let id_runs = [
        ("no specimen", LinearSpecimen::None),
        (
            "spring k1",
            LinearSpecimen::Spring {
                stiffness_n_per_m: 116_640.0,
            },
        ),
        (
            "spring k2",
            LinearSpecimen::Spring {
                stiffness_n_per_m: 88_540.0,
            },
        ),
    ];
    let mut overlay = Vec::new();
    for (k, (name, spec)) in id_runs.iter().enumerate() {
        let model = model_frf(&tf_x1_u(&rig, spec).unwrap(), &f);
        let (meas, coh) = measured_frf(&model, &f, 11 + k as u64);
        let fig = BodeFigure {
            title: format!("Identification, {name}: command to displacement"),
            series: vec![
                BodeSeries {
                    label: "Experimental".into(),
                    freq_hz: f.clone(),
                    h: meas.clone(),
                    coherence: Some(coh),
                    trace: Trace::Measured,
                    palette_index: None,
                    band: None,
                },
                BodeSeries {
                    label: "Identified model".into(),
                    freq_hz: f.clone(),
                    h: model.clone(),
                    coherence: None,
                    trace: Trace::Model,
                    palette_index: None,
                    band: None,
                },
            ],
            freq_range_hz: (0.0, 30.0),
            mag_range_db: None,
            phase: true,
            coherence: true,
            log_frequency: false,
            mag_label: String::new(),
        };
        let size = fig.recommended_size();
        figs.push((Figure::Bode(fig), size));
        for (label, h, trace) in [
            (format!("Experimental, {name}"), meas, Trace::Measured),
            (format!("Model, {name}"), model, Trace::Model),
        ] {
            overlay.push(BodeSeries {
                label,
                freq_hz: f.clone(),
                h,
                coherence: None,
                trace,
                palette_index: Some(k),
                band: None,
            });
        }
    }
    figs.push((
        Figure::Bode(BodeFigure {
            title: "Identification runs compared".into(),
            series: overlay,
            freq_range_hz: (0.0, 15.0),
            mag_range_db: Some((-20.0, 2.0)),
            phase: false,
            coherence: false,
            log_frequency: false,
            mag_label: String::new(),
        }),
        FULL_WIDTH,
    ));

    // Validation: Exp1-Exp4 (Table 2), command to force (Figs. 16-17).
    let exps = [
        (129_400.0, 1.0),
        (129_400.0, 2.0),
        (84_340.0, 1.0),
        (84_340.0, 2.0),
    ];
    for (k, &(stiffness, p)) in exps.iter().enumerate() {
        let spec = LinearSpecimen::Sdof {
            mass_kg: 3.8,
            damping_ns_per_m: 5.0,
            stiffness_n_per_m: stiffness,
        };
        let model = model_frf(&tf_f_u(&rig.at_p_gain(p), &spec).unwrap(), &f);
        let (meas, _) = measured_frf(&model, &f, 21 + k as u64);
        figs.push((
            Figure::Bode(BodeFigure {
                title: format!("Exp{}: command to force", k + 1),
                series: vec![
                    BodeSeries {
                        label: "Experimental".into(),
                        freq_hz: f.clone(),
                        h: meas,
                        coherence: None,
                        trace: Trace::Measured,
                        palette_index: None,
                        band: None,
                    },
                    BodeSeries {
                        label: "Simulated".into(),
                        freq_hz: f.clone(),
                        h: model,
                        coherence: None,
                        trace: Trace::Model,
                        palette_index: None,
                        band: None,
                    },
                ],
                freq_range_hz: (5.0, 35.0),
                mag_range_db: None,
                phase: false,
                coherence: false,
                log_frequency: false,
                mag_label: "Force/command (dB re 1 N/m)".into(),
            }),
            FULL_WIDTH,
        ));
    }

    // Seven runs' time records: four windows each, and residuals.
    let t: Arc<[f64]> = (0..N).map(|i| i as f64 / FS_HZ).collect();
    let u = command_cm();
    let run_names = [
        "No specimen",
        "Spring k1",
        "Spring k2",
        "Exp1",
        "Exp2",
        "Exp3",
        "Exp4",
    ];
    for (k, name) in run_names.iter().enumerate() {
        let wn2 = 3060.0 - 40.0 * k as f64;
        let mut noise = Noise(100 + k as u64);
        let measured: Vec<f64> = respond(&u, 267.0, wn2)
            .into_iter()
            .map(|x| x + 0.004 * noise.next())
            .collect();
        let simulated = respond(&u, 262.0, wn2 * 1.01);
        let residual: Vec<f64> = measured
            .iter()
            .zip(&simulated)
            .map(|(a, b)| a - b)
            .collect();
        let measured: Arc<[f64]> = measured.into();
        let simulated: Arc<[f64]> = simulated.into();
        let windows = [
            ("(a) 10-20 s", (10.0, 20.0)),
            ("(b) 40-50 s", (40.0, 50.0)),
            ("(c) 120-122 s", (120.0, 122.0)),
            ("(d) 170-171 s", (170.0, 171.0)),
        ];
        let panels = windows
            .iter()
            .map(|&(title, range)| TimePanel {
                title: title.into(),
                t_s: t.clone(),
                series: vec![
                    TimeSeries {
                        label: "Experimental".into(),
                        y: measured.clone(),
                        trace: Trace::Measured,
                        palette_index: None,
                    },
                    TimeSeries {
                        label: "Simulated".into(),
                        y: simulated.clone(),
                        trace: Trace::Model,
                        palette_index: None,
                    },
                ],
                t_range_s: range,
                y_label: "Displacement (cm)".into(),
                y_range: None,
            })
            .collect();
        let fig = PanelsFigure {
            title: format!("{name}: measured and simulated displacement"),
            panels,
            columns: 2,
        };
        let size = fig.recommended_size();
        figs.push((Figure::Panels(fig), size));
        figs.push((
            Figure::Lines(LinesFigure {
                title: format!("{name}: residual, measured minus simulated"),
                x_label: "Time (s)".into(),
                y_label: "Residual (cm)".into(),
                series: vec![XySeries {
                    label: "Residual".into(),
                    x: t.to_vec(),
                    y: residual,
                    trace: Trace::Measured,
                    palette_index: None,
                }],
                x_range: None,
                y_range: None,
                log_x: false,
                log_y: false,
                zero_line: true,
            }),
            FULL_WIDTH,
        ));
    }
    figs
}

fn save_examples(figs: &[(Figure, (u32, u32))], dir: &str) {
    let wanted = [
        (0, "bode-identification"),
        (3, "bode-overlay"),
        (4, "bode-force"),
        (8, "panels-time-windows"),
        (9, "lines-residual"),
    ];
    std::fs::create_dir_all(dir).expect("create the examples directory");
    let picked: Vec<(&Figure, (u32, u32))> = wanted
        .iter()
        .map(|&(i, _)| (&figs[i].0, figs[i].1))
        .collect();
    let all = Formats {
        png: true,
        svg: true,
    };
    for (r, &(_, name)) in render_many(&picked, all).into_iter().zip(&wanted) {
        let r = r.expect("example figure renders");
        let (png, svg) = (r.png.unwrap(), r.svg.unwrap());
        std::fs::write(format!("{dir}/{name}.png"), png).expect("write PNG");
        std::fs::write(format!("{dir}/{name}.svg"), svg).expect("write SVG");
    }
}

fn bench(c: &mut Criterion) {
    let figs = campaign();
    assert_eq!(figs.len(), 22);
    if let Ok(dir) = std::env::var("SERVOID_FIGURE_EXAMPLES") {
        save_examples(&figs, &dir);
    }
    let figs: Vec<(&Figure, (u32, u32))> = figs.iter().map(|(f, s)| (f, *s)).collect();
    let mut g = c.benchmark_group("figures");
    g.sample_size(10);
    g.throughput(Throughput::Elements(figs.len() as u64));
    for (id, png, svg) in [
        ("campaign_7_runs_22_figures_png_svg", true, true),
        ("campaign_7_runs_22_figures_png", true, false),
        ("campaign_7_runs_22_figures_svg", false, true),
    ] {
        let formats = Formats { png, svg };
        g.bench_function(id, |b| {
            b.iter(|| {
                let out = render_many(black_box(&figs), formats);
                assert!(out.iter().all(Result::is_ok));
                out
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
