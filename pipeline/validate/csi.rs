//! Control-structure interaction (paper Sec. 3.2.1, Eqs. 40-45): the
//! specimen's poles are zeros of the actuator's force path f/u = (m s^2 +
//! c s + k) x1/u (Eq. 45), so the actuator cannot push on the specimen at
//! its natural frequency: |f/u| has a notch there. Per validation specimen:
//! its natural frequency and damping ratio, the zero pair, the notch as the
//! log's force FRF shows it beside the model's, and what the actuator's
//! displacement path x1/u does at that frequency.
//!
//! Pure: a measured force FRF and the model in, a [`Csi`] out.

use nalgebra::Complex;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::model::{LinearSpecimen, RigParams, tf_f_u, tf_x1_u};

/// The search for a notch spans the natural frequency divided and
/// multiplied by this.
const SEARCH_FACTOR: f64 = 1.5;
/// Points of the model's magnitude over the search span.
const MODEL_POINTS: usize = 4001;
/// The measured magnitude (dB) is smoothed by a running median over this
/// many bins before its minimum is taken: one bin of an ETFE is as noisy as
/// the record is long.
const SMOOTH_BINS: usize = 9;
/// The bins within this many dB of the notch's bottom refine its frequency.
const VERTEX_DB: f64 = 1.0;

/// One validation specimen's interaction with the actuator.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Csi {
    pub run: String,
    /// sqrt(k/m) / 2 pi.
    pub natural_frequency_hz: f64,
    /// c / (2 sqrt(k m)).
    pub damping_ratio: f64,
    /// The force path's zero pair, the specimen's poles: roots of
    /// m s^2 + c s + k, as [re, im] in rad/s.
    pub zeros_rad_per_s: Vec<[f64; 2]>,
    /// The notch of |f/u| in the log's force FRF; null without a force
    /// channel or without a minimum inside the search span.
    pub notch_measured: Option<Notch>,
    /// The notch of |f/u| of the model (Eq. 45, without the command's hold).
    pub notch_model: Option<Notch>,
    /// The model's x1/u (Eq. 17) at the natural frequency.
    pub x1_u_at_natural_frequency: Response,
}

/// Where |f/u| is least near the natural frequency, and how deep it is:
/// the lower of the highest levels on either side within the search span,
/// minus the least.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Notch {
    pub frequency_hz: f64,
    pub depth_db: f64,
    /// |f/u| at the notch (dB re 1 N/m).
    pub magnitude_db: f64,
}

/// A frequency response value.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Response {
    pub magnitude_db: f64,
    pub phase_deg: f64,
}

/// The analysis for an SDOF specimen with mass and stiffness (None for any
/// other, or for one whose model leaves f64's range: the run's error says
/// so): `measured` is the log's force FRF as (frequency Hz, f/u in N/m)
/// bins, when it has a force channel.
pub fn csi(
    run: &str,
    rig: &RigParams,
    specimen: &LinearSpecimen,
    measured: Option<(&[f64], &[Complex<f64>])>,
) -> Option<Csi> {
    let LinearSpecimen::Sdof {
        mass_kg: m,
        damping_ns_per_m: c,
        stiffness_n_per_m: k,
    } = *specimen
    else {
        return None;
    };
    if !(m > 0.0 && k > 0.0) {
        return None;
    }
    let wn = (k / m).sqrt();
    let fn_hz = wn / (2.0 * std::f64::consts::PI);
    let zeta = c / (2.0 * (k * m).sqrt());
    // Roots of m s^2 + c s + k.
    let disc = Complex::new(c * c - 4.0 * m * k, 0.0).sqrt();
    let zeros = [(-c - disc) / (2.0 * m), (-c + disc) / (2.0 * m)];
    let mut zeros_rad_per_s: Vec<[f64; 2]> = zeros.iter().map(|z| [z.re, z.im]).collect();
    zeros_rad_per_s.sort_by(|a, b| a[1].total_cmp(&b[1]));

    let (lo, hi) = (fn_hz / SEARCH_FACTOR, fn_hz * SEARCH_FACTOR);
    let force = tf_f_u(rig, specimen).ok()?;
    let grid: Vec<f64> = (0..MODEL_POINTS)
        .map(|i| lo + (hi - lo) * i as f64 / (MODEL_POINTS - 1) as f64)
        .collect();
    let model_db: Vec<f64> = grid.iter().map(|&f| db(force.freq_response(f))).collect();
    let notch_model = notch(&grid, &model_db);

    let notch_measured = measured.and_then(|(freq, h)| {
        let (f, d): (Vec<f64>, Vec<f64>) = freq
            .iter()
            .zip(h)
            .filter(|(f, _)| (lo..=hi).contains(*f))
            .map(|(f, h)| (*f, db(*h)))
            .unzip();
        let smooth = running_median(&d, SMOOTH_BINS);
        let rough = notch(&f, &smooth)?;
        Some(Notch {
            frequency_hz: vertex(&f, &d, rough).unwrap_or(rough.frequency_hz),
            ..rough
        })
    });

    let x = tf_x1_u(rig, specimen).ok()?.freq_response(fn_hz);
    Some(Csi {
        run: run.to_string(),
        natural_frequency_hz: fn_hz,
        damping_ratio: zeta,
        zeros_rad_per_s,
        notch_measured,
        notch_model,
        x1_u_at_natural_frequency: Response {
            magnitude_db: db(x),
            phase_deg: x.arg().to_degrees(),
        },
    })
}

