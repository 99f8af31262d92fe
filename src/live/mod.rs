//! `imubake live`: sensors to a moving character in real time.
//!
//! Sources ([`source`]) send lines over one bounded channel to the session, which runs them
//! through the same code a file takes in causal mode: the readers' line parsers and cleaning
//! rules ([`crate::read::stream::LineStream`]) and the pipeline's incremental cores
//! ([`crate::pipeline::stream::PoseStream`]). Each frame goes out as a VMC bundle ([`vmc`]);
//! everything received is recorded as a take ([`record`]). `imubake setup` runs the same session
//! with a board ([`crate::setup`]) that sees every sample, and no mapping yet.
//!
//! Clock: a line keeps its own timestamp when one source sends it (a replayed file, a single
//! serial port); with several sources, whose devices' clocks differ, each data line is restamped
//! with the host's monotonic clock when it arrives (`--clock host`), as paper 002's driver does.
//! The recording holds the lines as the stream saw them, so converting it gives the same frames.

pub mod clock;
pub mod record;
pub mod source;
pub mod vmc;

use crate::anim::Pose;
use crate::convert::{ConvertError, Plan};
use crate::pipeline::stream::{PoseStream, StreamStatus};
use crate::read::stream::{HostStamps, LineFormat, LineStream, recorded_before_header};
use crate::take::{DroppedLines, LineReport, StreamSample, StreamValue};
use clock::{Judged, SourceClock};
use source::{Allow, Event, Link, SourceCounters, SourceSpec};
use std::net::{SocketAddr, UdpSocket};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{RecvTimeoutError, sync_channel};
use std::time::{Duration, Instant, SystemTime};

/// Where VMC goes by default (the Marionette's port).
pub const DEFAULT_VMC: &str = "127.0.0.1:39539";
/// Where calibration requests are heard by default (the Performer's port).
pub const DEFAULT_LISTEN: &str = "127.0.0.1:39540";

#[derive(Debug, thiserror::Error)]
pub enum LiveError {
    #[error("{0}")]
    Setup(#[from] ConvertError),
    /// The packet layout (`--layout`) cannot be read.
    #[error("{0}")]
    Layout(String),
    #[error("source `{source_name}`: {source}")]
    Source {
        source_name: String,
        #[source]
        source: std::io::Error,
    },
    #[error("{what} {addr}: {source}")]
    Network {
        what: &'static str,
        addr: SocketAddr,
        #[source]
        source: std::io::Error,
    },
    #[error("--record {}: {source}", .path.display())]
    Record {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A line the stream cannot go on from.
    #[error(transparent)]
    Line(#[from] crate::read::ReadError),
    /// The pose stream cannot be set up.
    #[error(transparent)]
    Stream(#[from] crate::pipeline::PipelineError),
    #[error(
        "rig `{0}` has no bones with Unity humanoid names for VMC (no `Hips`); name them in the rig file's `vmc_names:`"
    )]
    NoVmcNames(String),
}

impl crate::diagnostic::Diagnostic for LiveError {
    fn hint(&self) -> Option<&'static str> {
        match self {
            LiveError::Network { .. } => {
                Some("is another program using the port? (--vmc, --listen)")
            }
            LiveError::Source { .. } => Some("check --source (docs: live)"),
            _ => None,
        }
    }
}

/// Lines kept before the format is known (a device's boot messages), and their bytes at most;
/// more are not kept.
const MAX_EARLY_LINES: usize = 10_000;
const MAX_EARLY_BYTES: usize = 4 << 20;

/// A sensor silent this long (stream time, seconds) is said to be held at its last pose.
const STALE_NOTICE_S: f64 = 0.5;

/// Which clock data lines keep.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Clock {
    /// Each line's own timestamp.
    Source,
    /// The host's monotonic clock at arrival, since the session started, each sensor's stamps
    /// strictly rising ([`HostStamps`]).
    Host,
}

