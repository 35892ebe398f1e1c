//! Class masks (one `SemanticClass` id per pixel) and the IoU metrics used to judge them.

use image::GrayImage;

use crate::{NUM_CLASSES, PerceptionError};

/// A per-pixel class map: row-major, one byte per pixel, values are `SemanticClass` ids
/// (`0` = unknown … `14` = vegetation, as in `landing_geometry::SemanticClass`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ClassMask {
    width: u32,
    height: u32,
    data: Vec<u8>,
}

impl ClassMask {
    /// A mask from row-major class ids; `data.len()` must be `width * height` and every id below
    /// [`NUM_CLASSES`].
    pub fn new(width: u32, height: u32, data: Vec<u8>) -> Result<Self, PerceptionError> {
        if width == 0 || height == 0 {
            return Err(PerceptionError::invalid_input(
                "mask.size",
                format!("{width}x{height}"),
                "must not be empty",
            ));
        }
        let expected = width as usize * height as usize;
        if data.len() != expected {
            return Err(PerceptionError::invalid_input(
                "mask.data",
                format!("{} bytes", data.len()),
                format!("a {width}x{height} mask has {expected} pixels"),
            ));
        }
        if let Some(bad) = data.iter().find(|&&c| usize::from(c) >= NUM_CLASSES) {
            return Err(PerceptionError::invalid_input(
                "mask.data",
                format!("class id {bad}"),
                format!("class ids are below {NUM_CLASSES}"),
            ));
        }
        Ok(Self {
            width,
            height,
            data,
        })
    }

    /// A mask from an 8-bit label image (the simulator's label PNGs: value = class id).
    pub fn from_label_image(labels: &GrayImage) -> Result<Self, PerceptionError> {
        Self::new(labels.width(), labels.height(), labels.as_raw().clone())
    }

    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The class ids, row-major.
    pub fn as_slice(&self) -> &[u8] {
        &self.data
    }

    /// The class ids, row-major, by value.
    pub fn into_vec(self) -> Vec<u8> {
        self.data
    }

    /// The class at pixel `(x, y)`, or `None` outside the mask.
    pub fn get(&self, x: u32, y: u32) -> Option<u8> {
        (x < self.width && y < self.height)
            .then(|| self.data[y as usize * self.width as usize + x as usize])
    }

    /// The class seen at image pixel coordinates `(u, v)` of an image of `image_width ×
    /// image_height` pixels, the mask being stretched over the whole image. Pixel `(i, j)` covers
    /// `[i, i + 1) × [j, j + 1)`. Outside the image (or NaN) gives `0` (unknown).
    pub fn class_at_image_point(&self, u: f64, v: f64, image_width: u32, image_height: u32) -> u8 {
        if !(u >= 0.0 && v >= 0.0 && u < f64::from(image_width) && v < f64::from(image_height)) {
            return 0;
        }
        let x = (u * f64::from(self.width) / f64::from(image_width)) as u32;
        let y = (v * f64::from(self.height) / f64::from(image_height)) as u32;
        self.get(x.min(self.width - 1), y.min(self.height - 1))
            .unwrap_or(0)
    }

    /// Fuses masks of one image taken at several model input sizes, conservatively for landing:
    /// at the resolution of the first mask, a pixel keeps the first mask's class where no mask
    /// calls it an obstacle (`is_obstacle`), and takes the first obstacle class any mask gives it
    /// otherwise (each mask sampled at the pixel's centre, stretched over the same image). A
    /// small obstacle that one scale misses and another sees stays an obstacle. Put the finest
    /// mask first: coarser ones are sampled at its pixel centres, finer ones would be skipped
    /// over. `None` when `masks` is empty.
    pub fn fuse_keeping_obstacles(
        masks: &[ClassMask],
        is_obstacle: impl Fn(u8) -> bool,
    ) -> Option<ClassMask> {
        let (first, others) = masks.split_first()?;
        let (w, h) = (first.width, first.height);
        let mut data = first.data.clone();
        for other in others {
            // Column and row of `other` under each pixel centre of `first`.
            let column = |x: u32| {
                let c = (f64::from(x) + 0.5) * f64::from(other.width) / f64::from(w);
                (c as u32).min(other.width - 1) as usize
            };
            let columns: Vec<usize> = (0..w).map(column).collect();
            for y in 0..h {
                let oy = (((f64::from(y) + 0.5) * f64::from(other.height) / f64::from(h)) as u32)
                    .min(other.height - 1) as usize;
                let row = &other.data[oy * other.width as usize..][..other.width as usize];
                let out = &mut data[y as usize * w as usize..][..w as usize];
                for (pixel, &ox) in out.iter_mut().zip(&columns) {
                    let seen = row[ox];
                    if !is_obstacle(*pixel) && is_obstacle(seen) {
                        *pixel = seen;
                    }
                }
            }
        }
        Some(ClassMask {
            width: w,
            height: h,
            data,
        })
    }

