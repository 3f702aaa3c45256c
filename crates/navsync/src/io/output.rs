//! Crash-safe outputs: a file under its final name is whole or absent, one
//! writer per output folder (issue 32, "Nothing silent, nothing
//! half-written").
//!
//! - [`AtomicFile`]: written to `.navsync-<name>.<pid>-<k>.tmp` in the same
//!   folder, flushed with every error checked, renamed onto the final name
//!   by [`AtomicFile::commit`] only (rename is atomic within a file system,
//!   POSIX `rename(2)`); dropped uncommitted (an error, a panic) it removes
//!   its temporary. [`write_file`] is `std::fs::write` done that way. Not
//!   fsynced: whole-or-absent holds when the process dies, not across a
//!   power cut. Special files (`/dev/stdout`, `/dev/full`, a FIFO) are
//!   written in place: they have no partial state to hide.
//! - [`OutputDir`]: the folder's lock (`DIR/.navsync.lock`, an advisory
//!   `flock` the OS releases when the process dies, holding the pid, the
//!   command line and the start time), the removal of stale temporaries
//!   of earlier runs, and the files an earlier run of the same command
//!   wrote moved into `DIR/.previous/` (the list is `DIR/.navsync-files`,
//!   kept up to date at every commit), so that no reader takes an earlier
//!   run's file for this run's.
//! - [`abandon_temporaries`]: for a signal handler (the CLI owns signals;
//!   the core has no signal code): removes every temporary of this process
//!   and blocks every later commit, so that nothing is renamed onto a
//!   final name after the handler ran.
#![warn(missing_docs)]

use std::collections::BTreeSet;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, MutexGuard};
use std::time::SystemTime;

use crate::error::Error;

/// The temporaries of this process that are not committed yet.
static TEMPS: Mutex<BTreeSet<PathBuf>> = Mutex::new(BTreeSet::new());
/// The output folders this process holds: canonical root, command, the
/// files written under it (relative paths).
static DIRS: Mutex<Vec<DirState>> = Mutex::new(Vec::new());
static COUNTER: AtomicUsize = AtomicUsize::new(0);

/// The name of the lock file in an output folder.
pub const LOCK_NAME: &str = ".navsync.lock";
/// The list of the files each command wrote into an output folder.
pub const MANIFEST_NAME: &str = ".navsync-files";
/// Where an earlier run's files go.
pub const PREVIOUS_NAME: &str = ".previous";

struct DirState {
    root: PathBuf,
    command: String,
    /// Files of other commands (kept in the manifest).
    others: Vec<(String, String)>,
    written: Vec<String>,
}

fn temps() -> MutexGuard<'static, BTreeSet<PathBuf>> {
    TEMPS.lock().unwrap_or_else(|p| p.into_inner())
}

fn dirs() -> MutexGuard<'static, Vec<DirState>> {
    DIRS.lock().unwrap_or_else(|p| p.into_inner())
}

/// A fresh temporary name beside `path`: `.navsync-<name>.<pid>-<k>.tmp`.
pub fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    let k = COUNTER.fetch_add(1, Ordering::Relaxed);
    path.with_file_name(format!(".navsync-{name}.{}-{k}.tmp", std::process::id()))
}

/// The pid in a temporary's name (`.navsync-<name>.<pid>[-<k>].tmp`, the
/// smoother's `.navsync-<tag>-<pid>-<k>-<ns>.tmp` of earlier versions).
fn temp_pid(file_name: &str) -> Option<Option<u32>> {
    let inner = file_name.strip_prefix(".navsync-")?.strip_suffix(".tmp")?;
    let pid = match inner.rsplit_once('.') {
        Some((_, tail)) => tail.split('-').next().and_then(|p| p.parse().ok()),
        None => inner.split('-').nth(1).and_then(|p| p.parse().ok()),
    };
    Some(pid)
}

