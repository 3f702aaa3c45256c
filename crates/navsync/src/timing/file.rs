//! A rig log file to GPS-time-stamped KF-GINS files: the batch loop over
//! [`SyncEngine`] behind `navsync sync`, the demo and the Monte Carlo runs.
//!
//! The reader and the writer are stages ([`crate::stage`]): on their own
//! threads, or inline in a fleet's single-core tasks; memory stays bounded
//! by the batch size and the channel depth.

#![warn(missing_docs)]

use std::path::{Path, PathBuf};

use super::report::{SyncReport, TruthAccumulator, TruthTimes, format_week_sow};
use super::{IncrementBuilder, RateRule, SyncConfig, SyncEngine, SyncOutput};
use crate::error::{Diagnostics, Error};
use crate::io::heading::{HeadingObs, write_headings};
use crate::io::kfgins::{TextWriter, format_gnss_line};
use crate::io::riglog::{RigLogReader, RigRecord};
use crate::stage::{Consumer, Drain, Producer, Source, fill_batch};
use crate::types::ImuSample;

/// What a synchronization run produced.
pub struct SyncSummary {
    /// The synchronization report (`sync_report.json`).
    pub report: SyncReport,
    /// Lines skipped while reading the log (and other reading notes).
    pub read_diag: Diagnostics,
    /// Good records read from the log (all kinds).
    pub records: usize,
}

/// Batches passed between the reader, engine and writer threads.
const BATCH: usize = 8192;

/// The rig log as a reader stage.
struct RigBatches {
    reader: RigLogReader<std::fs::File>,
    diag: Diagnostics,
}

impl Producer for RigBatches {
    type Item = (RigRecord, usize);
    /// Reading notes and the number of records.
    type Output = (Diagnostics, usize);
    fn next_batch(&mut self) -> Result<Option<Vec<(RigRecord, usize)>>, Error> {
        fill_batch(BATCH, || self.reader.next_record(&mut self.diag))
    }
    fn finish(self) -> Result<(Diagnostics, usize), Error> {
        Ok((self.diag, self.reader.records()))
    }
}

/// `imu.txt`, `gnss.txt` and `imu_times.txt` (and the comparison with true
/// stamps) as a writer stage.
struct SyncFiles {
    imu_w: TextWriter,
    gnss_w: TextWriter,
    times_w: TextWriter,
    truth: Option<(TruthTimes, TruthAccumulator)>,
    inc: IncrementBuilder,
    buf_imu: Vec<u8>,
    buf_times: Vec<u8>,
    buf_gnss: Vec<u8>,
    truth_short: bool,
    /// Receiver headings, written to `heading_path` at the end.
    headings: Vec<HeadingObs>,
    heading_path: PathBuf,
}

impl Consumer for SyncFiles {
    type Item = SyncOutput;
    /// The stamp errors against the truth, and whether the truth ran out.
    type Output = (Option<TruthAccumulator>, bool);
    fn consume(&mut self, batch: Vec<SyncOutput>) -> Result<(), Error> {
        for o in batch {
            match o {
                SyncOutput::Imu(s) => {
                    if s.flags.unstamped {
                        self.buf_times.extend_from_slice(b"-1 nan\n");
                    } else {
                        format_week_sow(&mut self.buf_times, s.time);
                    }
                    if let Some((tt, acc)) = &mut self.truth {
                        match tt.next_time()? {
                            Some(true_t) => {
                                if !s.flags.unstamped && !s.flags.duplicate {
                                    acc.push(s.time, true_t, s.bound_s, s.flags.holdover)
                                }
                            }
                            None => self.truth_short = true,
                        }
                    }
                    if let Some(sample) = self.inc.push(s.time, &s.values, &s.flags) {
                        push_imu_line(&mut self.buf_imu, &sample);
                    }
                }
                SyncOutput::Gnss(g) => {
                    format_gnss_line(&mut self.buf_gnss, &g.fix());
                }
                SyncOutput::Heading(h) => self.headings.push(h),
            }
        }
        self.imu_w.write(&self.buf_imu)?;
        self.times_w.write(&self.buf_times)?;
        self.gnss_w.write(&self.buf_gnss)?;
        self.buf_imu.clear();
        self.buf_times.clear();
        self.buf_gnss.clear();
        Ok(())
    }
    fn finish(self) -> Result<(Option<TruthAccumulator>, bool), Error> {
        self.imu_w.finish()?;
        self.gnss_w.finish()?;
        self.times_w.finish()?;
        // Without headings, no heading file (nor one of an earlier run).
        if self.headings.is_empty() {
            match std::fs::remove_file(&self.heading_path) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                    return Err(Error::io(&self.heading_path, e));
                }
                _ => {}
            }
        } else {
            write_headings(&self.heading_path, &self.headings)?;
        }
        Ok((self.truth.map(|(_, acc)| acc), self.truth_short))
    }
}

/// Watches the raw counters of a rig log's records in file order, to say
/// why a log gave no GPS time: a counter that runs backwards (a reversed
/// or sorted-by-something-else file) is not a short log.
struct CounterOrder {
    half_range: u64,
    prev: Option<u64>,
    records: usize,
    backwards: usize,
    first_back_line: usize,
}

