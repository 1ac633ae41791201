"""Trajectories in the TUM format (``--trajectory-tum``, ``--truth-tum``) read by evo: on logs
of the project's simulator and of the foreign (Python ``mcap``) writer, for ``replay`` and
``localize``, evo's absolute pose error with no alignment (its Python API and the ``evo_ape``
command) equals the summary's ``truth.ate_rms_m`` and its rotation error the summary's
``heading_rms_rad``; the files are what vehicle-interfaces.md's planar pose says (z = 0, a
unit yaw quaternion, the frames' times exact to the microsecond)."""

from __future__ import annotations

import json
import math
import os
import pathlib
import shutil
import subprocess
import sys
import zipfile

import numpy as np
import pytest

evo_file = pytest.importorskip("evo.tools.file_interface", reason="evo is in requirements-dev.txt")
from evo.core import metrics, sync  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[3]
LOGS = ROOT / "fixtures" / "logs"
#: Logs with simulator truth: the project's writer (a straight drive, the square with its turns)
#: and the foreign writer (fixtures/make_pymcap_log.py).
TRUTH_LOGS = ["paper-experiment.mcap", "paper-square.mcap", "paper-experiment-pymcap.mcap"]
#: evo's association tolerance; the files' times are equal, so any small value pairs them.
MAX_DIFF_S = 1e-4


