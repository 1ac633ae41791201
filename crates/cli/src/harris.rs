//! `stereonav harris IMAGE [--threshold T] [--max-features N]`.

use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use harris_core::{DEFAULT_MAX_FEATURES, DEFAULT_THRESHOLD, Registers, detect};
use image::{DynamicImage, ImageReader};

/// Arguments of `stereonav harris`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    /// An 8-bit grayscale image, PGM or PNG. Colour or 16-bit images are refused: the board's
    /// sensors are 8-bit monochrome, and a silent conversion would hide a wrong input.
    image: PathBuf,
    /// The `THRESHOLD` register: a pixel is a candidate when its response r > T.
    #[arg(long, default_value_t = DEFAULT_THRESHOLD, allow_negative_numbers = true)]
    threshold: i32,
    /// The `MAX_FEATURES` register (1..=1023): features kept per image.
    #[arg(long, default_value_t = DEFAULT_MAX_FEATURES)]
    max_features: usize,
}

/// Reads an 8-bit grayscale image as `(width, height, row-major pixels)`.
pub(crate) fn read_gray8(path: &Path) -> Result<(usize, usize, Vec<u8>)> {
    let reader = ImageReader::open(path)
        .with_context(|| format!("cannot open image {}", path.display()))?
        .with_guessed_format()
        .with_context(|| format!("cannot read image {}", path.display()))?;
    let image = reader
        .decode()
        .with_context(|| format!("{} is not a readable PGM or PNG image", path.display()))?;
    let DynamicImage::ImageLuma8(gray) = image else {
        bail!(
            "{} is {:?}, expected 8-bit grayscale (convert it first, e.g. to an 8-bit PGM)",
            path.display(),
            image.color()
        );
    };
    let (width, height) = (gray.width() as usize, gray.height() as usize);
    Ok((width, height, gray.into_raw()))
}

pub(crate) fn run(args: &Args) -> Result<()> {
    let (width, height, pixels) = read_gray8(&args.image)?;
    let regs = Registers {
        width,
        height,
        threshold: args.threshold,
        max_features: args.max_features,
    };
    let detection = detect(&pixels, &regs).with_context(|| args.image.display().to_string())?;
    let mut out = BufWriter::new(io::stdout().lock());
    writeln!(out, "x_q4,y_q4,r")?;
    for f in &detection.features {
        writeln!(out, "{},{},{}", f.x_q4, f.y_q4, f.r)?;
    }
    out.flush()?;
    Ok(())
}
