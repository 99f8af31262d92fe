//! `imubake live --source SOURCE … --mapping JSON [--vmc HOST:PORT] [--record DIR] …`: sensors to
//! a moving character in real time (the library's `live` module), with a status line.

use super::convert::SettingsArgs;
use clap::Args;
use imubake::live::source::{Allow, SourceSpec};
use imubake::live::{Clock, LiveSettings, Phase, Report, Status};
use std::io::{IsTerminal, Write};
use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct LiveArgs {
    /// Where lines come from (repeatable): serial:PORT[@BAUD], udp:[ADDR:]PORT, tcp:HOST:PORT,
    /// stdin, file:CAPTURE[@SPEED]; serial, udp and tcp sources may end in :witmotion
    /// (WitMotion's packets) or :layout (the frames of --layout FILE)
    #[arg(long = "source", value_name = "SOURCE", required = true)]
    sources: Vec<SourceSpec>,
    /// Send VMC (OSC over UDP) here, or `off` [default: 127.0.0.1:39539]
    #[arg(long, value_name = "HOST:PORT|off")]
    vmc: Option<String>,
    /// Hear VMC calibration requests (/VMC/Ext/Set/Calib/Exec) here, or `off`
    /// [default: 127.0.0.1:39540]
    #[arg(long, value_name = "HOST:PORT|off")]
    listen: Option<String>,
    /// Record everything received as a take in DIR (DIR/<start time>.csv, or .log for SOU)
    #[arg(long, value_name = "DIR")]
    record: Option<PathBuf>,
    /// Accept UDP, TCP and VMC requests only from these senders (ADDR[/PREFIX],...)
    #[arg(long, value_name = "LIST")]
    allow: Option<Allow>,
    /// Timestamps: source (each line's own) or host (the host's clock at arrival) [default:
    /// source for one source, host for several]
    #[arg(long, value_name = "CLOCK")]
    clock: Option<Clock>,
    /// Show the pose in the browser: serve `imubake view`'s page on loopback at PORT [default:
    /// a free one, printed]
    #[arg(long, value_name = "PORT", num_args = 0..=1, default_missing_value = "0")]
    preview: Option<u16>,
    /// A source's time more than SECONDS ahead of its latest is a jump: dropped, or a restart
    /// of its clock when the lines after it agree [default: 10]
    #[arg(long, value_name = "SECONDS", value_parser = horizon)]
    time_horizon: Option<f64>,
    /// Print the session's summary as JSON at the end.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    settings: SettingsArgs,
}

fn address(flag: &str, value: Option<&str>, default: &str) -> anyhow::Result<Option<SocketAddr>> {
    let value = value.unwrap_or(default);
    if value == "off" {
        return Ok(None);
    }
    std::net::ToSocketAddrs::to_socket_addrs(value)
        .ok()
        .and_then(|mut a| a.next())
        .map(Some)
        .ok_or_else(|| anyhow::anyhow!("--{flag} {value}: expected HOST:PORT or off"))
}

fn horizon(s: &str) -> Result<f64, String> {
    let min = imubake::live::clock::RESTART_S;
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= min => Ok(v),
        _ => Err(format!("expected a number of seconds, at least {min}")),
    }
}

fn status_line(s: &Status) -> String {
    let phase = match &s.phase {
        Phase::Waiting => "waiting for data".to_string(),
        Phase::Calibrating { left_s } => format!("HOLD THE POSE: {left_s:.1} s left"),
        Phase::Running => format!("{} frames", s.frames),
    };
    let live = s.sensors.iter().filter(|x| x.silent_s < 0.5).count();
    let rate = if s.sensors.is_empty() {
        0.0
    } else {
        s.sensors.iter().map(|x| x.rate_hz).sum::<f64>() / s.sensors.len() as f64
    };
    let silent: Vec<&str> = s
        .sensors
        .iter()
        .filter(|x| x.silent_s >= 0.5)
        .map(|x| x.id.as_str())
        .collect();
    let mut line = format!(
        "{:>7.1} s · {phase} · sensors {live}/{} at {rate:.0} Hz · {} lines, {} dropped",
        s.elapsed_s,
        s.sensors.len(),
        s.lines,
        s.dropped_lines + s.overflowed
    );
    if s.lost_datagrams > 0 {
        line.push_str(&format!(" · {} datagrams lost", s.lost_datagrams));
    }
    if let Some((median, p99)) = s.latency_ms {
        line.push_str(&format!(" · latency {median:.2}/{p99:.2} ms"));
    }
    if !silent.is_empty() {
        line.push_str(&format!(" · silent: {}", silent.join(", ")));
    }
    line
}

/// The browser preview: the rig at rest on `imubake view`'s page, served on loopback beside the
/// session until it stops; its URL printed.
fn start_preview(
    plan: &imubake::convert::Plan,
    port: u16,
    stop: &std::sync::Arc<std::sync::atomic::AtomicBool>,
) -> anyhow::Result<std::sync::Arc<imubake::view::Preview>> {
    use imubake::view::{Preview, ServeOptions, Server, ViewTake};
    let (rig, _, _, options) = plan.stream()?;
    let preview = Preview::new(rig.units().metres_per_unit());
    let server = Server::bind(
        ViewTake::live(rig.clone(), options.fps, Vec::new()),
        &ServeOptions {
            listen: SocketAddr::from(([127, 0, 0, 1], port)),
        },
        Some(std::sync::Arc::clone(&preview)),
    )?;
    eprintln!("preview: {}", server.url());
    let stop = std::sync::Arc::clone(stop);
    std::thread::spawn(move || server.run(&stop));
    Ok(preview)
}

