//! The bundled still demo (`assets/demo-still`, made by `synth-still`): where it lies, what its
//! `truth.toml` says the `still` decoder needs, and the `still` run that decodes its speech groove.

use std::path::{Path, PathBuf};

use anyhow::{Result, anyhow};

use crate::io::wav::WavBits;
use crate::pipeline::still::StillSetup;
use crate::synth::still::StillSidecar;

use super::cli::StillArgs;

/// The bundled still demo folder, relative to the crate root.
pub const DEMO_STILL: &str = "assets/demo-still";

/// The demo folder: the first `assets/demo-still` that holds one ([`crate::assets::find`]:
/// the working folder, beside the executable, the source tree), else the source tree's, for
/// the error that names it.
#[must_use]
pub fn demo_still_dir() -> PathBuf {
    crate::assets::find(DEMO_STILL, |p| p.join("truth.toml").is_file())
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join(DEMO_STILL))
}

/// A generated still, ready to decode: the image, the groove that carries the sound, its
/// reference and the settings `groovescope still` takes.
#[derive(Clone, Debug, PartialEq)]
pub struct DemoStill {
    /// The image file.
    pub image: PathBuf,
    /// `--groove` (from 1): the groove at the configured radius, which carries the sound from
    /// its start.
    pub groove: usize,
    /// That groove's sound (the generator's reference WAV).
    pub reference: PathBuf,
    /// Axis, pixel size, speed, radius and cut.
    pub setup: StillSetup,
}

/// Reads the `truth.toml` of the generated still folder `dir`.
///
/// # Errors
/// One line naming the file: unreadable, not a still sidecar, or without grooves.
pub fn read_generated_still(dir: &Path) -> Result<DemoStill> {
    let path = dir.join("truth.toml");
    let text = crate::io::limits::read_toml_text(&path, "still sidecar")?;
    let sidecar: StillSidecar = toml::from_str(&text).map_err(|e| {
        let e = crate::toml_error::located(&text, &e);
        anyhow!("invalid still sidecar: {e}: {}", path.display())
    })?;
    let (t, cfg) = (&sidecar.truth, &sidecar.still);
    let groove = t
        .grooves
        .iter()
        .min_by(|a, b| {
            (a.radius_mm - cfg.radius_mm)
                .abs()
                .total_cmp(&(b.radius_mm - cfg.radius_mm).abs())
        })
        .ok_or_else(|| anyhow!("the still sidecar lists no grooves: {}", path.display()))?;
    Ok(DemoStill {
        image: dir.join(&t.image),
        groove: groove.number,
        reference: dir.join(&groove.reference),
        setup: StillSetup {
            axis: t.axis,
            um_per_px: t.um_per_px,
            rpm: t.rpm,
            radius_mm: groove.radius_mm,
            cut: t.cut,
            reverse: false,
        },
    })
}

impl DemoStill {
    /// The `groovescope still` arguments that decode this groove to `out` (24-bit) with the
    /// JSON `report`, scored against the reference; nothing is overwritten.
    #[must_use]
    pub fn still_args(&self, out: PathBuf, report: Option<PathBuf>) -> StillArgs {
        let s = &self.setup;
        StillArgs {
            image: self.image.clone(),
            um_per_px: s.um_per_px,
            rpm: s.rpm,
            radius_mm: s.radius_mm,
            axis: s.axis.name().into(),
            cut: s.cut.name().into(),
            groove: Some(self.groove),
            reverse: s.reverse,
            out,
            report,
            reference: Some(self.reference.clone()),
            params: None,
            bits: WavBits::Int24,
            force: false,
            quiet: false,
        }
    }
}
