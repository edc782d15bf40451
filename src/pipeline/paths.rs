//! Names that become path components: checked or encoded before they touch the disk.
//!
//! A stage name is a folder of `output_dir`, a partition `key=value` a folder of a dataset. A name
//! a user chose (stage, partition key, constant partition value) is refused at its YAML line unless it
//! is a plain component; a value read from the archive (a `{key}` matched in a file name) is
//! percent-encoded instead (`%2F` for `/`), as Hive partitioning does and pyarrow and polars decode.
//!
//! And paths as their bytes ([`bytes`], [`from_bytes`], [`folders`]): where a run asks after 10⁴
//! files or more, hashing and comparing a path's bytes whole is cheaper than `Path`'s `Hash` and
//! `Ord`, which parse components.

use std::os::unix::ffi::OsStrExt;
use std::path::Path;

/// Characters a component may hold as they are: letters, digits, `_`, `.`, `-`.
fn is_plain(byte: u8) -> bool {
    byte.is_ascii_alphanumeric() || matches!(byte, b'_' | b'.' | b'-')
}

/// Why `name` cannot be a folder name shakeflow creates, or None when it can: only
/// `[A-Za-z0-9_.-]`, not empty, not `.` or `..`, not starting with `.` (shakeflow's own entries,
/// such as `.shakeflow/`, start with one).
pub fn component_problem(name: &str) -> Option<String> {
    if name.is_empty() {
        return Some("it is empty".into());
    }
    if name == "." || name == ".." {
        return Some(format!("`{name}` names a folder itself or its parent"));
    }
    if let Some(c) = name.chars().find(|c| !c.is_ascii() || !is_plain(*c as u8)) {
        let what = match c {
            '/' | '\\' => "a path separator".to_string(),
            c if c.is_control() => format!("the control character U+{:04X}", c as u32),
            c => format!("`{c}`"),
        };
        return Some(format!("it holds {what}; only letters, digits, `_`, `.` and `-` may name a folder"));
    }
    if name.starts_with('.') {
        return Some("it starts with `.`, which shakeflow keeps for its own entries (`.shakeflow/`)".into());
    }
    None
}

/// `value` as one path component: plain bytes kept, every other byte as `%XX` (upper-case hex),
/// and a value of only dots (`.`, `..`) or an empty one encoded whole, so no value names a
/// parent folder or breaks out of its own.
pub fn encode_component(value: &str) -> String {
    let only_dots = value.bytes().all(|b| b == b'.');
    let mut out = String::with_capacity(value.len());
    for byte in value.bytes() {
        if is_plain(byte) && !(only_dots && byte == b'.') {
            out.push(byte as char);
        } else {
            out.push_str(&format!("%{byte:02X}"));
        }
    }
    if out.is_empty() {
        // Hive's name for an empty (null) partition value.
        out.push_str("__HIVE_DEFAULT_PARTITION__");
    }
    out
}

/// The inverse of [`encode_component`] (a `%` not followed by two hex digits is kept as it is).
pub fn decode_component(component: &str) -> String {
    if component == "__HIVE_DEFAULT_PARTITION__" {
        return String::new();
    }
    let bytes = component.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let hex = |b: u8| (b as char).to_digit(16);
        if bytes[i] == b'%' && i + 2 < bytes.len() {
            if let (Some(hi), Some(lo)) = (hex(bytes[i + 1]), hex(bytes[i + 2])) {
                out.push((hi * 16 + lo) as u8);
                i += 3;
                continue;
            }
        }
        out.push(bytes[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// `path`'s bytes.
pub fn bytes(path: &Path) -> &[u8] {
    path.as_os_str().as_bytes()
}

/// The path of `bytes` (the inverse of [`bytes`]).
pub fn from_bytes(bytes: &[u8]) -> &Path {
    Path::new(std::ffi::OsStr::from_bytes(bytes))
}

/// The folders of a path's bytes, deepest first: its bytes before each `/` but a leading one
/// (`/a/b/c` → `/a/b`, `/a`). Not normalised: a path spelled unusually (`a/./b`) gives its
/// folders as spelled.
pub fn folders(path: &[u8]) -> impl Iterator<Item = &[u8]> {
    memchr::memrchr_iter(b'/', path).filter(|&at| at > 0).map(move |at| &path[..at])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What `Path::ancestors` gives below the root, for the paths a walk makes.
    #[test]
    fn a_paths_folders_are_its_ancestors_below_the_root() {
        for path in ["/a/b/c.csv", "/a", "rel/x/y", "rel", "/a b/ü/c"] {
            let path = Path::new(path);
            let ancestors: Vec<&Path> =
                path.ancestors().skip(1).filter(|a| !a.as_os_str().is_empty() && *a != Path::new("/")).collect();
            assert_eq!(folders(bytes(path)).map(from_bytes).collect::<Vec<_>>(), ancestors, "{}", path.display());
        }
    }

    #[test]
    fn plain_names_pass_and_escapes_are_refused() {
        for ok in ["load", "baseline_floors", "FB-4", "v1.2", "a..b"] {
            assert_eq!(component_problem(ok), None, "{ok}");
        }
        for bad in ["", ".", "..", "/abs/dir", "a/b", "..\\x", ".hidden", "a b", "x\0y", "é"] {
            assert!(component_problem(bad).is_some(), "`{bad}` accepted");
        }
    }

    #[test]
    fn encoded_values_are_one_component_and_decode_back() {
        for value in ["x/../../../escaped", "..", ".", "", "090 (CUE)", "100%", "a=b", "FB-4", "Ñuñoa", "%2F"] {
            let encoded = encode_component(value);
            assert_eq!(component_problem(&encoded.replace('%', "_")), None, "`{value}` → `{encoded}`");
            assert!(!encoded.contains('/') && encoded != "." && encoded != "..", "`{value}` → `{encoded}`");
            assert_eq!(decode_component(&encoded), value, "`{value}` → `{encoded}`");
        }
        assert_eq!(encode_component("FB-4"), "FB-4", "plain values are unchanged");
        assert_eq!(encode_component("x/../y"), "x%2F..%2Fy");
    }
}
