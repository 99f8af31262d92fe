//! Shared by the benchmarks: the synthetic capture log of issue 2 and memory readings.
#![allow(dead_code)]

use std::fmt::Write as _;
use std::io::{BufWriter, Write};
use std::path::Path;

pub const RATE_HZ: usize = 100;

/// The sensor ids of `mappings/paper000_16imu_mixamo.json`.
pub const PAPER000_SENSORS: [&str; 16] = [
    "pelvis",
    "sternum",
    "left_shoulder_blade",
    "left_upper_arm",
    "left_forearm",
    "left_hand",
    "left_thigh",
    "left_shank",
    "left_foot",
    "right_shoulder_blade",
    "right_upper_arm",
    "right_forearm",
    "right_hand",
    "right_thigh",
    "right_shank",
    "right_foot",
];

/// Writes an imubake CSV of quaternions: `minutes` long, one row per sensor per 1/RATE_HZ s,
/// `time_s` with 4 decimals and quaternions with 6, sensors offset by 0.3 ms each (asynchronous).
/// Returns the file size in bytes.
pub fn write_log(path: &Path, minutes: usize, sensors: &[&str]) -> std::io::Result<u64> {
    let mut out = BufWriter::with_capacity(1 << 20, std::fs::File::create(path)?);
    writeln!(out, "time_s,sensor,qw,qx,qy,qz")?;
    let frames = minutes * 60 * RATE_HZ;
    for i in 0..frames {
        for (s, name) in sensors.iter().enumerate() {
            let t = i as f64 / RATE_HZ as f64 + s as f64 * 0.0003;
            let angle = 0.01 * i as f64 + s as f64;
            let (half_sin, half_cos) = (angle / 2.0).sin_cos();
            let axis = [0.6, 0.0, 0.8];
            writeln!(
                out,
                "{t:.4},{name},{:.6},{:.6},{:.6},{:.6}",
                half_cos,
                axis[0] * half_sin,
                axis[1] * half_sin,
                axis[2] * half_sin
            )?;
        }
    }
    // On disk before any timing: its writeback would otherwise compete with the first runs'
    // own writes (and their fsync).
    out.into_inner().map_err(|e| e.into_error())?.sync_all()?;
    Ok(std::fs::metadata(path)?.len())
}

/// The middle value (the upper of the two middle ones for an even count).
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// A field of /proc/self/status in KiB (`VmRSS:`, `VmHWM:`).
pub fn status_kib(field: &str) -> Option<u64> {
    proc_self_field("status", field)
}

