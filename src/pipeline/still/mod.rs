//! The still decoder: grooves found in a top-view image, both borders of each wall tracked along
//! the chosen groove with the shared border model, and the borders' displacement turned into sound.
//!
//! A still is read as *lines* (rows of a vertical still, columns of a horizontal one; time runs
//! along them) of *cross* samples. The decoder is pure and streams: the caller feeds the image in
//! bands of rows, twice.
//! 1. [`ProfileBuilder`] (first pass) keeps, for each block of `block_lines` lines, the median
//!    cross profile (robust to dust and text smaller than half a block) and the gradient energy
//!    along and across the grooves (to catch an axis that contradicts the image).
//! 2. [`detect_grooves`] finds the dark walls in every block profile against local dark and
//!    bright levels (uneven light), pairs walls into grooves at their narrow bottom, links the
//!    grooves from block to block into tracks (`link.rs`: drift, close neighbours, gaps under
//!    text, pieces dust split off) and numbers them from the image's left (top).
//! 3. [`RibbonBuilder`] (second pass) keeps only a band around the chosen groove's predicted path.
//! 4. [`track_borders`] fits every border of the groove on every line
//!    ([`crate::pipeline::edges::border`]).
//! 5. [`decode_borders`] rejects outliers robustly ([`clean`]), marks and interpolates gaps,
//!    takes out the slow path, turns the displacement into velocity on the groove's arc length
//!    and gives the signal at Vt / pixel.
//!
//! [`analyse_still`] runs all of it on an in-memory image (tests, benches, the workbench).

pub mod clean;
pub mod decode;
pub mod detect;
mod link;
pub mod measure;
pub mod profile;
pub mod ribbon;
pub mod track;

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests;

use serde::{Deserialize, Serialize};

pub use decode::{StillSignal, decode_borders};
pub use detect::{
    GrooveMap, GroovePath, GrooveTrack, choose_groove, detect_grooves, outside_image,
};
pub use profile::{ProfileBuilder, Profiles};
pub use ribbon::{Ribbon, RibbonBuilder};
pub use track::{BorderTracks, track_borders};

use super::edges::border::BorderParams;
use super::{StageError, check_range};
use crate::image::Image;
use crate::meta::Cut;

/// Which way the grooves run in a still.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Axis {
    /// Grooves run down the image; time runs down.
    #[default]
    Vertical,
    /// Grooves run across the image; time runs rightward.
    Horizontal,
}

impl Axis {
    /// Both axes.
    pub const ALL: [Axis; 2] = [Axis::Vertical, Axis::Horizontal];

    /// The axis of `name` ([`Axis::name`]).
    #[must_use]
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|a| a.name() == name)
    }

    /// Its name as the command line and the reports spell it.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Axis::Vertical => "vertical",
            Axis::Horizontal => "horizontal",
        }
    }

    /// What the image's rows and columns are to a still of this axis: (lines, cross samples).
    #[must_use]
    pub fn names(self) -> (&'static str, &'static str) {
        match self {
            Axis::Vertical => ("rows", "columns"),
            Axis::Horizontal => ("columns", "rows"),
        }
    }
}

/// Whether the walls look darker or brighter than the land.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum WallTone {
    /// Dark walls on bright land (coaxial or ring light: the walls reflect it away).
    #[default]
    Dark,
    /// Bright walls on dark land (low-angle light).
    Bright,
}

