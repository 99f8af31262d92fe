use super::frames::MAX_LINE_BYTES;
use super::*;
use proptest::prelude::*;

fn shipped(name: &str) -> Layout {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("layouts")
        .join(name);
    Layout::load(&path).unwrap()
}

fn decode_all(layout: &Layout, chunks: &[&[u8]]) -> Decoded {
    let mut decoder = Decoder::new();
    let mut out = Decoded::default();
    for c in chunks {
        decoder.push(layout, c, &mut out);
    }
    decoder.finish(layout, &mut out);
    out
}

/// An ESP32 frame as the struct in layouts/esp32_struct.yaml lays it out, its CRC computed here
/// bit by bit (CRC-16/CCITT-FALSE: polynomial 0x1021, initial 0xFFFF, no reflection).
fn esp32_frame(sensor: u8, t_us: u32, q: [f32; 4], gyro: [i16; 3], accel: [i16; 3]) -> Vec<u8> {
    let mut payload = vec![sensor];
    payload.extend_from_slice(&t_us.to_le_bytes());
    for v in q {
        payload.extend_from_slice(&v.to_le_bytes());
    }
    for v in gyro.iter().chain(&accel) {
        payload.extend_from_slice(&v.to_le_bytes());
    }
    let mut crc: u16 = 0xFFFF;
    for b in &payload {
        crc ^= u16::from(*b) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x1021
            } else {
                crc << 1
            };
        }
    }
    let mut frame = vec![0xAA, 0x55];
    frame.extend_from_slice(&payload);
    frame.extend_from_slice(&crc.to_le_bytes());
    frame
}

#[test]
fn the_shipped_layouts_load() {
    let m = shipped("paper004_data_matrix.yaml");
    assert_eq!(m.frame, FrameKind::Text);
    assert_eq!(
        m.types[&2],
        [Meaning::Qw, Meaning::Qx, Meaning::Qy, Meaning::Qz]
    );
    let e = shipped("esp32_struct.yaml");
    assert_eq!(e.frame, FrameKind::Binary);
    // 2 start + 1 + 4 + 16 + 6 + 6 + 2 CRC.
    assert_eq!(e.max_frame, 37);
}

#[test]
fn an_error_names_the_key() {
    let base = "layout: 1\nframe: binary\nstart: [0xAA]\nfields:\n  - {as: qw, encoding: f32le}\n  - {as: qx, encoding: f32le}\n  - {as: qy, encoding: f32le}\n";
    let e = Layout::parse(&format!("{base}  - {{as: qz, encoding: f33le}}\n")).unwrap_err();
    assert!(
        e.contains("fields[3].encoding") && e.contains("f33le"),
        "{e}"
    );
    let e = Layout::parse(base).unwrap_err();
    assert!(e.contains("fields") && e.contains("quaternion"), "{e}");
    let e = Layout::parse(&format!("{base}  - {{as: qz, encoding: decimal}}\n")).unwrap_err();
    assert!(e.contains("fields[3].encoding"), "{e}");
    let e = Layout::parse(&format!(
        "{base}  - {{as: qz, encoding: f32le}}\nchecksum: {{kind: md5}}\n"
    ))
    .unwrap_err();
    assert!(e.contains("checksum.kind") && e.contains("md5"), "{e}");
    let e = Layout::parse(&format!("{base}  - {{as: qz, encoding: f32le}}\nfps: 3\n")).unwrap_err();
    assert!(e.contains("fps"), "{e}");
    let e = Layout::parse("layout: 2\nframe: text\nfields: []\n").unwrap_err();
    assert!(e.starts_with("layout:"), "{e}");
    let text = "layout: 1\nframe: text\nfields:\n  - {as: yaw, encoding: decimal}\n  - {as: pitch, encoding: decimal}\n  - {as: roll, encoding: decimal}\n";
    assert!(Layout::parse(text).unwrap_err().starts_with("euler:"));
    assert!(
        Layout::parse(&format!("{text}euler: {{order: zyz, unit: deg}}\n"))
            .unwrap_err()
            .starts_with("euler.order")
    );
    Layout::parse(&format!("{text}euler: {{order: xyz, unit: rad}}\n")).unwrap();
}