impl std::str::FromStr for Clock {
    type Err = String;
    fn from_str(s: &str) -> Result<Clock, String> {
        match s {
            "source" => Ok(Clock::Source),
            "host" => Ok(Clock::Host),
            _ => Err(format!("unknown `{s}`; expected source or host")),
        }
    }
}

/// A live session's settings, validated.
#[derive(Debug, Clone)]
pub struct LiveSettings {
    pub sources: Vec<SourceSpec>,
    /// The conversion's plan (mapping, rig, fps, smoothing, root, world …), run causal.
    pub plan: Arc<Plan>,
    /// Where VMC bundles go (`None`: not sent).
    pub vmc: Option<SocketAddr>,
    /// Where calibration requests are heard (`None`: not at all).
    pub listen: Option<SocketAddr>,
    pub record: Option<PathBuf>,
    pub allow: Allow,
    /// `None`: source for one source, host for several.
    pub clock: Option<Clock>,
    /// Read lines from the terminal: `c` asks for a calibration.
    pub keys: bool,
    /// The browser preview's poses and status (`--preview`; its server runs beside the session).
    pub preview: Option<Arc<crate::view::Preview>>,
    /// `imubake setup`: every sample goes to its board; the plan needs no mapping then (without
    /// one the session makes no poses).
    pub setup: Option<Arc<crate::setup::Setup>>,
    /// How far ahead of its latest a source's time may be and still be in step (seconds,
    /// [`clock::DEFAULT_HORIZON_S`] by default): a time further is a jump ([`clock`]).
    pub time_horizon_s: f64,
}

/// One sensor's figures on the status line.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorStatus {
    pub id: String,
    /// Samples per second over the last status period.
    pub rate_hz: f64,
    /// Seconds since its last sample (stream time).
    pub silent_s: f64,
}

/// What the session is doing, every half second.
#[derive(Debug, Clone, PartialEq)]
pub enum Phase {
    /// No data line yet.
    Waiting,
    /// Hold the calibration pose for this much longer.
    Calibrating {
        left_s: f64,
    },
    Running,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Status {
    pub elapsed_s: f64,
    pub phase: Phase,
    pub frames: u64,
    pub sensors: Vec<SensorStatus>,
    pub lines: u64,
    pub dropped_lines: u64,
    /// Lines lost before the session could read them (a burst of datagrams).
    pub overflowed: u64,
    /// Datagrams the system dropped before a `udp:` source read them (see
    /// [`source::SourceCounters::lost_datagrams`]).
    pub lost_datagrams: u64,
    /// Median and 99th percentile, milliseconds, of the last frames' latency: from the arrival
    /// of the batch holding the sample that completed a frame to its bundle's sending.
    pub latency_ms: Option<(f64, f64)>,
}

/// What the session says as it goes.
#[derive(Debug, Clone)]
pub enum Report {
    Status(Status),
    /// A line for the terminal: a source reconnecting, a warning of the stream, a calibration.
    Notice(String),
}

/// How a session ended.
#[derive(Debug, Clone)]
pub struct Summary {
    pub frames: u64,
    pub lines: u64,
    /// The lines dropped: the first reports whole (line numbers are the recording's), then
    /// counts by reason.
    pub dropped: DroppedLines,
    /// Lines lost before the session read them: at its channel (a burst it could not keep up
    /// with), or longer than [`source::MAX_LINE`] (`too_long`).
    pub overflowed: u64,
    /// Of `overflowed`, the lines longer than [`source::MAX_LINE`].
    pub too_long: u64,
    /// Datagrams the system dropped before a `udp:` source read them.
    pub lost_datagrams: u64,
    pub recording: Option<PathBuf>,
    pub warnings: Vec<String>,
    pub latency_ms: Option<(f64, f64)>,
}

/// Latencies of the last frames, for the median and the 99th percentile.
struct Latencies {
    ring: Vec<f64>,
    next: usize,
}

impl Latencies {
    const KEEP: usize = 4096;

    fn push(&mut self, ms: f64) {
        if self.ring.len() < Self::KEEP {
            self.ring.push(ms);
        } else {
            self.ring[self.next] = ms;
        }
        self.next = (self.next + 1) % Self::KEEP;
    }

