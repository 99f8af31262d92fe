//! Where the hips' path went through a foot that slid: their horizontal velocity bridged across
//! a transient no body on its feet can make, decided over a whole take.
//!
//! The support path ([`super::support`]) moves the hips by minus the carrying foot's motion
//! relative to them. When that foot slides over the ground — a sideways gallop's feet skim it as
//! they close, a foot stepping down off a block drags — the hips take the slide as their own
//! motion, backwards: their velocity leaves its course and comes back within a few tenths of a
//! second. The ground pushes the body horizontally by friction alone, `|a_h| ≤ μ (g + a_y)`:
//! smoothed as below, a walk's or a run's hips accelerate at a few tenths of g, and the hardest
//! in issue 49's sources (CMU 01_01's hop landings) at under 1.5 g. So a transient beyond
//! [`SLIDE_ACCEL_G`] g that returns to where it left is a followed foot's slide, not the body's
//! motion.
//!
//! With `v(t)` the hips' horizontal velocity (a frame's step over `dt`) and `v̄(t)` its mean over
//! the `2k + 1` frames around `t`, `k = ⌊round(SMOOTH_S / dt) / 2⌋ ≥ 1` (7 frames at 60 fps, 3 at
//! 30: about [`SMOOTH_S`]), the smoothed acceleration is `a(t) = |v̄(t+1) − v̄(t−1)| / 2dt`. Each
//! frame on the feet with `a > SLIDE_ACCEL_G·g` starts a window, which grows over the frames on
//! either side while `a > RELEASE_G·g`, then by `k` frames on each side; overlapping
//! windows merge. A window `[i, j]` is left alone when a frame of it or next to it is in the air
//! (a flight's), when it lasts longer than [`LONGEST_S`], or when its velocities before and after
//! (`v₀ = v̄(i−1)`, `v₁ = v̄(j+1)`) differ by more than [`RETURN`] times its excursion — the
//! largest `|v̄(t) − ℓ(t)|` inside, `ℓ(t) = v₀ + (v₁ − v₀)(t − i + 1)/(j − i + 2)` the straight
//! line between them: that is a change of pace (a stop, a start), not a slide. Else:
//!
//! - **across a transfer** (the weight passes from foot to foot inside it): nothing fixes where
//!   the new foot stands relative to the old one's slide, so the hips cross at `ℓ`:
//!   `H(t) = H(t−1) + ℓ(t)·dt` for `i ≤ t ≤ j`, and the frames after move with `H(j)`, so the
//!   path goes on without a jump;
//! - **on one foot throughout**: the transient is that foot's pivot passing along its sole (heel
//!   to toes, as the other lands), which comes back, and the foot as a whole stood: the
//!   displacement `H(j+1) − H(i−1)` is kept and the path between follows the cubic Hermite curve
//!   meeting `H` and `v̄` at `i − 1` and `j + 1`.
//!
//! Measured on issue 49's sideways gallop (CMU 06_08:
//! `a_sideways_gallop_is_bridged_across_its_slides`) and issue 50's terrain (CMU 03_01–03_04):
//! `every_gait_walks_without_sliding` and `changing_ground_keeps_each_foot_on_its_own` print the
//! paths; at 60 fps no window opens on the other gaits there. A stream cannot wait for a slide's
//! end and keeps its path.

use super::transfer::hermite;
use nalgebra::Vector3;

/// A smoothed horizontal acceleration of the hips beyond this, × g, starts a window.
pub const SLIDE_ACCEL_G: f64 = 1.5;
/// … which spreads over the frames around it still accelerating beyond this, × g.
pub const RELEASE_G: f64 = 0.5;
/// The velocity is smoothed over about this long, s (centred, an odd number of frames).
pub const SMOOTH_S: f64 = 0.1;
/// A window whose velocities before and after differ by more than this fraction of its excursion
/// is a change of pace, not a slide.
pub const RETURN: f64 = 0.5;
/// A window longer than this, s, is no foot's slide (a foot slides for a stance at most: about
/// half a second at a walk) and no straight line describes the hips over it; it is left alone.
pub const LONGEST_S: f64 = 0.75;

/// A window bridged.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bridged {
    /// Its first and last frames.
    pub first: usize,
    pub last: usize,
    /// One foot carried throughout: its displacement kept, the path across smoothed.
    pub one_foot: bool,
}

