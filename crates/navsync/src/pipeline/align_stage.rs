//! The alignment stage of a batch run: the initial state from the data
//! (`crate::align`), a land vehicle's mounting yaw from the motion
//! (`crate::mount_search`) and the mounting a tilted IMU implies, each
//! from a pre-pass over the files (`stream_files`) before the filter
//! starts.

use super::*;

/// The initial state from the data (`align`), the land vehicle's mounting
/// yaw from the motion (`mount_search`) and the mounting a tilted IMU
/// implies, written into `fc`; with the alignment options as used (the
/// user's, with the sheet's lever arm, bias σ and mounting yaw filled in:
/// what summary.json reports).
pub(super) fn align_stage(
    cfg: &KfGinsConfig,
    opts: &FuseOptions,
    fc: &mut FusionConfig,
    headings: &[crate::io::heading::HeadingObs],
    diag: &mut Diagnostics,
) -> Result<
    (
        crate::align::Alignment,
        Option<crate::mount_search::MountYawDecision>,
        crate::align::AlignOptions,
    ),
    Error,
> {
    let mut mount_yaw = None;
    let mut ao = opts.align.unwrap_or_default();
    ao.lever_b = cfg.antenna_lever.into();
    ao.accel_bias_sd_mps2 = cfg.init_std.accel_bias.max();
    ao.mount_yaw_rad = opts.mount_deg[2].to_radians();
    if let Some(h) = &opts.heading {
        ao.dual_antenna_yaw_rad = h.dual_antenna_yaw_deg.to_radians();
        ao.dual_antenna_yaw_sd_rad = h.dual_antenna_yaw_sd_deg.to_radians();
    }
    let mut a = align_from_files(cfg, opts, &ao, fc.init_nav.time, headings)?;
    // A land vehicle's mounting yaw from the motion (`mount_search`):
    // taken when the sheet left it at 0 and it is clearly not 0.
    if opts.nhc.is_some() || opts.odometer.is_some() {
        let d = mount_yaw_from_files(cfg, opts, fc.init_nav.time, &a, ao.mount_yaw_rad)?;
        if d.adopted {
            let turn = Euler::new(0.0, 0.0, d.used_yaw_deg.to_radians() - ao.mount_yaw_rad);
            let c = crate::attitude::euler_to_dcm(&turn);
            if let Some(n) = fc.nhc.as_mut() {
                n.vehicle.c_bv = c * n.vehicle.c_bv;
            }
            if let Some(o) = fc.odometer.as_mut() {
                o.vehicle.c_bv = c * o.vehicle.c_bv;
            }
            ao.mount_yaw_rad = d.used_yaw_deg.to_radians();
            a = align_from_files(cfg, opts, &ao, fc.init_nav.time, headings)?;
        }
        if !d.message.is_empty() {
            diag.note(d.message.clone());
        }
        mount_yaw = Some(d);
    }
    if a.method == crate::align::AlignMethod::NoMotion {
        let gyro_bias_sd_rad_s = cfg.init_std.gyro_bias.max();
        let (yaw, rate) = (ao.mount_yaw_rad, ao.still_rate_rad_s);
        track_heading_before_start(cfg, opts, &mut a, yaw, gyro_bias_sd_rad_s, rate)?;
    }
    diag.note(a.note.clone());
    fc.init_nav = a.nav;
    fc.init_std.att = Vector3::from(a.att_sd_rad);
    let misalign_sd_rad = opts.accel_misalignment_sd_deg.unwrap_or(0.0).to_radians();
    if let Some(m) = a.levelling_coupling {
        fc.init_std.att.x = a.tilt_noise_sd_rad;
        fc.init_std.att.y = a.tilt_noise_sd_rad;
        fc.levelling_coupling = Some(m);
        fc.levelling_accel_misalignment_sd_rad = misalign_sd_rad;
    } else {
        // Levelled before the start (tilt carried by the gyros): the
        // misaligned axes' tilt error, uncorrelated with the states.
        fc.init_std.att.x = fc.init_std.att.x.hypot(misalign_sd_rad);
        fc.init_std.att.y = fc.init_std.att.y.hypot(misalign_sd_rad);
    }
    if let Some(h) = fc.heading.as_mut() {
        h.aligned_from_baseline = matches!(
            a.method,
            crate::align::AlignMethod::StaticLevellingAndDualAntenna
                | crate::align::AlignMethod::InMotionDualAntenna
        );
    }
    fc.init_std.pos = Vector3::from(a.pos_sd_m);
    fc.init_pos_from_antenna = true;
    fc.init_std.vel = Vector3::from(a.vel_sd_mps);
    mounting_from_tilt(opts, fc, &a, ao.mount_yaw_rad, diag);
    if matches!(
        a.method,
        crate::align::AlignMethod::NoMotion | crate::align::AlignMethod::NoMotionTrackHeading
    ) {
        // Too slow for the course: look for the heading in the track (when
        // the pre-pass found it, every chord is a heading measurement from
        // the start).
        fc.course_heading = Some(crate::fusion::course_heading::CourseHeadingOptions::new(
            ao.mount_yaw_rad,
        ));
    }
    Ok((a, mount_yaw, ao))
}

