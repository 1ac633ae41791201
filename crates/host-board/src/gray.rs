//! A camera image's pixels to the 8-bit gray rows the board's detector takes
//! (vehicle-interfaces.md 4.1): `mono8` as it is, `rgb8` and `bgr8` to gray, PNG and JPEG
//! decoded by the `image` crate; anything else refused by its name, never guessed.

use std::io::Cursor;

use image::{DynamicImage, ImageFormat, ImageReader, Limits};
use vehicle_log::ImagePayload;
use zune_core::bytestream::ZCursor;
use zune_core::colorspace::ColorSpace;
use zune_core::options::DecoderOptions;

/// Why an image gives no features.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ImageProblem {
    /// A pixel encoding or file format the board's 8-bit gray input cannot come from.
    #[error("{0}")]
    Unsupported(String),
    /// Not the `[camera]` table's size.
    #[error("{width}x{height} pixels, not the rig's {expected_width}x{expected_height}")]
    WrongSize {
        /// The image's columns.
        width: u32,
        /// The image's rows.
        height: u32,
        /// The rig's columns.
        expected_width: u32,
        /// The rig's rows.
        expected_height: u32,
    },
    /// The bytes do not hold the image they say (a damaged JPEG, rows missing, a message that
    /// does not decode).
    #[error("{0}")]
    Undecodable(String),
}

/// OpenCV's `cvtColor(..., COLOR_RGB2GRAY)` for 8 bits, `(4899 R + 9617 G + 1868 B + 2^13) >>
/// 14` (0.299, 0.587, 0.114 in 14-bit fixed point), so that a colour image gives the gray
/// image the OpenCV tools a user compares with give.
pub fn gray_of_rgb(r: u8, g: u8, b: u8) -> u8 {
    let y = (4899 * u32::from(r) + 9617 * u32::from(g) + 1868 * u32::from(b) + (1 << 13)) >> 14;
    // At most (16384 * 255 + 8192) >> 14 = 255.
    u8::try_from(y).unwrap_or(u8::MAX)
}

/// Rows of an 8-bit gray image, as the detector takes them.
pub(crate) enum Gray<'a> {
    /// `mono8` rows inside a message, `step` bytes apart.
    Mono { data: &'a [u8], step: usize },
    /// `rgb8` (`bgr` false) or `bgr8` rows, converted one at a time.
    Colour {
        data: &'a [u8],
        step: usize,
        bgr: bool,
    },
    /// A decoded file, rows `width` apart.
    Decoded(Vec<u8>),
}

impl Gray<'_> {
    /// Calls `row` with each of the `height` rows of `width` gray pixels, in order; stops at
    /// the first error.
    pub(crate) fn for_each_row<E>(
        &self,
        width: usize,
        height: usize,
        scratch: &mut Vec<u8>,
        mut row: impl FnMut(&[u8]) -> Result<(), E>,
    ) -> Result<(), E> {
        for y in 0..height {
            match self {
                Gray::Mono { data, step } => row(&data[y * step..y * step + width])?,
                Gray::Colour { data, step, bgr } => {
                    scratch.clear();
                    let px = &data[y * step..y * step + 3 * width];
                    scratch.extend(px.chunks_exact(3).map(|c| {
                        if *bgr {
                            gray_of_rgb(c[2], c[1], c[0])
                        } else {
                            gray_of_rgb(c[0], c[1], c[2])
                        }
                    }));
                    row(scratch)?;
                }
                Gray::Decoded(pixels) => row(&pixels[y * width..(y + 1) * width])?,
            }
        }
        Ok(())
    }
}

/// An image's size and what it is (`mono8`, ..., `PNG`, `JPEG`) from its message or its
/// file's header, without decoding the pixels.
pub fn describe(payload: &ImagePayload) -> Result<(u32, u32, String), ImageProblem> {
    match payload {
        ImagePayload::Raw {
            width,
            height,
            encoding,
            ..
        } => Ok((*width, *height, encoding.clone())),
        ImagePayload::Compressed { format, data } => {
            let (fmt, kind) = match image::guess_format(data) {
                Ok(ImageFormat::Png) => (ImageFormat::Png, "PNG"),
                Ok(ImageFormat::Jpeg) => (ImageFormat::Jpeg, "JPEG"),
                Ok(other) => {
                    return Err(ImageProblem::Unsupported(format!(
                        "compressed image of format {format:?} holds {other:?}"
                    )));
                }
                Err(_) => {
                    return Err(ImageProblem::Undecodable(format!(
                        "compressed image of format {format:?}: neither PNG nor JPEG"
                    )));
                }
            };
            let (w, h) = if fmt == ImageFormat::Jpeg {
                jpeg_decoder(data).1?
            } else {
                ImageReader::with_format(Cursor::new(data), fmt)
                    .into_dimensions()
                    .map_err(|e| ImageProblem::Undecodable(format!("{kind}: {e}")))?
            };
            Ok((w, h, kind.to_owned()))
        }
    }
}

