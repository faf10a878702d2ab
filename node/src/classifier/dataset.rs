//! Image files and datasets: PGM (P2/P5, maxval up to 65535), CSV (one image per file) and
//! TekScan ASCII exports (`.asf`, one image per frame; `B` = outside the sensor). A dataset is a
//! directory with one sub-directory per class.

use std::path::{Path, PathBuf};

use super::image::PressureImage;

/// A file that is not a readable image; names the file and, where it applies, the line.
#[derive(Clone, Debug, thiserror::Error, PartialEq, Eq)]
#[error("{path}{}: {msg}", line.map(|l| format!(":{l}")).unwrap_or_default())]
pub struct ImageError {
    /// The file.
    pub path: String,
    /// The line, for text formats.
    pub line: Option<usize>,
    /// What is wrong.
    pub msg: String,
}

fn err(path: &Path, line: Option<usize>, msg: impl Into<String>) -> ImageError {
    ImageError {
        path: path.display().to_string(),
        line,
        msg: msg.into(),
    }
}

fn bits_for(max: u32) -> u8 {
    if max > 255 { 16 } else { 8 }
}

/// Reads every image in a file (an `.asf` movie has one per frame).
pub fn read_images(path: &Path) -> Result<Vec<PressureImage>, ImageError> {
    let bytes = std::fs::read(path).map_err(|e| err(path, None, e.to_string()))?;
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    match ext.as_str() {
        "pgm" => parse_pgm_sequence(&bytes, path),
        "csv" | "txt" => Ok(vec![parse_csv(&bytes, path)?]),
        "asf" => parse_asf(&bytes, path),
        _ => Err(err(
            path,
            None,
            "unknown image format: use .pgm, .csv or .asf",
        )),
    }
}

/// One image from a file (the first frame of an `.asf`).
pub fn read_image(path: &Path) -> Result<PressureImage, ImageError> {
    read_images(path)?
        .into_iter()
        .next()
        .ok_or_else(|| err(path, None, "no image in file"))
}

/// Reads a PGM image (P2 text or P5 binary, 8 or 16 bit).
pub fn parse_pgm(b: &[u8], path: &Path) -> Result<PressureImage, ImageError> {
    parse_pgm_at(b, path).map(|(img, _)| img)
}

/// Every image of a PGM file: P5 images one after another (netpbm's image sequence, as
/// `presrs capture` keeps a stance's frames), or one P2 image.
pub fn parse_pgm_sequence(b: &[u8], path: &Path) -> Result<Vec<PressureImage>, ImageError> {
    let mut out = Vec::new();
    let mut pos = 0;
    loop {
        let (img, used) = parse_pgm_at(&b[pos..], path)?;
        out.push(img);
        pos += used;
        if b[pos..].iter().all(|c| c.is_ascii_whitespace()) {
            return Ok(out);
        }
    }
}

/// One PGM image at the start of `b`, and the bytes it takes (all of them for P2).
fn parse_pgm_at(b: &[u8], path: &Path) -> Result<(PressureImage, usize), ImageError> {
    let hd = pgm_header(b, path)?;
    let (px, used) = if hd.binary {
        p5_pixels(b, &hd, path)?
    } else {
        (p2_pixels(b, &hd, path)?, b.len())
    };
    Ok((
        PressureImage::new(hd.h, hd.w, bits_for(hd.maxval), px),
        used,
    ))
}

/// A PGM header, checked: the format, the size, the largest value, and where the pixels start.
struct PgmHeader {
    /// P5 (binary) rather than P2 (text).
    binary: bool,
    w: usize,
    h: usize,
    maxval: u32,
    /// The byte after the header's last token.
    pos: usize,
    /// The line `pos` is on (1-based).
    line: usize,
}

