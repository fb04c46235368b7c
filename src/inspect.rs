//! `groovescope inspect`: runs one group through every stage and dumps each intermediate output as PNG plus numbers.

use std::fmt::Write as _;
use std::path::Path;
use std::sync::Arc;

use anyhow::{Context, Result, bail};

use crate::io::{Scan, load_group, write_atomic};
use crate::pipeline::{GroupInput, PipelineParams, Stage, StageCache};
use crate::viz::{
    ColorMap, Rgba8Image, grey_image, heat_map, hough_image, robust_range, save_png,
    stripes_overlay,
};

/// Writes the in-focus map and the Hough accumulator image.
fn save_hough(
    out_dir: &Path,
    in_focus: &crate::image::Image,
    hough: &Rgba8Image,
    force: bool,
    written: &mut Vec<String>,
) -> Result<()> {
    save(
        out_dir,
        "in_focus.png",
        &grey_image(in_focus),
        force,
        written,
    )?;
    save(out_dir, "hough.png", hough, force, written)
}

fn save(
    dir: &Path,
    name: &str,
    img: &Rgba8Image,
    force: bool,
    written: &mut Vec<String>,
) -> Result<()> {
    save_png(img, &dir.join(name), force)?;
    written.push(name.to_string());
    Ok(())
}

/// Every file [`run_inspect`] can write.
const OUTPUT_NAMES: [&str; 12] = [
    "frame.png",
    "flow.png",
    "flow_u.png",
    "confidence.png",
    "depth.png",
    "stripes.png",
    "in_focus.png",
    "hough.png",
    "weights.png",
    "samples.csv",
    "edges.png",
    "edges.csv",
];

/// The edge stage's samples as CSV: each sample's groove position, every border's record `y`
/// and its standard error, every wall's displacement and velocity (NaN where none).
fn edges_csv(e: &crate::pipeline::edges::Edges) -> String {
    let mut csv = String::from("sample,s_um");
    for b in &e.borders {
        let name = b.id.name().replace(' ', "_");
        let _ = write!(csv, ",{name}_y_um,{name}_std_error_um");
    }
    for w in &e.walls {
        let side = format!("{:?}", w.side).to_lowercase();
        let _ = write!(
            csv,
            ",{side}_wall_displacement_um,{side}_wall_velocity_mm_s"
        );
    }
    csv.push('\n');
    let at = |v: &[f64], i: usize| v.get(i).copied().unwrap_or(f64::NAN);
    for (i, s) in e.positions_um.iter().enumerate() {
        let _ = write!(csv, "{i},{s}");
        for b in &e.borders {
            let _ = write!(csv, ",{},{}", at(&b.y_um, i), at(&b.std_error_um, i));
        }
        for w in &e.walls {
            let _ = write!(
                csv,
                ",{},{}",
                at(&w.displacement_um, i),
                at(&w.velocity_mm_s, i)
            );
        }
        csv.push('\n');
    }
    csv
}

