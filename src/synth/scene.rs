//! Depth-validation scenes (paper §5.2): a marble-textured cube, cylinder or sphere in front of a
//! textured plane, filmed by a translating pinhole camera; frames plus the true depth per frame.
//!
//! Files in the output folder: `f000.png …` (16-bit grey), `depth_000.f32 …` (true Z of every
//! pixel, see [`load_true_depth`]) and `scene.toml` ([`SceneMeta`]). The scene moves by
//! `(−frame_step_um, 0, 0)` per frame relative to the camera, so, exactly as in a scan, image
//! content moves toward −x by `u = −focal_px·frame_step_um/Z` px per frame and
//! `crate::pipeline::depth::depth_from_flow_um` applies with [`SceneMeta::geometry`].
//! Lengths are in µm (any unit works; only ratios matter).

use std::io::Write;
use std::path::Path;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::config::Table;
use super::noise::{Rng, hash_seq, marble};
use super::{SynthError, fill_out_dir};
use crate::image::Image;
use crate::io::frames::save_grey_png;
use crate::io::{Geometry, LoadError, write_atomic, write_atomic_with};

/// First bytes of a true-depth file.
pub const DEPTH_MAGIC: &[u8; 8] = b"GSDEPTH1";
/// Tilt of the cube about the vertical axis, degrees (three faces show).
const CUBE_YAW_DEG: f64 = 35.0;
/// Tilt of the cube and the cylinder about the horizontal axis, degrees.
const PITCH_DEG: f64 = 25.0;
/// Light direction (toward the light), not normalised.
const LIGHT_DIR: [f64; 3] = [-0.4, -0.5, -1.0];
/// Share of the brightness that does not depend on the surface normal.
const AMBIENT: f64 = 0.35;

/// The object in front of the plane.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SceneKind {
    /// A cube turned to show three faces.
    Cube,
    /// A cylinder with its axis across the image rows, tilted to show its top cap.
    Cylinder,
    /// A sphere.
    Sphere,
}

/// Settings of a depth-validation scene.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SceneConfig {
    /// Frame width.
    pub width_px: usize,
    /// Frame height.
    pub height_px: usize,
    /// Focal length in pixels.
    pub focal_px: f64,
    /// Scene travel toward −X per frame.
    pub frame_step_um: f64,
    /// Frames rendered.
    pub frames: usize,
    /// Distance of the background plane.
    pub plane_distance_um: f64,
    /// Distance of the object's centre.
    pub object_distance_um: f64,
    /// Cube side, cylinder diameter and height, sphere diameter.
    pub object_size_um: f64,
    /// Marble feature size.
    pub texture_scale_um: f64,
    /// Texture modulation depth (0–1).
    pub texture_contrast: f64,
    /// Gaussian noise σ in 8-bit grey levels.
    pub noise_sigma_8bit: f64,
    /// Texture and noise seed.
    pub seed: u32,
}

impl Default for SceneConfig {
    fn default() -> Self {
        Self {
            width_px: 256,
            height_px: 256,
            focal_px: 400.0,
            frame_step_um: 1.0,
            frames: 36,
            plane_distance_um: 400.0,
            object_distance_um: 300.0,
            object_size_um: 90.0,
            texture_scale_um: 3.0,
            texture_contrast: 0.8,
            noise_sigma_8bit: 0.0,
            seed: 1,
        }
    }
}

/// `scene.toml`: what was rendered and the camera geometry for the depth stage.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneMeta {
    /// The object.
    pub kind: SceneKind,
    /// Frames written.
    pub frames: usize,
    /// Focal length in pixels.
    pub focal_px: f64,
    /// Scene travel per frame (the U of u = −f·U/Z).
    pub frame_step_um: f64,
    /// Pixel size on the background plane (= plane distance / focal length).
    pub pixel_pitch_um: f64,
    /// Background plane distance (plays the land's part).
    pub working_distance_um: f64,
    /// The settings.
    pub config: SceneConfig,
}

impl SceneMeta {
    /// Camera geometry for the depth stage.
    #[must_use]
    pub fn geometry(&self) -> Geometry {
        Geometry {
            focal_px: self.focal_px,
            pixel_pitch_um: self.pixel_pitch_um,
            working_distance_um: self.working_distance_um,
            frame_step_um: self.frame_step_um,
        }
    }

