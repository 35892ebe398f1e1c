//! A fused approach over a flat 20 m × 20 m roof 10 m up, flown in five frames; prints where to
//! land after each one. Built by `cargo test`; run it against a server:
//!
//! ```sh
//! cargo run -p landing-client --example fused_approach -- http://127.0.0.1:50051
//! ```

use landing_client::v1::{Frame, PipelineOptions, SegmentationMode};
use landing_client::{
    ClientConfig, ClientError, FrameBuilder, FrameOutcome, LandingClient, PointCloudBuilder,
    StreamConfig,
};

#[tokio::main]
async fn main() -> Result<(), ClientError> {
    let server = std::env::args()
        .nth(1)
        .unwrap_or_else(|| landing_client::DEFAULT_SERVER.to_owned());
    let frames: Vec<Frame> = (0..5).map(roof_frame).collect::<Result<_, _>>()?;

    let client = LandingClient::connect(ClientConfig::new(server)).await?;
    let config = StreamConfig::fused().with_options(PipelineOptions {
        segmentation_mode: SegmentationMode::PointClasses as i32,
        ..Default::default()
    });
    let mut answers = client.stream(tokio_stream::iter(frames), config);
    while let Some(item) = answers.next().await {
        let item = item?;
        match &item.outcome {
            FrameOutcome::Result(r) => match r.best() {
                Some(best) => println!(
                    "frame {}: land at {:?}, {:.1} m clear, {} hole(s), fused from {} frame(s)",
                    item.sequence,
                    best.center_xyz(),
                    best.safe_radius_m,
                    best.holes().len(),
                    r.fusion.as_ref().map_or(0, |f| f.frames)
                ),
                None => println!("frame {}: no site yet", item.sequence),
            },
            other => println!("frame {}: {}", item.sequence, other.label()),
        }
    }
    Ok(())
}

/// One scan of the roof in world coordinates, every point classed as roof (4), a little more of
/// it seen in each frame.
fn roof_frame(sequence: u64) -> Result<Frame, ClientError> {
    let side = 12 + 2 * sequence as usize;
    let points: Vec<[f32; 3]> = (0..side * side)
        .map(|i| [(i % side) as f32, (i / side) as f32, 10.0])
        .collect();
    let classes = vec![4u8; points.len()];
    let cloud = PointCloudBuilder::new(&points)
        .classes(&classes)
        .frame_id("world")
        .build()?;
    Ok(FrameBuilder::new(sequence, cloud)
        .drone_id("example")
        .build())
}
