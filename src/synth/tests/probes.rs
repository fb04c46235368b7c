//! Probes run by hand (`--ignored`): timings of a paper-sized group and its parts, and preview scans for eyeballing.

use super::*;

/// Timing of one paper-sized group (run with `--ignored --nocapture`; the criterion bench
/// `benches/synth.rs` measures the same in release).
#[test]
#[ignore = "timing, not a check"]
fn time_a_paper_sized_group() {
    let sound = tone(1000.0, 0.02, 44_100);
    for (name, cfg) in [
        (
            "plain",
            SynthConfig {
                max_groups: Some(1),
                damage: SynthConfig::demo().damage,
                ..SynthConfig::default()
            },
        ),
        (
            "dual focus",
            SynthConfig {
                max_groups: Some(1),
                ..SynthConfig::dual_focus_demo()
            },
        ),
    ] {
        let g = Groove::new(&sound, &cfg).unwrap();
        let t0 = std::time::Instant::now();
        let frames = g.render_group(0);
        let secs = t0.elapsed().as_secs_f64();
        eprintln!(
            "{name}: {} frames of {}x{} in {secs:.2} s on {} threads",
            frames.len(),
            cfg.width_px,
            cfg.height_px,
            rayon::current_num_threads()
        );
    }
}

#[test]
#[ignore = "timing, not a check"]
fn time_the_parts() {
    let sound = tone(1000.0, 0.02, 44_100);
    let cfg = SynthConfig {
        max_groups: Some(1),
        ..SynthConfig::demo()
    };
    let g = Groove::new(&sound, &cfg).unwrap();
    let n = 1_000_000;
    let t0 = std::time::Instant::now();
    let mut acc = 0.0f64;
    for i in 0..n {
        acc += f64::from(noise::marble([i as f64 * 0.39, 17.0, 3.0], 3.0, 1));
    }
    eprintln!(
        "marble {:.0} ns",
        t0.elapsed().as_secs_f64() * 1e9 / n as f64
    );
    let t0 = std::time::Instant::now();
    for i in 0..n {
        acc += g.depth_um(i as f64 * 0.0005, -60.0 + (i % 1000) as f64 * 0.1);
    }
    eprintln!(
        "depth {:.0} ns",
        t0.elapsed().as_secs_f64() * 1e9 / n as f64
    );
    let t0 = std::time::Instant::now();
    for i in 0..n {
        acc += g
            .radiance(i as f64 * 0.0005, -60.0 + (i % 1000) as f64 * 0.1)
            .1;
    }
    eprintln!(
        "radiance {:.0} ns",
        t0.elapsed().as_secs_f64() * 1e9 / n as f64
    );
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let t0 = std::time::Instant::now();
    let f = pool.install(|| g.render_frame(0, 0));
    eprintln!(
        "frame {:.0} ns/px single thread {acc} {}",
        t0.elapsed().as_secs_f64() * 1e9 / (f.width * f.height) as f64,
        f.data[0]
    );
}

#[test]
#[ignore = "timing, not a check"]
fn time_the_blur() {
    let img = Image::from_fn(1280, 1024, |x, y| ((x * 7 + y * 13) % 17) as f32 / 16.0);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    for s in [0.8, 2.5, 10.0] {
        let t0 = std::time::Instant::now();
        let b = pool.install(|| blur::gaussian_blur(&img, s));
        eprintln!(
            "gauss {s}: {:.1} ms {}",
            t0.elapsed().as_secs_f64() * 1e3,
            b.data[5]
        );
    }
    let sigma = Image::filled(1280, 1024, 40.0);
    let t0 = std::time::Instant::now();
    let b = pool.install(|| blur::BlurStack::apply(&img, &sigma));
    eprintln!(
        "stack: {:.1} ms {}",
        t0.elapsed().as_secs_f64() * 1e3,
        b.data[5]
    );
}
/// Writes one-group demo scans for eyeballing: `SYNTH_PREVIEW_DIR=/tmp/x cargo test ... -- --ignored preview`.
#[test]
#[ignore = "writes preview scans"]
fn preview_scans() {
    let Ok(dir) = std::env::var("SYNTH_PREVIEW_DIR") else {
        return;
    };
    let dir = Path::new(&dir);
    let sound = chord(&[440.0, 1320.0], 0.05, 44_100);
    for (name, cfg) in [
        ("demo", SynthConfig::demo()),
        (
            "paper",
            SynthConfig {
                max_groups: Some(1),
                ..SynthConfig::default()
            },
        ),
        (
            "fig20",
            SynthConfig {
                max_groups: Some(3),
                ..SynthConfig::dual_focus_fig20()
            },
        ),
    ] {
        let sum = render_scan(&sound, &cfg, &dir.join(name), Job::unwatched()).unwrap();
        eprintln!("{name}: {sum:?}");
        // A half-size 8-bit copy of one frame, and a full-resolution crop of its centre.
        let g = if sum.groups > 1 { "g00001" } else { "g00000" };
        let f = crate::io::load_frame(&dir.join(name).join(g).join("f000.png")).unwrap();
        let half = Image::from_fn(f.width / 2, f.height / 2, |x, y| {
            0.25 * (f.data[2 * y * f.width + 2 * x]
                + f.data[2 * y * f.width + 2 * x + 1]
                + f.data[(2 * y + 1) * f.width + 2 * x]
                + f.data[(2 * y + 1) * f.width + 2 * x + 1])
        });
        save_grey_png(&half, &dir.join(format!("{name}_half.png")), false, true).unwrap();
        let crop = Image::from_fn(256, 256, |x, y| {
            f.data[(y + f.height / 2 - 128) * f.width + x + f.width / 2 - 128]
        });
        save_grey_png(&crop, &dir.join(format!("{name}_crop.png")), false, true).unwrap();
    }
    for kind in [SceneKind::Cube, SceneKind::Cylinder, SceneKind::Sphere] {
        let (img, _) = scene::render_scene_frame(kind, &SceneConfig::default(), 0).unwrap();
        save_grey_png(&img, &dir.join(format!("{kind:?}.png")), false, true).unwrap();
    }
}
