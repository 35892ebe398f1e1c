//! Planar regions: the paper's Algorithm 2, region growing over triangle adjacency.
//!
//! Entry point: [`extract_regions`]. Seeds are taken in triangle order (not at random, so results
//! are reproducible); each region grows breadth-first through edge-adjacent kept triangles. The
//! plane statistics (mean of the distinct points, area-weighted normal) are then summed over the
//! region's triangles in that order: the walk, free of the points' loads, runs ahead, and the
//! sums' loads, whose addresses are all known, overlap.

use crate::filter::{cross, norm2, sub};
use crate::triangulation::{EMPTY, Triangulation, next_halfedge};
use crate::{GeometryError, Xyz};

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

impl Regions {
    /// Keeps the regions whose `keep` flag is set (one per region, missing ones kept), in order;
    /// the triangles of the others are labelled [`EMPTY`].
    pub fn retain(&mut self, keep: &[bool]) {
        let mut index = vec![EMPTY; self.regions.len()];
        let mut next = 0u32;
        for (i, slot) in index.iter_mut().enumerate() {
            if keep.get(i).copied().unwrap_or(true) {
                *slot = next;
                next += 1;
            }
        }
        for label in &mut self.labels {
            if *label != EMPTY {
                *label = index[*label as usize];
            }
        }
        let mut i = 0;
        self.regions.retain(|_| {
            i += 1;
            index[i - 1] != EMPTY
        });
    }
}

/// Grows regions over the triangles whose `keep` flag is set (one flag per triangle); `points` are
/// the triangulated points with their z.
pub fn extract_regions<P: Xyz>(
    tri: &Triangulation,
    points: &[P],
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
    // Per point: the mark of the last region that counted it ([`plane`]).
    let mut stamp = vec![0u8; points.len()];
    for seed in 0..n {
        if !open[seed] {
            continue;
        }
        grow(tri, &mut open, seed as u32, &mut queue);
        if queue.len() >= params.min_triangles.max(1) {
            let label = regions.len() as u32;
            let triangles = std::mem::take(&mut queue);
            regions.push(plane(
                tri,
                points,
                triangles,
                (label, &mut labels),
                &mut stamp,
            ));
        }
    }
    Ok(Regions { regions, labels })
}

/// Fills `queue` with the region grown breadth-first from `seed` over the `open` triangles,
/// closing them. The walk reads only the mesh's adjacency and the flags, so it runs ahead of the
/// plane statistics ([`plane`]), which read the points in its order. It has no branch on whether
/// a neighbour is open (one no predictor guesses), only arithmetic.
fn grow(tri: &Triangulation, open: &mut [bool], seed: u32, queue: &mut Vec<u32>) {
    open[seed as usize] = false;
    queue.clear();
    queue.push(seed);
    // Every triangle is pushed once, so the head index bounds the loop by the triangle count.
    // The neighbours of a chunk of triangles are read first, then followed in order.
    let mut head = 0;
    let mut twins = [[EMPTY; 3]; CHUNK];
    while head < queue.len() {
        let ahead = &queue[head..queue.len().min(head + CHUNK)];
        for (twin, &t) in twins.iter_mut().zip(ahead) {
            let e = 3 * t as usize;
            *twin = [tri.halfedges[e], tri.halfedges[e + 1], tri.halfedges[e + 2]];
        }
        let len = ahead.len();
        head += len;
        for &o in twins[..len].iter().flatten() {
            if o != EMPTY {
                let nt = o as usize / 3;
                let was_open = open[nt];
                open[nt] = false;
                // Pushed, and popped again unless it was open.
                queue.push(nt as u32);
                queue.truncate(queue.len() - usize::from(!was_open));
            }
        }
    }
}

/// Triangles whose neighbours ([`grow`]) or corners ([`plane`]) are read in one loop with no
/// branch between the loads, so that their cache misses (the walk's order is not the mesh's,
/// nor the mesh's the points') overlap.
const CHUNK: usize = 64;

