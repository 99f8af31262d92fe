//! The VMC protocol out (<https://protocol.vmc.info>): OSC over UDP, one bundle per frame, as
//! Virtual Motion Capture sends to VSeeFace, Warudo, Unity (EVMC4U), Unreal (VMC4UE) and Blender
//! receivers.
//!
//! Each frame's bundle holds `/VMC/Ext/Root/Pos "root"` (at the origin, unrotated), one
//! `/VMC/Ext/Bone/Pos <name> px py pz qx qy qz qw` per named bone — its position (metres) and
//! rotation relative to the nearest sent bone above it (the hips': in the world, so the body
//! moves), with Unity's humanoid bone names — then `/VMC/Ext/T <time>` (the frame's time on the take's clock,
//! seconds). `/VMC/Ext/OK 1 <calibration state> 0` goes out once a second.
//!
//! # Axes
//! Unity is left-handed: X right, Y up, Z forward. The rig world is right-handed with Y up, the
//! character facing +Z and +X on its left; mirroring X maps one onto the other, a character
//! facing +Z faces Unity's +Z. A position `(x, y, z)` becomes `(−x, y, z)`; a rotation
//! `(w, x, y, z)` (the rotation `R` becomes `M R M`, `M = diag(−1, 1, 1)`) becomes
//! `(w, x, −y, −z)`. At the rest pose every joint frame is parallel to the world, as a VRM's
//! normalised bones are, so the local rotations apply to a VRM avatar as they are.
//!
//! # Names
//! The bones are the rig's body parts ([`crate::rig::anatomy`], whatever the joints' names) under
//! Unity's names: `Hips`; the spine's first joint `Spine`, its middle `Chest` and its top
//! `UpperChest` (two joints: `Spine`, `Chest`); the neck's first joint `Neck`; `Head`; per side
//! `Shoulder` (the clavicle), `UpperArm`, `LowerArm`, `Hand`, `UpperLeg`, `LowerLeg`, `Foot`,
//! `Toes`. A rig file's `vmc_names:` adds to or overrides them. Each bone's rotation is relative
//! to its parent in Unity's humanoid hierarchy (the nearest one sent: `Chest` without
//! `UpperChest` for the neck), W_parent⁻¹ ⊗ W_bone with W the joints' world rotations, and its
//! position the rest offset from it; the hips' are their world rotation and place. So a joint
//! between two sent bones (a spine of seven, CMU's `LHipJoint`) has its turn in the next bone's,
//! and a rig whose hierarchy is not Unity's (a centre of gravity above the hips and the spine)
//! still sends Unity's.

use crate::anim::Pose;
use crate::rig::Rig;
use crate::rig::anatomy::Anatomy;
use nalgebra::{UnitQuaternion, Vector3};
use rosc::{OscBundle, OscMessage, OscPacket, OscTime, OscType};

/// Unity's humanoid parent of a `HumanBodyBones` name: `Some(None)` for the hips (the top),
/// `None` for a name that is not one of the body's.
fn humanoid_parent(name: &str) -> Option<Option<&'static str>> {
    let side = |rest: &str| {
        let (side, bone) = name
            .strip_prefix("Left")
            .map(|b| ("Left", b))
            .or_else(|| name.strip_prefix("Right").map(|b| ("Right", b)))?;
        (bone == rest).then_some(side)
    };
    let sided = |bone: &str, parent: &'static str| -> Option<Option<&'static str>> {
        let s = side(bone)?;
        Some(Some(match (s, parent) {
            (_, "UpperChest" | "Hips") => parent,
            ("Left", "Shoulder") => "LeftShoulder",
            ("Left", "UpperArm") => "LeftUpperArm",
            ("Left", "LowerArm") => "LeftLowerArm",
            ("Left", "UpperLeg") => "LeftUpperLeg",
            ("Left", "LowerLeg") => "LeftLowerLeg",
            ("Left", "Foot") => "LeftFoot",
            ("Right", "Shoulder") => "RightShoulder",
            ("Right", "UpperArm") => "RightUpperArm",
            ("Right", "LowerArm") => "RightLowerArm",
            ("Right", "UpperLeg") => "RightUpperLeg",
            ("Right", "LowerLeg") => "RightLowerLeg",
            _ => "RightFoot",
        }))
    };
    match name {
        "Hips" => Some(None),
        "Spine" => Some(Some("Hips")),
        "Chest" => Some(Some("Spine")),
        "UpperChest" => Some(Some("Chest")),
        "Neck" => Some(Some("UpperChest")),
        "Head" => Some(Some("Neck")),
        _ => sided("Shoulder", "UpperChest")
            .or_else(|| sided("UpperArm", "Shoulder"))
            .or_else(|| sided("LowerArm", "UpperArm"))
            .or_else(|| sided("Hand", "LowerArm"))
            .or_else(|| sided("UpperLeg", "Hips"))
            .or_else(|| sided("LowerLeg", "UpperLeg"))
            .or_else(|| sided("Foot", "LowerLeg"))
            .or_else(|| sided("Toes", "Foot")),
    }
}

