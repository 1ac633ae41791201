//! Whole-image convenience calls (feature `alloc`), built on the row-streaming detector.

use alloc::{boxed::Box, vec, vec::Vec};

use crate::{Error, Feature, HarrisStream, MAX_SIZE, Registers};

/// Runs `$body` with `$stream` bound to a boxed detector whose line buffers fit `$width`:
/// the board's 752 pixels, or the next of a few larger capacities up to the ICD's 4095, so
/// that a small image does not pay for zeroing buffers sized for the largest one.
macro_rules! with_stream {
    ($regs:expr, |$stream:ident| $body:expr) => {{
        let regs: Registers = $regs;
        if regs.width <= crate::BOARD_WIDTH {
            let mut $stream = Box::new(HarrisStream::<{ crate::BOARD_WIDTH }>::new(regs)?);
            $body
        } else if regs.width <= 1536 {
            let mut $stream = Box::new(HarrisStream::<1536>::new(regs)?);
            $body
        } else {
            let mut $stream = Box::new(HarrisStream::<MAX_SIZE>::new(regs)?);
            $body
        }
    }};
}

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
    with_stream!(*regs, |stream| {
        let mut features = Vec::new();
        for row in image.chunks_exact(regs.width) {
            features.extend_from_slice(stream.push_row(row)?);
        }
        let summary = stream.finish()?;
        Ok(Detection {
            features,
            overflow: summary.overflow,
        })
    })
}

/// The response map `r(x, y)` of a row-major 8-bit image (ICD step 3), row-major, with zeros
/// outside `3 <= x <= W - 4`, `3 <= y <= H - 4` where the board computes no response.
/// `regs.threshold` and `regs.max_features` do not matter here.
pub fn response_map(image: &[u8], regs: &Registers) -> Result<Vec<i32>, Error> {
    check_image(image, regs)?;
    // No pixel is a candidate above i32::MAX, so the detector never stops early on overflow.
    let regs = Registers {
        threshold: i32::MAX,
        ..*regs
    };
    with_stream!(regs, |stream| {
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
    })
}
