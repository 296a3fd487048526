//! Time-domain validation measures: the paper's normalised errors (Eqs. 47-48),
//! fit percent, and the four windows of the chirp the paper shows (Figs. 9,
//! 12, 14, 19-22), located from the command's own instantaneous frequency so
//! that they work on real logs whose sweep law is not known.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Measured (E) against simulated (N) errors of one signal, in percent.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Errors {
    /// NRMSE = sqrt(sum (xE - xN)^2 / (n - 1)) / max|xE| * 100 (Eq. 47).
    pub nrmse_pct: f64,
    /// NAE = max|xE - xN| / max|xE| * 100 (Eq. 48).
    pub nae_pct: f64,
    /// 100 (1 - ||xE - xN|| / ||xE - mean(xE)||).
    pub fit_pct: f64,
    pub n_samples: usize,
}

/// Eqs. 47-48 and fit percent over two equally long records.
///
/// Returns None for fewer than two samples or a measured record that is
/// identically zero (the normalisation is undefined).
pub fn errors(measured: &[f64], simulated: &[f64]) -> Option<Errors> {
    let n = measured.len().min(simulated.len());
    if n < 2 {
        return None;
    }
    let (xe, xn) = (&measured[..n], &simulated[..n]);
    let peak = xe.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    if peak == 0.0 || !peak.is_finite() {
        return None;
    }
    let mean = xe.iter().sum::<f64>() / n as f64;
    let (mut sse, mut max_abs, mut sst) = (0.0, 0.0_f64, 0.0);
    for (e, s) in xe.iter().zip(xn) {
        let d = e - s;
        sse += d * d;
        max_abs = max_abs.max(d.abs());
        sst += (e - mean) * (e - mean);
    }
    Some(Errors {
        nrmse_pct: (sse / (n - 1) as f64).sqrt() / peak * 100.0,
        nae_pct: max_abs / peak * 100.0,
        fit_pct: if sst > 0.0 {
            100.0 * (1.0 - (sse / sst).sqrt())
        } else {
            f64::NAN
        },
        n_samples: n,
    })
}

/// A window of the record the paper plots.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Window {
    pub label: String,
    /// The command's instantaneous frequency the window is centred on (Hz).
    pub target_hz: f64,
    pub start_s: f64,
    pub end_s: f64,
}

/// The paper's four windows as (label, target frequency in Hz, length in s):
/// below 0.5 Hz around 10-20 s, about 2.5 Hz around 40-50 s, about 18 Hz
/// around 120-122 s and about 35 Hz at 170-171 s, for its 0.1-35 Hz
/// quadratic chirp over ~170 s. 0.35 Hz is where that chirp is at 15 s.
pub const PAPER_WINDOWS: [(&str, f64, f64); 4] = [
    ("below 0.5 Hz", 0.35, 10.0),
    ("about 2.5 Hz", 2.5, 10.0),
    ("about 18 Hz", 18.0, 2.0),
    ("about 35 Hz", 35.0, 1.0),
];

/// Hysteresis of the zero-crossing detector, as a fraction of the sweep's
/// amplitude: far above DAQ noise (on the UTFSM command its peaks reach
/// about 2 % of the amplitude) and crossed twice every period by a sweep of
/// roughly constant amplitude.
const CROSSING_HYSTERESIS: f64 = 0.1;

