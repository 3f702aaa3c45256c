//! `navsync live --record`: every record the live loop receives, on the
//! host counter, as a `rig-log v1` file (through the core's writer,
//! [`navsync::io::riglog::write`]), and the receiver's raw bytes as read
//! from its port (`--record-gnss`).
//!
//! A record is taken in by the engine thread before the engine sees it.
//! The threads' records reach the engine a little out of counter order
//! (an NMEA fix is known complete only when the next epoch starts), and a
//! rig log is read with only 10 ms of reordering tolerated, so records wait
//! [`HOLD`] in a queue sorted by counter. Both files are written to the OS
//! every [`FLUSH_EVERY`] (no fsync): a `kill -9` loses what arrived in the
//! last `HOLD + FLUSH_EVERY` (0.75 s), an OS crash what the page cache
//! held. A cut last line is skipped by the reader with its line number.

use std::collections::VecDeque;
use std::fs::{File, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use navsync::io::riglog::{RigHeader, RigRecord, write};

/// How long a record waits for earlier-stamped records from other threads.
pub const HOLD: Duration = Duration::from_millis(500);
/// How often the files are written to the OS.
pub const FLUSH_EVERY: Duration = Duration::from_millis(250);

/// A file that only grows, written to the OS every [`FLUSH_EVERY`].
struct AppendFile {
    path: PathBuf,
    file: File,
    buf: Vec<u8>,
    bytes: u64,
}

impl AppendFile {
    /// Creates `path`; an existing file is refused (a recording is never
    /// overwritten).
    fn create(path: &Path) -> io::Result<Self> {
        let file = OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(path)
            .map_err(|e| {
                let why = if e.kind() == io::ErrorKind::AlreadyExists {
                    "exists (a recording is never overwritten: give a new name)".to_string()
                } else {
                    e.to_string()
                };
                io::Error::new(e.kind(), format!("{}: {why}", path.display()))
            })?;
        Ok(AppendFile {
            path: path.to_path_buf(),
            file,
            buf: Vec::with_capacity(1 << 16),
            bytes: 0,
        })
    }

    fn flush(&mut self) -> io::Result<()> {
        if self.buf.is_empty() {
            return Ok(());
        }
        self.file
            .write_all(&self.buf)
            .map_err(|e| io::Error::new(e.kind(), format!("{}: {e}", self.path.display())))?;
        self.bytes += self.buf.len() as u64;
        self.buf.clear();
        Ok(())
    }
}

/// What was recorded.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct RecordCounts {
    pub imu: u64,
    pub gnss: u64,
    pub pps: u64,
    /// Receiver headings (`heading` records).
    pub headings: u64,
    /// Records that came after a later-stamped one had been written (they
    /// are written anyway; `sync` skips those more than 10 ms back).
    pub late: u64,
    pub rig_bytes: u64,
    pub raw_gnss_bytes: u64,
}

/// The rig log and the raw receiver bytes of a live run.
pub struct Recorder {
    rig: Option<AppendFile>,
    raw: Option<AppendFile>,
    /// Records by counter, waiting [`HOLD`]; equal counters keep arrival order.
    queue: VecDeque<RigRecord>,
    last_written: u64,
    last_flush: Instant,
    pub counts: RecordCounts,
}

impl Recorder {
    /// Creates the files (either may be `None`) and writes the header.
    pub fn create(
        rig: Option<&Path>,
        raw_gnss: Option<&Path>,
        header: &RigHeader,
        comments: &[&str],
    ) -> io::Result<Self> {
        let mut rig = rig.map(AppendFile::create).transpose()?;
        let raw = raw_gnss.map(AppendFile::create).transpose()?;
        if let Some(f) = rig.as_mut() {
            f.buf.extend_from_slice(header.to_text().as_bytes());
            for c in comments {
                f.buf.extend_from_slice(format!("# {c}\n").as_bytes());
            }
            f.flush()?;
        }
        Ok(Recorder {
            rig,
            raw,
            queue: VecDeque::new(),
            last_written: 0,
            last_flush: Instant::now(),
            counts: RecordCounts::default(),
        })
    }

