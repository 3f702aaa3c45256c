//! The live solution as KF-GINS files (FORMATS.md §1): `navresult.nav` at
//! every IMU epoch, `imu_err.txt` and `std.txt` once a second, through the
//! batch pipeline's writer ([`KfGinsSink`], its own writer thread). The
//! files are created at the first solution, whose GPS week they carry.

use std::path::{Path, PathBuf};

use navsync::fusion::NavOutput;
use navsync::pipeline::{KfGinsSink, NavSink};

pub struct FileSink {
    dir: PathBuf,
    sink: Option<KfGinsSink>,
}

impl FileSink {
    pub fn new(dir: &Path) -> Self {
        FileSink {
            dir: dir.to_path_buf(),
            sink: None,
        }
    }

    pub fn nav(&mut self, out: &NavOutput) -> Result<(), navsync::Error> {
        if self.sink.is_none() {
            self.sink = Some(KfGinsSink::create(&self.dir, out.nav.time.week())?);
        }
        match self.sink.as_mut() {
            Some(s) => s.nav(&out.nav, &out.imu),
            None => Ok(()),
        }
    }

    pub fn aux(&mut self, out: &NavOutput, sd: &[f64]) -> Result<(), navsync::Error> {
        match self.sink.as_mut() {
            Some(s) => s.aux(out.nav.time, &out.imu, sd, None),
            None => Ok(()),
        }
    }

    /// Flushes and closes the files (nothing when no solution came).
    pub fn finish(self) -> Result<(), navsync::Error> {
        match self.sink {
            Some(s) => s.finish(),
            None => Ok(()),
        }
    }
}
