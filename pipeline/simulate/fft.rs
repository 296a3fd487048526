//! The complex DFT the excitations are synthesised with, for any length
//! (170 s at 2048 Hz is 348,160 = 2^12 * 5 * 17 samples), by rustfft (mixed
//! radix, Rader or Bluestein as the length needs).

use nalgebra::Complex;

/// The unnormalised inverse DFT, x_j = sum_k X_k exp(+2 pi i j k / N).
pub(crate) fn inverse_dft(spectrum: &[Complex<f64>]) -> Vec<Complex<f64>> {
    let mut x = spectrum.to_vec();
    if x.len() > 1 {
        crate::fft::complex_inverse(x.len()).process(&mut x);
    }
    x
}

/// The forward DFT, X_k = sum_j x_j exp(-2 pi i j k / N) (tests and
/// analysis of generated signals).
#[cfg(test)]
pub(crate) fn forward_dft(signal: &[Complex<f64>]) -> Vec<Complex<f64>> {
    let mut x = signal.to_vec();
    if x.len() > 1 {
        crate::fft::complex_forward(x.len()).process(&mut x);
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// The DFT by its definition, angles reduced exactly: the independent truth.
    fn naive(x: &[Complex<f64>], sign: f64) -> Vec<Complex<f64>> {
        let n = x.len();
        (0..n)
            .map(|k| {
                x.iter()
                    .enumerate()
                    .map(|(j, v)| {
                        let a = sign * 2.0 * PI * ((j * k) % n) as f64 / n as f64;
                        v * Complex::new(a.cos(), a.sin())
                    })
                    .sum()
            })
            .collect()
    }

    fn pseudo_random(n: usize) -> Vec<Complex<f64>> {
        // A fixed linear congruential sequence: data only, no claim about it.
        let mut s: u64 = 0x2545_F491_4F6C_DD1D;
        let mut next = || {
            s = s.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        (0..n).map(|_| Complex::new(next(), next())).collect()
    }

    #[test]
    fn fft_matches_the_definition_for_several_lengths() {
        for n in [1, 2, 8, 12, 97, 256, 1000] {
            let x = pseudo_random(n);
            let norm: f64 = x.iter().map(|v| v.norm_sqr()).sum::<f64>().sqrt();
            for (sign, got) in [(1.0, inverse_dft(&x)), (-1.0, forward_dft(&x))] {
                let want = naive(&x, sign);
                let err = got
                    .iter()
                    .zip(want.iter())
                    .map(|(g, w)| (g - w).norm())
                    .fold(0.0, f64::max);
                // Worst-case error bound of a few eps * log2(N) * sqrt(N) * |x|.
                assert!(
                    err < 1e-13 * norm * (n as f64).sqrt().max(1.0),
                    "n = {n}: {err}"
                );
            }
        }
    }
}
