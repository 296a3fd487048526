//! A periodic command's steady periods (`steady_periods`): where the
//! command repeats itself sample for sample, between the rests and the
//! fades a designed multisine has. Over whole steady periods the response
//! is periodic too, so its transforms hold only lines. Averaging the
//! periods gives each line's noise from their spread, and the lines the
//! command leaves empty show the rig's nonlinear distortion above it
//! (`levels`; Pintelon & Schoukens 2012, Secs. 3.4 and 4.3).

use rustfft::num_complex::Complex;

use crate::fft::real_spectrum;

/// A steady sample repeats a period later to this share of the command's
/// RMS at the least (a generated command repeats exactly), or to
/// [`NOISE_MULTIPLE`] times the median difference a period apart where the
/// logged command carries noise.
const REPEAT_FLOOR: f64 = 1e-9;
const NOISE_MULTIPLE: f64 = 8.0;

/// The steady stretch's RMS against the command's, at least: a rest longer
/// than a period repeats itself too.
const MIN_STRETCH_RMS: f64 = 0.3;

/// The correlation of the command with itself a period later, at least:
/// a prefilter only (a multisine's fades and rests lower it, to 0.9 for
/// six steady periods of eight); the exact repetition decides.
const MIN_CORRELATION: f64 = 0.5;

/// A line is empty where its power is below this share of the largest
/// line's.
const EMPTY_LINE: f64 = 1e-8;

/// The stretch of a command made of whole periods that repeat exactly.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Steady {
    /// Its first sample.
    pub start: usize,
    /// The period (samples).
    pub period: usize,
    /// Whole periods from `start`, at least 2.
    pub count: usize,
}

