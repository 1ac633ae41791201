"""The rig model from Python: projection, Jacobians, triangulation, rig files."""

from __future__ import annotations

import pathlib

import numpy as np
import pytest

import stereonav
from stereonav import CAMERA_PARAMETERS, Camera, load_rig, project, triangulate

CAMERA = Camera(f=700.0, cx=376.0, cy=240.0, baseline=0.12, mount_z=1.0, mount_pitch=0.2)
POSE = np.array([0.4, -0.3, 0.7])


def landmarks(n: int = 20) -> np.ndarray:
    rng = np.random.default_rng(0)
    robot = np.column_stack([rng.uniform(0.5, 2.0, n), rng.uniform(-0.8, 0.8, n), rng.uniform(3.0, 4.0, n)])
    c, s = np.cos(POSE[2]), np.sin(POSE[2])
    world = robot.copy()
    world[:, 0] = POSE[0] + c * robot[:, 0] - s * robot[:, 1]
    world[:, 1] = POSE[1] + s * robot[:, 0] + c * robot[:, 1]
    return world


def test_projection_conventions() -> None:
    up = Camera(f=700.0, cx=376.0, cy=240.0, baseline=0.12)
    z = project([0.0, 0.0, 2.5], camera=up).z[0]
    assert z == pytest.approx([376.0 + 700 * 0.06 / 2.5, 240.0, 376.0 - 700 * 0.06 / 2.5, 240.0])
    assert z[0] - z[2] == pytest.approx(700 * 0.12 / 2.5)  # disparity f B / z


def test_project_then_triangulate_round_trip() -> None:
    points = landmarks()
    z = project(points, pose=POSE, camera=CAMERA).z
    back = triangulate(z, camera=CAMERA, pose=POSE, sigma_px=0.3)
    np.testing.assert_allclose(back.p_in_world, points, rtol=1e-9, atol=1e-9)
    assert back.cov_in_world.shape == (20, 3, 3)
    assert np.all(np.linalg.eigvalsh(back.cov_in_world) > 0)


@pytest.mark.parametrize("block", ["d_pose", "d_landmark", "d_camera"])
def test_jacobians_match_numerical_differentiation(block: str) -> None:
    points = landmarks(5)
    proj = project(points, pose=POSE, camera=CAMERA)
    analytic = getattr(proj, block)
    h = 1e-6
    for k in range(analytic.shape[2]):
        if block == "d_pose":
            d = np.zeros(3)
            d[k] = h
            plus = project(points, pose=POSE + d, camera=CAMERA).z
            minus = project(points, pose=POSE - d, camera=CAMERA).z
        elif block == "d_landmark":
            d = np.zeros(3)
            d[k] = h
            plus = project(points + d, pose=POSE, camera=CAMERA).z
            minus = project(points - d, pose=POSE, camera=CAMERA).z
        else:
            c = CAMERA.to_array()
            d = np.zeros(10)
            d[k] = h * max(1.0, abs(c[k]))
            plus = project(points, pose=POSE, camera=c + d).z
            minus = project(points, pose=POSE, camera=c - d).z
        numeric = (plus - minus) / (2 * (d[k]))
        np.testing.assert_allclose(analytic[:, :, k], numeric, rtol=1e-5, atol=1e-4, err_msg=f"{block}[{k}]")


def test_behind_and_infinite_points_are_nan() -> None:
    z = project([[0.0, 0.0, -1.0]], camera=Camera(700, 376, 240, 0.12)).z
    assert np.isnan(z).all()
    t = triangulate([[300.0, 240.0, 310.0, 240.0]], camera=CAMERA)
    assert np.isnan(t.p_in_rig).all()


def test_bad_arguments() -> None:
    with pytest.raises(stereonav.InputError, match=r"shape \(2, 2\)"):
        project(np.zeros((2, 2)), camera=CAMERA)
    with pytest.raises(stereonav.InputError, match="not a finite"):
        project([[0.0, np.nan, 2.0]], camera=CAMERA)
    with pytest.raises(stereonav.InputError, match=r"\(10,\)"):
        project([[0.0, 0.0, 2.0]], camera=[700.0, 376.0])
    with pytest.raises(TypeError):
        project([[0.0, 0.0, 2.0]], camera="camera")
    with pytest.raises(ValueError, match="pose"):
        triangulate([[400.0, 240.0, 380.0, 240.0]], camera=CAMERA, pose=[1.0, 2.0])


def test_load_rig(tmp_path: pathlib.Path) -> None:
    text = """
[camera]
width = 752
height = 480
f = 700.0
cx = 376.0
cy = 240.0
baseline = 0.12
[mount]
x = 0.0
y = 0.0
z = 1.0
roll = 0.0
pitch = 0.0
yaw = 0.0
[estimate]
parameters = ["baseline", "f"]
[prior]
f = 30.0
baseline = 0.01
[noise]
pixel = 0.3
velocity = 0.02
yaw_rate = 0.01
"""
    path = tmp_path / "rig.toml"
    path.write_text(text)
    rig = load_rig(path)
    assert rig.nominal.f == 700.0 and rig.nominal.mount_z == 1.0
    assert set(rig.estimate) == {"f", "baseline"} and rig.prior == {"f": 30.0, "baseline": 0.01}
    assert rig.pixel_noise == 0.3 and CAMERA_PARAMETERS[3] == "baseline"
    path.write_text(text.replace("f = 700.0\n", ""))
    with pytest.raises(stereonav.InputError, match=r"rig.toml: \[camera\] f: missing key"):
        load_rig(path)
    path.write_text(text.replace('"baseline", "f"', '"baseline", "focal"'))
    with pytest.raises(ValueError, match='unknown parameter "focal"'):
        load_rig(path)
    with pytest.raises(stereonav.InputError, match="cannot read"):
        load_rig(tmp_path / "missing.toml")