impl CounterOrder {
    fn new(counter_bits: u32) -> Self {
        CounterOrder {
            half_range: 1u64 << counter_bits.clamp(1, 64).saturating_sub(1),
            prev: None,
            records: 0,
            backwards: 0,
            first_back_line: 0,
        }
    }

    fn push(&mut self, counter: u64, line: usize) {
        self.records += 1;
        // A step back by less than half the counter's range is time
        // running backwards; by more, a wrap (FORMATS.md §2).
        if let Some(p) = self.prev
            && counter < p
            && p - counter < self.half_range
        {
            if self.backwards == 0 {
                self.first_back_line = line;
            }
            self.backwards += 1;
        }
        self.prev = Some(counter);
    }

    /// The engine's "no data" error with its likely cause: most records
    /// earlier than the one before, or every record skipped by the reader.
    fn explain(&self, e: Error, read_diag: &Diagnostics) -> Error {
        let Error::NoData { path, msg } = e else {
            return e;
        };
        let msg = if self.records >= 3 && 2 * self.backwards > self.records {
            format!(
                "time runs backwards from line {} ({} of {} records have a counter below the one \
                 before): a reversed or re-sorted log? Records must be in the order they were \
                 logged",
                self.first_back_line, self.backwards, self.records
            )
        } else if self.records == 0 && read_diag.total > 0 {
            match read_diag.items.first() {
                Some(first) => format!(
                    "no usable records: {} lines skipped, the first {first}",
                    read_diag.total
                ),
                None => format!("no usable records: {} lines skipped", read_diag.total),
            }
        } else {
            msg
        };
        Error::NoData { path, msg }
    }
}

/// Reads `rig`, synchronizes it, and writes `imu.txt`, `gnss.txt`,
/// `imu_times.txt` and `sync_report.json` into `out_dir`, and
/// `heading.txt` when the log has `heading` records. Rates become
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
    let reader = RigLogReader::open(rig, &mut read_diag)?;
    let header = reader.header().clone();
    let kind = header.imu_kind;
    let rule = rule.unwrap_or_else(|| RateRule::for_header(&header));

    // Reader stage: parsed records in batches.
    let mut records_in = Source::start(
        RigBatches {
            reader,
            diag: read_diag,
        },
        "rig-reader",
    )?;

    // Writer stage: increments, formatting and files.
    let truth_times = match truth {
        Some(p) => Some((TruthTimes::open(p)?, TruthAccumulator::default())),
        None => None,
    };
    let mut files_out = Drain::start(
        SyncFiles {
            imu_w: TextWriter::create(&out_dir.join("imu.txt"))?,
            gnss_w: TextWriter::create(&out_dir.join("gnss.txt"))?,
            times_w: TextWriter::create(&out_dir.join("imu_times.txt"))?,
            truth: truth_times,
            inc: IncrementBuilder::with_rule(kind, rule),
            buf_imu: Vec::with_capacity(1 << 20),
            buf_times: Vec::with_capacity(1 << 18),
            buf_gnss: Vec::with_capacity(1 << 12),
            truth_short: false,
            headings: Vec::new(),
            heading_path: out_dir.join("heading.txt"),
        },
        "sync-writer",
    )?;

    let mut order = CounterOrder::new(header.counter_bits);
    let mut engine = SyncEngine::new(&header, cfg);
    let mut out = Vec::with_capacity(BATCH * 2);
    // Read, synchronize and hand over; the reader is always joined, and on
    // any error the writer too before the error is returned.
    let mut feed = || -> Result<(), Error> {
        while let Some(batch) = records_in.next_batch()? {
            for (rec, line) in batch {
                order.push(rec.counter(), line);
                engine.push_into(rec, line, &mut out);
            }
            if out.len() >= BATCH {
                files_out.send(std::mem::replace(&mut out, Vec::with_capacity(BATCH * 2)))?;
            }
        }
        Ok(())
    };
    let fed = feed();
    let read = records_in.finish();
    let finished = fed.and_then(|()| {
        let (read_diag, records) = read?;
        let (rest, report) = engine.finish().map_err(|e| order.explain(e, &read_diag))?;
        out.extend(rest);
        files_out.send(out)?;
        Ok((read_diag, records, report))
    });
    let (mut read_diag, records, mut report) = match finished {
        Ok(v) => v,
        Err(e) => {
            let _ = files_out.finish();
            return Err(e);
        }
    };
    let (acc, truth_short) = files_out.finish()?;
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
    crate::io::output::write_file(&rp, json)?;
    Ok(SyncSummary {
        report,
        read_diag,
        records,
    })
}

/// Writes `out_dir/kf-gins.yaml`: the KF-GINS `template` with paths, rate
/// and start time replaced by this run's (`./imu.txt`, `./gnss.txt`).
pub fn write_kfgins_config(template: &Path, out_dir: &Path, r: &SyncReport) -> Result<(), Error> {
    let text = crate::io::text::read_config_text(template)?;
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
    crate::io::output::write_file(&p, out)
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
