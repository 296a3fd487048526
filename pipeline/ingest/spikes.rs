//! Isolated spikes and corrupt stretches in a logged channel: one sample or
//! a few adjacent ones that a corrupted transfer, a flipped bit or a DAQ
//! glitch put far from both neighbours, which a sweep's FRF turns into a rig
//! thousands of times off. `find` finds them; `interpolate` repairs them.
//!
//! A run of w = 1 to [`MAX_WIDTH`] samples is a spike when each departs from
//! the straight line through its two neighbours by more than [`THRESHOLD`]
//! times the channel's local scale (times (w+1)^2 / 9 beyond three
//! samples), all on one side; not where the neighbours disagree more (a
//! step), nor where the line through either side's samples explains it
//! (the edge of something that starts there). The local scale is a median
//! second difference over [`BLOCK`] samples, at least the record's median
//! and the converter step. Why these bounds: docs/methods.md, "Spikes".

/// How many local scales a spike departs by.
pub const THRESHOLD: f64 = 30.0;
/// The samples of a block the local scale is the median of.
pub const BLOCK: usize = 256;
/// The widest run of adjacent samples taken as one spike (a corrupt
/// stretch); longer ones are a held channel's (`ingest::held`) or the
/// signal's own.
pub const MAX_WIDTH: usize = 16;

/// One spike: its first sample, its width, its value(s) and neighbours.
#[derive(Debug, Clone, PartialEq)]
pub struct Spike {
    pub index: usize,
    pub width: usize,
    /// The sample farthest from its neighbours' line.
    pub value: f64,
    pub before: f64,
    pub after: f64,
    /// Its departure over the local scale.
    pub ratio: f64,
}

/// The isolated spikes of `x`, in order.
pub fn find(x: &[f64]) -> Vec<Spike> {
    let n = x.len();
    if n < 4 {
        return Vec::new();
    }
    if settled_clean(x) {
        return Vec::new();
    }
    by_rule(x)
}

/// The isolated spikes of `x` (at least 4 samples) by the module's rule.
fn by_rule(x: &[f64]) -> Vec<Spike> {
    let n = x.len();
    let departure = |j: usize| (x[j] - 0.5 * (x[j - 1] + x[j + 1])).abs();
    let scale = local_scales(x);
    let mut out: Vec<Spike> = Vec::new();
    let mut j = 1;
    while j + 1 < n {
        let s = scale[j / BLOCK];
        if departure(j) <= THRESHOLD * s {
            j += 1;
            continue;
        }
        // A one-sample spike, or the first of a stretch.
        let found = (1..=MAX_WIDTH)
            .filter(|w| j + w < n)
            .find_map(|w| spike_at(x, j, w, s));
        match found {
            Some(spike) => {
                j = spike.index + spike.width + 1;
                out.push(spike);
            }
            None => j += 1,
        }
    }
    out
}

/// Whether `x` has no spike, shown without the medians the rule takes: in
/// every block at least as many departures as its median's rank from the
/// top reach its largest over [`THRESHOLD`], so the median does, and the
/// local scale, at least the median, puts every departure within
/// [`THRESHOLD`] scales. One pass over each block against a selection per
/// block (most of the spike scan's cost on a clean channel); a block it
/// cannot settle leaves the channel to the whole rule, so the result is
/// the rule's either way.
fn settled_clean(x: &[f64]) -> bool {
    let n = x.len();
    let departure = |j: usize| departure_or_zero(x, j);
    let mut block = [0.0; BLOCK];
    (0..n.div_ceil(BLOCK)).all(|b| {
        let range = b * BLOCK..((b + 1) * BLOCK).min(n);
        let len = range.len();
        for (d, j) in block.iter_mut().zip(range) {
            *d = departure(j);
        }
        let block = &block[..len];
        let largest = block.iter().copied().fold(0.0, f64::max);
        // The median is the value at rank len / 2 from the bottom
        // (`local_scales`): it reaches `largest / THRESHOLD` when the
        // len - len / 2 largest do.
        let reaching = block.iter().filter(|d| THRESHOLD * **d >= largest).count();
        largest.is_finite() && reaching >= len - len / 2
    })
}

/// The run of `w` samples from `i` as a spike against the scale `s`, if it
/// is one.
fn spike_at(x: &[f64], i: usize, w: usize, s: f64) -> Option<Spike> {
    let (before, after) = (x[i - 1], x[i + w]);
    let line = |j: usize| before + (after - before) * (j - i + 1) as f64 / (w + 1) as f64;
    let d: Vec<f64> = (i..i + w).map(|j| x[j] - line(j)).collect();
    let least = d.iter().map(|v| v.abs()).fold(f64::INFINITY, f64::min);
    let same_side = d.iter().all(|v| v.signum() == d[0].signum());
    let chord = ((w + 1) * (w + 1)) as f64 / 9.0;
    if !(least > THRESHOLD * s * chord.max(1.0) && same_side && (after - before).abs() < least) {
        return None;
    }
    if edge_of(x, i, w, s) {
        return None;
    }
    let (k, far) = d
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
        .expect("w >= 1");
    Some(Spike {
        index: i,
        width: w,
        value: x[i + k],
        before,
        after,
        ratio: far.abs() / s,
    })
}

/// Whether the run of `w` samples from `i` lies on the line one side's two
/// nearest samples extend to, each within [`THRESHOLD`] scales `s` times the
/// square of its distance from that side: an onset or an end, which that
/// side explains.
fn edge_of(x: &[f64], i: usize, w: usize, s: f64) -> bool {
    let n = x.len();
    let within = |j: usize, predicted: f64, distance: usize| {
        (x[j] - predicted).abs() <= THRESHOLD * s * (distance * distance) as f64
    };
    let left = i >= 2 && {
        let (a, b) = (x[i - 2], x[i - 1]);
        (i..i + w).all(|j| within(j, b + (b - a) * (j + 1 - i) as f64, j + 1 - i))
    };
    let right = i + w + 1 < n && {
        let (a, b) = (x[i + w + 1], x[i + w]);
        (i..i + w).all(|j| within(j, b + (b - a) * (i + w - j) as f64, i + w - j))
    };
    left || right
}

