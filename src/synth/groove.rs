//! The groove model: the sound turned into a height field Z(s, y) (cross-section profile moved by
//! the displacement d(s) and the vertical offset h(s), plus damage), its shading, and the truth.
//!
//! # Stereo 45/45 (derivation)
//! The cutter profile is `P(u)` with `u = y − d(s)`; the surface depth is `max(0, P(u) + h(s))`.
//! On the left wall (smaller y, depth grows with y) `P = (T + u)·tan α`, so the wall plane is
//! `Z = WD + (T + y − d)·tan α + h`: `a = ∂Z/∂s = −d'·tan α + h'`, `b = tan α > 0`. The engine's
//! rule `tan θ = −a·sign(b)/√(1 + b²)` gives `tan θ_L = d'·sin α − h'·cos α`: the groove's motion
//! `(d', h')` projected on the left wall's normal `(sin α, −cos α)`. On the right wall
//! `Z = WD + (T − y + d)·tan α + h`, `a = d'·tan α + h'`, `b = −tan α`, so
//! `tan θ_R = d'·sin α + h'·cos α`. A stereo cut makes each wall carry its channel,
//! `tan θ_L = V_L/Vt` and `tan θ_R = V_R/Vt`; solving,
//! `d' = (V_L + V_R)/(2·sin α·Vt)` and `h' = (V_R − V_L)/(2·cos α·Vt)`, i.e. at 45°
//! `d = (m_L + m_R)/√2`, `h = (m_R − m_L)/√2` with `m` the integrated channel velocities.
//! Check: with only the left channel, `(d', h') ∝ (cos α, −sin α)`, which is the right wall's own
//! direction: the right wall slides along itself (unchanged) while the left wall moves along its
//! normal by `m_L`. For a lateral cut `h = 0` and each wall reads `tan θ = (V/Vt)·sin α`; for a
//! vertical cut `d = 0`, `tan θ_L = −(V/Vt)·cos α`, `tan θ_R = +(V/Vt)·cos α` (positive V = deeper).

use std::path::Path;

use super::SynthError;
use super::config::SynthConfig;
use super::damage::Damage;
use super::noise::marble;
use super::track::{Track, TrackPoint};
use crate::io::wav::{Audio, read_wav};
use crate::io::{Cut, LoadError};

/// Iteration stops when the ray parameter moves by less than this (µm).
pub const RAY_TOLERANCE_UM: f64 = 1e-6;
/// Iteration cap of the ray/height-field intersection.
pub const RAY_MAX_ITERATIONS: usize = 200;
/// Largest contraction factor of the fixed-point intersection accepted (steeper: an error).
const MAX_CONTRACTION: f64 = 0.9;
/// Groove positions beyond the scan covered by the tables and damage, µm.
const TABLE_MARGIN_UM: f64 = 200.0;

/// The groove cross-section: walls at angle α, optional arcs into a flat bottom.
#[derive(Clone, Copy, Debug)]
struct Profile {
    half_top_um: f64,
    depth_um: f64,
    tan_wall: f64,
    /// Half-width of the flat bottom (where the arcs start).
    flat_half_um: f64,
    radius_um: f64,
    arc_centre_depth_um: f64,
    /// |u| where the arc meets the wall.
    arc_end_um: f64,
}

impl Profile {
    fn new(cfg: &SynthConfig) -> Self {
        let alpha = cfg.wall_angle_deg.to_radians();
        let tan_wall = alpha.tan();
        let half_top_um = 0.5 * cfg.groove_top_width_um;
        let depth_um = cfg.groove_depth_um;
        let r = cfg.bottom_radius_um;
        let flat_half_um = half_top_um - (depth_um - r + r / alpha.cos()) / tan_wall;
        Self {
            half_top_um,
            depth_um,
            tan_wall,
            flat_half_um,
            radius_um: r,
            arc_centre_depth_um: depth_um - r,
            arc_end_um: flat_half_um + r * alpha.sin(),
        }
    }

    /// Cutter depth P(u) (negative beyond the top edges: the wall line continued) and dP/du.
    #[inline]
    fn eval(&self, u: f64) -> (f64, f64) {
        let a = u.abs();
        let sign = if u < 0.0 { -1.0 } else { 1.0 };
        if a <= self.flat_half_um {
            (self.depth_um, 0.0)
        } else if a < self.arc_end_um {
            let du = a - self.flat_half_um;
            let root = (self.radius_um * self.radius_um - du * du)
                .max(1e-12)
                .sqrt();
            (self.arc_centre_depth_um + root, -sign * du / root)
        } else {
            (
                (self.half_top_um - a) * self.tan_wall,
                -sign * self.tan_wall,
            )
        }
    }
}

