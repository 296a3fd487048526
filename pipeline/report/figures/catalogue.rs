//! Which figures a campaign gets and what each shows, as plain data for the
//! drawing in this module's parent: the paper's figures regenerated from a
//! campaign (Figs. 8, 11, 13 per identification
//! run; Fig. 15 all together; Figs. 16-17 command to force; Figs. 9, 12, 14,
//! 19-22 in the paper's four time windows), residuals, and the stiffness
//! sensitivity. Axis ranges follow the paper's figures. One builder per
//! figure kind: a run's figures are built while its log is in memory (the
//! force FRF, which needs the rig's model, from a small copy of its bins),
//! the campaign's at the end.

use std::sync::Arc;

use nalgebra::Complex;

use super::{
    BodeBand, BodeFigure, BodeSeries, Figure, LinesFigure, PanelsFigure, TimePanel, TimeSeries,
    Trace, XySeries, decimate_minmax_by,
};
use crate::fit::band::response_std;
use crate::fit::{Intersample, hold_response};
use crate::frf::Method;
use crate::lti::TransferFunction;
use crate::lti::complex_vec;
use crate::manifest::Role;
use crate::model::{LinearSpecimen, RigParams, x1_u_std};
use crate::report::{FigureSpec, Measured};
use crate::results::{RunResult, SensitivityResult, TfResult};
use crate::sensitivity::montecarlo::{MonteCarlo, MonteCarloPoint, PerParameter};
use crate::tracking::compensator::{self, Compensator, CompensatorOutcome, StiffnessPoint};
use crate::validate::TimeStage;
use crate::validate::csi::Csi;

/// Frequency (Hz) where the paper's FRF figures stop.
pub const FRF_MAX_HZ: f64 = 30.0;

/// Frequency (Hz) where the force path's bins (Figs. 16-17, Eq. 45) stop:
/// all the analysis keeps.
pub const FORCE_FRF_MAX_HZ: f64 = crate::frf::KEPT_MAX_HZ;

const _: () = assert!(FRF_MAX_HZ <= crate::frf::KEPT_MAX_HZ);

/// A run's figures that do not depend on the rig, drawn as soon as its log
/// is analysed: the FRF (for a validation run the caller passes the
/// result with the rig's model), the time windows and the residual; of
/// them only the FRF, with a validation run's time windows, unless
/// `every`. For an identification run, also what Fig. 15 needs of it.
pub fn log_figures(
    run: &RunResult,
    measured: &Measured<'_>,
    time: Option<&TimeStage>,
    intersample: Intersample,
    prediction: Option<&Prediction>,
    every: bool,
) -> (Vec<FigureSpec>, Option<OverlayRun>) {
    let frf = RunFrf::new(run, measured, intersample, prediction);
    let mut out = vec![frf_figure(run, measured, &frf)];
    let overlay = match (&frf.model, run.role) {
        (Some((model, _)), Role::NoSpecimen | Role::Spring) => Some(OverlayRun {
            id: run.id.clone(),
            freq_hz: frf.freq_hz.clone(),
            measured: frf.h.clone(),
            model: model.clone(),
        }),
        _ => None,
    };
    if let Some(time) = time {
        let fs = measured.sample_rate_hz;
        if every || run.role == Role::Validation {
            out.extend(time_figure(run, time, fs));
        }
        if every {
            out.push(residual_figure(run, time, fs));
        }
    }
    (out, overlay)
}

/// The figures of a run analysed without the rig
/// (`analysis::step::without_rig`): its log's figures and, with `every`,
/// the state trajectory of its time-domain check, with what Fig. 15 needs
/// of it.
pub fn fitted_figures(
    run: &crate::analysis::step::Fitted,
    intersample: Intersample,
    every: bool,
) -> (Vec<FigureSpec>, Option<OverlayRun>) {
    let Some(st) = &run.stage else {
        return (Vec::new(), None);
    };
    let time = run.time.as_ref();
    let measured = Measured::of(st);
    let (mut specs, overlay) = log_figures(&run.result, &measured, time, intersample, None, every);
    if let Some(t) = time.filter(|_| every) {
        specs.extend(subspace_figure(
            &run.result,
            &st.log.command_m,
            t,
            st.log.sample_rate_hz,
        ));
    }
    (specs, overlay)
}

/// The figures of a validated run (`analysis::step::Validated`), in page
/// order: its FRF with the model's band, the force path (Figs. 16-17) with
/// the control-structure interaction, its time windows and residual, the
/// compensator's figures and the state trajectory; the FRF and the time
/// windows alone unless `every`.
pub fn validated_figures(
    v: &crate::analysis::step::Validated,
    intersample: Intersample,
    every: bool,
) -> Vec<FigureSpec> {
    let (out, measured) = (&v.result, Measured::of(&v.stage));
    // The prediction's band, from the rig's covariance.
    let prediction = v.rig_cov.zip(v.specimen).map(|(cov, specimen)| Prediction {
        rig: v.rig_at_p,
        cov,
        specimen,
    });
    let (mut specs, _) = log_figures(
        out,
        &measured,
        v.time.as_ref(),
        intersample,
        prediction.as_ref(),
        every,
    );
    if !every {
        return specs;
    }
    if let (Some(bins), Some(model)) = (ForceBins::of(&measured), &out.force_tf) {
        let force = force_figure(out, &bins, model, intersample, v.csi.as_ref());
        specs.insert(1, force);
    }
    if let Some(g) = &v.plant {
        specs.extend(compensator_figures(out, g));
    }
    if let Some(t) = &v.time {
        specs.extend(subspace_figure(
            out,
            &v.stage.log.command_m,
            t,
            v.stage.log.sample_rate_hz,
        ));
    }
    specs
}

