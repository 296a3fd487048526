//! A model-based feedforward compensator for the identified plant: the
//! plant's inverse made proper by a low-pass, discretised for the
//! controller's sample rate, with a phase lead that makes up the delay the
//! low-pass, the sample-and-hold and the plant's own delay leave.
//!
//! For `G(s) = N(s)/D(s) e^{-s tau_p}` of relative degree `r` (`N` a
//! constant and `r = 4` for the paper's plant with an SDOF specimen,
//! Eqs. 34-35), `design` gives `F(s) = D(s) / N(s) * B(s)`, `B` the
//! Butterworth low-pass of order `r` and unit DC gain, so that
//! `G F = B e^{-s tau_p}` (Carrion & Spencer 2007; Phillips & Spencer 2013).
//! `F` is discretised by the bilinear (Tustin) map at the log's rate; the
//! controller runs `C(z) = E(z) F_d(z)`, `E` the extrapolation of the
//! command ahead by a cubic through its last four samples (Horiuchi et al.
//! 1999). Pure: the plant in, the filter's coefficients out. The design,
//! its references and its checks: docs/tracking.md, "The compensator".

use nalgebra::Complex;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::lti::{StateSpace, TransferFunction, zoh_response};
use crate::model::flow::RigAtLoad;
use crate::model::{self, LinearSpecimen, RigParams};
use crate::poly;
use crate::simulate::SimError;
use crate::simulate::discrete::simulate_linear;

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
        match self.a.len().max(self.b.len()) {
            0 | 1 => self.apply_fixed::<1>(x),
            2 => self.apply_fixed::<2>(x),
            3 => self.apply_fixed::<3>(x),
            4 => self.apply_fixed::<4>(x),
            5 => self.apply_fixed::<5>(x),
            6 => self.apply_fixed::<6>(x),
            7 => self.apply_fixed::<7>(x),
            8 => self.apply_fixed::<8>(x),
            _ => self.apply_any(x),
        }
    }

    /// Coefficient `i` of `v`, zero past its end (a shorter numerator or
    /// denominator).
    fn coef(v: &[f64], i: usize) -> f64 {
        v.get(i).copied().unwrap_or(0.0)
    }

    /// [`Compensator::apply`] with the state on the stack, for filters of
    /// `N` coefficients: the same sums in the same order.
    fn apply_fixed<const N: usize>(&self, x: &[f64]) -> Vec<f64> {
        let b: [f64; N] = std::array::from_fn(|i| Self::coef(&self.b, i));
        let a: [f64; N] = std::array::from_fn(|i| Self::coef(&self.a, i));
        let mut state = [0.0; N];
        x.iter()
            .map(|&xi| {
                let y = b[0] * xi + state[0];
                for i in 1..N {
                    let next = if i + 1 < N { state[i] } else { 0.0 };
                    state[i - 1] = next + b[i] * xi - a[i] * y;
                }
                y
            })
            .collect()
    }

    fn apply_any(&self, x: &[f64]) -> Vec<f64> {
        let n = self.a.len().max(self.b.len());
        let mut state = vec![0.0; n];
        x.iter()
            .map(|&xi| {
                let y = Self::coef(&self.b, 0) * xi + state[0];
                for i in 1..n {
                    let next = if i + 1 < n { state[i] } else { 0.0 };
                    state[i - 1] = next + Self::coef(&self.b, i) * xi - Self::coef(&self.a, i) * y;
                }
                y
            })
            .collect()
    }
}

/// The targets for the compensated plant over the band: a
/// delay under one sample and an amplitude within 1 %.
pub const TARGET_DELAY_SAMPLES: f64 = 1.0;
pub const TARGET_AMPLITUDE_PCT: f64 = 1.0;

/// Frequencies over the band where [`band_tracking`] reads the response.
const BAND_POINTS: usize = 200;

