//! WitMotion's binary serial protocol (WT901, WT901C, JY901, HWT901B …): 11-byte packets
//!
//! ```text
//! 0x55  type  d0 d1 d2 d3 d4 d5 d6 d7  sum      sum = (0x55 + type + d0 + … + d7) mod 256
//! ```
//!
//! with four little-endian int16 words w0..w3 in d0..d7 (WitMotion's protocol document, and its
//! SDKs' decoders):
//!
//! | type | content | scale |
//! |---|---|---|
//! | 0x50 | time: YY MM DD hh mm ss (bytes), ms (u16) | year 2000 + YY |
//! | 0x51 | acceleration x, y, z; temperature | w / 32768 · 16 g |
//! | 0x52 | angular velocity x, y, z | w / 32768 · 2000 °/s |
//! | 0x53 | angle: roll (x), pitch (y), yaw (z); version | w / 32768 · 180 ° |
//! | 0x54 | magnetic field x, y, z | raw counts (no universal unit) |
//! | 0x59 | quaternion Q0 (w), Q1, Q2, Q3 | w / 32768 |
//!
//! The angles are yaw, pitch, roll in Z-Y-X order (R = Rz(yaw) · Ry(pitch) · Rx(roll)) in an ENU
//! world ("north-east-sky"); the quaternion is the same attitude, w first. The orientation is the
//! quaternion when the device sends one, else the angles. In 6-axis mode (no magnetometer) the
//! yaw starts from zero at power-on: its heading is not north.
//!
//! Samples: a device sends one packet of each kind per output cycle, so a sample ends where a
//! kind repeats. Its time is its `0x50` packet's (the chip clock, which need not be UTC), else
//! `index / rate` with `--rate HZ` — then each sensor's first sample is t = 0, so sensors
//! recorded apart are aligned at their first packets (a limitation: only time packets place
//! them truly).
//!
//! A packet with a bad checksum is dropped (the decoder moves on by one byte and looks for the
//! next 0x55, as WitMotion's SDKs do) and counted; a warning names the byte offset of the first.

use super::{InputFormat, ReadError, ReadOptions};
use crate::take::{ClockUnit, ImuSample, Take, TakeBuilder, YawPitchRollDeg};
use crate::world::World;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use std::path::Path;

/// The packets' first byte.
pub const HEADER: u8 = 0x55;
/// A packet's length, bytes.
pub const PACKET: usize = 11;
/// Standard gravity, m/s² per g.
const G: f64 = 9.80665;

/// One packet's kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    Time,
    Acceleration,
    AngularVelocity,
    Angle,
    Magnetic,
    Quaternion,
    /// Another valid type (port status, pressure, GPS …; 0x55–0x5A, 0x5F): skipped.
    Other(u8),
}

impl Kind {
    fn of(byte: u8) -> Option<Kind> {
        Some(match byte {
            0x50 => Kind::Time,
            0x51 => Kind::Acceleration,
            0x52 => Kind::AngularVelocity,
            0x53 => Kind::Angle,
            0x54 => Kind::Magnetic,
            0x59 => Kind::Quaternion,
            0x55..=0x5A | 0x5F => Kind::Other(byte),
            _ => return None,
        })
    }
}

/// A checked packet: its kind, its payload and where it started in the stream.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Packet {
    pub kind: Kind,
    pub data: [u8; 8],
    /// Byte offset of its 0x55 in the stream.
    pub offset: u64,
}

impl Packet {
    /// The payload as four little-endian int16 words.
    pub fn words(&self) -> [i16; 4] {
        let d = &self.data;
        [0, 2, 4, 6].map(|i| i16::from_le_bytes([d[i], d[i + 1]]))
    }

    /// Three words times `full_scale / 32768`.
    fn scaled(&self, full_scale: f64) -> Vector3<f64> {
        let w = self.words();
        Vector3::new(w[0] as f64, w[1] as f64, w[2] as f64) * (full_scale / 32768.0)
    }

