"""``stereonav rig import`` (vehicle-interfaces.md section 5) against OpenCV itself.

From EuRoC V1_01's real ``sensor.yaml`` files (``../shared/data``; skipped without them) a
Kalibr ``camchain.yaml`` (``T_cn_cnm1 = inverse(T_BS_cam1) T_BS_cam0``), an OpenCV
``FileStorage`` written by ``cv2.FileStorage`` (``R``, ``T`` from the same transform) and ROS
``camera_info`` files (``R``, ``P`` from ``cv2.stereoRectify``) are imported with the command
line and with ``stereonav.import_rig`` (the same file, byte for byte) and compared with ``cv2.stereoRectify(..., flags=CALIB_ZERO_DISPARITY, alpha=0)``: ``f``,
``cx``, ``cy`` within 0.01 px, the baseline within 1 um, ``R1``, ``R2`` within 1e-6, and
``stereonav.rectify_points`` with the imported rig equal to ``cv2.undistortPoints(p, K, D, R,
P)`` iterated to convergence within 0.01 px over the image. A fisheye pair of our own making
(752 x 480, k1..k4, a small rotation, 0.11 m) likewise against ``cv2.fisheye.stereoRectify``
(``balance=0``) and ``cv2.fisheye.undistortPoints``; it needs no shared data.
``stereonav.import_rig``'s argument checks and errors (the command line's message) close it.
"""

from __future__ import annotations

import os
import pathlib
import subprocess
from typing import Any, Callable

import numpy as np
import numpy.typing as npt
import pytest

import stereonav

cv2 = pytest.importorskip("cv2")
tomllib = pytest.importorskip("tomllib")

ROOT = pathlib.Path(__file__).resolve().parents[3]
EUROC = ROOT.parent / "shared" / "data" / "euroc-v101-stereo"
SIZE = (752, 480)
CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-14)

#: The contract's tolerances (the brief of issue 17's `rig import`).
PIXEL_TOLERANCE = 0.01
BASELINE_TOLERANCE_M = 1e-6
ROTATION_TOLERANCE = 1e-6

Array = npt.NDArray[np.float64]


class Calibration:
    """A raw stereo calibration in OpenCV's terms: ``K1 D1 K2 D2 R T``, the image size, model."""

    def __init__(self, k1: Array, d1: Array, k2: Array, d2: Array, r: Array, t: Array, fisheye: bool) -> None:
        self.k1, self.d1, self.k2, self.d2 = k1, d1, k2, d2
        self.r, self.t = r, t.reshape(3, 1)
        self.fisheye = fisheye

    def opencv_rectify(self) -> tuple[Array, Array, Array, Array]:
        """``R1, R2, P1, P2`` of ``cv2.stereoRectify`` (``cv2.fisheye.stereoRectify``)."""
        if self.fisheye:
            r1, r2, p1, p2, _ = cv2.fisheye.stereoRectify(
                self.k1, self.d1, self.k2, self.d2, SIZE, self.r, self.t,
                flags=cv2.CALIB_ZERO_DISPARITY, balance=0.0, fov_scale=1.0,
            )
        else:
            r1, r2, p1, p2, *_ = cv2.stereoRectify(
                self.k1, self.d1, self.k2, self.d2, SIZE, self.r, self.t,
                flags=cv2.CALIB_ZERO_DISPARITY, alpha=0,
            )
        return r1, r2, p1, p2

    def opencv_rectify_points(self, points: Array, camera: str) -> Array:
        """``cv2.undistortPoints`` (``cv2.fisheye.undistortPoints``) iterated to convergence."""
        r1, r2, p1, p2 = self.opencv_rectify()
        k, d, r, p = (self.k1, self.d1, r1, p1) if camera == "left" else (self.k2, self.d2, r2, p2)
        undistort = cv2.fisheye.undistortPoints if self.fisheye else cv2.undistortPoints
        out = undistort(points.reshape(-1, 1, 2), k, d, R=r, P=p[:, :3], criteria=CRITERIA)
        return np.asarray(out, dtype=np.float64).reshape(-1, 2)


