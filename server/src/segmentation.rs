//! The segmentation model of the server: classifies a frame's points from its camera image.

use std::time::Duration;

use crate::Error;
use crate::pipeline::CameraImage;

/// Classes of every point of a frame, from the model, with the time of each step.
#[derive(Debug, Clone, PartialEq)]
pub struct Classified {
    pub classes: Vec<u8>,
    pub decode: Duration,
    pub segmentation: Duration,
    pub classification: Duration,
}

/// A loaded segmentation model with its ONNX Runtime sessions.
#[derive(Debug)]
pub struct Segmenter {
    name: String,
}

impl Segmenter {
    /// A short description for logs and `GetServiceInfo`.
    pub fn describe(&self) -> String {
        self.name.clone()
    }

    /// Segments `image` and gives each world point the class of the pixel it projects to.
    pub fn classify(&self, image: &CameraImage, world_points: &[[f32; 3]]) -> Result<Classified, Error> {
        let _ = (image, world_points);
        Err(Error::ModelUnavailable(format!("model {} cannot run in this build", self.name)))
    }
}
