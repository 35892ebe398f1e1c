//! Planar regions: the paper's Algorithm 2, region growing over triangle adjacency.
//!
//! Entry point: [`extract_regions`]. Seeds are taken in triangle order (not at random, so results
//! are reproducible); each region grows breadth-first through edge-adjacent kept triangles. The
//! plane statistics (mean of the distinct points, area-weighted normal) are gathered during the
//! same pass, while the triangle's points are in cache.

use crate::GeometryError;
use crate::filter::{cross, sub};
use crate::triangulation::{EMPTY, Triangulation};

/// Parameters of [`extract_regions`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RegionParams {
    /// Regions with fewer triangles are discarded (0 and 1 keep every region).
    pub min_triangles: usize,
}

impl Default for RegionParams {
    fn default() -> Self {
        Self {
            min_triangles: crate::Params::default().min_region_triangles,
        }
    }
}

/// One planar region: edge-connected kept triangles.
#[derive(Debug, Clone, PartialEq)]
pub struct Region {
    /// Triangle indices in growth order (the seed, the smallest index, first).
    pub triangles: Vec<u32>,
    /// Mean of the region's distinct points.
    pub mean: [f64; 3],
    /// Unit normal, area-weighted over the triangles, z up (`[0, 0, 1]` if degenerate).
    pub normal: [f64; 3],
    /// Number of distinct points.
    pub point_count: usize,
}

/// All regions of one triangulation.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Regions {
    /// The kept regions, in order of their seed triangle.
    pub regions: Vec<Region>,
    /// For every triangle, the index in `regions` of its region, or [`EMPTY`] (filtered out, or in a
    /// discarded small region).
    pub labels: Vec<u32>,
}

/// Grows regions over the triangles whose `keep` flag is set (one flag per triangle); `points` are
/// the triangulated points with their z.
pub fn extract_regions(
    tri: &Triangulation,
    points: &[[f64; 3]],
    keep: Vec<bool>,
    params: &RegionParams,
) -> Result<Regions, GeometryError> {
    let n = tri.len();
    if keep.len() != n {
        return Err(GeometryError::InvalidMesh {
            reason: format!("{} filter flags for {n} triangles", keep.len()),
        });
    }
    // `open[t]`: kept and not yet claimed by a region (Algorithm 2's T_f).
    let mut open = keep;
    let mut labels = vec![EMPTY; n];
    let mut regions = Vec::new();
    let mut queue: Vec<u32> = Vec::new();
    // Per point: the seed of the last region that counted it.
    let mut stamp = vec![EMPTY; points.len()];
    for seed in 0..n {
        if !open[seed] {
            continue;
        }
        open[seed] = false;
        queue.clear();
        queue.push(seed as u32);
        let (mut sum, mut normal, mut count) = ([0.0f64; 3], [0.0f64; 3], 0usize);
        // `queue` doubles as the region: every triangle is pushed once, so the head index bounds
        // the loop by the triangle count.
        let mut head = 0;
        while head < queue.len() {
            let t = queue[head] as usize;
            head += 1;
            let v = &tri.triangles[3 * t..3 * t + 3];
            for &i in v {
                if stamp[i as usize] != seed as u32 {
                    stamp[i as usize] = seed as u32;
                    let p = points[i as usize];
                    sum = [sum[0] + p[0], sum[1] + p[1], sum[2] + p[2]];
                    count += 1;
                }
            }
            let (a, b, c) = (
                points[v[0] as usize],
                points[v[1] as usize],
                points[v[2] as usize],
            );
            let nt = cross(sub(b, a), sub(c, a));
            normal = [normal[0] + nt[0], normal[1] + nt[1], normal[2] + nt[2]];
            for e in 3 * t..3 * t + 3 {
                let o = tri.halfedges[e];
                if o != EMPTY {
                    let nt = o as usize / 3;
                    if open[nt] {
                        open[nt] = false;
                        queue.push(nt as u32);
                    }
                }
            }
        }
        if queue.len() >= params.min_triangles.max(1) {
            let label = regions.len() as u32;
            for &t in &queue {
                labels[t as usize] = label;
            }
            let k = count.max(1) as f64;
            let len =
                (normal[0] * normal[0] + normal[1] * normal[1] + normal[2] * normal[2]).sqrt();
            let normal = if len > 0.0 && normal[2] > 0.0 {
                [normal[0] / len, normal[1] / len, normal[2] / len]
            } else {
                [0.0, 0.0, 1.0]
            };
            regions.push(Region {
                triangles: std::mem::take(&mut queue),
                mean: [sum[0] / k, sum[1] / k, sum[2] / k],
                normal,
                point_count: count,
            });
        }
    }
    Ok(Regions { regions, labels })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::triangulation::{TriangulationConfig, triangulate};

    #[test]
    fn a_removed_column_splits_a_grid_into_two_regions() {
        let mut pts = Vec::new();
        for y in 0..5 {
            for x in 0..9 {
                pts.push([f64::from(x), f64::from(y) + 0.01 * f64::from(x % 3), 0.0]);
            }
        }
        let tri = triangulate(&pts, &TriangulationConfig::default()).unwrap();
        // Drop every triangle that touches the column x = 4.
        let keep: Vec<bool> = tri
            .triangles
            .chunks_exact(3)
            .map(|t| t.iter().all(|&v| pts[v as usize][0] != 4.0))
            .collect();
        let kept = keep.iter().filter(|&&k| k).count();
        let r = extract_regions(&tri, &pts, keep, &RegionParams { min_triangles: 1 }).unwrap();
        assert_eq!(r.regions.len(), 2);
        let total: usize = r.regions.iter().map(|r| r.triangles.len()).sum();
        assert_eq!(total, kept);
        // Seeds in triangle order: each region starts at its smallest triangle.
        assert!(r.regions[0].triangles[0] < r.regions[1].triangles[0]);
        for region in &r.regions {
            assert_eq!(region.triangles.iter().min(), region.triangles.first());
            assert_eq!(region.normal, [0.0, 0.0, 1.0]);
            assert_eq!(region.point_count, 4 * 5);
        }
        let r = extract_regions(
            &tri,
            &pts,
            vec![true; tri.len()],
            &RegionParams {
                min_triangles: 1000,
            },
        )
        .unwrap();
        assert!(r.regions.is_empty());
        assert!(r.labels.iter().all(|&l| l == EMPTY));
    }
}
