//! A small complex FFT for synthesising periodic excitations of any length:
//! iterative radix-2 for powers of two, Bluestein's chirp-z algorithm
//! (Bluestein 1970; Rabiner, Schafer & Rader 1969) for every other length.
//! The crate has no FFT dependency, and excitations need exact DFTs of
//! lengths such as 170 s x 2048 Hz = 348,160 = 2^12 * 5 * 17.

use nalgebra::Complex;
use std::f64::consts::PI;

/// The unnormalised inverse DFT, x_j = sum_k X_k exp(+2 pi i j k / N).
pub(crate) fn inverse_dft(spectrum: &[Complex<f64>]) -> Vec<Complex<f64>> {
    let n = spectrum.len();
    if n <= 1 {
        return spectrum.to_vec();
    }
    if n.is_power_of_two() {
        let mut x = spectrum.to_vec();
        radix2(&mut x, 1.0);
        x
    } else {
        bluestein(spectrum, 1.0)
    }
}

/// The forward DFT, X_k = sum_j x_j exp(-2 pi i j k / N) (tests and
/// analysis of generated signals).
#[cfg(test)]
pub(crate) fn forward_dft(signal: &[Complex<f64>]) -> Vec<Complex<f64>> {
    let n = signal.len();
    if n <= 1 {
        return signal.to_vec();
    }
    if n.is_power_of_two() {
        let mut x = signal.to_vec();
        radix2(&mut x, -1.0);
        x
    } else {
        bluestein(signal, -1.0)
    }
}

/// In-place radix-2 decimation-in-time FFT with exponent sign `sign`
/// (-1 forward, +1 inverse), unnormalised. Twiddles are computed directly
/// from their angle (no recurrence), so the error stays O(eps log N).
fn radix2(x: &mut [Complex<f64>], sign: f64) {
    let n = x.len();
    debug_assert!(n.is_power_of_two());
    let bits = n.trailing_zeros();
    for i in 0..n {
        let j = i.reverse_bits() >> (usize::BITS - bits);
        if j > i {
            x.swap(i, j);
        }
    }
    let twiddles: Vec<Complex<f64>> = (0..n / 2)
        .map(|m| {
            let a = sign * 2.0 * PI * m as f64 / n as f64;
            Complex::new(a.cos(), a.sin())
        })
        .collect();
    let mut len = 2;
    while len <= n {
        let half = len / 2;
        let stride = n / len;
        for start in (0..n).step_by(len) {
            for m in 0..half {
                let w = twiddles[m * stride];
                let a = x[start + m];
                let b = x[start + m + half] * w;
                x[start + m] = a + b;
                x[start + m + half] = a - b;
            }
        }
        len *= 2;
    }
}

/// Bluestein: j k = (j^2 + k^2 - (j - k)^2) / 2 turns the DFT into a
/// convolution with the chirp c_m = exp(sign i pi m^2 / N), done with
/// radix-2 FFTs of a power-of-two length >= 2N - 1. m^2 is reduced modulo
/// 2N in integers so the chirp's angle is exact for any N.
fn bluestein(x: &[Complex<f64>], sign: f64) -> Vec<Complex<f64>> {
    let n = x.len();
    let two_n = 2 * n as u128;
    let chirp: Vec<Complex<f64>> = (0..n)
        .map(|m| {
            let m = m as u128;
            let r = (m * m) % two_n;
            let a = sign * PI * r as f64 / n as f64;
            Complex::new(a.cos(), a.sin())
        })
        .collect();
    let len = (2 * n - 1).next_power_of_two();
    let mut a = vec![Complex::new(0.0, 0.0); len];
    for k in 0..n {
        a[k] = x[k] * chirp[k];
    }
    let mut b = vec![Complex::new(0.0, 0.0); len];
    b[0] = chirp[0].conj();
    for m in 1..n {
        b[m] = chirp[m].conj();
        b[len - m] = chirp[m].conj();
    }
    radix2(&mut a, -1.0);
    radix2(&mut b, -1.0);
    for (p, q) in a.iter_mut().zip(b.iter()) {
        *p *= q;
    }
    radix2(&mut a, 1.0);
    let scale = 1.0 / len as f64;
    (0..n).map(|j| chirp[j] * a[j] * scale).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

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
