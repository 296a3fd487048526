//! Whether the rig behaved linearly at the amplitude a sweep drove it:
//! harmonics of the command in the response, and for a spring run the
//! spring's force against its displacement ([`spring_force`]). A sweep
//! holds one narrow band at a time, so power at twice or three times its
//! frequency, beyond what the command itself holds there and the noise,
//! is distortion: seal friction's odd harmonics in the displacement, a
//! stiffening spring's third in the force. Per block of the record, a
//! harmonic counts where its power exceeds [`SIGNIFICANT`] times the noise
//! and the linear part together, within [`BINS`] of 2p or 3p, and not where
//! one converter step explains it; a signal with harmonics in
//! [`MIN_BLOCKS`] blocks is not linear. The test's derivation and its
//! false-alarm rate: docs/methods.md, "The linearity check".

use nalgebra::{Complex, SMatrix, SVector};

use super::{Detrend, SegmentTransform, Window, window};

/// Bins each side of a peak whose power is counted with it.
pub const BINS: usize = 4;
/// A harmonic's power over the noise and the linear part beyond which it is
/// distortion.
pub const SIGNIFICANT: f64 = 10.0;
/// The fewest blocks with a harmonic that make a signal not linear.
pub const MIN_BLOCKS: usize = 3;

const BLOCKS: usize = 32;
const MIN_BLOCK: usize = 64;

/// Harmonics found in one signal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Found {
    /// Blocks with a harmonic, of those checked.
    pub blocks: usize,
    /// The largest harmonic's amplitude over the signal's in its block (a
    /// fundamental that vanishes, at a specimen's resonance, would make a
    /// ratio to it meaningless), its order (2 or 3) and the fundamental's
    /// frequency (Hz) there.
    pub largest: f64,
    pub order: usize,
    pub at_hz: f64,
}

/// The check of one run's log.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Linearity {
    /// Blocks of the sweep the check could read (p above 2 `BINS` + 1, 3p
    /// and a floor below Nyquist).
    pub checked: usize,
    /// Harmonics in the displacement beyond the command's.
    pub displacement: Option<Found>,
    /// Harmonics in the force beyond the displacement's.
    pub force: Option<Found>,
}

impl Linearity {
    /// Whether either signal holds harmonics in at least [`MIN_BLOCKS`]
    /// blocks.
    pub fn nonlinear(&self) -> bool {
        [self.displacement, self.force]
            .iter()
            .flatten()
            .any(|f| f.blocks >= MIN_BLOCKS)
    }
}

/// The specimen's force over its displacement at a frequency (Hz), its
/// dynamic stiffness, for the force's check.
pub type Stiffness<'a> = &'a dyn Fn(f64) -> Complex<f64>;

