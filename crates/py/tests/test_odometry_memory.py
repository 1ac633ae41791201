"""``scripts/odometry_memory.py`` (docs/odometry-memory.md): the odometry's error memory measured
from a recorded drive, vehicle-interfaces.md section 2's ``velocity_tau`` and ``yaw_rate_tau``."""

from __future__ import annotations

import pathlib
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parents[3]
SCRIPT = ROOT / "scripts" / "odometry_memory.py"


def run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, str(SCRIPT), *args], capture_output=True, text=True, timeout=300, check=False
    )


def test_the_self_test_recovers_a_known_memory() -> None:
    done = run("--selftest")
    assert done.returncode == 0, done.stderr
    assert "selftest: passed" in done.stdout


def test_bad_input_is_one_line_and_exit_2(tmp_path: pathlib.Path) -> None:
    odometry = tmp_path / "odom.csv"
    odometry.write_text("t,vx\n0,1\n0.1,1\n")
    truth = tmp_path / "truth.csv"
    truth.write_text("t,x,y,theta\n0,0,0,0\n")
    done = run("--odometry", str(odometry), "--truth", str(truth))
    assert done.returncode == 2
    assert "Traceback" not in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert "missing column" in done.stderr
