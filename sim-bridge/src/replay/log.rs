//! Step log files (`proto/ssrdrive/v1/log.proto`): length-delimited `LogRecord`s, a header
//! first. [`LogWriter`] writes `NAME.partial` and renames it when the run ends, so a file
//! without the suffix is complete; [`read_log`] reads either (whole, into memory: about 10 KB
//! per tick of a 320x96 camera), keeps every whole tick of a log cut short (and says so), and
//! refuses a corrupt record with its index.

use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};

use prost::Message;
use ssrdrive_proto::v1;

/// Format name in every header.
pub const LOG_FORMAT: &str = "ssrdrive-step-log";
/// Version written and read.
pub const LOG_VERSION: u32 = 1;
/// Largest record read, bytes (a tick of six 1600x900 PNG frames fits).
const MAX_RECORD_BYTES: u64 = 128 << 20;

/// The shortest and longest tick a header may name, seconds.
const MIN_TICK_S: f64 = 0.001;
const MAX_TICK_S: f64 = 1.0;

/// Why a log cannot be read or written.
pub type LogError = ssrdrive_support::files::FileError;

/// A log being written.
pub struct LogWriter {
    out: BufWriter<File>,
    partial: PathBuf,
    path: PathBuf,
}

impl LogWriter {
    /// Creates `path.partial` and writes the header.
    pub fn create(path: &Path, header: v1::LogHeader) -> Result<Self, LogError> {
        let mut partial = path.as_os_str().to_owned();
        partial.push(".partial");
        let partial = PathBuf::from(partial);
        let file = File::create(&partial).map_err(|e| LogError::io(&partial, e))?;
        let mut writer = Self {
            out: BufWriter::new(file),
            partial,
            path: path.to_path_buf(),
        };
        writer.write(v1::log_record::Record::Header(header))?;
        Ok(writer)
    }

    fn write(&mut self, record: v1::log_record::Record) -> Result<(), LogError> {
        let bytes = v1::LogRecord {
            record: Some(record),
        }
        .encode_length_delimited_to_vec();
        self.out
            .write_all(&bytes)
            .map_err(|e| LogError::io(&self.partial, e))
    }

    /// Appends one tick's record.
    pub fn tick(&mut self, tick: v1::LogTick) -> Result<(), LogError> {
        self.write(v1::log_record::Record::Tick(tick))
    }

    /// Flushes and renames the file to its final name.
    pub fn finish(mut self) -> Result<PathBuf, LogError> {
        self.out
            .flush()
            .map_err(|e| LogError::io(&self.partial, e))?;
        std::fs::rename(&self.partial, &self.path).map_err(|e| LogError::io(&self.path, e))?;
        Ok(self.path)
    }
}

/// A log read back.
#[derive(Debug, Clone)]
pub struct StepLog {
    /// The first record: format, who drove, route, seed, rig, tick length and ego box.
    pub header: v1::LogHeader,
    /// Every whole tick record, in order.
    pub ticks: Vec<v1::LogTick>,
    /// The file ended inside a record (a run that was cut off): the whole ticks before it are
    /// kept.
    pub truncated: bool,
}

fn read_varint(reader: &mut impl Read) -> std::io::Result<Option<u64>> {
    let mut value = 0u64;
    for shift in (0..64).step_by(7) {
        let mut byte = [0u8];
        if reader.read(&mut byte)? == 0 {
            return if shift == 0 {
                Ok(None)
            } else {
                Err(std::io::ErrorKind::UnexpectedEof.into())
            };
        }
        value |= u64::from(byte[0] & 0x7f) << shift;
        if byte[0] & 0x80 == 0 {
            return Ok(Some(value));
        }
    }
    Err(std::io::Error::new(
        std::io::ErrorKind::InvalidData,
        "length prefix longer than 10 bytes",
    ))
}

/// Reads a whole log (see the module doc for what is kept of a cut-off one).
pub fn read_log(path: &Path) -> Result<StepLog, LogError> {
    let file = File::open(path).map_err(|e| LogError::io(path, e))?;
    parse_log(BufReader::new(file), path)
}

/// [`read_log`] of the bytes `reader` gives; `path` names them in errors.
pub fn parse_log(mut reader: impl Read, path: &Path) -> Result<StepLog, LogError> {
    let mut header = None;
    let mut ticks = Vec::new();
    let mut truncated = false;
    for index in 0.. {
        let length = match read_varint(&mut reader) {
            Ok(Some(length)) => length,
            Ok(None) => break,
            Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => {
                truncated = true;
                break;
            }
            Err(e) => return Err(LogError::io(path, e)),
        };
        if length > MAX_RECORD_BYTES {
            return Err(LogError::invalid(
                path,
                format!("record {index} claims {length} bytes (at most {MAX_RECORD_BYTES})"),
            ));
        }
        let mut bytes = Vec::new();
        let read = (&mut reader)
            .take(length)
            .read_to_end(&mut bytes)
            .map_err(|e| LogError::io(path, e))?;
        if (read as u64) < length {
            truncated = true;
            break;
        }
        let record = v1::LogRecord::decode(bytes.as_slice())
            .map_err(|e| LogError::invalid(path, format!("record {index} is corrupt: {e}")))?;
        match (index, record.record) {
            (0, Some(v1::log_record::Record::Header(h))) => {
                if h.format != LOG_FORMAT || h.version != LOG_VERSION {
                    return Err(LogError::invalid(
                        path,
                        format!(
                            "format '{}' version {}; this build reads '{LOG_FORMAT}' version {LOG_VERSION}",
                            h.format, h.version
                        ),
                    ));
                }
                // 0 is a header without it (the simulator's tick is assumed); anything else
                // divides horizons into ticks, so it must be a real tick length.
                if h.tick_s != 0.0 && !(MIN_TICK_S..=MAX_TICK_S).contains(&h.tick_s) {
                    return Err(LogError::invalid(
                        path,
                        format!(
                            "header tick_s = {:?} s is outside {MIN_TICK_S}..{MAX_TICK_S} s",
                            h.tick_s
                        ),
                    ));
                }
                header = Some(h);
            }
            (0, _) => return Err(LogError::invalid(path, "does not start with a log header")),
            (_, Some(v1::log_record::Record::Tick(tick))) => ticks.push(tick),
            (_, _) => {
                return Err(LogError::invalid(
                    path,
                    format!("record {index} is not a tick"),
                ));
            }
        }
    }
    let header = header.ok_or_else(|| {
        LogError::invalid(
            path,
            if truncated {
                "cut off inside its header"
            } else {
                "empty file: no log header"
            },
        )
    })?;
    Ok(StepLog {
        header,
        ticks,
        truncated,
    })
}
