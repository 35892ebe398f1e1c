//! One conformance suite, run against both stores: a real SQLite file in a temporary directory
//! and a real PostgreSQL + PostGIS server started on loopback (`support/postgres.rs`). Each test
//! is a function of [`suite`] taking a [`Backend`], which opens handles to one fresh database; the
//! macro at the bottom instantiates every test for each store.

#[path = "support/postgres.rs"]
#[allow(dead_code)]
mod pg;

use std::sync::Arc;
use std::time::Duration;

use landing_catalog::{
    Candidate, Error, Found, LatLon, LocalFrame, Observation, ObservedSite, Order, Polygon,
    PostgisStore, SearchQuery, Site, SiteId, SiteKind, SqliteStore, Store, Timestamp, geojson,
};

/// Opens handles to one fresh database.
pub trait Backend {
    fn open(&self) -> Box<dyn Store>;
}

struct Sqlite {
    dir: tempfile::TempDir,
}

impl Sqlite {
    fn new() -> Self {
        Sqlite {
            dir: tempfile::tempdir().expect("a temp dir"),
        }
    }
}

impl Backend for Sqlite {
    fn open(&self) -> Box<dyn Store> {
        Box::new(SqliteStore::open(self.dir.path().join("catalog.sqlite")).expect("open SQLite"))
    }
}

struct Postgis {
    url: String,
    _server: Arc<pg::PgServer>,
}

impl Postgis {
    fn new() -> Self {
        let server = pg::shared();
        Postgis {
            url: server.create_database(),
            _server: server,
        }
    }
}

impl Backend for Postgis {
    fn open(&self) -> Box<dyn Store> {
        Box::new(PostgisStore::connect(&self.url).expect("connect to PostGIS"))
    }
}

/// The scenes: roofs laid out in metres east and north of a Manhattan block.
mod scene {
    use super::*;

    pub const ORIGIN: LatLon = LatLon::new(40.7484, -73.9857);
    const T0: i64 = 1_796_588_100_000;

    pub fn t(seconds: i64) -> Timestamp {
        Timestamp::from_unix_ms(T0 + seconds * 1000)
    }

    pub fn at(x: f64, y: f64) -> LatLon {
        LocalFrame::new(ORIGIN).to_lat_lon((x, y))
    }

    pub fn square(x: f64, y: f64, half: f64) -> Polygon {
        Polygon::rectangle(at(x - half, y - half), at(x + half, y + half))
    }

    /// A site of safe radius `r` at `(x, y)`, on a roof plane `h` m high.
    pub fn site(x: f64, y: f64, r: f64, h: f64) -> ObservedSite {
        ObservedSite {
            polygon: square(x, y, r + 1.0),
            center: at(x, y),
            safe_radius_m: r,
            plane_height_m: h,
            frames: 1,
        }
    }

    pub fn obs(
        s: i64,
        approach: &str,
        seen: Vec<Polygon>,
        sites: Vec<ObservedSite>,
    ) -> Observation {
        Observation {
            t: t(s),
            drone_id: format!("drone-{approach}"),
            approach_id: approach.into(),
            model_id: "model-a".into(),
            seen,
            sites,
        }
    }

    /// Everything within 5 km, every age, candidates too, one page.
    pub fn everything(store: &dyn Store) -> Vec<Found> {
        let mut q = SearchQuery::new(ORIGIN, 5000.0);
        q.max_age = None;
        q.page_size = 1000;
        q.include_candidates = true;
        let page = store.search(&q, t(0)).expect("search");
        assert!(page.next_page_token.is_empty());
        page.sites
    }

    /// A seeded linear congruential generator: the scenes need no more.
    pub struct Lcg(pub u64);

    impl Lcg {
        pub fn next(&mut self) -> u64 {
            self.0 = self
                .0
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            self.0 >> 33
        }

        pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
            lo + (hi - lo) * (self.next() as f64 / (1u64 << 31) as f64)
        }
    }

    /// Pages through `q` to its end and checks the concatenated pages against brute force over
    /// `records` (every record, filtered and ordered by the documented rules), and every
    /// reported distance. Returns how many results and pages there were.
    pub fn paged_like_brute_force(
        store: &dyn Store,
        records: &[Found],
        mut q: SearchQuery,
        now: Timestamp,
        case: usize,
    ) -> (usize, usize) {
        let cutoff = q.max_age.map(|a| now.saturating_sub(a));
        let mut want: Vec<(u8, f64, i64)> = records
            .iter()
            .filter_map(|f| {
                let s = &f.site;
                let d = landing_catalog::distance_m(q.center, s.center);
                let confirmed = s.kind == SiteKind::Confirmed;
                let keep = d <= q.radius_m
                    && s.safe_radius_m >= q.min_safe_radius_m
                    && (confirmed || q.include_candidates)
                    && (!confirmed || cutoff.is_none_or(|c| s.last_confirmed >= c));
                let key = match (q.order, confirmed) {
                    (Order::Distance, _) | (Order::Freshness, false) => d,
                    (Order::SafeRadius, _) => -s.safe_radius_m,
                    (Order::Freshness, true) => -(s.last_confirmed.unix_ms() as f64),
                };
                keep.then_some((u8::from(!confirmed), key, s.id.0))
            })
            .collect();
        want.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)).then(a.2.cmp(&b.2)));
        let want: Vec<i64> = want.into_iter().map(|w| w.2).collect();
        let (mut got, mut pages) = (Vec::new(), 0);
        let first = q.clone();
        for _ in 0..1000 {
            let page = store.search(&q, now).unwrap();
            assert!(page.sites.len() <= q.page_size as usize);
            for f in &page.sites {
                let d = landing_catalog::distance_m(q.center, f.site.center);
                assert!(
                    (f.distance_m - d).abs() < 0.01,
                    "distance {} against {d}",
                    f.distance_m
                );
            }
            got.extend(page.sites.iter().map(|f| f.site.id.0));
            pages += 1;
            if page.next_page_token.is_empty() {
                break;
            }
            q.page_token = page.next_page_token;
        }
        assert_eq!(got, want, "case {case}: {first:?}");
        (got.len(), pages)
    }

    pub fn field_of(e: Error) -> String {
        e.field()
            .unwrap_or_else(|| panic!("not a field error: {e}"))
            .to_string()
    }
}

mod suite {
    use super::scene::*;
    use super::*;