fn db(h: Complex<f64>) -> f64 {
    20.0 * h.norm().log10()
}

/// The least point of `db` over `f` when it lies inside (not at either end
/// of) the span; its depth against the highest level on each side.
fn notch(f: &[f64], db: &[f64]) -> Option<Notch> {
    let (i, &least) = db
        .iter()
        .enumerate()
        .filter(|(_, v)| v.is_finite())
        .min_by(|a, b| a.1.total_cmp(b.1))?;
    if i == 0 || i + 1 == db.len() {
        return None;
    }
    let high = |s: &[f64]| {
        s.iter()
            .copied()
            .filter(|v| v.is_finite())
            .fold(f64::NEG_INFINITY, f64::max)
    };
    let side = high(&db[..i]).min(high(&db[i + 1..]));
    Some(Notch {
        frequency_hz: f[i],
        depth_db: side - least,
        magnitude_db: least,
    })
}

/// The notch's frequency refined by a least-squares parabola through the
/// raw levels (dB) of the bins within [`VERTEX_DB`] of the smoothed least:
/// every bin near the bottom counts, not the one the noise made least.
/// None when the parabola opens downward or its vertex leaves those bins.
fn vertex(f: &[f64], db: &[f64], rough: Notch) -> Option<f64> {
    let near: Vec<(f64, f64)> = f
        .iter()
        .zip(db)
        .filter(|(_, d)| **d <= rough.magnitude_db + VERTEX_DB)
        .map(|(f, d)| (*f - rough.frequency_hz, *d))
        .collect();
    if near.len() < 5 {
        return None;
    }
    // Normal equations of d = a + b x + c x^2 (x centred on the rough notch).
    let mut m = nalgebra::Matrix3::<f64>::zeros();
    let mut r = nalgebra::Vector3::<f64>::zeros();
    for (x, d) in &near {
        let row = nalgebra::Vector3::new(1.0, *x, x * x);
        m += row * row.transpose();
        r += row * *d;
    }
    let coef = m.lu().solve(&r)?;
    if coef[2] <= 0.0 {
        return None;
    }
    let x = -coef[1] / (2.0 * coef[2]);
    let (lo, hi) = near
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p.0), hi.max(p.0))
        });
    (lo..=hi).contains(&x).then_some(rough.frequency_hz + x)
}