    /// Reads `scene.toml`.
    ///
    /// # Errors
    /// [`SynthError::Load`] naming the file.
    pub fn load(path: &Path) -> Result<Self, SynthError> {
        let text = std::fs::read_to_string(path).map_err(|e| LoadError::Io {
            problem: format!("cannot read scene metadata: {e}"),
            path: path.to_path_buf(),
        })?;
        toml::from_str(&text).map_err(|e| {
            SynthError::Load(LoadError::Metadata {
                problem: crate::toml_error::located(&text, &e),
                path: path.to_path_buf(),
            })
        })
    }
}

/// The `[scene]` table's checks.
const SCENE: Table = Table("scene");

impl SceneConfig {
    /// Camera geometry for the depth stage: the background plane plays the land's part, so the
    /// pixel pitch is its distance over the focal length.
    #[must_use]
    pub fn geometry(&self) -> Geometry {
        Geometry {
            focal_px: self.focal_px,
            pixel_pitch_um: self.plane_distance_um / self.focal_px,
            working_distance_um: self.plane_distance_um,
            frame_step_um: self.frame_step_um,
        }
    }

    /// Checks the settings.
    ///
    /// # Errors
    /// [`SynthError::Config`] naming the key (`scene.<key>`).
    pub fn validate(&self) -> Result<(), SynthError> {
        for (key, v) in [("width_px", self.width_px), ("height_px", self.height_px)] {
            if !(8..=8192).contains(&v) {
                return Err(SCENE.bad(key, format!("must lie in [8, 8192], got {v}")));
            }
        }
        if !(2..=1000).contains(&self.frames) {
            return Err(SCENE.bad(
                "frames",
                format!("must lie in [2, 1000], got {}", self.frames),
            ));
        }
        for (key, v) in [
            ("focal_px", self.focal_px),
            ("frame_step_um", self.frame_step_um),
            ("plane_distance_um", self.plane_distance_um),
            ("object_distance_um", self.object_distance_um),
            ("object_size_um", self.object_size_um),
            ("texture_scale_um", self.texture_scale_um),
        ] {
            SCENE.positive(key, v)?;
        }
        SCENE.within("texture_contrast", self.texture_contrast, 0.0, 1.0)?;
        SCENE.within("noise_sigma_8bit", self.noise_sigma_8bit, 0.0, 255.0)?;
        // The object's bounding sphere must lie between the camera and the plane.
        let reach = self.object_size_um * 0.9;
        if self.object_distance_um + reach >= self.plane_distance_um
            || self.object_distance_um - reach <= 0.0
        {
            return Err(SCENE.bad(
                "object_distance_um",
                format!(
                    "the object (centre {} µm, reach {reach:.1} µm) must lie between the camera and the plane at {} µm",
                    self.object_distance_um, self.plane_distance_um
                ),
            ));
        }
        Ok(())
    }
}

type V3 = [f64; 3];

fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn normalise(a: V3) -> V3 {
    let n = dot(a, a).sqrt();
    [a[0] / n, a[1] / n, a[2] / n]
}

/// Rotation (rows = local axes in world coordinates) from yaw about Y then pitch about X.
fn rotation(yaw_deg: f64, pitch_deg: f64) -> [V3; 3] {
    let (sy, cy) = yaw_deg.to_radians().sin_cos();
    let (sp, cp) = pitch_deg.to_radians().sin_cos();
    // world = Rx(pitch)·Ry(yaw)·local; rows of the inverse (transpose) map world to local.
    let r = [
        [cy, 0.0, sy],
        [sp * sy, cp, -sp * cy],
        [-cp * sy, sp, cp * cy],
    ];
    // Columns of r are the local axes in world coordinates; return them as rows.
    [
        [r[0][0], r[1][0], r[2][0]],
        [r[0][1], r[1][1], r[2][1]],
        [r[0][2], r[1][2], r[2][2]],
    ]
}

struct Object {
    kind: SceneKind,
    centre: V3,
    half: f64,
    axes: [V3; 3],
}

impl Object {
    fn to_local(&self, v: V3) -> V3 {
        [
            dot(self.axes[0], v),
            dot(self.axes[1], v),
            dot(self.axes[2], v),
        ]
    }

    fn to_world(&self, v: V3) -> V3 {
        let a = &self.axes;
        [
            a[0][0] * v[0] + a[1][0] * v[1] + a[2][0] * v[2],
            a[0][1] * v[0] + a[1][1] * v[1] + a[2][1] * v[2],
            a[0][2] * v[0] + a[1][2] * v[1] + a[2][2] * v[2],
        ]
    }

