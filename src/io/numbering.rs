//! Numbered names as positions: group folders and frames numbered `g00000, g00001, …` are
//! put in number order, and a number the sequence skips keeps its place.
//!
//! Name order alone would splice silently: a missing `g00003` would pull every later group one
//! step back along the groove (the sound loses a stretch and nothing says so), and unpadded
//! names sort `g10` before `g2`. So when every name is one prefix followed by a number (and one
//! extension), the numbers set the order, and when they lie on a regular step (1, or 2 for every
//! other group) they say where each entry lies: a skipped number gets the path it would have
//! had. That path does not exist, so reading it fails naming it: a missing group becomes a gap
//! under `--keep-going`, a missing frame fails its group. Numbers on no regular step
//! (timestamps) set the order only, as all numbers do when `scan.toml` says
//! `numbered_names = "order"` (timestamps of whole seconds can look like a regular step).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::LoadError;
use crate::meta::NumberedNames;

/// A name split around the number that ends its stem: `g00012` → prefix `g`, 12, 5 digits;
/// `f007.png` → prefix `f`, 7, 3 digits, extension `.png`.
#[derive(Debug, PartialEq)]
struct Numbered<'a> {
    prefix: &'a str,
    number: u64,
    digits: usize,
    extension: &'a str,
}

/// Most digits read as a number (`u64` holds every 18-digit number).
const MAX_DIGITS: usize = 18;

impl Numbered<'_> {
    /// Whether `other` is numbered the same way: one prefix and one extension.
    fn same_scheme(&self, other: &Numbered<'_>) -> bool {
        self.prefix == other.prefix && self.extension == other.extension
    }
}

fn numbered(path: &Path) -> Option<Numbered<'_>> {
    let name = path.file_name()?.to_str()?;
    let stem = path.file_stem()?.to_str()?;
    let extension = &name[stem.len()..];
    let prefix = stem.trim_end_matches(|c: char| c.is_ascii_digit());
    let digits = stem.len() - prefix.len();
    if digits == 0 || digits > MAX_DIGITS {
        return None;
    }
    Some(Numbered {
        prefix,
        number: stem[prefix.len()..].parse().ok()?,
        digits,
        extension,
    })
}

/// The entries of `paths` that are not part of a numbered scan: when every entry that
/// `holds_frames` shares one numbering (one prefix and one extension before and after the
/// number), the entries holding no frames whose names do not fit it (`notes/`,
/// `calibration/`); otherwise none. Such a folder is no group: in name order it would take a
/// place on the groove, shift every group after it, and fail the run there.
pub(super) fn strays(paths: &[PathBuf], holds_frames: impl Fn(usize) -> bool) -> Vec<usize> {
    let names: Vec<Option<Numbered<'_>>> = paths.iter().map(|p| numbered(p)).collect();
    let mut with_frames = (0..paths.len()).filter(|&i| holds_frames(i));
    let Some(Some(first)) = with_frames.next().map(|i| &names[i]) else {
        return Vec::new();
    };
    let fits = |n: &Option<Numbered<'_>>| n.as_ref().is_some_and(|n| n.same_scheme(first));
    if !with_frames.all(|i| fits(&names[i])) {
        return Vec::new();
    }
    (0..paths.len())
        .filter(|&i| !holds_frames(i) && !fits(&names[i]))
        .collect()
}

