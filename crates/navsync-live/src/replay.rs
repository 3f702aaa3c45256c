//! Devices without hardware: pseudo-terminals fed at real rate from a
//! generated stream, and PPS edges injected on the host clock. Used by the
//! tests and by `navsync live --selftest`.
//!
//! The scenario: a vehicle standing still at a given position; a 200 Hz IMU
//! (`rate` lines: Earth rate + normal gravity + white noise, FRD = NED);
//! a 10 Hz receiver (UBX NAV-PVT, or NMEA GGA + GST + RMC) whose fixes
//! arrive `gnss_latency_s` after their epoch; 1PPS edges at every GPS
//! second. With `dual_antenna`, each epoch also carries the azimuth of a
//! dual-antenna baseline (NAV-RELPOSNED after the NAV-PVT, or HDT after
//! the NMEA fix). GPS time runs `host_ppm` faster than the host counter, so the
//! engine has a real frequency error to estimate. The writer knows the
//! true GPS time of every IMU line, so stamps can be checked.

use std::io;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use navsync::earth::{Geodetic, gravity, omega_ie_n};
use navsync::io::text::push_f64;
use navsync::time::{GpsTime, NS_PER_S};
use navsync_receivers::gnsstime::{UtcTime, gps_to_unix_ns};
use navsync_receivers::nmea::{Date, Gga, Gst, Hdt, Rmc};
use navsync_receivers::ubx::{EsfRaw, EsfRawBlock, NavPvt, NavRelPosNed, encode_frame, esf_type};
use navsync_sim::rng;

use crate::hostclock;
use crate::pps::PpsInjector;

/// A pseudo-terminal pair in raw mode; the slave stays open here so that
/// bytes written before a reader opens it are kept.
pub struct Pty {
    master: OwnedFd,
    _slave: OwnedFd,
    /// The slave's device path (`/dev/pts/N`).
    pub slave_path: PathBuf,
}

impl Pty {
    pub fn open() -> io::Result<Self> {
        let (mut m, mut s) = (-1, -1);
        // SAFETY: zeroed termios is valid storage; cfmakeraw fills it.
        let mut t: libc::termios = unsafe { std::mem::zeroed() };
        // SAFETY: `t` is valid.
        unsafe { libc::cfmakeraw(&mut t) };
        // SAFETY: valid out-pointers; no name buffer; termios valid; no winsize.
        let rc =
            unsafe { libc::openpty(&mut m, &mut s, std::ptr::null_mut(), &t, std::ptr::null()) };
        if rc != 0 {
            return Err(io::Error::other(format!(
                "openpty: {}",
                io::Error::last_os_error()
            )));
        }
        // SAFETY: both descriptors were just created and are owned here.
        let (master, slave) = unsafe { (OwnedFd::from_raw_fd(m), OwnedFd::from_raw_fd(s)) };
        let mut name = [0 as libc::c_char; 128];
        // SAFETY: buffer valid for its length.
        let rc = unsafe { libc::ttyname_r(slave.as_raw_fd(), name.as_mut_ptr(), name.len()) };
        if rc != 0 {
            return Err(io::Error::from_raw_os_error(rc));
        }
        // SAFETY: ttyname_r wrote a NUL-terminated string.
        let path = unsafe { std::ffi::CStr::from_ptr(name.as_ptr()) }
            .to_string_lossy()
            .into_owned();
        Ok(Pty {
            master,
            _slave: slave,
            slave_path: PathBuf::from(path),
        })
    }

    /// Writes all of `bytes` to the master (what the device sends).
    pub fn write_all(&self, mut bytes: &[u8]) -> io::Result<()> {
        while !bytes.is_empty() {
            // SAFETY: valid descriptor and buffer.
            let n =
                unsafe { libc::write(self.master.as_raw_fd(), bytes.as_ptr().cast(), bytes.len()) };
            if n < 0 {
                let e = io::Error::last_os_error();
                if e.kind() == io::ErrorKind::Interrupted {
                    continue;
                }
                return Err(e);
            }
            bytes = &bytes[n as usize..];
        }
        Ok(())
    }
}

/// A device path that survives unplugging: a symlink to the current PTY.
pub struct PlugPort {
    pub link: PathBuf,
    pty: Option<Pty>,
}

