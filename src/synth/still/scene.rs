//! The still's geometry: every groove's centre path across the image, its walls' motions, and the
//! four borders (land|wall|bottom|wall|land) of each groove at any point along the image.
//!
//! # Coordinates
//! `Y` runs along the grooves (µm from the image's first line; time runs toward +Y), `X` across
//! them (µm from the image's first column of a vertical still, first row of a horizontal one).
//! Line `n` covers `Y ∈ [n·p, (n+1)·p]`, cross pixel `m` covers `X ∈ [m·p, (m+1)·p]`; border
//! positions in pixels use pixel-centre coordinates, `c = X/p − ½`.
//!
//! The *left* wall is the one on the left hand of someone facing the way time runs, which is the
//! inner wall (toward the spindle) of a record seen from above: the high-X wall of a vertical
//! still, the low-X wall of a horizontal one. A positive sound value moves that wall's border
//! toward the left-hand side; a lateral cut moves both walls so.
//!
//! All grooves share one slow path `P(Y)` (skew, wander and, when `curved`, the arc of the
//! record); groove `k`'s centre line is `X_k(Y) = X₀ + P(Y) + (k − (N−1)/2)·pitch·sec(Y)` with
//! `sec = √(1 + P′²)`, and its borders lie at perpendicular offsets `e` from it, i.e. at
//! `X_k + e·sec`. Time along groove `k` is `t₀ₖ + s(Y)/Vtₖ` where `s` is the arc length of the path.

use crate::io::Cut;
use crate::io::wav::Audio;
use crate::pipeline::still::{Axis, StillSetup};
use crate::synth::SynthError;
use crate::synth::noise::{Rng, hash_seq};
use crate::synth::track::Track;

use super::config::{MIN_LAND_UM, StillConfig, default_tones_hz};

/// Arc-length table entries per pixel along the image.
const ARC_STEPS_PER_PX: usize = 4;
/// Salt of the per-wall random choices (levels, rims).
const WALL_SALT: u64 = 0x5711_0001;
/// Salt of the wander phase.
const PATH_SALT: u64 = 0x5711_0002;

/// How one wall (or both, for a lateral cut) moves: its channel displacement along the
/// modulation direction as a function of time.
#[derive(Clone, Debug)]
pub enum Motion {
    /// A tone: displacement −A·cos(2πft) with A = V/(2πf), velocity V·sin(2πft).
    Tone {
        /// Frequency.
        freq_hz: f64,
        /// Velocity amplitude V, µm/s.
        peak_um_s: f64,
    },
    /// A cut sound: velocity linear between samples, displacement its exact integral.
    Sound {
        /// The integrated channel.
        track: Track,
        /// Its sample rate.
        rate_hz: f64,
    },
}

impl Motion {
    /// Displacement (µm) and velocity (µm/s) at time `t_secs`.
    #[must_use]
    pub fn at(&self, t_secs: f64) -> (f64, f64) {
        match self {
            Self::Tone { freq_hz, peak_um_s } => {
                let w = std::f64::consts::TAU * freq_hz;
                let (s, c) = (w * t_secs).sin_cos();
                (-peak_um_s / w * c, peak_um_s * s)
            }
            Self::Sound { track, rate_hz } => {
                let p = track.at(t_secs * rate_hz, 1.0);
                (p.value_um, p.velocity_um_s)
            }
        }
    }
}

/// One groove of the still.
#[derive(Clone, Debug)]
pub struct StillGroove {
    /// Radius, mm.
    pub radius_mm: f64,
    /// Groove speed Vt, µm/s.
    pub vt_um_s: f64,
    /// Time of the image's first line (Y = 0) in its sound, s.
    pub start_secs: f64,
    /// Left wall motion (channel 0).
    pub left: Motion,
    /// Right wall motion (channel 1; the same as `left` for a lateral cut).
    pub right: Motion,
    /// Tones of the walls (left, right), when the built-in tones are cut.
    pub tones_hz: Option<(f64, f64)>,
    /// Grey level of the low-X and high-X wall.
    pub wall_levels: [f64; 2],
    /// Bright rim at the land border of the low-X and high-X wall.
    pub rims: [bool; 2],
}

/// The still's whole geometry, ready to render and to answer ground-truth questions.
#[derive(Clone, Debug)]
pub struct StillScene {
    /// The settings.
    pub cfg: StillConfig,
    /// Grooves in order of increasing X (from the image's left or top).
    pub grooves: Vec<StillGroove>,
    /// +1 when the inner (left-hand) side is toward +X, −1 toward −X.
    inner_sign: f64,
    /// Lateral border displacement per channel displacement (1 for lateral, 1/sin of the wall
    /// angle for stereo).
    border_gain: f64,
    wander_phase_rad: f64,
    /// Arc length of the path at `Y = i·p/ARC_STEPS_PER_PX`, µm.
    arc_um: Vec<f64>,
}

