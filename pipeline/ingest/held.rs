//! A channel that holds one value while it should move: a stuck sensor, a
//! dropout to zero, a DAQ that stalled and repeated its last sample on
//! every channel. A channel of a moving test holds a value exactly only
//! where its converter's step hides the motion (a coarse code at rest, at a
//! slow crest) or where its command holds too (a step); it approaches and
//! leaves the value slowly, by a code. A stuck or dropped channel moves on
//! both sides of the stretch at a speed that would have carried it many
//! codes over the stretch, or leaves the value by a jump the signal's own
//! motion around it does not make.
//!
//! The command is not judged alone: a step or a random excitation after a
//! rest holds and then jumps as the test intends, and the logged command is
//! what the valve received. It counts only with the others: every channel
//! holding at once is the DAQ's stall.

use super::quantisation::quantum_step;

/// The fewest equal samples in a row taken as a held stretch (shorter ones
/// are the spike scan's, `ingest::spikes`).
pub const MIN_HELD: usize = 8;
/// A jump into or out of a held stretch beyond this many times the
/// channel's median sample-to-sample change around it is not the signal's
/// own: a sine's largest change is 1.4 times its median, Gaussian noise's
/// about 5 times over a few hundred samples.
pub const JUMP: f64 = 10.0;
/// Nor is a jump of fewer than this many converter steps (a coarse code
/// leaving its value).
pub const JUMP_STEPS: f64 = 3.0;
/// A channel that moves by more than this many converter steps on both
/// sides of a held stretch, each over half the stretch's length (4 to
/// [`SPEED_WINDOW`] samples) next to it, is stuck. A smooth crest held
/// within one code for L samples lies within 4 codes of its top L samples
/// away (its distance from the crest grows with the square of time), so the
/// half-length beside the hold moves it at most 3 or 4 codes.
pub const MOTION_STEPS: f64 = 6.0;
/// The most samples each side of a stretch its motion is read over.
const SPEED_WINDOW: usize = 16;
/// The changes around a stretch its local scale is the median of, each side.
const AROUND: usize = 256;

/// One held stretch.
#[derive(Debug, Clone, PartialEq)]
pub struct Held {
    /// Its first sample (0-based) and its length.
    pub start: usize,
    pub len: usize,
    pub value: f64,
    /// Why it is not the signal's own: the largest jump into or out of it
    /// over the local scale (0 when the motion around shows it), and the
    /// slower of the channel's speeds on either side, per sample.
    pub jump_ratio: f64,
    pub speed: f64,
}

/// A channel's converter step, or the smallest change between its samples
/// where it has no grid, and no less than 1e-12 of its peak: the least a
/// jump is measured against.
fn floor_step(x: &[f64]) -> f64 {
    let step = quantum_step(x).unwrap_or_else(|| {
        x.windows(2)
            .map(|w| (w[1] - w[0]).abs())
            .filter(|d| *d > 0.0)
            .fold(f64::INFINITY, f64::min)
    });
    let step = if step.is_finite() { step } else { 0.0 };
    let peak = x.iter().map(|v| v.abs()).fold(0.0, f64::max);
    step.max(1e-12 * peak)
}

/// The runs of at least [`MIN_HELD`] equal samples of `x`, as (start, len).
fn runs(x: &[f64]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut start = 0;
    for i in 1..=x.len() {
        if i == x.len() || x[i] != x[start] {
            if i - start >= MIN_HELD {
                out.push((start, i - start));
            }
            start = i;
        }
    }
    out
}

/// The median |x(k+1) - x(k)| over up to [`AROUND`] changes each side of
/// the stretch `start..end`.
fn scale_around(x: &[f64], start: usize, end: usize) -> f64 {
    let mut d: Vec<f64> = Vec::with_capacity(2 * AROUND);
    let lo = start.saturating_sub(AROUND);
    d.extend(x[lo..start].windows(2).map(|w| (w[1] - w[0]).abs()));
    let hi = (end + AROUND).min(x.len());
    if end < hi {
        d.extend(x[end..hi].windows(2).map(|w| (w[1] - w[0]).abs()));
    }
    if d.is_empty() {
        return 0.0;
    }
    let mid = d.len() / 2;
    *d.select_nth_unstable_by(mid, f64::total_cmp).1
}

