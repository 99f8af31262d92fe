//! What the sensors would have measured (`simulate --raw`): gyroscope, accelerometer and
//! magnetometer readings in each sensor's frame, from the same simulated body as the orientations.
//!
//! - **Gyroscope** (rad/s): the mean body rate in the sensor frame over the sample period `T`
//!   before the sample, `ω = log(q(t−T)⁻¹ ⊗ q(t)) / T` on the orientation track `q_rig_sensor` —
//!   what a MEMS gyro that samples fast and decimates (or reports delta angles) outputs; an
//!   instantaneous rate would fold the fusion's own step error into the test (2–4° on a walk with
//!   gyro integration alone) — plus a constant bias per sensor ([`GyroBias`]: a random
//!   direction with a magnitude uniform up to a bound, or each axis normal with a standard
//!   deviation) and white noise (σ `gyro_noise_dps` per axis).
//! - **Accelerometer** (m/s²): the specific force `f = a − g` of the sensor's position, in the
//!   sensor frame. The sensor sits at the **midpoint of its source bone** (between the source
//!   joint and its first child, or its end site), moved by the source's forward kinematics
//!   (root translation included; during the blend into the first frame the root speeds up
//!   smoothly from rest to the first frame's velocity, so the capture has no jolt), in the
//!   source's unit when it is given (`--source-units`), else scaled so its rest pose is 1.75 m
//!   tall (BVH files do not state their unit). `a` is the second difference of that position on a
//!   grid of at most 5 ms, low-passed by a Gaussian of σ = 15 ms (as a sensor's anti-aliasing
//!   filter would; it also keeps the motion capture's own position noise from being doubly
//!   differentiated into the readings), interpolated linearly at the sample instants. `g` points
//!   down at 9.80665 m/s². Plus white noise (σ `accel_noise`).
//! - **Magnetometer** (µT): the Earth's field in ENU, `F · (0, cos δ, −sin δ)` with dip `δ`
//!   (north and down, a northern-hemisphere field), in the sensor frame; plus, within a
//!   disturbance window, a field along east ramped in and out over 0.5 s (a magnet brought near);
//!   plus white noise (σ `mag_noise_ut`).
//! - **Sensor errors** (`--sensor-errors`, what `calibrate-sensors` takes away), each sensor its
//!   own draw ([`SensorErrors`]): the gyro reads `M·ω + b` with `M` lower triangular (paper 004's
//!   eq. 6: gains on the diagonal, misalignment below), the accelerometer `diag(k)·f + o`, the
//!   magnetometer `S·m + h` (soft iron `S` symmetric, hard iron `h`); noise is added after.

use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use serde::Serialize;

/// Standard gravity, m/s².
pub const G: f64 = 9.80665;

/// How each sensor's constant gyro bias is drawn, °/s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GyroBias {
    /// A random direction, its magnitude uniform in [0, bound].
    UpTo(f64),
    /// Each axis normal, with this standard deviation (the magnitude then averages ≈ 1.6 σ).
    SdPerAxis(f64),
}

impl GyroBias {
    /// The bias, rad/s, from three standard normal draws and one uniform draw in [0, 1) (both
    /// taken whatever the kind, so that the kind leaves every later draw as it was).
    pub fn draw(self, normals: Vector3<f64>, uniform: f64) -> Vector3<f64> {
        match self {
            GyroBias::UpTo(bound) => {
                normals.try_normalize(1e-12).unwrap_or_else(Vector3::x)
                    * (uniform * bound).to_radians()
            }
            GyroBias::SdPerAxis(sd) => normals * sd.to_radians(),
        }
    }
}