/// The header tokens (magic, width, height, maxval; '#' comments to the end of a line).
fn pgm_header(b: &[u8], path: &Path) -> Result<PgmHeader, ImageError> {
    let mut pos = 0;
    let mut line = 1;
    let mut tokens = Vec::new();
    while tokens.len() < 4 {
        while pos < b.len() && (b[pos].is_ascii_whitespace() || b[pos] == b'#') {
            if b[pos] == b'#' {
                while pos < b.len() && b[pos] != b'\n' {
                    pos += 1;
                }
            } else {
                if b[pos] == b'\n' {
                    line += 1;
                }
                pos += 1;
            }
        }
        let start = pos;
        while pos < b.len() && !b[pos].is_ascii_whitespace() {
            pos += 1;
        }
        if start == pos {
            return Err(err(
                path,
                Some(line),
                "PGM header ends early (need P2/P5, width, height, maxval)",
            ));
        }
        tokens.push((String::from_utf8_lossy(&b[start..pos]).to_string(), line));
    }
    let magic = tokens[0].0.as_str();
    if magic != "P2" && magic != "P5" {
        return Err(err(
            path,
            Some(1),
            format!("not a PGM file: magic `{magic}` (P2 or P5 expected)"),
        ));
    }
    let num = |i: usize, what: &str| -> Result<u32, ImageError> {
        tokens[i].0.parse::<u32>().map_err(|_| {
            err(
                path,
                Some(tokens[i].1),
                format!("bad {what} `{}`", tokens[i].0),
            )
        })
    };
    let (w, h, maxval) = (
        num(1, "width")? as usize,
        num(2, "height")? as usize,
        num(3, "maxval")?,
    );
    if w == 0 || h == 0 || w * h > 1 << 20 {
        return Err(err(
            path,
            Some(tokens[1].1),
            format!("image size {w}x{h} out of range"),
        ));
    }
    if maxval == 0 || maxval > 65535 {
        return Err(err(
            path,
            Some(tokens[3].1),
            format!("maxval {maxval} out of range 1..=65535"),
        ));
    }
    Ok(PgmHeader {
        binary: magic == "P5",
        w,
        h,
        maxval,
        pos,
        line,
    })
}

/// P5's pixels (one byte each, or two big-endian above maxval 255), and the bytes the image
/// takes with its header.
fn p5_pixels(b: &[u8], hd: &PgmHeader, path: &Path) -> Result<(Vec<u16>, usize), ImageError> {
    let (n, pos) = (hd.w * hd.h, hd.pos + 1); // the single whitespace after maxval
    let bpp = if hd.maxval > 255 { 2 } else { 1 };
    let data = b.get(pos..).unwrap_or(&[]);
    if data.len() < n * bpp {
        return Err(err(
            path,
            Some(hd.line),
            format!(
                "P5 data holds {} bytes, {}x{} needs {}",
                data.len(),
                hd.w,
                hd.h,
                n * bpp
            ),
        ));
    }
    let px = (0..n)
        .map(|i| {
            if bpp == 2 {
                u16::from_be_bytes([data[2 * i], data[2 * i + 1]])
            } else {
                data[i] as u16
            }
        })
        .collect();
    Ok((px, pos + n * bpp))
}

/// P2's pixels: decimal values after the header, '#' comments to the end of a line.
fn p2_pixels(b: &[u8], hd: &PgmHeader, path: &Path) -> Result<Vec<u16>, ImageError> {
    let (n, maxval, line) = (hd.w * hd.h, hd.maxval, hd.line);
    let mut px = Vec::with_capacity(n);
    let text = String::from_utf8_lossy(&b[hd.pos..]);
    for (ln, l) in text.lines().enumerate() {
        let l = l.split('#').next().unwrap_or("");
        for t in l.split_whitespace() {
            let v: u32 = t
                .parse()
                .map_err(|_| err(path, Some(line + ln), format!("bad pixel value `{t}`")))?;
            if v > maxval {
                return Err(err(
                    path,
                    Some(line + ln),
                    format!("pixel {v} above maxval {maxval}"),
                ));
            }
            px.push(v as u16);
        }
    }
    if px.len() != n {
        return Err(err(
            path,
            None,
            format!(
                "P2 data has {} values, {}x{} needs {n}",
                px.len(),
                hd.w,
                hd.h
            ),
        ));
    }
    Ok(px)
}

