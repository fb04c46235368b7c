//! Record damage fixed to the material: scratches across the groove, dust on top, missing wall
//! chunks; laid out per millimetre cell from a seed and looked up through buckets along s.

use super::config::DamageConfig;
use super::noise::{Rng, fbm3, hash_seq};

/// Length of a layout cell along the groove (features of one cell come from one seed).
const CELL_UM: f64 = 1000.0;
/// Bucket length for lookups along s.
const BUCKET_UM: f64 = 32.0;
/// Scratch half-widths (µm) are drawn from this range.
const SCRATCH_WIDTH_UM: (f64, f64) = (0.8, 2.5);
/// Scratch depths (µm) are drawn from this range: "slightly deep".
const SCRATCH_DEPTH_UM: (f64, f64) = (0.3, 1.2);
/// Largest scratch slant from straight across the groove, radians.
const SCRATCH_SLANT_RAD: f64 = 0.3;
/// Dust radii (µm).
const DUST_RADIUS_UM: (f64, f64) = (1.0, 5.0);
/// Dust height as a share of its radius.
const DUST_HEIGHT_RATIO: f64 = 0.5;
/// Width of the smooth edges of a flaked chunk (µm), keeping the surface slope bounded.
const CHUNK_TAPER_UM: f64 = 4.0;
/// How far (in wall depth, µm) a chunk bites into the land beyond the wall's top edge.
const CHUNK_LAND_BITE_UM: f64 = 1.0;
/// Feature size of the flaked surface's roughness.
const FLAKE_SCALE_UM: f64 = 2.0;
/// Bound of the flaked roughness' slope per µm of chunk depth: 0.45·0.5·|∇fBm| (≤ 3 per
/// lattice unit) / scale.
const FLAKE_GRAD_BOUND: f64 = 0.45 * 0.5 * 3.0 / FLAKE_SCALE_UM;
/// Features fade beyond this many widths/radii.
const CUTOFF_WIDTHS: f64 = 4.0;
/// Grey level of bright dust and scratch multiplier of bright scratches.
const BRIGHT_DUST_LEVEL: f32 = 0.9;
/// Grey level of dark dust.
const DARK_DUST_LEVEL: f32 = 0.03;

/// One damage feature in material coordinates.
#[derive(Clone, Debug, PartialEq)]
enum Feature {
    /// A thin groove across the record: s = s0 + y·tan(slant).
    Scratch {
        s0_um: f64,
        tan_slant: f64,
        cos_slant: f64,
        half_width_um: f64,
        depth_um: f64,
        albedo: f32,
    },
    /// A blob lying on the surface.
    Dust {
        s_um: f64,
        y_um: f64,
        radius_um: f64,
        height_um: f64,
        level: f32,
    },
    /// A stretch of wall replaced by a rough, deeper, dark surface (in groove coordinates).
    Chunk {
        s0_um: f64,
        s1_um: f64,
        right_wall: bool,
        bottom_um: f64,
        depth_um: f64,
        seed: u64,
    },
}

/// What the damage does at one surface point.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DamageHit {
    /// Added depth (µm, positive = deeper).
    pub depth_um: f64,
    /// Brightness multiplier of scratches (1 = none).
    pub scratch_mult: f32,
    /// Opacity of dust (0–1) and its grey level.
    pub dust_mask: f32,
    /// Grey level of the dust.
    pub dust_level: f32,
    /// Share of flaked surface (0–1).
    pub flake_mask: f32,
}

/// Every feature near the scanned stretch, bucketed along s.
#[derive(Clone, Debug, Default)]
pub struct Damage {
    features: Vec<Feature>,
    origin_um: f64,
    bucket_start: Vec<u32>,
    bucket_items: Vec<u32>,
    max_slope: f64,
}

fn smoothstep(e0: f64, e1: f64, x: f64) -> f64 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Largest value of |d/dx (x·e^{−x²}) ... |: the peak slope of a unit Gaussian bump of unit width.
const GAUSS_SLOPE: f64 = 0.858;

