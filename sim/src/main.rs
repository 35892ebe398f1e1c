//! The `landing-sim` command line: datasets, recordings, previews and sample scans.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use clap::{Parser, Subcommand};
use landing_sim::camera::{CameraConfig, Intrinsics, render};
use landing_sim::dataset::{DatasetConfig, Split, class_color, write_dataset};
use landing_sim::flight::{FlightConfig, ViewConfig, lidar_pose, random_view, view_of};
use landing_sim::lidar::{LidarConfig, scan};
use landing_sim::recording::{
    RecordConfig, busiest_roof, write_ply as write_recording_ply, write_recording,
};
use landing_sim::{AssetDistribution, AssetKind, World, WorldConfig};
use rand::SeedableRng;

#[derive(Parser)]
#[command(
    name = "landing-sim",
    version,
    about = "Procedural rooftop city simulator"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum Assets {
    /// Table III histograms (the paper's test worlds).
    Histogram,
    /// Kernel density estimate of the Table III data.
    Kde,
    /// Equal probability per asset (the paper's training worlds).
    Uniform,
}

impl Assets {
    fn distribution(self) -> AssetDistribution {
        match self {
            Assets::Histogram => AssetDistribution::ManhattanHistogram,
            Assets::Kde => AssetDistribution::ManhattanKde,
            Assets::Uniform => AssetDistribution::TRAINING,
        }
    }
}

/// The LiDAR's sampling; the defaults are the paper's sensor (16 beams, 100,000 points/s).
#[derive(clap::Args)]
struct LidarArgs {
    /// Laser beams, spread evenly over the vertical field of view.
    #[arg(long, default_value_t = LidarConfig::default().beams,
          value_parser = clap::value_parser!(u32).range(2..=256))]
    lidar_beams: u32,
    /// Points per second over all beams (one rotation per frame at the rotation rate).
    #[arg(long, default_value_t = LidarConfig::default().points_per_second)]
    lidar_points_per_second: f64,
}

impl LidarArgs {
    fn config(&self) -> anyhow::Result<LidarConfig> {
        let config = LidarConfig {
            beams: self.lidar_beams,
            points_per_second: self.lidar_points_per_second,
            ..Default::default()
        };
        config.validate().context("--lidar-points-per-second")?;
        Ok(config)
    }
}