/// `paths` (entries of `dir`, sorted by name) in the order they lie in: by number when every
/// name is one prefix, a number and one extension, and when the numbers lie on a regular step
/// ([`regular_step`]) and `names` says they are positions, with the path a skipped number would
/// have had in its place; otherwise unchanged (name order). `what` names the entries in errors.
///
/// # Errors
/// [`LoadError::NotAScan`] when two names carry one number (`g1` and `g01`), or the numbers
/// span more than `limit` entries.
pub(super) fn in_numbered_order(
    dir: &Path,
    paths: Vec<PathBuf>,
    limit: usize,
    what: &str,
    names_say: NumberedNames,
) -> Result<Vec<PathBuf>, LoadError> {
    let refuse = |problem: String| LoadError::NotAScan {
        problem,
        path: dir.to_path_buf(),
    };
    let Some(names) = paths
        .iter()
        .map(|p| numbered(p))
        .collect::<Option<Vec<_>>>()
    else {
        return Ok(paths);
    };
    let Some(first) = names.first() else {
        return Ok(paths);
    };
    if !names.iter().all(|n| n.same_scheme(first)) {
        return Ok(paths);
    }
    let mut by_number = BTreeMap::new();
    for (n, path) in names.iter().zip(&paths) {
        if let Some(other) = by_number.insert(n.number, path) {
            return Err(refuse(format!(
                "{what} {} and {} carry the same number, {}, so their order is unknown",
                file_name(other),
                file_name(path),
                n.number
            )));
        }
    }
    let numbers: Vec<u64> = by_number.keys().copied().collect();
    let (Some(&low), Some(&high)) = (numbers.first(), numbers.last()) else {
        return Ok(paths);
    };
    // Numbers not on a regular step are not positions (timestamps): they set the order only.
    let step = match names_say {
        NumberedNames::Positions => regular_step(&numbers),
        NumberedNames::Order => None,
    };
    let Some(step) = step else {
        return Ok(by_number.into_values().cloned().collect());
    };
    let places = (high - low) / step + 1;
    if places > limit as u64 {
        return Err(refuse(format!(
            "the {what} are numbered {low} to {high} in steps of {step}, more places than the limit of {limit}"
        )));
    }
    // A skipped number is written as its neighbours are, padded as the shortest of them is
    // (g00003 among g00000…g99999, g100000…).
    let width = names.iter().map(|n| n.digits).min().unwrap_or(1);
    Ok((0..places)
        .map(|k| {
            let number = low + k * step;
            match by_number.get(&number) {
                Some(path) => (*path).clone(),
                None => dir.join(format!(
                    "{}{number:0width$}{}",
                    first.prefix, first.extension
                )),
            }
        })
        .collect())
}

/// The step of `numbers` (sorted, distinct) when they lie on one, the gaps between neighbours
/// that are not one step being skipped numbers:
/// - 1 when at least half the gaps are 1 (`g0, g1, g3`), or 1 is the commonest gap (a scan
///   that lost most of its groups), and for two numbers, which cannot show a step of their
///   own (so `g0, g2` is a scan that lost `g1`: refused or a gap, never a silent splice);
/// - else the commonest gap when at least two gaps and half of them are that, and every gap is
///   a whole number of it (2 for every other group of a scan taken at twice the step);
/// - None otherwise (timestamps): the numbers set the order only.
fn regular_step(numbers: &[u64]) -> Option<u64> {
    let gaps: Vec<u64> = numbers.windows(2).map(|w| w[1] - w[0]).collect();
    let ones = gaps.iter().filter(|&&g| g == 1).count();
    if 2 * ones >= gaps.len() || gaps.len() == 1 {
        return Some(1);
    }
    let mut counts = BTreeMap::new();
    for &g in &gaps {
        *counts.entry(g).or_insert(0usize) += 1;
    }
    let (&step, &count) = counts
        .iter()
        .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(a.0)))?;
    // A scan that lost most of its groups still steps by 1 more often than by anything else.
    if step == 1 && count >= 2 {
        return Some(1);
    }
    let on_lattice = gaps.iter().all(|g| g % step == 0);
    (on_lattice && count >= 2 && 2 * count >= gaps.len()).then_some(step)
}

