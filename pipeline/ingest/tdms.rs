//! NI TDMS logs (LabVIEW and NI DAQ software), read by the `tedium` crate:
//! each channel a variable named `Group/Channel`, a vector of its samples,
//! found as in every array format (`arrays`). Where the plan asks the log
//! for its time base, a waveform channel's `wf_increment` (the sample
//! interval, s) gives the rate; a channel's `unit_string` is checked
//! against the manifest's unit. Numbers of any of TDMS's integer and float
//! types are widened to f64; DAQmx raw data (scaled by the reader from
//! the device's scaling information) is refused by the crate with a
//! message.

use std::cell::RefCell;
use std::io::Cursor;
use std::path::Path;

use tedium::{ChannelPath, PropertyPath, PropertyValue, TdmsError, TdmsFile, TdmsStorageType};

use super::arrays::{self, Arrays};
use super::plan::LogPlan;
use super::{FormatProblem, IngestError, MatVariable, Raw, RawTime};

/// Read a TDMS log as `plan` describes it.
pub(super) fn read<'a>(
    path: &Path,
    bytes: &[u8],
    plan: &'a LogPlan,
) -> Result<Raw<'a>, IngestError> {
    guarded(path, || arrays::read(path, &open(path, bytes)?, plan))
}

/// `f`, with a panic inside tedium on damaged bytes (fuzzing found a
/// division by zero in its reader of interleaved channels) reported as the
/// file's damage.
fn guarded<R>(path: &Path, f: impl FnOnce() -> Result<R, IngestError>) -> Result<R, IngestError> {
    super::guard_reader(f).unwrap_or_else(|p| {
        Err(unreadable(
            path,
            &format!("the TDMS reader failed on damaged bytes ({p})"),
        ))
    })
}

/// A TDMS log's channels with their units, and the rate its waveforms
/// state.
pub(super) fn columns(
    path: &Path,
    bytes: &[u8],
) -> Result<(Vec<super::LogColumn>, Option<f64>), IngestError> {
    guarded(path, || {
        let t = open(path, bytes)?;
        let rate = match t.own_time(path) {
            Ok(RawTime::Rate { hz, .. }) if hz.is_finite() && hz > 0.0 => Some(hz),
            _ => None,
        };
        Ok((arrays::columns(&t), rate))
    })
}

fn open<'p, 'b>(path: &'p Path, bytes: &'b [u8]) -> Result<Tdms<'p, 'b>, IngestError> {
    let file = TdmsFile::new(Cursor::new(bytes)).map_err(|e| unreadable(path, &said(&e)))?;
    let mut channels = Vec::new();
    let groups: Vec<String> = file.list_groups().map(str::to_owned).collect();
    for g in &groups {
        for ch in file.list_channels_in_group(&PropertyPath::group(g)) {
            let len = file.channel_length(&ch).unwrap_or(0);
            // A channel holds at least a byte a value: more declared than
            // the file has bytes is damage, not a buffer to allocate.
            let len = usize::try_from(len)
                .ok()
                .filter(|&n| n <= bytes.len())
                .ok_or_else(|| {
                    unreadable(
                        path,
                        &format!(
                            "channel `{}/{}` declares {len} values in a file of {} bytes",
                            ch.group_name(),
                            ch.channel_name(),
                            bytes.len()
                        ),
                    )
                })?;
            channels.push((ch, len));
        }
    }
    if channels.is_empty() {
        return Err(IngestError::HeaderOnly {
            path: path.to_path_buf(),
            what: "no channels".into(),
        });
    }
    Ok(Tdms {
        path,
        variables: channels
            .iter()
            .map(|(ch, len)| MatVariable {
                name: name_of(ch),
                size: vec![*len, 1],
            })
            .collect(),
        channels: channels.into_iter().map(|(ch, _)| ch).collect(),
        file: RefCell::new(file),
    })
}

fn name_of(ch: &ChannelPath) -> String {
    format!("{}/{}", ch.group_name(), ch.channel_name())
}