    pub fn insert_and_search(b: &dyn Backend) {
        let store = b.open();
        let sites = vec![
            site(0.0, 0.0, 5.0, 50.0),
            site(100.0, 0.0, 3.0, 30.0),
            site(0.0, 900.0, 4.0, 20.0),
        ];
        let seen = vec![
            square(0.0, 0.0, 20.0),
            square(100.0, 0.0, 20.0),
            square(0.0, 900.0, 20.0),
        ];
        let r = store.apply(&[obs(10, "a1", seen, sites.clone())]).unwrap();
        assert_eq!(
            (r.observations, r.inserted, r.updated, r.withdrawn),
            (1, 3, 0, 0)
        );

        let mut q = SearchQuery::new(at(20.0, 0.0), 500.0);
        let page = store.search(&q, t(20)).unwrap();
        assert!(page.next_page_token.is_empty());
        let d: Vec<f64> = page.sites.iter().map(|f| f.distance_m).collect();
        assert_eq!(d.len(), 2, "the roof 900 m away is outside 500 m: {d:?}");
        assert!(
            (d[0] - 20.0).abs() < 0.01 && (d[1] - 80.0).abs() < 0.01,
            "nearest first: {d:?}"
        );

        let s = &page.sites[0].site;
        assert_eq!(s.kind, SiteKind::Confirmed);
        assert_eq!((s.first_seen, s.last_confirmed), (t(10), t(10)));
        assert_eq!((s.frames, s.approaches), (1, 1));
        assert_eq!(
            (
                s.drone_id.as_str(),
                s.approach_id.as_str(),
                s.model_id.as_str()
            ),
            ("drone-a1", "a1", "model-a")
        );
        assert_eq!((s.safe_radius_m, s.plane_height_m), (5.0, 50.0));
        assert!((s.area_m2 - 144.0).abs() < 0.01, "{}", s.area_m2);
        assert!((s.center.latitude_deg - sites[0].center.latitude_deg).abs() < 1e-12);
        assert!((s.center.longitude_deg - sites[0].center.longitude_deg).abs() < 1e-12);
        assert_eq!(s.polygon.exterior.len(), 4);
        for (a, e) in s.polygon.exterior.iter().zip(&sites[0].polygon.exterior) {
            assert!(
                (a.latitude_deg - e.latitude_deg).abs() < 1e-12
                    && (a.longitude_deg - e.longitude_deg).abs() < 1e-12
            );
        }

        q.radius_m = 1000.0;
        assert_eq!(store.search(&q, t(20)).unwrap().sites.len(), 3);
        let counts = store.counts().unwrap();
        assert_eq!(
            (counts.confirmed, counts.candidates, counts.seen_areas),
            (3, 0, 3)
        );
        store.check_integrity().unwrap();
    }

    pub fn orders_and_filters(b: &dyn Backend) {
        let store = b.open();
        // Three roofs seen at different times, with different radii.
        store
            .apply(&[obs(
                10,
                "a",
                vec![square(0.0, 0.0, 10.0)],
                vec![site(0.0, 0.0, 2.0, 10.0)],
            )])
            .unwrap();
        store
            .apply(&[obs(
                20,
                "b",
                vec![square(50.0, 0.0, 10.0)],
                vec![site(50.0, 0.0, 6.0, 10.0)],
            )])
            .unwrap();
        store
            .apply(&[obs(
                30,
                "c",
                vec![square(100.0, 0.0, 10.0)],
                vec![site(100.0, 0.0, 4.0, 10.0)],
            )])
            .unwrap();
        let xs = |q: &SearchQuery, now: Timestamp| -> Vec<i64> {
            let f = LocalFrame::new(ORIGIN);
            store
                .search(q, now)
                .unwrap()
                .sites
                .iter()
                .map(|s| f.to_xy(s.site.center).0.round() as i64)
                .collect()
        };
        let mut q = SearchQuery::new(at(-10.0, 0.0), 500.0);
        assert_eq!(xs(&q, t(40)), [0, 50, 100]);
        q.order = Order::SafeRadius;
        assert_eq!(xs(&q, t(40)), [50, 100, 0]);
        q.order = Order::Freshness;
        assert_eq!(xs(&q, t(40)), [100, 50, 0]);
        q.min_safe_radius_m = 3.0;
        assert_eq!(xs(&q, t(40)), [100, 50]);
        q.min_safe_radius_m = 0.0;
        // Confirmed more than 15 s before now = t(40) is left out unless asked.
        q.max_age = Some(Duration::from_secs(15));
        assert_eq!(xs(&q, t(40)), [100]);
        q.max_age = None;
        assert_eq!(xs(&q, t(40)), [100, 50, 0]);
        // The default age limit is days, so all three are in.
        assert_eq!(xs(&SearchQuery::new(ORIGIN, 500.0), t(40)).len(), 3);
    }

    pub fn paging_is_complete_and_stable(b: &dyn Backend) {
        let store = b.open();
        // 25 roofs on a spiral: distinct distances, some equal radii.
        let sites: Vec<ObservedSite> = (0..25)
            .map(|i| {
                let a = f64::from(i) * 0.7;
                let d = 30.0 + 12.0 * f64::from(i);
                site(d * a.cos(), d * a.sin(), 1.0 + f64::from(i % 3), 10.0)
            })
            .collect();
        store.apply(&[obs(10, "a", vec![], sites)]).unwrap();
        for order in [Order::Distance, Order::SafeRadius, Order::Freshness] {
            let mut q = SearchQuery::new(ORIGIN, 1000.0);
            q.order = order;
            q.page_size = 100;
            let all: Vec<i64> = store
                .search(&q, t(20))
                .unwrap()
                .sites
                .iter()
                .map(|f| f.site.id.0)
                .collect();
            assert_eq!(all.len(), 25);
            q.page_size = 10;
            let mut paged = Vec::new();
            let mut sizes = Vec::new();
            loop {
                let page = store.search(&q, t(20)).unwrap();
                sizes.push(page.sites.len());
                paged.extend(page.sites.iter().map(|f| f.site.id.0));
                if page.next_page_token.is_empty() {
                    break;
                }
                q.page_token = page.next_page_token;
            }
            assert_eq!(sizes, [10, 10, 5], "{order:?}");
            assert_eq!(
                paged, all,
                "{order:?}: pages concatenate to the whole answer"
            );
        }
        // A write between pages neither repeats nor skips what was not changed.
        let mut q = SearchQuery::new(ORIGIN, 1000.0);
        q.page_size = 10;
        let first = store.search(&q, t(20)).unwrap();
        store
            .apply(&[obs(30, "b", vec![], vec![site(1.0, 1.0, 1.0, 80.0)])])
            .unwrap();
        q.page_token = first.next_page_token;
        let second = store.search(&q, t(30)).unwrap();
        let ids: std::collections::HashSet<i64> = first
            .sites
            .iter()
            .chain(&second.sites)
            .map(|f| f.site.id.0)
            .collect();
        assert_eq!(ids.len(), 20, "no result twice");
        assert!(second.sites[0].distance_m >= first.sites[9].distance_m);
    }

    pub fn page_tokens_are_checked(b: &dyn Backend) {
        let store = b.open();
        let sites: Vec<ObservedSite> = (0..5)
            .map(|i| site(f64::from(i) * 20.0, 0.0, 2.0, 10.0))
            .collect();
        store.apply(&[obs(10, "a", vec![], sites)]).unwrap();
        let mut q = SearchQuery::new(ORIGIN, 500.0);
        q.page_size = 2;
        let token = store.search(&q, t(20)).unwrap().next_page_token;
        assert!(!token.is_empty());
        // Tampered: one character changed, cut short, or not base64 at all.
        let mut tampered = token.clone().into_bytes();
        tampered[10] = if tampered[10] == b'A' { b'B' } else { b'A' };
        for bad in [
            String::from_utf8(tampered).unwrap(),
            token[..token.len() - 3].to_string(),
            "not a token!".into(),
        ] {
            let mut q2 = q.clone();
            q2.page_token = bad;
            assert_eq!(
                field_of(store.search(&q2, t(20)).unwrap_err()),
                "page_token"
            );
        }
        // Another search's parameters.
        for change in [
            (|q: &mut SearchQuery| q.radius_m = 400.0) as fn(&mut SearchQuery),
            |q| q.center = at(1.0, 0.0),
            |q| q.order = Order::SafeRadius,
            |q| q.include_candidates = true,
            |q| q.min_safe_radius_m = 1.0,
            |q| q.max_age = None,
        ] {
            let mut q2 = q.clone();
            q2.page_token = token.clone();
            change(&mut q2);
            assert_eq!(
                field_of(store.search(&q2, t(20)).unwrap_err()),
                "page_token"
            );
        }
        // The page size may change between pages.
        let mut q2 = q.clone();
        q2.page_token = token;
        q2.page_size = 10;
        assert_eq!(store.search(&q2, t(20)).unwrap().sites.len(), 3);
    }

