//! Scan-to-map registration: the small rigid correction that lays a new scan onto the map.
//!
//! A drone's navigation is good to a few centimetres and a tenth of a degree, but a tenth of a
//! degree of heading moves a point 40 m away by 7 cm, half a cell. Fused without correction,
//! scans taken from slightly wrong poses smear the map: roofs grow rough and obstacle cells
//! drift off their points. [`FusionMap::register`] finds, before a scan is added, the rotation
//! about the sensor and the translation that minimise the distances of the scan's points to the
//! local planes of the map (point-to-plane alignment, the roof planes for height, roll and
//! pitch; walls, parapets and obstacle sides for the horizontal position and heading). A Gaussian
//! prior on the correction, as wide as the pose error it corrects, keeps the directions the
//! scene does not constrain (a bare flat roof says nothing about heading) where the pose put
//! them.

use std::collections::HashMap;
use std::hash::BuildHasherDefault;

use nalgebra::{Isometry3, Matrix3, Matrix6, SymmetricEigen, UnitQuaternion, Vector3, Vector6};

use crate::{CellHasher, FusionMap};

/// At most this many of a scan's points are matched (every n-th, in scan order).
const MAX_POINTS: usize = 1024;
/// Fewer matched points than this and the scan is fused as it came.
const MIN_MATCHES: usize = 60;
/// A map neighbourhood (the 3 × 3 × 3 cells around a point) needs this many cells for a plane.
const MIN_NEIGHBOURS: usize = 6;
/// A neighbourhood is a plane when it spreads in two directions (its middle eigenvalue, m²), is
/// thin in the third (smallest over middle), and no cell lies farther than a few centimetres
/// from it (an edge, where a roof meets a wall, is no plane to slide along).
const MIN_SPREAD_M2: f64 = 0.002;
const MAX_THINNESS: f64 = 0.1;
const MAX_OFF_PLANE_M: f64 = 0.04;
/// Point-to-plane distances past this are not the same surface, metres.
const MAX_RESIDUAL_M: f64 = 0.2;
/// Distances up to this weigh fully (Huber), metres: about the LiDAR's range noise.
const HUBER_M: f64 = 0.03;
/// The prior: one standard deviation of the correction, in translation (metres) and rotation
/// (radians), against the distances' own (metres). Wider than the realistic pose error
/// (`landing-sim scenarios --pose-noise realistic`: 2-3 cm bias, 0.1° heading) so it does not
/// fight a real correction, narrow enough to hold an unconstrained direction.
const PRIOR_TRANSLATION_M: f64 = 0.1;
const PRIOR_ROTATION_RAD: f64 = 0.5 * std::f64::consts::PI / 180.0;
const RESIDUAL_SIGMA_M: f64 = 0.02;
/// Corrections larger than this are not a pose error but a wrong match: the scan is fused as it
/// came.
const MAX_TRANSLATION_M: f64 = 0.5;
const MAX_ROTATION_RAD: f64 = 2.0 * std::f64::consts::PI / 180.0;
/// Matching rounds (each re-finds the planes near the moved points) and solver steps per round.
const ROUNDS: usize = 2;
const STEPS: usize = 3;

/// A rigid correction found by [`FusionMap::register`]: rotate by [`Correction::rotation`] about
/// [`Correction::pivot`] (the sensor), then move by [`Correction::translation`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Correction {
    /// Rotation vector (axis times angle), radians, world axes.
    pub rotation: [f64; 3],
    /// Translation after the rotation, metres, world axes.
    pub translation: [f64; 3],
    /// The point the rotation turns about, world frame.
    pub pivot: [f64; 3],
    /// Scan points matched to a plane of the map.
    pub matched: usize,
    /// Root-mean-square point-to-plane distance of the matched points before and after, metres.
    pub rms_before_m: f64,
    pub rms_after_m: f64,
}

impl Correction {
    /// Moves a world point by the correction.
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let q = self.isometry() * nalgebra::Point3::from(v(p));
        [q.x, q.y, q.z]
    }

    /// The correction as a motion of the world: `pose' = isometry * pose` for every pose the
    /// scan came with.
    pub fn isometry(&self) -> Isometry3<f64> {
        let rotation = UnitQuaternion::from_scaled_axis(v(self.rotation));
        let pivot = v(self.pivot);
        let shift = pivot + v(self.translation) - rotation * pivot;
        Isometry3::from_parts(shift.into(), rotation)
    }

    /// Length of the translation, metres.
    pub fn translation_m(&self) -> f64 {
        v(self.translation).norm()
    }

    /// Angle of the rotation, degrees.
    pub fn rotation_deg(&self) -> f64 {
        v(self.rotation).norm().to_degrees()
    }
}

