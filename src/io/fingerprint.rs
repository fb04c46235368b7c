//! Fingerprints that tell runs and scans apart: a plan, journal, part or partial pack is only ever continued on the scan it was made from.

use super::Scan;

/// 64-bit FNV-1a of `bytes`, as 16 hex digits: a fingerprint for telling runs apart (not a
/// defence against forgery).
#[must_use]
pub fn fingerprint(bytes: &[u8]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    format!("{h:016x}")
}

/// The scan's fingerprint: its metadata (as canonical TOML), and every group's name and frame
/// count. The folder and the Zarr form of one scan have the same one.
#[must_use]
pub fn scan_fingerprint(scan: &Scan) -> String {
    fingerprint(identity_text(scan, true).as_bytes())
}

/// The fingerprint of the scan's metadata and group names alone: what an interrupted pack
/// must match to go on. A group mended by adding or removing a frame stays the same scan to
/// it (the store checks every group's frame count itself).
#[must_use]
pub fn scan_names_fingerprint(scan: &Scan) -> String {
    fingerprint(identity_text(scan, false).as_bytes())
}

/// The metadata as canonical TOML, then every group's name (and frame count).
fn identity_text(scan: &Scan, frame_counts: bool) -> String {
    let mut text = scan.meta.to_toml_string().unwrap_or_default();
    text.push_str(&format!("\ngroups {}\n", scan.groups.len()));
    for g in &scan.groups {
        if frame_counts {
            text.push_str(&format!("{} {}\n", g.name(), g.frame_count()));
        } else {
            text.push_str(&format!("{}\n", g.name()));
        }
    }
    text
}
