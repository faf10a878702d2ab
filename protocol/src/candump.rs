//! candump log files (`candump -l` format), read and written.
//!
//! One frame per line: `(SECONDS.MICROS) IFACE FRAME`, where FRAME is `ID#DATA` for classic CAN
//! (`ID#R` or `ID#Rn` for a remote frame), `ID##F DATA` for CAN FD with F one hex digit of flags
//! (1 = bit-rate switch, 2 = error state indicator). IDs of three hex digits are standard, of eight
//! are extended. Logs recorded with can-utils on a robot replay into the node, and our logs play
//! back with `canplayer`.

use std::io::{BufRead, Write};

use crate::frame::{CanFrame, Stamped, make_id};

/// A line that is not a candump record.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
#[error(
    "candump log line {line}: {msg} (expected `(SECONDS.MICROS) IFACE ID#DATA` or `ID##FLAGSDATA`)"
)]
pub struct LogError {
    /// 1-based line number in the log.
    pub line: usize,
    /// What is wrong with the line.
    pub msg: String,
}

/// One record of a log.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LogRecord {
    /// The interface column (`can0`).
    pub iface: String,
    /// The frame with its log timestamp (µs).
    pub stamped: Stamped,
}

/// Hex digit values, 0xFF for anything else: a table rather than `char::to_digit`, as a log's
/// data are most of its bytes.
const HEX: [u8; 256] = {
    let mut t = [0xFF; 256];
    let mut i = 0;
    while i < 10 {
        t[b'0' as usize + i] = i as u8;
        i += 1;
    }
    let mut i = 0;
    while i < 6 {
        t[b'a' as usize + i] = 10 + i as u8;
        t[b'A' as usize + i] = 10 + i as u8;
        i += 1;
    }
    t
};

fn hex_val(c: u8) -> Option<u8> {
    let v = HEX[c as usize];
    (v != 0xFF).then_some(v)
}

/// The six decimals of a log time's fraction (µs); digits past the sixth are dropped.
fn frac_us(frac: &str) -> Option<u64> {
    if frac.len() > 9 || !frac.bytes().all(|c| c.is_ascii_digit()) {
        return None;
    }
    let mut us = 0;
    for i in 0..6 {
        us = us * 10 + frac.as_bytes().get(i).map_or(0, |c| u64::from(c - b'0'));
    }
    Some(us)
}

fn parse_hex_bytes(s: &str, out: &mut [u8; 64]) -> Option<usize> {
    let b = s.as_bytes();
    if !b.len().is_multiple_of(2) || b.len() / 2 > 64 {
        return None;
    }
    for (i, pair) in b.chunks_exact(2).enumerate() {
        out[i] = hex_val(pair[0])? << 4 | hex_val(pair[1])?;
    }
    Some(b.len() / 2)
}

/// A log time (µs) as `candump -L` prints it: seconds with six decimals.
pub fn format_seconds(t_us: u64) -> String {
    format!("{}.{:06}", t_us / 1_000_000, t_us % 1_000_000)
}

/// Seconds as `candump -L` prints them (`1700000000.070680`, or whole seconds) to µs; digits
/// past the sixth decimal are dropped. `None` for anything else (signs, exponents, NaN).
pub fn parse_seconds(s: &str) -> Option<u64> {
    let (sec, frac) = s.split_once('.').unwrap_or((s, ""));
    if sec.is_empty() || !sec.bytes().all(|c| c.is_ascii_digit()) {
        return None;
    }
    let frac_us = frac_us(frac)?;
    sec.parse::<u64>()
        .ok()?
        .checked_mul(1_000_000)?
        .checked_add(frac_us)
}