impl Damage {
    /// Lays out damage over groove positions `[s_lo_um, s_hi_um]` and across `|y| <= y_span_um`.
    /// `groove_depth_um` and `tan_wall` size the chunks.
    #[must_use]
    pub fn new(
        cfg: &DamageConfig,
        s_lo_um: f64,
        s_hi_um: f64,
        y_span_um: f64,
        groove_depth_um: f64,
        tan_wall: f64,
    ) -> Self {
        let mut features = Vec::new();
        let c_lo = (s_lo_um / CELL_UM).floor() as i64;
        let c_hi = (s_hi_um / CELL_UM).floor() as i64;
        let seed = u64::from(cfg.seed);
        for c in c_lo..=c_hi {
            let cell0 = c as f64 * CELL_UM;
            let mut rng = Rng::new(hash_seq(seed, &[c as u64, 1]));
            for _ in 0..rng.poisson(cfg.scratches_per_mm * CELL_UM / 1000.0) {
                let slant = rng.range(-SCRATCH_SLANT_RAD, SCRATCH_SLANT_RAD);
                features.push(Feature::Scratch {
                    s0_um: cell0 + rng.range(0.0, CELL_UM),
                    tan_slant: slant.tan(),
                    cos_slant: slant.cos(),
                    half_width_um: rng.range(SCRATCH_WIDTH_UM.0, SCRATCH_WIDTH_UM.1),
                    depth_um: rng.range(SCRATCH_DEPTH_UM.0, SCRATCH_DEPTH_UM.1),
                    albedo: if rng.coin() { 1.8 } else { 0.3 },
                });
            }
            let mut rng = Rng::new(hash_seq(seed, &[c as u64, 2]));
            let area_mm2 = CELL_UM * 2.0 * y_span_um * 1e-6;
            for _ in 0..rng.poisson(cfg.dust_per_mm2 * area_mm2) {
                let r = rng.range(DUST_RADIUS_UM.0, DUST_RADIUS_UM.1);
                features.push(Feature::Dust {
                    s_um: cell0 + rng.range(0.0, CELL_UM),
                    y_um: rng.range(-y_span_um, y_span_um),
                    radius_um: r,
                    height_um: DUST_HEIGHT_RATIO * r,
                    level: if rng.coin() {
                        BRIGHT_DUST_LEVEL
                    } else {
                        DARK_DUST_LEVEL
                    },
                });
            }
            let mut rng = Rng::new(hash_seq(seed, &[c as u64, 3]));
            for _ in 0..rng.poisson(cfg.missing_wall_chunks_per_mm * CELL_UM / 1000.0) {
                let s0 = cell0 + rng.range(0.0, CELL_UM);
                let len = cfg.chunk_length_um * rng.range(0.7, 1.3);
                let frac = (cfg.chunk_wall_fraction * rng.range(0.8, 1.1)).min(1.0);
                features.push(Feature::Chunk {
                    s0_um: s0,
                    s1_um: s0 + len,
                    right_wall: rng.coin(),
                    bottom_um: frac * groove_depth_um,
                    depth_um: cfg.chunk_depth_um * rng.range(0.7, 1.3),
                    seed: rng.next_u64(),
                });
            }
        }
        for (i, ch) in cfg.chunks.iter().enumerate() {
            features.push(Feature::Chunk {
                s0_um: ch.start_um,
                s1_um: ch.start_um + ch.length_um,
                right_wall: ch.right_wall,
                bottom_um: ch.wall_fraction * groove_depth_um,
                depth_um: ch.depth_um,
                seed: hash_seq(seed, &[i as u64, 4]),
            });
        }
        let mut max_slope: f64 = 0.0;
        for f in &features {
            let slope = match f {
                Feature::Scratch {
                    half_width_um,
                    depth_um,
                    ..
                } => GAUSS_SLOPE * depth_um / half_width_um,
                Feature::Dust {
                    radius_um,
                    height_um,
                    ..
                } => GAUSS_SLOPE * height_um / radius_um,
                Feature::Chunk { depth_um, .. } => {
                    depth_um * (1.5 / CHUNK_TAPER_UM * tan_wall.max(1.0) + FLAKE_GRAD_BOUND)
                }
            };
            max_slope = max_slope.max(slope);
        }
        let mut out = Self {
            features,
            origin_um: s_lo_um - 2.0 * BUCKET_UM,
            bucket_start: Vec::new(),
            bucket_items: Vec::new(),
            max_slope,
        };
        out.build_buckets(s_lo_um, s_hi_um, y_span_um);
        out
    }

