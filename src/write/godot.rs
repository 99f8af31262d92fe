//! What Godot reads beside a take (`--engine godot`): the `<file>.import` settings its scene
//! importer uses on the first import of a `.glb` or `.gltf`, and the bone names it will show.
//!
//! Godot 3's glTF importer never keeps a file's own keys: it re-bakes every animation at the
//! import setting `animation/fps` — a whole number, 15 by default — and then runs a lossy
//! optimizer (on by default) over the keys. Both are settings of the `.import` file Godot keeps
//! beside each source, and it reads an existing one before its first import, so one written with
//! the file fixes them: the bake at the take's own rate (a fractional rate at the next whole rate
//! above it, never below: fewer keys than frames would drop motion) and no optimizer. Godot 3.2.3
//! checked (README, "A take into Godot"; `tests/outputs/godot_import.rs`).
//!
//! Godot 4 keeps the `.import` file but its scene importer's settings differ (`animation/fps` is
//! a real number there; the optimizer and compression are per animation, in `_subresources`):
//! not written, not tried (docs/src/godot.md).

use super::sidecar::OutputRecord;
use super::{OutputError, write_atomic};
use crate::anim::Animation;
use crate::fps::Fps;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::Path;

/// The rate Godot bakes the take's animation at: the take's rate when whole, else the next whole
/// rate above it (29.97 → 30), so that there is at least one key per frame.
pub fn bake_fps(fps: Fps) -> u64 {
    fps.num().div_ceil(fps.den())
}

/// The text of `<file>.import` for a take at `fps`: Godot's scene importer, the animation baked
/// at [`bake_fps`] with the optimizer off, its materials kept in the scene (no `.material` files
/// written beside the take). Godot fills in every other setting with its defaults and rewrites
/// the file on its first import.
pub fn import_file(fps: Fps) -> String {
    format!(
        "[remap]\n\n\
         importer=\"scene\"\n\n\
         [params]\n\n\
         materials/storage=0\n\
         animation/import=true\n\
         animation/fps={}\n\
         animation/optimizer/enabled=false\n",
        bake_fps(fps)
    )
}

/// Godot's sidecar record: the import files written beside the outputs, the rate they make Godot
/// bake at, and each bone's name as Godot 3 will show it (`LeftUpLeg` → `left_up_leg`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GodotRecord {
    pub import_files: Vec<String>,
    pub bake_fps: u64,
    /// The rig's joint name → the Godot skeleton's bone name.
    pub bone_names: BTreeMap<String, String>,
}

/// Writes `<file>.import` ([`import_file`]) beside each glTF output of the take in `dir`
/// (atomically, replacing one Godot rewrote: the take's rate may have changed), and says what it
/// wrote.
pub fn write_imports(
    dir: &Path,
    outputs: &[OutputRecord],
    animation: &Animation,
) -> Result<GodotRecord, OutputError> {
    let text = import_file(animation.fps());
    let mut import_files = Vec::new();
    for output in outputs
        .iter()
        .filter(|o| matches!(o.format, "glb" | "gltf"))
    {
        let name = format!("{}.import", output.path);
        let path = dir.join(&name);
        write_atomic(&path, |w| w.write_all(text.as_bytes())).map_err(|source| {
            OutputError::Write {
                path: path.clone(),
                source,
            }
        })?;
        import_files.push(name);
    }
    let joints = animation.rig().joints();
    let names = bone_names(joints.iter().map(|j| j.name.as_str()));
    Ok(GodotRecord {
        import_files,
        bake_fps: bake_fps(animation.fps()),
        bone_names: joints.iter().map(|j| j.name.clone()).zip(names).collect(),
    })
}

/// Each joint's bone name in Godot 3's skeleton, in the given order: [`bone_name`], then `_2`,
/// `_3`, … on a name already taken (as Godot's importer makes names unique in its skeleton).
pub fn bone_names<'a>(joints: impl IntoIterator<Item = &'a str>) -> Vec<String> {
    let mut taken = std::collections::HashSet::new();
    joints
        .into_iter()
        .map(|joint| {
            let base = bone_name(joint);
            let mut name = base.clone();
            let mut index = 1;
            while !taken.insert(name.clone()) {
                index += 1;
                name = format!("{base}_{index}");
            }
            name
        })
        .collect()
}

/// A glTF node name as Godot 3.2's glTF importer names the bone: every character but ASCII
/// letters, digits, `_` and space dropped, camel case split into snake
/// case, lower case, runs of spaces to `_`, runs of `_` to one, leading zeros of a number
/// dropped; `bone` when nothing is left.
pub fn bone_name(name: &str) -> String {
    let kept: String = name
        .chars()
        .filter(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | ' '))
        .collect();
    let snake = camelcase_to_underscore(&kept);
    let mut out = String::with_capacity(snake.len());
    for c in snake.chars() {
        let c = if c == ' ' { '_' } else { c };
        if c == '_' && out.ends_with('_') {
            continue;
        }
        out.push(c);
    }
    let out = strip_padding_zeros(&out);
    if out.is_empty() {
        "bone".to_string()
    } else {
        out
    }
}

