//! Property tests: no reader panics on any input, and the SOU line check is exactly the paper's
//! regular expression (checked against the `regex` crate, an independent implementation).

use imubake::read::{ReadOptions, detect_bytes, imubake_csv, sou, witmotion, xsens_mvnx};

/// A small valid MVNX document (two sensors, a calibration frame, three normal frames).
const MVNX: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<mvnx xmlns="http://www.xsens.com/mvn/mvnx" version="4">
<subject label="s" frameRate="60" segmentCount="1" configuration="Custom">
<sensors><sensor label="Pelvis"/><sensor label="T8"/></sensors>
<frames>
<frame time="0" type="tpose"><orientation>1 0 0 0</orientation></frame>
<frame time="0" index="0" type="normal"><footContacts>1 1 0 0</footContacts><sensorOrientation>1 0 0 0 0.5 0.5 0.5 0.5</sensorOrientation></frame>
<frame time="17" index="1" type="normal"><footContacts>0 0 1 1</footContacts><sensorOrientation>0.7071 0.7071 0 0 0.5 0.5 0.5 0.5</sensorOrientation></frame>
<frame time="33" index="2" type="normal"><sensorOrientation>0 1 0 0 1 0 0 0</sensorOrientation></frame>
</frames>
</subject>
</mvnx>
"#;
use proptest::prelude::*;
use std::path::Path;

const PAPER_REGEX: &str = r"^[0-9]+,[a-zA-Z0-9]+(,[ \-0-9\.]+){6}$";