/// Knobs of the still decoder (the `[still]` table of the params TOML).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StillParams {
    /// Lines per detection block (a block's median profile finds the grooves); default 32.
    pub block_lines: usize,
    /// Widest groove looked for, µm (sets the window of the local light levels); default 300.
    pub max_groove_width_um: f64,
    /// Narrowest wall looked for, µm (never under 1.5 px); default 1.
    pub min_wall_width_um: f64,
    /// Dark or bright walls; default dark.
    pub walls: WallTone,
    /// Smallest wall contrast, as a share of the local bright level; default 0.15.
    pub min_contrast: f64,
    /// Blocks a groove may be lost for (text, damage) and still be followed; default 12.
    pub max_gap_blocks: usize,
    /// Fewest blocks a groove must be found in; default 3.
    pub min_track_blocks: usize,
    /// Half-width of the search for each border around its predicted line, as a share of the
    /// wall's width (px never under 2); default 0.4.
    pub search_share: f64,
    /// A border further than this many robust σ from what the other borders and its
    /// neighbouring lines say is an outlier; default 5.
    pub outlier_sigmas: f64,
    /// Length of groove over which the slow path (skew, curvature, drift) is fitted as a
    /// quadratic and taken out (µm; a shorter still gets one quadratic); default 20000.
    pub path_window_um: f64,
    /// Wall angle from the record plane (stereo: a wall moving `a` along its normal moves its
    /// land border by `a / sin` of it); default 45.
    pub wall_angle_deg: f64,
    /// Largest share of a groove that may be lost before it is refused as not followed: the
    /// detection blocks it was not found in, or the lines without a usable border (bridged);
    /// 1 never refuses; default 0.5.
    pub max_lost_share: f64,
    /// The border model.
    pub border: BorderParams,
}

impl Default for StillParams {
    fn default() -> Self {
        Self {
            block_lines: 32,
            max_groove_width_um: 300.0,
            min_wall_width_um: 1.0,
            walls: WallTone::Dark,
            min_contrast: 0.15,
            max_gap_blocks: 12,
            min_track_blocks: 3,
            search_share: 0.4,
            outlier_sigmas: 5.0,
            path_window_um: 20_000.0,
            wall_angle_deg: 45.0,
            max_lost_share: 0.5,
            border: BorderParams::default(),
        }
    }
}

impl StillParams {
    /// Checks every knob.
    ///
    /// # Errors
    /// [`StageError::InvalidParam`] naming the first bad key.
    pub fn validate(&self) -> Result<(), StageError> {
        if !(4..=4096).contains(&self.block_lines) {
            return Err(StageError::InvalidParam {
                name: "still.block_lines".into(),
                problem: format!("{} is not in [4, 4096]", self.block_lines),
            });
        }
        check_range(
            "still.max_groove_width_um",
            self.max_groove_width_um,
            1e-3,
            1e6,
        )?;
        check_range("still.min_wall_width_um", self.min_wall_width_um, 0.0, 1e6)?;
        check_range("still.min_contrast", self.min_contrast, 0.0, 1.0)?;
        check_range("still.search_share", self.search_share, 0.05, 2.0)?;
        check_range("still.outlier_sigmas", self.outlier_sigmas, 1.0, 1e3)?;
        check_range("still.path_window_um", self.path_window_um, 1.0, 1e9)?;
        check_range("still.wall_angle_deg", self.wall_angle_deg, 10.0, 80.0)?;
        check_range("still.max_lost_share", self.max_lost_share, 0.0, 1.0)?;
        if self.min_track_blocks == 0 {
            return Err(StageError::InvalidParam {
                name: "still.min_track_blocks".into(),
                problem: "must be at least 1".into(),
            });
        }
        self.border.validate("still.border")
    }
}

/// Fewest samples of sound a second a still may give (the groove speed over the pixel size).
/// Below it nothing audible is resolved, and the output would be almost all interpolation: a
/// turntable speed typed as 0.002 rpm makes 126 µm of groove last ten seconds. It also bounds
/// the sound a still can make: the longest still, [`crate::io::still::MAX_STILL_SIDE_PX`]
/// pixels along the groove, lasts at most 70 minutes.
pub const MIN_STILL_RATE_HZ: f64 = 1000.0;

