//! What the commands print on standard output, without a panic when it cannot be written: a
//! reader that went away (`| head`) takes nothing more and is no error, and a write that fails
//! (a full disk under `>`) is one line naming standard output.

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
