//! Searching the catalog by place: [`SearchQuery`], its validation, ordering and checked page
//! tokens (Google AIP-158).
//!
//! A page token is opaque to callers: base64url of a version byte, a hash of the query's
//! parameters (everything but `page_size` and `page_token`), the age cut-off the first page fixed,
//! the position of the page's last result (its group, sort key and id: a keyset, so paging stays
//! right while writes go on) and a checksum over all of it. A token that does not decode, fails its
//! checksum or was made for other parameters is refused naming `page_token`. The checksum is not
//! a signature: a token grants nothing the query itself does not, it only must not be misread.

use std::time::Duration;

use base64::Engine as _;
use base64::engine::general_purpose::URL_SAFE_NO_PAD;
use sha2::{Digest, Sha256};

use crate::error::{Error, Result};
use crate::geo::LatLon;
use crate::model::{Site, SiteKind};
use crate::time::Timestamp;

/// Results per page when the query asks for 0.
pub const DEFAULT_PAGE_SIZE: usize = 20;
/// The most results per page; a larger `page_size` is lowered to it (AIP-158).
pub const MAX_PAGE_SIZE: usize = 1000;
/// The widest search radius, metres.
pub const MAX_SEARCH_RADIUS_M: f64 = 50_000.0;
/// The age beyond which confirmed sites are left out unless a query asks otherwise.
pub const DEFAULT_MAX_AGE: Duration = Duration::from_secs(7 * 24 * 3600);

/// How results are ordered. Confirmed sites always come before candidates; ties go by id.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash)]
pub enum Order {
    /// Nearest safest point first.
    #[default]
    Distance,
    /// Largest safe radius first.
    SafeRadius,
    /// Most recently confirmed first (candidates, which have no confirmation, nearest first).
    Freshness,
}

/// A search by place.
#[derive(Debug, Clone, PartialEq)]
pub struct SearchQuery {
    /// The centre of the search.
    pub center: LatLon,
    /// Sites whose safest point lies within this distance of `center`, metres, in (0,
    /// [`MAX_SEARCH_RADIUS_M`]].
    pub radius_m: f64,
    /// Results per page: 0 means [`DEFAULT_PAGE_SIZE`]; above [`MAX_PAGE_SIZE`] is lowered to it;
    /// negative is refused.
    pub page_size: i32,
    /// Empty for the first page, else the previous page's `next_page_token`.
    pub page_token: String,
    /// Leave out sites whose safe radius is smaller, metres (>= 0).
    pub min_safe_radius_m: f64,
    /// Leave out confirmed sites last confirmed longer ago than this; `None` returns every age.
    pub max_age: Option<Duration>,
    /// The order of results.
    pub order: Order,
    /// Also return candidate roofs, after the confirmed sites.
    pub include_candidates: bool,
}

impl SearchQuery {
    /// Checks every field (and the page token) as a search would, without a store: the error
    /// names the field. Lets a caller refuse a bad request before it knows whether a store is
    /// there to ask.
    pub fn validate(&self, now: Timestamp) -> Result<()> {
        Resolved::new(self, now).map(|_| ())
    }

    /// The first page of confirmed sites within `radius_m` of `center`, nearest first, no older
    /// than [`DEFAULT_MAX_AGE`], [`DEFAULT_PAGE_SIZE`] per page.
    pub fn new(center: LatLon, radius_m: f64) -> Self {
        SearchQuery {
            center,
            radius_m,
            page_size: 0,
            page_token: String::new(),
            min_safe_radius_m: 0.0,
            max_age: Some(DEFAULT_MAX_AGE),
            order: Order::Distance,
            include_candidates: false,
        }
    }
}

/// One result: the record and its distance from the query's centre.
#[derive(Debug, Clone, PartialEq)]
pub struct Found {
    /// The record.
    pub site: Site,
    /// From the query's centre to the site's safest point, metres.
    pub distance_m: f64,
}