impl PlugPort {
    pub fn new(link: &Path) -> io::Result<Self> {
        let mut p = PlugPort {
            link: link.to_path_buf(),
            pty: None,
        };
        p.plug()?;
        Ok(p)
    }

    /// A new device appears at the link.
    pub fn plug(&mut self) -> io::Result<()> {
        let pty = Pty::open()?;
        let _ = std::fs::remove_file(&self.link);
        std::os::unix::fs::symlink(&pty.slave_path, &self.link)?;
        self.pty = Some(pty);
        Ok(())
    }

    /// The device goes away (its reader sees a hang-up).
    pub fn unplug(&mut self) {
        self.pty = None;
        let _ = std::fs::remove_file(&self.link);
    }

    pub fn is_plugged(&self) -> bool {
        self.pty.is_some()
    }

    fn write(&self, bytes: &[u8]) -> io::Result<()> {
        match &self.pty {
            Some(p) => p.write_all(bytes),
            None => Ok(()),
        }
    }
}

/// GNSS message set of the replay.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum GnssKind {
    Ubx,
    Nmea,
}

/// The replayed scenario.
#[derive(Clone, Debug)]
pub struct ReplayConfig {
    pub duration_s: f64,
    pub imu_rate_hz: f64,
    pub gnss_rate_hz: f64,
    pub gnss: GnssKind,
    pub gnss_latency_s: f64,
    /// GPS time of the first second of the run.
    pub start: GpsTime,
    pub pos: Geodetic,
    /// GPS time runs this much faster than the host counter (ppm).
    pub host_ppm: f64,
    /// No PPS edges from `start_s` for `len_s` seconds (into the run).
    pub pps_gap: Option<(f64, f64)>,
    /// The IMU device unplugged from `start_s` for `len_s` seconds.
    pub imu_unplug: Option<(f64, f64)>,
    /// The IMU in UBX ESF-RAW messages on the GNSS port (5 samples a
    /// message, 1 ms time-tag ticks) instead of text lines on its own port.
    pub imu_esf: bool,
    /// A garbage line on the IMU port after every this many samples.
    pub imu_garbage_every: Option<u64>,
    /// A dual-antenna heading each epoch: (yaw of the baseline in the body
    /// frame, σ of its white noise), deg. The vehicle faces north, so the
    /// true azimuth is the baseline's yaw.
    pub dual_antenna: Option<(f64, f64)>,
    /// White-noise σ of gyro (rad/s) and accelerometer (m/s²) samples.
    pub gyro_sd: f64,
    pub accel_sd: f64,
    pub seed: u64,
}

impl Default for ReplayConfig {
    fn default() -> Self {
        ReplayConfig {
            duration_s: 10.0,
            imu_rate_hz: 200.0,
            gnss_rate_hz: 10.0,
            gnss: GnssKind::Ubx,
            gnss_latency_s: 0.04,
            start: GpsTime::from_week_sow(2400, 300_000.0),
            pos: Geodetic::from_deg(30.5278, 114.3556, 25.0),
            host_ppm: 25.0,
            pps_gap: None,
            imu_unplug: None,
            imu_esf: false,
            imu_garbage_every: None,
            dual_antenna: None,
            gyro_sd: 1e-4,
            accel_sd: 2e-3,
            seed: 2,
        }
    }
}

/// What the writer did.
#[derive(Clone, Debug, Default)]
pub struct ReplayStats {
    /// IMU lines written (not counting those while unplugged).
    pub imu_written: u64,
    pub imu_unplugged: u64,
    pub gnss_epochs: u64,
    pub pps_injected: u64,
    /// CPU time of the writer thread (s), to subtract from the process's.
    pub cpu_s: f64,
    /// Worst lateness of a write against its schedule (s).
    pub max_late_s: f64,
}

/// A running replay: the ports to give to `live`, and its writer thread.
pub struct Replay {
    pub imu_port: PathBuf,
    pub gnss_port: PathBuf,
    /// Host counter ↔ GPS time of the replay.
    pub clock: ReplayClock,
    handle: Option<JoinHandle<io::Result<ReplayStats>>>,
    stop: Arc<AtomicBool>,
}

/// The replay's relation between host counter and GPS time.
#[derive(Copy, Clone, Debug)]
pub struct ReplayClock {
    pub host0: u64,
    pub gps0: GpsTime,
    pub host_ppm: f64,
}

