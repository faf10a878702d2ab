//! What `train` is asked to do: the paper's split and preprocessing, and how the
//! unknown-ground checks are chosen ([`UnknownChecks`]: measured on the lab's runs by
//! `crate::training::choice`, or an expert's list).

use super::image::CropSpec;
use super::model::{MAX_DOWNSAMPLE, MAX_UNKNOWN_RATE};
use super::train::error::TrainError;
use crate::unknown::novelty::NoveltyScore;

/// How to train: the paper's split and the preprocessing. With the `clap` feature these are
/// also `presrs train`'s options (the field's doc is its help).
#[derive(Clone, Debug)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct TrainOptions {
    /// Images drawn per class (section 7.2: 20).
    #[cfg_attr(
        feature = "clap",
        arg(
            long,
            default_value_t = 20,
            help_heading = "The fit (the paper's split; the crop measured)"
        )
    )]
    pub per_class: usize,
    /// Of those, images to train on; the rest validate the kernel width (13 of 20).
    #[cfg_attr(
        feature = "clap",
        arg(
            long,
            default_value_t = 13,
            help_heading = "The fit (the paper's split; the crop measured)"
        )
    )]
    pub train: usize,
    /// Rows/columns removed before the features: `auto` keeps the rows and columns that carry
    /// your stances' load (each at least 0.25% of it; on the simulator's foot that is the
    /// paper's 0,3,6,0), or top,bottom,left,right (the paper: 2,2,2,2 on the static platform;
    /// 0,3,6,0 on its foot): a given crop that cuts loaded lines is warned about.
    #[cfg_attr(
        feature = "clap",
        arg(
            long,
            default_value = "auto",
            value_name = "auto|T,B,L,R",
            help_heading = "The fit (the paper's split; the crop measured)"
        )
    )]
    pub crop: CropSpec,
    /// Keep every k-th row and column after the crop (1 = full resolution, at most 8).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 1, value_parser = parse_downsample, help_heading = "The fit (the paper's split; the crop measured)"))]
    pub downsample: usize,
    /// Scale each image to the training set's mean total intensity (the paper's intensity
    /// scaling). Without it, `train` measures whether it finds more unknown ground (see
    /// --unknown-checks).
    #[cfg_attr(
        feature = "clap",
        arg(
            long,
            help_heading = "Unknown ground (measured on your runs, unless given)"
        )
    )]
    pub normalize_load: bool,
    /// PCA dimensions. Without it, `train` measures which finds more unknown ground: the most
    /// the samples support (up to the paper's 52) or the number that classifies the validation
    /// images best (see --unknown-checks).
    #[cfg_attr(
        feature = "clap",
        arg(
            long = "dims",
            value_name = "N",
            help_heading = "Unknown ground (measured on your runs, unless given)"
        )
    )]
    pub h: Option<usize>,
    /// Seed of the random split.
    #[cfg_attr(
        feature = "clap",
        arg(
            long,
            default_value_t = 1,
            help_heading = "The fit (the paper's split; the crop measured)"
        )
    )]
    pub seed: u64,
    /// The share of known-terrain images the model may call unknown (0..=0.5): the novelty
    /// threshold is set so that this share of held-out known images scores above it. 0 keeps
    /// the paper's classifier without the novelty score, which rejects almost nothing.
    #[cfg_attr(
        feature = "clap",
        arg(long, default_value_t = DEFAULT_UNKNOWN_RATE, value_parser = parse_rate, help_heading = "Unknown ground (measured on your runs, unless given)")
    )]
    pub unknown_rate: f64,
    /// Always call unknown an image whose load (summed working image, before normalisation)
    /// lies outside its terrain's band. Without it, `train` measures whether the check finds
    /// more unknown ground (see --unknown-checks).
    #[cfg_attr(
        feature = "clap",
        arg(
            long,
            help_heading = "Unknown ground (measured on your runs, unless given)"
        )
    )]
    pub check_load: bool,
    /// Always call unknown an image whose roughness lies outside its terrain's band. Without it,
    /// `train` measures whether the check finds more unknown ground (see --unknown-checks).
    #[cfg_attr(
        feature = "clap",
        arg(
            long,
            help_heading = "Unknown ground (measured on your runs, unless given)"
        )
    )]
    pub check_texture: bool,
    /// How the unknown-ground checks are chosen. `auto`: `train` leaves each terrain out in
    /// turn, scores every combination of novelty score, load normalisation, PCA dimensions and
    /// extra checks on the calibration run, keeps the one that finds the most left-out ground
    /// at --unknown-rate, and prints the table it chose from. Or an expert's list, e.g.
    /// `knn,normalize-load,texture`: a score (`knn-residual` or `knn`), then any of
    /// `normalize-load`, `dims-max`, `load`, `texture`, `energy` (the return map of the
    /// sessions' flights) and, with one session, `margin-F` (what is not named is off). The
    /// flags above pin their part in either case.
    #[cfg_attr(
        feature = "clap",
        arg(
            long,
            default_value = "auto",
            value_name = "LIST",
            help_heading = "Unknown ground (measured on your runs, unless given)"
        )
    )]
    pub unknown_checks: UnknownChecks,
    /// The deciding frame, ms after touchdown, as the lab sets it: one of the captured stance
    /// frames' times (30, 50, ..., 190) or the time the set was captured at (the capture
    /// config's `sample_ms`). Without it `train` measures the frame on the stances' frames,
    /// unless the set was captured at another time than the paper's 70 ms: then that one.
    #[cfg_attr(
        feature = "clap",
        arg(
            long,
            value_name = "MS",
            help_heading = "The fit (the paper's split; the crop measured)"
        )
    )]
    pub sample_ms: Option<u32>,
    /// Whether `train` measures the decisions' chance of being right
    /// ([`crate::classifier::confidence`]): a model for a robot does; a study that trains
    /// hundreds of models to count their decisions need not (it costs a fit per terrain).
    #[cfg_attr(feature = "clap", arg(skip = Confidence::Measure))]
    pub confidence: Confidence,
}

