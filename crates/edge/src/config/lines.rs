//! Where a key is written in a TOML file (for messages that name the line, also inside inline tables
//! and dotted keys), and the `--set section.key=value` overrides.

use super::ConfigError;
use toml_edit::{ImDocument, Item, TableLike};

/// 1-based line of byte offset `pos` in `text`.
pub(super) fn line_of(text: &str, pos: usize) -> usize {
    text.as_bytes()[..pos.min(text.len())].iter().filter(|&&b| b == b'\n').count() + 1
}

/// The `key = ...` or `[header]` written on the line holding `pos` (a syntax error has no parsed
/// key to name).
pub(super) fn key_near(text: &str, pos: usize) -> String {
    let line = text.lines().nth(line_of(text, pos) - 1).unwrap_or("").trim();
    let key = match line.strip_prefix('[') {
        Some(h) => h.trim_end_matches(']'),
        None => line.split('=').next().unwrap_or(""),
    };
    match key.trim() {
        "" => "?".to_string(),
        k => k.to_string(),
    }
}

/// 1-based line where dotted `key` is written in `text`; when it is not written (a default value),
/// the line of the nearest enclosing table that is; 0 when none is.
pub(super) fn key_line(text: &str, key: &str) -> usize {
    let Ok(doc) = ImDocument::parse(text) else { return 0 };
    let mut table: &dyn TableLike = doc.as_table();
    let mut best = 0;
    for seg in key.split('.') {
        let Some((k, item)) = table.get_key_value(seg) else { break };
        if let Some(span) = k.span().or_else(|| item.span()) {
            best = line_of(text, span.start);
        }
        match item {
            Item::Table(t) => {
                if let Some(span) = t.span() {
                    best = line_of(text, span.start);
                }
                table = t;
            }
            Item::Value(toml_edit::Value::InlineTable(t)) => table = t,
            _ => break,
        }
    }
    best
}

/// Applies one `--set section.key=value` to `doc` and returns the dotted key. The value is read as a
/// TOML value (`10`, `0.5`, `true`, `"text"`, `[1, 2]`); anything else is taken as a string, so
/// `--set source.path=/dev/video1` needs no quotes.
pub(super) fn apply_set(doc: &mut toml_edit::DocumentMut, assignment: &str) -> Result<String, ConfigError> {
    let bad =
        |message: &str| ConfigError::Override { assignment: assignment.to_string(), message: message.to_string() };
    let (key, raw) = assignment.split_once('=').ok_or_else(|| bad("expected section.key=value"))?;
    let key = key.trim();
    let segs: Vec<&str> = key.split('.').collect();
    if segs.iter().any(|s| s.is_empty() || !s.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')) {
        return Err(bad("the key must be dotted names, e.g. detector.rate_hz"));
    }
    let raw = raw.trim();
    let value: toml_edit::Value = raw.parse().unwrap_or_else(|_| toml_edit::Value::from(raw));
    let (last, parents) = segs.split_last().ok_or_else(|| bad("empty key"))?;
    let mut table: &mut dyn TableLike = doc.as_table_mut();
    for seg in parents {
        let item = table.entry(seg).or_insert(toml_edit::table());
        table = item.as_table_like_mut().ok_or_else(|| bad(&format!("`{seg}` is a value, not a section")))?;
    }
    table.insert(last, Item::Value(value));
    Ok(key.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn key_lines_in_tables_inline_tables_and_dotted_keys() {
        let text = "[a]\nx = 1\n\n[b]\nu = 0\nt = { p = 1, q = 2 }\nc.d = 3\n";
        assert_eq!(key_line(text, "a.x"), 2);
        assert_eq!(key_line(text, "b.t.q"), 6);
        assert_eq!(key_line(text, "b.c.d"), 7);
        assert_eq!(key_line(text, "b.missing"), 4, "an absent key: its section");
        assert_eq!(key_line(text, "z.y"), 0);
    }

    #[test]
    fn set_values_are_typed_or_strings() {
        let mut doc: toml_edit::DocumentMut = "[a]\nx = 1\n".parse().expect("toml");
        for s in ["a.x=2", "a.y=0.5", "b.c.d=/dev/video1", "b.e=true", "b.f=[1, 2]"] {
            apply_set(&mut doc, s).expect(s);
        }
        let t: toml::Table = toml::from_str(&doc.to_string()).expect("reads back");
        assert_eq!(t["a"]["x"].as_integer(), Some(2));
        assert_eq!(t["a"]["y"].as_float(), Some(0.5));
        assert_eq!(t["b"]["c"]["d"].as_str(), Some("/dev/video1"));
        assert_eq!(t["b"]["e"].as_bool(), Some(true));
        assert!(apply_set(&mut doc, "novalue").is_err());
        assert!(apply_set(&mut doc, "a.x.y=1").is_err(), "a.x is a value");
        assert!(apply_set(&mut doc, "a..b=1").is_err());
    }
}