/// Ground truth of the groove at one position along it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GrooveTruth {
    /// Groove position, µm from the scan start.
    pub s_um: f64,
    /// Time in the sound, s (scan start + s/Vt).
    pub time_secs: f64,
    /// Lateral position of the groove centre line (y, µm; includes `groove_offset_um`).
    pub displacement_um: f64,
    /// Vertical offset h (µm, positive = deeper).
    pub depth_offset_um: f64,
    /// Lateral cutter velocity Vt·∂d/∂s, mm/s.
    pub lateral_velocity_mm_s: f64,
    /// Vertical cutter velocity Vt·∂h/∂s, mm/s.
    pub vertical_velocity_mm_s: f64,
    /// Left wall tan θ = −a·sign(b)/√(1+b²) of its plane (= left wall velocity / Vt).
    pub left_tan_theta: f64,
    /// Right wall tan θ (= right wall velocity / Vt).
    pub right_tan_theta: f64,
}

/// Where the cover glass and the focal planes are.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Optics {
    /// Focal plane without glass, µm from the optical centre.
    pub focus_um: f64,
    /// Focal plane seen through the glass, µm.
    pub focus_glass_um: f64,
    /// Rows with y < this see through the glass (dual focus only).
    pub glass_edge_row: Option<f64>,
    /// Glass thickness, µm.
    pub glass_thickness_um: f64,
    /// Glass refractive index.
    pub glass_index: f64,
}

impl Optics {
    /// True when image row `row` sees the groove through the glass.
    #[must_use]
    pub fn sees_glass(&self, row: usize) -> bool {
        self.glass_edge_row.is_some_and(|edge| (row as f64) < edge)
    }
}

/// A groove ready to render: the sound integrated, the damage laid out, the optics placed.
#[derive(Clone, Debug)]
pub struct Groove {
    pub(crate) cfg: SynthConfig,
    profile: Profile,
    lateral: Track,
    vertical: Track,
    has_vertical: bool,
    pub(crate) damage: Damage,
    /// Groove speed, µm/s.
    pub(crate) vt_um_s: f64,
    rate_hz: f64,
    start_sample: i64,
    samples_per_um: f64,
    groups: usize,
    pub(crate) optics: Optics,
    reference: Audio,
    warnings: Vec<String>,
}

/// The sound with each channel's mean removed, read without copying it.
struct Centred<'a> {
    channels: &'a [Vec<f32>],
    means: Vec<f64>,
    /// The cut is stereo (two wall channels).
    stereo_cut: bool,
    /// A stereo cut of a sound with two channels (otherwise both walls get the mono mix).
    stereo: bool,
}

impl<'a> Centred<'a> {
    fn new(sound: &'a Audio, stereo_cut: bool) -> Self {
        let means = sound
            .channels
            .iter()
            .map(|c| c.iter().map(|&v| f64::from(v)).sum::<f64>() / c.len().max(1) as f64)
            .collect();
        Self {
            channels: &sound.channels,
            means,
            stereo_cut,
            stereo: stereo_cut && sound.channels.len() >= 2,
        }
    }

    fn len(&self) -> usize {
        self.channels.first().map_or(0, Vec::len)
    }

    /// Channel `c` at sample `n`, mean removed; 0 outside the sound.
    #[inline]
    fn at(&self, c: usize, n: i64) -> f64 {
        if n < 0 {
            return 0.0;
        }
        match (self.channels.get(c), self.means.get(c)) {
            (Some(ch), Some(m)) => ch.get(n as usize).map_or(0.0, |&v| f64::from(v) - m),
            _ => 0.0,
        }
    }

    fn mono(&self, n: i64) -> f64 {
        let k = self.channels.len().max(1);
        (0..k).map(|c| self.at(c, n)).sum::<f64>() / k as f64
    }

    /// Left channel of a stereo cut (the mono mix when the sound is mono).
    fn left(&self, n: i64) -> f64 {
        if self.stereo {
            self.at(0, n)
        } else {
            self.mono(n)
        }
    }

