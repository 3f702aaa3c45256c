//! 1PPS edges: a small trait with the Linux kernel implementation (RFC 2783
//! PPS API on `/dev/ppsN`) and an injected one for tests and replays.
//!
//! Kernel API (RFC 2783 §3; Linux `include/uapi/linux/pps.h`): `PPS_GETCAP`
//! tells the capabilities (`PPS_CAPTUREASSERT`, `PPS_CANWAIT`),
//! `PPS_GETPARAMS`/`PPS_SETPARAMS` enable assert capture, and `PPS_FETCH`
//! waits (with a timeout) for the next event and returns the latest assert
//! timestamp with its sequence number. The ioctl numbers encode the size of
//! a *pointer* (`_IOR('p', 0xa1, struct pps_kparams *)`): they differ
//! between 32- and 64-bit targets and between architectures, so they are
//! built with libc's `_IOR`/`_IOWR` for the target, never hard-coded.
//! Timestamps are `CLOCK_REALTIME` and converted to the host counter
//! ([`crate::hostclock::realtime_to_raw`]) right after each fetch.

use std::io;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Duration;

use crate::hostclock;

/// One 1PPS assert edge on the host clock.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub struct PpsEdge {
    /// Host counter (CLOCK_MONOTONIC_RAW ns) of the edge.
    pub host_ns: u64,
    /// Edges the source counted but could not deliver before this one.
    pub missed: u64,
}

/// A source of 1PPS edges.
pub trait PpsSource: Send {
    /// Waits up to `timeout` for the next edge; `Ok(None)` when none came.
    /// An error means the source is gone (the caller may reopen it).
    fn next_edge(&mut self, timeout: Duration) -> io::Result<Option<PpsEdge>>;
    /// What to call it in messages.
    fn name(&self) -> String;
}

// RFC 2783 / linux/pps.h
const PPS_CAPTUREASSERT: libc::c_int = 0x01;
const PPS_CANWAIT: libc::c_int = 0x100;
const PPS_TSFMT_TSPEC: libc::c_int = 0x1000;
const PPS_TIME_INVALID: u32 = 1;

#[repr(C)]
#[derive(Copy, Clone, Default, Debug)]
struct PpsKtime {
    sec: i64,
    nsec: i32,
    flags: u32,
}

#[repr(C)]
#[derive(Copy, Clone, Default, Debug)]
struct PpsKinfo {
    assert_sequence: u32,
    clear_sequence: u32,
    assert_tu: PpsKtime,
    clear_tu: PpsKtime,
    current_mode: libc::c_int,
}

#[repr(C)]
#[derive(Copy, Clone, Default, Debug)]
struct PpsKparams {
    api_version: libc::c_int,
    mode: libc::c_int,
    assert_off_tu: PpsKtime,
    clear_off_tu: PpsKtime,
}

#[repr(C)]
#[derive(Copy, Clone, Default, Debug)]
struct PpsFdata {
    info: PpsKinfo,
    timeout: PpsKtime,
}

const P: u32 = b'p' as u32;
/// `_IOR('p', 0xa1, struct pps_kparams *)`
pub(crate) const PPS_GETPARAMS: libc::Ioctl = libc::_IOR::<*mut libc::c_void>(P, 0xa1);
/// `_IOW('p', 0xa2, struct pps_kparams *)`
pub(crate) const PPS_SETPARAMS: libc::Ioctl = libc::_IOW::<*mut libc::c_void>(P, 0xa2);
/// `_IOR('p', 0xa3, int *)`
pub(crate) const PPS_GETCAP: libc::Ioctl = libc::_IOR::<*mut libc::c_int>(P, 0xa3);
/// `_IOWR('p', 0xa4, struct pps_fdata *)`
pub(crate) const PPS_FETCH: libc::Ioctl = libc::_IOWR::<*mut libc::c_void>(P, 0xa4);