impl ReplayClock {
    /// Host counter at GPS time `t`.
    pub fn host_at(&self, t: GpsTime) -> u64 {
        let dt = t.seconds_since(self.gps0);
        self.host0 + (dt / (1.0 + self.host_ppm * 1e-6) * 1e9).round() as u64
    }

    /// GPS time of host counter `h`.
    pub fn gps_at(&self, h: u64) -> GpsTime {
        let dh = (h as f64 - self.host0 as f64) * 1e-9;
        self.gps0.add_seconds(dh * (1.0 + self.host_ppm * 1e-6))
    }
}

/// True GPS time of IMU line `k` (the replay's sample clock).
pub fn imu_truth(cfg: &ReplayConfig, k: u64) -> GpsTime {
    // The first sample 3 ms after the first second (not on a PPS edge).
    cfg.start
        .add_seconds(0.003)
        .add_seconds(k as f64 / cfg.imu_rate_hz)
}

impl Replay {
    /// Creates the ports in `dir` and starts writing at real rate about
    /// `lead_s` from now (time for the reader to open the ports).
    pub fn start(
        cfg: ReplayConfig,
        dir: &Path,
        pps: PpsInjector,
        lead_s: f64,
    ) -> io::Result<Replay> {
        let imu = PlugPort::new(&dir.join("imu"))?;
        let gnss = PlugPort::new(&dir.join("gnss"))?;
        let clock = ReplayClock {
            host0: hostclock::now_ns() + (lead_s * 1e9) as u64,
            gps0: cfg.start,
            host_ppm: cfg.host_ppm,
        };
        let stop = Arc::new(AtomicBool::new(false));
        let (imu_port, gnss_port) = (imu.link.clone(), gnss.link.clone());
        let st = stop.clone();
        let handle = std::thread::Builder::new()
            .name("replay-writer".into())
            .spawn(move || write_loop(cfg, clock, imu, gnss, pps, &st))?;
        Ok(Replay {
            imu_port,
            gnss_port,
            clock,
            handle: Some(handle),
            stop,
        })
    }

    /// Waits for the writer to finish (or stops it) and returns its stats.
    pub fn finish(mut self, stop_now: bool) -> io::Result<ReplayStats> {
        if stop_now {
            self.stop.store(true, Ordering::SeqCst);
        }
        match self.handle.take() {
            Some(h) => h
                .join()
                .unwrap_or_else(|_| Err(io::Error::other("replay writer panicked"))),
            None => Ok(ReplayStats::default()),
        }
    }
}

