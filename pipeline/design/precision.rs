//! The rig's precision a planned night would reach: the Cramer-Rao
//! covariance of (beta1, a1b0, a2, a3), and of the delay, mode and piston
//! mass the joint fit found beyond the paper's model, from the joint fit's
//! Fisher information at the current rig, each run's FRF variance from its
//! command and the displacement's measured noise. The derivation:
//! docs/methods.md, "Predicted precision".

use nalgebra::{Complex, DMatrix, Matrix4};

use crate::fft;
use crate::fit::Intersample;
use crate::fit::problem::hold_response;
use crate::model::{self, LinearSpecimen, RigParams};

/// The rig parameters in the joint fit's order.
pub const NAMES: [&str; 4] = ["beta1", "a1b0", "a2", "a3"];

/// A planned run's x1/u as the joint fit would see it: its specimen, its
/// P gain, and the FRF's variance E|dH|^2 at each bin.
#[derive(Debug, Clone, PartialEq)]
pub struct PlannedRun {
    pub specimen: LinearSpecimen,
    pub p_gain: f64,
    pub freq_hz: Vec<f64>,
    pub variance: Vec<f64>,
}

/// The predicted covariance of (beta1, a1b0 at the rig's P gain, a2, a3),
/// with the extension's parameters estimated beside them; and the
/// extension's own stds.
#[derive(Debug, Clone, PartialEq)]
pub struct Precision {
    pub covariance: Matrix4<f64>,
    /// The extension's parameters (name, value, predicted std), in
    /// [`Extension::values`]' order.
    pub extension: Vec<(&'static str, f64, f64)>,
}

/// What the joint fit found beyond the paper's model, as it enters x1/u
/// (identify::joint's structures): a delay, a second-order mode in the
/// loop or outside it, the piston's mass on the oil column.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Extension {
    pub delay_s: Option<f64>,
    pub mode: Option<Mode>,
    pub piston_mass_kg: Option<f64>,
}

/// Where a mode sits (identify::joint's places).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Place {
    /// Inside the position loop: it multiplies the valve's gain.
    Loop,
    /// In the command path: a factor on x1/u.
    Command,
    /// On the logged displacement: a factor on x1/u.
    Measurement,
}

/// A second-order mode V = w^2 / (s^2 + 2 zeta w s + w^2): in the loop it
/// multiplies the valve's gain, outside it x1/u.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mode {
    pub place: Place,
    pub hz: f64,
    pub damping: f64,
}

impl Extension {
    /// Its parameters (name as results.json's rig.joint.parameters gives
    /// it, value), after the rig's four.
    pub fn values(&self) -> Vec<(&'static str, f64)> {
        let mut v = Vec::new();
        if let Some(t) = self.delay_s {
            v.push(("delay_s", t));
        }
        if let Some(m) = self.mode {
            let (hz, damping) = match m.place {
                Place::Loop => ("valve_hz", "valve_damping"),
                _ => ("mode_hz", "mode_damping"),
            };
            v.push((hz, m.hz));
            v.push((damping, m.damping));
        }
        if let Some(m) = self.piston_mass_kg {
            v.push(("piston_mass_kg", m));
        }
        v
    }

    /// The extension at `v`, values in [`Self::values`]' order.
    fn with_values(&self, v: &[f64]) -> Extension {
        let mut v = v.iter().copied();
        Extension {
            delay_s: self.delay_s.and(v.next()),
            mode: self.mode.and_then(|m| {
                Some(Mode {
                    hz: v.next()?,
                    damping: v.next()?,
                    ..m
                })
            }),
            piston_mass_kg: self.piston_mass_kg.and(v.next()),
        }
    }
}

/// x1/u at `f_hz` of the rig `at` (a1b0 at the run's P gain) with `ext`:
/// the joint fit's model (identify::joint), the specimen's S(s) = m s^2 +
/// c s + k (Eq. 15) plus the piston's m_p s^2, Q = (s + a3) S + a2 s,
/// D = (s + beta1) Q + a1b0 V in the loop (a1b0 with V outside it), the
/// numerator a1b0 V, times exp(-s tau).
pub fn x1_u(at: &RigParams, ext: &Extension, specimen: LinearSpecimen, f_hz: f64) -> Complex<f64> {
    let s = Complex::new(0.0, 2.0 * std::f64::consts::PI * f_hz);
    let (m, c, k) = specimen.mck();
    let sp = s * s * (m + ext.piston_mass_kg.unwrap_or(0.0)) + s * c + k;
    let q = (s + at.a3_per_s) * sp + s * at.a2_n_per_m;
    let a = at.a1b0_n_per_m_s2;
    let sbq = (s + at.beta1_per_s) * q;
    let h = match ext.mode {
        Some(mode) => {
            let w = 2.0 * std::f64::consts::PI * mode.hz;
            let v = w * w / (s * s + s * (2.0 * mode.damping * w) + w * w);
            match mode.place {
                Place::Loop => a * v / (sbq + a * v),
                _ => a * v / (sbq + a),
            }
        }
        None => a / (sbq + a),
    };
    match ext.delay_s {
        Some(tau) => h * (-s * tau).exp(),
        None => h,
    }
}

