//! Messages in plain words: serde's and TOML's refusals reworded for
//! people who write scene files, with the key and line they are about.

use std::path::Path;

use super::SceneError;

/// A value as the user wrote it, for messages: `the text "1.5"`, `32.0`,
/// `a table`, `an array`.
pub(super) fn plain_value(v: &toml::Value) -> String {
    match v {
        toml::Value::String(s) => format!("the text {s:?}"),
        toml::Value::Table(_) => "a table".into(),
        toml::Value::Array(_) => "an array".into(),
        v => v.to_string(),
    }
}

/// serde's messages in plain words: `invalid type: string "1.5", expected
/// f64` becomes `expected a number, got the text "1.5"`, Rust type names
/// become ranges (`u32`: a whole number from 0 to 4294967295; TOML's
/// integers are `i64`, so `u64` and `usize` reach 9223372036854775807) and
/// the struct names the settings they hold; a setting with a range of its
/// own gives it as `whole`, which an unsigned type's range gives way to.
/// `msg` is the message alone ([`toml::de::Error::message`]): the caller
/// names the key.
pub(super) fn plain_serde_message(msg: &str, whole: Option<(u32, u32)>) -> String {
    let msg = msg.trim().replace('\n', " ");
    let expected = |e: &str| -> String {
        let e = e.trim();
        if let ("u8" | "u16" | "u32" | "u64" | "usize", Some((lo, hi))) = (e, whole) {
            return format!("a whole number from {lo} to {hi}");
        }
        match e {
            "f64" | "f32" => "a number".into(),
            "u8" => "a whole number from 0 to 255".into(),
            "u16" => "a whole number from 0 to 65535".into(),
            "u32" => format!("a whole number from 0 to {}", u32::MAX),
            "u64" | "usize" => format!("a whole number from 0 to {}", i64::MAX),
            "i8" | "i16" | "i32" | "i64" | "isize" => "a whole number".into(),
            "a boolean" => "true or false".into(),
            "a string" | "string" => "text in quotes".into(),
            "a sequence" => "an array".into(),
            _ => {
                if let Some(n) = e.strip_prefix("an array of length ") {
                    return format!("an array of {n} values");
                }
                if let Some(name) = e.strip_prefix("struct ") {
                    let what = match name {
                        "SceneFile" => "scene",
                        "ImageCfg" => "image",
                        "CameraCfg" => "camera",
                        "VolumeCfg" => "volume",
                        "RawCfg" => "raw volume",
                        "SurfaceCfg" => "surface",
                        "BackdropCfg" => "backdrop",
                        "RenderCfg" => "render",
                        "SphereSpec" => "sphere phantom",
                        "MarschnerLobbSpec" => "Marschner-Lobb phantom",
                        "Hole" => "hole",
                        other => other,
                    };
                    return format!("a table of {what} settings");
                }
                e.to_string()
            }
        }
    };
    let got = |u: &str| -> String {
        let u = u.trim();
        let unquote = |s: &str| s.trim_matches('`').to_string();
        if let Some(s) = u.strip_prefix("string ") {
            format!("the text {s}")
        } else if let Some(s) = u
            .strip_prefix("floating point ")
            .or_else(|| u.strip_prefix("integer "))
            .or_else(|| u.strip_prefix("boolean "))
        {
            unquote(s)
        } else {
            match u {
                "map" => "a table".into(),
                "sequence" => "an array".into(),
                other => other.to_string(),
            }
        }
    };
    // A named choice (`kind`, `traversal`, …) given as a number or a
    // boolean: TOML's words ("unit variant, expected string only") name
    // neither.
    if msg.ends_with("expected string only") {
        return "expected the name of a choice, in quotes".into();
    }
    for prefix in ["invalid type: ", "invalid value: "] {
        if let Some(rest) = msg.strip_prefix(prefix)
            && let Some((u, e)) = rest.rsplit_once(", expected ")
        {
            return format!("expected {}, got {}", expected(e), got(u));
        }
    }
    if let Some(rest) = msg.strip_prefix("invalid length ")
        && let Some((n, e)) = rest.split_once(", expected ")
    {
        // TOML's words for an array longer than the setting's.
        if e.trim() == "fewer elements in array" {
            return format!("too many values in the array ({n})");
        }
        return format!("expected {}, got {n}", expected(e));
    }
    if let Some(rest) = msg.strip_prefix("missing field ") {
        return format!("missing key {rest}");
    }
    if let Some(rest) = msg.strip_prefix("unknown field ") {
        return format!("unknown key {rest}");
    }
    // serde lists the variants as `a`, `a` or `b`, or one of `a`, `b`, `c`.
    if let Some(rest) = msg.strip_prefix("unknown variant ")
        && let Some((got, expected)) = rest.split_once(", expected ")
    {
        return format!(
            "expected {}, got \"{}\"",
            expected.replace('`', "\""),
            got.trim_matches('`')
        );
    }
    msg
}

