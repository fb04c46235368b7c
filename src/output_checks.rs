//! The checks a command makes of the files it is about to write, before any work: no folder, no input, nothing existing without `--force`, nothing among a scan's data.

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};

/// Checks the files a command is about to write, before any work: none is a folder, each
/// one's folder exists, no two are the same file, none is one of the command's `inputs`
/// (`--force` or not: an input overwritten is lost), and none exists unless `force` says to
/// replace it.
///
/// # Errors
/// One line naming the path at fault.
pub(crate) fn check_outputs(paths: &[&Path], inputs: &[&Path], force: bool) -> Result<()> {
    for &out in paths {
        check_name_room(out)?;
    }
    // Existing files by their canonical path (links and `..` resolved), others as given.
    let identity = |p: &Path| {
        std::fs::canonicalize(p)
            .or_else(|_| std::path::absolute(p))
            .unwrap_or_else(|_| p.to_path_buf())
    };
    let inputs: Vec<PathBuf> = inputs
        .iter()
        .filter(|p| p.exists())
        .map(|p| identity(p))
        .collect();
    let mut seen = Vec::with_capacity(paths.len());
    for &out in paths {
        if out.is_dir() {
            bail!("the output is a folder, not a file name: {}", out.display());
        }
        // `x.wav/` names a folder: its write would fail only after the work.
        if out
            .as_os_str()
            .as_encoded_bytes()
            .last()
            .is_some_and(|&b| std::path::is_separator(char::from(b)))
        {
            bail!(
                "the output ends in a path separator, which names a folder, not a file: {}",
                out.display()
            );
        }
        check_parent_exists(out)?;
        let id = identity(out);
        if seen.contains(&id) {
            bail!("two outputs name the same file: {}", out.display());
        }
        if inputs.contains(&id) {
            bail!(
                "the output is one of this command's inputs, which it would destroy: {}",
                out.display()
            );
        }
        seen.push(id);
        if out.exists() && !force {
            bail!(
                "refusing to overwrite an existing file (use --force): {}",
                out.display()
            );
        }
    }
    Ok(())
}

/// Longest file name most file systems take (bytes; Linux's `NAME_MAX`).
const NAME_MAX_BYTES: usize = 255;
/// Bytes the names written beside an output add to its own: `.NAME.journal.PID.N.tmp`, the
/// longest (the journal's temporary file), with room for a 7-digit process id and a counter.
const HELPER_NAME_BYTES: usize = 32;

/// Refuses an output whose name leaves no room for the temporary, lock and journal files
/// written beside it: such a run would fail only when it first wrote one, after its work, and
/// its `--resume` the same way.
fn check_name_room(out: &Path) -> Result<()> {
    let len = out.file_name().map_or(0, |n| n.as_encoded_bytes().len());
    let most = NAME_MAX_BYTES - HELPER_NAME_BYTES;
    if len > most {
        bail!(
            "the output's name is {len} bytes long, more than the {most} that leave room for the temporary, lock and journal files written beside it (names of at most {NAME_MAX_BYTES} bytes): {}",
            out.display()
        );
    }
    Ok(())
}

/// Refuses outputs that would land among a scan's data, `--force` or not: in a folder inside
/// the scan folder (a group's: a file there is read as a frame, or replaces one), or anywhere
/// in a Zarr store. Beside the groups, in the scan folder itself, is allowed.
///
/// # Errors
/// One line naming the output and the scan.
pub(crate) fn check_outside_scan(paths: &[&Path], scan: &Path) -> Result<()> {
    // A scan that does not open is refused when it is opened.
    let Ok(scan_id) = std::fs::canonicalize(scan) else {
        return Ok(());
    };
    let store = scan_id.join("zarr.json").is_file();
    for &out in paths {
        let folder = out.parent().filter(|p| !p.as_os_str().is_empty());
        let Ok(folder) = std::fs::canonicalize(folder.unwrap_or(Path::new("."))) else {
            continue;
        };
        if store && folder.starts_with(&scan_id) {
            bail!(
                "the output lies inside the Zarr store it reads ({}), which it would alter: {}",
                scan.display(),
                out.display()
            );
        }
        if folder != scan_id && folder.starts_with(&scan_id) {
            bail!(
                "the output lies inside a folder of the scan it reads ({}), among its frames, which it would alter: {}",
                scan.display(),
                out.display()
            );
        }
    }
    Ok(())
}

/// Refuses an output folder (one a command makes and fills) inside a scan folder or store, or
/// the scan itself, `--force` or not: a folder there is read as a group, or alters one.
///
/// # Errors
/// One line naming the output and the scan.
pub(crate) fn check_folder_outside_scan(out: &Path, scan: &Path) -> Result<()> {
    let Ok(scan_id) = std::fs::canonicalize(scan) else {
        return Ok(());
    };
    // The folder as it will be: itself where it exists, else its parent's place joined.
    let id = std::fs::canonicalize(out).ok().or_else(|| {
        let parent = out.parent().filter(|p| !p.as_os_str().is_empty());
        let parent = std::fs::canonicalize(parent.unwrap_or(Path::new("."))).ok()?;
        Some(parent.join(out.file_name()?))
    });
    if id.is_some_and(|id| id.starts_with(&scan_id)) {
        bail!(
            "the output folder lies inside the scan it reads ({}), where it would be read as a group or alter one: {}",
            scan.display(),
            out.display()
        );
    }
    Ok(())
}

/// `second`, the result of writing a run's second output (its report) after `first` (its WAV):
/// on failure `first`, which the run has just written, is removed too, so a failed run leaves
/// neither; a lone WAV would make the same command refuse without `--force`.
///
/// # Errors
/// `second`'s error, saying the WAV was removed.
pub(crate) fn undo_first_on_error<T>(first: &Path, second: Result<T>) -> Result<T> {
    second.map_err(|e| {
        let removed = std::fs::remove_file(first).is_ok();
        if removed {
            anyhow::anyhow!(
                "{e:#} (the WAV it goes with was removed, so the same command writes both: {})",
                first.display()
            )
        } else {
            e
        }
    })
}

/// Refuses an output (a file, or a folder to be made) whose folder does not exist: a mistyped
/// path is named, not created.
///
/// # Errors
/// One line naming the missing folder.
pub(crate) fn check_parent_exists(out: &Path) -> Result<()> {
    if let Some(parent) = out.parent().filter(|p| !p.as_os_str().is_empty())
        && !parent.is_dir()
    {
        bail!("the output's folder does not exist: {}", parent.display());
    }
    Ok(())
}