/// The plant driven through the controller's zero-order hold at `fs`:
/// `G(i w) sinc(w T / 2) exp(-i w T / 2)`, the hold's continuous factor.
/// Sampled at `fs` the hold's images fold back onto it too
/// ([`crate::lti::ZohSampled`]): for Exp1's x1/u (relative degree 4) at
/// 30 Hz, 1e-9 of it at 2048 Hz, 8e-8 at 1 kHz and 1.7e-3 at 200 Hz.
pub fn held_response(plant: &TransferFunction, f_hz: f64, fs: f64) -> Complex<f64> {
    plant.freq_response(f_hz) * zoh_response(f_hz, fs)
}

/// Frequencies at which held plants are read, with all that does not
/// depend on the plant evaluated once: `s = i 2 pi f`, the hold's response
/// and the compensator's. Reading a plant on it is then its rational
/// function at each `s` (and its delay's phasor, when it has one): the
/// stiffness sweep and the bisection for the target stiffness read dozens
/// of plants on the same frequencies.
#[derive(Debug, Clone)]
pub struct HeldGrid {
    pub freq_hz: Vec<f64>,
    s: Vec<Complex<f64>>,
    hold: Vec<Complex<f64>>,
    comp: Option<Vec<Complex<f64>>>,
}

impl HeldGrid {
    /// The grid at `freq_hz` for a controller at `fs`, with `comp`'s
    /// response when given.
    pub fn new(freq_hz: Vec<f64>, fs: f64, comp: Option<&Compensator>) -> Self {
        Self {
            s: freq_hz
                .iter()
                .map(|&f| Complex::new(0.0, 2.0 * std::f64::consts::PI * f))
                .collect(),
            hold: freq_hz.iter().map(|&f| zoh_response(f, fs)).collect(),
            comp: comp.map(|c| freq_hz.iter().map(|&f| c.response(f)).collect()),
            freq_hz,
        }
    }

    /// The held plant's response at each frequency ([`held_response`]),
    /// times the compensator's when the grid has one.
    pub fn response<'a>(
        &'a self,
        plant: &'a TransferFunction,
    ) -> impl Iterator<Item = Complex<f64>> + 'a {
        self.s.iter().enumerate().map(move |(i, &s)| {
            let held = plant.eval(s) * self.hold[i];
            match &self.comp {
                Some(c) => held * c[i],
                None => held,
            }
        })
    }
}

/// How a plant, with or without the compensator, follows its command over
/// a band: the worst amplitude error and the range of the delay, from the
/// frequency response of the held plant (times the compensator's).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct BandTracking {
    /// max over the band of | |H| - 1 | (%).
    pub max_amplitude_error_pct: f64,
    /// The delay -arg H / w (phase unwrapped from low frequency), least and
    /// greatest over the band (samples; negative leads).
    pub delay_samples_min: f64,
    pub delay_samples_max: f64,
}

impl BandTracking {
    /// The largest delay or lead over the band (samples).
    pub fn max_abs_delay_samples(&self) -> f64 {
        self.delay_samples_min
            .abs()
            .max(self.delay_samples_max.abs())
    }

    /// The targets: under one sample, within 1 %.
    pub fn meets_target(&self) -> bool {
        self.max_abs_delay_samples() < TARGET_DELAY_SAMPLES
            && self.max_amplitude_error_pct < TARGET_AMPLITUDE_PCT
    }
}

/// The tracking of `plant` held at `fs`, times `comp` when given, over
/// `band_hz` (log-spaced points, both ends). The phase is unwrapped along
/// a grid that starts a hundred times below the band, where any plant here
/// lags by far less than half a cycle.
pub fn band_tracking(
    plant: &TransferFunction,
    comp: Option<&Compensator>,
    band_hz: (f64, f64),
    fs: f64,
) -> BandTracking {
    band_tracking_on(&band_grid(band_hz, fs, comp), plant, fs)
}

/// The points below the band that the phase is unwrapped along before it.
const LEAD_IN_POINTS: usize = 50;

