//! Robot logs with camera images (ROS 2 bags in MCAP, `vehicle-interfaces.md` 4.1) for Python:
//! the topics that `replay` and `localize` take ([`ros2_topics`]), a bag read whole with the
//! board on the host ([`read_bag`]) and the host's decode of one compressed image
//! ([`decode_image`]).
//!
//! [`read_bag`] reads the bag as the replay does: `vehicle_log::LogReader` with the named
//! topics, every image in log order into `host_board::HostBoard` with the rig's `[camera]`
//! size and `[board]` registers, the stereo frames it pairs and detects taken as they come
//! and the rest at the end. Its frames are those the replay's navigator is given (before the
//! replay orders them by time with the odometry), its image counts those of `SUMMARY.json`.
//! The odometry comes from the same reader, in log order. Nothing is estimated.
//!
//! A named topic the bag does not have is refused with the replay's error
//! (`replay::Error::MissingTopic`, the command line's message), a topic of another type with
//! the reader's; both, and a file that cannot be read or is not MCAP, raise
//! `stereonav.InputError` naming the file. An image that cannot be read is counted, never an
//! error.

use std::path::{Path, PathBuf};

use harris_core::Feature;
use host_board::{HostBoard, ImageCounts as HostCounts, StereoFeatures};
use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArrayMethods};
use pyo3::prelude::*;
use vehicle_log::{ImagePayload, LogReader, OdomSample, Record, Role, Ros2Topics};

use crate::calibration::file_error;
use crate::logs::LogDamage;
use crate::rig::PyRig;
use crate::stream::feature_array;
use crate::{FileError, input_error, pack_features};

/// The names of the three topics in the Python calls, in [`Role::index`] order.
const ARGUMENTS: [&str; 3] = ["left", "right", "odom"];

/// The topic given to the reader for a role that was not named: no ROS 2 bag has it (a ROS 2
/// topic name has no spaces), so that role reads nothing. (`vehicle_log::Ros2Topics` names
/// all three roles.)
const NOT_NAMED: [&str; 3] = [
    " (no left camera topic named)",
    " (no right camera topic named)",
    " (no odometry topic named)",
];

/// The ROS 2 topics of `replay` and `localize`: all three named, or none (the board's
/// stream). Errors: one or two named (the message names the missing ones), or an empty name.
pub(crate) fn ros2_topics(
    left: Option<String>,
    right: Option<String>,
    odom: Option<String>,
) -> Result<Option<Ros2Topics>, String> {
    let given = [left, right, odom];
    check_names(&given)?;
    match given {
        [Some(left), Some(right), Some(odom)] => Ok(Some(Ros2Topics { left, right, odom })),
        [None, None, None] => Ok(None),
        _ => {
            let missing: Vec<&str> = ARGUMENTS
                .iter()
                .zip(&given)
                .filter(|(_, t)| t.is_none())
                .map(|(name, _)| *name)
                .collect();
            let named: Vec<String> = ARGUMENTS
                .iter()
                .zip(&given)
                .filter_map(|(name, t)| t.as_ref().map(|t| format!("{name}={t:?}")))
                .collect();
            Err(format!(
                "a ROS 2 bag is read with all three topics named (left, right and odom) or \
                 none: {} missing (given {})",
                missing.join(" and "),
                named.join(", ")
            ))
        }
    }
}

/// Refuses an empty topic name.
fn check_names(given: &[Option<String>; 3]) -> Result<(), String> {
    match ARGUMENTS
        .iter()
        .zip(given)
        .find(|(_, t)| t.as_deref() == Some(""))
    {
        Some((name, _)) => Err(format!("{name} is an empty topic name")),
        None => Ok(()),
    }
}

/// What [`read_bag`] reads: the camera topics (with the board's registers) and the odometry
/// topic, each optional.
struct BagRequest {
    /// The topics given to the reader, [`NOT_NAMED`] for the roles not named.
    topics: Ros2Topics,
    /// Which roles were named, [`Role::index`] order.
    named: [bool; 3],
    /// The host board's registers, with the camera topics.
    regs: Option<harris_core::Registers>,
}

