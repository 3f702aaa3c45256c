//! Crash-safe outputs (issue 32): a file under its final name is whole or
//! absent whatever kills the run (SIGKILL, SIGINT, a full disk), stale
//! temporaries go at the next run, and one writer per output folder.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::{bin, json, run, temp_dir};

/// A simulated test-track drive of `secs` s (KF-GINS files) in `dir/sim`.
fn simulate(dir: &Path, secs: u32) -> PathBuf {
    let sim = dir.join("sim");
    let (ok, _, err) = run(bin()
        .args(["simulate", "--quiet", "--internal-rate", "0", "--scenario"])
        .args(["test-track", "--imu-grade", "adis16465", "--seed", "5"])
        .args(["--duration", &secs.to_string(), "--output"])
        .arg(&sim));
    assert!(ok, "{err}");
    sim.join("kf-gins.yaml")
}

fn fuse_smooth(config: &Path, out: &Path) -> Child {
    bin()
        .args(["fuse", "--smooth", "--config"])
        .arg(config)
        .arg("--output")
        .arg(out)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// Every file under `dir` (recursively), `.previous/` left out.
fn files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let Ok(rd) = std::fs::read_dir(dir) else {
        return out;
    };
    for e in rd.flatten() {
        let p = e.path();
        if p.is_dir() {
            if e.file_name() != ".previous" {
                out.extend(files(&p));
            }
        } else {
            out.push(p);
        }
    }
    out
}

fn temporaries(dir: &Path) -> Vec<PathBuf> {
    files(dir)
        .into_iter()
        .filter(|p| {
            let n = p.file_name().unwrap().to_string_lossy();
            n.starts_with(".navsync-") && n.ends_with(".tmp")
        })
        .collect()
}

/// Every line of a text table ends with a line end and has the same
/// number of fields as the first data line; the number of data lines and
/// the last line's first field.
fn whole_table(p: &Path) -> (usize, f64) {
    let text = std::fs::read_to_string(p).unwrap();
    assert!(
        text.is_empty() || text.ends_with('\n'),
        "{}: cut last line",
        p.display()
    );
    let mut width = None;
    let (mut n, mut last) = (0, f64::NAN);
    for (k, line) in text.lines().enumerate() {
        if line.starts_with('#') || line.trim().is_empty() {
            continue;
        }
        let f: Vec<&str> = line.split_whitespace().collect();
        let w = *width.get_or_insert(f.len());
        assert_eq!(f.len(), w, "{}:{}: {line}", p.display(), k + 1);
        n += 1;
        // navresult.nav: week sow …; the others: sow …
        last = f[if p.ends_with("navresult.nav") { 1 } else { 0 }]
            .parse()
            .unwrap_or(f64::NAN);
    }
    (n, last)
}

/// Every file under a final name in `out` is whole; with summary.json,
/// the files it lists are there and navresult.nav reaches its end_sow.
/// Returns whether summary.json (a finished run) is there.
fn check_whole(out: &Path) -> bool {
    for p in files(out) {
        let name = p.file_name().unwrap().to_string_lossy().into_owned();
        if name.starts_with('.') {
            continue;
        }
        if name.ends_with(".json") {
            let _: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&p).unwrap())
                .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        } else {
            whole_table(&p);
        }
    }
    let summary = out.join("summary.json");
    if !summary.exists() {
        return false;
    }
    let s = json(&summary);
    for f in s["files"].as_array().unwrap() {
        assert!(
            out.join(f.as_str().unwrap()).is_file(),
            "{f} listed, absent"
        );
    }
    let (n, last) = whole_table(&out.join("navresult.nav"));
    assert!(n > 1000, "{n} epochs");
    let end = s["end_sow"].as_f64().unwrap();
    assert!((last - end).abs() < 1e-3, "nav ends {last}, summary {end}");
    true
}

fn signal(child: &Child, sig: &str) {
    let ok = Command::new("kill")
        .args([sig, &child.id().to_string()])
        .status()
        .unwrap()
        .success();
    assert!(ok, "kill {sig}");
}