    /// This mask resampled to `width × height` by nearest neighbour (pixel centres).
    pub fn resized_nearest(&self, width: u32, height: u32) -> Result<Self, PerceptionError> {
        if width == 0 || height == 0 {
            return Err(PerceptionError::invalid_input(
                "mask.size",
                format!("{width}x{height}"),
                "must not be empty",
            ));
        }
        let mut data = Vec::with_capacity(width as usize * height as usize);
        for y in 0..height {
            let sy = ((f64::from(y) + 0.5) * f64::from(self.height) / f64::from(height)) as u32;
            for x in 0..width {
                let sx = ((f64::from(x) + 0.5) * f64::from(self.width) / f64::from(width)) as u32;
                data.push(
                    self.data[sy.min(self.height - 1) as usize * self.width as usize
                        + sx.min(self.width - 1) as usize],
                );
            }
        }
        Ok(Self {
            width,
            height,
            data,
        })
    }
}

/// Per-class intersection-over-union of a predicted mask against ground truth.
#[derive(Debug, Clone, PartialEq)]
pub struct IouReport {
    /// `iou[c]` for class id `c`; `None` where the class is absent from both masks, and always for
    /// class 0 (unknown pixels of the truth are ignored, as in training).
    pub per_class: [Option<f64>; NUM_CLASSES],
    /// Mean over the classes with an IoU.
    pub mean: f64,
    /// Pixel accuracy over the pixels whose truth is not unknown.
    pub pixel_accuracy: f64,
    /// Number of truth pixels of each class.
    pub truth_pixels: [u64; NUM_CLASSES],
}

impl IouReport {
    /// Mean IoU over the classes with at least `min_pixels` truth pixels: on a handful of frames,
    /// a class with a few dozen pixels makes the plain mean mostly noise.
    pub fn mean_over_classes_with(&self, min_pixels: u64) -> Option<f64> {
        let vals: Vec<f64> = (1..NUM_CLASSES)
            .filter(|&c| self.truth_pixels[c] >= min_pixels)
            .filter_map(|c| self.per_class[c])
            .collect();
        (!vals.is_empty()).then(|| vals.iter().sum::<f64>() / vals.len() as f64)
    }
}

/// IoU of `predicted` against `truth` (same size). Pixels whose truth is `0` are ignored.
pub fn iou(predicted: &ClassMask, truth: &ClassMask) -> Result<IouReport, PerceptionError> {
    let mut confusion = Confusion::default();
    confusion.add(predicted, truth)?;
    Ok(confusion.report())
}

/// Accumulates a confusion matrix over many frames, for a dataset-level IoU.
#[derive(Debug, Clone)]
pub struct Confusion {
    /// `counts[truth][predicted]`.
    counts: [[u64; NUM_CLASSES]; NUM_CLASSES],
}

impl Default for Confusion {
    fn default() -> Self {
        Self {
            counts: [[0; NUM_CLASSES]; NUM_CLASSES],
        }
    }
}

impl Confusion {
    /// Adds one frame. The masks must have the same size.
    pub fn add(&mut self, predicted: &ClassMask, truth: &ClassMask) -> Result<(), PerceptionError> {
        if predicted.width != truth.width || predicted.height != truth.height {
            return Err(PerceptionError::invalid_input(
                "mask.size",
                format!("{}x{}", predicted.width, predicted.height),
                format!("must match the truth's {}x{}", truth.width, truth.height),
            ));
        }
        for (&p, &t) in predicted.data.iter().zip(&truth.data) {
            if t != 0 {
                self.counts[usize::from(t)][usize::from(p)] += 1;
            }
        }
        Ok(())
    }

