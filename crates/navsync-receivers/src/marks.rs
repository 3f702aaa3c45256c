//! The receiver as a time source: TIM-TM2 time marks as GNSS-time stamps of
//! external events, and TIM-TP quantization errors to correct 1PPS edges.
//!
//! - A camera strobe (exposure signal on EXTINT) is stamped at mid-exposure,
//!   the mean of its rising and falling edges (seed 001 §2.3.1: "记录曝光开始
//!   和曝光结束的两个时间,并取均值").
//! - The 1PPS edge leaves the receiver on its own clock ticks, so it is
//!   early or late by a quantization error that the preceding TIM-TP
//!   reports for exactly that pulse ([F9] §5.17.2 qErr; ZED-F9R integration
//!   manual §3.10.10: the last TIM-TP before pulse T2 belongs to T2). A
//!   logger that latched the edge at local time `t_edge` saw the ideal
//!   second at `t_edge + qErr`: the sign measured by A. Wallin ("uBlox F9T
//!   qErr correction", 2019: time-interval counter start = reference,
//!   stop = u-blox PPS, qErr added) and used by clkpoc's PairQerr.

use navsync::time::GpsTime;

use crate::gnsstime::LeapSeconds;
use crate::ubx::{TimTm2, TimTp, TimeBase};

/// Which edge of an EXTINT signal.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum Edge {
    Rising,
    Falling,
}

/// One external-event edge in GPS time.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub(crate) struct EdgeStamp {
    pub time: GpsTime,
    pub edge: Edge,
    pub channel: u8,
    /// The receiver's rising-edge counter at this message.
    pub count: u16,
    /// Accuracy estimate (ns).
    pub(crate) acc_ns: u32,
}

/// A pulse (e.g. a camera exposure signal) with both edges, stamped at its
/// middle (seed 001 §2.3.1).
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub(crate) struct Strobe {
    pub channel: u8,
    pub rising: GpsTime,
    pub falling: GpsTime,
    /// (rising + falling) / 2.
    pub mid: GpsTime,
    pub count: u16,
}

/// What one TIM-TM2 message yields.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub(crate) struct MarkOutput {
    /// New edges, in time order.
    pub edges: Vec<EdgeStamp>,
    /// Pulses completed by this message.
    pub strobes: Vec<Strobe>,
    /// Anything wrong (time not valid, receiver time base, missed marks).
    pub problems: Vec<String>,
}

/// Turns TIM-TM2 messages into GPS-time event stamps, pairing rising and
/// falling edges per channel.
#[derive(Clone, Debug, Default)]
pub(crate) struct TimeMarks {
    open_rising: [Option<(GpsTime, u16)>; 4],
    last_count: [Option<u16>; 4],
    /// Longest pulse paired into a strobe (ns); longer ones are left as
    /// separate edges. Default 1 s.
    pub(crate) max_pulse_ns: i64,
}

impl TimeMarks {
    pub(crate) fn new() -> Self {
        TimeMarks {
            max_pulse_ns: 1_000_000_000,
            ..Default::default()
        }
    }

    /// GPS time of a TIM-TM2 edge in its time base: GNSS time is taken as
    /// GPS time (the u-blox default grid; CFG-TP-TIMEGRID selects it), UTC
    /// is converted with the leap seconds known; receiver time has no GNSS
    /// meaning and gives `None`.
    pub(crate) fn edge_to_gps(
        tb: TimeBase,
        ns_in_base: i64,
        leap: &LeapSeconds,
    ) -> Option<GpsTime> {
        match tb {
            TimeBase::Gnss => Some(GpsTime::from_ns(ns_in_base)),
            TimeBase::Utc => {
                let utc = crate::gnsstime::UtcTime::from_unix_ns(
                    ns_in_base + crate::gnsstime::GPS_EPOCH_UNIX_DAYS * 86_400 * 1_000_000_000,
                );
                Some(leap.utc_to_gps(&utc).0)
            }
            TimeBase::Receiver | TimeBase::Reserved => None,
        }
    }

