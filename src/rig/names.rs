//! What a joint's name says of its body part: one word and a side, from the naming schemes of the
//! suits, engines and tools people use. The resolution into parts (which needs the skeleton too)
//! is [`super::anatomy`]; the Blender add-on's `names.py` applies the same table.
//!
//! Recognised (any `namespace:` or `Armature|` prefix, `mixamorig_`, a `_chr00` suffix ignored):
//!
//! | scheme | example names |
//! |---|---|
//! | Mixamo | `Hips`, `Spine1`, `LeftShoulder` (the clavicle), `LeftArm`, `LeftForeArm`, `LeftUpLeg`, `LeftLeg`, `LeftToeBase` |
//! | Unity / VRM humanoid | `Chest`, `UpperChest`, `LeftUpperArm`, `LeftLowerArm`, `LeftUpperLeg`, `LeftLowerLeg`, `LeftToes` |
//! | game assets, Blender, Unreal | `UpperLeg_L`, `upper_arm.L`, `thigh_l`, `calf_r`, `clavicle_l`, `spine_01`, `ball_r` |
//! | CMU, Axis / Perception Neuron | `LowerBack`, `LHipJoint`, `Neck1`, `LeftFingerBase`, `Spine3` |
//! | Poser / DAZ | `hip`, `abdomen`, `chest`, `lCollar`, `lShldr` (the upper arm), `lForeArm`, `rButtock`, `lThigh`, `lShin`; Genesis's `lShldrBend`, `lForearmBend`, `lThighBend` (their `…Twist` are helpers) |
//! | SlimeVR | `Hip` (the pelvis), `Waist`, `Left-Hip` (the thigh), `Left-Knee`, `Left-Ankle`, `Left-Foot` (the toes, below the ankle) |
//! | Xsens MVN (BVH: joints named by the joint) | `Chest2`, `LeftCollar`, `LeftShoulder` (the upper arm), `LeftElbow`, `LeftWrist`, `LeftHip` (the thigh), `LeftKnee`, `LeftAnkle` |
//! | Xsens MVN segments | `Pelvis`, `L5`, `L3`, `T12`, `T8`, `LeftUpperArm`, `LeftToe` |
//! | Sony mocopi | `root`, `torso_1` … `torso_7`, `neck_1`, `l_shoulder`, `l_up_arm`, `l_low_arm`, `l_up_leg`, `l_low_leg`, `l_toes` |
//! | Rokoko | `Spine4`, `LeftThigh`, `LeftShin`, `LeftToe` |
//!
//! Two words mean different bones in different schemes, and only the skeleton tells which:
//! `Shoulder` is the clavicle when an upper arm hangs below it (Mixamo), else the upper arm
//! (MVN's BVH); a sided `Hip` is a hip joint when a thigh or another hip hangs below it (CMU's `LHipJoint`,
//! Poser's `rButtock`), else the thigh (MVN, SlimeVR). [`Word::Shoulder`] and [`Word::Hip`] say
//! so; [`super::anatomy`] decides.

/// Left or right, the body's own (not the viewer's).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Side {
    Left,
    Right,
}

impl Side {
    pub const BOTH: [Side; 2] = [Side::Left, Side::Right];

    /// `left`, `right`.
    pub fn name(self) -> &'static str {
        match self {
            Side::Left => "left",
            Side::Right => "right",
        }
    }

    /// `Left`, `Right`: the prefix of Mixamo's and Unity's names.
    pub fn prefix(self) -> &'static str {
        match self {
            Side::Left => "Left",
            Side::Right => "Right",
        }
    }

    /// 0 for left, 1 for right.
    pub fn index(self) -> usize {
        self as usize
    }
}

