//! `landing-sim`: a procedural rooftop city and the drone's sensors, standing in for the paper's
//! Unreal/AirSim testbed.
//!
//! A [`World`] is a grid of blocks of flat-roofed buildings with parapets and rooftop assets drawn
//! from the paper's Table III ([`assets`]: per-asset count histograms, a kernel density estimate
//! of them, or equal probabilities for training worlds), generated from a seed. Sensors:
//! [`camera::render`] ray-casts an RGB image with a class label per pixel, [`lidar::scan`] the
//! 16-beam 40°×60° LiDAR with each point's true class; both go through one bounding-volume
//! hierarchy over analytic boxes, cylinders, cones and spheres ([`scene`]). [`flight`] makes the
//! poses (T_world_sensor, camera in the optical convention), [`truth`] the per-frame ground truth
//! (roofs in view, obstacle footprints, true best landing point from
//! `landing_geometry::polylabel::polylabel`), [`noise`] the error of the poses a drone believes
//! (RTK GNSS + INS: [`noise::PoseNoise`]; frames carry it, the ground truth does not),
//! [`recording`] the MCAP recordings of flights (the format, its writer and its reader are
//! `landing_recording`'s), and [`dataset`] the image/label datasets (its module docs give the
//! manifest format).
//!
//! Classes are [`landing_geometry::SemanticClass`] ids everywhere.
//!
//! Command line (binary `landing-sim`):
//!
//! ```text
//! landing-sim dataset --seed 1 --images 2000 --split train --out DIR [--width 256 --height 192]
//! landing-sim record  --seed 1 --frames 15 --out F.mcap [--width 320 --height 240]
//! landing-sim preview --seed 1 --out F.png
//! landing-sim ply     --seed 1 --out samples/roof.ply
//! landing-sim scenarios --seed 2026 --out DIR            # 4 frames per approach, 40 m to 10 m
//! landing-sim scenarios --seed 9100 --rate-hz 10 --duration-s 4 --pose-noise realistic --out DIR
//! landing-sim scenarios --seed 2026 --revisits 2 --out DIR  # 3 visits an hour apart, visits.json
//! landing-sim footprints --seed 2026 --worlds 6 --out footprints.geojson
//! ```
//!
//! `scenarios` writes the `landing eval` set ([`scenarios`]): one approach per building,
//! `--frames` frames (default 4) at 10 Hz, or with `--rate-hz R` round(D·R)+1 frames at R Hz
//! over the same descent lasting `--duration-s D` (default 4 s); `--pose-noise realistic` makes
//! the frames carry an RTK-GNSS/INS pose error ([`noise::PoseNoise::REALISTIC`]). With
//! `--revisits N` every approach is flown N more times over roofs changed in between
//! ([`revisit`]), every frame carries its world's WGS-84 origin on Manhattan ([`geodetic`]),
//! and the set gets `visits.json` and its worlds' building footprints as GeoJSON
//! ([`footprints`]); `--origin manhattan` adds the origin to a set without revisits.
//!
//! Reading a recording from another crate:
//!
//! ```no_run
//! let pairs = landing_sim::recording::read_pairs("samples/rooftops.mcap".as_ref()).unwrap();
//! for (frame, truth) in &pairs {
//!     println!("frame {}: best radius {:.2} m", frame.sequence, truth.roofs[0].best_safe_radius_m);
//! }
//! ```
//!
//! ```
//! use landing_sim::{World, WorldConfig};
//! use landing_sim::camera::{render, CameraConfig, Intrinsics};
//! use landing_sim::flight::{view_of, ViewConfig};
//! use rand::SeedableRng;
//!
//! let world = World::generate(42, &WorldConfig::default()).unwrap();
//! let mut rng = rand::rngs::SmallRng::seed_from_u64(1);
//! let view = view_of(&world, 0, &ViewConfig::default(), &mut rng);
//! let intrinsics = Intrinsics::from_hfov(64, 48, 70.0).unwrap();
//! let img = render(&world, &intrinsics, &view.camera, &CameraConfig::default(), 7);
//! // Looking at a roof from 10-40 m up, the rooftop class is in view.
//! let rooftop = landing_geometry::SemanticClass::BuildingRooftop as u8;
//! assert!(img.labels.iter().any(|&l| l == rooftop));
//! ```

#![forbid(unsafe_code)]

pub mod assets;
pub mod camera;
pub mod dataset;
pub mod flight;
pub mod footprints;
pub mod geodetic;
pub mod lidar;
pub mod math;
pub mod noise;
pub mod recording;
pub mod revisit;
pub mod scenarios;
pub mod scene;
pub mod truth;
pub mod world;

use std::path::Path;

pub use assets::{AssetDistribution, AssetKind};
pub use world::{Asset, AssetSource, Building, World, WorldConfig};

/// Everything that can go wrong in this crate.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SimError {
    /// A configuration value is out of range.
    #[error("`{field}` = {value} is invalid: {reason}")]
    InvalidConfig {
        field: &'static str,
        value: String,
        reason: &'static str,
    },
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    /// Encoding or decoding an image failed.
    #[error("image codec: {0}")]
    Image(String),
    /// Writing or reading a recording failed.
    #[error(transparent)]
    Recording(#[from] landing_recording::Error),
    /// A geometry routine (polylabel) failed.
    #[error("geometry: {0}")]
    Geometry(String),
}

impl SimError {
    pub(crate) fn invalid(
        field: &'static str,
        value: impl std::fmt::Display,
        reason: &'static str,
    ) -> Self {
        SimError::InvalidConfig {
            field,
            value: value.to_string(),
            reason,
        }
    }

    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        SimError::Io {
            path: path.display().to_string(),
            source,
        }
    }
}