/// Creates a temporary file registered for removal by
/// [`abandon_temporaries`]; `read` also opens it for reading.
pub(crate) fn create_temp(path: &Path, read: bool) -> Result<File, Error> {
    let mut t = temps();
    let file = File::options()
        .read(read)
        .write(true)
        .create_new(true)
        .open(path)
        .map_err(|e| Error::io(path, e))?;
    t.insert(path.to_path_buf());
    Ok(file)
}

/// Removes a temporary (ignoring a missing one) and forgets it.
pub(crate) fn remove_temp(path: &Path) {
    let mut t = temps();
    if t.remove(path) {
        let _ = std::fs::remove_file(path);
    }
}

/// Removes every uncommitted temporary of this process and blocks every
/// later commit and temporary (the registry's lock is never released): for
/// a signal handler that exits next. Returns how many were removed.
pub fn abandon_temporaries() -> usize {
    let t = temps();
    let n = t.iter().filter(|p| std::fs::remove_file(p).is_ok()).count();
    std::mem::forget(t);
    n
}

/// A file written under a temporary name and renamed onto its final name
/// when whole ([`AtomicFile::commit`]).
pub struct AtomicFile {
    inner: Option<BufWriter<File>>,
    /// `None`: a special file written in place.
    tmp: Option<PathBuf>,
    path: PathBuf,
}

impl AtomicFile {
    /// Starts `path` (its folder must exist); nothing appears under `path`
    /// before [`AtomicFile::commit`].
    pub fn create(path: &Path) -> Result<Self, Error> {
        Self::with_capacity(path, 64 << 10)
    }

    /// As [`AtomicFile::create`] with a write buffer of `bytes`.
    pub fn with_capacity(path: &Path, bytes: usize) -> Result<Self, Error> {
        // A symbolic link: its target is replaced, not the link.
        let path = match std::fs::symlink_metadata(path) {
            Ok(m) if m.file_type().is_symlink() => {
                std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf())
            }
            _ => path.to_path_buf(),
        };
        if std::fs::metadata(&path).is_ok_and(|m| !m.is_file()) {
            let file = File::create(&path).map_err(|e| Error::io(&path, e))?;
            return Ok(AtomicFile {
                inner: Some(BufWriter::with_capacity(bytes, file)),
                tmp: None,
                path,
            });
        }
        let tmp = temp_path(&path);
        let file = create_temp(&tmp, false).map_err(|e| match e {
            Error::Io { source, .. } => Error::io(&path, source),
            e => e,
        })?;
        Ok(AtomicFile {
            inner: Some(BufWriter::with_capacity(bytes, file)),
            tmp: Some(tmp),
            path,
        })
    }

    /// The final name.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Appends bytes; an error names the final file.
    pub fn write(&mut self, bytes: &[u8]) -> Result<(), Error> {
        let w = self
            .inner
            .as_mut()
            .ok_or_else(|| Error::io(&self.path, std::io::Error::other("already failed")))?;
        w.write_all(bytes).map_err(|e| self.fail(e))
    }

    /// Drops the temporary after an error; the error naming the file.
    fn fail(&mut self, e: std::io::Error) -> Error {
        self.inner = None;
        if let Some(t) = &self.tmp {
            remove_temp(t);
        }
        Error::io(&self.path, e)
    }

    /// Flushes every byte (each error reported: `BufWriter`'s drop ignores
    /// them) and renames the temporary onto the final name.
    pub fn commit(mut self) -> Result<(), Error> {
        let Some(w) = self.inner.take() else {
            return Err(Error::io(
                &self.path,
                std::io::Error::other("already failed"),
            ));
        };
        let file = match w.into_inner() {
            Ok(f) => f,
            Err(e) => {
                let err = std::io::Error::new(e.error().kind(), e.error().to_string());
                return Err(self.fail(err));
            }
        };
        drop(file);
        let Some(tmp) = self.tmp.take() else {
            return Ok(());
        };
        let mut t = temps();
        let renamed = std::fs::rename(&tmp, &self.path);
        t.remove(&tmp);
        drop(t);
        if let Err(e) = renamed {
            let _ = std::fs::remove_file(&tmp);
            return Err(Error::io(&self.path, e));
        }
        record_written(&self.path);
        Ok(())
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if let Some(t) = self.tmp.take() {
            self.inner = None;
            remove_temp(&t);
        }
    }
}

