//! One-line documentation of every pipeline knob, the one source of it: printed by `groovescope params`, shown as GUI tooltips and made the params fields' doc comments.

/// Defines [`KNOB_DOCS`] and `knob!`, which gives a key's line as a string literal for the doc
/// comment of its params field: the table is the one source of every knob's documentation.
macro_rules! knob_docs {
    ($($key:tt => $doc:tt,)*) => {
        /// `(table.key, what it does)` for every key of [`super::PipelineParams`], read by the TOML
        /// writer and the workbench's tooltips, and through `knob!` by the fields' doc comments; a
        /// test keeps it complete.
        pub const KNOB_DOCS: &[(&str, &str)] = &[$(($key, $doc)),*];

        /// The documentation line of a knob (`table.key`) as a string literal.
        macro_rules! knob {
            $(($key) => { $doc };)*
        }
    };
}

knob_docs! {
    "path"
        => "reconstruction path: auto (dual focus when scan.toml has [dual_focus]), depth, dual_focus",
    "method"
        => "decoder: fused (the default: both, weighted per frequency band; best or within 0.1 dB of the best in every measured case, docs/ACCURACY.md), edges (the walls' sub-pixel borders), flow (wall tilt by optical flow)",
    "derivatives.mode"
        => "simoncelli: 7-frame pre-blur + p5/d5 filters; two_frame: simple differences of frame pairs",
    "derivatives.prewarp"
        => "shift frames back by the known land motion before filtering (keeps steps > 1 px linear)",
    "flow.method"
        => "groove_horn_schunck (with ∂u/∂y = −u/(c·f) on the walls), horn_schunck, lucas_kanade",
    "flow.solver"
        => "gauss_seidel or jacobi iteration for the Horn–Schunck variants",
    "flow.lambda"
        => "smoothness weight λ (α); larger = smoother flow",
    "flow.max_iterations"
        => "iteration cap (paper: 100; the groove method's wall-estimating plain pass keeps its own cap of at least that)",
    "flow.tolerance_px"
        => "convergence threshold τ on the mean flow update, px (the groove method's wall-estimating plain pass keeps its own, tighter threshold)",
    "flow.gradient_threshold"
        => "pixels with a weaker gradient carry no flow (grey levels per px)",
    "flow.lk_window_px"
        => "Lucas–Kanade window side, px (odd)",
    "depth.kalman"
        => "run the Barron–Ngai–Spies Kalman filter (false: average per-frame depths)",
    "depth.process_noise"
        => "Kalman process noise of the planar-orientation state, per frame",
    "depth.measurement_noise_px2"
        => "Kalman measurement noise of one flow value, px²",
    "depth.median_px"
        => "side of the median filter on the state µ (paper: 5)",
    "depth.min_confidence"
        => "flow values with lower confidence are ignored",
    "walls.method"
        => "depth_levels: bands between the land and bottom depth levels about each wall's mid-depth crossing; slope_runs: runs of rows steeper than min_slope",
    "walls.min_slope"
        => "|∂Z/∂Y| above this marks a wall pixel (45° walls give 1); depth_levels: least mean slope of a wall band",
    "walls.trim_px"
        => "rows trimmed from each end of a wall band, px",
    "hough.gradient_threshold"
        => "in-focus pixels have a gradient magnitude above this",
    "hough.theta_min_deg"
        => "start of the θ range of the Hough transform, degrees",
    "hough.theta_max_deg"
        => "end of the θ range, degrees",
    "hough.theta_step_deg"
        => "θ bin width, degrees (coarser is faster)",
    "hough.rho_step_px"
        => "ρ bin width, px (ρ runs from 0 to the image height)",
    "hough.peak_count"
        => "peaks searched for: 3, the stripes the dual-focus geometry shows (any other value is refused)",
    "hough.window_theta_deg"
        => "half-width of a peak's window in θ, degrees",
    "hough.window_rho_px"
        => "half-width of a peak's window in ρ, px",
    "hough.line_smoothing_px"
        => "moving-average half-width of the centroid lines, px",
    "orientation.robust"
        => "Lorentzian M-estimator (false: plain least squares)",
    "orientation.neighbourhood_px"
        => "side of the fitting neighbourhood about each sample on a wall line, px (paper: 100)",
    "orientation.sigma_start_um"
        => "starting Lorentzian scale σ, µm of residual",
    "orientation.sigma_decay"
        => "σ is multiplied by this each round (0 < f ≤ 1)",
    "orientation.sigma_min_um"
        => "σ never falls below this, µm",
    "orientation.residual_tolerance_um"
        => "τ1: stop when the weighted mean residual falls below this, µm",
    "orientation.divergence_factor"
        => "τ2: stop (diverged) when the residual grows by more than this factor",
    "orientation.max_iterations"
        => "iteration cap of the robust fit",
    "orientation.outlier_sigmas"
        => "residuals beyond this many σ count as outliers in the report",
    "orientation.max_wall_slope_change"
        => "reject a fit whose cross-groove wall slope strays from the group's median by more than this fraction (0 = off)",
    "sound.output_rate_hz"
        => "output sample rate, Hz (8000 to 192000; 44100 or 48000 usual)",
    "sound.native_spacing_um"
        => "spacing of the native samples along the groove, µm (0: one output sample)",
    "sound.normalize_peak"
        => "peak level after normalisation (0 < p ≤ 1); 0 scales velocity by full_scale_mm_s",
    "sound.full_scale_mm_s"
        => "groove velocity mapped to full scale when not normalising, mm/s",
    "dsp.lowpass"
        => "apply the 2nd-order Butterworth low-pass",
    "dsp.lowpass_hz"
        => "its −3 dB cutoff, Hz",
    "dsp.eq"
        => "playback EQ: flat, riaa, turnover500, or custom (a 78 chart's turnover and roll-off, the three keys below)",
    "dsp.eq_turnover_hz"
        => "custom EQ: bass turnover, the +3 dB point of the bass boost, Hz (78 charts: 250 to 800, often 300, 400 or 500)",
    "dsp.eq_rolloff_db"
        => "custom EQ: treble roll-off, the cut at 10 kHz, dB (0 = none; the charts' 5, 8.5, 10.5, 12, 13.7 (75 µs, as RIAA) or 16)",
    "dsp.eq_shelf_hz"
        => "custom EQ: where the bass boost levels off, Hz (below the turnover; RIAA 50, some charts 40 or 100)",
    "flow.groove_weight"
        => "weight γ of the groove-orientation penalty, as a multiple of λ",
    "flow.sor_omega"
        => "over-relaxation ω of Gauss–Seidel (1 = plain; 1 < ω < 2 converges faster); Jacobi ignores it",
    "depth.neighbourhood_px"
        => "side of the neighbourhood whose flows measure each pixel's plane (odd, px)",
    "walls.smooth_px"
        => "half-side of the box smoothing the depth map before differencing, px",
    "walls.column_window_px"
        => "columns over which the median wall band is taken, px (centred: an even count takes one more)",
    "hough.min_votes_per_column"
        => "a peak needs this many votes per image column",
    "hough.min_peak_ratio"
        => "a peak needs this fraction of the strongest peak's votes",
    "hough.peak_rho_band_px"
        => "find peaks on votes summed over ±this many ρ px (0 = plain Hough), for wiggling stripes",
    "hough.max_vote_points"
        => "at most this many in-focus pixels vote (0 = all); beyond it every k-th votes",
    "dsp.dc_block"
        => "apply a first-order DC-blocking high-pass first (per-group tilt bias becomes DC)",
    "dsp.dc_block_hz"
        => "its −3 dB corner, Hz",
    "edges.wall_angle_deg"
        => "wall angle from the record plane (°); default 45 (the standard cutter, and the 45/45 stereo cut). Sets the bottom depth from the walls' widths and a wall's velocity scale",
    "edges.band_half_height_px"
        => "fewest rows read on each side of the predicted border (px); default 8",
    "edges.band_sigmas"
        => "rows read on each side of a blurred border, in its edge spreads σ (measured per border and group by pilot fits; never past half the way to the next border; edges::blur); 0 = always band_half_height_px; default 3",
    "edges.max_band_half_height_px"
        => "most rows a blurred border's band reads on each side (px): the fits' cost grows with it; default 24",
    "edges.noisy_band_half_height_px"
        => "that most on a noisy camera (pixel noise at least noisy_grey_levels): more rows average the noise down (edges::noise); at or below max_band_half_height_px = off; default 40",
    "edges.noisy_grey_levels"
        => "pixel noise σ, in grey levels of 255, from which a group's frames count as noisy (Immerkær's estimate on the reference frame); default 0.75",
    "edges.bin_px"
        => "width of the sub-pixel bins of the straightened profiles (px); default 0.25",
    "edges.coarse_column_step"
        => "the coarse strips read every this many columns; default 4",
    "edges.column_sigma_px"
        => "lorentzian σ of a column's offset from its sample's border (px); default 1",
    "edges.column_rounds"
        => "most fits per border and sample while rejecting dust columns; default 3",
    "edges.border_sigma_um"
        => "lorentzian σ of a border's disagreement with the others (µm); default 0.3",
    "edges.border_floor_um"
        => "floor of a border's standard error when weighting the borders (µm); default 0.02",
    "edges.max_bridge_samples"
        => "longest run of missing samples bridged by interpolation; default 3",
    "edges.weight_window_samples"
        => "samples over which a border's squared standard error is averaged (geometric mean) into its weight when the borders are combined, so the mix of borders stays steady; 0 or 1 = each sample its own; default 32",
    "edges.all_frames"
        => "fit every frame of a group (true), or only the frames the flow stages read (false): on the dual-focus path their middle 7-frame window, about 30 % less CPU a group on the paper's dual-focus camera for 0–0.5 dB of SNR (docs/PERFORMANCE.md), on the depth path every frame either way; default true",
    "edges.despike_sigmas"
        => "a wall's displacement sample further than this many robust σ from the cubic through its two neighbours on each side, and the largest such within two samples, is an isolated outlier and put back on that cubic (edges::despike); 0 = off; default 5",
    "edges.burst_sigmas"
        => "a burst of 2 to 8 samples of a wall's displacement whose mean lies further than this many σ from the cubic through the two samples on each side (σ the larger of its block's scale for such bursts and the local noise), read on the track smoothed by [1, 2, 1]/4, is a click and put on that cubic (edges::bursts); 0 = off, as before 0.3.0; default 8",
    "edges.max_slope"
        => "steepest slope a groove's modulation can have (µm sideways per µm along it; 1 = 45°, a loud record about 0.1): a wall's displacement track that moves faster between samples splits there, and a stretch of at most max_excursion_samples beside a longer one is solved again from the track around it, or left as a gap (edges::plausible); 0 = off; default 1",
    "edges.max_excursion_samples"
        => "longest stretch of a wall's displacement track, split from the rest by steps steeper than max_slope, that is taken for an excursion and solved again; default 16",
    "edges.restart_solves"
        => "where a sample's solve, started from the median of its borders, rejects one, solve it again from each border's own reading and keep a solution fewer borders disagree with (edges::robust); false = the median start alone, as before 0.3.0; default true",
    "edges.refine"
        => "refine each border with one smooth curve over the group (edges::refine); default true",
    "edges.hard_width_px"
        => "edge spread (σ, px) of the group's sharpest samples below which a border counts as sharp: the refinement then reads where it crosses rows, not each column's crossing; default 0.45",
    "edges.crossing_sigma_px"
        => "standard error of one row crossing beyond its column gap (px); default 0.05",
    "edges.anchor_sigma_px"
        => "standard error given each sample's own fit in the refinement, per frame read (px); default 2 (it only holds borders that cross no row)",
    "edges.spline_smoothness"
        => "weight of the refined curve's third differences (1/px²); default 3",
    "edges.spline_frames"
        => "frames (spread over the group, the reference among them) the refinement reads; default 3",
    "edges.border.fit_half_window_px"
        => "half-width of the stretch of profile around the seed that the fit reads (px); default 6",
    "edges.border.min_width_px"
        => "smallest edge-spread σ the fit may take (px); default 0.3 (a pixel's own aperture)",
    "edges.border.max_width_px"
        => "largest edge-spread σ (px); default 4",
    "edges.border.min_contrast"
        => "smallest |high − low| for a border (grey level, 1 = full scale); default 0.02",
    "edges.border.max_iterations"
        => "iteration cap of the fit; default 30",
    "edges.border.tolerance_px"
        => "the fit stops when the position moves by less than this (px); default 1e-5",
    "edges.differentiator.half_taps"
        => "taps on each side of the centred filter; default 6 (13 taps)",
    "edges.differentiator.band"
        => "upper end of the design band as a share of Nyquist; default 0.8",
    "edges.differentiator.aperture_samples"
        => "box average (samples) the input already carries, compensated over the band; default 1",
    "edges.differentiator.ridge"
        => "ridge weight on Σc² (relative to the band's weight of 1 per design point); default 1e-4",
    "edges.differentiator.min_run"
        => "fewest samples in a run for any velocity there (shorter runs are gaps); default 3",
    "fusion.block_samples"
        => "analysis block length (samples, a power of two; shorter clips use the largest power of two that fits); default 256",
    "fusion.smoothing_blocks"
        => "blocks on each side whose difference spectra are averaged with a block's own; default 4",
    "still.block_lines"
        => "still images: lines per detection block (its median cross profile finds the grooves)",
    "still.max_groove_width_um"
        => "widest groove looked for, µm (sets the window of the local light levels)",
    "still.min_wall_width_um"
        => "narrowest wall looked for, µm (never under 1.5 px)",
    "still.walls"
        => "dark (walls darker than the land) or bright",
    "still.min_contrast"
        => "smallest wall contrast, as a share of the local bright level",
    "still.max_gap_blocks"
        => "blocks a groove may be lost for (text, damage) and still be followed",
    "still.min_track_blocks"
        => "fewest blocks a groove must be found in",
    "still.search_share"
        => "half-width of each border's search about its prediction, as a share of its wall's width",
    "still.outlier_sigmas"
        => "a border this many robust σ from what the other borders say is an outlier",
    "still.path_window_um"
        => "groove length over which the slow path (skew, curvature, drift) is fitted as a quadratic and taken out, µm",
    "still.wall_angle_deg"
        => "wall angle from the record plane (stereo: border motion × sin of it = channel)",
    "still.max_lost_share"
        => "largest share of a groove that may be lost (blocks it was not found in, lines without a usable border) before it is refused (1 = never)",
    "still.border.fit_half_window_px"
        => "half-width of the profile stretch the edge-spread fit reads, px",
    "still.border.min_width_px"
        => "smallest edge-spread σ the fit may take, px",
    "still.border.max_width_px"
        => "largest edge-spread σ, px",
    "still.border.min_contrast"
        => "smallest step between the fitted levels (grey level, 1 = full scale)",
    "still.border.max_iterations"
        => "iteration cap of the fit",
    "still.border.tolerance_px"
        => "the fit stops when the position moves by less than this, px",
}

