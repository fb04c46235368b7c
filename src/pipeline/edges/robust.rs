//! The four borders combined into the groove's motion, robustly: each border's constant offset,
//! Lorentzian rejection of borders that disagree (flakes, dust, scratches), and gaps marked and
//! bridged.
//!
//! A border's record `y` is `y_β = c_β + d + k_β·e`: `d` the groove's lateral displacement,
//! `e = h/tan α` the vertical offset `h` seen across the groove, `c_β` the border's place in
//! the cross-section (constant), and `k = (−1, 0, 0, +1)` for (left land, left bottom, right
//! bottom, right land) — a deeper groove widens at the land, while the bottom corners move with
//! `d` alone. A lateral cut has `e = 0`. Each sample solves for `d` (and `e`) by weighted least
//! squares over its borders (weights `1/se²`, the standard error floored at
//! `border_floor_um`; with `weight_window_samples` > 1, `se²` is its geometric mean over that
//! many samples around, see below), reweighted by the Lorentzian `1/(1 + r²/(2σ²))` of each border's residual
//! (σ = `border_sigma_um`) from a median start; the constants are the weighted means of
//! `y_β − d − k_β·e`, and the two steps alternate `ROUNDS` times. The constants' common
//! offset is fixed so that the lands (else the bottom corners) are symmetric about `d`, so `d`
//! is the groove's centre line; `e`'s offset (which the tracks cannot tell from the lands'
//! constants) so that its median is zero.
//!
//! Each border's fit reads texture fixed to the record, so its per-sample standard error
//! scatters around the border's true level. Weighting every sample by its own `1/se²` lets the
//! mix of borders jump from sample to sample, and the borders' different texture offsets turn
//! those jumps into broadband noise in `d`; a stretch's geometric mean keeps the mix steady
//! while still following a border that goes bad (flakes, blur) over a stretch.
//!
//! The left wall's displacement is `d − e` and the right wall's `d + e` (each wall's border
//! at the land moves by that). Where a wall's sample has no estimate it is a gap; gaps of at
//! most `max_bridge_samples` with two samples on each side are bridged by a cubic through
//! them and listed.

use std::ops::Range;

use super::plausible::resolve_excursions;
use super::profile::lorentzian_weight;
use crate::meta::Cut;

/// Alternations of the per-sample solve and the constants.
const ROUNDS: usize = 3;
/// Lorentzian reweightings of one sample's solve.
const SAMPLE_ITERATIONS: usize = 4;
/// A border weighing less than this share of its plain weight after the robust solve is
/// reported as rejected there.
pub const REJECTED_WEIGHT: f64 = 0.1;
/// `k_β` of the borders in [`super::BorderId`] order.
const K: [f64; 4] = [-1.0, 0.0, 0.0, 1.0];

/// What [`combine_borders`] needs besides the tracks.
#[derive(Clone, Copy, Debug)]
pub struct CombineParams {
    /// The cut (lateral: `e = 0`).
    pub cut: Cut,
    /// Lorentzian σ of a border's residual (µm).
    pub sigma_um: f64,
    /// Floor of a border's standard error (µm): texture, not pixel noise, limits it.
    pub floor_um: f64,
    /// Longest gap bridged by interpolation (samples).
    pub max_bridge: usize,
    /// Samples over which a border's squared standard error is averaged (geometrically) into
    /// its weight; 0 or 1 weighs each sample by its own.
    pub weight_window: usize,
    /// Most a wall may move between neighbouring samples (µm): the steepest groove slope
    /// times the samples' spacing; 0 = no check ([`super::plausible`]).
    pub max_step_um: f64,
    /// Longest excursion solved again (samples).
    pub max_excursion: usize,
}

impl CombineParams {
    /// The edge knobs' combination settings for a scan of `cut` whose samples lie
    /// `spacing_um` apart along the groove.
    #[must_use]
    pub fn from_edges(cut: Cut, params: &super::EdgeParams, spacing_um: f64) -> Self {
        Self {
            cut,
            sigma_um: params.border_sigma_um,
            floor_um: params.border_floor_um,
            max_bridge: params.max_bridge_samples,
            weight_window: params.weight_window_samples,
            max_step_um: params.max_slope * spacing_um,
            max_excursion: params.max_excursion_samples,
        }
    }
}

