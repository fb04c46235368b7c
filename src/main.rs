//! The `groovescope` binary: the workbench with no subcommand (when a display exists; without
//! one, the bundled still demo decoded to a WAV file), otherwise the command-line tool.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use groovescope::cli::{Cli, run, run_gui};
use groovescope::still::cli::run_still;
use groovescope::still::demo::{demo_still_dir, read_generated_still};

fn display_available() -> bool {
    ["DISPLAY", "WAYLAND_DISPLAY"]
        .iter()
        .any(|k| std::env::var_os(k).is_some_and(|v| !v.is_empty()))
}

/// A stem in the current folder under which none of `exts` exists yet: `stem`, `stem-2`, ...
fn fresh_stem(stem: &str, exts: &[&str]) -> String {
    let free = |s: &str| {
        exts.iter()
            .all(|e| !PathBuf::from(format!("{s}.{e}")).exists())
    };
    std::iter::once(stem.to_string())
        .chain((2..).map(|i| format!("{stem}-{i}")))
        .find(|s| free(s))
        .unwrap_or_else(|| stem.to_string())
}

/// True when `e` says the workbench window could not be opened at all.
fn no_window(e: &anyhow::Error) -> bool {
    #[cfg(feature = "gui")]
    {
        e.downcast_ref::<groovescope::app::NoWindow>().is_some()
    }
    #[cfg(not(feature = "gui"))]
    {
        let _ = e;
        false
    }
}

fn default_action() -> anyhow::Result<()> {
    if cfg!(feature = "gui") && display_available() {
        // The workbench (on the last scan, else the demo scan) with the demo still open in the
        // still window, its speech groove decoded and ready to play.
        let demo = read_generated_still(&demo_still_dir())?;
        match run_gui(Some(demo.image)) {
            Err(e) if no_window(&e) => {
                // A display variable with nothing behind it (ssh): decode as with no display.
                groovescope::tell!("{e}; decoding the demo still instead");
            }
            other => return other,
        }
    }
    // The WAV and its report share a stem that neither file has yet: nothing is overwritten.
    let stem = fresh_stem("groovescope-demo", &["wav", "report.json"]);
    let out = PathBuf::from(format!("{stem}.wav"));
    let report = PathBuf::from(format!("{stem}.report.json"));
    let demo = read_generated_still(&demo_still_dir())?;
    groovescope::say!(
        "no display: decoding groove {} of the demo still {} to {}",
        demo.groove,
        demo.image.display(),
        out.display()
    )?;
    run_still(&demo.still_args(out, Some(report.clone())))?;
    groovescope::say!("report: {}", report.display())?;
    Ok(())
}

fn main() -> ExitCode {
    groovescope::alloc::keep_freed_buffers();
    let cli = Cli::parse();
    let result = match cli.command {
        Some(cmd) => run(cmd),
        None => default_action(),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            groovescope::tell!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
