"""A fleet's logs on Dask (``stereonav.fleet``, ``vehicle-interfaces.md`` section 6).

Every row of :func:`stereonav.fleet.replay_logs` must equal a one-by-one
:func:`stereonav.replay` of the same log, on the default local cluster and on an existing
scheduler with two workers on the loopback (started here as ``dask scheduler`` and ``dask
worker`` processes, as an integrator runs them); a garbage, a foreign and a missing file give
their one-line error in their own row and stop nothing, and damaged logs that can still be
replayed (cut short, a chunk overwritten) are replayed as far as they go, what was lost in
their ``error``. Without the ``fleet`` extra,
``import stereonav`` works and ``stereonav.fleet`` says what to install.
"""

from __future__ import annotations

import math
import os
import pathlib
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator, Mapping
from typing import Any

import pytest

import stereonav

fleet = pytest.importorskip("stereonav.fleet")
pd = pytest.importorskip("pandas")
distributed = pytest.importorskip("distributed")

ROOT = pathlib.Path(__file__).resolve().parents[3]
LOGS = ROOT / "fixtures" / "logs"
#: Logs with the rig in their ``/rig`` channel, from two writers (ours and Python's mcap).
GOOD = [LOGS / "paper-experiment.mcap", LOGS / "paper-experiment-pymcap.mcap", LOGS / "paper-square.mcap"]


def same(a: Any, b: Any) -> bool:
    """Equal, with missing values (None, NaN, pandas' NA) equal to each other."""
    missing_a = a is None or a is pd.NA or (isinstance(a, float) and math.isnan(a))
    missing_b = b is None or b is pd.NA or (isinstance(b, float) and math.isnan(b))
    if missing_a or missing_b:
        return missing_a and missing_b
    return bool(a == b)


def assert_row_is(row: Mapping[str, Any], expected: Mapping[str, Any]) -> None:
    differ = {c: (row[c], expected[c]) for c in fleet.COLUMNS if not same(row[c], expected[c])}
    assert not differ, differ


def one_by_one(log: pathlib.Path) -> dict[str, Any]:
    """The row of a one-by-one replay, and its fixed columns checked against the summary."""
    summary = stereonav.replay(log).summary
    row = fleet.summary_row(str(log), summary)
    assert row["frames"] == summary["frames"] and row["lost"] == summary["lost"]
    assert row["landmarks"] == len(summary["landmarks"])
    assert row["baseline"] == summary["camera"]["baseline"]["value"]
    assert row["odom_scale_sigma"] == summary["vehicle"]["odom_scale"]["sigma"]
    return row


@pytest.fixture(scope="module")
def bad_logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, pathlib.Path]:
    d = tmp_path_factory.mktemp("bad")
    foreign = d / "not-a-log.mcap"
    foreign.write_bytes(b"this is no MCAP file\n" * 50)
    garbage = d / "garbage.mcap"
    garbage.write_bytes(b"\x89MCAP0\r\n" + bytes(range(256)) * 20)  # the magic, then garbage
    return {"foreign": foreign, "garbage": garbage, "missing": d / "no-such-log.mcap"}


