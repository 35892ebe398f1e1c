//! Image/label datasets for training and testing the segmentation model.
//!
//! `write_dataset` fills a directory with
//!
//! - `images/NNNNNN.png`: RGB8 renders,
//! - `labels/NNNNNN.png`: 8-bit grayscale, pixel value = [`landing_geometry::SemanticClass`] id,
//! - `manifest.csv`: one row per image, header
//!   `index,image,label,split,world_seed,building,altitude_m,pitch_deg,yaw_deg,width,height,fx,fy,cx,cy,rooftop_fraction`
//!   (paths relative to the directory),
//! - `manifest.json`: `{"split", "seed", "images", "width", "height", "classes": [names by id],
//!   "class_pixel_counts": [...], "asset_distribution", "files": "manifest.csv"}`.
//!
//! The train split is drawn from training worlds (equal probability per asset), the test split
//! from Manhattan worlds (Table III histograms); the world seeds of the two splits come from
//! different streams, so the splits never share a world. Every image is a pure function of
//! (seed, split, index), whatever the number of worker threads.

use std::io::Write;
use std::path::{Path, PathBuf};

use landing_geometry::SemanticClass;
use rand::SeedableRng;
use rand::rngs::SmallRng;

use crate::SimError;
use crate::assets::AssetDistribution;
use crate::camera::{CameraConfig, Intrinsics, Rendered, render};
use crate::flight::{ViewConfig, random_view};
use crate::world::{World, WorldConfig};

/// Which half of the data.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Split {
    /// Training worlds: equal asset probabilities.
    Train,
    /// Test worlds: Manhattan histograms.
    Test,
}

impl Split {
    pub fn name(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Test => "test",
        }
    }

    /// The asset distribution of this split's worlds.
    pub fn assets(self) -> AssetDistribution {
        match self {
            Split::Train => AssetDistribution::TRAINING,
            Split::Test => AssetDistribution::ManhattanHistogram,
        }
    }

    fn stream(self) -> u64 {
        match self {
            Split::Train => 0x7472_6169_6e00_0000,
            Split::Test => 0x7465_7374_0000_0000,
        }
    }
}

impl std::str::FromStr for Split {
    type Err = SimError;
    fn from_str(s: &str) -> Result<Self, SimError> {
        match s {
            "train" => Ok(Split::Train),
            "test" => Ok(Split::Test),
            other => Err(SimError::invalid(
                "split",
                other,
                "must be `train` or `test`",
            )),
        }
    }
}

/// What to write.
#[derive(Debug, Clone, PartialEq)]
pub struct DatasetConfig {
    pub seed: u64,
    pub images: u32,
    pub split: Split,
    pub width: u32,
    pub height: u32,
    pub camera: CameraConfig,
    pub view: ViewConfig,
    /// Consecutive images taken in one world before a new one is generated.
    pub images_per_world: u32,
    /// Worker threads (0: one per available core).
    pub jobs: usize,
}

impl Default for DatasetConfig {
    fn default() -> Self {
        Self {
            seed: 1,
            images: 100,
            split: Split::Train,
            width: 256,
            height: 192,
            camera: CameraConfig::default(),
            view: ViewConfig::default(),
            images_per_world: 20,
            jobs: 0,
        }
    }
}

/// What was written.
#[derive(Debug, Clone, PartialEq)]
pub struct DatasetSummary {
    pub dir: PathBuf,
    pub images: u32,
    /// Pixels per class id over the whole dataset.
    pub class_pixel_counts: [u64; SemanticClass::COUNT],
}

