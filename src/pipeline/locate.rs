//! Finds where a key path sits in a block-style YAML file, for error messages.
//!
//! serde_yaml reports positions only for syntax and type errors; checks made after parsing
//! (unknown stage type, missing input, cycle) need a line too. Pipeline files are plain block
//! YAML, so an indentation scan is enough; when it finds nothing the error simply has no line.

/// (line, column), both 1-based, of the key at `path` (e.g. `["stages", "filter", "type"]`).
pub fn key_position(text: &str, path: &[&str]) -> Option<(usize, usize)> {
    let mut stack: Vec<(usize, String)> = Vec::new();
    for (index, raw) in text.lines().enumerate() {
        let Some((indent, key)) = key_of_line(raw) else { continue };
        while stack.last().is_some_and(|(i, _)| *i >= indent) {
            stack.pop();
        }
        stack.push((indent, key));
        if stack.len() == path.len() && stack.iter().zip(path).all(|((_, k), p)| k == p) {
            return Some((index + 1, indent + 1));
        }
    }
    None
}

/// Position of `value` written under (or on the line of) the key at `path`: a list entry, say.
pub fn value_position(text: &str, path: &[&str], value: &str) -> Option<(usize, usize)> {
    let (line, column) = key_position(text, path)?;
    let key_indent = column - 1;
    for (offset, raw) in text.lines().skip(line - 1).enumerate() {
        if offset > 0 {
            let content = raw.trim_start();
            let indent = raw.len() - content.len();
            if !content.is_empty() && !content.starts_with('#') && indent <= key_indent && !content.starts_with('-') {
                break;
            }
        }
        let search_from = if offset == 0 { key_indent } else { 0 };
        if let Some(found) = find_token(&raw[search_from..], value) {
            return Some((line + offset, search_from + found + 1));
        }
    }
    Some((line, column))
}

fn find_token(haystack: &str, token: &str) -> Option<usize> {
    let bytes = haystack.as_bytes();
    haystack.match_indices(token).map(|(i, _)| i).find(|&i| {
        let before_ok = i == 0 || !is_name_byte(bytes[i - 1]);
        let after = i + token.len();
        let after_ok = after >= bytes.len() || !is_name_byte(bytes[after]);
        before_ok && after_ok
    })
}

fn is_name_byte(b: u8) -> bool {
    b.is_ascii_alphanumeric() || b == b'_' || b == b'.'
}

/// The indentation and key of a `key:` line (list markers count as indentation).
fn key_of_line(raw: &str) -> Option<(usize, String)> {
    let mut content = raw.trim_start();
    let mut indent = raw.len() - content.len();
    while let Some(rest) = content.strip_prefix("- ") {
        let trimmed = rest.trim_start();
        indent += content.len() - trimmed.len();
        content = trimmed;
    }
    if content.starts_with('#') || content.is_empty() {
        return None;
    }
    let colon = content.find(':')?;
    if !(content.len() == colon + 1 || content.as_bytes()[colon + 1] == b' ') {
        return None;
    }
    let key = content[..colon].trim().trim_matches(|c| c == '"' || c == '\'');
    (!key.is_empty() && !key.contains(' ')).then(|| (indent, key.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    const TEXT: &str = "version: 1\nstages:\n  load:\n    type: load\n    inputs: [floors]\n  base:\n    # comment\n    type: baselin\n    inputs:\n      - load\n      - missing\n";

    #[test]
    fn finds_nested_keys() {
        assert_eq!(key_position(TEXT, &["stages", "base", "type"]), Some((8, 5)));
        assert_eq!(key_position(TEXT, &["stages", "load"]), Some((3, 3)));
        assert_eq!(key_position(TEXT, &["stages", "nope"]), None);
    }

    #[test]
    fn finds_list_values() {
        assert_eq!(value_position(TEXT, &["stages", "base", "inputs"], "missing"), Some((11, 9)));
        assert_eq!(value_position(TEXT, &["stages", "load", "inputs"], "floors"), Some((5, 14)));
    }
}