/// `std::fs::write` made whole-or-absent: `bytes` under a temporary name,
/// renamed onto `path`.
pub fn write_file(path: impl AsRef<Path>, bytes: impl AsRef<[u8]>) -> Result<(), Error> {
    let mut f = AtomicFile::create(path.as_ref())?;
    f.write(bytes.as_ref())?;
    f.commit()
}

/// Notes a committed file in the manifest of the output folder holding it.
fn record_written(path: &Path) {
    let Some(parent) = path.parent() else { return };
    let parent = if parent.as_os_str().is_empty() {
        Path::new(".")
    } else {
        parent
    };
    let Ok(parent) = std::fs::canonicalize(parent) else {
        return;
    };
    let Some(name) = path.file_name() else { return };
    let full = parent.join(name);
    let mut d = dirs();
    // The innermost folder held (a `process` run's `fuse/` is its own).
    let Some(state) = d
        .iter_mut()
        .filter(|s| full.starts_with(&s.root))
        .max_by_key(|s| s.root.as_os_str().len())
    else {
        return;
    };
    let Ok(rel) = full.strip_prefix(&state.root) else {
        return;
    };
    let rel = rel.to_string_lossy().replace('\\', "/");
    if !state.written.contains(&rel) {
        state.written.push(rel.clone());
    }
    state.others.retain(|(_, f)| *f != rel);
    // The manifest is bookkeeping: a failure to write it costs the next
    // run's clean-up, never this run's files.
    let _ = write_manifest(state);
}

fn write_manifest(s: &DirState) -> std::io::Result<()> {
    let mut text =
        String::from("# navsync: the files each command wrote here (command<TAB>path)\n");
    for (c, f) in &s.others {
        text.push_str(&format!("{c}\t{f}\n"));
    }
    for f in &s.written {
        text.push_str(&format!("{}\t{f}\n", s.command));
    }
    let path = s.root.join(MANIFEST_NAME);
    let tmp = temp_path(&path);
    std::fs::write(&tmp, text)?;
    std::fs::rename(&tmp, &path).inspect_err(|_| {
        let _ = std::fs::remove_file(&tmp);
    })
}

/// An output folder held by this run: locked against a second writer,
/// cleaned of stale temporaries, an earlier run's files moved aside.
/// Dropping it releases the lock (so does the process's death).
pub struct OutputDir {
    root: PathBuf,
    _lock: File,
    notes: Vec<String>,
}

impl OutputDir {
    /// Takes `dir` (created if missing) for a run of `command`; an error
    /// names the run that holds it.
    pub fn open(dir: &Path, command: &str) -> Result<Self, Error> {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        let root = std::fs::canonicalize(dir).map_err(|e| Error::io(dir, e))?;
        let lock_path = root.join(LOCK_NAME);
        let mut lock = File::options()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&lock_path)
            .map_err(|e| Error::io(&lock_path, e))?;
        match lock.try_lock() {
            Ok(()) => {}
            Err(std::fs::TryLockError::WouldBlock) => {
                let holder = std::fs::read_to_string(&lock_path).unwrap_or_default();
                return Err(Error::Invalid(format!(
                    "{} is being written by another navsync run ({}); wait for it to end or choose another output folder",
                    dir.display(),
                    describe_holder(&holder)
                )));
            }
            Err(std::fs::TryLockError::Error(e)) => return Err(Error::io(&lock_path, e)),
        }
        let started = SystemTime::now();
        let cmdline: Vec<String> = std::env::args().collect();
        let info = format!(
            "pid {}\ncommand {}\nsince {}\n",
            std::process::id(),
            cmdline.join(" "),
            utc_text(started)
        );
        lock.set_len(0)
            .and_then(|_| lock.write_all(info.as_bytes()))
            .and_then(|_| lock.flush())
            .map_err(|e| Error::io(&lock_path, e))?;
        let mut notes = Vec::new();
        let stale = remove_stale_temporaries(&root, started);
        if !stale.is_empty() {
            notes.push(format!(
                "removed {} stale temporary file(s) of earlier runs in {} ({})",
                stale.len(),
                dir.display(),
                list_names(&stale)
            ));
        }
        let (mine, others) = read_manifest(&root, command);
        let moved = move_aside(&root, &mine)?;
        if !moved.is_empty() {
            notes.push(format!(
                "moved {} file(s) of an earlier `{command}` run into {} ({}): only this run's files are left under their names",
                moved.len(),
                dir.join(PREVIOUS_NAME).display(),
                list_names(&moved)
            ));
        }
        let state = DirState {
            root: root.clone(),
            command: command.to_string(),
            others,
            written: Vec::new(),
        };
        let _ = write_manifest(&state);
        dirs().push(state);
        Ok(OutputDir {
            root,
            _lock: lock,
            notes,
        })
    }

    /// What opening the folder did (stale temporaries removed, earlier
    /// files moved aside), one sentence each, for the user.
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    /// The files this run has committed under the folder so far (paths
    /// relative to it, in order).
    pub fn written(&self) -> Vec<String> {
        dirs()
            .iter()
            .find(|s| s.root == self.root)
            .map(|s| s.written.clone())
            .unwrap_or_default()
    }
}