/// Each border's weight `1/se²` per sample (None where the border is not seen), `se` floored
/// at `floor` and, with `window` > 1, `se²` the geometric mean of the floored `se²` of the
/// seen samples within `window/2` on each side.
fn border_weights(y: &[f64], se: &[f64], n: usize, floor: f64, window: usize) -> Vec<Option<f64>> {
    let var = |j: usize| -> Option<f64> {
        let (yv, sv) = (*y.get(j)?, *se.get(j)?);
        (yv.is_finite() && sv.is_finite()).then(|| sv.max(floor).powi(2))
    };
    if window <= 1 {
        return (0..n).map(|j| var(j).map(|v| 1.0 / v)).collect();
    }
    let logs: Vec<Option<f64>> = (0..n).map(|j| var(j).map(f64::ln)).collect();
    // Prefix sums of the logs and of the count of seen samples.
    let mut sum = vec![0.0; n + 1];
    let mut count = vec![0usize; n + 1];
    for (j, l) in logs.iter().enumerate() {
        sum[j + 1] = sum[j] + l.unwrap_or(0.0);
        count[j + 1] = count[j] + usize::from(l.is_some());
    }
    let half = window / 2;
    (0..n)
        .map(|j| {
            logs[j]?;
            let (lo, hi) = (j.saturating_sub(half), j.saturating_add(half + 1).min(n));
            let k = count[hi] - count[lo];
            (k > 0).then(|| (-(sum[hi] - sum[lo]) / k as f64).exp())
        })
        .collect()
}

/// The borders of a track combined.
#[derive(Clone, Debug, PartialEq)]
pub struct Combined {
    /// Each border's constant `c_β` (µm; NaN for a border never seen).
    pub constants_um: [f64; 4],
    /// Lateral displacement `d` per sample (µm, NaN = gap).
    pub d_um: Vec<f64>,
    /// `e = h/tan α` per sample (µm; zeros for a lateral cut, NaN = gap).
    pub e_um: Vec<f64>,
    /// Left and right wall displacement, `d ∓ e` (µm, NaN = gap; bridged gaps filled).
    pub walls_um: [Vec<f64>; 2],
    /// Their standard errors (µm; NaN where bridged or missing).
    pub walls_se_um: [Vec<f64>; 2],
    /// Each border's final weight per sample relative to its plain weight (0–1; 0 = not seen).
    pub border_weights: [Vec<f64>; 4],
    /// Per wall: sample ranges without an estimate (after bridging).
    pub gaps: [Vec<Range<usize>>; 2],
    /// Per wall: sample ranges filled by interpolation.
    pub bridged: [Vec<Range<usize>>; 2],
    /// Sample ranges where the track moved faster than a groove can and was solved again
    /// ([`super::plausible`]); a sample still out of reach is a gap.
    pub excursions: Vec<Range<usize>>,
}

/// Every sample's solve: `d`, `e`, their covariance (var_d, var_e, cov) and each border's
/// relative weight.
pub(super) struct Solves {
    /// Lateral displacement (µm, NaN = gap).
    pub d: Vec<f64>,
    /// `e` (µm; 0 for a lateral cut, NaN = gap).
    pub e: Vec<f64>,
    /// (var_d, var_e, cov(d, e)) (µm²).
    pub cov: Vec<[f64; 3]>,
    /// Each border's relative weight (0 where not seen).
    pub rel: Vec<[f64; 4]>,
}

impl Solves {
    /// `n` gaps.
    fn new(n: usize, lateral: bool) -> Self {
        Self {
            d: vec![f64::NAN; n],
            e: vec![if lateral { 0.0 } else { f64::NAN }; n],
            cov: vec![[f64::NAN; 3]; n],
            rel: vec![[0.0; 4]; n],
        }
    }

    /// Stores sample `j`'s solution, or a gap.
    pub(super) fn store(&mut self, j: usize, solution: Option<Solution>, lateral: bool) {
        let (d, e, cov, rel) = solution.unwrap_or((f64::NAN, f64::NAN, [f64::NAN; 3], [0.0; 4]));
        self.d[j] = d;
        self.e[j] = if lateral && d.is_finite() { 0.0 } else { e };
        self.cov[j] = cov;
        self.rel[j] = rel;
    }
}

fn finite_median(mut v: Vec<f64>) -> Option<f64> {
    v.retain(|x| x.is_finite());
    crate::pipeline::median(v)
}

