//! Reading the frames of a recording, each with the ground truth and label image logged with it.

use std::collections::BTreeMap;
use std::path::Path;

use landing_proto::v1;
use prost::Message;

use foxglove::messages as fox;

use crate::convert::{self, FoxgloveFrame, Image};
use crate::{
    CALIBRATION_TOPIC, CAMERA_RAW_TOPIC, CAMERA_TOPIC, Error, FRAME_HEADER_SCHEMA, FRAME_SCHEMA,
    FRAME_TOPIC, LABELS_RAW_TOPIC, LABELS_SCHEMA, LABELS_TOPIC, LIDAR_TOPIC, TF_TOPIC,
    TRUTH_SCHEMA,
};

/// One frame of a recording.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedFrame {
    /// The topic of its scan ([`crate::LIDAR_TOPIC`]), or of the whole `landing.v1.Frame`.
    pub topic: String,
    /// MCAP log time, nanoseconds.
    pub log_time_ns: u64,
    /// The frame.
    pub frame: v1::Frame,
    /// The ground truth logged at the same time, if any.
    pub truth: Option<v1::GroundTruth>,
    /// The true label image logged at the same time on [`LABELS_TOPIC`], if any, with the
    /// camera's pose and calibration.
    pub labels: Option<v1::CameraImage>,
}

/// Reads every frame of the MCAP file at `path`, in file order: one per log time with a header on
/// [`crate::FRAME_TOPIC`] or a `foxglove.PointCloud` on [`LIDAR_TOPIC`], put back together with
/// the cloud, image, calibration and transforms of that log time, and one per whole
/// `landing.v1.Frame` on any topic.
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

/// What one log time holds, before the frame is put back together.
#[derive(Default)]
struct Moment {
    header: Option<v1::FrameHeader>,
    /// The cloud and its MCAP sequence (the frame's, when there is no header).
    cloud: Option<(fox::PointCloud, u32)>,
    image: Option<Image>,
    calibration: Option<fox::CameraCalibration>,
    transforms: Option<fox::FrameTransforms>,
    labels: Option<Image>,
    legacy_labels: Option<v1::CameraImage>,
    truth: Option<v1::GroundTruth>,
}

/// The frames in file order: one put together from the Foxglove channels (by the log time of its
/// header or, from other tools, of its cloud) or a whole `landing.v1.Frame`.
enum Entry {
    Foxglove(u64),
    Whole(Box<RecordedFrame>),
}

fn read_messages(bytes: &[u8]) -> Result<Vec<RecordedFrame>, Error> {
    let mut entries = Vec::new();
    let mut moments: BTreeMap<u64, Moment> = BTreeMap::new();
    for message in messages(bytes) {
        file_message(&message?, &mut entries, &mut moments)?;
    }
    let mut frames = Vec::with_capacity(entries.len());
    for entry in entries {
        let mut frame = match entry {
            Entry::Whole(frame) => *frame,
            Entry::Foxglove(at) => assemble(at, &mut moments)?,
        };
        if let Some(m) = moments.get_mut(&frame.log_time_ns) {
            frame.truth = m.truth.take();
            if frame.labels.is_none() {
                frame.labels = m.legacy_labels.take();
            }
        }
        frames.push(frame);
    }
    if frames.is_empty() {
        return Err(Error::NoFrames);
    }
    Ok(frames)
}