fn sou_like_line() -> impl Strategy<Value = String> {
    // Mostly near-valid lines over the characters that matter, so both outcomes occur often.
    proptest::string::string_regex(r"[0-9]{0,3}(,[A-Za-z0-9_ ]{0,3}){0,1}(,[ \-0-9\.a]{0,4}){0,8}")
        .expect("valid strategy regex")
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn sou_check_equals_the_paper_regex(line in sou_like_line()) {
        let re = regex::Regex::new(PAPER_REGEX).unwrap();
        prop_assert_eq!(sou::format_problem(line.as_bytes()).is_none(), re.is_match(&line), "{:?}", line);
    }

    #[test]
    fn sou_reader_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..2048)) {
        let _ = sou::read_from(&bytes[..], Path::new("fuzz.log"), &ReadOptions::default());
        let _ = detect_bytes(&bytes);
    }

    /// MVNX: arbitrary bytes, and valid documents edited byte by byte (the XML parser, the
    /// numbers, the frame bookkeeping): a take whose tracks hold their invariants, or an error.
    #[test]
    fn mvnx_reader_never_panics(
        bytes in proptest::collection::vec(any::<u8>(), 0..1024),
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>(), 0u8..3), 0..12),
    ) {
        let _ = xsens_mvnx::read_from(&bytes[..], Path::new("fuzz.mvnx"), &ReadOptions::default());
        let mut doc = MVNX.as_bytes().to_vec();
        for (index, byte, op) in edits {
            if doc.is_empty() { doc.push(byte); continue; }
            let i = index.index(doc.len());
            match op {
                0 => doc[i] = byte,
                1 => doc.insert(i, byte),
                _ => { doc.remove(i); }
            }
        }
        if let Ok(take) = xsens_mvnx::read_from(&doc[..], Path::new("m.mvnx"), &ReadOptions::default()) {
            for s in take.sensors() {
                let times = s.primary_times_s();
                prop_assert!(times.windows(2).all(|w| w[0] < w[1]));
                prop_assert!(times.iter().all(|t| t.is_finite() && *t >= 0.0));
            }
        }
    }

    /// WitMotion: arbitrary bytes (and valid packets among them) decode to the same packets
    /// whatever pieces they arrive in, and a take of them is a take or an error, never a panic.
    #[test]
    fn witmotion_decoding_is_the_same_in_any_pieces(
        noise in proptest::collection::vec(any::<u8>(), 0..400),
        packets in proptest::collection::vec((0x50u8..0x5B, any::<[u8; 8]>(), any::<bool>()), 0..40),
        cuts in proptest::collection::vec(0usize..64, 0..20),
        rate in prop_oneof![Just(None), Just(Some(100.0))],
    ) {
        let mut bytes = noise;
        for (kind, data, corrupt) in packets {
            let mut p = vec![0x55, kind];
            p.extend_from_slice(&data);
            let sum = p.iter().fold(0u8, |s, &b| s.wrapping_add(b));
            p.push(if corrupt { sum.wrapping_add(1) } else { sum });
            bytes.extend(p);
        }
        let mut whole = witmotion::Decoder::new();
        let mut all = Vec::new();
        whole.push(&bytes, &mut all);
        let mut pieces = witmotion::Decoder::new();
        let mut got = Vec::new();
        let mut rest = &bytes[..];
        for cut in cuts {
            let (a, b) = rest.split_at(cut.min(rest.len()));
            pieces.push(a, &mut got);
            rest = b;
        }
        pieces.push(rest, &mut got);
        prop_assert_eq!(&all, &got);
        prop_assert_eq!(whole.bad_checksums, pieces.bad_checksums);
        let options = ReadOptions { rate_hz: rate, ..ReadOptions::default() };
        let recordings = [witmotion::Recording { id: "a".into(), bytes: &bytes }];
        if let Ok(take) = witmotion::take_of(&recordings, Path::new("w.bin"), &options) {
            for s in take.sensors() {
                let times = s.primary_times_s();
                prop_assert!(times.windows(2).all(|w| w[0] < w[1]));
            }
        }
        let mut lines = witmotion::CsvLines::new("a");
        let mut out = Vec::new();
        lines.push(&bytes, 0.0, &mut out);
        lines.finish(1.0, &mut out);
    }

    #[test]
    fn csv_reader_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..2048)) {
        let _ = imubake_csv::read_from(&bytes[..], Path::new("fuzz.csv"), &ReadOptions::default());
    }

    /// What a live session receives: any datagram or serial read is split into lines and fed to
    /// a line stream of either format (after a header, for CSV) and to the VMC request check,
    /// never panicking; the stream keeps its invariants (times increase per sensor).
    #[test]
    fn live_inputs_never_panic(
        chunks in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..300), 0..8),
        text in proptest::string::string_regex(r"([0-9]{1,6},N[0-9],[-0-9., ]{0,40}\n|[0-9.]{1,5},s[0-9],[-0-9., ]{0,30}\n|# calibrate t=[-0-9.a]{0,6}\n){0,12}").unwrap(),
        spec in ".{0,40}",
    ) {
        use imubake::live::source::{Allow, LineSplitter, SourceSpec};
        use imubake::read::stream::{LineFormat, LineStream};
        let _ = spec.parse::<SourceSpec>();
        let _ = spec.parse::<Allow>();
        for format in [LineFormat::Sou, LineFormat::ImubakeCsv] {
            let mut stream = LineStream::new(format, "fuzz", None);
            let mut samples = Vec::new();
            let mut n = 0;
            if format == LineFormat::ImubakeCsv {
                stream.push_line(1, b"time_s,sensor,qw,qx,qy,qz", &mut samples).unwrap();
                n = 1;
            }
            let mut split = LineSplitter::default();
            let mut lines = Vec::new();
            for c in chunks.iter().map(|c| c.as_slice()).chain(std::iter::once(text.as_bytes())) {
                prop_assert!(!imubake::live::vmc::is_calibration_request(c) || c.starts_with(b"/VMC") || c.starts_with(b"#bundle"));
                split.push(c, &mut lines);
            }
            split.finish(&mut lines);
            for l in &lines {
                n += 1;
                prop_assert!(l.len() <= imubake::live::source::MAX_LINE);
                // A clock reset is an error, anything else a sample or a dropped line.
                let _ = stream.push_line(n, l, &mut samples);
            }
            let _ = stream.finish(&mut samples);
            let mut last = std::collections::HashMap::new();
            for s in &samples {
                prop_assert!(s.t_s.is_finite());
                if let Some(prev) = last.insert(s.sensor.index(), s.t_s) {
                    prop_assert!(s.t_s > prev, "{} after {}", s.t_s, prev);
                }
            }
        }
    }

    /// `compare`'s angle tables: any text is a table or an error naming a line, never a panic.
    #[test]
    fn angle_table_reader_never_panics(
        text in proptest::string::string_regex(r"(frame,)?time_s(,[a-z_]{0,6}){0,3}\n([-0-9.ena, ]{0,16}\n){0,6}").unwrap(),
        bytes in proptest::collection::vec(any::<u8>(), 0..512),
    ) {
        for t in [text.as_str(), &String::from_utf8_lossy(&bytes)] {
            match imubake::analysis::AngleTable::parse_csv(t, Path::new("fuzz.csv")) {
                Ok(table) => {
                    prop_assert!(table.rows() > 0);
                    prop_assert!(table.time_s().windows(2).all(|w| w[0] < w[1]));
                    for n in table.names() {
                        prop_assert_eq!(table.column(n).unwrap().len(), table.rows());
                    }
                }
                Err(e) => prop_assert!(e.to_string().starts_with("fuzz.csv: line "), "{}", e),
            }
        }
    }

    /// Arbitrary edits of valid logs: every outcome is a take or an error, and a take's tracks
    /// keep their invariants (strictly increasing finite times starting at 0, unit quaternions).
    #[test]
    fn mutated_logs_give_takes_that_hold_invariants(
        which in 0usize..2,
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>(), 0u8..3), 0..40),
        skip_seconds in prop_oneof![Just(0.0), 0.0f64..0.2],
    ) {
        let base: &[u8] = if which == 0 {
            b"1000,N0,10,1,2,20,3,4\n1040,N0,11,1,2,21,3,4\n1020,N1,1,2,3,4,5,6\n1060,N1,1,2,3,4,5,6\n1100,N0,350,89.9,-179,0,0,0\n"
        } else {
            b"# world: nwu\ntime_s,sensor,qw,qx,qy,qz,gx_dps,gy_dps,gz_dps,ax_g,ay_g,az_g\n0.0,a,1,0,0,0,1,2,3,0,0,1\n0.01,b,0,1,0,0,1,2,3,0,0,1\n0.02,a,0.5,0.5,0.5,0.5,1,2,3,0,0,1\n0.015,a,1,0,0,0,0,0,0,0,0,1\n"
        };
        let mut bytes = base.to_vec();
        for (index, byte, op) in edits {
            if bytes.is_empty() { bytes.push(byte); continue; }
            let i = index.index(bytes.len());
            match op {
                0 => bytes[i] = byte,
                1 => bytes.insert(i, byte),
                _ => { bytes.remove(i); }
            }
        }
        let options = ReadOptions { skip_seconds, ..ReadOptions::default() };
        let result = if which == 0 {
            sou::read_from(&bytes[..], Path::new("m.log"), &options)
        } else {
            imubake_csv::read_from(&bytes[..], Path::new("m.csv"), &options)
        };
        if let Ok(take) = result {
            let mut earliest = f64::INFINITY;
            for s in take.sensors() {
                let times = s.primary_times_s();
                prop_assert!(times.windows(2).all(|w| w[0] < w[1]));
                prop_assert!(times.iter().all(|t| t.is_finite() && *t >= 0.0));
                earliest = earliest.min(s.first_time_s());
                if let Some(o) = s.orientation() {
                    for q in o.to_quaternions().values() {
                        prop_assert!((q.into_inner().norm() - 1.0).abs() < 1e-9);
                    }
                }
            }
            prop_assert_eq!(earliest, 0.0);
        }
    }
}

