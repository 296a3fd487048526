//! servoid's integration tests: the `servoid` binary run end to end.

mod cdp;
mod util;

mod accuracy;
mod bad_logs;
mod batch;
mod browser;
mod cli_conventions;
mod consistency;
mod corpus;
mod csi;
mod diagnosis;
mod disk_full;
mod docs;
mod drift;
mod figure_formats;
mod first_night;
mod fuzz_replay;
mod init;
mod joint;
mod layering;
mod log_formats;
mod manifest_errors;
mod memory;
mod models_mat;
mod mts;
mod output_set;
mod paper;
mod run_table;
mod schemas;
mod sensitivity;
mod shards;
mod simulate;
mod slurm;
mod time_domain;
mod tracking;
