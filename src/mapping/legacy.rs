//! Paper 002's mapping format (Listing 2), accepted verbatim as a legacy mode:
//!
//! ```json
//! {"N1": {"MPU1": {"target": "RightArm", "X": "+pitch1", "Y": "-roll1", "Z": "+yaw1"},
//!         "MPU2": {"target": "RightForeArm", "X": "+pitch2", "Y": "-roll2", "Z": "+yaw2"}}}
//! ```
//! Each target's Blender X/Y/Z Euler channel copies a signed yaw/pitch/roll of MPU1 (node
//! `<SOU>_0`) or MPU2 (node `<SOU>_1`).

use super::MappingError;
use serde_json::Value;
use std::path::Path;

/// One of a SOU's six angles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EulerSource {
    /// 0 yaw, 1 pitch, 2 roll.
    pub angle: usize,
    /// 1 or 2 (MPU1 → node `_0`, MPU2 → node `_1`).
    pub mpu: u8,
}

/// `±source`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LegacyChannel {
    pub sign: f64,
    pub source: EulerSource,
}

/// One MPU's target bone and its X, Y, Z channels.
#[derive(Debug, Clone, PartialEq)]
pub struct LegacyTarget {
    pub sou: String,
    pub mpu: u8,
    /// The node this MPU measures: `<SOU>_0` for MPU1, `<SOU>_1` for MPU2.
    pub node: String,
    pub target: String,
    /// Blender Euler X, Y, Z.
    pub channels: [LegacyChannel; 3],
}

#[derive(Debug, Clone, PartialEq)]
pub struct LegacyMapping {
    pub targets: Vec<LegacyTarget>,
}

/// True when the JSON is a Listing-2 mapping: an object of SOU ids whose values hold MPU1/MPU2.
pub fn looks_like(value: &Value) -> bool {
    let Some(map) = value.as_object() else {
        return false;
    };
    !map.is_empty()
        && !map.contains_key("sensors")
        && map.values().all(|v| {
            v.as_object()
                .is_some_and(|o| o.keys().any(|k| k == "MPU1" || k == "MPU2"))
        })
}

fn parse_channel(text: &str) -> Result<LegacyChannel, String> {
    let t: String = text.chars().filter(|c| !c.is_whitespace()).collect();
    let (sign, rest) = match t.chars().next() {
        Some('+') => (1.0, &t[1..]),
        Some('-') => (-1.0, &t[1..]),
        _ => (1.0, t.as_str()),
    };
    let lower = rest.to_ascii_lowercase();
    for (angle, name) in ["yaw", "pitch", "roll"].iter().enumerate() {
        if let Some(n) = lower.strip_prefix(name) {
            let mpu = match n {
                "1" => 1,
                "2" => 2,
                _ => break,
            };
            return Ok(LegacyChannel {
                sign,
                source: EulerSource { angle, mpu },
            });
        }
    }
    Err(format!(
        "`{text}`: expected a signed angle such as +yaw1, -pitch2 or +roll1"
    ))
}

pub fn parse(value: &Value, file: &Path) -> Result<LegacyMapping, MappingError> {
    let mut targets = Vec::new();
    let map = value.as_object().expect("looks_like checked");
    for (sou, entry) in map {
        let entry = entry.as_object().expect("looks_like checked");
        for (mpu_key, spec) in entry {
            let mpu = match mpu_key.as_str() {
                "MPU1" => 1,
                "MPU2" => 2,
                other => {
                    return Err(MappingError::new(
                        file,
                        format!("{sou}.{other}"),
                        "expected MPU1 or MPU2",
                    ));
                }
            };
            let key = |k: &str| format!("{sou}.{mpu_key}.{k}");
            let text = |k: &str| -> Result<&str, MappingError> {
                spec.get(k)
                    .and_then(Value::as_str)
                    .ok_or_else(|| MappingError::new(file, key(k), "missing or not a string"))
            };
            let target = text("target")?.to_string();
            let mut channels = Vec::with_capacity(3);
            for axis in ["X", "Y", "Z"] {
                let c = parse_channel(text(axis)?)
                    .map_err(|e| MappingError::new(file, key(axis), e))?;
                channels.push(c);
            }
            if targets.iter().any(|t: &LegacyTarget| t.target == target) {
                return Err(MappingError::new(
                    file,
                    key("target"),
                    format!("bone `{target}` is the target of two MPUs"),
                ));
            }
            targets.push(LegacyTarget {
                sou: sou.clone(),
                mpu,
                node: format!("{sou}_{}", mpu - 1),
                target,
                channels: [channels[0], channels[1], channels[2]],
            });
        }
    }
    Ok(LegacyMapping { targets })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn listing_2() {
        let text = r#"{"N1": {"MPU1": {"target": "RightArm", "X": "+pitch1", "Y": "- roll1", "Z": "+yaw1"},
                              "MPU2": {"target": "RightForeArm", "X": "pitch2", "Y": "-roll2", "Z": "+yaw2"}}}"#;
        let v: Value = serde_json::from_str(text).unwrap();
        assert!(looks_like(&v));
        let m = parse(&v, Path::new("l.json")).unwrap();
        assert_eq!(m.targets.len(), 2);
        assert_eq!(m.targets[0].node, "N1_0");
        assert_eq!(m.targets[1].node, "N1_1");
        assert_eq!(m.targets[0].channels[1].sign, -1.0);
        assert_eq!(
            m.targets[0].channels[1].source,
            EulerSource { angle: 2, mpu: 1 }
        );
        assert_eq!(m.targets[1].channels[0].sign, 1.0);
        let bad: Value = serde_json::from_str(
            r#"{"N1": {"MPU1": {"target": "A", "X": "+yaw3", "Y": "+yaw1", "Z": "+yaw1"}}}"#,
        )
        .unwrap();
        let e = parse(&bad, Path::new("l.json")).unwrap_err().to_string();
        assert!(e.contains("`N1.MPU1.X`"), "{e}");
    }
}