    /// Per-class and mean IoU of everything added so far.
    pub fn report(&self) -> IouReport {
        let mut per_class = [None; NUM_CLASSES];
        let mut truth_pixels = [0u64; NUM_CLASSES];
        let mut correct = 0u64;
        let mut total = 0u64;
        for c in 1..NUM_CLASSES {
            let tp = self.counts[c][c];
            let truth_c: u64 = self.counts[c].iter().sum();
            let pred_c: u64 = (1..NUM_CLASSES).map(|t| self.counts[t][c]).sum();
            let union = truth_c + pred_c - tp;
            if union > 0 {
                per_class[c] = Some(tp as f64 / union as f64);
            }
            truth_pixels[c] = truth_c;
            correct += tp;
            total += truth_c;
        }
        let present: Vec<f64> = per_class.iter().flatten().copied().collect();
        let mean = if present.is_empty() {
            0.0
        } else {
            present.iter().sum::<f64>() / present.len() as f64
        };
        IouReport {
            per_class,
            mean,
            pixel_accuracy: if total == 0 {
                0.0
            } else {
                correct as f64 / total as f64
            },
            truth_pixels,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn new_checks_length_and_ids() {
        assert!(ClassMask::new(2, 2, vec![0; 3]).is_err());
        let err = ClassMask::new(1, 1, vec![15]).unwrap_err();
        assert!(err.to_string().contains("class id 15"), "{err}");
        assert!(ClassMask::new(0, 4, vec![]).is_err());
    }

    #[test]
    fn class_at_image_point_scales_the_mask() {
        // 2x1 mask over a 640x480 image: left half sky, right half rooftop.
        let m = ClassMask::new(2, 1, vec![1, 4]).unwrap();
        assert_eq!(m.class_at_image_point(10.0, 10.0, 640, 480), 1);
        assert_eq!(m.class_at_image_point(319.9, 479.9, 640, 480), 1);
        assert_eq!(m.class_at_image_point(320.0, 0.0, 640, 480), 4);
        assert_eq!(m.class_at_image_point(640.0, 0.0, 640, 480), 0);
        assert_eq!(m.class_at_image_point(-0.1, 0.0, 640, 480), 0);
        assert_eq!(m.class_at_image_point(f64::NAN, 0.0, 640, 480), 0);
    }

    #[test]
    fn iou_ignores_unknown_truth() {
        let truth = ClassMask::new(4, 1, vec![0, 4, 4, 1]).unwrap();
        let pred = ClassMask::new(4, 1, vec![3, 4, 1, 1]).unwrap();
        let r = iou(&pred, &truth).unwrap();
        assert_eq!(r.per_class[4], Some(0.5));
        assert_eq!(r.per_class[1], Some(0.5));
        assert_eq!(
            r.per_class[3], None,
            "a prediction on an unknown pixel is ignored"
        );
        assert!((r.mean - 0.5).abs() < 1e-12);
        assert!((r.pixel_accuracy - 2.0 / 3.0).abs() < 1e-12);
        assert_eq!(r.truth_pixels[4], 2);
        assert_eq!(r.mean_over_classes_with(2), Some(0.5));
        assert_eq!(r.mean_over_classes_with(3), None);
    }

    #[test]
    fn resize_nearest_keeps_blocks() {
        let m = ClassMask::new(2, 2, vec![1, 2, 3, 4]).unwrap();
        let big = m.resized_nearest(4, 4).unwrap();
        assert_eq!(big.get(1, 1), Some(1));
        assert_eq!(big.get(2, 1), Some(2));
        assert_eq!(big.get(3, 3), Some(4));
        assert_eq!(big.resized_nearest(2, 2).unwrap(), m);
    }

    #[test]
    fn fusion_keeps_every_obstacle_and_the_first_masks_resolution() {
        // 4×2 at full size: rooftop (4) with a vent (7) the coarse mask misses.
        let fine = ClassMask::new(4, 2, vec![4, 4, 7, 4, 4, 4, 4, 4]).unwrap();
        // 2×1 coarse: a tarp (13) on the left half, rooftop on the right.
        let coarse = ClassMask::new(2, 1, vec![13, 4]).unwrap();
        let obstacle = |c: u8| c != 0 && c != 4;
        let fused =
            ClassMask::fuse_keeping_obstacles(&[fine.clone(), coarse.clone()], obstacle).unwrap();
        assert_eq!((fused.width(), fused.height()), (4, 2));
        assert_eq!(fused.as_slice(), &[13, 13, 7, 4, 13, 13, 4, 4]);
        // At the coarse mask's resolution the fine one is sampled at pixel centres: (1, 0) sees
        // fine (3, 1), rooftop; the vent at fine (2, 0) falls between centres.
        let fused = ClassMask::fuse_keeping_obstacles(&[coarse.clone(), fine], obstacle).unwrap();
        assert_eq!(fused.as_slice(), &[13, 4]);
        // One mask: itself. None: nothing.
        assert_eq!(
            ClassMask::fuse_keeping_obstacles(std::slice::from_ref(&coarse), obstacle),
            Some(coarse)
        );
        assert_eq!(ClassMask::fuse_keeping_obstacles(&[], obstacle), None);
    }
}
