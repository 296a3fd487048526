//! A periodic command's amplitude spectrum shaped for the rig: the share
//! of each run's power on each line that minimises the sum of the four
//! parameters' squared relative stds (an A-optimal design on the
//! logarithms), by the multiplicative algorithm of Silvey, Titterington &
//! Torsney (1978) with the exponent 1/2 of Yu (2010), each run's shares
//! summing to one. The derivation: docs/methods.md, "Shaped spectra".

use nalgebra::DMatrix;

use super::precision::{self, Extension, PlannedRun};
use crate::fit::Intersample;
use crate::model::{LinearSpecimen, RigParams};

/// A run of the night as the design shapes it: its specimen and P gain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunModel {
    pub specimen: LinearSpecimen,
    pub p_gain: f64,
}

/// The multiplicative algorithm's passes: the criterion settles to a part
/// in 1e6 well before on the paper's rigs.
const PASSES: usize = 2000;

/// Each run's shares of its power over `lines_hz` (each run's summing to
/// one) minimising the rig's four parameters' part of the trace of the
/// inverse of the summed information (the extension's parameters
/// estimated beside them), each run's information weighted by `scale[r]`
/// (its N_s rms^2) and each line's by 1 / `noise(f)`. None where no share
/// determines the rig.
#[allow(clippy::too_many_arguments)]
pub fn a_optimal(
    rig: &RigParams,
    ext: &Extension,
    runs: &[RunModel],
    scale: &[f64],
    lines_hz: &[f64],
    noise: impl Fn(f64) -> f64,
    intersample: Intersample,
    sample_rate_hz: f64,
) -> Option<Vec<Vec<f64>>> {
    let info: Vec<Vec<DMatrix<f64>>> = runs
        .iter()
        .zip(scale)
        .map(|(run, s)| {
            lines_hz
                .iter()
                .map(|&f| {
                    // A line of amplitude A has v = 4 lambda / (N_s A^2) and
                    // A^2 = 2 rms^2 w: its information is Re(g^H g) per
                    // unit of N_s rms^2 w / lambda.
                    precision::information(
                        rig,
                        ext,
                        run.specimen,
                        run.p_gain,
                        f,
                        intersample,
                        sample_rate_hz,
                    )
                    .map(|m| m * (s / noise(f)))
                })
                .collect::<Option<Vec<_>>>()
        })
        .collect::<Option<_>>()?;
    let flat = 1.0 / lines_hz.len() as f64;
    let mut shares = vec![vec![flat; lines_hz.len()]; runs.len()];
    let n = info.first()?.first()?.nrows();
    let total = |shares: &[Vec<f64>]| -> DMatrix<f64> {
        let mut m = DMatrix::zeros(n, n);
        for (w, i) in shares.iter().zip(&info) {
            for (w, i) in w.iter().zip(i) {
                m += i * *w;
            }
        }
        m
    };
    total(&shares).try_inverse()?;
    for _ in 0..PASSES {
        let inverse = total(&shares).try_inverse()?;
        // M^-1 A M^-1, A selecting the rig's four.
        let rig_part = inverse.columns(0, 4) * inverse.rows(0, 4);
        for (w, i) in shares.iter_mut().zip(&info) {
            // d_k = tr(M^-1 A M^-1 I_k): how much the criterion falls per
            // unit share on line k; at the optimum it is equal on every
            // line a run keeps.
            let d: Vec<f64> = i.iter().map(|i| rig_part.dot(i).max(0.0)).collect();
            let sum: f64 = w.iter().zip(&d).map(|(w, d)| w * d.sqrt()).sum();
            for (w, d) in w.iter_mut().zip(&d) {
                *w *= d.sqrt() / sum;
            }
        }
    }
    Some(shares)
}

/// The planned runs of a periodic command: each run's lines at the
/// variance its shares give, v = 2 lambda / (N_s rms^2 w), for the
/// prediction ([`super::precision::predict`]).
pub fn planned(
    runs: &[RunModel],
    scale: &[f64],
    lines_hz: &[f64],
    shares: &[Vec<f64>],
    noise: impl Fn(f64) -> f64,
) -> Vec<PlannedRun> {
    runs.iter()
        .zip(scale)
        .zip(shares)
        .map(|((run, s), w)| PlannedRun {
            specimen: run.specimen,
            p_gain: run.p_gain,
            freq_hz: lines_hz.to_vec(),
            variance: lines_hz
                .iter()
                .zip(w)
                .map(|(&f, w)| 2.0 * noise(f) / (s * w))
                .collect(),
        })
        .collect()
}

#[cfg(test)]
mod tests;
