//! The `landing-sim` command line: datasets, recordings, previews and sample scans.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use clap::{Parser, Subcommand};
use landing_recording::scene::class_color;
use landing_sim::camera::{CameraConfig, Intrinsics, render};
use landing_sim::dataset::{DatasetConfig, Split, write_dataset};
use landing_sim::flight::{FlightConfig, ViewConfig, lidar_pose, random_view, view_of};
use landing_sim::footprints::write_footprints;
use landing_sim::geodetic::scenario_origin;
use landing_sim::lidar::{LidarConfig, scan};
use landing_sim::noise::PoseNoise;
use landing_sim::recording::{
    RecordConfig, busiest_roof, write_ply as write_recording_ply, write_recording,
};
use landing_sim::revisit::ChangeRates;
use landing_sim::scenarios::{MANIFEST, Origin, Revisits, ScenarioConfig, write_scenarios};
use landing_sim::{AssetDistribution, World, WorldConfig};
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

/// The pose error the frames of a scenario carry.
#[derive(Clone, Copy, Debug, PartialEq, clap::ValueEnum)]
enum PoseNoiseArg {
    /// The true poses.
    None,
    /// RTK-fixed GNSS with a dual-antenna MEMS INS: a per-approach bias (2 cm horizontal,
    /// 3 cm vertical), a 1 cm/√s random walk, 0.03° roll/pitch and 0.1° yaw noise and a 0.1°
    /// heading bias (EVALUATION.md, "Pose noise").
    Realistic,
}

/// How an approach is sampled in time, and the pose error its frames carry.
#[derive(clap::Args)]
struct ApproachArgs {
    /// Frames per approach (from 40 m down to 10 m above the roof), timestamped at 10 Hz.
    #[arg(long, default_value_t = 4)]
    frames: u32,
    /// Sensor rate, Hz: the same descent from 40 m to 10 m, lasting --duration-s, sampled at
    /// this rate (round(duration × rate) + 1 frames, timestamps at this rate).
    #[arg(long, conflicts_with = "frames")]
    rate_hz: Option<f64>,
    /// Duration of the descent with --rate-hz, seconds.
    #[arg(long, default_value_t = 4.0, requires = "rate_hz")]
    duration_s: f64,
    /// Error of the poses the frames carry (the ground truth keeps the true poses).
    #[arg(long, value_enum, default_value = "none")]
    pose_noise: PoseNoiseArg,
}

impl ApproachArgs {
    fn flight(&self) -> anyhow::Result<FlightConfig> {
        let Some(rate_hz) = self.rate_hz else {
            return Ok(FlightConfig {
                frames: self.frames,
                ..Default::default()
            });
        };
        anyhow::ensure!(
            rate_hz.is_finite() && rate_hz > 0.0 && rate_hz <= 1000.0,
            "--rate-hz {rate_hz}: need 0 < rate <= 1000"
        );
        let d = self.duration_s;
        anyhow::ensure!(
            d.is_finite() && d > 0.0 && d <= 600.0,
            "--duration-s {d}: need 0 < duration <= 600"
        );
        let frames = (d * rate_hz).round() + 1.0;
        anyhow::ensure!(
            frames <= 100_000.0,
            "--duration-s {d} at --rate-hz {rate_hz} makes {frames} frames per approach (at most 100000)"
        );
        Ok(FlightConfig {
            frames: frames as u32,
            rate_hz,
            ..Default::default()
        })
    }

    fn pose_noise(&self) -> PoseNoise {
        match self.pose_noise {
            PoseNoiseArg::None => PoseNoise::NONE,
            PoseNoiseArg::Realistic => PoseNoise::REALISTIC,
        }
    }
}

/// Where the scenario worlds lie on the Earth.
#[derive(Clone, Copy, Debug, PartialEq, clap::ValueEnum)]
enum OriginArg {
    /// Nowhere: the frames carry no geodetic origin.
    None,
    /// On Manhattan's blocks around Midtown (40.75 N, 73.98 W), each world of a set in its own
    /// 500 m cell (seed mod 60 of a 3 × 20 grid along the avenues); writes footprints.geojson.
    Manhattan,
}

