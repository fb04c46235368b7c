//! Tests of the depth stage: planes of known depth and tilt, noisy frames, warnings and errors, the AVX2 and median-network paths; the fast filter against the reference in the sub-module.

use super::*;
use crate::pipeline::walls::test_support::{Rng, paper_geometry};

mod reference;

/// Z seen at pixel (x, y) of frame k on the plane Z = z0 + ax·X_world + ay·Y, where the
/// camera sits at X = k·U: 1/Z is linear in the pixel coordinates.
fn plane_z(x: usize, y: usize, k: usize, w: usize, h: usize, g: &Geometry, p: [f64; 3]) -> f64 {
    let [z0, ax, ay] = p;
    let (px, py) = (
        (x as f64 - (w as f64 - 1.0) / 2.0) / g.focal_px,
        (y as f64 - (h as f64 - 1.0) / 2.0) / g.focal_px,
    );
    (z0 + ax * k as f64 * g.frame_step_um) / (1.0 - ax * px - ay * py)
}

fn plane_flows(
    w: usize,
    h: usize,
    frames: usize,
    g: &Geometry,
    p: [f64; 3],
    noise_px: f64,
    seed: u64,
) -> Vec<FlowField> {
    let mut rng = Rng::new(seed);
    (0..frames)
        .map(|k| {
            let u = Image::from_fn(w, h, |x, y| {
                let z = plane_z(x, y, k, w, h, g, p);
                (-g.focal_px * g.frame_step_um / z + noise_px * rng.gauss()) as f32
            });
            FlowField::exact(u, k + 3)
        })
        .collect()
}

/// The plane `p` (see [`plane_z`]) seen by the paper's optics in `w` × `h` px frames, and its
/// flows ([`plane_flows`]).
struct PlaneScene {
    g: Geometry,
    w: usize,
    h: usize,
    p: [f64; 3],
    flows: Vec<FlowField>,
}

impl PlaneScene {
    /// The plane `p` and its flows in `frames` frames (indices from 3), with Gaussian noise of
    /// `noise_px` px seeded by `seed`.
    fn new(w: usize, h: usize, frames: usize, p: [f64; 3], noise_px: f64, seed: u64) -> Self {
        let g = paper_geometry();
        let flows = plane_flows(w, h, frames, &g, p, noise_px, seed);
        Self { g, w, h, p, flows }
    }

    /// Z seen at pixel (x, y) of frame k.
    fn z(&self, x: usize, y: usize, k: usize) -> f64 {
        plane_z(x, y, k, self.w, self.h, &self.g, self.p)
    }
}

/// Least-squares slope of Z against Y = (y − cy)·Z/f over the map.
fn tilt_dz_dy(map: &DepthMap, g: &Geometry) -> f64 {
    let (w, h) = (map.z_um.width, map.z_um.height);
    let (mut n, mut sy, mut sz, mut syy, mut syz) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for y in 0..h {
        for x in 0..w {
            let z = f64::from(map.z_um.get(x, y).unwrap());
            let yy = (y as f64 - (h as f64 - 1.0) / 2.0) * z / g.focal_px;
            n += 1.0;
            sy += yy;
            sz += z;
            syy += yy * yy;
            syz += yy * z;
        }
    }
    (syz - sy * sz / n) / (syy - sy * sy / n)
}

fn rel_err(map: &DepthMap, truth: impl Fn(usize, usize) -> f64) -> (f64, f64) {
    let (w, h) = (map.z_um.width, map.z_um.height);
    let (mut max, mut ss, mut n) = (0.0_f64, 0.0, 0.0);
    for y in 0..h {
        for x in 0..w {
            let t = truth(x, y);
            let e = (f64::from(map.z_um.get(x, y).unwrap()) - t) / t;
            max = max.max(e.abs());
            ss += e * e;
            n += 1.0;
        }
    }
    (max, (ss / n).sqrt())
}

