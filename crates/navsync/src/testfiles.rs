//! Files written by the core's unit tests: each in its own directory
//! under the temp dir, removed when the test passes. A failing test
//! (dropped while panicking) leaves it in place to be looked at.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// A file of one test; derefs to its path.
pub(crate) struct TempFile {
    dir: PathBuf,
    path: PathBuf,
}

impl std::ops::Deref for TempFile {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.path
    }
}

impl AsRef<Path> for TempFile {
    fn as_ref(&self) -> &Path {
        &self.path
    }
}

impl Drop for TempFile {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}

/// Writes `content` to `name` in a fresh directory
/// `navsync-<tag>-<pid>-<n>` (n counts the calls of this process, so
/// tests running in parallel never share a file).
pub(crate) fn temp_file(tag: &str, name: &str, content: impl AsRef<[u8]>) -> TempFile {
    static CALLS: AtomicUsize = AtomicUsize::new(0);
    let n = CALLS.fetch_add(1, Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!("navsync-{tag}-{}-{n}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, content).unwrap();
    TempFile { dir, path }
}
