//! `simulate`: the inverse of `convert`, for tests and samples. From BVH motion and a mapping,
//! the capture the mapping's sensors would have recorded.
//!
//! The simulated body: bone `b` driven by source joint `J` has the world orientation
//! `B_b(t) = W_J(t) ⊗ R_J⁻¹ ⊗ P_b` (rig world), where `W_J(t)` is the source joint's world
//! rotation, `R_J` its world rotation in the source's reference pose — its rest (every channel
//! zero), or frame N when the calibration pose is `frame:N` — and `P_b` the bone's orientation in
//! the mapping's calibration pose. So the subject holds the calibration pose while the source is
//! in its reference, and every bone's rotation since the calibration pose is the source joint's
//! rotation since the reference: a BVH played on its own skeleton, calibrated in its frame N, has
//! its own rotations (`P_b = R_J`), whatever its frame N looks like.
//!
//! Timeline: the calibration pose held for `hold_s`, a blend over `blend_s` from the reference
//! into the first source frame, then the source frames. When the mapping names a second calibration pose
//! (`calibration.second`), each bone also turns in the world by `S_b(t)`, from the first pose into
//! the second over the second before its window, held through it, and back over the second after
//! (`B_b = S_b ⊗ W_J ⊗ P_b`); the hold lasts until half a second after that. The sensors' positions
//! (for raw readings) do not follow those turns: the subject is taken to move between the poses
//! slowly enough for gravity alone to be felt. A sensor reads
//! `q_world_sensor = C⁻¹ ⊗ H ⊗ B_b(t) ⊗ q_bone_sensor ⊗ noise`, with `C` the world → rig rotation,
//! `H` a heading about +Y, `q_bone_sensor` the mount (random where the mapping says `calibrate`,
//! but consistent with a declared `forward` axis), sampled at its own instants (offset and
//! jitter; timestamps are the true instants at the output's precision), with optional dropouts.

pub mod raw;

use crate::bvh::Bvh;
use crate::mapping::{Mapping, Mount};
use crate::rig::{LengthUnit, Rig};
use crate::rotation::EulerOrder;
use crate::rotation::euler::from_quaternion;
use crate::rotation::slerp_shortest;
use crate::world::World;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use serde::Serialize;
use std::fmt::Write as _;

/// The capture format to write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CaptureFormat {
    /// imubake CSV with quaternions.
    Csv,
    /// Paper 002's SOU log (NED yaw/pitch/roll, ms timestamps) with debug text at the top.
    Sou,
}

#[derive(Debug, Clone, PartialEq)]
pub struct SimulateOptions {
    /// Source frames `first ..= last` (default: all).
    pub first_frame: usize,
    pub last_frame: Option<usize>,
    pub rate_hz: f64,
    /// Standard deviation of each sample's timing jitter, seconds (clipped to ±40 % of a period).
    pub jitter_s: f64,
    /// Orientation noise: the RMS angle, degrees, of a random rotation applied to every sample
    /// (sensor frame; each rotation-vector component is normal with σ = noise / √3).
    pub noise_deg: f64,
    /// Probability that a sample is lost.
    pub dropout: f64,
    /// Heading about +Y in degrees; `None` draws one at random.
    pub heading_deg: Option<f64>,
    pub seed: u64,
    pub hold_s: f64,
    pub blend_s: f64,
    pub format: CaptureFormat,
    /// Target bone → source joint names where they differ (others match by name, `mixamorig:`
    /// ignored).
    pub bone_map: Vec<(String, String)>,
    /// Write raw readings (gyroscope, accelerometer, magnetometer) instead of orientations
    /// ([`raw`]); imubake CSV only.
    pub raw: Option<raw::RawOptions>,
}

impl Default for SimulateOptions {
    fn default() -> Self {
        SimulateOptions {
            first_frame: 0,
            last_frame: None,
            rate_hz: 100.0,
            jitter_s: 0.0005,
            noise_deg: 0.0,
            dropout: 0.0,
            heading_deg: None,
            seed: 1,
            hold_s: 2.0,
            blend_s: 1.0,
            format: CaptureFormat::Csv,
            bone_map: Vec::new(),
            raw: None,
        }
    }
}