/// The readings' imperfections and the field.
#[derive(Debug, Clone, PartialEq)]
pub struct RawOptions {
    /// Gyro white noise, °/s (σ per axis).
    pub gyro_noise_dps: f64,
    /// Each sensor's constant gyro bias, as it is drawn.
    pub gyro_bias: GyroBias,
    /// Accelerometer white noise, m/s² (σ per axis).
    pub accel_noise: f64,
    /// Magnetometer white noise, µT (σ per axis).
    pub mag_noise_ut: f64,
    /// The Earth's field strength, µT.
    pub field_ut: f64,
    /// Its dip below the horizontal, degrees.
    pub dip_deg: f64,
    /// Write magnetometer columns (without: a 6D capture).
    pub magnetometer: bool,
    /// A magnetic disturbance: a field added in a time window.
    pub disturbance: Option<Disturbance>,
    /// The scale of the source's positions.
    pub source_scale: SourceScale,
    /// The sensors' intrinsic errors' sizes (each sensor draws its own), or none.
    pub errors: Option<ErrorSizes>,
}

/// How large the intrinsic errors drawn for each sensor are (`--sensor-errors`,
/// `key=value,...`; each drawn uniformly within ± its size, the hard iron's length exactly it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorSizes {
    /// The hard iron's length, µT.
    pub hard_iron_ut: f64,
    /// Each soft-iron element's deviation from the identity's.
    pub soft_iron: f64,
    /// Each gyro axis's gain error.
    pub gyro_gain: f64,
    /// The gyro axes' misalignment, radians (below-diagonal elements of `M`).
    pub gyro_misalignment: f64,
    /// Each accelerometer axis's offset, m/s².
    pub acc_offset: f64,
    /// Each accelerometer axis's gain error.
    pub acc_gain: f64,
}

impl Default for ErrorSizes {
    /// A cheap MEMS board's: 20 µT of hard iron, 5 % soft iron, 3 % gyro gain and 1° misalignment,
    /// 0.3 m/s² and 3 % on the accelerometer.
    fn default() -> Self {
        ErrorSizes {
            hard_iron_ut: 20.0,
            soft_iron: 0.05,
            gyro_gain: 0.03,
            gyro_misalignment: 1f64.to_radians(),
            acc_offset: 0.3,
            acc_gain: 0.03,
        }
    }
}

impl std::str::FromStr for ErrorSizes {
    type Err = String;
    /// `default`, or `hard_iron=20,soft_iron=0.05,gyro_gain=0.03,misalignment_deg=1,acc_offset=0.3,
    /// acc_gain=0.03` (any subset; the rest at their defaults, 0 to leave one out).
    fn from_str(s: &str) -> Result<Self, String> {
        let mut e = ErrorSizes::default();
        for part in s
            .split(',')
            .map(str::trim)
            .filter(|p| !p.is_empty() && *p != "default")
        {
            let (k, v) = part
                .split_once('=')
                .ok_or_else(|| format!("`{part}`: expected key=value"))?;
            let v: f64 = v
                .trim()
                .parse()
                .ok()
                .filter(|x: &f64| x.is_finite() && *x >= 0.0)
                .ok_or_else(|| format!("`{part}`: not a number ≥ 0"))?;
            match k.trim() {
                "hard_iron" => e.hard_iron_ut = v,
                "soft_iron" => e.soft_iron = v,
                "gyro_gain" => e.gyro_gain = v,
                "misalignment_deg" => e.gyro_misalignment = v.to_radians(),
                "acc_offset" => e.acc_offset = v,
                "acc_gain" => e.acc_gain = v,
                other => {
                    return Err(format!(
                        "unknown sensor error `{other}`; expected hard_iron, soft_iron, gyro_gain, \
                         misalignment_deg, acc_offset or acc_gain"
                    ));
                }
            }
        }
        Ok(e)
    }
}

/// One sensor's intrinsic errors (the truth `calibrate-sensors` should find). Matrices by rows.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SensorErrors {
    /// `M`: the gyro reads `M·ω + bias`.
    pub gyro_matrix: [[f64; 3]; 3],
    /// `k`, `o`: the accelerometer reads `diag(k)·f + o`.
    pub acc_gain: [f64; 3],
    pub acc_offset_m_s2: [f64; 3],
    /// `S`, `h`: the magnetometer reads `S·m + h`, µT.
    pub soft_iron: [[f64; 3]; 3],
    pub hard_iron_ut: [f64; 3],
}

fn rows(m: &Matrix3<f64>) -> [[f64; 3]; 3] {
    std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)]))
}

