//! `--set section.key=value` overrides: applied to the parsed TOML table
//! before validation (so an override is checked exactly like a value in
//! the file), and an error on a key an override wrote blamed on that
//! override.

use super::SceneError;
use super::words::number_reason;

/// Applies `section.key=value` (value in TOML syntax; bare words are strings).
pub fn apply_override(table: &mut toml::Table, arg: &str) -> Result<(), SceneError> {
    let err = |msg: &str| SceneError::Override {
        arg: arg.to_string(),
        msg: msg.to_string(),
    };
    let (_, value) = arg
        .split_once('=')
        .ok_or_else(|| err("expected section.key=value"))?;
    let key = override_key(arg);
    let parts: Vec<&str> = key.split('.').collect();
    if parts.iter().any(|p| p.is_empty()) {
        return Err(err("empty key"));
    }
    let value = value.trim();
    let parsed: toml::Value = match format!("v = {value}").parse::<toml::Table>() {
        Ok(mut t) => t.remove("v").unwrap_or(toml::Value::String(value.into())),
        // A number TOML cannot hold is refused as in a file, not taken
        // for a word.
        Err(_) => match number_reason(value) {
            Some(msg) => return Err(err(&msg)),
            None => toml::Value::String(value.to_string()),
        },
    };
    let mut cur = table;
    for p in &parts[..parts.len() - 1] {
        let entry = cur
            .entry(p.to_string())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
        cur = entry
            .as_table_mut()
            .ok_or_else(|| err(&format!("'{p}' is not a section")))?;
    }
    let last = parts[parts.len() - 1];
    // Switching a volume between file and phantom: drop the other source.
    if parts.len() >= 2 && parts[parts.len() - 2] == "volume" {
        if last == "path" {
            cur.remove("phantom");
        } else if last == "phantom" {
            cur.remove("path");
        }
    }
    cur.insert(last.to_string(), parsed);
    Ok(())
}

/// The key a `--set key=value` sets, as the scene's keys are written
/// (`camera . fov_y` is `camera.fov_y`).
fn override_key(arg: &str) -> String {
    let key = arg.split_once('=').map_or(arg, |(k, _)| k);
    key.split('.').map(str::trim).collect::<Vec<_>>().join(".")
}

/// The override that wrote `key` or a table holding it (the last one, as
/// the last wins in the table).
pub(super) fn culprit_override<'a>(key: &str, overrides: &'a [String]) -> Option<&'a String> {
    overrides.iter().rev().find(|o| {
        let k = override_key(o);
        key == k || key.starts_with(&format!("{k}.")) || key.starts_with(&format!("{k}["))
    })
}

/// An error on a key an override set (or inside it) is the override's: it
/// names `--set key=value` instead of the file. `written` is what the file
/// and the overrides wrote ([`written_keys`]).
pub(super) fn blame_override(
    e: SceneError,
    overrides: &[String],
    written: &[(String, String)],
) -> SceneError {
    let SceneError::Key { key, msg, path } = e else {
        return e;
    };
    // A missing lambda (nobody wrote one) is the fault of the override
    // that chose the smoothing spline.
    let culprit = culprit_override(&key, overrides).or_else(|| {
        let lambda_missing =
            key == "surface.lambda" && !written.iter().any(|(k, _)| k == "surface.lambda");
        lambda_missing
            .then(|| culprit_override("surface.filter", overrides))
            .flatten()
    });
    match culprit {
        Some(o) => SceneError::Override {
            arg: o.clone(),
            msg: if key == override_key(o) {
                msg
            } else {
                format!("[{key}] {msg}")
            },
        },
        None => SceneError::Key { path, key, msg },
    }
}

/// Every key of `t` as a dotted path with its value as written (TOML;
/// [`Scene::parse`](super::Scene::parse) replaces it by `--set key=value` for an override).
pub(super) fn written_keys(t: &toml::Table, prefix: &str, out: &mut Vec<(String, String)>) {
    for (k, v) in t {
        let key = format!("{prefix}{k}");
        if let toml::Value::Table(sub) = v {
            written_keys(sub, &format!("{key}."), out);
        }
        out.push((key, v.to_string()));
    }
}