    pub(crate) fn push(&mut self, tm: &TimTm2, leap: &LeapSeconds) -> MarkOutput {
        let mut out = MarkOutput::default();
        let ch = tm.ch as usize;
        if ch >= self.open_rising.len() {
            out.problems
                .push(format!("TIM-TM2 channel {} out of range", tm.ch));
            return out;
        }
        if !tm.time_valid() {
            out.problems.push(format!(
                "TIM-TM2 channel {ch}: time not valid (no fix); edges skipped"
            ));
            return out;
        }
        let tb = tm.time_base();
        if let Some(last) = self.last_count[ch] {
            let step = tm.count.wrapping_sub(last);
            if step > 1 && tm.new_rising_edge() {
                out.problems.push(format!(
                    "TIM-TM2 channel {ch}: rising-edge count jumped {last} → {}: {} marks not reported",
                    tm.count,
                    step - 1
                ));
            }
        }
        self.last_count[ch] = Some(tm.count);
        let mut edges = Vec::with_capacity(2);
        for (new, edge, ns) in [
            (tm.new_rising_edge(), Edge::Rising, tm.rising_ns()),
            (tm.new_falling_edge(), Edge::Falling, tm.falling_ns()),
        ] {
            if !new {
                continue;
            }
            match Self::edge_to_gps(tb, ns, leap) {
                Some(time) => edges.push(EdgeStamp {
                    time,
                    edge,
                    channel: tm.ch,
                    count: tm.count,
                    acc_ns: tm.acc_est_ns,
                }),
                None => out.problems.push(format!(
                    "TIM-TM2 channel {ch}: time base {tb:?} is not GNSS time; edge skipped"
                )),
            }
        }
        edges.sort_by_key(|e| e.time);
        for e in &edges {
            match e.edge {
                Edge::Rising => self.open_rising[ch] = Some((e.time, e.count)),
                Edge::Falling => {
                    if let Some((r, count)) = self.open_rising[ch].take() {
                        let width = e.time - r;
                        if (0..=self.max_pulse_ns).contains(&width) {
                            out.strobes.push(Strobe {
                                channel: e.channel,
                                rising: r,
                                falling: e.time,
                                mid: r + width / 2,
                                count,
                            });
                        }
                    }
                }
            }
        }
        out.edges = edges;
        out
    }
}

/// The logger-clock time of the ideal pulse, given the logger's timestamp
/// of a 1PPS edge (ns, any local time scale) and the qErr (ps) of that
/// pulse: `edge + qErr`, rounded to the ns.
pub(crate) fn correct_pps_edge(edge_local_ns: i64, q_err_ps: i32) -> i64 {
    edge_local_ns + (q_err_ps as i64 * 2 + 1000).div_euclid(2000)
}

/// GPS time at which the pulse edge really left the receiver: the pulse
/// time minus qErr (the edge is early by qErr).
pub(crate) fn pps_edge_gps(pulse: GpsTime, q_err_ps: i32) -> GpsTime {
    pulse + (-(q_err_ps as i64) * 2 + 1000).div_euclid(2000)
}

/// A pulse announced by TIM-TP.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub struct AnnouncedPulse {
    /// GPS time of the ideal pulse.
    pub time: GpsTime,
    pub q_err_ps: i32,
    pub q_err_valid: bool,
}

/// Why a PPS edge was left uncorrected.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum QErrMiss {
    /// No TIM-TP seen yet.
    NoTimTp,
    /// The held TIM-TP is for another pulse (lost message): correcting with
    /// it would be worse than not correcting.
    OtherPulse { announced: GpsTime },
    /// The receiver marked qErr invalid.
    Invalid,
}

/// Pairs PPS edges with the TIM-TP that announced them.
#[derive(Clone, Debug, Default)]
pub struct QErrCorrector {
    last: Option<AnnouncedPulse>,
}

impl QErrCorrector {
    pub fn new() -> Self {
        Self::default()
    }

    /// Holds the pulse a TIM-TP announces; returns it (GPS time), or `None`
    /// when its time base cannot be put on GPS time.
    pub fn push_tim_tp(&mut self, tp: &TimTp, leap: &LeapSeconds) -> Option<AnnouncedPulse> {
        let tb = if tp.utc_time_base() {
            TimeBase::Utc
        } else {
            TimeBase::Gnss
        };
        let time = TimeMarks::edge_to_gps(tb, tp.pulse_time_ns(), leap)?;
        let p = AnnouncedPulse {
            time,
            q_err_ps: tp.q_err_ps,
            q_err_valid: tp.q_err_valid(),
        };
        self.last = Some(p);
        Some(p)
    }

