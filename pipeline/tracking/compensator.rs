//! A model-based feedforward compensator for the identified plant (issue
//! 27, item 3): the plant's inverse made proper by a low-pass, discretised
//! for the controller's sample rate, with a phase lead that makes up the
//! delay the low-pass, the sample-and-hold and the plant's own delay leave.
//!
//! With the plant `G(s) = N(s)/D(s) e^{-s tau_p}` of relative degree `r`
//! (for the paper's plant with an SDOF specimen, Eqs. 34-35, `N` is a
//! constant and `r = 4`), the feedforward is
//!
//! `F(s) = D(s) / N(s) * B(s)`, `B` the Butterworth low-pass of order `r`
//! and unit gain at DC,
//!
//! so that `G F = B e^{-s tau_p}`: flat amplitude up to well below the
//! cut-off, and a delay of `tau_p` plus the low-pass's group delay. This is
//! the model-based feedforward of Carrion & Spencer (2007, "Model-based
//! strategies for real-time hybrid testing", NSEL Report 6, UIUC) and
//! Phillips & Spencer (2013, J. Eng. Mech. 139(2):219-228), which invert the
//! identified actuator-specimen model; they make it causal with a low-pass
//! (Carrion & Spencer) or backward differences (Phillips, Takada, Spencer &
//! Fujino 2014, Smart Struct. Syst. 14(6):1081-1103). The remaining delay is
//! taken up by extrapolating the command ahead by as much (Horiuchi et al.
//! 1999, Earthquake Eng. Struct. Dyn. 28(10):1121-1141: a cubic Lagrange
//! polynomial through the last four samples).
//!
//! `F` is discretised by the bilinear (Tustin) map at the log's rate; the
//! compensator a controller runs is `C(z) = E(z) F_d(z)`, `E` the
//! extrapolation. Pure: the plant in, the filter's coefficients out.

use nalgebra::Complex;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::lti::TransferFunction;
use crate::poly;

/// The cut-off's default: this many times the top of the fitted band, where
/// an r-th order Butterworth is flat to 1e-7 and its group delay (about
/// `1.3 r / omega_c` for r = 4) is short enough for a cubic extrapolation
/// to make it up within 0.2 % of amplitude at the band's top.
pub const CUTOFF_PER_BAND: f64 = 8.0;

/// The cut-off never goes above this fraction of the sampling rate (the
/// bilinear map squeezes frequencies near Nyquist).
pub const MAX_CUTOFF_PER_FS: f64 = 0.4;

/// A compensator's design, for results.json and models.mat.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Compensator {
    /// The rate the discrete filter runs at (Hz).
    pub sample_rate_hz: f64,
    /// The low-pass's cut-off (Hz) and order (the plant's relative degree).
    pub cutoff_hz: f64,
    pub order: usize,
    /// The continuous feedforward F(s) = num/den, highest power first.
    pub num_s: Vec<f64>,
    pub den_s: Vec<f64>,
    /// The delay the extrapolation makes up (s): the low-pass's group delay
    /// at low frequency, the hold's half sample and the plant's own delay.
    /// Zero without the lead.
    pub lead_s: f64,
    /// The discrete compensator C(z) = b(z^-1) / a(z^-1), lead included,
    /// coefficients of z^0, z^-1, ...; `a[0] = 1` (`filter(b, a, x)` in
    /// MATLAB, `scipy.signal.lfilter(b, a, x)`).
    pub b: Vec<f64>,
    pub a: Vec<f64>,
}

/// Why no compensator could be designed: a note, not a number.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CompensatorNote {
    #[error(
        "the plant has a zero at {re:.4} {im:+.4}i rad/s in the right half-plane: its inverse is unstable"
    )]
    NonMinimumPhase { re: f64, im: f64 },
    #[error("the plant has more zeros than poles")]
    Improper,
    #[error("the cut-off {cutoff_hz} Hz is not below {max_hz} Hz (0.4 of the sampling rate)")]
    CutoffTooHigh { cutoff_hz: f64, max_hz: f64 },
    #[error("the plant's gain at zero frequency is not finite and nonzero")]
    NoDcGain,
}

