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
    match (key, header(line)) {
        (Some(k), _) => format!("{} (line {line_no}): {message}", qualified(table, k)),
        // A table's header (`[dsp.foo]`, which [dsp] has no field for): the table it names.
        (None, Some(t)) => format!("{t} (line {line_no}): {message}"),
        (None, None) => format!("line {line_no}: {message}"),
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
/// written neither as `key = …` there nor as a `[table.key]` header (a merged table's keys
/// have no positions of their own).
#[must_use]
pub fn key_at(text: &str, table: Option<&str>, key: &str) -> String {
    let name = qualified(table, key);
    match line_of(text, table, key) {
        Some(n) => format!("{name} (line {n})"),
        None => name,
    }
}

/// The line (from 1) where `text` writes `key` of `[table]`: a `key = …` line under that
/// table's header, or the header of the table `key` names (`[table.key]`, `[[table.key]]`, or
/// one of its subtables).
fn line_of(text: &str, table: Option<&str>, key: &str) -> Option<usize> {
    let name = qualified(table, key);
    let mut current = None;
    for (i, line) in text.lines().enumerate() {
        if let Some(t) = header(line) {
            if t == name
                || t.strip_prefix(name.as_str())
                    .is_some_and(|r| r.starts_with('.'))
            {
                return Some(i + 1);
            }
            current = Some(t);
        } else if current == table && key_of(line) == Some(key) {
            return Some(i + 1);
        }
    }
    None
}

/// `base` with the TOML `text` laid over it: the keys of its `[table]` where it has one, else
/// its top-level keys. Tables merge key by key, so `[synth.damage]` with one key keeps the
/// base's others. No key the file writes is dropped unread: a key `T` has no field for is
/// refused by its `deny_unknown_fields`, and beside a `[table]` any other top-level key or
/// table (`seed = 3` above `[synth]`, which nothing would read) is refused.
///
/// # Errors
/// The problem as one line naming the key and its line (`table.key (line N): …`); the caller
/// adds the file.
pub fn overlay<T>(base: &T, text: &str, table: &str) -> Result<T, String>
where
    T: serde::Serialize + serde::de::DeserializeOwned,
{
    let base = toml::Table::try_from(base).map_err(|e| e.to_string())?;
    let mut user: toml::Table = toml::from_str(text).map_err(|e| located(text, &e))?;
    let under = match user.remove(table) {
        Some(toml::Value::Table(keys)) => {
            // The first of the others in the file (the table's order is alphabetical).
            let outside = user
                .keys()
                .min_by_key(|k| line_of(text, None, k).unwrap_or(usize::MAX));
            if let Some(k) = outside {
                let at = key_at(text, None, k);
                let line = at.strip_prefix(k.as_str()).unwrap_or("");
                return Err(format!(
                    "`{k}`{line} is outside the [{table}] table, and only [{table}]'s keys are \
                     read when the file has one (move it under [{table}], or remove it)"
                ));
            }
            user = keys;
            Some(table)
        }
        // `table = 3`: read as a top-level key, which `T` names as unknown.
        Some(other) => {
            user.insert(table.to_string(), other);
            None
        }
        None => None,
    };
    let over = |keys: &toml::Table| {
        let mut merged = base.clone();
        merge_into(&mut merged, keys.clone());
        toml::Value::Table(merged).try_into::<T>()
    };
    over(&user).map_err(|e| {
        // The merged table has no positions: name the first of the user's keys that fails
        // on its own, with its line in the file.
        let key = user.iter().find_map(|(k, v)| {
            let one = toml::Table::from_iter([(k.clone(), v.clone())]);
            over(&one).is_err().then_some(k.as_str())
        });
        match key {
            Some(k) => format!("{}: {}", key_at(text, under, k), e.message()),
            None => e.message().to_string(),
        }
    })
}

/// `over`'s keys laid into `base`: a table into the base's table of that name key by key,
/// anything else (a value, an array, a table where the base has none) replacing it whole.
fn merge_into(base: &mut toml::Table, over: toml::Table) {
    for (k, v) in over {
        match (base.get_mut(&k), v) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge_into(b, o),
            (_, v) => {
                base.insert(k, v);
            }
        }
    }
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

    /// A base with a nested table, as the generator's settings have (`[synth.damage]`).
    #[derive(Debug, PartialEq, serde::Serialize, serde::Deserialize)]
    #[serde(default, deny_unknown_fields)]
    struct Inner {
        dust: f64,
        scratches: f64,
    }

    #[derive(Debug, PartialEq, serde::Serialize, serde::Deserialize)]
    #[serde(default, deny_unknown_fields)]
    struct Outer {
        seed: u32,
        damage: Inner,
    }

    impl Default for Inner {
        fn default() -> Self {
            Self {
                dust: 0.0,
                scratches: 0.0,
            }
        }
    }

    impl Default for Outer {
        fn default() -> Self {
            Self {
                seed: 1,
                damage: Inner::default(),
            }
        }
    }

    fn preset() -> Outer {
        Outer {
            seed: 7,
            damage: Inner {
                dust: 2.0,
                scratches: 3.0,
            },
        }
    }

    #[test]
    fn a_key_beside_the_table_is_refused_with_its_line_not_dropped() {
        // `seed` above [synth] was dropped unread, and the preset's seed used.
        let text = "# mine\nseed = 3\n[synth]\ndamage.dust = 1.0\n";
        let e = overlay(&preset(), text, "synth").unwrap_err();
        assert_eq!(
            e,
            "`seed` (line 2) is outside the [synth] table, and only [synth]'s keys are read \
             when the file has one (move it under [synth], or remove it)"
        );
        // A table beside it (scan.toml's [record], or [damage] for [synth.damage]): the first
        // one in the file is named.
        let text = "[synth]\nseed = 3\n[zebra]\nx = 1\n[damage]\ndust = 1.0\n";
        let e = overlay(&preset(), text, "synth").unwrap_err();
        assert!(e.starts_with("`zebra` (line 3) is outside"), "{e}");
        // Without the table, top-level keys are its keys, and an unknown one is named.
        let got = overlay(&preset(), "seed = 3\n", "synth").unwrap();
        assert_eq!(got.seed, 3);
        let e = overlay(&preset(), "seed = 3\nseeed = 4\n", "synth").unwrap_err();
        assert!(
            e.starts_with("seeed (line 2): unknown field `seeed`"),
            "{e}"
        );
        let e = overlay(&preset(), "[synth]\nseeed = 4\n", "synth").unwrap_err();
        assert!(
            e.starts_with("synth.seeed (line 2): unknown field `seeed`"),
            "{e}"
        );
    }

    #[test]
    fn a_nested_table_keeps_the_bases_other_keys() {
        // [synth.damage] with one key replaced the preset's whole damage table by defaults.
        let got = overlay(&preset(), "[synth.damage]\ndust = 5.0\n", "synth").unwrap();
        assert_eq!(
            got,
            Outer {
                seed: 7,
                damage: Inner {
                    dust: 5.0,
                    scratches: 3.0
                }
            }
        );
        // The demo preset's scratches and chunks stay when the file sets only its dust.
        let demo = crate::synth::SynthConfig::demo();
        let text = "[synth.damage]\ndust_per_mm2 = 1.0\n";
        let got = overlay(&demo, text, "synth").unwrap();
        assert_eq!(got.damage.dust_per_mm2, 1.0);
        assert_eq!(got.damage.scratches_per_mm, demo.damage.scratches_per_mm);
        assert_eq!(
            got.damage.missing_wall_chunks_per_mm,
            demo.damage.missing_wall_chunks_per_mm
        );
        let e = overlay(&preset(), "[synth]\n[synth.damage]\ndusst = 5.0\n", "synth").unwrap_err();
        assert!(
            e.starts_with("synth.damage (line 2): unknown field `dusst`"),
            "{e}"
        );
    }

    #[test]
    fn a_tables_header_names_it() {
        // It was `line 3: unknown field `extra``, the table unnamed.
        let text = "seed = 1\n[damage]\ndust = 1.0\n[damage.extra]\n";
        let e = toml::from_str::<Outer>(text).unwrap_err();
        let line = located(text, &e);
        assert!(
            line.starts_with("damage.extra (line 4): unknown field `extra`"),
            "{line}"
        );
    }
}
