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

fn hex_val(c: u8) -> Option<u8> {
    (c as char).to_digit(16).map(|d| d as u8)
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
    if frac.len() > 9 || !frac.bytes().all(|c| c.is_ascii_digit()) {
        return None;
    }
    let frac_us: u64 = format!("{frac:0<6}")[..6].parse().ok()?;
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
    let line = line.trim();
    if line.is_empty() || line.starts_with('#') {
        return Ok(None);
    }
    let mut parts = line.split_whitespace();
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
    if frac.is_empty() || frac.len() > 9 || !frac.bytes().all(|c| c.is_ascii_digit()) {
        return Err(err("bad timestamp fraction"));
    }
    let frac_us = format!("{frac:0<6}")[..6]
        .parse::<u64>()
        .map_err(|_| err("bad timestamp fraction"))?;
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
}

/// Reads every record of the log file at `path` ([`read_log`]); the error names the file.
pub fn read_log_file(path: &std::path::Path) -> Result<Vec<LogRecord>, LogFileError> {
    let name = || path.display().to_string();
    let file = std::fs::File::open(path).map_err(|source| LogFileError::Open {
        path: name(),
        source,
    })?;
    read_log(std::io::BufReader::new(file)).map_err(|source| LogFileError::Line {
        path: name(),
        source,
    })
}

/// Reads every record of a log. Stops at the first bad line with its number.
pub fn read_log(r: impl BufRead) -> Result<Vec<LogRecord>, LogError> {
    let mut out = Vec::new();
    for (i, line) in r.lines().enumerate() {
        let line = line.map_err(|e| LogError {
            line: i + 1,
            msg: e.to_string(),
        })?;
        if let Some(rec) = parse_line(&line, i + 1)? {
            out.push(rec);
        }
    }
    Ok(out)
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
}