/// Design the compensator for `plant` at `sample_rate_hz`: the cut-off
/// `cutoff_hz`, or [`CUTOFF_PER_BAND`] times `band_top_hz` (at most
/// [`MAX_CUTOFF_PER_FS`] of the rate); with `lead`, the extrapolation.
pub fn design(
    plant: &TransferFunction,
    sample_rate_hz: f64,
    band_top_hz: f64,
    cutoff_hz: Option<f64>,
    lead: bool,
) -> Result<Compensator, CompensatorNote> {
    let max_hz = MAX_CUTOFF_PER_FS * sample_rate_hz;
    let fc = cutoff_hz.unwrap_or((CUTOFF_PER_BAND * band_top_hz).min(max_hz));
    if !(fc > 0.0 && fc <= max_hz) {
        return Err(CompensatorNote::CutoffTooHigh {
            cutoff_hz: fc,
            max_hz,
        });
    }
    let (num, den) = (
        poly::trim_leading_zeros(&plant.num),
        poly::trim_leading_zeros(&plant.den),
    );
    if num.len() > den.len() {
        return Err(CompensatorNote::Improper);
    }
    if let Some(z) = poly::roots(&num).into_iter().find(|z| z.re >= 0.0) {
        return Err(CompensatorNote::NonMinimumPhase { re: z.re, im: z.im });
    }
    let dc = plant.dc_gain();
    if !(dc.is_finite() && dc != 0.0) {
        return Err(CompensatorNote::NoDcGain);
    }
    let order = den.len() - num.len();
    let wc = 2.0 * std::f64::consts::PI * fc;
    // Butterworth poles wc exp(i pi (2k + r - 1) / (2r)), k = 1..r, and
    // B(s) = wc^r / prod (s - p_k).
    let poles: Vec<Complex<f64>> = (1..=order)
        .map(|k| {
            let angle = std::f64::consts::PI * (2 * k + order - 1) as f64 / (2 * order) as f64;
            Complex::from_polar(wc, angle)
        })
        .collect();
    let butter_den = poly::from_roots(&poles);
    let gain = wc.powi(order as i32);
    let num_s: Vec<f64> = den.iter().map(|c| c * gain).collect();
    let den_s = poly::mul(&num, &butter_den);
    let (mut b, mut a) = bilinear(&num_s, &den_s, sample_rate_hz);
    let dt = 1.0 / sample_rate_hz;
    // The delay left at low frequency, hold and plant delay included,
    // read from the discrete cascade's phase well below the cut-off.
    let lead_s = if lead {
        let f0 = 0.01 * fc;
        let w = 2.0 * std::f64::consts::PI * f0;
        let hold = Complex::from_polar(1.0, -w * dt / 2.0);
        let c = discrete_response(&b, &a, f0, dt);
        -(plant.freq_response(f0) * hold * c).arg() / w
    } else {
        0.0
    };
    if lead {
        let e = extrapolation(lead_s / dt);
        b = poly_z_mul(&b, &e);
    }
    // a[0] = 1.
    let a0 = a[0];
    b.iter_mut().for_each(|x| *x /= a0);
    a.iter_mut().for_each(|x| *x /= a0);
    Ok(Compensator {
        sample_rate_hz,
        cutoff_hz: fc,
        order,
        num_s,
        den_s,
        lead_s,
        b,
        a,
    })
}

/// The bilinear map s = (2/T)(1 - z^-1)/(1 + z^-1) of num(s)/den(s)
/// (highest power first, deg num <= deg den = n): coefficients of z^0,
/// z^-1, ... z^-n.
fn bilinear(num: &[f64], den: &[f64], fs: f64) -> (Vec<f64>, Vec<f64>) {
    let n = den.len() - 1;
    let k = 2.0 * fs;
    let map = |p: &[f64]| -> Vec<f64> {
        let deg = p.len() - 1;
        let mut out = vec![0.0; n + 1];
        for (i, &c) in p.iter().enumerate() {
            // The term c s^j, j = deg - i: c k^j (1 - z^-1)^j (1 + z^-1)^(n - j).
            let j = deg - i;
            let mut term = vec![c * k.powi(j as i32)];
            for _ in 0..j {
                term = poly_z_mul(&term, &[1.0, -1.0]);
            }
            for _ in 0..n - j {
                term = poly_z_mul(&term, &[1.0, 1.0]);
            }
            for (o, t) in out.iter_mut().zip(&term) {
                *o += t;
            }
        }
        out
    };
    (map(num), map(den))
}

/// The product of two polynomials in z^-1 (coefficients of z^0, z^-1, ...).
fn poly_z_mul(a: &[f64], b: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; a.len() + b.len() - 1];
    for (i, x) in a.iter().enumerate() {
        for (j, y) in b.iter().enumerate() {
            out[i + j] += x * y;
        }
    }
    out
}

/// Cubic Lagrange extrapolation `r` samples ahead through the last four
/// (Horiuchi et al. 1999): x[k + r] ~ sum_j e_j x[k - j], j = 0..3.
pub fn extrapolation(r: f64) -> [f64; 4] {
    [
        (r + 1.0) * (r + 2.0) * (r + 3.0) / 6.0,
        -r * (r + 2.0) * (r + 3.0) / 2.0,
        r * (r + 1.0) * (r + 3.0) / 2.0,
        -r * (r + 1.0) * (r + 2.0) / 6.0,
    ]
}

/// C(e^{i w T}) of b/a at `f_hz`.
pub fn discrete_response(b: &[f64], a: &[f64], f_hz: f64, dt: f64) -> Complex<f64> {
    let z1 = Complex::from_polar(1.0, -2.0 * std::f64::consts::PI * f_hz * dt);
    let at = |p: &[f64]| {
        p.iter()
            .rev()
            .fold(Complex::new(0.0, 0.0), |acc, &c| acc * z1 + c)
    };
    at(b) / at(a)
}

impl Compensator {
    /// The compensator's frequency response at `f_hz`.
    pub fn response(&self, f_hz: f64) -> Complex<f64> {
        discrete_response(&self.b, &self.a, f_hz, 1.0 / self.sample_rate_hz)
    }

    /// The command a controller running C sends for the desired
    /// displacement `x` (direct form II transposed, from rest).
    pub fn apply(&self, x: &[f64]) -> Vec<f64> {
        let n = self.a.len().max(self.b.len());
        let coef = |v: &[f64], i: usize| v.get(i).copied().unwrap_or(0.0);
        let mut state = vec![0.0; n];
        x.iter()
            .map(|&xi| {
                let y = coef(&self.b, 0) * xi + state[0];
                for i in 1..n {
                    let next = if i + 1 < n { state[i] } else { 0.0 };
                    state[i - 1] = next + coef(&self.b, i) * xi - coef(&self.a, i) * y;
                }
                y
            })
            .collect()
    }
}
