//! servoid: identification of servo-hydraulic actuators (hydraulic transfer
//! systems) from lab logs, after Maghareh, Silva & Dyke, "Servo-hydraulic
//! actuator in controllable canonical form: identification and experimental
//! validation", MSSP 100 (2018) 398-414.
//!
//! # Layers
//!
//! Each module imports only from the layers below it (`tests/layering.rs`
//! reads every `crate::` path under `pipeline/` and fails on an import that
//! points up):
//!
//! 1. `cli`: parses arguments, prints, decides the exit code.
//! 2. `run`: the only orchestrator. It loads either kind of manifest,
//!    schedules the analysis, draws the figures and writes the outputs.
//! 3. `report`: writes results.json, figures, the page and logs.
//! 4. `analysis`: a campaign's identification: each run's log stage, the
//!    rig (sequential and joint), the comparisons, the campaign's place in
//!    its rig's history, a simulated campaign; checked plans in, results
//!    out.
//! 5. `results`: the output contract (results.json, truth.json).
//! 6. `manifest`: reads and checks the manifests, and builds each stage's
//!    own settings.
//! 7. The stages, each owning its settings type: `ingest` (the only module
//!    that reads data files), `frf`, `fit`, `identify` (Eqs. 18-20),
//!    `validate` (Eqs. 47-48), `sensitivity`, `simulate`, `drift` (the rig's
//!    history and its alarm rule), `tracking` (how the actuator follows its
//!    command: delays, the frequency evaluation index, the tracking
//!    indicator, the RTHS benchmark's errors, the model-based compensator).
//!    Within this layer five uses run one way only: `sensitivity`
//!    propagates through `identify`'s algebra and predicts planned runs'
//!    covariance with `fit`'s Jacobian, `validate` drives models with
//!    `simulate`'s exact discretisation and integrators, and `tracking`
//!    measures in `validate`'s windows of a sweep and drives the
//!    compensated plant with `simulate`'s discretisation.
//! 8. `model`: the plant of Eq. 10 and its canonical form (Eqs. 34-35).
//! 9. `lti`: transfer functions and state spaces.
//! 10. `poly` (real polynomials), `units` (physical units and their SI
//!     factors) and `warning` (a warning's headline and detail).
//!
//! The numerical core (layers 7-10) is pure: data in, typed results out, the
//! same bits whatever the thread count. Errors are typed per stage and reach
//! `run::RunError` through `#[from]`.

pub mod analysis;
pub mod cli;
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
