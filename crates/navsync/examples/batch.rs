//! A batch run of KF-GINS files: the same streaming navigator, driven by the
//! file readers, written in KF-GINS layouts (`navresult.nav`, `imu_err.txt`,
//! `std.txt`) and summarised.
//!
//! ```sh
//! cargo run --release -p navsync --example batch -- navsync-demo/synced/kf-gins.yaml /tmp/out
//! ```

use std::path::PathBuf;

use navsync::error::{Diagnostics, Error};
use navsync::io::config::KfGinsConfig;
use navsync::pipeline::{FuseOptions, KfGinsSink, run};

fn main() -> Result<(), Error> {
    let mut args = std::env::args().skip(1).map(PathBuf::from);
    let (Some(config_path), Some(out_dir)) = (args.next(), args.next()) else {
        eprintln!("usage: batch KF-GINS.yaml OUTPUT_DIR");
        std::process::exit(2);
    };
    let cfg = KfGinsConfig::load(&config_path, &mut Diagnostics::with_cap(10))?;
    let opts = FuseOptions {
        output_dir: Some(out_dir.clone()),
        ..FuseOptions::default()
    };
    let mut sink = KfGinsSink::create(&out_dir, opts.week)?;
    let summary = run(&cfg, &opts, &mut sink, &mut |_| {})?;
    sink.finish()?;
    println!(
        "{:.1} s fused: {} GNSS fixes used, {} rejected; files in {}",
        summary.duration_s,
        summary.stats.gnss_fixes_used,
        summary.gnss_weighting.rejected.len(),
        out_dir.display()
    );
    Ok(())
}