/// A position in the rig world → Unity's axes.
pub fn to_unity_position(p: Vector3<f64>) -> [f32; 3] {
    [-p.x as f32, p.y as f32, p.z as f32]
}

/// A rotation in the rig world → Unity's axes, as VMC orders it: `[x, y, z, w]`.
pub fn to_unity_rotation(q: &UnitQuaternion<f64>) -> [f32; 4] {
    let q = q.quaternion();
    [q.i as f32, -q.j as f32, -q.k as f32, q.w as f32]
}

/// What VMC says of the calibration (`/VMC/Ext/OK`'s second argument).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CalibrationState {
    Uncalibrated = 0,
    WaitingForCalibrating = 1,
    Calibrating = 2,
    Calibrated = 3,
}

/// The bones a rig sends: (joint index, Unity name), in rig order.
#[derive(Debug, Clone)]
pub struct VmcSkeleton {
    bones: Vec<(usize, String)>,
    /// Each sent bone's parent among the sent: its nearest sent humanoid parent in Unity's
    /// hierarchy (the hips: none), or for a name of a rig file's own the nearest sent joint
    /// above it.
    above: Vec<Option<usize>>,
    /// Each sent bone's rest offset from the bone above it (metres, rig world).
    offsets: Vec<Vector3<f64>>,
    /// Whether every sent bone's parent joint is the bone above it (no joint in between): then
    /// the joints' local rotations are sent as they are.
    direct: bool,
    metres_per_unit: f64,
}

impl VmcSkeleton {
    /// The bones of `rig` with a Unity name (its body parts', see the module's docs; its rig
    /// file's `vmc_names` added or overriding). `None` when the rig has no hips to send.
    pub fn new(rig: &Rig) -> Option<VmcSkeleton> {
        let m = rig.units().metres_per_unit();
        let mut named: Vec<Option<String>> = vec![None; rig.len()];
        for (unity, j) in Anatomy::of(rig).unity_bones() {
            named[j] = Some(unity);
        }
        for (joint, unity) in rig.vmc_names() {
            if let Some(j) = rig.joint_index(joint) {
                named.iter_mut().for_each(|n| {
                    if n.as_deref() == Some(unity.as_str()) {
                        *n = None;
                    }
                });
                named[j] = Some(unity.clone());
            }
        }
        let bones: Vec<(usize, String)> = named
            .into_iter()
            .enumerate()
            .filter_map(|(j, n)| n.map(|n| (j, n)))
            .collect();
        if !bones.iter().any(|(_, n)| n == "Hips") {
            return None;
        }
        let rest = rig.rest_positions();
        let sent = |name: &str| bones.iter().find(|(_, n)| n == name).map(|&(j, _)| j);
        let mut above = Vec::with_capacity(bones.len());
        let mut offsets = Vec::with_capacity(bones.len());
        let mut direct = true;
        for (j, name) in &bones {
            let j = *j;
            // Unity's humanoid parent, the nearest one sent (the hips have none); a name that is
            // not Unity's: the nearest sent joint above it in the rig.
            let p = match humanoid_parent(name) {
                Some(mut up) => loop {
                    match up {
                        None => break None,
                        Some(u) => match sent(u) {
                            Some(k) => break Some(k),
                            None => up = humanoid_parent(u).flatten(),
                        },
                    }
                },
                None => {
                    let mut p = rig.joints()[j].parent;
                    while let Some(k) = p {
                        if bones.iter().any(|&(b, _)| b == k) {
                            break;
                        }
                        p = rig.joints()[k].parent;
                    }
                    p
                }
            };
            direct &= p == rig.joints()[j].parent;
            above.push(p);
            offsets.push(p.map_or(Vector3::zeros(), |p| (rest[j] - rest[p]) * m));
        }
        Some(VmcSkeleton {
            bones,
            above,
            offsets,
            direct,
            metres_per_unit: m,
        })
    }

