//! The Foxglove live view (`server.foxglove_listen`), seen by a WebSocket client of our own that
//! speaks the Foxglove protocol (`foxglove.sdk.v1`): it reads the channel adverts, subscribes,
//! and decodes what the server publishes for a frame it answers.

use std::time::Duration;

use futures_util::{SinkExt as _, StreamExt as _};
use landing_client::v1::SegmentationMode;
use landing_recording::foxglove_messages as fox;
use landing_server::telemetry::scrape;
use prost::Message as _;
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::{self, client::IntoClientRequest as _};

use crate::support::{TestServer, mode, scene, server_config};

type Socket =
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

/// Connects as a viewer and waits for the adverts of `topics`; returns their channel ids.
async fn connect(addr: std::net::SocketAddr, topics: &[&str]) -> (Socket, Vec<u64>) {
    let mut request = format!("ws://{addr}")
        .into_client_request()
        .expect("request");
    request.headers_mut().insert(
        "sec-websocket-protocol",
        "foxglove.sdk.v1".parse().expect("header"),
    );
    let (mut ws, response) = tokio_tungstenite::connect_async(request)
        .await
        .expect("connect to the live view");
    assert_eq!(
        response.headers()["sec-websocket-protocol"],
        "foxglove.sdk.v1"
    );
    let mut ids = vec![None; topics.len()];
    while ids.iter().any(Option::is_none) {
        let message = tokio::time::timeout(Duration::from_secs(10), ws.next())
            .await
            .expect("adverts within 10 s")
            .expect("open")
            .expect("a message");
        let tungstenite::Message::Text(text) = message else {
            continue;
        };
        let v: Value = serde_json::from_str(&text).expect("JSON");
        if v["op"] != "advertise" {
            continue;
        }
        for channel in v["channels"].as_array().expect("channels") {
            if let Some(i) = topics.iter().position(|t| channel["topic"] == *t) {
                assert_eq!(channel["encoding"], "protobuf");
                assert!(
                    channel["schemaName"]
                        .as_str()
                        .is_some_and(|s| s.starts_with("foxglove.")),
                    "{channel}"
                );
                ids[i] = channel["id"].as_u64();
            }
        }
    }
    (ws, ids.into_iter().map(Option::unwrap).collect())
}

/// The next binary message: (subscription id, log time, payload).
async fn next_message(ws: &mut Socket) -> Option<(u32, u64, Vec<u8>)> {
    loop {
        match ws.next().await?.ok()? {
            tungstenite::Message::Binary(b) if b.first() == Some(&0x01) => {
                let sub = u32::from_le_bytes(b[1..5].try_into().ok()?);
                let time = u64::from_le_bytes(b[5..13].try_into().ok()?);
                return Some((sub, time, b[13..].to_vec()));
            }
            _ => continue,
        }
    }
}

fn counter(text: &str, name: &str) -> f64 {
    text.lines()
        .find_map(|l| l.strip_prefix(name)?.strip_prefix(' '))
        .map_or(f64::NAN, |v| v.trim().parse().expect("a number"))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_viewer_sees_the_sites_and_the_scan_of_each_answered_frame() {
    let mut config = server_config();
    config.server.foxglove_listen = "127.0.0.1:0".into();
    config.server.metrics_listen = "127.0.0.1:0".into();
    let server = TestServer::with_config(config).await;
    let addr = server.foxglove_addr().expect("live view enabled");
    let metrics = server.metrics_addr().expect("metrics");
    let client = server.client().await;
    let s = scene(71);
    let options = mode(SegmentationMode::PointClasses);
    let detect = |i: usize| {
        let client = client.clone();
        let frame = s.frames[i % s.frames.len()].frame.clone();
        let options = options.clone();
        async move {
            client
                .detect_with(frame, Some(options))
                .await
                .expect("detect")
        }
    };

    // Nobody watching: the frame is answered and nothing is published.
    detect(0).await;
    let text = scrape(metrics).await.expect("scrape");
    assert_eq!(counter(&text, "landing_live_view_frames_total"), 0.0);

    let (mut ws, ids) = connect(addr, &["/landing/sites", "/lidar/points"]).await;
    let subscribe = json!({
        "op": "subscribe",
        "subscriptions": [
            { "id": 1, "channelId": ids[0] },
            { "id": 2, "channelId": ids[1] },
        ],
    });
    ws.send(tungstenite::Message::Text(subscribe.to_string().into()))
        .await
        .expect("subscribe");

    // The subscription takes effect asynchronously: answer frames until one is shown.
    let mut sent = 1;
    let (mut scene_update, mut cloud) = (None, None);
    let deadline = tokio::time::Instant::now() + Duration::from_secs(60);
    while scene_update.is_none() || cloud.is_none() {
        assert!(
            tokio::time::Instant::now() < deadline,
            "nothing shown in 60 s"
        );
        let result = detect(sent).await;
        let frame = &s.frames[sent % s.frames.len()].frame;
        sent += 1;
        while let Ok(Some((sub, time, payload))) =
            tokio::time::timeout(Duration::from_millis(500), next_message(&mut ws)).await
        {
            let ts = frame.timestamp.expect("timestamp");
            if time != landing_recording::log_time_ns(&ts) {
                continue; // an earlier frame's message
            }
            match sub {
                1 => {
                    scene_update = Some((
                        fox::SceneUpdate::decode(&payload[..]).expect("a SceneUpdate"),
                        result.clone(),
                    ))
                }
                2 => {
                    cloud = Some((
                        fox::PointCloud::decode(&payload[..]).expect("a PointCloud"),
                        frame.clone(),
                    ))
                }
                other => panic!("subscription {other}"),
            }
        }
    }

    // The sites, as the service answered them.
    let (update, result) = scene_update.expect("shown");
    assert!(!result.sites.is_empty(), "the scene has sites to show");
    assert_eq!(update.entities.len(), result.sites.len());
    for (entity, site) in update.entities.iter().zip(&result.sites) {
        assert_eq!(entity.frame_id, "world");
        assert_eq!(entity.id, format!("site-{}", site.rank));
        let text = &entity.texts[0].text;
        assert!(
            text.contains(&format!("#{}", site.rank))
                && text.contains(&format!("{:.1} m", site.safe_radius_m)),
            "{text}"
        );
        assert!(
            !entity.triangles[0].points.is_empty(),
            "the polygon is filled"
        );
    }
    // The scan, as the drone sent it.
    let (cloud, frame) = cloud.expect("shown");
    let sent_cloud = frame.point_cloud.as_ref().expect("cloud");
    assert_eq!(cloud.frame_id, "lidar");
    assert_eq!(&cloud.data[..], &sent_cloud.data[..]);

    let text = scrape(metrics).await.expect("scrape");
    assert!(
        counter(&text, "landing_live_view_frames_total") >= 1.0,
        "{text}"
    );
    drop(ws);
    server.stop().await;
}