/// The frequencies [`band_tracking`] reads a response at: [`LEAD_IN_POINTS`]
/// from a hundredth of the band's bottom, then [`BAND_POINTS`] over it.
fn band_grid(band_hz: (f64, f64), fs: f64, comp: Option<&Compensator>) -> HeldGrid {
    let (lo, hi) = band_hz;
    let lead_in =
        (0..LEAD_IN_POINTS).map(|i| lo * 0.01_f64.powf(1.0 - i as f64 / LEAD_IN_POINTS as f64));
    let band = (0..BAND_POINTS).map(|i| lo * (hi / lo).powf(i as f64 / (BAND_POINTS - 1) as f64));
    HeldGrid::new(lead_in.chain(band).collect(), fs, comp)
}

/// [`band_tracking`] of `plant` on a grid from [`band_grid`].
fn band_tracking_on(grid: &HeldGrid, plant: &TransferFunction, fs: f64) -> BandTracking {
    band_tracking_of(&grid.freq_hz, grid.response(plant), fs)
}

/// The tracking of the response values `h` at the frequencies `freq_hz` of
/// a [`band_grid`], read as [`band_tracking`] reads a plant's.
fn band_tracking_of(
    freq_hz: &[f64],
    h: impl Iterator<Item = Complex<f64>>,
    fs: f64,
) -> BandTracking {
    let mut phase = 0.0_f64;
    let mut prev: Option<f64> = None;
    let mut out = BandTracking {
        max_amplitude_error_pct: 0.0,
        delay_samples_min: f64::INFINITY,
        delay_samples_max: f64::NEG_INFINITY,
    };
    for (i, (&f, v)) in freq_hz.iter().zip(h).enumerate() {
        let arg = v.arg();
        phase = match prev {
            None => arg,
            Some(p) => {
                let step = (arg - p + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI)
                    - std::f64::consts::PI;
                phase + step
            }
        };
        prev = Some(arg);
        if i < LEAD_IN_POINTS {
            continue;
        }
        let delay = -phase / (2.0 * std::f64::consts::PI * f) * fs;
        out.max_amplitude_error_pct = out
            .max_amplitude_error_pct
            .max(100.0 * (v.norm() - 1.0).abs());
        out.delay_samples_min = out.delay_samples_min.min(delay);
        out.delay_samples_max = out.delay_samples_max.max(delay);
    }
    out
}

/// The compensated plant's tracking where the seals' friction acts at one
/// amplitude.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct SealsTracking {
    /// The displacement's amplitude (m) the friction's describing function
    /// is taken at.
    pub amplitude_m: f64,
    pub compensated: BandTracking,
}

/// What the seals' friction leaves of the compensator's
/// tracking at each of `amplitudes_m`: the compensator inverts the linear
/// plant, and the friction multiplies x1/u by [`model::friction_factor`]
/// (its describing function at that amplitude), which grows as the
/// amplitude falls. Each point is the compensated plant's tracking over
/// `band_hz` with that factor.
pub fn seals_tracking(
    plant: &TransferFunction,
    comp: &Compensator,
    (rig, specimen): (&RigParams, &LinearSpecimen),
    seals: &model::Seals,
    amplitudes_m: &[f64],
    band_hz: (f64, f64),
    fs: f64,
) -> Vec<SealsTracking> {
    let grid = band_grid(band_hz, fs, Some(comp));
    amplitudes_m
        .iter()
        .map(|&a| SealsTracking {
            amplitude_m: a,
            compensated: band_tracking_of(
                &grid.freq_hz,
                grid.response(plant)
                    .zip(&grid.freq_hz)
                    .map(|(h, &f)| h * model::friction_factor(rig, specimen, seals, a, f)),
                fs,
            ),
        })
        .collect()
}

/// The compensator designed on the model of one specimen, on the plant of
/// another: the tracking over the band with and without it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct StiffnessPoint {
    pub stiffness_n_per_m: f64,
    /// With the valve's flow law, the largest force this specimen takes
    /// over the band at the run's amplitude, over F_max: the load whose
    /// equivalent rig the line's plant is built on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub load_fraction: Option<f64>,
    pub uncompensated: BandTracking,
    pub compensated: BandTracking,
}