    /// The Unity names sent, in order.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.bones.iter().map(|(_, n)| n.as_str())
    }

    /// One frame's bundle, encoded.
    pub fn frame(&self, pose: &Pose, rig: &Rig) -> Vec<u8> {
        let mut content = Vec::with_capacity(self.bones.len() + 2);
        let mut root_args = vec![OscType::String("root".into())];
        root_args.extend(floats(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]));
        content.push(OscPacket::Message(OscMessage {
            addr: "/VMC/Ext/Root/Pos".into(),
            args: root_args,
        }));
        // World rotations and positions only when a joint lies between two sent bones or a top
        // bone is not the root: otherwise each bone's rotation is the joint's own local one.
        let roots_only = self
            .bones
            .iter()
            .zip(&self.above)
            .all(|(&(j, _), a)| a.is_some() || j == 0);
        let world = (!self.direct || !roots_only).then(|| rig.world_rotations(&pose.local));
        let positions = (!roots_only).then(|| rig.world_positions(&pose.local, pose.root));
        for (i, (j, name)) in self.bones.iter().enumerate() {
            let (position, rotation) = match self.above[i] {
                // The top bone carries the body's place in the world.
                None => {
                    let p = positions.as_ref().map_or(pose.root, |p| p[*j]);
                    let q = world.as_ref().map_or(pose.local[*j], |w| w[*j]);
                    (p * self.metres_per_unit, q)
                }
                Some(a) => {
                    let q = match &world {
                        Some(w) => w[a].inverse() * w[*j],
                        None => pose.local[*j],
                    };
                    (self.offsets[i], q)
                }
            };
            let mut args = vec![OscType::String(name.clone())];
            args.extend(floats(&to_unity_position(position)));
            args.extend(floats(&to_unity_rotation(&rotation)));
            content.push(OscPacket::Message(OscMessage {
                addr: "/VMC/Ext/Bone/Pos".into(),
                args,
            }));
        }
        content.push(OscPacket::Message(OscMessage {
            addr: "/VMC/Ext/T".into(),
            args: vec![OscType::Float(pose.time_s as f32)],
        }));
        encode(OscPacket::Bundle(OscBundle {
            timetag: OscTime {
                seconds: 0,
                fractional: 1,
            },
            content,
        }))
    }
}

/// `/VMC/Ext/OK 1 <state> 0`: a model is loaded (bones are being sent), its calibration state,
/// the normal calibration mode.
pub fn ok_message(state: CalibrationState) -> Vec<u8> {
    encode(OscPacket::Message(OscMessage {
        addr: "/VMC/Ext/OK".into(),
        args: vec![OscType::Int(1), OscType::Int(state as i32), OscType::Int(0)],
    }))
}

fn floats(v: &[f32]) -> impl Iterator<Item = OscType> + '_ {
    v.iter().map(|x| OscType::Float(*x))
}

fn encode(packet: OscPacket) -> Vec<u8> {
    // Encoding an OSC packet into memory fails only for a string with a NUL, which names here
    // cannot contain (rig names are checked); an empty datagram is sent then, never a panic.
    rosc::encoder::encode(&packet).unwrap_or_default()
}

