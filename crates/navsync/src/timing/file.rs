//! A rig log file to GPS-time-stamped KF-GINS files: the batch loop over
//! [`SyncEngine`] behind `navsync sync`, the demo and the Monte Carlo runs.
//!
//! The reader and the writer run on their own threads; memory stays
//! bounded by the channel depth.

use std::path::Path;
use std::sync::mpsc;

use super::report::{SyncReport, TruthAccumulator, TruthTimes, format_week_sow};
use super::{IncrementBuilder, RateRule, SyncConfig, SyncEngine, SyncOutput};
use crate::error::{Diagnostics, Error};
use crate::io::kfgins::{TextWriter, format_gnss_line};
use crate::io::riglog::{RigLogReader, RigRecord};
use crate::types::ImuSample;

/// What a synchronization run produced.
pub struct SyncSummary {
    pub report: SyncReport,
    /// Lines skipped while reading the log (and other reading notes).
    pub read_diag: Diagnostics,
    pub records: usize,
}

/// Batches passed between the reader, engine and writer threads.
const BATCH: usize = 8192;

fn thread_failed(what: &str) -> Error {
    Error::Invalid(format!("the {what} thread panicked"))
}

/// Reads `rig`, synchronizes it, and writes `imu.txt`, `gnss.txt`,
/// `imu_times.txt` and `sync_report.json` into `out_dir`. Rates become
/// increments by `rule`, or by what the header's `imu_rates` says. With
/// `truth` (a `week sow` line per `imu` record), stamps are compared with
/// it.
pub fn sync_file(
    rig: &Path,
    out_dir: &Path,
    cfg: SyncConfig,
    rule: Option<RateRule>,
    truth: Option<&Path>,
) -> Result<SyncSummary, Error> {
    std::fs::create_dir_all(out_dir).map_err(|e| Error::io(out_dir, e))?;
    let mut read_diag = Diagnostics::default();
    let mut reader = RigLogReader::open(rig, &mut read_diag)?;
    let header = reader.header().clone();
    let kind = header.imu_kind;
    let rule = rule.unwrap_or_else(|| RateRule::for_header(&header));

    // Reader thread: parsed records in batches.
    let (rec_tx, rec_rx) = mpsc::sync_channel::<Vec<(RigRecord, usize)>>(8);
    let reader_handle = std::thread::Builder::new()
        .name("rig-reader".into())
        .spawn(move || -> Result<(Diagnostics, usize), Error> {
            let mut diag = read_diag;
            let mut batch = Vec::with_capacity(BATCH);
            while let Some(r) = reader.next_record(&mut diag)? {
                batch.push(r);
                if batch.len() == BATCH {
                    let full = std::mem::replace(&mut batch, Vec::with_capacity(BATCH));
                    if rec_tx.send(full).is_err() {
                        break;
                    }
                }
            }
            if !batch.is_empty() {
                let _ = rec_tx.send(batch);
            }
            Ok((diag, reader.records()))
        })
        .map_err(|e| Error::io(rig, e))?;

    // Writer thread: formatting and files.
    let (out_tx, out_rx) = mpsc::sync_channel::<Vec<SyncOutput>>(8);
    let dir = out_dir.to_path_buf();
    let truth_path = truth.map(Path::to_path_buf);
    let writer_handle = std::thread::Builder::new()
        .name("sync-writer".into())
        .spawn(move || -> Result<(Option<TruthAccumulator>, bool), Error> {
            let mut imu_w = TextWriter::create(&dir.join("imu.txt"))?;
            let mut gnss_w = TextWriter::create(&dir.join("gnss.txt"))?;
            let mut times_w = TextWriter::create(&dir.join("imu_times.txt"))?;
            let mut truth = match &truth_path {
                Some(p) => Some((TruthTimes::open(p)?, TruthAccumulator::default())),
                None => None,
            };
            let mut inc = IncrementBuilder::with_rule(kind, rule);
            let mut buf_imu = Vec::with_capacity(1 << 20);
            let mut buf_times = Vec::with_capacity(1 << 18);
            let mut buf_gnss = Vec::with_capacity(1 << 12);
            let mut truth_short = false;
            for batch in out_rx {
                for o in batch {
                    match o {
                        SyncOutput::Imu(s) => {
                            if s.flags.unstamped {
                                buf_times.extend_from_slice(b"-1 nan\n");
                            } else {
                                format_week_sow(&mut buf_times, s.time);
                            }
                            if let Some((tt, acc)) = &mut truth {
                                match tt.next_time()? {
                                    Some(true_t) => {
                                        if !s.flags.unstamped && !s.flags.duplicate {
                                            acc.push(s.time, true_t, s.bound_s, s.flags.holdover)
                                        }
                                    }
                                    None => truth_short = true,
                                }
                            }
                            if let Some(sample) = inc.push(s.time, &s.values, &s.flags) {
                                push_imu_line(&mut buf_imu, &sample);
                            }
                        }
                        SyncOutput::Gnss(g) => {
                            format_gnss_line(&mut buf_gnss, &g.fix());
                        }
                    }
                }
                imu_w.write(&buf_imu)?;
                times_w.write(&buf_times)?;
                gnss_w.write(&buf_gnss)?;
                buf_imu.clear();
                buf_times.clear();
                buf_gnss.clear();
            }
            imu_w.finish()?;
            gnss_w.finish()?;
            times_w.finish()?;
            Ok((truth.map(|(_, acc)| acc), truth_short))
        })
        .map_err(|e| Error::io(out_dir, e))?;

    let mut engine = SyncEngine::new(&header, cfg);
    let mut out = Vec::with_capacity(BATCH * 2);
    let mut send_err = false;
    for batch in rec_rx {
        for (rec, line) in batch {
            engine.push_into(rec, line, &mut out);
        }
        if out.len() >= BATCH {
            let full = std::mem::replace(&mut out, Vec::with_capacity(BATCH * 2));
            if out_tx.send(full).is_err() {
                send_err = true;
                break;
            }
        }
    }
    let (mut read_diag, records) = reader_handle
        .join()
        .map_err(|_| thread_failed("rig reader"))??;
    let (rest, mut report) = match engine.finish() {
        Ok(v) => v,
        Err(e) => {
            drop(out_tx);
            let _ = writer_handle.join();
            return Err(e);
        }
    };
    out.extend(rest);
    if !send_err {
        let _ = out_tx.send(out);
    }
    drop(out_tx);
    let (acc, truth_short) = writer_handle
        .join()
        .map_err(|_| thread_failed("sync writer"))??;
    if truth_short && let Some(p) = truth {
        read_diag.push(
            p,
            0,
            "the truth file has fewer lines than the log has imu records",
        );
    }
    report.truth = acc.map(|a| a.finish());
    let json = serde_json::to_string_pretty(&report).map_err(|e| Error::Invalid(e.to_string()))?;
    let rp = out_dir.join("sync_report.json");
    std::fs::write(&rp, json).map_err(|e| Error::io(&rp, e))?;
    Ok(SyncSummary {
        report,
        read_diag,
        records,
    })
}

