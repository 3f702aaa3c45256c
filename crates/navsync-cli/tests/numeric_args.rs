//! Every numeric flag of every command (found by introspecting the clap
//! tree: the hidden `navsync __numeric-args`) against NaN, ±inf, ±1e300,
//! 0, −1, 1e-300 and huge integers, on the real binary with small valid
//! inputs, a time limit and an address-space limit (issue 32): no panic,
//! no abort, no hang, no unbounded allocation; a non-finite or absurd real
//! number is refused at parse time (exit 2) with the flag named.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use common::{bin, run, temp_dir};

const VALUES: [&str; 10] = [
    "NaN",
    "inf",
    "-inf",
    "1e300",
    "-1e300",
    "0",
    "-1",
    "1e-300",
    "18446744073709551616",
    "4294967296",
];
/// Values no real-valued flag may accept.
const ABSURD: [&str; 5] = ["NaN", "inf", "-inf", "1e300", "-1e300"];
const TIME_LIMIT: Duration = Duration::from_secs(20);
/// Address-space limit of each run (prlimit --as): far above what a small
/// input needs, far below a capacity overflow's attempt.
const MEMORY_LIMIT_BYTES: u64 = 4 << 30;

/// The small inputs every command runs on.
struct Fixture {
    dir: PathBuf,
    sim: PathBuf,
    rate_csv: PathBuf,
    speed: PathBuf,
    sensor: PathBuf,
    n: AtomicUsize,
}

impl Fixture {
    fn new(dir: &Path) -> Fixture {
        let sim = dir.join("sim");
        let (ok, _, err) = run(bin()
            .args([
                "simulate",
                "--scenario",
                "test-track",
                "--duration",
                "30",
                "--seed",
                "1",
                "--quiet",
                "--output",
            ])
            .arg(&sim));
        assert!(ok, "{err}");
        let speed = dir.join("speed.txt");
        let (ok, _, err) = run(bin()
            .args(["speed-sim", "--truth"])
            .arg(sim.join("truth.nav"))
            .arg("--out")
            .arg(&speed));
        assert!(ok, "{err}");
        let sensor = dir.join("sensor.yaml");
        let (ok, _, err) = run(bin().args(["init", "--output"]).arg(&sensor));
        assert!(ok, "{err}");
        let rate_csv = dir.join("rate.csv");
        let mut text = String::from("time,gx,gy,gz,ax,ay,az\n");
        for k in 0..400 {
            text += &format!("{:.3},0.001,0,0,0,0,-9.8\n", 1000.0 + k as f64 * 0.005);
        }
        std::fs::write(&rate_csv, text).unwrap();
        Fixture {
            dir: dir.to_path_buf(),
            sim,
            rate_csv,
            speed,
            sensor,
            n: AtomicUsize::new(0),
        }
    }

    fn sim(&self, name: &str) -> String {
        self.sim.join(name).display().to_string()
    }

    /// A fresh output path (`ext` "" for a folder).
    fn out(&self, ext: &str) -> String {
        let n = self.n.fetch_add(1, Ordering::Relaxed);
        self.dir.join(format!("out-{n}{ext}")).display().to_string()
    }

    /// A runnable argument list of `path` (positionals and flags with
    /// their values), so that a value that passes parsing is also run.
    fn base(&self, path: &str) -> Vec<(String, Option<String>)> {
        let p = |v: String| (String::new(), Some(v));
        let f = |k: &str, v: String| (k.to_string(), Some(v));
        let s = |k: &str| (k.to_string(), None);
        let cfg = self.sim("kf-gins.yaml");
        match path {
            "fuse" => vec![
                f("--config", cfg),
                f("--output", self.out("")),
                s("--estimate-time-offset"),
                s("--nhc"),
                s("--smooth"),
                f("--odometer", self.speed.display().to_string()),
            ],
            "simulate" => vec![
                f("--scenario", "test-track".into()),
                f("--duration", "20".into()),
                f("--output", self.out("")),
                s("--quiet"),
            ],
            "imu check" => vec![p(self.sim("imu.txt"))],
            "imu convert" => vec![p(self.sim("imu.txt")), p(self.out(".txt"))],
            "imu rate-study" => vec![
                f("--config", cfg),
                f("--truth", self.sim("truth.nav")),
                f("--rates", "200,100".into()),
            ],
            "report" => vec![
                f("--nav", self.sim("truth.nav")),
                f("--output", self.out(".html")),
            ],
            "export" => vec![
                p(self.sim("truth.nav")),
                f("--to", "csv".into()),
                f("--output", self.out(".csv")),
            ],
            "convert" => vec![
                f("--from", "rate-csv".into()),
                p(self.rate_csv.display().to_string()),
                f("--output", self.out("")),
            ],
            "sync" => vec![
                p(self.sim("rig.csv")),
                f("--output", self.out("")),
                s("--force"),
            ],
            "faults" => vec![
                f("--gnss", self.sim("gnss.txt")),
                f("--output", self.out("")),
                f("--skip-start", "1".into()),
                f("--count", "1".into()),
            ],
            "speed-sim" => vec![
                f("--truth", self.sim("truth.nav")),
                f("--out", self.out(".txt")),
            ],
            "track" => vec![f("--cn0", "35".into()), f("--duration", "5".into())],
            "demo" => vec![f("--output", self.out("")), f("--duration", "30".into())],
            "montecarlo" => vec![
                f("--runs", "1".into()),
                f("--duration", "30".into()),
                f("--output", self.out("")),
            ],
            "array" => vec![
                f("--imu", self.sim("imu.txt")),
                f("--imu", self.sim("imu.txt")),
                f("--gnss", self.sim("gnss.txt")),
                f("--config", cfg),
                f("--output", self.out("")),
            ],
            "process" => vec![
                p(self.sim("rig.csv")),
                f("--sensor", self.sensor.display().to_string()),
                f("--output", self.out("")),
            ],
            "batch" => vec![
                p(self.sim.display().to_string()),
                f("--output", self.out("")),
            ],
            _ => Vec::new(),
        }
    }
}