/// The files this process has committed under `dir` inside a folder it
/// holds ([`OutputDir`]), relative to `dir`, in order: what a run's
/// `summary.json` lists (`process`'s `fuse/` is inside its folder).
pub fn written_under(dir: &Path) -> Vec<String> {
    let Ok(dir) = std::fs::canonicalize(dir) else {
        return Vec::new();
    };
    let d = dirs();
    let Some(s) = d.iter().find(|s| dir.starts_with(&s.root)) else {
        return Vec::new();
    };
    let prefix = dir
        .strip_prefix(&s.root)
        .map(|p| p.to_string_lossy().replace('\\', "/"))
        .unwrap_or_default();
    s.written
        .iter()
        .filter_map(|f| {
            if prefix.is_empty() {
                Some(f.clone())
            } else {
                f.strip_prefix(&format!("{prefix}/")).map(str::to_string)
            }
        })
        .collect()
}

impl Drop for OutputDir {
    fn drop(&mut self) {
        dirs().retain(|s| s.root != self.root);
    }
}

fn describe_holder(text: &str) -> String {
    let field = |k: &str| {
        text.lines()
            .find_map(|l| l.strip_prefix(k).map(|v| v.trim().to_string()))
            .unwrap_or_else(|| "?".into())
    };
    format!(
        "pid {}, `{}`, since {}",
        field("pid "),
        field("command "),
        field("since ")
    )
}

fn list_names(names: &[String]) -> String {
    let mut s = names.iter().take(5).cloned().collect::<Vec<_>>().join(", ");
    if names.len() > 5 {
        s.push_str(&format!(", … {} more", names.len() - 5));
    }
    s
}

/// Whether process `pid` is alive: `/proc/<pid>` on Linux; elsewhere
/// unknown (`None`).
fn pid_alive(pid: u32) -> Option<bool> {
    cfg!(target_os = "linux").then(|| Path::new(&format!("/proc/{pid}")).exists())
}

/// Removes `.navsync-*.tmp` under `root` (not under `.previous/`) left by
/// a run that is dead or older than this one and not a temporary of this
/// process; their paths relative to `root`.
fn remove_stale_temporaries(root: &Path, started: SystemTime) -> Vec<String> {
    let me = std::process::id();
    let live = temps().clone();
    let mut removed = Vec::new();
    let mut stack = vec![(root.to_path_buf(), 0usize)];
    while let Some((dir, depth)) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            let Ok(ft) = e.file_type() else { continue };
            let path = e.path();
            if ft.is_dir() {
                // Bounded: output trees are a few levels deep.
                if name != PREVIOUS_NAME && depth < 4 {
                    stack.push((path, depth + 1));
                }
                continue;
            }
            let Some(pid) = temp_pid(&name) else { continue };
            if live.contains(&path) {
                continue;
            }
            let older = e
                .metadata()
                .and_then(|m| m.modified())
                .is_ok_and(|t| t < started);
            let dead = pid.is_none_or(|p| p != me && pid_alive(p) == Some(false));
            if (older || dead) && std::fs::remove_file(&path).is_ok() {
                let rel = path.strip_prefix(root).unwrap_or(&path);
                removed.push(rel.to_string_lossy().into_owned());
            }
        }
    }
    removed.sort();
    removed
}