/// What was simulated, for checking a conversion against it.
#[derive(Debug, Clone, Serialize)]
pub struct Truth {
    pub world: World,
    pub heading_deg: f64,
    /// Take time at which source frame `first_frame` plays.
    pub motion_start_s: f64,
    pub first_frame: usize,
    pub last_frame: usize,
    pub source_frame_time_s: f64,
    pub sensors: Vec<SensorTruth>,
    /// For raw readings: the field, and where the sensors sit.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub raw: Option<RawTruth>,
}

#[derive(Debug, Clone, Serialize)]
pub struct RawTruth {
    pub field_enu_ut: [f64; 3],
    /// Metres per unit of the source BVH (from its rest height).
    pub metres_per_source_unit: f64,
    /// Where each sensor sits on its bone.
    pub sensor_position: &'static str,
}

#[derive(Debug, Clone, Serialize)]
pub struct SensorTruth {
    pub sensor: String,
    pub bone: String,
    pub source_joint: String,
    /// q_bone_sensor [w, x, y, z].
    pub mount: [f64; 4],
    pub samples: usize,
    /// For raw readings: the gyro's constant bias, °/s (sensor frame).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gyro_bias_dps: Option<[f64; 3]>,
    /// For raw readings with `--sensor-errors`: the intrinsic errors drawn for it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub errors: Option<raw::SensorErrors>,
}

#[derive(Debug, Clone)]
pub struct Simulated {
    /// The capture file's text.
    pub text: String,
    pub truth: Truth,
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimulateError {
    #[error(
        "bone `{bone}` (sensor `{sensor}`) has no source joint in the BVH; add it to --bone-map (BONE=JOINT)"
    )]
    NoSourceJoint { sensor: String, bone: String },
    #[error("unknown bone `{0}` in the mapping's rig")]
    UnknownBone(String),
    #[error("the BVH has no frames in {first}..={last} (it has {frames})")]
    Frames {
        first: usize,
        last: usize,
        frames: usize,
    },
    #[error("the mapping's calibration pose `{0}` is not defined by the rig")]
    Pose(String),
    #[error("--as sou needs sensors named <SOU>_0 and <SOU>_1 in pairs; `{0}` has no partner")]
    SouPairs(String),
    #[error("{0}")]
    Invalid(String),
}

/// A small deterministic generator (SplitMix64), so the same seed gives the same capture on
/// every machine.
struct Rng(u64);

impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn normal(&mut self) -> f64 {
        let u1 = self.uniform().max(1e-300);
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
    /// A uniformly random rotation (Shoemake).
    fn rotation(&mut self) -> UnitQuaternion<f64> {
        let (u1, u2, u3) = (self.uniform(), self.uniform(), self.uniform());
        let tau = 2.0 * std::f64::consts::PI;
        let (a, b) = ((1.0 - u1).sqrt(), u1.sqrt());
        UnitQuaternion::from_quaternion(Quaternion::new(
            a * (tau * u2).sin(),
            a * (tau * u2).cos(),
            b * (tau * u3).sin(),
            b * (tau * u3).cos(),
        ))
    }
}

/// The source motion, interpolated in time.
struct Source {
    /// Local rotations of every frame in range, `[frame][joint]` (frames before `first` empty).
    locals: Vec<Vec<UnitQuaternion<f64>>>,
    /// The local rotations of the reference pose (module docs), and the world rotations.
    reference: Vec<UnitQuaternion<f64>>,
    reference_world: Vec<UnitQuaternion<f64>>,
    /// Each joint's translation from its parent (the root's: its position) per frame in range,
    /// source units (empty unless raw readings are simulated).
    translations: Vec<Vec<Vector3<f64>>>,
    rig: Rig,
    first: usize,
    last: usize,
}

impl Source {
    /// The world rotation of `joint` given each joint's local rotation: the product down its
    /// chain from the root (only the chain is evaluated).
    fn chain(
        &self,
        joint: usize,
        local: impl Fn(usize) -> UnitQuaternion<f64>,
    ) -> UnitQuaternion<f64> {
        let mut q = local(joint);
        let mut j = joint;
        while let Some(p) = self.rig.joints()[j].parent {
            q = local(p) * q;
            j = p;
        }
        q
    }