fn file_name(path: &Path) -> String {
    path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn order(names: &[&str]) -> Result<Vec<String>, LoadError> {
        let dir = Path::new("/scan");
        let mut paths: Vec<PathBuf> = names.iter().map(|n| dir.join(n)).collect();
        paths.sort();
        in_numbered_order(dir, paths, 100, "group folders", NumberedNames::Positions)
            .map(|v| v.iter().map(|p| file_name(p)).collect())
    }

    #[test]
    fn names_said_to_be_an_order_keep_no_place_for_a_skipped_number() {
        let dir = Path::new("/scan");
        let paths: Vec<PathBuf> = ["t100", "t101", "t103", "t99"]
            .iter()
            .map(|n| dir.join(n))
            .collect();
        let names = |say| {
            in_numbered_order(dir, paths.clone(), 100, "group folders", say)
                .unwrap()
                .iter()
                .map(|p| file_name(p))
                .collect::<Vec<_>>()
        };
        assert_eq!(names(NumberedNames::Order), ["t99", "t100", "t101", "t103"]);
        assert_eq!(
            names(NumberedNames::Positions),
            ["t99", "t100", "t101", "t102", "t103"]
        );
    }

    #[test]
    fn numbers_set_the_order_and_a_skipped_one_keeps_its_place() {
        let cases: [(&str, &[&str], &[&str]); 10] = [
            (
                "a skipped group, named as its neighbours",
                &["g00000", "g00001", "g00002", "g00004"],
                &["g00000", "g00001", "g00002", "g00003", "g00004"],
            ),
            (
                "frames out of order",
                &["f007.png", "f009.png", "f008.png"],
                &["f007.png", "f008.png", "f009.png"],
            ),
            (
                "a skipped frame",
                &["f1.tif", "f3.tif", "f4.tif"],
                &["f1.tif", "f2.tif", "f3.tif", "f4.tif"],
            ),
            (
                "timestamps: no regular step, the order only",
                &["t1701234567", "t1701234590", "t1701234602"],
                &["t1701234567", "t1701234590", "t1701234602"],
            ),
            (
                "nearly regular timestamps",
                &["t100", "t201", "t299", "t400"],
                &["t100", "t201", "t299", "t400"],
            ),
            (
                "every other group of a scan at twice the step, one missing",
                &["g0", "g10", "g2", "g4", "g8"],
                &["g0", "g2", "g4", "g6", "g8", "g10"],
            ),
            (
                "every other group",
                &["g0", "g2", "g4"],
                &["g0", "g2", "g4"],
            ),
            (
                "two numbers show no step: a scan of three that lost its middle",
                &["g0", "g2"],
                &["g0", "g1", "g2"],
            ),
            (
                "padded as the shortest name",
                &["g99998", "g99999", "g100000", "g100002"],
                &["g99998", "g99999", "g100000", "g100001", "g100002"],
            ),
            (
                "padded as the shortest name, across the width change",
                &["g99998", "g100000", "g100001"],
                &["g99998", "g99999", "g100000", "g100001"],
            ),
        ];
        for (case, names, want) in cases {
            assert_eq!(order(names).unwrap(), want, "{case}");
        }
        // One far folder: every place between is missing.
        assert_eq!(order(&["g0", "g1", "g2", "g9"]).unwrap().len(), 10);
        assert_eq!(
            order(&["g1", "g3", "g4"]).unwrap(),
            ["g1", "g2", "g3", "g4"]
        );
        assert_eq!(
            order(&["g0", "g1", "g3"]).unwrap(),
            ["g0", "g1", "g2", "g3"]
        );
        // Most groups lost: gaps 1, 1, 3, 4, 5; still steps of 1, the rest missing.
        assert_eq!(
            order(&["g0", "g1", "g2", "g5", "g9", "g14"]).unwrap().len(),
            15
        );
    }

    #[test]
    fn unpadded_numbers_go_in_number_order_not_name_order() {
        assert_eq!(
            order(&["g1", "g10", "g2", "g3", "g4", "g5", "g6", "g7", "g8", "g9"]).unwrap(),
            ["g1", "g2", "g3", "g4", "g5", "g6", "g7", "g8", "g9", "g10"]
        );
    }

    #[test]
    fn names_of_no_common_numbering_keep_name_order() {
        for names in [
            &["g00000", "g00002", "notes"][..],
            &["a1", "b3"],
            &["f000.png", "f002.tif"],
            &["take", "retake"],
        ] {
            let mut sorted: Vec<String> = names.iter().map(ToString::to_string).collect();
            sorted.sort();
            assert_eq!(order(names).unwrap(), sorted, "{names:?}");
        }
    }

    #[test]
    fn frameless_folders_outside_the_numbering_are_strays() {
        let paths: Vec<PathBuf> = ["calibration", "g00000", "g00001", "g00003", "notes"]
            .iter()
            .map(PathBuf::from)
            .collect();
        // g00003 holds no frames but fits: a group cut short, not a stray.
        let frames = [false, true, true, false, false];
        assert_eq!(strays(&paths, |i| frames[i]), [0, 4]);
        // A folder of frames outside the numbering: no numbering, so no strays.
        let frames = [true, true, true, false, false];
        assert!(strays(&paths, |i| frames[i]).is_empty());
        assert!(strays(&paths, |_| false).is_empty());
    }

    #[test]
    fn one_number_twice_and_a_span_past_the_limit_are_refused() {
        let msg = order(&["g1", "g01"]).unwrap_err().to_string();
        assert!(msg.contains("g01 and g1 carry the same number, 1"), "{msg}");
        assert!(msg.contains("/scan"), "{msg}");
        let dense: Vec<String> = (0..=100)
            .filter(|k| k % 10 != 5)
            .map(|k| format!("g{k}"))
            .collect();
        let dense: Vec<&str> = dense.iter().map(String::as_str).collect();
        let msg = order(&dense).unwrap_err().to_string();
        assert!(msg.contains("numbered 0 to 100 in steps of 1"), "{msg}");
        assert_eq!(order(&dense[..dense.len() - 1]).unwrap().len(), 100);
        // Past what u64 holds: not a number, so name order.
        let long = "g".to_string() + &"9".repeat(19);
        assert_eq!(order(&[&long, "g1"]).unwrap(), ["g1", long.as_str()]);
    }
}