/// Instantaneous frequency of a sweep from its upward zero crossings: the
/// crossing times (linear interpolation between samples), and the frequency
/// 1/dt between consecutive upward crossings placed at their midpoint.
///
/// Whole periods, not half periods: with any offset left in the signal the
/// rising and falling half-cycles differ in length, but a full period does
/// not. The sweep is the part of the record that strays from the record's
/// median (its rest level, which a real command need not hold at zero) by
/// more than `CROSSING_HYSTERESIS` (a tenth) of the largest excursion; the median of
/// that part is removed (robust to the slow start of a chirp, where a mean
/// is not). An upward crossing counts only once the signal has been below
/// -h and reaches +h (a Schmitt trigger, h the hysteresis), so noise on a
/// slow crossing or at rest adds none; it is placed where the signal last
/// crossed zero on the way up. Returns (time_s, frequency_hz) pairs.
pub fn instantaneous_frequency(u: &[f64], sample_rate_hz: f64) -> Vec<(f64, f64)> {
    if u.len() < 3 {
        return Vec::new();
    }
    let level = median(u);
    let peak = u.iter().fold(0.0_f64, |m, v| m.max((v - level).abs()));
    if !(peak > 0.0 && peak.is_finite()) {
        return Vec::new();
    }
    let h = CROSSING_HYSTERESIS * peak;
    let excited = |i: &usize| (u[*i] - level).abs() > h;
    let (Some(first), Some(last)) = ((0..u.len()).find(excited), (0..u.len()).rfind(excited))
    else {
        return Vec::new();
    };
    let centre = median(&u[first..=last]);
    let dt = 1.0 / sample_rate_hz;
    let mut crossings = Vec::new();
    let (mut armed, mut last_negative) = (false, None);
    for k in first..=last {
        let d = u[k] - centre;
        if d < 0.0 {
            last_negative = Some(k);
        }
        if d < -h {
            armed = true;
        } else if armed
            && d >= h
            && let Some(j) = last_negative
        {
            // u[j] < centre <= u[j + 1], and j < k.
            let (a, b) = (u[j] - centre, u[j + 1] - centre);
            crossings.push((j as f64 + a / (a - b)) * dt);
            armed = false;
        }
    }
    crossings
        .windows(2)
        .map(|w| (0.5 * (w[0] + w[1]), 1.0 / (w[1] - w[0])))
        .collect()
}

/// The median (upper middle element for an even count), by selection: the
/// element a full sort would put there, in linear time (a sort of each
/// 120 000-sample command was a fifth of a validation run).
fn median(x: &[f64]) -> f64 {
    let mut v = x.to_vec();
    let mid = v.len() / 2;
    *v.select_nth_unstable_by(mid, f64::total_cmp).1
}

/// Locate the paper's windows in a record from its command: each window is
/// centred where the (running-median smoothed) instantaneous frequency first
/// reaches its target, except the last target at the top of the sweep, whose
/// window ends where the sweep ends. Targets the sweep never reaches are
/// left out.
pub fn locate_windows(u: &[f64], sample_rate_hz: f64) -> Vec<Window> {
    let inst = instantaneous_frequency(u, sample_rate_hz);
    if inst.len() < 5 {
        return Vec::new();
    }
    // A running median over 3 periods rejects a single spurious crossing;
    // the end points are kept as they are (the slow start of a chirp has
    // only a few periods to spare).
    let smooth: Vec<(f64, f64)> = (0..inst.len())
        .map(|i| {
            if i == 0 || i + 1 == inst.len() {
                inst[i]
            } else {
                let mut f = [inst[i - 1].1, inst[i].1, inst[i + 1].1];
                f.sort_by(f64::total_cmp);
                (inst[i].0, f[1])
            }
        })
        .collect();
    let f_max = smooth.iter().fold(0.0_f64, |m, p| m.max(p.1));
    let t_end_sweep = smooth.last().map(|p| p.0).unwrap_or(0.0);
    let duration = u.len() as f64 / sample_rate_hz;
    let mut out = Vec::new();
    for (label, target, length) in PAPER_WINDOWS {
        // Within 3 % of the top of the sweep counts as "at the top".
        let (start, end) = if target >= 0.97 * f_max && target <= 1.03 * f_max {
            (t_end_sweep - length, t_end_sweep)
        } else if let Some(i) = smooth.iter().position(|p| p.1 >= target) {
            // Interpolate between the estimates around the target: at the
            // slow start they are seconds apart.
            let t = if i == 0 {
                smooth[0].0
            } else {
                let (a, b) = (smooth[i - 1], smooth[i]);
                a.0 + (target - a.1) / (b.1 - a.1) * (b.0 - a.0)
            };
            (t - 0.5 * length, t + 0.5 * length)
        } else {
            continue;
        };
        let start = start.max(0.0);
        let end = end.min(duration);
        if end > start {
            out.push(Window {
                label: label.to_string(),
                target_hz: target,
                start_s: start,
                end_s: end,
            });
        }
    }
    out
}