#[test]
fn paper_regex_examples_by_hand() {
    let re = regex::Regex::new(PAPER_REGEX).unwrap();
    for (line, ok) in [
        ("1000,N0,1,2,3,4,5,6", true),
        ("1000,N0, -1.5,2,3,4,5,6", true),
        ("1000,N0,1--2,2,3,4,5,6", true),
        ("1000,N0,1,2,3,4,5", false),
        ("1000,N0,1,2,3,4,5,6,7", false),
        ("1000,N_0,1,2,3,4,5,6", false),
        ("-1000,N0,1,2,3,4,5,6", false),
        ("1000,N0,1e3,2,3,4,5,6", false),
        ("1000,N0,,2,3,4,5,6", false),
    ] {
        assert_eq!(re.is_match(line), ok, "{line}");
        assert_eq!(sou::format_problem(line.as_bytes()).is_none(), ok, "{line}");
    }
}

mod one_line_edits {
    //! Changing one data line of a valid take (any edit but inserting NUL bytes) costs at most
    //! that line's samples: every other sample keeps its sensor, value and time (issue 10). The
    //! one exception the rule cannot avoid is documented: when the edited line is itself a valid
    //! sample of a sensor at a time that sensor already has, the two cannot be told apart and the
    //! first in the file is kept.