/// `--change-rates add=P,remove=P,moved=P,tarp=P` (keys left out keep their defaults).
fn parse_change_rates(text: &str) -> Result<ChangeRates, String> {
    let mut rates = ChangeRates::default();
    for part in text.split(',').filter(|p| !p.trim().is_empty()) {
        let (key, value) = part
            .split_once('=')
            .ok_or_else(|| format!("`{part}`: expected KEY=PROBABILITY"))?;
        let p: f64 = value
            .trim()
            .parse()
            .map_err(|_| format!("`{value}` is not a number"))?;
        if !(0.0..=1.0).contains(&p) {
            return Err(format!("{key}={value}: a rate is a probability in 0..=1"));
        }
        match key.trim() {
            "add" => rates.add = p,
            "remove" => rates.remove = p,
            "moved" => rates.moved = p,
            "tarp" => rates.tarp = p,
            other => {
                return Err(format!(
                    "unknown change `{other}` (add, remove, moved, tarp)"
                ));
            }
        }
    }
    Ok(rates)
}

/// Flying every approach of a scenario set again over changed roofs.
#[derive(clap::Args)]
struct RevisitArgs {
    /// Fly every approach N more times, --revisit-interval-s apart, with the roofs changed
    /// before each visit; files become vKK-w<seed>-b<building>.mcap, listed in time order in
    /// visits.json with what changed on which roof. Per roof and visit (--change-rates): a new
    /// AC unit, seating or planter 0.2, one loose asset (vents, AC, seating, ducts, tarp,
    /// planter) removed 0.2, one movable asset (AC, seating, tarp, planter) moved 0.5 (only
    /// about one roof in four has one), a tarp laid down 0.15. Far more than a city changes in
    /// an hour, on purpose: the default 36-roof set over 2 revisits sees every kind of change
    /// on its target roofs (and hundreds on their neighbours), while about half the roofs stay
    /// as they were at each visit, so what a catalog keeps is tested as much as what it
    /// replaces. Seeded, per roof.
    #[arg(long, value_parser = clap::value_parser!(u32).range(0..=i64::from(Revisits::MAX)))]
    revisits: Option<u32>,
    /// Seconds between visits (the frames' timestamps move by this much per visit).
    #[arg(long, default_value_t = 3600.0, requires = "revisits")]
    revisit_interval_s: f64,
    /// Per-roof, per-visit change probabilities, e.g. add=0.2,remove=0.2,moved=0.5,tarp=0.15.
    #[arg(long, value_parser = parse_change_rates, requires = "revisits")]
    change_rates: Option<ChangeRates>,
    /// Where the worlds lie: frames carry the WGS-84 origin (default: manhattan with
    /// --revisits, none without, so that plain sets stay as they were).
    #[arg(long, value_enum)]
    origin: Option<OriginArg>,
}

impl RevisitArgs {
    fn revisits(&self) -> Option<Revisits> {
        self.revisits.map(|count| Revisits {
            count,
            interval_s: self.revisit_interval_s,
            rates: self.change_rates.unwrap_or_default(),
        })
    }

    fn origin(&self) -> Origin {
        match self.origin {
            Some(OriginArg::Manhattan) => Origin::Manhattan,
            Some(OriginArg::None) => Origin::None,
            None if self.revisits.is_some() => Origin::Manhattan,
            None => Origin::None,
        }
    }
}

impl ScenariosArgs {
    /// The set these arguments describe.
    fn config(&self) -> anyhow::Result<ScenarioConfig> {
        let record = RecordConfig {
            flight: self.approach.flight()?,
            width: self.width,
            height: self.height,
            lidar: self.lidar.config()?,
            pose_noise: self.approach.pose_noise(),
            ..Default::default()
        };
        let revisits = self.visits.revisits();
        if let Some(r) = &revisits {
            r.validate().context("--revisits")?;
        }
        Ok(ScenarioConfig {
            seed: self.seed,
            worlds: self.worlds,
            buildings: self.buildings,
            record,
            origin: self.visits.origin(),
            revisits,
        })
    }
}