/// The manifest's files of `command` and the other commands' entries.
fn read_manifest(root: &Path, command: &str) -> (Vec<String>, Vec<(String, String)>) {
    let text = std::fs::read_to_string(root.join(MANIFEST_NAME)).unwrap_or_default();
    let mut mine = Vec::new();
    let mut others = Vec::new();
    for line in text.lines().filter(|l| !l.starts_with('#')) {
        let Some((c, f)) = line.split_once('\t') else {
            continue;
        };
        // Only plain relative paths inside the folder are ever moved.
        let p = Path::new(f);
        if p.is_absolute()
            || p.components()
                .any(|c| !matches!(c, std::path::Component::Normal(_)))
        {
            continue;
        }
        if c == command {
            mine.push(f.to_string());
        } else {
            others.push((c.to_string(), f.to_string()));
        }
    }
    (mine, others)
}

/// Moves the files `rel` (relative to `root`) that exist into
/// `root/.previous/` (emptied first when there is something to move).
fn move_aside(root: &Path, rel: &[String]) -> Result<Vec<String>, Error> {
    let present: Vec<&String> = rel.iter().filter(|f| root.join(f).is_file()).collect();
    if present.is_empty() {
        return Ok(Vec::new());
    }
    let prev = root.join(PREVIOUS_NAME);
    if prev.exists() {
        std::fs::remove_dir_all(&prev).map_err(|e| Error::io(&prev, e))?;
    }
    let mut moved = Vec::new();
    for f in present {
        let to = prev.join(f);
        if let Some(p) = to.parent() {
            std::fs::create_dir_all(p).map_err(|e| Error::io(p, e))?;
        }
        let from = root.join(f);
        std::fs::rename(&from, &to).map_err(|e| Error::io(&from, e))?;
        moved.push(f.clone());
    }
    Ok(moved)
}