/// What a name says of a bone.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Word {
    /// A skeleton's root without a body part of its own (`root`; mocopi's pelvis).
    Root,
    Pelvis,
    /// Any joint of the spine between the pelvis and the neck (`Spine2`, `chest`, `T8`, `torso_3`).
    Spine,
    Neck,
    Head,
    Clavicle,
    /// The clavicle or the upper arm (see the module's docs).
    Shoulder,
    UpperArm,
    Forearm,
    Hand,
    /// A hip joint or the thigh (see the module's docs).
    Hip,
    Thigh,
    Shank,
    Foot,
    Toes,
}

/// Central words (no side) → aliases, lower case without separators. Numbered forms (`spine3`,
/// `torso7`, `chest4`, `neck2`, `t12`) are matched by [`central_word`].
const CENTRAL: &[(Word, &[&str])] = &[
    (Word::Root, &["root"]),
    (Word::Pelvis, &["hips", "hip", "pelvis"]),
    (
        Word::Spine,
        &[
            "spine",
            "lowerback",
            "upperback",
            "waist",
            "chest",
            "upperchest",
            "abdomen",
            "abdomenlower",
            "abdomenupper",
            "chestlower",
            "chestupper",
            "torso",
        ],
    ),
    (Word::Neck, &["neck", "necklower", "neckupper"]),
    (Word::Head, &["head"]),
];

/// Sided words → aliases.
const SIDED: &[(Word, &[&str])] = &[
    (Word::Clavicle, &["clavicle", "collar", "clav"]),
    (Word::Shoulder, &["shoulder"]),
    (
        Word::UpperArm,
        &["arm", "upperarm", "uparm", "shldr", "humerus"],
    ),
    (Word::Forearm, &["forearm", "lowerarm", "lowarm", "elbow"]),
    (Word::Hand, &["hand", "wrist"]),
    (Word::Hip, &["hip", "hipjoint", "buttock"]),
    (Word::Thigh, &["upleg", "thigh", "upperleg", "femur"]),
    (
        Word::Shank,
        &["leg", "shin", "calf", "lowerleg", "lowleg", "knee", "tibia"],
    ),
    (Word::Foot, &["foot", "ankle"]),
    (Word::Toes, &["toebase", "toe", "toes", "ball"]),
];

fn normalise(s: &str) -> String {
    s.chars()
        .filter(|c| c.is_ascii_alphanumeric())
        .map(|c| c.to_ascii_lowercase())
        .collect()
}

/// A central word: an alias, or `spine`/`torso`/`chest`/`neck` followed by a number (`spine01`,
/// `torso7`), or vertebrae (`l5`, `t12`, `t8`: the spine; `c1`…`c7`: the neck).
fn central_word(n: &str) -> Option<Word> {
    if let Some((w, _)) = CENTRAL.iter().find(|(_, a)| a.contains(&n)) {
        return Some(*w);
    }
    let numbered = |stem: &str| {
        n.strip_prefix(stem)
            .is_some_and(|d| !d.is_empty() && d.len() <= 3 && d.bytes().all(|b| b.is_ascii_digit()))
    };
    if ["spine", "torso", "chest", "abdomen"]
        .iter()
        .any(|s| numbered(s))
    {
        return Some(Word::Spine);
    }
    if numbered("neck") {
        return Some(Word::Neck);
    }
    let vertebra = |stem: &str, max: u32| {
        n.strip_prefix(stem)
            .and_then(|d| d.parse::<u32>().ok())
            .is_some_and(|k| (1..=max).contains(&k) && !n[1..].starts_with('0'))
    };
    if vertebra("c", 7) {
        return Some(Word::Neck);
    }
    (vertebra("l", 5) || vertebra("t", 12)).then_some(Word::Spine)
}

fn sided_word(bare: &str) -> Option<Word> {
    let n = normalise(bare);
    // DAZ Genesis splits a limb into its bend joint (the part) and a twist helper.
    let n = n
        .strip_suffix("bend")
        .filter(|s| !s.is_empty())
        .unwrap_or(&n);
    SIDED.iter().find(|(_, a)| a.contains(&n)).map(|(w, _)| *w)
}

