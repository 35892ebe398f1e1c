//! Image and class-image decoding: any bytes as a PNG or JPEG camera image and as a PNG class
//! image. Each gives pixels or an error, never a panic, and no more pixels than the side limit.
#![no_main]

use landing_perception::{ImageData, decode_class_mask, decode_image};

/// `landing_perception`'s limit on either side of a decoded image.
const MAX_IMAGE_SIDE: u32 = 8192;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    for format in ["png", "jpeg"] {
        let image = ImageData::compressed(format, data).expect("a known format");
        if let Ok(rgb) = decode_image(image) {
            assert!(rgb.width() <= MAX_IMAGE_SIDE && rgb.height() <= MAX_IMAGE_SIDE);
        }
    }
    if let Ok(mask) = decode_class_mask(ImageData::Png(data)) {
        assert!(mask.as_slice().iter().all(|&c| c <= 14));
    }
});