    /// A change to a query.
    type Change = fn(&mut SearchQuery);

    pub fn bad_fields_are_named(b: &dyn Backend) {
        let store = b.open();
        let cases: [(Change, &str); 7] = [
            (|q| q.center.latitude_deg = 90.5, "center.latitude_deg"),
            (|q| q.center.latitude_deg = f64::NAN, "center.latitude_deg"),
            (|q| q.center.longitude_deg = -181.0, "center.longitude_deg"),
            (|q| q.radius_m = -1.0, "radius_m"),
            (|q| q.radius_m = f64::INFINITY, "radius_m"),
            (|q| q.page_size = -5, "page_size"),
            (|q| q.min_safe_radius_m = f64::NAN, "min_safe_radius_m"),
        ];
        for (change, field) in cases {
            let mut q = SearchQuery::new(ORIGIN, 100.0);
            change(&mut q);
            let e = store.search(&q, t(0)).unwrap_err();
            assert!(matches!(e, Error::InvalidArgument { .. }));
            assert_eq!(field_of(e), field);
        }
        // A page size above the maximum is lowered, not refused (AIP-158).
        let mut q = SearchQuery::new(ORIGIN, 100.0);
        q.page_size = 1_000_000;
        store.search(&q, t(0)).unwrap();
    }

    pub fn a_bad_batch_writes_nothing(b: &dyn Backend) {
        let store = b.open();
        let good = obs(
            10,
            "a",
            vec![square(0.0, 0.0, 10.0)],
            vec![site(0.0, 0.0, 3.0, 10.0)],
        );
        let mut bad = obs(
            11,
            "a",
            vec![],
            vec![site(50.0, 0.0, 3.0, 10.0), site(90.0, 0.0, 3.0, 10.0)],
        );
        bad.sites[1].safe_radius_m = f64::NAN;
        let e = store.apply(&[good.clone(), bad.clone()]).unwrap_err();
        assert_eq!(field_of(e), "observations[1].sites[1].safe_radius_m");
        bad.sites[1].safe_radius_m = 3.0;
        bad.sites[0].center.longitude_deg = 200.0;
        assert_eq!(
            field_of(store.apply(&[good, bad]).unwrap_err()),
            "observations[1].sites[0].center.longitude_deg"
        );
        let mut no_frames = obs(12, "a", vec![], vec![site(0.0, 0.0, 3.0, 10.0)]);
        no_frames.sites[0].frames = 0;
        assert_eq!(
            field_of(store.apply(&[no_frames]).unwrap_err()),
            "observations[0].sites[0].frames"
        );
        assert!(
            everything(&*store).is_empty(),
            "nothing of a refused batch is written"
        );
    }

    pub fn same_roof_is_updated(b: &dyn Backend) {
        let store = b.open();
        let roof = square(0.0, 0.0, 15.0);
        store
            .apply(&[obs(
                10,
                "a",
                vec![roof.clone()],
                vec![site(0.0, 0.0, 5.0, 30.0)],
            )])
            .unwrap();
        // The same approach again: frames counted, approaches not.
        let mut again = site(0.5, 0.0, 5.0, 30.1);
        again.frames = 4;
        let r = store
            .apply(&[obs(20, "a", vec![roof.clone()], vec![again])])
            .unwrap();
        assert_eq!((r.updated, r.inserted, r.withdrawn), (1, 0, 0));
        // Another approach sees the circle moved 3 m and smaller, 0.4 m higher: the same roof.
        let r = store
            .apply(&[obs(30, "b", vec![roof], vec![site(3.0, 0.0, 4.0, 30.4)])])
            .unwrap();
        assert_eq!((r.updated, r.inserted, r.withdrawn), (1, 0, 0));
        let all = everything(&*store);
        assert_eq!(all.len(), 1);
        let s = &all[0].site;
        assert_eq!(
            (s.first_seen, s.last_confirmed),
            (t(10), t(30)),
            "first seen kept"
        );
        assert_eq!((s.frames, s.approaches), (6, 2));
        assert_eq!(
            (s.safe_radius_m, s.plane_height_m),
            (4.0, 30.4),
            "the newest geometry"
        );
        assert!((LocalFrame::new(ORIGIN).to_xy(s.center).0 - 3.0).abs() < 1e-6);
        assert_eq!(s.approach_id, "b");
    }

    pub fn unseen_sites_keep_their_age(b: &dyn Backend) {
        let store = b.open();
        store
            .apply(&[obs(
                10,
                "a",
                vec![square(0.0, 0.0, 60.0)],
                vec![site(0.0, 0.0, 3.0, 10.0), site(40.0, 0.0, 3.0, 10.0)],
            )])
            .unwrap();
        // A later look resolves only the east part (x in 30..50): the west site is not in it.
        let r = store
            .apply(&[obs(
                20,
                "b",
                vec![square(40.0, 0.0, 10.0)],
                vec![site(40.0, 0.0, 3.0, 10.0)],
            )])
            .unwrap();
        assert_eq!((r.updated, r.withdrawn), (1, 0));
        let all = everything(&*store);
        let by_x = |x: f64| {
            all.iter()
                .find(|f| (LocalFrame::new(ORIGIN).to_xy(f.site.center).0 - x).abs() < 1.0)
                .unwrap()
        };
        assert_eq!(
            by_x(0.0).site.last_confirmed,
            t(10),
            "outside the look: untouched"
        );
        assert_eq!(by_x(40.0).site.last_confirmed, t(20));
    }

    pub fn blocked_sites_are_withdrawn(b: &dyn Backend) {
        let store = b.open();
        let sites = vec![
            site(0.0, 0.0, 4.0, 10.0),
            site(30.0, 0.0, 4.0, 10.0),
            site(60.0, 0.0, 4.0, 10.0),
            site(90.0, 0.0, 4.0, 10.0),
        ];
        store
            .apply(&[obs(10, "a", vec![square(45.0, 0.0, 60.0)], sites)])
            .unwrap();
        // The next look: x=0 seen, no site (a tarp); x=30 seen only at the circle's rim (x >= 33.5:
        // when in doubt, withdraw); x=60 found again 0.6 m higher (another plane: not the same roof);
        // x=90 not seen.
        let seen = vec![
            square(0.0, 0.0, 10.0),
            Polygon::rectangle(at(33.5, -10.0), at(50.0, 10.0)),
            square(60.0, 0.0, 10.0),
        ];
        let r = store
            .apply(&[obs(20, "b", seen, vec![site(60.0, 0.0, 4.0, 10.6)])])
            .unwrap();
        assert_eq!((r.withdrawn, r.inserted, r.updated), (3, 1, 0));
        let f = LocalFrame::new(ORIGIN);
        let mut left: Vec<(i64, Timestamp, f64)> = everything(&*store)
            .iter()
            .map(|x| {
                (
                    f.to_xy(x.site.center).0.round() as i64,
                    x.site.last_confirmed,
                    x.site.plane_height_m,
                )
            })
            .collect();
        left.sort_by_key(|l| l.0);
        assert_eq!(left, [(60, t(20), 10.6), (90, t(10), 10.0)]);
    }

