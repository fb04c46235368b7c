//! Fuzz targets: every parser and loader groovescope runs on files from outside, as `fn(&[u8])`.
//!
//! Shared by the libFuzzer binary (`fuzz/fuzz_targets/groovescope.rs`) and the corpus replay
//! in `tests/hostile_corpus.rs`, so every seed and every crash found runs in `cargo test`.
//! A target must never panic: errors are fine, panics are bugs; each also asserts what must
//! hold of what it accepted (round trips, sizes, value ranges). Adding a target is one
//! function here and one line in [`TARGETS`] (its seeds go in `fuzz/corpus/NAME/`).

use std::io::Cursor;
use std::path::Path;
use std::sync::atomic::AtomicBool;

use arbitrary::Unstructured;
use groovescope::engine::{ReconstructOptions, reconstruct};
use groovescope::io::frames::{RawFrame, RawSamples, grey_from_raw};
use groovescope::io::frames::{check_frame_bytes, decode_frame};
use groovescope::io::still::save_grey_image;
use groovescope::io::zarr::{ChunkLayout, SampleType, ZarrWriter, chunk_file};
use groovescope::io::{Scan, ScanMeta, flo, load_group, wav};
use groovescope::meta::Cut;
use groovescope::pipeline::PipelineParams;
use groovescope::pipeline::still::{Axis, StillSetup};
use groovescope::still::decode_still_file;
use groovescope::synth::still::{StillConfig, StillScene, render_still};

/// One fuzz target: its name (the corpus folder and `GROOVESCOPE_FUZZ_TARGET`) and function.
pub struct Target {
    /// Name of the target.
    pub name: &'static str,
    /// Runs one input; panics only on a bug.
    pub run: fn(&[u8]),
}

/// Every target, in the order `scripts/fuzz.sh` runs them.
pub const TARGETS: &[Target] = &[
    Target {
        name: "scan_toml",
        run: scan_toml,
    },
    Target {
        name: "params_toml",
        run: params_toml,
    },
    Target {
        name: "frame",
        run: frame,
    },
    Target {
        name: "scan_folder",
        run: scan_folder,
    },
    Target {
        name: "reference_wav",
        run: reference_wav,
    },
    Target {
        name: "flo",
        run: flo_file,
    },
    Target {
        name: "still",
        run: still_image,
    },
    Target {
        name: "zarr_store",
        run: zarr_store,
    },
];

/// The target called `name`.
#[must_use]
pub fn target(name: &str) -> Option<&'static Target> {
    TARGETS.iter().find(|t| t.name == name)
}

/// `scan.toml`: whatever validates writes back to text that reads back to the same text.
pub fn scan_toml(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let path = Path::new("scan.toml");
    let Ok(meta) = ScanMeta::from_toml_str(text, path) else {
        return;
    };
    let written = meta
        .to_toml_string()
        .expect("validated metadata serialises");
    let again = ScanMeta::from_toml_str(&written, path).expect("written metadata reads back");
    let rewritten = again
        .to_toml_string()
        .expect("read-back metadata serialises");
    assert_eq!(written, rewritten, "scan.toml does not round-trip");
    let geometry = meta.geometry();
    assert!(geometry.focal_px.is_finite() || geometry.focal_px.is_infinite());
    let _ = meta.groove_speed_mm_s(0);
    let _ = meta.check_against_scan(3, (64, 48));
}

/// The params / preset TOML: parse, validate, round-trip whatever validates.
pub fn params_toml(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(params) = PipelineParams::from_toml_str(text) else {
        return;
    };
    if params.validate().is_err() {
        return;
    }
    let written = params.to_toml_string().expect("valid params serialise");
    let again = PipelineParams::from_toml_str(&written).expect("written params read back");
    assert_eq!(
        written,
        again.to_toml_string().expect("read-back params serialise"),
        "params do not round-trip"
    );
    let _ = params.first_changed_stage(&PipelineParams::default());
}