/// The check of a sweep `u` -> `x` (and `force`, with the specimen's
/// dynamic stiffness: without it the force is not checked), sampled at
/// `sample_rate_hz`, whose converters' steps are `steps` (displacement,
/// force; 0 where a channel sits on no grid). None when the record is too
/// short for the blocks.
pub fn linearity(
    u: &[f64],
    x: &[f64],
    force: Option<(&[f64], Stiffness<'_>)>,
    sample_rate_hz: f64,
    steps: [f64; 2],
) -> Option<Linearity> {
    let n = u.len();
    if n / BLOCKS < MIN_BLOCK || x.len() != n || force.is_some_and(|(f, _)| f.len() != n) {
        return None;
    }
    let block = 1usize << (n / BLOCKS).ilog2();
    let start = |b: usize| b * (n - block) / (BLOCKS - 1);
    let df = sample_rate_hz / block as f64;
    let mut transform = SegmentTransform::new(block);
    let mut out = transform.make_output();
    let w = window(Window::BlackmanHarris, block);
    let mut power = |s: &[f64]| -> Vec<f64> {
        transform.run(s, Some(&w), Detrend::Mean, &mut out);
        out.iter().map(Complex::norm_sqr).collect()
    };
    let loudest = (0..BLOCKS)
        .map(|b| {
            let s = &u[start(b)..start(b) + block];
            let m = s.iter().sum::<f64>() / block as f64;
            s.iter().map(|v| (v - m).powi(2)).sum::<f64>()
        })
        .fold(0.0, f64::max);
    let mut checked = 0;
    let mut found: [Option<Found>; 2] = [None, None];
    for b in 0..BLOCKS {
        let range = start(b)..start(b) + block;
        let uu = power(&u[range.clone()]);
        if uu.iter().skip(1).sum::<f64>() < 1e-3 * loudest {
            continue;
        }
        let p = (1..uu.len())
            .max_by(|&a, &c| uu[a].total_cmp(&uu[c]))
            .unwrap_or(1);
        let floor_from = 4 * p + BINS + 1;
        if p <= 2 * BINS + 1 || floor_from + 16 > uu.len() {
            continue;
        }
        checked += 1;
        let xx = power(&x[range.clone()]);
        let ff = force.map(|(f, _)| power(&f[range.clone()]));
        let amplitude = |v: &[f64]| {
            let (lo, hi) = v
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &a| {
                    (lo.min(a), hi.max(a))
                });
            0.5 * (hi - lo)
        };
        // (signal, what drives it linearly, its amplitude in the block,
        // its linear gain's power at twice and three times the fundamental
        // over the fundamental's)
        let mut pairs = vec![(&xx, &uu, amplitude(&x[range.clone()]), [1.0, 1.0])];
        if let (Some(ff), Some((f, stiffness))) = (&ff, force) {
            let at = |h: usize| stiffness((h * p) as f64 * df).norm_sqr();
            let carried = [at(2) / at(1), at(3) / at(1)];
            pairs.push((ff, &xx, amplitude(&f[range.clone()]), carried));
        }
        for (k, (s, drive, a, gain)) in pairs.into_iter().enumerate() {
            let block = Block {
                signal: s,
                drive,
                fundamental: p,
                floor_from,
            };
            if let Some((ratio, h)) = block.harmonic(gain, a, steps[k]) {
                let f = found[k].get_or_insert(Found {
                    blocks: 0,
                    largest: 0.0,
                    order: h,
                    at_hz: p as f64 * df,
                });
                f.blocks += 1;
                if ratio > f.largest {
                    f.largest = ratio;
                    f.order = h;
                    f.at_hz = p as f64 * df;
                }
            }
        }
    }
    Some(Linearity {
        checked,
        displacement: found[0],
        force: found[1],
    })
}

/// One block's powers for the harmonic search: a signal, what drives it
/// linearly, the fundamental's bin and where the noise floor is read.
struct Block<'a> {
    signal: &'a [f64],
    drive: &'a [f64],
    fundamental: usize,
    floor_from: usize,
}

impl Block<'_> {
    /// The power in the band of `BINS` either side of bin `c`.
    fn band(s: &[f64], c: usize) -> f64 {
        s[c - BINS..=c + BINS].iter().sum()
    }

    /// The noise's power in a band, from the median of the bins above
    /// the harmonics (a chi-square with 2 degrees of freedom has its
    /// median at ln 2 times its mean).
    fn floor(&self) -> f64 {
        let mut tail = self.signal[self.floor_from..].to_vec();
        let mid = tail.len() / 2;
        *tail.select_nth_unstable_by(mid, f64::total_cmp).1 / std::f64::consts::LN_2
            * (2 * BINS + 1) as f64
    }

    /// The larger of the second and third harmonics beyond the noise and
    /// what the drive's own carry through the linear gain (`gain`: its
    /// power at twice and three times the fundamental over the
    /// fundamental's), as its share of the block's signal, with its
    /// order; None where neither shows, or where the share of the signal's
    /// amplitude `amplitude` is within the converter's `step`.
    fn harmonic(&self, gain: [f64; 2], amplitude: f64, step: f64) -> Option<(f64, usize)> {
        let (s, p) = (self.signal, self.fundamental);
        let (s1, d1) = (Self::band(s, p), Self::band(self.drive, p));
        if s1 <= 0.0 || d1 <= 0.0 {
            return None;
        }
        let noise = self.floor();
        let total: f64 = s.iter().skip(1).sum();
        let mut best: Option<(f64, usize)> = None;
        for h in [2, 3] {
            let linear = Self::band(self.drive, h * p) * s1 / d1 * gain[h - 2];
            let sh = Self::band(s, h * p);
            if sh > SIGNIFICANT * (noise + linear) && linear.is_finite() {
                // The harmonic's share of the block's signal, by its
                // power's share (a Blackman-Harris band of 9 bins holds a
                // line's power whole).
                let ratio = ((sh - noise - linear) / total).sqrt();
                if ratio * amplitude <= step {
                    continue;
                }
                if best.is_none_or(|(r, _)| ratio > r) {
                    best = Some((ratio, h));
                }
            }
        }
        best
    }
}

