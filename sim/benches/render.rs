//! Frames per second of the simulator: camera image with labels at 640×480 and 320×240.

use criterion::{Criterion, criterion_group, criterion_main};
use landing_sim::camera::{CameraConfig, Intrinsics, render};
use landing_sim::flight::{ViewConfig, view_of};
use landing_sim::{World, WorldConfig};
use rand::SeedableRng;

fn bench_render(c: &mut Criterion) {
    let world = World::generate(1, &WorldConfig::default()).expect("world");
    let mut rng = rand::rngs::SmallRng::seed_from_u64(3);
    let view = view_of(&world, 5, &ViewConfig::default(), &mut rng);
    for (w, h) in [(640u32, 480u32), (320, 240)] {
        let intr = Intrinsics::from_hfov(w, h, 70.0).expect("intrinsics");
        c.bench_function(&format!("camera_{w}x{h}"), |b| {
            b.iter(|| render(&world, &intr, &view.camera, &CameraConfig::default(), 1))
        });
    }
}

criterion_group!(benches, bench_render);
criterion_main!(benches);
