//! EGM96 geoid heights, to turn heights above mean sea level into
//! ellipsoidal heights where a receiver does not say the geoid separation
//! (NMEA GGA with an empty field 11: Unicore, Quectel, Ashtech, Telit…).
//!
//! Model: EGM96 (Lemoine et al. 1998, NASA/TP-1998-206861), the geoid of
//! WGS 84, synthesised from its spherical-harmonic coefficients to degree
//! and order 360 by the `egm96` crate (a port of NGA's F477 program,
//! coefficients from NGA's distribution; Zlib licence). One synthesis takes
//! about a millisecond, too slow for every fix of a 10 Hz day, so it is
//! sampled on a 5-arc-minute grid, node by node as positions reach them,
//! and interpolated bilinearly. GeographicLib's documentation of its
//! `egm96-5` grid gives 0.14 m as the largest bilinear interpolation error
//! of such a grid (0.005 m rms): far below a code receiver's vertical error.

use std::collections::HashMap;

/// How the separation is computed, for summaries.
pub const EGM96_SOURCE: &str = "EGM96 geoid (NGA/NASA, WGS 84): degree-360 spherical harmonics \
    (egm96 crate, after NGA's F477) on a 5' grid, bilinear interpolation (≤ 0.14 m)";

/// Grid spacing (degrees): 5 arc-minutes.
const STEP_DEG: f64 = 5.0 / 60.0;
/// Nodes around a parallel.
const NODES_PER_TURN: i32 = 4320;

/// EGM96 geoid separation N (geoid above the WGS 84 ellipsoid), so that
/// ellipsoidal height h = H (above mean sea level) + N. Grid nodes are
/// computed when first needed and kept.
#[derive(Clone, Debug, Default)]
pub struct Egm96Grid {
    nodes: HashMap<(i32, i32), f64>,
}

impl Egm96Grid {
    pub fn new() -> Self {
        Self::default()
    }

    /// Spherical-harmonic syntheses done so far (grid nodes computed).
    #[cfg(test)]
    pub(crate) fn nodes_computed(&self) -> usize {
        self.nodes.len()
    }

    fn node(&mut self, i: i32, j: i32) -> f64 {
        let j = j.rem_euclid(NODES_PER_TURN);
        *self.nodes.entry((i, j)).or_insert_with(|| {
            let lat = (i as f64 * STEP_DEG).clamp(-90.0, 90.0);
            egm96::egm96_compute_altitude_offset(lat, j as f64 * STEP_DEG)
        })
    }

    /// Geoid separation N (m) at a latitude and longitude (degrees);
    /// `None` for a latitude outside ±90° or a non-finite input.
    pub fn separation_m(&mut self, lat_deg: f64, lon_deg: f64) -> Option<f64> {
        if !(lat_deg.is_finite() && lon_deg.is_finite()) || lat_deg.abs() > 90.0 {
            return None;
        }
        let lon = lon_deg.rem_euclid(360.0);
        let (y, x) = (lat_deg / STEP_DEG, lon / STEP_DEG);
        let (i, j) = (y.floor(), x.floor());
        let (fy, fx) = (y - i, x - j);
        let (i, j) = (i as i32, j as i32);
        let n00 = self.node(i, j);
        let n01 = self.node(i, j + 1);
        let n10 = self.node(i + 1, j);
        let n11 = self.node(i + 1, j + 1);
        Some((1.0 - fy) * ((1.0 - fx) * n00 + fx * n01) + fy * ((1.0 - fx) * n10 + fx * n11))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// (lat°, lon°, published EGM96 N in m, tolerance m).
    const REFERENCE: [(f64, f64, f64, f64); 10] = [
        // NGA's EGM96 test points (INPUT.DAT of the EGM96 distribution,
        // expected undulations as listed with F477.F / INTPT.F).
        (38.628_155, 269.779_155, -31.628, 0.2),
        (-14.621_217, 305.021_114, -2.969, 0.2),
        (46.874_319, 102.448_729, -43.575, 0.2),
        (-23.617_446, 133.874_712, 15.871, 0.2),
        (38.625_473, 359.999_5, 50.066, 0.2),
        (-0.466_744, 0.002_3, 17.329, 0.2),
        // GeographicLib GeoidEval documentation example: Timbuktu,
        // 16:46:33N 3:00:34W → 28.7068 m with egm96-5.
        (16.775_833, -3.009_444, 28.7068, 0.2),
        // UNAVCO geoid height calculator (EGM96), to cm, as quoted by the
        // cesium-native EGM96 grid tests.
        (11.046_411, 135.890_126, 57.79, 1.0),
        (11.790_178, 77.266_369, -90.03, 1.0),
        (57.955_035, 6.946_187, 41.76, 1.0),
    ];

    #[test]
    fn within_a_metre_of_published_egm96_values() {
        let mut g = Egm96Grid::new();
        for (lat, lon, n_ref, tol) in REFERENCE {
            let n = g.separation_m(lat, lon).unwrap();
            // The same point given with a longitude in −180..180.
            let n2 = g.separation_m(lat, lon - 360.0).unwrap();
            assert!((n - n2).abs() < 1e-9);
            assert!(
                (n - n_ref).abs() < tol.min(1.0),
                "EGM96 at {lat}, {lon}: {n:.3} m, published {n_ref} m"
            );
        }
        assert_eq!(g.nodes_computed(), 4 * REFERENCE.len());
    }

    #[test]
    fn a_day_at_10_hz_needs_few_syntheses() {
        // 864 000 positions along a 300 km track: only the nodes of the
        // cells crossed are computed.
        let mut g = Egm96Grid::new();
        let n = 864_000;
        let t = std::time::Instant::now();
        let mut sum = 0.0;
        for k in 0..n {
            let f = k as f64 / n as f64;
            sum += g.separation_m(44.0 + 2.0 * f, -121.3 + 2.0 * f).unwrap();
        }
        let dt = t.elapsed();
        println!(
            "{n} look-ups in {dt:?}, {} nodes computed, mean N {:.3} m",
            g.nodes_computed(),
            sum / n as f64
        );
        assert!(g.nodes_computed() < 200, "{}", g.nodes_computed());
    }

    #[test]
    fn bad_input_is_none_not_a_panic() {
        let mut g = Egm96Grid::new();
        assert_eq!(g.separation_m(f64::NAN, 0.0), None);
        assert_eq!(g.separation_m(91.0, 0.0), None);
        assert_eq!(g.separation_m(0.0, f64::INFINITY), None);
        assert!(g.separation_m(90.0, 180.0).is_some());
        assert!(g.separation_m(-90.0, -180.0).is_some());
    }
}
