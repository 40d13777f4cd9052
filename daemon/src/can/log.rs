//! `candump -L` logging of every frame the daemon sends and receives, and a reader
//! to replay such logs.
//!
//! Format (can-utils `candump -L`, replayable with `canplayer`): one frame a line,
//!
//! ```text
//! (1700000000.123456) can0 121#0011223344556677
//! ```
//!
//! wall-clock seconds with exactly six fractional digits, the interface name, and
//! the frame as a 3-hex-digit standard id, `#`, and the data bytes in hex. The
//! same format is what a field engineer records on the machine with `candump -L
//! can0`, so a log from either side can be replayed through the codec.
//!
//! Why our own reader instead of `socketcan::dump::Reader`: its errors do not say
//! which line is wrong, and a replay tool should point at the line. The reader
//! accepts what this protocol can carry (standard-id classic data frames, with the
//! optional `R`/`T` direction field of `candump -x`) and rejects anything else
//! per line with a typed error; the iterator keeps going after a bad line, so a
//! caller can skip foreign traffic.

use std::fs::{File, OpenOptions};
use std::io::{self, BufRead, BufReader, BufWriter, Write};
use std::path::Path;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use async_trait::async_trait;
use thiserror::Error;

use super::{CanBus, CanError, CanFrame, MAX_STANDARD_ID};

/// One `candump -L` line: `(sec.usec) iface ID#DATA`.
pub fn format_line(timestamp: SystemTime, iface: &str, frame: &CanFrame) -> String {
    // A clock before 1970 is a broken clock; log 0 rather than fail to log.
    let t = timestamp.duration_since(UNIX_EPOCH).unwrap_or_default();
    format!(
        "({}.{:06}) {} {}",
        t.as_secs(),
        t.subsec_micros(),
        iface,
        frame
    )
}

/// Writes frames as `candump -L` lines.
///
/// Each line is flushed as it is written: the log matters most when the daemon
/// dies, and at the protocol's rates (tens of frames a second) a write per frame
/// costs nothing measurable.
#[derive(Debug)]
pub struct CandumpWriter<W: Write> {
    out: W,
    iface: String,
}

impl CandumpWriter<BufWriter<File>> {
    /// Append to the file at `path` (created if missing). Appending, not
    /// truncating, so a restart by systemd keeps the log of the run that failed.
    pub fn append_to(path: &Path, iface: &str) -> io::Result<Self> {
        let file = OpenOptions::new().create(true).append(true).open(path)?;
        Ok(Self::new(BufWriter::new(file), iface))
    }
}

impl<W: Write> CandumpWriter<W> {
    /// Log to `out`, naming the interface `iface` on every line. Interface names
    /// must not contain whitespace (they cannot, in Linux); any is replaced by `_`
    /// so the line stays parseable.
    pub fn new(out: W, iface: &str) -> Self {
        let iface: String = iface
            .chars()
            .map(|c| if c.is_whitespace() { '_' } else { c })
            .collect();
        let iface = if iface.is_empty() {
            "can".to_owned()
        } else {
            iface
        };
        Self { out, iface }
    }

    /// Append one frame with the given timestamp, and flush.
    pub fn write(&mut self, timestamp: SystemTime, frame: &CanFrame) -> io::Result<()> {
        writeln!(self.out, "{}", format_line(timestamp, &self.iface, frame))?;
        self.out.flush()
    }

    /// The underlying writer.
    pub fn into_inner(self) -> W {
        self.out
    }
}

/// A [`CanBus`] that logs every frame sent and received through it.
///
/// Logging is diagnostics, never a reason to stop talking to the machine: a write
/// error (full disk, say) is reported once through `tracing` and counted, and the
/// frame still goes out or comes in.
pub struct LoggingBus<B, W: Write = BufWriter<File>> {
    inner: B,
    log: CandumpWriter<W>,
    log_errors: u64,
}

impl<B: CanBus, W: Write + Send> LoggingBus<B, W> {
    /// Wrap `inner`, logging to `log`.
    pub fn new(inner: B, log: CandumpWriter<W>) -> Self {
        Self {
            inner,
            log,
            log_errors: 0,
        }
    }

    /// Frames that could not be logged.
    pub fn log_errors(&self) -> u64 {
        self.log_errors
    }

    /// The wrapped bus and the log writer.
    pub fn into_parts(self) -> (B, CandumpWriter<W>) {
        (self.inner, self.log)
    }