def matrix_node(fs: Any, name: str) -> Array:
    """A ``{rows, cols, data}`` mapping of a ``sensor.yaml`` (no ``!!opencv-matrix`` tag)."""
    node = fs.getNode(name)
    rows, cols = int(node.getNode("rows").real()), int(node.getNode("cols").real())
    data = node.getNode("data")
    return np.array([data.at(i).real() for i in range(rows * cols)]).reshape(rows, cols)


def sequence(fs: Any, name: str) -> Array:
    node = fs.getNode(name)
    return np.array([node.at(i).real() for i in range(node.size())])


def euroc() -> Calibration:
    if not (EUROC / "cam0-sensor.yaml").is_file():
        pytest.skip(f"no EuRoC sensor.yaml in {EUROC} (the shared data folder is absent)")
    cams = []
    for name in ("cam0", "cam1"):
        fs = cv2.FileStorage(str(EUROC / f"{name}-sensor.yaml"), cv2.FILE_STORAGE_READ)
        body_from_cam = matrix_node(fs, "T_BS")
        fu, fv, cu, cv = sequence(fs, "intrinsics")
        k = np.array([[fu, 0.0, cu], [0.0, fv, cv], [0.0, 0.0, 1.0]])
        assert fs.getNode("distortion_model").string() == "radial-tangential"
        assert list(sequence(fs, "resolution")) == list(SIZE)
        cams.append((body_from_cam, k, sequence(fs, "distortion_coefficients")))
        fs.release()
    cam1_from_cam0 = np.linalg.inv(cams[1][0]) @ cams[0][0]
    return Calibration(
        cams[0][1], cams[0][2], cams[1][1], cams[1][2],
        cam1_from_cam0[:3, :3].copy(), cam1_from_cam0[:3, 3].copy(), fisheye=False,
    )


def fisheye() -> Calibration:
    """A plausible 752 x 480 equidistant pair of our own: k1..k4, a small rotation, 0.11 m."""
    k1 = np.array([[360.0, 0.0, 375.0], [0.0, 360.4, 240.5], [0.0, 0.0, 1.0]])
    k2 = np.array([[361.2, 0.0, 378.3], [0.0, 361.0, 236.9], [0.0, 0.0, 1.0]])
    d1 = np.array([-0.0137, 0.0182, -0.0114, 0.0025])
    d2 = np.array([-0.0121, 0.0171, -0.0109, 0.0023])
    r, _ = cv2.Rodrigues(np.array([0.004, -0.01, 0.002]))
    return Calibration(k1, d1, k2, d2, np.asarray(r), np.array([-0.11, 0.0012, -0.0008]), fisheye=True)


# --- The three input formats, written from a calibration ----------------------------------------


def flow(values: npt.ArrayLike) -> str:
    return "[" + ", ".join(repr(float(v)) for v in np.asarray(values).ravel()) + "]"


def write_kalibr(cal: Calibration, path: pathlib.Path) -> pathlib.Path:
    transform = np.eye(4)
    transform[:3, :3], transform[:3, 3] = cal.r, cal.t.ravel()
    model = "equidistant" if cal.fisheye else "radtan"

    def camera(k: Array, d: Array) -> str:
        return (
            f"  camera_model: pinhole\n  distortion_coeffs: {flow(d)}\n  distortion_model: {model}\n"
            f"  intrinsics: {flow([k[0, 0], k[1, 1], k[0, 2], k[1, 2]])}\n"
            f"  resolution: [{SIZE[0]}, {SIZE[1]}]\n  rostopic: /cam/image_raw\n"
        )

    rows = "".join(f"  - {flow(row)}\n" for row in transform)
    path.write_text(
        "cam0:\n  cam_overlaps: [1]\n" + camera(cal.k1, cal.d1)
        + "cam1:\n  T_cn_cnm1:\n" + rows + "  cam_overlaps: [0]\n" + camera(cal.k2, cal.d2)
    )
    return path


def write_opencv(cal: Calibration, path: pathlib.Path) -> pathlib.Path:
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for name, value in (("K1", cal.k1), ("D1", cal.d1), ("K2", cal.k2), ("D2", cal.d2), ("R", cal.r), ("T", cal.t)):
        # As the calibration functions return them: D 1 x n (fisheye n x 1), T 3 x 1.
        shape = (-1, 1) if (name.startswith("D") and cal.fisheye) else ((1, -1) if name.startswith("D") else value.shape)
        fs.write(name, np.asarray(value, dtype=np.float64).reshape(shape))
    fs.write("width", SIZE[0])
    fs.write("height", SIZE[1])
    if cal.fisheye:
        fs.write("model", "equidistant")
    fs.release()
    return path


