//! The whole accuracy suite: every case rendered, reconstructed and scored into one markdown report.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use super::methods::{MethodScores, score_methods};
use super::{
    AccuracyError, AccuracyOptions, PHRASE, SceneDepthRow, TABLE2_FRAMES, case_err, heavy_damage,
    onset_secs, output_rate_hz, render, render_tone, scene_depth_table, score_scan,
    small_dual_focus, small_lateral, snr_from_r_db, sound_params, speak, two_sample_window_px,
};
use crate::io::wav::read_wav;
use crate::pipeline::edges::EdgeParams;
use crate::pipeline::eval::Scores;
use crate::pipeline::fusion::FusionParams;
use crate::pipeline::walls::WallMethod;
use crate::pipeline::{PathChoice, PipelineParams};
use crate::synth::{BUILTIN_RATE_HZ, SceneConfig, SceneKind, SynthConfig, arpeggio};

struct Report {
    md: String,
}

impl Report {
    fn line(&mut self, s: &str) {
        self.md.push_str(s);
        self.md.push('\n');
    }
}

/// r, SNR and SNR(r), for steady tones (whose envelope is flat, so envelope r says nothing).
fn tone_cells(s: &Scores) -> String {
    format!("{:.3} | {:.1} | {:.1}", s.r, s.snr_db, snr_from_r_db(s.r))
}

/// Where a tone table's scans go and what they are: case `"{f} Hz tone ({name})"`, folder
/// `work/{folder}_{f}`, rendered with `cfg`.
struct ToneScans<'a> {
    name: &'a str,
    folder: &'a str,
    work: &'a Path,
    cfg: SynthConfig,
}

/// A tone table: its head, then per frequency one scan rendered and scored with each of `runs`
/// (column label, params), a row of r, SNR and SNR(r) per run, and one log line. Each scan is
/// added to `decoders` for the decoders' section.
fn tone_table(
    rep: &mut Report,
    log: &mut dyn FnMut(&str),
    scans: &ToneScans<'_>,
    freqs: &[f64],
    runs: &[(String, PipelineParams)],
    decoders: &mut Vec<DecoderCase>,
) -> Result<(), AccuracyError> {
    let mut head = String::from("| tone |");
    for (label, _) in runs {
        head.push_str(&format!(" r ({label}) | SNR dB | SNR(r) dB |"));
    }
    rep.line(&head);
    rep.line(&format!("|---:|{}", "---:|".repeat(3 * runs.len())));
    for &f in freqs {
        let case = format!("{f} Hz tone ({})", scans.name);
        let dir = scans.work.join(format!("{}_{f}", scans.folder));
        render_tone(&case, f, &scans.cfg, &dir)?;
        decoders.push(DecoderCase {
            label: format!("{f} Hz tone, {}", scans.name),
            dir: dir.clone(),
            steady: true,
        });
        let mut cells = Vec::new();
        for (_, params) in runs {
            cells.push(score_scan(&case, &dir, params)?.0);
        }
        rep.line(&format!(
            "| {f} Hz | {} |",
            cells.iter().map(tone_cells).collect::<Vec<_>>().join(" | ")
        ));
        let r: Vec<String> = cells.iter().map(|s| format!("{:.3}", s.r)).collect();
        let snr: Vec<String> = cells.iter().map(|s| format!("{:.1}", s.snr_db)).collect();
        log(&format!(
            "{case}: r {}, SNR {} dB",
            r.join(" / "),
            snr.join(" / ")
        ));
    }
    rep.line("");
    Ok(())
}

/// A rendered scan that the decoders' section scores with every method.
struct DecoderCase {
    /// The row's name.
    label: String,
    /// The scan folder.
    dir: PathBuf,
    /// A steady tone (its envelope r says nothing, so the row leaves it out).
    steady: bool,
}

/// The params of the decoders' section: `reconstruct`'s defaults with the low-pass off, so
/// that tones above its 3 kHz are measured too.
fn decoder_params() -> PipelineParams {
    let mut p = PipelineParams::default();
    p.dsp.lowpass = false;
    p
}

