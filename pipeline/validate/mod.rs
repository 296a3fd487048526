//! The validation stage: a model driven by a run's measured command and held
//! against its measured response in the time domain (paper Sec. 4, Eqs.
//! 47-48, Figs. 9, 12, 14, 19-22).
//!
//! - [`metrics`]: the paper's normalised errors, fit percent, and the four
//!   windows of the chirp the paper shows.
//! - [`timedomain`]: the identified rig with a run's specimen (physical form,
//!   canonical form with and without Cn) or a run's fitted transfer
//!   function, simulated and compared; outlier runs flagged.
//!
//! Pure: signals in, typed results out.

pub mod csi;
pub mod metrics;
pub mod timedomain;

pub use metrics::{
    Errors, PAPER_WINDOWS, Window, errors, instantaneous_frequency, locate_windows, window_range,
};
pub use timedomain::{
    LoadPrediction, Record, SimplifiedCcf, TimeStage, ValidateError, ValidationMetrics,
    WindowErrors, fitted_run, flag_outliers, validation_run,
};