/// Why TOML refused `text` if it is a number TOML cannot hold, in the
/// words both a scene file and a `--set` value get: an integer literal
/// outside `i64` (TOML's integers), or a float literal beyond `f64`.
/// Decided from the literal itself, since TOML words these refusals
/// differently by size.
pub(super) fn number_reason(text: &str) -> Option<String> {
    let text = text.trim();
    let t: String = text.chars().filter(|&c| c != '_').collect();
    let (negative, unsigned) = match t.strip_prefix('-') {
        Some(rest) => (true, rest),
        None => (false, t.strip_prefix('+').unwrap_or(&t)),
    };
    let (radix, digits) = match unsigned.get(..2) {
        Some("0x") if unsigned.len() == t.len() => (16, &unsigned[2..]),
        Some("0o") if unsigned.len() == t.len() => (8, &unsigned[2..]),
        Some("0b") if unsigned.len() == t.len() => (2, &unsigned[2..]),
        _ => (10, unsigned),
    };
    if !digits.is_empty() && digits.chars().all(|c| c.is_digit(radix)) {
        // Digits beyond i128 do not fit i64 either.
        let fits = i128::from_str_radix(digits, radix)
            .ok()
            .and_then(|v| i64::try_from(if negative { -v } else { v }).ok())
            .is_some();
        return (!fits).then(|| {
            if negative {
                format!(
                    "whole numbers go down to {} (TOML integers are signed 64-bit), got {text}",
                    i64::MIN
                )
            } else {
                format!(
                    "whole numbers go up to {} (TOML integers are signed 64-bit), got {text}",
                    i64::MAX
                )
            }
        });
    }
    let float_syntax = unsigned.starts_with(|c: char| c.is_ascii_digit())
        && unsigned
            .chars()
            .all(|c| c.is_ascii_digit() || matches!(c, '.' | 'e' | 'E' | '+' | '-'));
    (float_syntax && t.parse::<f64>().is_ok_and(f64::is_infinite)).then(|| {
        format!("numbers must be finite; {text} is beyond the largest 64-bit float (about 1.8e308)")
    })
}

/// `s` as a TOML key (`camera.look_at`, `"a b".c`), without the `[`/`]`
/// of a header or the `=` after it.
fn is_toml_key(s: &str) -> bool {
    s.split('.').all(|part| {
        let part = part.trim();
        let bare = !part.is_empty()
            && part
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
        let quoted = part.len() >= 2
            && part.starts_with('"')
            && part.ends_with('"')
            && !part[1..part.len() - 1].contains('"');
        bare || quoted
    })
}

/// `line` without a trailing `# comment` (none inside quotes).
fn strip_comment(line: &str) -> &str {
    let mut quoted = false;
    for (i, c) in line.char_indices() {
        match c {
            '"' => quoted = !quoted,
            '#' if !quoted => return &line[..i],
            _ => {}
        }
    }
    line
}

/// The table a `[section]` (or `[[section]]`) header line names, if the
/// line is one.
fn section_header(line: &str) -> Option<String> {
    let l = strip_comment(line).trim();
    let name = l
        .strip_prefix("[[")
        .and_then(|l| l.strip_suffix("]]"))
        .or_else(|| l.strip_prefix('[').and_then(|l| l.strip_suffix(']')))?;
    is_toml_key(name).then(|| dotted_key(name))
}

/// A TOML key as the messages write it: parts trimmed, quotes dropped.
fn dotted_key(key: &str) -> String {
    key.split('.')
        .map(|p| p.trim().trim_matches('"'))
        .collect::<Vec<_>>()
        .join(".")
}

/// A TOML syntax error on one line: where (line and column), what, and the
/// line it is on (its first 80 characters), instead of the parser's
/// multi-line drawing, whose caret means nothing once joined into one line.
fn syntax_message(text: &str, e: &toml::de::Error) -> String {
    let what = e.message().trim().replace('\n', " ");
    let Some(start) = e
        .span()
        .map(|s| s.start)
        .filter(|&s| s <= text.len() && text.is_char_boundary(s))
    else {
        return e.to_string().trim().replace('\n', " ");
    };
    let line_start = text[..start].rfind('\n').map_or(0, |i| i + 1);
    let line_end = text[start..].find('\n').map_or(text.len(), |i| start + i);
    let line_no = text[..start].matches('\n').count() + 1;
    let column = text[line_start..start].chars().count() + 1;
    let line: String = text[line_start..line_end]
        .trim_end()
        .chars()
        .take(80)
        .map(|c| if c.is_control() { ' ' } else { c })
        .collect();
    format!("line {line_no}, column {column}: {what} (in: {line})")
}

/// A scene file TOML refused: a number out of TOML's range is named by its
/// key (as a `--set` of the same value is); other syntax errors are put on one
/// line ([`syntax_message`]).
pub(super) fn syntax_error(text: &str, path: &Path, e: &toml::de::Error) -> SceneError {
    let plain = || SceneError::Syntax {
        path: path.to_path_buf(),
        msg: syntax_message(text, e),
    };
    let Some(span) = e.span() else {
        return plain();
    };
    let Some(value) = text.get(span.clone()) else {
        return plain();
    };
    let Some(reason) = number_reason(value) else {
        return plain();
    };
    // The key: a `key =` line (the value may follow it on the line, in an
    // inline array say), under the last `[section]` header above it;
    // inside a multi-line array the line alone names no key.
    let line_start = text[..span.start].rfind('\n').map_or(0, |i| i + 1);
    let line = &text[line_start..span.start];
    let key = line
        .split_once('=')
        .map(|(k, _)| k)
        .filter(|k| is_toml_key(k))
        .map(dotted_key);
    let line_no = text[..span.start].matches('\n').count() + 1;
    let key = match key {
        Some(key) => match text[..line_start].lines().rev().find_map(section_header) {
            Some(section) => format!("{section}.{key}"),
            None => key,
        },
        None => format!("line {line_no}"),
    };
    SceneError::Key {
        path: path.to_path_buf(),
        key,
        msg: reason,
    }
}