/// Parses one log line. `Ok(None)` for blank lines and comments (`#`) and for error frames,
/// which carry no data for us.
pub fn parse_line(line: &str, line_no: usize) -> Result<Option<LogRecord>, LogError> {
    let err = |msg: &str| LogError {
        line: line_no,
        msg: msg.to_string(),
    };
    let line = line.trim_ascii();
    if line.is_empty() || line.starts_with('#') {
        return Ok(None);
    }
    // ASCII whitespace only: a record is ASCII, and the Unicode-aware split walked every
    // character of the data field one by one (most of the parsing time, by `perf`).
    let mut parts = line.split_ascii_whitespace();
    let ts = parts.next().ok_or_else(|| err("empty line"))?;
    let iface = parts.next().ok_or_else(|| err("no interface name"))?;
    let fr = parts.next().ok_or_else(|| err("no frame"))?;
    let ts = ts
        .strip_prefix('(')
        .and_then(|s| s.strip_suffix(')'))
        .ok_or_else(|| err("timestamp not in parentheses"))?;
    let (sec, frac) = ts
        .split_once('.')
        .ok_or_else(|| err("timestamp without a decimal point"))?;
    let sec: u64 = sec.parse().map_err(|_| err("bad timestamp seconds"))?;
    let frac_us = frac_us(frac)
        .filter(|_| !frac.is_empty())
        .ok_or_else(|| err("bad timestamp fraction"))?;
    let t_us = sec
        .checked_mul(1_000_000)
        .and_then(|s| s.checked_add(frac_us))
        .ok_or_else(|| err("timestamp out of range"))?;
    let (id_s, rest) = fr.split_once('#').ok_or_else(|| err("no `#` in frame"))?;
    if id_s.is_empty() || !id_s.bytes().all(|c| c.is_ascii_hexdigit()) {
        return Err(err("bad identifier"));
    }
    let raw = u32::from_str_radix(id_s, 16).map_err(|_| err("bad identifier"))?;
    if raw & 0x2000_0000 != 0 && id_s.len() == 8 {
        return Ok(None); // error frame (CAN_ERR_FLAG)
    }
    let extended = id_s.len() > 3;
    let id = make_id(raw, extended).ok_or_else(|| err("identifier out of range"))?;
    let mut data = [0u8; 64];
    let frame = if let Some(fd) = rest.strip_prefix('#') {
        let mut chars = fd.chars();
        let flags = chars
            .next()
            .and_then(|c| c.to_digit(16))
            .ok_or_else(|| err("CAN FD frame without flags digit"))?;
        let n = parse_hex_bytes(chars.as_str(), &mut data).ok_or_else(|| err("bad CAN FD data"))?;
        CanFrame::fd(id, &data[..n], flags & 1 != 0).ok_or_else(|| err("invalid CAN FD length"))?
    } else if let Some(r) = rest.strip_prefix('R') {
        let dlc = if r.is_empty() {
            0
        } else {
            r[..1].parse::<usize>().map_err(|_| err("bad remote DLC"))?
        };
        CanFrame::remote(id, dlc).ok_or_else(|| err("bad remote DLC"))?
    } else {
        // A trailing `_X` gives a raw DLC 9..15 for an 8-byte frame; the data is what counts.
        let d = rest.split('_').next().unwrap_or("");
        let n = parse_hex_bytes(d, &mut data).ok_or_else(|| err("bad data"))?;
        CanFrame::classic(id, &data[..n]).ok_or_else(|| err("classic frame longer than 8 bytes"))?
    };
    Ok(Some(LogRecord {
        iface: iface.to_string(),
        stamped: Stamped { t_us, frame },
    }))
}

/// A log file that could not be read: which file, and why.
#[derive(Debug, thiserror::Error)]
pub enum LogFileError {
    /// The file could not be opened.
    #[error("opening {path}: {source}")]
    Open {
        /// The file.
        path: String,
        /// What the OS said.
        source: std::io::Error,
    },
    /// A line is not a candump `-L` record.
    #[error("reading {path}: {source}")]
    Line {
        /// The file.
        path: String,
        /// The line and what is wrong with it.
        source: LogError,
    },
    /// Not a regular file (a pipe, `<(candump ...)`, a device): the log is read twice.
    #[error(
        "{path} is not a file (a pipe or a device): a log is read twice, checked to its end and \
         then replayed, so save it first, e.g. `timeout 5 candump -L can0 > bringup.log`, and \
         give that file"
    )]
    NotAFile {
        /// The path given.
        path: String,
    },
    /// The file no longer holds what [`LogFile::check`] read: it was cut short or rewritten
    /// between the check and the records' pass.
    #[error(
        "reading {path}: {msg} since it was checked; records up to line {line} were used (copy the log before replaying it while it is written)"
    )]
    Changed {
        /// The file.
        path: String,
        /// The last line read in the records' pass.
        line: usize,
        /// What differs.
        msg: String,
    },
}