    /// A client that holds a site's id means that site: an id is never given to another, even
    /// when the site that had it (the newest) was withdrawn.
    pub fn withdrawn_ids_are_not_reused(b: &dyn Backend) {
        let store = b.open();
        let roof = square(0.0, 0.0, 15.0);
        store
            .apply(&[obs(10, "a", vec![], vec![site(0.0, 0.0, 5.0, 10.0)])])
            .unwrap();
        let first = everything(&*store)[0].site.id;
        let r = store
            .apply(&[obs(20, "b", vec![roof.clone()], vec![])])
            .unwrap();
        assert_eq!(r.withdrawn, 1);
        store
            .apply(&[obs(30, "c", vec![], vec![site(0.0, 0.0, 5.0, 10.0)])])
            .unwrap();
        let again = everything(&*store);
        assert_eq!(again.len(), 1);
        assert_ne!(
            again[0].site.id, first,
            "a withdrawn site's id was given again"
        );
    }

    pub fn older_observations_never_overwrite(b: &dyn Backend) {
        let store = b.open();
        let roof = square(0.0, 0.0, 15.0);
        store
            .apply(&[obs(
                10,
                "a",
                vec![roof.clone()],
                vec![site(0.0, 0.0, 5.0, 10.0)],
            )])
            .unwrap();
        store
            .apply(&[obs(30, "b", vec![roof.clone()], vec![])])
            .unwrap(); // withdrawn at t=30
        // A late observation from t=20 still reports the site: the newer look stands.
        let r = store
            .apply(&[obs(
                20,
                "c",
                vec![roof.clone()],
                vec![site(0.0, 0.0, 5.0, 10.0)],
            )])
            .unwrap();
        assert_eq!((r.inserted, r.dropped_stale), (0, 1));
        assert!(everything(&*store).is_empty());
        // A roof confirmed at t=50; a late look from t=40 that saw it blocked withdraws nothing.
        store
            .apply(&[obs(
                50,
                "d",
                vec![square(100.0, 0.0, 15.0)],
                vec![site(100.0, 0.0, 5.0, 10.0)],
            )])
            .unwrap();
        let r = store
            .apply(&[obs(40, "e", vec![square(100.0, 0.0, 15.0)], vec![])])
            .unwrap();
        assert_eq!(r.withdrawn, 0);
        let all = everything(&*store);
        assert_eq!(all.len(), 1);
        assert_eq!(all[0].site.last_confirmed, t(50));
        // One batch out of order is applied in time order: the newer withdrawal wins.
        let r = store
            .apply(&[
                obs(70, "f", vec![square(200.0, 0.0, 15.0)], vec![]),
                obs(
                    60,
                    "g",
                    vec![square(200.0, 0.0, 15.0)],
                    vec![site(200.0, 0.0, 5.0, 10.0)],
                ),
            ])
            .unwrap();
        assert_eq!((r.inserted, r.withdrawn), (1, 1));
        assert_eq!(everything(&*store).len(), 1);
    }

    pub fn candidates_come_after_sites(b: &dyn Backend) {
        let store = b.open();
        let fc = |h: &str| {
            let ring = |x: f64| {
                let p = square(x, 0.0, 10.0).exterior;
                let mut c: Vec<[f64; 2]> = p
                    .iter()
                    .map(|q| [q.longitude_deg, q.latitude_deg])
                    .collect();
                c.push(c[0]);
                c
            };
            serde_json::json!({"type": "FeatureCollection", "features": [
                {"type": "Feature", "id": "b1", "properties": {"height": h}, "geometry": {"type": "Polygon", "coordinates": [ring(0.0)]}},
                {"type": "Feature", "id": "b2", "properties": {"roof_height": 12}, "geometry": {"type": "Polygon", "coordinates": [ring(40.0)]}},
            ]})
            .to_string()
        };
        let candidates: Vec<Candidate> = geojson::read_candidates(&fc("20")).unwrap();
        assert_eq!(store.import_candidates(&candidates, t(0)).unwrap(), 2);
        // Re-importing the same ids replaces them.
        store
            .import_candidates(&geojson::read_candidates(&fc("21.5")).unwrap(), t(1))
            .unwrap();
        assert_eq!(store.counts().unwrap().candidates, 2);

        // A confirmed site farther away than both candidates.
        store
            .apply(&[obs(10, "a", vec![], vec![site(300.0, 0.0, 3.0, 10.0)])])
            .unwrap();
        let mut q = SearchQuery::new(ORIGIN, 1000.0);
        assert_eq!(
            store.search(&q, t(20)).unwrap().sites.len(),
            1,
            "no candidates unless asked"
        );
        q.include_candidates = true;
        let all = store.search(&q, t(20)).unwrap().sites;
        let kinds: Vec<SiteKind> = all.iter().map(|f| f.site.kind).collect();
        assert_eq!(
            kinds,
            [
                SiteKind::Confirmed,
                SiteKind::Candidate,
                SiteKind::Candidate
            ]
        );
        let c = &all[1].site;
        assert_eq!(
            (c.source_id.as_deref(), c.plane_height_m),
            (Some("b1"), 21.5)
        );
        assert!(
            (c.safe_radius_m - 10.0).abs() < 0.15,
            "the footprint's inscribed circle: {}",
            c.safe_radius_m
        );
        assert!((c.area_m2 - 400.0).abs() < 0.1);
        // Paging across the boundary between sites and candidates.
        q.page_size = 1;
        let mut kinds = Vec::new();
        loop {
            let page = store.search(&q, t(20)).unwrap();
            kinds.extend(page.sites.iter().map(|f| f.site.kind));
            if page.next_page_token.is_empty() {
                break;
            }
            q.page_token = page.next_page_token;
        }
        assert_eq!(
            kinds,
            [
                SiteKind::Confirmed,
                SiteKind::Candidate,
                SiteKind::Candidate
            ]
        );
        // A look that finds the candidate roof blocked leaves the candidate alone.
        let r = store
            .apply(&[obs(30, "b", vec![square(0.0, 0.0, 20.0)], vec![])])
            .unwrap();
        assert_eq!(r.withdrawn, 0);
        assert_eq!(store.counts().unwrap().candidates, 2);
        // A bad footprint is refused by name, and nothing of it stored.
        let mut bad = candidates.clone();
        bad[1].roof_height_m = f64::NAN;
        assert_eq!(
            field_of(store.import_candidates(&bad, t(40)).unwrap_err()),
            "candidates[1].roof_height_m"
        );
    }