/// The four borders of one groove at one point, cross pixel-centre coordinates, ascending.
pub type Borders = [f64; 4];

fn sound_err(problem: impl Into<String>) -> SynthError {
    SynthError::Sound {
        problem: problem.into(),
    }
}

/// Per-channel tracks of `sound` (mean removed) scaled so the largest |value| cut is `peak_um_s`.
fn sound_tracks(sound: &Audio, stereo: bool, peak_um_s: f64) -> Result<[Track; 2], SynthError> {
    if sound.sample_rate_hz == 0 {
        return Err(sound_err("the sound has a zero sample rate"));
    }
    if sound.is_empty() || sound.channels.is_empty() {
        return Err(sound_err("the sound holds no samples"));
    }
    if sound.channels.iter().flatten().any(|v| !v.is_finite()) {
        return Err(sound_err("the sound holds NaN or infinite samples"));
    }
    let centred = |c: &[f32]| -> Vec<f64> {
        let mean = c.iter().map(|&v| f64::from(v)).sum::<f64>() / c.len().max(1) as f64;
        c.iter().map(|&v| f64::from(v) - mean).collect()
    };
    let chans: Vec<Vec<f64>> = sound.channels.iter().map(|c| centred(c)).collect();
    let mono: Vec<f64> = (0..sound.len())
        .map(|i| {
            chans
                .iter()
                .map(|c| c.get(i).copied().unwrap_or(0.0))
                .sum::<f64>()
                / chans.len() as f64
        })
        .collect();
    let (l, r) = match (stereo, chans.as_slice()) {
        (true, [a, b, ..]) => (a.clone(), b.clone()),
        _ => (mono.clone(), mono),
    };
    let peak = l.iter().chain(&r).fold(0.0f64, |m, v| m.max(v.abs()));
    let scale = if peak > 0.0 { peak_um_s / peak } else { 0.0 };
    let rate = f64::from(sound.sample_rate_hz);
    let last = sound.len() as i64 - 1;
    let track = |c: &[f64]| {
        Track::new(-2, last + 2, 0, rate, |n| {
            usize::try_from(n)
                .ok()
                .and_then(|i| c.get(i))
                .map_or(0.0, |v| v * scale)
        })
    };
    Ok([track(&l), track(&r)])
}

impl StillScene {
    /// What the still decoder is told to decode groove `k` (0-based) of this still: the
    /// still's axis, scale, speed and cut and the groove's radius, played forwards. None when
    /// there is no groove `k`.
    #[must_use]
    pub fn setup(&self, k: usize) -> Option<StillSetup> {
        let groove = self.grooves.get(k)?;
        Some(StillSetup {
            axis: self.cfg.axis,
            um_per_px: self.cfg.um_per_px,
            rpm: self.cfg.rpm,
            radius_mm: groove.radius_mm,
            cut: self.cfg.cut,
            reverse: false,
        })
    }

