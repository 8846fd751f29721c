//! `--set section.key=value` overrides: applied to the parsed TOML table
//! before validation (so an override is checked exactly like a value in
//! the file), and an error on a key an override wrote blamed on that
//! override.

use std::path::Path;

use super::SceneError;
use super::words::number_reason;

/// The keys whose value is a file path. The scene file's paths are read
/// from its folder; a path typed with `--set` is read from the current
/// directory, as every other path on the command line is.
const PATH_KEYS: [&str; 2] = ["volume.path", "backdrop.image"];

/// Applies `section.key=value` (value in TOML syntax; bare words are strings).
pub fn apply_override(table: &mut toml::Table, arg: &str) -> Result<(), SceneError> {
    let err = |msg: &str| SceneError::Override {
        arg: arg.to_string(),
        msg: msg.to_string(),
        over_limit: None,
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
        // `16\nimage.height=4` parses as two keys: the second would be
        // dropped without a word.
        Ok(t) if t.len() > 1 => {
            return Err(err(
                "the value holds a line break and more keys after it; give one section.key=value per --set",
            ));
        }
        Ok(mut t) => t.remove("v").unwrap_or(toml::Value::String(value.into())),
        // A number TOML cannot hold is refused as in a file, not taken
        // for a word.
        Err(_) => match number_reason(value) {
            Some(msg) => return Err(err(&msg)),
            None => toml::Value::String(value.to_string()),
        },
    };
    let parsed = match parsed {
        toml::Value::String(p) if PATH_KEYS.contains(&key.as_str()) => {
            toml::Value::String(from_current_dir(p))
        }
        v => v,
    };
    // Switching a volume between file and phantom drops the other source,
    // whichever key of it the override names (`volume.phantom.kind` as
    // much as the whole `volume.phantom` table): a scene has one. A file
    // whose name gives its format drops a raw layout too, which only a
    // headerless file reads.
    if let (["volume", source, ..], Some(toml::Value::Table(volume))) =
        (parts.as_slice(), table.get_mut("volume"))
    {
        match *source {
            "path" => {
                volume.remove("phantom");
                if let toml::Value::String(p) = &parsed
                    && crate::volume::Format::of(Path::new(p)).is_some()
                {
                    volume.remove("raw");
                }
            }
            "phantom" => {
                volume.remove("path");
                volume.remove("raw");
                // Another kind of phantom keeps only the settings every
                // kind has; the last kind's shape goes with it.
                if parts.get(2) == Some(&"kind")
                    && let Some(toml::Value::Table(phantom)) = volume.get_mut("phantom")
                    && phantom.get("kind") != Some(&parsed)
                {
                    phantom.retain(|k, _| ["format", "noise", "seed"].contains(&k));
                }
            }
            _ => {}
        }
    }
    // Likewise a backdrop has one pattern: a photograph set over a
    // checkerboard drops the checker's settings, and a checker set over a
    // photograph drops the photograph's.
    if let (["backdrop", pattern], Some(toml::Value::Table(backdrop))) =
        (parts.as_slice(), table.get_mut("backdrop"))
    {
        let drop: &[&str] = match *pattern {
            "image" => &["checker", "checker_colors"],
            "checker" => &["image", "width", "outside"],
            _ => &[],
        };
        for key in drop {
            backdrop.remove(*key);
        }
    }
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
    cur.insert(last.to_string(), parsed);
    Ok(())
}

/// `p` as an absolute path when it is relative, so that the scene's folder
/// does not become its base (kept as given if the current directory cannot
/// be read or is not UTF-8).
fn from_current_dir(p: String) -> String {
    if p.is_empty() || Path::new(&p).is_absolute() {
        return p;
    }
    std::path::absolute(&p)
        .ok()
        .and_then(|a| a.to_str().map(str::to_string))
        .unwrap_or(p)
}

/// The key a `--set key=value` sets, as the scene's keys are written
/// (`camera . fov_y` is `camera.fov_y`).
pub fn override_key(arg: &str) -> String {
    let key = arg.split_once('=').map_or(arg, |(k, _)| k);
    key.split('.').map(str::trim).collect::<Vec<_>>().join(".")
}

/// The keys an override writes: its own and, when its value is a table
/// (`render={supersampling="prss"}`), every key inside it, dotted
/// (`render.supersampling`), so a command that reads less of a scene can
/// name each setting a table override sets.
pub fn override_keys(arg: &str) -> Vec<String> {
    let key = override_key(arg);
    let mut keys = vec![key.clone()];
    if let Some((_, value)) = arg.split_once('=')
        && let Ok(mut t) = format!("v = {}", value.trim()).parse::<toml::Table>()
        && let Some(toml::Value::Table(table)) = t.remove("v")
    {
        let mut inner = Vec::new();
        written_keys(&table, &format!("{key}."), &mut inner);
        keys.extend(inner.into_iter().map(|(k, _)| k));
    }
    keys
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
/// names `--set key=value` instead of the file. So is an error on a section
/// the file does not have, which only an override can have made (an unknown
/// one, say). An error on a key the file wrote is the file's, but one an
/// override of the same section may have caused (`camera.kind` makes
/// `camera.height` needed) lists those overrides after the message.
/// `written` is what the file and the overrides wrote ([`written_keys`]),
/// `file_keys` what the file alone did.
pub(super) fn blame_override(
    e: SceneError,
    overrides: &[String],
    written: &[(String, String)],
    file_keys: &[String],
) -> SceneError {
    // A refusal over the memory limit keeps its type (the caller may have
    // lent part of the limit, and says so) whoever it is blamed on.
    let (path, key, msg, over_limit) = match e {
        SceneError::Key { path, key, msg } => (path, key, msg, None),
        SceneError::OverLimit { path, key, source } => {
            (path, key, source.to_string(), Some(source))
        }
        e => return e,
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
    let culprit = culprit.or_else(|| {
        let inside = format!("{key}.");
        if file_keys.contains(&key) {
            return None;
        }
        overrides
            .iter()
            .rev()
            .find(|o| override_key(o).starts_with(&inside))
    });
    match culprit {
        Some(o) => SceneError::Override {
            arg: o.clone(),
            msg: if key == override_key(o) {
                msg
            } else {
                format!("[{key}] {msg}")
            },
            over_limit,
        },
        None => {
            let section = key.split('.').next().unwrap_or_default();
            let near: Vec<String> = overrides
                .iter()
                .filter(|o| override_key(o).split('.').next() == Some(section))
                .map(|o| format!("--set {o}"))
                .collect();
            let read_with = if near.is_empty() {
                String::new()
            } else {
                format!(" (read with {})", near.join(", "))
            };
            match over_limit {
                Some(mut source) => {
                    source.hint.push_str(&read_with);
                    SceneError::OverLimit { path, key, source }
                }
                None => SceneError::Key {
                    path,
                    key,
                    msg: msg + &read_with,
                },
            }
        }
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
