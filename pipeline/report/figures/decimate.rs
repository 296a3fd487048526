//! Min/max decimation for drawing long records: per pixel column keep the
//! lowest and highest sample, so a one-sample spike in a million still shows.

/// Reduce `(x, y)` to at most `2 * buckets + 2` points for drawing.
///
/// The x span of the finite points is cut into `buckets` equal columns (one
/// per pixel column of the plot); in each column the first sample with the
/// lowest y and the first with the highest y are kept, plus the first and
/// last finite points. The kept points are returned in input order (time
/// order for a record), each exactly as given. Points where x or y is NaN or
/// infinite are dropped. If the input already has no more than
/// `2 * buckets + 2` finite points it is returned unchanged (minus the
/// non-finite ones); `buckets == 0` keeps only the first and last points.
/// Only the shorter length of `x` and `y` is used.
pub fn decimate_minmax(x: &[f64], y: &[f64], buckets: usize) -> (Vec<f64>, Vec<f64>) {
    let n = x.len().min(y.len());
    decimate_minmax_by(n, |i| x[i], |i| y[i], buckets)
}

/// [`decimate_minmax`] of the `n` points `(x(i), y(i))`, computed as they
/// are read: a record of 14 M samples is decimated without a copy of it
/// (nor of its time axis, where `x` computes it), and without a list of its
/// finite points. `x` and `y` are called more than once per point and must
/// give the same value each time.
pub fn decimate_minmax_by(
    n: usize,
    x: impl Fn(usize) -> f64,
    y: impl Fn(usize) -> f64,
    buckets: usize,
) -> (Vec<f64>, Vec<f64>) {
    let finite = |i: &usize| x(*i).is_finite() && y(*i).is_finite();
    let pick = |idx: &mut dyn Iterator<Item = usize>| -> (Vec<f64>, Vec<f64>) {
        idx.map(|i| (x(i), y(i))).unzip()
    };
    let limit = buckets.saturating_mul(2).saturating_add(2);
    // One pass: how many points are finite, the first and last, and the x
    // span.
    let (mut count, mut first, mut last) = (0usize, 0usize, 0usize);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for i in (0..n).filter(finite) {
        if count == 0 {
            first = i;
        }
        count += 1;
        last = i;
        lo = lo.min(x(i));
        hi = hi.max(x(i));
    }
    if count <= limit {
        return pick(&mut (0..n).filter(finite));
    }
    if buckets == 0 {
        return pick(&mut [first, last].into_iter());
    }

    let span = hi - lo;
    let column = |v: f64| -> usize {
        if span > 0.0 {
            (((v - lo) / span * buckets as f64) as usize).min(buckets - 1)
        } else {
            0
        }
    };

    let mut min_at: Vec<Option<usize>> = vec![None; buckets];
    let mut max_at: Vec<Option<usize>> = vec![None; buckets];
    for i in (0..n).filter(finite) {
        let b = column(x(i));
        let yi = y(i);
        if min_at[b].is_none_or(|j| yi < y(j)) {
            min_at[b] = Some(i);
        }
        if max_at[b].is_none_or(|j| yi > y(j)) {
            max_at[b] = Some(i);
        }
    }
    let mut keep: Vec<usize> = Vec::with_capacity(limit);
    keep.push(first);
    keep.push(last);
    keep.extend(min_at.into_iter().flatten());
    keep.extend(max_at.into_iter().flatten());
    keep.sort_unstable();
    keep.dedup();
    pick(&mut keep.into_iter())
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    /// A small deterministic generator (SplitMix64) for seeded signals.
    struct SplitMix(u64);
    impl SplitMix {
        fn next_u64(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        }
        fn unit(&mut self) -> f64 {
            (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    #[test]
    fn property_over_seeded_random_signals() {
        for seed in 0..40u64 {
            let mut rng = SplitMix(seed);
            let n = 1 + (rng.next_u64() % 20_000) as usize;
            let buckets = 1 + (rng.next_u64() % 700) as usize;
            // Random walk plus noise on a uniform time grid.
            let x: Vec<f64> = (0..n).map(|i| i as f64 / 2048.0).collect();
            let mut level = 0.0;
            let y: Vec<f64> = (0..n)
                .map(|_| {
                    level += rng.unit() - 0.5;
                    level + 0.1 * (rng.unit() - 0.5)
                })
                .collect();
            let (dx, dy) = decimate_minmax(&x, &y, buckets);

            assert!(dx.len() <= 2 * buckets + 2, "seed {seed}");
            assert_eq!(dx.len(), dy.len());
            // Every kept point is an original point: x is i / 2048, so the
            // index is recoverable, and y must be that sample's value.
            let idx: Vec<usize> = dx.iter().map(|v| (v * 2048.0).round() as usize).collect();
            for (k, &i) in idx.iter().enumerate() {
                assert_relative_eq!(dx[k], x[i]);
                assert_relative_eq!(dy[k], y[i]);
            }
            // Strictly increasing indices: time order, no duplicates.
            assert!(idx.windows(2).all(|w| w[0] < w[1]), "seed {seed}");
            // First, last, global max and min survive.
            assert_eq!(idx[0], 0);
            assert_eq!(*idx.last().unwrap(), n - 1);
            let gmax = y.iter().cloned().fold(f64::MIN, f64::max);
            let gmin = y.iter().cloned().fold(f64::MAX, f64::min);
            assert!(dy.contains(&gmax), "seed {seed}: max lost");
            assert!(dy.contains(&gmin), "seed {seed}: min lost");
        }
    }

    #[test]
    fn one_spike_in_a_million_survives() {
        let n = 1_000_000;
        let x: Vec<f64> = (0..n).map(|i| i as f64 * 1e-3).collect();
        let mut y: Vec<f64> = (0..n).map(|i| (i as f64 * 0.01).sin() * 1e-3).collect();
        y[777_777] = 5.0;
        let (dx, dy) = decimate_minmax(&x, &y, 1000);
        assert!(dx.len() <= 2002);
        let k = dy.iter().position(|&v| v == 5.0).expect("spike kept");
        assert_relative_eq!(dx[k], 777.777);
    }

    #[test]
    fn short_input_is_returned_as_is_and_nan_is_dropped() {
        let x = [0.0, 1.0, 2.0, 3.0];
        let y = [1.0, f64::NAN, 3.0, 4.0];
        let (dx, dy) = decimate_minmax(&x, &y, 10);
        assert_eq!(dx.len(), 3);
        assert_relative_eq!(dy[1], 3.0);
        let (dx, _) = decimate_minmax(&[], &[], 10);
        assert!(dx.is_empty());
    }

    #[test]
    fn degenerate_inputs() {
        // Constant x: one column, so first, last, min and max.
        let x = vec![2.0; 100];
        let y: Vec<f64> = (0..100).map(|i| ((i * 37) % 100) as f64).collect();
        let (_, dy) = decimate_minmax(&x, &y, 5);
        assert!(dy.len() <= 4);
        assert!(dy.contains(&99.0) && dy.contains(&0.0));
        // Zero buckets: first and last only.
        let (dx, _) = decimate_minmax(&(0..50).map(f64::from).collect::<Vec<_>>(), &y[..50], 0);
        assert_eq!(dx.len(), 2);
        assert_relative_eq!(dx[1], 49.0);
    }

    #[test]
    fn computed_points_decimate_as_the_same_points_materialised() {
        let fs = 2048.0;
        let n = 50_000;
        let y = |k: usize| ((k as f64 / fs) * 7.3).sin() + if k == 31_337 { 5.0 } else { 0.0 };
        let xs: Vec<f64> = (0..n).map(|k| k as f64 / fs).collect();
        let ys: Vec<f64> = (0..n).map(y).collect();
        for buckets in [0, 1, 700, 30_000] {
            let by = decimate_minmax_by(n, |k| k as f64 / fs, y, buckets);
            assert_eq!(by, decimate_minmax(&xs, &ys, buckets), "{buckets} buckets");
        }
        // The spike survives.
        let (_, dy) = decimate_minmax_by(n, |k| k as f64 / fs, y, 700);
        assert!(dy.iter().any(|v| *v > 4.0));
    }
}