/// The command's steady periods, if it has two or more: the period is
/// the lag of at least `min_period_s` at which the command best matches
/// itself, and the stretch the longest run of samples each equal to the
/// one a period later.
pub fn steady_periods(u: &[f64], sample_rate_hz: f64, min_period_s: f64) -> Option<Steady> {
    let n = u.len();
    let min_lag = ((min_period_s * sample_rate_hz).ceil() as usize).max(2);
    if n < 2 * min_lag + 1 {
        return None;
    }
    let rms = (u.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
    if !(rms > 0.0 && rms.is_finite()) {
        return None;
    }
    let period = period_of(u, min_lag)?;
    // The median difference a period apart, over at most SCAN samples.
    let stride = (n - period).div_ceil(SCAN).max(1);
    let mut differences: Vec<f64> = (0..n - period)
        .step_by(stride)
        .map(|j| (u[j + period] - u[j]).abs())
        .collect();
    let middle = differences.len() / 2;
    let median = *differences.select_nth_unstable_by(middle, f64::total_cmp).1;
    let tolerance = (REPEAT_FLOOR * rms).max(NOISE_MULTIPLE * median);
    // The runs of j with u[j + period] = u[j]: samples j..j+period of a
    // run repeat. The longest whose periods move, not a rest, is steady.
    let mut runs = Vec::new();
    let mut run_start = None;
    for j in 0..=n - period {
        let repeats = j < n - period && (u[j + period] - u[j]).abs() <= tolerance;
        match (repeats, run_start) {
            (true, None) => run_start = Some(j),
            (false, Some(first)) => {
                runs.push((first, j));
                run_start = None;
            }
            _ => {}
        }
    }
    runs.sort_by_key(|&(first, end)| std::cmp::Reverse(end - first));
    runs.into_iter().find_map(|(first, end)| {
        let len = end - first + period;
        let count = len / period;
        // Where the stretch reaches into a fade at either end (the ramp
        // within the tolerance of 1), the periods are centred in it.
        let start = first + (len - count * period) / 2;
        let stretch = &u[start..start + count * period];
        let stretch_rms =
            (stretch.iter().map(|v| v * v).sum::<f64>() / stretch.len() as f64).sqrt();
        (count >= 2 && stretch_rms >= MIN_STRETCH_RMS * rms).then_some(Steady {
            start,
            period,
            count,
        })
    })
}

/// The most samples the period's search transforms or scans: a long log's
/// command is searched on every D-th sample (D the least that leaves at
/// most this many), so that the search's memory stays a few tens of MB
/// whatever the log's length.
const SCAN: usize = 1 << 19;

/// The command's period (samples): the best lag of every D-th sample
/// ([`best_lag`]), then the lag within D of it, D times that, at which the
/// most of (at most [`SCAN`]) samples repeat to the last bit or, failing
/// that, differ least.
fn period_of(u: &[f64], min_lag: usize) -> Option<usize> {
    let n = u.len();
    let d = n.div_ceil(SCAN).max(1);
    let coarse: Vec<f64> = u.iter().step_by(d).copied().collect();
    let lag = best_lag(&coarse, (min_lag / d).max(2))? * d;
    let lags = lag.saturating_sub(d).max(min_lag)..=(lag + d).min(n / 2);
    let score = |l: usize| -> (usize, f64) {
        let stride = (n - l).div_ceil(SCAN).max(1);
        let (mut equal, mut sum) = (0usize, 0.0);
        for j in (0..n - l).step_by(stride) {
            let e = (u[j + l] - u[j]).abs();
            equal += usize::from(e == 0.0);
            sum += e;
        }
        (equal, sum)
    };
    let mut best: Option<(usize, usize, f64)> = None;
    for l in lags {
        let (equal, sum) = score(l);
        // More exact repeats first, then the smaller total difference; the
        // shorter lag on a tie.
        if best.is_none_or(|(_, e, s)| equal > e || (equal == e && sum < s)) {
            best = Some((l, equal, sum));
        }
    }
    let (period, equal, sum) = best?;
    // A period the coarse search cannot see (an odd one searched on every
    // second sample) shows as a multiple of it: the shortest divisor that
    // repeats as well is the period.
    let divisor = (2..=period / min_lag.max(1))
        .filter(|k| period % k == 0)
        .map(|k| period / k)
        .filter(|&l| {
            let (e, s) = score(l);
            e >= equal && s <= 1.05 * sum
        })
        .min();
    Some(divisor.unwrap_or(period))
}

/// The lag of at least `min_lag` (and at most half the record) with the
/// highest normalised correlation: of the correlation's peaks within 1e-3
/// of the highest, the shortest (a period's multiples correlate as well),
/// if it reaches [`MIN_CORRELATION`]. Peaks, not lags: a command sampled
/// far above its lines correlates within 1e-3 of the top a sample or two
/// off the period too.
fn best_lag(u: &[f64], min_lag: usize) -> Option<usize> {
    let n = u.len();
    let m = (2 * n).next_power_of_two();
    let mut padded = u.to_vec();
    padded.resize(m, 0.0);
    let forward = crate::fft::real_forward(m);
    let mut power = forward.make_output_vec();
    forward
        .process(&mut padded, &mut power)
        .expect("a buffer of the padded length");
    for c in &mut power {
        *c = Complex::new(c.norm_sqr(), 0.0);
    }
    // The transform's input is scratch after it: it takes the correlation.
    let r = &mut padded;
    crate::fft::real_inverse(m)
        .process(&mut power, r)
        .expect("a half spectrum of the padded length");
    let r = &*r;
    // Energies of the overlapping parts, for the normalisation.
    let mut head = vec![0.0; n + 1];
    for (j, v) in u.iter().enumerate() {
        head[j + 1] = head[j] + v * v;
    }
    let corr = |lag: usize| -> f64 {
        let a = head[n - lag];
        let b = head[n] - head[lag];
        // r[lag] is m times the correlation (the inverse is unnormalised).
        r[lag] / m as f64 / (a * b).sqrt().max(f64::MIN_POSITIVE)
    };
    let lags = min_lag..=n / 2;
    let top = lags.clone().map(corr).fold(f64::MIN, f64::max);
    if top < MIN_CORRELATION {
        return None;
    }
    let peak = |l: usize| {
        let c = corr(l);
        (l == min_lag || c >= corr(l - 1)) && (l == n / 2 || c >= corr(l + 1))
    };
    lags.into_iter().find(|&l| corr(l) >= top - 1e-3 && peak(l))
}

/// What a periodic log's periods say of its displacement over a band.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Levels {
    /// Lines the command excites in the band, and lines it leaves empty.
    pub excited: usize,
    pub empty: usize,
    /// The mean power (m^2, of each period's transform over its length)
    /// of the averaged periods' displacement at the excited lines: the
    /// output.
    pub output: f64,
    /// The mean variance (m^2) of the averaged periods' displacement at a
    /// line, from the periods' spread: the noise floor.
    pub noise: f64,
    /// The mean power (m^2) of the averaged periods' displacement at the
    /// empty lines: the noise floor where the rig is linear, more where it
    /// distorts.
    pub empty_power: f64,
    /// The noise floor (m^2) at the empty lines alone.
    pub empty_noise: f64,
}

