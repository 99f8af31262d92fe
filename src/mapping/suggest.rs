//! What a mapping error tells besides "unknown bone": the rig's bones nearest the name given (a
//! difference of case first, then the fewest edits) and the list of the rig's bones.

use crate::rig::Rig;

/// A name compared without case and without a Mixamo prefix (`mixamorig:`, `mixamorig1:`,
/// `mixamorig_`), as the rig matches names.
fn comparable(name: &str) -> String {
    let bare = match name.find(':') {
        Some(i) if name[..i].starts_with("mixamorig") => &name[i + 1..],
        _ => name.strip_prefix("mixamorig_").unwrap_or(name),
    };
    bare.to_lowercase()
}

/// At most this many suggestions.
const MAX_SUGGESTIONS: usize = 3;

/// The rig's bones nearest `name`, best first: the bones that differ from it only in case (and
/// Mixamo prefix); else those the fewest edits away (Damerau–Levenshtein distance on the
/// lower-cased names: insertions, deletions, substitutions, transpositions), when that distance
/// is at most a third of the name's length (at least 1, at most 3): a typo, not another bone.
/// Ties keep the rig's order; at most three.
pub fn nearest_bones<'r>(rig: &'r Rig, name: &str) -> Vec<&'r str> {
    let wanted = comparable(name);
    let names: Vec<(&str, String)> = rig
        .joints()
        .iter()
        .map(|j| (j.name.as_str(), comparable(&j.name)))
        .collect();
    let same_but_case: Vec<&str> = names
        .iter()
        .filter(|(_, c)| *c == wanted)
        .map(|(n, _)| *n)
        .take(MAX_SUGGESTIONS)
        .collect();
    if !same_but_case.is_empty() {
        return same_but_case;
    }
    let limit = (wanted.chars().count() / 3).clamp(1, 3);
    let scored: Vec<(&str, usize)> = names
        .iter()
        .map(|(n, c)| (*n, strsim::damerau_levenshtein(&wanted, c)))
        .filter(|&(_, d)| d <= limit)
        .collect();
    let Some(best) = scored.iter().map(|&(_, d)| d).min() else {
        return Vec::new();
    };
    scored
        .into_iter()
        .filter(|&(_, d)| d == best)
        .map(|(n, _)| n)
        .take(MAX_SUGGESTIONS)
        .collect()
}

/// `` `A` ``, `` `A` or `B` ``, `` `A`, `B` or `C` ``.
fn alternatives(names: &[&str]) -> String {
    let quoted: Vec<String> = names.iter().map(|n| format!("`{n}`")).collect();
    match quoted.split_last() {
        None => String::new(),
        Some((last, [])) => last.clone(),
        Some((last, rest)) => format!("{} or {last}", rest.join(", ")),
    }
}

/// The message of a bone the rig does not have: what was asked, the nearest bones when some are
/// near (`did you mean …?`), and every bone of the rig, in its order.
pub fn unknown_bone_message(rig: &Rig, bone: &str) -> String {
    let mut text = format!("unknown bone `{bone}` in rig `{}`", rig.name());
    let nearest = nearest_bones(rig, bone);
    if !nearest.is_empty() {
        text.push_str(&format!("; did you mean {}?", alternatives(&nearest)));
    }
    let all: Vec<&str> = rig.joints().iter().map(|j| j.name.as_str()).collect();
    text.push_str(&format!(
        " The rig's {} bones: {}",
        all.len(),
        all.join(", ")
    ));
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mixamo() -> Rig {
        crate::rig::load_rig("mixamo").unwrap()
    }

    #[test]
    fn a_difference_of_case_is_the_only_suggestion() {
        let rig = mixamo();
        assert_eq!(nearest_bones(&rig, "LeftForearm"), ["LeftForeArm"]);
        assert_eq!(nearest_bones(&rig, "HIPS"), ["Hips"]);
        assert_eq!(nearest_bones(&rig, "mixamorig:lefthand"), ["LeftHand"]);
    }

    #[test]
    fn typos_suggest_the_fewest_edits_and_far_names_nothing() {
        let rig = mixamo();
        // One letter dropped; two letters swapped.
        assert_eq!(nearest_bones(&rig, "LeftHnd"), ["LeftHand"]);
        assert_eq!(nearest_bones(&rig, "RightLge"), ["RightLeg"]);
        // Ties, in the rig's order: Spine3 is one edit from Spine, Spine1 and Spine2.
        assert_eq!(nearest_bones(&rig, "Spine3"), ["Spine", "Spine1", "Spine2"]);
        assert!(nearest_bones(&rig, "Tail").is_empty());
        assert!(nearest_bones(&rig, "Pelvis").is_empty());
    }

    #[test]
    fn the_message_lists_every_bone() {
        let rig = mixamo();
        let text = unknown_bone_message(&rig, "Spine3");
        assert!(
            text.starts_with(
                "unknown bone `Spine3` in rig `mixamo`; did you mean `Spine`, `Spine1` or `Spine2`?"
            ),
            "{text}"
        );
        for joint in rig.joints() {
            assert!(text.contains(&joint.name), "{} missing: {text}", joint.name);
        }
        let text = unknown_bone_message(&rig, "Tail");
        assert!(!text.contains("did you mean"), "{text}");
        assert!(text.contains(&format!("The rig's {} bones: Hips, ", rig.len())));
    }
}
