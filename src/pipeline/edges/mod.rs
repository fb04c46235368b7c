//! The edge decoder: sub-pixel borders between the walls and the land and bottom, read as groove displacement.
//!
//! A wall's borders move by the groove's whole lateral displacement — tens of pixels — which is
//! a far stronger cue than the wall tilt the flow method reads; their noise is flat in
//! displacement (so it rises 6 dB per octave once differentiated into velocity), and texture at
//! the border, fixed to the record, not pixel noise, limits them (`../shared/PHYSICS.md`).
//!
//! [`detect_edges`] runs on one group of frames:
//! 1. **Coarse borders** ([`coarse`]) on the middle frame: for every output sample, the four
//!    borders (left land, left bottom, right bottom, right land) from its full-height strip.
//! 2. **Bottom depth** from the walls' widths: a wall at angle α reaching from the land (at the
//!    working distance) to a corner `D` deeper spans `D/tan α` across the groove, and the corner
//!    is seen at the perspective of its own depth. The median over the samples and both walls.
//! 3. **Fine fits** ([`profile`]): each border of each sample over all frames, from straightened
//!    sub-pixel profiles of the sample's columns in every frame, placed by the frame step and the
//!    border's own distance ([`geometry`]), dust columns rejected; the border model is
//!    [`border`]'s.
//!    Sharp borders are refined with one smooth curve per border over the group ([`refine`]),
//!    which places samples whose border stays inside one pixel row.
//! 4. **Combination** ([`robust`]): every border mapped to record `y` at its own distance, the
//!    four combined per sample into the groove's displacement (robustly: flaked or dusty borders
//!    are rejected), gaps marked and short ones bridged.
//! 5. **Velocity** ([`differentiator`]): a designed least-squares FIR, one-sided at the ends.
//!
//! Samples are the scan's global grid (`j·Δ`, the flow method's positions), so the edge signal
//! stitches and fuses with the flow signal sample for sample. A border lost over the whole group
//! is a gap with a warning, not an error.

mod blur;
pub mod border;
pub mod bursts;
pub mod coarse;
pub mod despike;
pub mod differentiator;
pub mod erf;
pub mod geometry;
mod noise;
pub mod plausible;
mod predict;
pub mod profile;
#[cfg(test)]
mod reference;
pub mod refine;
pub mod robust;
mod signal;

use std::ops::Range;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use self::border::BorderParams;
use self::coarse::{StripBorders, depth_from_widths, gap_rows, median3, strip_borders_and_widths};
use self::differentiator::DifferentiatorParams;
use self::geometry::FrameGeometry;
use self::predict::interpolant;
use self::profile::{SampleBorder, SampleTask, fit_sample};
use self::refine::{RefineSample, refine_border};
use self::robust::{CombineParams, combine_borders};
use super::audio_signal::SoundParams;
use super::sampling::native_spacing_um;
use super::walls::WallSide;
use super::{StageError, check_range};
use crate::image::Image;
use crate::meta::{Cut, ScanMeta};

pub use signal::{BorderChannels, DecodedEdges, decode_border_signal};

/// Stage name used in errors.
const STAGE: &str = "edges";

/// The four borders of a groove, top to bottom of the frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BorderId {
    /// Land to left wall (dark to bright going down).
    LeftLand = 0,
    /// Left wall to bottom (bright to dark).
    LeftBottom = 1,
    /// Bottom to right wall (dark to bright).
    RightBottom = 2,
    /// Right wall to land (bright to dark).
    RightLand = 3,
}

impl BorderId {
    /// All four, in order.
    pub const ALL: [BorderId; 4] = [
        BorderId::LeftLand,
        BorderId::LeftBottom,
        BorderId::RightBottom,
        BorderId::RightLand,
    ];

    /// The wall the border belongs to.
    #[must_use]
    pub fn side(self) -> WallSide {
        match self {
            BorderId::LeftLand | BorderId::LeftBottom => WallSide::Left,
            BorderId::RightBottom | BorderId::RightLand => WallSide::Right,
        }
    }

    /// True for the borders at the land (the working distance), false at the bottom.
    #[must_use]
    pub fn at_land(self) -> bool {
        matches!(self, BorderId::LeftLand | BorderId::RightLand)
    }