/// A spring's force against its displacement: f = k x + k3 x^3 + c x' +
/// m x'' + f0 by least squares over the record gives k, its stiffness at
/// rest (x' and x'' by central differences: the load cell's own delay
/// against the LVDT's, the spring's damping and its mass take them). The
/// cubic term k3 itself is fitted with the other four, and a drift in time,
/// taken apart in each of [`SEGMENTS`]
/// stretches of the record: along a sweep each stretch holds a narrow band,
/// where anything linear between the two signals (a sensor's delay or
/// filter, whose gain and phase change across the sweep) is a constant
/// gain and phase, so only the shape within each cycle, which a linear
/// path leaves alone, can carry k3. Fitted over the whole record at once, a
/// 3-sample delay or an 80 Hz filter on the LVDT, whose effect grows with
/// frequency while the displacement's amplitude falls, reads as a spring
/// 0.7-1 % stiffer at 3.5 mm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpringForce {
    /// The stiffness the force and displacement give (N/m).
    pub stiffness_n_per_m: f64,
    /// The cubic term (N/m^3) and its t statistic.
    pub cubic_n_per_m3: f64,
    pub cubic_t: f64,
    /// The largest displacement from the record's mean (m), and the
    /// secant stiffness there over k, less 1: how much the spring
    /// stiffens at the test's amplitude.
    pub amplitude_m: f64,
    pub stiffening: f64,
}

/// Beyond this stiffening at the test's amplitude, with a t statistic
/// beyond [`STIFFENING_T`], a spring is not linear: the simulated springs 2
/// and 5 % stiffer at 4 mm of `tests/joint.rs` read 1.4-1.7 % and 3.6-4.4 %
/// at their 3.4-3.8 mm (t = 53-247), their linear twins pass.
pub const STIFFENING: f64 = 0.005;
pub const STIFFENING_T: f64 = 10.0;

impl SpringForce {
    pub fn stiffens(&self) -> bool {
        self.stiffening.abs() > STIFFENING && self.cubic_t.abs() > STIFFENING_T
    }
}

/// [`SpringForce`] of displacement `x` (m) and force `f` (N) sampled at
/// `sample_rate_hz`; None when the two differ in length, are too short or
/// the columns are degenerate.
pub fn spring_force(x: &[f64], f: &[f64], sample_rate_hz: f64) -> Option<SpringForce> {
    let n = x.len();
    if n != f.len() || n < 16 * SEGMENTS || sample_rate_hz.is_nan() || sample_rate_hz <= 0.0 {
        return None;
    }
    let mean = x.iter().sum::<f64>() / n as f64;
    let amplitude = x.iter().map(|v| (v - mean).abs()).fold(0.0, f64::max);
    if amplitude.is_nan() || amplitude <= 0.0 {
        return None;
    }
    // Columns in units of the amplitude and the sample interval, so that
    // each is of order one.
    let column = |i: usize| -> [f64; 5] {
        let z = (x[i] - mean) / amplitude;
        let v = (x[i + 1] - x[i - 1]) / (2.0 * amplitude);
        let a = (x[i + 1] - 2.0 * x[i] + x[i - 1]) / amplitude;
        [z, z * z * z, v, a, 1.0]
    };
    let mut ata = SMatrix::<f64, 5, 5>::zeros();
    let mut atb = SVector::<f64, 5>::zeros();
    for (i, &fi) in f.iter().enumerate().take(n - 1).skip(1) {
        let c = SVector::<f64, 5>::from(column(i));
        ata += c * c.transpose();
        atb += c * fi;
    }
    let chol = ata.cholesky()?;
    let theta = chol.solve(&atb);
    let k = theta[0] / amplitude;
    let (cubic, cubic_t) = segmented_cubic(f, n, &column)?;
    Some(SpringForce {
        stiffness_n_per_m: k,
        cubic_n_per_m3: cubic / amplitude.powi(3),
        cubic_t,
        amplitude_m: amplitude,
        stiffening: cubic / theta[0],
    })
}