impl Precision {
    /// Each parameter's predicted standard deviation.
    pub fn std(&self) -> [f64; 4] {
        std::array::from_fn(|i| self.covariance[(i, i)].sqrt())
    }

    /// Each parameter's predicted standard deviation over its value.
    pub fn relative_std(&self, rig: &RigParams) -> [f64; 4] {
        let values = values(rig);
        let std = self.std();
        std::array::from_fn(|i| std[i] / values[i].abs())
    }
}

/// The rig's (beta1, a1b0, a2, a3), in [`NAMES`]' order.
pub fn values(rig: &RigParams) -> [f64; 4] {
    [
        rig.beta1_per_s,
        rig.a1b0_n_per_m_s2,
        rig.a2_n_per_m,
        rig.a3_per_s,
    ]
}

fn with_values(rig: &RigParams, v: [f64; 4]) -> RigParams {
    RigParams {
        beta1_per_s: v[0],
        a1b0_n_per_m_s2: v[1],
        a2_n_per_m: v[2],
        a3_per_s: v[3],
        ..*rig
    }
}

/// The FRF variance an empirical transfer-function estimate over a whole
/// record gives at each bin of `band_hz`: E|dH_k|^2 = N lambda(f_k) /
/// |U_k|^2, with U the command's DFT over its N samples and lambda(f) the
/// displacement noise's variance per sample at f (its level E|N_k|^2 / N;
/// white noise of variance s^2 has lambda = s^2). For a periodic command,
/// give its steady periods: averaging P periods is the same record.
pub fn etfe_variance(
    u: &[f64],
    sample_rate_hz: f64,
    band_hz: [f64; 2],
    noise: impl Fn(f64) -> f64,
) -> (Vec<f64>, Vec<f64>) {
    let n = u.len();
    let spectrum = fft::real_spectrum(u);
    let (mut freq_hz, mut variance) = (Vec::new(), Vec::new());
    for (k, uk) in spectrum.iter().enumerate().skip(1) {
        let f = k as f64 * sample_rate_hz / n as f64;
        if f < band_hz[0] || f > band_hz[1] {
            continue;
        }
        let power = uk.norm_sqr();
        if power > 0.0 {
            freq_hz.push(f);
            variance.push(n as f64 * noise(f) / power);
        }
    }
    (freq_hz, variance)
}

/// The Cramer-Rao covariance of the rig from `runs`, at `rig` (a1b0 at
/// its P gain), the command held as `intersample` at `sample_rate_hz`;
/// None where the runs do not determine the four parameters.
///
/// Each bin's complex error has E|dH|^2 = v, so Re and Im each v / 2, and
/// the Fisher information of the logarithms of the parameters is the sum
/// over bins of (2 / v) Re(g^H g), g = dH/dln(theta) (docs/methods.md).
pub fn predict(
    rig: &RigParams,
    runs: &[PlannedRun],
    intersample: Intersample,
    sample_rate_hz: f64,
) -> Option<Precision> {
    predict_extended(
        rig,
        &Extension::default(),
        runs,
        intersample,
        sample_rate_hz,
    )
}

