//! The `landing` command line against a real server: each subcommand, its output, its exit code.

use std::path::PathBuf;

use landing_cli::exit;
use landing_cli::render::{RenderConfig, STAR_YELLOW, render};
use landing_client::v1::{self, SegmentationMode};
use landing_client::{FrameBuilder, PointCloudBuilder, unpack_point_cloud};
use landing_recording::{ANNOTATIONS_TOPIC, RESULT_TOPIC, SITES_TOPIC};
use prost::Message;
use serde_json::Value;

use crate::support::{TestServer, in_process, landing, mode, scene, scratch, untimed};

fn out_path(name: &str) -> PathBuf {
    scratch().join(name)
}

/// The sites of a result as (radius, centre) pairs, for comparing JSON with protobuf.
fn sites_of(r: &v1::FrameResult) -> Vec<(f64, [f64; 3])> {
    r.sites
        .iter()
        .map(|s| (s.safe_radius_m, s.center_xyz().unwrap_or_default()))
        .collect()
}

/// JSON numbers parse back to within an ulp or so; compare sites with a tolerance.
fn assert_same_sites(got: &[(f64, [f64; 3])], want: &[(f64, [f64; 3])]) {
    assert_eq!(got.len(), want.len(), "{got:?} vs {want:?}");
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * (1.0 + a.abs().max(b.abs()));
    for (g, w) in got.iter().zip(want) {
        assert!(
            close(g.0, w.0) && (0..3).all(|k| close(g.1[k], w.1[k])),
            "{g:?} vs {w:?}"
        );
    }
}

fn sites_of_json(v: &Value) -> Vec<(f64, [f64; 3])> {
    v["sites"]
        .as_array()
        .expect("sites")
        .iter()
        .map(|s| {
            let c: Vec<f64> = s["center"]
                .as_array()
                .expect("center")
                .iter()
                .map(|x| x.as_f64().expect("f64"))
                .collect();
            (
                s["safe_radius_m"].as_f64().expect("radius"),
                [c[0], c[1], c[2]],
            )
        })
        .collect()
}

