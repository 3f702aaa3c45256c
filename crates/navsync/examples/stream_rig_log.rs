//! Embed navsync as a stream: raw rig-log records (1PPS edges, counter
//! stamped IMU and GNSS records) go in one at a time, synchronized and fused
//! solutions come out through a custom sink, as they would from a serial
//! port. The same code serves a file and a live logger.
//!
//! ```sh
//! cargo run --release -- demo --output navsync-demo
//! cargo run --release -p navsync --example stream_rig_log -- \
//!     navsync-demo/sim/rig.csv navsync-demo/synced/kf-gins.yaml
//! ```

use std::path::PathBuf;

use navsync::error::{Diagnostics, Error};
use navsync::ins::{ImuErrors, NavState};
use navsync::io::config::KfGinsConfig;
use navsync::io::riglog::{RigLogReader, RigRecord};
use navsync::navigator::NavSink;
use navsync::navigator::Navigator;
use navsync::pipeline::{FuseOptions, fusion_config};
use navsync::timing::{SyncConfig, SyncMode};

/// Prints one line per second of solution and counts the rest.
#[derive(Default)]
struct OncePerSecond {
    last_second: Option<i64>,
    solutions: usize,
}

impl NavSink for OncePerSecond {
    fn nav(&mut self, nav: &NavState, _imu: &ImuErrors) -> Result<(), Error> {
        self.solutions += 1;
        let second = nav.time.ns().div_euclid(navsync::time::NS_PER_S);
        if self.last_second != Some(second) {
            self.last_second = Some(second);
            let e = nav.euler().to_deg();
            println!(
                "{:.3}  {:.8}° {:.8}° {:7.2} m  yaw {:7.2}°",
                nav.time.sow(),
                nav.pos.lat_rad.to_degrees(),
                nav.pos.lon_rad.to_degrees(),
                nav.pos.h_m,
                e[2]
            );
        }
        Ok(())
    }
}

fn main() -> Result<(), Error> {
    let mut args = std::env::args().skip(1).map(PathBuf::from);
    let (Some(rig_path), Some(config_path)) = (args.next(), args.next()) else {
        eprintln!("usage: stream_rig_log RIG.csv KF-GINS.yaml");
        std::process::exit(2);
    };
    let mut diag = Diagnostics::with_cap(100);
    // The filter's settings (noise, lever arm, initial state) from a
    // KF-GINS configuration; a program may build a FusionConfig directly.
    let cfg = KfGinsConfig::load(&config_path, &mut diag)?;
    // KF-GINS configurations give seconds of week only: the week is the
    // one of the log's first GNSS record.
    let mut week = 0;
    let mut scan = RigLogReader::open(&rig_path, &mut Diagnostics::with_cap(0))?;
    while let Some((record, _)) = scan.next_record(&mut Diagnostics::with_cap(0))? {
        if let RigRecord::Gnss(g) = record {
            week = g.time.week();
            break;
        }
    }
    let opts = FuseOptions {
        week,
        ..FuseOptions::default()
    };
    let mut reader = RigLogReader::open(&rig_path, &mut diag)?;
    // Causal synchronization: every sample is stamped from the past only,
    // as it would be live.
    let sync = SyncConfig {
        mode: SyncMode::Auto,
        causal: true,
        source: rig_path.display().to_string(),
        ..SyncConfig::default()
    };
    let mut nav = Navigator::new(fusion_config(&cfg, &opts)).with_rig_sync(reader.header(), sync);
    let mut sink = OncePerSecond::default();
    while let Some((record, _line)) = reader.next_record(&mut diag)? {
        nav.push_record(record, &mut sink)?;
    }
    let end = nav.finish(&mut sink)?;
    println!(
        "{} solutions, {} GNSS observations weighed, {} bad lines skipped",
        sink.solutions,
        end.fix_records.len(),
        diag.total
    );
    Ok(())
}