impl Drop for Replay {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

fn thread_cpu_s() -> f64 {
    // SAFETY: an all-zero rusage is valid; getrusage only writes it.
    let mut ru: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: `ru` is valid and writable.
    if unsafe { libc::getrusage(libc::RUSAGE_THREAD, &mut ru) } != 0 {
        return 0.0;
    }
    let tv = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    tv(ru.ru_utime) + tv(ru.ru_stime)
}

fn sleep_until(host_ns: u64, stop: &AtomicBool) -> bool {
    loop {
        if stop.load(Ordering::Relaxed) {
            return false;
        }
        let now = hostclock::now_ns();
        if now >= host_ns {
            return true;
        }
        std::thread::sleep(Duration::from_nanos((host_ns - now).min(50_000_000)));
    }
}

fn within(w: Option<(f64, f64)>, t: f64) -> bool {
    w.is_some_and(|(s, l)| t >= s && t < s + l)
}

fn utc_of(t: GpsTime) -> UtcTime {
    UtcTime::from_unix_ns(gps_to_unix_ns(t))
}

/// The receiver's bytes for the epoch valid at `t`; `heading_deg` is the
/// measured baseline azimuth when the scenario has one.
fn gnss_bytes(
    cfg: &ReplayConfig,
    t: GpsTime,
    noise: [f64; 3],
    heading_deg: Option<f64>,
) -> Vec<u8> {
    let (lat, lon, h) = (
        cfg.pos.lat_rad.to_degrees() + noise[0] / 111_320.0,
        cfg.pos.lon_rad.to_degrees() + noise[1] / (111_320.0 * cfg.pos.lat_rad.cos()),
        cfg.pos.h_m + noise[2],
    );
    let u = utc_of(t);
    match cfg.gnss {
        GnssKind::Ubx => {
            let Ok(mut p) = NavPvt::decode(&[0u8; NavPvt::LEN]) else {
                return Vec::new();
            };
            p.itow_ms = (t.ns().rem_euclid(navsync::time::NS_PER_WEEK) / 1_000_000) as u32;
            p.year = u.year as u16;
            p.month = u.month as u8;
            p.day = u.day as u8;
            p.hour = u.hour as u8;
            p.min = u.min as u8;
            p.sec = u.sec as u8;
            p.nano_ns = u.nano as i32;
            p.valid = 0x07;
            p.t_acc_ns = 20;
            p.fix_type = 3;
            p.flags = 0x01;
            p.num_sv = 14;
            p.lat_e7 = (lat * 1e7).round() as i32;
            p.lon_e7 = (lon * 1e7).round() as i32;
            p.height_mm = (h * 1e3).round() as i32;
            p.h_msl_mm = p.height_mm;
            p.h_acc_mm = 500;
            p.v_acc_mm = 800;
            p.s_acc_mm_s = 100;
            p.p_dop_e2 = 120;
            let mut bytes = encode_frame(0x01, 0x07, &p.encode()).unwrap_or_default();
            if let (Some(deg), Some((_, sd))) = (heading_deg, cfg.dual_antenna)
                && let Ok(mut r) = NavRelPosNed::decode(&[0u8; NavRelPosNed::LEN])
            {
                r.version = 1;
                r.itow_ms = p.itow_ms;
                r.rel_pos_length_cm = 100;
                r.rel_pos_heading_e5 = (deg.rem_euclid(360.0) * 1e5).round() as i32;
                r.acc_heading_e5 = (sd * 1e5).round() as u32;
                // gnssFixOK, relPosValid, carrSoln fixed, relPosHeadingValid.
                r.flags = 0x01 | 0x04 | (2 << 3) | 0x100;
                bytes.extend(encode_frame(0x01, 0x3C, &r.encode()).unwrap_or_default());
            }
            bytes
        }
        GnssKind::Nmea => {
            let tod = (u.hour as i64 * 3600 + u.min as i64 * 60 + u.sec as i64) * NS_PER_S
                + u.nano as i64;
            let rmc = Rmc {
                talker: "GN".into(),
                time_of_day_ns: Some(tod),
                date: Some(Date {
                    year: u.year,
                    month: u.month,
                    day: u.day,
                }),
                valid: true,
                lat_deg: Some(lat),
                lon_deg: Some(lon),
                speed_knots: Some(0.0),
                course_deg: None,
            };
            let gga = Gga {
                talker: "GN".into(),
                time_of_day_ns: Some(tod),
                lat_deg: Some(lat),
                lon_deg: Some(lon),
                quality: 1,
                num_sv: Some(14),
                hdop: Some(0.8),
                alt_msl_m: Some(h),
                geoid_sep_m: Some(0.0),
            };
            let gst = Gst {
                talker: "GN".into(),
                time_of_day_ns: Some(tod),
                rms_m: Some(0.5),
                semi_major_sd_m: None,
                semi_minor_sd_m: None,
                orientation_deg: None,
                lat_sd_m: Some(0.5),
                lon_sd_m: Some(0.5),
                alt_sd_m: Some(0.8),
            };
            let hdt = heading_deg
                .map(|deg| {
                    Hdt {
                        talker: "GN".into(),
                        heading_deg: Some(deg.rem_euclid(360.0)),
                    }
                    .to_sentence()
                })
                .unwrap_or_default();
            [rmc.to_sentence(), gga.to_sentence(), gst.to_sentence(), hdt]
                .concat()
                .into_bytes()
        }
    }
}

fn write_loop(
    cfg: ReplayConfig,
    clock: ReplayClock,
    mut imu: PlugPort,
    gnss: PlugPort,
    pps: PpsInjector,
    stop: &AtomicBool,
) -> io::Result<ReplayStats> {
    let mut st = ReplayStats::default();
    let mut noise = rng::stream(cfg.seed, "live-replay");
    let (sl, cl) = (cfg.pos.lat_rad.sin(), cfg.pos.lat_rad.cos());
    let w_ie = omega_ie_n(sl, cl);
    let g = gravity(sl, cfg.pos.h_m);
    let n_imu = (cfg.duration_s * cfg.imu_rate_hz).floor() as u64;
    let n_gnss = (cfg.duration_s * cfg.gnss_rate_hz).floor() as u64;
    let n_pps = cfg.duration_s.floor() as u64;
    let (mut k, mut m, mut s) = (0u64, 1u64, 1u64);
    let mut line = Vec::with_capacity(160);
    let mut esf_blocks: Vec<EsfRawBlock> = Vec::new();
    loop {
        // Next event of each stream (GPS time of its write).
        let t_imu = (k < n_imu).then(|| imu_truth(&cfg, k));
        let t_gnss = (m <= n_gnss).then(|| {
            cfg.start
                .add_seconds(m as f64 / cfg.gnss_rate_hz + cfg.gnss_latency_s)
        });
        let t_pps = (s <= n_pps).then(|| cfg.start + s as i64 * NS_PER_S);
        let Some(next) = [t_imu, t_gnss, t_pps].into_iter().flatten().min() else {
            break;
        };
        let due = clock.host_at(next);
        if !sleep_until(due, stop) {
            break;
        }
        st.max_late_s = st
            .max_late_s
            .max(hostclock::now_ns().saturating_sub(due) as f64 * 1e-9);
        let rel = next.seconds_since(cfg.start);
        if Some(next) == t_pps {
            if !within(cfg.pps_gap, rel) {
                pps.edge(due);
                st.pps_injected += 1;
            }
            s += 1;
        } else if Some(next) == t_imu {
            match (within(cfg.imu_unplug, rel), imu.is_plugged()) {
                (true, true) => imu.unplug(),
                (false, false) => imu.plug()?,
                _ => {}
            }
            if imu.is_plugged() {
                let vals = [
                    w_ie.x + cfg.gyro_sd * rng::normal(&mut noise),
                    w_ie.y + cfg.gyro_sd * rng::normal(&mut noise),
                    w_ie.z + cfg.gyro_sd * rng::normal(&mut noise),
                    cfg.accel_sd * rng::normal(&mut noise),
                    cfg.accel_sd * rng::normal(&mut noise),
                    -g + cfg.accel_sd * rng::normal(&mut noise),
                ];
                if cfg.imu_esf {
                    // [F9K] Table 11 scaling: gyro deg/s · 2¹², accel m/s² · 2¹⁰.
                    let tag = (123_456 + k * (1000.0 / cfg.imu_rate_hz).round() as u64) as u32;
                    for (i, (&ty, v)) in esf_type::IMU6.iter().zip(vals).enumerate() {
                        let lsb = if i < 3 {
                            v.to_degrees() * 4096.0
                        } else {
                            v * 1024.0
                        };
                        esf_blocks.push(EsfRawBlock {
                            data_type: ty,
                            field: (lsb.round() as i32 as u32) & 0x00FF_FFFF,
                            s_ttag: tag,
                        });
                    }
                    if k % 5 == 4 {
                        let m = EsfRaw {
                            reserved1: [0; 4],
                            blocks: std::mem::take(&mut esf_blocks),
                        };
                        gnss.write(&encode_frame(0x10, 0x03, &m.encode()).unwrap_or_default())?;
                    }
                } else {
                    line.clear();
                    for (i, v) in vals.iter().enumerate() {
                        if i > 0 {
                            line.push(b' ');
                        }
                        push_f64(&mut line, *v);
                    }
                    line.push(b'\n');
                    if cfg
                        .imu_garbage_every
                        .is_some_and(|n| n > 0 && k % n == n - 1)
                    {
                        line.extend_from_slice(b"\x00\xffnoise on the line 1 2\r\n");
                    }
                    imu.write(&line)?;
                }
                st.imu_written += 1;
            } else {
                st.imu_unplugged += 1;
            }
            k += 1;
        } else {
            let valid = cfg.start.add_seconds(m as f64 / cfg.gnss_rate_hz);
            let n = [
                0.3 * rng::normal(&mut noise),
                0.3 * rng::normal(&mut noise),
                0.5 * rng::normal(&mut noise),
            ];
            let heading = cfg
                .dual_antenna
                .map(|(yaw, sd)| yaw + sd * rng::normal(&mut noise));
            gnss.write(&gnss_bytes(&cfg, valid, n, heading))?;
            st.gnss_epochs += 1;
            m += 1;
        }
    }
    st.cpu_s = thread_cpu_s();
    // Give the reader time to drain the last bytes before the PTYs close.
    std::thread::sleep(Duration::from_millis(200));
    Ok(st)
}