/// The campaign's own figures: the identification runs together (Fig. 15,
/// when there are two or more) and the stiffness sensitivity.
pub fn campaign_figures(
    overlay: Vec<OverlayRun>,
    sensitivity: Option<&SensitivityResult>,
) -> Vec<FigureSpec> {
    let mut out = Vec::new();
    if overlay.len() >= 2 {
        out.push(overlay_figure(overlay));
    }
    if let Some(s) = sensitivity {
        out.push(sensitivity_figure(s));
        if let Some(mc) = &s.monte_carlo {
            out.extend(monte_carlo_figures(mc, &s.springs_n_per_m));
        }
    }
    out
}

/// A log's measured command-to-force FRF as Figs. 16-17 show it (5-35 Hz),
/// kept small so that it can wait for the rig while the log is dropped.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct ForceBins {
    sample_rate_hz: f64,
    freq_hz: Vec<f64>,
    #[serde(with = "complex_vec")]
    h: Vec<Complex<f64>>,
    coherence: Vec<f64>,
}

impl ForceBins {
    /// The bins as (frequency Hz, f/u N/m).
    pub fn bins(&self) -> (&[f64], &[Complex<f64>]) {
        (&self.freq_hz, &self.h)
    }

    pub fn of(measured: &Measured<'_>) -> Option<Self> {
        let ff = measured.force_frf?;
        let (freq_hz, h, coherence) = ff.positive_up_to(FORCE_FRF_MAX_HZ);
        Some(Self {
            sample_rate_hz: measured.sample_rate_hz,
            freq_hz,
            h,
            coherence,
        })
    }
}

/// A predicted model as the measurement sees it: plant, delay and the
/// command's hold by its continuous factor. The hold's aliases are left
/// out: at most 1.7e-3 of Exp1's x1/u at 30 Hz sampled at 200 Hz
/// (`tracking::compensator::held_response`), below what a figure shows. A
/// fitted model is drawn as its fit compared it ([`crate::fit::TfFit::as_logged`]).
pub fn model_response(
    tf: &TransferFunction,
    intersample: Intersample,
    fs: f64,
    freq: &[f64],
) -> Vec<Complex<f64>> {
    freq.iter()
        .map(|&f| tf.freq_response(f) * hold_response(intersample, fs, f))
        .collect()
}

fn tf_of(t: &TfResult, delay_s: f64) -> TransferFunction {
    TransferFunction {
        num: t.num.clone(),
        den: t.den.clone(),
        delay_s,
    }
}

/// A validation run's prediction with the rig's uncertainty: the rig and
/// the covariance of (beta1, a1b0, a2, a3) at the run's P gain, and its
/// specimen.
pub struct Prediction {
    pub rig: RigParams,
    pub cov: [[f64; 4]; 4],
    pub specimen: LinearSpecimen,
}