    /// Lays out the grooves of `cfg`; with `sound`, every groove carries it (the middle groove
    /// from `start_secs`, each turn further in one revolution later), otherwise the built-in tones.
    ///
    /// # Errors
    /// [`SynthError::Config`] for invalid settings or grooves that would cut into each other,
    /// [`SynthError::Sound`] for an unusable sound.
    pub fn new(cfg: &StillConfig, sound: Option<&Audio>) -> Result<Self, SynthError> {
        cfg.validate()?;
        let p = cfg.um_per_px;
        let inner_sign = match cfg.axis {
            Axis::Vertical => 1.0,
            Axis::Horizontal => -1.0,
        };
        let stereo = cfg.cut == Cut::Stereo;
        let border_gain = if stereo {
            1.0 / cfg.wall_angle_deg.to_radians().sin()
        } else {
            1.0
        };
        let peak_um_s = cfg.peak_velocity_mm_s * 1000.0;
        let tones = if cfg.tones_hz.is_empty() {
            default_tones_hz(cfg.grooves, cfg.cut)
        } else {
            cfg.tones_hz.clone()
        };
        let tracks = sound
            .map(|s| sound_tracks(s, stereo, peak_um_s))
            .transpose()?;
        let mid = 0.5 * (cfg.grooves as f64 - 1.0);
        let mut rng = Rng::new(hash_seq(u64::from(cfg.seed), &[WALL_SALT]));
        let mut grooves = Vec::with_capacity(cfg.grooves);
        for k in 0..cfg.grooves {
            // Turns further in (toward the left-hand side) are smaller and later.
            let inward = (k as f64 - mid) * inner_sign;
            let radius_mm = cfg.radius_mm - inward * cfg.pitch_um / 1000.0;
            let vt_um_s = cfg.groove_speed_um_s(radius_mm);
            let (left, right, tones_hz, start_secs) = match &tracks {
                Some([l, r]) => {
                    let rate_hz = f64::from(sound.map_or(1, |s| s.sample_rate_hz));
                    let m = |t: &Track| Motion::Sound {
                        track: t.clone(),
                        rate_hz,
                    };
                    let start = cfg.start_secs + inward * cfg.revolution_secs();
                    (m(l), m(r), None, start)
                }
                None => {
                    let (fl, fr) = if stereo {
                        (tones[2 * k], tones[2 * k + 1])
                    } else {
                        (tones[k], tones[k])
                    };
                    let m = |f: f64| Motion::Tone {
                        freq_hz: f,
                        peak_um_s,
                    };
                    (m(fl), m(fr), Some((fl, fr)), 0.0)
                }
            };
            let mut level =
                || cfg.wall_level * (1.0 + cfg.wall_level_spread * (2.0 * rng.uniform() - 1.0));
            let wall_levels = [level(), level()];
            let rims = [
                rng.uniform() < cfg.rim_fraction,
                rng.uniform() < cfg.rim_fraction,
            ];
            grooves.push(StillGroove {
                radius_mm,
                vt_um_s,
                start_secs,
                left,
                right,
                tones_hz,
                wall_levels,
                rims,
            });
        }
        let wander_phase_rad =
            std::f64::consts::TAU * Rng::new(hash_seq(u64::from(cfg.seed), &[PATH_SALT])).uniform();
        let mut scene = Self {
            cfg: cfg.clone(),
            grooves,
            inner_sign,
            border_gain,
            wander_phase_rad,
            arc_um: Vec::new(),
        };
        let steps = cfg.length_px * ARC_STEPS_PER_PX;
        let dy = p / ARC_STEPS_PER_PX as f64;
        let mut arc = Vec::with_capacity(steps + 1);
        let mut s = 0.0;
        arc.push(0.0);
        for i in 0..steps {
            // Simpson's rule on each step.
            let y0 = i as f64 * dy;
            let f = |y: f64| scene.path_slope(y).hypot(1.0);
            s += dy / 6.0 * (f(y0) + 4.0 * f(y0 + 0.5 * dy) + f(y0 + dy));
            arc.push(s);
        }
        scene.arc_um = arc;
        scene.check_clearance()?;
        Ok(scene)
    }

    /// Image length along the grooves, µm.
    fn length_um(&self) -> f64 {
        self.cfg.length_px as f64 * self.cfg.um_per_px
    }

    /// The common path P(Y), µm across.
    fn path(&self, y_um: f64) -> f64 {
        let c = &self.cfg;
        let l = self.length_um();
        let mut p = c.drift_um * (y_um / l - 0.5)
            + c.wander_um
                * (std::f64::consts::TAU * y_um / c.wander_period_um + self.wander_phase_rad).sin();
        if c.curved {
            let r = c.radius_mm * 1000.0;
            p += self.inner_sign * (y_um - 0.5 * l).powi(2) / (2.0 * r);
        }
        p
    }

    /// dP/dY.
    fn path_slope(&self, y_um: f64) -> f64 {
        let c = &self.cfg;
        let l = self.length_um();
        let w = std::f64::consts::TAU / c.wander_period_um;
        let mut d = c.drift_um / l + c.wander_um * w * (w * y_um + self.wander_phase_rad).cos();
        if c.curved {
            d += self.inner_sign * (y_um - 0.5 * l) / (c.radius_mm * 1000.0);
        }
        d
    }

    /// Arc length of the path from Y = 0, µm.
    #[must_use]
    pub fn arc_um(&self, y_um: f64) -> f64 {
        let q = (y_um / self.cfg.um_per_px * ARC_STEPS_PER_PX as f64).max(0.0);
        let i = q.floor() as usize;
        let last = self.arc_um.len().saturating_sub(1);
        if i >= last {
            let slope = self.path_slope(y_um).hypot(1.0);
            return self.arc_um.get(last).copied().unwrap_or(0.0)
                + (y_um - last as f64 * self.cfg.um_per_px / ARC_STEPS_PER_PX as f64) * slope;
        }
        let f = q - i as f64;
        self.arc_um[i] * (1.0 - f) + self.arc_um[i + 1] * f
    }