/// A kernel PPS device (`/dev/ppsN`).
pub(crate) struct KernelPps {
    fd: OwnedFd,
    path: PathBuf,
    last_seq: Option<u32>,
}

impl KernelPps {
    /// Opens `path`, checks that it can capture assert edges and wait for
    /// them, and enables assert capture (when permitted).
    pub(crate) fn open(path: &Path) -> io::Result<Self> {
        let c = std::ffi::CString::new(path.as_os_str().as_encoded_bytes()).map_err(|_| {
            io::Error::new(io::ErrorKind::InvalidInput, "PPS path holds a NUL byte")
        })?;
        let err = |what: &str| {
            let e = io::Error::last_os_error();
            io::Error::new(e.kind(), format!("{}: {what}: {e}", path.display()))
        };
        // SAFETY: valid NUL-terminated path.
        let mut raw = unsafe { libc::open(c.as_ptr(), libc::O_RDWR | libc::O_CLOEXEC) };
        if raw < 0 && io::Error::last_os_error().raw_os_error() == Some(libc::EACCES) {
            // Read-only suffices to fetch when capture is already enabled.
            // SAFETY: as above.
            raw = unsafe { libc::open(c.as_ptr(), libc::O_RDONLY | libc::O_CLOEXEC) };
        }
        if raw < 0 {
            return Err(err("cannot open PPS device"));
        }
        // SAFETY: freshly opened descriptor, owned here only.
        let fd = unsafe { OwnedFd::from_raw_fd(raw) };
        let mut caps: libc::c_int = 0;
        // SAFETY: PPS_GETCAP writes one int.
        if unsafe { libc::ioctl(fd.as_raw_fd(), PPS_GETCAP, &mut caps as *mut libc::c_int) } != 0 {
            return Err(err("PPS_GETCAP failed (not a PPS device?)"));
        }
        if caps & PPS_CAPTUREASSERT == 0 || caps & PPS_CANWAIT == 0 {
            return Err(io::Error::new(
                io::ErrorKind::Unsupported,
                format!(
                    "{}: PPS device cannot capture assert edges and wait for them (capabilities 0x{caps:x})",
                    path.display()
                ),
            ));
        }
        let mut params = PpsKparams::default();
        // SAFETY: PPS_GETPARAMS writes one pps_kparams.
        if unsafe {
            libc::ioctl(
                fd.as_raw_fd(),
                PPS_GETPARAMS,
                &mut params as *mut PpsKparams,
            )
        } == 0
            && params.mode & PPS_CAPTUREASSERT == 0
        {
            params.mode |= PPS_CAPTUREASSERT | PPS_TSFMT_TSPEC;
            // SAFETY: PPS_SETPARAMS reads one pps_kparams. Failure (no
            // permission) surfaces as fetch timeouts, reported by the caller.
            unsafe {
                libc::ioctl(
                    fd.as_raw_fd(),
                    PPS_SETPARAMS,
                    &mut params as *mut PpsKparams,
                )
            };
        }
        Ok(KernelPps {
            fd,
            path: path.to_path_buf(),
            last_seq: None,
        })
    }
}

impl PpsSource for KernelPps {
    fn next_edge(&mut self, timeout: Duration) -> io::Result<Option<PpsEdge>> {
        let mut d = PpsFdata {
            timeout: PpsKtime {
                sec: timeout.as_secs() as i64,
                nsec: timeout.subsec_nanos() as i32,
                flags: 0,
            },
            ..Default::default()
        };
        // SAFETY: PPS_FETCH reads the timeout and writes the info of one pps_fdata.
        let rc = unsafe { libc::ioctl(self.fd.as_raw_fd(), PPS_FETCH, &mut d as *mut PpsFdata) };
        if rc != 0 {
            let e = io::Error::last_os_error();
            return match e.raw_os_error() {
                Some(libc::ETIMEDOUT) | Some(libc::EINTR) => Ok(None),
                _ => Err(io::Error::new(
                    e.kind(),
                    format!("{}: PPS_FETCH: {e}", self.path.display()),
                )),
            };
        }
        let info = d.info;
        let seq = info.assert_sequence;
        if info.assert_tu.flags & PPS_TIME_INVALID != 0 || self.last_seq == Some(seq) {
            return Ok(None); // woken by a clear event, or nothing new
        }
        let missed = self
            .last_seq
            .map(|l| seq.wrapping_sub(l).saturating_sub(1) as u64)
            .unwrap_or(0);
        self.last_seq = Some(seq);
        let real = info.assert_tu.sec * 1_000_000_000 + info.assert_tu.nsec as i64;
        Ok(Some(PpsEdge {
            host_ns: hostclock::realtime_to_raw(real),
            missed,
        }))
    }