/// Waits until `cond` or 20 s.
fn wait_for(mut cond: impl FnMut() -> bool) -> bool {
    let t = Instant::now();
    while t.elapsed() < Duration::from_secs(20) {
        if cond() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    false
}

#[test]
fn sigkill_at_any_moment_leaves_whole_files_and_the_next_run_cleans_up() {
    let dir = temp_dir("sigkill");
    let config = simulate(&dir, 600);
    let out = dir.join("out");
    // How long a whole run takes here, then 20 kills spread over it
    // (a fixed pseudo-random sequence: the same moments every time).
    let t = Instant::now();
    let c = fuse_smooth(&config, &out);
    assert!(c.wait_with_output().unwrap().status.success());
    let full_ms = t.elapsed().as_millis() as u64;
    assert!(check_whole(&out));
    let (mut finished, mut with_temps) = (0, 0);
    let mut x: u64 = 0x9e37_79b9_7f4a_7c15;
    for _ in 0..20 {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        let delay = Duration::from_millis(x % (full_ms + 50));
        let mut c = fuse_smooth(&config, &out);
        std::thread::sleep(delay);
        c.kill().unwrap(); // SIGKILL
        let st = c.wait().unwrap();
        if st.success() {
            finished += 1;
        }
        if !temporaries(&out).is_empty() {
            with_temps += 1;
        }
        if check_whole(&out) {
            // A finished run's files are this run's: fuse wrote all of them.
            assert!(out.join("forward/navresult.nav").is_file());
        }
    }
    // The next run removes what the killed ones left and says so.
    let leftover = temporaries(&out).len();
    let o = fuse_smooth(&config, &out).wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    if leftover > 0 {
        assert!(
            err.contains(&format!("removed {leftover} stale temporary")),
            "{leftover} left: {err}"
        );
    }
    assert!(temporaries(&out).is_empty(), "{:?}", temporaries(&out));
    assert!(check_whole(&out));
    eprintln!(
        "20 SIGKILLs over a {full_ms} ms run: {finished} finished, {with_temps} left temporaries (removed by the next run)"
    );
    assert!(with_temps > 0, "no kill landed during the run");
}

#[test]
fn a_second_writer_refuses_naming_the_first_and_the_first_stays_whole() {
    let dir = temp_dir("lock");
    let config = simulate(&dir, 1200);
    let out = dir.join("out");
    let first = fuse_smooth(&config, &out);
    let pid = first.id().to_string();
    assert!(wait_for(|| {
        std::fs::read_to_string(out.join(".navsync.lock"))
            .is_ok_and(|t| t.contains(&format!("pid {pid}\n")))
    }));
    let (ok, _, err) = run(bin()
        .args(["fuse", "--config"])
        .arg(&config)
        .arg("--output")
        .arg(&out));
    let o = first.wait_with_output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(!ok, "the second writer ran");
    assert!(
        err.contains("being written by another navsync run")
            && err.contains(&format!("pid {pid}"))
            && err.contains("fuse --smooth")
            && err.contains("since "),
        "{err}"
    );
    assert!(check_whole(&out));
    // Free again once the first is done; a plain run moves the smoothed
    // run's forward/ aside instead of leaving it as this run's.
    let (ok, _, err) = run(bin()
        .args(["fuse", "--config"])
        .arg(&config)
        .arg("--output")
        .arg(&out));
    assert!(ok, "{err}");
    assert!(err.contains(".previous"), "{err}");
    assert!(!out.join("forward/navresult.nav").exists());
    assert!(out.join(".previous/forward/navresult.nav").is_file());
    assert!(check_whole(&out));
}

#[test]
fn sigint_and_sigterm_remove_partial_files_with_a_message() {
    let dir = temp_dir("sigint");
    let config = simulate(&dir, 600);
    for (sig, code) in [("-INT", 130), ("-TERM", 143)] {
        let out = dir.join(format!("out{sig}"));
        let c = fuse_smooth(&config, &out);
        // Once writing has begun.
        assert!(wait_for(|| !temporaries(&out).is_empty()));
        signal(&c, sig);
        let o = c.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(code), "{err}");
        assert!(
            err.contains("interrupted")
                && err.contains("partial file(s); nothing under a final name is partial"),
            "{err}"
        );
        assert!(temporaries(&out).is_empty(), "{:?}", temporaries(&out));
        assert!(!check_whole(&out), "an interrupted run left a summary");
    }
}