/// Writes `out_dir/kf-gins.yaml`: the KF-GINS `template` with paths, rate
/// and start time replaced by this run's (`./imu.txt`, `./gnss.txt`).
pub fn write_kfgins_config(template: &Path, out_dir: &Path, r: &SyncReport) -> Result<(), Error> {
    let text = std::fs::read_to_string(template).map_err(|e| Error::io(template, e))?;
    let rate = r.imu.rate_hz.unwrap_or(200.0).round();
    let start = r.first_stamp.map(|w| w.sow).unwrap_or(0.0);
    let mut out = String::new();
    out.push_str("# KF-GINS configuration written by navsync sync\n");
    for line in text.lines() {
        let key = line.split(':').next().unwrap_or("").trim();
        let new = match key {
            "imupath" => Some("imupath: \"./imu.txt\"".to_string()),
            "gnsspath" => Some("gnsspath: \"./gnss.txt\"".to_string()),
            "outputpath" => Some("outputpath: \"./out\"".to_string()),
            "imudatarate" => Some(format!("imudatarate: {rate}")),
            "starttime" => Some(format!("starttime: {start:.9}")),
            _ => None,
        };
        out.push_str(new.as_deref().unwrap_or(line));
        out.push('\n');
    }
    let p = out_dir.join("kf-gins.yaml");
    std::fs::write(&p, out).map_err(|e| Error::io(&p, e))
}

/// A KF-GINS IMU line, like `io::kfgins::format_imu_line` (every bit kept:
/// shortest round-trip form) but with a faster float printer.
fn push_imu_line(out: &mut Vec<u8>, s: &ImuSample) {
    s.time.write_sow(out);
    let mut b = zmij::Buffer::new();
    for v in s.dtheta.iter().chain(s.dvel.iter()) {
        out.push(b' ');
        out.extend_from_slice(b.format(*v).as_bytes());
    }
    out.push(b'\n');
}