/// One sample's solution: d, e, (var_d, var_e, cov), each border's relative weight.
pub(super) type Solution = (f64, f64, [f64; 3], [f64; 4]);

/// One sample's robust solve: borders `(k, z = y − c, w)`. `lateral` fixes e = 0. The
/// Lorentzian starts from `start` (d, e) where given. Else it starts from the medians of the
/// borders, and where that solve rejects a border it starts again from each border's own
/// reading: the Lorentzian's cost has a minimum for every set of borders that agree, and the
/// median of four (two of them off, say a dust grain on one corner and a flake at a land) can
/// start it at the wrong one. The solution whose cost ([`robust_cost`], which counts each
/// border once, so one border read precisely cannot outvote two that agree) is lower by more
/// than [`SWITCH_COST`] wins, so borders that agree keep their solve to the bit.
fn solve_sample(
    obs: &[(usize, f64, f64)],
    lateral: bool,
    sigma: f64,
    start: Option<(f64, f64)>,
) -> Option<Solution> {
    if let Some(de) = start {
        return iterate_sample(obs, lateral, sigma, de);
    }
    let first = iterate_sample(obs, lateral, sigma, median_start(obs, lateral)?)?;
    if obs.iter().all(|o| first.3[o.0] >= REJECTED_WEIGHT) {
        return Some(first);
    }
    let e0 = if lateral || !first.1.is_finite() {
        0.0
    } else {
        first.1
    };
    let mut best_cost = robust_cost(obs, sigma, &first);
    let mut best = first;
    for &(b, z, _) in obs {
        let Some(alt) = iterate_sample(obs, lateral, sigma, (z - K[b] * e0, e0)) else {
            continue;
        };
        let cost = robust_cost(obs, sigma, &alt);
        if cost < best_cost - SWITCH_COST {
            best = alt;
            best_cost = cost;
        }
    }
    Some(best)
}

/// How much lower another start's Lorentzian cost must be to replace the median start's
/// solution: ln 2, the cost of one border at half weight.
const SWITCH_COST: f64 = std::f64::consts::LN_2;

/// The Lorentzian cost of a solution, each border counted once: `Σ ln(1 + r²/(2σ²))`.
fn robust_cost(obs: &[(usize, f64, f64)], sigma: f64, sol: &Solution) -> f64 {
    let (d, e) = (sol.0, if sol.1.is_finite() { sol.1 } else { 0.0 });
    obs.iter()
        .map(|&(b, z, _)| {
            let r = z - d - K[b] * e;
            (1.0 + r * r / (2.0 * sigma * sigma)).ln()
        })
        .sum()
}

/// [`solve_sample`]'s Lorentzian reweightings from `(d, e)`.
fn iterate_sample(
    obs: &[(usize, f64, f64)],
    lateral: bool,
    sigma: f64,
    (mut d, mut e): (f64, f64),
) -> Option<Solution> {
    if obs.is_empty() {
        return None;
    }
    let k = |b: usize| K.get(b).copied().unwrap_or(0.0);
    let mut rel = [0.0; 4];
    let mut cov = [f64::NAN; 3];
    for _ in 0..SAMPLE_ITERATIONS {
        let (mut s00, mut s01, mut s11, mut b0, mut b1) = (0.0, 0.0, 0.0, 0.0, 0.0);
        let mut w_rel = [0.0; 4];
        for &(b, z, w) in obs {
            let kb = k(b);
            let r = z - d - if e.is_finite() { kb * e } else { 0.0 };
            let lw = lorentzian_weight(r, sigma);
            let ww = w * lw;
            if let Some(slot) = w_rel.get_mut(b) {
                *slot = lw;
            }
            s00 += ww;
            s01 += ww * kb;
            s11 += ww * kb * kb;
            b0 += ww * z;
            b1 += ww * kb * z;
        }
        rel = w_rel;
        if lateral || s11 <= 0.0 {
            // Laterally, or with no land border to see e: d from what there is.
            if s00 <= 0.0 {
                return None;
            }
            d = b0 / s00;
            cov = [1.0 / s00, f64::NAN, f64::NAN];
            if !lateral {
                e = f64::NAN;
            }
            continue;
        }
        let det = s00 * s11 - s01 * s01;
        if det <= 1e-12 * s00 * s11 {
            return None;
        }
        d = (b0 * s11 - b1 * s01) / det;
        e = (b1 * s00 - b0 * s01) / det;
        cov = [s11 / det, s00 / det, -s01 / det];
    }
    Some((d, e, cov, rel))
}