def write_ros(cal: Calibration, directory: pathlib.Path) -> tuple[pathlib.Path, pathlib.Path]:
    r1, r2, p1, p2 = cal.opencv_rectify()
    model = "equidistant" if cal.fisheye else "plumb_bob"
    paths = []
    for side, k, d, r, p in (("left", cal.k1, cal.d1, r1, p1), ("right", cal.k2, cal.d2, r2, p2)):
        coefficients = list(d.ravel()) + ([] if cal.fisheye else [0.0])  # ROS plumb_bob: 5
        text = (
            f"image_width: {SIZE[0]}\nimage_height: {SIZE[1]}\ncamera_name: {side}\n"
            f"camera_matrix:\n  rows: 3\n  cols: 3\n  data: {flow(k)}\n"
            f"distortion_model: {model}\n"
            f"distortion_coefficients:\n  rows: 1\n  cols: {len(coefficients)}\n  data: {flow(coefficients)}\n"
            f"rectification_matrix:\n  rows: 3\n  cols: 3\n  data: {flow(r)}\n"
            f"projection_matrix:\n  rows: 3\n  cols: 4\n  data: {flow(p)}\n"
        )
        path = directory / f"{side}.yaml"
        path.write_text(text)
        paths.append(path)
    return paths[0], paths[1]


# --- The command line ------------------------------------------------------------------------


def run_import(cli: pathlib.Path, args: list[str], out: pathlib.Path) -> dict[str, Any]:
    done = subprocess.run(
        [str(cli), "rig", "import", *args, "--out", str(out)],
        capture_output=True, text=True, timeout=60, check=False,
    )
    assert done.returncode == 0, done.stderr
    assert done.stderr == "", done.stderr
    assert str(out) in done.stdout
    stereonav.load_rig(out)  # loads through the Python module too
    with out.open("rb") as f:
        rig: dict[str, Any] = tomllib.load(f)
    return rig


def python_import(
    cli_out: pathlib.Path, python_out: pathlib.Path, **calibration: Any
) -> tuple[dict[str, Any], pathlib.Path]:
    """``stereonav.import_rig(**calibration)``: its ``to_toml()`` is the command line's file
    ``cli_out`` byte for byte, and the rig is what that file loads as. Writes the text to
    ``python_out`` and returns it parsed, for :func:`compare`."""
    config = stereonav.import_rig(**calibration)
    text = config.to_toml()
    assert text.encode("utf-8") == cli_out.read_bytes()
    assert config == stereonav.load_rig(cli_out)
    python_out.write_text(text, encoding="utf-8")
    rig: dict[str, Any] = tomllib.loads(text)
    return rig, python_out


def grid() -> Array:
    u, v = np.meshgrid(np.arange(0.0, SIZE[0], 8.0), np.arange(0.0, SIZE[1], 8.0))
    corners = np.array([[0.0, 0.0], [751.0, 0.0], [0.0, 479.0], [751.0, 479.0]])
    return np.vstack([np.column_stack([u.ravel(), v.ravel()]), corners])


#: The largest differences measured, per case, for the record (``pytest -s`` prints them).
MEASURED: dict[str, dict[str, float]] = {}