    pub fn expiry(b: &dyn Backend) {
        let store = b.open();
        store
            .apply(&[obs(
                0,
                "a",
                vec![square(0.0, 0.0, 10.0)],
                vec![site(0.0, 0.0, 3.0, 10.0)],
            )])
            .unwrap();
        store
            .apply(&[obs(
                3600,
                "b",
                vec![square(50.0, 0.0, 10.0)],
                vec![site(50.0, 0.0, 3.0, 10.0)],
            )])
            .unwrap();
        let c = Candidate {
            footprint: square(100.0, 0.0, 10.0),
            roof_height_m: 10.0,
            source_id: None,
        };
        store.import_candidates(&[c], t(0)).unwrap();
        let deleted = store
            .expire(t(3600 + 1800), Duration::from_secs(3600))
            .unwrap();
        assert_eq!(deleted, 1);
        let counts = store.counts().unwrap();
        assert_eq!(
            (counts.confirmed, counts.candidates, counts.seen_areas),
            (1, 1, 1)
        );
        assert_eq!(everything(&*store)[0].site.last_confirmed, t(3600));
        store.check_integrity().unwrap();
    }

    pub fn two_writers(b: &dyn Backend) {
        let writers = [b.open(), b.open()];
        // Ten roofs; both writers report every roof 10 times from their own approach, interleaved
        // in time, starting on an empty catalog at once: one site per roof must come out.
        std::thread::scope(|s| {
            for (w, store) in writers.iter().enumerate() {
                s.spawn(move || {
                    for round in 0..10_i64 {
                        let batch: Vec<Observation> = (0..10)
                            .map(|roof| {
                                let x = f64::from(roof) * 50.0;
                                let mut o = obs(
                                    round * 2 + w as i64,
                                    &format!("w{w}"),
                                    vec![square(x, 0.0, 10.0)],
                                    vec![site(x + 0.1 * w as f64, 0.0, 4.0, 10.0)],
                                );
                                o.sites[0].frames = 2;
                                o
                            })
                            .collect();
                        store.apply(&batch).unwrap();
                    }
                });
            }
        });
        let all = everything(&*writers[0]);
        assert_eq!(all.len(), 10, "one site per roof");
        for f in &all {
            // Each roof: 20 observations of 2 frames, less those a newer look had already passed
            // (at most the 10 of one writer, when the other ran first).
            assert!((20..=40).contains(&f.site.frames), "{}", f.site.frames);
            assert_eq!(
                f.site.last_confirmed,
                t(19),
                "the newest look is the last word"
            );
            assert!(f.site.first_seen <= t(1));
            assert!(f.site.approaches >= 1);
        }
        writers[1].check_integrity().unwrap();
    }

    pub fn reopen_keeps_everything(b: &dyn Backend) {
        {
            let store = b.open();
            store
                .apply(&[obs(10, "a", vec![], vec![site(0.0, 0.0, 3.0, 10.0)])])
                .unwrap();
        }
        // Opening again runs the migrations again: nothing to do, nothing lost.
        let store = b.open();
        store.check_integrity().unwrap();
        assert_eq!(everything(&*store).len(), 1);
        assert!(!store.backend().is_empty());
    }

    pub fn geojson_results(b: &dyn Backend) {
        let store = b.open();
        let mut with_hole = site(0.0, 0.0, 3.0, 10.0);
        with_hole.polygon = Polygon::new(
            square(0.0, 0.0, 10.0).exterior,
            vec![square(6.0, 6.0, 1.0).exterior],
        );
        store
            .apply(&[obs(10, "a", vec![], vec![with_hole])])
            .unwrap();
        let doc = geojson::write_results(&everything(&*store));
        assert_eq!(doc["type"], "FeatureCollection");
        let f = &doc["features"][0];
        assert_eq!(f["properties"]["kind"], "site");
        assert_eq!(f["properties"]["last_confirmed"], t(10).to_rfc3339());
        let rings = f["geometry"]["coordinates"].as_array().unwrap();
        assert_eq!(rings.len(), 2);
        let signed = |ring: &serde_json::Value| {
            let pts: Vec<(f64, f64)> = ring
                .as_array()
                .unwrap()
                .iter()
                .map(|p| (p[0].as_f64().unwrap(), p[1].as_f64().unwrap()))
                .collect();
            assert_eq!(pts.first(), pts.last(), "closed");
            pts.windows(2)
                .map(|w| w[0].0 * w[1].1 - w[1].0 * w[0].1)
                .sum::<f64>()
        };
        assert!(signed(&rings[0]) > 0.0, "outer ring counter-clockwise");
        assert!(signed(&rings[1]) < 0.0, "hole clockwise");
        let lon = rings[0][0][0].as_f64().unwrap();
        assert!(
            (lon - ORIGIN.longitude_deg).abs() < 0.001,
            "longitude first"
        );
    }

    /// Seeded random sites and searches, paged, against a brute-force answer over every record.
    /// `load_sites` stores records as they are (text fields with COPY's special characters
    /// included), refuses a bad record naming it, and ties in distance page by id.
    pub fn loaded_sites_are_stored_as_they_are(b: &dyn Backend) {
        let store = b.open();
        let record = |x: f64, r: f64| Site {
            id: SiteId(0),
            kind: SiteKind::Confirmed,
            polygon: square(x, 0.0, r + 1.0),
            center: at(x, 0.0),
            safe_radius_m: r,
            plane_height_m: 12.5,
            area_m2: (2.0 * (r + 1.0)).powi(2),
            first_seen: t(1),
            last_confirmed: t(2),
            frames: 7,
            approaches: 2,
            drone_id: "drone\twith\\odd\ncharacters\r".into(),
            approach_id: "a".into(),
            model_id: "m".into(),
            source_id: None,
        };
        // Five records at one point: equally near every query.
        let mut sites: Vec<Site> = (0..5).map(|_| record(30.0, 4.0)).collect();
        sites.push(record(60.0, 6.0));
        let mut candidate = record(90.0, 8.0);
        candidate.kind = SiteKind::Candidate;
        candidate.source_id = Some("building\\7".into());
        sites.push(candidate);
        let mut bad = sites.clone();
        bad[1].center.latitude_deg = 91.0;
        assert_eq!(
            field_of(store.load_sites(&bad).unwrap_err()),
            "sites[1].center.latitude_deg"
        );
        assert!(
            everything(&*store).is_empty(),
            "a refused load writes nothing"
        );
        assert_eq!(store.load_sites(&sites).unwrap(), 7);
        let all = everything(&*store);
        assert_eq!(all.len(), 7);
        let first = &all[0].site;
        let mut expected = sites[0].clone();
        expected.id = first.id;
        assert_eq!(first.drone_id, expected.drone_id);
        assert_eq!(
            (
                first.frames,
                first.approaches,
                first.first_seen,
                first.last_confirmed
            ),
            (7, 2, t(1), t(2))
        );
        assert!((first.center.latitude_deg - expected.center.latitude_deg).abs() < 1e-12);
        let c = all.last().unwrap();
        assert_eq!(c.site.kind, SiteKind::Candidate);
        assert_eq!(c.site.source_id.as_deref(), Some("building\\7"));
        // Ties in distance go by id, across pages of one.
        let mut q = SearchQuery::new(ORIGIN, 500.0);
        q.max_age = None;
        q.page_size = 1;
        let mut ids = Vec::new();
        loop {
            let page = store.search(&q, t(10)).unwrap();
            ids.extend(page.sites.iter().map(|f| f.site.id));
            if page.next_page_token.is_empty() {
                break;
            }
            q.page_token = page.next_page_token;
        }
        assert_eq!(ids.len(), 6, "{ids:?}");
        assert!(ids[..5].windows(2).all(|w| w[0] < w[1]), "{ids:?}");
        let counts = store.counts().unwrap();
        assert_eq!((counts.confirmed, counts.candidates), (6, 1));
        store.check_integrity().unwrap();
    }