    /// Right channel of a stereo cut (the mono mix when the sound is mono).
    fn right(&self, n: i64) -> f64 {
        if self.stereo {
            self.at(1, n)
        } else {
            self.mono(n)
        }
    }

    /// Largest |sample| of what is cut: both channels for stereo, the mono mix otherwise.
    fn peak(&self) -> f64 {
        (0..self.len() as i64).fold(0.0f64, |m, n| {
            if self.stereo {
                m.max(self.at(0, n).abs()).max(self.at(1, n).abs())
            } else {
                m.max(self.mono(n).abs())
            }
        })
    }

    /// The cut's channels from `start` over the scan, divided by `peak_in` (velocity / peak).
    fn reference(&self, rate: u32, start: i64, scan_samples: f64, peak_in: f64) -> Audio {
        let n = (scan_samples.floor() as usize + 1).min(self.len().saturating_sub(start as usize));
        let norm = if peak_in > 0.0 { 1.0 / peak_in } else { 0.0 };
        let take = |f: &dyn Fn(i64) -> f64| -> Vec<f32> {
            (0..n as i64)
                .map(|i| (f(start + i) * norm) as f32)
                .collect()
        };
        let channels = if self.stereo_cut {
            vec![take(&|n| self.left(n)), take(&|n| self.right(n))]
        } else {
            vec![take(&|n| self.mono(n))]
        };
        Audio {
            sample_rate_hz: rate,
            channels,
        }
    }
}

fn sound_err(problem: impl Into<String>) -> SynthError {
    SynthError::Sound {
        problem: problem.into(),
    }
}

