//! Digests of everything `detect` and its steps return, every f64 bit, on seeded clouds: the
//! check that a change meant only to make the geometry faster leaves its answers as they were.
//!
//! `cargo run --release -p landing-geometry --example detect_digest > after.txt`, on the old and
//! the new code, then `diff before.txt after.txt`. `-- 20k` (any substring of a case's name)
//! narrows it. Each line names a case and gives one FNV-1a digest per output: the triangle
//! filter's flags, the regions (labels, triangles, means, normals, point counts), the regions'
//! polygons, and `detect`'s sites as a scan with the defaults, with every site of every region
//! returned, and so as a fused map with keep-clear flags and keep-out disks. Main's digests, from
//! before the steps after the triangulation were made faster (2026-12-07), are in
//! `docs/log/2026-12-07-after-triangulation.md`.

use landing_geometry::boundary::{BoundaryParams, region_polygons};
use landing_geometry::filter::{FilterParams, filter_triangles};
use landing_geometry::regions::{RegionParams, extract_regions};
use landing_geometry::synthetic::{Scene, SceneParams, SecondRoof};
use landing_geometry::{
    Cloud, CloudKind, Detection, Disk, KeepClear, Params, Polygon, triangulate_points,
};

/// FNV-1a over 64-bit words.
struct Digest(u64);

impl Digest {
    fn new() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }

    fn word(&mut self, w: u64) {
        for b in w.to_le_bytes() {
            self.0 = (self.0 ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
        }
    }

    fn f64s(&mut self, v: &[f64]) {
        self.word(v.len() as u64);
        for x in v {
            self.word(x.to_bits());
        }
    }

    fn ring(&mut self, ring: &[[f64; 2]]) {
        self.word(ring.len() as u64);
        for p in ring {
            self.f64s(p);
        }
    }

    fn polygon(&mut self, p: &Polygon) {
        self.ring(&p.shell);
        self.word(p.holes.len() as u64);
        for h in &p.holes {
            self.ring(h);
        }
    }

    fn detection(&mut self, d: &Detection) {
        self.word(d.point_count as u64);
        self.word(d.triangle_count as u64);
        self.word(d.sites.len() as u64);
        for s in &d.sites {
            self.word(u64::from(s.rank));
            self.polygon(&s.polygon);
            self.f64s(&[s.plane_height_m, s.safe_radius_m, s.area_m2]);
            self.f64s(&s.center);
            self.f64s(&s.normal);
            self.word(s.point_count as u64);
            self.word(s.triangle_count as u64);
        }
    }
}

/// The seeded scenes: the benchmark's roofs (seed 1) at four sizes, and at two sizes a sloped
/// roof with a courtyard and a second, lower roof beside it (seed 2).
fn scenes() -> Vec<(String, Scene)> {
    let mut out = Vec::new();
    for (n, label) in [
        (1_500, "1.5k"),
        (20_000, "20k"),
        (100_000, "100k"),
        (1_000_000, "1M"),
    ] {
        let roof = Scene::generate(&SceneParams::with_points(n), 1);
        out.push((format!("roof-{label}"), roof));
    }
    for (n, label) in [(20_000, "20k"), (100_000, "100k")] {
        let params = SceneParams {
            roof_slope: 0.05,
            courtyard_m: Some([6.0, 4.0]),
            second_roof: Some(SecondRoof {
                size_m: [15.0, 25.0],
                height_m: 7.0,
                gap_m: 0.0,
            }),
            ..SceneParams::with_points(n)
        };
        out.push((format!("mixed-{label}"), Scene::generate(&params, 2)));
    }
    out
}

/// The digests of one case, `classes` given or not, with the number of regions and sites.
fn digests(scene: &Scene, classes: Option<&[u8]>) -> Vec<String> {
    let params = Params::default();
    let tri = triangulate_points(&scene.points).expect("triangulation");
    let pts: Vec<[f64; 3]> = scene.points.iter().map(|p| p.map(f64::from)).collect();
    let mask = filter_triangles(&tri, &pts, classes, &FilterParams::from(&params));
    let mut steps = [Digest::new(), Digest::new(), Digest::new()];
    for &k in &mask {
        steps[0].word(u64::from(k));
    }
    let regions = extract_regions(&tri, &pts, mask, &RegionParams::default()).expect("regions");
    for &l in &regions.labels {
        steps[1].word(u64::from(l));
    }
    for r in &regions.regions {
        steps[1].word(r.triangles.len() as u64);
        for &t in &r.triangles {
            steps[1].word(u64::from(t));
        }
        steps[1].f64s(&r.mean);
        steps[1].f64s(&r.normal);
        steps[1].word(r.point_count as u64);
    }
    let polygons =
        region_polygons(&tri, &pts, &regions, &BoundaryParams::default()).expect("polygons");
    for p in &polygons {
        steps[2].polygon(p);
    }
    let mut out: Vec<String> = steps.iter().map(|d| format!("{:016x}", d.0)).collect();
    out[1] += &format!(" ({} regions)", regions.regions.len());
    out.extend(detections(scene, classes).iter().map(|d| {
        let mut digest = Digest::new();
        digest.detection(d);
        format!("{:016x} ({} sites)", digest.0, d.sites.len())
    }));
    out
}

/// `detect` as a scan with the defaults; with every site of every region returned, however
/// small; and so as a fused map whose every 37th point is flagged keep-clear, with keep-out disks
/// at every 50th point.
fn detections(scene: &Scene, classes: Option<&[u8]>) -> Vec<Detection> {
    let every_site = Params {
        min_region_triangles: 1,
        min_safe_radius_m: 0.0,
        max_sites: 100_000,
        ..Params::default()
    };
    let flags: Vec<bool> = (0..scene.points.len()).map(|i| i % 37 == 0).collect();
    let disks: Vec<Disk> = (scene.points.iter().step_by(50))
        .map(|p| Disk {
            center: [f64::from(p[0]), f64::from(p[1])],
            radius: 0.2,
        })
        .collect();
    let keep_out = |_: [f64; 3], _: [f64; 3], _: [f64; 4]| disks.clone();
    let scan = Cloud::new(&scene.points, classes);
    let fused = scan
        .with_kind(CloudKind::FusedMap {
            cell_size_m: scene.spacing_m,
        })
        .with_keep_clear(KeepClear {
            disks: Some(&keep_out),
            points: Some(&flags),
        });
    [
        (scan, Params::default()),
        (scan, every_site.clone()),
        (fused, every_site),
    ]
    .iter()
    .map(|(cloud, params)| landing_geometry::detect(cloud, params).expect("detect"))
    .collect()
}

fn main() {
    let filter = std::env::args().nth(1).unwrap_or_default();
    println!("case: mask regions polygons | detect: scan, every site, fused");
    for (name, scene) in scenes() {
        for (with, classes) in [("classes", Some(&scene.classes[..])), ("none", None)] {
            let case = format!("{name} {with}");
            if !case.contains(&filter) {
                continue;
            }
            let d = digests(&scene, classes);
            println!("{case}: {} | {}", d[..3].join(" "), d[3..].join(" "));
        }
    }
}