    /// Largest radius first and freshest first where ties are the rule: few distinct radii and
    /// times, records stacked on one point, on cell corners and on the circle's edge, candidates
    /// among them; narrow, middling and wide circles, small pages (a page often ends inside a
    /// run of equal keys), age and radius filters. Every search pages to its end like brute
    /// force.
    pub fn keyed_orders_with_ties_match_brute_force(b: &dyn Backend) {
        let store = b.open();
        let mut rng = Lcg(0x5eed_0002);
        let radii = [1.0, 2.5, 4.0, 4.0, 7.5];
        let mut places: Vec<LatLon> = (0..500)
            .map(|_| at(rng.range(-2000.0, 2000.0), rng.range(-2000.0, 2000.0)))
            .collect();
        // Twelve records on one point; records on the corners of the stores' grid cells (any
        // grid of 1/400°, 1/200°, ... has corners there); records just inside and just outside
        // a 700 m circle around the origin.
        places.extend(std::iter::repeat_n(at(300.0, -200.0), 12));
        let corner = |k: f64| {
            LatLon::new(
                (ORIGIN.latitude_deg * 400.0).round() / 400.0 + k / 400.0,
                (ORIGIN.longitude_deg * 400.0).round() / 400.0 - k / 400.0,
            )
        };
        places.extend((-3..=3).map(|k| corner(f64::from(k))));
        // (Angles irregular: two points equally far by symmetry are a tie that each store's
        // floating-point distance breaks its own way, and nearest first orders by distance.)
        for i in 0..16 {
            let a = f64::from(i) * std::f64::consts::TAU / 16.0 + 0.013 * f64::from(i * i);
            let d = if i % 2 == 0 { 699.5 } else { 700.5 };
            places.push(at(d * a.cos(), d * a.sin()));
        }
        let sites: Vec<Site> = places
            .iter()
            .enumerate()
            .map(|(i, &center)| {
                let r = radii[(rng.next() % radii.len() as u64) as usize];
                let confirmed = t(60 * (rng.next() % 6) as i64);
                let candidate = i % 9 == 4;
                Site {
                    id: SiteId(0),
                    kind: if candidate {
                        SiteKind::Candidate
                    } else {
                        SiteKind::Confirmed
                    },
                    polygon: Polygon::rectangle(
                        LatLon::new(center.latitude_deg - 1e-4, center.longitude_deg - 1e-4),
                        LatLon::new(center.latitude_deg + 1e-4, center.longitude_deg + 1e-4),
                    ),
                    center,
                    safe_radius_m: r,
                    plane_height_m: 10.0,
                    area_m2: 100.0,
                    first_seen: t(0),
                    last_confirmed: confirmed,
                    frames: 1,
                    approaches: 1,
                    drone_id: "d".into(),
                    approach_id: "a".into(),
                    model_id: "m".into(),
                    source_id: candidate.then(|| format!("b{i}")),
                }
            })
            .collect();
        store.load_sites(&sites).unwrap();
        let records = everything(&*store);
        assert_eq!(records.len(), sites.len());
        let now = t(400);
        let (mut results, mut pages) = (0, 0);
        let widths = [100.0, 150.0, 700.0, 1300.0, 3000.0];
        for case in 0..60 {
            let center = match case % 4 {
                0 => ORIGIN,
                1 => at(300.0, -200.0),
                _ => at(rng.range(-1500.0, 1500.0), rng.range(-1500.0, 1500.0)),
            };
            let mut q = SearchQuery::new(center, widths[case % widths.len()]);
            q.order = [Order::SafeRadius, Order::Freshness, Order::Distance][case % 3];
            q.include_candidates = case % 2 == 1;
            q.min_safe_radius_m = [0.0, 2.5, 3.0][case % 7 % 3];
            q.max_age = match case % 4 {
                0 => None,
                1 => Some(Duration::from_secs(150)),
                _ => Some(Duration::from_secs(86_400)),
            };
            q.page_size = [1, 3, 7, 20][case % 4];
            let (got, n) = paged_like_brute_force(&*store, &records, q, now, case);
            results += got;
            pages += n;
        }
        assert!(
            results > 2000 && pages > 500,
            "{results} results on {pages} pages"
        );
    }

    /// A keyed search finds an updated site where it now is, with its new radius and time, once:
    /// the update moves it 13 m north across a line of the grid (the stores index it anew), and
    /// the search's circle reaches the new place but not the old one's cells.
    pub fn keyed_orders_follow_updates(b: &dyn Backend) {
        let store = b.open();
        let line = (ORIGIN.latitude_deg * 400.0).ceil() / 400.0;
        let north = |m: f64| LatLon::new(line + m / 111_195.0, ORIGIN.longitude_deg);
        let roof = |p: LatLon, r: f64| ObservedSite {
            polygon: Polygon::rectangle(
                LatLon::new(p.latitude_deg - 1e-4, p.longitude_deg - 1e-4),
                LatLon::new(p.latitude_deg + 1e-4, p.longitude_deg + 1e-4),
            ),
            center: p,
            safe_radius_m: r,
            plane_height_m: 10.0,
            frames: 1,
        };
        store
            .apply(&[obs(10, "a", vec![], vec![roof(north(-3.0), 8.0)])])
            .unwrap();
        store
            .apply(&[obs(20, "b", vec![], vec![roof(north(10.0), 9.0)])])
            .unwrap();
        let all = everything(&*store);
        assert_eq!(all.len(), 1, "the same roof, updated");
        assert_eq!(all[0].site.last_confirmed, t(20));
        let far = LocalFrame::new(north(10.0)).to_lat_lon((0.0, 200.0));
        for order in [Order::SafeRadius, Order::Freshness] {
            let mut q = SearchQuery::new(far, 201.0);
            q.order = order;
            let page = store.search(&q, t(30)).unwrap();
            assert_eq!(page.sites.len(), 1, "{order:?}");
            assert_eq!(page.sites[0].site.safe_radius_m, 9.0);
            assert_eq!(page.sites[0].site.last_confirmed, t(20));
        }
    }

