//! Tests of the blocked solver: bands, passes, SIMD and measured stops give the same bits; the coefficient layout; the convergence schedule.

use super::*;

/// A 37×230 tilted plane (odd width: halves of 19 and 18 columns, whole and partial blocks)
/// with wall sides in stripes of 40 rows, for the band and SIMD tests.
fn banded_problem() -> (Layout, Derivatives, WallSideMap) {
    let (w, h) = (37, 230);
    let frames = tilted_plane(w, h, 7, 0.6, 1.0, 100.0);
    let walls = WallSideMap {
        width: w,
        height: h,
        sign: (0..w * h).map(|i| [0, 1, -1][(i / w / 40) % 3]).collect(),
    };
    (
        Layout::new(w, h),
        middle(&frames, 0.0, &no_prewarp()),
        walls,
    )
}

#[test]
fn blocking_bands_and_simd_do_not_change_the_result() {
    let (lay, d, walls) = banded_problem();
    let p = FlowParams::default();
    let built = HsSystem::groove(&lay, &d, &walls, 100.0, &p, Isa::Portable);
    let fast = HsSystem::groove(&lay, &d, &walls, 100.0, &p, Isa::detect());
    // Both halves' coefficients of every row, in one array.
    assert!(built.coef == fast.coef);
    assert!(built.coef.iter().all(|c| c.is_finite()));
    for solver in [Solver::GaussSeidel, Solver::Jacobi] {
        for omega in [1.0, 1.7] {
            let p = FlowParams {
                solver,
                sor_omega: omega,
                max_iterations: 37,
                tolerance_px: 0.0,
                ..FlowParams::default()
            };
            for problem in [
                HsSystem::plain(&lay, &d, p.lambda),
                HsSystem::groove(&lay, &d, &walls, 100.0, &p, Isa::detect()),
            ] {
                let mut reference = SplitState::zeros(&lay);
                let (it, _) = problem.solve_with(&mut reference, &p, Isa::Portable, 1, Some(1));
                assert_eq!(it, 37);
                for (bands, block) in [(1, None), (2, Some(5)), (3, Some(4)), (4, Some(16))] {
                    let mut st = SplitState::zeros(&lay);
                    problem.solve_with(&mut st, &p, Isa::detect(), bands, block);
                    assert!(
                        st.e == reference.e && st.o == reference.o,
                        "{solver:?} ω {omega} bands {bands} block {block:?}"
                    );
                }
            }
        }
    }
}

/// With τ > 0 each block measures its changes; their sums, and so where the solve stops, do
/// not depend on how many row bands (threads) ran it.
#[test]
fn measured_stops_do_not_depend_on_the_bands() {
    let (lay, d, walls) = banded_problem();
    let p = FlowParams {
        tolerance_px: 1e-4,
        ..FlowParams::default()
    };
    for problem in [
        HsSystem::plain(&lay, &d, p.lambda),
        HsSystem::groove(&lay, &d, &walls, 100.0, &p, Isa::detect()),
    ] {
        // One measured block of 5 iterations: the same sums, to the bit.
        let sums: Vec<(f64, f64)> = (1..=4)
            .map(|bands| {
                let mut st = SplitState::zeros(&lay);
                problem.pass(Isa::detect(), &mut [&mut st], 10, bands, 1.0, Some(2), true)
            })
            .collect();
        assert!(sums[0].0 > 0.0 && sums[0].1 > 0.0);
        assert!(sums.iter().all(|s| s == &sums[0]), "{sums:?}");
        let mut reference = SplitState::zeros(&lay);
        let stop = problem.solve_with(&mut reference, &p, Isa::detect(), 1, None);
        for bands in [2, 3, 4] {
            let mut st = SplitState::zeros(&lay);
            let got = problem.solve_with(&mut st, &p, Isa::detect(), bands, None);
            assert_eq!(got, stop, "bands {bands}");
            assert!(st.e == reference.e && st.o == reference.o, "bands {bands}");
        }
    }
}