    /// A time packet as milliseconds since 2000-01-01 00:00 (the chip clock's date and time),
    /// kept whole so that differences are exact.
    fn time_ms(&self) -> Option<i64> {
        let d = &self.data;
        let (year, month, day) = (2000 + d[0] as i64, d[1] as i64, d[2] as i64);
        let (hour, minute, second) = (d[3] as i64, d[4] as i64, d[5] as i64);
        let ms = u16::from_le_bytes([d[6], d[7]]) as i64;
        if !(1..=12).contains(&month)
            || !(1..=31).contains(&day)
            || hour > 23
            || minute > 59
            || second > 60
            || ms >= 1000
        {
            return None;
        }
        let days = days_from_civil(year, month, day) - days_from_civil(2000, 1, 1);
        Some((days * 86_400 + hour * 3600 + minute * 60 + second) * 1000 + ms)
    }
}

/// Days since 1970-01-01 of a proleptic Gregorian date (Howard Hinnant's algorithm).
fn days_from_civil(y: i64, m: i64, d: i64) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let doy = (153 * (m + if m > 2 { -3 } else { 9 }) + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// Finds packets in a byte stream fed in pieces of any size.
#[derive(Debug, Default)]
pub struct Decoder {
    pending: Vec<u8>,
    /// Stream offset of `pending[0]`.
    offset: u64,
    /// Packets dropped for a bad checksum, and the first one's offset.
    pub bad_checksums: u64,
    pub first_bad_offset: Option<u64>,
    /// Bytes skipped while looking for a packet (noise, cut packets).
    pub skipped_bytes: u64,
}

impl Decoder {
    pub fn new() -> Decoder {
        Decoder::default()
    }

    /// Feeds bytes; the whole packets they complete go to `out`.
    pub fn push(&mut self, bytes: &[u8], out: &mut Vec<Packet>) {
        self.pending.extend_from_slice(bytes);
        let mut i = 0;
        while i + PACKET <= self.pending.len() {
            let p = &self.pending[i..i + PACKET];
            let kind = (p[0] == HEADER).then(|| Kind::of(p[1])).flatten();
            match kind {
                Some(kind) => {
                    let sum = p[..10].iter().fold(0u8, |s, &b| s.wrapping_add(b));
                    if sum == p[10] {
                        let mut data = [0u8; 8];
                        data.copy_from_slice(&p[2..10]);
                        out.push(Packet {
                            kind,
                            data,
                            offset: self.offset + i as u64,
                        });
                        i += PACKET;
                        continue;
                    }
                    self.bad_checksums += 1;
                    self.first_bad_offset.get_or_insert(self.offset + i as u64);
                    i += 1;
                }
                None => {
                    self.skipped_bytes += 1;
                    i += 1;
                }
            }
        }
        // Keep what may start a packet: from the next 0x55 on (at most one packet's worth).
        let keep_from = self.pending[i..]
            .iter()
            .position(|&b| b == HEADER)
            .map_or(self.pending.len(), |k| i + k);
        self.skipped_bytes += (keep_from - i) as u64;
        self.pending.drain(..keep_from);
        self.offset += keep_from as u64;
    }
}

/// One output cycle of a device: what its packets said.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Sample {
    /// Chip time, milliseconds since 2000-01-01 (`Some(None)`: a time packet with an impossible
    /// date).
    pub chip_time_ms: Option<Option<i64>>,
    pub accel_g: Option<Vector3<f64>>,
    pub gyro_dps: Option<Vector3<f64>>,
    /// Roll (x), pitch (y), yaw (z), degrees.
    pub angle_deg: Option<Vector3<f64>>,
    pub magnetic_raw: Option<Vector3<f64>>,
    /// w, x, y, z.
    pub quaternion: Option<[f64; 4]>,
    /// Offset of the sample's first packet.
    pub offset: u64,
}

impl Sample {
    fn has(&self, kind: Kind) -> bool {
        match kind {
            Kind::Time => self.chip_time_ms.is_some(),
            Kind::Acceleration => self.accel_g.is_some(),
            Kind::AngularVelocity => self.gyro_dps.is_some(),
            Kind::Angle => self.angle_deg.is_some(),
            Kind::Magnetic => self.magnetic_raw.is_some(),
            Kind::Quaternion => self.quaternion.is_some(),
            Kind::Other(_) => false,
        }
    }