/// What the caller knows about the still (the command line's settings).
#[derive(Clone, Debug, PartialEq)]
pub struct StillSetup {
    /// Which way the grooves run.
    pub axis: Axis,
    /// Pixel size on the record, µm.
    pub um_per_px: f64,
    /// Turntable speed.
    pub rpm: f64,
    /// Radius of the groove decoded, mm.
    pub radius_mm: f64,
    /// Lateral (mono) or 45/45 stereo (two channels).
    pub cut: Cut,
    /// Time runs up (vertical) or leftward (horizontal) instead.
    pub reverse: bool,
}

impl StillSetup {
    /// Groove speed Vt = 2π·rpm/60·R, µm/s.
    #[must_use]
    pub fn groove_speed_um_s(&self) -> f64 {
        std::f64::consts::TAU * self.rpm / 60.0 * self.radius_mm * 1000.0
    }

    /// Samples of sound per second that one pixel along the groove gives: Vt / pixel size.
    #[must_use]
    pub fn native_rate_hz(&self) -> f64 {
        self.groove_speed_um_s() / self.um_per_px
    }

    /// Checks the numbers.
    ///
    /// # Errors
    /// [`StageError::InvalidParam`] for a non-positive or non-finite value, settings that give
    /// fewer than [`MIN_STILL_RATE_HZ`] samples a second, or a vertical cut.
    pub fn validate(&self) -> Result<(), StageError> {
        check_range("um_per_px", self.um_per_px, 1e-6, 1e6)?;
        check_range("rpm", self.rpm, 1e-3, crate::meta::MAX_RPM)?;
        check_range(
            "radius_mm",
            self.radius_mm,
            1e-3,
            crate::meta::MAX_RADIUS_MM,
        )?;
        let rate_hz = self.native_rate_hz();
        if rate_hz < MIN_STILL_RATE_HZ {
            return Err(StageError::InvalidParam {
                name: "rpm, radius_mm and um_per_px".into(),
                problem: format!(
                    "a groove speed of {:.4} mm/s over {} µm pixels gives {rate_hz:.4} samples \
                     per second of sound, below the minimum of {MIN_STILL_RATE_HZ}: nothing \
                     audible is resolved (check the turntable speed, radius and pixel size)",
                    self.groove_speed_um_s() / 1000.0,
                    self.um_per_px
                ),
            });
        }
        if self.cut == Cut::Vertical {
            return Err(StageError::InvalidParam {
                name: "cut".into(),
                problem: "a vertical (hill-and-dale) cut does not move the borders seen from above"
                    .into(),
            });
        }
        Ok(())
    }
}

/// Everything the decoder found in a still: for the report and for drawing.
#[derive(Clone, Debug)]
pub struct StillAnalysis {
    /// Every groove found, numbered from the image's left (top).
    pub grooves: GrooveMap,
    /// Index into `grooves.grooves` of the groove decoded.
    pub chosen: usize,
    /// Its borders on every line.
    pub borders: BorderTracks,
    /// Its sound.
    pub signal: StillSignal,
}