    /// World rotation of `joint` at `frame` (fractional: slerp of local rotations).
    fn world_at(&self, joint: usize, frame: f64) -> UnitQuaternion<f64> {
        let f = frame.clamp(self.first as f64, self.last as f64);
        let k = (f.floor() as usize).min(self.last);
        let u = f - k as f64;
        let a = &self.locals[k];
        if u > 0.0 && k < self.last {
            let b = &self.locals[k + 1];
            self.chain(joint, |j| slerp_shortest(&a[j], &b[j], u))
        } else {
            self.chain(joint, |j| a[j])
        }
    }
}

/// A simulated sensor: its bone, the source joint that moves it, its bone's orientation in the
/// calibration pose and its mount.
struct Sim {
    sensor: String,
    bone: String,
    joint: usize,
    pose: UnitQuaternion<f64>,
    mount: UnitQuaternion<f64>,
    /// The bone's world-frame turn from the calibration pose into the second pose (identity
    /// without one).
    second: UnitQuaternion<f64>,
}

/// The second calibration pose on the timeline: the turn into it over [`POSE_TURN_S`] seconds
/// before `start_s`, held to `end_s`, and back over as long after.
#[derive(Clone, Copy)]
struct SecondPoseTimes {
    start_s: f64,
    end_s: f64,
}

/// How long the subject takes to move between calibration poses, seconds.
const POSE_TURN_S: f64 = 1.0;

impl SecondPoseTimes {
    /// How far into the second pose the subject is at `t`, 0 to 1 (smoothstep).
    fn weight(&self, t: f64) -> f64 {
        let x = if t < self.start_s {
            1.0 - (self.start_s - t) / POSE_TURN_S
        } else if t <= self.end_s {
            1.0
        } else {
            1.0 - (t - self.end_s) / POSE_TURN_S
        };
        let x = x.clamp(0.0, 1.0);
        x * x * (3.0 - 2.0 * x)
    }
}

/// What raw readings are made from ([`raw`] states the model).
struct RawInputs<'a> {
    bvh: &'a Bvh,
    source: &'a Source,
    sims: &'a [Sim],
    times: &'a [Vec<f64>],
    heading: UnitQuaternion<f64>,
    /// `q_enu_rig`.
    from_rig: UnitQuaternion<f64>,
    hold_s: f64,
    motion_start: f64,
    frame_time: f64,
    end_s: f64,
    /// The sensors' sample period, seconds.
    period_s: f64,
}