/// Reads a CSV image: one sensel row per line, comma separated.
pub fn parse_csv(b: &[u8], path: &Path) -> Result<PressureImage, ImageError> {
    let text = std::str::from_utf8(b).map_err(|_| err(path, None, "not UTF-8 text"))?;
    let mut px = Vec::new();
    let mut cols = 0;
    let mut rows = 0;
    let mut max = 0;
    for (i, l) in text.lines().enumerate() {
        let l = l.trim();
        if l.is_empty() || l.starts_with('#') {
            continue;
        }
        let mut n = 0;
        for t in l
            .split(|c: char| c == ',' || c.is_whitespace())
            .filter(|t| !t.is_empty())
        {
            let v: f64 = t
                .parse()
                .map_err(|_| err(path, Some(i + 1), format!("bad value `{t}`")))?;
            if !(0.0..=65535.0).contains(&v) {
                return Err(err(
                    path,
                    Some(i + 1),
                    format!("value {v} outside 0..=65535"),
                ));
            }
            let v = v.round() as u16;
            max = max.max(v as u32);
            px.push(v);
            n += 1;
        }
        if rows == 0 {
            cols = n;
        } else if n != cols {
            return Err(err(
                path,
                Some(i + 1),
                format!("row has {n} values, the first row has {cols}"),
            ));
        }
        rows += 1;
    }
    if rows == 0 || cols == 0 {
        return Err(err(path, None, "no values"));
    }
    Ok(PressureImage::new(rows, cols, bits_for(max), px))
}

/// Reads a TekScan ASCII export (`.asf`): every frame in the file.
pub fn parse_asf(b: &[u8], path: &Path) -> Result<Vec<PressureImage>, ImageError> {
    let text = String::from_utf8_lossy(b);
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim_end_matches('\r')));
    let (mut rows, mut cols) = (0usize, 0usize);
    let mut in_data = false;
    for (n, l) in lines.by_ref() {
        let mut kv = l.split_whitespace();
        match kv.next() {
            Some("ROWS") => {
                rows = kv
                    .next()
                    .and_then(|v| v.parse().ok())
                    .ok_or_else(|| err(path, Some(n), "bad ROWS"))?
            }
            Some("COLS") => {
                cols = kv
                    .next()
                    .and_then(|v| v.parse().ok())
                    .ok_or_else(|| err(path, Some(n), "bad COLS"))?
            }
            Some("ASCII_DATA") => {
                in_data = true;
                break;
            }
            _ => {}
        }
    }
    if !in_data || rows == 0 || cols == 0 {
        return Err(err(
            path,
            None,
            "not a TekScan ASCII export: needs ROWS, COLS and ASCII_DATA @@",
        ));
    }
    let mut out = Vec::new();
    let mut lines = lines.peekable();
    while let Some((n, l)) = lines.next() {
        let l = l.trim();
        if l.is_empty() {
            continue;
        }
        if l == "@@" {
            break;
        }
        if !l.starts_with("Frame") {
            return Err(err(
                path,
                Some(n),
                format!("expected `Frame N`, found `{l}`"),
            ));
        }
        let mut px = Vec::with_capacity(rows * cols);
        let mut mask = Vec::with_capacity(rows * cols);
        let mut max = 0u32;
        for r in 0..rows {
            let (n, l) = lines.next().ok_or_else(|| {
                err(
                    path,
                    Some(n),
                    format!("frame ends after {r} of {rows} rows"),
                )
            })?;
            let vals: Vec<&str> = l.trim().split(',').map(str::trim).collect();
            if vals.len() != cols {
                return Err(err(
                    path,
                    Some(n),
                    format!("row has {} values, COLS is {cols}", vals.len()),
                ));
            }
            for v in vals {
                let x = asf_value(v).map_err(|e| err(path, Some(n), e))?;
                max = max.max(x.unwrap_or(0) as u32);
                px.push(x.unwrap_or(0));
                mask.push(x.is_none());
            }
        }
        let mut img = PressureImage::new(rows, cols, bits_for(max), px);
        if mask.iter().any(|m| *m) {
            img.outside = Some(mask);
        }
        out.push(img);
    }
    if out.is_empty() {
        return Err(err(path, None, "no frames"));
    }
    Ok(out)
}