/// Why a scan was fused as it came.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum NotRegistered {
    /// Registration is off, or the map holds nothing yet.
    Nothing,
    /// Too few of the scan's points lie near a plane of the map.
    TooFewMatches { matched: usize },
    /// The best correction is too large to be a pose error.
    TooLarge { metres: f64, degrees: f64 },
}

impl std::fmt::Display for NotRegistered {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Nothing => write!(f, "nothing to register to"),
            Self::TooFewMatches { matched } => {
                write!(f, "only {matched} points matched the map's planes")
            }
            Self::TooLarge { metres, degrees } => {
                write!(
                    f,
                    "the correction ({metres:.2} m, {degrees:.2}°) is too large"
                )
            }
        }
    }
}

/// Each cell's neighbourhood plane (centroid, unit normal) when it forms one, as far as one
/// [`FusionMap::register`] call has looked, keyed with the map's own cell hash (several times
/// cheaper than SipHash).
type Planes =
    HashMap<[i32; 3], Option<(Vector3<f64>, Vector3<f64>)>, BuildHasherDefault<CellHasher>>;

/// One scan point matched to a local plane of the map (map-origin coordinates, metres).
struct Match {
    point: Vector3<f64>,
    centroid: Vector3<f64>,
    normal: Vector3<f64>,
}

impl<K> FusionMap<K> {
    /// The correction that lays `points` (a scan in the world frame, taken from `sensor`) onto
    /// the map, or why there is none. Call it before [`FusionMap::insert`]ing the scan, and move
    /// the scan (and every pose it came with) by the correction. Deterministic; reads the map
    /// only.
    pub fn register(
        &self,
        points: &[[f64; 3]],
        sensor: [f64; 3],
    ) -> Result<Correction, NotRegistered> {
        let Some(origin) = self
            .origin
            .filter(|_| self.params.register_scans && self.frames > 0)
        else {
            return Err(NotRegistered::Nothing);
        };
        let rel = |p: [f64; 3]| Vector3::new(p[0] - origin[0], p[1] - origin[1], p[2] - origin[2]);
        let step = points.len().div_ceil(MAX_POINTS).max(1);
        let sample: Vec<Vector3<f64>> = points
            .iter()
            .step_by(step)
            .filter(|p| p.iter().all(|c| c.is_finite()))
            .map(|&p| rel(p))
            .collect();
        let pivot = rel(sensor);
        if !pivot.iter().all(|c| c.is_finite()) {
            return Err(NotRegistered::Nothing);
        }

        // The correction so far: x = (rotation vector, translation), applied to the sample.
        let mut x = Vector6::zeros();
        let mut rms_before = None;
        let mut matched = 0;
        let mut rms_after = 0.0;
        // The plane of each cell's neighbourhood, once per call: a later round's point mostly
        // falls in the cell it fell in before (the correction is centimetres).
        let mut planes = Planes::default();
        for _ in 0..ROUNDS {
            let moved: Vec<Vector3<f64>> = sample.iter().map(|p| apply(&x, p, &pivot)).collect();
            let matches: Vec<Match> = moved
                .iter()
                .filter_map(|p| self.plane_near(p, &mut planes))
                .collect();
            matched = matches.len();
            if matched < MIN_MATCHES {
                return Err(NotRegistered::TooFewMatches { matched });
            }
            rms_before.get_or_insert_with(|| rms(&matches, &Vector6::zeros(), &pivot));
            // Gauss-Newton on the linearised distances, reweighted (Huber) each step; the
            // correction found in this round is `dx` on top of `x`.
            let mut dx = Vector6::zeros();
            for _ in 0..STEPS {
                dx = solve(&matches, &x, &dx, &pivot);
            }
            x += dx;
            rms_after = rms(&matches, &dx, &pivot);
        }
        let rotation = Vector3::new(x[0], x[1], x[2]);
        let translation = Vector3::new(x[3], x[4], x[5]);
        if rotation.norm() > MAX_ROTATION_RAD || translation.norm() > MAX_TRANSLATION_M {
            return Err(NotRegistered::TooLarge {
                metres: translation.norm(),
                degrees: rotation.norm().to_degrees(),
            });
        }
        Ok(Correction {
            rotation: rotation.into(),
            translation: translation.into(),
            pivot: sensor,
            matched,
            rms_before_m: rms_before.unwrap_or(0.0),
            rms_after_m: rms_after,
        })
    }

    /// The plane the map's cells around `p` (map-origin metres) form, when they form one, and
    /// `p` is near it. `planes` remembers each cell's neighbourhood plane (centroid, normal).
    fn plane_near(&self, p: &Vector3<f64>, planes: &mut Planes) -> Option<Match> {
        let c = self.params.cell_size_m;
        let key = [p.x, p.y, p.z].map(|v| (v / c).floor());
        if !key.iter().all(|k| k.abs() < 1.0e9) {
            return None;
        }
        let key = key.map(|k| k as i32);
        let (centroid, normal) = (*planes.entry(key).or_insert_with(|| self.plane_at(key)))?;
        (normal.dot(&(p - centroid)).abs() <= MAX_RESIDUAL_M).then_some(Match {
            point: *p,
            centroid,
            normal,
        })
    }