/// The decoders' section: every scan of `cases` scored with the flow, edge and fused methods
/// (`accuracy::methods::score_methods`), one row each, and one log line each.
fn decoder_section(
    log: &mut dyn FnMut(&str),
    cases: &[DecoderCase],
) -> Result<String, AccuracyError> {
    let mut rep = Report { md: String::new() };
    rep.line("## The three decoders: flow, edges and fused (the default)");
    rep.line("");
    rep.line(
        "Every scan of the sections below, reconstructed as `groovescope reconstruct SCAN \
         --method M` does with the default params but the low-pass off (so that tones above its \
         3 kHz are measured): the flow method (the paper's), the edge method (the borders \
         between wall and land, which move by the whole displacement) and the fused decoder \
         that `reconstruct` uses unless told otherwise; the last two columns are the fused \
         decoder with every default, the 3 kHz low-pass included (what `reconstruct SCAN` \
         gives: the edges' noise rises 6 dB per octave, and speech has little above 3 kHz). \
         The sections after this one measure the flow method's own knobs. env r: only where \
         the sound is not a steady tone.",
    );
    rep.line("");
    rep.line(
        "| scan | flow r | flow SNR dB | edges r | edges SNR dB | fused r | fused env r | fused SNR dB | fused r, defaults | SNR dB |",
    );
    rep.line("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    let params = decoder_params();
    for case in cases {
        let MethodScores {
            flow, edges, fused, ..
        } = score_methods(
            &case.label,
            &case.dir,
            &params,
            &EdgeParams::default(),
            &FusionParams::default(),
        )?;
        let (defaults, _) = score_scan(&case.label, &case.dir, &PipelineParams::default())?;
        let env = if case.steady {
            "—".to_string()
        } else {
            fused.envelope_r_text(3)
        };
        rep.line(&format!(
            "| {} | {:.3} | {:.1} | {:.3} | {:.1} | {:.3} | {env} | {:.1} | {:.3} | {:.1} |",
            case.label,
            flow.r,
            flow.snr_db,
            edges.r,
            edges.snr_db,
            fused.r,
            fused.snr_db,
            defaults.r,
            defaults.snr_db
        ));
        log(&format!(
            "{} by decoder: SNR flow {:.1}, edges {:.1}, fused {:.1} dB; fused with the defaults \
             {:.1} dB",
            case.label, flow.snr_db, edges.snr_db, fused.snr_db, defaults.snr_db
        ));
    }
    rep.line("");
    Ok(rep.md)
}

fn score_cells(s: &Scores) -> String {
    format!(
        "{:.3} | {} | {:.1} | {:.1}",
        s.r,
        s.envelope_r_text(3),
        s.snr_db,
        snr_from_r_db(s.r)
    )
}

/// Runs the whole suite and returns the markdown report. `log` receives one line per finished
/// case.
///
/// # Errors
/// [`AccuracyError`] naming the case that failed.
pub fn run_suite(
    opts: &AccuracyOptions,
    log: &mut dyn FnMut(&str),
) -> Result<String, AccuracyError> {
    let started = Instant::now();
    let tmp;
    let work: PathBuf = match &opts.keep {
        Some(dir) => {
            let empty = crate::io::atomic::dir_is_missing_or_empty(dir)?;
            if !empty {
                return Err(case_err(
                    "--keep",
                    format!("the folder is not empty: {}", dir.display()),
                ));
            }
            std::fs::create_dir_all(dir)
                .map_err(|e| case_err("--keep", format!("{e}: {}", dir.display())))?;
            dir.clone()
        }
        None => {
            tmp = tempfile::tempdir().map_err(|e| case_err("work folder", e))?;
            tmp.path().to_path_buf()
        }
    };
    let mut rep = Report { md: String::new() };
    let threads = rayon::current_num_threads();
    rep.line("# groovescope accuracy report");
    rep.line("");
    rep.line(&format!(
        "Made by `groovescope accuracy{}` (groovescope {}, {} threads). Every figure is measured \
         against the generator's ground truth: the reference sound of a rendered scan or the \
         true depth map of a rendered scene. r: Pearson r of the waveforms at the best lag \
         (searched within ±0.3 ms, refined to a fraction of a sample); env r: r of the peak envelopes; SNR: 10·log10(Σref²/Σ(ref − g·rec)²) after \
         the best gain (a DC offset counts as noise); SNR(r): the SNR that r alone implies, \
         10·log10(r²/(1 − r²)). Steady tones have flat envelopes, so their tables leave \
         envelope r out.",
        if opts.quick { " --quick" } else { "" },
        env!("CARGO_PKG_VERSION"),
        threads
    ));
    rep.line("");
    // The decoders' section goes here once every scan is rendered.
    let decoders_at = rep.md.len();
    let mut decoders = Vec::new();

    // --- Tones, dual-focus path.
    let small = small_dual_focus(1);
    let w2 = two_sample_window_px(&small);
    let tone_groups = if opts.quick { 8 } else { 16 };
    let freqs: &[f64] = if opts.quick {
        &[500.0, 1000.0, 2000.0, 5000.0]
    } else {
        &[200.0, 500.0, 1000.0, 2000.0, 5000.0, 10_000.0, 20_000.0]
    };
    rep.line("## Sinusoids, dual-focus path");
    rep.line("");
    rep.line(&format!(
        "The small camera (`accuracy::small_dual_focus`): 320×384 px frames of 0.78 µm, 7 frames \
         a group, a 16⅔ rpm disc at 60 mm (Vt ≈ {:.0} mm/s, one 44.1 kHz output sample every \
         {:.1} px), cover glass 0.11 mm n = 1.515, NA 0.45, 20 mm/s peak velocity, {} groups \
         (≈ {:.0} ms of sound) per tone. Low-pass off, except in the last three columns, which \
         add the default 2nd-order Butterworth low-pass at 3 kHz (it attenuates the 5 kHz and \
         higher tones themselves; r ignores gain). Orientation window: the default 100 px, and \
         {} px (about two output samples).",
        small.groove_speed_um_s() / 1000.0,
        small.groove_speed_um_s() / output_rate_hz() / small.pixel_pitch_um,
        tone_groups,
        tone_groups as f64 * small.group_step_um() / small.groove_speed_um_s() * 1000.0,
        w2
    ));
    rep.line("");
    let mut lp = sound_params(w2, true);
    lp.dsp.lowpass = true;
    let runs = [
        ("100 px".to_string(), sound_params(100, true)),
        (format!("{w2} px"), sound_params(w2, true)),
        (format!("{w2} px, 3 kHz LP"), lp),
    ];
    let scans = ToneScans {
        name: "dual focus",
        folder: "tone_df",
        work: &work,
        cfg: small_dual_focus(tone_groups),
    };
    tone_table(&mut rep, log, &scans, freqs, &runs, &mut decoders)?;

    // --- Tones, depth path.
    let lat = small_lateral(1);
    let wl = two_sample_window_px(&lat);
    let depth_groups = if opts.quick { 4 } else { 12 };
    let depth_freqs: &[f64] = if opts.quick {
        &[1000.0]
    } else {
        &[200.0, 500.0, 1000.0, 2000.0, 5000.0]
    };
    rep.line("## Sinusoids, depth path (no cover glass: flow → Kalman depth → orientation)");
    rep.line("");
    rep.line(&format!(
        "The same camera and disc (`accuracy::small_lateral`), everything in focus, 12 frames a \
         group, a 180 µm wide 70 µm deep groove, {depth_groups} groups per tone. Walls found by \
         depth levels (the default), with the orientation window at the default 100 px, at \
         {wl} px, and at {wl} px with the 3 kHz low-pass; the last columns find the walls by \
         slope runs (the method before 29 Nov 2026) at {wl} px, low-pass off."
    ));
    rep.line("");
    let depth_params = |window: usize, lowpass: bool, walls: WallMethod| {
        let mut p = sound_params(window, true);
        p.path = PathChoice::Depth;
        p.dsp.lowpass = lowpass;
        p.walls.method = walls;
        p
    };
    let runs = [
        (
            "100 px".to_string(),
            depth_params(100, false, WallMethod::DepthLevels),
        ),
        (
            format!("{wl} px"),
            depth_params(wl, false, WallMethod::DepthLevels),
        ),
        (
            format!("{wl} px, 3 kHz LP"),
            depth_params(wl, true, WallMethod::DepthLevels),
        ),
        (
            format!("slope runs, {wl} px"),
            depth_params(wl, false, WallMethod::SlopeRuns),
        ),
    ];
    let scans = ToneScans {
        name: "depth path",
        folder: "tone_depth",
        work: &work,
        cfg: small_lateral(depth_groups),
    };
    tone_table(&mut rep, log, &scans, depth_freqs, &runs, &mut decoders)?;

    // --- Speech, clean and damaged.
    let speech_groups = if opts.quick { 45 } else { 228 };
    rep.line("## Speech (espeak-ng), clean and damaged");
    rep.line("");
    match speak(PHRASE, &work).and_then(|wav| read_wav(&wav).ok()) {
        None => {
            rep.line("Skipped: `espeak-ng` is not installed or failed.");
            log("speech: skipped (espeak-ng missing)");
        }
        Some(speech) => {
            let onset = onset_secs(&speech);
            let clean = SynthConfig {
                start_secs: onset,
                ..small_dual_focus(speech_groups)
            };
            let damaged = SynthConfig {
                damage: heavy_damage(),
                ..clean.clone()
            };
            let dur = speech_groups as f64 * clean.group_step_um() / clean.groove_speed_um_s();
            rep.line(&format!(
                "`espeak-ng -s 160 \"{PHRASE}\"`, from its onset ({onset:.3} s), {speech_groups} \
                 groups (≈ {dur:.2} s) on the small dual-focus camera. The damaged groove adds \
                 {} scratches/mm, {} dust particles/mm² and {} missing wall chunks/mm (150 µm \
                 long, 45% of the wall). Robust: the Lorentzian M-estimator; LS: plain least \
                 squares.",
                heavy_damage().scratches_per_mm,
                heavy_damage().dust_per_mm2,
                heavy_damage().missing_wall_chunks_per_mm
            ));
            rep.line("");
            rep.line("| groove | fit | window | r | env r | SNR dB | SNR(r) dB |");
            rep.line("|---|---|---:|---:|---:|---:|---:|");
            for (name, cfg) in [("clean", &clean), ("damaged", &damaged)] {
                let case = format!("speech ({name})");
                let dir = work.join(format!("speech_{name}"));
                render(&case, &speech, cfg, &dir)?;
                decoders.push(DecoderCase {
                    label: case.clone(),
                    dir: dir.clone(),
                    steady: false,
                });
                let fits: &[bool] = if name == "clean" {
                    &[true]
                } else {
                    &[true, false]
                };
                for &robust in fits {
                    for window in [100, w2] {
                        let (s, _) = score_scan(&case, &dir, &sound_params(window, robust))?;
                        let fit = if robust { "robust" } else { "LS" };
                        rep.line(&format!(
                            "| {name} | {fit} | {window} px | {} |",
                            score_cells(&s)
                        ));
                        log(&format!(
                            "{case}, {fit}, {window} px: r {:.3}, env r {}, SNR {:.1} dB",
                            s.r,
                            s.envelope_r_text(3),
                            s.snr_db
                        ));
                    }
                }
            }
        }
    }
    rep.line("");

    // --- Melody.
    if !opts.quick {
        let case = "melody";
        let note = 0.03;
        let sound = arpeggio(note, BUILTIN_RATE_HZ);
        let groups = (4.0 * note * small.groove_speed_um_s() / small.group_step_um()) as usize;
        let dir = work.join("melody");
        render(case, &sound, &small_dual_focus(groups.max(1)), &dir)?;
        decoders.push(DecoderCase {
            label: case.to_string(),
            dir: dir.clone(),
            steady: false,
        });
        let (s, _) = score_scan(case, &dir, &sound_params(w2, true))?;
        rep.line("## Melody");
        rep.line("");
        rep.line(&format!(
            "C5 E5 G5 C6, {:.0} ms each, {} groups on the small dual-focus camera, window {w2} px.",
            note * 1000.0,
            groups
        ));
        rep.line("");
        rep.line("| sound | r | env r | SNR dB | SNR(r) dB |");
        rep.line("|---|---:|---:|---:|---:|");
        rep.line(&format!("| melody | {} |", score_cells(&s)));
        rep.line("");
        log(&format!("melody: r {:.3}, SNR {:.1} dB", s.r, s.snr_db));
    }

    // --- Paper Fig. 20: half a wall missing.
    {
        let case = "Fig. 20 scan";
        let groups = if opts.quick { 4 } else { 6 };
        let cfg = SynthConfig {
            max_groups: Some(groups),
            ..SynthConfig::dual_focus_fig20()
        };
        let dir = work.join("fig20");
        render_tone(case, 1000.0, &cfg, &dir)?;
        decoders.push(DecoderCase {
            label: format!("{case} (1 kHz tone)"),
            dir: dir.clone(),
            steady: true,
        });
        let robust = score_scan(case, &dir, &sound_params(100, true))?.0;
        let ls = score_scan(case, &dir, &sound_params(100, false))?.0;
        rep.line("## Paper Fig. 20: nearly half of a wall missing");
        rep.line("");
        rep.line(&format!(
            "`SynthConfig::dual_focus_fig20()`: the paper's optics (1280×1024 px of 0.39 µm, 12 \
             frames of 0.78 µm, 78 rpm at 115 mm), the upper 45% of the right wall missing from \
             300 to 1300 µm, a 1 kHz tone, {groups} groups, window 100 px."
        ));
        rep.line("");
        rep.line("| fit | r | SNR dB | SNR(r) dB |");
        rep.line("|---|---:|---:|---:|");
        rep.line(&format!("| robust | {} |", tone_cells(&robust)));
        rep.line(&format!("| least squares | {} |", tone_cells(&ls)));
        rep.line("");
        rep.line(&format!(
            "The robust fit gains Δr = {:+.3} over plain least squares.",
            robust.r - ls.r
        ));
        rep.line("");
        log(&format!(
            "Fig. 20: robust r {:.3}, LS r {:.3}",
            robust.r, ls.r
        ));
    }

    // --- Table 2 depth scenes.
    rep.line("## Depth scenes (paper §5.2, Table 2)");
    rep.line("");
    let scene = SceneConfig::default();
    rep.line(&format!(
        "`groovescope synth-scene` scenes: {}×{} px, focal length {} px, the background plane at \
         {} µm, the object's centre at {} µm, {} µm objects, the camera moving {} µm per frame; \
         derivatives, plain Horn–Schunck and the Kalman depth stage with default params. \
         Relative depth error |Z − Z_true|/Z_true on the object's pixels (an 8 px border left \
         out); the last column is the mean over every pixel, background included. The paper's \
         Kalman filter reached a mean error of about 7–9% at frame 27.",
        scene.width_px,
        scene.height_px,
        scene.focal_px,
        scene.plane_distance_um,
        scene.object_distance_um,
        scene.object_size_um,
        scene.frame_step_um
    ));
    rep.line("");
    rep.line("| scene | frame | < 5% | 5–15% | > 15% | mean ± σ (%) | all pixels mean (%) |");
    rep.line("|---|---:|---:|---:|---:|---:|---:|");
    let params = PipelineParams::default();
    let kinds: &[SceneKind] = if opts.quick {
        &[SceneKind::Sphere]
    } else {
        &[SceneKind::Cube, SceneKind::Cylinder, SceneKind::Sphere]
    };
    for &kind in kinds {
        let rows = scene_depth_table(kind, &scene, &TABLE2_FRAMES, &params)?;
        for SceneDepthRow { object: o, all: a } in &rows {
            rep.line(&format!(
                "| {kind:?} | {} | {:.1} | {:.1} | {:.1} | {:.2} ± {:.2} | {:.2} |",
                o.frame, o.below_5, o.from_5_to_15, o.above_15, o.mean, o.sigma, a.mean
            ));
        }
        if let Some(row) = rows.iter().find(|r| r.object.frame == 27) {
            log(&format!(
                "{kind:?}: frame 27 mean error {:.2}%",
                row.object.mean
            ));
        }
    }
    rep.line("");
    let section = decoder_section(log, &decoders)?;
    rep.md.insert_str(decoders_at, &section);
    let _ = writeln!(
        rep.md,
        "Suite time: {:.0} s.",
        started.elapsed().as_secs_f64()
    );
    Ok(rep.md)
}
