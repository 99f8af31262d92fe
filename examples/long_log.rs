//! Writes the synthetic capture log the benchmarks and `scripts/golden.sh` use: an imubake CSV of
//! quaternions for paper 000's 16 sensors at 100 Hz, `MINUTES` long (benches/common).
//!
//!   cargo run --release --example long_log -- <out.csv> [MINUTES]

#[path = "../benches/common/mod.rs"]
mod common;

fn main() {
    let mut args = std::env::args().skip(1);
    let Some(out) = args.next() else {
        eprintln!("usage: long_log <out.csv> [MINUTES] [raw]");
        std::process::exit(2);
    };
    let minutes: usize = args.next().and_then(|m| m.parse().ok()).unwrap_or(60);
    // `raw` as a third argument: the raw readings' twin of the same log.
    let write = if args.next().as_deref() == Some("raw") {
        common::write_raw_log
    } else {
        common::write_log
    };
    match write(
        std::path::Path::new(&out),
        minutes,
        &common::PAPER000_SENSORS,
    ) {
        Ok(bytes) => println!("{out}: {minutes} min, {bytes} bytes"),
        Err(e) => {
            eprintln!("{out}: {e}");
            std::process::exit(1);
        }
    }
}