impl RawInputs<'_> {
    /// Every joint's local rotation and translation at take time `t` (source units), on the
    /// timeline [`simulate`] plays: the reference pose during the hold, blended into the first frame, then the
    /// frames (rotations slerped, translations interpolated linearly).
    fn locals_at(&self, t: f64, blend_s: f64) -> (Vec<UnitQuaternion<f64>>, Vec<Vector3<f64>>) {
        let src = self.source;
        let first = src.first;
        let n = src.rig.len();
        if t < self.motion_start {
            let x = ((t - self.hold_s) / blend_s).clamp(0.0, 1.0);
            let u = x * x * (3.0 - 2.0 * x);
            let locals = src.locals[first]
                .iter()
                .zip(&src.reference)
                .map(|(q, r)| slerp_shortest(r, q, u))
                .collect();
            // The root starts moving as the rotations blend in: its speed ramps up from rest to
            // the first frame's (smoothstep), so position and velocity are continuous — no jolt
            // where the motion starts. Behind the first frame's position by
            // v₀ · blend · ∫ₓ¹ smoothstep = v₀ · blend · (½ − x³ + x⁴/2).
            let mut translations = src.translations[first].clone();
            let v0 = if first < src.last {
                (src.translations[first + 1][0] - src.translations[first][0]) / self.frame_time
            } else {
                Vector3::zeros()
            };
            translations[0] -= v0 * blend_s * (0.5 - x.powi(3) + x.powi(4) / 2.0);
            return (locals, translations);
        }
        let f = (first as f64 + (t - self.motion_start) / self.frame_time)
            .clamp(first as f64, src.last as f64);
        let k = (f.floor() as usize).min(src.last);
        let u = f - k as f64;
        if u > 0.0 && k < src.last {
            let (a, b) = (&src.locals[k], &src.locals[k + 1]);
            let (ta, tb) = (&src.translations[k], &src.translations[k + 1]);
            (
                (0..n).map(|j| slerp_shortest(&a[j], &b[j], u)).collect(),
                (0..n).map(|j| ta[j] * (1.0 - u) + tb[j] * u).collect(),
            )
        } else {
            (src.locals[k].clone(), src.translations[k].clone())
        }
    }

    /// The midpoint of each joint's bone (to its first child, or its end site) for locals and
    /// translations, source units.
    fn bone_midpoints(
        &self,
        locals: &[UnitQuaternion<f64>],
        translations: &[Vector3<f64>],
    ) -> Vec<Vector3<f64>> {
        let joints = self.bvh.joints();
        let (pos, world) = self.bvh.forward_kinematics(locals, translations);
        (0..joints.len())
            .map(|i| {
                let end = match joints.iter().position(|c| c.parent == Some(i)) {
                    Some(c) => pos[c],
                    None => pos[i] + world[i] * joints[i].end_site.unwrap_or_else(Vector3::zeros),
                };
                (pos[i] + end) / 2.0
            })
            .collect()
    }

    /// The source's rest-pose height (joints and end sites), source units.
    fn rest_height(&self) -> f64 {
        let joints = self.bvh.joints();
        let identity = vec![UnitQuaternion::identity(); joints.len()];
        let offsets: Vec<Vector3<f64>> = joints
            .iter()
            .enumerate()
            .map(|(i, j)| if i == 0 { Vector3::zeros() } else { j.offset })
            .collect();
        let (pos, _) = self.bvh.forward_kinematics(&identity, &offsets);
        let ys = joints
            .iter()
            .enumerate()
            .flat_map(|(i, j)| std::iter::once(pos[i].y).chain(j.end_site.map(|e| pos[i].y + e.y)));
        let (lo, hi) = ys.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), y| {
            (lo.min(y), hi.max(y))
        });
        hi - lo
    }

    /// The readings as CSV rows (after the header line), each sensor's gyro bias (°/s) and what
    /// the truth says of the field and the sensors' positions.
    fn capture(
        &self,
        options: &raw::RawOptions,
        rng: &mut Rng,
        world_at: impl Fn(&Sim, f64) -> UnitQuaternion<f64>,
    ) -> (
        String,
        Vec<[f64; 3]>,
        Vec<Option<raw::SensorErrors>>,
        RawTruth,
    ) {
        let blend_s = self.motion_start - self.hold_s;
        let scale = match options.source_scale {
            raw::SourceScale::MetresPerUnit(m) => m,
            raw::SourceScale::RestHeight(h) => {
                let height = self.rest_height();
                if height > 0.0 { h / height } else { 1.0 }
            }
        };
        // Sensor positions (rig world, metres) on a grid, and their accelerations.
        let step = self.frame_time.min(0.005);
        let steps = (self.end_s / step).ceil() as usize + 1;
        let mut positions: Vec<Vec<Vector3<f64>>> =
            vec![Vec::with_capacity(steps); self.sims.len()];
        for g in 0..steps {
            let (locals, translations) = self.locals_at(g as f64 * step, blend_s);
            let mid = self.bone_midpoints(&locals, &translations);
            for (k, s) in self.sims.iter().enumerate() {
                positions[k].push(self.heading * (mid[s.joint] * scale));
            }
        }
        let accelerations: Vec<Vec<Vector3<f64>>> = positions
            .iter()
            .map(|p| raw::accelerations(p, step))
            .collect();
        let field = raw::earth_field_enu(options);
        let east = Vector3::x();
        let up_rig = Vector3::y() * raw::G;
        let gyro_sigma = options.gyro_noise_dps.to_radians();
        let mut rows: Vec<(f64, usize, [f64; 9])> = Vec::new();
        let mut biases = Vec::with_capacity(self.sims.len());
        // The intrinsic errors come from a generator of their own, so that asking for them
        // leaves every other draw (and so the rest of the capture) as it was.
        let mut error_rng = Rng(rng.0 ^ 0x5EED_E770_5EED_E770);
        let errors: Vec<Option<raw::SensorErrors>> = self
            .sims
            .iter()
            .map(|_| {
                options
                    .errors
                    .map(|sizes| raw::SensorErrors::draw(&sizes, || error_rng.uniform()))
            })
            .collect();
        for (i, s) in self.sims.iter().enumerate() {
            let normals = Vector3::new(rng.normal(), rng.normal(), rng.normal());
            let bias = options.gyro_bias.draw(normals, rng.uniform());
            biases.push([bias.x, bias.y, bias.z].map(f64::to_degrees));
            let q_rig = |t: f64| self.heading * world_at(s, t) * s.pose * s.mount;
            for &t in &self.times[i] {
                let q = q_rig(t);
                let noise = |rng: &mut Rng, sigma: f64| {
                    Vector3::new(rng.normal(), rng.normal(), rng.normal()) * sigma
                };
                let rate = raw::mean_body_rate(q_rig, t, self.period_s);
                let specific_force =
                    q.inverse() * (raw::on_grid_at(&accelerations[i], step, t) + up_rig);
                let disturbance = options.disturbance.map_or(0.0, |d| d.strength_at(t));
                let q_enu = self.from_rig * q;
                let field_sensor = q_enu.inverse() * (field + east * disturbance);
                let (rate, specific_force, field_sensor) = match &errors[i] {
                    Some(e) => (
                        e.gyro(&rate),
                        e.accelerometer(&specific_force),
                        e.magnetometer(&field_sensor),
                    ),
                    None => (rate, specific_force, field_sensor),
                };
                let gyr = rate + bias + noise(rng, gyro_sigma);
                let acc = specific_force + noise(rng, options.accel_noise);
                let mag = field_sensor + noise(rng, options.mag_noise_ut);
                rows.push((
                    t,
                    i,
                    [
                        gyr.x, gyr.y, gyr.z, acc.x, acc.y, acc.z, mag.x, mag.y, mag.z,
                    ],
                ));
            }
        }
        rows.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let mut out = String::with_capacity(rows.len() * 120);
        out.push_str("# gyro rad/s, specific force m/s² and field µT in each sensor's frame\n");
        if options.magnetometer {
            out.push_str("time_s,sensor,gx,gy,gz,ax,ay,az,mx,my,mz\n");
        } else {
            out.push_str("time_s,sensor,gx,gy,gz,ax,ay,az\n");
        }
        let columns = if options.magnetometer { 9 } else { 6 };
        for (t, i, v) in &rows {
            let _ = write!(out, "{t:.6},{}", self.sims[*i].sensor);
            for x in &v[..columns] {
                let _ = write!(out, ",{x:.7}");
            }
            out.push('\n');
        }
        let truth = RawTruth {
            field_enu_ut: [field.x, field.y, field.z],
            metres_per_source_unit: scale,
            sensor_position: "the midpoint of the source bone (joint to first child or end site)",
        };
        (out, biases, errors, truth)
    }
}