/// Bridges `hips` (rig units, per frame; `airborne` per frame) where they went through a slide
/// (see the module), `dt` the frames' spacing (s) and `gravity` g in rig units per s². Only x
/// and z change; `left_weight` is the left foot's share of the weight per frame (the support
/// path's, [`super::support::left_weights`]). Returns the windows bridged.
pub fn bridge(
    hips: &mut [Vector3<f64>],
    airborne: &[bool],
    left_weight: &[f64],
    dt: f64,
    gravity: f64,
) -> Vec<Bridged> {
    let n = hips.len().min(airborne.len()).min(left_weight.len());
    let half = ((SMOOTH_S / dt).round() as usize / 2).max(1);
    if n < 2 * half + 3 || dt <= 0.0 || gravity <= 0.0 {
        return Vec::new();
    }
    let flat = |v: Vector3<f64>| Vector3::new(v.x, 0.0, v.z);
    // The first frame has no step of its own: it takes the second's.
    let v: Vec<Vector3<f64>> = (0..n)
        .map(|t| flat(hips[t.max(1)] - hips[t.max(1) - 1]) / dt)
        .collect();
    let smooth: Vec<Vector3<f64>> = (0..n)
        .map(|t| {
            let (a, b) = (t.saturating_sub(half), (t + half).min(n - 1));
            v[a..=b].iter().sum::<Vector3<f64>>() / (b - a + 1) as f64
        })
        .collect();
    let accel = |t: usize| {
        if t == 0 || t + 1 >= n {
            0.0
        } else {
            (smooth[t + 1] - smooth[t - 1]).norm() / (2.0 * dt)
        }
    };
    let (start, release) = (SLIDE_ACCEL_G * gravity, RELEASE_G * gravity);
    // The windows, grown and padded, overlapping ones merged.
    let mut windows: Vec<[usize; 2]> = Vec::new();
    let mut t = 1;
    while t + 1 < n {
        if airborne[t] || accel(t) <= start {
            t += 1;
            continue;
        }
        let (mut i, mut j) = (t, t);
        while i > 1 && !airborne[i - 1] && accel(i - 1) > release {
            i -= 1;
        }
        while j + 2 < n && !airborne[j + 1] && accel(j + 1) > release {
            j += 1;
        }
        let (i, j) = (i.saturating_sub(half).max(1), (j + half).min(n - 2));
        match windows.last_mut() {
            Some(last) if i <= last[1] + 1 => last[1] = last[1].max(j),
            _ => windows.push([i, j]),
        }
        t = j + 1;
    }
    // Each frame's horizontal step, the bridged windows' replaced by the line's or the curve's.
    let mut bridged = Vec::new();
    let mut step: Vec<Vector3<f64>> = v.iter().map(|v| v * dt).collect();
    for [i, j] in windows {
        if airborne[i - 1..=j + 1].iter().any(|&a| a) || (j + 1 - i) as f64 * dt > LONGEST_S {
            continue;
        }
        let (v0, v1) = (smooth[i - 1], smooth[j + 1]);
        let line = |t: usize| v0 + (v1 - v0) * ((t - i + 1) as f64 / (j - i + 2) as f64);
        let excursion = (i..=j)
            .map(|t| (smooth[t] - line(t)).norm())
            .fold(0.0, f64::max);
        if (v1 - v0).norm() > RETURN * excursion {
            continue;
        }
        let one_foot = left_weight[i..=j].iter().all(|&w| w == left_weight[i]);
        if one_foot {
            // One foot carried throughout: the displacement is its, the path across smoothed.
            let (a, b) = (i - 1, j + 1);
            let span = (b - a) as f64 * dt;
            let (p0, p1) = (flat(hips[a]), flat(hips[b]));
            let mut at = p0;
            for (t, s) in step.iter_mut().enumerate().take(j + 1).skip(i) {
                let tau = (t - a) as f64 / (b - a) as f64;
                let axis = |k: usize| hermite(p0[k], v0[k], p1[k], v1[k], span, tau);
                let p = Vector3::new(axis(0), 0.0, axis(2));
                *s = p - at;
                at = p;
            }
            step[b] = p1 - at;
        } else {
            for (t, s) in step.iter_mut().enumerate().take(j + 1).skip(i) {
                *s = line(t) * dt;
            }
        }
        bridged.push(Bridged {
            first: i,
            last: j,
            one_foot,
        });
    }
    // The path again from the first window on (before it, as it was to the bit).
    if let Some(&Bridged { first, .. }) = bridged.first() {
        for t in first..n {
            let p = hips[t - 1] + step[t];
            hips[t] = Vector3::new(p.x, hips[t].y, p.z);
        }
    }
    bridged
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const DT: f64 = 1.0 / 60.0;
    /// g in standing heights per s² (a 1.75 m subject; the hips below in h).
    const G: f64 = 9.80665 / 1.75;

    /// Hips walking along x at 1 h/s from x = 0, but at −1 h/s over frames 25–30 (a slide
    /// followed: 6 frames), 60 frames.
    fn walk_with_a_slide() -> Vec<Vector3<f64>> {
        let mut x = 0.0;
        (0..60)
            .map(|t| {
                if t > 0 {
                    x += if (25..=30).contains(&t) { -DT } else { DT };
                }
                Vector3::new(x, 0.9, 0.0)
            })
            .collect()
    }

    /// Across a transfer (the left foot's weight passes to the right at frame 28) the slide is
    /// bridged on the straight line between the velocities around it. By hand: the 7-frame mean
    /// velocity changes by 2/7 h/s a frame over frames 22–33, a smoothed acceleration of
    /// (2/7)/(2/60) ≈ 8.6 h/s² (1.53 g) at the edges and twice that inside, so the window opens
    /// (above 1.5 g), spans frames 21–34 (above 0.5 g) and, padded by 3, 18–37; the means at 17
    /// and 38 are 1 h/s, so the line is 1 h/s throughout and the hips walk straight on: x = t/60
    /// at every frame.
    #[test]
    fn a_slide_across_a_transfer_is_bridged() {
        let mut hips = walk_with_a_slide();
        let weights: Vec<f64> = (0..60).map(|t| if t < 28 { 1.0 } else { 0.0 }).collect();
        let bridged = bridge(&mut hips, &[false; 60], &weights, DT, G);
        assert_eq!(
            bridged,
            [Bridged {
                first: 18,
                last: 37,
                one_foot: false
            }]
        );
        for (t, p) in hips.iter().enumerate() {
            assert!((p.x - t as f64 * DT).abs() < 1e-12, "{t}: {}", p.x);
            assert_eq!((p.y, p.z), (0.9, 0.0));
        }
    }

    /// On one foot throughout, the same window keeps its displacement (frames 17 and 38 and all
    /// outside stay where they were) and the hips cross it on the cubic Hermite curve with end
    /// slopes 1 h/s. By hand, with Δ = 9/60 h over the 21 frames and m = 21/60 h, its slope is
    /// 6u(1 − u)Δ + m(6u² − 6u + 1) per unit u, least at u = ½: 1.5Δ − m/2 = 0.05 h > 0 — where
    /// the hips ran backwards over 6 frames, they now keep going forwards.
    #[test]
    fn a_slide_on_one_foot_keeps_its_displacement() {
        let original = walk_with_a_slide();
        let mut hips = original.clone();
        let bridged = bridge(&mut hips, &[false; 60], &[1.0; 60], DT, G);
        assert_eq!(
            bridged,
            [Bridged {
                first: 18,
                last: 37,
                one_foot: true
            }]
        );
        for t in (0..18).chain(38..60) {
            assert_eq!(hips[t], original[t], "{t}");
        }
        for t in 18..=38 {
            assert!(hips[t].x > hips[t - 1].x, "{t}");
        }
    }

    /// A change of pace is no slide: standing, then off at 2 h/s (a smoothed acceleration of
    /// 2·(1/7)/(2/60) ≈ 8.6 h/s², 1.53 g, at the start's edges and 17 h/s² inside); the
    /// velocities before and after differ by 2 h/s, more than half the excursion from the line
    /// between them (which is under 1 h/s): nothing changes. Nor does a slide with a frame in the
    /// air (a flight's).
    #[test]
    fn a_start_and_a_flight_are_left_alone() {
        let start: Vec<Vector3<f64>> = (0..60)
            .map(|t| Vector3::new(2.0 * DT * (t as f64 - 30.0).max(0.0), 0.9, 0.0))
            .collect();
        let mut hips = start.clone();
        assert!(bridge(&mut hips, &[false; 60], &[1.0; 60], DT, G).is_empty());
        assert_eq!(hips, start);
        let original = walk_with_a_slide();
        let mut hips = original.clone();
        let airborne: Vec<bool> = (0..60).map(|t| t == 27).collect();
        let weights: Vec<f64> = (0..60).map(|t| if t < 28 { 1.0 } else { 0.0 }).collect();
        assert!(bridge(&mut hips, &airborne, &weights, DT, G).is_empty());
        assert_eq!(hips, original);
    }

    proptest! {
        /// Any hips, flights and weights: only x and z change, nothing before the first window,
        /// every window within the take, at most [`LONGEST_S`] long and on the feet.
        #[test]
        fn bridging_changes_only_what_it_says(
            raw in prop::collection::vec(
                (-3.0f64..3.0, -1.0f64..1.0, any::<bool>(), 0u8..3),
                0..120,
            ),
        ) {
            let mut x = 0.0;
            let mut hips = Vec::new();
            for &(dx, y, _, _) in &raw {
                x += dx * DT;
                hips.push(Vector3::new(x, y, -x));
            }
            let airborne: Vec<bool> = raw.iter().map(|r| r.2).collect();
            let weights: Vec<f64> = raw.iter().map(|r| f64::from(r.3) / 2.0).collect();
            let original = hips.clone();
            let bridged = bridge(&mut hips, &airborne, &weights, DT, G);
            prop_assert_eq!(hips.len(), original.len());
            let first = bridged.first().map_or(hips.len(), |w| w.first);
            prop_assert_eq!(&hips[..first], &original[..first]);
            for (p, o) in hips.iter().zip(&original) {
                prop_assert_eq!(p.y, o.y);
            }
            for w in &bridged {
                prop_assert!(w.first >= 1 && w.last + 2 <= hips.len());
                prop_assert!((w.last + 1 - w.first) as f64 * DT <= LONGEST_S);
                prop_assert!(!airborne[w.first - 1..=w.last + 1].iter().any(|&a| a));
            }
        }
    }
}