    /// Nearest hit (ray parameter, world normal) of the ray o + t·d.
    fn hit(&self, o: V3, d: V3) -> Option<(f64, V3)> {
        let rel = [
            o[0] - self.centre[0],
            o[1] - self.centre[1],
            o[2] - self.centre[2],
        ];
        let (lo, ld) = (self.to_local(rel), self.to_local(d));
        let (t, n) = match self.kind {
            SceneKind::Sphere => {
                let r = self.half;
                let b = dot(lo, ld);
                let c = dot(lo, lo) - r * r;
                let a = dot(ld, ld);
                let disc = b * b - a * c;
                if disc < 0.0 {
                    return None;
                }
                let t = (-b - disc.sqrt()) / a;
                let p = [lo[0] + t * ld[0], lo[1] + t * ld[1], lo[2] + t * ld[2]];
                (t, p)
            }
            SceneKind::Cube => slab_hit(lo, ld, [self.half; 3])?,
            SceneKind::Cylinder => cylinder_hit(lo, ld, self.half, self.half)?,
        };
        (t > 0.0).then(|| (t, normalise(self.to_world(n))))
    }
}

/// Ray against the box |p_i| ≤ h_i: entry parameter and local normal.
fn slab_hit(o: V3, d: V3, h: V3) -> Option<(f64, V3)> {
    let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
    let mut axis = 0;
    let mut sign = 1.0;
    for i in 0..3 {
        if d[i].abs() < 1e-15 {
            if o[i].abs() > h[i] {
                return None;
            }
            continue;
        }
        let (a, b) = ((-h[i] - o[i]) / d[i], (h[i] - o[i]) / d[i]);
        let (near, far) = if a < b { (a, b) } else { (b, a) };
        if near > t0 {
            t0 = near;
            axis = i;
            sign = -d[i].signum();
        }
        t1 = t1.min(far);
    }
    if t0 > t1 {
        return None;
    }
    let mut n = [0.0; 3];
    n[axis] = sign;
    Some((t0, n))
}

/// Ray against a capped cylinder of radius `r` and half-height `h` along local y.
fn cylinder_hit(o: V3, d: V3, r: f64, h: f64) -> Option<(f64, V3)> {
    let mut best: Option<(f64, V3)> = None;
    let a = d[0] * d[0] + d[2] * d[2];
    if a > 1e-15 {
        let b = o[0] * d[0] + o[2] * d[2];
        let c = o[0] * o[0] + o[2] * o[2] - r * r;
        let disc = b * b - a * c;
        if disc >= 0.0 {
            let t = (-b - disc.sqrt()) / a;
            let y = o[1] + t * d[1];
            if y.abs() <= h {
                best = Some((t, [o[0] + t * d[0], 0.0, o[2] + t * d[2]]));
            }
        }
    }
    if d[1].abs() > 1e-15 {
        for cap in [-h, h] {
            let t = (cap - o[1]) / d[1];
            let (x, z) = (o[0] + t * d[0], o[2] + t * d[2]);
            if x * x + z * z <= r * r && best.is_none_or(|(bt, _)| t < bt) {
                best = Some((t, [0.0, cap.signum(), 0.0]));
            }
        }
    }
    best
}

fn make_object(kind: SceneKind, cfg: &SceneConfig) -> Object {
    let (yaw, pitch) = match kind {
        SceneKind::Cube => (CUBE_YAW_DEG, PITCH_DEG),
        SceneKind::Cylinder => (0.0, PITCH_DEG),
        SceneKind::Sphere => (0.0, 0.0),
    };
    Object {
        kind,
        centre: [
            0.5 * (cfg.frames as f64 - 1.0) * cfg.frame_step_um,
            0.0,
            cfg.object_distance_um,
        ],
        half: 0.5 * cfg.object_size_um,
        axes: rotation(yaw, pitch),
    }
}