#[derive(Subcommand)]
enum Command {
    /// Write an image/label dataset (PNG pairs + manifest.csv/manifest.json).
    Dataset {
        #[arg(long, default_value_t = 1)]
        seed: u64,
        #[arg(long, default_value_t = 100)]
        images: u32,
        /// `train` (equal asset probabilities) or `test` (Manhattan histograms).
        #[arg(long, default_value = "train")]
        split: String,
        #[arg(long)]
        out: PathBuf,
        #[arg(long, default_value_t = 256)]
        width: u32,
        #[arg(long, default_value_t = 192)]
        height: u32,
        /// Horizontal field of view, degrees.
        #[arg(long, default_value_t = 70.0)]
        hfov: f64,
        /// Images per generated world.
        #[arg(long, default_value_t = 20)]
        images_per_world: u32,
        /// Worker threads (0: one per core). The output does not depend on it.
        #[arg(long, default_value_t = 0)]
        jobs: usize,
    },
    /// Simulate an approach flight and write it as an MCAP recording.
    Record {
        #[arg(long, default_value_t = 1)]
        seed: u64,
        #[arg(long, default_value_t = 20)]
        frames: u32,
        #[arg(long)]
        out: PathBuf,
        #[arg(long, default_value_t = 320)]
        width: u32,
        #[arg(long, default_value_t = 240)]
        height: u32,
        #[arg(long, default_value_t = 70.0)]
        hfov: f64,
        #[arg(long, value_enum, default_value = "histogram")]
        assets: Assets,
        /// Roof to approach (default: the one with the most assets).
        #[arg(long)]
        building: Option<usize>,
        /// Height above the roof at the first frame, metres.
        #[arg(long, default_value_t = 40.0)]
        start_altitude: f64,
        /// Height above the roof at the last frame, metres.
        #[arg(long, default_value_t = 10.0)]
        end_altitude: f64,
        #[arg(long, default_value = "sim-1")]
        drone_id: String,
        #[command(flatten)]
        lidar: LidarArgs,
    },
    /// Write one LiDAR scan of a roof with obstacles as a PLY file in world coordinates.
    Ply {
        #[arg(long, default_value_t = 1)]
        seed: u64,
        #[arg(long)]
        out: PathBuf,
        /// Height above the roof, metres.
        #[arg(long, default_value_t = 20.0)]
        altitude: f64,
        /// Roof to scan (default: the one with the most assets).
        #[arg(long)]
        building: Option<usize>,
        #[command(flatten)]
        lidar: LidarArgs,
    },
    /// Write the `landing eval` scenario set: approach flights to many buildings of
    /// Manhattan-distribution worlds (seeds seed, seed+1, ...), one MCAP per building, buildings
    /// with a tarp or a water tower first.
    Scenarios {
        #[arg(long, default_value_t = 2026)]
        seed: u64,
        /// Worlds to draw buildings from.
        #[arg(long, default_value_t = 6)]
        worlds: u64,
        /// Buildings per world.
        #[arg(long, default_value_t = 6)]
        buildings: usize,
        /// Frames per approach (from 40 m down to 10 m above the roof).
        #[arg(long, default_value_t = 4)]
        frames: u32,
        #[arg(long)]
        out: PathBuf,
        #[arg(long, default_value_t = 320)]
        width: u32,
        #[arg(long, default_value_t = 240)]
        height: u32,
        #[command(flatten)]
        lidar: LidarArgs,
    },
    /// Render one view (image and colourised labels side by side) to a PNG.
    Preview {
        #[arg(long, default_value_t = 1)]
        seed: u64,
        #[arg(long)]
        out: PathBuf,
        #[arg(long, default_value_t = 640)]
        width: u32,
        #[arg(long, default_value_t = 480)]
        height: u32,
        #[arg(long, default_value_t = 70.0)]
        hfov: f64,
        #[arg(long, value_enum, default_value = "histogram")]
        assets: Assets,
    },
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Dataset {
            seed,
            images,
            split,
            out,
            width,
            height,
            hfov,
            images_per_world,
            jobs,
        } => {
            let split: Split = split.parse()?;
            let config = DatasetConfig {
                seed,
                images,
                split,
                width,
                height,
                camera: CameraConfig {
                    hfov_deg: hfov,
                    ..Default::default()
                },
                images_per_world,
                jobs,
                ..Default::default()
            };
            let start = Instant::now();
            let summary = write_dataset(&config, &out)
                .with_context(|| format!("writing dataset to {}", out.display()))?;
            let total: u64 = summary.class_pixel_counts.iter().sum();
            let roof = summary.class_pixel_counts[4] as f64 / total.max(1) as f64;
            println!(
                "wrote {} {} images to {} in {:.1} s (rooftop pixels {:.1} %)",
                summary.images,
                split.name(),
                out.display(),
                start.elapsed().as_secs_f64(),
                roof * 100.0
            );
        }
        Command::Record {
            seed,
            frames,
            out,
            width,
            height,
            hfov,
            assets,
            building,
            start_altitude,
            end_altitude,
            drone_id,
            lidar,
        } => {
            let config = RecordConfig {
                seed,
                world: WorldConfig {
                    assets: assets.distribution(),
                    ..Default::default()
                },
                flight: FlightConfig {
                    frames,
                    altitude_m: (start_altitude, end_altitude),
                    ..Default::default()
                },
                width,
                height,
                camera: CameraConfig {
                    hfov_deg: hfov,
                    ..Default::default()
                },
                lidar: lidar.config()?,
                building,
                drone_id,
                ..Default::default()
            };
            let start = Instant::now();
            let n = write_recording(&config, &out)
                .with_context(|| format!("writing {}", out.display()))?;
            let size = std::fs::metadata(&out).map(|m| m.len()).unwrap_or(0);
            println!(
                "wrote {n} frames to {} ({:.2} MB) in {:.1} s",
                out.display(),
                size as f64 / 1e6,
                start.elapsed().as_secs_f64()
            );
        }
        Command::Ply {
            seed,
            out,
            altitude,
            building,
            lidar,
        } => {
            let world = World::generate(seed, &WorldConfig::default())?;
            let b = building.unwrap_or_else(|| busiest_roof(&world));
            anyhow::ensure!(
                b < world.buildings.len(),
                "--building {b}: the world has {} buildings",
                world.buildings.len()
            );
            let view = ViewConfig {
                altitude_range_m: (altitude, altitude),
                pitch_range_deg: (70.0, 70.0),
                target_jitter: 0.0,
            };
            let mut rng = rand::rngs::SmallRng::seed_from_u64(seed);
            let v = view_of(&world, b, &view, &mut rng);
            let points = scan(&world, &lidar_pose(&v.camera), &lidar.config()?, seed)?;
            write_recording_ply(&points, &out)?;
            let roof = points.iter().filter(|p| p.building as usize == b).count();
            println!(
                "wrote {} points ({roof} on building {b}, {} assets on it) to {}",
                points.len(),
                world.buildings[b].assets.len(),
                out.display()
            );
        }
        Command::Scenarios {
            seed,
            worlds,
            buildings,
            frames,
            out,
            width,
            height,
            lidar,
        } => {
            let lidar = lidar.config()?;
            std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
            let start = Instant::now();
            let (mut files, mut total) = (0usize, 0usize);
            for world_seed in seed..seed + worlds {
                let world = World::generate(world_seed, &WorldConfig::default())?;
                let has = |b: usize, kind: AssetKind| {
                    world.buildings[b]
                        .assets
                        .iter()
                        .any(|&a| world.assets[a].kind == kind)
                };
                // Hard cases first (tarps, water towers on legs), then a seeded order.
                let mut order: Vec<usize> = (0..world.buildings.len()).collect();
                order.sort_by_key(|&b| {
                    let mix = (b as u64 ^ world_seed).wrapping_mul(0x9e37_79b9_7f4a_7c15);
                    (
                        !has(b, AssetKind::Tarp),
                        !has(b, AssetKind::WaterTower),
                        mix,
                    )
                });
                for &b in order.iter().take(buildings) {
                    let config = RecordConfig {
                        seed: world_seed,
                        flight: FlightConfig {
                            frames,
                            ..Default::default()
                        },
                        width,
                        height,
                        lidar,
                        building: Some(b),
                        drone_id: format!("w{world_seed}-b{b}"),
                        ..Default::default()
                    };
                    let path = out.join(format!("w{world_seed}-b{b:03}.mcap"));
                    total += write_recording(&config, &path)
                        .with_context(|| format!("writing {}", path.display()))?;
                    files += 1;
                }
            }
            println!(
                "wrote {total} frames of {files} approaches to {} in {:.1} s",
                out.display(),
                start.elapsed().as_secs_f64()
            );
        }
        Command::Preview {
            seed,
            out,
            width,
            height,
            hfov,
            assets,
        } => {
            let world = World::generate(
                seed,
                &WorldConfig {
                    assets: assets.distribution(),
                    ..Default::default()
                },
            )?;
            let mut rng = rand::rngs::SmallRng::seed_from_u64(seed);
            let view = random_view(&world, &ViewConfig::default(), &mut rng);
            let intr = Intrinsics::from_hfov(width, height, hfov)?;
            let start = Instant::now();
            let img = render(&world, &intr, &view.camera, &CameraConfig::default(), seed);
            let ms = start.elapsed().as_secs_f64() * 1e3;
            let mut canvas = image::RgbImage::new(width * 2, height);
            for y in 0..height {
                for x in 0..width {
                    let i = ((y * width + x) * 3) as usize;
                    canvas.put_pixel(
                        x,
                        y,
                        image::Rgb([img.rgb[i], img.rgb[i + 1], img.rgb[i + 2]]),
                    );
                    canvas.put_pixel(width + x, y, image::Rgb(class_color(img.label(x, y))));
                }
            }
            canvas
                .save(&out)
                .with_context(|| format!("writing {}", out.display()))?;
            println!(
                "wrote {} (building {}, {:.1} m above the roof, pitch {:.1}°, rendered in {ms:.1} ms)",
                out.display(),
                view.building,
                view.altitude_m,
                view.pitch_deg
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scenarios(extra: &[&str]) -> Result<LidarArgs, clap::Error> {
        let args = ["landing-sim", "scenarios", "--out", "x"]
            .iter()
            .chain(extra);
        match Cli::try_parse_from(args)?.command {
            Command::Scenarios { lidar, .. } => Ok(lidar),
            _ => unreachable!("parsed another subcommand"),
        }
    }

    #[test]
    fn lidar_flags_default_to_the_papers_sensor_and_name_themselves_when_wrong() {
        assert_eq!(
            scenarios(&[]).unwrap().config().unwrap(),
            LidarConfig::default()
        );
        let dense = scenarios(&["--lidar-beams", "64", "--lidar-points-per-second", "4e5"]);
        let dense = dense.unwrap().config().unwrap();
        assert_eq!((dense.beams, dense.points_per_second), (64, 4e5));

        let beams = scenarios(&["--lidar-beams", "1"])
            .err()
            .unwrap()
            .to_string();
        assert!(beams.contains("--lidar-beams"), "{beams}");
        let rate = scenarios(&["--lidar-points-per-second", "10"]).unwrap();
        let rate = format!("{:#}", rate.config().unwrap_err());
        assert!(rate.contains("--lidar-points-per-second"), "{rate}");
    }
}
