//! Seeded randomness for the generator: integer hashing, a SplitMix64 stream, Gaussian samples,
//! 3-D gradient noise, fBm and the marble solid texture fixed to the record material.

/// Golden-ratio increment of SplitMix64.
const SPLITMIX_GAMMA: u64 = 0x9E37_79B9_7F4A_7C15;
/// Lattice multipliers that decorrelate the three axes in [`hash3`].
const HASH_MUL_X: u64 = 0x9E37_79B9_7F4A_7C15;
/// See [`HASH_MUL_X`].
const HASH_MUL_Y: u64 = 0xC2B2_AE3D_27D4_EB4F;
/// See [`HASH_MUL_X`].
const HASH_MUL_Z: u64 = 0x1656_67B1_9E37_79F9;
/// Frequency ratio between fBm octaves (slightly off 2 so octaves do not share lattice lines).
const FBM_LACUNARITY: f64 = 2.03;
/// Octaves of fine detail in [`marble`]: the finest has a lattice of scale/2 (≈ 4 px at 3 µm).
const DETAIL_OCTAVES: u32 = 2;
/// Amplitude ratio between fBm octaves.
const FBM_GAIN: f64 = 0.5;

/// The SplitMix64 output function: a strong 64-bit mixer.
#[must_use]
pub fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Hashes a list of integers with a seed into one well-mixed 64-bit value.
#[must_use]
pub fn hash_seq(seed: u64, parts: &[u64]) -> u64 {
    let mut h = mix64(seed ^ SPLITMIX_GAMMA);
    for &p in parts {
        h = mix64(
            h ^ p
                .wrapping_mul(SPLITMIX_GAMMA)
                .wrapping_add(0x632B_E59B_D9B4_E019),
        );
    }
    h
}

/// Hash of a 3-D integer lattice point.
#[inline]
fn hash3(ix: i64, iy: i64, iz: i64, seed: u64) -> u64 {
    mix64(
        (ix as u64).wrapping_mul(HASH_MUL_X)
            ^ (iy as u64).wrapping_mul(HASH_MUL_Y)
            ^ (iz as u64).wrapping_mul(HASH_MUL_Z)
            ^ seed,
    )
}

/// A small deterministic random stream (SplitMix64).
#[derive(Clone, Debug)]
pub struct Rng {
    state: u64,
}

impl Rng {
    /// A stream started from `seed`.
    #[must_use]
    pub fn new(seed: u64) -> Self {
        Self { state: seed }
    }

    /// Next raw 64-bit value.
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(SPLITMIX_GAMMA);
        mix64(self.state)
    }

    /// Uniform in `[0, 1)`.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in `[lo, hi)`.
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// A fair coin.
    pub fn coin(&mut self) -> bool {
        self.next_u64() >> 63 == 1
    }

    /// Standard normal sample (Box–Muller).
    pub fn gaussian(&mut self) -> f64 {
        let u1 = 1.0 - self.uniform(); // (0, 1]
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }

    /// A Poisson-distributed count with mean `lambda` (Knuth for small means, a rounded normal above).
    pub fn poisson(&mut self, lambda: f64) -> usize {
        if !(lambda.is_finite() && lambda > 0.0) {
            return 0;
        }
        if lambda > 30.0 {
            let v = lambda + lambda.sqrt() * self.gaussian();
            return v.round().max(0.0) as usize;
        }
        let limit = (-lambda).exp();
        let mut k = 0usize;
        let mut p = self.uniform();
        while p > limit {
            k += 1;
            p *= self.uniform();
        }
        k
    }
}