/// One value of a TekScan frame: a reading, or `None` for `B` (a sensel outside the sensor's
/// shape).
fn asf_value(v: &str) -> Result<Option<u16>, String> {
    if v == "B" {
        return Ok(None);
    }
    let x: f64 = v.parse().map_err(|_| format!("bad value `{v}`"))?;
    if !(0.0..=65535.0).contains(&x) {
        return Err(format!("value {x} outside 0..=65535"));
    }
    Ok(Some(x.round() as u16))
}

/// Writes a binary PGM (P5), 8-bit when `img.bits` is 8 and every pixel fits, else 16-bit.
pub fn write_pgm(img: &PressureImage, path: &Path) -> std::io::Result<()> {
    let mut b = Vec::new();
    pgm_bytes(img, &mut b);
    std::fs::write(path, b)
}

/// Appends `img` as one binary PGM (`P5`; 16-bit for a 16-bit image or values past 255) to
/// `b`: several in a row are a multi-image file, as [`read_images`] reads it.
pub fn pgm_bytes(img: &PressureImage, b: &mut Vec<u8>) {
    let wide = img.bits > 8 || img.pixels.iter().any(|&p| p > 255);
    let maxval = if wide { 65535 } else { 255 };
    b.extend_from_slice(format!("P5\n{} {}\n{}\n", img.cols, img.rows, maxval).as_bytes());
    for &p in &img.pixels {
        if wide {
            b.extend_from_slice(&p.to_be_bytes());
        } else {
            b.push(p as u8);
        }
    }
}

/// One image of a dataset.
#[derive(Clone, Debug)]
pub struct Sample {
    /// The image's class, an index into [`Dataset::classes`].
    pub class: usize,
    /// The file it came from.
    pub path: PathBuf,
    /// Frame index within a multi-frame file.
    pub frame: usize,
    /// The image.
    pub image: PressureImage,
}

/// A dataset directory as `presrs train` reads it: `DIR/<class>/<images>`.
#[derive(Clone, Debug, Default)]
pub struct Dataset {
    /// The dataset's directory.
    pub root: PathBuf,
    /// Class names: the folder names, sorted.
    pub classes: Vec<String>,
    /// Every image read.
    pub samples: Vec<Sample>,
    /// Files skipped with `skip_bad`, with why.
    pub bad: Vec<ImageError>,
}

