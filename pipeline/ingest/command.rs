//! A command file: the command signal a controller's waveform generator
//! plays (as `servoid design` writes it, and as `servoid simulate` plays
//! it), read through the log readers: a `time_s` column in seconds and a
//! `command_m` column in metres, in any log format.

use std::path::{Path, PathBuf};

use super::{
    ChannelPlan, Channels, Column, CsvOptions, IngestError, LogFormat, LogPlan, Repair, Stamps,
    TimePlan, Timing, read_log,
};
use crate::units::Unit;

/// The time column of a command file (s).
pub const TIME_COLUMN: &str = "time_s";
/// The command column of a command file (m).
pub const COMMAND_COLUMN: &str = "command_m";

/// A command file as read.
#[derive(Debug, Clone, PartialEq)]
pub struct CommandFile {
    pub path: PathBuf,
    /// SHA-256 of the file's bytes, lowercase hexadecimal.
    pub sha256: String,
    /// 1 / (the time column's mean interval) (Hz).
    pub sample_rate_hz: f64,
    /// The command (m), one sample per time stamp.
    pub command_m: Vec<f64>,
}

/// Why a command file cannot be played.
#[derive(Debug, thiserror::Error)]
pub enum CommandFileError {
    #[error(transparent)]
    Read(#[from] IngestError),
    #[error(
        "{}: no log format has the extension of this command file (one of {})",
        path.display(),
        LogFormat::EXTENSIONS
    )]
    Format { path: PathBuf },
    #[error(
        "{}: the time stamps are off a uniform grid by more than half an interval; a waveform generator plays one sample per tick",
        path.display()
    )]
    Uneven { path: PathBuf },
}

/// Reads a command file: its `time_s` and `command_m` columns, with every
/// check a log's channels get (numbers, finite, time increasing).
pub fn read_command(path: &Path, max_bytes: u64) -> Result<CommandFile, CommandFileError> {
    let format = LogFormat::from_path(path).ok_or_else(|| CommandFileError::Format {
        path: path.to_path_buf(),
    })?;
    let metres = ChannelPlan {
        column: Column::Name(COMMAND_COLUMN.into()),
        unit: Unit::Meter,
        gain: 1.0,
        offset: 0.0,
        range: None,
        repair: Repair::None,
    };
    // The log readers need a displacement channel; it reads the command
    // column again, so any fault is found, and named, on the command first.
    let plan = LogPlan {
        path: path.to_path_buf(),
        format,
        csv: CsvOptions::default(),
        sha256: None,
        channels: Channels {
            time: TimePlan::Column {
                column: Column::Name(TIME_COLUMN.into()),
                to_s: 1.0,
            },
            command: metres.clone(),
            displacement: metres,
            force: None,
        },
        max_bytes,
    };
    let log = read_log(&plan)?;
    if let Timing::Measured {
        stamps: Stamps::Uneven,
        ..
    } = log.timing
    {
        return Err(CommandFileError::Uneven {
            path: path.to_path_buf(),
        });
    }
    Ok(CommandFile {
        path: log.path,
        sha256: log.sha256,
        sample_rate_hz: log.sample_rate_hz,
        command_m: log.command_m,
    })
}