/// One frame (PNG, TIFF or anything the decoder guesses): a decoded frame is grey in `[0, 1]`
/// and has the size the undecoded check reads from its header.
pub fn frame(data: &[u8]) {
    let path = Path::new("frame");
    let checked = check_frame_bytes(data, path);
    let Ok(img) = decode_frame(data, path) else {
        return;
    };
    assert_eq!(img.data.len(), img.width * img.height, "frame buffer size");
    assert!(
        img.data.iter().all(|v| (0.0..=1.0).contains(v)),
        "a decoded frame holds a value outside [0, 1]"
    );
    if let Ok(size) = checked {
        assert_eq!(
            size,
            (img.width, img.height),
            "header and decoded sizes differ"
        );
    }
}

/// `reference.wav`: read it; what reads has channels of one length and a non-zero rate.
pub fn reference_wav(data: &[u8]) {
    let Ok(audio) = wav::read_wav_from(Cursor::new(data), Path::new("reference.wav")) else {
        return;
    };
    assert!(audio.sample_rate_hz > 0 && !audio.is_empty());
    assert!(audio.channels.iter().all(|c| c.len() == audio.len()));
    let _ = audio.mono();
}

/// `.flo`: a field that reads encodes back to the same bytes.
pub fn flo_file(data: &[u8]) {
    let Ok((u, v)) = flo::decode_flo(data, Path::new("field.flo")) else {
        return;
    };
    assert_eq!(flo::encode_flo(&u, &v), data, ".flo does not round-trip");
}

/// A whole tiny scan folder built from the bytes (metadata, numbered groups of PNG or TIFF
/// frames, some damaged, a number skipped now and then, stray folders and dot files, an
/// optional `reference.wav`), opened and reconstructed with the defaults.
pub fn scan_folder(data: &[u8]) {
    let mut u = Unstructured::new(data);
    let Ok(dir) = scratch_dir() else {
        return;
    };
    if write_scan(&mut u, dir.path()).is_err() {
        return;
    }
    let Ok(scan) = Scan::open(dir.path()) else {
        return;
    };
    assert!(!scan.groups.is_empty());
    for group in &scan.groups {
        if let Ok(frames) = load_group(group) {
            assert!(frames.len() == group.frame_count());
        }
    }
    // The whole pipeline on one input in eight (it costs about ten loads).
    if !u.ratio(1u8, 8).unwrap_or(false) {
        return;
    }
    let keep_going = u.arbitrary::<bool>().unwrap_or(false);
    let opts = ReconstructOptions {
        params: PipelineParams::default(),
        groups: None,
        keep_going,
    };
    if let Ok(rec) = reconstruct(&scan, &opts, &mut |_| {}, &AtomicBool::new(false)) {
        assert!(rec.audio.channels.iter().flatten().all(|v| v.is_finite()));
    }
}

/// A fresh folder for one scan, in memory where `/dev/shm` exists.
fn scratch_dir() -> std::io::Result<tempfile::TempDir> {
    let shm = Path::new("/dev/shm");
    if shm.is_dir() {
        tempfile::tempdir_in(shm)
    } else {
        tempfile::tempdir()
    }
}

/// A number for a metadata key: usually sensible, sometimes anything.
fn number(u: &mut Unstructured, typical: f64) -> arbitrary::Result<f64> {
    Ok(match u.int_in_range(0u8..=7)? {
        0 => u.arbitrary::<f64>()?,
        1 => -typical,
        2 => 0.0,
        _ => typical * (0.5 + f64::from(u.int_in_range(0u8..=100)?) / 50.0),
    })
}