/// Simulates the capture. `rig` is the mapping's target rig (for the calibration pose).
pub fn simulate(
    bvh: &Bvh,
    rig: &Rig,
    mapping: &Mapping,
    options: &SimulateOptions,
) -> Result<Simulated, SimulateError> {
    if !(options.rate_hz.is_finite() && options.rate_hz > 0.0 && options.rate_hz <= 10_000.0) {
        return Err(SimulateError::Invalid(format!(
            "rate {} Hz is not in (0, 10000]",
            options.rate_hz
        )));
    }
    if !(0.0..1.0).contains(&options.dropout) {
        return Err(SimulateError::Invalid(format!(
            "dropout {} is not in [0, 1)",
            options.dropout
        )));
    }
    let frames = bvh.frame_count();
    let last = options
        .last_frame
        .unwrap_or(frames.saturating_sub(1))
        .min(frames.saturating_sub(1));
    if frames == 0 || options.first_frame > last {
        return Err(SimulateError::Frames {
            first: options.first_frame,
            last,
            frames,
        });
    }
    let mut source = Source {
        reference: Vec::new(),
        reference_world: Vec::new(),
        locals: (0..=last)
            .map(|f| {
                if f < options.first_frame {
                    Vec::new()
                } else {
                    bvh.local_rotations(f)
                }
            })
            .collect(),
        translations: if options.raw.is_some() {
            (0..=last)
                .map(|f| {
                    if f < options.first_frame {
                        Vec::new()
                    } else {
                        bvh.joint_translations(f)
                    }
                })
                .collect()
        } else {
            Vec::new()
        },
        rig: bvh
            .to_rig("source", LengthUnit::Centimetres)
            .map_err(|e| SimulateError::Invalid(format!("the BVH is not a valid rig: {e}")))?,
        first: options.first_frame,
        last,
    };
    // The source's reference: frame N for a calibration pose `frame:N`, else its rest.
    let reference = match mapping.calibration.as_ref().map(|c| &c.pose) {
        Some(crate::mapping::PoseRef::BvhFrame(n)) if *n < frames => bvh.local_rotations(*n),
        _ => vec![UnitQuaternion::identity(); source.rig.len()],
    };
    source.reference_world = (0..reference.len())
        .map(|j| source.chain(j, |k| reference[k]))
        .collect();
    source.reference = reference;
    let mut rng = Rng(options.seed);
    let world = match (options.format, &options.raw) {
        (CaptureFormat::Sou, Some(_)) => {
            return Err(SimulateError::Invalid(
                "raw readings are written as imubake CSV only (not --as sou)".into(),
            ));
        }
        (CaptureFormat::Sou, None) => World::Ned,
        // Raw readings: the field is given in ENU.
        (CaptureFormat::Csv, Some(_)) => World::Enu,
        (CaptureFormat::Csv, None) => mapping.world.unwrap_or(World::Enu),
    };
    let heading_deg = options
        .heading_deg
        .unwrap_or_else(|| rng.uniform() * 360.0 - 180.0);
    let heading = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), heading_deg.to_radians());
    let from_rig = world.to_rig().inverse();
    let pose_name = mapping
        .calibration
        .as_ref()
        .map_or("rest".to_string(), |c| c.pose.label());
    let pose = rig.pose(&pose_name).ok_or(SimulateError::Pose(pose_name))?;
    let pose_world = rig.world_rotations(&pose.local);

    // Sensors: bone, source joint, mount.
    let mut sims = Vec::new();
    for s in &mapping.sensors {
        let bone = rig
            .joint_index(&s.bone)
            .ok_or_else(|| SimulateError::UnknownBone(s.bone.clone()))?;
        let bone_name = rig.joints()[bone].name.clone();
        let source_name = options
            .bone_map
            .iter()
            .find(|(target, _)| rig.joint_index(target) == Some(bone))
            .map(|(_, src)| src.clone())
            .unwrap_or_else(|| bone_name.clone());
        let joint =
            source
                .rig
                .joint_index(&source_name)
                .ok_or_else(|| SimulateError::NoSourceJoint {
                    sensor: s.sensor.clone(),
                    bone: bone_name.clone(),
                })?;
        let p = pose_world[bone];
        let mount = match (&s.mount, s.forward) {
            (Mount::Fixed(q), _) => *q,
            (Mount::Calibrate, Some(axis)) => {
                // The declared axis must point where the body faces (+Z) in the pose:
                // P ⊗ mount ⊗ axis = +Z. Any rotation about +Z keeps that true.
                let to_z =
                    UnitQuaternion::rotation_between(&axis, &Vector3::z()).unwrap_or_else(|| {
                        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
                    });
                let spin = UnitQuaternion::from_axis_angle(
                    &Vector3::z_axis(),
                    rng.uniform() * std::f64::consts::TAU,
                );
                p.inverse() * spin * to_z
            }
            (Mount::Calibrate, None) => rng.rotation(),
        };
        sims.push(Sim {
            sensor: s.sensor.clone(),
            bone: bone_name,
            joint,
            pose: p,
            mount,
            second: UnitQuaternion::identity(),
        });
    }
    // A second calibration pose: held where the mapping says, the motion after it.
    let second = match mapping.calibration.as_ref().and_then(|c| c.second.as_ref()) {
        Some(second) => {
            let label = second.pose.label();
            let pose2 = rig.pose(&label).ok_or(SimulateError::Pose(label))?;
            let pose2_world = rig.world_rotations(&pose2.local);
            for s in &mut sims {
                let bone = rig.joint_index(&s.bone).expect("resolved above");
                s.second = pose2_world[bone] * s.pose.inverse();
            }
            Some(SecondPoseTimes {
                start_s: second.start_s,
                end_s: second.start_s + second.duration_s,
            })
        }
        None => None,
    };
    let hold_s = match second {
        Some(p) => options.hold_s.max(p.end_s + POSE_TURN_S + 0.5),
        None => options.hold_s,
    };
    // Bone `b`'s world-frame turn into the second pose at `t`.
    let second_turn = |s: &Sim, t: f64| -> UnitQuaternion<f64> {
        match second {
            Some(p) => slerp_shortest(&UnitQuaternion::identity(), &s.second, p.weight(t)),
            None => UnitQuaternion::identity(),
        }
    };

    let frame_time = bvh.frame_time_s();
    let motion_start = hold_s + options.blend_s;
    let end_s = motion_start + (last - options.first_frame) as f64 * frame_time;
    let first_local = &source.locals[options.first_frame];
    // A source joint's world rotation at take time t since the reference, W_J(t) ⊗ R_J⁻¹.
    let world_at = |joint: usize, t: f64| -> UnitQuaternion<f64> {
        let world = if t < hold_s {
            source.reference_world[joint]
        } else if t < motion_start {
            let u = (t - hold_s) / options.blend_s;
            let u = u * u * (3.0 - 2.0 * u); // smoothstep: no jerk at either end
            source.chain(joint, |j| {
                slerp_shortest(&source.reference[j], &first_local[j], u)
            })
        } else {
            source.world_at(
                joint,
                options.first_frame as f64 + (t - motion_start) / frame_time,
            )
        };
        world * source.reference_world[joint].inverse()
    };

    // Sampling instants per sensor (SOU nodes share their unit's instants).
    let quantum = match options.format {
        CaptureFormat::Csv => 1e-6,
        CaptureFormat::Sou => 1e-3,
    };
    let period = 1.0 / options.rate_hz;
    let instants = |rng: &mut Rng| -> Vec<f64> {
        let offset = rng.uniform() * period;
        let mut out = Vec::new();
        let mut i = 0u64;
        loop {
            let nominal = offset + i as f64 * period;
            if nominal > end_s {
                break;
            }
            let jitter = (rng.normal() * options.jitter_s).clamp(-0.4 * period, 0.4 * period);
            let t = ((nominal + jitter).max(0.0) / quantum).round() * quantum;
            if out.last().is_none_or(|&prev| t > prev) && rng.uniform() >= options.dropout {
                out.push(t);
            }
            i += 1;
        }
        out
    };
    let unit_of = |id: &str| id.rsplit_once('_').map(|(u, _)| u.to_string());
    let mut times: Vec<Vec<f64>> = Vec::with_capacity(sims.len());
    for (i, s) in sims.iter().enumerate() {
        let shared = match options.format {
            CaptureFormat::Sou => {
                let unit = unit_of(&s.sensor);
                sims[..i]
                    .iter()
                    .position(|o| unit.is_some() && unit_of(&o.sensor) == unit)
                    .map(|k| times[k].clone())
            }
            CaptureFormat::Csv => None,
        };
        let t = shared.unwrap_or_else(|| instants(&mut rng));
        times.push(t);
    }

    // What was simulated (with the gyro biases and the field for raw readings).
    let truth = |biases: Option<&[[f64; 3]]>,
                 errors: Option<&[Option<raw::SensorErrors>]>,
                 raw: Option<RawTruth>| Truth {
        world,
        heading_deg,
        motion_start_s: motion_start,
        first_frame: options.first_frame,
        last_frame: last,
        source_frame_time_s: frame_time,
        sensors: sims
            .iter()
            .enumerate()
            .map(|(i, s)| SensorTruth {
                sensor: s.sensor.clone(),
                bone: s.bone.clone(),
                source_joint: source.rig.joints()[s.joint].name.clone(),
                mount: [s.mount.w, s.mount.i, s.mount.j, s.mount.k],
                samples: times[i].len(),
                gyro_bias_dps: biases.map(|b| b[i]),
                errors: errors.and_then(|e| e[i].clone()),
            })
            .collect(),
        raw,
    };
    if let Some(raw_options) = &options.raw {
        let raw = RawInputs {
            bvh,
            source: &source,
            sims: &sims,
            times: &times,
            heading,
            from_rig,
            hold_s,
            motion_start,
            frame_time,
            end_s,
            period_s: 1.0 / options.rate_hz,
        };
        let (text, biases, errors, raw_truth) =
            raw.capture(raw_options, &mut rng, |s: &Sim, t: f64| {
                second_turn(s, t) * world_at(s.joint, t)
            });
        let header = format!(
            "# imubake simulate --raw: frames {}..={} of the BVH, heading {heading_deg:.3} deg, seed {}\n",
            options.first_frame, last, options.seed
        );
        return Ok(Simulated {
            text: header + &text,
            truth: truth(Some(&biases), Some(&errors), Some(raw_truth)),
        });
    }

    // Orientations.
    let noise_sigma = options.noise_deg.to_radians() / 3f64.sqrt();
    let mut rows: Vec<(f64, usize, UnitQuaternion<f64>)> = Vec::new();
    for (i, s) in sims.iter().enumerate() {
        for &t in &times[i] {
            let w = second_turn(s, t) * world_at(s.joint, t);
            let body = w * s.pose;
            let mut q = from_rig * heading * body * s.mount;
            if noise_sigma > 0.0 {
                let v = Vector3::new(rng.normal(), rng.normal(), rng.normal()) * noise_sigma;
                q *= UnitQuaternion::from_scaled_axis(v);
            }
            rows.push((t, i, q));
        }
    }
    rows.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));

    let text = match options.format {
        CaptureFormat::Csv => {
            let mut out = String::with_capacity(rows.len() * 64);
            let _ = writeln!(
                out,
                "# imubake simulate: frames {}..={} of the BVH, heading {heading_deg:.3} deg, seed {}",
                options.first_frame, last, options.seed
            );
            let _ = writeln!(out, "# world: {world}");
            out.push_str("time_s,sensor,qw,qx,qy,qz\n");
            for (t, i, q) in &rows {
                let _ = writeln!(
                    out,
                    "{t:.6},{},{:.9},{:.9},{:.9},{:.9}",
                    sims[*i].sensor, q.w, q.i, q.j, q.k
                );
            }
            out
        }
        CaptureFormat::Sou => sou_text(
            &sims.iter().map(|s| s.sensor.clone()).collect::<Vec<_>>(),
            &rows,
        )?,
    };
    Ok(Simulated {
        text,
        truth: truth(None, None, None),
    })
}