    fn record(&mut self, frame: &CanFrame) {
        if let Err(e) = self.log.write(SystemTime::now(), frame) {
            self.log_errors += 1;
            if self.log_errors == 1 {
                tracing::warn!(bus = self.inner.name(), error = %e, "CAN frame log write failed; further failures are counted only");
            }
        }
    }
}

impl<B: std::fmt::Debug, W: Write> std::fmt::Debug for LoggingBus<B, W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LoggingBus")
            .field("inner", &self.inner)
            .field("iface", &self.log.iface)
            .field("log_errors", &self.log_errors)
            .finish()
    }
}

#[async_trait]
impl<B: CanBus, W: Write + Send> CanBus for LoggingBus<B, W> {
    async fn send(&mut self, frame: &CanFrame) -> Result<(), CanError> {
        self.inner.send(frame).await?;
        // Logged after the send succeeded: the log shows what went on the bus.
        self.record(frame);
        Ok(())
    }

    async fn recv(&mut self) -> Result<CanFrame, CanError> {
        let frame = self.inner.recv().await?;
        self.record(&frame);
        Ok(frame)
    }

    fn name(&self) -> &str {
        self.inner.name()
    }
}

/// One replayed frame.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LogRecord {
    /// Time since the Unix epoch, microsecond resolution.
    pub timestamp: Duration,
    /// Interface name as logged.
    pub iface: String,
    /// The frame.
    pub frame: CanFrame,
}

/// What is wrong with a log line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum LineProblem {
    /// The line is not valid UTF-8 text.
    #[error("not UTF-8 text")]
    NotUtf8,
    /// Fewer than the three fields `(time) iface frame`.
    #[error("expected `(seconds.micros) iface ID#DATA`")]
    MissingField,
    /// A fourth field other than the `R`/`T` direction of `candump -x`.
    #[error("unexpected extra field")]
    ExtraField,
    /// The timestamp is not `(digits.6digits)`.
    #[error("timestamp is not `(seconds.micros)` with six digits of microseconds")]
    BadTimestamp,
    /// No `#` between id and data.
    #[error("frame has no `#` between id and data")]
    MissingHash,
    /// The id is not 3 hex digits ≤ 7FF.
    #[error("CAN id is not 3 hex digits up to 7FF")]
    BadId,
    /// An 8-digit id: extended (29-bit) or error frame, not part of this protocol.
    #[error("extended or error frame (8-digit id) is not supported")]
    ExtendedId,
    /// `ID#R…`: a remote frame.
    #[error("remote frame is not supported")]
    RemoteFrame,
    /// `ID##…`: a CAN FD frame.
    #[error("CAN FD frame is not supported")]
    FdFrame,
    /// `…_D`: a raw DLC above 8.
    #[error("raw DLC suffix `_x` is not supported")]
    DlcSuffix,
    /// Data is not an even number of hex digits.
    #[error("data is not pairs of hex digits")]
    BadData,
    /// More than 8 data bytes.
    #[error("more than 8 data bytes")]
    TooLong,
}

/// A log that cannot be read, or a line that cannot be parsed. Names the source and
/// the 1-based line.
#[derive(Debug, Error)]
pub enum ReplayError {
    /// The log file could not be opened.
    #[error("{source_name}: cannot open: {error}")]
    Open {
        /// File name.
        source_name: String,
        /// The OS error.
        error: io::Error,
    },
    /// Reading failed.
    #[error("{source_name} line {line}: read failed: {error}")]
    Io {
        /// File name (or the name given to the reader).
        source_name: String,
        /// 1-based line number.
        line: usize,
        /// The OS error.
        error: io::Error,
    },
    /// A line is not a supported `candump -L` record.
    #[error("{source_name} line {line}: {problem}: {text:?}")]
    Parse {
        /// File name (or the name given to the reader).
        source_name: String,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        problem: LineProblem,
        /// The offending line (trimmed, at most 120 characters).
        text: String,
    },
}

impl ReplayError {
    /// The line-level problem, if this is a parse error.
    pub fn problem(&self) -> Option<LineProblem> {
        match self {
            Self::Parse { problem, .. } => Some(*problem),
            _ => None,
        }
    }

    /// The 1-based line number, where there is one.
    pub fn line(&self) -> Option<usize> {
        match self {
            Self::Io { line, .. } | Self::Parse { line, .. } => Some(*line),
            Self::Open { .. } => None,
        }
    }
}

