//! The Foxglove live view (`server.foxglove_listen`): a WebSocket server (Foxglove SDK, protocol
//! `foxglove.sdk.v1`) that publishes, for each frame the service answers, the same channels a
//! recording has — the scan, the camera image and calibration, the sensor poses, and the answer as
//! a 3-D scene and as image annotations (`landing_recording`'s topics and drawings).
//!
//! It never slows the service:
//! - with no viewer subscribed, the handlers keep nothing and nothing is converted;
//! - the handlers hand a frame over in O(1) to a queue of [`QUEUE_FRAMES`]; when viewers fall
//!   behind, the oldest frame is dropped and counted (`landing_live_view_dropped_total`);
//! - conversion and encoding run on a thread of their own, never on the async runtime; the SDK
//!   then gives each viewer a bounded backlog of its own that also drops its oldest messages.

use std::collections::VecDeque;
use std::net::SocketAddr;
use std::sync::{Arc, Condvar, Mutex};

use anyhow::Context as _;
use foxglove::messages as fox;
use foxglove::{Channel, Context, WebSocketServer, WebSocketServerHandle};
use landing_proto::v1;
use landing_recording::{self as recording, convert::Image, scene};

use crate::telemetry::Metrics;

/// Frames waiting for the publisher thread; a newer frame pushes out the oldest.
pub const QUEUE_FRAMES: usize = 4;

/// Messages each viewer's connection may have waiting (the SDK's own bound, oldest dropped).
const VIEWER_BACKLOG: usize = 256;

/// The channels, on the recording's topics.
struct Channels {
    cloud: Channel<fox::PointCloud>,
    image: Channel<fox::CompressedImage>,
    raw_image: Channel<fox::RawImage>,
    calibration: Channel<fox::CameraCalibration>,
    transforms: Channel<fox::FrameTransforms>,
    sites: Channel<fox::SceneUpdate>,
    annotations: Channel<fox::ImageAnnotations>,
}

impl Channels {
    fn new(ctx: &Arc<Context>) -> Self {
        Self {
            cloud: ctx.channel_builder(recording::LIDAR_TOPIC).build(),
            image: ctx.channel_builder(recording::CAMERA_TOPIC).build(),
            raw_image: ctx.channel_builder(recording::CAMERA_RAW_TOPIC).build(),
            calibration: ctx.channel_builder(recording::CALIBRATION_TOPIC).build(),
            transforms: ctx.channel_builder(recording::TF_TOPIC).build(),
            sites: ctx.channel_builder(recording::SITES_TOPIC).build(),
            annotations: ctx.channel_builder(recording::ANNOTATIONS_TOPIC).build(),
        }
    }

    /// Whether any viewer is subscribed to any channel.
    fn watched(&self) -> bool {
        self.sensors_watched() || self.sites.has_sinks() || self.annotations.has_sinks()
    }

    /// Whether any viewer is subscribed to the frame's own data (scan, image, calibration,
    /// poses): only then is the frame split into Foxglove messages, which copies its bytes.
    fn sensors_watched(&self) -> bool {
        self.cloud.has_sinks()
            || self.image.has_sinks()
            || self.raw_image.has_sinks()
            || self.calibration.has_sinks()
            || self.transforms.has_sinks()
    }

    /// Converts and logs one answered frame, each message only if someone subscribed to it.
    fn publish(&self, frame: &v1::Frame, response: &v1::StreamLandingSitesResponse) {
        let at = frame
            .timestamp
            .as_ref()
            .map(recording::log_time_ns)
            .filter(|&t| t > 0)
            .unwrap_or_else(now_ns);
        match self
            .sensors_watched()
            .then(|| recording::frame_to_foxglove(frame))
        {
            Some(Ok(parts)) => {
                if let Some(cloud) = &parts.cloud {
                    self.cloud.log_with_time(cloud, at);
                }
                match &parts.image {
                    Some(Image::Compressed(img)) => self.image.log_with_time(img, at),
                    Some(Image::Raw(img)) => self.raw_image.log_with_time(img, at),
                    None => {}
                }
                if let Some(c) = &parts.calibration {
                    self.calibration.log_with_time(c, at);
                }
                self.transforms.log_with_time(&parts.transforms, at);
            }
            // A frame a viewer cannot place (two sensors, one name) is still answered; only its
            // sensor data is not shown.
            Some(Err(e)) => tracing::debug!(error = %e, "live view: frame not shown"),
            None => {}
        }
        if self.sites.has_sinks() {
            self.sites.log_with_time(&scene::sites_scene(response), at);
        }
        if self.annotations.has_sinks()
            && let Some(a) = frame
                .image
                .as_ref()
                .and_then(|camera| scene::sites_annotations(response, camera))
        {
            self.annotations.log_with_time(&a, at);
        }
    }
}

fn now_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

/// A frame and its answer, waiting to be shown.
type Shown = (v1::Frame, v1::StreamLandingSitesResponse);

