//! Reading frames from MCAP recordings and writing stream results as MCAP.
//!
//! A recording holds `landing.v1.Frame` messages (protobuf encoding, the schema named by the
//! fully-qualified message name) on one or more topics, next to ground truth the client ignores
//! and, in the simulator's recordings, the true label image of each frame (`/camera/labels`,
//! same log time), which `--segmentation class-image` sends as the frame's class image.
//! Results are written as `landing.v1.StreamLandingSitesResponse` messages with the log time of
//! the frame they answer, so both files line up when opened together in Foxglove.

use std::collections::BTreeMap;
use std::io::{BufWriter, Seek, Write};
use std::path::Path;

use landing_proto::v1::{CameraImage, Frame, StreamLandingSitesResponse};
pub use landing_sim::recording::LABELS_TOPIC;
use prost::Message;

use crate::ClientError;

/// The schema name of recorded frames.
pub const FRAME_SCHEMA: &str = "landing.v1.Frame";
/// The schema name of written results.
pub const RESULT_SCHEMA: &str = "landing.v1.StreamLandingSitesResponse";
/// The topic results are written to.
pub const RESULT_TOPIC: &str = "/landing/results";

/// One frame of a recording.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedFrame {
    /// The topic it was recorded on.
    pub topic: String,
    /// MCAP log time, nanoseconds.
    pub log_time_ns: u64,
    /// The frame.
    pub frame: Frame,
    /// The label image recorded with it on [`LABELS_TOPIC`], if any.
    pub labels: Option<CameraImage>,
}

/// Reads every `landing.v1.Frame` of the recording, in file order.
pub fn read_frames(path: &Path) -> Result<Vec<RecordedFrame>, ClientError> {
    let bytes = std::fs::read(path).map_err(|e| ClientError::io(path, e))?;
    frames_from_bytes(&bytes).map_err(|reason| ClientError::Recording {
        path: path.display().to_string(),
        reason,
    })
}

/// Parses the frames of an MCAP file held in memory.
pub fn frames_from_bytes(bytes: &[u8]) -> Result<Vec<RecordedFrame>, String> {
    let mut frames = Vec::new();
    let mut labels = BTreeMap::new();
    let stream = mcap::MessageStream::new(bytes).map_err(|e| e.to_string())?;
    for message in stream {
        let message = message.map_err(|e| e.to_string())?;
        if message.channel.topic == LABELS_TOPIC {
            let image = CameraImage::decode(&message.data[..])
                .map_err(|e| format!("message {} on `{LABELS_TOPIC}`: {e}", message.sequence))?;
            labels.insert(message.log_time, image);
            continue;
        }
        let is_frame = message
            .channel
            .schema
            .as_ref()
            .is_some_and(|s| s.name == FRAME_SCHEMA && s.encoding == "protobuf");
        if !is_frame {
            continue;
        }
        let frame = Frame::decode(&message.data[..]).map_err(|e| {
            format!(
                "message {} on `{}` is not a landing.v1.Frame: {e}",
                message.sequence, message.channel.topic
            )
        })?;
        frames.push(RecordedFrame {
            topic: message.channel.topic.clone(),
            log_time_ns: message.log_time,
            frame,
            labels: None,
        });
    }
    if frames.is_empty() {
        return Err(format!("no `{FRAME_SCHEMA}` messages (protobuf) found"));
    }
    for f in &mut frames {
        f.labels = labels.remove(&f.log_time_ns);
    }
    Ok(frames)
}

/// Writes stream responses to an MCAP file.
pub struct ResultWriter<W: Write + Seek> {
    writer: mcap::Writer<W>,
    channel: u16,
    sequence: u32,
}

impl ResultWriter<BufWriter<std::fs::File>> {
    /// Creates (or truncates) `path`.
    pub fn create(path: &Path) -> Result<Self, ClientError> {
        let file = std::fs::File::create(path).map_err(|e| ClientError::io(path, e))?;
        Self::new(BufWriter::new(file)).map_err(|e| match e {
            ClientError::Recording { reason, .. } => ClientError::Recording {
                path: path.display().to_string(),
                reason,
            },
            other => other,
        })
    }
}

impl<W: Write + Seek> ResultWriter<W> {
    /// Starts a recording on `w`.
    pub fn new(w: W) -> Result<Self, ClientError> {
        let err = |e: mcap::McapError| ClientError::Recording {
            path: String::new(),
            reason: e.to_string(),
        };
        let mut writer = mcap::WriteOptions::new()
            .profile("")
            .library(concat!("landing-client ", env!("CARGO_PKG_VERSION")))
            .create(w)
            .map_err(err)?;
        let schema = writer
            .add_schema(
                RESULT_SCHEMA,
                "protobuf",
                landing_proto::FILE_DESCRIPTOR_SET,
            )
            .map_err(err)?;
        let channel = writer
            .add_channel(schema, RESULT_TOPIC, "protobuf", &BTreeMap::new())
            .map_err(err)?;
        Ok(Self {
            writer,
            channel,
            sequence: 0,
        })
    }