    /// Human-readable name.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            BorderId::LeftLand => "left land border",
            BorderId::LeftBottom => "left bottom border",
            BorderId::RightBottom => "right bottom border",
            BorderId::RightLand => "right land border",
        }
    }
}

/// Knobs of the edge stage.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EdgeParams {
    /// The border model's fit.
    pub border: BorderParams,
    /// The displacement-to-velocity filter.
    pub differentiator: DifferentiatorParams,
    #[doc = knob!("edges.wall_angle_deg")]
    pub wall_angle_deg: f64,
    #[doc = knob!("edges.band_half_height_px")]
    pub band_half_height_px: f64,
    #[doc = knob!("edges.band_sigmas")]
    pub band_sigmas: f64,
    #[doc = knob!("edges.max_band_half_height_px")]
    pub max_band_half_height_px: f64,
    #[doc = knob!("edges.noisy_band_half_height_px")]
    pub noisy_band_half_height_px: f64,
    #[doc = knob!("edges.noisy_grey_levels")]
    pub noisy_grey_levels: f64,
    #[doc = knob!("edges.bin_px")]
    pub bin_px: f64,
    #[doc = knob!("edges.coarse_column_step")]
    pub coarse_column_step: usize,
    #[doc = knob!("edges.column_sigma_px")]
    pub column_sigma_px: f64,
    #[doc = knob!("edges.column_rounds")]
    pub column_rounds: u32,
    #[doc = knob!("edges.border_sigma_um")]
    pub border_sigma_um: f64,
    #[doc = knob!("edges.border_floor_um")]
    pub border_floor_um: f64,
    #[doc = knob!("edges.max_bridge_samples")]
    pub max_bridge_samples: usize,
    #[doc = knob!("edges.weight_window_samples")]
    pub weight_window_samples: usize,
    #[doc = knob!("edges.all_frames")]
    pub all_frames: bool,
    #[doc = knob!("edges.despike_sigmas")]
    pub despike_sigmas: f64,
    #[doc = knob!("edges.burst_sigmas")]
    pub burst_sigmas: f64,
    #[doc = knob!("edges.max_slope")]
    pub max_slope: f64,
    #[doc = knob!("edges.max_excursion_samples")]
    pub max_excursion_samples: usize,
    #[doc = knob!("edges.restart_solves")]
    pub restart_solves: bool,
    #[doc = knob!("edges.refine")]
    pub refine: bool,
    #[doc = knob!("edges.hard_width_px")]
    pub hard_width_px: f64,
    #[doc = knob!("edges.crossing_sigma_px")]
    pub crossing_sigma_px: f64,
    #[doc = knob!("edges.anchor_sigma_px")]
    pub anchor_sigma_px: f64,
    #[doc = knob!("edges.spline_smoothness")]
    pub spline_smoothness: f64,
    #[doc = knob!("edges.spline_frames")]
    pub spline_frames: usize,
}

/// Default of [`EdgeParams::despike_sigmas`].
const DEFAULT_DESPIKE: f64 = 5.0;

impl Default for EdgeParams {
    fn default() -> Self {
        Self {
            border: BorderParams::default(),
            differentiator: DifferentiatorParams::default(),
            wall_angle_deg: 45.0,
            band_half_height_px: 8.0,
            band_sigmas: 3.0,
            max_band_half_height_px: 24.0,
            noisy_band_half_height_px: 40.0,
            noisy_grey_levels: 0.75,
            bin_px: 0.25,
            coarse_column_step: 4,
            column_sigma_px: 1.0,
            column_rounds: 3,
            border_sigma_um: 0.3,
            border_floor_um: 0.02,
            max_bridge_samples: 3,
            weight_window_samples: 32,
            all_frames: true,
            despike_sigmas: DEFAULT_DESPIKE,
            burst_sigmas: 8.0,
            max_slope: 1.0,
            max_excursion_samples: 16,
            restart_solves: true,
            refine: true,
            hard_width_px: 0.45,
            crossing_sigma_px: 0.05,
            anchor_sigma_px: 2.0,
            spline_smoothness: 3.0,
            spline_frames: 3,
        }
    }
}

