//! The groove's path from the sound: cutter velocities (piecewise linear between samples) and
//! their exact integrals, the lateral displacement d(s) and the vertical offset h(s).

/// One integrated motion component (lateral or vertical) over a window of sound samples.
///
/// Velocity is linear between samples, so the displacement is an exact piecewise quadratic and
/// its derivative is exactly the interpolated velocity.
#[derive(Clone, Debug, Default)]
pub struct Track {
    /// Velocity at each stored sample, µm/s.
    vel_um_s: Vec<f64>,
    /// Displacement at each stored sample, µm (∫ velocity dt from the scan start, plus `offset`).
    cum_um: Vec<f64>,
    /// Sound sample index of the first stored sample.
    first_sample: i64,
    /// Seconds per sample.
    dt_s: f64,
}

/// Displacement and its slope along the groove at one point.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TrackPoint {
    /// Displacement, µm.
    pub value_um: f64,
    /// d(value)/ds (dimensionless) = velocity / Vt.
    pub slope: f64,
    /// Velocity, µm/s.
    pub velocity_um_s: f64,
}

impl Track {
    /// Builds a track from per-sample velocities `vel(n)` (µm/s) for sound samples
    /// `first..=last`; the displacement is zero at sample `zero_sample` (the scan start).
    /// `vel` returns 0 outside the sound.
    pub fn new(
        first: i64,
        last: i64,
        zero_sample: i64,
        rate_hz: f64,
        vel: impl Fn(i64) -> f64,
    ) -> Self {
        let dt_s = 1.0 / rate_hz;
        let n = (last - first + 1).max(2) as usize;
        let vel_um_s: Vec<f64> = (0..n).map(|i| vel(first + i as i64)).collect();
        let mut cum_um = Vec::with_capacity(n);
        let mut acc = 0.0;
        cum_um.push(0.0);
        for w in vel_um_s.windows(2) {
            acc += 0.5 * (w[0] + w[1]) * dt_s;
            cum_um.push(acc);
        }
        let zero_idx = (zero_sample - first).clamp(0, n as i64 - 1) as usize;
        let zero = cum_um.get(zero_idx).copied().unwrap_or(0.0);
        for c in &mut cum_um {
            *c -= zero;
        }
        Self {
            vel_um_s,
            cum_um,
            first_sample: first,
            dt_s,
        }
    }

    /// Adds a constant to the displacement everywhere.
    pub fn shift(&mut self, by_um: f64) {
        for c in &mut self.cum_um {
            *c += by_um;
        }
    }

    /// Smallest and largest displacement at the samples between sound samples `a` and `b`.
    #[must_use]
    pub fn range_between(&self, a: i64, b: i64) -> (f64, f64) {
        let n = self.cum_um.len() as i64;
        let lo = (a - self.first_sample).clamp(0, n - 1) as usize;
        let hi = (b - self.first_sample).clamp(0, n - 1) as usize;
        let slice = self.cum_um.get(lo..=hi).unwrap_or(&[]);
        slice
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
                (l.min(v), h.max(v))
            })
    }

    /// Largest |velocity| stored, µm/s.
    #[must_use]
    pub fn max_abs_velocity_um_s(&self) -> f64 {
        self.vel_um_s.iter().fold(0.0, |m, v| m.max(v.abs()))
    }

    /// Evaluates the track at fractional sound-sample index `q`; constant outside the window.
    #[inline]
    #[must_use]
    pub fn at(&self, q: f64, vt_um_s: f64) -> TrackPoint {
        let rel = q - self.first_sample as f64;
        let last = self.cum_um.len() - 1;
        if rel.is_nan() || rel < 0.0 {
            return TrackPoint {
                value_um: self.cum_um.first().copied().unwrap_or(0.0),
                ..TrackPoint::default()
            };
        }
        let i = rel.floor() as usize;
        if i >= last {
            return TrackPoint {
                value_um: self.cum_um.get(last).copied().unwrap_or(0.0),
                ..TrackPoint::default()
            };
        }
        let tau = rel - i as f64;
        let (v0, v1) = (self.vel_um_s[i], self.vel_um_s[i + 1]);
        let dv = v1 - v0;
        let value_um = self.cum_um[i] + self.dt_s * tau * (v0 + 0.5 * dv * tau);
        let velocity_um_s = v0 + dv * tau;
        TrackPoint {
            value_um,
            slope: velocity_um_s / vt_um_s,
            velocity_um_s,
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;

    #[test]
    fn integral_of_a_sine_velocity_is_a_cosine() {
        let rate = 48_000.0;
        let f = 1000.0;
        let amp = 1.0e4; // µm/s
        let vel = |n: i64| amp * (std::f64::consts::TAU * f * n as f64 / rate).sin();
        let t = Track::new(-10, 10_000, 0, rate, vel);
        let vt = 1e6;
        for k in [0.0, 17.3, 480.5, 2001.25] {
            let p = t.at(k, vt);
            let time = k / rate;
            let want = amp / (std::f64::consts::TAU * f)
                * (1.0 - (std::f64::consts::TAU * f * time).cos());
            // Linear velocity between 48 samples per period: the integral is within 0.3% of peak.
            assert!(
                (p.value_um - want).abs() < 3e-3 * 2.0 * amp / (std::f64::consts::TAU * f),
                "{k}: {p:?} {want}"
            );
            let want_v = amp * (std::f64::consts::TAU * f * time).sin();
            assert!((p.velocity_um_s - want_v).abs() < 0.01 * amp, "{k}");
            assert!((p.slope - p.velocity_um_s / vt).abs() < 1e-15);
        }
        // The slope is the exact derivative of the value.
        let h = 1e-4;
        let d = (t.at(100.3 + h, vt).value_um - t.at(100.3 - h, vt).value_um) / (2.0 * h) * rate;
        assert!((d - t.at(100.3, vt).velocity_um_s).abs() < 1e-3 * amp);
        // Constant outside the window.
        assert_eq!(t.at(-50.0, vt).slope, 0.0);
        assert_eq!(t.at(1e9, vt).value_um, t.at(10_000.0, vt).value_um);
    }
}