/// Files one message: a whole `landing.v1.Frame` as an entry of its own, a part of a Foxglove
/// frame into the moment of its log time. Other schemas, topics and encodings are skipped.
fn file_message(
    message: &mcap::Message<'_>,
    entries: &mut Vec<Entry>,
    moments: &mut BTreeMap<u64, Moment>,
) -> Result<(), Error> {
    let Some(schema) = message
        .channel
        .schema
        .as_ref()
        .filter(|s| s.encoding == "protobuf")
        .map(|s| s.name.as_str())
    else {
        return Ok(());
    };
    let topic = message.channel.topic.as_str();
    let at = message.log_time;
    match (schema, topic) {
        (FRAME_SCHEMA, _) => entries.push(Entry::Whole(Box::new(RecordedFrame {
            topic: topic.to_string(),
            log_time_ns: at,
            frame: decode(message, FRAME_SCHEMA)?,
            truth: None,
            labels: None,
        }))),
        (FRAME_HEADER_SCHEMA, FRAME_TOPIC) => {
            let header = decode(message, FRAME_HEADER_SCHEMA)?;
            frame_moment(at, entries, moments).header = Some(header);
        }
        ("foxglove.PointCloud", LIDAR_TOPIC) => {
            let cloud = decode(message, "foxglove.PointCloud")?;
            frame_moment(at, entries, moments).cloud = Some((cloud, message.sequence));
        }
        ("foxglove.CompressedImage", CAMERA_TOPIC) => {
            moments.entry(at).or_default().image = Some(Image::Compressed(decode(
                message,
                "foxglove.CompressedImage",
            )?));
        }
        ("foxglove.RawImage", CAMERA_RAW_TOPIC) => {
            moments.entry(at).or_default().image =
                Some(Image::Raw(decode(message, "foxglove.RawImage")?));
        }
        ("foxglove.CameraCalibration", CALIBRATION_TOPIC) => {
            moments.entry(at).or_default().calibration =
                Some(decode(message, "foxglove.CameraCalibration")?);
        }
        ("foxglove.FrameTransforms", TF_TOPIC) => {
            moments.entry(at).or_default().transforms =
                Some(decode(message, "foxglove.FrameTransforms")?);
        }
        ("foxglove.CompressedImage", LABELS_TOPIC) => {
            moments.entry(at).or_default().labels = Some(Image::Compressed(decode(
                message,
                "foxglove.CompressedImage",
            )?));
        }
        ("foxglove.RawImage", LABELS_RAW_TOPIC) => {
            moments.entry(at).or_default().labels =
                Some(Image::Raw(decode(message, "foxglove.RawImage")?));
        }
        (LABELS_SCHEMA, LABELS_TOPIC) => {
            moments.entry(at).or_default().legacy_labels = Some(decode(message, LABELS_SCHEMA)?);
        }
        (TRUTH_SCHEMA, _) => {
            moments.entry(at).or_default().truth = Some(decode(message, TRUTH_SCHEMA)?);
        }
        _ => {}
    }
    Ok(())
}

/// The moment of log time `at` for a frame's header or cloud; the first of the two to come
/// opens the frame's entry, so frames keep file order.
fn frame_moment<'a>(
    at: u64,
    entries: &mut Vec<Entry>,
    moments: &'a mut BTreeMap<u64, Moment>,
) -> &'a mut Moment {
    let m = moments.entry(at).or_default();
    if m.header.is_none() && m.cloud.is_none() {
        entries.push(Entry::Foxglove(at));
    }
    m
}

/// The message's data decoded as `schema`.
fn decode<T: Message + Default>(
    message: &mcap::Message<'_>,
    schema: &'static str,
) -> Result<T, Error> {
    T::decode(&message.data[..]).map_err(|e| Error::Decode {
        topic: message.channel.topic.clone(),
        sequence: message.sequence,
        schema,
        reason: e.to_string(),
    })
}

/// The frame of log time `at` from its Foxglove messages; the label image takes the camera's pose
/// and calibration. A cloud without a header keeps the cloud's MCAP sequence and time.
fn assemble(at: u64, moments: &mut BTreeMap<u64, Moment>) -> Result<RecordedFrame, Error> {
    let m = moments.entry(at).or_default();
    let (cloud, sequence) = m.cloud.take().unzip();
    let sequence = sequence.unwrap_or_default();
    // A scan recorded by another tool, without our header: its MCAP sequence and time.
    let header = m.header.take().unwrap_or_else(|| v1::FrameHeader {
        sequence: u64::from(sequence),
        timestamp: cloud
            .as_ref()
            .and_then(|c| c.timestamp)
            .map(convert::from_fox_time),
        ..Default::default()
    });
    let sequence = header.sequence as u32;
    let parts = FoxgloveFrame {
        header,
        cloud,
        image: m.image.take(),
        calibration: m.calibration.take(),
        transforms: m.transforms.take().unwrap_or_default(),
    };
    let invalid = |topic: &str, reason: String| Error::Decode {
        topic: topic.to_string(),
        sequence,
        schema: "foxglove.CameraCalibration",
        reason,
    };
    let frame = convert::frame_from_foxglove(&parts).map_err(|e| invalid(CALIBRATION_TOPIC, e))?;
    let labels = match m.labels.take() {
        Some(image) => Some(
            convert::camera_from_foxglove(&image, parts.calibration.as_ref(), &parts.transforms)
                .map_err(|e| invalid(CALIBRATION_TOPIC, e))?,
        ),
        None => None,
    };
    Ok(RecordedFrame {
        topic: LIDAR_TOPIC.to_string(),
        log_time_ns: at,
        frame,
        truth: None,
        labels,
    })
}