/// Godot's `String::camelcase_to_underscore(true)`: an `_` before an upper-case letter that
/// follows neither an upper-case letter nor a digit, before the last upper-case letter of a run
/// followed by two lower-case ones (`HTTPServer` → `http_server`), before a digit that follows
/// no digit, and before a letter that follows a digit and precedes a lower-case letter or a
/// digit; then lower case.
fn camelcase_to_underscore(name: &str) -> String {
    let c: Vec<char> = name.chars().collect();
    let upper = |i: usize| c.get(i).is_some_and(|c| c.is_ascii_uppercase());
    let lower = |i: usize| c.get(i).is_some_and(|c| c.is_ascii_lowercase());
    let digit = |i: usize| c.get(i).is_some_and(|c| c.is_ascii_digit());
    let mut out = String::with_capacity(name.len() + 4);
    for (i, ch) in c.iter().enumerate() {
        if i > 0 {
            let split = (upper(i) && !upper(i - 1) && !digit(i - 1))
                || (upper(i - 1) && upper(i) && lower(i + 1) && lower(i + 2))
                || (digit(i) && !digit(i - 1))
                || (!digit(i) && digit(i - 1) && (lower(i + 1) || digit(i + 1)));
            if split {
                out.push('_');
            }
        }
        out.push(ch.to_ascii_lowercase());
    }
    out
}

/// The regular expression substitution `0+(\d+)` → `$1`, everywhere, left to right: a run of
/// digits that starts with `0` loses its leading zeros, keeping at least one digit
/// (`spine_01` → `spine_1`, `bone_007` → `bone_7`, `hand_100` → `hand_10`: the match starts at
/// the first `0`).
fn strip_padding_zeros(s: &str) -> String {
    let c: Vec<char> = s.chars().collect();
    let mut out = String::with_capacity(s.len());
    let mut i = 0;
    while i < c.len() {
        if c[i] == '0' {
            let zeros_end = (i..c.len()).find(|&k| c[k] != '0').unwrap_or(c.len());
            let digits_end = (zeros_end..c.len())
                .find(|&k| !c[k].is_ascii_digit())
                .unwrap_or(c.len());
            if digits_end - i >= 2 {
                // `0+` takes every zero it can while `\d+` still gets one digit.
                let kept_from = if digits_end > zeros_end {
                    zeros_end
                } else {
                    digits_end - 1
                };
                out.extend(&c[kept_from..digits_end]);
                i = digits_end;
                continue;
            }
        }
        out.push(c[i]);
        i += 1;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fractional_rate_bakes_at_the_next_whole_rate_above_it() {
        let fps = |s: &str| s.parse::<Fps>().unwrap();
        assert_eq!(bake_fps(fps("30")), 30);
        assert_eq!(bake_fps(fps("29.97")), 30);
        assert_eq!(bake_fps(fps("23.976")), 24);
        assert_eq!(bake_fps(fps("120")), 120);
        let text = import_file(fps("30000/1001"));
        assert!(text.contains("\nanimation/fps=30\n"), "{text}");
        assert!(
            text.contains("\nanimation/optimizer/enabled=false\n"),
            "{text}"
        );
        assert!(
            text.starts_with("[remap]\n\nimporter=\"scene\"\n"),
            "{text}"
        );
    }

    /// By hand, from the rules of Godot 3.2's `camelcase_to_underscore` and `_sanitize_bone_name`
    /// (each name's expected value worked out rule by rule). Which characters survive (not `-`,
    /// `.`, `:` or `Ä`) was seen in Godot 3.2.3 itself, which tests/outputs/godot_import.rs runs on
    /// such names.
    #[test]
    fn bone_names_follow_godot_3_rules() {
        let cases = [
            ("Hips", "hips"),
            ("LeftUpLeg", "left_up_leg"),
            ("Spine1", "spine_1"),
            ("LeftToeBase", "left_toe_base"),
            ("mixamorig:LeftHand", "mixamorig_left_hand"),
            ("mixamorig:hand", "mixamorighand"),
            ("thigh.L", "thigh_l"),
            ("x-y Hand", "xy_hand"),
            ("HTTPServer", "http_server"),
            ("thigh_l", "thigh_l"),
            ("Bip01 L Thigh", "bip_1_l_thigh"),
            ("spine_01", "spine_1"),
            ("Hand100", "hand_10"),
            ("Toe2Tip", "toe_2_tip"),
            ("pelvis", "pelvis"),
            ("a/b", "ab"),
            ("", "bone"),
            (":", "bone"),
            ("ÄrmL", "rm_l"),
        ];
        for (name, godot) in cases {
            assert_eq!(bone_name(name), godot, "{name}");
        }
        assert_eq!(
            bone_names(["Spine1", "spine_1", "Spine01", "Hips"]),
            ["spine_1", "spine_1_2", "spine_1_3", "hips"]
        );
    }
}