/// The heading of a vehicle too slow for the alignment's course, found in
/// the GNSS track before the filter starts (`fusion::course_heading`'s
/// chords against the vertical gyro's integrated yaw), so that the filter
/// never runs with its heading held. While it is held, every aid whose
/// model needs the heading (the NHC's lateral row, the odometer along the
/// vehicle's axis, the biases the fixes reach through the yaw–velocity
/// correlation) is linearised at a heading that may be 180° off: on the
/// Husky bag with its true mounting the forward heading then wandered by
/// 50–100° after the in-run acquisition, and with the heading known from
/// the start it held within 17° of the course.
///
/// The nominal yaw ψ̂(t) is the alignment's plus the integral of the rate
/// about the vertical (the gyro along the levelled down axis), less the
/// mean of that rate over the standstill at the start when there is one
/// (the vertical gyro bias and the earth rate's vertical component; only
/// samples turning slower than `still_rate_rad_s`, the alignment's
/// standstill rate). The
/// chords measure δ = c + α − ψ̂; once they agree (the in-run test), the
/// alignment's attitude is turned by δ̄ about the vertical, with σ the
/// chords' plus what an unknown vertical bias (`gyro_bias_sd_rad_s`, the
/// sheet's turn-on σ, or the standstill mean's own σ) turns the yaw
/// between the start and the last chord (a bound on the drift to the
/// chords' mean time). Nothing changes when the
/// chords never agree (a drone flying sideways, a straight road).
fn track_heading_before_start(
    cfg: &KfGinsConfig,
    opts: &FuseOptions,
    a: &mut crate::align::Alignment,
    mount_yaw_rad: f64,
    gyro_bias_sd_rad_s: f64,
    still_rate_rad_s: f64,
) -> Result<(), Error> {
    use crate::fusion::course_heading::{CourseHeading, CourseHeadingOptions, yaw_of};
    let c_nb = a.nav.c_nb();
    let down_b = Vector3::new(c_nb[(2, 0)], c_nb[(2, 1)], c_nb[(2, 2)]);
    let start = a.nav.time;
    let still_s = if a.standstill_s >= MIN_STANDSTILL_FOR_BIAS_S {
        a.standstill_s
    } else {
        0.0
    };
    let track = std::cell::RefCell::new((
        CourseHeading::new(CourseHeadingOptions::new(mount_yaw_rad)),
        yaw_of(&a.nav.q_nb),
        // The standstill's vertical rate: angle (rad) and time (s).
        (0.0f64, 0.0f64),
        start,
    ));
    let rate_bias = |st: &(f64, f64)| if st.1 > 0.0 { st.0 / st.1 } else { 0.0 };
    let found = stream_files(
        cfg,
        opts,
        start,
        |f| {
            let (ch, yaw, _, _) = &mut *track.borrow_mut();
            let sd_h = f.pos_sd.x.max(f.pos_sd.y);
            ch.push(f.time, f.pos.lat_rad, f.pos.lon_rad, sd_h, *yaw)
        },
        |s| {
            let (_, yaw, still, last) = &mut *track.borrow_mut();
            let dt = s.time.seconds_since(*last).max(0.0);
            *last = s.time;
            let turn = down_b.dot(&s.dtheta);
            // At rest by the fixes and by the gyros too (a skid-steer
            // robot turns on the spot with the fixes still).
            let at_rest = s.dtheta.norm() <= still_rate_rad_s * dt;
            if s.time.seconds_since(start) <= still_s && at_rest && dt > 0.0 {
                still.0 += turn;
                still.1 += dt;
            }
            *yaw += turn - rate_bias(still) * dt;
        },
    )?;
    let Some(h) = found else {
        return Ok(());
    };
    let (_, _, still, _) = track.into_inner();
    // The vertical bias left: the standstill mean's σ (angle random walk
    // over its length) or, without one, the sheet's turn-on σ.
    let bias_sd = if still.1 > 0.0 {
        cfg.noise.arw.max() / still.1.sqrt()
    } else {
        gyro_bias_sd_rad_s
    };
    // Drift to the acquisition, the last chord's end: a bound on the drift
    // to the chords' mean time.
    let drift_rad = bias_sd * h.time.seconds_since(start);
    a.nav.q_nb = crate::attitude::turned_in_yaw(&a.nav.q_nb, h.offset_rad);
    a.att_sd_rad[2] = h.sd_rad.hypot(drift_rad);
    a.method = crate::align::AlignMethod::NoMotionTrackHeading;
    a.note = format!(
        "levelled, the vehicle too slow for the heading from its velocity; heading found in the GNSS track before the \
         run ({} chords of the track agreeing within {:.1}° over courses spanning {:.0}°, by {:.1} s of week): the \
         levelled yaw turned by {:.1}°, σ {:.1}° (the chords' {:.1}° and {:.1}° of vertical gyro drift to them)",
        h.chords,
        h.spread_rad.to_degrees(),
        h.course_span_rad.to_degrees(),
        h.time_sow,
        h.offset_rad.to_degrees(),
        a.att_sd_rad[2].to_degrees(),
        h.sd_rad.to_degrees(),
        drift_rad.to_degrees()
    );
    Ok(())
}