    fn name(&self) -> String {
        self.path.display().to_string()
    }
}

/// Edges pushed by another thread (tests, replays, a GPIO poller).
pub(crate) struct InjectedPps {
    rx: mpsc::Receiver<u64>,
}

/// The sending half of [`InjectedPps`].
#[derive(Clone)]
pub struct PpsInjector {
    tx: mpsc::Sender<u64>,
}

impl PpsInjector {
    /// Injects an edge that happened at host counter `host_ns`.
    pub fn edge(&self, host_ns: u64) {
        let _ = self.tx.send(host_ns);
    }
}

/// An injector and the source it feeds.
pub(crate) fn injected() -> (PpsInjector, InjectedPps) {
    let (tx, rx) = mpsc::channel();
    (PpsInjector { tx }, InjectedPps { rx })
}

impl PpsSource for InjectedPps {
    fn next_edge(&mut self, timeout: Duration) -> io::Result<Option<PpsEdge>> {
        match self.rx.recv_timeout(timeout) {
            Ok(host_ns) => Ok(Some(PpsEdge { host_ns, missed: 0 })),
            Err(mpsc::RecvTimeoutError::Timeout) => Ok(None),
            Err(mpsc::RecvTimeoutError::Disconnected) => {
                std::thread::sleep(timeout);
                Ok(None)
            }
        }
    }

    fn name(&self) -> String {
        "injected PPS".into()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    // `Ioctl` is c_ulong or c_int depending on the target: the casts are not no-ops everywhere.
    #[allow(clippy::unnecessary_cast)]
    #[test]
    fn ioctl_numbers_match_the_kernel_headers() {
        // linux/pps.h on x86_64 (8-byte pointers), asm-generic ioctl layout.
        #[cfg(all(target_arch = "x86_64", target_os = "linux"))]
        {
            assert_eq!(PPS_GETPARAMS as u64, 0x800870a1);
            assert_eq!(PPS_SETPARAMS as u64, 0x400870a2);
            assert_eq!(PPS_GETCAP as u64, 0x800870a3);
            assert_eq!(PPS_FETCH as u64, 0xc00870a4);
        }
        // The size field is a pointer's size on every target.
        let size = ((PPS_FETCH as u64) >> 16) & 0x1fff;
        assert_eq!(size as usize, std::mem::size_of::<*mut u8>());
    }

    #[test]
    fn missing_or_wrong_devices_are_clear_errors() {
        let e = KernelPps::open(Path::new("/dev/pps-navsync-none"))
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.contains("/dev/pps-navsync-none") && e.contains("cannot open"),
            "{e}"
        );
        let e = KernelPps::open(Path::new("/dev/null"))
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("PPS_GETCAP"), "{e}");
    }

    #[test]
    fn injected_edges_arrive_and_timeouts_are_none() {
        let (inj, mut src) = injected();
        inj.edge(42);
        assert_eq!(
            src.next_edge(Duration::from_millis(10)).unwrap(),
            Some(PpsEdge {
                host_ns: 42,
                missed: 0
            })
        );
        assert_eq!(src.next_edge(Duration::from_millis(5)).unwrap(), None);
    }
}
