//! Writing recordings: frames, ground truth, label images and the service's answers.

use std::collections::BTreeMap;
use std::io::{BufWriter, Seek, Write};
use std::path::Path;

use landing_proto::v1;
use prost::Message;

use crate::{
    Error, FRAME_SCHEMA, FRAME_TOPIC, LABELS_SCHEMA, LABELS_TOPIC, RESULT_SCHEMA, RESULT_TOPIC,
    TRUTH_SCHEMA, TRUTH_TOPIC,
};

/// An MCAP writer (zstd chunks) for the channels of this crate. A channel is added when its first
/// message is written, so a file holds only the channels it uses. Give the messages of one frame
/// the same log time: that is how [`crate::read`] pairs them.
pub struct Writer<W: Write + Seek> {
    writer: mcap::Writer<W>,
    /// Channel id and message count per topic.
    channels: BTreeMap<&'static str, (u16, u32)>,
}

impl Writer<BufWriter<std::fs::File>> {
    /// Creates (or truncates) the file at `path`.
    pub fn create(path: &Path, library: &str) -> Result<Self, Error> {
        let file = std::fs::File::create(path).map_err(|e| Error::io(path, e))?;
        Self::new(BufWriter::new(file), library)
    }
}

impl<W: Write + Seek> Writer<W> {
    /// Starts a recording on `w`; `library` names the writing program in the file's header.
    pub fn new(w: W, library: &str) -> Result<Self, Error> {
        let writer = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .profile("")
            .library(library)
            .create(w)?;
        Ok(Self {
            writer,
            channels: BTreeMap::new(),
        })
    }

    /// Appends a frame on [`FRAME_TOPIC`]; its MCAP sequence is the frame's (truncated to 32 bits).
    pub fn write_frame(&mut self, log_time_ns: u64, frame: &v1::Frame) -> Result<(), Error> {
        self.write(
            FRAME_TOPIC,
            FRAME_SCHEMA,
            log_time_ns,
            Some(frame.sequence),
            frame,
        )
    }

    /// Appends a frame's ground truth on [`TRUTH_TOPIC`].
    pub fn write_truth(&mut self, log_time_ns: u64, truth: &v1::GroundTruth) -> Result<(), Error> {
        self.write(
            TRUTH_TOPIC,
            TRUTH_SCHEMA,
            log_time_ns,
            Some(truth.sequence),
            truth,
        )
    }

    /// Appends a frame's true label image on [`LABELS_TOPIC`].
    pub fn write_labels(
        &mut self,
        log_time_ns: u64,
        sequence: u64,
        labels: &v1::CameraImage,
    ) -> Result<(), Error> {
        self.write(
            LABELS_TOPIC,
            LABELS_SCHEMA,
            log_time_ns,
            Some(sequence),
            labels,
        )
    }

    /// Appends an answer on [`RESULT_TOPIC`]; use the answered frame's log time.
    pub fn write_result(
        &mut self,
        log_time_ns: u64,
        response: &v1::StreamLandingSitesResponse,
    ) -> Result<(), Error> {
        self.write(RESULT_TOPIC, RESULT_SCHEMA, log_time_ns, None, response)
    }

    /// Writes the summary and returns the sink.
    pub fn finish(mut self) -> Result<W, Error> {
        self.writer.finish()?;
        Ok(self.writer.into_inner())
    }

    /// `sequence` is the MCAP message sequence; `None` counts the topic's messages from 1.
    fn write(
        &mut self,
        topic: &'static str,
        schema: &'static str,
        log_time_ns: u64,
        sequence: Option<u64>,
        message: &impl Message,
    ) -> Result<(), Error> {
        let (channel, count) = match self.channels.get_mut(topic) {
            Some(entry) => entry,
            None => {
                let schema_id = self.writer.add_schema(
                    schema,
                    "protobuf",
                    landing_proto::FILE_DESCRIPTOR_SET,
                )?;
                let channel =
                    self.writer
                        .add_channel(schema_id, topic, "protobuf", &BTreeMap::new())?;
                self.channels.entry(topic).or_insert((channel, 0))
            }
        };
        *count += 1;
        let header = mcap::records::MessageHeader {
            channel_id: *channel,
            sequence: sequence.map_or(*count, |s| s as u32),
            log_time: log_time_ns,
            publish_time: log_time_ns,
        };
        self.writer
            .write_to_known_channel(&header, &message.encode_to_vec())?;
        Ok(())
    }
}

/// Nanoseconds since the Unix epoch of a protobuf timestamp (0 before the epoch).
pub fn log_time_ns(ts: &prost_types::Timestamp) -> u64 {
    u64::try_from(ts.seconds)
        .unwrap_or(0)
        .saturating_mul(1_000_000_000)
        .saturating_add(u64::try_from(ts.nanos).unwrap_or(0))
}