/// `x` with each spike replaced by the straight line between its
/// neighbours.
pub fn interpolate(x: &mut [f64], spikes: &[Spike]) {
    for s in spikes {
        let step = (s.after - s.before) / (s.width + 1) as f64;
        for (k, v) in x[s.index..s.index + s.width].iter_mut().enumerate() {
            *v = s.before + step * (k + 1) as f64;
        }
    }
}

/// |x(j) - (x(j-1) + x(j+1))/2|, and 0 at either end (which has one
/// neighbour): the departures the block medians are taken over.
fn departure_or_zero(x: &[f64], j: usize) -> f64 {
    if j == 0 || j + 1 == x.len() {
        0.0
    } else {
        (x[j] - 0.5 * (x[j - 1] + x[j + 1])).abs()
    }
}

/// The local scale of each block of `x` (see the module's rule).
fn local_scales(x: &[f64]) -> Vec<f64> {
    let n = x.len();
    let departure = |j: usize| departure_or_zero(x, j);
    // One block's departures at a time: a copy of the whole channel's was
    // as large as the channel. A departure is an absolute value, so its
    // bits order as it does (`f64::total_cmp` on values of one sign), and
    // selecting among integers is the cheaper comparison.
    let mut block: Vec<u64> = Vec::with_capacity(BLOCK);
    let medians: Vec<f64> = (0..n.div_ceil(BLOCK))
        .map(|b| {
            block.clear();
            block.extend((b * BLOCK..((b + 1) * BLOCK).min(n)).map(|j| departure(j).to_bits()));
            let mid = block.len() / 2;
            f64::from_bits(*block.select_nth_unstable(mid).1)
        })
        .collect();
    let mut sorted = medians.clone();
    let mid = sorted.len() / 2;
    let typical = *sorted.select_nth_unstable_by(mid, f64::total_cmp).1;
    let peak = x.iter().map(|v| v.abs()).fold(0.0, f64::max);
    let step = x
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .filter(|d| *d > 0.0)
        .fold(f64::INFINITY, f64::min);
    let step = if step.is_finite() { step } else { 0.0 };
    let floor = typical.max(step).max(1e-12 * peak);
    (0..medians.len())
        .map(|b| {
            let lo = b.saturating_sub(1);
            let hi = (b + 2).min(medians.len());
            medians[lo..hi].iter().copied().fold(floor, f64::max)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ingest::test_signals::sweep;

    /// One flipped sample in a sweep is found where it is, with its
    /// neighbours; interpolated, the record is the sweep again.
    #[test]
    fn a_single_bad_sample_is_found_and_repaired() {
        let clean = sweep(20_000);
        assert!(find(&clean).is_empty());
        let mut bad = clean.clone();
        bad[12_345] = -3.725;
        let spikes = find(&bad);
        assert_eq!(spikes.len(), 1, "{spikes:?}");
        let s = &spikes[0];
        // Exact: the sample's value as it was set.
        assert_eq!((s.index, s.width, s.value), (12_345, 1, -3.725));
        assert_eq!((s.before, s.after), (clean[12_344], clean[12_346]));
        interpolate(&mut bad, &spikes);
        // The line through the neighbours differs from the sweep by its
        // curvature over two samples.
        assert!((bad[12_345] - clean[12_345]).abs() < 1e-5);
    }

    /// The shortcut that settles a clean channel gives what the rule
    /// gives: on a sweep, with noise, quantised to a converter's step
    /// (half its departures zero, which the shortcut leaves to the rule),
    /// with a step, and with spikes; and it does settle the clean ones.
    #[test]
    fn settling_a_clean_channel_gives_the_rules_answer() {
        let clean = sweep(50_000);
        let noise = crate::ingest::tests::lcg(7, clean.len());
        let noisy: Vec<f64> = clean
            .iter()
            .zip(&noise)
            .map(|(v, e)| v + 5e-6 * e)
            .collect();
        let quantised: Vec<f64> = clean.iter().map(|v| (v / 1e-4).round() * 1e-4).collect();
        let mut step = noisy.clone();
        for v in &mut step[30_000..] {
            *v += 0.01;
        }
        let mut spiky = noisy.clone();
        spiky[777] = 1.5;
        spiky[40_000] -= 0.2;
        spiky[40_001] -= 0.25;
        assert!(settled_clean(&clean) && settled_clean(&noisy));
        assert!(!settled_clean(&quantised) && !settled_clean(&spiky));
        for (name, x) in [
            ("clean", &clean),
            ("noisy", &noisy),
            ("quantised", &quantised),
            ("step", &step),
            ("spiky", &spiky),
        ] {
            assert_eq!(find(x), by_rule(x), "{name}");
        }
        assert_eq!(find(&spiky).len(), 2);
    }

    /// Two bad samples in a row are one spike; a step is none.
    #[test]
    fn two_samples_are_one_spike_and_a_step_is_none() {
        let mut x = sweep(10_000);
        x[5000] += 0.5;
        x[5001] += 0.6;
        let spikes = find(&x);
        assert_eq!(spikes.len(), 1, "{spikes:?}");
        assert_eq!((spikes[0].index, spikes[0].width), (5000, 2));
        let mut step = sweep(10_000);
        for v in &mut step[6000..] {
            *v += 0.5;
        }
        assert!(find(&step).is_empty());
    }
}
