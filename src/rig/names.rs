//! Joint names to anatomical parts: the humanoid naming schemes of the suits and engines people
//! use, each reduced to one canonical part per bone — the names of the built-in `mixamo` rig
//! (Hips, Spine, Spine1, Spine2, Neck, Head, and per side Shoulder, Arm, ForeArm, Hand, UpLeg,
//! Leg, Foot, ToeBase). The Blender add-on's `names.py` applies the same rules.
//!
//! Recognised: Mixamo (`mixamorig:LeftArm`, any `namespace:` or `|` prefix), Unity/VRM humanoid
//! (`LeftUpperArm`, `LeftLowerLeg`), `.L/.R`, `_l/_r`, `_L/_R`, `l_`/`r_` (`upper_arm.L`,
//! `upperarm_l` as in Unreal's mannequin, `l_up_arm` as in mocopi), CMU/Axis (`LeftUpLeg`,
//! `LowerBack`, `Spine3`), SlimeVR (`Hip`, `Waist`, `Chest`, `UpperChest`, `LeftUpperLeg`), Xsens
//! MVN's segments (`Pelvis`, `L5`, `T12`, `T8`, `RightUpperArm`, `LeftToe`), and a spine numbered
//! from the hips (`spine_01` … `spine_03`).

/// The canonical parts, in hierarchy order.
pub const CANONICAL: [&str; 22] = [
    "Hips",
    "Spine",
    "Spine1",
    "Spine2",
    "Neck",
    "Head",
    "LeftShoulder",
    "LeftArm",
    "LeftForeArm",
    "LeftHand",
    "LeftUpLeg",
    "LeftLeg",
    "LeftFoot",
    "LeftToeBase",
    "RightShoulder",
    "RightArm",
    "RightForeArm",
    "RightHand",
    "RightUpLeg",
    "RightLeg",
    "RightFoot",
    "RightToeBase",
];

/// Side-free part → its aliases (lower case, no separators).
const ALIASES: &[(&str, &[&str])] = &[
    ("Hips", &["hips", "pelvis", "hip"]),
    ("Spine", &["spine", "spine01", "waist", "lowerback", "l5"]),
    ("Spine1", &["spine1", "spine02", "chest", "t12"]),
    (
        "Spine2",
        &["spine2", "spine03", "upperchest", "spine3", "t8"],
    ),
    ("Neck", &["neck", "neck01", "neck1"]),
    ("Head", &["head"]),
    ("Shoulder", &["shoulder", "clavicle", "collar"]),
    ("Arm", &["arm", "upperarm", "uparm"]),
    ("ForeArm", &["forearm", "lowerarm", "lowarm"]),
    ("Hand", &["hand", "wrist"]),
    ("UpLeg", &["upleg", "thigh", "upperleg"]),
    (
        "Leg",
        &["leg", "shin", "calf", "lowerleg", "lowleg", "knee"],
    ),
    ("Foot", &["foot", "ankle"]),
    ("ToeBase", &["toebase", "toe", "toes", "ball"]),
];

const CENTRAL: [&str; 6] = ["Hips", "Spine", "Spine1", "Spine2", "Neck", "Head"];

fn normalise(s: &str) -> String {
    s.chars()
        .filter(|c| c.is_ascii_alphanumeric())
        .map(|c| c.to_ascii_lowercase())
        .collect()
}

fn part_of_alias(bare: &str) -> Option<&'static str> {
    let n = normalise(bare);
    ALIASES
        .iter()
        .find(|(_, aliases)| aliases.contains(&n.as_str()))
        .map(|(part, _)| *part)
}

/// `mixamorig:LeftArm`, `Armature|LeftArm`, `mixamorig_LeftArm` → `LeftArm`.
fn strip_namespace(name: &str) -> &str {
    let name = name.rsplit([':', '|']).next().unwrap_or(name);
    match name.get(..10) {
        Some(p) if p.eq_ignore_ascii_case("mixamorig_") => &name[10..],
        _ => name,
    }
}

/// Splits a side off the name: a prefix (`Left`, `Right`, `l_`, `r.`) or a suffix (`_l`, `.R`,
/// `Left`) — the latter only when what remains is a part's alias. `('L' | 'R', rest)`.
fn side_of(bare: &str) -> Option<(char, &str)> {
    let lower = bare.to_ascii_lowercase();
    for (word, side) in [("left", 'L'), ("right", 'R')] {
        if lower.starts_with(word) && bare.len() > word.len() {
            let rest = bare[word.len()..].trim_start_matches(['_', '.', '-', ' ']);
            if !rest.is_empty() {
                return Some((side, rest));
            }
        }
    }
    for (letter, side) in [('l', 'L'), ('r', 'R')] {
        let mut chars = lower.chars();
        if chars.next() == Some(letter)
            && matches!(chars.next(), Some('_' | '.' | '-' | ' '))
            && bare.len() > 2
        {
            return Some((side, &bare[2..]));
        }
    }
    for (word, side) in [("left", 'L'), ("right", 'R'), ("l", 'L'), ("r", 'R')] {
        if lower.len() > word.len() && lower.ends_with(word) {
            let rest = bare[..bare.len() - word.len()].trim_end_matches(['_', '.', '-', ' ']);
            // `_l`/`.R` need the separator; a bare `l` ending a word (`Spinal`) is not a side.
            let separated = rest.len() < bare.len() - word.len();
            if (word.len() > 1 || separated) && part_of_alias(rest).is_some() {
                return Some((side, rest));
            }
        }
    }
    None
}