/// Longest line read as a record. A candump line of a 64-byte CAN FD frame is about 170
/// characters; a file without a line break in its first 4 KiB is not a candump log, and reading
/// it as one line would hold all of it in memory.
pub const MAX_LINE: usize = 4096;

/// A log's records one at a time, in constant memory: the line buffer is reused, and only the
/// record in hand is held. Yields the first bad line as an error, then ends.
pub struct LogReader<R> {
    r: R,
    line: String,
    line_no: usize,
    done: bool,
}

impl<R: BufRead> LogReader<R> {
    /// Reads records from `r`.
    pub fn new(r: R) -> Self {
        Self {
            r,
            line: String::with_capacity(256),
            line_no: 0,
            done: false,
        }
    }

    /// Lines read so far (1-based number of the last one).
    pub fn lines_read(&self) -> usize {
        self.line_no
    }

    fn fail(&mut self, msg: String) -> Option<Result<LogRecord, LogError>> {
        self.done = true;
        Some(Err(LogError {
            line: self.line_no,
            msg,
        }))
    }
}

impl<R: BufRead> Iterator for LogReader<R> {
    type Item = Result<LogRecord, LogError>;

    fn next(&mut self) -> Option<Self::Item> {
        while !self.done {
            self.line.clear();
            let mut line = std::io::Read::take(&mut self.r, MAX_LINE as u64 + 1);
            let n = match line.read_line(&mut self.line) {
                Ok(n) => n,
                Err(e) => {
                    self.line_no += 1;
                    return self.fail(e.to_string());
                }
            };
            if n == 0 {
                self.done = true;
                return None;
            }
            self.line_no += 1;
            if n > MAX_LINE {
                return self.fail(format!(
                    "longer than {MAX_LINE} bytes: not a candump log (a binary file, or a recording rather than its log?)"
                ));
            }
            match parse_line(&self.line, self.line_no) {
                Ok(Some(rec)) => return Some(Ok(rec)),
                Ok(None) => {}
                Err(e) => {
                    self.done = true;
                    return Some(Err(e));
                }
            }
        }
        None
    }
}

/// A log file checked from end to end, to be read record by record in constant memory.
///
/// Nothing a log drives (a capture writing images, a replay printing decisions) should start on
/// a log that turns out bad half-way: [`LogFile::check`] reads every line first (about 1 s per
/// 200 MB), then [`LogFile::records`] reads them again, stopping at the last line checked. An
/// hours-long robot log is never held in memory (before, a 200 MB log took 196 MB resident).
#[derive(Clone, Debug)]
pub struct LogFile {
    path: std::path::PathBuf,
    lines: usize,
    /// Records in the file (error frames, comments and blank lines not counted).
    pub records: usize,
    /// Log time of the first record and of the last (µs); `None` for a log without records.
    pub span_us: Option<(u64, u64)>,
}

impl LogFile {
    /// Reads the log at `path` from end to end; the error names the file and the first bad line.
    pub fn check(path: &std::path::Path) -> Result<Self, LogFileError> {
        // A pipe would be empty on the second pass: refused, naming the fix.
        if std::fs::metadata(path).is_ok_and(|m| !m.file_type().is_file()) {
            return Err(LogFileError::NotAFile {
                path: path.display().to_string(),
            });
        }
        let mut reader = LogReader::new(open(path)?);
        let (mut records, mut span_us) = (0, None);
        for rec in reader.by_ref() {
            let t = rec
                .map_err(|source| LogFileError::Line {
                    path: path.display().to_string(),
                    source,
                })?
                .stamped
                .t_us;
            records += 1;
            span_us = Some(span_us.map_or((t, t), |(a, _): (u64, u64)| (a, t)));
        }
        Ok(Self {
            path: path.to_path_buf(),
            lines: reader.lines_read(),
            records,
            span_us,
        })
    }

    /// The file.
    pub fn path(&self) -> &std::path::Path {
        &self.path
    }

    /// The checked records, read again from the file, one at a time. Call
    /// [`LogRecords::finish`] after: it says whether the file still held them all.
    pub fn records(&self) -> Result<LogRecords<'_>, LogFileError> {
        Ok(LogRecords {
            reader: LogReader::new(open(&self.path)?),
            file: self,
            read: 0,
            changed: None,
        })
    }
}

