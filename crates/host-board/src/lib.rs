//! The camera board on the host (vehicle-interfaces.md 4.1): for a robot that records its
//! cameras' images (a ROS 2 bag) instead of carrying the board, the host does what the board
//! would: each image to 8-bit gray ([`gray`]: `mono8`, `rgb8`, `bgr8`, PNG, JPEG), the left and
//! right images paired by stamp ([`pair`]), and the board's Harris arithmetic on each
//! (`harris-core`, row by row, with the rig's `[board]` registers and `[camera]` size), so that
//! what comes out ([`StereoFeatures`]) is what the board's stream would have carried, raw pixel
//! coordinates included: the lens tables of the rig map them as they map the board's.
//!
//! Nothing here fails on an image: one that cannot be read (another size, an encoding or
//! format the board's input cannot come from, bytes that do not decode) or that finds no
//! partner is counted in [`ImageCounts`], with the first reason of each kind kept for the
//! report, and the drive goes on.
#![forbid(unsafe_code)]
#![deny(missing_docs)]

pub mod gray;
pub mod pair;

use harris_core::{Feature, HarrisStream, Registers};
use serde::Serialize;
use vehicle_log::{CameraImage, Side};

pub use gray::ImageProblem;
pub use pair::{Paired, Pairer};

/// One stereo frame's features, as a board packet carries them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StereoFeatures {
    /// The frame's time: the left image's stamp, us.
    pub t_us: u64,
    /// The left image's features in the board's order.
    pub left: Vec<Feature>,
    /// The right image's.
    pub right: Vec<Feature>,
    /// Either image had more than `MAX_FEATURES` features (the board's overflow flag).
    pub overflow: bool,
    /// The right image's stamp, us.
    pub right_t_us: u64,
    /// The two images' log times, ns: where they are in the bag (`[left, right]`).
    pub log_time_ns: [u64; 2],
}

/// What became of a log's camera images.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct ImageCounts {
    /// Left images read.
    pub left: u64,
    /// Right images read.
    pub right: u64,
    /// Stereo frames detected (both images read).
    pub frames: u64,
    /// Images without a partner within a quarter of the frame interval (frames with one
    /// image).
    pub unpaired: u64,
    /// Images of another size than the rig's `[camera]`.
    pub wrong_size: u64,
    /// Images of an encoding or format that is not read (`mono8`, `rgb8`, `bgr8`, PNG, JPEG
    /// are).
    pub unsupported: u64,
    /// Images whose bytes or message do not decode.
    pub undecodable: u64,
    /// Frames lost because one of their images could not be read (counted above too).
    pub frames_dropped: u64,
    /// Pairings decided before they were certain, because the images held passed the
    /// pairer's limits ([`pair::MAX_HELD`], [`pair::MAX_HELD_BYTES`]: a bag far from stamp
    /// order).
    pub pairing_forced: u64,
    /// The first problem of each kind, one line each, for the report.
    #[serde(skip)]
    pub first_problems: Vec<String>,
}

impl ImageCounts {
    fn problem(&mut self, side: Side, t_us: Option<u64>, problem: &ImageProblem) {
        let (count, kind) = match problem {
            ImageProblem::WrongSize { .. } => (&mut self.wrong_size, "of the wrong size"),
            ImageProblem::Unsupported(_) => (&mut self.unsupported, "not readable"),
            ImageProblem::Undecodable(_) => (&mut self.undecodable, "undecodable"),
        };
        *count += 1;
        if *count == 1 {
            let at = t_us.map_or(String::new(), |t| format!(" at {t} us"));
            self.first_problems
                .push(format!("{} image{at} {kind}: {problem}", side_name(side)));
        }
    }

    /// Images that gave no features, for whatever reason.
    pub fn bad_images(&self) -> u64 {
        self.wrong_size + self.unsupported + self.undecodable
    }
}

fn side_name(side: Side) -> &'static str {
    match side {
        Side::Left => "left",
        Side::Right => "right",
    }
}

/// The detector, sized for the images (the board's width needs the smallest buffers).
enum Detector {
    Board(Box<HarrisStream<{ harris_core::BOARD_WIDTH }>>),
    Wide(Box<HarrisStream<{ harris_core::MAX_SIZE }>>),
}

/// The board on the host: images in, stereo features out (see the crate docs).
pub struct HostBoard {
    regs: Registers,
    detector: Detector,
    pairer: Pairer,
    counts: ImageCounts,
    /// A colour row's gray pixels.
    scratch: Vec<u8>,
}

impl std::fmt::Debug for HostBoard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HostBoard")
            .field("regs", &self.regs)
            .field("held", &self.pairer.held())
            .field("counts", &self.counts)
            .finish_non_exhaustive()
    }
}

impl HostBoard {
    /// The board with `regs` (the rig's `[camera]` size and `[board]` registers). Errors: a
    /// register outside board-icd.md's range.
    pub fn new(regs: Registers) -> Result<Self, harris_core::Error> {
        let detector = if regs.width <= harris_core::BOARD_WIDTH {
            Detector::Board(Box::new(HarrisStream::new(regs)?))
        } else {
            Detector::Wide(Box::new(HarrisStream::new(regs)?))
        };
        Ok(Self {
            regs,
            detector,
            pairer: Pairer::new(),
            counts: ImageCounts::default(),
            scratch: Vec::new(),
        })
    }