/// Runs group `group` of `scan_dir` and writes PNGs and CSV files into `out_dir`.
///
/// Stages that fail are reported, and the outputs of the stages before them are still written,
/// so an operator can see where a disc fails. Ctrl-C stops it at the next stage, before
/// anything is written.
///
/// # Errors
/// When the scan or group cannot be read, or a file cannot be written.
pub fn run_inspect(
    scan_dir: &Path,
    group: usize,
    out_dir: &Path,
    params: &PipelineParams,
    force: bool,
) -> Result<()> {
    let scan = Scan::open(scan_dir)?;
    let Some(entry) = scan.groups.get(group) else {
        bail!(
            "group {group} does not exist (the scan has {} groups): {}",
            scan.groups.len(),
            scan_dir.display()
        );
    };
    let frames = load_group(entry)?;
    let input = GroupInput {
        group,
        frames: Arc::new(frames),
        first_frame: 0,
        meta: Arc::new(scan.meta.clone()),
    };
    let mut cache = StageCache::default();
    // Ctrl-C stops at the next stage; nothing is written then.
    let interrupted = crate::job::interrupted();
    let outcome = cache.run_from(Stage::Derivatives, &input, params, &mut |_, _| {
        !interrupted.load(std::sync::atomic::Ordering::Relaxed)
    });
    crate::cli::stop_if_interrupted("inspect")?;
    std::fs::create_dir_all(out_dir)
        .with_context(|| format!("cannot create folder: {}", out_dir.display()))?;
    let mut written = Vec::new();
    if let Some(d) = cache.derivatives().and_then(|d| d.get(d.len() / 2)) {
        save(
            out_dir,
            "frame.png",
            &grey_image(&d.image),
            force,
            &mut written,
        )?;
    }
    if let Some(f) = cache.flows().and_then(|f| f.get(f.len() / 2)) {
        let land = scan.meta.geometry().land_flow_px() as f32;
        save(
            out_dir,
            "flow.png",
            &crate::viz::flow_image(f, land),
            force,
            &mut written,
        )?;
        save(
            out_dir,
            "flow_u.png",
            &heat_map(&f.u, robust_range(&f.u.data), ColorMap::Viridis),
            force,
            &mut written,
        )?;
        save(
            out_dir,
            "confidence.png",
            &heat_map(&f.confidence, None, ColorMap::Inferno),
            force,
            &mut written,
        )?;
    }
    if let Some(depth) = cache.depth() {
        save(
            out_dir,
            "depth.png",
            &heat_map(
                &depth.map.z_um,
                robust_range(&depth.map.z_um.data),
                ColorMap::Viridis,
            ),
            force,
            &mut written,
        )?;
    }
    if let Some(st) = cache.stripes() {
        let frame = cache
            .derivatives()
            .as_ref()
            .and_then(|d| d.get(d.len() / 2))
            .map(|d| d.image.clone())
            .unwrap_or_default();
        let hough = hough_image(&st.accumulator, &st.peaks, Some(st.dropped));
        save_hough(out_dir, &st.in_focus, &hough, force, &mut written)?;
        save(
            out_dir,
            "stripes.png",
            &stripes_overlay(&frame, st),
            force,
            &mut written,
        )?;
    }
    let stripes_failed = cache.stripes().is_none()
        && outcome.is_err()
        && cache.flows().is_some()
        && params.uses_dual_focus(&input.meta);
    if stripes_failed {
        // Segmentation failed: the in-focus map and the accumulator with its peaks show why.
        let mid = |n: usize| n / 2;
        if let (Some(d), Some(f)) = (
            cache.derivatives().and_then(|d| d.get(mid(d.len()))),
            cache.flows().and_then(|f| f.get(mid(f.len()))),
        ) && let Ok((in_focus, acc, peaks)) =
            crate::pipeline::hough::hough_diagnostics(d, f, &params.hough)
        {
            let hough = hough_image(&acc, &peaks, None);
            save_hough(out_dir, &in_focus, &hough, force, &mut written)?;
        }
    }
    if let Some(o) = cache.orientation() {
        save(
            out_dir,
            "weights.png",
            &heat_map(
                &o.orientation.weight_map,
                Some((0.0, 1.0)),
                ColorMap::Inferno,
            ),
            force,
            &mut written,
        )?;
        let mut csv = String::from("wall,x_px,s_um,tan_theta,outlier_fraction,a,b\n");
        for wall in &o.orientation.walls {
            for smp in &wall.samples {
                let s_um = o.grid.column0_um + f64::from(smp.x_px) * o.grid.um_per_px;
                let (of, a, b) = smp.fit.map_or((f64::NAN, f64::NAN, f64::NAN), |f| {
                    (f.outlier_fraction, f.a, f.b)
                });
                let _ = writeln!(
                    csv,
                    "{:?},{},{s_um},{},{of},{a},{b}",
                    wall.side, smp.x_px, smp.tan_theta
                );
            }
        }
        write_atomic(&out_dir.join("samples.csv"), csv.as_bytes(), force)?;
        written.push("samples.csv".into());
    }
    if let Some(e) = cache.edges() {
        if let Some(frame) = input.frames.get(e.coarse.frame) {
            let img = crate::viz::edges_overlay(frame, e);
            save(out_dir, "edges.png", &img, force, &mut written)?;
        }
        write_atomic(&out_dir.join("edges.csv"), edges_csv(e).as_bytes(), force)?;
        written.push("edges.csv".into());
    }
    // What an earlier inspect left here and this one did not write (a stage that failed or
    // did not run on this path) would pass for this group's; it is named, never removed.
    let stale: Vec<&str> = OUTPUT_NAMES
        .iter()
        .copied()
        .filter(|name| !written.iter().any(|w| w == name) && out_dir.join(name).is_file())
        .collect();
    crate::say!(
        "wrote {} files into {}: {}",
        written.len(),
        out_dir.display(),
        written.join(", ")
    )?;
    if !stale.is_empty() {
        crate::tell!(
            "warning: {} in {} are not from this run (an earlier inspect left them)",
            stale.join(", "),
            out_dir.display()
        );
    }
    if let Err(e) = outcome {
        bail!("group {group}: {e}");
    }
    Ok(())
}
