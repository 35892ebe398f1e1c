//! Triangle filtering: the paper's Algorithm 1.
//!
//! Entry point: [`filter_triangles`]. A triangle is kept when its longest 3-D edge is shorter than
//! `l_max`, all three vertices have a landable class (or the cloud is unclassified), and either its
//! unit normal is steep enough (`|n · k| > min_normal_dot`) or its vertical extent is below `z_min` (the
//! bypass that keeps sensor noise from punching spurious holes into a flat mesh).

use crate::triangulation::Triangulation;
use crate::{Params, Xyz};

/// Parameters of [`filter_triangles`]; `Default` gives the paper's values.
#[derive(Debug, Clone, PartialEq)]
pub struct FilterParams {
    /// `l_max`, metres: a triangle with a 3-D edge at least this long is dropped.
    pub max_triangle_edge_m: f64,
    /// `min_normal_dot`: a triangle needs `|n · k| > min_normal_dot` (unless the `z_min` bypass applies).
    pub min_normal_dot: f64,
    /// `z_min`, metres: a triangle with a smaller vertical extent skips the normal test.
    pub max_triangle_height_m: f64,
    /// `V`: classes allowed at all three vertices. Ignored when there are no classes.
    pub landable_classes: Vec<u8>,
}

impl Default for FilterParams {
    fn default() -> Self {
        Self::from(&Params::default())
    }
}

impl From<&Params> for FilterParams {
    fn from(p: &Params) -> Self {
        Self {
            max_triangle_edge_m: p.max_triangle_edge_m,
            min_normal_dot: p.min_normal_dot,
            max_triangle_height_m: p.max_triangle_height_m,
            landable_classes: p.landable_classes.clone(),
        }
    }
}

/// Returns one flag per triangle of `tri`: true when the triangle passes Algorithm 1.
///
/// `points` are the triangulated points with their z; `classes`, when given, has one entry per
/// point (checked by [`crate::detect`]).
pub fn filter_triangles<P: Xyz>(
    tri: &Triangulation,
    points: &[P],
    classes: Option<&[u8]>,
    params: &FilterParams,
) -> Vec<bool> {
    let mut landable = [false; 256];
    for &c in &params.landable_classes {
        landable[usize::from(c)] = true;
    }
    let l_max2 = params.max_triangle_edge_m * params.max_triangle_edge_m;
    // |n·k| > min_normal_dot with n = c / |c| is c_z^2 > min_normal_dot^2 |c|^2 (min_normal_dot >= 0): no square root.
    let dot_min2 = params.min_normal_dot.max(0.0).powi(2);
    let z_min = params.max_triangle_height_m;
    // One flag per point, so a triangle costs three byte loads for the class test.
    let allowed: Option<Vec<bool>> =
        classes.map(|c| c.iter().map(|&c| landable[usize::from(c)]).collect());
    tri.triangles
        .chunks_exact(3)
        .map(|t| {
            let (ia, ib, ic) = (t[0] as usize, t[1] as usize, t[2] as usize);
            if let Some(ok) = &allowed
                && !(ok[ia] && ok[ib] && ok[ic])
            {
                return false;
            }
            let (a, b, c) = (points[ia].xyz(), points[ib].xyz(), points[ic].xyz());
            let ab = sub(b, a);
            let ac = sub(c, a);
            let bc = sub(c, b);
            let longest2 = norm2(ab).max(norm2(ac)).max(norm2(bc));
            if longest2.is_nan() || longest2 >= l_max2 {
                return false;
            }
            let n = cross(ab, ac);
            if n[2] * n[2] > dot_min2 * norm2(n) {
                return true;
            }
            let z_extent = a[2].max(b[2]).max(c[2]) - a[2].min(b[2]).min(c[2]);
            z_extent < z_min
        })
        .collect()
}

#[inline]
pub(crate) fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

#[inline]
pub(crate) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[inline]
pub(crate) fn norm2(a: [f64; 3]) -> f64 {
    a[0] * a[0] + a[1] * a[1] + a[2] * a[2]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one(points: [[f64; 3]; 3], classes: Option<&[u8]>, params: &FilterParams) -> bool {
        let tri = Triangulation {
            triangles: vec![0, 1, 2],
            halfedges: vec![u32::MAX; 3],
        };
        filter_triangles(&tri, &points, classes, params)[0]
    }

    #[test]
    fn flat_small_roof_triangle_passes() {
        let p = [[0.0, 0.0, 5.0], [1.0, 0.0, 5.0], [0.0, 1.0, 5.0]];
        assert!(one(p, None, &FilterParams::default()));
        assert!(one(p, Some(&[4, 4, 4]), &FilterParams::default()));
    }

    #[test]
    fn a_non_landable_vertex_drops_the_triangle() {
        let p = [[0.0, 0.0, 5.0], [1.0, 0.0, 5.0], [0.0, 1.0, 5.0]];
        assert!(!one(p, Some(&[4, 8, 4]), &FilterParams::default()));
    }

    #[test]
    fn long_edges_are_dropped_in_3d() {
        // 2-D edges of at most 3.6 m, but a 3 m rise makes an edge 4.24 m long in 3-D.
        let p = [[0.0, 0.0, 0.0], [3.0, 0.0, 0.0], [0.0, 2.0, 0.0]];
        assert!(one(p, None, &FilterParams::default()));
        let p = [[0.0, 0.0, 0.0], [3.0, 0.0, 3.0], [0.0, 2.0, 0.0]];
        assert!(!one(
            p,
            None,
            &FilterParams {
                min_normal_dot: 0.0,
                ..FilterParams::default()
            }
        ));
        // Exactly l_max is dropped: the paper's test is strict.
        let p = [[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        assert!(!one(p, None, &FilterParams::default()));
    }

    #[test]
    fn steep_triangles_are_dropped_unless_low() {
        // 45 degrees, 1 m rise: dropped.
        let p = [[0.0, 0.0, 0.0], [1.0, 0.0, 1.0], [0.0, 1.0, 0.0]];
        assert!(!one(p, None, &FilterParams::default()));
        // Steep but only 5 cm tall (a tiny noisy triangle): the z_min bypass keeps it.
        let p = [[0.0, 0.0, 0.0], [0.05, 0.0, 0.05], [0.0, 0.05, 0.0]];
        assert!(one(p, None, &FilterParams::default()));
        // The bypass still needs landable classes.
        assert!(!one(p, Some(&[4, 4, 2]), &FilterParams::default()));
    }
}
