//! `imubake setup --source SOURCE … --out DIR [--rig NAME|FILE]`: a suit brought up in the
//! browser (the library's `setup` module on a live session without a mapping).

use clap::Args;
use imubake::live::source::{Allow, SourceSpec};
use imubake::live::{Clock, LiveSettings, Report};
use imubake::setup::Setup;
use imubake::setup::board::Board;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;

#[derive(Debug, Args)]
pub struct SetupArgs {
    /// Where lines come from (repeatable), as `live --source`: serial:PORT[@BAUD], udp:[ADDR:]PORT,
    /// tcp:HOST:PORT (each may end in :witmotion or :layout), stdin, file:CAPTURE[@SPEED]
    #[arg(long = "source", value_name = "SOURCE", required = true)]
    sources: Vec<SourceSpec>,
    /// The folder Save writes the mapping, subject and sensor calibration into
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// The rig whose bones the sensors go on: a built-in name or a rig file [default: mixamo]
    #[arg(long, value_name = "NAME|FILE")]
    rig: Option<String>,
    /// The packet layout of `:layout` sources (YAML)
    #[arg(long, value_name = "FILE.yaml")]
    layout: Option<PathBuf>,
    /// Serve the page on loopback at PORT [default: a free one, printed]
    #[arg(long, value_name = "PORT", default_value_t = 0)]
    port: u16,
    /// Accept UDP and TCP only from these senders (ADDR[/PREFIX],...)
    #[arg(long, value_name = "LIST")]
    allow: Option<Allow>,
    /// Timestamps: source or host [default: source for one source, host for several]
    #[arg(long, value_name = "CLOCK")]
    clock: Option<Clock>,
}

pub fn run(args: SetupArgs) -> anyhow::Result<ExitCode> {
    use imubake::view::{ServeOptions, Server, ViewTake};
    let flags = imubake::config::Config {
        rig: args.rig.clone(),
        layout: args.layout.clone(),
        ..Default::default()
    };
    let plan = Arc::new(imubake::config::plan(flags, None)?);
    let rig = plan.rig();
    let rig_name = args.rig.clone().unwrap_or_else(|| "mixamo".into());
    let setup = Arc::new(Setup::new(
        Board::of_rig(rig),
        args.out.clone(),
        rig.clone(),
        rig_name,
        args.sources.iter().map(|s| s.to_string()).collect(),
    ));
    let stop = super::stop_on_signals()?;
    let server = Server::bind(
        ViewTake::live(rig.clone(), "60".parse().expect("a rate"), Vec::new()),
        &ServeOptions {
            listen: SocketAddr::from(([127, 0, 0, 1], args.port)),
        },
        None,
    )?
    .with_setup(Arc::clone(&setup));
    eprintln!("setup: {}", server.url());
    {
        let stop = Arc::clone(&stop);
        std::thread::spawn(move || server.run(&stop));
    }
    let settings = LiveSettings {
        sources: args.sources.clone(),
        plan,
        vmc: None,
        listen: None,
        record: None,
        allow: args.allow.clone().unwrap_or_default(),
        clock: args.clock,
        keys: false,
        preview: None,
        setup: Some(setup),
        time_horizon_s: imubake::live::clock::DEFAULT_HORIZON_S,
    };
    let summary = imubake::live::run(&settings, Arc::clone(&stop), |r| {
        if let Report::Notice(text) = r {
            eprintln!("{text}");
        }
    })?;
    for r in summary.dropped.reports().iter().take(20) {
        eprintln!("dropped: line {}: {} ({})", r.line, r.reason, r.text);
    }
    // The sources ended (a replayed file): the page stays until Ctrl-C.
    while !stop.load(std::sync::atomic::Ordering::Relaxed) {
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    Ok(ExitCode::SUCCESS)
}
