//! `stereonav rig import` end to end (vehicle-interfaces.md section 5): a Kalibr, an OpenCV
//! and a ROS calibration of EuRoC's cameras written as rig files that load, with OpenCV's
//! numbers; and one-line errors for every kind of bad input. The comparison with OpenCV
//! itself, over the whole image, is crates/py/tests/test_rig_import.py.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure is the test failing

use crate::common;

use std::path::PathBuf;

use common::{assert_one_line_error, s, stereonav};
use rig_model::Rig;
use rig_model::lens::LensModel;

fn scratch(name: &str) -> PathBuf {
    common::scratch("rig-import-cli", name)
}

/// `cv2.stereoRectify(..., flags=CALIB_ZERO_DISPARITY, alpha=0)` of EuRoC V1_01 (OpenCV
/// 5.0.0): `f`, `cx`, `cy` of `P1` and `-P2[0,3] / P2[0,0]`.
const OPENCV_EUROC: [f64; 4] = [
    436.244295647102,
    364.44123458862305,
    256.95167541503906,
    0.1100778421917611,
];

/// EuRoC V1_01's two cameras as Kalibr's camchain.yaml (`T_cn_cnm1 = inverse(T_BS_cam1)
/// T_BS_cam0` of their sensor.yaml).
const CAMCHAIN: &str = "\
cam0:
  cam_overlaps: [1]
  camera_model: pinhole
  distortion_coeffs: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]
  distortion_model: radtan
  intrinsics: [458.654, 457.296, 367.215, 248.375]
  resolution: [752, 480]
  rostopic: /cam0/image_raw
cam1:
  T_cn_cnm1:
  - [0.9999972564778812, 0.0023120671924238864, 0.0003760081024155938, -0.11007380812718678]
  - [-0.0023171357232812354, 0.9998980485066438, 0.014089835846648196, 0.00039912154701414806]
  - [-0.0003433931205241621, -0.01409066845271459, 0.9999006626377283, -0.0008537025033580449]
  - [0.0, 0.0, 0.0, 1.0]
  cam_overlaps: [0]
  camera_model: pinhole
  distortion_coeffs: [-0.28368365, 0.07451284, -0.00010473, -3.5559070e-05]
  distortion_model: radtan
  intrinsics: [457.587, 456.134, 379.999, 255.238]
  resolution: [752, 480]
  rostopic: /cam1/image_raw
";

/// The same calibration as OpenCV 4's `cv2.FileStorage` writes it (`%YAML:1.0`).
const OPENCV: &str = "%YAML:1.0
---
K1: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 458.654, 0., 367.21499999999997, 0., 457.29599999999999,
       248.375, 0., 0., 1. ]
D1: !!opencv-matrix
   rows: 1
   cols: 5
   dt: d
   data: [ -0.28340810999999999, 0.073959070000000002,
       0.00019358999999999999, 1.7618711400000001e-05, 0. ]
K2: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 457.58699999999999, 0., 379.99900000000002, 0.,
       456.13400000000001, 255.238, 0., 0., 1. ]
D2: !!opencv-matrix
   rows: 1
   cols: 5
   dt: d
   data: [ -0.28368365000000001, 0.074512839999999997, -0.00010473,
       -3.5559070000000001e-05, 0. ]
R: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 0.99999725647788118, 0.0023120671924238864,
       0.0003760081024155938, -0.0023171357232812354,
       0.99989804850664377, 0.014089835846648196, -0.0003433931205241621,
       -0.01409066845271459, 0.99990066263772825 ]
T: !!opencv-matrix
   rows: 3
   cols: 1
   dt: d
   data: [ -0.11007380812718678, 0.00039912154701414806,
       -0.00085370250335804494 ]
width: 752
height: 480
";

/// A ROS camera_info file; `{P}` is the projection matrix's data.
fn camera_info(k: &str, d: &str, r: &str, p: &str) -> String {
    format!(
        "image_width: 752\nimage_height: 480\ncamera_name: cam\ncamera_matrix:\n  rows: 3\n  \
         cols: 3\n  data: [{k}]\ndistortion_model: plumb_bob\ndistortion_coefficients:\n  \
         rows: 1\n  cols: 5\n  data: [{d}]\nrectification_matrix:\n  rows: 3\n  cols: 3\n  \
         data: [{r}]\nprojection_matrix:\n  rows: 3\n  cols: 4\n  data: [{p}]\n"
    )
}

const ROS_LEFT_K: &str = "458.654, 0.0, 367.215, 0.0, 457.296, 248.375, 0.0, 0.0, 1.0";
const ROS_LEFT_D: &str = "-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05, 0.0";
const ROS_LEFT_R: &str = "0.9999663475300326, -0.0014227391387192799, 0.008079580483489718, \
    0.001365741834640079, 0.9999741760894847, 0.007055629199258192, -0.00808941015693637, \
    -0.007044357138835821, 0.9999424675829172";