#[derive(Default)]
struct Queue<T = Shown> {
    frames: VecDeque<T>,
    stopped: bool,
}

impl<T> Queue<T> {
    /// Appends `item`, dropping the oldest when [`QUEUE_FRAMES`] are waiting; says whether it
    /// dropped one.
    fn push(&mut self, item: T) -> bool {
        let dropped = self.frames.len() >= QUEUE_FRAMES && self.frames.pop_front().is_some();
        self.frames.push_back(item);
        dropped
    }
}

/// The running live view, until [`LiveView::stop`].
pub(crate) struct LiveView {
    /// The channels' context: the SDK's server and channels hold it only weakly.
    _context: Arc<Context>,
    server: Mutex<Option<WebSocketServerHandle>>,
    channels: Arc<Channels>,
    queue: Arc<(Mutex<Queue>, Condvar)>,
    publisher: Mutex<Option<std::thread::JoinHandle<()>>>,
    metrics: Metrics,
    /// The bound address (port 0 resolved).
    pub addr: SocketAddr,
}

impl std::fmt::Debug for LiveView {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveView")
            .field("addr", &self.addr)
            .finish()
    }
}

impl LiveView {
    /// Binds `addr` and starts serving viewers.
    pub async fn start(addr: SocketAddr, metrics: Metrics) -> anyhow::Result<Self> {
        let ctx = Context::new();
        let channels = Arc::new(Channels::new(&ctx));
        let server = WebSocketServer::new()
            .name(concat!("landing-server ", env!("CARGO_PKG_VERSION")))
            .context(&ctx)
            .bind(addr.ip().to_string(), addr.port())
            .message_backlog_size(VIEWER_BACKLOG)
            .start()
            .await
            .with_context(|| format!("bind server.foxglove_listen {addr}"))?;
        let addr = SocketAddr::new(addr.ip(), server.port());
        let queue = Arc::new((Mutex::new(Queue::default()), Condvar::new()));
        let publisher = {
            let (queue, channels, metrics) = (queue.clone(), channels.clone(), metrics.clone());
            std::thread::Builder::new()
                .name("live-view".into())
                .spawn(move || publish_loop(&queue, &channels, &metrics))
                .context("start the live view's thread")?
        };
        Ok(Self {
            _context: ctx,
            server: Mutex::new(Some(server)),
            channels,
            queue,
            publisher: Mutex::new(Some(publisher)),
            metrics,
            addr,
        })
    }

    /// Whether a viewer is subscribed: only then do the handlers keep a frame for [`Self::show`].
    pub fn watched(&self) -> bool {
        self.channels.watched()
    }

    /// Queues an answered frame for the viewers; never waits. When the queue is full the oldest
    /// frame is dropped and counted.
    pub fn show(&self, frame: v1::Frame, response: v1::StreamLandingSitesResponse) {
        let (lock, wake) = &*self.queue;
        let mut q = lock.lock().unwrap_or_else(|e| e.into_inner());
        let dropped = q.push((frame, response));
        drop(q);
        wake.notify_one();
        if dropped {
            self.metrics.live_view_dropped();
        }
    }

    /// Stops the publisher thread, then closes the listener and every viewer's connection.
    pub async fn stop(&self) {
        let (lock, wake) = &*self.queue;
        lock.lock().unwrap_or_else(|e| e.into_inner()).stopped = true;
        wake.notify_all();
        let publisher = self
            .publisher
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .take();
        if let Some(t) = publisher {
            // The thread finishes the frame it is showing (milliseconds), off the runtime.
            let _ = tokio::task::spawn_blocking(move || t.join()).await;
        }
        let server = self.server.lock().unwrap_or_else(|e| e.into_inner()).take();
        if let Some(server) = server {
            server.stop().wait().await;
        }
    }
}

/// The publisher thread: shows queued frames until stopped.
fn publish_loop(queue: &(Mutex<Queue>, Condvar), channels: &Channels, metrics: &Metrics) {
    let (lock, wake) = queue;
    loop {
        let next = {
            let mut q = lock.lock().unwrap_or_else(|e| e.into_inner());
            loop {
                if q.stopped {
                    return;
                }
                if let Some(shown) = q.frames.pop_front() {
                    break shown;
                }
                q = wake.wait(q).unwrap_or_else(|e| e.into_inner());
            }
        };
        let (frame, response) = next;
        // A viewer that left while the frame waited costs nothing more.
        if channels.watched() {
            channels.publish(&frame, &response);
            metrics.live_view_published();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_full_queue_drops_its_oldest_frame() {
        let mut q = Queue::<u32>::default();
        for i in 0..QUEUE_FRAMES as u32 {
            assert!(!q.push(i));
        }
        assert!(q.push(99));
        assert_eq!(q.frames.len(), QUEUE_FRAMES);
        assert_eq!(q.frames.front(), Some(&1));
        assert_eq!(q.frames.back(), Some(&99));
    }
}