/// A run's command-to-displacement FRF as drawn, with the model beside it:
/// the fitted model for identification runs, the rig's prediction for
/// validation runs.
struct RunFrf {
    f_max: f64,
    freq_hz: Vec<f64>,
    h: Vec<Complex<f64>>,
    coherence: Vec<f64>,
    model: Option<(Vec<Complex<f64>>, &'static str)>,
    /// The fitted model's +-2 std band (identification runs).
    band: Option<BodeBand>,
}

impl RunFrf {
    fn new(
        run: &RunResult,
        measured: &Measured<'_>,
        intersample: Intersample,
        prediction: Option<&Prediction>,
    ) -> Self {
        let fs = measured.sample_rate_hz;
        let f_max = FRF_MAX_HZ.max(run.fit.as_ref().map_or(0.0, |f| f.band_hz[1]));
        let (freq_hz, h, coherence) = measured.frf.positive_up_to(f_max);
        let model = match (measured.fit, run.role) {
            (Some(fit), _) => Some((fit.as_logged(intersample, fs, &freq_hz), "identified model")),
            (None, Role::Validation) => run.tf.as_ref().map(|t| {
                (
                    model_response(&tf_of(t, t.delay_s), intersample, fs, &freq_hz),
                    "model (identified rig)",
                )
            }),
            _ => None,
        };
        // The fitted model's uncertainty, propagated from its covariance;
        // for a prediction, the rig's through Eq. 17.
        let band = match (measured.fit, prediction) {
            (Some(fit), _) => {
                let sd = response_std(fit, &freq_hz);
                Some(BodeBand {
                    magnitude_db: sd.magnitude_db,
                    phase_rad: sd.phase_rad,
                })
            }
            (None, Some(p)) if run.role == Role::Validation => {
                // No band where a perturbed model leaves f64's range (the
                // run's error says why its model is missing).
                x1_u_std(&p.rig, &p.cov, &p.specimen, &freq_hz).map(|(magnitude_db, phase_rad)| {
                    BodeBand {
                        magnitude_db,
                        phase_rad,
                    }
                })
            }
            _ => None,
        };
        Self {
            f_max,
            freq_hz,
            h,
            coherence,
            model,
            band,
        }
    }
}

/// Figs. 8, 11 and 13: one run's measured FRF and its model, magnitude,
/// phase and coherence.
fn frf_figure(run: &RunResult, measured: &Measured<'_>, frf: &RunFrf) -> FigureSpec {
    let mut series = vec![BodeSeries {
        label: "Experimental".into(),
        freq_hz: frf.freq_hz.clone(),
        h: frf.h.clone(),
        coherence: Some(frf.coherence.clone()),
        trace: Trace::Measured,
        palette_index: Some(0),
        band: None,
    }];
    if let Some((hm, label)) = &frf.model {
        series.push(BodeSeries {
            label: match frf.band {
                Some(_) => format!("{label} (+-2 std shaded)"),
                None => label.to_string(),
            },
            freq_hz: frf.freq_hz.clone(),
            h: hm.clone(),
            coherence: None,
            trace: Trace::Model,
            palette_index: Some(1),
            band: frf.band.clone(),
        });
    }
    let bode = BodeFigure {
        title: format!("{}: command to displacement", run.id),
        series,
        freq_range_hz: (0.0, frf.f_max),
        mag_range_db: None,
        phase: true,
        coherence: true,
        log_frequency: false,
        mag_label: "Magnitude (dB)".into(),
    };
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
    let estimator = match measured.frf.method {
        Method::H1 => "H1",
        Method::H2 => "H2",
        Method::Etfe => "ETFE",
        Method::Lpm => "ETFE, LPM transient out",
    };
    FigureSpec {
        id: format!("frf-{}", run.id),
        title: format!("{}: frequency response, command to displacement", run.id),
        caption: format!(
            "Counterpart of the paper's Figs. 8, 11 and 13: measured FRF ({estimator} estimate, {} averages) and the model, magnitude, phase and coherence.{fit_note}",
            measured.frf.n_averages
        ),
        size: bode.recommended_size(),
        figure: Figure::Bode(bode),
    }
}

/// Figs. 16-17: command to force, measured against Eq. 45; the specimen's
/// poles are zeros of the force path.
pub fn force_figure(
    run: &RunResult,
    measured: &ForceBins,
    model: &TfResult,
    intersample: Intersample,
    csi: Option<&Csi>,
) -> FigureSpec {
    let mut fig = force_bode(run, measured, model, intersample);
    let mut notes = String::new();
    if let Some(c) = csi {
        mark_notches(&mut fig, c);
        notes = notch_note(c);
    }
    FigureSpec {
        id: format!("force-{}", run.id),
        title: format!("{}: frequency response, command to force", run.id),
        caption: format!(
            "Counterpart of the paper's Figs. 16-17: the specimen's poles are zeros of the force path (Eq. 45){}.",
            run.natural_frequency_hz
                .map(|f| format!("; its natural frequency is {f:.1} Hz"))
                .unwrap_or_default()
        ) + &notes,
        size: fig.recommended_size(),
        figure: Figure::Bode(fig),
    }
}

/// The measured command-to-force FRF beside Eq. 45's, 5-35 Hz.
fn force_bode(
    run: &RunResult,
    measured: &ForceBins,
    model: &TfResult,
    intersample: Intersample,
) -> BodeFigure {
    let freq = measured.freq_hz.clone();
    let (h, coh) = (measured.h.clone(), measured.coherence.clone());
    let hm = model_response(
        &tf_of(model, 0.0),
        intersample,
        measured.sample_rate_hz,
        &freq,
    );
    BodeFigure {
        title: format!("{}: command to force", run.id),
        series: vec![
            BodeSeries {
                label: "Experimental".into(),
                freq_hz: freq.clone(),
                h,
                coherence: Some(coh),
                trace: Trace::Measured,
                palette_index: Some(0),
                band: None,
            },
            BodeSeries {
                label: "Simulated (Eq. 45)".into(),
                freq_hz: freq,
                h: hm,
                coherence: None,
                trace: Trace::Model,
                palette_index: Some(1),
                band: None,
            },
        ],
        freq_range_hz: (5.0, 35.0),
        mag_range_db: None,
        phase: false,
        coherence: false,
        log_frequency: false,
        mag_label: "Force/command (dB re 1 N/m)".into(),
    }
}

/// The notches of the measured (series 0) and modelled (series 1) curves
/// marked as vertical strokes over the magnitude panel, from 10 dB under
/// the lower notch to 10 dB over the top of both curves in view.
fn mark_notches(fig: &mut BodeFigure, c: &Csi) {
    let level = |h: &[Complex<f64>]| {
        fig.series[0]
            .freq_hz
            .iter()
            .zip(h)
            .filter(|(f, _)| (5.0..=35.0).contains(*f))
            .map(|(_, h)| 20.0 * h.norm().log10())
            .filter(|v| v.is_finite())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                (lo.min(v), hi.max(v))
            })
    };
    let (lo_m, hi_m) = level(&fig.series[0].h);
    let (lo_s, hi_s) = level(&fig.series[1].h);
    let (lo, hi) = (lo_m.min(lo_s) - 10.0, hi_m.max(hi_s) + 10.0);
    for (notch, label, slot) in [
        (c.notch_measured, "measured notch", 0),
        (c.notch_model, "model notch", 1),
    ] {
        if let Some(n) = notch {
            fig.series.push(BodeSeries {
                label: format!(
                    "{label} {:.2} Hz, {:.0} dB deep",
                    n.frequency_hz, n.depth_db
                ),
                freq_hz: vec![n.frequency_hz; 2],
                h: [lo, hi]
                    .iter()
                    .map(|db| Complex::new(10f64.powf(db / 20.0), 0.0))
                    .collect(),
                coherence: None,
                trace: Trace::Reference,
                palette_index: Some(slot),
                band: None,
            });
        }
    }
}

