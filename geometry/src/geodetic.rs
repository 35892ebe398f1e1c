//! Local ENU (metres) to WGS-84 latitude/longitude/height, through earth-centred ECEF: how the
//! service puts latitude and longitude on its sites, and the simulator places its worlds.

/// A WGS-84 position: degrees and metres above the ellipsoid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geodetic {
    pub latitude_deg: f64,
    pub longitude_deg: f64,
    pub altitude_m: f64,
}

/// WGS-84 semi-major axis, metres.
const A: f64 = 6_378_137.0;
/// WGS-84 flattening.
const F: f64 = 1.0 / 298.257_223_563;
/// First eccentricity squared.
const E2: f64 = F * (2.0 - F);

/// The geodetic position of the point `enu` (east, north, up metres) of the local frame whose
/// origin is `origin`.
pub fn enu_to_geodetic(origin: Geodetic, enu: [f64; 3]) -> Geodetic {
    let [x0, y0, z0] = geodetic_to_ecef(origin);
    let (slat, clat) = origin.latitude_deg.to_radians().sin_cos();
    let (slon, clon) = origin.longitude_deg.to_radians().sin_cos();
    let [e, n, u] = enu;
    let dx = -slon * e - slat * clon * n + clat * clon * u;
    let dy = clon * e - slat * slon * n + clat * slon * u;
    let dz = clat * n + slat * u;
    ecef_to_geodetic([x0 + dx, y0 + dy, z0 + dz])
}

/// The local ENU coordinates (east, north, up metres) of `g` in the frame whose origin is
/// `origin`: the inverse of [`enu_to_geodetic`].
pub fn geodetic_to_enu(origin: Geodetic, g: Geodetic) -> [f64; 3] {
    let [x0, y0, z0] = geodetic_to_ecef(origin);
    let [x, y, z] = geodetic_to_ecef(g);
    let (dx, dy, dz) = (x - x0, y - y0, z - z0);
    let (slat, clat) = origin.latitude_deg.to_radians().sin_cos();
    let (slon, clon) = origin.longitude_deg.to_radians().sin_cos();
    [
        -slon * dx + clon * dy,
        -slat * clon * dx - slat * slon * dy + clat * dz,
        clat * clon * dx + clat * slon * dy + slat * dz,
    ]
}

/// Earth-centred, earth-fixed coordinates of a geodetic position.
pub fn geodetic_to_ecef(g: Geodetic) -> [f64; 3] {
    let (slat, clat) = g.latitude_deg.to_radians().sin_cos();
    let (slon, clon) = g.longitude_deg.to_radians().sin_cos();
    let n = A / (1.0 - E2 * slat * slat).sqrt();
    [
        (n + g.altitude_m) * clat * clon,
        (n + g.altitude_m) * clat * slon,
        (n * (1.0 - E2) + g.altitude_m) * slat,
    ]
}

/// The geodetic position of ECEF coordinates (fixed-point iteration on the latitude, which
/// converges to well below a millimetre in a handful of steps for any point near the surface).
pub fn ecef_to_geodetic(p: [f64; 3]) -> Geodetic {
    let [x, y, z] = p;
    let lon = y.atan2(x);
    let r = x.hypot(y);
    let mut lat = z.atan2(r * (1.0 - E2));
    let mut h = 0.0;
    // Bounded: each step gains several digits; 10 steps are far more than enough.
    for _ in 0..10 {
        let s = lat.sin();
        let n = A / (1.0 - E2 * s * s).sqrt();
        h = if lat.cos().abs() > 1e-10 {
            r / lat.cos() - n
        } else {
            z.abs() - n * (1.0 - E2)
        };
        let next = z.atan2(r * (1.0 - E2 * n / (n + h)));
        let done = (next - lat).abs() < 1e-14;
        lat = next;
        if done {
            break;
        }
    }
    Geodetic {
        latitude_deg: lat.to_degrees(),
        longitude_deg: lon.to_degrees(),
        altitude_m: h,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ZURICH: Geodetic = Geodetic {
        latitude_deg: 47.3769,
        longitude_deg: 8.5417,
        altitude_m: 408.0,
    };

    #[test]
    fn origin_maps_to_itself() {
        let g = enu_to_geodetic(ZURICH, [0.0, 0.0, 0.0]);
        assert!((g.latitude_deg - ZURICH.latitude_deg).abs() < 1e-10);
        assert!((g.longitude_deg - ZURICH.longitude_deg).abs() < 1e-10);
        assert!((g.altitude_m - ZURICH.altitude_m).abs() < 1e-6);
    }

    #[test]
    fn ecef_round_trip() {
        for g in [
            ZURICH,
            Geodetic {
                latitude_deg: -33.9,
                longitude_deg: 151.2,
                altitude_m: -20.0,
            },
            Geodetic {
                latitude_deg: 89.9,
                longitude_deg: -179.0,
                altitude_m: 3000.0,
            },
            Geodetic {
                latitude_deg: 0.0,
                longitude_deg: 0.0,
                altitude_m: 0.0,
            },
        ] {
            let back = ecef_to_geodetic(geodetic_to_ecef(g));
            assert!(
                (back.latitude_deg - g.latitude_deg).abs() < 1e-9,
                "{g:?} {back:?}"
            );
            assert!(
                (back.longitude_deg - g.longitude_deg).abs() < 1e-9,
                "{g:?} {back:?}"
            );
            assert!(
                (back.altitude_m - g.altitude_m).abs() < 1e-4,
                "{g:?} {back:?}"
            );
        }
    }

    #[test]
    fn one_kilometre_north_and_east_at_known_scales() {
        // Meridian radius of curvature M and prime-vertical N at the origin latitude give the
        // degree lengths; the offsets are small enough for the linearisation to hold to 1e-6.
        let lat = ZURICH.latitude_deg.to_radians();
        let s2 = lat.sin().powi(2);
        let m = A * (1.0 - E2) / (1.0 - E2 * s2).powf(1.5);
        let n = A / (1.0 - E2 * s2).sqrt();
        let north = enu_to_geodetic(ZURICH, [0.0, 1000.0, 0.0]);
        let expected_dlat = (1000.0 / (m + ZURICH.altitude_m)).to_degrees();
        assert!((north.latitude_deg - ZURICH.latitude_deg - expected_dlat).abs() < 1e-6);
        let east = enu_to_geodetic(ZURICH, [1000.0, 0.0, 0.0]);
        let expected_dlon = (1000.0 / ((n + ZURICH.altitude_m) * lat.cos())).to_degrees();
        assert!((east.longitude_deg - ZURICH.longitude_deg - expected_dlon).abs() < 1e-6);
        // Moving along the tangent plane rises above the curved ellipsoid: about d^2 / 2R.
        assert!(
            (east.altitude_m - ZURICH.altitude_m - 0.0785).abs() < 0.01,
            "{east:?}"
        );
        let up = enu_to_geodetic(ZURICH, [0.0, 0.0, 50.0]);
        assert!((up.altitude_m - ZURICH.altitude_m - 50.0).abs() < 1e-6);
    }

    #[test]
    fn enu_round_trip() {
        for enu in [[0.0, 0.0, 0.0], [12.5, -40.0, 31.0], [-950.0, 1200.0, -5.0]] {
            let back = geodetic_to_enu(ZURICH, enu_to_geodetic(ZURICH, enu));
            for k in 0..3 {
                assert!((back[k] - enu[k]).abs() < 1e-6, "{enu:?} {back:?}");
            }
        }
    }
}