impl EdgeParams {
    /// Checks every knob.
    ///
    /// # Errors
    /// [`StageError::InvalidParam`] naming the first bad key (`edges.…`).
    pub fn validate(&self) -> Result<(), StageError> {
        self.border.validate("edges.border")?;
        self.differentiator.validate("edges.differentiator")?;
        check_range("edges.wall_angle_deg", self.wall_angle_deg, 1.0, 89.0)?;
        check_range(
            "edges.band_half_height_px",
            self.band_half_height_px,
            2.0,
            256.0,
        )?;
        check_range("edges.band_sigmas", self.band_sigmas, 0.0, 100.0)?;
        check_range(
            "edges.max_band_half_height_px",
            self.max_band_half_height_px,
            self.band_half_height_px,
            256.0,
        )?;
        check_range(
            "edges.noisy_band_half_height_px",
            self.noisy_band_half_height_px,
            2.0,
            256.0,
        )?;
        check_range(
            "edges.noisy_grey_levels",
            self.noisy_grey_levels,
            0.0,
            255.0,
        )?;
        check_range("edges.bin_px", self.bin_px, 0.01, 4.0)?;
        check_range("edges.column_sigma_px", self.column_sigma_px, 1e-3, 1e3)?;
        check_range("edges.border_sigma_um", self.border_sigma_um, 1e-4, 1e4)?;
        check_range("edges.border_floor_um", self.border_floor_um, 1e-6, 1e4)?;
        check_range("edges.despike_sigmas", self.despike_sigmas, 0.0, 1e3)?;
        check_range("edges.burst_sigmas", self.burst_sigmas, 0.0, 1e3)?;
        check_range("edges.max_slope", self.max_slope, 0.0, 1e3)?;
        check_range("edges.hard_width_px", self.hard_width_px, 0.0, 100.0)?;
        check_range(
            "edges.crossing_sigma_px",
            self.crossing_sigma_px,
            1e-4,
            100.0,
        )?;
        check_range("edges.anchor_sigma_px", self.anchor_sigma_px, 1e-4, 100.0)?;
        check_range("edges.spline_smoothness", self.spline_smoothness, 0.0, 1e9)?;
        for (name, v) in [
            ("edges.coarse_column_step", self.coarse_column_step),
            ("edges.column_rounds", self.column_rounds as usize),
            ("edges.spline_frames", self.spline_frames),
        ] {
            if v == 0 {
                return Err(StageError::InvalidParam {
                    name: name.into(),
                    problem: "must be at least 1".into(),
                });
            }
        }
        Ok(())
    }
}

/// One border over the group's samples.
#[derive(Clone, Debug, PartialEq)]
pub struct BorderTrack {
    /// Which border.
    pub id: BorderId,
    /// Distance of its surface from the optical centre (µm; NaN when the bottom depth is unknown).
    pub z_um: f64,
    /// Record `y` per sample (µm from the optical axis; NaN = not found).
    pub y_um: Vec<f64>,
    /// Its standard error (µm).
    pub std_error_um: Vec<f64>,
    /// Its weight in the combination relative to its plain weight (0 = rejected or not seen).
    pub weight: Vec<f64>,
    /// Per sample, the fine fit: every frame's row, the reference frame's column weights.
    pub fits: Vec<Option<SampleBorder>>,
}

/// One wall over the group's samples.
#[derive(Clone, Debug, PartialEq)]
pub struct WallEdges {
    /// Which wall.
    pub side: WallSide,
    /// The wall's lateral displacement (record `y` of its land border, µm, relative to the
    /// groove's cross-section; NaN = gap).
    pub displacement_um: Vec<f64>,
    /// Its standard error (µm; NaN where bridged).
    pub std_error_um: Vec<f64>,
    /// The wall's velocity as the flow method reads it, `Vt·tan θ` = `Vt·sin α·∂y/∂s` (mm/s).
    pub velocity_mm_s: Vec<f64>,
}

/// The coarse pass of one group: the frame it read and how noisy that frame is (its border
/// rows, which the fine fit starts from, stay inside the stage).
#[derive(Clone, Debug, PartialEq)]
pub struct CoarseRead {
    /// Index in the group of the frame the coarse borders were read on.
    pub frame: usize,
    /// That frame's pixel noise (σ, grey levels of 255; None where the frame is too small to say).
    pub pixel_noise_grey_levels: Option<f64>,
    /// The most rows a blurred border's band read on each side (px): the noisy cap on a noisy
    /// frame (`edges::noise`).
    pub band_cap_px: f64,
}