/// What a model's confidence is: see [`TrainOptions::confidence`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Confidence {
    /// The measured chance of being right (a robot's model).
    #[default]
    Measure,
    /// The Parzen posterior (a study's model, whose confidence nobody reads).
    Posterior,
}

/// `--downsample`: 1..=MAX_DOWNSAMPLE, refused as the command line is read (`train` refuses it
/// too, for callers that build the options themselves).
#[cfg(feature = "clap")]
fn parse_downsample(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(k) if (1..=MAX_DOWNSAMPLE).contains(&k) => Ok(k),
        _ => Err(format!(
            "`{s}` is not a factor in 1..={MAX_DOWNSAMPLE} (1: full resolution)"
        )),
    }
}

/// `--unknown-rate`: a share in 0..=MAX_UNKNOWN_RATE (as `parse_downsample`).
#[cfg(feature = "clap")]
fn parse_rate(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(r) if (0.0..=MAX_UNKNOWN_RATE).contains(&r) => Ok(r),
        _ => Err(format!(
            "`{s}` is not a share in 0..={MAX_UNKNOWN_RATE} (0.02 is 2%)"
        )),
    }
}

/// `train --unknown-rate`'s default: 2% of known-terrain images may be called unknown.
pub const DEFAULT_UNKNOWN_RATE: f64 = 0.02;

impl Default for TrainOptions {
    fn default() -> Self {
        Self {
            per_class: 20,
            train: 13,
            crop: CropSpec::Auto,
            downsample: 1,
            normalize_load: false,
            h: None,
            seed: 1,
            unknown_rate: DEFAULT_UNKNOWN_RATE,
            check_load: false,
            check_texture: false,
            unknown_checks: UnknownChecks::Auto,
            sample_ms: None,
            confidence: Confidence::Measure,
        }
    }
}