    fn extent(f: &Feature, y_span_um: f64) -> (f64, f64) {
        match f {
            Feature::Scratch {
                s0_um,
                tan_slant,
                half_width_um,
                cos_slant,
                ..
            } => {
                let reach = y_span_um * tan_slant.abs() + CUTOFF_WIDTHS * half_width_um / cos_slant;
                (s0_um - reach, s0_um + reach)
            }
            Feature::Dust {
                s_um, radius_um, ..
            } => (
                s_um - CUTOFF_WIDTHS * radius_um,
                s_um + CUTOFF_WIDTHS * radius_um,
            ),
            Feature::Chunk { s0_um, s1_um, .. } => (*s0_um, *s1_um),
        }
    }

    fn build_buckets(&mut self, s_lo_um: f64, s_hi_um: f64, y_span_um: f64) {
        let n = (((s_hi_um - self.origin_um) / BUCKET_UM).ceil() as usize + 3).max(1);
        let mut lists: Vec<Vec<u32>> = vec![Vec::new(); n];
        for (i, f) in self.features.iter().enumerate() {
            let (a, b) = Self::extent(f, y_span_um);
            if b < s_lo_um - BUCKET_UM || a > s_hi_um + BUCKET_UM {
                continue;
            }
            let ba = (((a - self.origin_um) / BUCKET_UM).floor().max(0.0)) as usize;
            let bb = (((b - self.origin_um) / BUCKET_UM).floor().max(0.0)) as usize;
            for list in lists.iter_mut().take(bb.min(n - 1) + 1).skip(ba) {
                list.push(i as u32);
            }
        }
        self.bucket_start = Vec::with_capacity(n + 1);
        self.bucket_items.clear();
        for list in &lists {
            self.bucket_start.push(self.bucket_items.len() as u32);
            self.bucket_items.extend_from_slice(list);
        }
        self.bucket_start.push(self.bucket_items.len() as u32);
    }

    /// Number of features laid out.
    #[must_use]
    pub fn len(&self) -> usize {
        self.features.len()
    }