pub fn run(args: LiveArgs) -> anyhow::Result<ExitCode> {
    let mut convert = args.settings.settings()?;
    if convert.given.fps == imubake::convert::Layer::Default {
        // A live view runs smoother than a file's default 30 fps.
        convert.pipeline.fps = "60".parse().expect("a frame rate");
    }
    let mut ignored = Vec::new();
    if convert.pipeline.trim.is_some() {
        ignored.push("--trim");
    }
    if convert.in_place {
        ignored.push("--in-place");
    }
    if convert.bind_frame {
        ignored.push("--bind-frame");
    }
    if convert.engine.is_some() {
        ignored.push("--engine");
    }
    if convert.report {
        ignored.push("--report");
    }
    if !ignored.is_empty() {
        eprintln!(
            "warning: {} apply to files, not to a live session (the recording converts with them)",
            ignored.join(", ")
        );
    }
    let plan = std::sync::Arc::new(imubake::convert::Plan::resolve(convert)?);
    let stop = super::stop_on_signals()?;
    let preview = match args.preview {
        Some(port) => Some(start_preview(&plan, port, &stop)?),
        None => None,
    };
    let settings = LiveSettings {
        sources: args.sources.clone(),
        plan,
        vmc: address("vmc", args.vmc.as_deref(), imubake::live::DEFAULT_VMC)?,
        listen: address(
            "listen",
            args.listen.as_deref(),
            imubake::live::DEFAULT_LISTEN,
        )?,
        record: args.record.clone(),
        allow: args.allow.clone().unwrap_or_default(),
        clock: args.clock,
        keys: std::io::stdin().is_terminal() && !args.sources.contains(&SourceSpec::Stdin),
        preview,
        setup: None,
        time_horizon_s: args
            .time_horizon
            .unwrap_or(imubake::live::clock::DEFAULT_HORIZON_S),
    };
    let terminal = std::io::stderr().is_terminal();
    if settings.keys {
        eprintln!("press c and Enter to calibrate again; Ctrl-C ends the session");
    }
    let mut last_printed = std::time::Instant::now() - std::time::Duration::from_secs(10);
    let summary = imubake::live::run(&settings, stop, |r| {
        let mut err = std::io::stderr().lock();
        match r {
            Report::Notice(text) => {
                if terminal {
                    let _ = write!(err, "\r\x1b[2K");
                }
                let _ = writeln!(err, "{text}");
            }
            Report::Status(s) => {
                if terminal {
                    let _ = write!(err, "\r\x1b[2K{}", status_line(&s));
                } else if last_printed.elapsed().as_secs() >= 5 {
                    let _ = writeln!(err, "{}", status_line(&s));
                    last_printed = std::time::Instant::now();
                }
            }
        }
        let _ = err.flush();
    })?;
    if terminal {
        eprintln!();
    }
    let where_ = summary
        .recording
        .as_ref()
        .map_or_else(|| "live".to_string(), |p| p.display().to_string());
    for r in summary.dropped.reports().iter().take(20) {
        eprintln!(
            "dropped: {where_}: line {}: {} ({})",
            r.line, r.reason, r.text
        );
    }
    let dropped = summary.dropped.total();
    if dropped > 20 {
        eprintln!("… and {} more dropped lines", dropped - 20);
        if summary.dropped.omitted() > 0 {
            let by_reason: Vec<String> = summary
                .dropped
                .omitted_by_reason()
                .iter()
                .map(|(reason, n)| format!("{n} {reason}"))
                .collect();
            eprintln!(
                "  (the first {} are listed in --json; of the {} after them: {})",
                summary.dropped.reports().len(),
                summary.dropped.omitted(),
                by_reason.join(", ")
            );
        }
    }
    for w in &summary.warnings {
        eprintln!("warning: {w}");
    }
    if summary.overflowed > summary.too_long {
        eprintln!(
            "warning: {} lines lost: they came faster than the session could take them",
            summary.overflowed - summary.too_long
        );
    }
    if summary.too_long > 0 {
        eprintln!(
            "warning: {} lines longer than {} KiB dropped",
            summary.too_long,
            imubake::live::source::MAX_LINE >> 10
        );
    }
    if summary.lost_datagrams > 0 {
        eprintln!(
            "warning: {} datagrams dropped by the system before they were read (its receive \
             buffer full; a busy machine, or a sender faster than the session)",
            summary.lost_datagrams
        );
    }
    if args.json {
        let json = serde_json::json!({
            "frames": summary.frames,
            "lines": summary.lines,
            "dropped_lines": summary.dropped.reports(),
            "dropped_total": summary.dropped.total(),
            "dropped_omitted_by_reason": summary
                .dropped
                .omitted_by_reason()
                .iter()
                .map(|(reason, n)| serde_json::json!({"reason": reason, "lines": n}))
                .collect::<Vec<_>>(),
            "overflowed": summary.overflowed,
            "too_long": summary.too_long,
            "lost_datagrams": summary.lost_datagrams,
            "recording": summary.recording,
            "latency_ms": summary.latency_ms.map(|(m, p)| serde_json::json!({"median": m, "p99": p})),
            "warnings": summary.warnings,
        });
        println!("{json}");
    } else {
        eprintln!(
            "{} frames from {} lines ({} dropped){}",
            summary.frames,
            summary.lines,
            dropped,
            summary
                .recording
                .as_ref()
                .map(|p| format!("; recorded as {}", p.display()))
                .unwrap_or_default()
        );
    }
    Ok(ExitCode::SUCCESS)
}
