//! Which foot carries the body, decided over a whole take: the support path.
//!
//! A foot that carries the body holds still on the ground, so the hips move by minus its motion
//! relative to them: each frame `t` and foot `f` imply a hips velocity
//! `v_f(t) = −(p_f(t) − p_f(t−1)) / dt` (`p_f` the point the foot pivots on, relative to the
//! hips; all three axes). The foot that really carries the body implies the hips' real motion,
//! which changes slowly (a body accelerates at a fraction of g); a swinging foot, or one sliding
//! off, implies a velocity that jumps and swings. So the support path `s(t) ∈ {left, right}` is
//! the one that minimises
//!
//! ```text
//! C = Σ_t  |v_s(t)(t) − v_s(t−1)(t−1)| / (A · dt)      the hips' acceleration, in units of A
//!        + a_s(t)(t) / H                                 its foot's height above the other's
//!        + λ · [s(t) ≠ s(t−1)]                            a switch
//! ```
//!
//! with `A` = [`ACCEL_UNIT_G`] g, `H` = [`HEIGHT_UNIT_H`] h and λ = [`SWITCH_COST`]: a
//! first-order chain over two states, solved exactly by dynamic programming (Viterbi) in
//! `O(frames)`. The per-frame scores a stream uses ([`super::RootCore::push`]) judge each frame
//! from the hips' recent velocity, which follows whichever foot they chose: once they follow a
//! foot that slides, it looks planted and the planted one looks swinging (a sideways shuffle, a
//! backwards step). A path over the whole take has no such memory to lock onto — every frame's
//! choice is paid for by its neighbours' — which is why a whole take decodes it and a stream,
//! which cannot wait for the frames after, does not.

use nalgebra::Vector3;

/// The acceleration that costs one unit, in g (9.81 m/s² on a 1.75 m body, in standing heights).
/// Walking moves the hips at a few tenths of g; a swinging foot implies several g.
pub const ACCEL_UNIT_G: f64 = 1.0;
/// A foot this much higher than the other costs one unit per frame, × h: the lower foot is the
/// one on the ground, other things equal (double support, standing).
pub const HEIGHT_UNIT_H: f64 = 0.01;
/// Passing the weight to the other foot costs this many units, so that noise does not flicker it.
pub const SWITCH_COST: f64 = 1.0;

/// What one frame says about each foot ([left, right]), in standing heights `h`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SupportCues {
    /// The hips' velocity were this foot planted, h / s (nil on a take's first frame).
    pub implied: [Vector3<f64>; 2],
    /// How much higher this foot's lowest point is than the other's, h (≥ 0, one of them 0).
    pub above: [f64; 2],
}

/// The path's cost `C` (see the module), for `path[t]` ∈ {0 left, 1 right}; `frame_time_s` the
/// frames' spacing, `gravity_h_s2` g in standing heights per s².
pub fn cost(cues: &[SupportCues], path: &[usize], frame_time_s: f64, gravity_h_s2: f64) -> f64 {
    let unit = ACCEL_UNIT_G * gravity_h_s2 * frame_time_s;
    let mut total = 0.0;
    for (t, (c, &s)) in cues.iter().zip(path).enumerate() {
        total += c.above[s] / HEIGHT_UNIT_H;
        if t > 0 {
            let p = path[t - 1];
            total += (c.implied[s] - cues[t - 1].implied[p]).norm() / unit;
            if p != s {
                total += SWITCH_COST;
            }
        }
    }
    total
}

/// The support path of least [`cost`]: per frame 0 (left) or 1 (right).
pub fn decode(cues: &[SupportCues], frame_time_s: f64, gravity_h_s2: f64) -> Vec<usize> {
    let Some(first) = cues.first() else {
        return Vec::new();
    };
    let unit = ACCEL_UNIT_G * gravity_h_s2 * frame_time_s;
    let mut best = first.above.map(|a| a / HEIGHT_UNIT_H);
    // The state each frame's best path to each state came from.
    let mut from = vec![[0usize; 2]; cues.len()];
    for t in 1..cues.len() {
        let (c, before) = (&cues[t], &cues[t - 1]);
        let mut next = [0.0; 2];
        for s in 0..2 {
            let step = |p: usize| {
                best[p]
                    + (c.implied[s] - before.implied[p]).norm() / unit
                    + if p == s { 0.0 } else { SWITCH_COST }
            };
            let p = usize::from(step(1) < step(0));
            next[s] = step(p) + c.above[s] / HEIGHT_UNIT_H;
            from[t][s] = p;
        }
        best = next;
    }
    let mut s = usize::from(best[1] < best[0]);
    let mut path = vec![0; cues.len()];
    for t in (0..cues.len()).rev() {
        path[t] = s;
        s = from[t][s];
    }
    path
}

/// A support path without its flickers: a foot that carries the body for fewer than
/// `min_frames` frames between two stretches of the other (a frame or two where the sensors' noise
/// tipped the balance; no foot lands and lifts that fast) leaves the weight with the other. The
/// path's first and last stretches are kept, however short.
pub fn without_flickers(path: &mut [usize], min_frames: usize) {
    let n = path.len();
    let mut t = 0;
    while t < n {
        let start = t;
        while t < n && path[t] == path[start] {
            t += 1;
        }
        if start > 0 && t < n && t - start < min_frames {
            let other = path[start - 1];
            path[start..t].fill(other);
        }
    }
}

