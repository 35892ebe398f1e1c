//! `SearchLandingSites` to the catalog and back: [`SearchRequest`] → [`SearchQuery`] (every field
//! named; the catalog checks the ranges and the page token and names the field as the request
//! spells it), and a [`SearchPage`] → `SearchLandingSitesResponse` ([`response`]).

use std::time::{Duration, SystemTime};

use landing_catalog::{Found, LatLon, Order, SearchPage, SearchQuery, SiteKind};
use landing_proto::v1;

use crate::Error;

/// A search request with the server's default age limit (`catalog.max_age_s`), for an unset
/// `max_age`.
pub(crate) struct SearchRequest<'a> {
    pub request: &'a v1::SearchLandingSitesRequest,
    pub default_max_age: Duration,
}

impl TryFrom<SearchRequest<'_>> for SearchQuery {
    type Error = Error;

    fn try_from(r: SearchRequest<'_>) -> Result<Self, Error> {
        let v1::SearchLandingSitesRequest {
            center,
            radius_m,
            page_size,
            page_token,
            min_safe_radius_m,
            max_age,
            order,
            include_candidates,
        } = r.request;
        // The altitude is not part of a search by place.
        let center = center
            .as_ref()
            .map(|c| LatLon::new(c.latitude_deg, c.longitude_deg))
            .ok_or_else(|| Error::invalid("center", "required: the centre of the search"))?;
        let max_age = match max_age {
            None => r.default_max_age,
            Some(d) => age(d)?,
        };
        let order = match v1::SiteOrder::try_from(*order) {
            Ok(v1::SiteOrder::Unspecified) => Order::Distance,
            Ok(v1::SiteOrder::SafeRadius) => Order::SafeRadius,
            Ok(v1::SiteOrder::Freshness) => Order::Freshness,
            Err(_) => {
                return Err(Error::invalid(
                    "order",
                    format!("{order} is not a SiteOrder"),
                ));
            }
        };
        Ok(SearchQuery {
            center,
            radius_m: *radius_m,
            page_size: *page_size,
            page_token: page_token.clone(),
            min_safe_radius_m: *min_safe_radius_m,
            max_age: Some(max_age),
            order,
            include_candidates: *include_candidates,
        })
    }
}

/// A positive `max_age`.
fn age(d: &prost_types::Duration) -> Result<Duration, Error> {
    let refuse =
        |why: &str| Error::invalid("max_age", format!("{}s {}ns {why}", d.seconds, d.nanos));
    if !(0..1_000_000_000).contains(&d.nanos) {
        return Err(refuse("is not a duration (nanos in 0..1e9)"));
    }
    let seconds = u64::try_from(d.seconds).map_err(|_| refuse("is negative"))?;
    let age = Duration::new(seconds, d.nanos as u32);
    if age.is_zero() {
        return Err(refuse(
            "is zero: ask for a positive age, or leave it unset for the server's",
        ));
    }
    Ok(age)
}

/// The response of one page.
pub(crate) fn response(page: SearchPage) -> v1::SearchLandingSitesResponse {
    v1::SearchLandingSitesResponse {
        sites: page.sites.iter().map(catalog_site).collect(),
        next_page_token: page.next_page_token,
    }
}

/// One result as the API gives it: the record in WGS-84 (altitudes: the roof plane's height)
/// with its times and its distance from the search's centre.
fn catalog_site(f: &Found) -> v1::CatalogSite {
    let s = &f.site;
    let point = |p: &LatLon, altitude_m: f64| v1::GeodeticPoint {
        latitude_deg: p.latitude_deg,
        longitude_deg: p.longitude_deg,
        altitude_m,
    };
    let ring = |r: &[LatLon]| v1::GeodeticRing {
        points: r.iter().map(|p| point(p, s.plane_height_m)).collect(),
    };
    let time =
        |t: landing_catalog::Timestamp| Some(prost_types::Timestamp::from(SystemTime::from(t)));
    v1::CatalogSite {
        id: s.id.0.to_string(),
        kind: match s.kind {
            SiteKind::Confirmed => v1::SiteKind::Site,
            SiteKind::Candidate => v1::SiteKind::Candidate,
        } as i32,
        center: Some(point(&s.center, s.plane_height_m)),
        safe_radius_m: s.safe_radius_m,
        polygon: s.polygon.rings().map(ring).collect(),
        plane_height_m: s.plane_height_m,
        area_m2: s.area_m2,
        first_seen: time(s.first_seen),
        last_confirmed: time(s.last_confirmed),
        frames: s.frames,
        approaches: s.approaches,
        drone_id: s.drone_id.clone(),
        model_id: s.model_id.clone(),
        distance_m: f.distance_m,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn request() -> v1::SearchLandingSitesRequest {
        v1::SearchLandingSitesRequest {
            center: Some(v1::GeodeticPoint {
                latitude_deg: 40.75,
                longitude_deg: -73.99,
                altitude_m: 12.0,
            }),
            radius_m: 500.0,
            ..Default::default()
        }
    }

    fn query(r: &v1::SearchLandingSitesRequest) -> Result<SearchQuery, Error> {
        SearchQuery::try_from(SearchRequest {
            request: r,
            default_max_age: Duration::from_secs(60),
        })
    }

    fn field(e: Error) -> String {
        match e {
            Error::InvalidArgument(v) => v[0].field.clone(),
            other => panic!("{other}"),
        }
    }

    #[test]
    fn every_field_is_carried_and_defaults_are_the_servers() {
        let q = query(&request()).unwrap();
        assert_eq!(q.center, LatLon::new(40.75, -73.99));
        assert_eq!(q.max_age, Some(Duration::from_secs(60)));
        assert_eq!(q.order, Order::Distance);
        let mut r = request();
        r.max_age = Some(prost_types::Duration {
            seconds: 3600,
            nanos: 0,
        });
        r.order = v1::SiteOrder::Freshness as i32;
        r.include_candidates = true;
        r.page_size = 7;
        r.min_safe_radius_m = 2.5;
        let q = query(&r).unwrap();
        assert_eq!(q.max_age, Some(Duration::from_secs(3600)));
        assert_eq!(
            (
                q.order,
                q.include_candidates,
                q.page_size,
                q.min_safe_radius_m
            ),
            (Order::Freshness, true, 7, 2.5)
        );
    }

    #[test]
    fn bad_fields_are_named() {
        let mut r = request();
        r.center = None;
        assert_eq!(field(query(&r).unwrap_err()), "center");
        let mut r = request();
        r.order = 9;
        assert_eq!(field(query(&r).unwrap_err()), "order");
        for (seconds, nanos) in [(0, 0), (-5, 0), (1, -1)] {
            let mut r = request();
            r.max_age = Some(prost_types::Duration { seconds, nanos });
            assert_eq!(field(query(&r).unwrap_err()), "max_age");
        }
    }
}