def compare(name: str, cal: Calibration, rig: dict[str, Any], path: pathlib.Path) -> None:
    r1, r2, p1, p2 = cal.opencv_rectify()
    camera = rig["camera"]
    measured = {
        "f_px": abs(camera["f"] - p1[0, 0]),
        "cx_px": abs(camera["cx"] - p1[0, 2]),
        "cy_px": abs(camera["cy"] - p1[1, 2]),
        "baseline_m": abs(camera["baseline"] - (-p2[0, 3] / p2[0, 0])),
        "R": max(
            np.abs(np.reshape(rig["lens"]["left"]["rectification"], (3, 3)) - r1).max(),
            np.abs(np.reshape(rig["lens"]["right"]["rectification"], (3, 3)) - r2).max(),
        ),
    }
    points = grid()
    for side, k, d in (("left", cal.k1, cal.d1), ("right", cal.k2, cal.d2)):
        lens = rig["lens"][side]
        assert lens["model"] == ("equidistant" if cal.fisheye else "plumb_bob")
        assert [lens["fx"], lens["fy"], lens["cx"], lens["cy"]] == [k[0, 0], k[1, 1], k[0, 2], k[1, 2]]
        np.testing.assert_array_equal(lens["coefficients"][: len(d.ravel())], d.ravel())
        ours = stereonav.rectify_points(points, path, camera=side)
        theirs = cal.opencv_rectify_points(points, side)
        finite = np.all(np.isfinite(ours), axis=1) & np.all(np.isfinite(theirs), axis=1)
        assert finite.mean() > 0.99, f"{side}: {finite.mean()}"
        measured[f"points_{side}_px"] = float(np.abs(ours[finite] - theirs[finite]).max())
    MEASURED[name] = measured
    print(name, {k: f"{v:.2e}" for k, v in measured.items()})
    for key in ("f_px", "cx_px", "cy_px"):
        assert measured[key] < PIXEL_TOLERANCE, (key, measured)
    assert measured["baseline_m"] < BASELINE_TOLERANCE_M, measured
    assert measured["R"] < ROTATION_TOLERANCE, measured
    assert measured["points_left_px"] < PIXEL_TOLERANCE, measured
    assert measured["points_right_px"] < PIXEL_TOLERANCE, measured


CALIBRATIONS: dict[str, Callable[[], Calibration]] = {"radtan": euroc, "fisheye": fisheye}


@pytest.mark.parametrize("lens", sorted(CALIBRATIONS))
def test_kalibr_camchain_equals_opencv(lens: str, cli: pathlib.Path, tmp_path: pathlib.Path) -> None:
    cal = CALIBRATIONS[lens]()
    out = tmp_path / "rig.toml"
    camchain = write_kalibr(cal, tmp_path / "camchain.yaml")
    rig = run_import(cli, ["--kalibr", str(camchain)], out)
    compare(f"kalibr-{lens}", cal, rig, out)
    compare(f"python-kalibr-{lens}", cal, *python_import(out, tmp_path / "python.toml", kalibr=camchain))


@pytest.mark.parametrize("lens", sorted(CALIBRATIONS))
def test_opencv_filestorage_equals_opencv(lens: str, cli: pathlib.Path, tmp_path: pathlib.Path) -> None:
    cal = CALIBRATIONS[lens]()
    out = tmp_path / "rig.toml"
    stereo = write_opencv(cal, tmp_path / "stereo.yml")
    assert stereo.read_text().startswith("%YAML")
    rig = run_import(cli, ["--opencv", str(stereo)], out)
    compare(f"opencv-{lens}", cal, rig, out)
    compare(f"python-opencv-{lens}", cal, *python_import(out, tmp_path / "python.toml", opencv=str(stereo)))


@pytest.mark.parametrize("lens", sorted(CALIBRATIONS))
def test_ros_camera_info_is_used_as_given(lens: str, cli: pathlib.Path, tmp_path: pathlib.Path) -> None:
    cal = CALIBRATIONS[lens]()
    out = tmp_path / "rig.toml"
    left, right = write_ros(cal, tmp_path)
    rig = run_import(cli, ["--ros", str(left), str(right)], out)
    compare(f"ros-{lens}", cal, rig, out)
    compare(f"python-ros-{lens}", cal, *python_import(out, tmp_path / "python.toml", ros=(left, right)))
    # As given: exactly OpenCV's numbers, to the digits the files hold.
    r1, _, p1, p2 = cal.opencv_rectify()
    assert rig["camera"]["f"] == float(p1[0, 0])
    assert rig["camera"]["baseline"] == pytest.approx(-p2[0, 3] / p2[0, 0], rel=1e-15)
    np.testing.assert_array_equal(rig["lens"]["left"]["rectification"], r1.ravel())


