//! The grid the embedded store orders by key within: a site's cell is the 1/400° × 1/400° square
//! (about 280 m × 210 m at New York's latitude) its safest point lies in.
//!
//! The store keeps, per order, an index by (kind, cell, key, id): the records of one cell in the
//! order's own order. A search by largest safe radius or freshest first reads the cells under
//! the search circle's box side by side, each from its best record on, and merges them, so it
//! reads about a page plus one record per cell instead of the whole circle.

use crate::geo::{Bbox, LatLon};

/// Cells per degree, in latitude and in longitude.
pub(crate) const CELLS_PER_DEGREE: f64 = 400.0;

/// A cell's number: its row (latitude) times this, plus its column (longitude). Columns run
/// from -72 000 to 72 000, less than half of it, so numbers are unique.
const ROW_STRIDE: i64 = 1 << 20;

/// The cell number as SQL over a row's `latitude_deg` and `longitude_deg`: the same floor and
/// the same numbering as [`cell_of`] (SQLite's `CAST` truncates toward zero; the comparison
/// takes one off below zero). A macro so that the migration that fills the column can `concat!`
/// it into its SQL.
macro_rules! cell_sql {
    () => {
        "((CAST(latitude_deg * 400.0 AS INTEGER) \
         - (latitude_deg * 400.0 < CAST(latitude_deg * 400.0 AS INTEGER))) * 1048576 \
         + CAST(longitude_deg * 400.0 AS INTEGER) \
         - (longitude_deg * 400.0 < CAST(longitude_deg * 400.0 AS INTEGER)))"
    };
}
pub(crate) use cell_sql;

/// The cell `p` lies in.
pub(crate) fn cell_of(p: LatLon) -> i64 {
    row(p.latitude_deg) * ROW_STRIDE + row(p.longitude_deg)
}

/// The cells that meet `b`, when there are at most `max` of them.
pub(crate) fn covering(b: &Bbox, max: usize) -> Option<Vec<i64>> {
    if b.is_empty() {
        return Some(Vec::new());
    }
    let (rows, cols) = (
        row(b.min_lat)..=row(b.max_lat),
        row(b.min_lon)..=row(b.max_lon),
    );
    let n = (rows.end() - rows.start() + 1).saturating_mul(cols.end() - cols.start() + 1);
    if n > i64::try_from(max).unwrap_or(i64::MAX) {
        return None;
    }
    Some(
        rows.flat_map(|r| cols.clone().map(move |c| r * ROW_STRIDE + c))
            .collect(),
    )
}

fn row(deg: f64) -> i64 {
    (deg * CELLS_PER_DEGREE).floor() as i64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sql_numbers_cells_as_rust_does() {
        let conn = rusqlite::Connection::open_in_memory().unwrap();
        let points = [
            (40.7128, -74.0060),
            (-33.8688, 151.2093),
            (0.0, 0.0),
            (-0.0001, -0.0001),
            (-0.0025, 0.0025),
            (89.99, -179.99),
            (-90.0, 180.0),
            (51.5, -0.1275),
        ];
        for (lat, lon) in points {
            let sql: i64 = conn
                .query_row(
                    &format!(
                        "SELECT {} FROM (SELECT ?1 AS latitude_deg, ?2 AS longitude_deg)",
                        cell_sql!()
                    ),
                    [lat, lon],
                    |r| r.get(0),
                )
                .unwrap();
            assert_eq!(sql, cell_of(LatLon::new(lat, lon)), "{lat}, {lon}");
        }
    }

    #[test]
    fn covering_holds_every_point_of_the_box() {
        let b = Bbox {
            min_lat: 40.7001,
            max_lat: 40.7099,
            min_lon: -74.0099,
            max_lon: -74.0001,
        };
        let cells = covering(&b, 100).unwrap();
        assert_eq!(cells.len(), 4 * 4);
        for i in 0..=98 {
            for j in 0..=98 {
                let p = LatLon::new(
                    40.7001 + 0.0001 * f64::from(i),
                    -74.0099 + 0.0001 * f64::from(j),
                );
                assert!(cells.contains(&cell_of(p)), "{p:?}");
            }
        }
        assert_eq!(covering(&b, 15), None);
    }
}