/// `specimen` with its stiffness set to `k` (a spring where there was
/// none): the specimen a compensator meets when the one it was designed
/// for differs only in stiffness, the paper's theme (Sec. 2.3).
pub fn with_stiffness(specimen: &LinearSpecimen, k: f64) -> LinearSpecimen {
    match *specimen {
        LinearSpecimen::None | LinearSpecimen::Spring { .. } => LinearSpecimen::Spring {
            stiffness_n_per_m: k,
        },
        LinearSpecimen::Sdof {
            mass_kg,
            damping_ns_per_m,
            ..
        } => LinearSpecimen::Sdof {
            mass_kg,
            damping_ns_per_m,
            stiffness_n_per_m: k,
        },
    }
}

/// `comp`, designed for `specimen` on `rig`, on the plant with each of the
/// stiffnesses `ks` instead (Eqs. 34-35), the rig at each one's load; a
/// stiffness whose plant leaves f64's range, or whose load reaches F_max,
/// is left out.
pub fn stiffness_sweep(
    rig: &RigAtLoad,
    specimen: &LinearSpecimen,
    comp: &Compensator,
    ks: &[f64],
    band_hz: (f64, f64),
) -> Vec<StiffnessPoint> {
    let fs = comp.sample_rate_hz;
    let (bare, with) = (
        band_grid(band_hz, fs, None),
        band_grid(band_hz, fs, Some(comp)),
    );
    ks.iter()
        .filter_map(|&k| {
            let line = with_stiffness(specimen, k);
            let plant = model::tf_x1_u(&rig.for_specimen(&line)?, &line).ok()?;
            Some(StiffnessPoint {
                stiffness_n_per_m: k,
                load_fraction: rig.load_fraction(&line),
                uncompensated: band_tracking_on(&bare, &plant, fs),
                compensated: band_tracking_on(&with, &plant, fs),
            })
        })
        .collect()
}

/// The stiffnesses around the designed-for specimen's over which `comp`
/// still meets the targets over the band ([`BandTracking::meets_target`]),
/// searched within `range_n_per_m` (extended to take in the specimen's own)
/// by bisection on each side to 1e-6 of the stiffness; None when the
/// compensator misses the targets on its own specimen. A bound equal to
/// the range's end means the targets hold that far at least.
pub fn target_stiffness(
    rig: &RigAtLoad,
    specimen: &LinearSpecimen,
    comp: &Compensator,
    range_n_per_m: (f64, f64),
    band_hz: (f64, f64),
) -> Option<[f64; 2]> {
    let fs = comp.sample_rate_hz;
    let grid = band_grid(band_hz, fs, Some(comp));
    let meets = |k: f64| {
        let line = with_stiffness(specimen, k);
        rig.for_specimen(&line)
            .and_then(|r| model::tf_x1_u(&r, &line).ok())
            .is_some_and(|g| band_tracking_on(&grid, &g, fs).meets_target())
    };
    let own = model::tf_x1_u(&rig.for_specimen(specimen)?, specimen).ok()?;
    if !band_tracking_on(&grid, &own, fs).meets_target() {
        return None;
    }
    let k0 = specimen.mck().2;
    // From `inside` (meets) toward `outside` (the range's end): the last
    // stiffness that meets.
    let edge = |inside: f64, outside: f64| {
        if meets(outside) {
            return outside;
        }
        let (mut a, mut b) = (inside, outside);
        while (b - a).abs() > 1e-6 * a.abs().max(b.abs()) {
            let mid = if a > 0.0 && b > 0.0 {
                (a * b).sqrt()
            } else {
                0.5 * (a + b)
            };
            if meets(mid) { a = mid } else { b = mid }
        }
        a
    };
    let lo = if k0 > 0.0 {
        edge(k0, range_n_per_m.0.min(k0))
    } else {
        0.0
    };
    let hi = edge(k0, range_n_per_m.1.max(k0));
    Some([lo, hi])
}