impl BagRequest {
    /// Errors: one camera topic without the other, cameras without a rig, nothing named, an
    /// empty name.
    fn new(
        left: Option<String>,
        right: Option<String>,
        odom: Option<String>,
        regs: Option<harris_core::Registers>,
    ) -> Result<Self, String> {
        let given = [left, right, odom];
        check_names(&given)?;
        let named = [given[0].is_some(), given[1].is_some(), given[2].is_some()];
        match named {
            [true, false, _] | [false, true, _] => {
                let (has, lacks) = if named[0] {
                    ("left", "right")
                } else {
                    ("right", "left")
                };
                return Err(format!(
                    "{has} is named without {lacks}: a bag's stereo frames need both camera \
                     topics"
                ));
            }
            [false, false, false] => {
                return Err(
                    "no topic named: name the camera topics (left and right), the odometry \
                     topic (odom), or all three"
                        .to_owned(),
                );
            }
            _ => {}
        }
        if named[0] && regs.is_none() {
            return Err(
                "reading a bag's camera images needs a rig (its [camera] size and [board] \
                 registers): give rig_path"
                    .to_owned(),
            );
        }
        let [left, right, odom] = given;
        let or_not =
            |t: Option<String>, role: Role| t.unwrap_or_else(|| NOT_NAMED[role.index()].to_owned());
        Ok(Self {
            topics: Ros2Topics {
                left: or_not(left, Role::Left),
                right: or_not(right, Role::Right),
                odom: or_not(odom, Role::Odom),
            },
            named,
            regs: if named[0] { regs } else { None },
        })
    }
}

/// The image counts of a bag (`host_board::ImageCounts`): what became of its camera images.
/// `SUMMARY.json`'s `counts` has them as `images_left`, `images_right`, `frames`,
/// `images_unpaired`, `images_wrong_size`, `images_unsupported`, `images_undecodable` and
/// `image_frames_dropped`.
#[pyclass(module = "stereonav._native", frozen, get_all, eq)]
#[derive(Clone, PartialEq, Eq)]
pub(crate) struct ImageCounts {
    /// Left images read.
    left: u64,
    /// Right images read.
    right: u64,
    /// Stereo frames detected (both images read).
    frames: u64,
    /// Images without a partner within a quarter of the frame interval.
    unpaired: u64,
    /// Images of another size than the rig's `[camera]`.
    wrong_size: u64,
    /// Images of an encoding or format that is not read.
    unsupported: u64,
    /// Images whose bytes or message do not decode.
    undecodable: u64,
    /// Frames lost because one of their images could not be read (counted above too).
    frames_dropped: u64,
    /// The first problem of each kind, one line each.
    problems: Vec<String>,
}

impl From<&HostCounts> for ImageCounts {
    fn from(c: &HostCounts) -> Self {
        Self {
            left: c.left,
            right: c.right,
            frames: c.frames,
            unpaired: c.unpaired,
            wrong_size: c.wrong_size,
            unsupported: c.unsupported,
            undecodable: c.undecodable,
            frames_dropped: c.frames_dropped,
            problems: c.first_problems.clone(),
        }
    }
}

#[pymethods]
impl ImageCounts {
    fn __repr__(&self) -> String {
        format!(
            "ImageCounts(left={}, right={}, frames={}, unpaired={}, wrong_size={}, \
             unsupported={}, undecodable={}, frames_dropped={})",
            self.left,
            self.right,
            self.frames,
            self.unpaired,
            self.wrong_size,
            self.unsupported,
            self.undecodable,
            self.frames_dropped
        )
    }
}

/// One stereo frame of a bag, detected on the host: what the board's packet would carry.
#[pyclass(module = "stereonav._native", frozen, get_all)]
pub(crate) struct BagFrame {
    /// The frame's time: the left image's stamp, us.
    t_us: u64,
    /// The left image's features, `(N,)` of `FEATURE_DTYPE`, in the board's order.
    left: Py<PyAny>,
    /// The right image's.
    right: Py<PyAny>,
    /// Either image had more than `MAX_FEATURES` features.
    overflow: bool,
}

#[pymethods]
impl BagFrame {
    fn __repr__(&self, py: Python<'_>) -> String {
        let len = |a: &Py<PyAny>| a.bind(py).len().unwrap_or_default();
        format!(
            "BagFrame(t_us={}, left=<{} features>, right=<{} features>, overflow={})",
            self.t_us,
            len(&self.left),
            len(&self.right),
            if self.overflow { "True" } else { "False" }
        )
    }
}

