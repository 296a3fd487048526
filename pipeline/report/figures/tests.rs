//! Figure-level tests.
