//! A campaign's identification, run by run and together, and what else
//! needs the checked manifest: each log read, checked and its FRFs
//! estimated and fitted (`log_stage`), what each run gives the rig
//! (`evidence`), the rig by the paper's procedure (`rig`, Fig. 6, Eqs.
//! 18-20) and by the joint grey-box fit (`joint`, its friction corrected by
//! simulating the fitted rig in `friction`), each run's result from
//! its stage and the rig (`run_result`), the published numbers beside the
//! recomputed ones (`compare`), the campaign's place in its rig's history
//! (`history`) and a simulated campaign from its manifest (`simulated`).
//! Pure: a checked campaign and its logs' bytes in, typed results out;
//! `run` schedules it and writes what it gives.

pub mod compare;
pub mod conclusions;
pub mod evidence;
pub mod friction;
pub mod history;
pub mod joint;
pub mod log_stage;
pub mod rig;
pub mod run_result;
pub mod sensitivity;
pub mod simulated;
pub mod step;

pub use rig::{FailedRun, RigError};
