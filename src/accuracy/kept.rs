//! Hand-run sections of the report that a regenerated report keeps verbatim (between markers).
//!
//! The decoders-side-by-side section of docs/ACCURACY.md is measured by the commands it lists
//! (paper-optics scans of several minutes each), not by the suite. When the suite rewrites an
//! existing report, every block between [`KEPT_BEGIN`] and [`KEPT_END`] of the old file comes
//! back unchanged, in its old order, right after the new report's title.

/// Opens a block the suite keeps (the rest of the line is free text).
pub const KEPT_BEGIN: &str = "<!-- kept by groovescope accuracy: begin";
/// Closes it.
pub const KEPT_END: &str = "<!-- kept by groovescope accuracy: end -->";

/// The kept blocks of `old`, each from its [`KEPT_BEGIN`] line to its [`KEPT_END`] line
/// inclusive. A block without an end is not kept (so a broken marker never swallows the rest).
#[must_use]
pub fn kept_blocks(old: &str) -> Vec<&str> {
    let mut blocks = Vec::new();
    let mut rest = old;
    let mut offset = 0;
    while let Some(begin) = rest.find(KEPT_BEGIN) {
        let after = &rest[begin..];
        let Some(end) = after.find(KEPT_END) else {
            break;
        };
        let stop = end + KEPT_END.len();
        blocks.push(&old[offset + begin..offset + begin + stop]);
        offset += begin + stop;
        rest = &old[offset..];
    }
    blocks
}

/// `new` with the kept blocks of `old` put back after its first line (the title), each followed
/// by a blank line. `new` unchanged when `old` has none.
#[must_use]
pub fn with_kept(new: &str, old: &str) -> String {
    let blocks = kept_blocks(old);
    if blocks.is_empty() {
        return new.to_string();
    }
    let (title, body) = match new.find('\n') {
        Some(i) => new.split_at(i + 1),
        None => (new, ""),
    };
    let mut out =
        String::with_capacity(new.len() + blocks.iter().map(|b| b.len() + 2).sum::<usize>());
    out.push_str(title);
    out.push('\n');
    for b in blocks {
        out.push_str(b);
        out.push_str("\n\n");
    }
    out.push_str(body.trim_start_matches('\n'));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const OLD: &str = "# groovescope accuracy report\n\n\
        <!-- kept by groovescope accuracy: begin (hand-run) -->\n\
        ## Decoders side by side\n\n| a | b |\n|---|---|\n| 1 | 2 |\n\
        <!-- kept by groovescope accuracy: end -->\n\n\
        Made by `groovescope accuracy` (old).\n\n## Sinusoids\n\nold figures\n";
    const NEW: &str = "# groovescope accuracy report\n\nMade by `groovescope accuracy` (new).\n\n## Sinusoids\n\nnew figures\n";

    #[test]
    fn a_regenerated_report_keeps_the_marked_section_verbatim_and_takes_the_new_figures() {
        let merged = with_kept(NEW, OLD);
        let block = kept_blocks(OLD);
        assert_eq!(block.len(), 1);
        assert!(block[0].starts_with(KEPT_BEGIN) && block[0].ends_with(KEPT_END));
        assert!(block[0].contains("| 1 | 2 |"));
        assert!(merged.contains(block[0]), "{merged}");
        assert!(merged.starts_with("# groovescope accuracy report\n\n<!-- kept"));
        assert!(merged.contains("new figures") && !merged.contains("old figures"));
        assert!(merged.contains("(new)") && !merged.contains("(old)"));
        // Regenerating again changes nothing.
        assert_eq!(with_kept(NEW, &merged), merged);
    }

    #[test]
    fn no_markers_or_an_unclosed_one_keep_nothing() {
        assert_eq!(with_kept(NEW, "# old report\n\nno markers\n"), NEW);
        let unclosed = format!("# r\n\n{KEPT_BEGIN} -->\n## half a section\n");
        assert!(kept_blocks(&unclosed).is_empty());
        assert_eq!(with_kept(NEW, &unclosed), NEW);
    }
}
