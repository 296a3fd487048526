//! Planned FFTs, one planner per thread for every stage.
//!
//! Planning a transform computes its twiddle factors, one `sincos` each,
//! which for a long record's length (2^6 x 3 x 5^4 for 120 s at 1 kHz)
//! costs as much as running it. rustfft and realfft keep their plans by
//! length inside a planner, so a planner kept per thread plans each length
//! once per thread: a night's runs share their lengths. Plans are
//! deterministic, so which thread made one does not change a bit of a
//! result.

use std::cell::RefCell;
use std::sync::Arc;

use realfft::{ComplexToReal, RealFftPlanner, RealToComplex};
use rustfft::{Fft, FftPlanner};

thread_local! {
    static REAL: RefCell<RealFftPlanner<f64>> = RefCell::new(RealFftPlanner::new());
    static COMPLEX: RefCell<FftPlanner<f64>> = RefCell::new(FftPlanner::new());
}

/// The real-to-complex transform of `n` samples.
pub fn real_forward(n: usize) -> Arc<dyn RealToComplex<f64>> {
    REAL.with(|p| p.borrow_mut().plan_fft_forward(n))
}

/// The DFT X_k = sum_j x_j e^{-2 pi i jk/n} of real `x`, k = 0..=n/2.
pub fn real_spectrum(x: &[f64]) -> Vec<rustfft::num_complex::Complex<f64>> {
    let mut input = x.to_vec();
    let fwd = real_forward(x.len());
    let mut spectrum = fwd.make_output_vec();
    fwd.process(&mut input, &mut spectrum)
        .expect("a buffer of the transform's length");
    spectrum
}

/// The complex-to-real transform back to `n` samples.
pub fn real_inverse(n: usize) -> Arc<dyn ComplexToReal<f64>> {
    REAL.with(|p| p.borrow_mut().plan_fft_inverse(n))
}

/// The complex forward transform of `n` points, `X_k = sum_j x_j e^{-2 pi i jk/n}`.
pub fn complex_forward(n: usize) -> Arc<dyn Fft<f64>> {
    COMPLEX.with(|p| p.borrow_mut().plan_fft_forward(n))
}

/// The complex inverse transform of `n` points, unnormalised.
pub fn complex_inverse(n: usize) -> Arc<dyn Fft<f64>> {
    COMPLEX.with(|p| p.borrow_mut().plan_fft_inverse(n))
}