fn open(path: &std::path::Path) -> Result<std::io::BufReader<std::fs::File>, LogFileError> {
    std::fs::File::open(path)
        .map(|f| std::io::BufReader::with_capacity(1 << 16, f))
        .map_err(|source| LogFileError::Open {
            path: path.display().to_string(),
            source,
        })
}

/// The records of a [`LogFile`], streamed. Ends early if the file changed since its check;
/// [`LogRecords::finish`] then says so.
pub struct LogRecords<'a> {
    reader: LogReader<std::io::BufReader<std::fs::File>>,
    file: &'a LogFile,
    read: usize,
    changed: Option<String>,
}

impl Iterator for LogRecords<'_> {
    type Item = LogRecord;

    fn next(&mut self) -> Option<LogRecord> {
        if self.changed.is_some() || self.reader.lines_read() >= self.file.lines {
            return None;
        }
        match self.reader.next() {
            Some(Ok(rec)) => {
                self.read += 1;
                Some(rec)
            }
            Some(Err(e)) => {
                self.changed = Some(format!("a line changed ({e})"));
                None
            }
            None => {
                self.changed = Some(format!(
                    "the log ends at line {} of the {} checked ({} of its {} records read)",
                    self.reader.lines_read(),
                    self.file.lines,
                    self.read,
                    self.file.records
                ));
                None
            }
        }
    }
}

impl LogRecords<'_> {
    /// Records handed out so far.
    pub fn read(&self) -> usize {
        self.read
    }

    /// `Ok` unless the file was cut short or a line of it changed since its check (stopping
    /// early by the caller's choice is fine).
    pub fn finish(self) -> Result<(), LogFileError> {
        match self.changed {
            Some(msg) => Err(LogFileError::Changed {
                path: self.file.path.display().to_string(),
                line: self.reader.lines_read(),
                msg,
            }),
            None => Ok(()),
        }
    }
}

/// Reads every record of the log file at `path` into memory ([`read_log`]); the error names the
/// file. For short logs: a robot's log is read with [`LogFile`].
pub fn read_log_file(path: &std::path::Path) -> Result<Vec<LogRecord>, LogFileError> {
    read_log(open(path)?).map_err(|source| LogFileError::Line {
        path: path.display().to_string(),
        source,
    })
}

/// Reads every record of a log into memory. Stops at the first bad line with its number.
pub fn read_log(r: impl BufRead) -> Result<Vec<LogRecord>, LogError> {
    LogReader::new(r).collect()
}

