//! Image decoding (PNG, JPEG, raw RGB8; class images from 8-bit grayscale PNG or raw mono8) and
//! the model's preprocessing (resize and normalise).

use std::io::Cursor;

use image::{ColorType, DynamicImage, ImageFormat, ImageReader, Limits, RgbImage};

use crate::{ClassMask, NUM_CLASSES, PerceptionError};

/// The largest width or height accepted, in pixels; bigger images are refused before decoding.
pub const MAX_IMAGE_SIDE: u32 = 8192;

/// Per-channel mean of the RGB values in [0, 1] that the model was trained with (ImageNet's).
pub const NORMALIZE_MEAN: [f32; 3] = [0.485, 0.456, 0.406];
/// Per-channel standard deviation that the model was trained with (ImageNet's).
pub const NORMALIZE_STD: [f32; 3] = [0.229, 0.224, 0.225];

/// An image as it arrives in a frame: encoded bytes, or raw packed rows.
#[derive(Debug, Clone, Copy)]
pub enum ImageData<'a> {
    /// A PNG file's bytes (any colour type; converted to RGB8).
    Png(&'a [u8]),
    /// A JPEG file's bytes.
    Jpeg(&'a [u8]),
    /// Raw RGB8 pixels, `height` rows of `step` bytes, each row starting with `width * 3` pixel bytes.
    Rgb8 {
        /// Pixels per row.
        width: u32,
        /// Rows.
        height: u32,
        /// Bytes per row, at least `width * 3`.
        step: u32,
        /// At least `step * (height - 1) + width * 3` bytes.
        data: &'a [u8],
    },
    /// Raw 8-bit single-channel pixels (a class image), `height` rows of `step` bytes.
    Mono8 {
        /// Pixels per row.
        width: u32,
        /// Rows.
        height: u32,
        /// Bytes per row, at least `width`.
        step: u32,
        /// At least `step * (height - 1) + width` bytes.
        data: &'a [u8],
    },
}

impl<'a> ImageData<'a> {
    /// An encoded image with its format named as in `CompressedImage.format`: `png`, `jpeg` or `jpg`
    /// (case-insensitive).
    pub fn compressed(format: &str, data: &'a [u8]) -> Result<Self, PerceptionError> {
        match format.to_ascii_lowercase().as_str() {
            "png" => Ok(Self::Png(data)),
            "jpeg" | "jpg" => Ok(Self::Jpeg(data)),
            _ => Err(PerceptionError::invalid_input(
                "compressed.format",
                format!("{format:?}"),
                "expected \"png\" or \"jpeg\"",
            )),
        }
    }
}

/// Decodes an image into packed RGB8.
///
/// Errors name the format and say what is wrong; images wider or taller than [`MAX_IMAGE_SIDE`]
/// are refused.
pub fn decode_image(data: ImageData<'_>) -> Result<RgbImage, PerceptionError> {
    match data {
        ImageData::Png(bytes) => Ok(decode_encoded(bytes, ImageFormat::Png, "png")?.into_rgb8()),
        ImageData::Jpeg(bytes) => Ok(decode_encoded(bytes, ImageFormat::Jpeg, "jpeg")?.into_rgb8()),
        ImageData::Rgb8 {
            width,
            height,
            step,
            data,
        } => {
            let pixels = packed_rows(width, height, step, 3, data, "rgb8")?;
            RgbImage::from_raw(width, height, pixels).ok_or_else(|| {
                PerceptionError::invalid_input("raw.data", width, "buffer does not match the size")
            })
        }
        ImageData::Mono8 { .. } => Err(PerceptionError::invalid_input(
            "raw.encoding",
            "\"mono8\"",
            "the model needs colour: \"rgb8\", PNG or JPEG",
        )),
    }
}

/// Decodes a class image (pixel value = `SemanticClass` id) into a [`ClassMask`]: an 8-bit
/// grayscale PNG or raw mono8 rows. JPEG (lossy, it would change the ids), colour images and ids
/// of no class are refused, naming the field.
pub fn decode_class_mask(data: ImageData<'_>) -> Result<ClassMask, PerceptionError> {
    let (width, height, pixels, field) = match data {
        ImageData::Png(bytes) => {
            let image = decode_encoded(bytes, ImageFormat::Png, "png")?;
            if image.color() != ColorType::L8 {
                return Err(PerceptionError::invalid_input(
                    "compressed.data",
                    format!("a {:?} PNG", image.color()),
                    "a class image is 8-bit grayscale (L8), one class id per pixel",
                ));
            }
            let gray = image.into_luma8();
            (
                gray.width(),
                gray.height(),
                gray.into_raw(),
                "compressed.data",
            )
        }
        ImageData::Jpeg(_) => {
            return Err(PerceptionError::invalid_input(
                "compressed.format",
                "\"jpeg\"",
                "a class image must be lossless: PNG or raw mono8",
            ));
        }
        ImageData::Rgb8 { .. } => {
            return Err(PerceptionError::invalid_input(
                "raw.encoding",
                "\"rgb8\"",
                "a class image is \"mono8\", one class id per pixel",
            ));
        }
        ImageData::Mono8 {
            width,
            height,
            step,
            data,
        } => (
            width,
            height,
            packed_rows(width, height, step, 1, data, "mono8")?,
            "raw.data",
        ),
    };
    if let Some(i) = pixels.iter().position(|&c| usize::from(c) >= NUM_CLASSES) {
        let w = width as usize;
        return Err(PerceptionError::invalid_input(
            field,
            format!("{} at pixel ({}, {})", pixels[i], i % w, i / w),
            format!("class ids are below {NUM_CLASSES}"),
        ));
    }
    ClassMask::new(width, height, pixels)
}

fn decode_encoded(
    bytes: &[u8],
    format: ImageFormat,
    name: &str,
) -> Result<DynamicImage, PerceptionError> {
    if bytes.is_empty() {
        return Err(PerceptionError::Decode {
            format: name.to_owned(),
            message: "no bytes".to_owned(),
        });
    }
    let mut reader = ImageReader::with_format(Cursor::new(bytes), format);
    let mut limits = Limits::default();
    limits.max_image_width = Some(MAX_IMAGE_SIDE);
    limits.max_image_height = Some(MAX_IMAGE_SIDE);
    reader.limits(limits);
    reader.decode().map_err(|e| PerceptionError::Decode {
        format: name.to_owned(),
        message: e.to_string(),
    })
}

/// Checks a raw image's layout and packs its rows (`channels` bytes per pixel), dropping any
/// padding.
fn packed_rows(
    width: u32,
    height: u32,
    step: u32,
    channels: usize,
    data: &[u8],
    encoding: &str,
) -> Result<Vec<u8>, PerceptionError> {
    if width == 0 || width > MAX_IMAGE_SIDE {
        return Err(PerceptionError::invalid_input(
            "raw.width",
            width,
            format!("must be in 1..={MAX_IMAGE_SIDE}"),
        ));
    }
    if height == 0 || height > MAX_IMAGE_SIDE {
        return Err(PerceptionError::invalid_input(
            "raw.height",
            height,
            format!("must be in 1..={MAX_IMAGE_SIDE}"),
        ));
    }
    let row = width as usize * channels;
    let step = step as usize;
    if step < row {
        return Err(PerceptionError::invalid_input(
            "raw.step",
            step,
            format!("must be at least width * {channels} = {row}"),
        ));
    }
    let needed = step * (height as usize - 1) + row;
    if data.len() < needed {
        return Err(PerceptionError::invalid_input(
            "raw.data",
            format!("{} bytes", data.len()),
            format!("{width}x{height} {encoding} with step {step} needs at least {needed} bytes"),
        ));
    }
    let mut pixels = Vec::with_capacity(row * height as usize);
    for r in 0..height as usize {
        pixels.extend_from_slice(&data[r * step..r * step + row]);
    }
    Ok(pixels)
}

/// Resizes (bilinear) to `width × height` and normalises with [`NORMALIZE_MEAN`] and
/// [`NORMALIZE_STD`], giving the model's input as planar NCHW float32 (`3 * height * width` values).
///
/// The resampling is `image::imageops::resize` with `FilterType::Triangle` to the bit (the same
/// taps and weights, the same float operations in the same order, rounded to 8 bits as it
/// rounds), done row by row on flat buffers and written straight into the planes: the generic
/// version, pixel by pixel and column by column, took about a quarter of a frame's time outside
/// the model (BENCHMARKS.md, "One input size in streams; faster preprocessing").
pub fn preprocess(image: &RgbImage, width: u32, height: u32) -> Vec<f32> {
    let plane = width as usize * height as usize;
    let mut out = vec![0.0f32; 3 * plane];
    let scale: [f32; 3] = std::array::from_fn(|c| 1.0 / (255.0 * NORMALIZE_STD[c]));
    let offset: [f32; 3] = std::array::from_fn(|c| NORMALIZE_MEAN[c] / NORMALIZE_STD[c]);
    let mut put = |i: usize, rgb: [u8; 3]| {
        for c in 0..3 {
            out[c * plane + i] = f32::from(rgb[c]) * scale[c] - offset[c];
        }
    };
    if image.dimensions() == (width, height) {
        for (i, px) in image.as_raw().chunks_exact(3).enumerate() {
            put(i, [px[0], px[1], px[2]]);
        }
        return out;
    }
    let (source_width, source_height) = image.dimensions();
    let stride = 3 * source_width as usize;
    // Columns first: `height` rows at the source's width, unrounded.
    let mut rows = vec![0.0f32; height as usize * stride];
    for (row, (first, weights)) in rows
        .chunks_exact_mut(stride)
        .zip(triangle_taps(source_height, height))
    {
        for (k, &w) in weights.iter().enumerate() {
            let source = &image.as_raw()[(first + k) * stride..][..stride];
            for (acc, &v) in row.iter_mut().zip(source) {
                *acc += f32::from(v) * w;
            }
        }
    }
    let columns = triangle_taps(source_width, width);
    for (y, row) in rows.chunks_exact(stride).enumerate() {
        for (x, (first, weights)) in columns.iter().enumerate() {
            let mut rgb = [0.0f32; 3];
            for (k, &w) in weights.iter().enumerate() {
                let px = &row[3 * (first + k)..][..3];
                for c in 0..3 {
                    rgb[c] += px[c] * w;
                }
            }
            put(y * width as usize + x, rgb.map(round_to_u8));
        }
    }
    out
}

/// For each of `to` output samples along an axis of `from` input samples: the first input
/// sample it reads and the normalised weights of it and those after it. A triangle kernel,
/// stretched over the scale when shrinking, exactly as `image`'s `FilterType::Triangle`
/// computes them.
fn triangle_taps(from: u32, to: u32) -> Vec<(usize, Vec<f32>)> {
    let ratio = from as f32 / to as f32;
    let stretch = ratio.max(1.0);
    (0..to)
        .map(|o| {
            let centre = (o as f32 + 0.5) * ratio;
            let first = ((centre - stretch).floor() as i64).clamp(0, i64::from(from) - 1);
            let end = ((centre + stretch).ceil() as i64).clamp(first + 1, i64::from(from));
            let centre = centre - 0.5;
            let mut weights: Vec<f32> = (first..end)
                .map(|i| (1.0 - ((i as f32 - centre) / stretch).abs()).max(0.0))
                .collect();
            let sum = weights.iter().fold(0.0, |s, w| s + w);
            for w in &mut weights {
                *w /= sum;
            }
            (first as usize, weights)
        })
        .collect()
}

/// A resampled value as an 8-bit channel: clamped to 0..=255 and rounded half away from zero,
/// as `f32::round` does, without its library call (the fraction of a non-negative float below
/// 2^24 is exact).
fn round_to_u8(v: f32) -> u8 {
    let v = v.clamp(0.0, 255.0);
    let whole = v as u8;
    whole + u8::from(v - f32::from(whole) >= 0.5)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn raw_rgb8_with_padding_drops_the_padding() {
        // 2x2 image, rows padded to 8 bytes.
        let data = [1, 2, 3, 4, 5, 6, 99, 99, 7, 8, 9, 10, 11, 12];
        let img = decode_image(ImageData::Rgb8 {
            width: 2,
            height: 2,
            step: 8,
            data: &data,
        })
        .unwrap();
        assert_eq!(img.as_raw(), &[1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12]);
    }

    #[test]
    fn raw_rgb8_too_short_names_the_field() {
        let err = decode_image(ImageData::Rgb8 {
            width: 4,
            height: 4,
            step: 12,
            data: &[0; 40],
        })
        .unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains("raw.data") && msg.contains("48"), "{msg}");
    }

    #[test]
    fn raw_rgb8_short_step_is_refused() {
        let err = decode_image(ImageData::Rgb8 {
            width: 4,
            height: 1,
            step: 11,
            data: &[0; 12],
        })
        .unwrap_err();
        assert!(err.to_string().contains("raw.step"), "{err}");
    }

    #[test]
    fn png_roundtrip_and_garbage() {
        let img = RgbImage::from_fn(5, 3, |x, y| image::Rgb([x as u8 * 10, y as u8 * 20, 7]));
        let mut png = Vec::new();
        img.write_to(&mut Cursor::new(&mut png), ImageFormat::Png)
            .unwrap();
        let back = decode_image(ImageData::compressed("PNG", &png).unwrap()).unwrap();
        assert_eq!(back, img);
        let err = decode_image(ImageData::Jpeg(&png)).unwrap_err();
        assert!(err.to_string().contains("jpeg"), "{err}");
        assert!(ImageData::compressed("bmp", &png).is_err());
    }

    #[test]
    fn class_images_decode_from_gray_png_and_padded_mono8() {
        let labels = image::GrayImage::from_fn(3, 2, |x, y| image::Luma([(x + 3 * y) as u8 + 1]));
        let mut png = Vec::new();
        labels
            .write_to(&mut Cursor::new(&mut png), ImageFormat::Png)
            .unwrap();
        let mask = decode_class_mask(ImageData::Png(&png)).unwrap();
        assert_eq!((mask.width(), mask.height()), (3, 2));
        assert_eq!(mask.as_slice(), &[1, 2, 3, 4, 5, 6]);
        let raw = decode_class_mask(ImageData::Mono8 {
            width: 3,
            height: 2,
            step: 4,
            data: &[1, 2, 3, 99, 4, 5, 6],
        })
        .unwrap();
        assert_eq!(raw, mask);
    }

    #[test]
    fn bad_class_images_name_the_field() {
        let msg = |e: PerceptionError| e.to_string();
        // An id of no class, with where it is.
        let e = decode_class_mask(ImageData::Mono8 {
            width: 2,
            height: 1,
            step: 2,
            data: &[4, 200],
        })
        .unwrap_err();
        let e = msg(e);
        assert!(
            e.contains("raw.data") && e.contains("200 at pixel (1, 0)"),
            "{e}"
        );
        // A colour PNG.
        let rgb = RgbImage::from_pixel(2, 2, image::Rgb([4, 4, 4]));
        let mut png = Vec::new();
        rgb.write_to(&mut Cursor::new(&mut png), ImageFormat::Png)
            .unwrap();
        let e = msg(decode_class_mask(ImageData::Png(&png)).unwrap_err());
        assert!(e.contains("compressed.data") && e.contains("Rgb8"), "{e}");
        let e = msg(decode_class_mask(ImageData::Jpeg(&png)).unwrap_err());
        assert!(
            e.contains("compressed.format") && e.contains("lossless"),
            "{e}"
        );
        let e = msg(decode_class_mask(ImageData::Mono8 {
            width: 4,
            height: 2,
            step: 3,
            data: &[0; 8],
        })
        .unwrap_err());
        assert!(e.contains("raw.step"), "{e}");
        // And a class image is no camera image.
        let e = msg(decode_image(ImageData::Mono8 {
            width: 1,
            height: 1,
            step: 1,
            data: &[4],
        })
        .unwrap_err());
        assert!(e.contains("raw.encoding"), "{e}");
    }

    #[test]
    fn preprocess_resizes_exactly_as_image_does() {
        use rand::{Rng, SeedableRng, rngs::SmallRng};
        // Noise over gradients: every rounding case of the resampler shows up.
        let mut rng = SmallRng::seed_from_u64(7);
        for (from, to) in [
            ((320, 240), (256, 192)),
            ((640, 480), (256, 192)),
            ((320, 240), (160, 120)),
            ((7, 5), (3, 2)),
            ((5, 3), (11, 7)),
            ((320, 240), (320, 120)),
            ((1, 1), (4, 3)),
            ((33, 1), (5, 1)),
        ] {
            let image = RgbImage::from_fn(from.0, from.1, |x, y| {
                let n: u8 = rng.random();
                image::Rgb([(x * 7 + y) as u8 ^ n, n, (y * 3) as u8 / 2 + n / 2])
            });
            // At its own size `preprocess` only normalises: the reference is image's resize.
            let resized =
                image::imageops::resize(&image, to.0, to.1, image::imageops::FilterType::Triangle);
            assert_eq!(
                preprocess(&image, to.0, to.1),
                preprocess(&resized, to.0, to.1),
                "{from:?} -> {to:?}"
            );
        }
    }

    #[test]
    fn rounding_to_u8_matches_f32_round() {
        for v in [
            0.0f32, 0.49999997, 0.5, 1.5, 2.5, 254.49998, 254.5, 255.0, 300.0, -3.0,
        ] {
            let expected = v.clamp(0.0, 255.0).round() as u8;
            assert_eq!(round_to_u8(v), expected, "{v}");
        }
        for i in 0..=255 * 64 {
            let v = i as f32 / 64.0;
            assert_eq!(round_to_u8(v), v.round() as u8, "{v}");
        }
    }

    #[test]
    fn preprocess_normalises_per_channel_planes() {
        let img = RgbImage::from_pixel(4, 2, image::Rgb([255, 0, 128]));
        let t = preprocess(&img, 4, 2);
        assert_eq!(t.len(), 3 * 8);
        let expect_r = (1.0 - NORMALIZE_MEAN[0]) / NORMALIZE_STD[0];
        let expect_g = (0.0 - NORMALIZE_MEAN[1]) / NORMALIZE_STD[1];
        assert!((t[0] - expect_r).abs() < 1e-5);
        assert!((t[8] - expect_g).abs() < 1e-5);
        // Resizing a constant image keeps it constant.
        let t2 = preprocess(&img, 2, 1);
        assert!((t2[0] - expect_r).abs() < 1e-5);
    }
}
