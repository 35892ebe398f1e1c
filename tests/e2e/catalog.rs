//! The fleet's catalog over real gRPC with a real SQLite file: a fused approach with a geodetic
//! origin fills it and `SearchLandingSites` finds its sites with their ages and distances; a frame
//! without an origin is answered and counted, not catalogued; malformed searches get
//! INVALID_ARGUMENT naming the field; a catalog whose database is down leaves frames answered and
//! searches UNAVAILABLE naming the catalog.

use std::time::{Duration, Instant, SystemTime};

use landing_client::v1::landing_service_client::LandingServiceClient;
use landing_client::v1::{self, SegmentationMode};
use landing_client::{
    FrameOutcome, PointCloudBuilder, StreamConfig, StreamItem, unpack_point_cloud,
};
use landing_server::Config;
use landing_server::telemetry::scrape;
use tonic::transport::Channel;
use tonic_types::StatusExt as _;

use crate::support::{TestServer, landing, mode, scene, scratch, server_config, stream_with};

/// Where the test frames' world origin lies: midtown Manhattan, 10 m above the ellipsoid.
const ORIGIN: v1::GeodeticPoint = v1::GeodeticPoint {
    latitude_deg: 40.7484,
    longitude_deg: -73.9857,
    altitude_m: 10.0,
};

/// A server whose catalog is the SQLite file `name` in the scratch directory, writing at once.
fn catalog_config(name: &str) -> Config {
    let mut c = server_config();
    c.server.metrics_listen = "127.0.0.1:0".into();
    c.catalog.enabled = true;
    c.catalog.path = scratch().join(name);
    let _ = std::fs::remove_file(&c.catalog.path);
    c.catalog.flush_interval_s = 0.05;
    c.catalog.observe_interval_s = 0.0;
    c
}

/// A fused approach over `seed`'s frames, each with `origin`.
async fn approach(
    server: &TestServer,
    seed: u64,
    origin: Option<v1::GeodeticPoint>,
) -> Vec<StreamItem> {
    let frames: Vec<v1::Frame> = scene(seed)
        .frames
        .iter()
        .map(|f| v1::Frame {
            geodetic_origin: origin,
            ..f.frame.clone()
        })
        .collect();
    let items = approach_over(server, frames).await;
    for item in &items {
        assert!(
            matches!(item.outcome, FrameOutcome::Result(_)),
            "every frame is answered: {:?}",
            item.outcome
        );
    }
    items
}

/// A fused approach over `frames`, classes from the points (the simulator's).
async fn approach_over(server: &TestServer, frames: Vec<v1::Frame>) -> Vec<StreamItem> {
    let config = StreamConfig {
        max_in_flight: 4,
        ..StreamConfig::fused().with_options(mode(SegmentationMode::PointClasses))
    };
    stream_with(server, frames, config, None).await
}

/// `seed`'s frames with `origin`, every point classed as a tarp: the roofs covered.
fn covered(seed: u64) -> Vec<v1::Frame> {
    let tarp = landing_geometry::SemanticClass::Tarp as u8;
    scene(seed)
        .frames
        .iter()
        .map(|f| {
            let mut frame = f.frame.clone();
            let cloud = frame.point_cloud.take().unwrap();
            let points = unpack_point_cloud(&cloud).unwrap().points;
            let classes = vec![tarp; points.len()];
            let packed = PointCloudBuilder::new(&points)
                .classes(&classes)
                .build()
                .unwrap();
            frame.point_cloud = Some(v1::PointCloud {
                fields: packed.fields,
                point_stride: packed.point_stride,
                data: packed.data,
                ..cloud
            });
            frame.geodetic_origin = Some(ORIGIN);
            frame
        })
        .collect()
}

async fn raw_client(server: &TestServer) -> LandingServiceClient<Channel> {
    let channel = Channel::from_shared(server.url.clone())
        .unwrap()
        .connect()
        .await
        .expect("connect");
    LandingServiceClient::new(channel)
}

fn search_near(center: v1::GeodeticPoint, radius_m: f64) -> v1::SearchLandingSitesRequest {
    v1::SearchLandingSitesRequest {
        center: Some(center),
        radius_m,
        ..Default::default()
    }
}