    /// The registers.
    pub fn registers(&self) -> Registers {
        self.regs
    }

    /// Takes an image of the log, in log order.
    pub fn push(&mut self, image: CameraImage) {
        match image.side {
            Side::Left => {
                self.counts.left += 1;
                self.pairer.push_left(image);
            }
            Side::Right => {
                self.counts.right += 1;
                self.pairer.push_right(image);
            }
        }
    }

    /// Counts an image whose message did not decode (it has no stamp to pair by).
    pub fn push_undecodable(&mut self, side: Side, problem: &str) {
        match side {
            Side::Left => self.counts.left += 1,
            Side::Right => self.counts.right += 1,
        }
        self.counts
            .problem(side, None, &ImageProblem::Undecodable(problem.to_owned()));
    }

    /// No more images.
    pub fn end(&mut self) {
        self.pairer.end();
    }

    /// The next stereo frame whose pairing is certain, detected; `None` when none is ready
    /// (push more, or end).
    pub fn pop(&mut self) -> Option<StereoFeatures> {
        loop {
            let paired = self.pairer.pop();
            self.counts.pairing_forced = self.pairer.forced();
            match paired? {
                Paired::Alone(_) => self.counts.unpaired += 1,
                Paired::Frame { left, right } => {
                    let l = self.detect(&left);
                    let r = self.detect(&right);
                    match (l, r) {
                        (Some((l, lo)), Some((r, ro))) => {
                            self.counts.frames += 1;
                            return Some(StereoFeatures {
                                t_us: left.t_us,
                                left: l,
                                right: r,
                                overflow: lo || ro,
                                right_t_us: right.t_us,
                                log_time_ns: [left.log_time_ns, right.log_time_ns],
                            });
                        }
                        _ => self.counts.frames_dropped += 1,
                    }
                }
            }
        }
    }

    /// What became of the images so far.
    pub fn counts(&self) -> &ImageCounts {
        &self.counts
    }

    /// The features of one image and the overflow flag, or `None` (counted) when it cannot
    /// be read.
    fn detect(&mut self, image: &CameraImage) -> Option<(Vec<Feature>, bool)> {
        match detect_image(&mut self.detector, &self.regs, image, &mut self.scratch) {
            Ok(found) => Some(found),
            Err(problem) => {
                self.counts.problem(image.side, Some(image.t_us), &problem);
                None
            }
        }
    }
}

/// The board's features of one image's payload, with `regs`. A standalone form of what
/// [`HostBoard`] does per image (benchmarks, tests, the Python module).
pub fn detect_payload(
    payload: &vehicle_log::ImagePayload,
    regs: &Registers,
) -> Result<(Vec<Feature>, bool), ImageProblem> {
    let mut board =
        HostBoard::new(*regs).map_err(|e| ImageProblem::Unsupported(format!("registers: {e}")))?;
    let image = CameraImage {
        side: Side::Left,
        t_us: 0,
        log_time_ns: 0,
        payload: payload.clone(),
    };
    detect_image(&mut board.detector, regs, &image, &mut board.scratch)
}

/// The gray pixels of one payload as the host board sees them (`width x height`, row-major).
pub fn gray_pixels(
    payload: &vehicle_log::ImagePayload,
    width: u32,
    height: u32,
) -> Result<Vec<u8>, ImageProblem> {
    let gray = gray::gray(payload, width, height)?;
    let mut pixels = Vec::with_capacity(width as usize * height as usize);
    let mut scratch = Vec::new();
    gray.for_each_row::<()>(width as usize, height as usize, &mut scratch, |row| {
        pixels.extend_from_slice(row);
        Ok(())
    })
    .ok();
    Ok(pixels)
}

fn detect_image(
    detector: &mut Detector,
    regs: &Registers,
    image: &CameraImage,
    scratch: &mut Vec<u8>,
) -> Result<(Vec<Feature>, bool), ImageProblem> {
    // Registers are checked by `HostBoard::new`, and sizes by `gray`: these fit in u32.
    let (w, h) = (
        u32::try_from(regs.width).unwrap_or(u32::MAX),
        u32::try_from(regs.height).unwrap_or(u32::MAX),
    );
    let gray = gray::gray(&image.payload, w, h)?;
    let detector_err = |e: harris_core::Error| ImageProblem::Undecodable(format!("detector: {e}"));
    let mut features = Vec::new();
    macro_rules! run {
        ($stream:expr) => {{
            let stream = $stream;
            stream.reset();
            gray.for_each_row(regs.width, regs.height, scratch, |row| {
                features.extend_from_slice(stream.push_row(row)?);
                Ok(())
            })
            .map_err(detector_err)?;
            stream.finish().map_err(detector_err)?.overflow
        }};
    }
    let overflow = match detector {
        Detector::Board(s) => run!(s.as_mut()),
        Detector::Wide(s) => run!(s.as_mut()),
    };
    Ok((features, overflow))
}
