//! What the commands print on standard output and standard error, without a panic when it cannot
//! be written: a reader that went away (`| head`) takes nothing more and is no error, a write to
//! standard output that fails (a full disk under `>`) is one line naming it, and a line standard
//! error cannot take (`2>/dev/full`) is lost, since there is nowhere left to say so. Paths in
//! commands printed to paste are quoted for the shell.

use std::io::{ErrorKind, Write};

/// Writes `text` to standard output and flushes it.
///
/// # Errors
/// When the write fails for any reason but a closed pipe.
pub fn write_text(text: &str) -> anyhow::Result<()> {
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(e) if e.kind() != ErrorKind::BrokenPipe => {
            Err(anyhow::anyhow!("cannot write to standard output: {e}"))
        }
        _ => Ok(()),
    }
}

/// Writes one line (`args` and a newline) to standard output ([`write_text`]).
///
/// # Errors
/// As [`write_text`].
pub fn write_line(args: std::fmt::Arguments<'_>) -> anyhow::Result<()> {
    write_text(&format!("{args}\n"))
}

/// `println!` that returns [`write_line`]'s result instead of panicking.
#[macro_export]
macro_rules! say {
    ($($arg:tt)*) => {
        $crate::stdout::write_line(format_args!($($arg)*))
    };
}

/// Writes one line (`args` and a newline) to standard error; one it cannot take is lost.
pub fn tell_line(args: std::fmt::Arguments<'_>) {
    // Nowhere is left to report a failed write to standard error: the line is dropped.
    let _ = writeln!(std::io::stderr().lock(), "{args}");
}

/// `eprintln!` that drops a line standard error cannot take instead of panicking
/// ([`tell_line`]).
#[macro_export]
macro_rules! tell {
    ($($arg:tt)*) => {
        $crate::stdout::tell_line(format_args!($($arg)*))
    };
}

/// `path` as one word for a POSIX shell: bare when it holds only safe characters, else in
/// single quotes (a quote inside written as `'\''`).
#[must_use]
pub fn shell_quoted(path: &std::path::Path) -> String {
    let text = path.to_string_lossy();
    let safe = |c: char| c.is_ascii_alphanumeric() || "/._-+:,=@%".contains(c);
    if !text.is_empty() && text.chars().all(safe) {
        text.into_owned()
    } else {
        format!("'{}'", text.replace('\'', r"'\''"))
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;
    use std::path::Path;

    #[test]
    fn quoted_paths_reach_the_shell_as_one_word() {
        for p in [
            "plain/path.zarr",
            "ü dir/z ø.zarr",
            "it's here",
            "a$b`c\"d e",
        ] {
            let out = std::process::Command::new("sh")
                .arg("-c")
                .arg(format!("printf %s {}", shell_quoted(Path::new(p))))
                .output()
                .unwrap();
            assert_eq!(String::from_utf8(out.stdout).unwrap(), p);
        }
    }
}