/// Writes `scan.toml`, groups of frames and maybe `reference.wav` into `dir`.
fn write_scan(u: &mut Unstructured, dir: &Path) -> arbitrary::Result<()> {
    let groups = u.int_in_range(0usize..=3)?;
    let width = u.int_in_range(1u32..=32)?;
    let height = u.int_in_range(1u32..=32)?;
    let mut meta = format!(
        "format = 1\n[record]\nrpm = {}\nradius_mm = {}\ncut = \"{}\"\n",
        number(u, 78.0)?,
        number(u, 115.0)?,
        u.choose(&["lateral", "stereo", "vertical", "sideways"])?
    );
    if u.ratio(1u8, 4)? {
        let n = u.int_in_range(0usize..=4)?;
        let radii: Vec<String> = (0..n)
            .map(|_| number(u, 100.0).map(|r| r.to_string()))
            .collect::<Result<_, _>>()?;
        meta += &format!("group_radius_mm = [{}]\n", radii.join(", "));
    }
    meta += &format!(
        "[camera]\npixel_pitch_um = {}\nworking_distance_mm = {}\n[motion]\nframe_step_um = {}\ngroup_step_um = {}\n",
        number(u, 0.39)?,
        number(u, 4.0)?,
        number(u, 0.78)?,
        number(u, 8.0)?
    );
    if u.ratio(1u8, 3)? {
        meta += &format!(
            "[dual_focus]\nfocus_distance_mm = {}\nglass_thickness_mm = {}\nglass_index = {}\nglass_side = \"{}\"\nglass_edge_row = {}\n",
            number(u, 4.0)?,
            number(u, 0.11)?,
            number(u, 1.5)?,
            u.choose(&["top", "bottom"])?,
            number(u, f64::from(height) / 2.0)?
        );
    }
    if u.ratio(1u8, 16)? {
        let len = u.int_in_range(0usize..=64)?;
        meta = String::from_utf8_lossy(u.bytes(len)?).into_owned();
    }
    std::fs::write(dir.join("scan.toml"), meta).map_err(fail)?;
    // Numbered folders as transfers leave them: padded or not, a number now and then skipped.
    let unpadded = u.ratio(1u8, 4)?;
    let mut number = u.int_in_range(0usize..=1)?;
    for g in 0..groups {
        let name = if unpadded {
            format!("g{number}")
        } else {
            format!("g{number:05}")
        };
        number += if u.ratio(1u8, 6)? { 2 } else { 1 };
        let group_dir = dir.join(name);
        std::fs::create_dir(&group_dir).map_err(fail)?;
        let frames = u.int_in_range(5usize..=9)?;
        for k in 0..frames {
            let (bytes, ext) = frame_bytes(u, width, height, g * 16 + k)?;
            std::fs::write(group_dir.join(format!("f{k:03}.{ext}")), &bytes).map_err(fail)?;
            // A frame left in a second format, and another program's dot file.
            if u.ratio(1u8, 32)? {
                let other = if ext == "png" { "tif" } else { "png" };
                std::fs::write(group_dir.join(format!("f{k:03}.{other}")), &bytes).map_err(fail)?;
            }
            if u.ratio(1u8, 32)? {
                std::fs::write(
                    group_dir.join(format!("._f{k:03}.{ext}")),
                    b"\0\x05\x16\x07",
                )
                .map_err(fail)?;
            }
        }
    }
    // A folder that is no group: empty, or holding notes.
    if u.ratio(1u8, 8)? {
        let stray = dir.join(u.choose(&["notes", "calibration", ".thumbnails", "g"])?);
        std::fs::create_dir_all(&stray).map_err(fail)?;
        if u.arbitrary::<bool>()? {
            std::fs::write(stray.join("transfer.txt"), b"stylus-free").map_err(fail)?;
        }
    }
    if u.ratio(1u8, 3)? {
        let mut bytes = wav_bytes(u)?;
        damage(u, &mut bytes)?;
        std::fs::write(dir.join("reference.wav"), bytes).map_err(fail)?;
    }
    Ok(())
}

