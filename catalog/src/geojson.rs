//! GeoJSON (RFC 7946) in and out: candidate roofs from building footprints, search results for
//! GIS tools, and the polygon encoding both stores keep.
//!
//! # Reading candidates
//!
//! [`read_candidates`] takes a `FeatureCollection` (or a single `Feature`) whose features are
//! building footprints: `Polygon` or `MultiPolygon` geometries (each part of a multipolygon becomes
//! its own candidate) in WGS-84 longitude, latitude order. The roof height is the first of these
//! properties that is present, as a number or a numeric string (an `m` suffix is allowed, as
//! OpenStreetMap writes it):
//!
//! | property | meaning |
//! |---|---|
//! | `roof_height_m`, `roof_height` | the roof's height |
//! | `height_m`, `height`, `building:height`, `HEIGHT` | the building's height |
//!
//! When a ground elevation is also given (`ground_elevation_m`, `ground_elevation`,
//! `base_elevation`), it is added, so the result is the roof's altitude like the fleet's plane
//! heights; without one the height is taken as it is. A feature with no height, or a geometry of
//! another type, is refused naming it (`features[3].properties.height`), so a wrong file is not
//! half-imported. The feature's `id` (string or number), or else a property `id`, becomes the
//! candidate's `source_id`: importing the file again replaces rather than duplicates.
//!
//! # Writing results
//!
//! [`write_results`] gives a `FeatureCollection` with one `Polygon` feature per result, outer rings
//! counter-clockwise and holes clockwise, rings closed, and the record's fields as properties
//! (times as RFC 3339 UTC).

use serde_json::{Map, Value, json};

use crate::error::{Error, Result};
use crate::geo::{LatLon, Polygon, ring_orientation};
use crate::model::{Candidate, SiteKind};
use crate::query::Found;

/// The properties read as a roof height, in order of preference.
pub const HEIGHT_PROPERTIES: [&str; 6] = [
    "roof_height_m",
    "roof_height",
    "height_m",
    "height",
    "building:height",
    "HEIGHT",
];

/// The properties read as a ground elevation added to the height.
pub const GROUND_PROPERTIES: [&str; 3] =
    ["ground_elevation_m", "ground_elevation", "base_elevation"];

/// The candidates in a GeoJSON text (see the module docs). Every candidate is validated.
pub fn read_candidates(text: &str) -> Result<Vec<Candidate>> {
    let doc: Value = serde_json::from_str(text)
        .map_err(|e| Error::invalid("geojson", format!("not JSON: {e}")))?;
    let features: Vec<(String, &Value)> = match doc.get("type").and_then(Value::as_str) {
        Some("FeatureCollection") => doc
            .get("features")
            .and_then(Value::as_array)
            .ok_or_else(|| Error::invalid("features", "missing or not an array"))?
            .iter()
            .enumerate()
            .map(|(i, f)| (format!("features[{i}]"), f))
            .collect(),
        Some("Feature") => vec![("feature".to_string(), &doc)],
        other => {
            return Err(Error::invalid(
                "type",
                format!("{other:?}: expected a FeatureCollection of building footprints"),
            ));
        }
    };
    let mut out = Vec::new();
    for (field, f) in features {
        out.extend(feature_candidates(f, &field)?);
    }
    Ok(out)
}

/// The candidates of one feature (`field` names it): one per polygon of its footprint, at its
/// roof height above the ellipsoid, with its id (`id#i` for the parts of a multipolygon).
fn feature_candidates(f: &Value, field: &str) -> Result<Vec<Candidate>> {
    let props = f.get("properties").and_then(Value::as_object);
    let height = find_number(props, &HEIGHT_PROPERTIES, field)?.ok_or_else(|| {
        Error::invalid(
            format!("{field}.properties.height"),
            format!(
                "no roof height: expected one of {}",
                HEIGHT_PROPERTIES.join(", ")
            ),
        )
    })?;
    let ground = find_number(props, &GROUND_PROPERTIES, field)?.unwrap_or(0.0);
    let id = f
        .get("id")
        .or_else(|| props.and_then(|p| p.get("id")))
        .and_then(|v| match v {
            Value::String(s) => Some(s.clone()),
            Value::Number(n) => Some(n.to_string()),
            _ => None,
        });
    let polygons = footprints(f, field)?;
    let parts = polygons.len();
    let mut out = Vec::with_capacity(parts);
    for (i, footprint) in polygons.into_iter().enumerate() {
        let source_id = match (&id, parts) {
            (Some(id), 1) => Some(id.clone()),
            (Some(id), _) => Some(format!("{id}#{i}")),
            (None, _) => None,
        };
        let c = Candidate {
            footprint,
            roof_height_m: ground + height,
            source_id,
        };
        c.validate(field)?;
        out.push(c);
    }
    Ok(out)
}

