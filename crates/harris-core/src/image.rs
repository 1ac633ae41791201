//! Whole-image convenience calls (feature `alloc`), built on the row-streaming detector.

use alloc::{boxed::Box, vec, vec::Vec};

use crate::{Error, Feature, HarrisStream, MAX_SIZE, Registers};

/// Line-buffer capacity of the whole-image calls: every width the ICD allows.
const WHOLE_IMAGE_CAPACITY: usize = MAX_SIZE;

/// The features of one image, as the board would send them.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Detection {
    /// At most `MAX_FEATURES` features in raster order.
    pub features: Vec<Feature>,
    /// More than `MAX_FEATURES` features were found (the camera's overflow flag).
    pub overflow: bool,
}

fn check_image(image: &[u8], regs: &Registers) -> Result<(), Error> {
    regs.validate()?;
    let expected = regs.width * regs.height;
    if image.len() != expected {
        return Err(Error::ImageSize {
            width: regs.width,
            height: regs.height,
            expected,
            actual: image.len(),
        });
    }
    Ok(())
}

/// Detects the features of a row-major 8-bit image of `regs.width x regs.height` pixels,
/// exactly as the board does (ICD section 2).
pub fn detect(image: &[u8], regs: &Registers) -> Result<Detection, Error> {
    check_image(image, regs)?;
    let mut stream = Box::new(HarrisStream::<WHOLE_IMAGE_CAPACITY>::new(*regs)?);
    let mut features = Vec::new();
    for row in image.chunks_exact(regs.width) {
        features.extend_from_slice(stream.push_row(row)?);
    }
    let summary = stream.finish()?;
    Ok(Detection { features, overflow: summary.overflow })
}

/// The response map `r(x, y)` of a row-major 8-bit image (ICD step 3), row-major, with zeros
/// outside `3 <= x <= W - 4`, `3 <= y <= H - 4` where the board computes no response.
/// `regs.threshold` and `regs.max_features` do not matter here.
pub fn response_map(image: &[u8], regs: &Registers) -> Result<Vec<i32>, Error> {
    check_image(image, regs)?;
    // No pixel is a candidate above i32::MAX, so the detector never stops early on overflow.
    let regs = Registers { threshold: i32::MAX, ..*regs };
    let mut stream = Box::new(HarrisStream::<WHOLE_IMAGE_CAPACITY>::new(regs)?);
    stream.compute_every_response();
    let mut map = vec![0; image.len()];
    for row in image.chunks_exact(regs.width) {
        stream.push_row(row)?;
        if let Some((y, r)) = stream.last_response_row() {
            let start = y * regs.width;
            if let Some(out) = map.get_mut(start..start + regs.width) {
                out.copy_from_slice(r);
            }
        }
    }
    stream.finish()?;
    Ok(map)
}
