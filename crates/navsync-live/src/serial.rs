//! Serial ports in raw mode (termios), read with a timeout (poll).
//!
//! A port that is not a terminal (a FIFO, a file) is read as it is, without
//! termios settings. A vanished device (USB adapter unplugged, PTY master
//! closed) reads as [`std::io::ErrorKind::BrokenPipe`]; the caller reopens.

use std::io;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The termios speed constant of a standard baud rate.
pub(crate) fn baud_constant(baud: u32) -> Option<libc::speed_t> {
    Some(match baud {
        1200 => libc::B1200,
        2400 => libc::B2400,
        4800 => libc::B4800,
        9600 => libc::B9600,
        19200 => libc::B19200,
        38400 => libc::B38400,
        57600 => libc::B57600,
        115200 => libc::B115200,
        230400 => libc::B230400,
        460800 => libc::B460800,
        500000 => libc::B500000,
        576000 => libc::B576000,
        921600 => libc::B921600,
        1000000 => libc::B1000000,
        1500000 => libc::B1500000,
        2000000 => libc::B2000000,
        3000000 => libc::B3000000,
        4000000 => libc::B4000000,
        _ => return None,
    })
}

/// Checks a baud rate before any port is opened.
pub(crate) fn check_baud(baud: u32) -> Result<(), String> {
    match baud_constant(baud) {
        Some(_) => Ok(()),
        None => Err(format!(
            "baud rate {baud} is not a standard rate (1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200, 230400, 460800, 500000, 576000, 921600, 1000000, 1500000, 2000000, 3000000, 4000000)"
        )),
    }
}

/// An open serial port (or other readable character source).
pub(crate) struct SerialPort {
    fd: OwnedFd,
    path: PathBuf,
    /// False for a source that is not a terminal (no termios applied).
    pub is_tty: bool,
}

fn os_err(path: &Path, what: &str) -> io::Error {
    let e = io::Error::last_os_error();
    io::Error::new(e.kind(), format!("{}: {what}: {e}", path.display()))
}

impl SerialPort {
    /// Opens `path` non-blocking, raw 8N1 at `baud`, no flow control.
    pub(crate) fn open(path: &Path, baud: u32) -> io::Result<Self> {
        let speed = baud_constant(baud).ok_or_else(|| {
            io::Error::new(
                io::ErrorKind::InvalidInput,
                check_baud(baud).err().unwrap_or_default(),
            )
        })?;
        let c = std::ffi::CString::new(path.as_os_str().as_encoded_bytes()).map_err(|_| {
            io::Error::new(io::ErrorKind::InvalidInput, "device path holds a NUL byte")
        })?;
        // SAFETY: `c` is a valid NUL-terminated path.
        let raw = unsafe {
            libc::open(
                c.as_ptr(),
                libc::O_RDWR | libc::O_NOCTTY | libc::O_NONBLOCK | libc::O_CLOEXEC,
            )
        };
        if raw < 0 {
            return Err(os_err(path, "cannot open"));
        }
        // SAFETY: `raw` is a freshly opened descriptor owned by nobody else.
        let fd = unsafe { OwnedFd::from_raw_fd(raw) };
        // SAFETY: an all-zero termios is valid storage for tcgetattr.
        let mut t: libc::termios = unsafe { std::mem::zeroed() };
        // SAFETY: valid descriptor and writable termios.
        if unsafe { libc::tcgetattr(fd.as_raw_fd(), &mut t) } != 0 {
            if io::Error::last_os_error().raw_os_error() == Some(libc::ENOTTY) {
                return Ok(SerialPort {
                    fd,
                    path: path.to_path_buf(),
                    is_tty: false,
                });
            }
            return Err(os_err(path, "tcgetattr"));
        }
        // SAFETY: `t` was filled by tcgetattr; these only modify it.
        unsafe {
            libc::cfmakeraw(&mut t);
            libc::cfsetispeed(&mut t, speed);
            libc::cfsetospeed(&mut t, speed);
        }
        t.c_cflag |= libc::CLOCAL | libc::CREAD;
        t.c_cflag &= !(libc::CRTSCTS | libc::CSTOPB | libc::PARENB);
        t.c_iflag &= !(libc::IXON | libc::IXOFF | libc::IXANY);
        t.c_cc[libc::VMIN] = 0;
        t.c_cc[libc::VTIME] = 0;
        // SAFETY: valid descriptor and termios.
        if unsafe { libc::tcsetattr(fd.as_raw_fd(), libc::TCSANOW, &t) } != 0 {
            return Err(os_err(path, &format!("setting raw mode at {baud} baud")));
        }
        Ok(SerialPort {
            fd,
            path: path.to_path_buf(),
            is_tty: true,
        })
    }

    /// Reads what is there, waiting up to `timeout`; `Ok(0)` when nothing
    /// came. A device that went away is `ErrorKind::BrokenPipe`.
    pub(crate) fn read_timeout(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize> {
        let mut p = libc::pollfd {
            fd: self.fd.as_raw_fd(),
            events: libc::POLLIN,
            revents: 0,
        };
        let ms = timeout.as_millis().min(i32::MAX as u128) as i32;
        // SAFETY: one valid pollfd.
        let n = unsafe { libc::poll(&mut p, 1, ms) };
        if n < 0 {
            let e = io::Error::last_os_error();
            if e.kind() == io::ErrorKind::Interrupted {
                return Ok(0);
            }
            return Err(e);
        }
        if n == 0 {
            return Ok(0);
        }
        if p.revents & libc::POLLIN == 0 {
            // POLLHUP / POLLERR / POLLNVAL without data.
            return Err(self.gone("hung up"));
        }
        // SAFETY: `buf` is valid for `buf.len()` writable bytes.
        let r = unsafe { libc::read(p.fd, buf.as_mut_ptr().cast(), buf.len()) };
        if r < 0 {
            let e = io::Error::last_os_error();
            return match e.kind() {
                io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted => Ok(0),
                _ if e.raw_os_error() == Some(libc::EIO) => Err(self.gone("I/O error")),
                _ => Err(io::Error::new(
                    e.kind(),
                    format!("{}: read: {e}", self.path.display()),
                )),
            };
        }
        if r == 0 {
            if self.is_tty {
                return Err(self.gone("end of data"));
            }
            // A FIFO with no writer or the end of a file: wait like a quiet port.
            std::thread::sleep(timeout.min(Duration::from_millis(50)));
        }
        Ok(r as usize)
    }

    fn gone(&self, what: &str) -> io::Error {
        io::Error::new(
            io::ErrorKind::BrokenPipe,
            format!("{}: device gone ({what})", self.path.display()),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_baud_and_missing_device_are_clear_errors() {
        assert!(check_baud(115200).is_ok());
        let e = check_baud(123).unwrap_err();
        assert!(e.contains("123") && e.contains("115200"), "{e}");
        let e = SerialPort::open(Path::new("/dev/navsync-no-such-tty"), 115200)
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.contains("/dev/navsync-no-such-tty") && e.contains("cannot open"),
            "{e}"
        );
        let e = SerialPort::open(Path::new("/dev/null"), 7).err().unwrap();
        assert_eq!(e.kind(), io::ErrorKind::InvalidInput);
    }
}
