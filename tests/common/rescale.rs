//! A BVH in another length unit: every `OFFSET` and every position channel multiplied by one
//! factor, the rotations and the frame time unchanged — the same motion measured in other units
//! (CMU's BVHs, in 1/0.45 inch, become centimetres with `factor = 2.54 / 0.45`).

/// `text` (a BVH file) with its lengths multiplied by `factor`.
pub fn scaled(text: &str, factor: f64) -> String {
    let at = text.find("MOTION").expect("a BVH has a MOTION section");
    let (hierarchy, motion) = text.split_at(at);
    let scale = |words: &[&str]| -> String {
        words
            .iter()
            .map(|w| format!("{}", w.parse::<f64>().expect("a number") * factor))
            .collect::<Vec<_>>()
            .join(" ")
    };
    let mut out = String::with_capacity(text.len() + text.len() / 4);
    // Which of a frame's columns are positions, in channel order.
    let mut positions = Vec::new();
    for line in hierarchy.lines() {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.first() {
            Some(&"OFFSET") => {
                let indent = &line[..line.len() - line.trim_start().len()];
                out.push_str(&format!("{indent}OFFSET {}\n", scale(&words[1..])));
                continue;
            }
            Some(&"CHANNELS") => {
                positions.extend(words[2..].iter().map(|c| c.ends_with("position")));
            }
            _ => {}
        }
        out.push_str(line.trim_end_matches('\r'));
        out.push('\n');
    }
    let mut lines = motion.lines();
    for line in lines.by_ref().take(3) {
        out.push_str(line.trim_end_matches('\r'));
        out.push('\n');
    }
    for line in lines.filter(|l| !l.trim().is_empty()) {
        let values: Vec<String> = line
            .split_whitespace()
            .zip(&positions)
            .map(
                |(v, &position)| {
                    if position { scale(&[v]) } else { v.to_string() }
                },
            )
            .collect();
        out.push_str(&values.join(" "));
        out.push('\n');
    }
    out
}