/// The documentation line of `key` (`table.key`), if any.
#[must_use]
pub fn knob_doc(key: &str) -> Option<&'static str> {
    KNOB_DOCS.iter().find(|(k, _)| *k == key).map(|(_, d)| *d)
}

/// TOML of `params` with each key preceded by its documentation comment.
///
/// # Errors
/// When serialisation fails.
pub fn documented_toml(params: &super::PipelineParams) -> Result<String, toml::ser::Error> {
    let plain = params.to_toml_string()?;
    let mut out = String::with_capacity(plain.len() * 3);
    let mut table = String::new();
    for line in plain.lines() {
        let trimmed = line.trim();
        if let Some(name) = trimmed.strip_prefix('[').and_then(|t| t.strip_suffix(']')) {
            table = name.to_string();
        } else if let Some((key, _)) = trimmed.split_once(" = ") {
            let full = if table.is_empty() {
                key.to_string()
            } else {
                format!("{table}.{key}")
            };
            if let Some(doc) = knob_doc(&full) {
                out.push_str("# ");
                out.push_str(doc);
                out.push('\n');
            }
        }
        out.push_str(line);
        out.push('\n');
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_default_key_is_documented() {
        let plain = super::super::PipelineParams::default()
            .to_toml_string()
            .unwrap();
        let doc = documented_toml(&super::super::PipelineParams::default()).unwrap();
        let keys = plain.lines().filter(|l| l.contains(" = ")).count();
        let comments = doc.lines().filter(|l| l.starts_with("# ")).count();
        assert_eq!(keys, comments, "undocumented keys in:\n{doc}");
        let back = super::super::PipelineParams::from_toml_str(&doc).unwrap();
        assert_eq!(back, super::super::PipelineParams::default());
    }
}