#[test]
fn exact_flows_of_a_plane_tilted_across_give_depth_and_tilt() {
    let s = PlaneScene::new(96, 64, 6, [4000.0, 0.0, 0.8], 0.0, 1);
    // 11 px: wider than the direct window sums, so the f64 running sums are used.
    for (kalman, neighbourhood_px) in [(true, 5), (true, 11), (false, 5)] {
        let map = estimate_depth(
            &s.flows,
            &s.g,
            &DepthParams {
                kalman,
                neighbourhood_px,
                ..DepthParams::default()
            },
        )
        .unwrap();
        assert_eq!(map.frame_index, 8);
        let (max, _) = rel_err(&map, |x, y| s.z(x, y, 5));
        assert!(max < 1e-3, "kalman {kalman}: max relative error {max}");
        let tilt = tilt_dz_dy(&map, &s.g);
        assert!((tilt - 0.8).abs() < 0.008, "kalman {kalman}: tilt {tilt}");
        assert!(
            map.variance.data.iter().all(|v| v.is_finite() && *v >= 0.0),
            "kalman {kalman}"
        );
    }
}

#[test]
fn plane_tilted_along_the_motion_is_tracked_into_the_last_frame() {
    // Z changes by 0.8·U = 0.62 µm per frame under each pixel: a wrong re-indexing or a
    // map left in an earlier frame's grid is off by ≥ 1.5e-4.
    let s = PlaneScene::new(80, 40, 6, [4000.0, 0.8, 0.3], 0.0, 1);
    let map = estimate_depth(&s.flows, &s.g, &DepthParams::default()).unwrap();
    let (max, _) = rel_err(&map, |x, y| s.z(x, y, 5));
    assert!(max < 2e-5, "max relative error {max}");
    let (max_first, _) = rel_err(&map, |x, y| s.z(x, y, 0));
    assert!(max_first > 5e-4, "{max_first}");
}

#[test]
fn avx2_bands_give_the_same_bits() {
    let Some(avx2) = Isa::avx2() else {
        return;
    };
    let PlaneScene { g, w, h, flows, .. } =
        PlaneScene::new(53, 40, 3, [4000.0, 0.3, -0.5], 0.05, 4);
    let land = g.focal_px * g.frame_step_um / g.working_distance_um;
    let filter = Filter {
        width: w,
        height: h,
        r: 2,
        land_shift_px: land,
        noise_var: 1e-4 / (land * land),
        q: [1e-6 / 4.0, 1e-6 / 4.0, 1e-6],
        p0: [
            INITIAL_VARIANCE / 4.0,
            INITIAL_VARIANCE / 4.0,
            INITIAL_VARIANCE,
        ],
        isa: Isa::Portable,
    };
    let fast = Filter {
        isa: avx2,
        ..filter
    };
    let frames: Vec<FrameInput> = flows
        .iter()
        .enumerate()
        .map(|(k, flow)| {
            let mut meas = Measurements::default();
            meas.fill(flow, -land, 1e-3);
            FrameInput {
                meas,
                steps: (k > 0).then_some(1.0),
            }
        })
        .collect();
    let (mut plain, mut plain_var) = (vec![0.0; w * h], vec![0.0; w * h]);
    let (mut simd, mut simd_var) = (plain.clone(), plain_var.clone());
    let mut sc = SweepScratch::default();
    let a = filter.band(0, &frames, (&mut plain, &mut plain_var), &mut sc);
    let b = fast.band(0, &frames, (&mut simd, &mut simd_var), &mut sc);
    assert_eq!(a, b);
    let bits = |s: &[f32]| -> Vec<u32> { s.iter().map(|v| v.to_bits()).collect() };
    assert!(plain.iter().any(|&v| v != 1.0 && v.is_finite()));
    assert_eq!(bits(&plain), bits(&simd));
    assert_eq!(bits(&plain_var), bits(&simd_var));
}