/// The caption's sentence on the notches.
fn notch_note(c: &Csi) -> String {
    format!(
        " The notches of |f/u| are marked (Sec. 3.2.1): measured {} and modelled {}.",
        c.notch_measured
            .map(|n| format!("{:.2} Hz", n.frequency_hz))
            .unwrap_or_else(|| "not found".into()),
        c.notch_model
            .map(|n| format!("{:.2} Hz", n.frequency_hz))
            .unwrap_or_else(|| "not found".into()),
    )
}

/// Figs. 9, 12, 14 and 19-22: the paper's four windows, measured against
/// simulated displacement (and the simplified canonical form beside them
/// when it was stable enough to simulate). None when the sweep reaches no
/// window.
fn time_figure(run: &RunResult, time: &TimeStage, fs: f64) -> Option<FigureSpec> {
    let panels = time_panels(run, time, fs);
    if panels.is_empty() {
        return None;
    }
    let fig = PanelsFigure {
        title: format!("{}: measured and simulated displacement", run.id),
        panels,
        columns: 2,
    };
    let m = &time.metrics;
    // The windows the sweep reaches (a sweep that stops short of 35 Hz has
    // fewer than the paper's four).
    let windows = time
        .windows
        .iter()
        .map(|w| format!("{} ({:.1}-{:.1} s)", w.label, w.start_s, w.end_s))
        .collect::<Vec<_>>()
        .join(", ");
    Some(FigureSpec {
        id: format!("time-{}", run.id),
        title: format!("{}: time-domain comparison", run.id),
        caption: format!(
            "Counterpart of the paper's Figs. 9, 12, 14 and 19-22: {} driven by the measured command, in the windows of the sweep {windows}. Whole record: NRMSE {:.2} %, NAE {:.2} % (Eqs. 47-48).",
            m.model, m.nrmse_pct, m.nae_pct
        ),
        size: fig.recommended_size(),
        figure: Figure::Panels(fig),
    })
}

/// One panel per window, lettered (a)-(d).
///
/// Each panel holds its window's samples only (two beyond each edge, more
/// than the renderer's one for lines entering the panel), not the whole
/// record: four copies of a 14 M-sample record were 460 MB.
fn time_panels(run: &RunResult, time: &TimeStage, fs: f64) -> Vec<TimePanel> {
    let n = time.x1_measured.len().min(time.x1_simulated.len());
    let simplified = time.x1_simplified.as_ref().filter(|x| x.len() >= n);
    let simulated_label = if run.role == Role::Validation {
        "Simulated"
    } else {
        "Identified model"
    };
    let letters = ["(a)", "(b)", "(c)", "(d)"];
    time.windows
        .iter()
        .enumerate()
        .map(|(k, w)| {
            let i0 = first_sample_not(n, fs, &|t| t < w.start_s).saturating_sub(2);
            let i1 = (first_sample_not(n, fs, &|t| t <= w.end_s) + 2)
                .min(n)
                .max(i0);
            let t: Arc<[f64]> = (i0..i1).map(|k| k as f64 / fs).collect::<Vec<_>>().into();
            let cm = |x: &[f64]| -> Arc<[f64]> {
                x[i0..i1]
                    .iter()
                    .map(|v| v * 100.0)
                    .collect::<Vec<_>>()
                    .into()
            };
            let mut series = vec![
                TimeSeries {
                    label: "Experimental".into(),
                    y: cm(&time.x1_measured),
                    trace: Trace::Measured,
                    palette_index: Some(0),
                },
                TimeSeries {
                    label: simulated_label.into(),
                    y: cm(&time.x1_simulated),
                    trace: Trace::Model,
                    palette_index: Some(1),
                },
            ];
            if let Some(y) = simplified {
                series.push(TimeSeries {
                    label: "Simplified CCF (Cn dropped)".into(),
                    y: cm(y),
                    trace: Trace::Model,
                    palette_index: Some(3),
                });
            }
            TimePanel {
                title: format!(
                    "{} {} ({:.0}-{:.0} s)",
                    letters.get(k).copied().unwrap_or(""),
                    w.label,
                    w.start_s,
                    w.end_s
                ),
                t_s: t,
                series,
                t_range_s: (w.start_s, w.end_s),
                y_label: "Disp (cm)".into(),
                y_range: None,
            }
        })
        .collect()
}