/// The edge stage's output for one group.
#[derive(Clone, Debug, PartialEq)]
pub struct Edges {
    /// Group index.
    pub group: usize,
    /// The scan's cut.
    pub cut: Cut,
    /// Global index of the first sample (its position is `first_sample·spacing_um`).
    pub first_sample: i64,
    /// Sample spacing along the groove (µm).
    pub spacing_um: f64,
    /// Groove position of each sample (µm from the scan start).
    pub positions_um: Vec<f64>,
    /// Groove speed Vt at this group (mm/s).
    pub groove_speed_mm_s: f64,
    /// Wall angle used (rad).
    pub wall_angle_rad: f64,
    /// Bottom depth below the land from the walls' widths (µm; NaN when not measured).
    pub bottom_depth_um: f64,
    /// What the coarse pass read on the group's reference frame.
    pub coarse: CoarseRead,
    /// The four borders, in [`BorderId`] order.
    pub borders: Vec<BorderTrack>,
    /// Each border's constant place in the cross-section (µm).
    pub constants_um: [f64; 4],
    /// Left and right wall.
    pub walls: Vec<WallEdges>,
    /// Per wall (left, right): sample ranges without a value.
    pub gaps: [Vec<Range<usize>>; 2],
    /// Per wall: sample ranges bridged by interpolation.
    pub bridged: [Vec<Range<usize>>; 2],
    /// What went wrong without stopping the stage (a border lost over the whole group, …).
    pub warnings: Vec<String>,
}

/// Median of the finite values.
fn finite_median(mut v: Vec<f64>) -> Option<f64> {
    v.retain(|x| x.is_finite());
    super::median(v)
}

/// `count` frame indices spread evenly over `len` frames, `reference` among them.
fn spread_frames(len: usize, reference: usize, count: usize) -> Vec<usize> {
    if count >= len {
        return (0..len).collect();
    }
    let mut picks: Vec<usize> = (0..count)
        .map(|k| {
            if count == 1 {
                reference
            } else {
                ((k * (len - 1)) as f64 / (count - 1) as f64).round() as usize
            }
        })
        .collect();
    if !picks.contains(&reference)
        && let Some(nearest) = picks.iter_mut().min_by_key(|p| p.abs_diff(reference))
    {
        *nearest = reference;
    }
    picks.sort_unstable();
    picks.dedup();
    picks
}

fn check_frames(frames: &[Image]) -> Result<(usize, usize), StageError> {
    let Some(first) = frames.first() else {
        return Err(StageError::BadInput {
            stage: STAGE,
            problem: "no frames".into(),
        });
    };
    if frames.iter().any(|f| !f.same_size(first)) {
        return Err(StageError::BadInput {
            stage: STAGE,
            problem: "the frames differ in size".into(),
        });
    }
    if first.width < 16 || first.height < 16 {
        return Err(StageError::BadInput {
            stage: STAGE,
            problem: format!("{}×{} px frames are too small", first.width, first.height),
        });
    }
    Ok((first.width, first.height))
}