/// Where a command moves slowly the actuator follows it through a gain
/// that is nearly flat in frequency, x = g0 u + g1 u' + g2 u'' + g3 u'''
/// (the rig's x1/u to third order in s), whatever the rig and its
/// specimen. A channel that reads the displacement through a cubic, x (1 +
/// e (x/A)^2), adds e u^3 / A^2 there: in phase with u at three times its
/// frequency, which no linear term holds (friction's distortion follows
/// the velocity's sign, a quarter period away). The fit over the record's
/// slow stretches (each window of 1 / [`SLOW_HZ`] whose command's
/// frequency, the RMS of u' over 2 pi the RMS of u about its centre, is
/// below `SLOW_HZ`) gives e with its t statistic.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SlowCubic {
    /// The gain's change at the command's amplitude (a share: 0.003 is
    /// 0.3 %), its t statistic, the amplitude (m) and the seconds fitted.
    pub share: f64,
    pub t: f64,
    pub amplitude_m: f64,
    pub seconds: f64,
}

/// The command's frequency below which a stretch counts as slow (Hz).
pub const SLOW_HZ: f64 = 0.5;
/// Beyond this share and t statistic a cubic in the slow stretches is the
/// reading's, not noise: on the paper's rig at 18 bits the clean sweep's
/// share is 3e-4 (t 6, what the third-order expansion leaves), a 0.3 %
/// cubic's 2.9e-3 (t 57).
pub const SLOW_CUBIC_SHARE: f64 = 1e-3;
pub const SLOW_CUBIC_T: f64 = 10.0;

impl SlowCubic {
    pub fn significant(&self) -> bool {
        self.share.abs() > SLOW_CUBIC_SHARE && self.t.abs() > SLOW_CUBIC_T
    }
}

/// The command's derivatives are differences over this span (s): at 1 kHz
/// a converter's step differenced over one sample is larger than u'' of a
/// 0.5 Hz sweep, and the span's own error is (w h)^2 / 12, 2e-4 at 0.5 Hz.
const SLOW_SPAN_S: f64 = 1.0 / (40.0 * SLOW_HZ);
/// What the start of motion leaves to decay before the slow fit starts
/// (s): a sweep starts from rest with its full slope, and the rig's
/// transient is no polynomial in u.
const SLOW_ONSET_S: f64 = 1.0 / (2.0 * SLOW_HZ);

