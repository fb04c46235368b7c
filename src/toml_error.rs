//! One line for a TOML read error: the `table.key` it stands at and its line number, since the
//! parser's own message ("invalid value: integer `-1`, expected u32") names neither.

/// `message` located in `text`: `table.key (line N): message` where the error has a position,
/// else `message` alone.
#[must_use]
pub fn located(text: &str, error: &toml::de::Error) -> String {
    let message = error.message().trim_end();
    if let Some(field) = message
        .strip_prefix("missing field `")
        .and_then(|m| m.split_once('`'))
        .map(|(f, _)| f)
    {
        return missing(text, error, field);
    }
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
    let key = key_of(line).filter(|k| !k.is_empty() && !k.starts_with('['));
    let table = text[..line_start].lines().rev().find_map(header);
    match key {
        Some(k) => format!("{} (line {line_no}): {message}", qualified(table, k)),
        None => format!("line {line_no}: {message}"),
    }
}

/// A missing table or key `field`: the table it is missing from (the parser points at that
/// table, or at the file's start for a top-level one, whose first line is no help), and the
/// name the file spells otherwise where only the case differs (`[Motion]` for `[motion]`).
fn missing(text: &str, error: &toml::de::Error, field: &str) -> String {
    let table = error
        .span()
        .and_then(|s| text.get(s.start..))
        .and_then(|rest| rest.lines().next())
        .and_then(header);
    let mut line = match table {
        Some(t) => format!("[{t}] lacks the key `{field}`"),
        None => format!("the table [{field}] (or top-level key `{field}`) is missing"),
    };
    let spelt = text.lines().find_map(|l| {
        let name = header(l)
            .map(|t| t.rsplit('.').next().unwrap_or(t).trim())
            .or_else(|| key_of(l))?;
        (name != field && name.eq_ignore_ascii_case(field)).then(|| l.trim().to_string())
    });
    if let Some(spelt) = spelt {
        line.push_str(&format!(
            " (the file has `{spelt}`: names are lower case and case counts)"
        ));
    }
    line
}

/// The table a `[table]` or `[[table]]` header line names; a comment may follow it
/// (`[synth]  # mine`).
fn header(line: &str) -> Option<&str> {
    let bare = line.split_once('#').map_or(line, |(b, _)| b).trim();
    bare.strip_prefix('[')?
        .strip_suffix(']')
        .map(|t| t.trim_matches(['[', ']']).trim())
}

/// The key of a `key = value` line (before its first `=`, trimmed).
fn key_of(line: &str) -> Option<&str> {
    line.split_once('=').map(|(k, _)| k.trim())
}

/// `table.key`, or `key` at the top level.
fn qualified(table: Option<&str>, key: &str) -> String {
    table.map_or_else(|| key.to_string(), |t| format!("{t}.{key}"))
}

/// `key` of `text`'s `[table]` (top-level keys with `table` None) named with its line, as
/// [`located`] names a parse error: `table.key (line N)`; without the line when the key is
/// not written as `key = …` there (a merged table's keys have no positions of their own).
#[must_use]
pub fn key_at(text: &str, table: Option<&str>, key: &str) -> String {
    let name = qualified(table, key);
    let mut current = None;
    for (i, line) in text.lines().enumerate() {
        if let Some(t) = header(line) {
            current = Some(t);
        } else if current == table && key_of(line) == Some(key) {
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
    fn a_missing_table_or_key_is_named_with_a_wrongly_cased_spelling() {
        let line = error_of("format = 1\n[Flow]\nmax_iterations = 3\n");
        assert_eq!(
            line,
            "the table [flow] (or top-level key `flow`) is missing (the file has `[Flow]`: \
             names are lower case and case counts)"
        );
        let line = error_of("[flow]\nMax_Iterations = 3\n");
        assert_eq!(
            line,
            "[flow] lacks the key `max_iterations` (the file has `Max_Iterations = 3`: names \
             are lower case and case counts)"
        );
        let line = error_of("[flow]\n");
        assert_eq!(line, "[flow] lacks the key `max_iterations`");
    }

    #[test]
    fn a_wrong_type_is_named_too_and_a_broken_file_gets_its_line() {
        let line = error_of("[flow]\nmax_iterations = \"many\"\n");
        assert!(line.starts_with("flow.max_iterations (line 2): "), "{line}");
        let line = error_of("[flow\nmax_iterations = 3\n");
        assert!(line.starts_with("line 1: "), "{line}");
    }
}
