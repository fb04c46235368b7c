//! The `synth-still` and `still` subcommands: generate a top-view still with its truth, and
//! decode a still image of a record into a WAV file.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

use crate::io::Cut;
use crate::pipeline::still::Axis;
use crate::synth::still::{StillConfig, StillScene, write_still};

/// Arguments of `synth-still`.
#[derive(Debug, clap::Args)]
pub struct SynthStillArgs {
    /// Sound to cut into every groove (WAV; the middle groove from `start_secs`, each turn further
    /// in one revolution later); without it, or --melody, each wall gets a built-in tone.
    pub sound: Option<PathBuf>,
    /// Output folder (must not exist or be empty): still.png|tif, grooveN.wav, truth.toml.
    #[arg(long)]
    pub out: PathBuf,
    /// Still settings TOML (the `[still]` keys; missing keys take the preset's values).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Starting settings: test (1000×4000 px, 7 grooves) or demo (the bundled 80 000 px strip).
    #[arg(long, value_parser = ["test", "demo"], default_value = "test")]
    pub preset: String,
    /// Grooves run down (vertical) or across (horizontal) the image (overrides the config).
    #[arg(long, value_parser = ["vertical", "horizontal"])]
    pub axis: Option<String>,
    /// lateral or stereo (overrides the config).
    #[arg(long, value_parser = ["lateral", "stereo"])]
    pub cut: Option<String>,
    /// The built-in melody (C5 E5 G5 C6) in every groove instead of tones.
    #[arg(long, conflicts_with = "sound")]
    pub melody: bool,
    /// Duration of the melody (s).
    #[arg(long, default_value_t = 1.0)]
    pub duration: f64,
    /// Seed of texture, levels, rims, dust and noise (overrides the config).
    #[arg(long)]
    pub seed: Option<u32>,
    /// No summary line.
    #[arg(long)]
    pub quiet: bool,
}

/// `base` with the keys of the TOML file `path` (optionally under a `[table]`) laid over it.
///
/// # Errors
/// When the file cannot be read or a key or value is invalid (the message names the file).
pub fn overlay_toml<T>(base: &T, path: &Path, table: &str, what: &str) -> Result<T>
where
    T: serde::Serialize + serde::de::DeserializeOwned,
{
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read {what}: {}", path.display()))?;
    let mut merged: toml::Table = toml::to_string(base)
        .ok()
        .and_then(|t| toml::from_str(&t).ok())
        .unwrap_or_default();
    let user: toml::Table = toml::from_str(&text)
        .map_err(|e| anyhow::anyhow!("invalid {what}: {}: {}", e.message(), path.display()))?;
    let user = match user.get(table) {
        Some(toml::Value::Table(t)) => t.clone(),
        _ => user,
    };
    merged.extend(user);
    toml::Value::Table(merged)
        .try_into::<T>()
        .map_err(|e| anyhow::anyhow!("invalid {what}: {}: {}", e.message(), path.display()))
}

/// Runs `synth-still`.
///
/// # Errors
/// Invalid settings, an unusable sound, an output folder that is not empty, write failures.
pub fn run_synth_still(args: &SynthStillArgs) -> Result<()> {
    let base = if args.preset == "demo" {
        StillConfig::demo()
    } else {
        StillConfig::default()
    };
    let mut cfg = match &args.config {
        Some(p) => overlay_toml(&base, p, "still", "still settings")?,
        None => base,
    };
    match args.axis.as_deref() {
        Some("vertical") => cfg.axis = Axis::Vertical,
        Some("horizontal") => cfg.axis = Axis::Horizontal,
        _ => {}
    }
    match args.cut.as_deref() {
        Some("lateral") => cfg.cut = Cut::Lateral,
        Some("stereo") => cfg.cut = Cut::Stereo,
        _ => {}
    }
    if let Some(seed) = args.seed {
        cfg.seed = seed;
    }
    if !(args.duration.is_finite() && args.duration > 0.0) {
        bail!(
            "--duration must be a positive number of seconds, got {}",
            args.duration
        );
    }
    let sound = if args.melody {
        Some(crate::synth::arpeggio(
            args.duration / 4.0,
            crate::synth::BUILTIN_RATE_HZ,
        ))
    } else if let Some(p) = &args.sound {
        Some(crate::io::wav::read_wav(p)?)
    } else {
        None
    };
    let scene = StillScene::new(&cfg, sound.as_ref()).map_err(|e| match (&args.sound, e) {
        (Some(p), crate::synth::SynthError::Sound { problem }) => {
            anyhow::anyhow!("unusable sound: {problem}: {}", p.display())
        }
        (_, e) => e.into(),
    })?;
    let summary = write_still(&scene, &args.out)?;
    if !args.quiet {
        let t = &summary.truth;
        println!(
            "wrote {} ({} × {} px, {} grooves, {:?} axis); decode groove N with: groovescope still {} \
             --um-per-px {} --rpm {:.4} --radius-mm <grooves[N].radius_mm in truth.toml> --axis {} --groove N",
            summary.image.display(),
            t.width_px,
            t.height_px,
            t.grooves.len(),
            t.axis,
            summary.image.display(),
            t.um_per_px,
            t.rpm,
            match t.axis {
                Axis::Vertical => "vertical",
                Axis::Horizontal => "horizontal",
            }
        );
    }
    Ok(())
}