/// The region of `triangles` (in growth order), labelled `label` in `labels`: the mean of its
/// distinct points and its area-weighted normal, summed in growth order. `stamp` marks the
/// points already counted.
fn plane<P: Xyz>(
    tri: &Triangulation,
    points: &[P],
    triangles: Vec<u32>,
    (label, labels): (u32, &mut [u32]),
    stamp: &mut [u8],
) -> Region {
    // One byte a point: the regions take turns at the marks 1 to 255, cleared between rounds.
    let mark = (label % 255) as u8 + 1;
    if mark == 1 && label > 0 {
        stamp.fill(0);
    }
    let (mut sum, mut normal, mut count) = ([0.0f64; 3], [0.0f64; 3], 0usize);
    // The corners of a chunk of triangles are read first, then summed in order.
    let mut corners = [[[0.0f64; 3]; 3]; CHUNK];
    for chunk in triangles.chunks(CHUNK) {
        let mut vertices = [[0u32; 3]; CHUNK];
        for (v, &t) in vertices.iter_mut().zip(chunk) {
            labels[t as usize] = label;
            let t = 3 * t as usize;
            *v = [tri.triangles[t], tri.triangles[t + 1], tri.triangles[t + 2]];
        }
        for (c, v) in corners.iter_mut().zip(&vertices[..chunk.len()]) {
            *c = v.map(|i| points[i as usize].xyz());
        }
        for (v, &[a, b, c]) in vertices.iter().zip(&corners[..chunk.len()]) {
            for (&i, p) in v.iter().zip([a, b, c]) {
                if stamp[i as usize] != mark {
                    stamp[i as usize] = mark;
                    sum = [sum[0] + p[0], sum[1] + p[1], sum[2] + p[2]];
                    count += 1;
                }
            }
            let nt = cross(sub(b, a), sub(c, a));
            normal = [normal[0] + nt[0], normal[1] + nt[1], normal[2] + nt[2]];
        }
    }
    let k = count.max(1) as f64;
    let len = (normal[0] * normal[0] + normal[1] * normal[1] + normal[2] * normal[2]).sqrt();
    let normal = if len > 0.0 && normal[2] > 0.0 {
        [normal[0] / len, normal[1] / len, normal[2] / len]
    } else {
        [0.0, 0.0, 1.0]
    };
    Region {
        triangles,
        mean: [sum[0] / k, sum[1] / k, sum[2] / k],
        normal,
        point_count: count,
    }
}

/// Most triangles in a pinhole that [`close_pinholes`] closes.
pub const MAX_PINHOLE_TRIANGLES: usize = 8;

/// A pinhole's points may span at most this many times `z_min` vertically.
pub const PINHOLE_Z_FACTOR: f64 = 1.5;