    /// Appends one response, logged at `log_time_ns` (use the answered frame's log time).
    pub fn write(
        &mut self,
        log_time_ns: u64,
        response: &StreamLandingSitesResponse,
    ) -> Result<(), ClientError> {
        self.sequence += 1;
        self.writer
            .write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id: self.channel,
                    sequence: self.sequence,
                    log_time: log_time_ns,
                    publish_time: log_time_ns,
                },
                &response.encode_to_vec(),
            )
            .map_err(|e| ClientError::Recording {
                path: String::new(),
                reason: e.to_string(),
            })
    }

    /// Writes the summary and flushes.
    pub fn finish(mut self) -> Result<W, ClientError> {
        let err = |e: mcap::McapError| ClientError::Recording {
            path: String::new(),
            reason: e.to_string(),
        };
        self.writer.finish().map_err(err)?;
        Ok(self.writer.into_inner())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use landing_proto::v1::{FrameResult, stream_landing_sites_response::Outcome};

    /// Writes frames the way a recorder does, with a second, unrelated channel in between.
    fn recording(frames: &[Frame]) -> Vec<u8> {
        let mut w = mcap::Writer::new(std::io::Cursor::new(Vec::new())).unwrap();
        let s = w
            .add_schema(FRAME_SCHEMA, "protobuf", landing_proto::FILE_DESCRIPTOR_SET)
            .unwrap();
        let c = w
            .add_channel(s, "/drone/frame", "protobuf", &BTreeMap::new())
            .unwrap();
        let other = w
            .add_channel(0, "/truth", "json", &BTreeMap::new())
            .unwrap();
        for (i, f) in frames.iter().enumerate() {
            let h = |channel_id| mcap::records::MessageHeader {
                channel_id,
                sequence: i as u32,
                log_time: i as u64 * 100_000_000,
                publish_time: 0,
            };
            w.write_to_known_channel(&h(c), &f.encode_to_vec()).unwrap();
            w.write_to_known_channel(&h(other), b"{}").unwrap();
        }
        w.finish().unwrap();
        w.into_inner().into_inner()
    }

    #[test]
    fn reads_only_frame_messages_in_order() {
        let frames: Vec<Frame> = (0..3)
            .map(|i| Frame {
                sequence: i,
                drone_id: "d".into(),
                ..Default::default()
            })
            .collect();
        let read = frames_from_bytes(&recording(&frames)).unwrap();
        assert_eq!(read.len(), 3);
        assert_eq!(read[2].frame, frames[2]);
        assert_eq!(read[1].log_time_ns, 100_000_000);
        assert_eq!(read[0].topic, "/drone/frame");
    }

    #[test]
    fn the_simulators_label_images_come_with_their_frames() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../samples/rooftops.mcap");
        let read = read_frames(&path).unwrap();
        assert!(!read.is_empty());
        for r in &read {
            let labels = r.labels.as_ref().expect("every simulated frame has labels");
            let image = r.frame.image.as_ref().unwrap();
            // Same camera, same moment: the labels are the image's.
            assert_eq!(labels.calibration, image.calibration);
            assert_eq!(labels.pose, image.pose);
            assert_eq!(labels.timestamp, r.frame.timestamp);
        }
        // A recording without them reads as before.
        let bare = frames_from_bytes(&recording(&[Frame::default()])).unwrap();
        assert_eq!(bare[0].labels, None);
    }

    #[test]
    fn a_file_without_frames_is_an_error() {
        let err = frames_from_bytes(&recording(&[])).unwrap_err();
        assert!(err.contains("no `landing.v1.Frame`"), "{err}");
        assert!(frames_from_bytes(b"not an mcap file").is_err());
    }

    #[test]
    fn written_results_read_back() {
        let mut w = ResultWriter::new(std::io::Cursor::new(Vec::new())).unwrap();
        let response = StreamLandingSitesResponse {
            sequence: 4,
            outcome: Some(Outcome::Result(FrameResult {
                sequence: 4,
                ..Default::default()
            })),
        };
        w.write(42, &response).unwrap();
        let bytes = w.finish().unwrap().into_inner();
        let msgs: Vec<_> = mcap::MessageStream::new(&bytes)
            .unwrap()
            .map(|m| m.unwrap())
            .collect();
        assert_eq!(msgs.len(), 1);
        assert_eq!(msgs[0].log_time, 42);
        assert_eq!(msgs[0].channel.topic, RESULT_TOPIC);
        assert_eq!(
            StreamLandingSitesResponse::decode(&msgs[0].data[..]).unwrap(),
            response
        );
    }
}