/// Loads `dir/<class>/<files>`. Classes are sorted by name. A bad file is an error unless
/// `skip_bad`, which records it in `bad` and goes on.
pub fn load_dataset(dir: &Path, skip_bad: bool) -> Result<Dataset, ImageError> {
    let read_dir = |p: &Path| -> Result<Vec<PathBuf>, ImageError> {
        let mut v: Vec<PathBuf> = std::fs::read_dir(p)
            .map_err(|e| err(p, None, format!("cannot list directory: {e}")))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .collect();
        v.sort();
        Ok(v)
    };
    let mut ds = Dataset {
        root: dir.to_path_buf(),
        ..Dataset::default()
    };
    // Hidden folders are not classes (a capture's `.stance` frames, a `.git`).
    let hidden = |p: &PathBuf| {
        p.file_name()
            .is_some_and(|n| n.to_string_lossy().starts_with('.'))
    };
    for class_dir in read_dir(dir)?
        .into_iter()
        .filter(|p| p.is_dir() && !hidden(p))
    {
        let k = ds.classes.len();
        ds.classes.push(
            class_dir
                .file_name()
                .map(|n| n.to_string_lossy().to_string())
                .unwrap_or_default(),
        );
        for f in read_dir(&class_dir)?.into_iter().filter(|p| p.is_file()) {
            match read_images(&f) {
                Ok(imgs) => {
                    for (frame, image) in imgs.into_iter().enumerate() {
                        ds.samples.push(Sample {
                            class: k,
                            path: f.clone(),
                            frame,
                            image,
                        });
                    }
                }
                Err(e) if skip_bad => ds.bad.push(e),
                Err(mut e) => {
                    e.msg.push_str(SKIP_HINT);
                    return Err(e);
                }
            }
        }
    }
    if ds.classes.is_empty() {
        return Err(err(
            dir,
            None,
            "no class sub-directories: a dataset is DIR/<class>/<images>",
        ));
    }
    // One sensor, one size and depth: the images of another than most are named (or skipped).
    let mut sizes: Vec<((usize, usize, u8), usize)> = Vec::new();
    for s in &ds.samples {
        let size = (s.image.rows, s.image.cols, s.image.bits);
        match sizes.iter_mut().find(|(z, _)| *z == size) {
            Some((_, n)) => *n += 1,
            None => sizes.push((size, 1)),
        }
    }
    if let Some(&((rows, cols, bits), most)) = sizes.iter().max_by_key(|(_, n)| *n)
        && sizes.len() > 1
    {
        let odd = |s: &Sample| (s.image.rows, s.image.cols, s.image.bits) != (rows, cols, bits);
        let say = |s: &Sample| {
            err(
                &s.path,
                None,
                format!(
                    "a {}x{} {}-bit image, but {most} of the dataset's images are \
                     {rows}x{cols} {bits}-bit",
                    s.image.rows, s.image.cols, s.image.bits
                ),
            )
        };
        if !skip_bad && let Some(s) = ds.samples.iter().find(|s| odd(s)) {
            let mut e = say(s);
            e.msg.push_str(SKIP_HINT);
            return Err(e);
        }
        let bad: Vec<ImageError> = ds.samples.iter().filter(|s| odd(s)).map(say).collect();
        ds.bad.extend(bad);
        ds.samples.retain(|s| !odd(s));
    }
    Ok(ds)
}

/// Appended to a bad file's error when it stops a dataset from loading.
const SKIP_HINT: &str = " (remove it, or pass --skip-bad to leave out the files that are not \
                         images of the dataset's size)";

#[cfg(test)]
mod tests {
    use super::*;