/// Values by hand: 0x3F800000 is 1.0, 0x3F000000 0.5, 0xBF000000 −0.5, 0x42B40000 90.0.
#[test]
fn data_matrix_rows_decode_by_type() {
    let m = shipped("paper004_data_matrix.yaml");
    let text = b"1 1 2 3F800000 00000000 00000000 00000000\n\
                 3 1 1 42B40000 00000000 00000000\r\n\
                 \n\
                 2 0 2 3F000000 3F000000 BF000000 3F000000\n\
                 2 1 7 3F800000\n\
                 2 1 2 3F80000 00000000 00000000 00000000\n\
                 2 1 2 3F800000 00000000 00000000";
    let d = decode_all(&m, &[text]);
    assert_eq!(d.frames.len(), 3, "{d:?}");
    assert_eq!(
        (
            d.frames[0].get(Meaning::Sensor),
            d.frames[0].get(Meaning::Qw)
        ),
        (Some(1.0), Some(1.0))
    );
    assert_eq!(
        (d.frames[1].kind, d.frames[1].get(Meaning::Yaw)),
        (Some(1), Some(90.0))
    );
    assert_eq!(d.frames[1].line, 2);
    assert_eq!(
        (
            d.frames[2].get(Meaning::Valid),
            d.frames[2].get(Meaning::Qz)
        ),
        (Some(0.0), Some(0.5))
    );
    assert_eq!(d.frames[2].get(Meaning::Qy), Some(-0.5));
    let bad: Vec<(u64, &str)> = d.bad.iter().map(|b| (b.line, b.reason.as_str())).collect();
    assert_eq!(bad.len(), 3, "{bad:?}");
    assert_eq!(bad[0], (5, "unknown type 7"));
    assert!(bad[1].0 == 6 && bad[1].1.contains("`3F80000`"), "{bad:?}");
    assert!(bad[2].0 == 7 && bad[2].1.contains("3 values"), "{bad:?}");
    // Euler angles compose as declared: yaw 90° about z turns x onto y.
    let q = m.orientation(&d.frames[1]).unwrap().unwrap();
    assert!((q * Vector3::x() - Vector3::y()).norm() < 1e-12);
}

#[test]
fn binary_frames_resynchronise_after_a_bad_one() {
    let e = shipped("esp32_struct.yaml");
    let good = esp32_frame(
        4,
        10_000,
        [1.0, 0.0, 0.0, 0.0],
        [100, -200, 300],
        [0, 0, 2048],
    );
    let mut bad = esp32_frame(5, 20_000, [0.5, 0.5, 0.5, 0.5], [1, 2, 3], [4, 5, 6]);
    bad[10] ^= 0x40;
    let mut stream = b"junk".to_vec();
    stream.extend(&good);
    stream.extend(&bad);
    stream.extend(&good);
    stream.extend(&good[..20]);
    let d = decode_all(&e, &[&stream]);
    assert_eq!(d.frames.len(), 2);
    assert_eq!(d.frames[0].offset, 4);
    assert_eq!(d.frames[1].offset, 4 + 2 * 37);
    let f = &d.frames[0];
    assert_eq!(f.get(Meaning::Time), Some(10_000.0));
    assert_eq!(f.get(Meaning::Gy), Some(-200.0 * 0.06103515625));
    assert_eq!(f.get(Meaning::Az), Some(1.0));
    assert_eq!(d.bad[0].offset, 4 + 37);
    assert!(d.bad[0].reason.starts_with("bad checksum"), "{:?}", d.bad);
    assert_eq!(
        d.bad.last().unwrap().reason,
        "an incomplete frame at the end"
    );
    assert_eq!((d.skipped_bytes, d.first_skipped_offset), (4 + 36, Some(0)));
}

proptest! {
    /// Any bytes, in any chunks: no panic, the same frames as read at once, and the decoder never
    /// holds more than a frame and a chunk.
    #[test]
    fn any_bytes_in_any_chunks_decode_the_same(
        bytes in proptest::collection::vec(any::<u8>(), 0..600),
        cuts in proptest::collection::vec(0usize..600, 0..8),
        frames in proptest::collection::vec((any::<u8>(), any::<u32>(), any::<i16>()), 0..4),
    ) {
        let e = shipped("esp32_struct.yaml");
        let m = shipped("paper004_data_matrix.yaml");
        let mut stream = bytes.clone();
        for (i, (s, t, g)) in frames.iter().enumerate() {
            let at = (i * 97) % (stream.len() + 1);
            let f = esp32_frame(*s, *t, [0.5; 4], [*g; 3], [1; 3]);
            stream.splice(at..at, f);
        }
        for layout in [&e, &m] {
            let whole = decode_all(layout, &[&stream]);
            let mut cuts = cuts.clone();
            cuts.push(0);
            cuts.push(stream.len());
            cuts.sort_unstable();
            let chunks: Vec<&[u8]> = cuts
                .windows(2)
                .map(|w| &stream[w[0].min(stream.len())..w[1].min(stream.len())])
                .collect();
            let mut decoder = Decoder::new();
            let mut out = Decoded::default();
            for c in &chunks {
                decoder.push(layout, c, &mut out);
                prop_assert!(decoder.buffered() <= layout.max_frame.max(MAX_LINE_BYTES) + c.len());
            }
            decoder.finish(layout, &mut out);
            prop_assert_eq!(&out, &whole);
        }
        // Every inserted frame that no other bytes overlap is found.
        let whole = decode_all(&e, &[&stream]);
        prop_assert!(whole.frames.len() <= frames.len() + stream.len() / 37);
        // Live: the same bytes as CSV lines, whatever the chunks: no panic, one line a frame
        // with an orientation, after one header.
        for layout in [e, m] {
            let mut lines = CsvLines::new(std::sync::Arc::new(layout), "port");
            let mut out = Vec::new();
            for c in stream.chunks(cuts.first().copied().unwrap_or(7).max(1)) {
                lines.push(c, 0.5, &mut out);
            }
            lines.finish(1.0, &mut out);
            for line in out.iter().skip(1) {
                prop_assert!(std::str::from_utf8(line).is_ok());
            }
        }
    }
}
