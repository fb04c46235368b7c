//! The `groovescope` binary: the workbench with no subcommand (when a display exists), otherwise the command-line tool.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::Parser;
use groovescope::cli::{Cli, ReconstructArgs, run, run_gui, run_reconstruct};

/// The bundled demo scan, relative to the crate root.
const DEMO_SCAN: &str = "assets/demo";

fn demo_scan() -> PathBuf {
    let here = Path::new(DEMO_SCAN);
    if here.join("scan.toml").is_file() {
        return here.to_path_buf();
    }
    Path::new(env!("CARGO_MANIFEST_DIR")).join(DEMO_SCAN)
}

fn display_available() -> bool {
    ["DISPLAY", "WAYLAND_DISPLAY"]
        .iter()
        .any(|k| std::env::var_os(k).is_some_and(|v| !v.is_empty()))
}

/// A file name in the current folder that does not exist yet: `stem.ext`, `stem-2.ext`, ...
fn fresh_name(stem: &str, ext: &str) -> PathBuf {
    let first = PathBuf::from(format!("{stem}.{ext}"));
    if !first.exists() {
        return first;
    }
    (2..)
        .map(|i| PathBuf::from(format!("{stem}-{i}.{ext}")))
        .find(|p| !p.exists())
        .unwrap_or(first)
}

fn default_action() -> anyhow::Result<()> {
    if cfg!(feature = "gui") && display_available() {
        return run_gui(None);
    }
    let out = fresh_name("groovescope-demo", "wav");
    let report = out.with_extension("report.json");
    println!(
        "no display: reconstructing the demo scan {} to {}",
        demo_scan().display(),
        out.display()
    );
    let args = ReconstructArgs {
        scan: demo_scan(),
        out,
        params: None,
        report: Some(report.clone()),
        path: "auto".into(),
        method: None,
        bits: groovescope::io::wav::WavBits::Int24,
        first_group: None,
        groups: None,
        keep_going: false,
        force: false,
        quiet: false,
        side: Default::default(),
    };
    run_reconstruct(&args)?;
    println!("report: {}", report.display());
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
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
