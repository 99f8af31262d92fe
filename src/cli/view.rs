//! `imubake view <take> [--port N] [--listen ADDR] [--open]`: a take in the browser (the
//! library's `view` module). A capture is converted first, with the `convert` settings, into a
//! temporary folder removed at the end.

use super::convert::SettingsArgs;
use clap::Args;
use imubake::view::{ServeOptions, Server, ViewTake};
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct ViewArgs {
    /// A converted take (its `.imubake.json` sidecar, a `.bvh` or a `.glb`), or a capture
    /// (file or session folder) converted first with the settings below.
    take: PathBuf,
    /// Port to serve on [default: a free one, printed]
    #[arg(long, value_name = "N", default_value_t = 0)]
    port: u16,
    /// Address to listen on: loopback unless this says otherwise (0.0.0.0 for every interface)
    #[arg(long, value_name = "ADDR", default_value_t = IpAddr::V4(Ipv4Addr::LOCALHOST))]
    listen: IpAddr,
    /// Open the page in the default browser.
    #[arg(long)]
    open: bool,
    /// Length of the GLB chunks the page loads as it plays, seconds.
    #[arg(long, value_name = "S", default_value_t = 60.0, value_parser = parse_chunk)]
    chunk_seconds: f64,
    #[command(flatten)]
    settings: SettingsArgs,
}

fn parse_chunk(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 && v <= 3600.0 => Ok(v),
        _ => Err(format!(
            "`{s}` is not a chunk length in seconds (0 < S ≤ 3600)"
        )),
    }
}

pub fn run(args: ViewArgs) -> anyhow::Result<ExitCode> {
    // Converted into a folder that lives as long as the server (removed when it stops).
    let mut _converted: Option<tempfile::TempDir> = None;
    let take = if imubake::view::motion::is_converted(&args.take) {
        ViewTake::open(&args.take, args.chunk_seconds)?
    } else {
        let dir = tempfile::Builder::new().prefix("imubake-view-").tempdir()?;
        let plan = args.settings.plan()?;
        let outcome = imubake::convert::convert(&args.take, dir.path(), &plan)?;
        eprintln!(
            "{} converted ({} frames at {} fps)",
            args.take.display(),
            outcome.sidecar.frames,
            outcome.sidecar.fps
        );
        let mut take = ViewTake::open(&outcome.sidecar_path, args.chunk_seconds)?;
        take.source = args.take.display().to_string();
        _converted = Some(dir);
        take
    };
    let stop = super::stop_on_signals()?;
    let server = Server::bind(
        take,
        &ServeOptions {
            listen: SocketAddr::new(args.listen, args.port),
        },
        None,
    )?;
    let url = server.url();
    println!("imubake view: {url} (Ctrl-C to stop)");
    if args.open
        && let Err(e) = webbrowser::open(&url)
    {
        eprintln!("cannot open a browser ({e}); open {url}");
    }
    server.run(&stop);
    Ok(ExitCode::SUCCESS)
}
