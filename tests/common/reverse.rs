//! A BVH played backwards in time: the same hierarchy, its frames in reverse order. Every frame
//! is a pose the body took, and the poses follow each other as closely as forwards, so a walk
//! becomes a kinematically valid walk backwards (its feet plant and lift in reverse: a heel strike
//! becomes a toe-off).

/// `text` (a BVH file) with its frame lines in reverse order; the header, `Frames:` and
/// `Frame Time:` unchanged.
pub fn reversed(text: &str) -> String {
    let at = text.find("MOTION").expect("a BVH has a MOTION section");
    let (hierarchy, motion) = text.split_at(at);
    let mut lines = motion.lines();
    let head: Vec<&str> = lines.by_ref().take(3).collect();
    let mut frames: Vec<&str> = lines.filter(|l| !l.trim().is_empty()).collect();
    frames.reverse();
    let mut out = String::with_capacity(text.len());
    out.push_str(hierarchy);
    for line in head.iter().chain(&frames) {
        out.push_str(line.trim_end_matches('\r'));
        out.push('\n');
    }
    out
}