/// One page of results.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SearchPage {
    /// The results, in the query's order.
    pub sites: Vec<Found>,
    /// The token for the next page; empty on the last page.
    pub next_page_token: String,
}

/// Where a page ends: the last result's group (0 confirmed, 1 candidates), sort key and id.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Cursor {
    pub group: u8,
    pub key: f64,
    pub id: i64,
}

/// A validated query, ready for a store.
#[derive(Debug, Clone)]
pub(crate) struct Resolved {
    pub center: LatLon,
    pub radius_m: f64,
    pub page_size: usize,
    pub min_safe_radius_m: f64,
    /// Confirmed sites last confirmed before this are left out.
    pub cutoff: Option<Timestamp>,
    pub order: Order,
    pub include_candidates: bool,
    pub after: Option<Cursor>,
    hash: [u8; 8],
}

/// A store's answer for one group: the group's results after `after`, in order, at most `limit`.
pub(crate) type FetchGroup<'a> =
    dyn FnMut(&Resolved, SiteKind, Option<(f64, i64)>, usize) -> Result<Vec<Found>> + 'a;

impl Resolved {
    /// Validates `q` (errors name the field) and fixes the age cut-off (from the token on later
    /// pages, so one search's pages agree).
    pub fn new(q: &SearchQuery, now: Timestamp) -> Result<Self> {
        q.center.validate("center")?;
        if !(q.radius_m.is_finite() && q.radius_m > 0.0 && q.radius_m <= MAX_SEARCH_RADIUS_M) {
            return Err(Error::invalid(
                "radius_m",
                format!(
                    "{} is not a radius in (0, {MAX_SEARCH_RADIUS_M}] m",
                    q.radius_m
                ),
            ));
        }
        let page_size = match q.page_size {
            n if n < 0 => {
                return Err(Error::invalid("page_size", format!("{n} is negative")));
            }
            0 => DEFAULT_PAGE_SIZE,
            n => usize::try_from(n)
                .unwrap_or(MAX_PAGE_SIZE)
                .min(MAX_PAGE_SIZE),
        };
        if !(q.min_safe_radius_m.is_finite() && q.min_safe_radius_m >= 0.0) {
            return Err(Error::invalid(
                "min_safe_radius_m",
                format!("{} is not a radius >= 0 m", q.min_safe_radius_m),
            ));
        }
        let hash = query_hash(q);
        let mut r = Resolved {
            center: q.center,
            radius_m: q.radius_m,
            page_size,
            min_safe_radius_m: q.min_safe_radius_m,
            cutoff: q.max_age.map(|a| now.saturating_sub(a)),
            order: q.order,
            include_candidates: q.include_candidates,
            after: None,
            hash,
        };
        if !q.page_token.is_empty() {
            let (cutoff, cursor) = decode_token(&q.page_token, &hash)?;
            r.cutoff = cutoff;
            r.after = Some(cursor);
        }
        Ok(r)
    }

    /// A record's place in the order, within its group (ascending).
    pub fn sort_key(&self, site: &Site, distance_m: f64) -> f64 {
        match (self.order, site.kind) {
            (Order::Distance, _) | (Order::Freshness, SiteKind::Candidate) => distance_m,
            (Order::SafeRadius, _) => -site.safe_radius_m,
            (Order::Freshness, SiteKind::Confirmed) => -(site.last_confirmed.unix_ms() as f64),
        }
    }

    /// Whether a record passes the query's filters (radius, minimum safe radius, age).
    pub fn admits(&self, site: &Site, distance_m: f64) -> bool {
        distance_m <= self.radius_m
            && site.safe_radius_m >= self.min_safe_radius_m
            && (site.kind == SiteKind::Candidate
                || self.cutoff.is_none_or(|c| site.last_confirmed >= c))
    }

