//! navsync-live: `navsync live` on Linux — GNSS and IMU serial ports and a
//! kernel PPS device, every arrival stamped on one host clock, synchronized
//! ([`navsync::timing::SyncEngine`]) and fused ([`navsync::fusion::Fusion`])
//! in real time.
//!
//! - [`hostclock`]: the host counter (`CLOCK_MONOTONIC_RAW`, ns) and the
//!   conversion of kernel PPS (`CLOCK_REALTIME`) stamps onto it.
//! - [`serial`]: raw termios ports read with a timeout.
//! - [`pps`]: the [`pps::PpsSource`] trait, RFC 2783 kernel PPS and an
//!   injected source.
//! - [`imu`]: the accepted IMU line formats, what the line reader tells the
//!   engine (losses, reopens, lines read together) and the ESF tag timing.
//! - [`gnss`]: receiver bytes → fixes with their receive time.
//! - [`live`]: the loop (threads, bounded channel, reopen, status).
//! - [`files`]: the solution as KF-GINS files.
//! - [`record`]: `--record`: the received records as a rig log, the
//!   receiver's raw bytes.
//! - [`replay`], [`selftest`]: PTYs fed at real rate; the measurement.
//!
//! Kept out of `navsync` and `navsync-receivers` so that their users need
//! neither libc nor Linux.

pub mod files;
pub(crate) mod gnss;
pub mod hostclock;
pub mod imu;
pub(crate) mod latency;
pub mod live;
pub(crate) mod pps;
pub mod record;
pub mod replay;
pub mod selftest;
pub(crate) mod serial;

pub use live::{LiveConfig, LiveReport, LiveSink, LiveStatus, PortConfig, PpsInput, run};

/// One status line: elapsed time, clock state, ports, counts, solution.
pub fn status_line(s: &LiveStatus) -> String {
    let up = |b: bool| if b { "up" } else { "DOWN" };
    let c = &s.counts;
    let mut line = format!(
        "[{:8.1} s] clock {:<9} ({}) imu {} gnss {} pps {} | imu {} (bad {}, lost {}) sol {} | gnss {} fused {} | pps {}",
        s.elapsed_s,
        format!("{:?}", s.state).to_lowercase(),
        s.mode,
        up(s.imu_up),
        up(s.gnss_up),
        up(s.pps_up),
        c.imu_lines,
        c.imu_bad_lines,
        c.imu_lost,
        c.solutions,
        c.gnss_fixes,
        c.gnss_fused,
        c.pps_edges,
    );
    if let (Some(t), Some(p), Some(a)) = (s.time, s.pos, s.att_deg) {
        line.push_str(&format!(
            " | {} {:.3} {:.8} {:.8} {:.3} att {:.2} {:.2} {:.2}",
            t.week(),
            t.sow(),
            p[0],
            p[1],
            p[2],
            a[0],
            a[1],
            a[2]
        ));
    }
    if let Some(l) = s.latency_median_us {
        line.push_str(&format!(" | latency median {l:.0} µs"));
    }
    if let Some(b) = s.bound_us {
        line.push_str(&format!(", stamp bound {b:.1} µs"));
    }
    line
}
