//! Simulation speed: camera image with labels, LiDAR scan, and a whole frame (image + labels +
//! scan + ground truth) at 640×480 and 320×240, on one core.

use criterion::{Criterion, criterion_group, criterion_main};
use landing_sim::camera::{CameraConfig, Intrinsics, render};
use landing_sim::flight::{ViewConfig, lidar_pose, view_of};
use landing_sim::lidar::{LidarConfig, scan};
use landing_sim::recording::busiest_roof;
use landing_sim::truth::{TruthConfig, ground_truth};
use landing_sim::{World, WorldConfig};
use rand::SeedableRng;

fn bench_sim(c: &mut Criterion) {
    let world = World::generate(1, &WorldConfig::default()).expect("world");
    let b = busiest_roof(&world);
    let mut rng = rand::rngs::SmallRng::seed_from_u64(3);
    let view = view_of(&world, b, &ViewConfig::default(), &mut rng);
    let lp = lidar_pose(&view.camera);
    let lidar = LidarConfig::default();
    c.bench_function("lidar_scan", |bench| {
        bench.iter(|| scan(&world, &lp, &lidar, 1).expect("scan"))
    });
    for (w, h) in [(640u32, 480u32), (320, 240)] {
        let intr = Intrinsics::from_hfov(w, h, 70.0).expect("intrinsics");
        let cam = CameraConfig::default();
        c.bench_function(&format!("camera_{w}x{h}"), |bench| {
            bench.iter(|| render(&world, &intr, &view.camera, &cam, 1))
        });
        c.bench_function(&format!("frame_{w}x{h}"), |bench| {
            bench.iter(|| {
                let img = render(&world, &intr, &view.camera, &cam, 1);
                let pts = scan(&world, &lp, &lidar, 1).expect("scan");
                let gt = ground_truth(&world, &pts, b, &TruthConfig::default()).expect("truth");
                (img, gt)
            })
        });
    }
}

criterion_group!(benches, bench_sim);
criterion_main!(benches);