    /// One page: confirmed sites, then candidates when asked, from the cursor on. `fetch` returns
    /// one group's admitted results after a keyset position, ordered by (key, id), at most `limit`.
    pub fn page(&self, fetch: &mut FetchGroup<'_>) -> Result<SearchPage> {
        let limit = self.page_size + 1;
        let mut found: Vec<(u8, f64, Found)> = Vec::with_capacity(limit);
        let groups: &[(u8, SiteKind)] = if self.include_candidates {
            &[(0, SiteKind::Confirmed), (1, SiteKind::Candidate)]
        } else {
            &[(0, SiteKind::Confirmed)]
        };
        for &(group, kind) in groups {
            let after = match self.after {
                Some(c) if c.group > group => continue,
                Some(c) if c.group == group => Some((c.key, c.id)),
                _ => None,
            };
            let want = limit - found.len();
            for f in fetch(self, kind, after, want)?.into_iter().take(want) {
                let key = self.sort_key(&f.site, f.distance_m);
                found.push((group, key, f));
            }
            if found.len() >= limit {
                break;
            }
        }
        let more = found.len() > self.page_size;
        found.truncate(self.page_size);
        let next_page_token = match found.last() {
            Some(&(group, key, ref f)) if more => encode_token(
                &self.hash,
                self.cutoff,
                Cursor {
                    group,
                    key,
                    id: f.site.id.0,
                },
            ),
            _ => String::new(),
        };
        Ok(SearchPage {
            sites: found.into_iter().map(|(_, _, f)| f).collect(),
            next_page_token,
        })
    }
}

/// Sorts one group's admitted results and keeps those after the keyset position (the embedded
/// store's ordering; PostGIS orders in SQL).
pub(crate) fn order_group(
    r: &Resolved,
    mut all: Vec<Found>,
    after: Option<(f64, i64)>,
    limit: usize,
) -> Vec<Found> {
    let key = |f: &Found| (r.sort_key(&f.site, f.distance_m), f.site.id.0);
    all.retain(|f| {
        let (k, id) = key(f);
        after.is_none_or(|(ak, aid)| k.total_cmp(&ak).then(id.cmp(&aid)).is_gt())
    });
    all.sort_by(|a, b| {
        let (ka, ia) = key(a);
        let (kb, ib) = key(b);
        ka.total_cmp(&kb).then(ia.cmp(&ib))
    });
    all.truncate(limit);
    all
}

const TOKEN_VERSION: u8 = 1;
const TOKEN_LEN: usize = 1 + 8 + 9 + 1 + 8 + 8 + 8;

fn query_hash(q: &SearchQuery) -> [u8; 8] {
    let mut h = Sha256::new();
    h.update(b"landing-catalog search v1");
    h.update(q.center.latitude_deg.to_le_bytes());
    h.update(q.center.longitude_deg.to_le_bytes());
    h.update(q.radius_m.to_le_bytes());
    h.update(q.min_safe_radius_m.to_le_bytes());
    match q.max_age {
        Some(a) => {
            h.update([1]);
            h.update(a.as_millis().to_le_bytes());
        }
        None => h.update([0]),
    }
    h.update([q.order as u8, u8::from(q.include_candidates)]);
    first8(&h.finalize())
}

fn checksum(body: &[u8]) -> [u8; 8] {
    let mut h = Sha256::new();
    h.update(b"landing-catalog page token");
    h.update(body);
    first8(&h.finalize())
}

fn first8(bytes: &[u8]) -> [u8; 8] {
    let mut out = [0; 8];
    out.copy_from_slice(&bytes[..8]);
    out
}

fn encode_token(hash: &[u8; 8], cutoff: Option<Timestamp>, c: Cursor) -> String {
    let mut b = Vec::with_capacity(TOKEN_LEN);
    b.push(TOKEN_VERSION);
    b.extend_from_slice(hash);
    b.push(u8::from(cutoff.is_some()));
    b.extend_from_slice(&cutoff.map_or(0, Timestamp::unix_ms).to_le_bytes());
    b.push(c.group);
    b.extend_from_slice(&c.key.to_le_bytes());
    b.extend_from_slice(&c.id.to_le_bytes());
    let sum = checksum(&b);
    b.extend_from_slice(&sum);
    URL_SAFE_NO_PAD.encode(b)
}