    /// Time in groove `k`'s sound at `Y`, s.
    #[must_use]
    pub fn time_secs(&self, k: usize, y_um: f64) -> f64 {
        self.grooves
            .get(k)
            .map_or(0.0, |g| g.start_secs + self.arc_um(y_um) / g.vt_um_s)
    }

    /// The four borders of groove `k` at `Y`, µm across, ascending (land|wall, wall|bottom,
    /// bottom|wall, wall|land).
    #[must_use]
    pub fn borders_um(&self, k: usize, y_um: f64) -> [f64; 4] {
        let Some(g) = self.grooves.get(k) else {
            return [f64::NAN; 4];
        };
        let c = &self.cfg;
        let sec = self.path_slope(y_um).hypot(1.0);
        let mid = 0.5 * (c.grooves as f64 - 1.0);
        let x0 = 0.5 * c.across_px as f64 * c.um_per_px;
        let centre = x0 + self.path(y_um) + (k as f64 - mid) * c.pitch_um * sec;
        let t = self.time_secs(k, y_um);
        let (dl, _) = g.left.at(t);
        let (dr, _) = g.right.at(t);
        // Channel displacement toward the left-hand side → border displacement along +X.
        let (d_left, d_right) = (
            dl * self.border_gain * self.inner_sign,
            dr * self.border_gain * self.inner_sign,
        );
        let (d_lo, d_hi) = if self.inner_sign > 0.0 {
            (d_right, d_left)
        } else {
            (d_left, d_right)
        };
        let m = 0.5 * (d_lo + d_hi);
        let (hw, hb) = (0.5 * c.top_width_um, 0.5 * c.bottom_width_um);
        [
            centre + (-hw + d_lo) * sec,
            centre + (-hb + m) * sec,
            centre + (hb + m) * sec,
            centre + (hw + d_hi) * sec,
        ]
    }

    /// The borders of groove `k` at the centre of line `line`, cross pixel-centre coordinates.
    #[must_use]
    pub fn borders_px(&self, k: usize, line: usize) -> Borders {
        let p = self.cfg.um_per_px;
        self.borders_um(k, (line as f64 + 0.5) * p)
            .map(|x| x / p - 0.5)
    }

    /// Channel velocities (left wall, right wall) of groove `k` at `Y`, mm/s.
    #[must_use]
    pub fn velocities_mm_s(&self, k: usize, y_um: f64) -> (f64, f64) {
        let Some(g) = self.grooves.get(k) else {
            return (f64::NAN, f64::NAN);
        };
        let t = self.time_secs(k, y_um);
        (g.left.at(t).1 / 1000.0, g.right.at(t).1 / 1000.0)
    }

    /// Which of groove `k`'s walls (low-X, high-X) is the left wall: index 1 when the left-hand
    /// side is toward +X.
    #[must_use]
    pub fn left_wall_index(&self) -> usize {
        usize::from(self.inner_sign > 0.0)
    }

    /// Refuses grooves that come closer than [`MIN_LAND_UM`] anywhere (checked at every line).
    fn check_clearance(&self) -> Result<(), SynthError> {
        let p = self.cfg.um_per_px;
        for line in 0..self.cfg.length_px {
            let y = (line as f64 + 0.5) * p;
            for k in 1..self.grooves.len() {
                let a = self.borders_um(k - 1, y);
                let b = self.borders_um(k, y);
                if b[0] - a[3] < MIN_LAND_UM {
                    return Err(SynthError::Config {
                        key: "still.peak_velocity_mm_s".into(),
                        problem: format!(
                            "grooves {k} and {} come {:.1} µm close at line {line} (at least {MIN_LAND_UM} µm \
                             of land is needed); lower the velocity or widen pitch_um",
                            k + 1,
                            b[0] - a[3]
                        ),
                    });
                }
            }
            for k in 0..self.grooves.len() {
                let b = self.borders_um(k, y);
                if b[1] - b[0] <= 0.0 || b[3] - b[2] <= 0.0 {
                    return Err(SynthError::Config {
                        key: "still.peak_velocity_mm_s".into(),
                        problem: format!(
                            "a wall of groove {} vanishes at line {line}: the stereo swing is wider \
                             than the wall; lower the velocity or widen top_width_um",
                            k + 1
                        ),
                    });
                }
            }
        }
        Ok(())
    }
}