impl Levels {
    /// The empty lines' power over the noise floor: 1 within its scatter,
    /// 1 +- 1 / sqrt(empty), for a linear rig.
    pub fn distortion_to_noise(&self) -> f64 {
        self.empty_power / self.empty_noise
    }
}

/// The levels of `y` over `steady`'s periods of `u`, at the lines (of
/// 1 / period) in `band_hz`.
pub fn levels(
    u: &[f64],
    y: &[f64],
    steady: Steady,
    sample_rate_hz: f64,
    band_hz: (f64, f64),
) -> Option<Levels> {
    let p = steady.period;
    // Each period's transform over its length: a line of amplitude A has
    // magnitude A / 2.
    let blocks = |x: &[f64]| -> Vec<Vec<Complex<f64>>> {
        (0..steady.count)
            .map(|m| {
                real_spectrum(&x[steady.start + m * p..steady.start + (m + 1) * p])
                    .iter()
                    .map(|c| c / p as f64)
                    .collect()
            })
            .collect()
    };
    let (us, ys) = (blocks(u), blocks(y));
    let count = steady.count as f64;
    let lines: Vec<usize> = (1..=p / 2)
        .filter(|&k| {
            let f = k as f64 * sample_rate_hz / p as f64;
            f >= band_hz.0 && f <= band_hz.1
        })
        .collect();
    let mean_at =
        |s: &[Vec<Complex<f64>>], k: usize| s.iter().map(|b| b[k]).sum::<Complex<f64>>() / count;
    let input: Vec<f64> = lines.iter().map(|&k| mean_at(&us, k).norm_sqr()).collect();
    let top = input.iter().copied().fold(0.0, f64::max);
    if top <= 0.0 {
        return None;
    }
    let (mut output, mut noise, mut empty_noise, mut empty_power) = (0.0, 0.0, 0.0, 0.0);
    let (mut excited, mut empty) = (0usize, 0usize);
    for (&k, &uk) in lines.iter().zip(&input) {
        let mean = mean_at(&ys, k);
        // The variance of the mean of `count` periods.
        let spread =
            ys.iter().map(|b| (b[k] - mean).norm_sqr()).sum::<f64>() / (count - 1.0) / count;
        noise += spread;
        if uk >= EMPTY_LINE * top {
            excited += 1;
            output += mean.norm_sqr();
        } else {
            empty += 1;
            empty_power += mean.norm_sqr();
            empty_noise += spread;
        }
    }
    (excited > 0 && empty > 0 && empty_noise > 0.0).then(|| Levels {
        excited,
        empty,
        output: output / excited as f64,
        noise: noise / lines.len() as f64,
        empty_power: empty_power / empty as f64,
        empty_noise: empty_noise / empty as f64,
    })
}

#[cfg(test)]
mod tests;