/// Parse one `candump -L` line (without its newline).
pub fn parse_line(line: &str) -> Result<LogRecord, LineProblem> {
    let mut fields = line.split_ascii_whitespace();
    let (Some(ts), Some(iface), Some(frame)) = (fields.next(), fields.next(), fields.next()) else {
        return Err(LineProblem::MissingField);
    };
    match fields.next() {
        None | Some("R") | Some("T") => {}
        Some(_) => return Err(LineProblem::ExtraField),
    }
    if fields.next().is_some() {
        return Err(LineProblem::ExtraField);
    }
    Ok(LogRecord {
        timestamp: parse_timestamp(ts)?,
        iface: iface.to_owned(),
        frame: parse_frame(frame)?,
    })
}

fn parse_timestamp(ts: &str) -> Result<Duration, LineProblem> {
    let inner = ts
        .strip_prefix('(')
        .and_then(|s| s.strip_suffix(')'))
        .ok_or(LineProblem::BadTimestamp)?;
    let (sec, usec) = inner.split_once('.').ok_or(LineProblem::BadTimestamp)?;
    let all_digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    if !all_digits(sec) || usec.len() != 6 || !all_digits(usec) {
        return Err(LineProblem::BadTimestamp);
    }
    let sec: u64 = sec.parse().map_err(|_| LineProblem::BadTimestamp)?;
    let usec: u32 = usec.parse().map_err(|_| LineProblem::BadTimestamp)?;
    Ok(Duration::new(sec, usec * 1000))
}

/// Parse `ID#DATA` (standard-id classic data frames only).
pub fn parse_frame(text: &str) -> Result<CanFrame, LineProblem> {
    let (id, data) = text.split_once('#').ok_or(LineProblem::MissingHash)?;
    let is_hex = |s: &str| s.bytes().all(|b| b.is_ascii_hexdigit());
    let id = match id.len() {
        3 if is_hex(id) => u16::from_str_radix(id, 16).map_err(|_| LineProblem::BadId)?,
        8 if is_hex(id) => return Err(LineProblem::ExtendedId),
        _ => return Err(LineProblem::BadId),
    };
    if id > MAX_STANDARD_ID {
        return Err(LineProblem::BadId);
    }
    if data.starts_with('#') {
        return Err(LineProblem::FdFrame);
    }
    if data.starts_with(['R', 'r']) {
        return Err(LineProblem::RemoteFrame);
    }
    if data.contains('_') {
        return Err(LineProblem::DlcSuffix);
    }
    if data.len() % 2 != 0 || !is_hex(data) {
        return Err(LineProblem::BadData);
    }
    if data.len() > 16 {
        return Err(LineProblem::TooLong);
    }
    let mut bytes = [0u8; 8];
    for (i, pair) in data.as_bytes().chunks_exact(2).enumerate() {
        // Both are ASCII hex digits (checked above), so this cannot fail.
        let s = std::str::from_utf8(pair).map_err(|_| LineProblem::BadData)?;
        bytes[i] = u8::from_str_radix(s, 16).map_err(|_| LineProblem::BadData)?;
    }
    CanFrame::new(id, &bytes[..data.len() / 2]).map_err(|_| LineProblem::BadData)
}

/// Reads a `candump -L` log as an iterator of records.
///
/// Blank lines and lines starting with `#` are skipped (comments in hand-written
/// test logs). A bad line yields an error and iteration continues with the next
/// one; a read error ends the iteration after it is reported.
#[derive(Debug)]
pub struct CandumpReader<R> {
    input: R,
    source_name: String,
    line: usize,
    buf: Vec<u8>,
    done: bool,
}

impl CandumpReader<BufReader<File>> {
    /// Open the log at `path`.
    pub fn open(path: &Path) -> Result<Self, ReplayError> {
        let name = path.display().to_string();
        let file = File::open(path).map_err(|error| ReplayError::Open {
            source_name: name.clone(),
            error,
        })?;
        Ok(Self::new(BufReader::new(file), &name))
    }
}

impl<R: BufRead> CandumpReader<R> {
    /// Read from `input`; `source_name` appears in errors.
    pub fn new(input: R, source_name: &str) -> Self {
        Self {
            input,
            source_name: source_name.to_owned(),
            line: 0,
            buf: Vec::new(),
            done: false,
        }
    }
}

impl<R: BufRead> Iterator for CandumpReader<R> {
    type Item = Result<LogRecord, ReplayError>;