/// Sample index range [start, end) of a window.
pub fn window_range(w: &Window, sample_rate_hz: f64, n: usize) -> std::ops::Range<usize> {
    let a = ((w.start_s * sample_rate_hz).round().max(0.0) as usize).min(n);
    let b = ((w.end_s * sample_rate_hz).round().max(0.0) as usize).min(n);
    a..b.max(a)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn errors_by_hand() {
        // xE = [1, -2, 4, 0], xN = [1, -1, 3, 1]: d = [0, -1, 1, -1],
        // sse = 3, max|xE| = 4, NRMSE = sqrt(3/3)/4 = 25 %, NAE = 1/4 = 25 %.
        // mean(xE) = 0.75, sst = 0.0625 + 7.5625 + 10.5625 + 0.5625 = 18.75,
        // fit = 100 (1 - sqrt(3/18.75)) = 60 %.
        let e = errors(&[1.0, -2.0, 4.0, 0.0], &[1.0, -1.0, 3.0, 1.0]).unwrap();
        assert_relative_eq!(e.nrmse_pct, 25.0, max_relative = 1e-14);
        assert_relative_eq!(e.nae_pct, 25.0, max_relative = 1e-14);
        assert_relative_eq!(e.fit_pct, 60.0, max_relative = 1e-12);
        assert!(errors(&[0.0, 0.0], &[1.0, 1.0]).is_none());
        assert!(errors(&[1.0], &[1.0]).is_none());
    }

    /// The paper's command: a quadratic chirp 0.1 -> 35 Hz over 170 s
    /// (MATLAB's chirp(t, f0, t1, f1, 'quadratic')), with a lead-in.
    fn paper_chirp(fs: f64, lead_in_s: f64) -> Vec<f64> {
        let (f0, f1, t1) = (0.1, 35.0, 170.0);
        let n = ((t1 + lead_in_s + 1.0) * fs) as usize;
        (0..n)
            .map(|k| {
                let t = k as f64 / fs - lead_in_s;
                if (0.0..=t1).contains(&t) {
                    let phase = 2.0
                        * std::f64::consts::PI
                        * (f0 * t + (f1 - f0) * t.powi(3) / (3.0 * t1 * t1));
                    3e-3 * phase.sin()
                } else {
                    0.0
                }
            })
            .collect()
    }

    #[test]
    fn instantaneous_frequency_follows_the_quadratic_law() {
        let fs = 1024.0;
        // An offset of a third of the amplitude must not bias the estimate.
        let u: Vec<f64> = paper_chirp(fs, 0.0).iter().map(|v| v + 1e-3).collect();
        let inst = instantaneous_frequency(&u, fs);
        // f(t) = 0.1 + 34.9 (t/170)^2. A period-long average of a sweeping
        // frequency is biased by about f'' T^2 / 24 relative (under 1 % here
        // for t > 10 s, where the period is ~4 s), negligible above 1 Hz.
        assert!(inst.len() > 1000);
        for &(t, f) in inst.iter().filter(|p| p.0 > 10.0) {
            let want = 0.1 + 34.9 * (t / 170.0).powi(2);
            let tol = if want < 1.0 { 1e-2 } else { 1e-3 };
            assert!((f - want).abs() < tol * want, "t = {t}: {f} vs {want}");
        }
    }

    #[test]
    fn windows_land_where_the_paper_plots_them() {
        // Paper: 10-20 s, 40-50 s, 120-122 s, 170-171 s (their record had
        // about a second of lead-in). From the law: f = 0.35 Hz at 14.4 s,
        // 2.5 Hz at 44.6 s, 18 Hz at 121.7 s, 35 Hz at 170 s.
        let fs = 1024.0;
        let lead = 1.0;
        let u = paper_chirp(fs, lead);
        let w = locate_windows(&u, fs);
        assert_eq!(w.len(), 4);
        let centre = |i: usize| 0.5 * (w[i].start_s + w[i].end_s) - lead;
        let law_t = |f: f64| 170.0 * ((f - 0.1) / 34.9).sqrt();
        assert!((centre(0) - law_t(0.35)).abs() < 0.5, "{:?}", w[0]);
        assert!((centre(1) - law_t(2.5)).abs() < 0.3, "{:?}", w[1]);
        assert!((centre(2) - law_t(18.0)).abs() < 0.1, "{:?}", w[2]);
        assert!((w[3].end_s - lead - 170.0).abs() < 0.05, "{:?}", w[3]);
        assert_relative_eq!(w[3].end_s - w[3].start_s, 1.0, epsilon = 1e-12);
    }

    #[test]
    fn a_sweep_that_stops_short_has_fewer_windows() {
        // 0.1 -> 20 Hz: the 35 Hz window does not exist.
        let fs = 1000.0;
        let (f0, f1, t1) = (0.1, 20.0, 60.0);
        let u: Vec<f64> = (0..(t1 * fs) as usize)
            .map(|k| {
                let t = k as f64 / fs;
                (2.0 * std::f64::consts::PI * (f0 * t + (f1 - f0) * t * t / (2.0 * t1))).sin()
            })
            .collect();
        let w = locate_windows(&u, fs);
        let labels: Vec<&str> = w.iter().map(|x| x.label.as_str()).collect();
        assert_eq!(labels, ["below 0.5 Hz", "about 2.5 Hz", "about 18 Hz"]);
    }

    /// Regression (the UTFSM MTS logs): a recorded command rests at a
    /// non-zero level (-0.21 mm against a 2 mm sweep) with DAQ noise (0.015
    /// mm rms) for seconds before and after the sweep. Every sample then
    /// cleared the old 1e-3 x peak floor, the noise at rest crossed the
    /// median hundreds of times a second, and every window landed at 0 s.
    #[test]
    fn windows_of_a_noisy_offset_command_with_rest_land_on_the_sweep() {
        let fs = 1000.0;
        let (f0, f1, t1, lead, tail) = (0.1, 20.0, 50.0, 7.0, 4.0);
        let (offset, amplitude, noise_rms) = (-0.21, 2.0, 0.015);
        let n = ((lead + t1 + tail) * fs) as usize;
        // Uniform noise in (-1, 1) has rms 1/sqrt(3).
        let mut state = 2022_u64;
        let mut noise = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            ((state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0) * noise_rms * 3f64.sqrt()
        };
        let u: Vec<f64> = (0..n)
            .map(|k| {
                let t = k as f64 / fs - lead;
                let sweep = if (0.0..=t1).contains(&t) {
                    let phase =
                        2.0 * std::f64::consts::PI * (f0 * t + (f1 - f0) * t * t / (2.0 * t1));
                    amplitude * phase.sin()
                } else {
                    0.0
                };
                offset + sweep + noise()
            })
            .collect();
        let inst = instantaneous_frequency(&u, fs);
        assert!(
            inst.iter().all(|p| p.0 > lead - 1.0 && p.1 < 1.05 * f1),
            "crossings outside the sweep or above its top: {:?}",
            inst.iter().find(|p| p.0 <= lead - 1.0 || p.1 >= 1.05 * f1)
        );
        let w = locate_windows(&u, fs);
        let labels: Vec<&str> = w.iter().map(|x| x.label.as_str()).collect();
        assert_eq!(labels, ["below 0.5 Hz", "about 2.5 Hz", "about 18 Hz"]);
        // This sweep passes 0.35 Hz inside its first period, so the first
        // window sits on the first whole-period estimate: its centre is
        // within the sweep's first 3 s (phase 4 pi at 3.0 s).
        let centre0 = 0.5 * (w[0].start_s + w[0].end_s) - lead;
        assert!((0.0..3.0).contains(&centre0), "{:?}", w[0]);
        // Linear law: f = f0 + (f1 - f0) t / t1.
        let law_t = |f: f64| lead + (f - f0) / (f1 - f0) * t1;
        for (win, target, tol) in [(&w[1], 2.5, 0.3), (&w[2], 18.0, 0.1)] {
            let centre = 0.5 * (win.start_s + win.end_s);
            assert!(
                (centre - law_t(target)).abs() < tol,
                "{}: centre {centre} s, law {} s",
                win.label,
                law_t(target)
            );
        }
    }
}