const ROS_LEFT_P: &str = "436.244295647102, 0.0, 364.44123458862305, 0.0, 0.0, \
    436.244295647102, 256.95167541503906, 0.0, 0.0, 0.0, 1.0, 0.0";
const ROS_RIGHT_K: &str = "457.587, 0.0, 379.999, 0.0, 456.134, 255.238, 0.0, 0.0, 1.0";
const ROS_RIGHT_D: &str = "-0.28368365, 0.07451284, -0.00010473, -3.5559070e-05, 0.0";
const ROS_RIGHT_R: &str = "0.9999633526194371, -0.0036258118715556003, 0.007755443660230329, \
    0.0036803985472554446, 0.9999684752771629, -0.007035845251224842, -0.007729688520780125, \
    0.007064130529506773, 0.9999451734846435";
const ROS_RIGHT_P: &str = "436.244295647102, 0.0, 364.44123458862305, -48.020830733297664, \
    0.0, 436.244295647102, 256.95167541503906, 0.0, 0.0, 0.0, 1.0, 0.0";

fn write(name: &str, text: &str) -> PathBuf {
    let path = scratch(name);
    std::fs::write(&path, text).unwrap();
    path
}

/// Imports and loads the rig; stdout names the file written and nothing goes to stderr.
fn import(args: &[&str], out_name: &str) -> Rig {
    let out = scratch(out_name);
    let mut all = vec!["rig", "import"];
    all.extend_from_slice(args);
    all.extend_from_slice(&["--out", s(&out)]);
    let done = stereonav(&all);
    assert!(
        done.status.success(),
        "{}",
        String::from_utf8_lossy(&done.stderr)
    );
    assert!(
        done.stderr.is_empty(),
        "{}",
        String::from_utf8_lossy(&done.stderr)
    );
    assert!(String::from_utf8_lossy(&done.stdout).contains(s(&out)));
    Rig::load(&out).unwrap()
}

fn assert_opencv_euroc(rig: &Rig, tolerance_px: f64) {
    let [f, cx, cy, baseline] = OPENCV_EUROC;
    let c = &rig.nominal;
    assert!((c.f - f).abs() < tolerance_px, "f {} vs {f}", c.f);
    assert!((c.cx - cx).abs() < tolerance_px, "cx {} vs {cx}", c.cx);
    assert!((c.cy - cy).abs() < tolerance_px, "cy {} vs {cy}", c.cy);
    assert!(
        (c.baseline - baseline).abs() < 1e-9,
        "baseline {}",
        c.baseline
    );
    assert_eq!((rig.width, rig.height), (752, 480));
    let lens = rig.lens.expect("[lens] tables");
    assert_eq!(lens.left.fx, 458.654);
    assert_eq!(lens.right.cy, 255.238);
    assert!(matches!(
        lens.right.model,
        LensModel::PlumbBob { k1, k3, .. } if k1 == -0.283_683_65 && k3 == 0.0
    ));
    // The defaults a calibration does not give.
    assert_eq!(rig.nominal.mount.z, 1.0);
    assert_eq!(rig.estimate, vec![rig_model::Param::Baseline]);
    assert_eq!(rig.noise.pixel, 0.3);
}

#[test]
fn kalibr_camchain_gives_opencvs_rectification() {
    let rig = import(
        &["--kalibr", s(&write("camchain.yaml", CAMCHAIN))],
        "kalibr.toml",
    );
    assert_opencv_euroc(&rig, 1e-4);
    let text = std::fs::read_to_string(scratch("kalibr.toml")).unwrap();
    assert!(text.contains("fill them in"), "{text}");
}

#[test]
fn opencv_filestorage_gives_opencvs_rectification() {
    let rig = import(
        &["--opencv", s(&write("stereo.yml", OPENCV))],
        "opencv.toml",
    );
    assert_opencv_euroc(&rig, 1e-4);
}

#[test]
fn ros_camera_info_is_taken_as_given() {
    let left = write(
        "left.yaml",
        &camera_info(ROS_LEFT_K, ROS_LEFT_D, ROS_LEFT_R, ROS_LEFT_P),
    );
    let right = write(
        "right.yaml",
        &camera_info(ROS_RIGHT_K, ROS_RIGHT_D, ROS_RIGHT_R, ROS_RIGHT_P),
    );
    let rig = import(&["--ros", s(&left), s(&right)], "ros.toml");
    assert_opencv_euroc(&rig, 0.0 + f64::EPSILON * 1e3);
    let lens = rig.lens.unwrap();
    assert_eq!(lens.left.rectification[(0, 2)], 0.008079580483489718);
}

