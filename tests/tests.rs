//! servoid's integration tests: the `servoid` binary run end to end.

mod util;

mod manifest_errors;
mod paper;
mod schemas;