impl SensorErrors {
    /// Draws one sensor's errors: `uniform` gives numbers in [0, 1).
    pub fn draw(sizes: &ErrorSizes, mut uniform: impl FnMut() -> f64) -> SensorErrors {
        let mut pm = |size: f64| (2.0 * uniform() - 1.0) * size;
        let mut m = Matrix3::identity();
        for r in 0..3 {
            m[(r, r)] += pm(sizes.gyro_gain);
            for c in 0..r {
                m[(r, c)] = pm(sizes.gyro_misalignment);
            }
        }
        let acc_gain = [0; 3].map(|_| 1.0 + pm(sizes.acc_gain));
        let acc_offset = [0; 3].map(|_| pm(sizes.acc_offset));
        let mut soft = Matrix3::identity();
        for r in 0..3 {
            for c in r..3 {
                let d = pm(sizes.soft_iron);
                soft[(r, c)] += d;
                if c != r {
                    soft[(c, r)] += d;
                }
            }
        }
        let dir = Vector3::new(pm(1.0), pm(1.0), pm(1.0))
            .try_normalize(1e-9)
            .unwrap_or_else(Vector3::x);
        SensorErrors {
            gyro_matrix: rows(&m),
            acc_gain,
            acc_offset_m_s2: acc_offset,
            soft_iron: rows(&soft),
            hard_iron_ut: (dir * sizes.hard_iron_ut).into(),
        }
    }

    fn matrix(m: &[[f64; 3]; 3]) -> Matrix3<f64> {
        Matrix3::from_fn(|r, c| m[r][c])
    }

    /// What the gyro reads for the rate `w` (before bias and noise).
    pub fn gyro(&self, w: &Vector3<f64>) -> Vector3<f64> {
        Self::matrix(&self.gyro_matrix) * w
    }

    pub fn accelerometer(&self, f: &Vector3<f64>) -> Vector3<f64> {
        f.component_mul(&Vector3::from(self.acc_gain)) + Vector3::from(self.acc_offset_m_s2)
    }

    pub fn magnetometer(&self, m: &Vector3<f64>) -> Vector3<f64> {
        Self::matrix(&self.soft_iron) * m + Vector3::from(self.hard_iron_ut)
    }
}

/// How long a unit of the source BVH is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SourceScale {
    /// Metres per unit, known (`--source-units in` → 0.0254).
    MetresPerUnit(f64),
    /// Unknown: the rest pose is this tall, metres.
    RestHeight(f64),
}

impl std::str::FromStr for SourceScale {
    type Err = String;
    /// `m`, `cm`, `mm`, `in`, or a number of metres per unit.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let m = match s.trim() {
            "m" => 1.0,
            "cm" => 0.01,
            "mm" => 0.001,
            "in" => 0.0254,
            other => other
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite() && *x > 0.0)
                .ok_or_else(|| format!("`{s}`: expected m, cm, mm, in or metres per unit"))?,
        };
        Ok(SourceScale::MetresPerUnit(m))
    }
}

impl Default for RawOptions {
    fn default() -> Self {
        RawOptions {
            gyro_noise_dps: 0.3,
            gyro_bias: GyroBias::UpTo(0.5),
            accel_noise: 0.05,
            mag_noise_ut: 0.3,
            field_ut: 50.0,
            dip_deg: 65.0,
            magnetometer: true,
            disturbance: None,
            source_scale: SourceScale::RestHeight(1.75),
            errors: None,
        }
    }
}

/// A field of `field_ut` along east added from `start_s` to `end_s` (ramped over 0.5 s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Disturbance {
    pub start_s: f64,
    pub end_s: f64,
    pub field_ut: f64,
}

