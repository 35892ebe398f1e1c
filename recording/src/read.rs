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
/// A malformed file is an error, never a panic or an abort. mcap 0.26 panics on some files (an
/// unchecked length addition in its record reader), so its parsing runs under `catch_unwind` and
/// a panic becomes [`Error::Mcap`]; and it reserves memory for each record a chunk declares, so a
/// declared length near 2^64 failed to allocate and aborted the process, which no
/// `catch_unwind` can answer. Records are therefore read with mcap's own
/// `record_length_limit`, [`MAX_RECORD_BYTES`]. Both were found by the `recording` fuzz target
/// (RELIABILITY.md).
pub fn read_bytes(bytes: &[u8]) -> Result<Vec<RecordedFrame>, Error> {
    // Nothing outside the closure is touched: a panic leaves no half-updated state behind.
    std::panic::catch_unwind(|| read_messages(bytes)).unwrap_or_else(|_| {
        Err(Error::Mcap(
            "malformed file: the MCAP reader gave up on a record length".into(),
        ))
    })
}

/// The largest record a recording may hold: twice the server's 64 MiB request limit, a frame's
/// most. mcap zero-fills a record's buffer before decompressing into it, so this is also the
/// most memory a small malformed file can make the reader take (the fuzzer's peak RSS follows
/// it).
pub const MAX_RECORD_BYTES: usize = 128 << 20;

/// The messages of a whole MCAP file, read with the record length limit.
fn messages(bytes: &[u8]) -> impl Iterator<Item = Result<mcap::Message<'static>, Error>> + '_ {
    use mcap::sans_io::{LinearReaderOptions, MessageReadEvent, MessageReader};
    let mut reader = MessageReader::new_with_options(
        LinearReaderOptions::default().with_record_length_limit(MAX_RECORD_BYTES),
    );
    let mut rest = bytes;
    std::iter::from_fn(move || {
        loop {
            match reader.next_event()? {
                Ok(MessageReadEvent::ReadRequest(want)) => {
                    // At the end of the file this inserts nothing, and the reader says what is
                    // missing.
                    let n = want.min(rest.len());
                    reader.insert(n).copy_from_slice(&rest[..n]);
                    reader.notify_read(n);
                    rest = &rest[n..];
                }
                Ok(MessageReadEvent::Message(m)) => return Some(Ok(m)),
                Err(e) => return Some(Err(e.into())),
            }
        }
    })
}

fn read_messages(bytes: &[u8]) -> Result<Vec<RecordedFrame>, Error> {
    let mut frames = Vec::new();
    let mut truths = BTreeMap::new();
    let mut labels = BTreeMap::new();
    for message in messages(bytes) {
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