    fn is_empty(&self) -> bool {
        *self
            == Sample {
                offset: self.offset,
                ..Sample::default()
            }
    }

    /// The attitude: the quaternion when sent, else the angles (Z-Y-X, intrinsic), q_enu_sensor.
    pub fn orientation(&self) -> Option<UnitQuaternion<f64>> {
        if let Some([w, x, y, z]) = self.quaternion
            && let Some((q, _)) = super::unit_quaternion(Quaternion::new(w, x, y, z))
        {
            return Some(q);
        }
        self.angle_deg.map(|a| {
            YawPitchRollDeg {
                yaw: a.z,
                pitch: a.y,
                roll: a.x,
            }
            .to_quaternion()
        })
    }
}

/// Groups packets into samples: a sample ends where a kind it already has comes again.
#[derive(Debug, Default)]
pub struct Assembler {
    current: Sample,
}

impl Assembler {
    pub fn push(&mut self, p: &Packet, out: &mut Vec<Sample>) {
        if self.current.has(p.kind) {
            out.push(std::mem::take(&mut self.current));
        }
        if self.current.is_empty() {
            self.current.offset = p.offset;
        }
        let c = &mut self.current;
        match p.kind {
            Kind::Time => c.chip_time_ms = Some(p.time_ms()),
            Kind::Acceleration => c.accel_g = Some(p.scaled(16.0)),
            Kind::AngularVelocity => c.gyro_dps = Some(p.scaled(2000.0)),
            Kind::Angle => c.angle_deg = Some(p.scaled(180.0)),
            Kind::Magnetic => c.magnetic_raw = Some(p.scaled(32768.0)),
            Kind::Quaternion => {
                let w = p.words();
                c.quaternion = Some(w.map(|v| v as f64 / 32768.0));
            }
            Kind::Other(_) => {}
        }
    }

    /// The last sample, if it holds anything.
    pub fn finish(&mut self, out: &mut Vec<Sample>) {
        let last = std::mem::take(&mut self.current);
        if !last.is_empty() {
            out.push(last);
        }
    }
}

/// Every sample of a whole recording, and the decoder's counts.
pub fn samples(bytes: &[u8]) -> (Vec<Sample>, Decoder) {
    let mut decoder = Decoder::new();
    let mut packets = Vec::new();
    decoder.push(bytes, &mut packets);
    let mut assembler = Assembler::default();
    let mut samples = Vec::new();
    for p in &packets {
        assembler.push(p, &mut samples);
    }
    assembler.finish(&mut samples);
    (samples, decoder)
}

/// A live WitMotion stream as imubake CSV lines — `time_s,sensor,qw,qx,qy,qz` and, when the
/// device sends them, `gx_dps,gy_dps,gz_dps,ax_g,ay_g,az_g` — the text the session's line stages
/// read (`imubake live --source serial:…:witmotion`). Time: the chip clock from its first sample,
/// else the host's seconds the caller passes.
#[derive(Debug)]
pub struct CsvLines {
    sensor: String,
    decoder: Decoder,
    assembler: Assembler,
    /// Whether the header written has the inertial columns (`None`: no header yet).
    inertial: Option<bool>,
    chip_t0: Option<i64>,
    packets: Vec<Packet>,
    samples: Vec<Sample>,
}

impl CsvLines {
    pub fn new(sensor: &str) -> CsvLines {
        CsvLines {
            sensor: sensor.to_string(),
            decoder: Decoder::new(),
            assembler: Assembler::default(),
            inertial: None,
            chip_t0: None,
            packets: Vec::new(),
            samples: Vec::new(),
        }
    }

    /// A new connection to the same device (a serial port reopened): bytes and packets half
    /// received are dropped; the header already written and the clock's origin stay, so the
    /// lines carry on as one stream.
    pub fn restart(&mut self) {
        let bad = self.decoder.bad_checksums;
        let first = self.decoder.first_bad_offset;
        self.decoder = Decoder::new();
        self.decoder.bad_checksums = bad;
        self.decoder.first_bad_offset = first;
        self.assembler = Assembler::default();
    }