impl Groove {
    /// Integrates `sound` into a groove for `cfg`.
    ///
    /// # Errors
    /// [`SynthError::Config`] for invalid or absurd settings (walls the optics cannot see, a
    /// groove leaving the frame, focal planes off the walls), [`SynthError::Sound`] for an
    /// empty sound, a zero rate, non-finite samples or a sound too short for one group.
    pub fn new(sound: &Audio, cfg: &SynthConfig) -> Result<Self, SynthError> {
        cfg.validate()?;
        if sound.sample_rate_hz == 0 {
            return Err(sound_err("the sound has a zero sample rate"));
        }
        if sound.channels.is_empty() || sound.is_empty() {
            return Err(sound_err("the sound holds no samples"));
        }
        if sound.channels.iter().any(|c| c.len() != sound.len()) {
            return Err(sound_err("the sound's channels differ in length"));
        }
        if sound.channels.iter().flatten().any(|v| !v.is_finite()) {
            return Err(sound_err("the sound holds NaN or infinite samples"));
        }
        let rate_hz = f64::from(sound.sample_rate_hz);
        let vt_um_s = cfg.groove_speed_um_s();
        let len = sound.len() as i64;
        let start_sample = (cfg.start_secs * rate_hz).round() as i64;
        if start_sample >= len {
            return Err(SynthError::Config {
                key: "synth.start_secs".into(),
                problem: format!(
                    "{} s is beyond the end of the {:.3} s sound",
                    cfg.start_secs,
                    sound.duration_secs()
                ),
            });
        }
        let avail_um = (len - 1 - start_sample) as f64 / rate_hz * vt_um_s;
        let span_um = cfg.group_span_um();
        let group_step_um = cfg.group_step_um();
        if avail_um < span_um {
            return Err(sound_err(format!(
                "the sound is too short: one group covers {span_um:.1} µm of groove, which is {:.4} s at \
                 {:.1} mm/s, but only {:.4} s remain after start_secs",
                span_um / vt_um_s,
                vt_um_s / 1000.0,
                avail_um / vt_um_s
            )));
        }
        let fit = ((avail_um - span_um) / group_step_um).floor() as usize + 1;
        let groups = cfg.max_groups.map_or(fit, |m| m.min(fit));
        let scan_end_um = (groups - 1) as f64 * group_step_um + span_um;

        // Velocities: DC removed per channel, one common scale so max |V| = peak.
        let src = Centred::new(sound, cfg.cut == Cut::Stereo);
        let peak_in = src.peak();
        let peak_um_s = cfg.peak_velocity_mm_s * 1000.0;
        let scale = if peak_in > 0.0 {
            peak_um_s / peak_in
        } else {
            0.0
        };
        let alpha = cfg.wall_angle_deg.to_radians();
        let lat_vel = |n: i64| match cfg.cut {
            Cut::Lateral => src.mono(n) * scale,
            Cut::Vertical => 0.0,
            Cut::Stereo => (src.left(n) + src.right(n)) * scale / (2.0 * alpha.sin()),
        };
        let vert_vel = |n: i64| match cfg.cut {
            Cut::Lateral => 0.0,
            Cut::Vertical => src.mono(n) * scale,
            Cut::Stereo => (src.right(n) - src.left(n)) * scale / (2.0 * alpha.cos()),
        };

        let geo_reach = cfg.width_px as f64 * cfg.pixel_pitch_um * (cfg.groove_depth_um + 100.0)
            / (cfg.working_distance_mm * 1000.0);
        let s_lo = -geo_reach - TABLE_MARGIN_UM;
        let s_hi = scan_end_um + geo_reach + TABLE_MARGIN_UM;
        let samples_per_um = rate_hz / vt_um_s;
        let n_lo = start_sample + (s_lo * samples_per_um).floor() as i64 - 2;
        let n_hi = start_sample + (s_hi * samples_per_um).ceil() as i64 + 2;
        let n_end = start_sample + (scan_end_um * samples_per_um).ceil() as i64;

        let mut lateral = Track::new(n_lo, n_hi, start_sample, rate_hz, lat_vel);
        let (lo, hi) = lateral.range_between(start_sample, n_end);
        lateral.shift(-0.5 * (lo + hi) + cfg.groove_offset_um);
        let lat_swing = 0.5 * (hi - lo);
        let has_vertical = cfg.cut != Cut::Lateral;
        let mut vertical = if has_vertical {
            Track::new(n_lo, n_hi, start_sample, rate_hz, vert_vel)
        } else {
            Track::new(0, 1, 0, rate_hz, |_| 0.0)
        };
        let (vlo, vhi) = vertical.range_between(start_sample, n_end);
        vertical.shift(-0.5 * (vlo + vhi));
        let vert_swing = 0.5 * (vhi - vlo);

        let profile = Profile::new(cfg);
        let wd_um = cfg.working_distance_mm * 1000.0;
        let half_frame_um = 0.5 * cfg.height_px as f64 * cfg.pixel_pitch_um;
        let reach_um = cfg.groove_offset_um.abs()
            + lat_swing
            + profile.half_top_um
            + vert_swing / profile.tan_wall;
        if reach_um > half_frame_um {
            return Err(SynthError::Config {
                key: "synth.peak_velocity_mm_s".into(),
                problem: format!(
                    "the groove leaves the frame: its edge reaches {reach_um:.1} µm from the centre row \
                     (swing ±{lat_swing:.1} µm lateral, ±{vert_swing:.1} µm vertical) but the frame's half \
                     height is {half_frame_um:.1} µm; lower peak_velocity_mm_s or groove_offset_um, or raise height_px"
                ),
            });
        }

        let max_slope_s = profile.tan_wall * lateral.max_abs_velocity_um_s() / vt_um_s
            + vertical.max_abs_velocity_um_s() / vt_um_s;
        let y_span_um = half_frame_um * (1.0 + (cfg.groove_depth_um + 50.0) / wd_um) + 20.0;
        let damage = Damage::new(
            &cfg.damage,
            s_lo,
            s_hi,
            y_span_um,
            cfg.groove_depth_um,
            profile.tan_wall,
        );
        let cx = 0.5 * (cfg.width_px as f64 - 1.0);
        let cy = 0.5 * (cfg.height_px as f64 - 1.0);
        let ray_y = cy * cfg.pixel_pitch_um / wd_um;
        let ray_x = cx * cfg.pixel_pitch_um / wd_um;
        let contraction = ray_y * (profile.tan_wall + damage.max_slope())
            + ray_x * (max_slope_s + damage.max_slope());
        if contraction >= MAX_CONTRACTION {
            return Err(SynthError::Config {
                key: "synth.wall_angle_deg".into(),
                problem: format!(
                    "walls steeper than the optics can see: edge rays ({:.3} rad off axis) meet \
                     surfaces of slope up to {:.2}, so parts of the walls are hidden (contraction {contraction:.2} >= {MAX_CONTRACTION})",
                    ray_y.atan(),
                    profile.tan_wall + damage.max_slope()
                ),
            });
        }

        let mut warnings = Vec::new();
        if sound.channels.len() > 1 && cfg.cut != Cut::Stereo {
            warnings.push(format!(
                "the sound has {} channels and a {} cut carries one: their mono mix is cut \
                 (and written as reference.wav); a stereo cut carries two",
                sound.channels.len(),
                cfg.cut.name(),
            ));
        }
        let optics = Self::place_optics(cfg, &profile, wd_um, cy, lat_swing, &mut warnings);
        let reference = src.reference(
            sound.sample_rate_hz,
            start_sample,
            scan_end_um * samples_per_um,
            peak_in,
        );
        Ok(Self {
            cfg: cfg.clone(),
            profile,
            lateral,
            vertical,
            has_vertical,
            damage,
            vt_um_s,
            rate_hz,
            start_sample,
            samples_per_um,
            groups,
            optics,
            reference,
            warnings,
        })
    }

