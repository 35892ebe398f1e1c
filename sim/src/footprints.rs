//! Building footprints with roof heights as GeoJSON, the shape a city's open-data portal
//! publishes: what a landing-site catalog imports as candidate roofs known beforehand.
//!
//! [`footprints`] gives an RFC 7946 `FeatureCollection` in WGS-84: one `Polygon` feature per
//! building of each world, the building's outline (walls' outer faces) as one closed,
//! counter-clockwise ring of `[longitude, latitude]` positions. Properties:
//!
//! | property | meaning |
//! |---|---|
//! | `roof_height_m` | roof surface above the building's ground, metres |
//! | `ground_elevation_m` | the ground's height above the WGS-84 ellipsoid (the world origin's altitude), metres |
//! | `parapet_height_m` | the parapet wall above the roof (0 when none), metres |
//! | `world`, `building` | the world's seed and the building's index in it |
//!
//! The feature `id` is `w<seed>-b<building>` (building with three digits, as the scenario files
//! name it), so importing the file again replaces rather than duplicates.
//!
//! ```
//! use landing_sim::footprints::footprints;
//! use landing_sim::geodetic::scenario_origin;
//! use landing_sim::{World, WorldConfig};
//!
//! let world = World::generate(2026, &WorldConfig::default()).unwrap();
//! let doc = footprints(&[(&world, scenario_origin(2026))]);
//! let first = &doc["features"][0];
//! assert_eq!(first["geometry"]["type"], "Polygon");
//! assert_eq!(first["properties"]["roof_height_m"], world.buildings[0].height_m);
//! ```

use std::path::Path;

use serde_json::{Value, json};

use crate::SimError;
use crate::geodetic::{Geodetic, enu_to_geodetic};
use crate::world::World;

/// The footprints of every building of each world placed at its origin (see the module docs).
pub fn footprints(worlds: &[(&World, Geodetic)]) -> Value {
    let features: Vec<Value> = worlds
        .iter()
        .flat_map(|&(world, origin)| world_features(world, origin))
        .collect();
    json!({ "type": "FeatureCollection", "features": features })
}

/// Writes [`footprints`] to `path`, pretty-printed.
pub fn write_footprints(worlds: &[(&World, Geodetic)], path: &Path) -> Result<(), SimError> {
    let text = serde_json::to_string_pretty(&footprints(worlds)).map_err(|e| SimError::Io {
        path: path.display().to_string(),
        source: e.into(),
    })?;
    std::fs::write(path, text + "\n").map_err(|e| SimError::io(path, e))
}

/// One feature per building of `world`.
fn world_features(world: &World, origin: Geodetic) -> Vec<Value> {
    world
        .buildings
        .iter()
        .enumerate()
        .map(|(bi, b)| {
            let mut ring: Vec<Value> = b
                .outline()
                .iter()
                .map(|p| {
                    let g = enu_to_geodetic(origin, [p[0], p[1], 0.0]);
                    json!([g.longitude_deg, g.latitude_deg])
                })
                .collect();
            ring.push(ring[0].clone());
            json!({
                "type": "Feature",
                "id": format!("w{}-b{bi:03}", world.seed),
                "geometry": { "type": "Polygon", "coordinates": [ring] },
                "properties": {
                    "world": world.seed,
                    "building": bi,
                    "roof_height_m": b.height_m,
                    "ground_elevation_m": origin.altitude_m,
                    "parapet_height_m": b.parapet_height_m,
                },
            })
        })
        .collect()
}
