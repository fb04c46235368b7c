//! The error function and the standard normal CDF and density, for the edge-spread border model.

/// 1/√2, for Φ(z) = (1 + erf(z/√2))/2.
const FRAC_1_SQRT_2: f64 = std::f64::consts::FRAC_1_SQRT_2;
/// 1/√(2π), the normal density's peak.
const FRAC_1_SQRT_2PI: f64 = 0.398_942_280_401_432_7;

/// erf(x) by W. J. Cody's rational approximations (relative error below 1e-15 in f64 for
/// |x| < 0.5; below 1e-13 elsewhere through erfc's continued form).
#[must_use]
#[allow(clippy::excessive_precision)] // Cody's published coefficients, kept as printed
pub fn erf(x: f64) -> f64 {
    let a = x.abs();
    if a < 0.5 {
        // erf(x) = x·P(x²)/Q(x²)
        const P: [f64; 5] = [
            3.161_123_743_870_565_6,
            113.864_154_151_050_16,
            377.485_237_685_302_0,
            3_209.377_589_138_469_4,
            0.185_777_706_184_603_15,
        ];
        const Q: [f64; 4] = [
            23.601_290_952_344_122,
            244.024_637_934_444_17,
            1_282.616_526_077_372_3,
            2_844.236_833_439_170_6,
        ];
        let z = x * x;
        let mut num = P[4] * z;
        let mut den = z;
        for i in 0..3 {
            num = (num + P[i]) * z;
            den = (den + Q[i]) * z;
        }
        x * (num + P[3]) / (den + Q[3])
    } else if a >= ERF_IS_ONE {
        // erfc(a) < 2⁻⁵⁴ here, so 1 − erfc(a) rounds to 1 exactly.
        if x < 0.0 { -1.0 } else { 1.0 }
    } else {
        let c = erfc_abs(a);
        if x < 0.0 { c - 1.0 } else { 1.0 - c }
    }
}

/// From here on `1 − erfc(a)` rounds to exactly 1 in f64: erfc(6) ≈ 2.2e-17 lies below half the
/// spacing of the doubles just under 1 (2⁻⁵⁴ ≈ 5.6e-17), so erf needs no exponentials there.
const ERF_IS_ONE: f64 = 6.0;

/// erfc(a) for a ≥ 0.5 (Cody).
#[allow(clippy::excessive_precision)] // Cody's published coefficients, kept as printed
fn erfc_abs(a: f64) -> f64 {
    if a >= 26.5 {
        return 0.0;
    }
    if a <= 4.0 {
        const C: [f64; 9] = [
            0.564_188_496_988_670_1,
            8.883_149_794_388_376,
            66.119_190_637_141_63,
            298.635_138_197_400_1,
            881.952_221_241_769_1,
            1_712.047_612_634_070_7,
            2_051.078_377_826_071_6,
            1_230.339_354_797_997_2,
            2.153_115_354_744_038_3e-8,
        ];
        const D: [f64; 8] = [
            15.744_926_110_709_835,
            117.693_950_891_312_5,
            537.181_101_862_009_9,
            1_621.389_574_566_690_3,
            3_290.799_235_733_459_7,
            4_362.619_090_143_247,
            3_439.367_674_143_721_6,
            1_230.339_354_803_749_4,
        ];
        let mut num = C[8] * a;
        let mut den = a;
        for i in 0..7 {
            num = (num + C[i]) * a;
            den = (den + D[i]) * a;
        }
        let r = (num + C[7]) / (den + D[7]);
        return scaled_exp(a) * r;
    }
    const P: [f64; 6] = [
        0.305_326_634_961_232_36,
        0.360_344_899_949_804_45,
        0.125_781_726_111_229_25,
        0.016_083_785_148_742_275,
        6.587_491_615_298_378e-4,
        0.016_315_387_137_302_097,
    ];
    const Q: [f64; 5] = [
        2.568_520_192_289_822,
        1.872_952_849_923_460_4,
        0.527_905_102_951_428_4,
        0.060_518_341_312_441_32,
        0.002_335_204_976_268_691_8,
    ];
    const FRAC_1_SQRT_PI: f64 = 0.564_189_583_547_756_3;
    let z = 1.0 / (a * a);
    let mut num = P[5] * z;
    let mut den = z;
    for i in 0..4 {
        num = (num + P[i]) * z;
        den = (den + Q[i]) * z;
    }
    let r = z * (num + P[4]) / (den + Q[4]);
    scaled_exp(a) * (FRAC_1_SQRT_PI - r) / a
}

/// exp(−a²), computed as exp(−s²)·exp(−(a − s)(a + s)) with s = a rounded to 1/16 (Cody's
/// trick against the rounding error of a² for large a).
fn scaled_exp(a: f64) -> f64 {
    let s = (a * 16.0).trunc() / 16.0;
    (-s * s).exp() * (-(a - s) * (a + s)).exp()
}

/// The standard normal CDF Φ(z).
#[must_use]
pub fn normal_cdf(z: f64) -> f64 {
    0.5 * (1.0 + erf(z * FRAC_1_SQRT_2))
}

/// The standard normal density φ(z).
#[must_use]
pub fn normal_pdf(z: f64) -> f64 {
    FRAC_1_SQRT_2PI * (-0.5 * z * z).exp()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn erf_is_exactly_one_where_the_shortcut_says() {
        // The shortcut returns what the full formula rounds to, over its whole range.
        let mut a = ERF_IS_ONE;
        while a < 27.0 {
            assert_eq!(1.0 - erfc_abs(a), 1.0, "erf({a})");
            assert_eq!(erfc_abs(a) - 1.0, -1.0, "erf(-{a})");
            assert_eq!(erf(a), 1.0);
            assert_eq!(erf(-a), -1.0);
            a += 1e-3;
        }
        // Just below it the formula still differs from 1.
        assert!(1.0 - erfc_abs(5.5) < 1.0);
    }

    #[test]
    fn erf_matches_known_values() {
        for (x, want) in [
            (0.0, 0.0),
            (0.1, 0.112_462_916_018_284_9),
            (0.5, 0.520_499_877_813_046_5),
            (1.0, 0.842_700_792_949_714_9),
            (2.0, 0.995_322_265_018_952_7),
            (3.5, 0.999_999_256_901_627_7),
            (4.5, 0.999_999_999_803_383_9),
            (5.0, 0.999_999_999_998_462_5),
        ] {
            assert!((erf(x) - want).abs() < 1e-14, "erf({x}) = {}", erf(x));
            assert!((erf(-x) + want).abs() < 1e-14);
        }
        assert!((normal_cdf(1.0) - 0.841_344_746_068_542_9).abs() < 1e-14);
    }
}