    /// [`Groove::new`] for the sound of a WAV file; sound problems name the file.
    ///
    /// # Errors
    /// As [`Groove::new`]; an unreadable, non-WAV, empty or too short sound is a
    /// [`SynthError::Load`] whose message ends with the file path.
    pub fn from_wav(sound_path: &Path, cfg: &SynthConfig) -> Result<Self, SynthError> {
        cfg.validate()?;
        let sound = read_wav(sound_path)?;
        Self::new(&sound, cfg).map_err(|e| match e {
            SynthError::Sound { problem } => SynthError::Load(LoadError::Sound {
                problem,
                path: sound_path.to_path_buf(),
            }),
            other => other,
        })
    }

    fn place_optics(
        cfg: &SynthConfig,
        profile: &Profile,
        wd_um: f64,
        cy: f64,
        lat_swing: f64,
        warnings: &mut Vec<String>,
    ) -> Optics {
        let focus_um = cfg.focus_distance_um();
        let Some(df) = &cfg.dual_focus else {
            return Optics {
                focus_um,
                focus_glass_um: focus_um,
                glass_edge_row: None,
                glass_thickness_um: 0.0,
                glass_index: 1.0,
            };
        };
        let shift = df.focus_shift_um();
        let (z1, z2) = (focus_um - wd_um, focus_um - wd_um + shift);
        // Right wall at zero displacement: depth (T − u)·tan α.
        let u1 = profile.half_top_um - z1 / profile.tan_wall;
        let u2 = profile.half_top_um - z2 / profile.tan_wall;
        let y_edge = cfg.groove_offset_um + 0.5 * (u1 + u2);
        let z_edge = wd_um + 0.5 * (z1 + z2);
        let row = (cy + y_edge * wd_um / (cfg.pixel_pitch_um * z_edge)).round();
        let room = 0.5 * (u1 - u2);
        if lat_swing > room {
            warnings.push(format!(
                "the groove swings ±{lat_swing:.1} µm but the right-wall focus stripes are only \
                 {room:.1} µm from the glass edge: they cross it at loud passages"
            ));
        }
        Optics {
            focus_um,
            focus_glass_um: focus_um + shift,
            glass_edge_row: Some(row),
            glass_thickness_um: df.glass_thickness_mm * 1000.0,
            glass_index: df.glass_index,
        }
    }

    /// The settings this groove was built with.
    #[must_use]
    pub fn config(&self) -> &SynthConfig {
        &self.cfg
    }

    /// Groups the scan holds.
    #[must_use]
    pub fn groups(&self) -> usize {
        self.groups
    }

    /// Groove length the scan covers at the land, µm.
    #[must_use]
    pub fn scan_length_um(&self) -> f64 {
        (self.groups - 1) as f64 * self.cfg.group_step_um() + self.cfg.group_span_um()
    }

    /// Groove speed Vt, mm/s.
    #[must_use]
    pub fn groove_speed_mm_s(&self) -> f64 {
        self.vt_um_s / 1000.0
    }

    /// Sound sample at the scan start (s = 0).
    #[must_use]
    pub fn start_sample(&self) -> i64 {
        self.start_sample
    }

    /// Cover glass and focal planes.
    #[must_use]
    pub fn optics(&self) -> Optics {
        self.optics
    }

    /// Non-fatal problems found while building.
    #[must_use]
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// Number of damage features laid out.
    #[must_use]
    pub fn damage_features(&self) -> usize {
        self.damage.len()
    }