/// tedium's error with its causes (its I/O error says only "IO Error"),
/// and a file that ends inside a segment called what it most likely is.
fn said(e: &TdmsError) -> String {
    let mut text = e.to_string();
    let mut source = std::error::Error::source(e);
    while let Some(s) = source {
        text.push_str(&format!(": {s}"));
        source = s.source();
    }
    match e {
        TdmsError::IoError(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => {
            format!("the file is cut short inside a segment; {text}")
        }
        TdmsError::EndOfFile => format!("the file is cut short; {text}"),
        _ => text,
    }
}

fn unreadable(path: &Path, e: &dyn std::fmt::Display) -> IngestError {
    IngestError::format(path, FormatProblem::TdmsUnreadable { why: e.to_string() })
}

struct Tdms<'p, 'b> {
    path: &'p Path,
    file: RefCell<TdmsFile<Cursor<&'b [u8]>>>,
    variables: Vec<MatVariable>,
    channels: Vec<ChannelPath>,
}

impl Tdms<'_, '_> {
    fn channel(&self, name: &str) -> (&ChannelPath, usize) {
        let i = self
            .variables
            .iter()
            .position(|v| v.name == name)
            .expect("a listed variable");
        (&self.channels[i], self.variables[i].size[0])
    }

    /// A channel's values as type `T`, widened; None when the channel is
    /// not stored as `T`.
    fn read_as<T: TdmsStorageType + Default + Clone + Into<f64>>(
        &self,
        ch: &ChannelPath,
        len: usize,
    ) -> Result<Option<Vec<f64>>, TdmsError> {
        let mut v = vec![T::default(); len];
        match self.file.borrow_mut().read_channel(ch, &mut v) {
            Ok(()) => Ok(Some(v.into_iter().map(Into::into).collect())),
            Err(TdmsError::DataTypeMismatch(..)) => Ok(None),
            Err(e) => Err(e),
        }
    }

    fn property(&self, ch: &ChannelPath, key: &str) -> Option<PropertyValue> {
        let p = PropertyPath::channel(ch.group_name(), ch.channel_name());
        self.file.borrow().read_property(&p, key).ok()?.cloned()
    }
}

impl Arrays for Tdms<'_, '_> {
    fn variables(&self) -> &[MatVariable] {
        &self.variables
    }

    fn values(&self, name: &str, _channel: &'static str) -> Result<Vec<f64>, IngestError> {
        let (ch, len) = self.channel(name);
        // The stored type cannot be asked: try each numeric one in turn.
        let readers: [&dyn Fn() -> Result<Option<Vec<f64>>, TdmsError>; 8] = [
            &|| self.read_as::<f64>(ch, len),
            &|| self.read_as::<f32>(ch, len),
            &|| self.read_as::<i32>(ch, len),
            &|| self.read_as::<i16>(ch, len),
            &|| self.read_as::<u32>(ch, len),
            &|| self.read_as::<u16>(ch, len),
            &|| self.read_as::<i8>(ch, len),
            &|| self.read_as::<u8>(ch, len),
        ];
        let read = || -> Result<Option<Vec<f64>>, TdmsError> {
            for r in readers {
                if let Some(v) = r()? {
                    return Ok(Some(v));
                }
            }
            Ok(None)
        };
        match read() {
            Ok(Some(v)) => Ok(v),
            Ok(None) => Err(unreadable(
                self.path,
                &format!("channel `{name}` holds neither floats nor integers of 32 bits or fewer"),
            )),
            Err(e) => Err(unreadable(self.path, &said(&e))),
        }
    }

    /// The rate from the first waveform channel's `wf_increment`: TDMS
    /// waveforms carry their sample interval, not their times.
    fn own_time(&self, path: &Path) -> Result<RawTime, IngestError> {
        let increment =
            self.channels
                .iter()
                .find_map(|ch| match self.property(ch, "wf_increment")? {
                    PropertyValue::DoubleFloat(d) => Some(d),
                    PropertyValue::SingleFloat(f) => Some(f64::from(f)),
                    _ => None,
                });
        match increment {
            // A zero or negative interval becomes a rate the log's checks
            // refuse, naming where it came from.
            Some(dt) => Ok(RawTime::Rate {
                hz: 1.0 / dt,
                from: "the TDMS channel's wf_increment",
            }),
            None => Err(IngestError::format(
                path,
                FormatProblem::NoTimeBase {
                    variables: self.variables.clone(),
                },
            )),
        }
    }

    fn stated_unit(&self, name: &str) -> Option<String> {
        let (ch, _) = self.channel(name);
        match self.property(ch, "unit_string")? {
            PropertyValue::String(s) => Some(s),
            _ => None,
        }
    }
}
