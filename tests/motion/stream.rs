//! A stream equals the whole take: the bundled samples and a real take (the x-IMU3 lower body in
//! ../shared/data), fed one row at a time with the rows shuffled within 100 ms, through the
//! reorder buffer and the pipeline's incremental cores, give the same frames (within 1e-9 per
//! quaternion component) as the whole-take conversion in causal mode, which runs on the same
//! cores. The default (zero-phase) conversion is held byte-identical by scripts/golden.sh.

use crate::common;

use imubake::anim::{Animation, Pose};
use imubake::mapping::{Mapping, MappingFile, load_mapping};
use imubake::pipeline::stream::{PoseStream, StreamStatus};
use imubake::pipeline::{PipelineOptions, run};
use imubake::read::stream::{LineFormat, LineStream};
use imubake::read::{ReadOptions, read_take};
use imubake::rig::load_rig;
use imubake::take::{OrientationTrack, Take};
use std::path::{Path, PathBuf};

fn repo(p: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(p)
}

fn mapping(path: &Path) -> Mapping {
    match load_mapping(path).unwrap() {
        MappingFile::Quaternion(m) => m,
        MappingFile::Legacy(_) => panic!("a quaternion mapping"),
    }
}

fn causal_options(fps: &str) -> PipelineOptions {
    PipelineOptions {
        fps: fps.parse().unwrap(),
        causal: true,
        ..PipelineOptions::default()
    }
}