    fn summary(&self) -> Option<(f64, f64)> {
        if self.ring.is_empty() {
            return None;
        }
        let mut v = self.ring.clone();
        v.sort_by(f64::total_cmp);
        let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
        Some((at(0.5), at(0.99)))
    }
}

/// The stages once the format (and so the world) is known.
struct Running {
    lines: LineStream,
    /// `None`: a setup session without a mapping (samples go to the board only).
    poses: Option<PoseStream>,
    /// The sensors' world (`--world`, else the mapping's, else the format's).
    world: crate::world::World,
    /// LineStream sensor index → PoseStream index (`None`: not mapped).
    index: Vec<Option<Option<usize>>>,
    /// Sensors whose raw readings could not be fused (left out).
    refused: Vec<bool>,
    /// What to say on the terminal (fusion's warnings and errors).
    notices: Vec<String>,
}

/// Runs a session until `stop` is set or every source has ended; `report` hears the status and
/// notices.
pub fn run(
    settings: &LiveSettings,
    stop: Arc<AtomicBool>,
    mut report: impl FnMut(Report),
) -> Result<Summary, LiveError> {
    // What the pose stream runs on; a setup session may have no mapping yet.
    let stream = match settings.plan.stream() {
        Ok((_, mapping, mapping_file, options)) => Some((
            mapping,
            mapping_file,
            crate::pipeline::PipelineOptions {
                causal: true,
                ..options.clone()
            },
        )),
        Err(_) if settings.setup.is_some() => None,
        Err(e) => return Err(e.into()),
    };
    let rig = settings.plan.rig();
    let skeleton = vmc::VmcSkeleton::new(rig);
    let vmc_out = match settings.vmc {
        Some(addr) => {
            let skeleton = skeleton
                .clone()
                .ok_or_else(|| LiveError::NoVmcNames(rig.name().to_string()))?;
            let local: SocketAddr = if addr.is_ipv4() {
                "0.0.0.0:0".parse().expect("an address")
            } else {
                "[::]:0".parse().expect("an address")
            };
            let socket = UdpSocket::bind(local)
                .and_then(|s| s.connect(addr).map(|()| s))
                .map_err(|source| LiveError::Network {
                    what: "--vmc",
                    addr,
                    source,
                })?;
            Some((socket, skeleton))
        }
        None => None,
    };
    // Each frame out: the VMC bundle and the browser preview, as asked.
    let send_out = |pose: &Pose| {
        if let Some((socket, skeleton)) = &vmc_out {
            let _ = socket.send(&skeleton.frame(pose, rig));
        }
        if let Some(preview) = &settings.preview {
            preview.pose(pose);
        }
    };
    let clock = settings.clock.unwrap_or(if settings.sources.len() > 1 {
        Clock::Host
    } else {
        Clock::Source
    });
    if let Some(dir) = &settings.record {
        for path in record::recover(dir).map_err(|source| LiveError::Record {
            path: dir.clone(),
            source,
        })? {
            report(Report::Notice(format!(
                "warning: a recording left by an earlier session that did not end is now {}",
                path.display()
            )));
        }
    }

    // The packet layout of `:layout` sources, read once (the plan checked it).
    let layout = match &settings.plan.settings().read.layout {
        Some(path) => Some(Arc::new(
            crate::read::layout::Layout::load(path)
                .map_err(|e| LiveError::Layout(e.to_string()))?,
        )),
        None => None,
    };
    let (tx, rx) = sync_channel::<Event>(1024);
    let mut counters = Vec::new();
    let mut threads = Vec::new();
    for (i, spec) in settings.sources.iter().enumerate() {
        let c = Arc::new(SourceCounters::default());
        counters.push(Arc::clone(&c));
        let link = Link {
            source: i,
            tx: tx.clone(),
            stop: Arc::clone(&stop),
            counters: c,
        };
        let thread = source::start(spec, link, settings.allow.clone(), layout.clone())?;
        // Not joined: a read of stdin cannot be interrupted (a pipe that stays open and silent
        // would hold the session's end forever); the thread ends with the process.
        if *spec != SourceSpec::Stdin {
            threads.push(thread);
        }
    }
    if let Some(addr) = settings.listen {
        let socket = UdpSocket::bind(addr).map_err(|source| LiveError::Network {
            what: "--listen",
            addr,
            source,
        })?;
        let _ = socket.set_read_timeout(Some(Duration::from_millis(100)));
        let tx = tx.clone();
        let stop = Arc::clone(&stop);
        let allow = settings.allow.clone();
        threads.push(std::thread::spawn(move || {
            let mut buf = vec![0u8; 65_536];
            while !stop.load(Ordering::Relaxed) {
                if let Ok((n, from)) = socket.recv_from(&mut buf)
                    && allow.admits(from.ip())
                    && vmc::is_calibration_request(&buf[..n])
                    && tx
                        .send(Event::Calibrate {
                            from: format!("VMC request from {from}"),
                        })
                        .is_err()
                {
                    return;
                }
            }
        }));
    }
    if settings.keys {
        // Not joined: a read of the terminal cannot be interrupted; it ends with the process.
        let tx = tx.clone();
        std::thread::spawn(move || {
            let stdin = std::io::stdin();
            let mut line = String::new();
            while std::io::BufRead::read_line(&mut stdin.lock(), &mut line).is_ok_and(|n| n > 0) {
                if line.trim().eq_ignore_ascii_case("c")
                    && tx
                        .send(Event::Calibrate {
                            from: "the terminal".into(),
                        })
                        .is_err()
                {
                    return;
                }
                line.clear();
            }
        });
    }
    drop(tx);

    let started = Instant::now();
    let stamp = record::stamp(SystemTime::now());
    let mut open = vec![true; settings.sources.len()];
    let mut host_stamps: Vec<HostStamps> = settings
        .sources
        .iter()
        .map(|_| HostStamps::default())
        .collect();
    let mut source_clocks: Vec<SourceClock> = settings
        .sources
        .iter()
        .map(|_| SourceClock::new(settings.time_horizon_s))
        .collect();
    // What the source clocks decided, by source, in arrival order; `one`: a line's.
    let mut judged: Vec<(usize, Judged)> = Vec::new();
    let mut one: Vec<Judged> = Vec::new();
    // When the lines being handled arrived (for the latency).
    let mut batch_at = Instant::now();
    // Lines the source clocks dropped (the streams' own drops are theirs).
    let mut clock_dropped = DroppedLines::default();
    let mut format: Option<LineFormat> = None;
    // Lines before the format is known (a SOU log's debug text), bounded.
    let mut early: Vec<Vec<u8>> = Vec::new();
    let mut early_bytes = 0usize;
    let mut early_full = false;
    let mut recorder: Option<record::Recorder> = None;
    let mut running: Option<Running> = None;
    let mut line_no: u64 = 0;
    let mut samples: Vec<StreamSample> = Vec::with_capacity(64);
    let mut frames: u64 = 0;
    let mut latencies = Latencies {
        ring: Vec::new(),
        next: 0,
    };
    let mut warned = 0usize;
    let mut last_status = Instant::now();
    let mut last_ok = Instant::now() - Duration::from_secs(2);
    let mut per_sensor: Vec<(u64, f64)> = Vec::new(); // samples this period, last time
    let mut pending_calibration = false;
    let mut silent: Vec<bool> = Vec::new();
    let name = PathBuf::from("live");

    let result: Result<(), LiveError> = (|| {
        // The last pass (`ending`) decides what the source clocks still hold.
        let mut ending = false;
        loop {
            let mut event = None;
            if open.iter().any(|o| *o) && !stop.load(Ordering::Relaxed) {
                match rx.recv_timeout(Duration::from_millis(50)) {
                    Ok(e) => event = Some(e),
                    Err(RecvTimeoutError::Timeout) => {}
                    Err(RecvTimeoutError::Disconnected) => ending = true,
                }
            } else {
                ending = true;
            }
            if ending {
                for (source, c) in source_clocks.iter_mut().enumerate() {
                    c.finish(&mut one);
                    judged.extend(one.drain(..).map(|j| (source, j)));
                }
                batch_at = Instant::now();
            }
            match event {
                Some(Event::Lines { source, lines, at }) => {
                    // The host's clock when the lines arrived, not when they are handled.
                    let arrived_s = at.saturating_duration_since(started).as_secs_f64();
                    batch_at = at;
                    for line in lines {
                        match clock {
                            Clock::Source => {
                                // A SOU line without a timestamp gets the host's on arrival.
                                let line = host_stamps[source]
                                    .stamp_untimed(&line, arrived_s)
                                    .unwrap_or(line);
                                source_clocks[source].judge(line, &mut one);
                            }
                            Clock::Host => one.push(Judged::Take {
                                line: host_stamps[source].stamp(&line, arrived_s).unwrap_or(line),
                                t_s: None,
                            }),
                        }
                        judged.extend(one.drain(..).map(|j| (source, j)));
                    }
                }
                Some(Event::Notice { source, text }) => {
                    report(Report::Notice(format!(
                        "{}: {text}",
                        settings.sources[source]
                    )));
                }
                Some(Event::Closed { source, error }) => {
                    open[source] = false;
                    source_clocks[source].finish(&mut one);
                    judged.extend(one.drain(..).map(|j| (source, j)));
                    batch_at = Instant::now();
                    report(Report::Notice(match error {
                        None => format!("{}: ended", settings.sources[source]),
                        Some(e) => format!("{}: ended: {e}", settings.sources[source]),
                    }));
                }
                Some(Event::Calibrate { from }) => {
                    pending_calibration = true;
                    report(Report::Notice(format!("calibration asked for ({from})")));
                }
                None => {}
            }
            for (source, judgement) in judged.drain(..) {
                let (line, dropped_because) = match judgement {
                    Judged::Take { line, .. } => (line, None),
                    Judged::Drop { line, reason } => (line, Some(reason)),
                    Judged::Notice(text) => {
                        report(Report::Notice(format!(
                            "warning: {}: {text}",
                            settings.sources[source]
                        )));
                        continue;
                    }
                };
                if format.is_none() {
                    let Some(f) = LineFormat::recognise(&line) else {
                        if early.len() < MAX_EARLY_LINES
                            && early_bytes + line.len() <= MAX_EARLY_BYTES
                        {
                            early_bytes += line.len();
                            early.push(line);
                        } else if !early_full {
                            early_full = true;
                            report(Report::Notice(format!(
                                "warning: {MAX_EARLY_LINES} lines (or {} MiB) and no SOU line \
                                 or imubake CSV header yet: later lines are neither read nor \
                                 recorded until one comes",
                                MAX_EARLY_BYTES >> 20
                            )));
                        }
                        continue;
                    };
                    format = Some(f);
                    if let Some(dir) = &settings.record {
                        let ext = if f == LineFormat::Sou { "log" } else { "csv" };
                        recorder =
                            Some(record::Recorder::start(dir, &stamp, ext).map_err(|source| {
                                LiveError::Record {
                                    path: dir.clone(),
                                    source,
                                }
                            })?);
                    }
                    let stream_name = recorder
                        .as_ref()
                        .map_or_else(|| name.clone(), |r| r.path().to_path_buf());
                    let mut lines = LineStream::new(f, stream_name, None);
                    early_bytes = 0;
                    for l in std::mem::take(&mut early) {
                        line_no += 1;
                        if let Some(r) = &mut recorder {
                            // A CSV's recording must read as one: text before its header is
                            // kept as a comment.
                            let recorded = match f {
                                LineFormat::ImubakeCsv => recorded_before_header(&l),
                                LineFormat::Sou => l.as_slice().into(),
                            };
                            r.line(&recorded).map_err(|e| record_error(settings, e))?;
                        }
                        lines.push_line(line_no, &l, &mut samples)?;
                    }
                    running = Some(start_running(lines, rig, stream.as_ref(), settings)?);
                }
                line_no += 1;
                if let Some(r) = &mut recorder {
                    r.line(&line).map_err(|e| record_error(settings, e))?;
                }
                if let Some(reason) = dropped_because {
                    clock_dropped.push(LineReport::new(None, line_no, reason, &line));
                    continue;
                }
                let Some(run) = &mut running else {
                    continue;
                };
                run.lines.push_line(line_no, &line, &mut samples)?;
                let at = batch_at;
                feed(
                    run,
                    settings.setup.as_deref(),
                    &mut samples,
                    &mut per_sensor,
                    &mut |pose: &Pose| {
                        frames += 1;
                        send_out(pose);
                        latencies.push(at.elapsed().as_secs_f64() * 1e3);
                    },
                );
            }
            if let Some(r) = &mut recorder {
                r.batch_done().map_err(|e| record_error(settings, e))?;
            }
            if pending_calibration {
                pending_calibration = false;
                if let Some(poses) = running.as_mut().and_then(|r| r.poses.as_mut()) {
                    let t = poses.latest_s().max(0.0);
                    match poses.recalibrate(t) {
                        Ok(left) => {
                            if let Some(r) = &mut recorder {
                                r.line(format!("# calibrate t={t:.6}").as_bytes())
                                    .map_err(|e| record_error(settings, e))?;
                                line_no += 1;
                            }
                            report(Report::Notice(format!(
                                "calibrating: hold the pose for {left:.1} s from t = {t:.3} s"
                            )));
                        }
                        Err(e) => report(Report::Notice(format!("cannot calibrate now: {e}"))),
                    }
                }
            }
            if let Some(run) = &mut running {
                if let Some(poses) = &mut run.poses {
                    for w in &poses.warnings()[warned.min(poses.warnings().len())..] {
                        report(Report::Notice(format!("warning: {w}")));
                    }
                    warned = poses.warnings().len();
                    for w in poses.take_fusion_warnings() {
                        report(Report::Notice(format!("warning: {w}")));
                    }
                }
                for n in run.notices.drain(..) {
                    report(Report::Notice(n));
                }
            }
            if let Some((socket, _)) = &vmc_out
                && last_ok.elapsed() >= Duration::from_secs(1)
            {
                let poses = running.as_ref().and_then(|r| r.poses.as_ref());
                let state = match poses.map(|p| p.status()) {
                    // A heading too unsure to trust: calibrated, but waiting for a better one.
                    Some(StreamStatus::Running { .. })
                        if poses.is_some_and(|p| p.heading_unsure()) =>
                    {
                        vmc::CalibrationState::WaitingForCalibrating
                    }
                    Some(StreamStatus::Running { .. }) => vmc::CalibrationState::Calibrated,
                    Some(StreamStatus::Calibrating { .. }) => vmc::CalibrationState::Calibrating,
                    None => vmc::CalibrationState::WaitingForCalibrating,
                };
                let _ = socket.send(&vmc::ok_message(state));
                last_ok = Instant::now();
            }
            if last_status.elapsed() >= Duration::from_millis(500) {
                let period = last_status.elapsed().as_secs_f64();
                last_status = Instant::now();
                let now = status(
                    started,
                    running.as_ref(),
                    frames,
                    line_no,
                    &counters,
                    &mut per_sensor,
                    period,
                    latencies.summary(),
                    clock_dropped.total(),
                );
                // A sensor that stops is held at its last pose (the resampler's rule): say so
                // once, and again when it returns.
                silent.resize(now.sensors.len(), false);
                for (s, was) in now.sensors.iter().zip(silent.iter_mut()) {
                    let is = s.silent_s > STALE_NOTICE_S && s.silent_s.is_finite();
                    if is && !*was {
                        report(Report::Notice(format!(
                            "warning: sensor `{}` is silent ({:.1} s): held at its last pose",
                            s.id, s.silent_s
                        )));
                    } else if !is && *was {
                        report(Report::Notice(format!("sensor `{}` is back", s.id)));
                    }
                    *was = is;
                }
                if let Some(preview) = &settings.preview {
                    preview_status(preview, &now);
                }
                report(Report::Status(now));
            }
            if ending {
                break;
            }
        }
        Ok(())
    })();
    stop.store(true, Ordering::Relaxed);
    // A source blocked sending into a full channel gets an error now, instead of waiting forever
    // for a session that has stopped reading.
    drop(rx);
    // The end: what the reorder buffer and the smoothers hold comes out, the recording closes.
    let mut warnings = Vec::new();
    if let Some(run) = &mut running {
        let mut send = |pose: &Pose| {
            frames += 1;
            send_out(pose);
        };
        let _ = run.lines.finish(&mut samples);
        feed(
            run,
            settings.setup.as_deref(),
            &mut samples,
            &mut per_sensor,
            &mut send,
        );
        if let Some(poses) = &mut run.poses {
            if let Err(e) = poses.finish(&mut send) {
                warnings.push(e.to_string());
            }
            warnings.extend(poses.warnings().iter().cloned());
        }
    }
    // Every stage's dropped lines, in line order: the source clocks', the line parsers', the
    // stream's.
    let dropped = match &running {
        Some(run) => {
            let mut parts = vec![&clock_dropped, run.lines.dropped_lines()];
            parts.extend(run.lines.take().map(|t| t.dropped_lines()));
            DroppedLines::merged(&parts)
        }
        None => clock_dropped,
    };
    let recording = match recorder {
        Some(r) => Some(r.finish().map_err(|e| record_error(settings, e))?),
        None => None,
    };
    for t in threads {
        let _ = t.join();
    }
    result?;
    Ok(Summary {
        frames,
        lines: line_no,
        dropped,
        overflowed: total(&counters, |c| {
            c.overflowed.load(Ordering::Relaxed) + c.too_long.load(Ordering::Relaxed)
        }),
        too_long: total(&counters, |c| c.too_long.load(Ordering::Relaxed)),
        lost_datagrams: total(&counters, |c| c.lost_datagrams.load(Ordering::Relaxed)),
        recording,
        warnings,
        latency_ms: latencies.summary(),
    })
}

fn record_error(settings: &LiveSettings, source: std::io::Error) -> LiveError {
    LiveError::Record {
        path: settings.record.clone().unwrap_or_default(),
        source,
    }
}

/// The pose stream for `lines`, once the format has said the sensors' world (a CSV after its
/// header); none without a mapping (`stream`).
fn start_running(
    lines: LineStream,
    rig: &crate::rig::Rig,
    stream: Option<&(
        &crate::mapping::Mapping,
        &std::path::Path,
        crate::pipeline::PipelineOptions,
    )>,
    settings: &LiveSettings,
) -> Result<Running, LiveError> {
    let world = settings
        .plan
        .read_options()
        .world
        .or(stream.and_then(|(mapping, _, _)| mapping.world))
        .unwrap_or(lines.world());
    let poses = match stream {
        Some((mapping, mapping_file, options)) => Some(PoseStream::from_mapping(
            rig,
            mapping,
            mapping_file,
            world,
            options,
        )?),
        None => None,
    };
    Ok(Running {
        lines,
        poses,
        world,
        index: Vec::new(),
        refused: Vec::new(),
        notices: Vec::new(),
    })
}

/// The samples a line let out, to the setup's board and through the pose stream.
fn feed(
    run: &mut Running,
    setup: Option<&crate::setup::Setup>,
    samples: &mut Vec<StreamSample>,
    per_sensor: &mut Vec<(u64, f64)>,
    on_pose: &mut impl FnMut(&Pose),
) {
    if samples.is_empty() {
        return;
    }
    let Some(take) = run.lines.take() else {
        samples.clear();
        return;
    };
    let ids = take.sensor_ids();
    for s in samples.drain(..) {
        let k = s.sensor.index();
        if let Some(setup) = setup {
            setup.sample(&ids[k], s.t_s, s.value, run.world);
        }
        let Some(poses) = &mut run.poses else {
            continue;
        };
        if k >= run.index.len() {
            run.index.resize(k + 1, None);
        }
        let i = *run.index[k].get_or_insert_with(|| poses.sensor_index(&ids[k]));
        if let Some(i) = i {
            if i >= per_sensor.len() {
                per_sensor.resize(i + 1, (0, f64::NEG_INFINITY));
            }
            per_sensor[i].0 += 1;
            per_sensor[i].1 = s.t_s;
            match s.value {
                StreamValue::Raw { imu, mag } => {
                    if run.refused.get(i).copied().unwrap_or(false) {
                        continue;
                    }
                    if let Err(e) = poses.push_raw(i, s.t_s, imu, mag, &mut *on_pose) {
                        // Readings in the wrong units: the sensor is left out, said once.
                        run.refused.resize(poses.sensors().len(), false);
                        run.refused[i] = true;
                        run.notices
                            .push(format!("error: {e}; its readings are left out"));
                    }
                }
                value => {
                    if let Some(q) = value.orientation() {
                        poses.push(i, s.t_s, q, &mut *on_pose);
                    }
                }
            }
        }
    }
}

/// The status line, for the browser preview's panel.
fn preview_status(preview: &crate::view::Preview, s: &Status) {
    let (phase, left) = match s.phase {
        Phase::Waiting => ("waiting", None),
        Phase::Calibrating { left_s } => ("calibrating", Some(left_s)),
        Phase::Running => ("running", None),
    };
    let sensors: Vec<crate::view::live::SensorLine<'_>> = s
        .sensors
        .iter()
        .map(|x| crate::view::live::SensorLine {
            id: &x.id,
            rate_hz: x.rate_hz,
            silent_s: x.silent_s,
        })
        .collect();
    preview.status(phase, left, s.frames, &sensors);
}

/// One count summed over every source.
fn total(counters: &[Arc<SourceCounters>], count: impl Fn(&SourceCounters) -> u64) -> u64 {
    counters.iter().map(|c| count(c)).sum()
}

#[allow(clippy::too_many_arguments)]
fn status(
    started: Instant,
    running: Option<&Running>,
    frames: u64,
    lines: u64,
    counters: &[Arc<SourceCounters>],
    per_sensor: &mut [(u64, f64)],
    period_s: f64,
    latency_ms: Option<(f64, f64)>,
    clock_dropped: u64,
) -> Status {
    let phase = match running.map(|r| r.poses.as_ref().map(|p| p.status())) {
        None => Phase::Waiting,
        Some(None) => Phase::Running,
        Some(Some(StreamStatus::Calibrating { left_s })) => Phase::Calibrating { left_s },
        Some(Some(StreamStatus::Running { .. })) => Phase::Running,
    };
    let mut sensors = Vec::new();
    let mut dropped_lines = clock_dropped;
    if let Some(run) = running {
        if let Some(poses) = &run.poses {
            let latest = poses.latest_s();
            for (i, s) in poses.sensors().iter().enumerate() {
                let (n, last) = per_sensor.get(i).copied().unwrap_or((0, f64::NEG_INFINITY));
                sensors.push(SensorStatus {
                    id: s.sensor.clone(),
                    rate_hz: n as f64 / period_s,
                    silent_s: if last.is_finite() {
                        (latest - last).max(0.0)
                    } else {
                        f64::INFINITY
                    },
                });
            }
        }
        dropped_lines += run.lines.dropped_lines().total()
            + run.lines.take().map_or(0, |t| t.dropped_lines().total());
    }
    for p in per_sensor.iter_mut() {
        p.0 = 0;
    }
    Status {
        elapsed_s: started.elapsed().as_secs_f64(),
        phase,
        frames,
        sensors,
        lines,
        dropped_lines,
        overflowed: total(counters, |c| {
            c.overflowed.load(Ordering::Relaxed) + c.too_long.load(Ordering::Relaxed)
        }),
        lost_datagrams: total(counters, |c| c.lost_datagrams.load(Ordering::Relaxed)),
        latency_ms,
    }
}