/// The number after `field` in /proc/self/`file` (`field` with its colon).
fn proc_self_field(file: &str, field: &str) -> Option<u64> {
    let text = std::fs::read_to_string(format!("/proc/self/{file}")).ok()?;
    let line = text.lines().find(|l| l.starts_with(field))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

/// This process's CPU so far (`getrusage(RUSAGE_SELF)`, every thread): user and system seconds,
/// minor page faults and voluntary waits, and the bytes it had the disk read (`/proc/self/io`).
/// Wall time on this shared machine drifts from hour to hour; the CPU a run took, and how much
/// of it went to the kernel, says whether a slow run worked more or the host ran slower; its
/// waits and disk reads, whether idle cores waited for something (an input no longer cached).
#[derive(Debug, Clone, Copy)]
pub struct Cpu {
    pub user_s: f64,
    pub system_s: f64,
    pub minor_faults: u64,
    /// Times a thread gave up its core to wait (a lock, a channel, the disk).
    pub waits: u64,
    /// Bytes read from the storage device, not from the page cache (`None` where the kernel
    /// does not count them).
    pub disk_read_bytes: Option<u64>,
}

impl Cpu {
    pub fn now() -> Cpu {
        // SAFETY: `getrusage` fills the zeroed struct it is given and keeps no reference to it.
        let usage = unsafe {
            let mut usage: libc::rusage = std::mem::zeroed();
            libc::getrusage(libc::RUSAGE_SELF, &mut usage);
            usage
        };
        let seconds = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
        Cpu {
            user_s: seconds(usage.ru_utime),
            system_s: seconds(usage.ru_stime),
            minor_faults: usage.ru_minflt as u64,
            waits: usage.ru_nvcsw as u64,
            // Every thread of the process, in bytes.
            disk_read_bytes: proc_self_field("io", "read_bytes:"),
        }
    }

    /// User and system seconds together.
    pub fn total_s(&self) -> f64 {
        self.user_s + self.system_s
    }

    /// What was spent between `earlier` and `self`.
    pub fn since(self, earlier: Cpu) -> Cpu {
        Cpu {
            user_s: self.user_s - earlier.user_s,
            system_s: self.system_s - earlier.system_s,
            minor_faults: self.minor_faults - earlier.minor_faults,
            waits: self.waits - earlier.waits,
            disk_read_bytes: self
                .disk_read_bytes
                .zip(earlier.disk_read_bytes)
                .map(|(now, then)| now - then),
        }
    }
}

/// Resets the peak-memory mark (VmHWM) to the current resident size.
pub fn reset_peak() {
    let _ = std::fs::write("/proc/self/clear_refs", "5");
}

pub fn minutes_from_env() -> usize {
    std::env::var("IMUBAKE_BENCH_MINUTES")
        .ok()
        .and_then(|m| m.parse().ok())
        .unwrap_or(60)
}

/// The raw twin of [`write_log`]: the same sensors, instants and motion (each sensor turning at
/// 1 rad/s about (0.6, 0, 0.8)), as the readings an IMU would give — gyro (rad/s), specific force
/// (m/s²) and field (µT), each in the sensor frame, 6 decimals. Returns the file size in bytes.
pub fn write_raw_log(path: &Path, minutes: usize, sensors: &[&str]) -> std::io::Result<u64> {
    use nalgebra::{UnitQuaternion, Vector3};
    let mut out = BufWriter::with_capacity(1 << 20, std::fs::File::create(path)?);
    writeln!(out, "time_s,sensor,gx,gy,gz,ax,ay,az,mx,my,mz")?;
    let frames = minutes * 60 * RATE_HZ;
    let axis = nalgebra::Unit::new_normalize(Vector3::new(0.6, 0.0, 0.8));
    let gyro = axis.into_inner() * (0.01 * RATE_HZ as f64);
    let (up, field) = (Vector3::new(0.0, 0.0, 9.81), Vector3::new(0.0, 20.0, -40.0));
    for i in 0..frames {
        for (s, name) in sensors.iter().enumerate() {
            let t = i as f64 / RATE_HZ as f64 + s as f64 * 0.0003;
            let q = UnitQuaternion::from_axis_angle(&axis, 0.01 * i as f64 + s as f64);
            let (a, m) = (q.inverse() * up, q.inverse() * field);
            writeln!(
                out,
                "{t:.4},{name},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6}",
                gyro.x, gyro.y, gyro.z, a.x, a.y, a.z, m.x, m.y, m.z
            )?;
        }
    }
    // On disk before any timing: its writeback would otherwise compete with the first runs'
    // own writes (and their fsync).
    out.into_inner().map_err(|e| e.into_error())?.sync_all()?;
    Ok(std::fs::metadata(path)?.len())
}

/// How fast this host runs this hour, by work that does not depend on imubake's code: this
/// shared machine's speed drifts by up to half from hour to hour (no stolen time shows in
/// `/proc/stat`; the same work simply takes more CPU), so a figure is only comparable with
/// another beside the probe taken with it.
#[derive(Debug, Clone, Copy)]
pub struct HostProbe {
    /// Nanoseconds for std to format a number with `{:.6}` and parse it back, with every core
    /// doing the same at once (scalar, branchy work, like most of a conversion; it changes with
    /// the Rust toolchain, not with imubake).
    pub number_ns: f64,
    /// Microseconds for the kernel to back a 4 KiB page of fresh memory on its first write.
    pub fault_us: f64,
}

impl HostProbe {
    /// The median of a few short rounds of each (~0.5 s in all).
    pub fn measure() -> HostProbe {
        const NUMBERS: usize = 200_000;
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        // Each thread times its own loop: the slowest core's start would otherwise count.
        let number_round = || {
            let per_core: Vec<f64> = std::thread::scope(|scope| {
                let handles: Vec<_> = (0..cores)
                    .map(|core| {
                        scope.spawn(move || {
                            let mut text = String::with_capacity(32);
                            let mut sum = 0.0;
                            // A fixed sequence of values between −1000 and 1000 (an LCG).
                            let mut state = 0x9e37_79b9_7f4a_7c15_u64 ^ core as u64;
                            let start = std::time::Instant::now();
                            for _ in 0..NUMBERS {
                                state = state
                                    .wrapping_mul(6_364_136_223_846_793_005)
                                    .wrapping_add(1_442_695_040_888_963_407);
                                let v =
                                    (state >> 11) as f64 / (1u64 << 53) as f64 * 2000.0 - 1000.0;
                                text.clear();
                                let _ = write!(text, "{v:.6}");
                                sum += text.parse::<f64>().unwrap_or(0.0);
                            }
                            std::hint::black_box(sum);
                            start.elapsed().as_secs_f64() * 1e9 / NUMBERS as f64
                        })
                    })
                    .collect();
                handles
                    .into_iter()
                    .map(|h| h.join().unwrap_or(f64::NAN))
                    .collect()
            });
            per_core.iter().sum::<f64>() / per_core.len() as f64
        };
        let fault_round = || {
            const BYTES: usize = 64 << 20;
            // Zeroed memory this large comes straight from the kernel, not yet backed.
            let mut fresh = vec![0u8; BYTES];
            let start = std::time::Instant::now();
            for page in fresh.chunks_mut(4096) {
                page[0] = 1;
            }
            let secs = start.elapsed().as_secs_f64();
            std::hint::black_box(&fresh);
            secs * 1e6 / (BYTES / 4096) as f64
        };
        HostProbe {
            number_ns: median((0..7).map(|_| number_round()).collect()),
            fault_us: median((0..5).map(|_| fault_round()).collect()),
        }
    }
}

impl std::fmt::Display for HostProbe {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "host probe: {:.0} ns to format and parse a number (std, every core at once), \
             {:.2} µs to back a fresh 4 KiB page",
            self.number_ns, self.fault_us
        )
    }
}