def test_the_old_opencv_header_and_its_errors(cli: pathlib.Path, tmp_path: pathlib.Path) -> None:
    """OpenCV 4's ``%YAML:1.0`` first line is read; a broken file gets one line naming it."""
    cal = fisheye()
    stereo = write_opencv(cal, tmp_path / "stereo.yml")
    text = stereo.read_text()
    assert text.startswith("%YAML 1.2\n---\n")
    old = tmp_path / "old.yml"
    old.write_text("%YAML:1.0\n" + text.split("---\n", 1)[1])
    rig = run_import(cli, ["--opencv", str(old)], tmp_path / "rig.toml")
    compare("opencv-fisheye-yaml1.0", cal, rig, tmp_path / "rig.toml")

    broken = tmp_path / "broken.yml"
    broken.write_text(text.replace("T: !!opencv-matrix\n   rows: 3", "T: !!opencv-matrix\n   rows: 2"))
    done = subprocess.run(
        [str(cli), "rig", "import", "--opencv", str(broken), "--out", str(tmp_path / "x.toml")],
        capture_output=True, text=True, timeout=60, check=False,
    )
    assert done.returncode != 0
    assert done.stderr.count("\n") == 1 and "T: 2 x 1 matrix with 3 numbers" in done.stderr, done.stderr
    assert not (tmp_path / "x.toml").exists()
    # Python raises the command line's message.
    with pytest.raises(stereonav.InputError) as raised:
        stereonav.import_rig(opencv=broken)
    assert done.stderr == f"stereonav: error: {raised.value}\n"


def test_a_baseline_in_millimetres_warns_in_python_as_on_the_command_line(
    cli: pathlib.Path, tmp_path: pathlib.Path
) -> None:
    """A baseline over 2 (metres expected): the command line's warning on stderr, the same
    text as a ``UserWarning`` from Python, and the same file either way."""
    cal = fisheye()
    cal.t = cal.t * 1000.0
    stereo = write_opencv(cal, tmp_path / "stereo-mm.yml")
    out = tmp_path / "rig.toml"
    done = subprocess.run(
        [str(cli), "rig", "import", "--opencv", str(stereo), "--out", str(out)],
        capture_output=True, text=True, timeout=60, check=False,
    )
    assert done.returncode == 0, done.stderr
    assert done.stderr.startswith("stereonav: warning: baseline 110.0"), done.stderr
    with pytest.warns(UserWarning) as warned:
        config = stereonav.import_rig(opencv=stereo)
    assert [f"stereonav: warning: {w.message}\n" for w in warned] == [done.stderr]
    assert config.to_toml().encode("utf-8") == out.read_bytes()


def test_import_rig_takes_exactly_one_calibration_of_paths(tmp_path: pathlib.Path) -> None:
    """Wrong combinations and types of arguments raise one line naming them; so does a file
    that is not there."""
    path = tmp_path / "camchain.yaml"
    refused: list[tuple[Callable[[], object], type[stereonav.Error], str]] = [
        (lambda: stereonav.import_rig(), stereonav.InputTypeError, "import_rig needs one of kalibr="),
        (
            lambda: stereonav.import_rig(kalibr=path, opencv=path),
            stereonav.InputTypeError,
            "import_rig takes one calibration, got kalibr and opencv",
        ),
        (
            lambda: stereonav.import_rig(ros=str(path)),  # type: ignore[arg-type]
            stereonav.InputTypeError,
            "ros must be a pair of paths (left, right), got str",
        ),
        (
            lambda: stereonav.import_rig(ros=(path,)),  # type: ignore[arg-type]
            stereonav.InputError,
            "ros must be two paths (left, right), got 1",
        ),
        (
            lambda: stereonav.import_rig(kalibr=3),  # type: ignore[arg-type]
            stereonav.InputTypeError,
            "kalibr must be a path (str or os.PathLike), got int",
        ),
        (
            lambda: stereonav.import_rig(ros=(path, b"right.yaml")),  # type: ignore[arg-type]
            stereonav.InputTypeError,
            "ros[1] must be a path (str or os.PathLike), got bytes",
        ),
        (
            lambda: stereonav.import_rig(opencv=os.fsencode(path)),  # type: ignore[arg-type]
            stereonav.InputTypeError,
            "opencv must be a path (str or os.PathLike), got bytes",
        ),
        (lambda: stereonav.import_rig(kalibr=path), stereonav.InputError, f"cannot read {path}: "),
    ]
    for call, error, message in refused:
        with pytest.raises(error) as raised:
            call()
        assert str(raised.value).startswith(message), (str(raised.value), message)
        assert "\n" not in str(raised.value)
