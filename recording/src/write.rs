//! Writing recordings: frames, ground truth, label images and the service's answers, each with its
//! Foxglove drawing.

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::io::{BufWriter, Seek, Write};
use std::path::Path;

use foxglove::Encode;
use landing_proto::v1;
use prost::Message;

use crate::convert::{self, FoxgloveFrame, Image};
use crate::{
    ANNOTATIONS_TOPIC, CALIBRATION_TOPIC, CAMERA_RAW_TOPIC, CAMERA_TOPIC, Error,
    FRAME_HEADER_SCHEMA, FRAME_TOPIC, LABELS_RAW_TOPIC, LABELS_TOPIC, LIDAR_TOPIC, RESULT_SCHEMA,
    RESULT_TOPIC, SITES_TOPIC, TF_TOPIC, TRUTH_SCENE_TOPIC, TRUTH_SCHEMA, TRUTH_TOPIC, scene,
};

/// An MCAP writer (zstd chunks) for the channels of this crate. A channel is added when its first
/// message is written, so a file holds only the channels it uses. Give the messages of one frame
/// the same log time: that is how [`crate::read`] pairs them.
pub struct Writer<W: Write + Seek> {
    writer: mcap::Writer<W>,
    /// Schema id per schema name.
    schemas: BTreeMap<String, u16>,
    /// Channel id and message count per topic.
    channels: BTreeMap<&'static str, (u16, u32)>,
}

/// A message and the schema it is recorded under.
trait Recorded: Message {
    fn schema() -> (Cow<'static, str>, Cow<'static, [u8]>);
}

macro_rules! landing_schema {
    ($($t:ty => $name:expr),* $(,)?) => {$(
        impl Recorded for $t {
            fn schema() -> (Cow<'static, str>, Cow<'static, [u8]>) {
                ($name.into(), landing_proto::FILE_DESCRIPTOR_SET.into())
            }
        }
    )*};
}

landing_schema!(
    v1::FrameHeader => FRAME_HEADER_SCHEMA,
    v1::GroundTruth => TRUTH_SCHEMA,
    v1::StreamLandingSitesResponse => RESULT_SCHEMA,
);

macro_rules! foxglove_schema {
    ($($t:ty),* $(,)?) => {$(
        impl Recorded for $t {
            fn schema() -> (Cow<'static, str>, Cow<'static, [u8]>) {
                let s = <$t as Encode>::get_schema().expect("every Foxglove schema type has a schema");
                (s.name.into(), s.data)
            }
        }
    )*};
}

use foxglove::messages as fox;
foxglove_schema!(
    fox::PointCloud,
    fox::CompressedImage,
    fox::RawImage,
    fox::CameraCalibration,
    fox::FrameTransforms,
    fox::SceneUpdate,
    fox::ImageAnnotations,
);

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
            schemas: BTreeMap::new(),
            channels: BTreeMap::new(),
        })
    }

    /// Appends a frame: its header on [`FRAME_TOPIC`], and its scan, camera image, calibration
    /// and sensor poses on their Foxglove channels. The MCAP sequence of each is the frame's
    /// (truncated to 32 bits).
    pub fn write_frame(&mut self, log_time_ns: u64, frame: &v1::Frame) -> Result<(), Error> {
        let parts = convert::frame_to_foxglove(frame)?;
        self.write_foxglove_frame(log_time_ns, &parts)
    }

    /// Like [`Writer::write_frame`], for a frame already split into its Foxglove messages.
    pub fn write_foxglove_frame(
        &mut self,
        log_time_ns: u64,
        parts: &FoxgloveFrame,
    ) -> Result<(), Error> {
        let seq = Some(parts.header.sequence);
        self.write(FRAME_TOPIC, log_time_ns, seq, &parts.header)?;
        if let Some(cloud) = &parts.cloud {
            self.write(LIDAR_TOPIC, log_time_ns, seq, cloud)?;
        }
        match &parts.image {
            Some(Image::Compressed(img)) => self.write(CAMERA_TOPIC, log_time_ns, seq, img)?,
            Some(Image::Raw(img)) => self.write(CAMERA_RAW_TOPIC, log_time_ns, seq, img)?,
            None => {}
        }
        if let Some(calibration) = &parts.calibration {
            self.write(CALIBRATION_TOPIC, log_time_ns, seq, calibration)?;
        }
        if !parts.transforms.transforms.is_empty() {
            self.write(TF_TOPIC, log_time_ns, seq, &parts.transforms)?;
        }
        Ok(())
    }

    /// Appends a frame's ground truth on [`TRUTH_TOPIC`], and its drawing on
    /// [`TRUTH_SCENE_TOPIC`].
    pub fn write_truth(&mut self, log_time_ns: u64, truth: &v1::GroundTruth) -> Result<(), Error> {
        let seq = Some(truth.sequence);
        self.write(TRUTH_TOPIC, log_time_ns, seq, truth)?;
        self.write(
            TRUTH_SCENE_TOPIC,
            log_time_ns,
            seq,
            &scene::truth_scene(truth),
        )
    }

    /// Appends a frame's true label image on [`LABELS_TOPIC`] (raw: [`LABELS_RAW_TOPIC`]). It is
    /// pixel-registered with the camera image, whose pose and calibration it shares.
    pub fn write_labels(
        &mut self,
        log_time_ns: u64,
        sequence: u64,
        labels: &v1::CameraImage,
    ) -> Result<(), Error> {
        let seq = Some(sequence);
        match convert::camera_to_foxglove(labels).0 {
            Some(Image::Compressed(img)) => self.write(LABELS_TOPIC, log_time_ns, seq, &img),
            Some(Image::Raw(img)) => self.write(LABELS_RAW_TOPIC, log_time_ns, seq, &img),
            None => Ok(()),
        }
    }

    /// Appends an answer on [`RESULT_TOPIC`], drawn on [`SITES_TOPIC`] and, given the answered
    /// frame's camera image, on [`ANNOTATIONS_TOPIC`]. Use the answered frame's log time.
    pub fn write_result(
        &mut self,
        log_time_ns: u64,
        response: &v1::StreamLandingSitesResponse,
        camera: Option<&v1::CameraImage>,
    ) -> Result<(), Error> {
        self.write(RESULT_TOPIC, log_time_ns, None, response)?;
        self.write(
            SITES_TOPIC,
            log_time_ns,
            None,
            &scene::sites_scene(response),
        )?;
        if let Some(a) = camera.and_then(|c| scene::sites_annotations(response, c)) {
            self.write(ANNOTATIONS_TOPIC, log_time_ns, None, &a)?;
        }
        Ok(())
    }

    /// Writes the summary and returns the sink.
    pub fn finish(mut self) -> Result<W, Error> {
        self.writer.finish()?;
        Ok(self.writer.into_inner())
    }

    /// `sequence` is the MCAP message sequence; `None` counts the topic's messages from 1.
    fn write<M: Recorded>(
        &mut self,
        topic: &'static str,
        log_time_ns: u64,
        sequence: Option<u64>,
        message: &M,
    ) -> Result<(), Error> {
        let (channel, count) = match self.channels.get_mut(topic) {
            Some(entry) => entry,
            None => {
                let (name, data) = M::schema();
                let schema_id = match self.schemas.get(name.as_ref()) {
                    Some(&id) => id,
                    None => {
                        let id = self.writer.add_schema(&name, "protobuf", &data)?;
                        self.schemas.insert(name.into_owned(), id);
                        id
                    }
                };
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