impl TrainOptions {
    /// The options that no data can make work: a downsampling factor, an unknown rate or a
    /// split out of range. [`train`](super::train::train) checks them too; a caller that trains
    /// later (an experiment's last section) checks them before it starts.
    pub fn check(&self) -> Result<(), TrainError> {
        if !(1..=MAX_DOWNSAMPLE).contains(&self.downsample) {
            return Err(TrainError::Downsample(self.downsample));
        }
        if !(0.0..=MAX_UNKNOWN_RATE).contains(&self.unknown_rate) {
            return Err(TrainError::UnknownRate(self.unknown_rate));
        }
        if self.train == 0 || self.train >= self.per_class {
            return Err(TrainError::BadSplit {
                train: self.train,
                per_class: self.per_class,
            });
        }
        Ok(())
    }
}

/// PCA dimensions of a model.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Dims {
    /// The number that classifies the validation images best (section 4.2; it varies with the
    /// split, from 8 to 52 on the same data).
    Accuracy,
    /// As many as the samples support, up to the paper's 52.
    Max,
}

/// One combination of the unknown-ground options: what `train` compares and a model keeps.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Candidate {
    /// The novelty score.
    pub score: NoveltyScore,
    /// Each image scaled to the training set's mean load before its features.
    pub normalize_load: bool,
    /// PCA dimensions.
    pub dims: Dims,
    /// The load check.
    pub load: bool,
    /// The texture check.
    pub texture: bool,
    /// The energy check: a stance whose flight after is not what its terrain's return map
    /// gives for the flight before it is unknown (fitted on the sessions' flights).
    pub energy: bool,
    /// With one session, the factor on the thresholds its own time blocks set, in hundredths
    /// (115: x1.15); [`Margin::MEASURED`] for thresholds set on another session.
    pub margin: Margin,
}

/// A factor on a model's novelty thresholds, in hundredths: how far past what one session
/// measured of itself the next session's known ground may lie and still be known
/// (docs/decisions/unknown-one-session.md).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Margin(pub u16);

impl Margin {
    /// The thresholds as calibrated: another session measured them.
    pub const MEASURED: Margin = Margin(100);
    /// One session, when nothing chose another: the factor the project measured before the
    /// session's time blocks calibrated it (`SAME_RUN_MARGIN`).
    pub const ONE_SESSION: Margin = Margin(115);
    /// The factors `train` weighs with one session, largest first (a tie goes to the larger).
    pub const ONE_SESSION_GRID: [Margin; 4] = [Margin(150), Margin(130), Margin(115), Margin(100)];

    /// The factor.
    pub fn factor(self) -> f64 {
        self.0 as f64 / 100.0
    }
}

impl Candidate {
    /// Today's model when nothing is chosen: the combined score, no normalisation, dimensions
    /// by accuracy, no extra check (what `train` did before it chose).
    pub const PLAIN: Candidate = Candidate {
        score: NoveltyScore::KnnResidual,
        normalize_load: false,
        dims: Dims::Accuracy,
        load: false,
        texture: false,
        energy: false,
        margin: Margin::ONE_SESSION,
    };

    /// Extra checks it carries (0-3): fewer is preferred where the figures tie.
    pub fn extra_checks(&self) -> usize {
        self.load as usize + self.texture as usize + self.energy as usize
    }
}

/// `knn,normalize-load,dims-max,texture`: the list `--unknown-checks` takes and `train` prints.
impl std::fmt::Display for Candidate {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self.score {
            NoveltyScore::KnnResidual => "knn-residual",
            NoveltyScore::Knn => "knn",
        })?;
        for (on, name) in [
            (self.normalize_load, "normalize-load"),
            (self.dims == Dims::Max, "dims-max"),
            (self.load, "load"),
            (self.texture, "texture"),
            (self.energy, "energy"),
        ] {
            if on {
                write!(f, ",{name}")?;
            }
        }
        if self.margin != Margin::ONE_SESSION {
            write!(f, ",margin-{:.2}", self.margin.factor())?;
        }
        Ok(())
    }
}