/// Closes the pinholes of `regions`: each connected set of at most [`MAX_PINHOLE_TRIANGLES`]
/// triangles outside every region, all of whose neighbours are triangles of one region, that
/// holds no point of its own (every vertex of its triangles is a vertex of that region), whose
/// triangles have no edge of `max_triangle_edge_m` or longer, and whose points span less than
/// [`PINHOLE_Z_FACTOR`] × `max_triangle_height_m` vertically, joins that region.
///
/// Such a hole is no obstacle. An obstacle the scan hit has points inside its hole (its top, its
/// sides, or a point whose class may not be landed on), and every point around a pinhole is a
/// landable point of the plane. The pinhole is there because Algorithm 1 rejected the triangles
/// between those points for their slope: in a dense cloud (a fused map's cells, 0.1-0.15 m
/// apart) a few centimetres of range noise tilt a short triangle past `min_normal_dot` with a vertical
/// extent just over `z_min`, and one such pinhole in the middle of a roof caps every safe circle
/// around it. A gap in the scan (an edge of `max_triangle_edge_m` or more), a step between two planes (two
/// regions around it) and anything taller are left as they are. The regions' plane statistics
/// are not updated (the pinhole's points are already the region's).
pub fn close_pinholes(
    tri: &Triangulation,
    points: &[[f64; 3]],
    regions: &mut Regions,
    max_triangle_edge_m: f64,
    max_triangle_height_m: f64,
) {
    let n = tri.len();
    let labels = &mut regions.labels;
    let l_max2 = max_triangle_edge_m * max_triangle_edge_m;
    let max_extent = PINHOLE_Z_FACTOR * max_triangle_height_m;
    // Per triangle: whether a search has met it, so that a triangle is searched at most once.
    let mut seen = vec![false; n];
    let mut pocket: Vec<u32> = Vec::with_capacity(MAX_PINHOLE_TRIANGLES + 1);
    let mut rim: Vec<u32> = Vec::new();
    for start in 0..n {
        if labels[start] != EMPTY || seen[start] {
            continue;
        }
        // The edge-connected set of unlabelled triangles around `start`, up to one too many.
        pocket.clear();
        rim.clear();
        pocket.push(start as u32);
        seen[start] = true;
        let (mut region, mut closed) = (EMPTY, true);
        let mut head = 0;
        while head < pocket.len() && closed {
            let t = pocket[head] as usize;
            head += 1;
            for e in 3 * t..3 * t + 3 {
                let o = tri.halfedges[e];
                if o == EMPTY {
                    closed = false; // on the convex hull: open to the outside
                    break;
                }
                let nt = o as usize / 3;
                let label = labels[nt];
                if label == EMPTY {
                    if !pocket.contains(&(nt as u32)) {
                        if pocket.len() == MAX_PINHOLE_TRIANGLES {
                            closed = false;
                            break;
                        }
                        seen[nt] = true;
                        pocket.push(nt as u32);
                    }
                } else if region == EMPTY || region == label {
                    region = label;
                    // Both ends of an edge the pinhole shares with the region are on its rim.
                    rim.push(tri.triangles[e]);
                    rim.push(tri.triangles[next_halfedge(e)]);
                } else {
                    closed = false; // between two regions: a step, not a pinhole
                    break;
                }
            }
        }
        if !closed || region == EMPTY {
            continue;
        }
        // With every vertex on the rim (checked below), the rim's points are the pinhole's.
        let (lo, hi) = rim
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &i| {
                let z = points[i as usize][2];
                (lo.min(z), hi.max(z))
            });
        let pinhole = hi - lo < max_extent
            && pocket.iter().all(|&t| {
                let v = &tri.triangles[3 * t as usize..3 * t as usize + 3];
                let [a, b, c] = [0, 1, 2].map(|k| points[v[k] as usize]);
                let longest2 = norm2(sub(b, a)).max(norm2(sub(c, b))).max(norm2(sub(a, c)));
                v.iter().all(|i| rim.contains(i)) && longest2 < l_max2
            });
        if pinhole {
            for &t in &pocket {
                labels[t as usize] = region;
            }
            regions.regions[region as usize]
                .triangles
                .extend_from_slice(&pocket);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::triangulation::triangulate;

    /// A 0.15 m grid of 9 × 7 points at z = 0 (slightly jittered so the triangulation is
    /// unique), triangulated.
    fn grid() -> (Vec<[f64; 3]>, Triangulation) {
        let mut pts = Vec::new();
        for y in 0..7 {
            for x in 0..9 {
                let j = 0.001 * f64::from((x * 7 + y * 3) % 5);
                pts.push([0.15 * f64::from(x) + j, 0.15 * f64::from(y) - j, 0.0]);
            }
        }
        let tri = triangulate(&pts).unwrap();
        (pts, tri)
    }

    /// The triangles touching any of `points` (indices).
    fn touching(tri: &Triangulation, points: &[usize]) -> Vec<bool> {
        tri.triangles
            .chunks_exact(3)
            .map(|t| t.iter().any(|&v| points.contains(&(v as usize))))
            .collect()
    }

    /// Regions of `tri` with `drop` triangles filtered out, pinholes closed; the number of
    /// unlabelled triangles before and after.
    fn close(pts: &[[f64; 3]], tri: &Triangulation, drop: &[bool], l_max: f64) -> (usize, usize) {
        let keep = drop.iter().map(|d| !d).collect();
        let mut r = extract_regions(tri, pts, keep, &RegionParams { min_triangles: 1 }).unwrap();
        let holes = |r: &Regions| r.labels.iter().filter(|&&l| l == EMPTY).count();
        let before = holes(&r);
        close_pinholes(tri, pts, &mut r, l_max, 0.1);
        let total: usize = r.regions.iter().map(|g| g.triangles.len()).sum();
        assert_eq!(
            total,
            tri.len() - holes(&r),
            "labels and region lists agree"
        );
        (before, holes(&r))
    }

    #[test]
    fn a_pinhole_with_no_point_of_its_own_joins_its_region() {
        let (mut pts, tri) = grid();
        // The two triangles on the edge between points (4, 3) and (5, 3), inside the grid.
        let (a, b) = (3 * 9 + 4, 3 * 9 + 5);
        let pair: Vec<bool> = tri
            .triangles
            .chunks_exact(3)
            .map(|t| t.contains(&(a as u32)) && t.contains(&(b as u32)))
            .collect();
        assert_eq!(pair.iter().filter(|&&d| d).count(), 2);
        assert_eq!(close(&pts, &tri, &pair, 4.0), (2, 0));
        // Not when a triangle has an edge of l_max or longer (a gap in the scan)...
        assert_eq!(close(&pts, &tri, &pair, 0.15), (2, 2));
        // ... nor when its points span 1.5 z_min or more (a step, not noise).
        pts[a][2] = 0.16;
        assert_eq!(close(&pts, &tri, &pair, 4.0), (2, 2));
        pts[a][2] = 0.14;
        assert_eq!(close(&pts, &tri, &pair, 4.0), (2, 0));
    }

    #[test]
    fn a_hole_with_a_point_inside_or_open_or_large_stays() {
        let (pts, tri) = grid();
        // Every triangle around point (4, 3): the point is inside the hole (an obstacle's top).
        let star = touching(&tri, &[3 * 9 + 4]);
        let (before, after) = close(&pts, &tri, &star, 4.0);
        assert!(before >= 4 && after == before, "{before} {after}");
        // Around two neighbouring points: more triangles than a pinhole may have.
        let big = touching(&tri, &[3 * 9 + 4, 3 * 9 + 5]);
        let (before, after) = close(&pts, &tri, &big, 4.0);
        assert!(before > MAX_PINHOLE_TRIANGLES && after == before);
        // A triangle on the convex hull opens to the outside.
        let on_hull = (0..tri.len())
            .find(|&t| (0..3).any(|k| tri.halfedges[3 * t + k] == EMPTY))
            .unwrap();
        let corner: Vec<bool> = (0..tri.len()).map(|t| t == on_hull).collect();
        assert_eq!(close(&pts, &tri, &corner, 4.0), (1, 1));
    }

    #[test]
    fn retain_drops_regions_and_relabels_the_rest() {
        let (pts, tri) = grid();
        // Two regions: the triangles left of x = 0.4 and those right of x = 0.8.
        let x = |t: usize| {
            let v = &tri.triangles[3 * t..3 * t + 3];
            v.iter().map(|&i| pts[i as usize][0]).sum::<f64>() / 3.0
        };
        let keep: Vec<bool> = (0..tri.len()).map(|t| x(t) < 0.4 || x(t) > 0.8).collect();
        let mut r = extract_regions(&tri, &pts, keep, &RegionParams { min_triangles: 1 }).unwrap();
        assert_eq!(r.regions.len(), 2);
        let second = r.regions[1].clone();
        r.retain(&[false, true]);
        assert_eq!(r.regions, vec![second.clone()]);
        for (t, &label) in r.labels.iter().enumerate() {
            let expected = if second.triangles.contains(&(t as u32)) {
                0
            } else {
                EMPTY
            };
            assert_eq!(label, expected, "triangle {t}");
        }
    }

    #[test]
    fn the_256th_region_counts_a_point_it_shares_with_the_first() {
        // 256 lone triangles (no neighbours), each a region of its own; the first and the last
        // share point 0, the others have their own points. The last takes the first one's mark
        // again (one byte a point), so the marks must have been cleared in between.
        let mut triangles = Vec::new();
        for k in 0..256u32 {
            let base = 1 + 3 * k;
            let first = if k == 0 || k == 255 { 0 } else { base };
            triangles.extend([first, base + 1, base + 2]);
        }
        let pts: Vec<[f64; 3]> = (0..1 + 3 * 256)
            .map(|i| [f64::from(i), f64::from(i % 3), 0.0])
            .collect();
        let tri = Triangulation {
            halfedges: vec![EMPTY; triangles.len()],
            triangles,
        };
        let keep = vec![true; tri.len()];
        let r = extract_regions(&tri, &pts, keep, &RegionParams { min_triangles: 1 }).unwrap();
        assert_eq!(r.regions.len(), 256);
        assert!(r.regions.iter().all(|g| g.point_count == 3));
        assert_eq!(r.regions[255].mean[0], (0.0 + 767.0 + 768.0) / 3.0);
    }

    #[test]
    fn a_removed_column_splits_a_grid_into_two_regions() {
        let mut pts = Vec::new();
        for y in 0..5 {
            for x in 0..9 {
                pts.push([f64::from(x), f64::from(y) + 0.01 * f64::from(x % 3), 0.0]);
            }
        }
        let tri = triangulate(&pts).unwrap();
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
