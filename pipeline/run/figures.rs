//! The campaign's figures as plain data for `report::figures`: the paper's
//! figures regenerated from a campaign (Figs. 8, 11, 13 per identification
//! run; Fig. 15 all together; Figs. 16-17 command to force; Figs. 9, 12, 14,
//! 19-22 in the paper's four time windows), residuals, and the stiffness
//! sensitivity. Axis ranges follow the paper's figures.

use std::sync::Arc;

use nalgebra::Complex;

use super::Analysis;
use crate::fit::hold_response;
use crate::lti::TransferFunction;
use crate::manifest::{Campaign, Role};
use crate::report::FigureSpec;
use crate::report::figures::{
    BodeFigure, BodeSeries, Figure, LinesFigure, PanelsFigure, TimePanel, TimeSeries, Trace,
    XySeries, decimate_minmax,
};

/// Frequency (Hz) where the paper's FRF figures stop.
const FRF_MAX_HZ: f64 = 30.0;

fn measured_bins(
    freq: &[f64],
    h: &[Complex<f64>],
    coh: &[f64],
    f_max: f64,
) -> (Vec<f64>, Vec<Complex<f64>>, Vec<f64>) {
    let mut out = (Vec::new(), Vec::new(), Vec::new());
    for i in 0..freq.len() {
        if freq[i] > 0.0 && freq[i] <= f_max {
            out.0.push(freq[i]);
            out.1.push(h[i]);
            out.2.push(coh[i]);
        }
    }
    out
}

/// The fitted model as the measurement sees it: plant, delay and the
/// command's hold.
fn model_response(
    tf: &TransferFunction,
    campaign: &Campaign,
    fs: f64,
    freq: &[f64],
) -> Vec<Complex<f64>> {
    freq.iter()
        .map(|&f| tf.freq_response(f) * hold_response(campaign.identification.intersample, fs, f))
        .collect()
}