/// [`predict`] for a rig with `ext` beyond the paper's model, whose
/// parameters the fit estimates beside the rig's four: the Fisher
/// information of all their logarithms, inverted whole, so that the
/// rig's stds carry what the extension takes from them.
pub fn predict_extended(
    rig: &RigParams,
    ext: &Extension,
    runs: &[PlannedRun],
    intersample: Intersample,
    sample_rate_hz: f64,
) -> Option<Precision> {
    let theta = parameters(rig, ext);
    let n = theta.len();
    let mut fisher = DMatrix::<f64>::zeros(n, n);
    for run in runs {
        for (&f, &v) in run.freq_hz.iter().zip(&run.variance) {
            if !(v.is_finite() && v > 0.0) {
                continue;
            }
            let info = information(
                rig,
                ext,
                run.specimen,
                run.p_gain,
                f,
                intersample,
                sample_rate_hz,
            )?;
            fisher += info * (2.0 / v);
        }
    }
    let inverse = fisher.try_inverse()?;
    let cov = |i: usize, j: usize| theta[i] * inverse[(i, j)] * theta[j];
    let covariance = Matrix4::from_fn(cov);
    let extension: Vec<(&'static str, f64, f64)> = ext
        .values()
        .into_iter()
        .enumerate()
        .map(|(k, (name, value))| (name, value, cov(4 + k, 4 + k).sqrt()))
        .collect();
    ((0..n).all(|i| cov(i, i).is_finite() && cov(i, i) > 0.0)).then_some(Precision {
        covariance,
        extension,
    })
}

/// A bin's Fisher information of the logarithms of the rig's four
/// parameters and the extension's, per unit of 2 / E|dH|^2: Re(g^H g),
/// g = dH/dln(theta), the command held as `intersample`.
pub fn information(
    rig: &RigParams,
    ext: &Extension,
    specimen: LinearSpecimen,
    p_gain: f64,
    f_hz: f64,
    intersample: Intersample,
    sample_rate_hz: f64,
) -> Option<DMatrix<f64>> {
    if *ext == Extension::default() {
        let m = line_information(rig, specimen, p_gain, f_hz, intersample, sample_rate_hz)?;
        return Some(DMatrix::from_fn(4, 4, |i, j| m[(i, j)]));
    }
    let theta = parameters(rig, ext);
    let g = extended_gradient(rig, ext, &theta, specimen, p_gain, f_hz)?;
    let hold = hold_response(intersample, sample_rate_hz, f_hz).norm_sqr();
    let n = theta.len();
    Some(DMatrix::from_fn(n, n, |i, j| {
        (g[i].conj() * g[j]).re * hold
    }))
}

/// The rig's four parameters, then the extension's.
fn parameters(rig: &RigParams, ext: &Extension) -> Vec<f64> {
    values(rig)
        .into_iter()
        .chain(ext.values().into_iter().map(|(_, v)| v))
        .collect()
}

/// dH/dln(theta_j) of the extended x1/u at `f_hz` for each of `theta`
/// (the rig's four, then the extension's), by central differences.
fn extended_gradient(
    rig: &RigParams,
    ext: &Extension,
    theta: &[f64],
    specimen: LinearSpecimen,
    p_gain: f64,
    f_hz: f64,
) -> Option<Vec<Complex<f64>>> {
    const STEP: f64 = 1e-5;
    let h = |t: &[f64]| -> Complex<f64> {
        let r = with_values(rig, [t[0], t[1], t[2], t[3]]).at_p_gain(p_gain);
        x1_u(&r, &ext.with_values(&t[4..]), specimen, f_hz)
    };
    let g: Vec<Complex<f64>> = (0..theta.len())
        .map(|j| {
            let (mut up, mut down) = (theta.to_vec(), theta.to_vec());
            up[j] *= STEP.exp();
            down[j] *= (-STEP).exp();
            (h(&up) - h(&down)) / (2.0 * STEP)
        })
        .collect();
    g.iter()
        .all(|g| g.re.is_finite() && g.im.is_finite())
        .then_some(g)
}

/// Re(g^H g) at `f_hz`, g = dH/dln(theta) of x1/u ([`line_gradient`]): a
/// bin's Fisher information of the logarithms of the four parameters per
/// unit of 2 / E|dH|^2.
pub fn line_information(
    rig: &RigParams,
    specimen: LinearSpecimen,
    p_gain: f64,
    f_hz: f64,
    intersample: Intersample,
    sample_rate_hz: f64,
) -> Option<Matrix4<f64>> {
    let g = line_gradient(rig, specimen, p_gain, f_hz, intersample, sample_rate_hz)?;
    Some(Matrix4::from_fn(|i, j| (g[i].conj() * g[j]).re))
}

/// dH/dln(theta_j) of x1/u at `f_hz`, the command held as `intersample`:
/// by central differences (a relative step of 1e-5: the model is a ratio
/// of polynomials, smooth in each).
pub fn line_gradient(
    rig: &RigParams,
    specimen: LinearSpecimen,
    p_gain: f64,
    f_hz: f64,
    intersample: Intersample,
    sample_rate_hz: f64,
) -> Option<[Complex<f64>; 4]> {
    const STEP: f64 = 1e-5;
    let theta = values(rig);
    let h = |t: [f64; 4]| -> Option<Complex<f64>> {
        let at = with_values(rig, t).at_p_gain(p_gain);
        Some(model::tf_x1_u(&at, &specimen).ok()?.freq_response(f_hz))
    };
    let hold = hold_response(intersample, sample_rate_hz, f_hz);
    let mut g = [Complex::new(0.0, 0.0); 4];
    for (j, gj) in g.iter_mut().enumerate() {
        let (mut up, mut down) = (theta, theta);
        up[j] *= STEP.exp();
        down[j] *= (-STEP).exp();
        *gj = (h(up)? - h(down)?) / (2.0 * STEP) * hold;
    }
    Some(g)
}

#[cfg(test)]
mod tests;