/// zune-jpeg's decoder of a payload's bytes.
type JpegDecoder<'a> = zune_jpeg::JpegDecoder<ZCursor<&'a [u8]>>;

/// A strict JPEG decoder of `data` to 8-bit gray (the Y channel of a colour JPEG), its
/// headers read: the decoder and the image's size.
fn jpeg_decoder(data: &[u8]) -> (JpegDecoder<'_>, Result<(u32, u32), ImageProblem>) {
    let options = DecoderOptions::default()
        .set_strict_mode(true)
        .jpeg_set_out_colorspace(ColorSpace::Luma)
        .set_max_width(usize::from(u16::MAX))
        .set_max_height(usize::from(u16::MAX));
    let mut decoder = zune_jpeg::JpegDecoder::new_with_options(ZCursor::new(data), options);
    let dims = decoder
        .decode_headers()
        .map_err(|e| ImageProblem::Undecodable(format!("JPEG: {e}")))
        .and_then(|()| {
            decoder
                .info()
                .map(|i| (u32::from(i.width), u32::from(i.height)))
                .ok_or_else(|| ImageProblem::Undecodable("JPEG: no frame header".to_owned()))
        });
    (decoder, dims)
}

/// The gray rows of `payload`, which must be `width x height` pixels.
pub(crate) fn gray(
    payload: &ImagePayload,
    width: u32,
    height: u32,
) -> Result<Gray<'_>, ImageProblem> {
    let size_check = |w: u32, h: u32| {
        if (w, h) == (width, height) {
            Ok(())
        } else {
            Err(ImageProblem::WrongSize {
                width: w,
                height: h,
                expected_width: width,
                expected_height: height,
            })
        }
    };
    match payload {
        ImagePayload::Raw {
            width: w,
            height: h,
            encoding,
            step,
            data,
        } => {
            let channels = match encoding.as_str() {
                "mono8" => 1,
                "rgb8" | "bgr8" => 3,
                other => {
                    return Err(ImageProblem::Unsupported(format!(
                        "encoding {other:?} (mono8, rgb8 and bgr8 are read)"
                    )));
                }
            };
            size_check(*w, *h)?;
            let step = *step as usize;
            let row_bytes = channels * *w as usize;
            let need = step.saturating_mul(h.saturating_sub(1) as usize) + row_bytes;
            if step < row_bytes || data.len() < need {
                return Err(ImageProblem::Undecodable(format!(
                    "{encoding} image of {w}x{h} with step {step} needs {need} bytes, the \
                     message holds {}",
                    data.len()
                )));
            }
            Ok(if channels == 1 {
                Gray::Mono { data, step }
            } else {
                Gray::Colour {
                    data,
                    step,
                    bgr: encoding == "bgr8",
                }
            })
        }
        ImagePayload::Compressed { format, data } => {
            let found = image::guess_format(data).ok();
            let kind = match found {
                Some(ImageFormat::Png) => "PNG",
                Some(ImageFormat::Jpeg) => "JPEG",
                Some(other) => {
                    return Err(ImageProblem::Unsupported(format!(
                        "compressed image of format {format:?} holds {other:?} (PNG and JPEG are \
                         read)"
                    )));
                }
                None => {
                    return Err(ImageProblem::Undecodable(format!(
                        "compressed image of format {format:?}: its {} bytes are neither PNG \
                         nor JPEG",
                        data.len()
                    )));
                }
            };
            let fmt = found.unwrap_or(ImageFormat::Png);
            if fmt == ImageFormat::Jpeg {
                // The size is checked against the rig's before any pixel is decoded.
                let (mut decoder, dims) = jpeg_decoder(data);
                let (w, h) = dims?;
                size_check(w, h)?;
                let pixels = decoder
                    .decode()
                    .map_err(|e| ImageProblem::Undecodable(format!("JPEG: {e}")))?;
                if pixels.len() != width as usize * height as usize {
                    return Err(ImageProblem::Undecodable(format!(
                        "JPEG: {} gray pixels decoded for {width}x{height}",
                        pixels.len()
                    )));
                }
                return Ok(Gray::Decoded(pixels));
            }
            let undecodable =
                |e: image::ImageError| ImageProblem::Undecodable(format!("{kind}: {e}"));
            let (w, h) = ImageReader::with_format(Cursor::new(data), fmt)
                .into_dimensions()
                .map_err(undecodable)?;
            size_check(w, h)?;
            let mut reader = ImageReader::with_format(Cursor::new(data), fmt);
            let mut limits = Limits::default();
            limits.max_image_width = Some(width);
            limits.max_image_height = Some(height);
            reader.limits(limits);
            let decoded = reader.decode().map_err(undecodable)?;
            let pixels = match decoded {
                DynamicImage::ImageLuma8(g) => g.into_raw(),
                DynamicImage::ImageRgb8(rgb) => rgb
                    .pixels()
                    .map(|p| gray_of_rgb(p.0[0], p.0[1], p.0[2]))
                    .collect(),
                other => {
                    return Err(ImageProblem::Unsupported(format!(
                        "{kind} of {:?} pixels (8-bit gray or RGB are read)",
                        other.color()
                    )));
                }
            };
            Ok(Gray::Decoded(pixels))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rgb_weights_are_opencvs() {
        assert_eq!(gray_of_rgb(255, 255, 255), 255);
        assert_eq!(gray_of_rgb(0, 0, 0), 0);
        // cv2.cvtColor(np.array([[[255, 0, 0]]], np.uint8), cv2.COLOR_RGB2GRAY) == 76
        assert_eq!(gray_of_rgb(255, 0, 0), 76);
        assert_eq!(gray_of_rgb(0, 255, 0), 150);
        assert_eq!(gray_of_rgb(0, 0, 255), 29);
    }

    fn synthetic(width: u32, height: u32) -> Vec<u8> {
        (0..height)
            .flat_map(|y| {
                (0..width).map(move |x| {
                    let d = (f64::from(x) - 40.0).hypot(f64::from(y) - 30.0);
                    u8::try_from((250.0 * (-d * d / 50.0).exp()) as u32 + 20).unwrap_or(255)
                })
            })
            .collect()
    }

    fn jpeg(pixels: &[u8], width: u32, height: u32, colour: image::ExtendedColorType) -> Vec<u8> {
        use image::ImageEncoder;
        let mut out = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 95)
            .write_image(pixels, width, height, colour)
            .unwrap();
        out
    }

    fn decode(data: Vec<u8>, width: u32, height: u32) -> Result<Vec<u8>, ImageProblem> {
        let payload = ImagePayload::Compressed {
            format: "jpeg".to_owned(),
            data,
        };
        match gray(&payload, width, height)? {
            Gray::Decoded(p) => Ok(p),
            _ => unreachable!("a JPEG decodes"),
        }
    }

    #[test]
    fn jpeg_cut_short_is_undecodable() {
        let (w, h) = (96, 64);
        let px = synthetic(w, h);
        let data = jpeg(&px, w, h, image::ExtendedColorType::L8);
        let full = decode(data.clone(), w, h).unwrap();
        let worst = full
            .iter()
            .zip(&px)
            .map(|(a, b)| a.abs_diff(*b))
            .max()
            .unwrap();
        assert!(worst <= 8, "quality 95 JPEG off by {worst}");
        for cut in [data.len() / 2, data.len() - 3] {
            let e = decode(data[..cut].to_vec(), w, h).unwrap_err();
            assert!(
                matches!(e, ImageProblem::Undecodable(_)),
                "cut at {cut}: {e:?}"
            );
        }
        let e = decode(data, w + 1, h).unwrap_err();
        assert!(
            matches!(e, ImageProblem::WrongSize { width: 96, .. }),
            "{e:?}"
        );
    }

    #[test]
    fn colour_jpeg_gives_its_luma() {
        let (w, h) = (96, 64);
        let px = synthetic(w, h);
        let rgb: Vec<u8> = px.iter().flat_map(|&g| [g, g, g]).collect();
        let data = jpeg(&rgb, w, h, image::ExtendedColorType::Rgb8);
        let luma = decode(data, w, h).unwrap();
        let worst = luma
            .iter()
            .zip(&px)
            .map(|(a, b)| a.abs_diff(*b))
            .max()
            .unwrap();
        assert!(worst <= 8, "luma off by {worst}");
    }
}