    /// Packets dropped for a bad checksum so far.
    pub fn bad_checksums(&self) -> u64 {
        self.decoder.bad_checksums
    }

    /// Feeds bytes received when the host's clock said `host_s`; complete samples' lines go to
    /// `out` (the header before the first).
    pub fn push(&mut self, bytes: &[u8], host_s: f64, out: &mut Vec<Vec<u8>>) {
        self.packets.clear();
        self.decoder.push(bytes, &mut self.packets);
        for p in &self.packets {
            self.assembler.push(p, &mut self.samples);
        }
        self.lines(host_s, out);
    }

    /// The last sample, at the stream's end.
    pub fn finish(&mut self, host_s: f64, out: &mut Vec<Vec<u8>>) {
        self.assembler.finish(&mut self.samples);
        self.lines(host_s, out);
    }

    fn lines(&mut self, host_s: f64, out: &mut Vec<Vec<u8>>) {
        for s in self.samples.drain(..) {
            let Some(q) = s.orientation() else { continue };
            let inertial = *self.inertial.get_or_insert_with(|| {
                let with = s.accel_g.is_some() && s.gyro_dps.is_some();
                let mut header = b"time_s,sensor,qw,qx,qy,qz".to_vec();
                if with {
                    header.extend_from_slice(b",gx_dps,gy_dps,gz_dps,ax_g,ay_g,az_g");
                }
                out.push(header);
                with
            });
            let t = match s.chip_time_ms.flatten() {
                Some(chip) => (chip - *self.chip_t0.get_or_insert(chip)) as f64 / 1000.0,
                None => host_s,
            };
            let mut line = format!(
                "{t:.6},{},{:.9},{:.9},{:.9},{:.9}",
                self.sensor, q.w, q.i, q.j, q.k
            );
            if inertial {
                let (Some(g), Some(a)) = (s.gyro_dps, s.accel_g) else {
                    continue;
                };
                line.push_str(&format!(
                    ",{:.6},{:.6},{:.6},{:.6},{:.6},{:.6}",
                    g.x, g.y, g.z, a.x, a.y, a.z
                ));
            }
            out.push(line.into_bytes());
        }
    }
}

/// True when the bytes start (within a packet) with three valid packets in a row.
pub fn looks_like(head: &[u8]) -> bool {
    (0..PACKET.min(head.len())).any(|start| {
        let mut decoder = Decoder::new();
        let mut packets = Vec::new();
        let end = head.len().min(start + 3 * PACKET);
        decoder.push(&head[start..end], &mut packets);
        packets.len() == 3 && packets[0].offset == 0 && decoder.bad_checksums == 0
    })
}

/// A sensor's recording: its id and bytes.
pub struct Recording<'a> {
    pub id: String,
    pub bytes: &'a [u8],
}