/// [`SlowCubic`] of the displacement `x` against its command `u`, sampled
/// at `sample_rate_hz`; None with fewer than two slow windows or a
/// degenerate fit.
pub fn slow_cubic(u: &[f64], x: &[f64], sample_rate_hz: f64) -> Option<SlowCubic> {
    let n = u.len();
    let h = (SLOW_SPAN_S * sample_rate_hz).round() as usize;
    let w = (sample_rate_hz / SLOW_HZ).round() as usize;
    if x.len() != n || h < 2 || n < 2 * w {
        return None;
    }
    let rms = |v: &mut dyn Iterator<Item = f64>| {
        let (s, k) = v.fold((0.0, 0usize), |(s, k), a| (s + a * a, k + 1));
        (s / k.max(1) as f64).sqrt()
    };
    let (lo, hi) = u
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
            (l.min(v), h.max(v))
        });
    if hi <= lo {
        return None;
    }
    let centre = u.iter().sum::<f64>() / n as f64;
    let amplitude = (hi - centre).max(centre - lo);
    let onset = u.iter().position(|v| (v - u[0]).abs() > 0.01 * (hi - lo))?
        + (SLOW_ONSET_S * sample_rate_hz).round() as usize;
    let first = onset.max(2 * h);
    let derivative = |k: usize| 0.5 * (u[k + h] - u[k - h]) / h as f64;
    // A corner (a command limited or held, a step) is no polynomial in the
    // derivatives, nor is the rig's settling after it: a window is taken
    // where the command's second differences stay within twice a sine's
    // at SLOW_HZ, (w h)^2 of the amplitude.
    let bend = 2.0 * (2.0 * std::f64::consts::PI * SLOW_HZ * h as f64 / sample_rate_hz).powi(2);
    let smooth = |j: usize| ((u[j + h] - 2.0 * u[j] + u[j - h]) / amplitude).abs() <= bend;
    let slow: Vec<std::ops::Range<usize>> = (0..n.saturating_sub(first) / w)
        .map(|c| first + c * w..(first + (c + 1) * w).min(n - 2 * h))
        .filter(|r| {
            let level = rms(&mut u[r.clone()].iter().map(|v| v - centre));
            let speed = rms(&mut r.clone().map(derivative)) * sample_rate_hz;
            level > 0.0
                && speed < 2.0 * std::f64::consts::PI * SLOW_HZ * level
                && r.clone().all(smooth)
        })
        .collect();
    if slow.len() < 2 {
        return None;
    }
    // Columns in units of the amplitude and the span.
    let column = |k: usize| -> [f64; 7] {
        let v = |j: isize| (u[k.wrapping_add_signed(j * h as isize)] - centre) / amplitude;
        let z = v(0);
        [
            1.0,
            k as f64 / n as f64,
            z,
            0.5 * (v(1) - v(-1)),
            v(1) - 2.0 * z + v(-1),
            0.5 * (v(2) - 2.0 * v(1) + 2.0 * v(-1) - v(-2)),
            z * z * z,
        ]
    };
    let mut ata = SMatrix::<f64, 7, 7>::zeros();
    let mut atb = SVector::<f64, 7>::zeros();
    let (mut btb, mut rows) = (0.0, 0usize);
    for k in slow.iter().flat_map(|r| r.clone()) {
        let c = SVector::<f64, 7>::from(column(k));
        let y = (x[k] - centre) / amplitude;
        ata += c * c.transpose();
        atb += c * y;
        btb += y * y;
        rows += 1;
    }
    if rows < 2 * w {
        return None;
    }
    let chol = ata.cholesky()?;
    let theta = chol.solve(&atb);
    let rss = (btb - 2.0 * theta.dot(&atb) + theta.dot(&(ata * theta))).max(0.0);
    let sigma2 = rss / (rows as f64 - 7.0);
    let mut unit = SVector::<f64, 7>::zeros();
    unit[6] = 1.0;
    let var = chol.solve(&unit)[6] * sigma2;
    let gain = theta[2];
    (gain.abs() > 0.0 && var > 0.0).then(|| SlowCubic {
        share: theta[6] / gain,
        t: theta[6] / var.sqrt(),
        amplitude_m: amplitude,
        seconds: rows as f64 / sample_rate_hz,
    })
}

/// Stretches of the record the cubic term's fit takes the linear terms
/// apart in.
pub const SEGMENTS: usize = 16;

