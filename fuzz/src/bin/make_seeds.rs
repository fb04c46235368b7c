//! Writes the seed corpus: small valid files of every kind each target reads, into `fuzz/corpus/TARGET/`.
//!
//! Run from the repository root: `cargo run --manifest-path fuzz/Cargo.toml --bin make-seeds`.
//! Crash inputs found by fuzzing are kept beside these seeds under `crash-*` names.

// Linked for the coverage hooks the instrumented libraries call (its `main` is not used).
use libfuzzer_sys as _;

use std::io::Cursor;
use std::path::Path;

use groovescope::image::Image;
use groovescope::io::flo::encode_flo;
use groovescope::pipeline::PipelineParams;

const SCAN_TOML: &str = "format = 1\n[record]\nrpm = 78.0\nradius_mm = 115.0\ncut = \"lateral\"\n\
[camera]\npixel_pitch_um = 0.39\nworking_distance_mm = 4.0\n[motion]\nframe_step_um = 0.78\ngroup_step_um = 460.2\n";

const DUAL_FOCUS: &str = "[dual_focus]\nfocus_distance_mm = 4.0\nglass_thickness_mm = 0.11\n\
glass_index = 1.515\nglass_side = \"bottom\"\nglass_edge_row = 610.0\n";

fn write(dir: &Path, name: &str, bytes: &[u8]) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    std::fs::write(dir.join(name), bytes)
}

fn encoded(img: &image::DynamicImage, format: image::ImageFormat) -> Vec<u8> {
    let mut out = Cursor::new(Vec::new());
    img.write_to(&mut out, format)
        .expect("encoding a small image");
    out.into_inner()
}

/// A PNG whose header claims `w`×`h` pixels (checksums fixed up, image data left small).
fn png_claiming(mut png: Vec<u8>, w: u32, h: u32) -> Vec<u8> {
    png[16..20].copy_from_slice(&w.to_be_bytes());
    png[20..24].copy_from_slice(&h.to_be_bytes());
    let crc = crc32fast::hash(&png[12..29]);
    png[29..33].copy_from_slice(&crc.to_be_bytes());
    png
}

fn wav(spec: hound::WavSpec, n: usize) -> Vec<u8> {
    let mut out = Cursor::new(Vec::new());
    let mut w = hound::WavWriter::new(&mut out, spec).expect("a WAV header");
    for i in 0..n * usize::from(spec.channels) {
        let s = (i as f32 * 0.3).sin();
        if spec.sample_format == hound::SampleFormat::Float {
            w.write_sample(s).expect("a sample");
        } else {
            let full = (1i64 << (spec.bits_per_sample - 1)) - 1;
            w.write_sample((f64::from(s) * full as f64) as i32)
                .expect("a sample");
        }
    }
    w.finalize().expect("a finished WAV");
    out.into_inner()
}

fn main() -> std::io::Result<()> {
    let root = Path::new("fuzz/corpus");
    let d = root.join("scan_toml");
    write(&d, "minimal.toml", SCAN_TOML.as_bytes())?;
    write(
        &d,
        "dual_focus.toml",
        format!("{SCAN_TOML}{DUAL_FOCUS}").as_bytes(),
    )?;
    let spiral = SCAN_TOML.replace(
        "cut = \"lateral\"\n",
        "cut = \"stereo\"\ngroup_radius_mm = [115.0, 114.99, 114.98]\n",
    );
    write(
        &d,
        "spiral_synth.toml",
        format!("{spiral}[synth]\nseed = 7\nnote = \"x\"\n").as_bytes(),
    )?;

    let d = root.join("params_toml");
    let defaults = PipelineParams::default()
        .to_toml_string()
        .expect("default params serialise");
    write(&d, "defaults.toml", defaults.as_bytes())?;
    write(
        &d,
        "preset.toml",
        b"path = \"dual_focus\"\n[flow]\nlambda = 0.5\n[hough]\ntheta_step_deg = 0.5\n",
    )?;

    let d = root.join("frame");
    let grey = image::GrayImage::from_fn(16, 12, |x, y| {
        image::Luma([((x * 37 + y * 91) % 251) as u8])
    });
    let l8 = image::DynamicImage::ImageLuma8(grey);
    let l16 = image::DynamicImage::ImageLuma16(l8.to_luma16());
    let rgb8 = image::DynamicImage::ImageRgb8(l8.to_rgb8());
    let rgba16 = image::DynamicImage::ImageRgba16(l8.to_rgba16());
    let png = image::ImageFormat::Png;
    let tiff = image::ImageFormat::Tiff;
    write(&d, "grey8.png", &encoded(&l8, png))?;
    write(&d, "grey16.png", &encoded(&l16, png))?;
    write(&d, "rgb8.png", &encoded(&rgb8, png))?;
    write(&d, "rgba16.png", &encoded(&rgba16, png))?;
    write(&d, "grey8.tif", &encoded(&l8, tiff))?;
    write(&d, "grey16.tif", &encoded(&l16, tiff))?;
    write(&d, "rgb8.tif", &encoded(&rgb8, tiff))?;
    write(
        &d,
        "huge-header.png",
        &png_claiming(encoded(&l8, png), 50_000, 50_000),
    )?;

    let d = root.join("scan_folder");
    write(&d, "zeros", &[0u8; 96])?;
    write(&d, "ones", &[0xffu8; 96])?;
    let ramp: Vec<u8> = (0..=255).collect();
    write(&d, "ramp", &ramp)?;
    let mixed: Vec<u8> = (0..512u32).map(|i| (i * 97 % 256) as u8).collect();
    write(&d, "mixed", &mixed)?;

    // The still and Zarr targets build their files from the bytes, like `scan_folder`.
    for name in ["still", "zarr_store"] {
        let d = root.join(name);
        write(&d, "zeros", &[0u8; 96])?;
        write(&d, "ramp", &ramp)?;
        write(&d, "mixed", &mixed)?;
    }

    let d = root.join("reference_wav");
    let int = |channels, bits| hound::WavSpec {
        channels,
        sample_rate: 48_000,
        bits_per_sample: bits,
        sample_format: hound::SampleFormat::Int,
    };
    write(&d, "mono16.wav", &wav(int(1, 16), 32))?;
    write(&d, "stereo24.wav", &wav(int(2, 24), 16))?;
    let float = hound::WavSpec {
        channels: 2,
        sample_rate: 44_100,
        bits_per_sample: 32,
        sample_format: hound::SampleFormat::Float,
    };
    write(&d, "stereo32f.wav", &wav(float, 16))?;

    let d = root.join("flo");
    let u = Image::from_fn(3, 2, |x, y| x as f32 - 0.5 * y as f32);
    let v = Image::from_fn(3, 2, |x, _| 0.25 * x as f32);
    write(&d, "small.flo", &encode_flo(&u, &v))?;
    println!("wrote the seed corpus under {}", root.display());
    Ok(())
}