/// The polygons of a feature's `Polygon` or `MultiPolygon` geometry.
fn footprints(f: &Value, field: &str) -> Result<Vec<Polygon>> {
    let geometry = f
        .get("geometry")
        .ok_or_else(|| Error::invalid(format!("{field}.geometry"), "missing"))?;
    let gfield = format!("{field}.geometry");
    match geometry.get("type").and_then(Value::as_str) {
        Some("Polygon") => Ok(vec![polygon_from_coordinates(
            geometry.get("coordinates").unwrap_or(&Value::Null),
            &format!("{gfield}.coordinates"),
        )?]),
        Some("MultiPolygon") => geometry
            .get("coordinates")
            .and_then(Value::as_array)
            .ok_or_else(|| Error::invalid(format!("{gfield}.coordinates"), "not an array"))?
            .iter()
            .enumerate()
            .map(|(i, c)| polygon_from_coordinates(c, &format!("{gfield}.coordinates[{i}]")))
            .collect(),
        other => Err(Error::invalid(
            format!("{gfield}.type"),
            format!("{other:?}: a footprint is a Polygon or MultiPolygon"),
        )),
    }
}

/// Search results as a GeoJSON `FeatureCollection` (see the module docs).
pub fn write_results(results: &[Found]) -> Value {
    let features: Vec<Value> = results
        .iter()
        .map(|f| {
            let s = &f.site;
            let mut p = Map::new();
            p.insert("id".into(), json!(s.id.0));
            let kind = match s.kind {
                SiteKind::Confirmed => "site",
                SiteKind::Candidate => "candidate",
            };
            p.insert("kind".into(), json!(kind));
            p.insert("distance_m".into(), json!(f.distance_m));
            p.insert("center_latitude_deg".into(), json!(s.center.latitude_deg));
            p.insert("center_longitude_deg".into(), json!(s.center.longitude_deg));
            p.insert("safe_radius_m".into(), json!(s.safe_radius_m));
            p.insert("plane_height_m".into(), json!(s.plane_height_m));
            p.insert("area_m2".into(), json!(s.area_m2));
            if s.kind == SiteKind::Confirmed {
                p.insert("first_seen".into(), json!(s.first_seen.to_rfc3339()));
                p.insert(
                    "last_confirmed".into(),
                    json!(s.last_confirmed.to_rfc3339()),
                );
                p.insert("frames".into(), json!(s.frames));
                p.insert("approaches".into(), json!(s.approaches));
                p.insert("drone_id".into(), json!(s.drone_id));
                p.insert("model_id".into(), json!(s.model_id));
            }
            if let Some(src) = &s.source_id {
                p.insert("source_id".into(), json!(src));
            }
            json!({
                "type": "Feature",
                "id": s.id.0,
                "geometry": polygon_geometry(&s.polygon, true),
                "properties": Value::Object(p),
            })
        })
        .collect();
    json!({ "type": "FeatureCollection", "features": features })
}

/// A GeoJSON `Polygon` geometry with closed rings; `rfc7946_orientation` turns the outer ring
/// counter-clockwise and holes clockwise, else rings keep their order.
pub fn polygon_geometry(p: &Polygon, rfc7946_orientation: bool) -> Value {
    let ring = |r: &[LatLon], ccw: bool| -> Value {
        let mut pts: Vec<LatLon> = r.to_vec();
        if rfc7946_orientation && (ring_orientation(&pts) > 0.0) != ccw {
            pts.reverse();
        }
        if let Some(&first) = pts.first() {
            pts.push(first);
        }
        Value::Array(
            pts.iter()
                .map(|q| json!([q.longitude_deg, q.latitude_deg]))
                .collect(),
        )
    };
    let mut rings = vec![ring(&p.exterior, true)];
    rings.extend(p.holes.iter().map(|h| ring(h, false)));
    json!({ "type": "Polygon", "coordinates": rings })
}

/// The polygon of a GeoJSON `Polygon`'s `coordinates` (rings of `[lon, lat]`, closed or not).
/// Checks shape only; [`Polygon::validate`] checks values.
pub fn polygon_from_coordinates(c: &Value, field: &str) -> Result<Polygon> {
    let rings = c
        .as_array()
        .filter(|r| !r.is_empty())
        .ok_or_else(|| Error::invalid(field, "expected an array of rings"))?;
    let mut parsed = Vec::with_capacity(rings.len());
    for (i, r) in rings.iter().enumerate() {
        let pts = r.as_array().ok_or_else(|| {
            Error::invalid(format!("{field}[{i}]"), "expected an array of positions")
        })?;
        let mut ring = Vec::with_capacity(pts.len());
        for (j, pt) in pts.iter().enumerate() {
            let xy = pt
                .as_array()
                .filter(|a| a.len() >= 2)
                .and_then(|a| Some((a[0].as_f64()?, a[1].as_f64()?)));
            let (lon, lat) = xy.ok_or_else(|| {
                Error::invalid(
                    format!("{field}[{i}][{j}]"),
                    "expected [longitude, latitude]",
                )
            })?;
            ring.push(LatLon::new(lat, lon));
        }
        parsed.push(ring);
    }
    let exterior = parsed.remove(0);
    Ok(Polygon::new(exterior, parsed))
}