#[inline]
fn fade(t: f64) -> f64 {
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

#[inline]
fn lerp(a: f64, b: f64, t: f64) -> f64 {
    a + (b - a) * t
}

/// Dot product of the corner gradient picked by `h` (12 cube-edge directions) with the offset.
#[inline]
fn grad(h: u64, x: f64, y: f64, z: f64) -> f64 {
    match (h >> 60) & 15 {
        0 | 12 => x + y,
        1 | 13 => -x + y,
        2 => x - y,
        3 => -x - y,
        4 => x + z,
        5 => -x + z,
        6 => x - z,
        7 => -x - z,
        8 => y + z,
        9 | 14 => -y + z,
        10 => y - z,
        _ => -y - z,
    }
}

/// 3-D gradient (Perlin) noise, roughly in `[-1, 1]`, unit lattice spacing.
#[must_use]
pub fn perlin3(x: f64, y: f64, z: f64, seed: u64) -> f64 {
    let (fx, fy, fz) = (x.floor(), y.floor(), z.floor());
    let (ix, iy, iz) = (fx as i64, fy as i64, fz as i64);
    let (rx, ry, rz) = (x - fx, y - fy, z - fz);
    let (u, v, w) = (fade(rx), fade(ry), fade(rz));
    let g = |dx: i64, dy: i64, dz: i64| {
        grad(
            hash3(ix + dx, iy + dy, iz + dz, seed),
            rx - dx as f64,
            ry - dy as f64,
            rz - dz as f64,
        )
    };
    let x00 = lerp(g(0, 0, 0), g(1, 0, 0), u);
    let x10 = lerp(g(0, 1, 0), g(1, 1, 0), u);
    let x01 = lerp(g(0, 0, 1), g(1, 0, 1), u);
    let x11 = lerp(g(0, 1, 1), g(1, 1, 1), u);
    lerp(lerp(x00, x10, v), lerp(x01, x11, v), w)
}

/// Fractal Brownian motion: `octaves` of [`perlin3`], result roughly in `[-1, 1]`.
#[must_use]
pub fn fbm3(p: [f64; 3], octaves: u32, seed: u64) -> f64 {
    let (mut sum, mut amp, mut norm, mut freq) = (0.0, 1.0, 0.0, 1.0);
    for o in 0..octaves {
        let off = f64::from(o) * 17.31;
        sum += amp
            * perlin3(
                p[0] * freq + off,
                p[1] * freq - off,
                p[2] * freq + 0.5 * off,
                seed.wrapping_add(u64::from(o)),
            );
        norm += amp;
        amp *= FBM_GAIN;
        freq *= FBM_LACUNARITY;
    }
    if norm > 0.0 { sum / norm } else { 0.0 }
}

/// A marble-like solid texture in `[0, 1]` at point `p` (µm), with features of about `scale_um`.
///
/// Veins: the sine of a skew coordinate, bent by fBm turbulence; plus fBm detail so every
/// direction carries gradient at the pixel scale.
#[must_use]
pub fn marble(p: [f64; 3], scale_um: f64, seed: u64) -> f32 {
    let inv = 1.0 / scale_um;
    let q = [p[0] * inv, p[1] * inv, p[2] * inv];
    let turb = fbm3([q[0] * 0.5, q[1] * 0.5, q[2] * 0.5], 3, seed ^ 0x5EED_0001);
    let veins =
        (std::f64::consts::TAU * (0.31 * q[0] + 0.23 * q[1] + 0.17 * q[2]) + 4.0 * turb).sin();
    let detail = fbm3(q, DETAIL_OCTAVES, seed ^ 0x5EED_0002);
    let v = 0.5 + 0.22 * veins + 0.55 * detail;
    v.clamp(0.0, 1.0) as f32
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;

    #[test]
    fn rng_is_deterministic_and_roughly_uniform() {
        let mut a = Rng::new(42);
        let mut b = Rng::new(42);
        let xs: Vec<f64> = (0..10_000).map(|_| a.uniform()).collect();
        let ys: Vec<f64> = (0..10_000).map(|_| b.uniform()).collect();
        assert_eq!(xs, ys);
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        assert!((mean - 0.5).abs() < 0.01, "{mean}");
        let mut g = Rng::new(7);
        let n = 20_000;
        let s: Vec<f64> = (0..n).map(|_| g.gaussian()).collect();
        let m = s.iter().sum::<f64>() / n as f64;
        let var = s.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / n as f64;
        assert!(m.abs() < 0.03 && (var - 1.0).abs() < 0.05, "{m} {var}");
        let mut p = Rng::new(9);
        let total: usize = (0..5000).map(|_| p.poisson(2.5)).sum();
        assert!((total as f64 / 5000.0 - 2.5).abs() < 0.1);
    }

    #[test]
    fn perlin_is_zero_on_lattice_and_bounded() {
        assert_eq!(perlin3(3.0, -2.0, 5.0, 1), 0.0);
        let mut lo = f64::MAX;
        let mut hi = f64::MIN;
        for i in 0..2000 {
            let v = perlin3(i as f64 * 0.137, i as f64 * 0.071, i as f64 * 0.029, 3);
            lo = lo.min(v);
            hi = hi.max(v);
        }
        assert!(lo > -1.5 && hi < 1.5 && hi - lo > 0.5, "{lo} {hi}");
    }

    #[test]
    fn marble_varies_at_the_requested_scale() {
        // Neighbouring samples a tenth of the scale apart are close; samples far apart are not.
        let mut near = 0.0;
        let mut far = 0.0;
        for i in 0..500 {
            let x = i as f64 * 3.7;
            let a = marble([x, 1.0, 0.0], 3.0, 5);
            near += (a - marble([x + 0.3, 1.0, 0.0], 3.0, 5)).abs();
            far += (a - marble([x + 30.0, 1.0, 0.0], 3.0, 5)).abs();
        }
        assert!(near * 3.0 < far, "{near} {far}");
    }
}