/// The seed of world `index` of a split.
pub fn world_seed(seed: u64, split: Split, index: u32) -> u64 {
    let mut z =
        seed ^ split.stream() ^ (u64::from(index) << 20).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

struct Row {
    index: u32,
    world_seed: u64,
    building: usize,
    altitude_m: f64,
    pitch_deg: f64,
    yaw_deg: f64,
    rooftop_fraction: f64,
    counts: [u64; SemanticClass::COUNT],
}

/// Renders and writes a dataset into `dir` (created if missing).
pub fn write_dataset(config: &DatasetConfig, dir: &Path) -> Result<DatasetSummary, SimError> {
    config.view.validate()?;
    let intr = Intrinsics::from_hfov(config.width, config.height, config.camera.hfov_deg)?;
    if config.images_per_world == 0 {
        return Err(SimError::invalid(
            "images_per_world",
            0,
            "must be at least 1",
        ));
    }
    for sub in ["images", "labels"] {
        let p = dir.join(sub);
        std::fs::create_dir_all(&p).map_err(|e| SimError::io(&p, e))?;
    }
    let rows = render_worlds(config, &intr, dir)?;
    let mut totals = [0u64; SemanticClass::COUNT];
    for r in &rows {
        for (t, c) in totals.iter_mut().zip(r.counts) {
            *t += c;
        }
    }
    write_file(
        &dir.join("manifest.csv"),
        manifest_csv(config, &intr, &rows).as_bytes(),
    )?;
    write_file(
        &dir.join("manifest.json"),
        manifest_json(config, &intr, rows.len(), &totals).as_bytes(),
    )?;
    Ok(DatasetSummary {
        dir: dir.to_path_buf(),
        images: rows.len() as u32,
        class_pixel_counts: totals,
    })
}

/// Renders the images of every world into `dir` on [`DatasetConfig::jobs`] threads, world `wi`
/// on thread `wi % jobs`; the rows in image order.
fn render_worlds(
    config: &DatasetConfig,
    intr: &Intrinsics,
    dir: &Path,
) -> Result<Vec<Row>, SimError> {
    let worlds = config.images.div_ceil(config.images_per_world);
    let jobs = if config.jobs == 0 {
        std::thread::available_parallelism().map_or(1, |n| n.get())
    } else {
        config.jobs
    }
    .clamp(1, 64)
    .min(worlds.max(1) as usize);

    let results: Vec<Result<Vec<Row>, SimError>> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..jobs)
            .map(|job| {
                scope.spawn(move || {
                    let mut rows = Vec::new();
                    let mut wi = job as u32;
                    while wi < worlds {
                        rows.extend(world_images(config, intr, dir, wi)?);
                        wi += jobs as u32;
                    }
                    Ok(rows)
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| {
                h.join().unwrap_or_else(|_| {
                    Err(SimError::invalid(
                        "jobs",
                        "worker",
                        "a worker thread panicked",
                    ))
                })
            })
            .collect()
    });
    let mut rows = Vec::new();
    for r in results {
        rows.extend(r?);
    }
    rows.sort_by_key(|r| r.index);
    Ok(rows)
}

/// `manifest.csv`: one line per image with its view and the camera intrinsics.
fn manifest_csv(config: &DatasetConfig, intr: &Intrinsics, rows: &[Row]) -> String {
    let mut csv = String::from(
        "index,image,label,split,world_seed,building,altitude_m,pitch_deg,yaw_deg,width,height,fx,fy,cx,cy,rooftop_fraction\n",
    );
    for r in rows {
        csv.push_str(&format!(
            "{i},images/{i:06}.png,labels/{i:06}.png,{},{},{},{:.3},{:.3},{:.3},{},{},{:.6},{:.6},{:.6},{:.6},{:.4}\n",
            config.split.name(),
            r.world_seed,
            r.building,
            r.altitude_m,
            r.pitch_deg,
            r.yaw_deg,
            intr.width,
            intr.height,
            intr.fx,
            intr.fy,
            intr.cx,
            intr.cy,
            r.rooftop_fraction,
            i = r.index,
        ));
    }
    csv
}

/// `manifest.json`: the split, the camera, the class names and the pixel count of each class.
fn manifest_json(
    config: &DatasetConfig,
    intr: &Intrinsics,
    images: usize,
    totals: &[u64; SemanticClass::COUNT],
) -> String {
    let names: Vec<String> = SemanticClass::ALL
        .iter()
        .map(|c| format!("\"{}\"", c.name()))
        .collect();
    let counts: Vec<String> = totals.iter().map(u64::to_string).collect();
    format!(
        "{{\n  \"split\": \"{}\",\n  \"seed\": {},\n  \"images\": {},\n  \"width\": {},\n  \"height\": {},\n  \"fx\": {:.6},\n  \"fy\": {:.6},\n  \"cx\": {:.6},\n  \"cy\": {:.6},\n  \"asset_distribution\": \"{}\",\n  \"classes\": [{}],\n  \"class_pixel_counts\": [{}],\n  \"files\": \"manifest.csv\"\n}}\n",
        config.split.name(),
        config.seed,
        images,
        intr.width,
        intr.height,
        intr.fx,
        intr.fy,
        intr.cx,
        intr.cy,
        match config.split {
            Split::Train => "uniform",
            Split::Test => "manhattan-histogram",
        },
        names.join(", "),
        counts.join(", "),
    )
}

fn world_images(
    config: &DatasetConfig,
    intr: &Intrinsics,
    dir: &Path,
    wi: u32,
) -> Result<Vec<Row>, SimError> {
    let ws = world_seed(config.seed, config.split, wi);
    let world = World::generate(
        ws,
        &WorldConfig {
            assets: config.split.assets(),
            ..Default::default()
        },
    )?;
    let mut rng = SmallRng::seed_from_u64(ws ^ 0x7669_6577);
    let first = wi * config.images_per_world;
    let last = (first + config.images_per_world).min(config.images);
    let mut rows = Vec::new();
    for index in first..last {
        let view = random_view(&world, &config.view, &mut rng);
        let img = render(
            &world,
            intr,
            &view.camera,
            &config.camera,
            ws.wrapping_add(u64::from(index)),
        );
        let mut counts = [0u64; SemanticClass::COUNT];
        for &l in &img.labels {
            counts[usize::from(l).min(SemanticClass::COUNT - 1)] += 1;
        }
        let roof = counts[SemanticClass::BuildingRooftop as usize] as f64 / img.labels.len() as f64;
        write_file(
            &dir.join(format!("images/{index:06}.png")),
            &encode_rgb_png(&img)?,
        )?;
        write_file(
            &dir.join(format!("labels/{index:06}.png")),
            &encode_label_png(&img)?,
        )?;
        rows.push(Row {
            index,
            world_seed: ws,
            building: view.building,
            altitude_m: view.altitude_m,
            pitch_deg: view.pitch_deg,
            yaw_deg: view.yaw_deg,
            rooftop_fraction: roof,
            counts,
        });
    }
    Ok(rows)
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<(), SimError> {
    let mut f = std::fs::File::create(path).map_err(|e| SimError::io(path, e))?;
    f.write_all(bytes).map_err(|e| SimError::io(path, e))
}

fn encode_png(
    data: &[u8],
    width: u32,
    height: u32,
    color: image::ExtendedColorType,
) -> Result<Vec<u8>, SimError> {
    use image::ImageEncoder;
    use image::codecs::png::{CompressionType, FilterType, PngEncoder};
    let mut out = Vec::new();
    PngEncoder::new_with_quality(&mut out, CompressionType::Fast, FilterType::Adaptive)
        .write_image(data, width, height, color)
        .map_err(|e| SimError::Image(e.to_string()))?;
    Ok(out)
}

/// The RGB image as PNG bytes.
pub fn encode_rgb_png(img: &Rendered) -> Result<Vec<u8>, SimError> {
    encode_png(
        &img.rgb,
        img.width,
        img.height,
        image::ExtendedColorType::Rgb8,
    )
}

/// The label image as 8-bit grayscale PNG bytes (value = class id).
pub fn encode_label_png(img: &Rendered) -> Result<Vec<u8>, SimError> {
    encode_png(
        &img.labels,
        img.width,
        img.height,
        image::ExtendedColorType::L8,
    )
}
