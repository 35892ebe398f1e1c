//! What most tests go through: a real server on `127.0.0.1:0`, seeded scenes recorded as real
//! MCAP files, the in-process pipeline as the reference, and [`check`].

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Duration;

use landing_client::v1::{self, PipelineOptions, SegmentationMode};
use landing_client::{
    ClientConfig, FrameOutcome, LandingClient, RetryPolicy, StreamConfig, StreamItem,
};
use landing_recording::RecordedFrame;
use landing_server::pipeline::Pipeline;
use landing_server::{Config, RunningServer, convert, run_pipeline};
use landing_sim::recording::{RecordConfig, encode_recording, simulate};

/// The workspace root.
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ has a parent")
        .to_path_buf()
}

/// The shipped model and the ONNX Runtime library, when both are in place.
pub fn model_files() -> Option<(PathBuf, PathBuf)> {
    let root = workspace_root();
    let model = root.join("models/rooftop-segmentation.onnx");
    let ort = std::env::var_os("ORT_DYLIB_PATH")
        .map(PathBuf::from)
        .unwrap_or_else(|| root.join(".ort/libonnxruntime.so"));
    (model.is_file() && ort.is_file()).then_some((model, ort))
}

/// A per-process scratch directory.
pub fn scratch() -> PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let d = std::env::temp_dir().join(format!("landing-e2e-{}", std::process::id()));
        std::fs::create_dir_all(&d).expect("create the scratch directory");
        d
    })
    .clone()
}

/// The test server configuration: loopback, ephemeral port, no metrics listener, the real model
/// when it is installed (geometry only otherwise).
pub fn server_config() -> Config {
    let mut c = Config::default();
    c.server.listen = "127.0.0.1:0".into();
    c.server.metrics_listen = String::new();
    c.server.shutdown_grace_s = 20.0;
    c.pipeline.geometry_workers = 2;
    // The catalog's tests turn it on, with a file of their own.
    c.catalog.enabled = false;
    match model_files() {
        Some((model, ort)) => {
            c.segmentation.enabled = true;
            c.segmentation.model_path = model;
            c.segmentation.ort_library = ort;
        }
        None => c.segmentation.enabled = false,
    }
    c
}

/// A server running in this process.
pub struct TestServer {
    pub url: String,
    pub config: Config,
    running: Option<RunningServer>,
    reference: OnceLock<Pipeline>,
}

impl TestServer {
    /// Starts the server with [`server_config`].
    pub async fn start() -> Self {
        Self::with_config(server_config()).await
    }

    /// Starts the server with `config` on `127.0.0.1:0`.
    pub async fn with_config(config: Config) -> Self {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
            .await
            .expect("bind 127.0.0.1:0");
        let running = landing_server::start(config.clone(), listener)
            .await
            .expect("start the server");
        let scheme = if config.tls.cert_path.as_os_str().is_empty() {
            "http"
        } else {
            "https"
        };
        Self {
            url: format!("{scheme}://{}", running.addr),
            config,
            running: Some(running),
            reference: OnceLock::new(),
        }
    }

    /// The `/metrics` address, when the config enables it.
    pub fn metrics_addr(&self) -> Option<std::net::SocketAddr> {
        self.running.as_ref()?.metrics_addr
    }

    /// The Foxglove live view's address, when the config enables it.
    pub fn foxglove_addr(&self) -> Option<std::net::SocketAddr> {
        self.running.as_ref()?.foxglove_addr
    }

    /// Client settings for this server (no retries, so tests see every refusal).
    pub fn client_config(&self) -> ClientConfig {
        let mut c = ClientConfig::new(self.url.clone());
        c.retry = RetryPolicy::none();
        c.request_timeout = Some(Duration::from_secs(120));
        c
    }

    /// A connected client.
    pub async fn client(&self) -> LandingClient {
        LandingClient::connect(self.client_config())
            .await
            .expect("connect to the test server")
    }

    /// The same pipeline the server runs (same defaults, same model), in this process.
    pub fn reference(&self) -> &Pipeline {
        self.reference.get_or_init(|| {
            let mut p = Pipeline::geometry_only(landing_geometry_defaults());
            if self.config.segmentation.enabled {
                let s = landing_server::segmentation::Segmenter::load(&self.config.segmentation)
                    .expect("load the model in process");
                p.segmenter = Some(Arc::new(s));
            }
            p
        })
    }

    /// Graceful shutdown; waits for the drain.
    pub async fn stop(mut self) {
        if let Some(r) = self.running.take() {
            r.shutdown().await.expect("clean shutdown");
        }
    }

    /// Starts the graceful shutdown and returns its handle without waiting.
    pub fn begin_shutdown(&mut self) -> tokio::task::JoinHandle<()> {
        let r = self.running.take().expect("server running");
        tokio::spawn(async move { r.shutdown().await.expect("clean shutdown") })
    }
}

fn landing_geometry_defaults() -> landing_geometry::Params {
    landing_geometry::Params::default()
}

/// A seeded simulated flight, recorded as MCAP: the frames with their ground truth, and the file.
pub struct Scene {
    pub frames: Vec<RecordedFrame>,
    pub path: PathBuf,
}

/// Frames per scene: enough for streams with several frames in flight, few enough to simulate
/// quickly.
pub const SCENE_FRAMES: u32 = 6;

