//! Image decoding (PNG, JPEG, raw RGB8) and the model's preprocessing (resize and normalise).

use std::io::Cursor;

use image::{ImageFormat, ImageReader, Limits, RgbImage, imageops::FilterType};

use crate::PerceptionError;

/// The largest width or height accepted, in pixels; bigger images are refused before decoding.
pub const MAX_IMAGE_SIDE: u32 = 8192;

/// Per-channel mean of the RGB values in [0, 1] that the model was trained with (ImageNet's).
pub const NORMALIZE_MEAN: [f32; 3] = [0.485, 0.456, 0.406];
/// Per-channel standard deviation that the model was trained with (ImageNet's).
pub const NORMALIZE_STD: [f32; 3] = [0.229, 0.224, 0.225];

/// An image as it arrives in a frame: encoded bytes, or raw packed RGB8 rows.
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
        ImageData::Png(bytes) => decode_encoded(bytes, ImageFormat::Png, "png"),
        ImageData::Jpeg(bytes) => decode_encoded(bytes, ImageFormat::Jpeg, "jpeg"),
        ImageData::Rgb8 {
            width,
            height,
            step,
            data,
        } => decode_raw(width, height, step, data),
    }
}

fn decode_encoded(
    bytes: &[u8],
    format: ImageFormat,
    name: &str,
) -> Result<RgbImage, PerceptionError> {
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
    let image = reader.decode().map_err(|e| PerceptionError::Decode {
        format: name.to_owned(),
        message: e.to_string(),
    })?;
    Ok(image.into_rgb8())
}

fn decode_raw(
    width: u32,
    height: u32,
    step: u32,
    data: &[u8],
) -> Result<RgbImage, PerceptionError> {
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
    let row = width as usize * 3;
    let step = step as usize;
    if step < row {
        return Err(PerceptionError::invalid_input(
            "raw.step",
            step,
            format!("must be at least width * 3 = {row}"),
        ));
    }
    let needed = step * (height as usize - 1) + row;
    if data.len() < needed {
        return Err(PerceptionError::invalid_input(
            "raw.data",
            format!("{} bytes", data.len()),
            format!("{width}x{height} rgb8 with step {step} needs at least {needed} bytes"),
        ));
    }
    let mut pixels = Vec::with_capacity(row * height as usize);
    for r in 0..height as usize {
        pixels.extend_from_slice(&data[r * step..r * step + row]);
    }
    RgbImage::from_raw(width, height, pixels).ok_or_else(|| {
        PerceptionError::invalid_input("raw.data", width, "buffer does not match the size")
    })
}

/// Resizes (bilinear) to `width × height` and normalises with [`NORMALIZE_MEAN`] and
/// [`NORMALIZE_STD`], giving the model's input as planar NCHW float32 (`3 * height * width` values).
pub fn preprocess(image: &RgbImage, width: u32, height: u32) -> Vec<f32> {
    let resized;
    let source = if image.width() == width && image.height() == height {
        image
    } else {
        resized = image::imageops::resize(image, width, height, FilterType::Triangle);
        &resized
    };
    let plane = width as usize * height as usize;
    let mut out = vec![0.0f32; 3 * plane];
    let scale: [f32; 3] = std::array::from_fn(|c| 1.0 / (255.0 * NORMALIZE_STD[c]));
    let offset: [f32; 3] = std::array::from_fn(|c| NORMALIZE_MEAN[c] / NORMALIZE_STD[c]);
    for (i, px) in source.as_raw().chunks_exact(3).enumerate() {
        for c in 0..3 {
            out[c * plane + i] = f32::from(px[c]) * scale[c] - offset[c];
        }
    }
    out
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
