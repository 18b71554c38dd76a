//! Host side of the firmware-to-host state (`../src/state.rs`):
//!
//! * [`template`] turns the host's own partial state of the fixture (written by
//!   `vltm direct|column … --partial`) into the header template the firmware fills: the same
//!   JSON with the values only the MCU knows (`rows`, `report`, `legs`, `crc32`) replaced by
//!   the markers `"@ROWS@"`, `"@REPORT@"`, `"@LEGS@"`, `"@CRC@"`, after checking that its sizes
//!   are the firmware's;
//! * [`compare`] checks two `.npy` volumes against each other within `rtol` of the largest
//!   value (the merged firmware + host state against the host's whole run).
//!
//! No JSON crate: the header is written by serde_json in compact form, and only its top-level
//! keys are located (strings and nesting tracked), so the rest is copied byte for byte.

use crate::npz;

/// The top-level `key: value` spans of a compact JSON object: `(key, value_start, value_end)`.
fn top_level(json: &str) -> Result<Vec<(String, usize, usize)>, String> {
    let b = json.as_bytes();
    if b.first() != Some(&b'{') || b.last() != Some(&b'}') {
        return Err("header is not a JSON object".into());
    }
    let mut out = Vec::new();
    let (mut depth, mut in_str, mut esc) = (0usize, false, false);
    let mut key_start = None;
    let mut key: Option<String> = None;
    let mut value_start = None;
    for (i, &c) in b.iter().enumerate() {
        if in_str {
            if esc {
                esc = false;
            } else if c == b'\\' {
                esc = true;
            } else if c == b'"' {
                in_str = false;
                if depth == 1
                    && value_start.is_none()
                    && let Some(s) = key_start.take()
                {
                    key = Some(json[s + 1..i].to_string());
                }
            }
            continue;
        }
        match c {
            b'"' => {
                in_str = true;
                if depth == 1 && value_start.is_none() && key.is_none() {
                    key_start = Some(i);
                }
            }
            b':' if depth == 1 && key.is_some() && value_start.is_none() => {
                value_start = Some(i + 1);
            }
            b'{' | b'[' => depth += 1,
            b'}' | b']' | b',' => {
                if depth == 1
                    && (c == b',' || c == b'}')
                    && let (Some(k), Some(v)) = (key.take(), value_start.take())
                {
                    out.push((k, v, i));
                }
                if c != b',' {
                    depth = depth.checked_sub(1).ok_or("unbalanced JSON")?;
                }
            }
            _ => {}
        }
    }
    if depth != 0 || in_str {
        return Err("unbalanced JSON".into());
    }
    Ok(out)
}

/// The header JSON of a partial state file.
fn header(bytes: &[u8]) -> Result<&str, String> {
    if bytes.get(..8) != Some(b"VLTMPART") {
        return Err("not a vltm partial state (magic)".into());
    }
    let word = |i: usize| {
        bytes
            .get(i..i + 4)
            .map(|s| u32::from_le_bytes([s[0], s[1], s[2], s[3]]) as usize)
            .ok_or("truncated")
    };
    if word(8)? != 1 {
        return Err("partial state version is not 1".into());
    }
    let h = word(12)?;
    let json = bytes.get(16..16 + h).ok_or("truncated header")?;
    std::str::from_utf8(json).map_err(|_| "header is not UTF-8".into())
}

/// The template of `part` (the host's partial state of the fixture), checked to hold
/// `n_spads`, `n_points` and `n_acc` as the firmware's buffers do.
pub fn template(
    part: &[u8],
    n_spads: usize,
    n_points: usize,
    n_acc: usize,
) -> Result<String, String> {
    let json = header(part)?;
    let keys = top_level(json)?;
    let value = |k: &str| {
        keys.iter()
            .find(|(name, ..)| name == k)
            .map(|&(_, a, b)| &json[a..b])
            .ok_or_else(|| format!("header has no `{k}`"))
    };
    for (k, want) in [
        ("n_spads", n_spads),
        ("n_points", n_points),
        ("n_acc", n_acc),
        ("n_from", 0),
    ] {
        let got = value(k)?;
        if got != want.to_string() {
            return Err(format!(
                "the host's state has {k} = {got}, the firmware's buffers {want}: \
                 src/fixture.rs and the host's probe differ"
            ));
        }
    }
    if n_spads == 0 && value("legs")? != "[]" {
        return Err("a diagonal's state with column legs".into());
    }
    let mut out = String::new();
    let mut at = 0;
    let mut spans: Vec<_> = keys
        .iter()
        .filter_map(|(k, a, b)| {
            let m = match k.as_str() {
                "rows" => "\"@ROWS@\"",
                "report" => "\"@REPORT@\"",
                "crc32" => "\"@CRC@\"",
                "legs" if n_spads > 0 => "\"@LEGS@\"",
                _ => return None,
            };
            Some((*a, *b, m))
        })
        .collect();
    spans.sort_unstable();
    for (a, b, m) in spans {
        out.push_str(&json[at..a]);
        out.push_str(m);
        at = b;
    }
    out.push_str(&json[at..]);
    Ok(out)
}

/// `max |a − b| / max |b|` of two `.npy` volumes of one shape.
pub fn compare(a: &[u8], b: &[u8]) -> Result<f64, String> {
    let (a, b) = (npz::npy(a)?, npz::npy(b)?);
    if a.shape != b.shape {
        return Err(format!("shapes differ: {:?} and {:?}", a.shape, b.shape));
    }
    let big = b.values.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let diff = a
        .values
        .iter()
        .zip(&b.values)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    if big.is_nan() || big <= 0.0 || !diff.is_finite() {
        return Err("empty or non-finite volume".into());
    }
    Ok(diff / big)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn top_level_skips_nested_keys_and_strings() {
        let j = r#"{"a":{"rows":1},"rows":[[0,8]],"s":"x,}\"","report":{"rows":8}}"#;
        let k = top_level(j).unwrap();
        let names: Vec<_> = k.iter().map(|(n, ..)| n.as_str()).collect();
        assert_eq!(names, ["a", "rows", "s", "report"]);
        assert_eq!(&j[k[1].1..k[1].2], "[[0,8]]");
        assert_eq!(&j[k[3].1..k[3].2], r#"{"rows":8}"#);
    }
}