#[derive(Subcommand)]
enum Command {
    /// Write an image/label dataset (PNG pairs + manifest.csv/manifest.json).
    Dataset(DatasetArgs),
    /// Simulate an approach flight and write it as an MCAP recording.
    Record(RecordArgs),
    /// Write one LiDAR scan of a roof with obstacles as a PLY file in world coordinates.
    Ply(PlyArgs),
    /// Write the `landing eval` scenario set: approach flights to many buildings of
    /// Manhattan-distribution worlds (seeds seed, seed+1, ...), one MCAP per building, buildings
    /// with a tarp or a water tower first.
    ///
    /// Each approach descends from 40 m to 10 m above the roof: --frames frames at 10 Hz (the
    /// default, 4), or with --rate-hz R frames at R Hz over --duration-s seconds (default 4:
    /// 41 frames at 10 Hz). --pose-noise realistic makes the frames carry an RTK GNSS + INS pose
    /// error; the ground truth and the scans keep the true poses.
    Scenarios(ScenariosArgs),
    /// Write the building footprints of scenario worlds (seeds seed, seed+1, ...) with roof
    /// heights as a GeoJSON FeatureCollection in WGS-84, each world on Manhattan as `scenarios`
    /// places it: the candidate roofs a city's open-data portal would publish.
    Footprints(FootprintsArgs),
    /// Render one view (image and colourised labels side by side) to a PNG.
    Preview(PreviewArgs),
}

#[derive(clap::Args)]
struct DatasetArgs {
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
}

#[derive(clap::Args)]
struct RecordArgs {
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
}

#[derive(clap::Args)]
struct PlyArgs {
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
}

#[derive(clap::Args)]
struct ScenariosArgs {
    #[arg(long, default_value_t = 2026)]
    seed: u64,
    /// Worlds to draw buildings from.
    #[arg(long, default_value_t = 6)]
    worlds: u64,
    /// Buildings per world.
    #[arg(long, default_value_t = 6)]
    buildings: usize,
    #[command(flatten)]
    approach: ApproachArgs,
    #[arg(long)]
    out: PathBuf,
    #[arg(long, default_value_t = 320)]
    width: u32,
    #[arg(long, default_value_t = 240)]
    height: u32,
    #[command(flatten)]
    lidar: LidarArgs,
    #[command(flatten)]
    visits: RevisitArgs,
}

#[derive(clap::Args)]
struct FootprintsArgs {
    #[arg(long, default_value_t = 2026)]
    seed: u64,
    /// Worlds, of seeds seed, seed+1, ...
    #[arg(long, default_value_t = 6)]
    worlds: u64,
    /// The GeoJSON file to write.
    #[arg(long)]
    out: PathBuf,
}

#[derive(clap::Args)]
struct PreviewArgs {
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
}

fn main() -> anyhow::Result<()> {
    match Cli::parse().command {
        Command::Dataset(args) => dataset_cmd(args),
        Command::Record(args) => record_cmd(args),
        Command::Ply(args) => ply_cmd(args),
        Command::Scenarios(args) => scenarios_cmd(args),
        Command::Footprints(args) => footprints_cmd(args),
        Command::Preview(args) => preview_cmd(args),
    }
}

/// `landing-sim dataset`: image/label pairs and their manifests.
fn dataset_cmd(args: DatasetArgs) -> anyhow::Result<()> {
    let split: Split = args.split.parse()?;
    let config = DatasetConfig {
        seed: args.seed,
        images: args.images,
        split,
        width: args.width,
        height: args.height,
        camera: CameraConfig {
            hfov_deg: args.hfov,
            ..Default::default()
        },
        images_per_world: args.images_per_world,
        jobs: args.jobs,
        ..Default::default()
    };
    let out = args.out;
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
    Ok(())
}

