//! servoid: servo-hydraulic actuators identified from lab logs, after Maghareh, Silva & Dyke,
//! MSSP 100 (2018) 398-414. Layers, top first; a module uses only its own layer and those below:
//! 1. `cli`: arguments, printing, the exit code.
//! 2. `run`: the only orchestrator: manifests in, outputs written.
//! 3. `report`: results.json, figures, the pages and logs.
//! 4. `analysis`: a campaign's identification: checked plans in, results out.
//! 5. `results`: the output contract (results.json, truth.json).
//! 6. `manifest`: reads and checks the manifests, builds each stage's settings.
//! 7. The stages: `ingest` (the only reader of data files), `frf`, `fit`, `identify` (a run's
//!    TF fit, Eqs. 18-20, the joint fit), `validate`, `sensitivity`, `simulate`, `drift`,
//!    `tracking`, `design`. One way only within: identify -> frf, fit; design -> fit, simulate;
//!    sensitivity -> identify, fit, frf, simulate; validate -> simulate; tracking -> validate,
//!    simulate.
//! 8. `model`: the plant of Eq. 10 and its canonical form (Eqs. 34-35); 9. `lti`: transfer
//!    functions, state spaces; 10. `fft`, `poly`, `units`, `warning`. tests/layering.rs checks.

pub mod analysis;
pub mod cli;
pub mod design;
pub mod drift;
pub mod fft;
pub mod fit;
pub mod frf;
pub mod identify;
pub mod ingest;
pub mod lti;
pub mod manifest;
pub mod model;
pub mod poly;
pub mod report;
pub mod results;
pub mod run;
pub mod sensitivity;
pub mod simulate;
pub mod tracking;
pub mod units;
pub mod validate;
pub mod warning;