/// The first sample k (of n, at k / fs) whose time is not `before` the
/// edge: a partition point over times computed, not stored.
fn first_sample_not(n: usize, fs: f64, before: &dyn Fn(f64) -> bool) -> usize {
    let (mut lo, mut hi) = (0, n);
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        if before(mid as f64 / fs) {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    lo
}

/// Measured minus simulated displacement over the whole record, min/max
/// decimated so no peak is lost.
fn residual_figure(run: &RunResult, time: &TimeStage, fs: f64) -> FigureSpec {
    let n = time.x1_measured.len().min(time.x1_simulated.len());
    // Computed as decimated: a long record's time axis and residual are
    // never held whole.
    let (x, y) = decimate_minmax_by(
        n,
        |k| k as f64 / fs,
        |k| (time.x1_measured[k] - time.x1_simulated[k]) * 1e3,
        1500,
    );
    FigureSpec {
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
    }
}

/// The most points a subspace loop is drawn with: an ellipse reads the
/// same from 2,000 as from the 12,000 two periods at 0.35 Hz hold at 2 kHz.
const SUBSPACE_POINTS: usize = 2000;

/// The synchronized subspace plot (Mercan & Ricles 2007): the displacement
/// against its command over two periods at the middle of each of the
/// paper's windows, measured and (for a validation run) as the identified
/// model predicts it, beside the line of perfect tracking. A loop's width
/// is the phase lag at that frequency, its tilt from the diagonal the
/// amplitude error; traced anticlockwise, the actuator lags. None without
/// windows.
pub fn subspace_figure(
    run: &RunResult,
    command_m: &[f64],
    time: &TimeStage,
    fs: f64,
) -> Option<FigureSpec> {
    let n = command_m
        .len()
        .min(time.x1_measured.len())
        .min(time.x1_simulated.len());
    let mut series = Vec::new();
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for (i, w) in time.windows.iter().enumerate() {
        let mid = 0.5 * (w.start_s + w.end_s);
        let half = (1.0 / w.target_hz).min(0.5 * (w.end_s - w.start_s));
        let a = (((mid - half) * fs).round().max(0.0) as usize).min(n);
        let b = (((mid + half) * fs).round().max(0.0) as usize).min(n);
        if b <= a + 2 {
            continue;
        }
        let step = (b - a).div_ceil(SUBSPACE_POINTS);
        let pick =
            |x: &[f64]| -> Vec<f64> { x[a..b].iter().step_by(step).map(|v| v * 1e3).collect() };
        let x = pick(command_m);
        for v in &x {
            (lo, hi) = (lo.min(*v), hi.max(*v));
        }
        series.push(XySeries {
            label: format!("{}: measured", w.label),
            x: x.clone(),
            y: pick(&time.x1_measured),
            trace: Trace::Measured,
            palette_index: Some(i),
        });
        if run.role == Role::Validation {
            series.push(XySeries {
                label: format!("{}: predicted", w.label),
                x,
                y: pick(&time.x1_simulated),
                trace: Trace::Model,
                palette_index: Some(i),
            });
        }
    }
    if series.is_empty() {
        return None;
    }
    series.push(XySeries {
        label: "perfect tracking".into(),
        x: vec![lo, hi],
        y: vec![lo, hi],
        trace: Trace::Reference,
        palette_index: None,
    });
    Some(FigureSpec {
        id: format!("subspace-{}", run.id),
        title: format!("{}: synchronized subspace plot", run.id),
        caption: "Displacement against its command over two periods in the middle of each window (Mercan & Ricles 2007). A loop traced anticlockwise lags its command; its width is the phase lag at that frequency, its tilt from the diagonal the amplitude error.".into(),
        figure: Figure::Lines(LinesFigure {
            title: format!("{}: displacement against command", run.id),
            x_label: "Command (mm)".into(),
            y_label: "Displacement (mm)".into(),
            series,
            x_range: None,
            y_range: None,
            log_x: false,
            log_y: false,
            zero_line: false,
        }),
        size: (900, 800),
    })
}

/// Points of the compensator's frequency-response figure.
const COMPENSATOR_POINTS: usize = 300;

/// A validation run's compensator: the predicted FRF of the
/// held plant `plant` (x1/u with the run's specimen) with and without it,
/// from the band's bottom to past the low-pass's cut-off; and how the
/// compensated tracking degrades when the specimen's stiffness differs
/// from the one it was designed for. None without a design.
pub fn compensator_figures(run: &RunResult, plant: &TransferFunction) -> Vec<FigureSpec> {
    let tracking = run.tracking.as_ref().map(|t| t.get());
    let Some(outcome) = tracking.as_ref().and_then(|t| t.compensator.as_ref()) else {
        return Vec::new();
    };
    let Some(c) = &outcome.design else {
        return Vec::new();
    };
    let mut figures = vec![compensator_bode_figure(run, outcome, c, plant)];
    figures.extend(compensator_stiffness_figure(run, &outcome.stiffness));
    figures
}

/// The held plant's predicted FRF without and with the compensator `c`,
/// beside perfect tracking.
fn compensator_bode_figure(
    run: &RunResult,
    outcome: &CompensatorOutcome,
    c: &Compensator,
    plant: &TransferFunction,
) -> FigureSpec {
    let fs = c.sample_rate_hz;
    let lo = outcome.band_hz[0];
    let hi = (2.0 * c.cutoff_hz).min(0.45 * fs);
    let freq_hz: Vec<f64> = (0..COMPENSATOR_POINTS)
        .map(|i| lo * (hi / lo).powf(i as f64 / (COMPENSATOR_POINTS - 1) as f64))
        .collect();
    let held: Vec<Complex<f64>> = freq_hz
        .iter()
        .map(|&f| compensator::held_response(plant, f, fs))
        .collect();
    let series = |label: &str, h: Vec<Complex<f64>>, trace, slot| BodeSeries {
        label: label.into(),
        freq_hz: freq_hz.clone(),
        h,
        coherence: None,
        trace,
        palette_index: slot,
        band: None,
    };
    let bode = BodeFigure {
        title: format!("{}: predicted tracking, command to displacement", run.id),
        series: vec![
            series("without compensator", held.clone(), Trace::Model, Some(1)),
            series(
                "with compensator",
                held.iter()
                    .zip(&freq_hz)
                    .map(|(h, &f)| h * c.response(f))
                    .collect(),
                Trace::Model,
                Some(2),
            ),
            series(
                "perfect tracking",
                vec![Complex::new(1.0, 0.0); freq_hz.len()],
                Trace::Reference,
                None,
            ),
        ],
        freq_range_hz: (lo, hi),
        mag_range_db: None,
        phase: true,
        coherence: false,
        log_frequency: true,
        mag_label: String::new(),
    };
    FigureSpec {
        id: format!("compensator-{}", run.id),
        title: format!("{}: model-based compensator", run.id),
        caption: format!(
            "The identified plant with this specimen, driven through the hold at {fs} Hz, without and with the compensator (its inverse times a Butterworth low-pass of order {} at {:.0} Hz, with a lead of {:.3} ms): predicted from the model, not measured. The band is {}-{} Hz.",
            c.order,
            c.cutoff_hz,
            1e3 * c.lead_s,
            outcome.band_hz[0],
            outcome.band_hz[1]
        ),
        size: bode.recommended_size(),
        figure: Figure::Bode(bode),
    }
}

/// The compensated tracking's worst amplitude error and delay against the
/// specimen's stiffness, the run's own marked; None with fewer than two
/// stiffnesses.
fn compensator_stiffness_figure(run: &RunResult, points: &[StiffnessPoint]) -> Option<FigureSpec> {
    if points.len() < 2 {
        return None;
    }
    let k: Vec<f64> = points.iter().map(|p| p.stiffness_n_per_m).collect();
    let mut lines = vec![
        XySeries {
            label: "worst amplitude error over the band (%)".into(),
            x: k.clone(),
            y: points
                .iter()
                .map(|p| p.compensated.max_amplitude_error_pct)
                .collect(),
            trace: Trace::Model,
            palette_index: Some(1),
        },
        XySeries {
            label: "worst delay or lead over the band (samples)".into(),
            x: k.clone(),
            y: points
                .iter()
                .map(|p| p.compensated.max_abs_delay_samples())
                .collect(),
            trace: Trace::Model,
            palette_index: Some(2),
        },
        XySeries {
            label: "target (1 % and 1 sample)".into(),
            x: vec![k[0], k[k.len() - 1]],
            y: vec![1.0, 1.0],
            trace: Trace::Reference,
            palette_index: None,
        },
    ];
    let own = run.specimen.linear_mck().map_or(0.0, |(_, _, k)| k);
    if own > 0.0 {
        mark_springs(&mut lines, &[own]);
        if let Some(l) = lines.last_mut() {
            l.label = "designed for".into();
        }
    }
    Some(FigureSpec {
        id: format!("compensator-stiffness-{}", run.id),
        title: format!("{}: the compensator on other specimens", run.id),
        caption: "The compensator designed for this specimen, on the identified plant with the specimen's stiffness changed over the sensitivity analysis's range (mass and damping kept): the worst amplitude error and delay over the band, predicted from the model.".into(),
        figure: Figure::Lines(LinesFigure {
            title: format!("{}: compensated tracking against specimen stiffness", run.id),
            x_label: "Specimen stiffness k (N/m)".into(),
            y_label: "Error (% or samples)".into(),
            series: lines,
            x_range: None,
            y_range: None,
            log_x: true,
            log_y: true,
            zero_line: false,
        }),
        size: (1200, 600),
    })
}

/// An identification run's FRF kept for Fig. 15.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct OverlayRun {
    id: String,
    freq_hz: Vec<f64>,
    #[serde(with = "complex_vec")]
    measured: Vec<Complex<f64>>,
    #[serde(with = "complex_vec")]
    model: Vec<Complex<f64>>,
}