#[test]
fn direct_and_prefix_window_sums_agree() {
    let PlaneScene { g, w, h, flows, .. } =
        PlaneScene::new(41, 23, 1, [4000.0, 0.3, -0.5], 0.05, 7);
    let land = g.focal_px * g.frame_step_um / g.working_distance_um;
    let mut meas = Measurements::default();
    meas.fill(&flows[0], -land, 1e-3);
    // Some pixels without weight, so windows are partly empty.
    for i in (0..w * h).step_by(5) {
        meas.w[i] = 0.0;
        meas.wm[i] = 0.0;
    }
    for r in 1..=DIRECT_WINDOW_MAX_R {
        let filter = Filter {
            width: w,
            height: h,
            r,
            land_shift_px: land,
            noise_var: 1e-4 / (land * land),
            q: [0.0; 3],
            p0: [1.0; 3],
            isa: Isa::detect(),
        };
        for y in [0, r, h / 2, h - 1] {
            let mut vs = vec![[0.0; 5]; w];
            for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
                filter.slide(&mut vs, &meas, yy, 1.0);
            }
            let mut sc = SweepScratch {
                info: vec![0.0; 9 * w],
                ..SweepScratch::default()
            };
            filter.prefix_info(y, &vs, &mut sc);
            let want = std::mem::take(&mut sc.info);
            sc.info = vec![0.0; 9 * w];
            filter.direct_info(y, &meas, &mut sc);
            let scale = want.iter().fold(0.0_f32, |m, v| m.max(v.abs()));
            assert!(scale > 0.0);
            for (i, (a, b)) in sc.info.iter().zip(&want).enumerate() {
                assert!(
                    (a - b).abs() <= 1e-5 * scale,
                    "r {r} y {y} [{i}]: {a} vs {b}"
                );
            }
        }
    }
}

#[test]
fn kalman_over_six_noisy_frames_beats_one_frame() {
    let s = PlaneScene::new(120, 80, 6, [4000.0, 0.2, 0.8], 0.02, 9);
    // The filter's noise model matches the flows; the plane does not change.
    let params = DepthParams {
        measurement_noise_px2: 0.02 * 0.02,
        process_noise: 1e-9,
        ..DepthParams::default()
    };
    let truth = |x, y| s.z(x, y, 5);
    let (_, rms6) = rel_err(&estimate_depth(&s.flows, &s.g, &params).unwrap(), truth);
    let (_, rms1) = rel_err(
        &estimate_depth(&s.flows[5..], &s.g, &params).unwrap(),
        truth,
    );
    let raw = DepthMap {
        z_um: Image::from_fn(s.w, s.h, |x, y| {
            depth_from_flow_um(s.flows[5].u.get(x, y).unwrap(), &s.g)
        }),
        variance: Image::zeros(s.w, s.h),
        frame_index: 8,
        warnings: Vec::new(),
    };
    let (_, rms_raw) = rel_err(&raw, truth);
    assert!(rms6 < 0.6 * rms1, "6 frames {rms6}, 1 frame {rms1}");
    assert!(rms1 < rms_raw, "1 frame {rms1}, raw {rms_raw}");
    let avg = DepthParams {
        kalman: false,
        ..params
    };
    let (_, rms_avg) = rel_err(&estimate_depth(&s.flows, &s.g, &avg).unwrap(), truth);
    assert!(rms_avg < rms_raw, "average {rms_avg}, raw {rms_raw}");
}

#[test]
fn dropped_frames_and_unmeasured_pixels_are_warnings() {
    let PlaneScene {
        g, w, h, mut flows, ..
    } = PlaneScene::new(40, 30, 4, [4000.0, 0.0, 0.0], 0.0, 1);
    flows[1].confidence = Image::zeros(w, h);
    flows[3].frame_index += 2;
    for f in &mut flows {
        for y in 0..h {
            for x in w - 10..w {
                f.confidence.data[y * w + x] = 0.0;
            }
        }
    }
    flows[2].u.data[w * 15 + 20] = f32::NAN;
    let map = estimate_depth(&flows, &g, &DepthParams::default()).unwrap();
    let all = map.warnings.join("\n");
    assert!(all.contains("flow 1 (frame 4) dropped"), "{all}");
    assert!(all.contains("missing"), "{all}");
    assert!(all.contains("never measured"), "{all}");
    assert!(all.contains("non-finite flow"), "{all}");
    assert_eq!(map.frame_index, 8);
    // New content enters at the right, where nothing is ever confident.
    assert!(map.z_um.get(w - 3, 15).unwrap().is_nan());
    let z = map.z_um.get(10, 15).unwrap();
    assert!((z - 4000.0).abs() < 0.1, "{z}");
}