/// `mixamorig:LeftArm`, `Armature|LeftArm`, `mixamorig_LeftArm`, `LeftArm_chr00` → `LeftArm`.
fn strip_decoration(name: &str) -> &str {
    let mut name = name.rsplit([':', '|']).next().unwrap_or(name);
    if name.len() > 10
        && name
            .get(..10)
            .is_some_and(|p| p.eq_ignore_ascii_case("mixamorig_"))
    {
        name = &name[10..];
    }
    // Perception Neuron's character suffix.
    if let Some(i) = name.rfind("_chr")
        && name[i + 4..].len() == 2
        && name[i + 4..].bytes().all(|b| b.is_ascii_digit())
        && i > 0
    {
        name = &name[..i];
    }
    name
}

/// Splits a side off the name: a word (`Left`, `right_`), a letter with a separator (`l_`,
/// `r.`, `-L`, `_r`), or a letter before a capital (`lThigh`, `RHipJoint`) — a suffix or a bare
/// letter only when what remains is a sided word.
fn side_of(bare: &str) -> Option<(Side, &str)> {
    let lower = bare.to_ascii_lowercase();
    for (word, side) in [("left", Side::Left), ("right", Side::Right)] {
        if lower.starts_with(word) && bare.len() > word.len() {
            let rest = bare[word.len()..].trim_start_matches(['_', '.', '-', ' ']);
            if !rest.is_empty() {
                return Some((side, rest));
            }
        }
    }
    let letter = |c: u8| match c.to_ascii_lowercase() {
        b'l' => Some(Side::Left),
        b'r' => Some(Side::Right),
        _ => None,
    };
    let b = bare.as_bytes();
    if b.len() > 2
        && let Some(side) = letter(b[0])
    {
        // `l_up_arm`, `L-Thigh`
        if matches!(b[1], b'_' | b'.' | b'-' | b' ') {
            return Some((side, &bare[2..]));
        }
        // `lThigh`, `RHipJoint`: a capital after the letter, and a sided word after it.
        if b[1].is_ascii_uppercase() && sided_word(&bare[1..]).is_some() {
            return Some((side, &bare[1..]));
        }
    }
    for (word, side) in [
        ("left", Side::Left),
        ("right", Side::Right),
        ("l", Side::Left),
        ("r", Side::Right),
    ] {
        if lower.len() > word.len() && lower.ends_with(word) {
            let rest = bare[..bare.len() - word.len()].trim_end_matches(['_', '.', '-', ' ']);
            // `_l`/`.R` need the separator; a bare `l` ending a word (`Spinal`) is not a side.
            let separated = rest.len() < bare.len() - word.len();
            if (word.len() > 1 || separated) && sided_word(rest).is_some() {
                return Some((side, rest));
            }
        }
    }
    None
}

/// Bones a rig drives through constraints (Rigify's deform and mechanism bones): never a part.
fn is_mechanism(name: &str) -> bool {
    [
        "DEF-", "ORG-", "MCH-", "VIS-", "WGT-", "DEF_", "ORG_", "MCH_",
    ]
    .iter()
    .any(|p| name.starts_with(p))
}