@pytest.fixture(scope="module")
def damaged_logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, pathlib.Path]:
    """Damaged logs that are still replayed as far as they go: one cut short (power lost),
    one with a chunk overwritten in the middle."""
    d = tmp_path_factory.mktemp("damaged")
    data = GOOD[2].read_bytes()
    cut = d / "cut.mcap"
    cut.write_bytes(data[: len(data) * 6 // 10])
    overwritten = d / "overwritten.mcap"
    third = len(data) // 3
    overwritten.write_bytes(data[:third] + bytes(4096) + data[third + 4096 :])
    return {"cut": cut, "overwritten": overwritten}


@pytest.fixture(scope="module")
def expected(damaged_logs: dict[str, pathlib.Path]) -> dict[str, dict[str, Any]]:
    return {str(p): one_by_one(p) for p in [*GOOD, *damaged_logs.values()]}


def check_table(table: Any, logs: list[pathlib.Path], expected: Mapping[str, Mapping[str, Any]]) -> None:
    assert list(table.columns) == list(fleet.COLUMNS)
    assert list(table["log"]) == [str(p) for p in logs]
    for (_, row), log in zip(table.iterrows(), logs):
        if str(log) in expected:
            assert_row_is(row, expected[str(log)])
            if log in GOOD:
                assert row["error"] is None, row["error"]
            else:  # damaged, replayed as far as it goes: what was lost, in one line
                error = row["error"]
                assert isinstance(error, str) and "\n" not in error, error
                assert error.startswith("damaged log, replayed as far as it goes: "), error
                assert row["damage"] in error and row["frames"] > 0
        else:
            error = row["error"]
            assert isinstance(error, str) and error and "\n" not in error, error
            assert all(same(row[c], None) for c in fleet.COLUMNS if c not in ("log", "error"))


def test_rows_equal_one_by_one_replays_on_the_default_local_cluster(
    bad_logs: dict[str, pathlib.Path], damaged_logs: dict[str, pathlib.Path],
    expected: dict[str, dict[str, Any]]
) -> None:
    logs = [GOOD[0], bad_logs["foreign"], GOOD[1], bad_logs["garbage"], GOOD[2], bad_logs["missing"],
            damaged_logs["cut"], damaged_logs["overwritten"]]
    seen: list[tuple[int, int]] = []
    table = fleet.replay_logs(logs, progress=lambda done, total, row: seen.append((done, total)))
    check_table(table, logs, expected)
    assert seen == [(i, len(logs)) for i in range(1, len(logs) + 1)]
    assert "no-such-log.mcap" in table["error"].iloc[5]
    assert str(table["frames"].dtype) == "Int64" and table["frames"].iloc[0] == 961


@pytest.fixture(scope="module")
def loopback_scheduler(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """``dask scheduler`` and ``dask worker --nworkers 2`` on 127.0.0.1, as processes."""
    dask = shutil.which("dask", path=os.path.dirname(sys.executable)) or shutil.which("dask")
    if dask is None:
        pytest.fail("the `dask` command of dask[distributed] is not installed")
    d = tmp_path_factory.mktemp("scheduler")
    file = d / "scheduler.json"
    env = dict(os.environ, DASK_DISTRIBUTED__LOGGING__DISTRIBUTED="error")
    procs = [
        subprocess.Popen(
            [dask, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
             # Its HTTP server (health, metrics) on any free port, not 8787.
             "--dashboard-address", "127.0.0.1:0", "--scheduler-file", str(file)],
            cwd=d, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )
    ]
    try:
        deadline = time.monotonic() + 60
        while not file.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        procs.append(
            subprocess.Popen(
                [dask, "worker", "--scheduler-file", str(file), "--nworkers", "2",
                 "--nthreads", "1", "--no-dashboard"],
                cwd=d, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            )
        )
        with distributed.Client(scheduler_file=str(file), timeout=60) as client:
            client.wait_for_workers(2, timeout=120)
            address = client.scheduler.address
        yield address
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in reversed(procs):
            p.wait(timeout=30)


def test_rows_equal_one_by_one_replays_on_an_existing_two_worker_scheduler(
    loopback_scheduler: str, bad_logs: dict[str, pathlib.Path],
    damaged_logs: dict[str, pathlib.Path], expected: dict[str, dict[str, Any]]
) -> None:
    assert loopback_scheduler.startswith("tcp://127.0.0.1:")
    logs = [bad_logs["garbage"], *GOOD, damaged_logs["cut"], bad_logs["foreign"],
            damaged_logs["overwritten"]]
    table = fleet.replay_logs(logs, scheduler=loopback_scheduler, progress=False)
    check_table(table, logs, expected)
    # Relative paths are this process's, whatever the workers' working directory.
    here = os.getcwd()
    try:
        os.chdir(ROOT)
        relative = [GOOD[0].relative_to(ROOT)]
        again = fleet.replay_logs(relative, scheduler=loopback_scheduler, progress=False)
    finally:
        os.chdir(here)
    assert again["error"].iloc[0] is None
    assert_row_is(again.iloc[0], {**expected[str(GOOD[0])], "log": str(relative[0])})


def test_a_rig_file_for_every_log_is_used_as_replay_uses_it() -> None:
    rig = LOGS / "paper-experiment.rig.toml"
    table = fleet.replay_logs([GOOD[0]], rig, n_workers=1, progress=False)
    want = fleet.summary_row(str(GOOD[0]), stereonav.replay(GOOD[0], rig).summary)
    assert_row_is(table.iloc[0], want)


def test_the_command_writes_csv_and_parquet(
    tmp_path: pathlib.Path, bad_logs: dict[str, pathlib.Path], expected: dict[str, dict[str, Any]]
) -> None:
    logs = [GOOD[0], bad_logs["foreign"]]
    for name in ("fleet.csv", "fleet.parquet"):
        out = tmp_path / name
        result = subprocess.run(
            [sys.executable, "-m", "stereonav.fleet", *map(str, logs), "--workers", "1", "--out", str(out)],
            capture_output=True, text=True, timeout=300, check=False,
        )
        assert result.returncode == 0, result.stderr
        assert f"{out}: 2 logs, 1 failed, 0 damaged" in result.stdout
        table = pd.read_csv(out) if name.endswith(".csv") else pd.read_parquet(out)
        assert list(table.columns) == list(fleet.COLUMNS)
        assert table["frames"].iloc[0] == expected[str(GOOD[0])]["frames"]
        assert table["baseline"].iloc[0] == pytest.approx(expected[str(GOOD[0])]["baseline"], rel=1e-12)
        assert "MCAP" in str(table["error"].iloc[1]) or "mcap" in str(table["error"].iloc[1]).lower()
    # The replay's options pass through.
    out = tmp_path / "skip.csv"
    result = subprocess.run(
        [sys.executable, "-m", "stereonav.fleet", str(GOOD[0]), "--workers", "1", "--skip-phase1",
         "--no-progress", "--out", str(out)],
        capture_output=True, text=True, timeout=300, check=False,
    )
    assert result.returncode == 0, result.stderr
    skipped = pd.read_csv(out).iloc[0]
    want = stereonav.replay(GOOD[0], skip_phase1=True).summary
    assert bool(skipped["phase1_skipped"]) is True
    assert skipped["baseline"] == pytest.approx(want["camera"]["baseline"]["value"], rel=1e-12)
    bad = subprocess.run(
        [sys.executable, "-m", "stereonav.fleet", str(GOOD[0]), "--out", str(tmp_path / "t.xlsx")],
        capture_output=True, text=True, timeout=60, check=False,
    )
    assert bad.returncode == 2 and ".csv or .parquet" in bad.stderr


def test_bad_arguments_are_refused_with_a_clear_error() -> None:
    with pytest.raises(TypeError, match="one path"):
        fleet.replay_logs(str(GOOD[0]))
    with pytest.raises(TypeError, match=r"log_paths\[1\]"):
        fleet.replay_logs([GOOD[0], 3])
    with pytest.raises(TypeError, match="scheduler"):
        fleet.replay_logs([GOOD[0]], scheduler=8786)
    with pytest.raises(ValueError, match="n_workers"):
        fleet.replay_logs([GOOD[0]], n_workers=0)
    with pytest.raises(ValueError, match="local cluster"):
        fleet.replay_logs([GOOD[0]], scheduler="tcp://127.0.0.1:1", n_workers=2)
    empty = fleet.replay_logs([])
    assert list(empty.columns) == list(fleet.COLUMNS) and len(empty) == 0


def test_without_the_fleet_extra_the_package_works_and_fleet_says_what_to_install() -> None:
    # Dask and pandas hidden from a fresh interpreter by a meta-path finder that refuses them.
    code = """
import sys
class Hide:
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in ('distributed', 'dask', 'pandas'):
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
sys.meta_path.insert(0, Hide())
import stereonav
assert stereonav.harris is not None
try:
    stereonav.fleet
except ImportError as e:
    print(e)
else:
    raise SystemExit('stereonav.fleet imported without Dask')
"""
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=False)
    assert result.returncode == 0, result.stderr
    assert "pip install 'stereonav[fleet]'" in result.stdout, result.stdout
    assert "crates/py[fleet]" in result.stdout