    pub fn random_searches_match_brute_force(b: &dyn Backend) {
        let store = b.open();
        let mut rng = Lcg(0x5eed_0001);
        for batch in 0..6 {
            let observations: Vec<Observation> = (0..10)
                .map(|k| {
                    let sites = (0..6)
                        .map(|_| {
                            let (x, y) = (rng.range(-1500.0, 1500.0), rng.range(-1500.0, 1500.0));
                            site(x, y, rng.range(0.5, 9.0), rng.range(0.0, 60.0).round())
                        })
                        .collect();
                    obs(
                        batch * 600 + k * 30,
                        &format!("r{batch}-{k}"),
                        vec![],
                        sites,
                    )
                })
                .collect();
            store.apply(&observations).unwrap();
        }
        let candidates: Vec<Candidate> = (0..25)
            .map(|i| Candidate {
                footprint: square(
                    rng.range(-1500.0, 1500.0),
                    rng.range(-1500.0, 1500.0),
                    rng.range(4.0, 20.0),
                ),
                roof_height_m: 20.0,
                source_id: Some(format!("c{i}")),
            })
            .collect();
        store.import_candidates(&candidates, t(0)).unwrap();
        let records = everything(&*store);
        assert!(records.len() > 250, "{}", records.len());
        let now = t(3600);
        let (mut results, mut pages) = (0, 0);
        for case in 0..40 {
            let mut q = SearchQuery::new(
                at(rng.range(-1200.0, 1200.0), rng.range(-1200.0, 1200.0)),
                rng.range(50.0, 1500.0),
            );
            q.order = [Order::Distance, Order::SafeRadius, Order::Freshness][case % 3];
            q.include_candidates = case % 2 == 0;
            q.min_safe_radius_m = if case % 4 == 1 {
                rng.range(0.0, 6.0)
            } else {
                0.0
            };
            q.max_age = match case % 5 {
                0 => None,
                1 => Some(Duration::from_secs(rng.range(0.0, 3600.0) as u64)),
                _ => Some(Duration::from_secs(86_400)),
            };
            q.page_size = 1 + (rng.next() % 40) as i32;
            let (got, n) = paged_like_brute_force(&*store, &records, q, now, case);
            results += got;
            pages += n;
        }
        // The cases are not vacuous: many results, most searches over several pages.
        assert!(
            results > 1000 && pages > 100,
            "{results} results on {pages} pages"
        );
    }
}

macro_rules! conformance {
    ($store:ident, $backend:expr) => {
        mod $store {
            use super::*;

            #[test]
            fn insert_and_search() {
                suite::insert_and_search(&$backend);
            }
            #[test]
            fn orders_and_filters() {
                suite::orders_and_filters(&$backend);
            }
            #[test]
            fn paging_is_complete_and_stable() {
                suite::paging_is_complete_and_stable(&$backend);
            }
            #[test]
            fn page_tokens_are_checked() {
                suite::page_tokens_are_checked(&$backend);
            }
            #[test]
            fn bad_fields_are_named() {
                suite::bad_fields_are_named(&$backend);
            }
            #[test]
            fn a_bad_batch_writes_nothing() {
                suite::a_bad_batch_writes_nothing(&$backend);
            }
            #[test]
            fn same_roof_is_updated() {
                suite::same_roof_is_updated(&$backend);
            }
            #[test]
            fn unseen_sites_keep_their_age() {
                suite::unseen_sites_keep_their_age(&$backend);
            }
            #[test]
            fn blocked_sites_are_withdrawn() {
                suite::blocked_sites_are_withdrawn(&$backend);
            }
            #[test]
            fn withdrawn_ids_are_not_reused() {
                suite::withdrawn_ids_are_not_reused(&$backend);
            }
            #[test]
            fn older_observations_never_overwrite() {
                suite::older_observations_never_overwrite(&$backend);
            }
            #[test]
            fn candidates_come_after_sites() {
                suite::candidates_come_after_sites(&$backend);
            }
            #[test]
            fn expiry() {
                suite::expiry(&$backend);
            }
            #[test]
            fn two_writers() {
                suite::two_writers(&$backend);
            }
            #[test]
            fn reopen_keeps_everything() {
                suite::reopen_keeps_everything(&$backend);
            }
            #[test]
            fn geojson_results() {
                suite::geojson_results(&$backend);
            }
            #[test]
            fn loaded_sites_are_stored_as_they_are() {
                suite::loaded_sites_are_stored_as_they_are(&$backend);
            }
            #[test]
            fn random_searches_match_brute_force() {
                suite::random_searches_match_brute_force(&$backend);
            }
            #[test]
            fn keyed_orders_with_ties_match_brute_force() {
                suite::keyed_orders_with_ties_match_brute_force(&$backend);
            }
            #[test]
            fn keyed_orders_follow_updates() {
                suite::keyed_orders_follow_updates(&$backend);
            }
        }
    };
}

conformance!(sqlite, Sqlite::new());
conformance!(postgis, Postgis::new());

/// What only one store has: files, schema versions, connections.
mod specific {
    use super::scene::*;
    use super::*;