/// The channel's motion over half the stretch `start..end` (4 to
/// [`SPEED_WINDOW`] samples) next to it on each side, and that window's
/// length: the smaller of the two (0 at a record's end).
fn motion_around(x: &[f64], start: usize, end: usize) -> (f64, usize) {
    let w = ((end - start) / 2).clamp(4, SPEED_WINDOW);
    if start < w + 1 || end + w >= x.len() {
        return (0.0, w);
    }
    let before = (x[start - 1] - x[start - 1 - w]).abs();
    let after = (x[end + w] - x[end]).abs();
    (before.min(after), w)
}

/// The held stretches of `x` that are not the signal's own: those it
/// enters or leaves by a jump, and those the channel moves fast on both
/// sides of.
pub fn find(x: &[f64]) -> Vec<Held> {
    let candidates = runs(x);
    if candidates.is_empty() {
        return Vec::new();
    }
    let step = floor_step(x);
    let mut out = Vec::new();
    for (start, len) in candidates {
        let end = start + len;
        let value = x[start];
        let entry = if start > 0 {
            (value - x[start - 1]).abs()
        } else {
            0.0
        };
        let exit = if end < x.len() {
            (x[end] - value).abs()
        } else {
            0.0
        };
        let (motion, window) = motion_around(x, start, end);
        let moving = motion > MOTION_STEPS * step;
        let jump = entry.max(exit);
        let jump_ratio = if jump > JUMP_STEPS * step {
            jump / scale_around(x, start, end).max(step)
        } else {
            0.0
        };
        if moving || jump_ratio > JUMP {
            out.push(Held {
                start,
                len,
                value,
                jump_ratio: if jump_ratio > JUMP { jump_ratio } else { 0.0 },
                speed: motion / window as f64,
            });
        }
    }
    out
}

/// Whether `x` holds one value over most (nine tenths) of `start..start +
/// len`: a channel frozen with another.
pub fn holds_over(x: &[f64], start: usize, len: usize) -> bool {
    let end = (start + len).min(x.len());
    if start >= end {
        return false;
    }
    runs(&x[start..end])
        .iter()
        .any(|&(_, l)| l as f64 >= 0.9 * (end - start) as f64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ingest::test_signals::sweep;

    fn quantise(x: &[f64], q: f64) -> Vec<f64> {
        x.iter().map(|v| (v / q).round() * q).collect()
    }

    /// A displacement that follows its sweep, however coarse its
    /// converter (10 bits over +-50 mm), with rests before and after that
    /// hold one code, holds nothing the test does not explain.
    #[test]
    fn a_coarse_channel_at_rest_and_in_motion_is_not_held() {
        let mut u = vec![0.0; 1000];
        u.extend(sweep(30_000));
        u.extend(vec![0.0; 1000]);
        let x = quantise(&u.iter().map(|v| 0.9 * v).collect::<Vec<_>>(), 0.1 / 1024.0);
        assert!(runs(&x).len() > 10, "a coarse code holds often");
        assert_eq!(find(&x), Vec::new());
        // A square wave's displacement rests while the command holds.
        let sq: Vec<f64> = (0..8000)
            .map(|i| if (i / 1000) % 2 == 0 { 0.002 } else { -0.002 })
            .collect();
        let mut y = vec![0.0; 8000];
        for i in 1..8000 {
            y[i] = y[i - 1] + 0.05 * (sq[i] - y[i - 1]);
        }
        assert_eq!(find(&quantise(&y, 0.1 / 1024.0)), Vec::new());
    }

    /// A sensor stuck for 2 s in the sweep is found by the motion around
    /// it, with its place; a 50-sample dropout to zero by its jumps.
    #[test]
    fn a_stuck_sensor_and_a_dropout_are_found() {
        let u = sweep(40_000);
        let mut x: Vec<f64> = u.iter().map(|v| 0.9 * v).collect();
        let held = x[20_000];
        for v in &mut x[20_000..22_000] {
            *v = held;
        }
        let found = find(&x);
        assert_eq!(found.len(), 1, "{found:?}");
        assert_eq!((found[0].start, found[0].len), (20_000, 2000));
        assert!(
            found[0].speed * 16.0 > MOTION_STEPS * 0.1 / 1024.0,
            "{found:?}"
        );

        let mut y: Vec<f64> = u.iter().map(|v| 0.9 * v).collect();
        for v in &mut y[3_000..3_050] {
            *v = 0.0;
        }
        let found = find(&y);
        assert_eq!(found.len(), 1, "{found:?}");
        assert_eq!(
            (found[0].start, found[0].len, found[0].value),
            (3_000, 50, 0.0)
        );
        assert!(found[0].jump_ratio > JUMP, "{found:?}");
    }
}