/// One frame file: a textured PNG or TIFF (8 or 16 bit, grey or colour), sometimes of
/// another size, sometimes damaged.
fn frame_bytes(
    u: &mut Unstructured,
    width: u32,
    height: u32,
    seed: usize,
) -> arbitrary::Result<(Vec<u8>, &'static str)> {
    let (w, h) = if u.ratio(1u8, 32)? {
        (u.int_in_range(1u32..=40)?, u.int_in_range(1u32..=40)?)
    } else {
        (width, height)
    };
    let phase = u.arbitrary::<u8>()?;
    let texture = |x: u32, y: u32| -> u8 {
        let v = (x * 37 + y * 91 + seed as u32 * 13) % 251;
        (v as u8).wrapping_add(phase)
    };
    let img = image::GrayImage::from_fn(w, h, |x, y| image::Luma([texture(x, y)]));
    let dynimg = match u.int_in_range(0u8..=3)? {
        0 => image::DynamicImage::ImageLuma8(img),
        1 => image::DynamicImage::ImageLuma16(image::ImageBuffer::from_fn(w, h, |x, y| {
            image::Luma([u16::from(texture(x, y)) * 257])
        })),
        2 => image::DynamicImage::ImageRgb8(image::DynamicImage::ImageLuma8(img).to_rgb8()),
        _ => image::DynamicImage::ImageRgba16(image::DynamicImage::ImageLuma8(img).to_rgba16()),
    };
    let (format, ext) = if u.ratio(1u8, 4)? {
        (image::ImageFormat::Tiff, "tif")
    } else {
        (image::ImageFormat::Png, "png")
    };
    let mut out = Cursor::new(Vec::new());
    if format == image::ImageFormat::Png {
        // Fast, unfiltered PNGs: encoding is input-building, not what is fuzzed.
        use image::codecs::png::{CompressionType, FilterType, PngEncoder};
        dynimg
            .write_with_encoder(PngEncoder::new_with_quality(
                &mut out,
                CompressionType::Fast,
                FilterType::NoFilter,
            ))
            .map_err(fail)?;
    } else {
        dynimg.write_to(&mut out, format).map_err(fail)?;
    }
    let mut bytes = out.into_inner();
    if u.ratio(1u8, 24)? {
        damage(u, &mut bytes)?;
    }
    Ok((bytes, ext))
}

/// A short valid WAV file (8–32 bit integer or 32-bit float, 1–2 channels).
fn wav_bytes(u: &mut Unstructured) -> arbitrary::Result<Vec<u8>> {
    let float = u.arbitrary::<bool>()?;
    let spec = hound::WavSpec {
        channels: u.int_in_range(1u16..=2)?,
        sample_rate: *u.choose(&[8_000u32, 44_100, 48_000, 1])?,
        bits_per_sample: if float {
            32
        } else {
            *u.choose(&[8u16, 16, 24, 32])?
        },
        sample_format: if float {
            hound::SampleFormat::Float
        } else {
            hound::SampleFormat::Int
        },
    };
    let mut out = Cursor::new(Vec::new());
    let mut w = hound::WavWriter::new(&mut out, spec).map_err(fail)?;
    let n = u.int_in_range(0usize..=64)? * usize::from(spec.channels);
    for i in 0..n {
        let r = if float {
            w.write_sample((i as f32 * 0.1).sin())
        } else {
            w.write_sample(((i as f32 * 0.1).sin() * 100.0) as i32)
        };
        r.map_err(fail)?;
    }
    w.finalize().map_err(fail)?;
    Ok(out.into_inner())
}

/// Cuts the file short or overwrites a few bytes.
fn damage(u: &mut Unstructured, bytes: &mut Vec<u8>) -> arbitrary::Result<()> {
    if bytes.is_empty() {
        return Ok(());
    }
    if u.arbitrary::<bool>()? {
        let keep = u.int_in_range(0..=bytes.len() - 1)?;
        bytes.truncate(keep);
    } else {
        for _ in 0..u.int_in_range(1u8..=4)? {
            let at = u.int_in_range(0..=bytes.len() - 1)?;
            bytes[at] = u.arbitrary()?;
        }
    }
    Ok(())
}

/// A still image: a small generated micrograph (grooves, dust, text, rims, blur, noise) saved
/// as an 8/16-bit PNG or TIFF and sometimes damaged, or the bytes themselves as the file; decoded
/// with settings that may contradict it. What decodes is finite sound, one or two channels of
/// one length.
pub fn still_image(data: &[u8]) {
    let mut u = Unstructured::new(data);
    let Ok(dir) = scratch_dir() else {
        return;
    };
    let Ok((path, setup, groove)) = write_still(&mut u, dir.path()) else {
        return;
    };
    let Ok(run) = decode_still_file(&path, &setup, groove, &PipelineParams::default()) else {
        return;
    };
    let channels = &run.audio.channels;
    assert!(
        matches!(channels.len(), 1 | 2),
        "a still decodes to 1 or 2 channels"
    );
    assert!(channels.iter().all(|c| c.len() == channels[0].len()));
    assert!(channels.iter().flatten().all(|v| v.is_finite()));
}