/// A ROS 2 bag read whole with the board on the host. Arrays are copied out on access.
#[pyclass(module = "stereonav._native", frozen)]
pub(crate) struct BagContents {
    frames: Vec<StereoFeatures>,
    images: Option<ImageCounts>,
    odometry: Vec<OdomSample>,
    /// `(role argument, topic, type)` of each named topic.
    topics: Vec<(&'static str, String, String)>,
    /// Messages read per named topic, [`Role::index`] order.
    messages: [u64; 3],
    warnings: Vec<String>,
    truncated: Option<String>,
    damage: vehicle_log::Damage,
}

/// The features of one side as a `(N,)` `FEATURE_DTYPE` array.
fn features(py: Python<'_>, f: &[Feature]) -> PyResult<Py<PyAny>> {
    feature_array(py, pack_features(f))
}

#[pymethods]
impl BagContents {
    /// The stereo frames in the order the host board pairs them (stamp order).
    #[getter]
    fn frames(&self, py: Python<'_>) -> PyResult<Vec<BagFrame>> {
        self.frames
            .iter()
            .map(|f| {
                Ok(BagFrame {
                    t_us: f.t_us,
                    left: features(py, &f.left)?,
                    right: features(py, &f.right)?,
                    overflow: f.overflow,
                })
            })
            .collect()
    }

    /// What became of the camera images; None when no camera topic was named.
    #[getter]
    fn images(&self) -> Option<ImageCounts> {
        self.images.clone()
    }

    /// The odometry in log order: `(t_us (S,), vx vy vtheta (S, 3))`.
    #[getter]
    fn odometry<'py>(
        &self,
        py: Python<'py>,
    ) -> (Bound<'py, PyArray1<u64>>, Bound<'py, PyArray2<f64>>) {
        let o = &self.odometry;
        let t: Vec<u64> = o.iter().map(|s| s.t_us).collect();
        let values = Array2::from_shape_fn((o.len(), 3), |(i, k)| {
            let s = &o[i];
            [s.vx, s.vy, s.vtheta][k]
        });
        (t.into_pyarray(py), values.into_pyarray(py))
    }

    /// `[(argument, topic, type), ...]` of each named topic (`type` as `pkg/Type`).
    #[getter]
    fn topics(&self) -> Vec<(&'static str, String, String)> {
        self.topics.clone()
    }

    /// Messages read on the named topics: `[left, right, odom]`.
    #[getter]
    fn messages(&self) -> [u64; 3] {
        self.messages
    }

    /// What looked wrong but did not stop the reading, one line each.
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.warnings.clone()
    }

    /// Why the bag ends early (cut short), or None.
    #[getter]
    fn truncated(&self) -> Option<&str> {
        self.truncated.as_deref()
    }

    /// What could not be read.
    #[getter]
    fn damage(&self) -> LogDamage {
        LogDamage(self.damage.clone())
    }
}

/// The stereo frames `host` has ready, onto `frames`.
fn drain(host: &mut HostBoard, frames: &mut Vec<StereoFeatures>) {
    while let Some(f) = host.pop() {
        frames.push(f);
    }
}

/// Reads the bag at `path` as [`BagRequest`] says (see the module docs).
fn read(path: &Path, request: BagRequest) -> Result<BagContents, FileError> {
    replay::check_topics(&request.topics)?;
    let mut reader = LogReader::open(path)?;
    reader.set_ros2_topics(request.topics.clone());
    let mut host = match request.regs {
        Some(regs) => Some(HostBoard::new(regs).map_err(|e| replay::Error::HostBoard {
            path: path.to_path_buf(),
            problem: e.to_string(),
        })?),
        None => None,
    };
    let mut frames = Vec::new();
    let mut odometry = Vec::new();
    for record in reader.by_ref() {
        match record? {
            Record::Image(image) => {
                if let Some(host) = &mut host {
                    host.push(image);
                    drain(host, &mut frames);
                }
            }
            Record::BadImage { side, problem, .. } => {
                if let Some(host) = &mut host {
                    host.push_undecodable(side, &problem);
                }
            }
            Record::Odom(sample) if request.named[Role::Odom.index()] => odometry.push(sample),
            _ => {}
        }
    }
    if let Some(host) = &mut host {
        host.end();
        drain(host, &mut frames);
    }
    let met = reader.ros2_met();
    let mut topics = Vec::new();
    for role in Role::ALL {
        if !request.named[role.index()] {
            continue;
        }
        let topic = request.topics.topic(role).to_owned();
        match met.iter().find(|(r, _)| *r == role) {
            Some((_, type_name)) => {
                topics.push((ARGUMENTS[role.index()], topic, type_name.clone()))
            }
            None => {
                return Err(Box::new(replay::Error::MissingTopic {
                    path: path.to_path_buf(),
                    option: role.option(),
                    topic,
                    topics: reader.bag_topics(),
                }));
            }
        }
    }
    let counts = reader.ros2_counts();
    Ok(BagContents {
        frames,
        images: host.as_ref().map(|h| ImageCounts::from(h.counts())),
        odometry,
        topics,
        messages: [0, 1, 2].map(|i| if request.named[i] { counts[i] } else { 0 }),
        warnings: reader.warnings().to_vec(),
        truncated: reader.truncated().map(str::to_owned),
        damage: reader.damage().clone(),
    })
}