/// The median start of a sample's solve: d from the borders that do not see e (or all,
/// laterally), e from the lands.
fn median_start(obs: &[(usize, f64, f64)], lateral: bool) -> Option<(f64, f64)> {
    let k = |b: usize| K.get(b).copied().unwrap_or(0.0);
    let corners: Vec<f64> = obs
        .iter()
        .filter(|o| lateral || k(o.0) == 0.0)
        .map(|o| o.1)
        .collect();
    let lands: Vec<(f64, f64)> = obs
        .iter()
        .filter(|o| k(o.0) != 0.0)
        .map(|o| (k(o.0), o.1))
        .collect();
    let d =
        finite_median(corners).or_else(|| finite_median(lands.iter().map(|l| l.1).collect()))?;
    let e = if lateral {
        0.0
    } else {
        finite_median(lands.iter().map(|(kk, z)| (z - d) * kk).collect()).unwrap_or(f64::NAN)
    };
    Some((d, e))
}

/// Combines the four border tracks (record `y` and standard error per sample, µm; NaN = not
/// seen), all the same length (see the module docs).
#[must_use]
pub fn combine_borders(y: &[Vec<f64>; 4], se: &[Vec<f64>; 4], p: &CombineParams) -> Combined {
    let n = y.iter().map(Vec::len).min().unwrap_or(0);
    let lateral = p.cut == Cut::Lateral;
    let weights: [Vec<Option<f64>>; 4] =
        std::array::from_fn(|b| border_weights(&y[b], &se[b], n, p.floor_um, p.weight_window));
    let weight = |b: usize, j: usize| -> Option<f64> { weights[b].get(j).copied().flatten() };
    let mut c: [f64; 4] =
        std::array::from_fn(|b| finite_median(y[b][..n].to_vec()).unwrap_or(f64::NAN));
    let mut s = Solves::new(n, lateral);
    let observations = |j: usize, c: &[f64; 4]| -> Vec<(usize, f64, f64)> {
        (0..4)
            .filter_map(|b| Some((b, y[b][j] - c[b], weight(b, j)?)))
            .filter(|o| o.1.is_finite())
            .collect()
    };
    for _ in 0..ROUNDS {
        for j in 0..n {
            let obs = observations(j, &c);
            s.store(j, solve_sample(&obs, lateral, p.sigma_um, None), lateral);
        }
        for (b, cb) in c.iter_mut().enumerate() {
            let (mut sw, mut sz) = (0.0, 0.0);
            for (j, &yj) in y[b][..n].iter().enumerate() {
                let Some(w) = weight(b, j) else { continue };
                let ej = if K[b] == 0.0 { 0.0 } else { s.e[j] };
                let r = yj - s.d[j] - K[b] * ej;
                if r.is_finite() {
                    let ww = w * s.rel[j][b];
                    sw += ww;
                    sz += ww * r;
                }
            }
            if sw > 0.0 {
                *cb = sz / sw;
            }
        }
        // Gauge: the lands (else the corners) symmetric about d.
        let pair = |a: usize, b: usize| {
            (c[a].is_finite() && c[b].is_finite()).then(|| 0.5 * (c[a] + c[b]))
        };
        if let Some(off) = pair(0, 3).or_else(|| pair(1, 2)) {
            for cb in &mut c {
                *cb -= off;
            }
        }
    }
    if !lateral && let Some(m) = finite_median(s.e.clone()) {
        // e → e − m moves the lands' constants by ∓m and leaves every border's y alone.
        for v in &mut s.e {
            *v -= m;
        }
        c[0] -= m;
        c[3] += m;
    }
    let excursions = resolve_excursions(&mut s, p, |j, start| {
        solve_sample(&observations(j, &c), lateral, p.sigma_um, Some(start))
    });
    let Solves { d, e, cov, rel } = s;
    let mut walls_um = [vec![f64::NAN; n], vec![f64::NAN; n]];
    let mut walls_se_um = [vec![f64::NAN; n], vec![f64::NAN; n]];
    for j in 0..n {
        let [vd, ve, cde] = cov[j];
        for (side, sign) in [(0usize, -1.0f64), (1, 1.0)] {
            let v = d[j] + sign * e[j];
            if v.is_finite() {
                walls_um[side][j] = v;
                let var = if lateral {
                    vd
                } else {
                    vd + ve + 2.0 * sign * cde
                };
                walls_se_um[side][j] = var.max(0.0).sqrt();
            }
        }
    }
    let mut gaps: [Vec<Range<usize>>; 2] = Default::default();
    let mut bridged: [Vec<Range<usize>>; 2] = Default::default();
    for side in 0..2 {
        let (g, b) = bridge_gaps(&mut walls_um[side], p.max_bridge);
        gaps[side] = g;
        bridged[side] = b;
    }
    let border_weights = std::array::from_fn(|b| (0..n).map(|j| rel[j][b]).collect());
    Combined {
        excursions,
        constants_um: c,
        d_um: d,
        e_um: e,
        walls_um,
        walls_se_um,
        border_weights,
        gaps,
        bridged,
    }
}

