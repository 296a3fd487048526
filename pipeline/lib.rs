//! servoid: identification of servo-hydraulic actuators (hydraulic transfer
//! systems) from lab logs, after Maghareh, Silva & Dyke, "Servo-hydraulic
//! actuator in controllable canonical form: identification and experimental
//! validation", MSSP 100 (2018) 398-414.
//!
//! Stages, one module each, with one-way dependencies: `manifest` (what the
//! lab wrote, checked) -> `identify` (Eqs. 18-20) over `model` (Eq. 10 and the
//! canonical form) and `lti`/`poly` (transfer functions, state space) ->
//! `results` (the results.json contract) -> `report` (writing). `run` is the
//! only module that knows all of them; `cli` decides the exit code.

pub mod cli;
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
pub mod schema;
pub mod sensitivity;
pub mod simulate;
pub mod validate;