fn decode_token(token: &str, hash: &[u8; 8]) -> Result<(Option<Timestamp>, Cursor)> {
    let bad = |why: &str| Error::invalid("page_token", why.to_string());
    let b = URL_SAFE_NO_PAD
        .decode(token)
        .map_err(|_| bad("not a token this service issued"))?;
    if b.len() != TOKEN_LEN || b[0] != TOKEN_VERSION {
        return Err(bad("not a token this service issued"));
    }
    let (body, sum) = b.split_at(TOKEN_LEN - 8);
    if checksum(body) != sum {
        return Err(bad("the token is damaged"));
    }
    if &body[1..9] != hash {
        return Err(bad("the token belongs to a search with other parameters"));
    }
    let i64_at = |at: usize| i64::from_le_bytes(first8(&body[at..at + 8]));
    let cutoff = (body[9] == 1).then(|| Timestamp::from_unix_ms(i64_at(10)));
    let group = body[18];
    let key = f64::from_le_bytes(first8(&body[19..27]));
    if group > 1 || key.is_nan() {
        return Err(bad("the token is damaged"));
    }
    Ok((
        cutoff,
        Cursor {
            group,
            key,
            id: i64_at(27),
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn query() -> SearchQuery {
        SearchQuery::new(LatLon::new(40.7, -74.0), 500.0)
    }

    #[test]
    fn tokens_round_trip_and_refuse_tampering() {
        let q = query();
        let r = Resolved::new(&q, Timestamp::from_unix_ms(1_000_000_000)).unwrap();
        let c = Cursor {
            group: 0,
            key: 12.5,
            id: 42,
        };
        let t = encode_token(&r.hash, r.cutoff, c);
        let mut next = q.clone();
        next.page_token = t.clone();
        next.page_size = 7; // page size may change between pages
        let r2 = Resolved::new(&next, Timestamp::from_unix_ms(2_000_000_000)).unwrap();
        assert_eq!(r2.after, Some(c));
        assert_eq!(r2.cutoff, r.cutoff, "the first page's cut-off holds");
        // Every single-character change is refused.
        let chars: Vec<char> = t.chars().collect();
        for i in 0..chars.len() {
            let mut m = chars.clone();
            m[i] = if m[i] == 'A' { 'B' } else { 'A' };
            let mut q2 = q.clone();
            q2.page_token = m.into_iter().collect();
            let e = Resolved::new(&q2, Timestamp::from_unix_ms(0)).unwrap_err();
            assert_eq!(e.field(), Some("page_token"), "{e}");
        }
        let mut other = next.clone();
        other.radius_m = 501.0;
        let e = Resolved::new(&other, Timestamp::from_unix_ms(0)).unwrap_err();
        assert!(e.to_string().contains("other parameters"), "{e}");
    }

    /// A change to a query.
    type Change = fn(&mut SearchQuery);

    #[test]
    fn bad_fields_are_named() {
        let now = Timestamp::from_unix_ms(0);
        let cases: [(Change, &str); 6] = [
            (|q| q.center.latitude_deg = 91.0, "center.latitude_deg"),
            (
                |q| q.center.longitude_deg = f64::NAN,
                "center.longitude_deg",
            ),
            (|q| q.radius_m = 0.0, "radius_m"),
            (|q| q.page_size = -1, "page_size"),
            (|q| q.min_safe_radius_m = -1.0, "min_safe_radius_m"),
            (|q| q.page_token = "%%".into(), "page_token"),
        ];
        for (change, field) in cases {
            let mut q = query();
            change(&mut q);
            assert_eq!(Resolved::new(&q, now).unwrap_err().field(), Some(field));
        }
        let mut q = query();
        q.page_size = 5000;
        assert_eq!(Resolved::new(&q, now).unwrap().page_size, MAX_PAGE_SIZE);
    }
}