    fn p() -> &'static Path {
        Path::new("t.pgm")
    }

    #[test]
    fn pgm_p2_p5_8_and_16_bit() {
        let img = parse_pgm(b"P2\n# c\n3 2\n255\n1 2 3\n4 5 255\n", p()).unwrap();
        assert_eq!((img.rows, img.cols, img.bits), (2, 3, 8));
        assert_eq!(img.pixels, vec![1, 2, 3, 4, 5, 255]);
        let mut b = b"P5\n2 1\n65535\n".to_vec();
        b.extend_from_slice(&[0x12, 0x34, 0xFF, 0xFF]);
        let img = parse_pgm(&b, p()).unwrap();
        assert_eq!(img.pixels, vec![0x1234, 0xFFFF]);
        assert_eq!(img.bits, 16);
        let dir = std::env::temp_dir().join(format!("presrs-pgm-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        for im in [
            PressureImage::new(2, 2, 8, vec![0, 1, 254, 255]),
            PressureImage::new(1, 2, 16, vec![300, 65535]),
        ] {
            let f = dir.join("x.pgm");
            write_pgm(&im, &f).unwrap();
            assert_eq!(read_image(&f).unwrap(), im);
        }
    }

    #[test]
    fn bad_files_name_file_and_line() {
        let e = parse_pgm(b"P2\n2 2\n255\n1 2\n3 x\n", p()).unwrap_err();
        assert_eq!(e.line, Some(5));
        assert!(
            e.to_string().starts_with("t.pgm:5: bad pixel value `x`"),
            "{e}"
        );
        assert!(
            parse_pgm(b"P2\n2 2\n255\n1 2 3\n", p())
                .unwrap_err()
                .msg
                .contains("needs 4")
        );
        assert!(
            parse_pgm(b"P6\n2 2\n255\n", p())
                .unwrap_err()
                .msg
                .contains("magic")
        );
        assert!(
            parse_pgm(b"P5\n2 2\n70000\n", p())
                .unwrap_err()
                .msg
                .contains("maxval")
        );
        assert!(
            parse_pgm(b"P5\n4 4\n255\n\x01\x02", p())
                .unwrap_err()
                .msg
                .contains("needs 16")
        );
        let e = parse_csv(b"1,2,3\n4 5\n", Path::new("a.csv")).unwrap_err();
        assert_eq!(e.line, Some(2));
        assert!(parse_csv(b"1,-2\n", Path::new("a.csv")).is_err());
    }

    #[test]
    fn csv_commas_or_spaces() {
        let img = parse_csv(b"1, 2,3\n4 5 6\n\n", Path::new("a.csv")).unwrap();
        assert_eq!((img.rows, img.cols), (2, 3));
        assert_eq!(img.pixels, vec![1, 2, 3, 4, 5, 6]);
    }

    #[test]
    fn tekscan_asf_real_sample() {
        let f =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/tekscan/FrasP01L.asf");
        let imgs = read_images(&f).unwrap();
        assert_eq!(imgs.len(), 205);
        let i = &imgs[100];
        assert_eq!((i.rows, i.cols), (60, 21));
        let mask = i.outside.as_ref().unwrap();
        assert!(mask[0] && !mask[9]); // "B,B,...,B,0" in row 0
        assert!(imgs.iter().any(|im| im.pixels.iter().any(|&p| p > 0)));
        // `B` sensels are not damage: a row of only `B` is never dead, a row of zeros is.
        let synth = b"ROWS 3\nCOLS 2\nASCII_DATA @@\nFrame 1\nB,B\n0,0\n5,B\n@@\n";
        let img = &parse_asf(synth, Path::new("s.asf")).unwrap()[0];
        let (dr, dc) = super::super::repair::zero_lines(img);
        assert_eq!(dr, vec![false, true, false]);
        assert_eq!(dc, vec![false, true]);
        let bad = b"ROWS 2\nCOLS 2\nASCII_DATA @@\n\nFrame 1\n1,2\n3\n";
        let e = parse_asf(bad, Path::new("x.asf")).unwrap_err();
        assert_eq!(e.line, Some(7));
    }

    #[test]
    fn a_bad_file_in_a_dataset_is_named_with_the_way_out() {
        let dir = std::env::temp_dir().join(format!("presrs-ds-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        for class in ["wood", "clay"] {
            std::fs::create_dir_all(dir.join(class)).unwrap();
            for i in 0..3 {
                let f = dir.join(class).join(format!("{i}.pgm"));
                std::fs::write(f, b"P2\n2 2\n255\n1 2\n3 4\n").unwrap();
            }
        }
        let odd = dir.join("clay").join("odd.pgm");
        std::fs::write(&odd, b"P2\n3 1\n255\n1 2 3\n").unwrap();
        let e = load_dataset(&dir, false).unwrap_err().to_string();
        assert!(
            e.contains("odd.pgm") && e.contains("1x3") && e.contains("--skip-bad"),
            "{e}"
        );
        let ds = load_dataset(&dir, true).unwrap();
        assert_eq!((ds.samples.len(), ds.bad.len()), (6, 1));
        std::fs::remove_file(&odd).unwrap();
        let notes = dir.join("wood").join("notes.txt");
        std::fs::write(&notes, "notes about this set\n").unwrap();
        let e = load_dataset(&dir, false).unwrap_err().to_string();
        assert!(e.contains("notes.txt") && e.contains("--skip-bad"), "{e}");
        assert_eq!(load_dataset(&dir, true).unwrap().bad.len(), 1);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