/// What `name` says: its side (for limbs) and word, or `None` when it names no main body part
/// (fingers, twist and helper bones, end effectors, eyes).
pub fn classify(name: &str) -> Option<(Option<Side>, Word)> {
    if is_mechanism(name) {
        return None;
    }
    let bare = strip_decoration(name);
    if let Some((side, rest)) = side_of(bare) {
        if let Some(word) = sided_word(rest) {
            return Some((Some(side), word));
        }
        // A sided name that is no limb (`LeftEye`, `LeftHandIndex1`).
        return None;
    }
    central_word(&normalise(bare)).map(|w| (None, w))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn l(w: Word) -> Option<(Option<Side>, Word)> {
        Some((Some(Side::Left), w))
    }
    fn r(w: Word) -> Option<(Option<Side>, Word)> {
        Some((Some(Side::Right), w))
    }
    fn c(w: Word) -> Option<(Option<Side>, Word)> {
        Some((None, w))
    }

    #[test]
    fn the_schemes_people_use_say_the_same_words() {
        use Word::*;
        let cases = [
            // Mixamo, with and without namespaces.
            ("mixamorig:LeftArm", l(UpperArm)),
            ("mixamorig1:RightForeArm", r(Forearm)),
            ("mixamorig_Hips", c(Pelvis)),
            ("Armature|Spine2", c(Spine)),
            ("LeftShoulder", l(Shoulder)),
            ("LeftToeBase", l(Toes)),
            // Unity / VRM humanoid.
            ("LeftUpperArm", l(UpperArm)),
            ("RightLowerLeg", r(Shank)),
            ("UpperChest", c(Spine)),
            ("LeftToes", l(Toes)),
            // Game assets, Blender, Unreal's mannequin.
            ("UpperLeg_L", l(Thigh)),
            ("LowerLeg_L", l(Shank)),
            ("UpperArm_L", l(UpperArm)),
            ("Foot_R", r(Foot)),
            ("upper_arm.L", l(UpperArm)),
            ("thigh.R", r(Thigh)),
            ("calf_r", r(Shank)),
            ("clavicle_l", l(Clavicle)),
            ("spine_01", c(Spine)),
            ("ball_r", r(Toes)),
            ("neck_01", c(Neck)),
            // CMU, Axis, Perception Neuron.
            ("LowerBack", c(Spine)),
            ("LHipJoint", l(Hip)),
            ("Neck1", c(Neck)),
            ("Spine3", c(Spine)),
            ("RightUpLeg_chr00", r(Thigh)),
            // Poser / DAZ.
            ("hip", c(Pelvis)),
            ("abdomen", c(Spine)),
            ("chest", c(Spine)),
            ("lCollar", l(Clavicle)),
            ("lShldr", l(UpperArm)),
            ("rForeArm", r(Forearm)),
            ("rButtock", r(Hip)),
            ("lThigh", l(Thigh)),
            ("lShin", l(Shank)),
            ("lFoot", l(Foot)),
            ("lShldrBend", l(UpperArm)),
            ("lForearmBend", l(Forearm)),
            ("rThighBend", r(Thigh)),
            ("lShldrTwist", None),
            ("C7", c(Neck)),
            ("センター", None),
            ("左足ＩＫ_mixamo", None),
            // SlimeVR.
            ("Hip", c(Pelvis)),
            ("Waist", c(Spine)),
            ("Left-Hip", l(Hip)),
            ("Right-Knee", r(Shank)),
            ("Left-Foot", l(Foot)),
            // Xsens MVN: BVH (joint-named) and segments.
            ("Chest4", c(Spine)),
            ("LeftCollar", l(Clavicle)),
            ("LeftElbow", l(Forearm)),
            ("LeftWrist", l(Hand)),
            ("RightAnkle", r(Foot)),
            ("L5", c(Spine)),
            ("T12", c(Spine)),
            ("LeftToe", l(Toes)),
            // mocopi.
            ("root", c(Root)),
            ("torso_7", c(Spine)),
            ("neck_2", c(Neck)),
            ("l_up_arm", l(UpperArm)),
            ("r_low_leg", r(Shank)),
            ("l_shoulder", l(Shoulder)),
            // Not main bones.
            ("LeftHandIndex1", None),
            ("LeftForeArmTwist", None),
            ("LeftEye", None),
            ("Left", None),
            ("Arm", None),
            ("RThumb", None),
            ("LFingers", None),
            ("End", None),
            ("HeadTop_End", None),
            ("DEF-upper_arm.L", None),
            ("Spinal", None),
            ("L0", None),
            ("T13", None),
        ];
        for (name, word) in cases {
            assert_eq!(classify(name), word, "{name}");
        }
    }
}