    use imubake::read::{ReadOptions, imubake_csv, sou};
    use imubake::take::{OrientationTrack, Take};
    use proptest::prelude::*;
    use std::collections::BTreeMap;
    use std::path::Path;

    /// (sensor, time in µs on the source's own clock) → the sample's values.
    type Samples = BTreeMap<(String, i64), [u64; 4]>;

    fn source_zero_s(take: &Take) -> f64 {
        let text = &take.source().start_timestamp;
        let (value, unit) = text.split_once(' ').unwrap();
        let v: f64 = value.parse().unwrap();
        match unit {
            "s" => v,
            "ms" => v * 1e-3,
            _ => panic!("unexpected unit in {text}"),
        }
    }

    fn samples(take: &Take) -> Samples {
        let zero = source_zero_s(take);
        let mut out = Samples::new();
        for s in take.sensors() {
            let key = |t: f64| (s.id().to_string(), ((t + zero) * 1e6).round() as i64);
            match s.orientation() {
                Some(OrientationTrack::Quaternion(track)) => {
                    for (t, q) in track.iter() {
                        let q = q.into_inner();
                        out.insert(key(t), [q.w, q.i, q.j, q.k].map(f64::to_bits));
                    }
                }
                Some(OrientationTrack::YawPitchRollDeg(track)) => {
                    for (t, v) in track.iter() {
                        out.insert(key(t), [v.yaw, v.pitch, v.roll, 0.0].map(f64::to_bits));
                    }
                }
                None => {}
            }
        }
        out
    }

    /// The (sensor, µs) keys a line names when it reads as data: CSV `time_s,sensor,…`, SOU
    /// `ms,ID,…` (two sensors). Loose on purpose: a key named by a line that is then dropped
    /// only widens what the test allows for that line.
    fn keys_of_line(line: &str, sou_format: bool) -> Vec<(String, i64)> {
        let fields: Vec<&str> = line.trim_end_matches('\r').split(',').collect();
        if fields.len() < 2 {
            return Vec::new();
        }
        let Ok(t) = fields[0].trim().parse::<f64>() else {
            return Vec::new();
        };
        if !t.is_finite() {
            return Vec::new();
        }
        // Readers trim ASCII whitespace around a field (not a vertical tab).
        let id = fields[1].trim_ascii();
        if sou_format {
            let us = (t * 1e3).round() as i64;
            vec![(format!("{id}_0"), us), (format!("{id}_1"), us)]
        } else {
            vec![(id.to_string(), (t * 1e6).round() as i64)]
        }
    }

    fn base(sou_format: bool) -> String {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let (file, lines) = if sou_format {
            ("samples/sou_wave.log", 240)
        } else {
            ("samples/walk.csv", 403)
        };
        let text = std::fs::read_to_string(root.join(file)).unwrap();
        text.lines().take(lines).map(|l| format!("{l}\n")).collect()
    }

    fn read(bytes: &[u8], sou_format: bool) -> Result<Take, String> {
        let r = if sou_format {
            sou::read_from(bytes, Path::new("e.log"), &ReadOptions::default())
        } else {
            imubake_csv::read_from(bytes, Path::new("e.csv"), &ReadOptions::default())
        };
        r.map_err(|e| e.to_string())
    }