/// Every key path of a JSON document (`.sites[].center`): its schema without the values.
fn json_paths(v: &Value) -> std::collections::BTreeSet<String> {
    fn walk(v: &Value, path: String, out: &mut std::collections::BTreeSet<String>) {
        match v {
            Value::Object(m) => {
                for (k, v) in m {
                    walk(v, format!("{path}.{k}"), out);
                }
            }
            Value::Array(a) => {
                for v in a {
                    walk(v, format!("{path}[]"), out);
                }
            }
            _ => {}
        }
        out.insert(path);
    }
    let mut out = std::collections::BTreeSet::new();
    walk(v, String::new(), &mut out);
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn info_prints_version_classes_and_defaults() {
    let server = TestServer::start().await;
    let (code, out) = landing(&["--server", &server.url, "info", "--json"]).await;
    assert_eq!(code, exit::OK);
    let v: Value = serde_json::from_str(&out).expect("json");
    assert!(!v["version"].as_str().expect("version").is_empty());
    let classes = v["classes"].as_array().expect("classes");
    assert!(
        classes.iter().any(|c| c["name"] == "building rooftop"),
        "{classes:?}"
    );
    assert_eq!(v["default_options"]["max_triangle_edge_m"], "4");
    let (code, table) = landing(&["--server", &server.url, "info"]).await;
    assert_eq!(code, exit::OK);
    assert!(
        table.contains("min_normal_dot") && table.contains("0.96"),
        "{table}"
    );
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn detect_on_a_recording_and_on_a_ply_matches_the_pipeline() {
    let server = TestServer::start().await;
    let s = scene(61);
    let last = s.frames.len() - 1;
    let path = s.path.to_str().expect("path");
    let (code, out) = landing(&[
        "--server",
        &server.url,
        "detect",
        path,
        "--frame",
        &last.to_string(),
        "--segmentation",
        "point-classes",
        "--json",
    ])
    .await;
    assert_eq!(code, exit::OK, "{out}");
    let v: Value = serde_json::from_str(&out).expect("json");
    let want = in_process(
        server.reference(),
        &s.frames[last].frame,
        &mode(SegmentationMode::PointClasses),
    )
    .expect("pipeline");
    assert_same_sites(&sites_of_json(&v), &sites_of(&want));
    assert!(!want.sites.is_empty());

    // The same scan as a PLY in world coordinates with classes.
    let cloud = s.frames[last].frame.point_cloud.as_ref().expect("cloud");
    let unpacked = unpack_point_cloud(cloud).expect("unpack");
    let world = unpacked.to_world(cloud.pose.as_ref());
    let classes = unpacked.classes.expect("classes");
    let mut ply = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nproperty uchar class\nend_header\n",
        world.len()
    );
    let pts: Vec<[f32; 3]> = world
        .iter()
        .map(|p| [p[0] as f32, p[1] as f32, p[2] as f32])
        .collect();
    for (p, c) in pts.iter().zip(&classes) {
        ply.push_str(&format!("{} {} {} {c}\n", p[0], p[1], p[2]));
    }
    let ply_path = out_path("scene-61.ply");
    std::fs::write(&ply_path, ply).expect("write ply");
    let (code, out) = landing(&[
        "--server",
        &server.url,
        "detect",
        ply_path.to_str().expect("path"),
        "--segmentation",
        "point-classes",
        "--json",
    ])
    .await;
    assert_eq!(code, exit::OK, "{out}");
    let frame = FrameBuilder::new(
        0,
        PointCloudBuilder::new(&pts)
            .classes(&classes)
            .build()
            .expect("cloud"),
    )
    .build();
    let want = in_process(
        server.reference(),
        &frame,
        &mode(SegmentationMode::PointClasses),
    )
    .expect("pipeline");
    let v: Value = serde_json::from_str(&out).expect("json");
    assert_same_sites(&sites_of_json(&v), &sites_of(&want));

    // `landing-server detect --json` on the same PLY prints the same schema and sites.
    let options = landing_server::pipeline::FrameOptions {
        segmentation_mode: SegmentationMode::PointClasses,
        ..Default::default()
    };
    let pipeline = landing_server::pipeline::Pipeline::geometry_only(Default::default());
    let offline =
        landing_server::detect::detect_ply(&ply_path, &options, &pipeline).expect("offline detect");
    let offline = landing_server::detect::to_json(&offline);
    assert_eq!(json_paths(&offline), json_paths(&v), "{offline}\nvs\n{v}");
    assert_same_sites(&sites_of_json(&offline), &sites_of(&want));

    let (code, table) = landing(&[
        "--server",
        &server.url,
        "detect",
        path,
        "--frame",
        &last.to_string(),
    ])
    .await;
    assert_eq!(code, exit::OK);
    assert!(
        table.contains("rank") || table.contains("0 site(s)"),
        "{table}"
    );
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn replay_writes_json_lines_and_mcap_equal_to_the_pipeline() {
    let server = TestServer::start().await;
    let s = scene(62);
    let jsonl = out_path("replay-62.jsonl");
    let mcap = out_path("replay-62.mcap");
    let (code, out) = landing(&[
        "--server",
        &server.url,
        "replay",
        s.path.to_str().expect("path"),
        "--single-frame",
        "--segmentation",
        "point-classes",
        "--jsonl",
        jsonl.to_str().expect("path"),
        "--out",
        mcap.to_str().expect("path"),
    ])
    .await;
    assert_eq!(code, exit::OK, "{out}");
    assert!(
        out.contains(&format!("{} frames: {} ok", s.frames.len(), s.frames.len())),
        "{out}"
    );

    let options = mode(SegmentationMode::PointClasses);
    let expected: Vec<v1::FrameResult> = s
        .frames
        .iter()
        .map(|f| in_process(server.reference(), &f.frame, &options).expect("pipeline"))
        .collect();
    let lines: Vec<Value> = std::fs::read_to_string(&jsonl)
        .expect("jsonl")
        .lines()
        .map(|l| serde_json::from_str(l).expect("json line"))
        .collect();
    assert_eq!(lines.len(), expected.len());
    for (line, want) in lines.iter().zip(&expected) {
        assert_eq!(line["sequence"], want.sequence);
        assert_eq!(line["outcome"], "ok");
        assert_same_sites(&sites_of_json(&line["result"]), &sites_of(want));
    }

    let bytes = std::fs::read(&mcap).expect("mcap");
    let all: Vec<_> = mcap::MessageStream::new(&bytes)
        .expect("mcap")
        .map(|m| m.expect("message"))
        .collect();
    let count = |topic: &str| all.iter().filter(|m| m.channel.topic == topic).count();
    // Each answer drawn in 3-D and over its camera image.
    assert_eq!(count(SITES_TOPIC), expected.len());
    assert_eq!(count(ANNOTATIONS_TOPIC), expected.len());
    // The inputs come along, so the output replays on its own: the same frames.
    let replayed = landing_recording::read_bytes(&bytes).expect("the output is a recording");
    let frames = |r: &[landing_recording::RecordedFrame]| -> Vec<v1::Frame> {
        r.iter().map(|r| r.frame.clone()).collect()
    };
    assert_eq!(frames(&replayed), frames(&s.frames[..expected.len()]));
    let messages: Vec<_> = all
        .iter()
        .filter(|m| m.channel.topic == RESULT_TOPIC)
        .collect();
    assert_eq!(messages.len(), expected.len());
    for ((m, want), rec) in messages.iter().zip(&expected).zip(&s.frames) {
        assert_eq!(m.channel.topic, RESULT_TOPIC);
        let ts = rec.frame.timestamp.expect("timestamp");
        assert_eq!(
            m.log_time,
            ts.seconds as u64 * 1_000_000_000 + ts.nanos as u64,
            "aligned with the input"
        );
        let r = v1::StreamLandingSitesResponse::decode(&m.data[..]).expect("decode");
        let Some(v1::stream_landing_sites_response::Outcome::Result(got)) = r.outcome else {
            panic!("{r:?}")
        };
        assert_eq!(untimed(got), untimed(want.clone()));
    }

    // Every frame refused (bad option) is exit 4, with the field in the output.
    let (code, out) = landing(&[
        "--server",
        &server.url,
        "--json",
        "replay",
        s.path.to_str().expect("path"),
        "--min-normal-dot",
        "1.5",
    ])
    .await;
    assert_eq!(code, exit::FRAMES_FAILED, "{out}");
    assert!(out.contains("options.min_normal_dot"), "{out}");
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn loadtest_reports_exactly_once_delivery() {
    let server = TestServer::start().await;
    let s = scene(63);
    let (code, out) = landing(&[
        "--server",
        &server.url,
        "loadtest",
        s.path.to_str().expect("path"),
        "--streams",
        "2",
        "--duration",
        "2",
        "--segmentation",
        "none",
        "--json",
    ])
    .await;
    assert_eq!(code, exit::OK, "{out}");
    let v: Value = serde_json::from_str(&out).expect("json");
    assert!(v["sent"].as_u64().expect("sent") > 0);
    assert_eq!(v["sent"], v["answered"]);
    assert_eq!(v["unanswered"], 0);
    assert!(v["latency_ms"]["p50"].as_f64().expect("p50") > 0.0);
    assert!(v["throughput_fps"].as_f64().expect("fps") > 0.0);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn render_draws_the_site_where_it_is() {
    let server = TestServer::start().await;
    let s = scene(64);
    let last = s.frames.len() - 1;
    let png = out_path("render-64.png");
    let (code, out) = landing(&[
        "--server",
        &server.url,
        "render",
        s.path.to_str().expect("path"),
        "--frame",
        &last.to_string(),
        "--segmentation",
        "point-classes",
        "--sites",
        "1",
        "--out",
        png.to_str().expect("path"),
    ])
    .await;
    assert_eq!(code, exit::OK, "{out}");
    let image = image::open(&png).expect("a PNG").to_rgb8();

    // Where the site is: project it the way the renderer does.
    let frame = &s.frames[last].frame;
    let result = in_process(
        server.reference(),
        frame,
        &mode(SegmentationMode::PointClasses),
    )
    .expect("pipeline");
    let layout = render(
        frame,
        &result,
        &RenderConfig {
            max_sites: 1,
            ..RenderConfig::default()
        },
    )
    .expect("render");
    assert_eq!((image.width(), image.height()), layout.image.dimensions());
    let site = result.sites.first().expect("a site");
    let c = site.center.expect("centre");
    let centre = [c.x, c.y, c.z];
    let (x, y) = layout
        .top_down_pixel(centre)
        .expect("centre in the top-down panel");
    assert_eq!(
        *image.get_pixel(x, y),
        STAR_YELLOW,
        "the star marks the centre from above"
    );
    if let Some((x, y)) = layout.camera_pixel(centre) {
        assert_eq!(
            *image.get_pixel(x, y),
            STAR_YELLOW,
            "the star marks the centre in the camera image"
        );
    }
    // Inside the safe circle but away from the star: the polygon's green.
    let off = [c.x + site.safe_radius_m * 0.7, c.y, c.z];
    let (x, y) = layout.top_down_pixel(off).expect("in the panel");
    let p = image.get_pixel(x, y).0;
    assert!(
        p[1] > p[0] + 30 && p[1] > p[2] + 30,
        "green inside the polygon, got {p:?}"
    );
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_unreachable_server_is_exit_3() {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .expect("bind")
        .local_addr()
        .expect("addr")
        .port();
    let url = format!("http://127.0.0.1:{port}");
    let s = scene(61);
    assert_eq!(
        landing(&["--server", &url, "info"]).await.0,
        exit::UNREACHABLE
    );
    assert_eq!(
        landing(&["--server", &url, "replay", s.path.to_str().expect("path")])
            .await
            .0,
        exit::UNREACHABLE
    );
}