    /// The sound stretch the scan covers (from s = 0), as cutter velocity over
    /// `peak_velocity_mm_s`: the cut's channel count (2 for stereo: left, right wall channels).
    #[must_use]
    pub fn reference(&self) -> &Audio {
        &self.reference
    }

    #[inline]
    fn tracks(&self, s: f64) -> (TrackPoint, TrackPoint) {
        let q = self.start_sample as f64 + s * self.samples_per_um;
        let lat = self.lateral.at(q, self.vt_um_s);
        let vert = if self.has_vertical {
            self.vertical.at(q, self.vt_um_s)
        } else {
            TrackPoint::default()
        };
        (lat, vert)
    }

    /// Depth below the land (µm) of the surface at material point `(s, y)`, damage included.
    #[inline]
    #[must_use]
    pub fn depth_um(&self, s: f64, y: f64) -> f64 {
        let (lat, vert) = self.tracks(s);
        let u = y - lat.value_um;
        let (p, _) = self.profile.eval(u);
        let w = p + vert.value_um;
        let hit = self.damage.at(s, y, u, w, self.profile.flat_half_um, false);
        w.max(0.0) + hit.depth_um
    }

    /// Grey level (before blur and noise) of the surface at `(s, y)` and its depth (µm).
    #[must_use]
    pub fn radiance(&self, s: f64, y: f64) -> (f32, f64) {
        let c = &self.cfg;
        let (lat, vert) = self.tracks(s);
        let u = y - lat.value_um;
        let (p, dp) = self.profile.eval(u);
        let w = p + vert.value_um;
        let hit = self.damage.at(s, y, u, w, self.profile.flat_half_um, true);
        let depth = w.max(0.0) + hit.depth_um;
        let (slope_w, flat) = if w > 0.0 {
            let frac = (p / self.profile.depth_um).clamp(0.0, 1.0);
            (
                (dp.abs() / self.profile.tan_wall).min(1.0),
                c.land_brightness + (c.bottom_brightness - c.land_brightness) * frac,
            )
        } else {
            (0.0, c.land_brightness)
        };
        let base = flat + (c.wall_brightness - flat) * slope_w;
        let tex = marble([s, y, depth], c.texture_scale_um, u64::from(c.seed));
        let mut v = base as f32 * (1.0 + c.texture_contrast as f32 * (2.0 * tex - 1.0));
        v *= hit.scratch_mult;
        if hit.flake_mask > 0.0 {
            let flake = c.flake_brightness as f32 * (0.5 + tex);
            v += (flake - v) * hit.flake_mask;
        }
        if hit.dust_mask > 0.0 {
            let dust = hit.dust_level * (0.8 + 0.4 * tex);
            v += (dust - v) * hit.dust_mask;
        }
        (v, depth)
    }

    /// The true groove motion at groove position `s_um` (µm from the scan start).
    #[must_use]
    pub fn truth(&self, s_um: f64) -> GrooveTruth {
        let (lat, vert) = self.tracks(s_um);
        let alpha = self.cfg.wall_angle_deg.to_radians();
        let (sa, ca) = (alpha.sin(), alpha.cos());
        GrooveTruth {
            s_um,
            time_secs: (self.start_sample as f64 + s_um * self.samples_per_um) / self.rate_hz,
            displacement_um: lat.value_um,
            depth_offset_um: vert.value_um,
            lateral_velocity_mm_s: lat.velocity_um_s / 1000.0,
            vertical_velocity_mm_s: vert.velocity_um_s / 1000.0,
            left_tan_theta: lat.slope * sa - vert.slope * ca,
            right_tan_theta: lat.slope * sa + vert.slope * ca,
        }
    }

    /// Groove position seen by column `x_px` at the land in frame `frame` of group `group`:
    /// `group·group_step + frame·frame_step + x·pitch` (µm).
    #[must_use]
    pub fn land_s_um(&self, group: usize, frame: usize, x_px: f64) -> f64 {
        group as f64 * self.cfg.group_step_um()
            + frame as f64 * self.cfg.frame_step_um
            + x_px * self.cfg.pixel_pitch_um
    }
}

/// The true groove motion at `s_um` (see [`Groove::truth`]).
#[must_use]
pub fn groove_truth(groove: &Groove, s_um: f64) -> GrooveTruth {
    groove.truth(s_um)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests;