/// Whether a datagram received on `--listen` asks for a calibration
/// (`/VMC/Ext/Set/Calib/Exec`, alone or in a bundle). Any bytes: never panics.
pub fn is_calibration_request(datagram: &[u8]) -> bool {
    fn any(p: &OscPacket) -> bool {
        match p {
            OscPacket::Message(m) => m.addr == "/VMC/Ext/Set/Calib/Exec",
            OscPacket::Bundle(b) => b.content.iter().any(any),
        }
    }
    rosc::decoder::decode_udp(datagram).is_ok_and(|(_, p)| any(&p))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rotating a vector in the rig world and then mirroring it is mirroring it and then
    /// rotating it by the converted rotation.
    #[test]
    fn the_axis_conversion_mirrors_x() {
        let q = UnitQuaternion::from_euler_angles(0.3, -0.7, 1.1);
        let v = Vector3::new(0.2, -0.5, 0.9);
        // Rotate in the rig world, then mirror; or mirror, then rotate by the converted q.
        let rotated = to_unity_position(q * v);
        let [x, y, z, w] = to_unity_rotation(&q);
        let qu = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
            w as f64, x as f64, y as f64, z as f64,
        ));
        let [a, b, c] = to_unity_position(v);
        let mirrored_then_rotated = qu * Vector3::new(a as f64, b as f64, c as f64);
        for i in 0..3 {
            assert!((rotated[i] as f64 - mirrored_then_rotated[i]).abs() < 1e-6);
        }
    }

    /// A rig whose root is a centre of gravity above the hips and the spine (not Unity's
    /// hierarchy): the hips go out with their world rotation and place, the spine relative to
    /// the hips, whatever the rig's own parents.
    #[test]
    fn a_rig_not_shaped_like_unity_sends_unity_relations() {
        let text = "name: cog\njoints:\n  - {name: COG, offset: [0, 1, 0]}\n  - {name: Hips, parent: COG, offset: [0, -0.05, 0]}\n  - {name: LeftUpLeg, parent: Hips, offset: [0.1, 0, 0]}\n  - {name: LeftLeg, parent: LeftUpLeg, offset: [0, -0.45, 0]}\n  - {name: RightUpLeg, parent: Hips, offset: [-0.1, 0, 0]}\n  - {name: RightLeg, parent: RightUpLeg, offset: [0, -0.45, 0]}\n  - {name: Spine, parent: COG, offset: [0, 0.1, 0]}\n  - {name: LeftArm, parent: Spine, offset: [0.2, 0.3, 0]}\n  - {name: RightArm, parent: Spine, offset: [-0.2, 0.3, 0]}\n";
        let rig = crate::rig::file::parse_rig(text, std::path::Path::new("cog.yaml")).unwrap();
        let s = VmcSkeleton::new(&rig).unwrap();
        let names: Vec<&str> = s.names().collect();
        assert_eq!(names[0], "Hips", "{names:?}");
        assert!(
            names.contains(&"Spine") && !names.contains(&"COG"),
            "{names:?}"
        );
        // The centre of gravity turns 90° about Y; nothing else turns.
        let mut local = vec![UnitQuaternion::identity(); rig.len()];
        local[0] = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), std::f64::consts::FRAC_PI_2);
        let pose = Pose {
            frame: 0,
            time_s: 0.0,
            local,
            root: Vector3::new(0.0, 1.0, 0.0),
            contact: [false; 2],
            airborne: false,
        };
        let bundle = s.frame(&pose, &rig);
        let Ok((_, OscPacket::Bundle(b))) = rosc::decoder::decode_udp(&bundle) else {
            panic!("not a bundle");
        };
        let bone = |name: &str| -> Vec<f32> {
            b.content
                .iter()
                .find_map(|p| match p {
                    OscPacket::Message(m)
                        if m.addr == "/VMC/Ext/Bone/Pos"
                            && m.args[0] == OscType::String(name.into()) =>
                    {
                        Some(
                            m.args[1..]
                                .iter()
                                .map(|a| a.clone().float().unwrap())
                                .collect(),
                        )
                    }
                    _ => None,
                })
                .unwrap()
        };
        let hips = bone("Hips");
        // World rotation 90° about Y: (x, y, z, w) = (0, sin 45°, 0, cos 45°), Unity's y negated.
        let h = std::f32::consts::FRAC_1_SQRT_2;
        assert!(
            (hips[4] + h).abs() < 1e-6 && (hips[6] - h).abs() < 1e-6,
            "{hips:?}"
        );
        // Its place: the COG's at (0, 1, 0) and the hips 5 cm below it.
        assert!((hips[1] - 0.95).abs() < 1e-6, "{hips:?}");
        // The spine does not turn relative to the hips; its offset is from them (15 cm up).
        let spine = bone("Spine");
        assert!((spine[6].abs() - 1.0).abs() < 1e-6, "{spine:?}");
        assert!((spine[1] - 0.15).abs() < 1e-6, "{spine:?}");
    }

    #[test]
    fn mixamo_and_sou12_have_unity_names_and_calibration_requests_are_read() {
        let rig = crate::rig::load_rig("mixamo").unwrap();
        let s = VmcSkeleton::new(&rig).unwrap();
        let names: Vec<&str> = s.names().collect();
        assert_eq!(names.len(), 22);
        assert!(names.contains(&"LeftUpperArm") && names.contains(&"RightToes"));
        let sou = crate::rig::load_rig("sou12").unwrap();
        assert_eq!(VmcSkeleton::new(&sou).unwrap().names().count(), 12);
        let request = encode(OscPacket::Message(OscMessage {
            addr: "/VMC/Ext/Set/Calib/Exec".into(),
            args: vec![OscType::Int(0)],
        }));
        assert!(is_calibration_request(&request));
        assert!(!is_calibration_request(&ok_message(
            CalibrationState::Calibrated
        )));
        assert!(!is_calibration_request(b"garbage"));
    }
}