/// A SOU log: debug text, then `ms,SOU,yaw1,pitch1,roll1,yaw2,pitch2,roll2` per instant.
fn sou_text(
    ids: &[String],
    rows: &[(f64, usize, UnitQuaternion<f64>)],
) -> Result<String, SimulateError> {
    let mut units: Vec<(String, Option<usize>, Option<usize>)> = Vec::new();
    for (i, id) in ids.iter().enumerate() {
        let (unit, node) = id
            .rsplit_once('_')
            .ok_or_else(|| SimulateError::SouPairs(id.clone()))?;
        let slot = match units.iter().position(|u| u.0 == unit) {
            Some(k) => k,
            None => {
                units.push((unit.to_string(), None, None));
                units.len() - 1
            }
        };
        match node {
            "0" => units[slot].1 = Some(i),
            "1" => units[slot].2 = Some(i),
            _ => return Err(SimulateError::SouPairs(id.clone())),
        }
    }
    let mut out = String::from(
        "[    1.802] usb 1-1.2: new full-speed USB device\nCalibrating MPU9250 ... keep still\n",
    );
    let ypr = |q: &UnitQuaternion<f64>| {
        let a = from_quaternion(q, EulerOrder::ZYX).map(f64::to_degrees);
        [a[0].rem_euclid(360.0), a[1], a[2]]
    };
    if let Some((unit, n0, _)) = units
        .iter()
        .find(|(_, n0, n1)| n0.is_none() || n1.is_none())
    {
        let present = if n0.is_some() { 0 } else { 1 };
        return Err(SimulateError::SouPairs(format!("{unit}_{present}")));
    }
    // Rows come sorted by time; both nodes of a unit share instants.
    let mut k = 0;
    while k < rows.len() {
        let t = rows[k].0;
        let mut at_t = Vec::new();
        while k < rows.len() && rows[k].0 == t {
            at_t.push(&rows[k]);
            k += 1;
        }
        for (unit, n0, n1) in &units {
            let find = |n: Option<usize>| at_t.iter().find(|r| Some(r.1) == n).map(|r| ypr(&r.2));
            if let (Some(a), Some(b)) = (find(*n0), find(*n1)) {
                let _ = writeln!(
                    out,
                    "{},{unit},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3}",
                    (t * 1000.0).round() as u64,
                    a[0],
                    a[1],
                    a[2],
                    b[0],
                    b[1],
                    b[2]
                );
            }
        }
    }
    Ok(out)
}