def run_cli(cli: pathlib.Path, *args: str | os.PathLike[str]) -> subprocess.CompletedProcess[str]:
    p = subprocess.run([str(cli), *map(str, args)], capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    return p


def evo_errors(truth: pathlib.Path, est: pathlib.Path) -> tuple[float, float, int]:
    """evo's APE with no alignment: (translation RMSE, rotation-angle RMSE in radians, poses)."""
    ref = evo_file.read_tum_trajectory_file(str(truth))
    traj = evo_file.read_tum_trajectory_file(str(est))
    ref, traj = sync.associate_trajectories(ref, traj, max_diff=MAX_DIFF_S)
    out = []
    for relation in (metrics.PoseRelation.translation_part, metrics.PoseRelation.rotation_angle_rad):
        ape = metrics.APE(relation)
        ape.process_data((ref, traj))
        out.append(float(ape.get_statistic(metrics.StatisticsType.rmse)))
    return out[0], out[1], traj.num_poses


def evo_ape_command(tmp: pathlib.Path, truth: pathlib.Path, est: pathlib.Path) -> float:
    """The ``evo_ape tum`` command's translation RMSE (no ``--align``), from its saved results."""
    exe = shutil.which("evo_ape", path=os.path.dirname(sys.executable)) or shutil.which("evo_ape")
    if exe is None:
        pytest.fail("the evo_ape command of evo is not installed")
    res = tmp / f"{est.stem}-ape.zip"
    env = dict(os.environ, HOME=str(tmp), MPLBACKEND="Agg")  # evo keeps its settings in ~/.evo
    p = subprocess.run(
        [exe, "tum", str(truth), str(est), "--t_max_diff", str(MAX_DIFF_S), "--no_warnings",
         "--save_results", str(res)],
        capture_output=True, text=True, timeout=300, env=env,
    )
    assert p.returncode == 0, p.stdout + p.stderr
    with zipfile.ZipFile(res) as z:
        stats = json.loads(z.read("stats.json"))
    return float(stats["rmse"])


def read_tum(path: pathlib.Path) -> np.ndarray:
    lines = path.read_text().splitlines()
    assert lines[0] == "# timestamp tx ty tz qx qy qz qw"
    return np.array([[float(v) for v in line.split(" ")] for line in lines[1:]])


@pytest.fixture(scope="module")
def replays(cli: pathlib.Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, pathlib.Path]:
    """Each truth log replayed once with no flags, writing the TUM files, CSV and summary."""
    out = {}
    for name in TRUTH_LOGS:
        d = tmp_path_factory.mktemp(name.removesuffix(".mcap"))
        run_cli(cli, "replay", LOGS / name, "--trajectory-tum", d / "est.tum",
                "--truth-tum", d / "truth.tum", "--trajectory", d / "traj.csv",
                "--summary", d / "summary.json", "--save-map", d / "map")
        out[name] = d
    return out


@pytest.mark.parametrize("name", TRUTH_LOGS)
def test_replay_ate_equals_evo_ape(replays: dict[str, pathlib.Path], name: str,
                                   tmp_path: pathlib.Path) -> None:
    d = replays[name]
    truth = json.loads((d / "summary.json").read_text())["truth"]
    ate, rot, n = evo_errors(d / "truth.tum", d / "est.tum")
    frames = json.loads((d / "summary.json").read_text())["frames"]
    assert n == frames  # every frame of the log has a true pose, and evo paired them all
    assert ate == pytest.approx(truth["ate_rms_m"], rel=1e-9, abs=1e-12)
    assert rot == pytest.approx(truth["heading_rms_rad"], rel=1e-9, abs=1e-12)
    assert evo_ape_command(tmp_path, d / "truth.tum", d / "est.tum") == pytest.approx(
        truth["ate_rms_m"], rel=1e-9, abs=1e-12)


@pytest.mark.parametrize("name", TRUTH_LOGS)
def test_the_tum_trajectory_is_the_csv_trajectory(replays: dict[str, pathlib.Path], name: str) -> None:
    d = replays[name]
    tum = read_tum(d / "est.tum")
    csv = np.genfromtxt(d / "traj.csv", delimiter=",", names=True)
    assert len(tum) == len(csv)
    # Times exact to the microsecond: the text, not a float round trip.
    stamps = [line.split(" ")[0] for line in (d / "est.tum").read_text().splitlines()[1:]]
    assert stamps == [f"{int(t) // 1_000_000}.{int(t) % 1_000_000:06d}" for t in csv["t_us"]]
    np.testing.assert_array_equal(tum[:, 1], csv["x"])
    np.testing.assert_array_equal(tum[:, 2], csv["y"])
    np.testing.assert_array_equal(tum[:, 3:6], 0.0)  # planar: z = 0, qx = qy = 0
    qz, qw = tum[:, 6], tum[:, 7]
    np.testing.assert_allclose(np.hypot(qz, qw), 1.0, rtol=0, atol=1e-15)
    yaw = 2.0 * np.arctan2(qz, qw)
    d_yaw = np.angle(np.exp(1j * (yaw - csv["theta"])))
    np.testing.assert_allclose(d_yaw, 0.0, rtol=0, atol=1e-12)
    if name == "paper-square.mcap":  # the square turns: the quaternions are not all yaw 0
        assert np.ptp(np.unwrap(yaw)) > math.pi


def test_localize_ate_equals_evo_ape(cli: pathlib.Path, replays: dict[str, pathlib.Path],
                                     tmp_path: pathlib.Path) -> None:
    # The square drive localised on its own map: only localised frames have a line.
    d = replays["paper-square.mcap"]
    est, truth_file = tmp_path / "loc.tum", tmp_path / "loc-truth.tum"
    run_cli(cli, "localize", LOGS / "paper-square.mcap", "--map", d / "map",
            "--trajectory-tum", est, "--truth-tum", truth_file, "--trajectory", tmp_path / "loc.csv",
            "--summary", tmp_path / "loc.json")
    summary = json.loads((tmp_path / "loc.json").read_text())
    truth = summary["truth"]
    csv = np.genfromtxt(tmp_path / "loc.csv", delimiter=",", names=True)
    localized = int(np.sum(csv["localized"] == 1))
    assert truth["localized_frames"] == localized > 0.5 * len(csv)
    ate, rot, n = evo_errors(truth_file, est)
    assert n == localized
    assert ate == pytest.approx(truth["ate_rms_m"], rel=1e-9, abs=1e-12)
    assert rot == pytest.approx(truth["heading_rms_rad"], rel=1e-9, abs=1e-12)
    assert evo_ape_command(tmp_path, truth_file, est) == pytest.approx(
        truth["ate_rms_m"], rel=1e-9, abs=1e-12)


def test_truth_tum_on_a_log_without_truth_is_empty_with_a_warning(
        cli: pathlib.Path, tmp_path: pathlib.Path) -> None:
    static = ROOT.parent / "shared" / "data" / "euroc-v101-static"
    if not (static / "log.mcap").is_file():
        pytest.skip("../shared/data/euroc-v101-static (a real log, no truth) is not here")
    p = run_cli(cli, "replay", static / "log.mcap", "--rig", static / "rig.toml",
                "--trajectory-tum", tmp_path / "est.tum", "--truth-tum", tmp_path / "truth.tum")
    assert "the log has no truth: --truth-tum wrote no pose" in p.stderr
    assert (tmp_path / "truth.tum").read_text().splitlines() == ["# timestamp tx ty tz qx qy qz qw"]
    assert len(read_tum(tmp_path / "est.tum")) > 0


def test_an_unwritable_tum_path_is_one_line_naming_it(cli: pathlib.Path, tmp_path: pathlib.Path) -> None:
    bad = tmp_path / "no-such-dir" / "est.tum"
    p = subprocess.run([str(cli), "replay", str(LOGS / "paper-experiment.mcap"),
                        "--trajectory-tum", str(bad)], capture_output=True, text=True, timeout=300)
    assert p.returncode != 0
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "TRAJ.tum" in lines[0] and str(bad) in lines[0], p.stderr


def test_python_writes_the_same_tum_files_as_the_command_line(
        cli: pathlib.Path, replays: dict[str, pathlib.Path], tmp_path: pathlib.Path) -> None:
    import stereonav

    for name in TRUTH_LOGS:
        r = stereonav.replay(LOGS / name)
        r.write_trajectory_tum(tmp_path / "py.tum")
        assert (tmp_path / "py.tum").read_bytes() == (replays[name] / "est.tum").read_bytes()
    d = replays["paper-square.mcap"]
    run_cli(cli, "localize", LOGS / "paper-square.mcap", "--map", d / "map",
            "--trajectory-tum", tmp_path / "loc-cli.tum")
    loc = stereonav.localize(LOGS / "paper-square.mcap", d / "map")
    loc.write_trajectory_tum(tmp_path / "loc-py.tum")
    assert (tmp_path / "loc-py.tum").read_bytes() == (tmp_path / "loc-cli.tum").read_bytes()
    assert len(read_tum(tmp_path / "loc-py.tum")) == int(np.sum(loc.trajectory["localized"]))
    with pytest.raises(stereonav.InputError, match="TRAJ.tum"):
        r.write_trajectory_tum(tmp_path / "no-such-dir" / "x.tum")