/// Runs an import that must fail with one line on stderr containing `needle`.
fn refused(args: &[&str], needle: &str) {
    let out = scratch("refused.toml");
    let _ = std::fs::remove_file(&out);
    let mut all = vec!["rig", "import"];
    all.extend_from_slice(args);
    all.extend_from_slice(&["--out", s(&out)]);
    assert_one_line_error(&stereonav(&all), needle);
    assert!(!out.exists(), "nothing written on failure");
}

fn kalibr_refused(name: &str, camchain: &str, needle: &str) {
    refused(&["--kalibr", s(&write(name, camchain))], needle);
}

fn opencv_refused(name: &str, stereo: &str, needle: &str) {
    refused(&["--opencv", s(&write(name, stereo))], needle);
}

#[test]
fn unreadable_or_non_yaml_files_are_named() {
    refused(
        &["--kalibr", "/no/such/camchain.yaml"],
        "cannot read /no/such/camchain.yaml",
    );
    kalibr_refused("bad.yaml", "cam0: [1, 2\n", "bad.yaml: not a YAML file");
    let binary = scratch("binary.yaml");
    std::fs::write(&binary, [0xff_u8, 0xfe, 0x00, 0x12]).unwrap();
    refused(&["--kalibr", s(&binary)], "cannot read");
    kalibr_refused("list.yaml", "- 1\n- 2\n", "expected a YAML mapping");
    kalibr_refused("empty.yaml", "", "empty YAML file");
}

#[test]
fn one_camera_only_is_refused() {
    let cam0_only = CAMCHAIN.split("cam1:").next().unwrap();
    kalibr_refused("cam0.yaml", cam0_only, "one camera only (no cam1)");
    let left = write(
        "left1.yaml",
        &camera_info(ROS_LEFT_K, ROS_LEFT_D, ROS_LEFT_R, ROS_LEFT_P),
    );
    // clap's own message: two values for --ros.
    assert_one_line_error(
        &stereonav(&[
            "rig",
            "import",
            "--ros",
            s(&left),
            "--out",
            s(&scratch("x.toml")),
        ]),
        "2 values required",
    );
    assert_one_line_error(
        &stereonav(&["rig", "import", "--out", s(&scratch("x.toml"))]),
        "--kalibr",
    );
}

#[test]
fn unknown_models_are_refused() {
    kalibr_refused(
        "omni.yaml",
        &CAMCHAIN.replacen("camera_model: pinhole", "camera_model: omni", 1),
        "cam0.camera_model: unknown camera model \"omni\" (known: pinhole)",
    );
    kalibr_refused(
        "fov.yaml",
        &CAMCHAIN.replace("distortion_model: radtan", "distortion_model: fov"),
        "unknown distortion model \"fov\" (known: radtan, equidistant)",
    );
    kalibr_refused(
        "mixed.yaml",
        &CAMCHAIN.replacen(
            "distortion_model: radtan",
            "distortion_model: equidistant",
            1,
        ),
        "the left lens is equidistant and the right one plumb_bob",
    );
    let left = write(
        "rational.yaml",
        &camera_info(ROS_LEFT_K, ROS_LEFT_D, ROS_LEFT_R, ROS_LEFT_P)
            .replace("plumb_bob", "rational_polynomial"),
    );
    let right = write(
        "right2.yaml",
        &camera_info(ROS_RIGHT_K, ROS_RIGHT_D, ROS_RIGHT_R, ROS_RIGHT_P),
    );
    refused(
        &["--ros", s(&left), s(&right)],
        "distortion_model: unknown distortion model \"rational_polynomial\" (known: plumb_bob, equidistant)",
    );
    opencv_refused(
        "model.yml",
        &format!("{OPENCV}model: kannala\n"),
        "model: unknown model \"kannala\"",
    );
}