/// A centred running median over `w` points (fewer at the ends).
fn running_median(x: &[f64], w: usize) -> Vec<f64> {
    let half = w / 2;
    (0..x.len())
        .map(|i| {
            let mut win = x[i.saturating_sub(half)..(i + half + 1).min(x.len())].to_vec();
            let mid = win.len() / 2;
            *win.select_nth_unstable_by(mid, f64::total_cmp).1
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    /// The paper's rig (Table 1 values) and an SDOF specimen.
    fn rig() -> RigParams {
        RigParams {
            beta1_per_s: 267.0,
            a1b0_n_per_m_s2: 2.412e9,
            a2_n_per_m: 7.881e5,
            a3_per_s: 16.118,
            p_gain: 1.0,
        }
    }

    const SPECIMEN: LinearSpecimen = LinearSpecimen::Sdof {
        mass_kg: 15.0,
        damping_ns_per_m: 60.0,
        stiffness_n_per_m: 120_000.0,
    };

    #[test]
    fn natural_frequency_damping_and_zeros_by_hand() {
        let c = csi("exp", &rig(), &SPECIMEN, None).unwrap();
        // sqrt(120000 / 15) = 89.443 rad/s = 14.235 Hz; zeta = 60 /
        // (2 sqrt(1.8e6)) = 0.022361.
        assert_relative_eq!(
            c.natural_frequency_hz,
            89.442_719_1 / (2.0 * std::f64::consts::PI),
            max_relative = 1e-9
        );
        assert_relative_eq!(c.damping_ratio, 0.022_360_68, max_relative = 1e-6);
        // -c/2m = -2 rad/s, +-sqrt(k/m - (c/2m)^2) = +-89.420 rad/s.
        assert_relative_eq!(c.zeros_rad_per_s[0][0], -2.0, max_relative = 1e-12);
        assert_relative_eq!(
            c.zeros_rad_per_s[1][1],
            (8000.0f64 - 4.0).sqrt(),
            max_relative = 1e-12
        );
        assert_relative_eq!(
            c.zeros_rad_per_s[0][1],
            -(8000.0f64 - 4.0).sqrt(),
            max_relative = 1e-12
        );
        assert!(c.notch_measured.is_none());
    }

    /// |m (jw)^2 + c jw + k| is least at w* = sqrt(k/m - c^2 / 2m^2); x1/u
    /// varies little across the notch, so the model's notch sits within a
    /// few tenths of a percent of it, and is deep (the zero pair is lightly
    /// damped: about 20 log10(1 / 2 zeta) dB below its shoulders at least).
    #[test]
    fn the_model_notch_is_where_the_specimen_polynomial_is_least() {
        let c = csi("exp", &rig(), &SPECIMEN, None).unwrap();
        let w_star = (8000.0f64 - 3600.0 / (2.0 * 225.0)).sqrt();
        let n = c.notch_model.unwrap();
        assert_relative_eq!(
            n.frequency_hz,
            w_star / (2.0 * std::f64::consts::PI),
            max_relative = 3e-3
        );
        assert!(n.depth_db > 20.0, "{n:?}");
    }

    /// A measured FRF made from the model with 10 % multiplicative noise
    /// (+-0.4 dB): the notch is found within a tenth of its half-power
    /// half-width (zeta fn = 0.32 Hz).
    #[test]
    fn a_noisy_measured_notch_is_found() {
        let force = tf_f_u(&rig(), &SPECIMEN).unwrap();
        let df = 0.01;
        let freq: Vec<f64> = (1..3500).map(|i| i as f64 * df).collect();
        let mut state = 7u64;
        let h: Vec<Complex<f64>> = freq
            .iter()
            .map(|&f| {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let u = (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
                force.freq_response(f) * (1.0 + 0.1 * u)
            })
            .collect();
        let c = csi("exp", &rig(), &SPECIMEN, Some((&freq, &h))).unwrap();
        let (m, n) = (c.notch_measured.unwrap(), c.notch_model.unwrap());
        assert!(
            (m.frequency_hz - n.frequency_hz).abs() <= 2.0 * df,
            "{m:?} {n:?}"
        );
        assert!(m.depth_db > 15.0, "{m:?}");
    }

    #[test]
    fn only_sdof_specimens_with_mass_and_stiffness() {
        let spring = LinearSpecimen::Spring {
            stiffness_n_per_m: 1e5,
        };
        assert!(csi("k", &rig(), &spring, None).is_none());
        assert!(csi("n", &rig(), &LinearSpecimen::None, None).is_none());
    }
}