    /// The plane (centroid, unit normal) the cells around the cell `key` form, when they form
    /// one.
    fn plane_at(&self, key: [i32; 3]) -> Option<(Vector3<f64>, Vector3<f64>)> {
        let c = self.params.cell_size_m;
        let mut means = [Vector3::zeros(); 27];
        let mut n = 0;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let k = [key[0] + dx, key[1] + dy, key[2] + dz];
                    if let Some(cell) = self.cells.get(&k) {
                        means[n] = Vector3::new(
                            (f64::from(k[0]) + f64::from(cell.mean[0])) * c,
                            (f64::from(k[1]) + f64::from(cell.mean[1])) * c,
                            (f64::from(k[2]) + f64::from(cell.mean[2])) * c,
                        );
                        n += 1;
                    }
                }
            }
        }
        if n < MIN_NEIGHBOURS {
            return None;
        }
        let means = &means[..n];
        let centroid = means.iter().sum::<Vector3<f64>>() / n as f64;
        let covariance = means
            .iter()
            .map(|m| (m - centroid) * (m - centroid).transpose())
            .sum::<Matrix3<f64>>()
            / n as f64;
        let eigen = SymmetricEigen::new(covariance);
        let mut order = [0, 1, 2];
        order.sort_by(|&a, &b| eigen.eigenvalues[a].total_cmp(&eigen.eigenvalues[b]));
        let (smallest, middle) = (eigen.eigenvalues[order[0]], eigen.eigenvalues[order[1]]);
        if middle < MIN_SPREAD_M2 || smallest > MAX_THINNESS * middle {
            return None;
        }
        let normal = eigen.eigenvectors.column(order[0]).into_owned();
        if means
            .iter()
            .any(|m| normal.dot(&(m - centroid)).abs() > MAX_OFF_PLANE_M)
        {
            return None;
        }
        Some((centroid, normal))
    }
}

/// `p` moved by the linearised correction `x` about `pivot`.
fn apply(x: &Vector6<f64>, p: &Vector3<f64>, pivot: &Vector3<f64>) -> Vector3<f64> {
    let (w, t) = (
        Vector3::new(x[0], x[1], x[2]),
        Vector3::new(x[3], x[4], x[5]),
    );
    p + w.cross(&(p - pivot)) + t
}

/// One reweighted Gauss-Newton step: the correction `dx` (on top of the points' `x`) that
/// minimises the Huber-weighted point-to-plane distances plus the prior on `x + dx`.
fn solve(
    matches: &[Match],
    x: &Vector6<f64>,
    dx: &Vector6<f64>,
    pivot: &Vector3<f64>,
) -> Vector6<f64> {
    let mut h = Matrix6::zeros();
    let mut g = Vector6::zeros();
    for m in matches {
        let p = apply(dx, &m.point, pivot);
        let r = m.normal.dot(&(p - m.centroid));
        if r.abs() > MAX_RESIDUAL_M {
            continue;
        }
        let weight = if r.abs() <= HUBER_M {
            1.0
        } else {
            HUBER_M / r.abs()
        };
        let d = m.point - pivot;
        let jr = d.cross(&m.normal);
        let j = Vector6::new(jr.x, jr.y, jr.z, m.normal.x, m.normal.y, m.normal.z);
        h += weight * j * j.transpose();
        // Linearised about dx = 0: r(dx) ≈ r0 + j·dx, so use r0 = r - j·dx.
        g += weight * j * (r - j.dot(dx));
    }
    // Prior on the total correction x + dx, scaled to the distances' variance.
    let rot = (RESIDUAL_SIGMA_M / PRIOR_ROTATION_RAD).powi(2);
    let tra = (RESIDUAL_SIGMA_M / PRIOR_TRANSLATION_M).powi(2);
    let prior = Vector6::new(rot, rot, rot, tra, tra, tra);
    for i in 0..6 {
        h[(i, i)] += prior[i];
        g[i] += prior[i] * x[i];
    }
    match h.cholesky() {
        Some(c) => -c.solve(&g),
        None => *dx,
    }
}

/// Root-mean-square distance of the matched points, moved by `dx`, to their planes.
fn rms(matches: &[Match], dx: &Vector6<f64>, pivot: &Vector3<f64>) -> f64 {
    let sum: f64 = matches
        .iter()
        .map(|m| {
            m.normal
                .dot(&(apply(dx, &m.point, pivot) - m.centroid))
                .powi(2)
        })
        .sum();
    (sum / matches.len().max(1) as f64).sqrt()
}

fn v(a: [f64; 3]) -> Vector3<f64> {
    Vector3::new(a[0], a[1], a[2])
}
