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

pub mod scatter;

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
    /// Start a sample's solve again from each border where the median start rejects one.
    pub restart: bool,
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
            restart: params.restart_solves,
        }
    }
}

/// Each border's weight `1/se²` per sample (NaN where the border is not seen: a weight is never
/// NaN, and a side's samples are millions, so not an `Option`'s 16 bytes), `se` floored
/// at `floor` and, with `window` > 1, `se²` the geometric mean of the floored `se²` of the
/// seen samples within `window/2` on each side.
fn border_weights(y: &[f64], se: &[f64], n: usize, floor: f64, window: usize) -> Vec<f64> {
    let var = |j: usize| -> Option<f64> {
        let (yv, sv) = (*y.get(j)?, *se.get(j)?);
        (yv.is_finite() && sv.is_finite()).then(|| sv.max(floor).powi(2))
    };
    if window <= 1 {
        return (0..n)
            .map(|j| var(j).map_or(f64::NAN, |v| 1.0 / v))
            .collect();
    }
    let logs: Vec<f64> = (0..n).map(|j| var(j).map_or(f64::NAN, f64::ln)).collect();
    let means = crate::pipeline::finite_window_means(&logs, window / 2);
    logs.iter()
        .zip(means)
        .map(|(l, mean)| {
            if l.is_finite() {
                (-mean).exp()
            } else {
                f64::NAN
            }
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
    /// Per sample, how much more the kept borders scatter from sample to sample than their
    /// standard errors say (at least 1; [`scatter`]): the factor the fused decoder may raise
    /// `walls_se_um`'s variance by.
    pub scatter: Vec<f64>,
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

/// Where a sample's solve starts.
#[derive(Clone, Copy, Debug)]
enum Start {
    /// From this (d, e).
    At(f64, f64),
    /// From the medians of the borders; with `restart`, again from each border's own reading
    /// where that solve rejects a border.
    Median {
        /// Start again where a border is rejected (`edges.restart_solves`).
        restart: bool,
    },
}

/// One sample's robust solve: borders `(k, z = y − c, w)`. `lateral` fixes e = 0. The
/// Lorentzian starts as `start` says. From the medians with `restart`, where that solve rejects
/// a border it starts again from each border's own reading: the Lorentzian's cost has a minimum
/// for every set of borders that agree, and the median of four (two of them off, say a dust
/// grain on one corner and a flake at a land) can start it at the wrong one. The solution whose
/// cost ([`robust_cost`], which counts each border once, so one border read precisely cannot
/// outvote two that agree) is lower by more than [`SWITCH_COST`] wins, so borders that agree
/// keep their solve to the bit.
fn solve_sample(
    obs: &[(usize, f64, f64)],
    lateral: bool,
    sigma: f64,
    start: Start,
) -> Option<Solution> {
    let restart = match start {
        Start::At(d, e) => return iterate_sample(obs, lateral, sigma, (d, e)),
        Start::Median { restart } => restart,
    };
    let first = iterate_sample(obs, lateral, sigma, median_start(obs, lateral)?)?;
    if !restart || obs.iter().all(|o| first.3[o.0] >= REJECTED_WEIGHT) {
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
    let weights: [Vec<f64>; 4] =
        std::array::from_fn(|b| border_weights(&y[b], &se[b], n, p.floor_um, p.weight_window));
    let weight =
        |b: usize, j: usize| -> Option<f64> { weights[b].get(j).copied().filter(|w| !w.is_nan()) };
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
            let start = Start::Median { restart: p.restart };
            s.store(j, solve_sample(&obs, lateral, p.sigma_um, start), lateral);
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
        solve_sample(
            &observations(j, &c),
            lateral,
            p.sigma_um,
            Start::At(start.0, start.1),
        )
    });
    let Solves { d, e, cov, rel } = s;
    let residual = |b: usize, j: usize| -> f64 {
        let ej = if K[b] == 0.0 { 0.0 } else { e[j] };
        y[b][j] - c[b] - d[j] - K[b] * ej
    };
    let scatter =
        scatter::scatter_factors(n, &residual, &weight, &rel, if lateral { 1 } else { 2 });
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
        scatter,
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
mod tests;