    /// True without any feature.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.features.is_empty()
    }

    /// Upper bound of the surface slope the damage adds (for the ray-tracer's convergence check).
    #[must_use]
    pub fn max_slope(&self) -> f64 {
        self.max_slope
    }

    /// The damage at material point `(s, y)`; `u` is the position across the groove relative to
    /// its centre line, `wall_depth_um` the undamaged groove depth there (negative beyond the
    /// land edge) and `bottom_half_um` the half-width of the flat bottom in `u`.
    /// With `shade` false only `depth_um` is filled in.
    #[inline]
    #[must_use]
    pub fn at(
        &self,
        s: f64,
        y: f64,
        u: f64,
        wall_depth_um: f64,
        bottom_half_um: f64,
        shade: bool,
    ) -> DamageHit {
        let mut hit = DamageHit {
            scratch_mult: 1.0,
            ..DamageHit::default()
        };
        if self.features.is_empty() {
            return hit;
        }
        let b = (s - self.origin_um) / BUCKET_UM;
        if b.is_nan() || b < 0.0 {
            return hit;
        }
        let b = b as usize;
        let (Some(&lo), Some(&hi)) = (self.bucket_start.get(b), self.bucket_start.get(b + 1))
        else {
            return hit;
        };
        let Some(items) = self.bucket_items.get(lo as usize..hi as usize) else {
            return hit;
        };
        for &i in items {
            let Some(f) = self.features.get(i as usize) else {
                continue;
            };
            match *f {
                Feature::Scratch {
                    s0_um,
                    tan_slant,
                    cos_slant,
                    half_width_um,
                    depth_um,
                    albedo,
                } => {
                    let dist = (s - s0_um - y * tan_slant) * cos_slant / half_width_um;
                    if dist.abs() < CUTOFF_WIDTHS {
                        let g = (-dist * dist).exp();
                        hit.depth_um += depth_um * g;
                        if shade {
                            hit.scratch_mult *= 1.0 + (albedo - 1.0) * g as f32;
                        }
                    }
                }
                Feature::Dust {
                    s_um,
                    y_um,
                    radius_um,
                    height_um,
                    level,
                } => {
                    let (ds, dy) = ((s - s_um) / radius_um, (y - y_um) / radius_um);
                    let rho2 = ds * ds + dy * dy;
                    if rho2 < CUTOFF_WIDTHS * CUTOFF_WIDTHS {
                        let g = (-rho2).exp();
                        hit.depth_um -= height_um * g;
                        if shade {
                            let m = smoothstep(0.1, 0.6, g) as f32;
                            if m > hit.dust_mask {
                                hit.dust_mask = m;
                                hit.dust_level = level;
                            }
                        }
                    }
                }
                Feature::Chunk {
                    s0_um,
                    s1_um,
                    right_wall,
                    bottom_um,
                    depth_um,
                    seed,
                } => {
                    if (u > 0.0) != right_wall
                        || u.abs() <= bottom_half_um
                        || s < s0_um
                        || s > s1_um
                    {
                        continue;
                    }
                    let e_s = smoothstep(s0_um, s0_um + CHUNK_TAPER_UM, s)
                        * (1.0 - smoothstep(s1_um - CHUNK_TAPER_UM, s1_um, s));
                    let e_w = smoothstep(
                        -CHUNK_LAND_BITE_UM - CHUNK_TAPER_UM,
                        -CHUNK_LAND_BITE_UM,
                        wall_depth_um,
                    ) * (1.0
                        - smoothstep(bottom_um - CHUNK_TAPER_UM, bottom_um, wall_depth_um));
                    let env = e_s * e_w;
                    if env > 0.0 {
                        let p = [
                            s / FLAKE_SCALE_UM,
                            y / FLAKE_SCALE_UM,
                            wall_depth_um / FLAKE_SCALE_UM,
                        ];
                        let rough = 0.5 + 0.5 * fbm3(p, 2, seed);
                        hit.depth_um += depth_um * env * (0.55 + 0.45 * rough);
                        hit.flake_mask = hit.flake_mask.max(env as f32);
                    }
                }
            }
        }
        hit
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;
    use crate::synth::config::WallChunk;

    #[test]
    fn layout_is_seeded_and_independent_of_the_stretch() {
        let cfg = DamageConfig {
            scratches_per_mm: 3.0,
            dust_per_mm2: 50.0,
            missing_wall_chunks_per_mm: 1.0,
            ..DamageConfig::default()
        };
        let a = Damage::new(&cfg, 0.0, 5000.0, 200.0, 70.0, 1.0);
        let b = Damage::new(&cfg, 0.0, 5000.0, 200.0, 70.0, 1.0);
        assert_eq!(a.features, b.features);
        assert!(a.len() > 20, "{}", a.len());
        // A longer stretch holds the same features in the shared cells.
        let c = Damage::new(&cfg, 0.0, 9000.0, 200.0, 70.0, 1.0);
        assert_eq!(c.features[..3], a.features[..3]);
        let other = Damage::new(
            &DamageConfig {
                seed: 2,
                ..cfg.clone()
            },
            0.0,
            5000.0,
            200.0,
            70.0,
            1.0,
        );
        assert_ne!(other.features, a.features);
        assert!(
            a.max_slope() > 0.0 && a.max_slope() < 8.0,
            "{}",
            a.max_slope()
        );
    }

    #[test]
    fn a_chunk_deepens_only_its_wall_and_stretch() {
        let cfg = DamageConfig {
            chunks: vec![WallChunk {
                start_um: 100.0,
                length_um: 50.0,
                right_wall: true,
                wall_fraction: 0.5,
                depth_um: 6.0,
            }],
            ..DamageConfig::default()
        };
        let d = Damage::new(&cfg, 0.0, 500.0, 200.0, 70.0, 1.0);
        // Right wall, 15 µm below the land, mid-chunk: deeper and flaked.
        let hit = d.at(125.0, 60.0, 60.0, 15.0, 10.0, true);
        assert!(hit.depth_um > 2.0 && hit.flake_mask > 0.99, "{hit:?}");
        // Same depth on the left wall, below the chunk's fraction, or outside the stretch: intact.
        assert_eq!(d.at(125.0, -60.0, -60.0, 15.0, 10.0, true).depth_um, 0.0);
        assert_eq!(d.at(125.0, 40.0, 40.0, 50.0, 10.0, true).depth_um, 0.0);
        assert_eq!(d.at(160.0, 60.0, 60.0, 15.0, 10.0, true).depth_um, 0.0);
    }
}
