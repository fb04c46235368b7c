//! One line for a TOML read error: the `table.key` it stands at and its line number, since the
//! parser's own message ("invalid value: integer `-1`, expected u32") names neither.

/// `message` located in `text`: `table.key (line N): message` where the error has a position,
/// else `message` alone.
#[must_use]
pub fn located(text: &str, error: &toml::de::Error) -> String {
    let message = error.message().trim_end();
    let Some(start) = error.span().map(|s| s.start) else {
        return message.to_string();
    };
    let Some(before) = text.get(..start) else {
        return message.to_string();
    };
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    let line_no = before.matches('\n').count() + 1;
    let line = text[line_start..].lines().next().unwrap_or("");
    // The key of a `key = value` line, under the last `[table]` header above it.
    let key = line
        .split_once('=')
        .map(|(k, _)| k.trim())
        .filter(|k| !k.is_empty() && !k.starts_with('['));
    let table = text[..line_start].lines().rev().find_map(|l| {
        let l = l.trim();
        l.strip_prefix('[')
            .and_then(|r| r.strip_suffix(']'))
            .map(|t| t.trim_matches(['[', ']']).trim().to_string())
    });
    match (table, key) {
        (Some(t), Some(k)) => format!("{t}.{k} (line {line_no}): {message}"),
        (None, Some(k)) => format!("{k} (line {line_no}): {message}"),
        _ => format!("line {line_no}: {message}"),
    }
}

/// `key` of `text`'s `[table]` (top-level keys with `table` None) named with its line, as
/// [`located`] names a parse error: `table.key (line N)`; without the line when the key is
/// not written as `key = …` there (a merged table's keys have no positions of their own).
#[must_use]
pub fn key_at(text: &str, table: Option<&str>, key: &str) -> String {
    let name = table.map_or_else(|| key.to_string(), |t| format!("{t}.{key}"));
    let mut current: Option<String> = None;
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        // A header may carry a comment: `[synth]  # mine`.
        let bare = line.split_once('#').map_or(line, |(b, _)| b).trim_end();
        if let Some(header) = bare.strip_prefix('[').and_then(|r| r.strip_suffix(']')) {
            current = Some(header.trim_matches(['[', ']']).trim().to_string());
        } else if current.as_deref() == table
            && line.split_once('=').is_some_and(|(k, _)| k.trim() == key)
        {
            return format!("{name} (line {})", i + 1);
        }
    }
    name
}

#[cfg(test)]
mod tests {
    use super::*;

    fn error_of(text: &str) -> String {
        #[derive(Debug, serde::Deserialize)]
        #[allow(dead_code)] // read only to fail
        struct Flow {
            max_iterations: u32,
        }
        #[derive(Debug, serde::Deserialize)]
        #[allow(dead_code)]
        struct Doc {
            flow: Flow,
        }
        let e = toml::from_str::<Doc>(text).unwrap_err();
        located(text, &e)
    }

    #[test]
    fn a_key_is_found_under_its_own_table() {
        let text = "width_px = 1\n[synth]  # mine\n# size\nwidth_px = 64\n  height_pxx = 9\n";
        assert_eq!(
            key_at(text, Some("synth"), "width_px"),
            "synth.width_px (line 4)"
        );
        assert_eq!(
            key_at(text, Some("synth"), "height_pxx"),
            "synth.height_pxx (line 5)"
        );
        assert_eq!(key_at(text, None, "width_px"), "width_px (line 1)");
        assert_eq!(key_at(text, Some("synth"), "seed"), "synth.seed");
    }

    #[test]
    fn a_bad_value_is_named_by_table_key_and_line() {
        let text = "# my settings\n[flow]\nmax_iterations = -1\n";
        let line = error_of(text);
        assert!(
            line.starts_with("flow.max_iterations (line 3): ") && line.contains("u32"),
            "{line}"
        );
    }

    #[test]
    fn a_wrong_type_is_named_too_and_a_broken_file_gets_its_line() {
        let line = error_of("[flow]\nmax_iterations = \"many\"\n");
        assert!(line.starts_with("flow.max_iterations (line 2): "), "{line}");
        let line = error_of("[flow\nmax_iterations = 3\n");
        assert!(line.starts_with("line 1: "), "{line}");
    }
}
