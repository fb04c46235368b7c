//! Repository hygiene: every source file starts with a `//!` line, the pipeline imports no disk, clock, GUI or audio code, `unsafe` stays in the SIMD module, printing cannot panic, files stay short.
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

/// Paths the pure pipeline must not reach: the disk and the scan reader (`io`), the workbench
/// (`app`), the GUI and audio crates, the clock and sleeping.
const PIPELINE_BANNED: &[&str] = &[
    "crate::io",
    "crate::app",
    "crate::playback",
    "std::fs",
    "std::time",
    "thread::sleep",
    "egui",
    "eframe",
    "cpal",
    "hound",
    "rfd",
];

/// The code of `text` that is not test code: `//` comments dropped, and everything from the
/// first `#[cfg(test)]` on (test modules come last in a file).
fn non_test_code(text: &str) -> String {
    let mut out = String::new();
    for line in text.lines() {
        let trimmed = line.trim_start();
        if trimmed.starts_with("#[cfg(test)]") {
            break;
        }
        let code = match line.find("//") {
            Some(i) => &line[..i],
            None => line,
        };
        out.push_str(code);
        out.push('\n');
    }
    out
}

/// Every `use` item of `code` (joined over lines, up to its `;`), and every other path of `code`
/// that names a banned module inline, each with the banned path it reaches.
fn banned_uses(code: &str) -> Vec<(String, &'static str)> {
    let mut found = Vec::new();
    let mut rest = code;
    // `use` items, grouped imports expanded: `use crate::{io::Scan, x}` reaches `crate::io`.
    while let Some(i) = rest.find("use ") {
        let before_ok = i == 0 || !rest.as_bytes()[i - 1].is_ascii_alphanumeric();
        let Some(len) = rest[i..].find(';') else {
            break;
        };
        let item: String = rest[i..i + len]
            .split_whitespace()
            .collect::<Vec<_>>()
            .join(" ");
        if before_ok {
            let flat = item.replace(' ', "");
            for &banned in PIPELINE_BANNED {
                let (root, leaf) = banned.rsplit_once("::").unwrap_or(("", banned));
                let grouped = !root.is_empty()
                    && flat.contains(&format!("{root}::{{"))
                    && flat
                        .split(['{', ',', '}'])
                        .any(|part| part == leaf || part.starts_with(&format!("{leaf}::")));
                if flat.contains(banned) || grouped {
                    found.push((item.clone(), banned));
                }
            }
        }
        rest = &rest[i + len..];
    }
    // Inline paths such as `crate::io::load_group(..)` or `std::time::Instant::now()`.
    for line in code.lines() {
        if line.trim_start().starts_with("use ") {
            continue;
        }
        for &banned in PIPELINE_BANNED {
            if line.contains(&format!("{banned}::")) || line.contains(&format!("{banned}(")) {
                found.push((line.trim().to_string(), banned));
            }
        }
    }
    found
}

#[test]
fn the_purity_check_catches_each_kind_of_import() {
    for bad in [
        "use crate::io::Scan;",
        "use crate::io;",
        "use crate::{\n    io::Scan,\n    pipeline::Stage,\n};",
        "use std::fs::File;",
        "use std::{fs, path::Path};",
        "use std::time::Instant;",
        "use std::thread::sleep;",
        "    let t = std::time::Instant::now();",
        "    std::thread::sleep(d);",
        "    let s = crate::io::Scan::open(p)?;",
        "use egui::Ui;",
    ] {
        assert!(!banned_uses(bad).is_empty(), "missed: {bad}");
    }
    for fine in [
        "use crate::meta::ScanMeta;",
        "use std::path::Path;",
        "use super::sampling::native_spacing_um;",
        "// use crate::io::Scan;",
    ] {
        assert!(
            banned_uses(&non_test_code(fine)).is_empty(),
            "flagged: {fine}"
        );
    }
    let with_tests =
        "use crate::meta::Cut;\n#[cfg(test)]\nmod tests {\n    use crate::io::Scan;\n}\n";
    assert!(banned_uses(&non_test_code(with_tests)).is_empty());
}

#[test]
fn pipeline_never_imports_io_app_disk_clock_gui_or_audio() {
    let mut stray = Vec::new();
    for f in src_files_where(|rel| rel.starts_with("src/pipeline/")) {
        let name = f.file_name().unwrap().to_string_lossy();
        // Test modules (`tests.rs`, `test_support.rs`) may read scans from disk and time things.
        if name == "tests.rs" || name == "test_support.rs" {
            continue;
        }
        let text = std::fs::read_to_string(&f).unwrap();
        for (item, banned) in banned_uses(&non_test_code(&text)) {
            stray.push(format!("{}: `{item}` reaches {banned}", f.display()));
        }
    }
    assert!(
        stray.is_empty(),
        "the pipeline must stay pure:\n{}",
        stray.join("\n")
    );
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

/// The files under `src/` whose path from the crate root (`src/…`, with `/`) `keep` accepts.
fn src_files_where(keep: impl Fn(&str) -> bool) -> Vec<std::path::PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    rust_files(&root.join("src"), &mut files);
    files.retain(|p| {
        keep(
            &p.strip_prefix(root)
                .unwrap()
                .to_string_lossy()
                .replace('\\', "/"),
        )
    });
    files
}

#[test]
fn unsafe_lives_only_in_the_simd_module_and_the_allocator_setup() {
    let allowed = ["src/pipeline/simd/", "src/alloc.rs"];
    let stray: Vec<_> = src_files_where(|rel| !allowed.iter().any(|a| rel.starts_with(a)))
        .into_iter()
        .filter(|p| unsafe_lines(&std::fs::read_to_string(p).unwrap()) > 0)
        .collect();
    assert!(stray.is_empty(), "unsafe outside pipeline/simd: {stray:?}");
    assert!(unsafe_lines("let a = 1; // unsafe { b }") == 0);
    assert!(unsafe_lines("    unsafe { v.set_len(n) };") == 1);
}

#[test]
fn source_files_stay_under_700_lines() {
    let long: Vec<_> = src_files_where(|_| true)
        .into_iter()
        .map(|p| {
            let n = std::fs::read_to_string(&p).unwrap().lines().count();
            (p, n)
        })
        .filter(|&(_, n)| n > 700)
        .collect();
    assert!(long.is_empty(), "split these along their seams: {long:?}");
}

/// Printing macros that panic when their stream cannot be written (`2>/dev/full`, a closed
/// pipe) in `code`.
fn panicking_prints(code: &str) -> usize {
    ["println!(", "print!(", "eprintln!(", "eprint!("]
        .iter()
        .map(|m| {
            code.match_indices(m)
                .filter(|&(i, _)| !code[..i].ends_with(|c: char| c.is_alphanumeric() || c == '_'))
                .count()
        })
        .sum()
}

#[test]
fn the_program_prints_only_through_the_macros_that_cannot_panic() {
    let program = |rel: &str| {
        !(rel.contains("/tests/") || rel.ends_with("tests.rs") || rel == "src/stdout.rs")
    };
    let stray: Vec<_> = src_files_where(program)
        .into_iter()
        .filter(|p| panicking_prints(&non_test_code(&std::fs::read_to_string(p).unwrap())) > 0)
        .collect();
    assert!(
        stray.is_empty(),
        "use crate::say! or crate::tell!: {stray:?}"
    );
    assert_eq!(
        panicking_prints("eprintln!(\"x\"); crate::tell!(\"y\"); println!(\"z\")"),
        2
    );
    assert_eq!(panicking_prints("my_println!(a); say!(b)"), 0);
}