/// The cubic term (in `column`'s units) and its t statistic, with each
/// stretch's linear terms and drift its own ([`SpringForce`]): the normal
/// equations of (k_j, c_j, m_j, f0_j, d_j) per stretch j and one k3.
fn segmented_cubic(f: &[f64], n: usize, column: &dyn Fn(usize) -> [f64; 5]) -> Option<(f64, f64)> {
    const PER: usize = 5;
    let p = PER * SEGMENTS + 1;
    let cubic = p - 1;
    let mut ata = nalgebra::DMatrix::<f64>::zeros(p, p);
    let mut atb = nalgebra::DVector::<f64>::zeros(p);
    let mut btb = 0.0;
    let rows = n - 2;
    for (i, &fi) in f.iter().enumerate().take(n - 1).skip(1) {
        let j = (i - 1) * SEGMENTS / rows;
        let [z, z3, v, a, _] = column(i);
        // Time within the stretch, about -1/2 to 1/2.
        let t = ((i - 1) * SEGMENTS) as f64 / rows as f64 - j as f64 - 0.5;
        let entries = [
            (PER * j, z),
            (PER * j + 1, v),
            (PER * j + 2, a),
            (PER * j + 3, 1.0),
            (PER * j + 4, t),
            (cubic, z3),
        ];
        for &(r, vr) in &entries {
            atb[r] += vr * fi;
            for &(c, vc) in &entries {
                ata[(r, c)] += vr * vc;
            }
        }
        btb += fi * fi;
    }
    // Each column scaled to a unit diagonal: a slow stretch's x'' is some
    // 1e-7 of its x, which Cholesky would otherwise lose. A column that is
    // zero throughout (a stretch at rest) is dropped.
    let scale = nalgebra::DVector::from_fn(p, |i, _| match ata[(i, i)] {
        d if d > 0.0 => 1.0 / d.sqrt(),
        _ => 0.0,
    });
    let mut scaled = ata.clone();
    for r in 0..p {
        for c in 0..p {
            scaled[(r, c)] *= scale[r] * scale[c];
        }
        if scale[r] == 0.0 {
            scaled[(r, r)] = 1.0;
        }
    }
    let chol = scaled.cholesky()?;
    let theta = chol.solve(&atb.component_mul(&scale)).component_mul(&scale);
    let rss = (btb - 2.0 * theta.dot(&atb) + theta.dot(&(&ata * &theta))).max(0.0);
    let sigma2 = rss / (rows as f64 - p as f64);
    // The cubic's diagonal element of the inverse, from one solve.
    let mut unit = nalgebra::DVector::<f64>::zeros(p);
    unit[cubic] = 1.0;
    let var = chol.solve(&unit)[cubic] * scale[cubic] * scale[cubic] * sigma2;
    Some((theta[cubic], theta[cubic] / var.sqrt()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::Draws;

    /// A quadratic chirp 1-40 Hz over 30 s at 1 kHz, amplitude `a`.
    fn sweep(a: f64) -> Vec<f64> {
        (0..30_000)
            .map(|i| {
                let t = i as f64 / 1000.0;
                a * (2.0 * std::f64::consts::PI * (t + 39.0 * t * t * t / (3.0 * 900.0))).sin()
            })
            .collect()
    }

    /// A linear response holds no harmonics; one through a cubic holds the
    /// third at the ratio the cubic's Fourier series gives: for
    /// x + e x^3 with x = A sin, the third harmonic is e A^3 / 4 over a
    /// fundamental of A + 3 e A^3 / 4.
    #[test]
    fn a_cubic_shows_its_third_harmonic_and_a_line_none() {
        let u = sweep(1.0);
        let mut rng = Draws::new(3, "linearity tests");
        let noisy = |x: &[f64], rng: &mut Draws| -> Vec<f64> {
            x.iter().map(|v| v + 1e-4 * rng.normal()).collect()
        };
        let linear = noisy(&u.iter().map(|v| 0.8 * v).collect::<Vec<_>>(), &mut rng);
        let l = linearity(&u, &linear, None, 1000.0, [0.0; 2]).unwrap();
        assert!(l.checked > 10, "{l:?}");
        assert!(!l.nonlinear() && l.displacement.is_none(), "{l:?}");
        let e = 0.04;
        let cubic: Vec<f64> = u.iter().map(|v| v + e * v * v * v).collect();
        let l = linearity(&u, &noisy(&cubic, &mut rng), None, 1000.0, [0.0; 2]).unwrap();
        assert!(l.nonlinear(), "{l:?}");
        let found = l.displacement.unwrap();
        assert_eq!(found.order, 3);
        let want = (e / 4.0) / (1.0 + 3.0 * e / 4.0);
        assert!(
            (found.largest / want - 1.0).abs() < 0.05,
            "{} vs {want}",
            found.largest
        );
    }

    /// A quadratic chirp from 0.1 Hz through a linear lag x = u(t - 20 ms)
    /// (its slow seconds see a gain and a phase) read by an LVDT with a
    /// cubic, x (1 + 0.003 (x / A)^2): the slow fit gives the 0.3 % back;
    /// the same without the cubic gives none.
    #[test]
    fn a_sensors_cubic_shows_where_the_command_is_slow() {
        let (fs, a) = (1000.0, 0.004);
        let command = |t: f64| {
            if t < 1.0 {
                0.0
            } else {
                let s = t - 1.0;
                a * (2.0
                    * std::f64::consts::PI
                    * (0.1 * s + 34.9 * s * s * s / (3.0 * 58.0 * 58.0)))
                    .sin()
            }
        };
        let mut rng = Draws::new(8, "slow cubic");
        let t: Vec<f64> = (0..60_000).map(|i| i as f64 / fs).collect();
        let u: Vec<f64> = t.iter().map(|&t| command(t)).collect();
        let linear: Vec<f64> = t
            .iter()
            .map(|&t| command(t - 0.02) + 2e-6 * rng.normal())
            .collect();
        let cubic: Vec<f64> = linear
            .iter()
            .map(|&x| x * (1.0 + 0.003 * (x / a).powi(2)))
            .collect();
        let clean = slow_cubic(&u, &linear, fs).unwrap();
        assert!(!clean.significant(), "{clean:?}");
        let found = slow_cubic(&u, &cubic, fs).unwrap();
        assert!(found.significant(), "{found:?}");
        assert!((found.share / 0.003 - 1.0).abs() < 0.1, "{found:?}");
        assert!(found.seconds > 2.0, "{found:?}");
    }

    /// A linear spring logged through a sensor that is not the load cell's
    /// twin: the LVDT 3 samples late, drifting 2 um/s, on a sweep whose
    /// amplitude falls with frequency as an actuator's does (4 mm at 1 Hz,
    /// half of it at 15 Hz). The force is k times the true displacement;
    /// nothing in it grows faster than the displacement, and the fit says
    /// so, finding k within 0.5 %.
    #[test]
    fn a_delayed_drifting_lvdt_is_not_a_stiffening_spring() {
        let (fs, k, tau, drift) = (1000.0, 116_640.0, 3e-3, 2e-6);
        let displacement = |t: f64| {
            let f = 1.0 + 39.0 * t * t / 900.0;
            let phase = 2.0 * std::f64::consts::PI * (t + 39.0 * t * t * t / (3.0 * 900.0));
            0.004 / (1.0 + (f / 15.0).powi(2) * 3.0).sqrt() * phase.sin()
        };
        let mut rng = Draws::new(5, "linearity tests");
        let times: Vec<f64> = (0..30_000).map(|i| i as f64 / fs).collect();
        let f: Vec<f64> = times
            .iter()
            .map(|&t| k * displacement(t) + rng.normal())
            .collect();
        let x: Vec<f64> = times
            .iter()
            .map(|&t| displacement(t - tau) + drift * t)
            .collect();
        let s = spring_force(&x, &f, fs).unwrap();
        assert!(!s.stiffens(), "{s:?}");
        assert!(s.stiffening.abs() < STIFFENING, "{s:?}");
        assert!((s.stiffness_n_per_m / k - 1.0).abs() < 5e-3, "{s:?}");
    }

    /// A spring's force f = k x + k3 x^3 with noise gives k and k3 back,
    /// and its stiffening at the amplitude, k3 A^2 / k; a linear spring's
    /// does not stiffen.
    #[test]
    fn a_springs_force_gives_its_stiffness_and_stiffening() {
        let x: Vec<f64> = sweep(0.004);
        let mut rng = Draws::new(4, "linearity tests");
        let (k, k3) = (116_640.0, 3.6e8);
        let f: Vec<f64> = x
            .iter()
            .map(|v| k * v + k3 * v * v * v + rng.normal())
            .collect();
        let s = spring_force(&x, &f, 1000.0).unwrap();
        assert!((s.stiffness_n_per_m / k - 1.0).abs() < 1e-3, "{s:?}");
        assert!((s.cubic_n_per_m3 / k3 - 1.0).abs() < 0.02, "{s:?}");
        // The amplitude about the record's mean, as the fit reads it.
        let mean = x.iter().sum::<f64>() / x.len() as f64;
        let a = x.iter().fold(0.0_f64, |m, v| m.max((v - mean).abs()));
        assert!((s.amplitude_m / a - 1.0).abs() < 1e-12);
        assert!((s.stiffening - k3 * a * a / k).abs() < 1e-3, "{s:?}");
        assert!(s.stiffens());
        let f: Vec<f64> = x.iter().map(|v| k * v + rng.normal()).collect();
        let s = spring_force(&x, &f, 1000.0).unwrap();
        assert!(!s.stiffens(), "{s:?}");
        assert!((s.stiffness_n_per_m / k - 1.0).abs() < 1e-3, "{s:?}");
    }
}