/// A standstill at the start at least this long (s) gives the vertical
/// gyro's bias for the track's heading (`track_heading_before_start`).
const MIN_STANDSTILL_FOR_BIAS_S: f64 = 2.0;

/// An IMU tilted far more than a road or a parked drone tilts (20°) with
/// no mounting given is mounted so: its roll and pitch in the vehicle are
/// the levelled ones (a level vehicle's attitude is the mounting's; Groves
/// §5.6.2), for the NHC's and the odometer's C_b^v (an odometer along a
/// tilted IMU's x axis would measure a vertical speed), with the mounting
/// yaw given or found in the motion.
fn mounting_from_tilt(
    opts: &FuseOptions,
    fc: &mut FusionConfig,
    a: &crate::align::Alignment,
    mount_yaw_rad: f64,
    diag: &mut Diagnostics,
) {
    let sheet_mount = opts.mount_deg;
    let odometer = fc.odometer.is_some();
    if (opts.nhc.is_some() || odometer) && sheet_mount[0] == 0.0 && sheet_mount[1] == 0.0 {
        let e = a.nav.euler();
        let limit = MOUNT_TILT_FROM_GRAVITY_DEG.to_radians();
        if e.roll_rad.abs() > limit || e.pitch_rad.abs() > limit {
            let yaw_deg = mount_yaw_rad.to_degrees();
            let mount = Euler::from_deg(e.roll_rad.to_degrees(), e.pitch_rad.to_degrees(), yaw_deg);
            if let (Some(n), Some(nhc)) = (&opts.nhc, fc.nhc.as_mut()) {
                nhc.vehicle = VehicleConstraint::new(&mount, Vector3::from(n.lever_m), n.sd_mps);
            }
            if let Some(o) = fc.odometer.as_mut() {
                o.vehicle = VehicleConstraint::new(&mount, o.vehicle.lever_b, o.vehicle.nhc_sd);
            }
            diag.note(format!(
                "the IMU is tilted by roll {:.1}°, pitch {:.1}° at the start and the sheet gives no mounting: \
                 taken as its mounting in the vehicle for the {}, mount_deg [{:.1}, {:.1}, {:.1}] \
                 (set mount_deg in the sheet to override)",
                e.roll_rad.to_degrees(),
                e.pitch_rad.to_degrees(),
                match (opts.nhc.is_some(), odometer) {
                    (true, true) => "NHC and the odometer",
                    (false, true) => "odometer",
                    _ => "NHC",
                },
                e.roll_rad.to_degrees(),
                e.pitch_rad.to_degrees(),
                yaw_deg
            ));
        }
    }
}