/// How one run ended.
enum Outcome {
    Exit(i32, String),
    Signal(String),
    Timeout,
}

fn run_limited(args: &[String]) -> Outcome {
    let exe = env!("CARGO_BIN_EXE_navsync");
    let mut cmd = if Path::new("/usr/bin/prlimit").exists() {
        let mut c = Command::new("/usr/bin/prlimit");
        c.arg(format!("--as={MEMORY_LIMIT_BYTES}"))
            .arg("--")
            .arg(exe);
        c
    } else {
        Command::new(exe)
    };
    let mut child = cmd
        .args(args)
        .env("NO_COLOR", "1")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // stderr drained on a thread so that a chatty run cannot block.
    let mut pipe = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = std::io::Read::read_to_string(&mut pipe, &mut s);
        s
    });
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            let err = reader.join().unwrap();
            return match status.code() {
                Some(c) => Outcome::Exit(c, err),
                None => Outcome::Signal(err),
            };
        }
        if start.elapsed() > TIME_LIMIT {
            let _ = child.kill();
            let _ = child.wait();
            return Outcome::Timeout;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[test]
fn every_numeric_flag_survives_hostile_values() {
    let out = bin().arg("__numeric-args").output().unwrap();
    assert!(out.status.success());
    let listing = String::from_utf8(out.stdout).unwrap();
    let flags: Vec<(String, String, String)> = listing
        .lines()
        .map(|l| {
            let v: Vec<&str> = l.split('\t').collect();
            (v[0].to_string(), v[1].to_string(), v[2].to_string())
        })
        .collect();
    // The introspection finds the flags of the tour.
    for (path, flag) in [
        ("fuse", "--time-offset-search"),
        ("fuse", "--gnss-sd-floor"),
        ("imu convert", "--rate"),
        ("simulate", "--internal-rate"),
        ("report", "--time-offset-truth"),
        ("montecarlo", "--jobs"),
        ("convert", "--esf-meas-tick-us"),
        ("sync", "--imu-output-delay"),
    ] {
        assert!(
            flags.iter().any(|(p, f, _)| p == path && f == flag),
            "{path} {flag} not found in {listing}"
        );
    }
    assert!(flags.len() > 100, "{} numeric flags", flags.len());

    let dir = temp_dir("hostile");
    let fx = Fixture::new(&dir);
    let cases: Vec<(usize, &str)> = (0..flags.len())
        .flat_map(|i| VALUES.iter().map(move |v| (i, *v)))
        .collect();
    let next = AtomicUsize::new(0);
    let failures = Mutex::new(Vec::new());
    let start = Instant::now();
    std::thread::scope(|s| {
        for _ in 0..2 {
            s.spawn(|| {
                loop {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    let Some(&(i, value)) = cases.get(k) else {
                        break;
                    };
                    let (path, flag, kind) = &flags[i];
                    let v = match kind.as_str() {
                        "real3" => format!("{value},{value},{value}"),
                        "real2" => format!("{value},{value}"),
                        _ => value.to_string(),
                    };
                    let mut args: Vec<String> = path.split(' ').map(str::to_string).collect();
                    for (k, val) in fx.base(path) {
                        if &k == flag {
                            continue;
                        }
                        if !k.is_empty() {
                            args.push(k);
                        }
                        args.extend(val);
                    }
                    args.push(format!("{flag}={v}"));
                    let what = format!("navsync {}", args.join(" "));
                    let fail = match run_limited(&args) {
                        Outcome::Timeout => Some(format!("{what}: no answer in {TIME_LIMIT:?}")),
                        Outcome::Signal(e) => Some(format!("{what}: killed by a signal: {e}")),
                        Outcome::Exit(c, e) if c == 101 || e.contains("panicked") => {
                            Some(format!("{what}: panic: {e}"))
                        }
                        Outcome::Exit(c, e)
                            if kind.starts_with("real") && ABSURD.contains(&value) =>
                        {
                            (c != 2 || !e.contains(flag.as_str()))
                                .then(|| format!("{what}: accepted (exit {c}): {e}"))
                        }
                        Outcome::Exit(..) => None,
                    };
                    if let Some(f) = fail {
                        failures.lock().unwrap().push(f);
                    }
                }
            });
        }
    });
    let failures = failures.into_inner().unwrap();
    assert!(
        failures.is_empty(),
        "{} of {} runs failed:\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n")
    );
    eprintln!(
        "{} flags × {} values in {:.1} s",
        flags.len(),
        VALUES.len(),
        start.elapsed().as_secs_f64()
    );
}
