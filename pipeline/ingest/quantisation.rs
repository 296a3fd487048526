//! A channel's quantisation step, read off its samples: an A/D converter
//! (or a logger writing fixed decimals) puts every sample on a grid of one
//! step, and a simulation of the channel that should look like it (the
//! stiffness sensitivity's Monte Carlo) rounds to the same grid.

/// The step of the grid `values` sit on, or None when they do not sit on
/// one (a float channel, a resampled or filtered one). The step is the
/// smallest gap between distinct values; the grid is accepted when every
/// distinct value is a whole number of steps from the smallest, to a
/// thousandth of a step (what unit conversion to SI can leave), and the
/// grid is coarse enough to be one (at most 2^24 steps over the range, a
/// 24-bit converter).
pub fn quantum_step(values: &[f64]) -> Option<f64> {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.len() < 16 {
        return None;
    }
    v.sort_by(f64::total_cmp);
    v.dedup();
    if v.len() < 3 {
        return None;
    }
    let step = v
        .windows(2)
        .map(|w| w[1] - w[0])
        .fold(f64::INFINITY, f64::min);
    let (lo, hi) = (v[0], v[v.len() - 1]);
    if step <= 0.0 || (hi - lo) / step > (1u64 << 24) as f64 {
        return None;
    }
    let on_grid = v.iter().all(|x| {
        let r = (x - lo) / step;
        (r - r.round()).abs() < 1e-3
    });
    on_grid.then_some(step)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 18 bits over +-50 mm, converted to m as ingest does (a scale that is
    /// not a power of two): the step comes back, to round-off.
    #[test]
    fn an_adc_grid_is_found_after_unit_conversion() {
        let lsb_mm = 100.0 / f64::from(1u32 << 18);
        let values: Vec<f64> = (0..5000)
            .map(|i| {
                let mm = 3.0 * (i as f64 * 0.01).sin();
                (mm / lsb_mm).round() * lsb_mm * 1e-3
            })
            .collect();
        let step = quantum_step(&values).unwrap();
        assert!((step / (lsb_mm * 1e-3) - 1.0).abs() < 1e-9, "{step}");
    }

    /// Values off any coarse grid (a smooth float signal) have none; nor do
    /// too few distinct values.
    #[test]
    fn a_float_channel_has_no_grid() {
        let values: Vec<f64> = (0..5000).map(|i| (i as f64 * 0.0137).sin()).collect();
        assert_eq!(quantum_step(&values), None);
        assert_eq!(quantum_step(&[1.0; 100]), None);
    }
}