/// Writes one record in `candump -l` format.
pub fn write_record(w: &mut impl Write, iface: &str, st: &Stamped) -> std::io::Result<()> {
    let f = &st.frame;
    write!(w, "({}) {iface} ", format_seconds(st.t_us))?;
    if f.is_extended() {
        write!(w, "{:08X}", f.raw_id())?;
    } else {
        write!(w, "{:03X}", f.raw_id())?;
    }
    if f.is_fd() {
        write!(w, "##{:X}", if f.is_brs() { 1 } else { 0 })?;
    } else {
        write!(w, "#")?;
    }
    if f.is_remote() {
        write!(w, "R")?;
        if !f.is_empty() {
            write!(w, "{}", f.len())?;
        }
    } else {
        for b in f.data() {
            write!(w, "{b:02X}")?;
        }
    }
    writeln!(w)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    #[test]
    fn seconds_round_trip_as_candump_prints_them() {
        for us in [0, 1, 999_999, 1_700_000_000_070_680] {
            assert_eq!(parse_seconds(&format_seconds(us)), Some(us));
        }
        assert_eq!(parse_seconds("30"), Some(30_000_000));
        assert_eq!(parse_seconds("1.5"), Some(1_500_000));
        assert_eq!(parse_seconds("1.1234567"), Some(1_123_456));
        for bad in ["", "x", "-1", "1e3", "NaN", "1.2.3", ".5"] {
            assert_eq!(parse_seconds(bad), None, "{bad}");
        }
    }

    #[test]
    fn round_trip_all_kinds() {
        let recs = [
            CanFrame::classic(make_id(0x123, false).unwrap(), &[0xDE, 0xAD]).unwrap(),
            CanFrame::classic(make_id(0x1ABCDEF0, true).unwrap(), &[]).unwrap(),
            CanFrame::fd(make_id(0x600, false).unwrap(), &[7; 64], true).unwrap(),
            CanFrame::fd(make_id(0x601, false).unwrap(), &[1; 12], false).unwrap(),
            CanFrame::remote(make_id(0x7FF, false).unwrap(), 3).unwrap(),
        ];
        let mut out = Vec::new();
        for (i, f) in recs.iter().enumerate() {
            write_record(
                &mut out,
                "vcan0",
                &Stamped {
                    t_us: 1_700_000_000_000_000 + i as u64 * 7,
                    frame: *f,
                },
            )
            .unwrap();
        }
        let text = String::from_utf8(out).unwrap();
        assert!(
            text.starts_with("(1700000000.000000) vcan0 123#DEAD\n"),
            "{text}"
        );
        assert!(text.contains(" 600##1070707"));
        let back = read_log(text.as_bytes()).unwrap();
        assert_eq!(back.len(), recs.len());
        for (r, f) in back.iter().zip(&recs) {
            assert_eq!(&r.stamped.frame, f);
            assert_eq!(r.iface, "vcan0");
        }
        assert_eq!(back[2].stamped.t_us, 1_700_000_000_000_014);
    }

    #[test]
    fn can_utils_lines_parse() {
        let r = parse_line("(1436509052.249713) can0 12345678#1122334455667788", 1)
            .unwrap()
            .unwrap();
        assert!(r.stamped.frame.is_extended());
        assert_eq!(r.stamped.t_us, 1436509052249713);
        let r = parse_line("(0.5) vcan1 0A0#00_9", 1).unwrap().unwrap();
        assert_eq!(r.stamped.t_us, 500_000);
        assert_eq!(r.stamped.frame.data(), &[0]);
        assert_eq!(
            parse_line("(1.000000) can0 20000080#0000000000000000", 1),
            Ok(None)
        );
    }

    #[test]
    fn bad_lines_name_the_line() {
        for bad in [
            "1.0 can0 123#00",
            "(1.0) can0",
            "(1.0) can0 123",
            "(1.0) can0 XYZ#00",
            "(1.0) can0 123#0",
            "(1.0) can0 123#001122334455667788",
            "(1.0) can0 800#00",
            "(1.0) can0 123##G00",
            "(1.0) can0 123##1000000000000000000000",
            "(1.x) can0 123#00",
        ] {
            let e = parse_line(bad, 42).unwrap_err();
            assert_eq!(e.line, 42, "{bad}");
            assert!(e.to_string().contains("line 42"));
        }
    }

    /// A file of its own under the system's temp folder, removed on drop.
    struct TempLog(std::path::PathBuf);

    impl TempLog {
        fn new(name: &str, text: &[u8]) -> Self {
            let p = std::env::temp_dir()
                .join(format!("presrs-candump-{}-{name}.log", std::process::id()));
            std::fs::write(&p, text).unwrap();
            Self(p)
        }
    }

    impl Drop for TempLog {
        fn drop(&mut self) {
            let _ = std::fs::remove_file(&self.0);
        }
    }

    fn lines(n: usize) -> String {
        (0..n)
            .map(|i| {
                format!(
                    "({}.{:06}) can0 123#{:02X}\n",
                    i / 100,
                    (i % 100) * 10_000,
                    i % 256
                )
            })
            .collect()
    }

    #[test]
    fn reader_streams_what_read_log_reads_and_stops_at_the_first_bad_line() {
        let mut text = lines(5);
        text.push_str("# a comment\n\n(1.0) can0 20000080#0000000000000000\n");
        text.push_str(&lines(3));
        let all = read_log(text.as_bytes()).unwrap();
        assert_eq!(all.len(), 8);
        let streamed: Vec<_> = LogReader::new(text.as_bytes())
            .map(Result::unwrap)
            .collect();
        assert_eq!(streamed, all);

        text.push_str("(2.0) can0 123#0\n");
        text.push_str(&lines(2));
        let mut r = LogReader::new(text.as_bytes());
        assert_eq!(r.by_ref().take_while(Result::is_ok).count(), 8);
        assert_eq!(r.lines_read(), 12, "the bad line is line 12");
        assert!(r.next().is_none(), "nothing after the first bad line");
        let e = read_log(text.as_bytes()).unwrap_err();
        assert_eq!(e.line, 12);
    }

    #[test]
    fn a_file_without_line_breaks_is_refused_not_read_whole() {
        let text = vec![b'7'; 3 * MAX_LINE];
        let e = read_log(&text[..]).unwrap_err();
        assert_eq!(e.line, 1);
        assert!(e.msg.contains("not a candump log"), "{e}");
        // The longest record a log holds, a 64-byte CAN FD frame on a long interface name,
        // stays far inside the limit.
        let mut w = Vec::new();
        let fd = CanFrame::fd(make_id(0x1FFF_FFFF, true).unwrap(), &[0xAB; 64], true).unwrap();
        let st = Stamped {
            t_us: u64::MAX / 2,
            frame: fd,
        };
        write_record(&mut w, "a-long-interface0", &st).unwrap();
        assert!(w.len() < 200, "{}", w.len());
        assert_eq!(read_log(&w[..]).unwrap()[0].stamped, st);
    }

    #[test]
    fn log_file_checks_then_streams_every_record() {
        let text = lines(250);
        let f = TempLog::new("stream", text.as_bytes());
        let log = LogFile::check(&f.0).unwrap();
        assert_eq!(log.records, 250);
        assert_eq!(log.span_us, Some((0, 2_490_000)));
        let mut recs = log.records().unwrap();
        let got: Vec<_> = recs.by_ref().collect();
        assert_eq!(got, read_log(text.as_bytes()).unwrap());
        assert_eq!(recs.read(), 250);
        recs.finish().unwrap();

        // Stopping early by choice is not an error.
        let mut recs = log.records().unwrap();
        assert_eq!(recs.by_ref().take(10).count(), 10);
        recs.finish().unwrap();
    }

    #[test]
    fn log_file_check_names_the_file_and_line_and_streams_nothing() {
        let mut text = lines(20);
        text.push_str("(9.0) can0 XYZ#00\n");
        let f = TempLog::new("bad", text.as_bytes());
        let e = LogFile::check(&f.0).unwrap_err().to_string();
        assert!(e.contains(&f.0.display().to_string()), "{e}");
        assert!(e.contains("line 21"), "{e}");
        let e = LogFile::check(Path::new("/nonexistent/presrs.log")).unwrap_err();
        assert!(e.to_string().contains("/nonexistent/presrs.log"), "{e}");
    }

    #[test]
    fn a_log_changed_after_its_check_is_reported_not_silently_cut() {
        let f = TempLog::new("changed", lines(100).as_bytes());
        let log = LogFile::check(&f.0).unwrap();

        // Cut short.
        std::fs::write(&f.0, lines(40)).unwrap();
        let mut recs = log.records().unwrap();
        assert_eq!(recs.by_ref().count(), 40);
        let e = recs.finish().unwrap_err().to_string();
        assert!(e.contains("40 of its 100 records"), "{e}");
        assert!(e.contains(&f.0.display().to_string()), "{e}");

        // A line rewritten bad.
        let mut text = lines(30);
        text.push_str("(1.0) can0 123#0\n");
        text.push_str(&lines(69));
        std::fs::write(&f.0, &text).unwrap();
        let mut recs = log.records().unwrap();
        assert_eq!(recs.by_ref().count(), 30);
        let e = recs.finish().unwrap_err().to_string();
        assert!(e.contains("line 31"), "{e}");

        // Grown (a candump still writing it): the records checked, and no more.
        std::fs::write(&f.0, lines(150)).unwrap();
        let mut recs = log.records().unwrap();
        assert_eq!(recs.by_ref().count(), 100);
        recs.finish().unwrap();
    }

    #[test]
    fn a_pipe_is_refused_naming_the_fix_not_replayed_empty() {
        // /dev/null stands in for `<(candump ...)`: not a regular file.
        let e = LogFile::check(std::path::Path::new("/dev/null")).unwrap_err();
        assert!(matches!(e, LogFileError::NotAFile { .. }), "{e}");
        assert!(
            e.to_string().contains("candump -L can0 > bringup.log"),
            "{e}"
        );
    }
}