/// Finds the borders of every wall in one group's frames and turns them into displacement and
/// velocity per wall (see the module docs). `frames[0]` is frame `first_frame` of group `group`.
///
/// # Errors
/// [`StageError::InvalidParam`] for bad params or spacing, [`StageError::BadInput`] for no
/// frames or frames of different or tiny sizes. Borders that cannot be found are gaps (with a
/// warning), not errors.
pub fn detect_edges(
    frames: &[Image],
    first_frame: usize,
    group: usize,
    meta: &ScanMeta,
    sound: &SoundParams,
    params: &EdgeParams,
) -> Result<Edges, StageError> {
    params.validate()?;
    let (width, height) = check_frames(frames)?;
    let geo = FrameGeometry::new(meta, width, height);
    let vt = meta.groove_speed_mm_s(group);
    let spacing = native_spacing_um(meta, sound);
    check_range("sound spacing (µm)", spacing, 1e-6, 1e6)?;
    let alpha = params.wall_angle_deg.to_radians();
    let wd = geo.working_distance_um;
    let reference = frames.len() / 2;
    let cams: Vec<f64> = (0..frames.len())
        .map(|k| geo.cam_s_um(group, first_frame + k))
        .collect();
    let cam_ref = cams[reference];
    let half = 0.5 * spacing;

    // 1. Coarse borders on the reference frame, for the samples it sees whole at the land.
    let sample_range = |cam_lo: f64, cam_hi: f64, z: f64| {
        let s_lo = geo.s_at(cam_lo, -0.5, z);
        let s_hi = geo.s_at(cam_hi, width as f64 - 0.5, z);
        let j_lo = ((s_lo + half) / spacing).ceil() as i64;
        let j_hi = ((s_hi - half) / spacing).floor() as i64;
        j_lo..j_hi + 1
    };
    let coarse_js = sample_range(cam_ref, cam_ref, wd);
    let (coarse_rows, coarse_widths): (Vec<(i64, StripBorders)>, Vec<StripBorders>) = coarse_js
        .clone()
        .into_par_iter()
        .map(|j| {
            let s = j as f64 * spacing;
            let x_lo = geo.x_at(cam_ref, s - half, wd).ceil().max(0.0) as usize;
            let x_hi = (geo.x_at(cam_ref, s + half, wd).floor() as usize).min(width - 1);
            let cols: Vec<usize> = (x_lo..=x_hi).step_by(params.coarse_column_step).collect();
            let (rows, widths) = strip_borders_and_widths(&frames[reference], &cols, params);
            ((j, rows), widths)
        })
        .unzip();

    // 2. Bottom depth.
    let tan_a = alpha.tan();
    let depths: Vec<f64> = coarse_rows
        .iter()
        .flat_map(|(_, r)| depth_from_widths(r, &geo, tan_a))
        .collect();
    let bottom_depth_um = finite_median(depths).unwrap_or(f64::NAN);
    let z_of = |id: BorderId| {
        if id.at_land() {
            wd
        } else {
            wd + bottom_depth_um
        }
    };

    // Samples: any frame sees them whole at the deepest border.
    let z_deep = if bottom_depth_um.is_finite() {
        wd + bottom_depth_um
    } else {
        wd
    };
    let (cam_first, cam_last) = (
        cams[0].min(cams[cams.len() - 1]),
        cams[0].max(cams[cams.len() - 1]),
    );
    let js = sample_range(cam_first, cam_last, z_deep);
    let first_sample = js.start;
    let n = usize::try_from(js.end - js.start).unwrap_or(0);
    let positions_um: Vec<f64> = js.clone().map(|j| j as f64 * spacing).collect();

    // 3. Predictions and fine fits; a noisy camera's blurred borders read wider bands.
    let (capped, pixel_noise_grey_levels) = noise::capped_for_noise(params, &frames[reference]);
    let params = &capped;
    let frame_list: Vec<(&Image, f64, usize)> = frames
        .iter()
        .zip(&cams)
        .enumerate()
        .map(|(k, (f, &c))| (f, c, first_frame + k))
        .collect();
    // The four borders are independent: fitted side by side, kept in order.
    let fitted: Vec<(BorderTrack, Option<String>)> = BorderId::ALL
        .into_par_iter()
        .map(|id| {
            let z = z_of(id);
            let rows: Vec<f64> = median3(
                &coarse_rows
                    .iter()
                    .map(|(_, r)| r[id as usize])
                    .collect::<Vec<_>>(),
            );
            let points: Vec<(f64, f64)> = coarse_rows
                .iter()
                .zip(&rows)
                .filter(|(_, r)| r.is_finite() && z.is_finite())
                .map(|((j, _), &r)| (*j as f64 * spacing, geo.y_at(r, geo.apparent_z_um(z, r))))
                .collect();
            let typical_row = finite_median(rows.clone()).unwrap_or(f64::NAN);
            let z_app = geo.apparent_z_um(z, typical_row);
            let predict = (!points.is_empty()).then(|| interpolant(points.clone()));
            let task_at = |i: usize| {
                let s = positions_um[i];
                predict.as_ref().map(|p| SampleTask {
                    s_lo_um: s - half,
                    s_hi_um: s + half,
                    z_um: z_app,
                    predict_y: p,
                })
            };
            // A blurred border is fitted over a band sized to its blur.
            let reference_only = &frame_list[reference..=reference];
            let strip_widths: Vec<f64> = coarse_widths.iter().map(|w| w[id as usize]).collect();
            let sized = blur::sized_to_blur(
                params,
                &strip_widths,
                n,
                gap_rows(&coarse_rows, id),
                &|i, pilot| {
                    let task = task_at(i)?;
                    fit_sample(reference_only, 0, &geo, &task, pilot).map(|f| f.fit.width_px)
                },
            );
            let params = &sized;
            let fits: Vec<Option<SampleBorder>> = (0..n)
                .into_par_iter()
                .map(|i| fit_sample(&frame_list, reference, &geo, &task_at(i)?, params))
                .collect();
            let refined = if params.refine && predict.is_some() {
                let samples: Vec<Option<RefineSample>> = fits
                    .iter()
                    .enumerate()
                    .map(|(i, f)| {
                        let f = f.as_ref()?;
                        Some(RefineSample {
                            task: task_at(i)?,
                            fit: f.fit,
                            row_px: f.row_px,
                            column_weights: &f.column_weights,
                        })
                    })
                    .collect();
                let subset: Vec<(&Image, f64)> =
                    spread_frames(frames.len(), reference, params.spline_frames)
                        .into_iter()
                        .map(|k| (&frames[k], cams[k]))
                        .collect();
                refine_border(&subset, cam_ref, &geo, &samples, spacing, params)
            } else {
                vec![None; n]
            };
            let mut y_um = vec![f64::NAN; n];
            let mut std_error_um = vec![f64::NAN; n];
            for (i, f) in fits.iter().enumerate() {
                if let Some(f) = f {
                    let row = refined.get(i).copied().flatten().unwrap_or(f.row_px);
                    y_um[i] = geo.y_at(row, z_app);
                    std_error_um[i] = f.std_error_px * geo.um_per_px(z_app);
                }
            }
            let lost = (n > 0 && y_um.iter().all(|v| v.is_nan())).then(|| {
                format!(
                    "group {group}: the {} was lost over the whole group",
                    id.name()
                )
            });
            (
                BorderTrack {
                    id,
                    z_um: z,
                    y_um,
                    std_error_um,
                    weight: vec![0.0; n],
                    fits,
                },
                lost,
            )
        })
        .collect();
    let mut borders = Vec::with_capacity(4);
    let mut warnings = Vec::new();
    for (track, lost) in fitted {
        borders.push(track);
        warnings.extend(lost);
    }

    // 4. Combination.
    let ys: [Vec<f64>; 4] = std::array::from_fn(|b| borders[b].y_um.clone());
    let ses: [Vec<f64>; 4] = std::array::from_fn(|b| borders[b].std_error_um.clone());
    let combined = combine_borders(
        &ys,
        &ses,
        &CombineParams::from_edges(meta.record.cut, params, spacing),
    );
    for (track, w) in borders.iter_mut().zip(combined.border_weights.iter()) {
        track.weight.clone_from(w);
    }

    // 5. Velocity per wall: Vt·sin α·∂y/∂s.
    let velocities = signal::wall_velocities(
        &combined.walls_um,
        meta.record.cut,
        vt * alpha.sin() / spacing,
        &params.differentiator,
    );
    let walls: Vec<WallEdges> = [WallSide::Left, WallSide::Right]
        .into_iter()
        .zip(combined.walls_um.iter().zip(&combined.walls_se_um))
        .zip(velocities)
        .map(|((side, (disp, se)), velocity_mm_s)| WallEdges {
            side,
            displacement_um: disp.clone(),
            std_error_um: se.clone(),
            velocity_mm_s,
        })
        .collect();
    for (side, gaps) in ["left", "right"].iter().zip(&combined.gaps) {
        if n > 0 && gaps.iter().map(ExactSizeIterator::len).sum::<usize>() == n {
            warnings.push(format!(
                "group {group}: no {side} wall displacement anywhere (a gap)"
            ));
        }
    }
    Ok(Edges {
        group,
        cut: meta.record.cut,
        first_sample,
        spacing_um: spacing,
        positions_um,
        groove_speed_mm_s: vt,
        wall_angle_rad: alpha,
        bottom_depth_um,
        coarse: CoarseRead {
            frame: reference,
            pixel_noise_grey_levels,
            band_cap_px: params.max_band_half_height_px,
        },
        borders,
        constants_um: combined.constants_um,
        walls,
        gaps: combined.gaps,
        bridged: combined.bridged,
        warnings,
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests;