impl std::str::FromStr for Disturbance {
    type Err = String;
    /// `START:END[:MICROTESLA]` (seconds; 30 µT by default).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let parts: Vec<&str> = s.split(':').collect();
        let num = |p: &str| -> Result<f64, String> {
            p.trim()
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite() && *x >= 0.0)
                .ok_or_else(|| format!("`{s}`: `{p}` is not a number ≥ 0"))
        };
        match parts.as_slice() {
            [a, b] | [a, b, _] => {
                let d = Disturbance {
                    start_s: num(a)?,
                    end_s: num(b)?,
                    field_ut: parts.get(2).map_or(Ok(30.0), |f| num(f))?,
                };
                if d.end_s <= d.start_s {
                    return Err(format!("`{s}`: the end is not after the start"));
                }
                Ok(d)
            }
            _ => Err(format!(
                "`{s}`: expected START:END[:MICROTESLA], e.g. 10:15:30"
            )),
        }
    }
}

impl Disturbance {
    /// The disturbing field's strength at `t` (0 outside the window, ramped at its edges).
    pub fn strength_at(&self, t: f64) -> f64 {
        const RAMP_S: f64 = 0.5;
        if t <= self.start_s || t >= self.end_s {
            return 0.0;
        }
        let edge = ((t - self.start_s).min(self.end_s - t) / RAMP_S).min(1.0);
        self.field_ut * edge * edge * (3.0 - 2.0 * edge)
    }
}

/// The Earth's field in ENU, µT.
pub fn earth_field_enu(options: &RawOptions) -> Vector3<f64> {
    let dip = options.dip_deg.to_radians();
    options.field_ut * Vector3::new(0.0, dip.cos(), -dip.sin())
}

/// The mean body rate in the sensor frame over the `period_s` before `t`, rad/s, from an
/// orientation track `q(t)` (at the start of the track, over the period after it).
pub fn mean_body_rate(
    q: impl Fn(f64) -> UnitQuaternion<f64>,
    t: f64,
    period_s: f64,
) -> Vector3<f64> {
    let start = (t - period_s).max(0.0);
    let end = start + period_s;
    (q(start).inverse() * q(end)).scaled_axis() / period_s
}

/// Accelerations (rig units per s²) of a position track sampled every `step_s`, low-passed by a
/// Gaussian of σ = [`ACCEL_SMOOTHING_S`]: second differences (the ends copied from their
/// neighbours), then the kernel (truncated at 3σ, renormalised at the ends).
pub fn accelerations(positions: &[Vector3<f64>], step_s: f64) -> Vec<Vector3<f64>> {
    let n = positions.len();
    if n < 3 {
        return vec![Vector3::zeros(); n];
    }
    let mut raw = vec![Vector3::zeros(); n];
    for i in 1..n - 1 {
        raw[i] = (positions[i + 1] - 2.0 * positions[i] + positions[i - 1]) / (step_s * step_s);
    }
    raw[0] = raw[1];
    raw[n - 1] = raw[n - 2];
    let sigma = ACCEL_SMOOTHING_S / step_s;
    let half = (3.0 * sigma).ceil() as isize;
    let kernel: Vec<f64> = (-half..=half)
        .map(|k| (-0.5 * (k as f64 / sigma).powi(2)).exp())
        .collect();
    (0..n as isize)
        .map(|i| {
            let (mut sum, mut weight) = (Vector3::zeros(), 0.0);
            for (k, w) in (-half..=half).zip(&kernel) {
                let j = i + k;
                if j >= 0 && (j as usize) < n {
                    sum += raw[j as usize] * *w;
                    weight += w;
                }
            }
            sum / weight
        })
        .collect()
}

/// The σ of the Gaussian low-pass on accelerations, seconds.
pub const ACCEL_SMOOTHING_S: f64 = 0.015;

