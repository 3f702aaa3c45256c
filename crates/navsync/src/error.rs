//! Typed errors and reported skips.
//!
//! Every error names where it happened (file and line, or configuration
//! key) and what was expected. Problems that lose nothing but the bad record
//! itself are not errors: they are [`Diagnostic`]s, collected and reported.
#![warn(missing_docs)]

use std::fmt;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

/// Everything that can stop a navsync operation.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file could not be opened, read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file that failed.
        path: PathBuf,
        /// The underlying I/O error.
        #[source]
        source: std::io::Error,
    },
    /// A record is malformed and cannot be skipped safely.
    #[error("{}:{line}: {msg}", path.display())]
    Parse {
        /// The file holding the record.
        path: PathBuf,
        /// 1-based line number of the record.
        line: usize,
        /// What is wrong with it and what was expected.
        msg: String,
    },
    /// A configuration is missing a key or holds a bad value.
    #[error("{}: {msg}", path.display())]
    Config {
        /// The configuration file (or sheet) concerned.
        path: PathBuf,
        /// The key and what is wrong with its value.
        msg: String,
    },
    /// The input holds no usable data.
    #[error("{}: {msg}", path.display())]
    NoData {
        /// The input that held nothing usable.
        path: PathBuf,
        /// Why nothing was usable.
        msg: String,
    },
    /// The filter's covariance lost symmetry or positive definiteness.
    #[error("filter covariance broke at GPS time {time}: {msg}")]
    Covariance {
        /// GPS time of the filter epoch at which it broke.
        time: crate::time::GpsTime,
        /// Which check failed.
        msg: String,
    },
    /// The navigation state or its covariance broke down (a value not
    /// finite, off the earth, a variance not positive): the run stops
    /// rather than write it.
    #[error("the navigation solution broke down at GPS time {time}: {msg}")]
    Diverged {
        /// GPS time of the IMU epoch at which it broke.
        time: crate::time::GpsTime,
        /// What broke, and the IMU record that was being processed.
        msg: String,
    },
    /// Inconsistent options or arguments; holds the message.
    #[error("{0}")]
    Invalid(String),
}

impl Error {
    /// An I/O error on `path`.
    pub fn io(path: &Path, source: std::io::Error) -> Self {
        Error::Io {
            path: path.to_path_buf(),
            source,
        }
    }

    /// A parse error at `path:line`.
    pub fn parse(path: &Path, line: usize, msg: impl Into<String>) -> Self {
        Error::Parse {
            path: path.to_path_buf(),
            line,
            msg: msg.into(),
        }
    }

    /// A configuration error in `path`.
    pub fn config(path: &Path, msg: impl Into<String>) -> Self {
        Error::Config {
            path: path.to_path_buf(),
            msg: msg.into(),
        }
    }
}

/// A reported skip or warning: something was wrong with one record and that
/// record alone was dropped (or a condition worth telling the user).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Diagnostic {
    /// The file concerned (empty when not file-related).
    pub(crate) file: String,
    /// 1-based line, 0 when not line-related.
    pub(crate) line: usize,
    /// What was wrong and what was done.
    pub message: String,
}

impl fmt::Display for Diagnostic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match (self.file.is_empty(), self.line) {
            (true, _) => write!(f, "{}", self.message),
            (false, 0) => write!(f, "{}: {}", self.file, self.message),
            (false, l) => write!(f, "{}:{}: {}", self.file, l, self.message),
        }
    }
}

/// A bounded collector of diagnostics: keeps the first `cap` in full and
/// counts the rest, so that a file with a million bad lines cannot exhaust
/// memory.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Diagnostics {
    /// The first diagnostics, in order.
    pub items: Vec<Diagnostic>,
    /// How many were reported in all (may exceed `items.len()`).
    pub total: usize,
    #[serde(skip)]
    cap: usize,
}

impl Diagnostics {
    /// Keeps at most `cap` diagnostics in full.
    pub fn with_cap(cap: usize) -> Self {
        Diagnostics {
            items: Vec::new(),
            total: 0,
            cap,
        }
    }

    /// Records one diagnostic.
    pub fn push(&mut self, file: &Path, line: usize, message: impl Into<String>) {
        self.total += 1;
        let cap = if self.cap == 0 { 1000 } else { self.cap };
        if self.items.len() < cap {
            self.items.push(Diagnostic {
                file: file.display().to_string(),
                line,
                message: message.into(),
            });
        }
    }

    /// Records a diagnostic not tied to a file.
    pub fn note(&mut self, message: impl Into<String>) {
        self.push(Path::new(""), 0, message);
    }

    /// Appends all of `other`.
    pub(crate) fn extend(&mut self, other: Diagnostics) {
        let extra = other.total - other.items.len();
        for d in other.items {
            self.total += 1;
            let cap = if self.cap == 0 { 1000 } else { self.cap };
            if self.items.len() < cap {
                self.items.push(d);
            }
        }
        self.total += extra;
    }

    /// True when nothing was reported.
    pub fn is_empty(&self) -> bool {
        self.total == 0
    }
}

/// Result alias for navsync.
pub type Result<T, E = Error> = std::result::Result<T, E>;
