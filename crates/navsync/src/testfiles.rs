//! Scratch directories for tests, navsync's own and those of crates built
//! on it: each under the temp dir, removed when dropped, and kept when
//! dropped while the thread panics (a failed test's files stay to be
//! looked at).

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// A fresh directory `navsync-<tag>-<pid>-<n>` (n counts this process's
/// directories, so tests running in parallel never share one). It derefs
/// to its path: the directory itself, or a path inside it
/// ([`TestDir::at`]).
pub struct TestDir {
    root: PathBuf,
    path: PathBuf,
}

impl TestDir {
    /// A new, empty directory.
    ///
    /// # Panics
    /// When the directory cannot be made: this is for tests.
    pub fn new(tag: &str) -> TestDir {
        static CREATED: AtomicUsize = AtomicUsize::new(0);
        let n = CREATED.fetch_add(1, Ordering::Relaxed);
        let root = std::env::temp_dir().join(format!("navsync-{tag}-{}-{n}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        std::fs::create_dir_all(&root)
            .unwrap_or_else(|e| panic!("cannot make {}: {e}", root.display()));
        TestDir {
            path: root.clone(),
            root,
        }
    }

    /// The same directory, now standing for `name` inside it (removed
    /// with it).
    pub fn at(mut self, name: &str) -> TestDir {
        self.path = self.root.join(name);
        self
    }

    /// The directory removed on drop.
    pub fn root(&self) -> &Path {
        &self.root
    }
}

impl std::ops::Deref for TestDir {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.path
    }
}

impl AsRef<Path> for TestDir {
    fn as_ref(&self) -> &Path {
        &self.path
    }
}

impl AsRef<OsStr> for TestDir {
    fn as_ref(&self) -> &OsStr {
        self.path.as_os_str()
    }
}

impl Drop for TestDir {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.root);
        }
    }
}

/// `content` written to `name` in a new [`TestDir`], which stands for the
/// file.
///
/// # Panics
/// When the file cannot be written: this is for tests.
pub fn temp_file(tag: &str, name: &str, content: impl AsRef<[u8]>) -> TestDir {
    let d = TestDir::new(tag).at(name);
    std::fs::write(&*d, content).unwrap_or_else(|e| panic!("cannot write {}: {e}", d.display()));
    d
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_passing_test_leaves_nothing_and_a_failing_one_keeps_its_files() {
        let f = temp_file("testfiles", "a.txt", "1 2 3\n");
        let root = f.root().to_path_buf();
        assert_eq!(std::fs::read_to_string(&*f).unwrap(), "1 2 3\n");
        assert_eq!(f.parent(), Some(root.as_path()));
        drop(f);
        assert!(!root.exists());
        // Dropped while panicking: kept.
        let kept = std::thread::spawn(|| {
            let d = TestDir::new("testfiles");
            let root = d.root().to_path_buf();
            let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(move || {
                let _d = d;
                panic!("a failing test");
            }));
            assert!(r.is_err());
            root
        })
        .join()
        .unwrap();
        assert!(kept.is_dir());
        std::fs::remove_dir_all(kept).unwrap();
    }
}
