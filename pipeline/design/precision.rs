//! The rig's precision a planned night would reach: the Cramer-Rao
//! covariance of (beta1, a1b0, a2, a3) from the joint fit's Fisher
//! information at the current rig, each run's FRF variance from its command
//! and the displacement's measured noise. The derivation: docs/methods.md,
//! "Predicted precision".

use nalgebra::{Complex, Matrix4, Vector4};

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

/// The predicted covariance of (beta1, a1b0 at the rig's P gain, a2, a3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Precision {
    pub covariance: Matrix4<f64>,
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
    let theta = values(rig);
    let mut fisher = Matrix4::<f64>::zeros();
    for run in runs {
        for (&f, &v) in run.freq_hz.iter().zip(&run.variance) {
            if !(v.is_finite() && v > 0.0) {
                continue;
            }
            let info = line_information(
                rig,
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
    let d = Matrix4::from_diagonal(&Vector4::from(theta));
    let covariance = d * inverse * d;
    (0..4)
        .all(|i| covariance[(i, i)].is_finite() && covariance[(i, i)] > 0.0)
        .then_some(Precision { covariance })
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
