//! Repository hygiene: every source file starts with a `//!` line, and the pipeline never touches the GUI or audio crates.
#![allow(clippy::unwrap_used)] // tests may panic

use std::path::Path;

fn rust_files(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
}

#[test]
fn every_file_starts_with_a_module_doc_line() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    for d in ["src", "tests", "benches"] {
        if root.join(d).is_dir() {
            rust_files(&root.join(d), &mut files);
        }
    }
    let missing: Vec<_> = files
        .iter()
        .filter(|p| !std::fs::read_to_string(p).unwrap().starts_with("//!"))
        .collect();
    assert!(
        missing.is_empty(),
        "files without a //! first line: {missing:?}"
    );
}

#[test]
fn pipeline_never_imports_gui_audio_or_disk_crates() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("src/pipeline");
    let mut files = Vec::new();
    rust_files(&root, &mut files);
    for f in files {
        let text = std::fs::read_to_string(&f).unwrap();
        for banned in ["egui", "eframe", "cpal", "hound", "rfd", "std::fs"] {
            assert!(!text.contains(banned), "{} mentions {banned}", f.display());
        }
    }
}

/// Lines of `text` outside `//` comments that use `unsafe` (blocks, functions, externs).
fn unsafe_lines(text: &str) -> usize {
    text.lines()
        .map(|l| l.split("//").next().unwrap_or(""))
        .filter(|code| {
            ["unsafe {", "unsafe fn", "unsafe extern", "unsafe impl"]
                .iter()
                .any(|u| code.contains(u))
        })
        .count()
}

#[test]
fn unsafe_lives_only_in_the_simd_module_and_the_allocator_setup() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    rust_files(&root.join("src"), &mut files);
    // The FFmpeg bindings (feature `video`) read a C struct through a raw pointer.
    let allowed = ["src/pipeline/simd/", "src/alloc.rs", "src/io/video/"];
    let stray: Vec<_> = files
        .iter()
        .filter(|p| {
            let rel = p
                .strip_prefix(root)
                .unwrap()
                .to_string_lossy()
                .replace('\\', "/");
            !allowed.iter().any(|a| rel.starts_with(a))
        })
        .filter(|p| unsafe_lines(&std::fs::read_to_string(p).unwrap()) > 0)
        .collect();
    assert!(stray.is_empty(), "unsafe outside pipeline/simd: {stray:?}");
    assert!(unsafe_lines("let a = 1; // unsafe { b }") == 0);
    assert!(unsafe_lines("    unsafe { v.set_len(n) };") == 1);
}

#[test]
fn pipeline_files_stay_under_700_lines() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("src/pipeline");
    let mut files = Vec::new();
    rust_files(&root, &mut files);
    let long: Vec<_> = files
        .iter()
        .map(|p| (p, std::fs::read_to_string(p).unwrap().lines().count()))
        .filter(|&(_, n)| n > 700)
        .collect();
    assert!(long.is_empty(), "split these along their seams: {long:?}");
}