/// Writes one still into `dir`; returns its path, the decoder's settings and the groove asked for.
fn write_still(
    u: &mut Unstructured,
    dir: &Path,
) -> arbitrary::Result<(std::path::PathBuf, StillSetup, Option<usize>)> {
    let ext = *u.choose(&["png", "tif"])?;
    let path = dir.join(format!("still.{ext}"));
    let axis = *u.choose(&[Axis::Vertical, Axis::Horizontal])?;
    let cut = *u.choose(&[Cut::Lateral, Cut::Stereo])?;
    let cfg = StillConfig {
        length_px: u.int_in_range(16usize..=192)?,
        across_px: u.int_in_range(8usize..=128)?,
        axis,
        cut,
        um_per_px: 0.5 + f64::from(u.int_in_range(0u8..=30)?) / 10.0,
        grooves: u.int_in_range(1usize..=3)?,
        pitch_um: number(u, 100.0)?,
        top_width_um: number(u, 56.0)?,
        bottom_width_um: number(u, 6.0)?,
        drift_um: number(u, 20.0)?,
        wander_um: number(u, 12.0)?,
        dust_per_mpx: number(u, 100.0)?.abs(),
        text: if u.arbitrary()? {
            "GS 1".into()
        } else {
            String::new()
        },
        text_height_px: u.int_in_range(4usize..=16)?,
        blur_sigma_px: f64::from(u.int_in_range(0u8..=20)?) / 10.0,
        noise_sigma: f64::from(u.int_in_range(0u8..=20)?) / 200.0,
        // The noise fields behind texture and uneven light cost more to render than the
        // decoder takes, so most inputs go without.
        texture: if u.ratio(1u8, 8)? { 0.08 } else { 0.0 },
        illumination_unevenness: if u.ratio(1u8, 8)? { 0.35 } else { 0.0 },
        rim_fraction: f64::from(u.int_in_range(0u8..=10)?) / 10.0,
        seed: u.arbitrary()?,
        ..StillConfig::default()
    };
    let sixteen = u.arbitrary::<bool>()?;
    let raw = u.ratio(1u8, 8)?;
    if !raw {
        // A configuration the generator refuses is not an input for the decoder.
        let scene = StillScene::new(&cfg, None).map_err(fail)?;
        let img = render_still(&scene).image;
        save_grey_image(&img, &path, sixteen, false).map_err(fail)?;
        if u.ratio(1u8, 8)? {
            let mut bytes = std::fs::read(&path).map_err(fail)?;
            damage(u, &mut bytes)?;
            std::fs::write(&path, bytes).map_err(fail)?;
        }
    }
    // The decoder is told the truth, or a wrong axis, scale, speed or groove.
    let setup = StillSetup {
        axis: if u.ratio(1u8, 8)? {
            match axis {
                Axis::Vertical => Axis::Horizontal,
                Axis::Horizontal => Axis::Vertical,
            }
        } else {
            axis
        },
        um_per_px: if u.ratio(1u8, 8)? {
            number(u, 1.0)?
        } else {
            cfg.um_per_px
        },
        rpm: number(u, cfg.rpm)?,
        radius_mm: number(u, cfg.radius_mm)?,
        cut: if u.ratio(1u8, 16)? {
            Cut::Vertical
        } else {
            cut
        },
        reverse: u.arbitrary()?,
    };
    let groove = if u.arbitrary()? {
        Some(u.int_in_range(0usize..=4)?)
    } else {
        None
    };
    if raw {
        let len = u.len();
        std::fs::write(&path, u.bytes(len)?).map_err(fail)?;
    }
    Ok((path, setup, groove))
}

/// A Zarr scan store: a tiny valid store (uint8, uint16 or float32 samples) made by the writer,
/// then maybe damaged (its metadata edited, a chunk cut short, overwritten or deleted). Opened
/// and every group loaded: an intact store gives back exactly the frames written, a damaged one
/// an error or frames of the store's size.
pub fn zarr_store(data: &[u8]) {
    let mut u = Unstructured::new(data);
    let Ok(dir) = scratch_dir() else {
        return;
    };
    let store = dir.path().join("scan.zarr");
    let Ok((written, damaged)) = write_zarr(&mut u, &store) else {
        return;
    };
    let scan = match Scan::open(&store) {
        Ok(scan) => scan,
        Err(e) => {
            assert!(damaged, "an intact store does not open: {e}");
            return;
        }
    };
    for (group, frames) in scan.groups.iter().zip(&written) {
        match load_group(group) {
            Ok(loaded) => {
                assert_eq!(loaded.len(), group.frame_count());
                if !damaged {
                    let want: Vec<_> = frames.iter().cloned().map(grey_from_raw).collect();
                    assert!(loaded == want, "an intact store reads back other frames");
                }
            }
            Err(_) => assert!(damaged, "an intact store's group does not load"),
        }
    }
}