/// How the unknown-ground checks are chosen (`--unknown-checks`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum UnknownChecks {
    /// Measured on the training and calibration runs (`crate::training::choice`).
    #[default]
    Auto,
    /// An expert's choice.
    Fixed(Candidate),
}

/// An `--unknown-checks` list that names something else.
#[derive(Debug, thiserror::Error, Clone, PartialEq, Eq)]
#[error(
    "`{0}` is not an --unknown-checks item: use auto, or a score (knn-residual or knn) with any \
     of normalize-load, dims-max, load, texture, energy and margin-F (1 <= F <= 3: with one session, \
     the factor on its thresholds), comma-separated"
)]
pub struct ParseUnknownChecksError(pub String);

impl std::str::FromStr for UnknownChecks {
    type Err = ParseUnknownChecksError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if s.trim() == "auto" {
            return Ok(UnknownChecks::Auto);
        }
        let mut c = Candidate::PLAIN;
        for item in s.split(',').map(str::trim) {
            match item {
                "knn-residual" => c.score = NoveltyScore::KnnResidual,
                "knn" => c.score = NoveltyScore::Knn,
                "normalize-load" => c.normalize_load = true,
                "dims-max" => c.dims = Dims::Max,
                "load" => c.load = true,
                "texture" => c.texture = true,
                "energy" => c.energy = true,
                m if m.starts_with("margin-") => {
                    c.margin = m["margin-".len()..]
                        .parse::<f64>()
                        .ok()
                        .filter(|f| (1.0..=3.0).contains(f))
                        .map(|f| Margin((f * 100.0).round() as u16))
                        .ok_or_else(|| ParseUnknownChecksError(m.to_string()))?
                }
                other => return Err(ParseUnknownChecksError(other.to_string())),
            }
        }
        Ok(UnknownChecks::Fixed(c))
    }
}

impl TrainOptions {
    /// The options for one candidate: its parts, with the flags' pins on top.
    pub fn with_candidate(&self, c: &Candidate) -> TrainOptions {
        let mut o = self.clone();
        o.normalize_load |= c.normalize_load;
        o.check_load |= c.load;
        o.check_texture |= c.texture;
        if o.h.is_none() && c.dims == Dims::Max {
            o.h = Some(MAX_DIMS);
        }
        o.unknown_checks = UnknownChecks::Fixed(*c);
        o
    }

    /// The novelty score these options train with.
    pub fn score(&self) -> NoveltyScore {
        match self.unknown_checks {
            UnknownChecks::Fixed(c) => c.score,
            UnknownChecks::Auto => NoveltyScore::KnnResidual,
        }
    }
}

/// The paper's number of PCA dimensions, the most a model takes unless `--dims` says more.
pub const MAX_DIMS: usize = 52;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_checks_parse_and_print_the_same_list() {
        assert_eq!("auto".parse(), Ok(UnknownChecks::Auto));
        for list in [
            "knn-residual",
            "knn,normalize-load,dims-max,load,texture,energy",
            "knn,texture",
            "knn,texture,margin-1.30",
        ] {
            let Ok(UnknownChecks::Fixed(c)) = list.parse::<UnknownChecks>() else {
                panic!("{list}");
            };
            assert_eq!(c.to_string(), list);
        }
        let e = "knn,sand".parse::<UnknownChecks>().unwrap_err();
        assert!(e.to_string().contains("`sand`"), "{e}");
    }

    #[test]
    fn the_flags_pin_their_part_of_a_candidate() {
        let o = TrainOptions {
            normalize_load: true,
            h: Some(8),
            ..TrainOptions::default()
        };
        let c = Candidate {
            dims: Dims::Max,
            texture: true,
            ..Candidate::PLAIN
        };
        let w = o.with_candidate(&c);
        assert!(w.normalize_load && w.check_texture && !w.check_load);
        assert_eq!(w.h, Some(8));
        assert_eq!(w.unknown_checks, UnknownChecks::Fixed(c));
    }
}
