//! Profiling aid: fuses one synthetic 60-minute, 100 Hz sensor with the filter given (default
//! offline), for `perf record`.
use imubake::take::{ImuSample, Track};
use nalgebra::{UnitQuaternion, Vector3};

fn main() {
    let spec = std::env::args().nth(1).unwrap_or_else(|| "offline".into());
    let n = 360_000;
    let dt = 0.01;
    let mut q = UnitQuaternion::identity();
    let (mut samples, mut mags, mut times) = (Vec::new(), Vec::new(), Vec::new());
    for i in 0..n {
        let t = i as f64 * dt;
        let w = Vector3::new((0.7 * t).sin(), (0.3 * t).cos(), 0.5 * (0.11 * t).sin()) * 2.0;
        q *= UnitQuaternion::from_scaled_axis(w * dt);
        samples.push(ImuSample {
            gyro_rad_s: w,
            accel_m_s2: q.inverse() * Vector3::new(0.0, 0.0, 9.81),
        });
        mags.push(q.inverse() * Vector3::new(0.0, 20.0, -40.0));
        times.push(t);
    }
    let inertial = Track::new(times.clone(), samples).unwrap();
    let mag = Track::new(times, mags).unwrap();
    let fusion: imubake::fusion::Fusion = spec.parse().unwrap();
    let start = std::time::Instant::now();
    for _ in 0..3 {
        std::hint::black_box(imubake::fusion::fuse("s", &inertial, Some(&mag), &fusion).unwrap());
    }
    println!(
        "{spec}: {:.1} ns/sample",
        start.elapsed().as_secs_f64() * 1e9 / (3 * n) as f64
    );
}