/// The scene of `seed` (simulated once per process, then shared).
pub fn scene(seed: u64) -> Arc<Scene> {
    static SCENES: OnceLock<Mutex<HashMap<u64, Arc<Scene>>>> = OnceLock::new();
    let scenes = SCENES.get_or_init(Default::default);
    // Holding the lock while simulating keeps concurrent tests from simulating the same seed twice.
    let mut map = scenes.lock().unwrap_or_else(|e| e.into_inner());
    map.entry(seed)
        .or_insert_with(|| {
            let mut config = RecordConfig {
                seed,
                drone_id: format!("e2e-{seed}"),
                ..RecordConfig::default()
            };
            config.flight.frames = SCENE_FRAMES;
            let (world, frames) = simulate(&config).expect("simulate the scene");
            let bytes = encode_recording(&world, &frames, &config).expect("encode the recording");
            let path = scratch().join(format!("scene-{seed}.mcap"));
            std::fs::write(&path, &bytes).expect("write the recording");
            let frames = landing_recording::read_bytes(&bytes).expect("read the recording back");
            assert_eq!(frames.len(), SCENE_FRAMES as usize);
            Arc::new(Scene { frames, path })
        })
        .clone()
}

/// Options selecting only a segmentation mode.
pub fn mode(m: SegmentationMode) -> PipelineOptions {
    PipelineOptions {
        segmentation_mode: m as i32,
        ..Default::default()
    }
}

/// What the in-process pipeline answers for `frame`: the result, or the gRPC code of its error.
pub fn in_process(
    pipeline: &Pipeline,
    frame: &v1::Frame,
    options: &PipelineOptions,
) -> Result<v1::FrameResult, tonic::Code> {
    let request = v1::DetectLandingSitesRequest {
        frame: Some(frame.clone()),
        options: Some(options.clone()),
    };
    let status = |e: &landing_server::Error| landing_server::status::to_status(e).code();
    let (f, o) = convert::request_parts(&request, &pipeline.defaults).map_err(|e| status(&e))?;
    let out = run_pipeline(&f, &o, pipeline).map_err(|e| status(&e))?;
    Ok(v1::FrameResult::from(&out))
}

/// A result without its timings, which differ run to run.
pub fn untimed(mut r: v1::FrameResult) -> v1::FrameResult {
    r.timings = None;
    r
}

/// Streams every frame of scene `seed` through `server` with `options`, and checks that the
/// answers come one per frame, in order, each equal to what the in-process pipeline gives for
/// that frame. Returns the answers for further checks.
pub async fn check(server: &TestServer, seed: u64, options: PipelineOptions) -> Vec<StreamItem> {
    let frames: Vec<v1::Frame> = scene(seed).frames.iter().map(|f| f.frame.clone()).collect();
    check_frames(server, &frames, options).await
}

/// [`check`] on any frames.
pub async fn check_frames(
    server: &TestServer,
    frames: &[v1::Frame],
    options: PipelineOptions,
) -> Vec<StreamItem> {
    let items = stream_all(server, frames.to_vec(), options.clone()).await;
    assert_eq!(items.len(), frames.len(), "one answer per frame");
    for (item, frame) in items.iter().zip(frames) {
        assert_eq!(item.sequence, frame.sequence, "answers in order");
        let expected = in_process(server.reference(), frame, &options);
        match (&item.outcome, expected) {
            (FrameOutcome::Result(got), Ok(want)) => {
                assert_eq!(
                    untimed(got.clone()),
                    untimed(want),
                    "frame {}",
                    frame.sequence
                );
            }
            (FrameOutcome::Error(e), Err(code)) => {
                assert_eq!(e.code, code, "frame {}", frame.sequence)
            }
            (got, want) => panic!(
                "frame {}: stream gave {got:?}, in process {want:?}",
                frame.sequence
            ),
        }
    }
    items
}

/// Streams `frames` (BLOCK policy, window 4) and collects every answer; panics if the stream
/// breaks.
pub async fn stream_all(
    server: &TestServer,
    frames: Vec<v1::Frame>,
    options: PipelineOptions,
) -> Vec<StreamItem> {
    let config = StreamConfig {
        options: Some(options),
        max_in_flight: 4,
        ..StreamConfig::single_frame()
    };
    stream_with(server, frames, config, None).await
}

/// Streams `frames` with `config`, asking for a fusion reset before frame index `reset_at`, and
/// collects every answer; panics if the stream breaks.
pub async fn stream_with(
    server: &TestServer,
    frames: Vec<v1::Frame>,
    config: StreamConfig,
    reset_at: Option<usize>,
) -> Vec<StreamItem> {
    let client = server.client().await;
    let (mut tx, mut rx) = client.open_stream(config);
    let sender = tokio::spawn(async move {
        for (i, f) in frames.into_iter().enumerate() {
            if Some(i) == reset_at {
                tx.reset_fusion();
            }
            tx.send(f).await.expect("send a frame");
        }
    });
    let mut items = Vec::new();
    while let Some(item) = rx.next().await {
        items.push(item.expect("stream answer"));
    }
    sender.await.expect("sender task");
    items
}

/// Runs the `landing` CLI in process; returns the exit code and stdout.
pub async fn landing(args: &[&str]) -> (u8, String) {
    let mut out = Vec::new();
    let mut argv = vec!["landing"];
    argv.extend_from_slice(args);
    let code = landing_cli::run(argv, &mut out).await;
    (code, String::from_utf8(out).expect("utf-8 output"))
}