#[test]
fn bad_input_and_params_are_errors() {
    let PlaneScene { g, flows, .. } = PlaneScene::new(20, 10, 3, [4000.0, 0.0, 0.0], 0.0, 1);
    let p = DepthParams::default();
    assert!(matches!(
        estimate_depth(&[], &g, &p),
        Err(StageError::BadInput { .. })
    ));
    let mut rev = flows.clone();
    rev.swap(0, 2);
    assert!(matches!(
        estimate_depth(&rev, &g, &p),
        Err(StageError::BadInput { .. })
    ));
    let mut odd = flows.clone();
    odd[1].confidence = Image::zeros(21, 10);
    assert!(matches!(
        estimate_depth(&odd, &g, &p),
        Err(StageError::BadInput { .. })
    ));
    for bad in [
        DepthParams {
            median_px: 4,
            ..p.clone()
        },
        DepthParams {
            neighbourhood_px: 0,
            ..p.clone()
        },
        DepthParams {
            measurement_noise_px2: f32::NAN,
            ..p.clone()
        },
        DepthParams {
            process_noise: -1.0,
            ..p.clone()
        },
    ] {
        assert!(matches!(
            estimate_depth(&flows, &g, &bad),
            Err(StageError::InvalidParam { .. })
        ));
    }
    let no_step = Geometry {
        frame_step_um: 0.0,
        ..g
    };
    assert!(matches!(
        estimate_depth(&flows, &no_step, &p),
        Err(StageError::InvalidParam { .. })
    ));
}

#[test]
fn median_network_matches_selection() {
    let mut rng = Rng::new(4);
    let (w, h) = (45, 23);
    let mut v: Vec<f32> = (0..w * h).map(|_| rng.gauss() as f32).collect();
    for i in (0..w * h).step_by(97) {
        v[i] = f32::NAN;
    }
    let mut buf = Vec::new();
    for (m, isa) in [3, 5, 7]
        .into_iter()
        .flat_map(|m| [Some(Isa::Portable), Isa::avx2()].map(|isa| isa.map(|i| (m, i))))
        .flatten()
    {
        let r = m / 2;
        let mut out = vec![0.0; w * h];
        median_filter(&v, w, h, m, &mut out, isa);
        for y in 0..h {
            for x in 0..w {
                let (rx, ry) = (r.min(x).min(w - 1 - x), r.min(y).min(h - 1 - y));
                let want = median_select(&v, w, x, y, rx, ry, &mut buf);
                assert_eq!(
                    out[y * w + x].to_bits(),
                    want.to_bits(),
                    "m {m} at ({x}, {y}), {isa:?}"
                );
            }
        }
    }
}

#[test]
fn median_network_paths_agree_with_sorting_including_ties() {
    assert_eq!(MedianNetwork::new(25).pairs.len(), 114);
    let mut rng = Rng::new(9);
    for n in [1, 9, 25, 49] {
        let net = MedianNetwork::new(n);
        for _ in 0..200 {
            // Few distinct values, so ties are common.
            let input: Vec<[f32; MEDIAN_LANES]> = (0..n)
                .map(|_| std::array::from_fn(|_| (rng.gauss() * 3.0).round() as f32))
                .collect();
            let want: [f32; MEDIAN_LANES] = std::array::from_fn(|l| {
                let mut col: Vec<f32> = input.iter().map(|v| v[l]).collect();
                col.sort_by(f32::total_cmp);
                col[n / 2]
            });
            for isa in [Some(Isa::Portable), Isa::avx2()].into_iter().flatten() {
                let mut a = input.clone();
                assert_eq!(net.run(isa, &mut a), Some(want), "n {n}, {isa:?}");
            }
        }
        let short = &mut vec![[0.0; MEDIAN_LANES]; n - 1];
        assert_eq!(net.run(Isa::detect(), short), None);
    }
}

#[test]
fn depth_from_flow_matches_the_land() {
    let g = paper_geometry();
    let z = depth_from_flow_um(g.land_flow_px() as f32, &g);
    assert!((z - 4000.0).abs() < 1e-2, "{z}");
    assert!(depth_from_flow_um(0.5, &g).is_nan());
}