    /// An edit of one line: substitute, insert or delete a byte (never a NUL), cut the line, or
    /// replace one digit with another (times and values stay numbers: the hard case).
    #[derive(Debug, Clone)]
    enum Edit {
        Substitute(prop::sample::Index, u8),
        Insert(prop::sample::Index, u8),
        Delete(prop::sample::Index),
        Cut(prop::sample::Index),
        Digit(prop::sample::Index, u8),
    }

    fn edit() -> impl Strategy<Value = Edit> {
        let byte = 1u8..=255;
        prop_oneof![
            (any::<prop::sample::Index>(), byte.clone()).prop_map(|(i, b)| Edit::Substitute(i, b)),
            (any::<prop::sample::Index>(), byte).prop_map(|(i, b)| Edit::Insert(i, b)),
            any::<prop::sample::Index>().prop_map(Edit::Delete),
            any::<prop::sample::Index>().prop_map(Edit::Cut),
            (any::<prop::sample::Index>(), 0u8..10).prop_map(|(i, d)| Edit::Digit(i, d)),
            (any::<prop::sample::Index>(), 0u8..10).prop_map(|(i, d)| Edit::Digit(i, d)),
        ]
    }

    fn apply(line: &mut Vec<u8>, e: &Edit) {
        if line.is_empty() {
            if let Edit::Insert(_, b) | Edit::Substitute(_, b) = e {
                line.push(*b);
            }
            return;
        }
        match e {
            Edit::Substitute(i, b) => {
                let i = i.index(line.len());
                line[i] = *b;
            }
            Edit::Insert(i, b) => line.insert(i.index(line.len() + 1), *b),
            Edit::Delete(i) => {
                line.remove(i.index(line.len()));
            }
            Edit::Cut(i) => line.truncate(i.index(line.len())),
            Edit::Digit(i, d) => {
                let digits: Vec<usize> = (0..line.len())
                    .filter(|&k| line[k].is_ascii_digit())
                    .collect();
                if !digits.is_empty() {
                    line[digits[i.index(digits.len())]] = b'0' + d;
                }
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(600))]

        #[test]
        fn one_edited_line_costs_at_most_its_own_samples(
            sou_format in any::<bool>(),
            which in any::<prop::sample::Index>(),
            edits in proptest::collection::vec(edit(), 1..5),
        ) {
            let text = base(sou_format);
            let lines: Vec<&str> = text.lines().collect();
            // Data lines only: not the CSV's comments and header.
            let data: Vec<usize> = (0..lines.len())
                .filter(|&i| sou_format || !(lines[i].starts_with('#') || lines[i].starts_with("time_s")))
                .collect();
            let at = data[which.index(data.len())];
            let mut line = lines[at].as_bytes().to_vec();
            for e in &edits {
                apply(&mut line, e);
            }
            let edited_line = String::from_utf8_lossy(&line).into_owned();
            let mut bytes = Vec::new();
            for (i, l) in lines.iter().enumerate() {
                if i == at { bytes.extend_from_slice(&line); } else { bytes.extend_from_slice(l.as_bytes()); }
                bytes.push(b'\n');
            }
            let original = samples(&read(text.as_bytes(), sou_format).unwrap());
            let edited = read(&bytes, sou_format)
                .map_err(|e| TestCaseError::fail(format!("{e}\nedited line {}: {edited_line:?}", at + 1)))?;
            let edited = samples(&edited);
            // What the line may cost or add: its own samples, and what the edited text names.
            let mut allowed: Vec<(String, i64)> = keys_of_line(lines[at], sou_format);
            for piece in edited_line.split('\n') {
                allowed.extend(keys_of_line(piece, sou_format));
            }
            for (key, value) in &original {
                if allowed.contains(key) { continue; }
                prop_assert_eq!(edited.get(key), Some(value),
                    "sample {:?} lost or changed by editing line {} into {:?}", key, at + 1, edited_line);
            }
            for key in edited.keys() {
                prop_assert!(original.contains_key(key) || allowed.contains(key),
                    "sample {:?} appeared from editing line {} into {:?}", key, at + 1, edited_line);
            }
        }
    }
}
