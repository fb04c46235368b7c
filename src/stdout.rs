//! What the commands print on standard output and standard error, without a panic when it cannot
//! be written: a reader that went away (`| head`) takes nothing more and is no error, a write to
//! standard output that fails (a full disk under `>`) is one line naming it, and a line standard
//! error cannot take (`2>/dev/full`) is lost, since there is nowhere left to say so.

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