    #[test]
    fn sqlite_file_is_wal_versioned_and_checked() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("catalog.sqlite");
        let store = SqliteStore::open(&path).unwrap();
        assert_eq!(store.schema_version().unwrap(), 4);
        store
            .apply(&[obs(10, "a", vec![], vec![site(0.0, 0.0, 3.0, 10.0)])])
            .unwrap();
        store.check_integrity().unwrap();
        drop(store);
        let raw = rusqlite::Connection::open(&path).unwrap();
        let mode: String = raw
            .query_row("PRAGMA journal_mode", [], |r| r.get(0))
            .unwrap();
        assert_eq!(mode, "wal");
        // A file from a newer build is refused, not misread.
        raw.execute("INSERT INTO schema_version (version) VALUES (99)", [])
            .unwrap();
        drop(raw);
        let e = SqliteStore::open(&path).unwrap_err();
        assert!(
            matches!(e, Error::Corrupt { .. }) && e.to_string().contains("99"),
            "{e}"
        );
    }

    /// A file written at schema version 1 (the R*Tree without auxiliary columns) is migrated
    /// on open and answers as before.
    #[test]
    fn sqlite_version_1_file_is_migrated() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("catalog.sqlite");
        let raw = rusqlite::Connection::open(&path).unwrap();
        raw.execute_batch(
            "CREATE TABLE schema_version (version INTEGER NOT NULL);
             INSERT INTO schema_version VALUES (1);
             CREATE TABLE sites (id INTEGER PRIMARY KEY, kind INTEGER NOT NULL, polygon TEXT NOT NULL,
                 latitude_deg REAL NOT NULL, longitude_deg REAL NOT NULL, safe_radius_m REAL NOT NULL,
                 plane_height_m REAL NOT NULL, area_m2 REAL NOT NULL, first_seen_ms INTEGER NOT NULL,
                 last_confirmed_ms INTEGER NOT NULL, frames INTEGER NOT NULL,
                 approaches INTEGER NOT NULL, drone_id TEXT NOT NULL, approach_id TEXT NOT NULL,
                 model_id TEXT NOT NULL, source_id TEXT UNIQUE);
             CREATE INDEX sites_kind_last_confirmed ON sites (kind, last_confirmed_ms);
             CREATE VIRTUAL TABLE sites_rtree USING rtree (id, min_lat, max_lat, min_lon, max_lon);
             CREATE TABLE seen (id INTEGER PRIMARY KEY, observed_ms INTEGER NOT NULL,
                 polygon TEXT NOT NULL);
             CREATE INDEX seen_observed ON seen (observed_ms);
             CREATE VIRTUAL TABLE seen_rtree USING rtree (id, min_lat, max_lat, min_lon, max_lon);",
        )
        .unwrap();
        let s = site(0.0, 0.0, 3.0, 10.0);
        let polygon = geojson::polygon_geometry(&s.polygon, false).to_string();
        let (lat, lon) = (s.center.latitude_deg, s.center.longitude_deg);
        raw.execute(
            "INSERT INTO sites VALUES (7, 0, ?1, ?2, ?3, 3.0, 10.0, 64.0, ?4, ?4, 1, 1, 'd', 'a', \
             'm', NULL)",
            rusqlite::params![polygon, lat, lon, t(10).unix_ms()],
        )
        .unwrap();
        raw.execute(
            "INSERT INTO sites_rtree VALUES (7, ?1, ?2, ?3, ?4)",
            rusqlite::params![lat - 0.001, lat + 0.001, lon - 0.001, lon + 0.001],
        )
        .unwrap();
        drop(raw);
        let store = SqliteStore::open(&path).unwrap();
        assert_eq!(store.schema_version().unwrap(), 4);
        store.check_integrity().unwrap();
        let page = store
            .search(&SearchQuery::new(ORIGIN, 100.0), t(20))
            .unwrap();
        assert_eq!(page.sites.len(), 1);
        assert_eq!(page.sites[0].site.id.0, 7);
        assert_eq!(page.sites[0].site.safe_radius_m, 3.0);
    }

    /// Records for the migration tests: spread over a few of the grid's cells (west of
    /// Greenwich and north of the equator, so a wrong floor shows), radii and times varied.
    fn spread_sites() -> Vec<Site> {
        let mut rng = Lcg(0x5eed_0003);
        (0..200)
            .map(|i| {
                let center = at(rng.range(-900.0, 900.0), rng.range(-900.0, 900.0));
                Site {
                    id: SiteId(0),
                    kind: SiteKind::Confirmed,
                    polygon: Polygon::rectangle(
                        LatLon::new(center.latitude_deg - 1e-4, center.longitude_deg - 1e-4),
                        LatLon::new(center.latitude_deg + 1e-4, center.longitude_deg + 1e-4),
                    ),
                    center,
                    safe_radius_m: rng.range(1.0, 15.0),
                    plane_height_m: 10.0,
                    area_m2: 100.0,
                    first_seen: t(0),
                    last_confirmed: t(i64::from(i % 50)),
                    frames: 1,
                    approaches: 1,
                    drone_id: "d".into(),
                    approach_id: "a".into(),
                    model_id: "m".into(),
                    source_id: None,
                }
            })
            .collect()
    }

    /// Both keyed orders over a migrated store page like brute force.
    fn keyed_orders_answer(store: &dyn Store) {
        let records = everything(store);
        assert_eq!(records.len(), 200);
        for (case, order) in [Order::SafeRadius, Order::Freshness]
            .into_iter()
            .enumerate()
        {
            let mut q = SearchQuery::new(at(100.0, -50.0), 600.0);
            q.order = order;
            q.page_size = 9;
            let (got, pages) = paged_like_brute_force(store, &records, q, t(60), case);
            assert!(got > 50 && pages > 5, "{got} results on {pages} pages");
        }
    }

    /// A file written at schema version 2 (no grid cells, no keyed indexes) is migrated on open:
    /// every site gets its cell, and the keyed orders answer as brute force.
    #[test]
    fn sqlite_version_2_file_is_migrated() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("catalog.sqlite");
        SqliteStore::open(&path)
            .unwrap()
            .load_sites(&spread_sites())
            .unwrap();
        // Back to version 2's columns and indexes (the ids aside: version 4 made them AUTOINCREMENT).
        let raw = rusqlite::Connection::open(&path).unwrap();
        raw.execute_batch(
            "DROP INDEX sites_by_radius; DROP INDEX sites_by_freshness;
             ALTER TABLE sites DROP COLUMN cell; DELETE FROM schema_version WHERE version >= 3;",
        )
        .unwrap();
        drop(raw);
        let store = SqliteStore::open(&path).unwrap();
        assert_eq!(store.schema_version().unwrap(), 4);
        store.check_integrity().unwrap();
        keyed_orders_answer(&store);
    }

    /// A database at schema version 1 (no `btree_gist`, no keyed indexes) is migrated at connect.
    #[test]
    fn postgis_version_1_schema_is_migrated() {
        let server = pg::shared();
        let url = server.create_database();
        PostgisStore::connect(&url)
            .unwrap()
            .load_sites(&spread_sites())
            .unwrap();
        let mut raw = postgres::Client::connect(&url, postgres::NoTls).unwrap();
        raw.batch_execute(
            "DROP INDEX catalog_sites_keys; DROP INDEX catalog_sites_radius;
             DROP EXTENSION btree_gist;
             DELETE FROM catalog_schema_version WHERE version = 2;",
        )
        .unwrap();
        drop(raw);
        let store = PostgisStore::connect(&url).unwrap();
        assert_eq!(store.schema_version().unwrap(), 2);
        store.check_integrity().unwrap();
        keyed_orders_answer(&store);
    }

    #[test]
    fn sqlite_integrity_check_finds_a_broken_index() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("catalog.sqlite");
        let store = SqliteStore::open(&path).unwrap();
        store
            .apply(&[obs(10, "a", vec![], vec![site(0.0, 0.0, 3.0, 10.0)])])
            .unwrap();
        let raw = rusqlite::Connection::open(&path).unwrap();
        raw.execute("DELETE FROM sites_rtree", []).unwrap();
        let e = store.check_integrity().unwrap_err();
        assert!(matches!(e, Error::Corrupt { .. }), "{e}");
    }

    #[test]
    fn postgis_reconnects_after_losing_its_connection() {
        let server = pg::shared();
        let url = server.create_database();
        let store = PostgisStore::connect(&url).unwrap();
        assert_eq!(store.schema_version().unwrap(), 2);
        store
            .apply(&[obs(10, "a", vec![], vec![site(0.0, 0.0, 3.0, 10.0)])])
            .unwrap();
        // The server ends every session of the store's database (a restart, a failover).
        let mut admin =
            postgres::Client::connect(&server.url("postgres"), postgres::NoTls).unwrap();
        let dbname = url
            .rsplit("dbname=")
            .next()
            .unwrap()
            .split(' ')
            .next()
            .unwrap()
            .to_string();
        admin
            .execute(
                "SELECT pg_terminate_backend(pid) FROM pg_stat_activity WHERE datname = $1",
                &[&dbname],
            )
            .unwrap();
        // The call that meets the dead connection fails as unavailable storage; the next one
        // connects again.
        let mut answered = false;
        for _ in 0..3 {
            match store.search(&SearchQuery::new(ORIGIN, 100.0), t(20)) {
                Ok(page) => {
                    assert_eq!(page.sites.len(), 1);
                    answered = true;
                    break;
                }
                Err(e) => assert!(
                    matches!(
                        e,
                        Error::Storage {
                            backend: "postgis",
                            ..
                        }
                    ),
                    "{e}"
                ),
            }
        }
        assert!(answered, "the store connected again");
    }
}
