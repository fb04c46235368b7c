//! libFuzzer entry point: runs the target named by `GROOVESCOPE_FUZZ_TARGET` on each input.
#![no_main]

use std::sync::OnceLock;

use groovescope_fuzz::{TARGETS, Target, target};

/// The target chosen once per process.
fn chosen() -> &'static Target {
    static CHOSEN: OnceLock<&'static Target> = OnceLock::new();
    CHOSEN.get_or_init(|| {
        let name = std::env::var("GROOVESCOPE_FUZZ_TARGET").unwrap_or_default();
        target(&name).unwrap_or_else(|| {
            let names: Vec<_> = TARGETS.iter().map(|t| t.name).collect();
            eprintln!("set GROOVESCOPE_FUZZ_TARGET to one of: {}", names.join(", "));
            std::process::exit(2)
        })
    })
}

libfuzzer_sys::fuzz_target!(|data: &[u8]| (chosen().run)(data));
