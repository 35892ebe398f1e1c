//! Graceful drain: frames read before the shutdown are answered; frames the server never read
//! are reported unanswered by the client (never silently lost, never re-sent).

use std::time::Duration;

use landing_client::v1::{Frame, SegmentationMode};
use landing_client::{
    ClientConfig, ClientError, FrameOutcome, LandingClient, ServingStatus, StreamConfig, StreamItem,
};

use crate::support::{TestServer, mode, scene, scratch, server_config};

/// Frames cycling through a scene, with fresh sequence numbers.
fn many_frames(n: usize) -> Vec<Frame> {
    let s = scene(51);
    (0..n)
        .map(|i| {
            let mut f = s.frames[i % s.frames.len()].frame.clone();
            f.sequence = i as u64;
            f
        })
        .collect()
}

/// Streams `frames`; calls `stop` after the first answer; returns the answers and the end.
async fn stream_and_stop<F>(
    client: &LandingClient,
    frames: Vec<Frame>,
    stop: F,
) -> (Vec<StreamItem>, Option<ClientError>)
where
    F: FnOnce(),
{
    let (mut tx, mut rx) = client.open_stream(StreamConfig {
        options: Some(mode(SegmentationMode::None)),
        max_in_flight: 4,
        ..StreamConfig::single_frame()
    });
    let sender = tokio::spawn(async move {
        for f in frames {
            if tx.send(f).await.is_err() {
                break;
            }
        }
    });
    let mut stop = Some(stop);
    let mut items = Vec::new();
    let mut end = None;
    while let Some(item) = tokio::time::timeout(Duration::from_secs(120), rx.next())
        .await
        .expect("the stream ends")
    {
        match item {
            Ok(i) => {
                items.push(i);
                if let Some(s) = stop.take() {
                    s();
                }
            }
            Err(e) => end = Some(e),
        }
    }
    let _ = sender.await;
    (items, end)
}

/// Answers are a processed prefix of what was sent; the rest is reported, not lost.
fn assert_drained(items: &[StreamItem], end: Option<ClientError>, sent_max: u64) {
    assert!(!items.is_empty());
    // A frame read in the instant the drain begins is refused with UNAVAILABLE (a status, not
    // lost): refusals may only follow the processed frames, never come between them.
    let processed = items
        .iter()
        .take_while(|i| matches!(i.outcome, FrameOutcome::Result(_)))
        .count();
    assert!(processed > 0, "the first frames were processed");
    for (k, i) in items.iter().enumerate() {
        assert_eq!(i.sequence, k as u64, "answers in order, none twice");
        if k >= processed {
            assert!(
                matches!(&i.outcome, FrameOutcome::Error(e) if e.code == tonic::Code::Unavailable),
                "frame {k} after the drain: {:?}",
                i.outcome.label()
            );
        }
    }
    match end {
        None => {}
        Some(ClientError::StreamBroken { unanswered, .. }) => {
            let first = items.len() as u64;
            for (k, s) in unanswered.iter().enumerate() {
                assert_eq!(*s, first + k as u64, "unanswered frames are the tail");
                assert!(*s < sent_max);
            }
        }
        Some(other) => panic!("unexpected end of stream: {other}"),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn shutdown_during_a_stream_drains_it() {
    let mut server = TestServer::start().await;
    let client = server.client().await;
    let frames = many_frames(60);
    let mut handle = None;
    let (items, end) =
        stream_and_stop(&client, frames, || handle = Some(server.begin_shutdown())).await;
    assert!(items.len() < 60, "the shutdown cut the stream short");
    assert_drained(&items, end, 60);
    handle
        .expect("shutdown started")
        .await
        .expect("shutdown finished");
}

/// Not a test of its own: the body of the server process that [`sigterm_drains_a_stream`] starts
/// by re-executing this test binary with `LANDING_E2E_SERVER_CONFIG` set.
#[test]
fn server_process() {
    if let Some(config) = std::env::var_os("LANDING_E2E_SERVER_CONFIG") {
        let args = [
            "landing-server".into(),
            "serve".into(),
            "--config".into(),
            config,
        ];
        let code = landing_server::cli::cli_main_from(args);
        std::process::exit(if code == std::process::ExitCode::SUCCESS {
            0
        } else {
            1
        });
    }
}

/// Reads the server process's JSON log until its "serving landing.v1" line and returns the
/// address it names; the rest of the log goes on to this process's stderr.
async fn serving_address(log: std::process::ChildStderr) -> Option<String> {
    let (tx, rx) = tokio::sync::oneshot::channel();
    std::thread::spawn(move || {
        use std::io::BufRead as _;
        let mut tx = Some(tx);
        for line in std::io::BufReader::new(log).lines() {
            let Ok(line) = line else { break };
            eprintln!("{line}");
            let Ok(entry) = serde_json::from_str::<serde_json::Value>(&line) else {
                continue;
            };
            let fields = &entry["fields"];
            if fields["message"] == "serving landing.v1"
                && let (Some(addr), Some(tx)) = (fields["addr"].as_str(), tx.take())
            {
                let _ = tx.send(addr.to_string());
            }
        }
    });
    rx.await.ok()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigterm_drains_a_stream() {
    // The child binds port 0 and logs the address it got: no port is picked here and freed for
    // another test's server to take.
    let mut config = server_config();
    config.server.listen = "127.0.0.1:0".into();
    config.log.format = landing_server::config::LogFormat::Json;
    config.log.filter = "info".into();
    let path = scratch().join(format!("server-{}.toml", std::process::id()));
    std::fs::write(&path, config.to_toml()).expect("write the config");
    let mut child = std::process::Command::new(std::env::current_exe().expect("test binary"))
        .args([
            "shutdown::server_process",
            "--exact",
            "--nocapture",
            "--test-threads=1",
        ])
        .env("LANDING_E2E_SERVER_CONFIG", &path)
        .env_remove("RUST_LOG")
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("start the server process");
    let addr = serving_address(child.stderr.take().expect("piped stderr"));
    let addr = tokio::time::timeout(Duration::from_secs(60), addr)
        .await
        .expect("the server process serves within a minute")
        .expect("the server process logs its address");
    let url = format!("http://{addr}");
    let mut client = None;
    for _ in 0..600 {
        if let Ok(c) = LandingClient::connect(ClientConfig::new(url.clone())).await
            && matches!(c.health("").await, Ok(ServingStatus::Serving))
        {
            client = Some(c);
            break;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let client = client.expect("the server process answers health within a minute");
    let pid = child.id().to_string();
    let (items, end) = stream_and_stop(&client, many_frames(60), || {
        let ok = std::process::Command::new("kill")
            .args(["-TERM", &pid])
            .status()
            .expect("run kill")
            .success();
        assert!(ok, "kill -TERM {pid}");
    })
    .await;
    assert_drained(&items, end, 60);
    let status = tokio::task::spawn_blocking(move || child.wait())
        .await
        .expect("join")
        .expect("wait");
    assert!(
        status.success(),
        "the server exits 0 after draining: {status}"
    );
}