/// `YYYY-MM-DDThh:mm:ssZ` (civil from days: H. Hinnant, "chrono-Compatible
/// Low-Level Date Algorithms", `civil_from_days`).
fn utc_text(t: SystemTime) -> String {
    let secs = t
        .duration_since(SystemTime::UNIX_EPOCH)
        .map(|d| d.as_secs() as i64)
        .unwrap_or(0);
    let (days, sod) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z",
        sod / 3600,
        sod / 60 % 60,
        sod % 60
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testfiles::TestDir;

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn a_file_appears_only_when_committed_and_a_dropped_one_leaves_nothing() {
        let d = TestDir::new("atomic");
        let p = d.join("a.txt");
        let mut f = AtomicFile::create(&p).unwrap();
        f.write(b"hello\n").unwrap();
        assert!(!p.exists());
        assert_eq!(names(&d).len(), 1, "one temporary");
        f.commit().unwrap();
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "hello\n");
        assert_eq!(names(&d), ["a.txt"]);
        let mut g = AtomicFile::create(&p).unwrap();
        g.write(b"half").unwrap();
        drop(g);
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "hello\n");
        assert_eq!(names(&d), ["a.txt"], "the temporary is removed");
    }

    #[test]
    fn a_full_device_is_an_error_naming_it() {
        let p = Path::new("/dev/full");
        if !p.exists() {
            return;
        }
        let err = write_file(p, vec![b'x'; 200_000]).unwrap_err().to_string();
        assert!(err.starts_with("/dev/full:"), "{err}");
        assert!(p.exists(), "the device is not replaced");
    }

    #[test]
    fn temporary_names_carry_the_pid() {
        let t = temp_path(Path::new("/x/navresult.nav"));
        let n = t.file_name().unwrap().to_string_lossy().into_owned();
        assert!(n.starts_with(".navsync-navresult.nav."), "{n}");
        assert_eq!(temp_pid(&n), Some(Some(std::process::id())));
        assert_eq!(
            temp_pid(".navsync-forward-4242-3-123456.tmp"),
            Some(Some(4242))
        );
        assert_eq!(temp_pid("navresult.nav"), None);
    }

    #[test]
    fn a_second_writer_is_refused_naming_the_first() {
        let d = TestDir::new("outlock");
        let first = OutputDir::open(&d, "fuse").unwrap();
        let err = match OutputDir::open(&d, "fuse") {
            Ok(_) => panic!("a second writer was let in"),
            Err(e) => e.to_string(),
        };
        assert!(
            err.contains(&format!("pid {}", std::process::id())) && err.contains("since 20"),
            "{err}"
        );
        drop(first);
        OutputDir::open(&d, "fuse").unwrap();
    }

    #[test]
    fn stale_temporaries_are_removed_and_earlier_files_moved_aside() {
        let d = TestDir::new("outstale");
        std::fs::create_dir_all(d.join("forward")).unwrap();
        // A dead pid (beyond Linux's pid_max) and an old one of the
        // smoother's earlier naming.
        std::fs::write(d.join(".navsync-navresult.nav.4194399-0.tmp"), "x").unwrap();
        std::fs::write(d.join("forward/.navsync-nodes-4194399-1-5.tmp"), "x").unwrap();
        {
            let out = OutputDir::open(&d, "fuse").unwrap();
            assert!(
                out.notes()[0].contains("removed 2 stale"),
                "{:?}",
                out.notes()
            );
            write_file(d.join("time_offset.txt"), "t").unwrap();
            write_file(d.join("forward/navresult.nav"), "n").unwrap();
            write_file(d.join("navresult.nav"), "n").unwrap();
            assert_eq!(
                out.written(),
                ["time_offset.txt", "forward/navresult.nav", "navresult.nav"]
            );
            assert_eq!(written_under(&d.join("forward")), ["navresult.nav"]);
        }
        assert_eq!(
            names(&d),
            [
                ".navsync-files",
                ".navsync.lock",
                "forward",
                "navresult.nav",
                "time_offset.txt"
            ]
        );
        // Another command's files stay; this command's earlier ones go.
        std::fs::write(d.join("kf-gins.yaml"), "k").unwrap();
        {
            let out = OutputDir::open(&d, "sync").unwrap();
            write_file(d.join("kf-gins.yaml"), "k2").unwrap();
            assert!(out.notes().is_empty(), "{:?}", out.notes());
        }
        let out = OutputDir::open(&d, "fuse").unwrap();
        assert!(
            out.notes()[0].contains("moved 3 file(s)"),
            "{:?}",
            out.notes()
        );
        write_file(d.join("navresult.nav"), "n2").unwrap();
        assert!(!d.join("time_offset.txt").exists());
        assert!(d.join(".previous/time_offset.txt").exists());
        assert!(d.join(".previous/forward/navresult.nav").exists());
        assert_eq!(
            std::fs::read_to_string(d.join("kf-gins.yaml")).unwrap(),
            "k2"
        );
    }

    #[test]
    fn abandon_list_is_the_live_temporaries() {
        // Not calling abandon_temporaries (it blocks the registry for the
        // whole test process): the registry holds exactly the live ones.
        let d = TestDir::new("outreg");
        let f = AtomicFile::create(&d.join("a")).unwrap();
        let tmp = f.tmp.clone().unwrap();
        assert!(temps().contains(&tmp));
        drop(f);
        assert!(!temps().contains(&tmp));
    }

    #[test]
    fn utc_text_is_civil_time() {
        let t = SystemTime::UNIX_EPOCH + std::time::Duration::from_secs(1_764_857_696);
        assert_eq!(utc_text(t), "2025-12-04T14:14:56Z");
    }
}