/// Renders frame `frame` of a scene: the grey image (quantised to 16 bits) and the true Z map.
///
/// # Errors
/// [`SynthError::Config`] for invalid settings.
pub fn render_scene_frame(
    kind: SceneKind,
    cfg: &SceneConfig,
    frame: usize,
) -> Result<(Image, Image), SynthError> {
    cfg.validate()?;
    let obj = make_object(kind, cfg);
    let (w, h) = (cfg.width_px, cfg.height_px);
    let (cx, cy) = (0.5 * (w as f64 - 1.0), 0.5 * (h as f64 - 1.0));
    let cam = [frame as f64 * cfg.frame_step_um, 0.0, 0.0];
    let light = normalise(LIGHT_DIR);
    let mut img = Image::zeros(w, h);
    let mut depth = Image::zeros(w, h);
    let seed = u64::from(cfg.seed);
    let sigma = (cfg.noise_sigma_8bit / 255.0) as f32;
    img.data
        .par_chunks_mut(w)
        .zip(depth.data.par_chunks_mut(w))
        .enumerate()
        .for_each(|(row, (out, zout))| {
            let mut rng = Rng::new(hash_seq(seed ^ 0x5CE4E, &[frame as u64, row as u64]));
            for (x, (o, zo)) in out.iter_mut().zip(zout.iter_mut()).enumerate() {
                let d = [
                    (x as f64 - cx) / cfg.focal_px,
                    (row as f64 - cy) / cfg.focal_px,
                    1.0,
                ];
                let plane_t = cfg.plane_distance_um;
                let (t, n) = match obj.hit(cam, d) {
                    Some((t, n)) if t < plane_t => (t, n),
                    _ => (plane_t, [0.0, 0.0, -1.0]),
                };
                let p = [cam[0] + t * d[0], cam[1] + t * d[1], cam[2] + t * d[2]];
                let tex = marble(p, cfg.texture_scale_um, seed);
                let lambert = dot(n, light).max(0.0);
                let albedo = 0.5 + cfg.texture_contrast * (f64::from(tex) - 0.5);
                let shade = albedo * (AMBIENT + (1.0 - AMBIENT) * lambert);
                let noisy = shade as f32 + sigma * rng.gaussian() as f32;
                *o = (noisy.clamp(0.0, 1.0) * 65_535.0).round() / 65_535.0;
                *zo = t as f32;
            }
        });
    Ok((img, depth))
}

/// Writes a true-depth map: [`DEPTH_MAGIC`], width and height as little-endian u32, then
/// width·height little-endian f32 values (Z, row-major).
///
/// # Errors
/// [`SynthError::Load`] naming the file.
pub fn save_true_depth(depth: &Image, path: &Path) -> Result<(), SynthError> {
    write_atomic_with(path, false, |w| {
        w.write_all(DEPTH_MAGIC)?;
        w.write_all(&(depth.width as u32).to_le_bytes())?;
        w.write_all(&(depth.height as u32).to_le_bytes())?;
        for v in &depth.data {
            w.write_all(&v.to_le_bytes())?;
        }
        Ok(())
    })?;
    Ok(())
}

/// Reads a true-depth map written by [`render_scene`] (format in [`save_true_depth`]).
///
/// # Errors
/// [`SynthError::Load`] naming the file when it is missing, not a depth file, or truncated.
pub fn load_true_depth(path: &Path) -> Result<Image, SynthError> {
    let err = |problem: String| {
        SynthError::Load(LoadError::BadFrame {
            problem,
            path: path.to_path_buf(),
        })
    };
    let bytes = std::fs::read(path).map_err(|e| err(format!("cannot read depth file: {e}")))?;
    let Some(head) = bytes.get(..16) else {
        return Err(err("too short for a depth file".into()));
    };
    if &head[..8] != DEPTH_MAGIC {
        return Err(err("not a depth file (bad magic)".into()));
    }
    let w = u32::from_le_bytes([head[8], head[9], head[10], head[11]]) as usize;
    let h = u32::from_le_bytes([head[12], head[13], head[14], head[15]]) as usize;
    let body = &bytes[16..];
    if body.len() != w * h * 4 {
        return Err(err(format!(
            "holds {} bytes of samples, {w}x{h} needs {}",
            body.len(),
            w * h * 4
        )));
    }
    let data = body
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    Image::from_vec(w, h, data).ok_or_else(|| err("size does not match its data".into()))
}