/// Reads the ROS 2 bag (MCAP) at `log_path` whole with the board on the host, as the replay
/// reads it: the camera topics `left` and `right` (both or neither; with them, `rig` gives the
/// image size and the board's registers) paired and detected, the odometry topic `odom`
/// decoded. Raises `stereonav.InputError` for topics named badly, a named topic the bag does
/// not have or of another type, or a file that cannot be read. The GIL is released.
#[pyfunction]
#[pyo3(signature = (log_path, rig, left, right, odom))]
pub(crate) fn read_bag(
    py: Python<'_>,
    log_path: PathBuf,
    rig: Option<PyRef<'_, PyRig>>,
    left: Option<String>,
    right: Option<String>,
    odom: Option<String>,
) -> PyResult<BagContents> {
    let regs = rig.map(|r| r.rig.board_registers());
    let request = BagRequest::new(left, right, odom, regs).map_err(|e| input_error(py, e))?;
    py.detach(|| read(&log_path, request))
        .map_err(|e| file_error(py, &*e))
}

/// The gray pixels of one PNG or JPEG file's bytes as the host board decodes them
/// (`host_board::gray_pixels`: 8-bit gray as it is, RGB to gray with OpenCV's weights), at
/// the file's own size: a `(H, W)` `uint8` array. Raises `stereonav.InputError` for bytes
/// that are neither PNG nor JPEG, do not decode, or hold pixels the host does not read
/// (16-bit, alpha). The GIL is released.
#[pyfunction]
pub(crate) fn decode_image<'py>(
    py: Python<'py>,
    data: Vec<u8>,
) -> PyResult<Bound<'py, PyArray2<u8>>> {
    let payload = ImagePayload::Compressed {
        format: String::new(),
        data,
    };
    let decoded = py.detach(|| {
        let (width, height, _) = host_board::gray::describe(&payload)?;
        let pixels = host_board::gray_pixels(&payload, width, height)?;
        Ok::<_, host_board::ImageProblem>((width, height, pixels))
    });
    // The payload has no `format` field to name: leave its empty name out of the message.
    let (width, height, pixels) = decoded.map_err(|e| {
        let message = e.to_string().replace(" of format \"\"", "");
        input_error(py, format!("decode_image: {message}"))
    })?;
    PyArray1::from_vec(py, pixels).reshape([height as usize, width as usize])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(t: &str) -> Option<String> {
        Some(t.to_owned())
    }

    #[test]
    fn replay_topics_are_all_or_none_and_the_missing_are_named() {
        assert_eq!(ros2_topics(None, None, None), Ok(None));
        let all = ros2_topics(s("/l"), s("/r"), s("/o")).expect("all three");
        assert_eq!(
            all,
            Some(Ros2Topics {
                left: "/l".into(),
                right: "/r".into(),
                odom: "/o".into()
            })
        );
        let e = ros2_topics(s("/l"), None, None).expect_err("two missing");
        assert!(e.contains("right and odom missing"), "{e}");
        assert!(e.contains("left=\"/l\""), "{e}");
        let e = ros2_topics(None, s("/r"), s("/o")).expect_err("left missing");
        assert!(e.contains(": left missing"), "{e}");
        let e = ros2_topics(s("/l"), s(""), s("/o")).expect_err("empty");
        assert_eq!(e, "right is an empty topic name");
    }

    #[test]
    fn bag_requests_need_both_cameras_and_a_rig_for_them() {
        let regs = harris_core::Registers::default();
        let e = BagRequest::new(s("/l"), None, s("/o"), Some(regs)).err();
        assert!(e.is_some_and(|e| e.contains("left is named without right")));
        assert!(BagRequest::new(None, None, None, Some(regs)).is_err());
        let e = BagRequest::new(s("/l"), s("/r"), None, None).err();
        assert!(e.is_some_and(|e| e.contains("needs a rig")));
        let odom_only = BagRequest::new(None, None, s("/o"), None).expect("odometry only");
        assert_eq!(odom_only.named, [false, false, true]);
        assert_eq!(odom_only.topics.left, NOT_NAMED[0]);
        assert!(odom_only.regs.is_none());
        // The placeholders can be no ROS 2 topic and are no two alike.
        for (i, t) in NOT_NAMED.iter().enumerate() {
            assert!(t.contains(' '));
            assert_eq!(NOT_NAMED.iter().filter(|u| *u == t).count(), 1, "{i}");
        }
    }
}