    pub fn records_rig(&self) -> bool {
        self.rig.is_some()
    }

    pub fn records_raw(&self) -> bool {
        self.raw.is_some()
    }

    /// Takes a record in (written within [`HOLD`] + [`FLUSH_EVERY`]).
    pub fn record(&mut self, r: RigRecord) {
        if self.rig.is_none() {
            return;
        }
        match r {
            RigRecord::Imu { .. } => self.counts.imu += 1,
            RigRecord::Gnss(_) => self.counts.gnss += 1,
            RigRecord::Pps { .. } => self.counts.pps += 1,
            RigRecord::Heading(_) => self.counts.headings += 1,
            RigRecord::Mark { .. } => {}
        }
        let c = r.counter();
        if c < self.last_written {
            self.counts.late += 1;
        }
        let at = self
            .queue
            .iter()
            .rposition(|q| q.counter() <= c)
            .map_or(0, |i| i + 1);
        self.queue.insert(at, r);
    }

    /// Appends bytes read from the receiver's port.
    pub fn raw_gnss(&mut self, bytes: &[u8]) {
        if let Some(f) = self.raw.as_mut() {
            f.buf.extend_from_slice(bytes);
        }
    }

    /// Writes what is due when [`FLUSH_EVERY`] has passed; call often.
    pub fn tick(&mut self, now_ns: u64) -> io::Result<()> {
        if self.last_flush.elapsed() < FLUSH_EVERY {
            return Ok(());
        }
        self.last_flush = Instant::now();
        self.write_due(now_ns.saturating_sub(HOLD.as_nanos() as u64))
    }

    /// Writes everything (the end of a run).
    pub fn finish(&mut self) -> io::Result<()> {
        self.write_due(u64::MAX)
    }

    fn write_due(&mut self, upto_ns: u64) -> io::Result<()> {
        if let Some(f) = self.rig.as_mut() {
            while let Some(r) = self.queue.front()
                && r.counter() <= upto_ns
            {
                self.last_written = self.last_written.max(r.counter());
                write::record(&mut f.buf, r);
                self.queue.pop_front();
            }
            f.flush()?;
            self.counts.rig_bytes = f.bytes;
        }
        if let Some(f) = self.raw.as_mut() {
            f.flush()?;
            self.counts.raw_gnss_bytes = f.bytes;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use navsync::io::riglog::ImuKind;

    #[test]
    fn records_leave_in_counter_order_and_existing_files_are_refused() {
        let dir = navsync::testfiles::TestDir::new("record");
        let p = dir.join("rig.csv");
        let h = RigHeader::new(1e9, 64, ImuKind::Rate);
        let mut r = Recorder::create(Some(&p), None, &h, &["a comment"]).unwrap();
        let imu = |c| RigRecord::Imu {
            counter: c,
            values: [c as f64, 0.0, 0.0, 0.0, 0.0, 0.0],
        };
        for rec in [
            imu(10),
            imu(20),
            imu(20),
            RigRecord::Pps { counter: 15 },
            imu(30),
        ] {
            r.record(rec);
        }
        r.write_due(20).unwrap();
        r.record(RigRecord::Pps { counter: 18 });
        r.finish().unwrap();
        let text = std::fs::read_to_string(&p).unwrap();
        let recs: Vec<&str> = text.lines().filter(|l| !l.starts_with('#')).collect();
        assert_eq!(
            recs,
            [
                "imu,10,10.0,0.0,0.0,0.0,0.0,0.0",
                "pps,15",
                "imu,20,20.0,0.0,0.0,0.0,0.0,0.0",
                "imu,20,20.0,0.0,0.0,0.0,0.0,0.0",
                "pps,18",
                "imu,30,30.0,0.0,0.0,0.0,0.0,0.0"
            ]
        );
        assert!(text.starts_with("# rig-log v1\n") && text.contains("# a comment\n"));
        assert_eq!(r.counts.late, 1);
        let e = Recorder::create(Some(&p), None, &h, &[]).err().unwrap();
        assert!(e.to_string().contains("never overwritten"), "{e}");
    }
}