/// The displacement the plant `ss` (first output x1, Eq. 10) gives when a
/// controller runs `comp` on the desired displacement `desired`, sampled at
/// the compensator's rate through a zero-order hold. The rig rests at the
/// first desired sample before the record begins; C has the plant's
/// inverse gain at DC, so the displacement rests there too, and only the
/// departures from it pass through the filter from rest.
///
/// Returns the displacement and the largest command the controller sends
/// (m; at rest, `x0 / G(0)`): an inverse asks for much more than the
/// desired displacement where that has content the plant attenuates (a
/// sweep cut off mid-cycle asks for a step), which the actuator's stroke
/// and valve may not give.
pub fn compensated_displacement(
    ss: &StateSpace,
    comp: &Compensator,
    desired: &[f64],
) -> Result<(Vec<f64>, f64), SimError> {
    let x0 = desired.first().copied().unwrap_or(0.0);
    let departures: Vec<f64> = desired.iter().map(|v| v - x0).collect();
    let command = comp.apply(&departures);
    let outputs = ss.c.nrows();
    let mut y = simulate_linear(ss, &command, 1.0 / comp.sample_rate_hz, &vec![0.0; outputs])?;
    let mut x1 = y.swap_remove(model::OUT_X1);
    x1.iter_mut().for_each(|v| *v += x0);
    let dc = ss.eval(model::OUT_X1, Complex::new(0.0, 0.0)).re;
    let rest = if x0 == 0.0 { 0.0 } else { x0 / dc };
    let peak = command
        .iter()
        .fold(rest.abs(), |m, c| m.max((rest + c).abs()));
    Ok((x1, peak))
}

/// The compensator of one validation run: designed on the identified plant
/// with the run's specimen, its tracking over the run's band with and
/// without it, on the run's own command, and on specimens of other
/// stiffness.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct CompensatorOutcome {
    /// The design; null with `note` when the plant has no usable inverse.
    pub design: Option<Compensator>,
    pub note: Option<String>,
    /// The band the tracking is read over (the run's fitted band, Hz).
    pub band_hz: [f64; 2],
    /// The held plant alone and with the compensator, over the band.
    pub uncompensated: BandTracking,
    pub compensated: Option<BandTracking>,
    /// Whether the compensated plant meets the targets over the
    /// band: a delay under one sample, an amplitude within 1 %.
    pub meets_target: Option<bool>,
    /// The tracking measures of the displacement the plant with the
    /// compensator gives for the run's measured command (as `predicted`
    /// without it).
    pub predicted: Option<super::Tracking>,
    /// The largest command the compensator sends for the run's command
    /// (m), beside that command's own peak in `peak_desired_m`.
    pub peak_command_m: Option<f64>,
    pub peak_desired_m: Option<f64>,
    /// The compensator on the plant with the specimen's stiffness changed,
    /// over the stiffness sensitivity's range.
    pub stiffness: Vec<StiffnessPoint>,
    /// The specimens' stiffnesses (N/m) around this one's for which the
    /// compensator still meets the targets; null when it misses them on
    /// its own.
    pub target_stiffness_n_per_m: Option<[f64; 2]>,
    /// Where the joint fit found the seals' friction: the compensated
    /// tracking it leaves at the run's peak command and at a tenth and a
    /// hundredth of it (the friction weighs more at small amplitudes, and
    /// a linear compensator cannot remove it).
    #[serde(default)]
    pub seals: Vec<SealsTracking>,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The stack-held filters of each length give the bits the general one
    /// gives, numerator and denominator of equal and unequal lengths.
    #[test]
    fn the_fixed_filters_are_the_general_one() {
        let plant = TransferFunction::new(&[1.0e6], &[1.0, 90.0, 1.0e6]).unwrap();
        let base = design(&plant, 1024.0, 30.0, None, true).unwrap();
        let mut seed = 5u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let x: Vec<f64> = (0..2000).map(|_| next()).collect();
        for n in 1..=10 {
            for extra in [0, 1] {
                let mut c = base.clone();
                c.b = (0..n).map(|_| next()).collect();
                c.a = std::iter::once(1.0)
                    .chain((1..n + extra).map(|_| 0.3 * next()))
                    .collect();
                let (fast, general) = (c.apply(&x), c.apply_any(&x));
                assert!(
                    fast.iter()
                        .zip(&general)
                        .all(|(f, g)| f.to_bits() == g.to_bits()),
                    "{n} numerator and {} denominator coefficients",
                    n + extra
                );
            }
        }
    }
}