/// Renders a scene into `out_dir` (created, or empty): frames, true depths and `scene.toml`.
/// Cancelling `job` stops before the next frame; the folder is written as `fill_out_dir` writes
/// one, so a run that fails, is cancelled or is killed leaves no half folder there.
///
/// # Errors
/// [`SynthError::Config`] for invalid settings, [`SynthError::OutputExists`] for a non-empty
/// folder, [`SynthError::Load`] for write failures, [`SynthError::Cancelled`].
pub fn render_scene(
    kind: SceneKind,
    cfg: &SceneConfig,
    out_dir: &Path,
    job: crate::job::Job<'_>,
) -> Result<SceneMeta, SynthError> {
    cfg.validate()?;
    let geom = cfg.geometry();
    let meta = SceneMeta {
        kind,
        frames: cfg.frames,
        focal_px: geom.focal_px,
        frame_step_um: geom.frame_step_um,
        pixel_pitch_um: geom.pixel_pitch_um,
        working_distance_um: geom.working_distance_um,
        config: cfg.clone(),
    };
    let text = toml::to_string_pretty(&meta).map_err(|e| SynthError::Config {
        key: "scene".into(),
        problem: format!("cannot be written as TOML: {e}"),
    })?;
    let fw = super::digits(cfg.frames, 3);
    fill_out_dir(out_dir, |dir| {
        (0..cfg.frames)
            .into_par_iter()
            .try_for_each(|k| -> Result<(), SynthError> {
                if job.is_cancelled() {
                    return Err(SynthError::Cancelled);
                }
                let (img, depth) = render_scene_frame(kind, cfg, k)?;
                save_grey_png(&img, &dir.join(format!("f{k:0fw$}.png")), true, false)?;
                save_true_depth(&depth, &dir.join(format!("depth_{k:0fw$}.f32")))?;
                job.report(k + 1, cfg.frames);
                Ok(())
            })?;
        write_atomic(&dir.join("scene.toml"), text.as_bytes(), false)?;
        Ok(meta)
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;

    fn small() -> SceneConfig {
        SceneConfig {
            width_px: 96,
            height_px: 96,
            focal_px: 150.0,
            frames: 8,
            plane_distance_um: 150.0,
            object_distance_um: 110.0,
            object_size_um: 30.0,
            ..SceneConfig::default()
        }
    }

    #[test]
    fn depth_maps_hold_the_true_geometry() {
        let cfg = small();
        // Sphere: the plane at 150 µm, the nearest point at 110 − 15 = 95 µm.
        let (_, z) = render_scene_frame(SceneKind::Sphere, &cfg, 3).unwrap();
        let (lo, hi) = z.finite_range().unwrap();
        assert!((hi - 150.0).abs() < 1e-4, "{hi}");
        assert!((lo - 95.0).abs() < 0.2, "{lo}");
        // Cube and cylinder: the front is nearer than the centre, the back hidden by the front.
        for kind in [SceneKind::Cube, SceneKind::Cylinder] {
            let (_, z) = render_scene_frame(kind, &cfg, 3).unwrap();
            let (lo, _) = z.finite_range().unwrap();
            assert!(lo > 110.0 - 27.0 && lo < 110.0 - 10.0, "{kind:?}: {lo}");
        }
    }

    #[test]
    fn background_moves_by_focal_over_distance() {
        // f·U/Z = 150·1/150 = 1 px per frame, toward −x.
        let cfg = small();
        let (a, _) = render_scene_frame(SceneKind::Sphere, &cfg, 0).unwrap();
        let (b, _) = render_scene_frame(SceneKind::Sphere, &cfg, 1).unwrap();
        // Top-left corner rows are background in both frames.
        for y in 0..10 {
            for x in 0..40 {
                let va = a.get(x + 1, y).unwrap();
                let vb = b.get(x, y).unwrap();
                assert!((va - vb).abs() < 2e-4, "({x},{y}): {va} {vb}");
            }
        }
    }

    #[test]
    fn files_round_trip_and_bad_settings_fail() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("cube");
        let meta = render_scene(
            SceneKind::Cube,
            &small(),
            &out,
            crate::job::Job::unwatched(),
        )
        .unwrap();
        let back = SceneMeta::load(&out.join("scene.toml")).unwrap();
        assert_eq!(meta, back);
        assert!((back.geometry().land_flow_px() + 1.0).abs() < 1e-12);
        let z = load_true_depth(&out.join("depth_005.f32")).unwrap();
        let (_, want) = render_scene_frame(SceneKind::Cube, &small(), 5).unwrap();
        assert_eq!(z, want);
        let f = crate::io::load_frame(&out.join("f007.png")).unwrap();
        assert_eq!(f.width, 96);
        // A second run into the same folder is refused.
        assert!(matches!(
            render_scene(
                SceneKind::Cube,
                &small(),
                &out,
                crate::job::Job::unwatched()
            ),
            Err(SynthError::OutputExists { .. })
        ));
        std::fs::write(dir.path().join("junk.f32"), b"GSDEPTH1\x02\0\0\0").unwrap();
        let e = load_true_depth(&dir.path().join("junk.f32")).unwrap_err();
        assert!(e.to_string().contains("junk.f32"), "{e}");
        let bad = SceneConfig {
            object_distance_um: 149.0,
            ..small()
        };
        assert!(matches!(bad.validate(), Err(SynthError::Config { .. })));
    }
}