/// Runs of non-finite samples (NaN gaps) in `v`.
#[must_use]
pub fn nan_runs(v: &[f64]) -> Vec<Range<usize>> {
    false_runs(v.iter().map(|x| x.is_finite()))
}

/// The index ranges where `ok` yields false.
pub fn false_runs(ok: impl IntoIterator<Item = bool>) -> Vec<Range<usize>> {
    let mut out = Vec::new();
    let mut start = None;
    let mut n = 0;
    for (i, o) in ok.into_iter().enumerate() {
        n = i + 1;
        match (o, start) {
            (false, None) => start = Some(i),
            (true, Some(s)) => {
                out.push(s..i);
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        out.push(s..n);
    }
    out
}

/// Fills NaN runs of at most `max_len` samples that have two finite samples on each side with
/// the cubic through those four; returns the runs left as gaps and the runs bridged.
pub fn bridge_gaps(v: &mut [f64], max_len: usize) -> (Vec<Range<usize>>, Vec<Range<usize>>) {
    let mut gaps = Vec::new();
    let mut bridged = Vec::new();
    for run in nan_runs(v) {
        let ok = |i: Option<usize>| i.and_then(|i| v.get(i)).is_some_and(|x| x.is_finite());
        let (s, e) = (run.start, run.end);
        let nodes = [s.checked_sub(2), s.checked_sub(1), Some(e), Some(e + 1)];
        if run.len() > max_len || !nodes.iter().all(|&i| ok(i)) {
            gaps.push(run);
            continue;
        }
        let pts: Vec<(f64, f64)> = nodes.iter().flatten().map(|&i| (i as f64, v[i])).collect();
        for i in run.clone() {
            v[i] = crate::pipeline::lagrange(&pts, i as f64);
        }
        bridged.push(run);
    }
    (gaps, bridged)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;

    fn params(cut: Cut) -> CombineParams {
        CombineParams {
            cut,
            sigma_um: 0.5,
            floor_um: 0.01,
            max_bridge: 3,
            weight_window: 0,
            max_step_um: 0.0,
            max_excursion: 0,
        }
    }

    /// Border tracks of a groove moving by `d(j)` and `e(j)`, with a small deterministic jitter.
    fn tracks(n: usize, d: impl Fn(usize) -> f64, e: impl Fn(usize) -> f64) -> [Vec<f64>; 4] {
        let c = [-90.0, -20.0, 20.0, 90.0];
        std::array::from_fn(|b| {
            (0..n)
                .map(|j| {
                    let jitter = 0.01 * ((j * 7 + b * 13) % 5) as f64 - 0.02;
                    c[b] + 3.0 + d(j) + K[b] * e(j) + jitter
                })
                .collect()
        })
    }

    #[test]
    fn lateral_walls_follow_the_displacement_and_a_flaked_border_is_rejected() {
        let n = 40;
        let d = |j: usize| 5.0 * (j as f64 * 0.4).sin();
        let mut y = tracks(n, d, |_| 0.0);
        // A flake: the left land border jumps 30 µm for samples 10..17.
        for v in &mut y[0][10..17] {
            *v += 30.0;
        }
        let se: [Vec<f64>; 4] = std::array::from_fn(|_| vec![0.02; n]);
        let c = combine_borders(&y, &se, &params(Cut::Lateral));
        for j in 0..n {
            // The groove's centre: the lands are symmetric (constants ±90 → centre 3.0 + d).
            let want = 3.0 + d(j);
            for side in 0..2 {
                assert!(
                    (c.walls_um[side][j] - want).abs() < 0.05,
                    "{j}: {}",
                    c.walls_um[side][j]
                );
            }
        }
        for j in 10..17 {
            assert!(
                c.border_weights[0][j] < REJECTED_WEIGHT,
                "{j}: {}",
                c.border_weights[0][j]
            );
        }
        assert!(c.border_weights[1][12] > 0.5);
        assert!(c.gaps[0].is_empty() && c.gaps[1].is_empty());
    }

    #[test]
    fn a_stretch_where_most_borders_are_off_is_solved_again_from_the_track_around_it() {
        // As on a heavily damaged scan: for five samples dust moves the right bottom corner
        // 25 µm, a flake moves the left land 45 µm and the right land is not seen, so the
        // median start falls on the wrong borders; only the left bottom corner is right.
        let n = 120;
        let d = |j: usize| 2.0 * (j as f64 * 0.15).sin();
        let mut y = tracks(n, d, |_| 0.0);
        let stretch = 50..55;
        y[0][stretch.clone()].iter_mut().for_each(|v| *v += 45.0);
        y[2][stretch.clone()].iter_mut().for_each(|v| *v += 25.0);
        y[3][stretch].fill(f64::NAN);
        let se: [Vec<f64>; 4] = std::array::from_fn(|_| vec![0.02; n]);
        let off = combine_borders(&y, &se, &params(Cut::Lateral));
        assert!(off.excursions.is_empty());
        assert!(
            (off.walls_um[0][52] - (3.0 + d(52))).abs() > 10.0,
            "the median start fails"
        );
        // Samples 1 µm apart along the groove, slopes up to 1: the track may move 1 µm a sample.
        let p = CombineParams {
            max_step_um: 1.0,
            max_excursion: 16,
            ..params(Cut::Lateral)
        };
        let c = combine_borders(&y, &se, &p);
        assert_eq!(c.excursions, vec![50..55]);
        for j in 0..n {
            let want = 3.0 + d(j);
            // One border alone carries the excursion: its own jitter (±0.02 µm) and constant.
            let tol = if (50..55).contains(&j) { 0.1 } else { 0.05 };
            assert!(
                (c.walls_um[0][j] - want).abs() < tol,
                "{j}: {}",
                c.walls_um[0][j]
            );
        }
        assert!(c.border_weights[1][52] > 0.5 && c.border_weights[2][52] < REJECTED_WEIGHT);
    }

    #[test]
    fn two_borders_that_agree_outvote_one_read_precisely() {
        // Laterally, z = y − c per border: the left land 40 µm off (a flake), the left bottom
        // 5 µm off (dust) but read four times as precisely, the two right borders on the
        // groove. The median of the four (2.5 µm) starts the Lorentzian where the precise
        // border's weight carries it.
        let sigma = 0.5;
        let obs = [
            (0, 40.0, 100.0),
            (1, 5.0, 400.0),
            (2, 0.0, 100.0),
            (3, 0.0, 100.0),
        ];
        let from_median = iterate_sample(&obs, true, sigma, median_start(&obs, true).unwrap());
        assert!(
            (from_median.unwrap().0 - 5.0).abs() < 0.3,
            "{from_median:?}"
        );
        let (d, _, _, rel) = solve_sample(&obs, true, sigma, None).unwrap();
        assert!(d.abs() < 0.3, "d {d}");
        assert!(
            rel[1] < REJECTED_WEIGHT && rel[2] > 0.5 && rel[3] > 0.5,
            "{rel:?}"
        );
        // Borders that agree: the median start's solve, to the bit.
        let clean = [
            (0, 0.1, 100.0),
            (1, -0.1, 400.0),
            (2, 0.05, 100.0),
            (3, 0.0, 100.0),
        ];
        // (Debug text: the covariance holds NaN, which equals nothing.)
        assert_eq!(
            format!("{:?}", solve_sample(&clean, true, sigma, None)),
            format!(
                "{:?}",
                iterate_sample(&clean, true, sigma, median_start(&clean, true).unwrap())
            )
        );
    }

    #[test]
    fn stereo_walls_move_apart_with_the_vertical_offset() {
        let n = 30;
        let d = |j: usize| 2.0 * (j as f64 * 0.3).sin();
        let e = |j: usize| 1.5 * (j as f64 * 0.7).cos();
        let y = tracks(n, d, e);
        let se: [Vec<f64>; 4] = std::array::from_fn(|_| vec![0.02; n]);
        let c = combine_borders(&y, &se, &params(Cut::Stereo));
        // The constants' gauge puts the groove centre at the lands' midpoint; e's offset is
        // its median, so compare e and the walls about their first sample.
        for j in 0..n {
            assert!((c.d_um[j] - (3.0 + d(j))).abs() < 0.05, "{j}");
            let de = (c.e_um[j] - c.e_um[0]) - (e(j) - e(0));
            assert!(de.abs() < 0.05, "{j}: {de}");
            for (side, sign) in [(0, -1.0), (1, 1.0)] {
                let got = c.walls_um[side][j] - c.walls_um[side][0];
                let want = d(j) - d(0) + sign * (e(j) - e(0));
                assert!((got - want).abs() < 0.07, "{side} {j}: {got} vs {want}");
            }
        }
        assert!(crate::pipeline::median(c.e_um.clone()).unwrap().abs() < 1e-9);
    }

    #[test]
    fn stretch_weights_keep_the_mix_steady_where_standard_errors_scatter() {
        // Four borders with the same true noise (0.1 µm) whose fits' standard errors scatter
        // by a factor of up to 4 from sample to sample, independently of their errors: per-
        // sample weights then mix the borders unevenly, a stretch's weights do not.
        let n = 400;
        let mut state = 12_345u64;
        let mut uniform = move || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let d = |j: usize| 4.0 * (j as f64 * 0.05).sin();
        let c = [-90.0, -20.0, 20.0, 90.0];
        let mut y: [Vec<f64>; 4] = Default::default();
        let mut se: [Vec<f64>; 4] = Default::default();
        for b in 0..4 {
            for j in 0..n {
                // Sum of four uniforms: near-normal noise of σ 0.1 µm.
                let z = (0..4).map(|_| uniform() - 0.5).sum::<f64>() * 0.1 * 3f64.sqrt();
                y[b].push(c[b] + d(j) + z);
                se[b].push(0.1 * 4f64.powf(2.0 * uniform() - 1.0));
            }
        }
        let rms_error = |window: usize| {
            let p = CombineParams {
                weight_window: window,
                ..params(Cut::Lateral)
            };
            let comb = combine_borders(&y, &se, &p);
            let err: Vec<f64> = (0..n).map(|j| comb.d_um[j] - d(j)).collect();
            let mean = err.iter().sum::<f64>() / n as f64;
            (err.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / n as f64).sqrt()
        };
        let (own, stretch) = (rms_error(0), rms_error(32));
        // Equal weights would give 0.1/√4 = 0.05 µm.
        assert!(stretch < 0.058, "stretch weights: {stretch:.4} µm");
        assert!(
            own > 1.15 * stretch,
            "own {own:.4} µm, stretch {stretch:.4} µm"
        );
    }

    #[test]
    fn missing_samples_become_gaps_or_are_bridged() {
        let n = 30;
        let mut y = tracks(n, |j| 0.1 * j as f64, |_| 0.0);
        for b in &mut y {
            b[8] = f64::NAN; // one sample: bridged
            for v in &mut b[15..25] {
                *v = f64::NAN; // ten: a gap
            }
        }
        let se: [Vec<f64>; 4] = std::array::from_fn(|_| vec![0.02; n]);
        let c = combine_borders(&y, &se, &params(Cut::Lateral));
        assert_eq!(c.bridged[0], vec![8..9]);
        assert_eq!(c.gaps[0], vec![15..25]);
        assert!((c.walls_um[0][8] - (3.0 + 0.8)).abs() < 0.05);
        assert!(c.walls_um[0][20].is_nan());
    }

    #[test]
    fn bridging_needs_two_samples_on_each_side() {
        let mut v = vec![0.0, f64::NAN, 2.0, 3.0, 4.0, f64::NAN, f64::NAN, 7.0, 8.0];
        let (gaps, bridged) = bridge_gaps(&mut v, 3);
        assert_eq!(gaps, vec![1..2]);
        assert_eq!(bridged, vec![5..7]);
        assert!((v[5] - 5.0).abs() < 1e-12 && (v[6] - 6.0).abs() < 1e-12);
    }
}
