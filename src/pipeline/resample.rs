//! Resampling rotation tracks onto the take's frame grid (conventions.md, "Time and frames"):
//! slerp between the two nearest samples, held at the first/last sample outside the track.

use crate::fps::Fps;
use crate::take::Track;
use nalgebra::{Quaternion, UnitQuaternion};

/// Spherical linear interpolation along the shorter arc; `u` in [0, 1]. Unlike nalgebra's
/// `slerp` it never panics (rotations 180° apart take a well-defined path).
pub fn slerp_shortest(
    a: &UnitQuaternion<f64>,
    b: &UnitQuaternion<f64>,
    u: f64,
) -> UnitQuaternion<f64> {
    let qa = a.into_inner();
    let mut qb = b.into_inner();
    let mut dot = qa.dot(&qb);
    if dot < 0.0 {
        qb = -qb;
        dot = -dot;
    }
    let q: Quaternion<f64> = if dot > 0.9995 {
        // Nearly equal: normalised linear interpolation is exact to ~1e-7 rad and stable.
        qa * (1.0 - u) + qb * u
    } else {
        let theta = dot.min(1.0).acos();
        let s = theta.sin();
        qa * (((1.0 - u) * theta).sin() / s) + qb * ((u * theta).sin() / s)
    };
    UnitQuaternion::from_quaternion(q)
}

/// The track's value at time `t`: slerp between the bracketing samples, held outside.
pub fn sample_at(track: &Track<UnitQuaternion<f64>>, t: f64) -> UnitQuaternion<f64> {
    let times = track.times_s();
    let values = track.values();
    match times.partition_point(|&x| x <= t) {
        0 => values[0],
        i if i == times.len() => values[i - 1],
        i => slerp_shortest(
            &values[i - 1],
            &values[i],
            (t - times[i - 1]) / (times[i] - times[i - 1]),
        ),
    }
}

/// Samples `track` at frames `first .. first + frames` of `fps`.
pub fn resample(
    track: &Track<UnitQuaternion<f64>>,
    fps: Fps,
    first: usize,
    frames: usize,
) -> Vec<UnitQuaternion<f64>> {
    resample_at(
        track,
        (first..first + frames).map(|n| fps.frame_time_of(n as u64)),
    )
}

/// Samples `track` at increasing times (slerp between the bracketing samples, held outside).
pub fn resample_at(
    track: &Track<UnitQuaternion<f64>>,
    times_s: impl IntoIterator<Item = f64>,
) -> Vec<UnitQuaternion<f64>> {
    let times = track.times_s();
    let values = track.values();
    let times_s = times_s.into_iter();
    let mut out = Vec::with_capacity(times_s.size_hint().0);
    // The times increase, so the bracketing sample only moves forward.
    let mut i = 0;
    for t in times_s {
        while i < times.len() && times[i] <= t {
            i += 1;
        }
        let q = if i == 0 {
            values[0]
        } else if i == times.len() {
            values[times.len() - 1]
        } else {
            let (t0, t1) = (times[i - 1], times[i]);
            slerp_shortest(&values[i - 1], &values[i], (t - t0) / (t1 - t0))
        };
        out.push(q);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn about_y(deg: f64) -> UnitQuaternion<f64> {
        UnitQuaternion::from_axis_angle(&Vector3::y_axis(), deg.to_radians())
    }

    #[test]
    fn uniform_track_at_its_own_rate_is_the_identity() {
        let fps: Fps = "50".parse().unwrap();
        let times: Vec<f64> = (0..100).map(|n| fps.frame_time_of(n)).collect();
        let values: Vec<_> = (0..100).map(|n| about_y(n as f64 * 7.3)).collect();
        let track = Track::new(times, values.clone()).unwrap();
        let out = resample(&track, fps, 0, 100);
        for (a, b) in out.iter().zip(&values) {
            assert!(a.angle_to(b) < 1e-12);
        }
    }

    #[test]
    fn slerp_midpoint_holds_and_shortest_arc_by_hand() {
        let track = Track::new(vec![0.1, 0.3], vec![about_y(10.0), about_y(50.0)]).unwrap();
        let out = resample(&track, "10".parse().unwrap(), 0, 5);
        // Frames at 0.0 (held), 0.1, 0.2 (midway: 30°), 0.3, 0.4 (held).
        let deg: Vec<f64> = out.iter().map(|q| q.angle().to_degrees()).collect();
        for (a, b) in deg.iter().zip([10.0, 10.0, 30.0, 50.0, 50.0]) {
            assert!((a - b).abs() < 1e-9, "{deg:?}");
        }
        // 170° and -170° are 20° apart through 180°.
        let m = slerp_shortest(&about_y(170.0), &about_y(-170.0), 0.5);
        assert!(m.angle_to(&about_y(180.0)) < 1e-9);
        // Exactly opposite rotations do not panic.
        let q = slerp_shortest(&about_y(0.0), &about_y(180.0), 0.5);
        assert!((q.angle().to_degrees() - 90.0).abs() < 1e-9);
    }
}