/// The left foot's share of the weight per frame from a support path: the mean of
/// `[path == left]` over `±blend` frames, so the weight passes over `2·blend + 1` frames
/// rather than at once (the two feet's surfaces put the hips at heights that differ by the
/// sensors' error; blended, they do not jump).
pub fn left_weights(path: &[usize], blend: usize) -> Vec<f64> {
    let n = path.len();
    (0..n)
        .map(|t| {
            let (a, b) = (t.saturating_sub(blend), (t + blend).min(n - 1));
            path[a..=b].iter().filter(|&&s| s == 0).count() as f64 / (b - a + 1) as f64
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const G: f64 = 9.80665 / 1.75;
    const DT: f64 = 1.0 / 60.0;

    fn cue(left: [f64; 2], right: [f64; 2], above: [f64; 2]) -> SupportCues {
        SupportCues {
            implied: [
                Vector3::new(left[0], left[1], 0.0),
                Vector3::new(right[0], right[1], 0.0),
            ],
            above,
        }
    }

    /// A sliding foot that is lower is still not the support when the other implies steady hips:
    /// the left foot implies the hips walking at 1 h/s throughout; the right, 0.002 h lower
    /// (0.2 units a frame against the left), implies a velocity growing by 0.5 h/s a frame
    /// (30 h/s², about 5 g: 5 units a frame). By hand the all-left path costs 20 · 0.2 = 4 units,
    /// any right frame at least 5 more: all left.
    #[test]
    fn steady_hips_beat_a_lower_sliding_foot() {
        let cues: Vec<SupportCues> = (0..20)
            .map(|t| cue([1.0, 0.0], [-3.0 + 0.5 * t as f64, 0.0], [0.002, 0.0]))
            .collect();
        let path = decode(&cues, DT, G);
        assert_eq!(path, vec![0; 20]);
        assert!((cost(&cues, &path, DT, G) - 20.0 * 0.2).abs() < 1e-9);
    }

    /// Double support: both feet imply the same steady hips, so the lower foot carries them —
    /// the left for the first ten frames, then the right once the left is 0.005 h higher (0.5
    /// units a frame), one switch (1 unit) rather than ten frames on the higher foot.
    #[test]
    fn in_double_support_the_lower_foot_carries() {
        let cues: Vec<SupportCues> = (0..20)
            .map(|t| {
                let above = if t < 10 { [0.0, 0.005] } else { [0.005, 0.0] };
                cue([1.0, 0.0], [1.0, 0.0], above)
            })
            .collect();
        let path = decode(&cues, DT, G);
        let expected: Vec<usize> = (0..20).map(|t| usize::from(t >= 10)).collect();
        assert_eq!(path, expected);
        assert_eq!(
            left_weights(&path, 1)[8..12],
            [1.0, 2.0 / 3.0, 1.0 / 3.0, 0.0]
        );
        assert_eq!(left_weights(&[0, 1], 3), vec![0.5, 0.5]);
    }

    proptest! {
        /// The path decoded is a path of least cost: no path of up to 9 frames, enumerated
        /// by brute force, costs less.
        #[test]
        fn decoding_finds_the_cheapest_path(
            raw in prop::collection::vec(
                (-3.0f64..3.0, -3.0f64..3.0, -3.0f64..3.0, -3.0f64..3.0, 0.0f64..0.03, any::<bool>()),
                1..10,
            )
        ) {
            let cues: Vec<SupportCues> = raw
                .iter()
                .map(|&(a, b, c, d, up, which)| {
                    cue([a, b], [c, d], if which { [up, 0.0] } else { [0.0, up] })
                })
                .collect();
            let n = cues.len();
            let path = decode(&cues, DT, G);
            let decoded = cost(&cues, &path, DT, G);
            let cheapest = (0..1usize << n)
                .map(|bits| {
                    let p: Vec<usize> = (0..n).map(|t| (bits >> t) & 1).collect();
                    cost(&cues, &p, DT, G)
                })
                .fold(f64::INFINITY, f64::min);
            prop_assert!(decoded <= cheapest + 1e-9, "{decoded} vs {cheapest}");
        }
    }

    proptest! {
        /// Without its flickers a path has no stretch shorter than the minimum but its first and
        /// last, keeps their feet, and is its own without them.
        #[test]
        fn no_flicker_is_left(path in prop::collection::vec(0usize..2, 0..60), min in 1usize..5) {
            let mut clean = path.clone();
            without_flickers(&mut clean, min);
            let stretches = |p: &[usize]| {
                let mut out: Vec<(usize, usize)> = Vec::new();
                for &f in p {
                    match out.last_mut() {
                        Some((foot, len)) if *foot == f => *len += 1,
                        _ => out.push((f, 1)),
                    }
                }
                out
            };
            let s = stretches(&clean);
            for &(_, len) in s.iter().skip(1).take(s.len().saturating_sub(2)) {
                prop_assert!(len >= min, "{clean:?}");
            }
            prop_assert_eq!(clean.first(), path.first());
            prop_assert_eq!(clean.last(), path.last());
            let mut again = clean.clone();
            without_flickers(&mut again, min);
            prop_assert_eq!(again, clean);
        }
    }

    /// A frame or two of the other foot between two stretches of one is noise; three frames
    /// are a support, and the path's ends stay as they are.
    #[test]
    fn flickers_leave_the_weight_where_it_was() {
        let mut path = vec![0, 0, 0, 0, 1, 0, 0, 0, 1, 1, 0, 0, 0, 1, 1, 1, 0, 0, 0, 1];
        without_flickers(&mut path, 3);
        assert_eq!(
            path,
            [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 0, 0, 0, 1]
        );
        let mut starts_short = vec![1, 0, 0, 0];
        without_flickers(&mut starts_short, 3);
        assert_eq!(starts_short, [1, 0, 0, 0]);
    }
}