#[test]
fn missing_and_mistyped_keys_are_named() {
    kalibr_refused(
        "nointr.yaml",
        &CAMCHAIN.replacen(
            "  intrinsics: [458.654, 457.296, 367.215, 248.375]\n",
            "",
            1,
        ),
        "cam0.intrinsics: missing key",
    );
    kalibr_refused(
        "strintr.yaml",
        &CAMCHAIN.replacen("[458.654, 457.296, 367.215, 248.375]", "fast", 1),
        "cam0.intrinsics: expected a list, found string \"fast\"",
    );
    kalibr_refused(
        "notnum.yaml",
        &CAMCHAIN.replacen("458.654", "abc", 1),
        "cam0.intrinsics[0]: expected a number, found string \"abc\"",
    );
    kalibr_refused(
        "three.yaml",
        &CAMCHAIN.replacen(
            "[458.654, 457.296, 367.215, 248.375]",
            "[458.654, 457.296, 367.215]",
            1,
        ),
        "cam0.intrinsics: 3 numbers; expected 4 (fu fv pu pv)",
    );
    kalibr_refused(
        "not.yaml",
        &CAMCHAIN.replacen("T_cn_cnm1", "T_cam_imu", 1),
        "cam1.T_cn_cnm1: missing key",
    );
    kalibr_refused(
        "size.yaml",
        &CAMCHAIN.replacen("[752, 480]", "[640, 480]", 1),
        "cam0's resolution 640 x 480 differs from cam1's 752 x 480",
    );
    opencv_refused(
        "nowidth.yml",
        &OPENCV.replace("width: 752\n", ""),
        "width: missing key",
    );
    opencv_refused(
        "fwidth.yml",
        &OPENCV.replace("width: 752", "width: 752.5"),
        "width: expected an integer, found number 752.5",
    );
}

#[test]
fn wrong_matrix_sizes_are_named() {
    kalibr_refused(
        "t3.yaml",
        &CAMCHAIN.replace("  - [0.0, 0.0, 0.0, 1.0]\n", ""),
        "cam1.T_cn_cnm1: 3 rows; expected a 4 x 4 matrix",
    );
    kalibr_refused(
        "lastrow.yaml",
        &CAMCHAIN.replace("[0.0, 0.0, 0.0, 1.0]", "[0.0, 0.0, 0.5, 1.0]"),
        "last row [0, 0, 0.5, 1]",
    );
    opencv_refused(
        "k2x2.yml",
        &OPENCV.replacen("   rows: 3\n   cols: 3", "   rows: 2\n   cols: 2", 1),
        "K1: 2 x 2 matrix with 9 numbers of data",
    );
    opencv_refused(
        "r3x1.yml",
        &OPENCV.replace(
            "R: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 0.99999725647788118, 0.0023120671924238864,\n       0.0003760081024155938, -0.0023171357232812354,\n       0.99989804850664377, 0.014089835846648196, -0.0003433931205241621,\n       -0.01409066845271459, 0.99990066263772825 ]",
            "R: !!opencv-matrix\n   rows: 3\n   cols: 1\n   dt: d\n   data: [ 0.01, 0.02, 0.03 ]",
        ),
        "R: a 3 x 1 matrix; expected 3 x 3",
    );
    opencv_refused(
        "skew.yml",
        &OPENCV.replacen(
            "458.654, 0., 367.21499999999997",
            "458.654, 0.5, 367.21499999999997",
            1,
        ),
        "is not a camera matrix",
    );
    opencv_refused(
        "notrot.yml",
        &OPENCV.replacen("0.99999725647788118", "1.2", 1),
        "R: not a rotation matrix",
    );
}

#[test]
fn non_finite_numbers_and_a_zero_translation_are_refused() {
    opencv_refused(
        "nan.yml",
        &OPENCV.replacen("458.654", ".Nan", 1),
        "K1.data[0]: NaN is not a finite number",
    );
    kalibr_refused(
        "inf.yaml",
        &CAMCHAIN.replacen("-0.28340811", "-.inf", 1),
        "cam0.distortion_coeffs[0]: -inf is not a finite number",
    );
    opencv_refused(
        "t0.yml",
        &OPENCV.replace(
            "[ -0.11007380812718678, 0.00039912154701414806,\n       -0.00085370250335804494 ]",
            "[ 0., 0., 0. ]",
        ),
        "the translation between the cameras (0, 0, 0) has length 0",
    );
    opencv_refused(
        "swapped.yml",
        &OPENCV.replace("[ -0.11007380812718678,", "[ 0.11007380812718678,"),
        "the right camera is to the left of the left one",
    );
    let left = write(
        "left3.yaml",
        &camera_info(ROS_LEFT_K, ROS_LEFT_D, ROS_LEFT_R, ROS_LEFT_P),
    );
    let right = write(
        "right3.yaml",
        &camera_info(ROS_RIGHT_K, ROS_RIGHT_D, ROS_RIGHT_R, ROS_RIGHT_P),
    );
    refused(
        &["--ros", s(&right), s(&left)],
        "is not [f 0 cx 0; 0 f cy 0; 0 0 1 0]",
    );
}

#[test]
fn an_unwritable_output_is_named() {
    let out = "/no/such/dir/rig.toml";
    assert_one_line_error(
        &stereonav(&[
            "rig",
            "import",
            "--kalibr",
            s(&write("camchain2.yaml", CAMCHAIN)),
            "--out",
            out,
        ]),
        "cannot write /no/such/dir/rig.toml",
    );
}
