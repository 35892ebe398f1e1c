//! The real binary as a server process: it binds, serves, and on SIGTERM drains and exits 0.

use std::io::{BufRead as _, BufReader};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use landing_proto::v1;
use landing_proto::v1::landing_service_client::LandingServiceClient;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigterm_drains_and_exits_zero() {
    let mut child = Command::new(env!("CARGO_BIN_EXE_landing-server"))
        .args(["serve", "--listen", "127.0.0.1:0", "--metrics-listen", ""])
        .env("LANDING__SEGMENTATION__ENABLED", "false")
        // No catalog file in the crate's directory.
        .env("LANDING__CATALOG__ENABLED", "false")
        .env("LANDING__LOG__FORMAT", "json")
        .env("LANDING__SERVER__SHUTDOWN_GRACE_S", "5")
        .env_remove("RUST_LOG")
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stderr = child.stderr.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel::<String>();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    let mut log = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(30);
    let addr = loop {
        let line = rx
            .recv_timeout(deadline.saturating_duration_since(Instant::now()))
            .expect("no 'serving' log line");
        log.push(line.clone());
        let Ok(doc) = serde_json::from_str::<serde_json::Value>(&line) else {
            continue;
        };
        if doc["fields"]["message"] == "serving landing.v1" {
            break doc["fields"]["addr"].as_str().unwrap().to_owned();
        }
    };
    let mut client = LandingServiceClient::connect(format!("http://{addr}"))
        .await
        .unwrap();
    let info = client
        .get_service_info(v1::GetServiceInfoRequest {})
        .await
        .unwrap()
        .into_inner();
    assert_eq!(info.version, env!("CARGO_PKG_VERSION"));

    let status = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let started = Instant::now();
    let exit = loop {
        if let Some(exit) = child.try_wait().unwrap() {
            break exit;
        }
        assert!(
            started.elapsed() < Duration::from_secs(10),
            "still running 10 s after SIGTERM"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    log.extend(rx.try_iter());
    assert!(exit.success(), "exit {exit:?}; log:\n{}", log.join("\n"));
    let log = log.join("\n");
    assert!(
        log.contains("SIGTERM received") && log.contains("draining") && log.contains("stopped"),
        "{log}"
    );
}

#[tokio::test]
async fn the_shutdown_handlers_are_installed_before_the_future_is_polled() {
    // The server announces itself before its shutdown future is first polled. The handlers
    // were once installed on that first poll, and a SIGTERM in between killed the process with
    // the default action (exit by signal 15, seen in CI). Here that would kill this test.
    let shutdown = landing_server::server::shutdown_signal().unwrap();
    let pid = std::process::id().to_string();
    assert!(
        Command::new("kill")
            .args(["-TERM", &pid])
            .status()
            .unwrap()
            .success()
    );
    tokio::time::timeout(Duration::from_secs(5), shutdown)
        .await
        .expect("the SIGTERM sent before the first poll was not seen");
}

/// The JSON log lines that `landing-server serve`, with the shipped model and `env`, writes
/// until it announces that it serves; then it is stopped with SIGTERM.
fn startup_log(env: &[(&str, &str)]) -> Vec<serde_json::Value> {
    let model = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../models/rooftop-segmentation.onnx"
    );
    let mut command = Command::new(env!("CARGO_BIN_EXE_landing-server"));
    command
        .args(["serve", "--listen", "127.0.0.1:0", "--metrics-listen", ""])
        .env("LANDING__SEGMENTATION__MODEL_PATH", model)
        .env("LANDING__CATALOG__ENABLED", "false")
        .env("LANDING__LOG__FORMAT", "json")
        .env_remove("RUST_LOG")
        .env_remove("ORT_LOG")
        .stderr(Stdio::piped());
    for (k, v) in env {
        command.env(k, v);
    }
    let mut child = command.spawn().unwrap();
    let stderr = child.stderr.take().unwrap();
    // Read on a thread to the end: the server still logs while it drains, into an open pipe.
    let (tx, rx) = std::sync::mpsc::channel::<String>();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    let mut lines = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let line = rx
            .recv_timeout(deadline.saturating_duration_since(Instant::now()))
            .unwrap_or_else(|e| panic!("no 'serving' log line ({e}): {lines:#?}"));
        let doc: serde_json::Value = serde_json::from_str(&line)
            .unwrap_or_else(|e| panic!("not a JSON log line ({e}): {line}"));
        let serving = doc["fields"]["message"] == "serving landing.v1";
        lines.push(doc);
        if serving {
            break;
        }
    }
    let pid = child.id().to_string();
    assert!(
        Command::new("kill")
            .args(["-TERM", &pid])
            .status()
            .unwrap()
            .success()
    );
    let exit = child.wait().unwrap();
    assert!(exit.success(), "exit {exit:?}; log: {lines:#?}");
    lines
}

/// The lines of ONNX Runtime's own log (its messages come through `tracing` as `ort::logging`;
/// the `ort` crate's own lines, such as the one naming the library it loaded, are not its).
fn ort_lines(log: &[serde_json::Value]) -> Vec<&serde_json::Value> {
    log.iter()
        .filter(|l| l["target"] == "ort::logging")
        .collect()
}

#[test]
fn onnx_runtime_logs_at_warning_by_default_and_as_configured() {
    // Needs the ONNX Runtime library (scripts/setup-ort.sh) and the shipped model.
    let quiet = startup_log(&[]);
    let below_warning: Vec<_> = ort_lines(&quiet)
        .into_iter()
        .filter(|l| !matches!(l["level"].as_str(), Some("WARN" | "ERROR")))
        .collect();
    assert!(below_warning.is_empty(), "{below_warning:#?}");
    assert!(
        quiet
            .iter()
            .any(|l| l["fields"]["message"] == "segmentation model loaded"),
        "the model was not loaded: {quiet:#?}"
    );

    // The key turns them back on: loading the model is about 200 INFO lines.
    let chatty = startup_log(&[("LANDING__SEGMENTATION__ORT_LOG_LEVEL", "info")]);
    let info = ort_lines(&chatty)
        .into_iter()
        .filter(|l| l["level"] == "INFO")
        .count();
    assert!(
        info >= 20,
        "{info} ONNX Runtime INFO lines with ort_log_level = \"info\""
    );
}