/// Every figure of an analysed campaign, in a fixed order.
pub fn build(analysis: &Analysis, campaign: &Campaign) -> Vec<FigureSpec> {
    let mut out = Vec::new();
    let results = &analysis.results;
    let mut overlay = Vec::new();
    for (i, (run, art)) in results.runs.iter().zip(&analysis.artifacts).enumerate() {
        let Some(stage) = &art.stage else { continue };
        let fs = stage.log.sample_rate_hz;
        let f_max = FRF_MAX_HZ.max(run.fit.as_ref().map_or(0.0, |f| f.band_hz[1]));
        let (freq, h, coh) = measured_bins(
            &stage.frf.freq_hz,
            &stage.frf.h,
            &stage.frf.coherence,
            f_max,
        );
        // The displacement FRF: the fitted model for identification runs, the
        // rig's prediction for validation runs.
        let model = match (&stage.fit, run.role) {
            (Some(fit), _) => Some((
                model_response(&fit.tf, campaign, fs, &freq),
                "identified model",
            )),
            (None, Role::Validation) => run.tf.as_ref().map(|t| {
                let tf = TransferFunction {
                    num: t.num.clone(),
                    den: t.den.clone(),
                    delay_s: t.delay_s,
                };
                (
                    model_response(&tf, campaign, fs, &freq),
                    "model (identified rig)",
                )
            }),
            _ => None,
        };
        let mut series = vec![BodeSeries {
            label: "Experimental".into(),
            freq_hz: freq.clone(),
            h: h.clone(),
            coherence: Some(coh),
            trace: Trace::Measured,
            palette_index: Some(0),
        }];
        if let Some((hm, label)) = &model {
            series.push(BodeSeries {
                label: label.to_string(),
                freq_hz: freq.clone(),
                h: hm.clone(),
                coherence: None,
                trace: Trace::Model,
                palette_index: Some(1),
            });
        }
        let bode = BodeFigure {
            title: format!("{}: command to displacement", run.id),
            series,
            freq_range_hz: (0.0, f_max),
            mag_range_db: None,
            phase: true,
            coherence: true,
            log_frequency: false,
            mag_label: "Magnitude (dB)".into(),
        };
        let size = bode.recommended_size();
        let fit_note = run
            .fit
            .as_ref()
            .map(|f| {
                format!(
                    " Fitted over {}-{} Hz ({} bins, fit {:.1} %, mean coherence {:.3}).",
                    f.band_hz[0], f.band_hz[1], f.n_bins, f.fit_percent, f.coherence_mean
                )
            })
            .unwrap_or_default();
        out.push(FigureSpec {
            id: format!("frf-{}", run.id),
            title: format!("{}: frequency response, command to displacement", run.id),
            caption: format!(
                "Counterpart of the paper's Figs. 8, 11 and 13: measured FRF ({} estimate, {} averages) and the model, magnitude, phase and coherence.{fit_note}",
                match stage.frf.estimator {
                    crate::manifest::Estimator::H1 => "H1",
                    crate::manifest::Estimator::H2 => "H2",
                    crate::manifest::Estimator::Etfe => "ETFE",
                },
                stage.frf.n_averages
            ),
            figure: Figure::Bode(bode),
            size,
        });
        if matches!(run.role, Role::NoSpecimen | Role::Spring)
            && let Some((hm, _)) = &model
        {
            overlay.push((i, run.id.clone(), freq.clone(), h.clone(), hm.clone()));
        }

        // Figs. 16-17: command to force, measured against Eq. 45.
        if let (Some(ff), Some(model_f)) = (&stage.force_frf, &run.force_tf) {
            let (freq, h, coh) = measured_bins(&ff.freq_hz, &ff.h, &ff.coherence, 35.0);
            let tf = TransferFunction {
                num: model_f.num.clone(),
                den: model_f.den.clone(),
                delay_s: 0.0,
            };
            let hm = model_response(&tf, campaign, fs, &freq);
            let fig = BodeFigure {
                title: format!("{}: command to force", run.id),
                series: vec![
                    BodeSeries {
                        label: "Experimental".into(),
                        freq_hz: freq.clone(),
                        h,
                        coherence: Some(coh),
                        trace: Trace::Measured,
                        palette_index: Some(0),
                    },
                    BodeSeries {
                        label: "Simulated (Eq. 45)".into(),
                        freq_hz: freq,
                        h: hm,
                        coherence: None,
                        trace: Trace::Model,
                        palette_index: Some(1),
                    },
                ],
                freq_range_hz: (5.0, 35.0),
                mag_range_db: None,
                phase: false,
                coherence: false,
                log_frequency: false,
                mag_label: "Force/command (dB re 1 N/m)".into(),
            };
            let size = fig.recommended_size();
            out.push(FigureSpec {
                id: format!("force-{}", run.id),
                title: format!("{}: frequency response, command to force", run.id),
                caption: format!(
                    "Counterpart of the paper's Figs. 16-17: the specimen's poles are zeros of the force path (Eq. 45){}.",
                    run.natural_frequency_hz
                        .map(|f| format!("; its natural frequency is {f:.1} Hz"))
                        .unwrap_or_default()
                ),
                figure: Figure::Bode(fig),
                size,
            });
        }

        // The paper's four windows, measured against simulated displacement.
        if let Some(time) = &art.time {
            let n = time.x1_measured.len().min(time.x1_simulated.len());
            let t: Arc<[f64]> = (0..n).map(|k| k as f64 / fs).collect::<Vec<_>>().into();
            let cm = |x: &[f64]| -> Arc<[f64]> {
                x[..n].iter().map(|v| v * 100.0).collect::<Vec<_>>().into()
            };
            let measured = cm(&time.x1_measured);
            let simulated = cm(&time.x1_simulated);
            // The paper's simplified CCF beside the full model, when it is
            // stable enough to have been simulated.
            let simplified = time
                .x1_simplified
                .as_ref()
                .filter(|x| x.len() >= n)
                .map(|x| cm(x));
            let letters = ["(a)", "(b)", "(c)", "(d)"];
            let panels: Vec<TimePanel> = time
                .windows
                .iter()
                .enumerate()
                .map(|(k, w)| TimePanel {
                    title: format!(
                        "{} {} ({:.0}-{:.0} s)",
                        letters.get(k).copied().unwrap_or(""),
                        w.label,
                        w.start_s,
                        w.end_s
                    ),
                    t_s: t.clone(),
                    series: vec![
                        TimeSeries {
                            label: "Experimental".into(),
                            y: measured.clone(),
                            trace: Trace::Measured,
                            palette_index: Some(0),
                        },
                        TimeSeries {
                            label: if run.role == Role::Validation {
                                "Simulated".into()
                            } else {
                                "Identified model".into()
                            },
                            y: simulated.clone(),
                            trace: Trace::Model,
                            palette_index: Some(1),
                        },
                    ]
                    .into_iter()
                    .chain(simplified.as_ref().map(|y| TimeSeries {
                        label: "Simplified CCF (Cn dropped)".into(),
                        y: y.clone(),
                        trace: Trace::Model,
                        palette_index: Some(3),
                    }))
                    .collect(),
                    t_range_s: (w.start_s, w.end_s),
                    y_label: "Disp (cm)".into(),
                    y_range: None,
                })
                .collect();
            if !panels.is_empty() {
                let fig = PanelsFigure {
                    title: format!("{}: measured and simulated displacement", run.id),
                    panels,
                    columns: 2,
                };
                let size = fig.recommended_size();
                let m = &time.metrics;
                // The windows the sweep reaches (a sweep that stops short of
                // 35 Hz has fewer than the paper's four).
                let windows = time
                    .windows
                    .iter()
                    .map(|w| format!("{} ({:.1}-{:.1} s)", w.label, w.start_s, w.end_s))
                    .collect::<Vec<_>>()
                    .join(", ");
                out.push(FigureSpec {
                    id: format!("time-{}", run.id),
                    title: format!("{}: time-domain comparison", run.id),
                    caption: format!(
                        "Counterpart of the paper's Figs. 9, 12, 14 and 19-22: {} driven by the measured command, in the windows of the sweep {windows}. Whole record: NRMSE {:.2} %, NAE {:.2} % (Eqs. 47-48).",
                        m.model, m.nrmse_pct, m.nae_pct
                    ),
                    figure: Figure::Panels(fig),
                    size,
                });
            }
            // Residual over the whole record, min/max decimated.
            let tt: Vec<f64> = t.to_vec();
            let r: Vec<f64> = (0..n)
                .map(|k| (time.x1_measured[k] - time.x1_simulated[k]) * 1e3)
                .collect();
            let (x, y) = decimate_minmax(&tt, &r, 1500);
            out.push(FigureSpec {
                id: format!("residual-{}", run.id),
                title: format!("{}: displacement residual", run.id),
                caption: "Measured minus simulated displacement over the whole record (min/max per pixel column, so no peak is lost).".into(),
                figure: Figure::Lines(LinesFigure {
                    title: format!("{}: measured - simulated displacement", run.id),
                    x_label: "Time (s)".into(),
                    y_label: "Residual (mm)".into(),
                    series: vec![XySeries {
                        label: "residual".into(),
                        x,
                        y,
                        trace: Trace::Measured,
                        palette_index: Some(2),
                    }],
                    x_range: None,
                    y_range: None,
                    log_x: false,
                    log_y: false,
                    zero_line: true,
                }),
                size: (1200, 450),
            });
        }
    }

    // Fig. 15: every identification run together, 0-15 Hz.
    if overlay.len() >= 2 {
        let mut series = Vec::new();
        for (k, (_, id, freq, h, hm)) in overlay.iter().enumerate() {
            series.push(BodeSeries {
                label: format!("{id} (experimental)"),
                freq_hz: freq.clone(),
                h: h.clone(),
                coherence: None,
                trace: Trace::Measured,
                palette_index: Some(k),
            });
            series.push(BodeSeries {
                label: format!("{id} (identified)"),
                freq_hz: freq.clone(),
                h: hm.clone(),
                coherence: None,
                trace: Trace::Model,
                palette_index: Some(k),
            });
        }
        let fig = BodeFigure {
            title: "Identification runs: command to displacement".into(),
            series,
            freq_range_hz: (0.0, 15.0),
            mag_range_db: None,
            phase: false,
            coherence: false,
            log_frequency: false,
            mag_label: "Magnitude (dB)".into(),
        };
        let size = fig.recommended_size();
        out.push(FigureSpec {
            id: "frf-identification".into(),
            title: "All identification runs".into(),
            caption: "Counterpart of the paper's Fig. 15: the rig with no specimen and with each spring, measured (solid) and identified (dashed).".into(),
            figure: Figure::Bode(fig),
            size,
        });
    }

    // The stiffness sensitivity (paper Sec. 2.3).
    if let Some(s) = &results.sensitivity {
        let k = &s.sweep.stiffness_n_per_m;
        let pct = |v: &[f64]| v.iter().map(|x| 100.0 * x).collect::<Vec<_>>();
        let mut series = vec![
            XySeries {
                label: "a1b0".into(),
                x: k.clone(),
                y: pct(&s.sweep.rel_std_a1b0),
                trace: Trace::Model,
                palette_index: Some(0),
            },
            XySeries {
                label: "a2".into(),
                x: k.clone(),
                y: pct(&s.sweep.rel_std_a2),
                trace: Trace::Model,
                palette_index: Some(1),
            },
            XySeries {
                label: "a3".into(),
                x: k.clone(),
                y: pct(&s.sweep.rel_std_a3),
                trace: Trace::Model,
                palette_index: Some(2),
            },
        ];
        let all: Vec<f64> = series.iter().flat_map(|s| s.y.clone()).collect();
        let (lo, hi) = all
            .iter()
            .fold((f64::INFINITY, 0.0_f64), |(a, b), v| (a.min(*v), b.max(*v)));
        for (j, ks) in s.springs_n_per_m.iter().enumerate() {
            series.push(XySeries {
                label: if j == 0 {
                    "campaign's springs".into()
                } else {
                    String::new()
                },
                x: vec![*ks, *ks],
                y: vec![lo, hi],
                trace: Trace::Reference,
                palette_index: None,
            });
        }
        out.push(FigureSpec {
            id: "sensitivity".into(),
            title: "Sensitivity to the spring stiffness".into(),
            caption: format!(
                "Relative standard deviation of the identified a1b0, a2 and a3 from one no-specimen run and one spring of stiffness k ({}).",
                s.basis
            ),
            figure: Figure::Lines(LinesFigure {
                title: "Identified parameters against spring stiffness".into(),
                x_label: "Spring stiffness k (N/m)".into(),
                y_label: "Relative std (%)".into(),
                series,
                x_range: None,
                y_range: None,
                log_x: true,
                log_y: true,
                zero_line: false,
            }),
            size: (1200, 600),
        });
    }
    out
}