/// Fig. 15: every identification run together, 0-15 Hz.
fn overlay_figure(runs: Vec<OverlayRun>) -> FigureSpec {
    let mut series = Vec::with_capacity(2 * runs.len());
    for (k, r) in runs.into_iter().enumerate() {
        series.push(BodeSeries {
            label: format!("{} (experimental)", r.id),
            freq_hz: r.freq_hz.clone(),
            h: r.measured,
            coherence: None,
            trace: Trace::Measured,
            palette_index: Some(k),
            band: None,
        });
        series.push(BodeSeries {
            label: format!("{} (identified)", r.id),
            freq_hz: r.freq_hz,
            h: r.model,
            coherence: None,
            trace: Trace::Model,
            palette_index: Some(k),
            band: None,
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
    FigureSpec {
        // Not `frf-identification`: run figures are `frf-<run>`, and a run
        // named `identification` overwrote it. Campaign figures
        // start as a run's do (`frf-`, `force-`, `time-`, `residual-`).
        id: "identification-frf".into(),
        title: "All identification runs".into(),
        caption: "Counterpart of the paper's Fig. 15: the rig with no specimen and with each spring, measured (solid) and identified (dashed).".into(),
        size: fig.recommended_size(),
        figure: Figure::Bode(fig),
    }
}

/// The campaign's springs as dotted verticals over the finite span of
/// `series`, labelled once.
fn mark_springs(series: &mut Vec<XySeries>, springs: &[f64]) {
    let (lo, hi) = series
        .iter()
        .flat_map(|s| &s.y)
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(*v), b.max(*v))
        });
    for (j, ks) in springs.iter().enumerate() {
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
}

/// The stiffness sensitivity (paper Sec. 2.3), with the campaign's springs
/// marked.
fn sensitivity_figure(s: &SensitivityResult) -> FigureSpec {
    let k = &s.analytic.sweep.stiffness_n_per_m;
    let pct = |v: &[f64]| v.iter().map(|x| 100.0 * x).collect::<Vec<_>>();
    let mut series: Vec<XySeries> = [
        ("a1b0", &s.analytic.sweep.rel_std_a1b0),
        ("a2", &s.analytic.sweep.rel_std_a2),
        ("a3", &s.analytic.sweep.rel_std_a3),
    ]
    .into_iter()
    .enumerate()
    .map(|(i, (label, v))| XySeries {
        label: label.into(),
        x: k.clone(),
        y: pct(v),
        trace: Trace::Model,
        palette_index: Some(i),
    })
    .collect();
    mark_springs(&mut series, &s.springs_n_per_m);
    FigureSpec {
        id: "sensitivity".into(),
        title: "Sensitivity to the spring stiffness".into(),
        caption: format!(
            "Relative standard deviation of the identified a1b0, a2 and a3 from one no-specimen run and one spring of stiffness k ({}).",
            s.analytic.basis
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
    }
}

/// The rig's history: each parameter over the campaigns (a1b0 referred to
/// P = 1), with its +-2 std band; the last point is this campaign. None with
/// fewer than two entries.
pub fn history_figure(entries: &[crate::drift::Entry]) -> Option<FigureSpec> {
    if entries.len() < 2 {
        return None;
    }
    let x: Arc<[f64]> = (1..=entries.len()).map(|k| k as f64).collect();
    let n = entries.len() as f64;
    let mut units = vec![
        ("beta1", "beta1 (1/s)", 1.0),
        ("a1b0", "a1b0 at P = 1 (N/(m s^2))", 1.0),
        ("a2", "a2 (N/m)", 1.0),
        ("a3", "a3 (1/s)", 1.0),
    ];
    // The night's delay, where the entries measured one (none before
    // servoid did: those entries leave a gap).
    if entries.iter().any(|e| e.delay_s.is_some()) {
        units.push(("delay", "actuator delay (ms)", 1e3));
    }
    let panels = units
        .iter()
        .map(|&(name, label, scale)| {
            let p: Vec<(f64, f64)> = entries
                .iter()
                .map(|e| match e.parameter(name) {
                    Some((v, s)) => (v * scale, s.unwrap_or(0.0) * scale),
                    None => (f64::NAN, 0.0),
                })
                .collect();
            let line = |f: &dyn Fn(&(f64, f64)) -> f64| -> Arc<[f64]> { p.iter().map(f).collect() };
            let series = |label: &str, y: Arc<[f64]>, trace| TimeSeries {
                label: label.into(),
                y,
                trace,
                palette_index: Some(0),
            };
            TimePanel {
                title: name.to_string(),
                t_s: x.clone(),
                series: vec![
                    series("value", line(&|q| q.0), Trace::Measured),
                    series("+2 std", line(&|q| q.0 + 2.0 * q.1), Trace::Reference),
                    series("-2 std", line(&|q| q.0 - 2.0 * q.1), Trace::Reference),
                ],
                t_range_s: (0.5, n + 0.5),
                y_label: label.into(),
                y_range: None,
            }
        })
        .collect();
    let fig = PanelsFigure {
        title: format!("Rig history: {}", entries[0].rig),
        panels,
        columns: 2,
    };
    Some(FigureSpec {
        id: "history".into(),
        title: "The rig's history".into(),
        caption: format!(
            "Each identified parameter over the rig's last {} campaigns (entry number; the last is this campaign), with its +-2 std band, and the night's actuator delay where it was measured. An alarm is raised when a value moves from the median of its recent entries by more than the manifest's threshold times the larger of its std and the history's scatter (for the delay, at least 0.25 ms).",
            entries.len()
        ),
        size: fig.recommended_size(),
        figure: Figure::Panels(fig),
    })
}

/// The Monte Carlo: each parameter's spread against k, solid,
/// beside the analytic prediction at the same stiffnesses, dashed, in the
/// same colour; and each parameter's bias against k.
fn monte_carlo_figures(mc: &MonteCarlo, springs: &[f64]) -> Vec<FigureSpec> {
    let pts: Vec<&MonteCarloPoint> = mc.points.iter().filter(|p| p.rel_std.is_some()).collect();
    let k: Vec<f64> = pts.iter().map(|p| p.stiffness_n_per_m).collect();
    let column = |get: &dyn Fn(&MonteCarloPoint) -> Option<[f64; 4]>, j: usize| -> Vec<f64> {
        pts.iter()
            .map(|p| get(p).map_or(f64::NAN, |v| 100.0 * v[j]))
            .collect()
    };
    let mut spread = Vec::new();
    let mut bias = Vec::new();
    for (j, name) in PerParameter::NAMES.iter().enumerate() {
        spread.push(XySeries {
            label: format!("{name}, Monte Carlo"),
            x: k.clone(),
            y: column(&|p| p.rel_std.map(PerParameter::to_array), j),
            trace: Trace::Measured,
            palette_index: Some(j),
        });
        spread.push(XySeries {
            label: format!("{name}, analytic"),
            x: k.clone(),
            y: column(&|p| p.analytic_rel_std.map(PerParameter::to_array), j),
            trace: Trace::Model,
            palette_index: Some(j),
        });
        bias.push(XySeries {
            label: (*name).into(),
            x: k.clone(),
            y: column(&|p| p.rel_bias.map(PerParameter::to_array), j),
            trace: Trace::Measured,
            palette_index: Some(j),
        });
    }
    // The mean's own sampling error, so a bias can be told from noise:
    // +-2 std / sqrt(n) of a2 (a1b0 and a3 are alike).
    for (sign, label) in [(1.0, "a2 +-2 standard errors"), (-1.0, "")] {
        bias.push(XySeries {
            label: label.into(),
            x: k.clone(),
            y: pts
                .iter()
                .map(|p| {
                    p.rel_std.map_or(f64::NAN, |s| {
                        sign * 200.0 * s.a2 / (p.identified as f64).sqrt()
                    })
                })
                .collect(),
            trace: Trace::Reference,
            palette_index: None,
        });
    }
    mark_springs(&mut spread, springs);
    mark_springs(&mut bias, springs);
    vec![
        FigureSpec {
            id: "sensitivity-monte-carlo".into(),
            title: "Monte Carlo against the analytic prediction".into(),
            caption: format!(
                "Relative std of beta1, a1b0, a2 and a3 over {} simulated identifications per stiffness (solid) and the first-order prediction (dashed). {}",
                mc.seeds, mc.agreement.summary
            ),
            figure: Figure::Lines(LinesFigure {
                title: "Spread of the identified parameters against spring stiffness".into(),
                x_label: "Spring stiffness k (N/m)".into(),
                y_label: "Relative std (%)".into(),
                series: spread,
                x_range: None,
                y_range: None,
                log_x: true,
                log_y: true,
                zero_line: false,
            }),
            size: (1200, 600),
        },
        FigureSpec {
            id: "sensitivity-bias".into(),
            title: "Monte Carlo bias".into(),
            caption: format!(
                "Mean of {} simulated identifications per stiffness over the true value, minus 1, with the mean's own sampling error (dotted).",
                mc.seeds
            ),
            figure: Figure::Lines(LinesFigure {
                title: "Bias of the identified parameters against spring stiffness".into(),
                x_label: "Spring stiffness k (N/m)".into(),
                y_label: "Relative bias (%)".into(),
                series: bias,
                x_range: None,
                y_range: None,
                log_x: true,
                log_y: false,
                zero_line: true,
            }),
            size: (1200, 600),
        },
    ]
}

/// `servoid design`'s figure: each designed run's displacement at the
/// night's excited lines, against the noise it has to clear over the
/// periods read (`design::night::LineLevels`).
pub fn design_figure(d: &crate::results::DesignResult) -> FigureSpec {
    let lines = &d.lines;
    let mm = |v: &[f64]| -> Vec<f64> { v.iter().map(|v| 1e3 * v).collect() };
    let mut series: Vec<XySeries> = d
        .runs
        .iter()
        .zip(&lines.displacement_m)
        .enumerate()
        .map(|(i, (run, x))| XySeries {
            label: run.id.clone(),
            x: lines.freq_hz.clone(),
            y: mm(x),
            trace: Trace::Model,
            palette_index: Some(i),
        })
        .collect();
    series.push(XySeries {
        label: "noise over the periods read".into(),
        x: lines.freq_hz.clone(),
        y: mm(&lines.noise_m),
        trace: Trace::Reference,
        palette_index: None,
    });
    FigureSpec {
        id: "lines".into(),
        title: "The night's lines".into(),
        caption: format!(
            "Each identification run's displacement at the {} lines its command excites, as the plant at {} predicts it (the command's amplitude at the line through |x1/u|, Eq. 17), against the displacement noise's amplitude at a line over the {} periods read ({}): the ratio is the line's signal-to-noise ratio.",
            lines.freq_hz.len(),
            d.rig_from,
            d.periods.saturating_sub(crate::design::night::UNREAD),
            d.noise_from
        ),
        figure: Figure::Lines(LinesFigure {
            title: format!("{}: displacement at the excited lines", d.campaign),
            x_label: "Frequency (Hz)".into(),
            y_label: "Amplitude (mm)".into(),
            series,
            x_range: None,
            y_range: None,
            log_x: true,
            log_y: true,
            zero_line: false,
        }),
        size: (1200, 600),
    }
}