/// A take from WitMotion recordings, one per sensor. `path` names the take in reports.
pub fn take_of(
    recordings: &[Recording<'_>],
    path: &Path,
    options: &ReadOptions,
) -> Result<Take, ReadError> {
    let world = options.world.unwrap_or(World::Enu);
    let mut take = TakeBuilder::new(path, InputFormat::WitMotion, world, ClockUnit::Seconds);
    for rec in recordings {
        let (samples, decoder) = samples(rec.bytes);
        take.set_file((recordings.len() > 1).then(|| rec.id.clone()));
        if decoder.bad_checksums > 0 {
            take.warn(format!(
                "{}: {} packets with a bad checksum dropped (the first at byte offset {})",
                rec.id,
                decoder.bad_checksums,
                decoder.first_bad_offset.unwrap_or(0)
            ));
        }
        if samples.is_empty() {
            take.warn(format!("{}: no WitMotion packet found", rec.id));
            continue;
        }
        let timed = samples.iter().any(|s| s.chip_time_ms.is_some());
        // Times from the first valid chip time, in whole milliseconds: exact differences.
        let chip_t0 = samples.iter().find_map(|s| s.chip_time_ms.flatten());
        let rate = match (timed, options.rate_hz) {
            (true, _) => None,
            (false, Some(rate)) => Some(rate),
            (false, None) => {
                return Err(ReadError::format(
                    path,
                    format!(
                        "{}: no time packets (0x50); give the output rate with --rate HZ",
                        rec.id
                    ),
                ));
            }
        };
        let sensor = take.sensor(&rec.id);
        for (k, s) in samples.iter().enumerate() {
            // Reports name the sample by its byte offset (a binary stream has no lines).
            let line = s.offset + 1;
            let raw = format!("sample at byte offset {}", s.offset);
            let t = match rate {
                Some(rate) => k as f64 / rate,
                None => match s.chip_time_ms {
                    Some(Some(ms)) => (ms - chip_t0.unwrap_or(ms)) as f64 / 1000.0,
                    Some(None) => {
                        take.drop_line(
                            line,
                            "a time packet with an impossible date",
                            raw.as_bytes(),
                        );
                        continue;
                    }
                    None => {
                        take.drop_line(line, "a sample without its time packet", raw.as_bytes());
                        continue;
                    }
                },
            };
            if let Some(q) = s.orientation() {
                take.push_quaternion(sensor, t, q, line, raw.as_bytes())
                    .map_err(|e| ReadError::take(path, e))?;
            }
            if let (Some(acc), Some(gyro)) = (s.accel_g, s.gyro_dps) {
                let sample = ImuSample {
                    gyro_rad_s: gyro * std::f64::consts::PI / 180.0,
                    accel_m_s2: acc * G,
                };
                take.push_inertial(sensor, t, sample, line, raw.as_bytes())
                    .map_err(|e| ReadError::take(path, e))?;
            }
            if let Some(m) = s.magnetic_raw {
                take.push_magnetometer(sensor, t, m, line, raw.as_bytes())
                    .map_err(|e| ReadError::take(path, e))?;
            }
        }
    }
    take.set_file(None);
    if options.rate_hz.is_some() && recordings.len() > 1 {
        take.warn(
            "--rate: the sensors are aligned at their first packets (no time packets place them)",
        );
    }
    take.finish(options.skip_seconds)
        .map_err(|e| ReadError::take(path, e))
}

/// Reads one recording (a file, its stem the sensor id) or a folder of them.
pub fn read(path: &Path, options: &ReadOptions) -> Result<Take, ReadError> {
    let files: Vec<std::path::PathBuf> = if path.is_dir() {
        super::visible_files(path)?
            .into_iter()
            .filter(|f| super::sniff(f).is_ok_and(|head| looks_like(&head)))
            .collect()
    } else {
        vec![path.to_path_buf()]
    };
    let contents: Vec<(String, Vec<u8>)> = files
        .iter()
        .map(|f| {
            let bytes = std::fs::read(f).map_err(|e| ReadError::io(f, e))?;
            let id = super::take_stem(f);
            Ok((id, bytes))
        })
        .collect::<Result<_, ReadError>>()?;
    let recordings: Vec<Recording<'_>> = contents
        .iter()
        .map(|(id, bytes)| Recording {
            id: id.clone(),
            bytes,
        })
        .collect();
    take_of(&recordings, path, options)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn packet(kind: u8, words: [i16; 4]) -> Vec<u8> {
        let mut p = vec![HEADER, kind];
        for w in words {
            p.extend_from_slice(&w.to_le_bytes());
        }
        let sum = p.iter().fold(0u8, |s, &b| s.wrapping_add(b));
        p.push(sum);
        p
    }

    #[test]
    fn scales_by_hand() {
        // 16384 / 32768 · 16 g = 8 g; −8192 / 32768 · 2000 °/s = −500 °/s; 16384 → 90°.
        let mut bytes = packet(0x51, [16384, 0, -32768, 2500]);
        bytes.extend(packet(0x52, [-8192, 0, 0, 0]));
        bytes.extend(packet(0x53, [16384, 0, -16384, 0]));
        bytes.extend(packet(0x59, [32767, 0, 0, 0]));
        let (samples, decoder) = samples(&bytes);
        assert_eq!(decoder.bad_checksums, 0);
        assert_eq!(samples.len(), 1);
        let s = samples[0];
        assert_eq!(s.accel_g, Some(Vector3::new(8.0, 0.0, -16.0)));
        assert_eq!(s.gyro_dps, Some(Vector3::new(-500.0, 0.0, 0.0)));
        assert_eq!(s.angle_deg, Some(Vector3::new(90.0, 0.0, -90.0)));
        assert!((s.quaternion.unwrap()[0] - 32767.0 / 32768.0).abs() < 1e-15);
    }

    #[test]
    fn time_packets_are_the_chip_clock() {
        // 2024-03-19 16:44:16.689 → days since 2000-01-01: 8844 (24 years incl. 6 leap days = 8766,
        // + Jan 31 + Feb 29 + 18 = 78).
        let p = Packet {
            kind: Kind::Time,
            data: [
                24,
                3,
                19,
                16,
                44,
                16,
                689u16.to_le_bytes()[0],
                689u16.to_le_bytes()[1],
            ],
            offset: 0,
        };
        let t = p.time_ms().unwrap();
        let expected = ((8844 * 86400 + 16 * 3600 + 44 * 60 + 16) * 1000) + 689;
        assert_eq!(t, expected);
        let bad = Packet {
            data: [24, 13, 1, 0, 0, 0, 0, 0],
            ..p
        };
        assert!(bad.time_ms().is_none());
    }

    #[test]
    fn bad_checksums_and_noise_are_skipped_and_counted() {
        let good = packet(0x51, [1, 2, 3, 4]);
        let mut broken = packet(0x52, [1, 2, 3, 4]);
        broken[10] ^= 0xFF;
        // A stray 0x55 would itself open a (bad) packet: 0x55 is a valid type byte.
        let mut bytes = vec![0x00, 0x13];
        bytes.extend(&good);
        bytes.extend(&broken);
        bytes.extend(&good);
        // Fed one byte at a time, as a serial port may deliver them.
        let mut d = Decoder::new();
        let mut out = Vec::new();
        for b in &bytes {
            d.push(std::slice::from_ref(b), &mut out);
        }
        assert_eq!(out.len(), 2);
        assert_eq!(out[0].offset, 2);
        assert_eq!(out[1].offset, 2 + 22);
        assert_eq!(d.bad_checksums, 1);
        assert_eq!(d.first_bad_offset, Some(13));
        assert_eq!(d.skipped_bytes, 2 + 10);
    }

    #[test]
    fn a_reopened_stream_keeps_one_header_and_drops_the_half_packet() {
        let sample = |yaw: i16| {
            let mut b = packet(0x51, [0, 0, 2048, 0]);
            b.extend(packet(0x52, [0, 0, 0, 0]));
            b.extend(packet(0x53, [0, 0, yaw, 0]));
            b
        };
        let mut lines = CsvLines::new("imu");
        let mut out = Vec::new();
        let first = [sample(0), sample(100)].concat();
        lines.push(&first, 0.0, &mut out);
        // Half of a third sample, then the port goes away and comes back.
        lines.push(&sample(200)[..15], 0.02, &mut out);
        lines.restart();
        lines.push(&[sample(300), sample(400)].concat(), 1.0, &mut out);
        lines.finish(1.01, &mut out);
        let text: Vec<String> = out
            .iter()
            .map(|l| String::from_utf8_lossy(l).into_owned())
            .collect();
        assert_eq!(
            text[0],
            "time_s,sensor,qw,qx,qy,qz,gx_dps,gy_dps,gz_dps,ax_g,ay_g,az_g"
        );
        assert_eq!(text.iter().filter(|l| l.starts_with("time_s")).count(), 1);
        // Samples 0, 100, 300, 400 (the half one is gone): 4 rows. The second ends when the
        // half sample's 0x51 arrives; the last comes out at the end.
        assert_eq!(text.len(), 1 + 4, "{text:?}");
        assert!(
            text[1].starts_with("0.000000,imu,1.000000000,"),
            "{}",
            text[1]
        );
    }
}