/// Linear interpolation of a track sampled every `step_s` from 0 (held at its ends).
pub fn on_grid_at(values: &[Vector3<f64>], step_s: f64, t: f64) -> Vector3<f64> {
    let x = (t / step_s).max(0.0);
    let k = x.floor() as usize;
    if k + 1 >= values.len() {
        return values[values.len() - 1];
    }
    let u = x - k as f64;
    values[k] * (1.0 - u) + values[k + 1] * u
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gyro_biases_are_drawn_as_asked() {
        // 4000 draws from the simulation's own generator: with a standard deviation per axis,
        // each axis's sample mean is within 4 standard errors of 0 (σ/√n = 0.032 °/s) and its
        // sample SD within 5 % of σ (its standard error is σ/√(2n), 1.1 %); with a bound, no
        // magnitude passes it and they average half of it (uniform; SE 0.3/√n·bound).
        let mut rng = super::super::Rng(7);
        let n = 4000;
        let mut draw = |kind: GyroBias| -> Vec<Vector3<f64>> {
            (0..n)
                .map(|_| {
                    let normals = Vector3::new(rng.normal(), rng.normal(), rng.normal());
                    kind.draw(normals, rng.uniform()).map(f64::to_degrees)
                })
                .collect()
        };
        let sd = draw(GyroBias::SdPerAxis(2.0));
        for axis in 0..3 {
            let mean = sd.iter().map(|b| b[axis]).sum::<f64>() / n as f64;
            let var = sd.iter().map(|b| (b[axis] - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
            assert!(
                mean.abs() < 4.0 * 2.0 / (n as f64).sqrt(),
                "axis {axis}: mean {mean}"
            );
            assert!(
                (var.sqrt() - 2.0).abs() < 0.1,
                "axis {axis}: SD {}",
                var.sqrt()
            );
        }
        let up_to = draw(GyroBias::UpTo(2.0));
        assert!(up_to.iter().all(|b| b.norm() <= 2.0));
        let mean = up_to.iter().map(|b| b.norm()).sum::<f64>() / n as f64;
        assert!((mean - 1.0).abs() < 0.05, "mean magnitude {mean}");
    }

    #[test]
    fn a_point_on_a_circle_accelerates_towards_the_centre() {
        // r = 0.5 m at 2 rad/s: |a| = ω² r = 2 m/s², towards the centre.
        let step = 0.002;
        let (r, w) = (0.5, 2.0);
        let p: Vec<Vector3<f64>> = (0..2000)
            .map(|i| {
                let t = i as f64 * step;
                Vector3::new(r * (w * t).cos(), 0.0, r * (w * t).sin())
            })
            .collect();
        let a = accelerations(&p, step);
        let i = 1000;
        let expected = -p[i] * w * w;
        // The Gaussian low-pass scales a sinusoid by exp(−(ωσ)²/2): 0.99955 at 2 rad/s.
        let gain = (-0.5 * (w * ACCEL_SMOOTHING_S).powi(2)).exp();
        assert!(
            (a[i] - expected * gain).norm() < 1e-4,
            "{:?} vs {:?}",
            a[i],
            expected
        );
    }

    #[test]
    fn body_rate_of_a_constant_spin_and_of_a_speeding_one() {
        let omega = Vector3::new(0.3, -1.2, 2.0);
        let q0 = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 0.4);
        // Turning about its own axes: q(t) = q0 ⊗ exp(ω t).
        let q = |t: f64| q0 * UnitQuaternion::from_scaled_axis(omega * t);
        assert!((mean_body_rate(q, 1.0, 0.01) - omega).norm() < 1e-9);
        // About z at a rate 2t: the mean over [0.99, 1] is 2 · 0.995 rad/s.
        let q = |t: f64| UnitQuaternion::from_axis_angle(&Vector3::z_axis(), t * t);
        assert!((mean_body_rate(q, 1.0, 0.01) - Vector3::z() * 1.99).norm() < 1e-9);
    }

    #[test]
    fn the_field_dips_and_the_disturbance_ramps() {
        let o = RawOptions::default();
        let f = earth_field_enu(&o);
        assert!((f.norm() - 50.0).abs() < 1e-12);
        assert!((f.z.atan2(f.y).to_degrees() + 65.0).abs() < 1e-9);
        let d: Disturbance = "10:15:40".parse().unwrap();
        assert_eq!(d.strength_at(9.9), 0.0);
        assert!((d.strength_at(12.0) - 40.0).abs() < 1e-12);
        assert!(d.strength_at(10.25) > 0.0 && d.strength_at(10.25) < 40.0);
        assert!("15:10".parse::<Disturbance>().is_err());
    }
}