    /// Corrects the logger timestamp of the PPS edge that marks GPS second
    /// `pulse` with the held TIM-TP when it announced that very pulse.
    pub fn correct(&self, edge_local_ns: i64, pulse: GpsTime) -> Result<i64, QErrMiss> {
        let p = self.last.ok_or(QErrMiss::NoTimTp)?;
        if p.time != pulse {
            return Err(QErrMiss::OtherPulse { announced: p.time });
        }
        if !p.q_err_valid {
            return Err(QErrMiss::Invalid);
        }
        Ok(correct_pps_edge(edge_local_ns, p.q_err_ps))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tm2(flags: u8, count: u16, r_ms: u32, r_ns: u32, f_ms: u32, f_ns: u32) -> TimTm2 {
        TimTm2 {
            ch: 0,
            flags,
            count,
            wn_r: 2300,
            wn_f: 2300,
            tow_ms_r: r_ms,
            tow_sub_ms_r_ns: r_ns,
            tow_ms_f: f_ms,
            tow_sub_ms_f_ns: f_ns,
            acc_est_ns: 20,
        }
    }

    #[test]
    fn strobe_mid_exposure() {
        let leap = LeapSeconds::new();
        let mut m = TimeMarks::new();
        // GNSS base (bits 3..4 = 1), time valid, new rising and falling.
        let f = 0x80 | 0x40 | 0x08 | 0x04;
        let out = m.push(&tm2(f, 7, 1000, 250, 1005, 750), &leap);
        assert_eq!(out.edges.len(), 2);
        assert_eq!(out.strobes.len(), 1);
        let s = out.strobes[0];
        let r = GpsTime::from_week_ns(2300, 1_000_000_250);
        assert_eq!(s.rising, r);
        assert_eq!(s.falling - s.rising, 5_000_500);
        assert_eq!(s.mid - r, 2_500_250);
    }

    #[test]
    fn edges_in_separate_messages_pair_and_receiver_base_is_refused() {
        let leap = LeapSeconds::new();
        let mut m = TimeMarks::new();
        let o1 = m.push(&tm2(0x80 | 0x40 | 0x08, 1, 2000, 0, 1500, 0), &leap);
        assert_eq!((o1.edges.len(), o1.strobes.len()), (1, 0));
        let o2 = m.push(&tm2(0x04 | 0x40 | 0x08, 1, 2000, 0, 2010, 0), &leap);
        assert_eq!(o2.strobes.len(), 1);
        assert_eq!(
            o2.strobes[0].mid,
            GpsTime::from_week_ns(2300, 2_005_000_000)
        );
        let o3 = m.push(&tm2(0x80 | 0x40, 3, 3000, 0, 0, 0), &leap);
        assert!(o3.edges.is_empty());
        assert_eq!(o3.problems.len(), 2, "{:?}", o3.problems); // count jump + receiver base
    }

    #[test]
    fn utc_base_marks_get_leap_seconds() {
        let leap = LeapSeconds::new();
        let mut m = TimeMarks::new();
        // UTC base (bits 3..4 = 2); a 2023 week: GPS − UTC = 18 s.
        let out = m.push(&tm2(0x80 | 0x40 | 0x10, 1, 5000, 0, 0, 0), &leap);
        assert_eq!(
            out.edges[0].time,
            GpsTime::from_week_ns(2300, 23_000_000_000)
        );
    }

    #[test]
    fn qerr_removes_the_sawtooth() {
        // A pulse early by e = -qErr: the logger latches T + e; adding qErr
        // gives back T exactly (to the ns).
        let t_local_ideal = 5_000_000_000i64;
        for q_ps in [-21_000, -3_499, 0, 4_500, 10_250] {
            let latched = t_local_ideal - (q_ps as i64) / 1000;
            let c = correct_pps_edge(latched, q_ps);
            assert!((c - t_local_ideal).abs() <= 1, "{q_ps}: {c}");
        }
        let leap = LeapSeconds::new();
        let mut q = QErrCorrector::new();
        assert_eq!(q.correct(0, GpsTime::EPOCH), Err(QErrMiss::NoTimTp));
        let tp = TimTp {
            tow_ms: 1000,
            tow_sub_ms: 0,
            q_err_ps: -7000,
            week: 2300,
            flags: 0,
            ref_info: 0,
        };
        let p = q.push_tim_tp(&tp, &leap).unwrap();
        assert_eq!(q.correct(100, p.time), Ok(93));
        assert!(matches!(
            q.correct(100, p.time + 1_000_000_000),
            Err(QErrMiss::OtherPulse { .. })
        ));
        assert_eq!(pps_edge_gps(p.time, -7000), p.time + 7);
    }
}