/// Cutting a block into wavefront passes changes no bit: neither the state nor the measured
/// sums, for red–black and Jacobi, plain and groove.
#[test]
fn passes_do_not_change_the_result() {
    let (lay, d, walls) = banded_problem();
    for solver in [Solver::GaussSeidel, Solver::Jacobi] {
        let p = FlowParams {
            solver,
            ..FlowParams::default()
        };
        for problem in [
            HsSystem::plain(&lay, &d, p.lambda),
            HsSystem::groove(&lay, &d, &walls, 100.0, &p, Isa::detect()),
        ] {
            let run = |pass_levels| {
                let mut st = SplitState::zeros(&lay);
                let mut other = (solver == Solver::Jacobi).then(|| st.clone());
                let sums = problem.block(
                    Isa::detect(),
                    &mut st,
                    other.as_mut(),
                    13,
                    2,
                    1.0,
                    true,
                    pass_levels,
                );
                (st, sums)
            };
            let (whole, sums) = run(64);
            assert!(sums.0 > 0.0 && sums.1 > 0.0, "{solver:?}");
            for pass_levels in [1, 2, 5, 8] {
                let (st, got) = run(pass_levels);
                assert!(
                    st.e == whole.e && st.o == whole.o && got == sums,
                    "{solver:?} passes of {pass_levels} levels: {got:?} against {sums:?}"
                );
            }
        }
    }
}

#[test]
fn coefficient_slots_cover_each_half_row_once() {
    for w in [2, 3, 16, 17, 31, 40, 1280] {
        let lay = Layout::new(w, 1);
        for half in 0..2 {
            let cr = CoefRow::new(&lay, half, GROOVE_COEFS);
            let mut seen = vec![false; cr.len()];
            for i in 0..cr.n {
                for k in 0..cr.c {
                    let at = cr.at(i, k);
                    assert!(!seen[at], "w {w} half {half}: column {i} coefficient {k}");
                    seen[at] = true;
                }
                // Column i is lane i div m of vector i mod m, in the state as here.
                assert_eq!(cr.at(i, 0), (i % lay.m) * LANES * cr.c + i / lay.m);
                assert_eq!(lay.slot(i), (i % lay.m) * PAIR + i / lay.m);
            }
            // What is left is the padding.
            let unseen = seen.iter().filter(|s| !**s).count();
            assert_eq!(unseen, (lay.slots() - cr.n) * cr.c);
            // `each_slot` visits the columns in order, at their slots.
            let mut next = 0;
            lay.each_slot(cr.n, |i, at| {
                assert_eq!((i, at), (next, lay.slot(next)), "w {w} half {half}");
                next += 1;
            });
            assert_eq!(next, cr.n);
        }
    }
}

#[test]
fn geometric_decay_predicts_the_iterations_left() {
    // 1e-2 after 16 iterations, 1e-3 after 32: a tenth per 16 iterations, so 1e-5 needs
    // 32 more.
    assert_eq!(
        iterations_to_tolerance((16, 1e-2), (32, 1e-3), 1e-5),
        Some(32)
    );
    assert_eq!(
        iterations_to_tolerance((16, 1e-2), (32, 1e-3), 0.9e-3),
        Some(1)
    );
    // Growing, flat or missing changes predict nothing.
    assert_eq!(iterations_to_tolerance((16, 1e-3), (32, 1e-2), 1e-5), None);
    assert_eq!(iterations_to_tolerance((16, 1e-3), (32, 1e-3), 1e-5), None);
    assert_eq!(iterations_to_tolerance((16, 1e-3), (32, 0.0), 1e-5), None);
    assert_eq!(iterations_to_tolerance((16, 1e-2), (32, 1e-3), 0.0), None);
}

#[test]
fn adaptive_blocks_stop_close_to_where_every_iteration_is_checked() {
    let (w, h) = (64, 48);
    let frames = translating(w, h, 7, 0.4, -0.2, 5);
    let d = middle(&frames, 0.0, &no_prewarp());
    let lay = Layout::new(w, h);
    let p = FlowParams {
        max_iterations: 1000,
        tolerance_px: 1e-6,
        sor_omega: 1.0,
        ..params(FlowMethod::HornSchunck)
    };
    let problem = HsSystem::plain(&lay, &d, p.lambda);
    let mut st = SplitState::zeros(&lay);
    let (exact, ok) = problem.solve_with(&mut st, &p, Isa::detect(), 1, Some(1));
    assert!(ok && exact > 2 * MAX_BLOCK_ITERATIONS as u32, "{exact}");
    let mut st = SplitState::zeros(&lay);
    let (adaptive, ok) = problem.solve(&mut st, &p, Isa::detect());
    assert!(ok);
    assert!(
        adaptive >= exact && adaptive <= exact + 3,
        "checked every iteration: {exact}, adaptive blocks: {adaptive}"
    );
}
