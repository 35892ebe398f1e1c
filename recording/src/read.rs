//! Reading the frames of a recording, each with the ground truth and label image logged with it.

use std::collections::BTreeMap;
use std::path::Path;

use landing_proto::v1;
use prost::Message;

use crate::{Error, FRAME_SCHEMA, LABELS_SCHEMA, LABELS_TOPIC, TRUTH_SCHEMA};

/// One frame of a recording.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedFrame {
    /// The topic it was recorded on.
    pub topic: String,
    /// MCAP log time, nanoseconds.
    pub log_time_ns: u64,
    /// The frame.
    pub frame: v1::Frame,
    /// The ground truth logged at the same time, if any.
    pub truth: Option<v1::GroundTruth>,
    /// The label image logged at the same time on [`LABELS_TOPIC`], if any.
    pub labels: Option<v1::CameraImage>,
}

/// Reads every `landing.v1.Frame` of the MCAP file at `path`, in file order.
pub fn read(path: &Path) -> Result<Vec<RecordedFrame>, Error> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    read_bytes(&bytes)
}

/// Like [`read`], from the bytes of a whole file.
///
/// A malformed file is an error, never a panic: mcap 0.26 panics on some (an unchecked length
/// addition in its record reader, found by the `recording` fuzz target; see RELIABILITY.md), so
/// its parsing runs under `catch_unwind` and a panic becomes [`Error::Mcap`].
pub fn read_bytes(bytes: &[u8]) -> Result<Vec<RecordedFrame>, Error> {
    check_chunk_sizes(bytes)?;
    // Nothing outside the closure is touched: a panic leaves no half-updated state behind.
    std::panic::catch_unwind(|| read_messages(bytes)).unwrap_or_else(|_| {
        Err(Error::Mcap(
            "malformed file: the MCAP reader gave up on a record length".into(),
        ))
    })
}

/// The largest uncompressed chunk a recording may declare. mcap 0.26 reserves a chunk's
/// declared uncompressed size before it decompresses, and a reservation that fails aborts the
/// process: no `catch_unwind` can answer it (found by the `recording` fuzz target, a chunk
/// claiming 5.8e17 bytes). Our writer's chunks hold a frame or a few, far below this.
pub const MAX_CHUNK_BYTES: u64 = 1 << 30;

/// Walks the file's top-level records (opcode, u64 length, body) and refuses a chunk that
/// declares more than [`MAX_CHUNK_BYTES`] uncompressed; everything else is mcap's to judge.
fn check_chunk_sizes(bytes: &[u8]) -> Result<(), Error> {
    const CHUNK: u8 = 0x06;
    const FOOTER: u8 = 0x02;
    const MAGIC: usize = 8;
    let u64_at = |at: usize| {
        let b = bytes.get(at..at.checked_add(8)?)?;
        Some(u64::from_le_bytes(b.try_into().ok()?))
    };
    let mut at = MAGIC;
    // `at` is within the file whenever it is added to (`get` checks it first), so no sum here
    // can overflow; the next record's offset is a checked sum.
    while let Some(&opcode) = bytes.get(at) {
        let Some(length) = u64_at(at + 1) else { break };
        let body = at + 9;
        // A chunk's body starts with its message start and end times, then its uncompressed size.
        if opcode == CHUNK
            && let Some(size) = u64_at(body + 16)
            && size > MAX_CHUNK_BYTES
        {
            return Err(Error::Mcap(format!(
                "malformed file: the chunk at byte {at} declares {size} bytes uncompressed, \
                 more than the {MAX_CHUNK_BYTES} a recording may hold in one chunk"
            )));
        }
        match usize::try_from(length)
            .ok()
            .and_then(|l| body.checked_add(l))
        {
            Some(next) if opcode != FOOTER => at = next,
            _ => break,
        }
    }
    Ok(())
}

fn read_messages(bytes: &[u8]) -> Result<Vec<RecordedFrame>, Error> {
    let mut frames = Vec::new();
    let mut truths = BTreeMap::new();
    let mut labels = BTreeMap::new();
    for message in mcap::MessageStream::new(bytes)? {
        let message = message?;
        let schema = message
            .channel
            .schema
            .as_ref()
            .filter(|s| s.encoding == "protobuf")
            .map(|s| s.name.as_str());
        let topic = &message.channel.topic;
        let decode_error = |schema: &'static str, e: prost::DecodeError| Error::Decode {
            topic: topic.clone(),
            sequence: message.sequence,
            schema,
            reason: e.to_string(),
        };
        match schema {
            Some(FRAME_SCHEMA) => {
                let frame = v1::Frame::decode(&message.data[..])
                    .map_err(|e| decode_error(FRAME_SCHEMA, e))?;
                frames.push(RecordedFrame {
                    topic: topic.clone(),
                    log_time_ns: message.log_time,
                    frame,
                    truth: None,
                    labels: None,
                });
            }
            Some(TRUTH_SCHEMA) => {
                let truth = v1::GroundTruth::decode(&message.data[..])
                    .map_err(|e| decode_error(TRUTH_SCHEMA, e))?;
                truths.insert(message.log_time, truth);
            }
            Some(LABELS_SCHEMA) if topic == LABELS_TOPIC => {
                let image = v1::CameraImage::decode(&message.data[..])
                    .map_err(|e| decode_error(LABELS_SCHEMA, e))?;
                labels.insert(message.log_time, image);
            }
            _ => {}
        }
    }
    if frames.is_empty() {
        return Err(Error::NoFrames);
    }
    for f in &mut frames {
        f.truth = truths.remove(&f.log_time_ns);
        f.labels = labels.remove(&f.log_time_ns);
    }
    Ok(frames)
}
