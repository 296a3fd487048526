//! A channel that sits at one of its extremes: a sensor or converter at the
//! end of its range (clipped), or one of the things that look like it and
//! are valid data. A value repeated at the peak (`plateau`) is clipping
//! only when nothing else explains it:
//!
//! - quantisation (`quantised_crest`): a smooth crest's top code holds at
//!   most 2.4 times the samples of the code below it, a rail many times
//!   more ([`QUANTISED_PEAK_RATIO`]);
//! - the command holding still: a step or square-wave command, and the
//!   displacement and force that settle with it (`held_with_command`);
//! - a command limited in the controller: the logged command is what the
//!   valve received, so it is analysed as it is, and said.
//!
//! The crest's bound: docs/methods.md, "Clipping".

use super::quantisation::quantum_step;

/// The top code may hold this many times the samples of the code one step
/// inward before the peak is taken for a rail: a sine crest gives at most
/// 2.4, noise on it less.
pub const QUANTISED_PEAK_RATIO: f64 = 4.0;

/// A channel's samples held at one of its extremes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plateau {
    /// "maximum" or "minimum".
    pub which: &'static str,
    pub level: f64,
    /// The share of the samples at it.
    pub fraction: f64,
}

/// The extreme (maximum or minimum) at which most samples of `x` sit, with
/// that share of the samples; `None` when `x` is empty.
pub fn plateau(x: &[f64]) -> Option<Plateau> {
    if x.is_empty() {
        return None;
    }
    let max = x.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let min = x.iter().copied().fold(f64::INFINITY, f64::min);
    // Exact equality on purpose: a clipped channel repeats its rail value.
    let at_max = x.iter().filter(|&&v| v == max).count();
    let at_min = x.iter().filter(|&&v| v == min).count();
    let n = x.len() as f64;
    Some(if at_max >= at_min {
        Plateau {
            which: "maximum",
            level: max,
            fraction: at_max as f64 / n,
        }
    } else {
        Plateau {
            which: "minimum",
            level: min,
            fraction: at_min as f64 / n,
        }
    })
}

/// Whether the samples of `x` at its extreme `p` are a quantised crest: `x`
/// sits on a converter's grid and the code one step inward holds at least
/// 1 / [`QUANTISED_PEAK_RATIO`] as many samples.
pub fn quantised_crest(x: &[f64], p: &Plateau) -> bool {
    let Some(q) = quantum_step(x) else {
        return false;
    };
    let inward = if p.which == "maximum" {
        p.level - q
    } else {
        p.level + q
    };
    let near = |v: f64, level: f64| (v - level).abs() <= 1e-3 * q;
    let (top, below) = x.iter().fold((0usize, 0usize), |(t, b), &v| {
        (
            t + usize::from(near(v, p.level)),
            b + usize::from(near(v, inward)),
        )
    });
    top as f64 <= QUANTISED_PEAK_RATIO * below as f64
}

/// The share of the samples where `x` sits at the level `p` during which
/// the command `u` holds still (equals a neighbour): a channel that rests
/// at its extreme because its command does (a step) has most of them.
pub fn held_with_command(x: &[f64], u: &[f64], p: &Plateau) -> f64 {
    let n = x.len().min(u.len());
    let (mut at, mut held) = (0usize, 0usize);
    for i in 0..n {
        if x[i] != p.level {
            continue;
        }
        at += 1;
        let still = (i > 0 && u[i] == u[i - 1]) || (i + 1 < n && u[i] == u[i + 1]);
        held += usize::from(still);
    }
    if at == 0 {
        0.0
    } else {
        held as f64 / at as f64
    }
}

/// The share of the command's samples that sit at its maximum, its minimum
/// or its first value (the rest before the test): nearly all of a step or
/// square-wave command's, a fraction of a limited sweep's.
pub fn at_levels(u: &[f64]) -> f64 {
    let Some(&first) = u.first() else {
        return 0.0;
    };
    let max = u.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let min = u.iter().copied().fold(f64::INFINITY, f64::min);
    let at = u
        .iter()
        .filter(|&&v| v == max || v == min || v == first)
        .count();
    at as f64 / u.len() as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 18 bits over +-50 mm, as the bundled instrument chain writes.
    fn quantise(v: f64, bits: u32, full_scale: f64) -> f64 {
        let q = 2.0 * full_scale / f64::from(1u32 << bits);
        (v / q).round() * q
    }

    fn chirp(n: usize, amplitude: f64) -> Vec<f64> {
        (0..n)
            .map(|i| {
                let t = i as f64 / 1000.0;
                amplitude * (2.0 * std::f64::consts::PI * (0.1 * t + 0.3 * t * t)).sin()
            })
            .collect()
    }

    /// A 0.3 mm sweep on an 18-bit converter repeats its top code in about
    /// sqrt(2 q / A) / pi of its samples, over the 1 % a clip check
    /// tolerates; the code below holds within 2.4 times fewer: a crest, not a
    /// rail.
    #[test]
    fn a_quantised_crest_is_not_a_rail() {
        let x: Vec<f64> = chirp(60_000, 0.3)
            .into_iter()
            .map(|v| quantise(v, 18, 50.0))
            .collect();
        let p = plateau(&x).unwrap();
        let q = 100.0 / f64::from(1u32 << 18);
        let predicted = (2.0 * q / 0.3).sqrt() / std::f64::consts::PI;
        assert!(p.fraction > 0.01, "{p:?}");
        assert!(
            (p.fraction / predicted - 1.0).abs() < 0.5,
            "{p:?} against {predicted}"
        );
        assert!(quantised_crest(&x, &p));
    }

    /// The same sweep through a converter whose range ends at 0.25 mm: the
    /// rail holds a sixth of the samples and the code below it a few.
    #[test]
    fn a_rail_is_not_a_crest() {
        let x: Vec<f64> = chirp(60_000, 0.3)
            .into_iter()
            .map(|v| quantise(v.min(0.25), 18, 50.0))
            .collect();
        let p = plateau(&x).unwrap();
        assert_eq!(p.which, "maximum");
        assert!(p.fraction > 0.1, "{p:?}");
        assert!(!quantised_crest(&x, &p));
        // A float channel has no grid: its repeated peak is a rail.
        let float: Vec<f64> = chirp(60_000, 0.3)
            .into_iter()
            .map(|v| v.min(0.25))
            .collect();
        assert!(!quantised_crest(&float, &plateau(&float).unwrap()));
    }

    /// A square wave's displacement rests at its extremes while the command
    /// holds; a clipped displacement sits at its rail while the command
    /// moves.
    #[test]
    fn a_command_that_holds_explains_a_plateau() {
        let u: Vec<f64> = (0..4000)
            .map(|i| if (i / 500) % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let x: Vec<f64> = u.iter().map(|v| 0.9 * v).collect();
        let p = plateau(&x).unwrap();
        assert_eq!(held_with_command(&x, &u, &p), 1.0);
        assert!(at_levels(&u) > 0.99);
        let sweep = chirp(4000, 1.0);
        let clipped: Vec<f64> = sweep.iter().map(|v| v.min(0.5)).collect();
        let p = plateau(&clipped).unwrap();
        assert_eq!(held_with_command(&clipped, &sweep, &p), 0.0);
        // A sweep limited at 3/4 of its amplitude holds its levels a
        // minority of the time.
        let limited: Vec<f64> = sweep.iter().map(|v| v.clamp(-0.75, 0.75)).collect();
        assert!(at_levels(&limited) < 0.5, "{}", at_levels(&limited));
    }
}