    fn next(&mut self) -> Option<Self::Item> {
        while !self.done {
            self.buf.clear();
            self.line += 1;
            match self.input.read_until(b'\n', &mut self.buf) {
                Ok(0) => self.done = true,
                Ok(_) => {
                    let parse_err = |problem, text: &str| ReplayError::Parse {
                        source_name: self.source_name.clone(),
                        line: self.line,
                        problem,
                        text: text.chars().take(120).collect(),
                    };
                    let Ok(text) = std::str::from_utf8(&self.buf) else {
                        let lossy = String::from_utf8_lossy(&self.buf).trim().to_owned();
                        return Some(Err(parse_err(LineProblem::NotUtf8, &lossy)));
                    };
                    let text = text.trim();
                    if text.is_empty() || text.starts_with('#') {
                        continue;
                    }
                    return Some(parse_line(text).map_err(|p| parse_err(p, text)));
                }
                Err(error) => {
                    self.done = true;
                    return Some(Err(ReplayError::Io {
                        source_name: self.source_name.clone(),
                        line: self.line,
                        error,
                    }));
                }
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_like_candump() {
        let t = UNIX_EPOCH + Duration::new(1_700_000_000, 123_456_789);
        let f = CanFrame::new(0x123, &[0x00, 0x11, 0x22, 0x33, 0x44, 0x55, 0x66, 0x77]).unwrap();
        assert_eq!(
            format_line(t, "can0", &f),
            "(1700000000.123456) can0 123#0011223344556677"
        );
    }

    #[test]
    fn parses_lines() {
        let r = parse_line("(1700000000.000001) vcan0 07F#DEADbeef T").unwrap();
        assert_eq!(r.timestamp, Duration::new(1_700_000_000, 1_000));
        assert_eq!(r.iface, "vcan0");
        assert_eq!(
            r.frame,
            CanFrame::new(0x7F, &[0xDE, 0xAD, 0xBE, 0xEF]).unwrap()
        );
        assert_eq!(parse_line("(1.000000) can0 100#").unwrap().frame.len(), 0);
    }

    #[test]
    fn rejects_bad_lines_with_the_reason() {
        use LineProblem::*;
        let cases = [
            ("(1.000000) can0", MissingField),
            ("(1.000000) can0 123#00 X", ExtraField),
            ("(1.000000) can0 123#00 R extra", ExtraField),
            ("1.000000 can0 123#00", BadTimestamp),
            ("(1.00000) can0 123#00", BadTimestamp),
            ("(1.0000001) can0 123#00", BadTimestamp),
            ("(x.000000) can0 123#00", BadTimestamp),
            ("(1.000000) can0 12300", MissingHash),
            ("(1.000000) can0 800#00", BadId),
            ("(1.000000) can0 12#00", BadId),
            ("(1.000000) can0 12G#00", BadId),
            ("(1.000000) can0 00000123#00", ExtendedId),
            ("(1.000000) can0 123#R", RemoteFrame),
            ("(1.000000) can0 123##1001122", FdFrame),
            ("(1.000000) can0 123#0011223344556677_9", DlcSuffix),
            ("(1.000000) can0 123#001", BadData),
            ("(1.000000) can0 123#0x", BadData),
            ("(1.000000) can0 123#+1", BadData),
            ("(1.000000) can0 123#001122334455667788", TooLong),
        ];
        for (line, want) in cases {
            assert_eq!(parse_line(line).map(|_| ()), Err(want), "{line}");
        }
    }

    #[test]
    fn reader_names_lines_and_continues() {
        let text = b"# comment\n\n(1.000000) can0 123#01\n(2.000000) can0 zzz#01\n\xff\xfe\n(3.000000) can0 124#02\n";
        let got: Vec<_> = CandumpReader::new(&text[..], "mem.log").collect();
        assert_eq!(got.len(), 4);
        assert_eq!(got[0].as_ref().unwrap().frame.id(), 0x123);
        let e = got[1].as_ref().unwrap_err();
        assert_eq!(e.line(), Some(4));
        assert_eq!(e.problem(), Some(LineProblem::BadId));
        assert!(e.to_string().starts_with("mem.log line 4: "), "{e}");
        assert_eq!(
            got[2].as_ref().unwrap_err().problem(),
            Some(LineProblem::NotUtf8)
        );
        assert_eq!(got[3].as_ref().unwrap().frame.id(), 0x124);
    }
}