/// Why a still could not be decoded.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StillError {
    /// A setting is invalid.
    #[error(transparent)]
    Param(#[from] StageError),
    /// No groove was found.
    #[error("no groove found: {looked}")]
    NoGroove {
        /// Where and what the detector looked for.
        looked: String,
    },
    /// The groove was found, but no line of one of its channels gave a usable border.
    #[error(
        "the groove was found, but none of its {lines} lines gave a usable border{wall} (a dim \
         image, such as 10 or 12 bits stored in 16, has borders under [still.border] \
         min_contrast = {min_contrast} of full scale: lower it)"
    )]
    NoBorders {
        /// Lines of the groove.
        lines: usize,
        /// "" or " for the right wall".
        wall: &'static str,
        /// The border fit's smallest contrast.
        min_contrast: f64,
    },
    /// `--groove` asks for a groove that is not there.
    #[error(
        "groove {asked} asked for, but {found} grooves were found (numbered 1–{found} from the image's {side})"
    )]
    GrooveOutOfRange {
        /// The number asked for.
        asked: usize,
        /// Grooves found.
        found: usize,
        /// `left` or `top`.
        side: &'static str,
    },
    /// Most of the chosen groove was lost: what came out would be mostly bridging (an image of
    /// no grooves, a worn-flat stretch, or settings that do not fit the image).
    #[error(
        "groove {number} could not be followed: {lost}; more than still.max_lost_share = \
         {share} of it is lost (does the image show grooves, and do --um-per-px and --axis fit it?)"
    )]
    NotFollowed {
        /// The groove's `--groove` number.
        number: usize,
        /// What was lost: "it was found in only 12 of the image's 62 blocks", "860 of 1200
        /// lines of channel 0 had no usable border".
        lost: String,
        /// The share allowed.
        share: f64,
    },
    /// The structure of the image runs the other way.
    #[error(
        "the grooves run {found} but --axis {given} was given (gradient energy across the given axis is \
         {ratio:.2}× that along it); use --axis {found}"
    )]
    AxisContradicts {
        /// The axis given.
        given: &'static str,
        /// The axis the image shows.
        found: &'static str,
        /// Energy ratio.
        ratio: f64,
    },
}

/// The image's size in lines and cross samples for `axis`.
#[must_use]
pub fn lines_and_cross(width: usize, height: usize, axis: Axis) -> (usize, usize) {
    match axis {
        Axis::Vertical => (height, width),
        Axis::Horizontal => (width, height),
    }
}

/// A [`StageError::BadInput`] of the still stage, as a [`StillError`].
pub(crate) fn bad_input(problem: String) -> StillError {
    StageError::BadInput {
        stage: "still",
        problem,
    }
    .into()
}

/// Checks that `values` grey values are whole rows of `width` that fit in an image of
/// `height` rows after the `rows_seen` already fed (the streaming builders' `push_rows`).
///
/// # Errors
/// [`bad_input`] saying what does not fit.
pub(crate) fn check_whole_rows(
    values: usize,
    width: usize,
    rows_seen: usize,
    height: usize,
) -> Result<(), StillError> {
    if !values.is_multiple_of(width) || rows_seen + values / width > height {
        return Err(bad_input(format!(
            "{values} values are not whole rows of {width} inside the image's {height} rows"
        )));
    }
    Ok(())
}

/// Checks that all `height` rows of the image were fed (the streaming builders' `finish`).
///
/// # Errors
/// [`bad_input`] saying how many were.
pub(crate) fn check_all_rows(rows_seen: usize, height: usize) -> Result<(), StillError> {
    if rows_seen != height {
        return Err(bad_input(format!(
            "only {rows_seen} of the image's {height} rows were read"
        )));
    }
    Ok(())
}

/// Decodes groove `groove` (1-based; `None`: the most complete near the centre) of an
/// in-memory image, running both passes over it.
///
/// # Errors
/// [`StillError`] for bad settings, no groove, a groove out of range or a contradicting axis.
pub fn analyse_still(
    image: &Image,
    setup: &StillSetup,
    groove: Option<usize>,
    params: &StillParams,
) -> Result<StillAnalysis, StillError> {
    params.validate()?;
    setup.validate()?;
    let mut profiles = ProfileBuilder::new(image.width, image.height, setup.axis, params)?;
    profiles.push_rows(&image.data)?;
    let profiles = profiles.finish()?;
    let grooves = detect_grooves(&profiles, setup, params)?;
    let chosen = choose_groove(&grooves, groove)?;
    let mut ribbon = RibbonBuilder::new(&grooves, chosen, image.width, image.height, params)?;
    ribbon.push_rows(&image.data)?;
    let ribbon = ribbon.finish()?;
    let borders = track_borders(&ribbon, params);
    let signal = decode_borders(&borders, setup, params)?;
    Ok(StillAnalysis {
        grooves,
        chosen,
        borders,
        signal,
    })
}