/// The canonical part of a joint name, or `None` when it is not one of the main humanoid bones
/// (fingers, twist and helper bones, end effectors).
pub fn canonical(name: &str) -> Option<&'static str> {
    let bare = strip_namespace(name);
    let (side, bare) = match side_of(bare) {
        Some((side, rest)) => (Some(side), rest),
        None => (None, bare),
    };
    let part = part_of_alias(bare)?;
    let central = CENTRAL.contains(&part);
    match (central, side) {
        (true, None) => Some(part),
        (false, Some(side)) => {
            let prefix = if side == 'L' { "Left" } else { "Right" };
            CANONICAL
                .iter()
                .find(|c| c.strip_prefix(prefix) == Some(part))
                .copied()
        }
        _ => None,
    }
}

/// `(part, joint index)` for a skeleton's joint names: the first joint of each part, in order.
pub fn match_joints<'a>(names: impl IntoIterator<Item = &'a str>) -> Vec<(&'static str, usize)> {
    let mut out: Vec<(&'static str, usize)> = Vec::new();
    for (i, name) in names.into_iter().enumerate() {
        if let Some(part) = canonical(name)
            && !out.iter().any(|(p, _)| *p == part)
        {
            out.push((part, i));
        }
    }
    out
}

/// `(source joint, target joint)` pairs of the parts both skeletons have, in canonical order.
pub fn auto_map<'a, 'b>(
    source: impl IntoIterator<Item = &'a str>,
    target: impl IntoIterator<Item = &'b str>,
) -> Vec<(usize, usize)> {
    let source = match_joints(source);
    let target = match_joints(target);
    CANONICAL
        .iter()
        .filter_map(|part| {
            let s = source.iter().find(|(p, _)| p == part)?.1;
            let t = target.iter().find(|(p, _)| p == part)?.1;
            Some((s, t))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_schemes_people_use_name_the_same_parts() {
        let cases: &[(&str, Option<&str>)] = &[
            // Mixamo, with and without namespaces.
            ("mixamorig:LeftArm", Some("LeftArm")),
            ("mixamorig1:RightForeArm", Some("RightForeArm")),
            ("mixamorig_Hips", Some("Hips")),
            ("Armature|Spine2", Some("Spine2")),
            // Unity / VRM humanoid.
            ("LeftUpperArm", Some("LeftArm")),
            ("RightLowerLeg", Some("RightLeg")),
            ("UpperChest", Some("Spine2")),
            ("LeftToes", Some("LeftToeBase")),
            // Suffixes: Blender, Unreal's mannequin.
            ("upper_arm.L", Some("LeftArm")),
            ("thigh.R", Some("RightUpLeg")),
            ("upperarm_l", Some("LeftArm")),
            ("calf_r", Some("RightLeg")),
            ("clavicle_l", Some("LeftShoulder")),
            ("spine_01", Some("Spine")),
            ("spine_03", Some("Spine2")),
            ("foot_l", Some("LeftFoot")),
            ("ball_r", Some("RightToeBase")),
            // CMU, Axis Neuron.
            ("LeftUpLeg", Some("LeftUpLeg")),
            ("LowerBack", Some("Spine")),
            ("Neck1", Some("Neck")),
            ("RightToeBase", Some("RightToeBase")),
            // SlimeVR.
            ("Hip", Some("Hips")),
            ("Waist", Some("Spine")),
            ("Chest", Some("Spine1")),
            ("LeftUpperLeg", Some("LeftUpLeg")),
            // Xsens MVN segments.
            ("L5", Some("Spine")),
            ("T12", Some("Spine1")),
            ("T8", Some("Spine2")),
            ("RightUpperLeg", Some("RightUpLeg")),
            ("LeftToe", Some("LeftToeBase")),
            // mocopi-style prefixes.
            ("l_up_arm", Some("LeftArm")),
            ("r_low_leg", Some("RightLeg")),
            // Not main bones.
            ("LeftHandIndex1", None),
            ("LeftForeArmTwist", None),
            ("Left", None),
            ("Arm", None),      // a limb needs a side
            ("LeftHips", None), // the centre has none
            ("RThumb", None),
            ("End", None),
        ];
        for (name, part) in cases {
            assert_eq!(canonical(name), *part, "{name}");
        }
    }

    #[test]
    fn skeletons_map_part_by_part_and_first_match_wins() {
        // CMU's spine: LowerBack, Spine, Spine1; Neck then Neck1.
        let cmu = [
            "Hips",
            "LowerBack",
            "Spine",
            "Spine1",
            "Neck",
            "Neck1",
            "Head",
            "LeftArm",
        ];
        let mixamo = [
            "Hips", "Spine", "Spine1", "Spine2", "Neck", "Head", "LeftArm",
        ];
        let pairs = auto_map(cmu, mixamo);
        let named: Vec<(&str, &str)> = pairs.iter().map(|&(s, t)| (cmu[s], mixamo[t])).collect();
        assert_eq!(
            named,
            [
                ("Hips", "Hips"),
                ("LowerBack", "Spine"),
                ("Spine1", "Spine1"),
                ("Neck", "Neck"),
                ("Head", "Head"),
                ("LeftArm", "LeftArm"),
            ]
        );
    }
}
