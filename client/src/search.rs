//! [`SiteSearch`]: a `SearchLandingSitesRequest` in one line, for
//! [`crate::LandingClient::search_landing_sites`].

use std::time::Duration;

use landing_proto::v1::{GeodeticPoint, SearchLandingSitesRequest, SiteOrder};

/// A search of the fleet's landing-site catalog by place: a centre and a radius, then what to
/// change from the server's defaults (20 per page, nearest first, confirmed sites no older than
/// the server's `catalog.max_age_s`, no candidates). Every site found is a candidate for a drone
/// to confirm with its own stream, never a clearance to land.
///
/// ```
/// use std::time::Duration;
/// use landing_client::SiteSearch;
/// use landing_client::v1::SiteOrder;
///
/// let request = SiteSearch::near(40.7484, -73.9857, 500.0)
///     .min_safe_radius_m(3.0)
///     .max_age(Duration::from_secs(3600))
///     .order(SiteOrder::Freshness)
///     .page_size(50)
///     .build();
/// assert_eq!(request.radius_m, 500.0);
/// assert_eq!(request.max_age.unwrap().seconds, 3600);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct SiteSearch(SearchLandingSitesRequest);

impl SiteSearch {
    /// Sites whose safest point lies within `radius_m` metres of the WGS-84 point.
    pub fn near(latitude_deg: f64, longitude_deg: f64, radius_m: f64) -> Self {
        Self(SearchLandingSitesRequest {
            center: Some(GeodeticPoint {
                latitude_deg,
                longitude_deg,
                altitude_m: 0.0,
            }),
            radius_m,
            ..Default::default()
        })
    }

    /// Results per page (the server lowers more than 1000 to 1000).
    pub fn page_size(mut self, n: i32) -> Self {
        self.0.page_size = n;
        self
    }

    /// The page after the one that gave this `next_page_token`.
    pub fn page_token(mut self, token: impl Into<String>) -> Self {
        self.0.page_token = token.into();
        self
    }

    /// Leaves out sites whose safe radius is smaller, metres.
    pub fn min_safe_radius_m(mut self, m: f64) -> Self {
        self.0.min_safe_radius_m = m;
        self
    }

    /// Leaves out sites last confirmed longer ago.
    pub fn max_age(mut self, age: Duration) -> Self {
        self.0.max_age = prost_types::Duration::try_from(age).ok();
        self
    }

    /// The order of the results (confirmed sites always before candidates).
    pub fn order(mut self, order: SiteOrder) -> Self {
        self.0.order = order as i32;
        self
    }

    /// Also returns candidate roofs known beforehand, after the confirmed sites.
    pub fn include_candidates(mut self, yes: bool) -> Self {
        self.0.include_candidates = yes;
        self
    }

    /// The request.
    pub fn build(self) -> SearchLandingSitesRequest {
        self.0
    }
}

impl From<SiteSearch> for SearchLandingSitesRequest {
    fn from(s: SiteSearch) -> Self {
        s.build()
    }
}