/// Writes a store at `dir` from the bytes; returns the frames written per group and whether
/// the store was damaged afterwards.
fn write_zarr(u: &mut Unstructured, dir: &Path) -> arbitrary::Result<(Vec<Vec<RawFrame>>, bool)> {
    let groups = u.int_in_range(1usize..=3)?;
    let frames = u.int_in_range(7usize..=9)?;
    // Wide enough for the scan.toml below, whose groups must overlap: 2 µm group steps
    // within the 8 px (3.1 µm) left of 24 px between the stitcher's margins.
    let (w, h) = (u.int_in_range(24usize..=32)?, u.int_in_range(1usize..=24)?);
    let sample_type = *u.choose(&[SampleType::U8, SampleType::U16, SampleType::F32])?;
    let layout = ChunkLayout {
        frames,
        width: w,
        height: h,
        sample_type,
    };
    let mut writer = ZarrWriter::create(dir, layout, 1).map_err(fail)?;
    let mut written = Vec::new();
    for g in 0..groups {
        let group: Vec<RawFrame> = (0..frames)
            .map(|k| {
                let v = |i: usize| (i * 37 + k * 91 + g * 13) % 251;
                let samples = match sample_type {
                    SampleType::U8 => RawSamples::U8((0..w * h).map(|i| v(i) as u8).collect()),
                    SampleType::U16 => {
                        RawSamples::U16((0..w * h).map(|i| (v(i) * 257) as u16).collect())
                    }
                    SampleType::F32 => {
                        RawSamples::F32((0..w * h).map(|i| v(i) as f32 / 250.0).collect())
                    }
                };
                RawFrame {
                    width: w,
                    height: h,
                    samples,
                }
            })
            .collect();
        writer
            .write_group(&format!("g{g:05}"), &group, dir)
            .map_err(fail)?;
        written.push(group);
    }
    let scan_toml = "format = 1\n[record]\nrpm = 78.0\nradius_mm = 115.0\ncut = \"lateral\"\n\
        [camera]\npixel_pitch_um = 0.39\nworking_distance_mm = 4.0\n\
        [motion]\nframe_step_um = 0.78\ngroup_step_um = 2.0\n";
    writer.finish(scan_toml).map_err(fail)?;
    // The chunk file of group `g`, as the reader names it.
    let chunk = |g: usize| chunk_file(dir, g);
    let damaged = match u.int_in_range(0u8..=7)? {
        0..=2 => false,
        3 => {
            let path = dir.join("zarr.json");
            let mut bytes = std::fs::read(&path).map_err(fail)?;
            damage(u, &mut bytes)?;
            std::fs::write(&path, bytes).map_err(fail)?;
            true
        }
        4 => {
            let path = dir.join("frames").join("zarr.json");
            let mut bytes = std::fs::read(&path).map_err(fail)?;
            damage(u, &mut bytes)?;
            std::fs::write(&path, bytes).map_err(fail)?;
            true
        }
        5 => {
            let g = u.int_in_range(0..=groups - 1)?;
            std::fs::remove_file(chunk(g)).map_err(fail)?;
            true
        }
        _ => {
            let path = chunk(u.int_in_range(0..=groups - 1)?);
            let mut bytes = std::fs::read(&path).map_err(fail)?;
            damage(u, &mut bytes)?;
            std::fs::write(&path, bytes).map_err(fail)?;
            true
        }
    };
    Ok((written, damaged))
}

/// Any failure while building an input: the input is not one this target tries.
fn fail<E>(_: E) -> arbitrary::Error {
    arbitrary::Error::IncorrectFormat
}