/// `landing-sim record`: one approach flight as an MCAP recording.
fn record_cmd(args: RecordArgs) -> anyhow::Result<()> {
    let config = RecordConfig {
        seed: args.seed,
        world: WorldConfig {
            assets: args.assets.distribution(),
            ..Default::default()
        },
        flight: FlightConfig {
            frames: args.frames,
            altitude_m: (args.start_altitude, args.end_altitude),
            ..Default::default()
        },
        width: args.width,
        height: args.height,
        camera: CameraConfig {
            hfov_deg: args.hfov,
            ..Default::default()
        },
        lidar: args.lidar.config()?,
        building: args.building,
        drone_id: args.drone_id,
        ..Default::default()
    };
    let out = args.out;
    let start = Instant::now();
    let n = write_recording(&config, &out).with_context(|| format!("writing {}", out.display()))?;
    let size = std::fs::metadata(&out).map(|m| m.len()).unwrap_or(0);
    println!(
        "wrote {n} frames to {} ({:.2} MB) in {:.1} s",
        out.display(),
        size as f64 / 1e6,
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

/// `landing-sim ply`: one LiDAR scan of a roof, in world coordinates.
fn ply_cmd(args: PlyArgs) -> anyhow::Result<()> {
    let seed = args.seed;
    let world = World::generate(seed, &WorldConfig::default())?;
    let b = args.building.unwrap_or_else(|| busiest_roof(&world));
    anyhow::ensure!(
        b < world.buildings.len(),
        "--building {b}: the world has {} buildings",
        world.buildings.len()
    );
    let view = ViewConfig {
        altitude_range_m: (args.altitude, args.altitude),
        pitch_range_deg: (70.0, 70.0),
        target_jitter: 0.0,
    };
    let mut rng = rand::rngs::SmallRng::seed_from_u64(seed);
    let v = view_of(&world, b, &view, &mut rng);
    let points = scan(&world, &lidar_pose(&v.camera), &args.lidar.config()?, seed)?;
    write_recording_ply(&points, &args.out)?;
    let roof = points.iter().filter(|p| p.building as usize == b).count();
    println!(
        "wrote {} points ({roof} on building {b}, {} assets on it) to {}",
        points.len(),
        world.buildings[b].assets.len(),
        args.out.display()
    );
    Ok(())
}

/// `landing-sim scenarios`: the `landing eval` scenario set, one MCAP per approached building
/// (and visit).
fn scenarios_cmd(args: ScenariosArgs) -> anyhow::Result<()> {
    let config = args.config()?;
    let out = &args.out;
    let start = Instant::now();
    let set =
        write_scenarios(&config, out).with_context(|| format!("writing {}", out.display()))?;
    let visits = match config.revisits {
        Some(r) => format!(
            " ({} visits, {} roof changes; {MANIFEST})",
            r.count + 1,
            set.changes
        ),
        None => String::new(),
    };
    println!(
        "wrote {} frames of {} approaches to {}{visits} in {:.1} s",
        set.frames,
        set.files,
        out.display(),
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

/// `landing-sim footprints`: the scenario worlds' building footprints as GeoJSON.
fn footprints_cmd(args: FootprintsArgs) -> anyhow::Result<()> {
    let worlds = (args.seed..args.seed + args.worlds)
        .map(|seed| {
            Ok((
                World::generate(seed, &WorldConfig::default())?,
                scenario_origin(seed),
            ))
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let placed: Vec<(&World, _)> = worlds.iter().map(|(w, g)| (w, *g)).collect();
    write_footprints(&placed, &args.out)
        .with_context(|| format!("writing {}", args.out.display()))?;
    let n: usize = worlds.iter().map(|(w, _)| w.buildings.len()).sum();
    println!(
        "wrote {n} building footprints of {} worlds to {}",
        worlds.len(),
        args.out.display()
    );
    Ok(())
}

/// `landing-sim preview`: one rendered view beside its colourised labels.
fn preview_cmd(args: PreviewArgs) -> anyhow::Result<()> {
    let (seed, width, height) = (args.seed, args.width, args.height);
    let world = World::generate(
        seed,
        &WorldConfig {
            assets: args.assets.distribution(),
            ..Default::default()
        },
    )?;
    let mut rng = rand::rngs::SmallRng::seed_from_u64(seed);
    let view = random_view(&world, &ViewConfig::default(), &mut rng);
    let intr = Intrinsics::from_hfov(width, height, args.hfov)?;
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
        .save(&args.out)
        .with_context(|| format!("writing {}", args.out.display()))?;
    println!(
        "wrote {} (building {}, {:.1} m above the roof, pitch {:.1}°, rendered in {ms:.1} ms)",
        args.out.display(),
        view.building,
        view.altitude_m,
        view.pitch_deg
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scenarios_args(extra: &[&str]) -> Result<ScenariosArgs, clap::Error> {
        let args = ["landing-sim", "scenarios", "--out", "x"]
            .iter()
            .chain(extra);
        match Cli::try_parse_from(args)?.command {
            Command::Scenarios(args) => Ok(args),
            _ => unreachable!("parsed another subcommand"),
        }
    }

    fn scenarios(extra: &[&str]) -> Result<LidarArgs, clap::Error> {
        Ok(scenarios_args(extra)?.lidar)
    }

    fn approach(extra: &[&str]) -> Result<ApproachArgs, clap::Error> {
        let args = ["landing-sim", "scenarios", "--out", "x"]
            .iter()
            .chain(extra);
        match Cli::try_parse_from(args)?.command {
            Command::Scenarios(args) => Ok(args.approach),
            _ => unreachable!("parsed another subcommand"),
        }
    }

    /// Frame `i` of the scenario of building `b` of world `world` as the CLI would write it.
    fn scenario_frames(
        extra: &[&str],
        world: u64,
        b: usize,
        size: (u32, u32),
    ) -> Vec<landing_proto::v1::Frame> {
        let mut args = vec!["--width".to_string(), size.0.to_string()];
        args.extend(["--height".to_string(), size.1.to_string()]);
        args.extend(extra.iter().map(|s| s.to_string()));
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let set = scenarios_args(&args).unwrap().config().unwrap();
        let config = set.record_config(world, b, landing_sim::recording::Visit::FIRST);
        let (w, frames) = landing_sim::recording::simulate(&config).unwrap();
        frames
            .iter()
            .map(|f| {
                landing_sim::recording::frame_messages(&w, f, &config)
                    .unwrap()
                    .0
            })
            .collect()
    }

    fn poses(f: &landing_proto::v1::Frame) -> [f64; 14] {
        let p = |pose: &Option<landing_proto::v1::Pose>| {
            let pose = pose.unwrap();
            let (t, q) = (pose.position.unwrap(), pose.orientation.unwrap());
            [t.x, t.y, t.z, q.x, q.y, q.z, q.w]
        };
        let (c, l) = (
            p(&f.image.as_ref().unwrap().pose),
            p(&f.point_cloud.as_ref().unwrap().pose),
        );
        std::array::from_fn(|i| if i < 7 { c[i] } else { l[i - 7] })
    }

    fn assert_close(got: [f64; 14], want: [f64; 14]) {
        for (g, w) in got.iter().zip(want) {
            assert!((g - w).abs() < 1e-12, "{got:?} != {want:?}");
        }
    }

    /// Frames 0 and 3 of `scenarios --seed 2026` building 29, as written before `--rate-hz`
    /// and `--pose-noise` existed (camera position, quaternion xyzw, then the LiDAR's).
    const BEFORE_FIRST: [f64; 14] = [
        69.93958004119037,
        57.85696681808146,
        58.0,
        -0.4401189548472991,
        0.8302514842766678,
        -0.30218682723204104,
        0.16019019910076762,
        69.9712802459404,
        57.835468975378305,
        58.032139380484324,
        0.12406795064904763,
        0.4039967063955791,
        -0.2660645787803211,
        0.8663737327283878,
    ];
    const BEFORE_LAST: [f64; 14] = [
        96.99417532994353,
        39.509595294731064,
        28.0,
        -0.4679190294768078,
        0.8826942454210036,
        -0.03853926305499857,
        0.02042978603179327,
        97.03539953851794,
        39.481638644025395,
        28.004357787137383,
        0.19833286946049528,
        0.6458221129055098,
        -0.21644234648370053,
        0.7047911619923016,
    ];

    #[test]
    fn without_rate_hz_the_scenarios_are_todays() {
        let a = approach(&[]).unwrap();
        assert_eq!(
            a.flight().unwrap(),
            FlightConfig {
                frames: 4,
                ..Default::default()
            }
        );
        assert_eq!(a.pose_noise(), PoseNoise::NONE);
        let frames = scenario_frames(&[], 2026, 29, (320, 240));
        assert_eq!(frames.len(), 4);
        assert_close(poses(&frames[0]), BEFORE_FIRST);
        assert_close(poses(&frames[3]), BEFORE_LAST);
        let ts = frames[3].timestamp.unwrap();
        assert_eq!((ts.seconds, ts.nanos), (1_767_225_600, 300_000_000));
        let points = frames[0].point_cloud.as_ref().unwrap().data.len();
        assert_eq!(points, 1630 * 17);
    }

    #[test]
    fn rate_hz_samples_the_same_descent_at_the_sensor_rate() {
        let ten = approach(&["--rate-hz", "10"]).unwrap().flight().unwrap();
        assert_eq!((ten.frames, ten.rate_hz), (41, 10.0));
        let twenty = approach(&["--rate-hz", "20", "--duration-s", "2.5"]).unwrap();
        let twenty = twenty.flight().unwrap();
        assert_eq!((twenty.frames, twenty.rate_hz), (51, 20.0));
        assert_eq!(
            (ten.altitude_m, ten.pitch_deg),
            (
                FlightConfig::default().altitude_m,
                FlightConfig::default().pitch_deg
            )
        );

        // The first and last frames are today's, 4 s apart.
        let frames = scenario_frames(&["--rate-hz", "10"], 2026, 29, (64, 48));
        assert_eq!(frames.len(), 41);
        assert_close(poses(&frames[0]), BEFORE_FIRST);
        assert_close(poses(&frames[40]), BEFORE_LAST);
        let ts = frames[40].timestamp.unwrap();
        assert_eq!((ts.seconds, ts.nanos), (1_767_225_604, 0));
        let ts = frames[1].timestamp.unwrap();
        assert_eq!((ts.seconds, ts.nanos), (1_767_225_600, 100_000_000));

        let both = approach(&["--frames", "4", "--rate-hz", "10"])
            .err()
            .unwrap();
        assert_eq!(both.kind(), clap::error::ErrorKind::ArgumentConflict);
        let alone = approach(&["--duration-s", "2"]).err().unwrap();
        assert_eq!(
            alone.kind(),
            clap::error::ErrorKind::MissingRequiredArgument
        );
        for (flags, name) in [
            (["--rate-hz", "0", "--duration-s", "4"], "--rate-hz"),
            (
                ["--rate-hz", "10", "--duration-s=-1", "--pose-noise=none"],
                "--duration-s",
            ),
            (["--rate-hz", "1000", "--duration-s", "600"], "at most"),
        ] {
            let err = approach(&flags).unwrap().flight().unwrap_err().to_string();
            assert!(err.contains(name), "{err}");
        }
    }

    #[test]
    fn pose_noise_flag_picks_the_model() {
        let a = approach(&["--pose-noise", "realistic"]).unwrap();
        assert_eq!(a.pose_noise(), PoseNoise::REALISTIC);
        assert!(approach(&["--pose-noise", "wild"]).is_err());
        // The frames carry the error; the first pose is off by centimetres, not metres.
        let noisy = scenario_frames(&["--pose-noise", "realistic"], 2026, 29, (64, 48));
        let (got, want) = (poses(&noisy[0]), BEFORE_FIRST);
        let d = ((got[0] - want[0]).powi(2) + (got[1] - want[1]).powi(2)).sqrt();
        assert!(d > 1e-4 && d < 0.2, "{d}");
    }

    #[test]
    fn revisit_flags_set_the_visits_the_rates_and_the_origin() {
        let plain = scenarios_args(&[]).unwrap().config().unwrap();
        assert_eq!((plain.revisits, plain.origin), (None, Origin::None));
        let placed = scenarios_args(&["--origin", "manhattan"]).unwrap();
        assert_eq!(placed.config().unwrap().origin, Origin::Manhattan);

        let set = scenarios_args(&["--revisits", "3"])
            .unwrap()
            .config()
            .unwrap();
        let want = Revisits {
            count: 3,
            interval_s: 3600.0,
            rates: ChangeRates::default(),
        };
        assert_eq!((set.revisits, set.origin), (Some(want), Origin::Manhattan));
        let flags = [
            "--revisits",
            "1",
            "--revisit-interval-s",
            "60",
            "--change-rates",
            "tarp=1,moved=0",
            "--origin",
            "none",
        ];
        let set = scenarios_args(&flags).unwrap().config().unwrap();
        let r = set.revisits.unwrap();
        assert_eq!(
            (r.interval_s, r.rates.tarp, r.rates.moved),
            (60.0, 1.0, 0.0)
        );
        assert_eq!(
            (r.rates.add, set.origin),
            (ChangeRates::default().add, Origin::None)
        );

        for (flags, name) in [
            (vec!["--revisit-interval-s", "60"], "--revisits"),
            (vec!["--revisits", "100"], "--revisits"),
            (
                vec!["--revisits", "1", "--change-rates", "tarp=2"],
                "probability",
            ),
            (
                vec!["--revisits", "1", "--change-rates", "paint=0.1"],
                "paint",
            ),
        ] {
            let err = scenarios_args(&flags).err().unwrap().to_string();
            assert!(err.contains(name), "{err}");
        }
        let bad = scenarios_args(&["--revisits", "1", "--revisit-interval-s", "0"]).unwrap();
        let err = format!("{:#}", bad.config().unwrap_err());
        assert!(err.contains("revisit_interval_s"), "{err}");
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