/// The alignment pre-pass: reads the IMU and GNSS files from `start` until
/// the aligner has the initial state.
/// A land vehicle's mounting yaw from the motion over the run
/// (`mount_search`), the IMU levelled by the alignment's roll and pitch,
/// decided against the sheet's `sheet_yaw_rad`.
fn mount_yaw_from_files(
    cfg: &KfGinsConfig,
    opts: &FuseOptions,
    start: GpsTime,
    a: &crate::align::Alignment,
    sheet_yaw_rad: f64,
) -> Result<crate::mount_search::MountYawDecision, Error> {
    use crate::mount_search::{MountSearch, MountSearchOptions, decide};
    let e = a.nav.euler();
    let search = MountSearch::new(MountSearchOptions::default(), e.roll_rad, e.pitch_rad);
    let search = std::cell::RefCell::new(search);
    stream_files(
        cfg,
        opts,
        start,
        |f| {
            search.borrow_mut().push_fix(f);
            None::<()>
        },
        |s| search.borrow_mut().push_imu(s),
    )?;
    let search = search.into_inner();
    Ok(decide(search.finish(), sheet_yaw_rad.to_degrees()))
}

/// Streams the IMU and GNSS files from `start` in time order, each fix
/// before the IMU sample at or after it, to `on_fix` and `on_imu` (the
/// alignment's and the mounting search's pre-passes); `on_fix` returning
/// `Some` stops there with it.
fn stream_files<T>(
    cfg: &KfGinsConfig,
    opts: &FuseOptions,
    start: GpsTime,
    mut on_fix: impl FnMut(&GnssFix) -> Option<T>,
    mut on_imu: impl FnMut(&ImuSample),
) -> Result<Option<T>, Error> {
    let mut diag = Diagnostics::with_cap(10);
    let mut gnss = GnssInput::open(&cfg.gnss_path, opts)?;
    let mut imu = ImuReader::open(&cfg.imu_path, opts.week)?;
    let mut next_fix = gnss.next_fix(&mut diag)?;
    while let Some(s) = imu.next_sample(&mut diag)? {
        if s.time < start {
            continue;
        }
        while let Some(f) = next_fix
            && f.time <= s.time
        {
            if f.time >= start
                && let Some(done) = on_fix(&f)
            {
                return Ok(Some(done));
            }
            next_fix = gnss.next_fix(&mut diag)?;
        }
        on_imu(&s);
    }
    Ok(None)
}

fn align_from_files(
    cfg: &KfGinsConfig,
    opts: &FuseOptions,
    ao: &crate::align::AlignOptions,
    start: GpsTime,
    headings: &[crate::io::heading::HeadingObs],
) -> Result<crate::align::Alignment, Error> {
    let aligner = std::cell::RefCell::new(crate::align::Aligner::new(*ao));
    // Headings go in before the fix at or after their time.
    let mut hi = headings.partition_point(|h| h.time < start);
    let done = stream_files(
        cfg,
        opts,
        start,
        |f| {
            let mut aligner = aligner.borrow_mut();
            while let Some(h) = headings.get(hi)
                && h.time <= f.time
            {
                aligner.push_heading(h);
                hi += 1;
            }
            aligner.push_gnss(f)
        },
        |s| aligner.borrow_mut().push_imu(s),
    )?;
    if let Some(a) = done {
        return Ok(a);
    }
    let mut aligner = aligner.into_inner();
    for h in headings.get(hi..).unwrap_or_default() {
        aligner.push_heading(h);
    }
    aligner.finish().ok_or_else(|| Error::NoData {
        path: cfg.gnss_path.clone(),
        msg: "no GNSS fix after the start time: the initial position is unknown, and no initpos/initatt were given".into(),
    })
}