/// Searches until the catalog returns something (the writer runs beside the stream), for at
/// most ten seconds.
async fn search_until_found(
    client: &mut LandingServiceClient<Channel>,
    request: v1::SearchLandingSitesRequest,
) -> v1::SearchLandingSitesResponse {
    let give_up = Instant::now() + Duration::from_secs(10);
    loop {
        let page = client
            .search_landing_sites(request.clone())
            .await
            .expect("search")
            .into_inner();
        if !page.sites.is_empty() || Instant::now() > give_up {
            return page;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// Waits until the catalog has written what the streams so far sent it: an empty queue and no
/// new write for 300 ms (a stream's last observation is queued as its stream closes).
async fn settle(server: &TestServer) {
    let addr = server.metrics_addr().expect("metrics enabled");
    let read = || async move {
        let text = scrape(addr).await.unwrap();
        (
            value(&text, "landing_catalog_queue_depth"),
            value(&text, "landing_catalog_writes_total"),
            value(&text, "landing_catalog_dropped_total"),
        )
    };
    let give_up = Instant::now() + Duration::from_secs(10);
    let mut last = read().await;
    loop {
        tokio::time::sleep(Duration::from_millis(300)).await;
        let now = read().await;
        if (now == last && now.0 == Some(0.0)) || Instant::now() > give_up {
            return;
        }
        last = now;
    }
}

/// The value of the series written exactly as `series`, if present.
fn value(text: &str, series: &str) -> Option<f64> {
    text.lines()
        .find_map(|l| l.strip_prefix(series)?.strip_prefix(' '))
        .map(|v| v.trim().parse().expect("a number"))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_fused_approach_with_an_origin_fills_the_catalog_and_a_search_finds_it() {
    let server = TestServer::with_config(catalog_config("fill.sqlite")).await;
    let mut client = raw_client(&server).await;
    let before = SystemTime::now();

    // Without an origin: answered as always, counted, not catalogued.
    let plain = approach(&server, 41, None).await;
    let metrics = scrape(server.metrics_addr().unwrap()).await.unwrap();
    let no_origin = "landing_catalog_frames_total{outcome=\"no_geodetic_origin\"}";
    assert_eq!(value(&metrics, no_origin), Some(plain.len() as f64));

    let items = approach(&server, 41, Some(ORIGIN)).await;
    let last = items.last().and_then(|i| i.outcome.result()).unwrap();
    assert!(!last.sites.is_empty(), "the approach finds sites");
    settle(&server).await;
    let page = search_until_found(&mut client, search_near(ORIGIN, 500.0)).await;
    assert!(
        !page.sites.is_empty(),
        "the catalog knows the approach's sites"
    );
    let now = SystemTime::now();
    let mut previous = 0.0;
    for site in &page.sites {
        assert_eq!(site.kind, v1::SiteKind::Site as i32);
        // Every catalog site is one of the approach's answers', at the same place (the last
        // answer's, unless that answer did not resolve its ground).
        let center = site.center.unwrap();
        let answered = items
            .iter()
            .filter_map(|i| i.outcome.result())
            .flat_map(|r| &r.sites)
            .filter_map(|s| s.center_geodetic)
            .any(|g| {
                (g.latitude_deg - center.latitude_deg).abs() < 1e-9
                    && (g.longitude_deg - center.longitude_deg).abs() < 1e-9
            });
        assert!(answered, "{site:?}");
        assert!(
            site.frames >= 3,
            "confirmed by min_frames answers: {site:?}"
        );
        assert_eq!(site.approaches, 1);
        assert_eq!(site.drone_id, "e2e-41");
        let confirmed = SystemTime::try_from(site.last_confirmed.unwrap()).unwrap();
        assert!(
            before <= confirmed && confirmed <= now,
            "the server's clock"
        );
        assert!(site.polygon.first().is_some_and(|r| r.points.len() >= 3));
        // Nearest first, with the distance from the search's centre.
        assert!(site.distance_m >= previous && site.distance_m <= 500.0);
        previous = site.distance_m;
    }
    let metrics = scrape(server.metrics_addr().unwrap()).await.unwrap();
    let sites = value(&metrics, "landing_catalog_sites{kind=\"site\"}").unwrap();
    assert_eq!(sites, page.sites.len() as f64, "{metrics}");
    assert_eq!(value(&metrics, "landing_catalog_connected"), Some(1.0));
    assert!(value(&metrics, "landing_catalog_writes_total").unwrap() >= 1.0);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn malformed_searches_name_their_field() {
    let server = TestServer::with_config(catalog_config("malformed.sqlite")).await;
    let mut client = raw_client(&server).await;
    // Wait until the writer thread has opened the store, so the cases below meet a live catalog.
    let give_up = Instant::now() + Duration::from_secs(10);
    while let Err(status) = client
        .search_landing_sites(search_near(ORIGIN, 500.0))
        .await
    {
        assert_eq!(status.code(), tonic::Code::Unavailable, "{status:?}");
        assert!(Instant::now() < give_up, "the catalog never opened");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let at = |latitude_deg: f64| v1::GeodeticPoint {
        latitude_deg,
        ..ORIGIN
    };
    let cases: Vec<(v1::SearchLandingSitesRequest, &str)> = vec![
        (search_near(at(91.0), 500.0), "center.latitude_deg"),
        (search_near(ORIGIN, -1.0), "radius_m"),
        (
            v1::SearchLandingSitesRequest {
                page_size: -1,
                ..search_near(ORIGIN, 500.0)
            },
            "page_size",
        ),
        (
            v1::SearchLandingSitesRequest {
                page_token: "bm90IGEgdG9rZW4".into(),
                ..search_near(ORIGIN, 500.0)
            },
            "page_token",
        ),
        (
            v1::SearchLandingSitesRequest {
                center: None,
                ..search_near(ORIGIN, 500.0)
            },
            "center",
        ),
        (
            v1::SearchLandingSitesRequest {
                max_age: Some(prost_types::Duration {
                    seconds: -1,
                    nanos: 0,
                }),
                ..search_near(ORIGIN, 500.0)
            },
            "max_age",
        ),
    ];
    for (request, field) in cases {
        let status = client.search_landing_sites(request).await.unwrap_err();
        assert_eq!(
            status.code(),
            tonic::Code::InvalidArgument,
            "{field}: {status:?}"
        );
        let details = status.get_error_details();
        let fields: Vec<&str> = details
            .bad_request()
            .map(|b| {
                b.field_violations
                    .iter()
                    .map(|v| v.field.as_str())
                    .collect()
            })
            .unwrap_or_default();
        assert_eq!(fields, vec![field], "{status:?}");
    }
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_tampered_page_token_is_refused() {
    let server = TestServer::with_config(catalog_config("tokens.sqlite")).await;
    approach(&server, 41, Some(ORIGIN)).await;
    settle(&server).await;
    let mut client = raw_client(&server).await;
    let first = v1::SearchLandingSitesRequest {
        page_size: 1,
        ..search_near(ORIGIN, 500.0)
    };
    let page = search_until_found(&mut client, first.clone()).await;
    assert_eq!(page.sites.len(), 1);
    if page.next_page_token.is_empty() {
        // One site only: there is no token to tamper with (the malformed case covers a forged one).
        server.stop().await;
        return;
    }
    let mut token: Vec<char> = page.next_page_token.chars().collect();
    token[5] = if token[5] == 'A' { 'B' } else { 'A' };
    let tampered = v1::SearchLandingSitesRequest {
        page_token: token.into_iter().collect(),
        ..first.clone()
    };
    let status = client.search_landing_sites(tampered).await.unwrap_err();
    assert_eq!(status.code(), tonic::Code::InvalidArgument);
    let details = status.get_error_details();
    assert_eq!(
        details.bad_request().unwrap().field_violations[0].field,
        "page_token"
    );
    // The genuine token gives the next page, with another site.
    let next = v1::SearchLandingSitesRequest {
        page_token: page.next_page_token.clone(),
        ..first
    };
    let second = client
        .search_landing_sites(next)
        .await
        .unwrap()
        .into_inner();
    assert_eq!(second.sites.len(), 1);
    assert_ne!(second.sites[0].id, page.sites[0].id);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn with_the_database_down_frames_are_answered_and_searches_are_unavailable() {
    // A port nothing listens on.
    let port = {
        let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        l.local_addr().unwrap().port()
    };
    let mut config = catalog_config("unused.sqlite");
    config.catalog.url = format!("postgres://landing@127.0.0.1:{port}/catalog?connect_timeout=2");
    config.catalog.retry_interval_s = 0.2;
    let server = TestServer::with_config(config).await;
    let items = approach(&server, 41, Some(ORIGIN)).await;
    assert!(items.iter().all(|i| i.outcome.result().is_some()));
    let mut client = raw_client(&server).await;
    let status = client
        .search_landing_sites(search_near(ORIGIN, 500.0))
        .await
        .unwrap_err();
    assert_eq!(status.code(), tonic::Code::Unavailable, "{status:?}");
    assert!(status.message().contains("catalog"), "{}", status.message());
    // A bad request is the caller's to fix, database or not.
    let bad_center = v1::GeodeticPoint {
        latitude_deg: 91.0,
        ..ORIGIN
    };
    let status = client
        .search_landing_sites(search_near(bad_center, 500.0))
        .await
        .unwrap_err();
    assert_eq!(status.code(), tonic::Code::InvalidArgument, "{status:?}");
    let details = status.get_error_details();
    let violation = details
        .bad_request()
        .map(|b| b.field_violations[0].field.as_str());
    assert_eq!(violation, Some("center.latitude_deg"), "{status:?}");
    let metrics = scrape(server.metrics_addr().unwrap()).await.unwrap();
    assert_eq!(value(&metrics, "landing_catalog_connected"), Some(0.0));
    assert!(value(&metrics, "landing_catalog_write_failures_total").unwrap() >= 1.0);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_server_without_a_catalog_says_so() {
    let server = TestServer::start().await;
    let mut client = raw_client(&server).await;
    let status = client
        .search_landing_sites(search_near(ORIGIN, 500.0))
        .await
        .unwrap_err();
    assert_eq!(status.code(), tonic::Code::Unavailable);
    assert!(
        status.message().contains("catalog.enabled"),
        "{}",
        status.message()
    );
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_cli_imports_candidates_and_lists_them_as_a_table_json_and_geojson() {
    let config = catalog_config("cli.sqlite");
    let store = config.catalog.path.display().to_string();
    let server = TestServer::with_config(config).await;
    // A 30 m x 20 m footprint about 100 m north-east of the origin, 45 m high.
    let (lat, lon) = (ORIGIN.latitude_deg + 0.0009, ORIGIN.longitude_deg + 0.0012);
    let (dlat, dlon) = (0.00009, 0.00018);
    let ring = [
        [lon, lat],
        [lon + dlon, lat],
        [lon + dlon, lat + dlat],
        [lon, lat + dlat],
        [lon, lat],
    ];
    let footprints = serde_json::json!({
        "type": "FeatureCollection",
        "features": [{
            "type": "Feature",
            "id": "bldg-1",
            "geometry": { "type": "Polygon", "coordinates": [ring] },
            "properties": { "height": 45.0 },
        }],
    });
    let file = scratch().join("footprints.geojson");
    std::fs::write(&file, footprints.to_string()).unwrap();
    let (code, out) = landing(&[
        "catalog",
        "import",
        file.to_str().unwrap(),
        "--catalog",
        &store,
    ])
    .await;
    assert_eq!(code, 0, "{out}");
    assert!(out.contains("imported 1 candidate roofs"), "{out}");

    let near = format!("{},{}", ORIGIN.latitude_deg, ORIGIN.longitude_deg);
    let search = ["sites", "--near", &near, "--radius", "500", "--candidates"];
    let with = |extra: &[&str]| {
        let mut args = vec!["--server", server.url.as_str()];
        args.extend_from_slice(&search);
        args.extend_from_slice(extra);
        args.into_iter().map(str::to_owned).collect::<Vec<_>>()
    };
    let run = |args: Vec<String>| async move {
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        landing(&refs).await
    };
    let (code, table) = run(with(&[])).await;
    assert_eq!(code, 0, "{table}");
    assert!(
        table.contains("candidate") && table.contains("never a clearance"),
        "{table}"
    );
    let (code, json) = run(with(&["--json"])).await;
    assert_eq!(code, 0, "{json}");
    let json: serde_json::Value = serde_json::from_str(&json).unwrap();
    let site = &json["sites"][0];
    assert_eq!(site["kind"], "candidate");
    let distance = site["distance_m"].as_f64().unwrap();
    assert!((100.0..200.0).contains(&distance), "{site}");
    let (code, geojson) = run(with(&["--geojson"])).await;
    assert_eq!(code, 0, "{geojson}");
    let geojson: serde_json::Value = serde_json::from_str(&geojson).unwrap();
    assert_eq!(geojson["type"], "FeatureCollection");
    let feature = &geojson["features"][0];
    assert_eq!(feature["geometry"]["type"], "Polygon");
    let ring = feature["geometry"]["coordinates"][0].as_array().unwrap();
    assert_eq!(ring.first(), ring.last(), "closed ring");
    assert_eq!(feature["properties"]["kind"], "candidate");

    let (code, out) = run(vec![
        "--server".into(),
        server.url.clone(),
        "sites".into(),
        "--near".into(),
        "91,0".into(),
        "--radius".into(),
        "500".into(),
    ])
    .await;
    assert_eq!(code, 1, "{out}");
    server.stop().await;
}

#[path = "../../catalog/tests/support/postgres.rs"]
#[allow(dead_code)]
mod pg;

/// A fresh PostGIS database on the shared test server, as a `postgres://` URL.
fn postgis_url(server: &pg::PgServer) -> String {
    let conninfo = server.create_database();
    let field = |key: &str| {
        conninfo
            .split_whitespace()
            .find_map(|kv| kv.strip_prefix(key)?.strip_prefix('='))
            .expect("a conninfo field")
            .to_owned()
    };
    format!(
        "postgres://postgres@127.0.0.1:{}/{}?connect_timeout=10",
        field("port"),
        field("dbname")
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_fused_approach_fills_a_postgis_catalog_and_a_search_finds_it() {
    // The PostgreSQL client runs a runtime of its own: off this one.
    let (postgres, url) = tokio::task::spawn_blocking(|| {
        let postgres = pg::shared();
        let url = postgis_url(&postgres);
        (postgres, url)
    })
    .await
    .unwrap();
    let mut config = catalog_config("postgis-unused.sqlite");
    config.catalog.url = url;
    let server = TestServer::with_config(config).await;
    approach(&server, 41, Some(ORIGIN)).await;
    let mut client = raw_client(&server).await;
    let page = search_until_found(&mut client, search_near(ORIGIN, 500.0)).await;
    assert!(
        !page.sites.is_empty(),
        "the PostGIS catalog knows the approach's sites"
    );
    assert!(
        page.sites
            .iter()
            .all(|s| s.kind == v1::SiteKind::Site as i32 && s.distance_m <= 500.0 && s.frames >= 3)
    );
    let metrics = scrape(server.metrics_addr().unwrap()).await.unwrap();
    assert_eq!(value(&metrics, "landing_catalog_connected"), Some(1.0));
    server.stop().await;
    // The server stops where it may block.
    tokio::task::spawn_blocking(move || drop(postgres))
        .await
        .unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_later_approach_that_finds_the_roofs_covered_withdraws_their_sites() {
    let server = TestServer::with_config(catalog_config("withdraw.sqlite")).await;
    approach(&server, 41, Some(ORIGIN)).await;
    settle(&server).await;
    let mut client = raw_client(&server).await;
    let before = search_until_found(&mut client, search_near(ORIGIN, 500.0)).await;
    assert!(!before.sites.is_empty());

    // The same approach again, the roofs under a tarp: no site, and every one is withdrawn.
    let items = approach_over(&server, covered(41)).await;
    settle(&server).await;
    assert!(
        items
            .iter()
            .all(|i| i.outcome.result().is_some_and(|r| r.sites.is_empty())),
        "nothing is landable under a tarp"
    );
    let give_up = Instant::now() + Duration::from_secs(10);
    let after = loop {
        let page = client
            .search_landing_sites(search_near(ORIGIN, 500.0))
            .await
            .unwrap()
            .into_inner();
        if page.sites.is_empty() || Instant::now() > give_up {
            break page;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    };
    assert!(
        after.sites.is_empty(),
        "withdrawn at once: {:?}",
        after.sites
    );
    let metrics = scrape(server.metrics_addr().unwrap()).await.unwrap();
    let withdrawn = "landing_catalog_site_changes_total{change=\"withdrawn\"}";
    assert_eq!(
        value(&metrics, withdrawn),
        Some(before.sites.len() as f64),
        "{metrics}"
    );
    server.stop().await;
}