/// A small tmpfs at `dir` while it lives (mounting needs root: `None`
/// otherwise).
struct SmallDisk(PathBuf);

impl SmallDisk {
    fn mount(dir: &Path, size: &str) -> Option<SmallDisk> {
        std::fs::create_dir_all(dir).unwrap();
        let ok = Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs"])
            .arg(dir)
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
        ok.then(|| SmallDisk(dir.to_path_buf()))
    }
}

impl Drop for SmallDisk {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(&self.0).status();
    }
}

#[test]
fn a_full_disk_is_a_clear_error_and_leaves_no_truncated_file() {
    let dir = temp_dir("full");
    let config = simulate(&dir, 120);
    let nav = dir.join("fused/navresult.nav");
    let (ok, _, err) = run(bin()
        .args(["fuse", "--config"])
        .arg(&config)
        .arg("--output")
        .arg(dir.join("fused")));
    assert!(ok, "{err}");
    // A one-file output onto a full device.
    let (ok, _, err) = run(bin()
        .args(["export", "--to", "csv", "--output", "/dev/full"])
        .arg(&nav));
    assert!(!ok);
    assert!(
        err.contains("/dev/full") && err.contains("No space left"),
        "{err}"
    );
    // A 1 MB file system: fuse (3.3 MB of navresult.nav) and simulate.
    let Some(disk) = SmallDisk::mount(&dir.join("disk"), "1m") else {
        eprintln!("note: mount -t tmpfs refused (not root?): the small-disk part is skipped");
        return;
    };
    let out = disk.0.join("out");
    let (ok, _, err) = run(bin()
        .args(["fuse", "--config"])
        .arg(&config)
        .arg("--output")
        .arg(&out));
    assert!(!ok, "fuse on a full disk succeeded");
    assert!(
        err.contains("No space left") && err.contains(&*out.to_string_lossy()),
        "{err}"
    );
    let left: Vec<PathBuf> = files(&out)
        .into_iter()
        .filter(|p| {
            !p.file_name()
                .unwrap()
                .to_string_lossy()
                .starts_with(".navsync")
        })
        .collect();
    for p in &left {
        whole_table(p);
    }
    assert!(!out.join("navresult.nav").exists(), "{left:?}");
    assert!(temporaries(&out).is_empty(), "{:?}", temporaries(&out));
    let sim = disk.0.join("sim");
    let (ok, _, err) = run(bin()
        .args([
            "simulate",
            "--quiet",
            "--scenario",
            "test-track",
            "--duration",
            "120",
        ])
        .arg("--output")
        .arg(&sim));
    assert!(!ok && err.contains("No space left"), "{err}");
    assert!(!sim.join("imu.txt").exists() && temporaries(&sim).is_empty());
    drop(disk);
}

#[test]
fn report_on_a_cut_solution_says_incomplete_and_poor() {
    let dir = temp_dir("cut");
    let config = simulate(&dir, 120);
    let out = dir.join("out");
    let (ok, _, err) = run(bin()
        .args(["fuse", "--config"])
        .arg(&config)
        .arg("--output")
        .arg(&out));
    assert!(ok, "{err}");
    let nav = out.join("navresult.nav");
    let (ok, text, err) = run(bin()
        .args(["report", "--nav"])
        .arg(&nav)
        .arg("--output")
        .arg(dir.join("whole.html")));
    assert!(ok, "{err}");
    assert!(!text.contains("verdict: poor"), "{text}");
    let full = std::fs::read(&nav).unwrap();
    // Cut inside a line, then at a line end (the cut line removed).
    let mid = full.len() / 2;
    let at_line = full[..mid].iter().rposition(|&b| b == b'\n').unwrap() + 1;
    for (cut, why) in [
        (mid, "last line is cut"),
        (at_line, "before the last solution"),
    ] {
        std::fs::write(&nav, &full[..cut]).unwrap();
        let (_, text, err) = run(bin()
            .args(["report", "--nav"])
            .arg(&nav)
            .arg("--output")
            .arg(dir.join("cut.html")));
        assert!(text.contains("verdict: poor"), "{text}{err}");
        assert!(err.contains(why) && err.contains("incomplete"), "{err}");
    }
}