/// A small deterministic generator (xorshift) for the shuffle.
struct Rng(u64);
impl Rng {
    fn unit(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Data lines shuffled so that each arrives up to `within_s` of stream time late: ordered by
/// their time plus a random delay in [0, within_s).
fn shuffled(lines: Vec<(f64, String)>, within_s: f64, seed: u64) -> Vec<String> {
    let mut rng = Rng(seed);
    let mut keyed: Vec<(f64, String)> = lines
        .into_iter()
        .map(|(t, l)| (t + within_s * rng.unit(), l))
        .collect();
    keyed.sort_by(|a, b| a.0.total_cmp(&b.0));
    keyed.into_iter().map(|(_, l)| l).collect()
}

/// The frames a stream of `header` then `rows` gives, one line at a time, what it said while
/// calibrating, and the stream at its end.
fn stream_frames(
    format: LineFormat,
    header: &[String],
    rows: &[String],
    mapping_path: &Path,
    options: &PipelineOptions,
) -> (Vec<Pose>, Vec<StreamStatus>, PoseStream) {
    let mapping = mapping(mapping_path);
    let rig = load_rig(mapping.rig.as_deref().unwrap_or("mixamo")).unwrap();
    let mut lines = LineStream::new(format, "stream", None);
    let mut samples = Vec::new();
    let mut line_no = 0;
    for line in header {
        line_no += 1;
        lines
            .push_line(line_no, line.as_bytes(), &mut samples)
            .unwrap();
    }
    let world = mapping.world.unwrap_or(lines.world());
    let mut poses = PoseStream::from_mapping(&rig, &mapping, mapping_path, world, options).unwrap();
    let mut frames = Vec::new();
    let mut statuses = Vec::new();
    let deliver = |lines: &LineStream,
                   poses: &mut PoseStream,
                   samples: &mut Vec<imubake::take::StreamSample>,
                   frames: &mut Vec<Pose>| {
        let ids = lines.take().unwrap().sensor_ids().to_vec();
        for s in samples.drain(..) {
            if let Some(i) = poses.sensor_index(&ids[s.sensor.index()]) {
                poses.push(
                    i,
                    s.t_s,
                    s.value.orientation().expect("orientation rows"),
                    &mut |p: &Pose| frames.push(p.clone()),
                );
            }
        }
    };
    for row in rows {
        line_no += 1;
        lines
            .push_line(line_no, row.as_bytes(), &mut samples)
            .unwrap();
        deliver(&lines, &mut poses, &mut samples, &mut frames);
        statuses.push(poses.status());
    }
    lines.finish(&mut samples).unwrap();
    deliver(&lines, &mut poses, &mut samples, &mut frames);
    poses
        .finish(&mut |p: &Pose| frames.push(p.clone()))
        .unwrap();
    (frames, statuses, poses)
}

fn whole_take(take: &Take, mapping_path: &Path, options: &PipelineOptions) -> Animation {
    let mapping = mapping(mapping_path);
    let rig = load_rig(mapping.rig.as_deref().unwrap_or("mixamo")).unwrap();
    run(take, &rig, &mapping, mapping_path, options)
        .unwrap()
        .animation
}

fn assert_same(stream: &[Pose], whole: &Animation) {
    assert_eq!(stream.len(), whole.frames(), "frame count");
    let mut worst: f64 = 0.0;
    for (n, pose) in stream.iter().enumerate() {
        assert_eq!(pose.frame, n as u64);
        for (j, q) in pose.local.iter().enumerate() {
            let w = whole.local(j)[n];
            for c in 0..4 {
                worst = worst.max((q.coords[c] - w.coords[c]).abs());
            }
        }
        assert!((pose.root - whole.root_positions()[n]).norm() < 1e-12);
    }
    assert!(worst <= 1e-9, "worst component difference {worst:e}");
    eprintln!(
        "{} frames, worst component difference {worst:e}",
        stream.len()
    );
}

/// The data lines of a text capture with each one's time, and the lines before them.
fn split_lines(
    text: &str,
    is_data: impl Fn(&str) -> Option<f64>,
) -> (Vec<String>, Vec<(f64, String)>) {
    let mut header = Vec::new();
    let mut rows = Vec::new();
    for line in text.lines() {
        match is_data(line) {
            Some(t) => rows.push((t, line.to_string())),
            None if rows.is_empty() => header.push(line.to_string()),
            // Debug text among the data is delivered where it stands.
            None => rows.push((rows.last().map_or(0.0, |r| r.0), line.to_string())),
        }
    }
    (header, rows)
}

#[test]
fn the_walk_sample_streamed_row_by_row_equals_the_whole_take() {
    let path = repo("samples/walk.csv");
    let mapping_path = repo("mappings/paper000_16imu_mixamo.json");
    let options = causal_options("60");
    let take = read_take(&path, &ReadOptions::default()).unwrap();
    let whole = whole_take(&take, &mapping_path, &options);
    let text = std::fs::read_to_string(&path).unwrap();
    let (header, rows) = split_lines(&text, |l| {
        l.split(',').next().and_then(|t| t.parse::<f64>().ok())
    });
    let rows = shuffled(rows, 0.1, 2026);
    let (frames, statuses, _) = stream_frames(
        LineFormat::ImubakeCsv,
        &header,
        &rows,
        &mapping_path,
        &options,
    );
    assert_same(&frames, &whole);
    // While the subject holds the pose (the first second), the stream says so and emits nothing.
    match statuses[0] {
        StreamStatus::Calibrating { left_s } => assert!(left_s > 0.8 && left_s <= 1.0, "{left_s}"),
        other => panic!("{other:?}"),
    }
    assert!(matches!(
        statuses.last(),
        Some(StreamStatus::Running { .. })
    ));
}

#[test]
fn the_sou_sample_streamed_row_by_row_equals_the_whole_take() {
    let path = repo("samples/sou_wave.log");
    let mapping_path = repo("samples/sou_wave.mapping.json");
    let mut options = causal_options("30");
    options.smoothing = "butterworth:cutoff=5"
        .parse::<imubake::smooth::Method>()
        .map(|m| imubake::smooth::Smoothing {
            method: m,
            bones: Default::default(),
        })
        .unwrap();
    let take = read_take(&path, &ReadOptions::default()).unwrap();
    let whole = whole_take(&take, &mapping_path, &options);
    let text = std::fs::read_to_string(&path).unwrap();
    let (header, rows) = split_lines(&text, |l| {
        imubake::read::sou::parse_line(l.as_bytes())
            .ok()
            .map(|(ms, _, _)| ms as f64 / 1000.0)
    });
    let rows = shuffled(rows, 0.1, 7);
    let (frames, _, _) = stream_frames(LineFormat::Sou, &header, &rows, &mapping_path, &options);
    assert_same(&frames, &whole);
}

#[test]
fn a_real_take_streamed_row_by_row_equals_the_whole_take() {
    let Some(session) = common::shared("fullbody/xio_lower_body_7imu") else {
        return;
    };
    let mapping_path = repo("mappings/xio_lower_body_7imu_mixamo.json");
    let options = causal_options("60");
    let take = read_take(&session, &ReadOptions::default()).unwrap();
    // The take's orientation samples as imubake CSV rows (exact: Rust prints floats to
    // round-trip). The whole take is read from those rows too: its clock then starts at the first
    // orientation sample, as the stream's does (the session's own starts at its first sample of
    // any kind).
    let header = vec![
        format!("# world: {}", take.source().world),
        "time_s,sensor,qw,qx,qy,qz".to_string(),
    ];
    let mut rows = Vec::new();
    for sensor in take.sensors() {
        let Some(OrientationTrack::Quaternion(track)) = sensor.orientation() else {
            continue;
        };
        for (t, q) in track.iter() {
            rows.push((
                t,
                format!(
                    "{t:?},{},{:?},{:?},{:?},{:?}",
                    sensor.id(),
                    q.w,
                    q.i,
                    q.j,
                    q.k
                ),
            ));
        }
    }
    rows.sort_by(|a, b| a.0.total_cmp(&b.0));
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("xio.csv");
    let text: String = header
        .iter()
        .cloned()
        .chain(rows.iter().map(|r| r.1.clone()))
        .map(|l| l + "\n")
        .collect();
    std::fs::write(&csv, text).unwrap();
    let whole = whole_take(
        &read_take(&csv, &ReadOptions::default()).unwrap(),
        &mapping_path,
        &options,
    );
    let rows = shuffled(rows, 0.1, 99);
    let (frames, _, _) = stream_frames(
        LineFormat::ImubakeCsv,
        &header,
        &rows,
        &mapping_path,
        &options,
    );
    assert_same(&frames, &whole);
}

/// Live cannot refuse a subject standing in front of it (issue 47): the walk streamed with a
/// mapping that declares no forward axis — nothing gives the heading before the first frame,
/// since a stream does not wait for the walk — keeps streaming with the sensors' north and says so
/// loudly with the ways out; then, as the knees and elbows flex (issue 48), the hinges give a sure
/// heading: said with its stream time, no longer unsure (`live` then sends VMC's "calibrated"),
/// and from then on the body faces as with the shipped mapping, whose pelvis declares its forward
/// axis (two estimates: within their uncertainties' sum).
#[test]
fn a_stream_with_an_unknown_heading_goes_on_and_says_so() {
    let path = repo("samples/walk.csv");
    let text = std::fs::read_to_string(&path).unwrap();
    let (header, rows) = split_lines(&text, |l| {
        l.split(',').next().and_then(|t| t.parse::<f64>().ok())
    });
    let rows: Vec<String> = rows.into_iter().map(|(_, line)| line).collect();
    let declared = repo("mappings/paper000_16imu_mixamo.json");
    let dir = tempfile::tempdir().unwrap();
    let mut json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&declared).unwrap()).unwrap();
    json["sensors"]["pelvis"]
        .as_object_mut()
        .unwrap()
        .remove("forward");
    let undeclared = dir.path().join("no_forward.json");
    std::fs::write(&undeclared, json.to_string()).unwrap();
    let options = causal_options("60");
    let stream = |m: &Path| stream_frames(LineFormat::ImubakeCsv, &header, &rows, m, &options);
    let (frames, _, sure) = stream(&declared);
    assert!(!sure.heading_unsure());
    let (unsure_frames, statuses, unsure) = stream(&undeclared);
    assert_eq!(unsure_frames.len(), frames.len());
    assert!(matches!(
        statuses.last(),
        Some(StreamStatus::Running { .. })
    ));
    let said = unsure.warnings().join("\n");
    assert!(
        said.contains("HEADING UNKNOWN")
            && said.contains("calibration.second")
            && said.contains("knees and elbows"),
        "{said}"
    );
    // Sure from the hinges, from a stream time the warnings give.
    assert!(!unsure.heading_unsure(), "{said}");
    let (declared_c, hinges_c) = (sure.calibration().unwrap(), unsure.calibration().unwrap());
    assert_eq!(hinges_c.heading_source.label(), "hinges");
    let from_s = hinges_c
        .heading_from_s
        .expect("refined as the take went on");
    assert!(said.contains(&format!("from {from_s:.3} s on")), "{said}");
    let window_end = 1.0; // the shipped mapping's calibration: the first second
    eprintln!(
        "sure from {from_s:.2} s: {:.2}° (±{:.1}°) against {:.2}° (±{:.1}°) declared",
        hinges_c.heading.scaled_axis().y.to_degrees(),
        hinges_c.heading_uncertainty_deg,
        declared_c.heading.scaled_axis().y.to_degrees(),
        declared_c.heading_uncertainty_deg
    );
    assert!(from_s > window_end && from_s < window_end + 6.0, "{from_s}");
    let apart = hinges_c.heading.angle_to(&declared_c.heading).to_degrees();
    assert!(
        apart <= hinges_c.heading_uncertainty_deg + declared_c.heading_uncertainty_deg,
        "{apart}°"
    );
    // Every joint turns alike once the heading is sure (after the smoother has settled); before,
    // the knees and elbows flexed about axes turned by the heading's error (a rotation since
    // calibration conjugated by it; the hips, barely turning since, cannot show it).
    let worst = |a: &Pose, b: &Pose| {
        a.local
            .iter()
            .zip(&b.local)
            .map(|(x, y)| x.angle_to(y).to_degrees())
            .fold(0.0, f64::max)
    };
    let worst_over = |keep: &dyn Fn(f64) -> bool| {
        frames
            .iter()
            .zip(&unsure_frames)
            .filter(|(f, _)| keep(f.time_s))
            .map(|(a, b)| worst(a, b))
            .fold(0.0, f64::max)
    };
    let before = worst_over(&|t| t > window_end && t < from_s);
    let after = worst_over(&|t| t > from_s + 0.5);
    eprintln!("joints apart: up to {before:.1}° before, {after:.2}° after");
    assert!(before > 10.0, "{before}°");
    assert!(after <= 2.0 * apart + 1.0, "{after}° against {apart}°");
}