fn find_number(
    props: Option<&Map<String, Value>>,
    names: &[&str],
    field: &str,
) -> Result<Option<f64>> {
    let Some(props) = props else { return Ok(None) };
    for name in names {
        let Some(v) = props.get(*name) else { continue };
        let parsed = match v {
            Value::Number(n) => n.as_f64(),
            Value::String(s) => s.trim().trim_end_matches('m').trim().parse::<f64>().ok(),
            Value::Null => continue,
            _ => None,
        };
        return match parsed {
            Some(x) if x.is_finite() => Ok(Some(x)),
            _ => Err(Error::invalid(
                format!("{field}.properties.{name}"),
                format!("{v} is not a height in metres"),
            )),
        };
    }
    Ok(None)
}

/// A polygon as a store keeps it (the GeoJSON geometry [`polygon_geometry`] wrote); what cannot be
/// read back is [`Error::Corrupt`] in `backend`.
pub(crate) fn stored_polygon(text: &str, backend: &'static str) -> Result<Polygon> {
    let corrupt = |e: &dyn std::fmt::Display| Error::Corrupt {
        backend,
        what: format!("a stored polygon: {e}"),
    };
    let v: serde_json::Value = serde_json::from_str(text).map_err(|e| corrupt(&e))?;
    polygon_from_coordinates(&v["coordinates"], "polygon").map_err(|e| corrupt(&e))
}

/// A count as the stores keep it (a signed 64-bit column), saturating.
pub(crate) fn stored_count(n: u64) -> i64 {
    i64::try_from(n).unwrap_or(i64::MAX)
}

#[cfg(test)]
mod tests {
    use super::*;

    const FOOTPRINTS: &str = r#"{
      "type": "FeatureCollection",
      "features": [
        {"type": "Feature", "id": "bldg-1",
         "properties": {"height": 42.5, "ground_elevation_m": 10},
         "geometry": {"type": "Polygon", "coordinates": [[[-73.9860, 40.7480], [-73.9855, 40.7480],
           [-73.9855, 40.7484], [-73.9860, 40.7484], [-73.9860, 40.7480]]]}},
        {"type": "Feature", "properties": {"building:height": "30 m", "id": 7},
         "geometry": {"type": "MultiPolygon", "coordinates": [
           [[[-73.9870, 40.7480], [-73.9868, 40.7480], [-73.9868, 40.7482]]],
           [[[-73.9880, 40.7480], [-73.9878, 40.7480], [-73.9878, 40.7482]]]]}}
      ]}"#;

    #[test]
    fn reads_polygons_multipolygons_and_heights() {
        let c = read_candidates(FOOTPRINTS).unwrap();
        assert_eq!(c.len(), 3);
        assert_eq!(c[0].roof_height_m, 52.5);
        assert_eq!(c[0].source_id.as_deref(), Some("bldg-1"));
        assert_eq!(
            c[0].footprint.exterior.len(),
            4,
            "the closing point is dropped"
        );
        assert_eq!(c[1].roof_height_m, 30.0);
        assert_eq!(c[2].source_id.as_deref(), Some("7#1"));
    }

    #[test]
    fn refuses_missing_heights_and_wrong_geometry_by_name() {
        let no_height = FOOTPRINTS.replace("\"height\": 42.5", "\"name\": \"x\"");
        let e = read_candidates(&no_height).unwrap_err();
        assert_eq!(e.field(), Some("features[0].properties.height"));
        let point = FOOTPRINTS.replace(
            "\"Polygon\", \"coordinates\": [[[-73.9860",
            "\"Point\", \"coordinates\": [[[-73.9860",
        );
        let e = read_candidates(&point).unwrap_err();
        assert_eq!(e.field(), Some("features[0].geometry.type"));
        let bad = FOOTPRINTS.replace("\"30 m\"", "\"tall\"");
        assert_eq!(
            read_candidates(&bad).unwrap_err().field(),
            Some("features[1].properties.building:height")
        );
    }

    #[test]
    fn written_rings_are_closed_and_counter_clockwise() {
        let cw = Polygon::new(
            vec![
                LatLon::new(0.0, 0.0),
                LatLon::new(0.001, 0.0),
                LatLon::new(0.001, 0.001),
                LatLon::new(0.0, 0.001),
            ],
            vec![],
        );
        assert!(ring_orientation(&cw.exterior) < 0.0);
        let g = polygon_geometry(&cw, true);
        let ring = g["coordinates"][0].as_array().unwrap();
        assert_eq!(ring.first(), ring.last());
        let back = polygon_from_coordinates(&g["coordinates"], "c").unwrap();
        assert!(ring_orientation(&back.exterior) > 0.0);
    }
}
