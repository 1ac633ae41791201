"""Python gives what the command line gives (``vehicle-interfaces.md`` section 6): every rig
table reaches the stack, whichever front end reads it.

* :class:`stereonav.RigConfig` shows every table and key the Rust reader reads
  (``_native.rig_file_keys()``, the reader's own list): a table or key one side reads and the
  other does not fails here.
* For every scenario of ``fixtures/scenarios`` (simulated with the nominal rig file a user
  would have, ``stereonav simulate --rig``) and for its log rewritten by the Python ``mcap``
  writer (another writer, another chunk size, no compression), ``stereonav.replay`` with the
  rig file's path and with the :class:`RigConfig` gives the summary ``stereonav replay --rig``
  writes, key for key. A rig with every table (lenses, a vehicle off its defaults, the board's
  registers, the odometry's time constants) likewise.
* ``Navigator`` fed the log's frames by hand, ``calibrate_log``, ``localize`` and
  ``fleet.replay_logs`` agree with their command-line forms on a real-lens log with a rig file.

The scenarios whose replays take minutes (the halls, the warehouse, the 8-hour shift) are in
the slow tier (``pytest -m slow``, ``bash scripts/test.sh --slow``).
"""

from __future__ import annotations

import functools
import json
import math
import pathlib
import subprocess
from typing import Any

import numpy as np
import pytest

import stereonav
from stereonav import RigConfig, _native, load_rig

ROOT = pathlib.Path(__file__).resolve().parents[3]
SCENARIOS = ROOT / "fixtures" / "scenarios"

#: Scenarios whose two replays take more than a few seconds each: the slow tier. The slipping
#: wheels' aisle keeps phase 1's batch for its whole 2000 frames (docs/vehicle.md, "Odometry
#: with memory"): two minutes in this build.
SLOW = {
    "aisle-vehicle-slip",
    "hall-dense-localize",
    "hall-dense-map",
    "hall-localize",
    "hall-map",
    "hall-radtan",
    "warehouse",
    "warehouse-shift",
}
ALL = sorted(p.name[: -len(".toml")] for p in SCENARIOS.glob("*.toml") if not p.name.endswith(".rig.toml"))


def scenario_params() -> list[Any]:
    return [pytest.param(name, marks=pytest.mark.slow) if name in SLOW else name for name in ALL]


@pytest.fixture(scope="module")
def scratch(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    return tmp_path_factory.mktemp("parity")


def run(cli: pathlib.Path, *args: object, timeout: float = 3000) -> subprocess.CompletedProcess[str]:
    done = subprocess.run(
        [str(cli), *map(str, args)], capture_output=True, text=True, timeout=timeout, check=False
    )
    assert done.returncode == 0, f"stereonav {' '.join(map(str, args))}: {done.stderr}"
    return done


@functools.lru_cache(maxsize=None)
def simulated(cli: pathlib.Path, scratch: pathlib.Path, name: str) -> tuple[pathlib.Path, pathlib.Path]:
    """The scenario's log and the nominal rig file a user would have (``simulate --rig``)."""
    log, rig = scratch / f"{name}.mcap", scratch / f"{name}.rig.toml"
    run(cli, "simulate", SCENARIOS / f"{name}.toml", "--out", log, "--rig", rig)
    return log, rig


def rewritten(log: pathlib.Path) -> pathlib.Path:
    """The log rewritten by the reference Python ``mcap`` writer: 16 KiB chunks, no
    compression, its own indexes and summary."""
    from mcap.writer import CompressionType

    import mcap_copy

    return mcap_copy.rewrite(
        log, log.with_name(log.stem + "-pymcap.mcap"), chunk_size=16 * 1024, compression=CompressionType.NONE
    )


def cli_summary(cli: pathlib.Path, command: str, log: pathlib.Path, *args: object) -> dict[str, Any]:
    summary = log.with_name(f"{log.stem}-{command}-{abs(hash(args)) % 10**8}.json")
    run(cli, command, log, *args, "--summary", summary)
    result: dict[str, Any] = json.loads(summary.read_text())
    return result


def assert_same_summary(python: dict[str, Any], command_line: dict[str, Any]) -> None:
    """Key for key and number for number (``NaN`` equal to ``NaN``). No key of a summary
    depends on the machine or the time, so all of them are compared."""
    assert set(python) == set(command_line)

    def same(a: Any, b: Any, at: str) -> None:
        if isinstance(a, dict) and isinstance(b, dict):
            assert set(a) == set(b), at
            for key in a:
                same(a[key], b[key], f"{at}.{key}")
        elif isinstance(a, list) and isinstance(b, list):
            assert len(a) == len(b), at
            for i, (x, y) in enumerate(zip(a, b)):
                same(x, y, f"{at}[{i}]")
        elif isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
            pass
        else:
            assert a == b and type(a) is type(b), f"{at}: {a!r} (Python) != {b!r} (command line)"

    same(python, command_line, "summary")


# --- The rig object shows every table the reader reads -------------------------------------------

#: How RigConfig shows each ``(table, key)`` of the rig file. A table or key the Rust reader
#: learns must be added here, or the test below fails.
SHOWN = {
    "camera": lambda rig, key: {
        "width": rig.width, "height": rig.height, "f": rig.nominal.f, "cx": rig.nominal.cx,
        "cy": rig.nominal.cy, "baseline": rig.nominal.baseline,
    }[key],
    "mount": lambda rig, key: getattr(rig.nominal, f"mount_{key}"),
    "estimate": lambda rig, key: list(rig.estimate) if key == "parameters" else None,
    "prior": lambda rig, key: rig.prior[key],
    "noise": lambda rig, key: {
        "pixel": rig.pixel_noise, "velocity": rig.velocity_noise, "yaw_rate": rig.yaw_rate_noise,
        "velocity_tau": rig.velocity_tau, "yaw_rate_tau": rig.yaw_rate_tau,
    }[key],
    "vehicle": lambda rig, key: getattr(rig.vehicle, key),
    "lens.left": lambda rig, key: getattr(rig.lens.left, key),
    "lens.right": lambda rig, key: getattr(rig.lens.right, key),
    "board": lambda rig, key: getattr(rig.board, key),
}

FULL_RIG = """
[camera]
width = 752
height = 480
f = 436.2443
cx = 364.4412
cy = 256.9517
baseline = 0.110078

[mount]
x = 0.1
y = -0.05
z = 1.2
roll = 0.01
pitch = 0.02
yaw = -0.03

[estimate]
parameters = ["baseline", "f", "odom_scale", "time_offset"]

[prior]
baseline = 0.005
f = 20.0
odom_scale = 0.02
time_offset = 0.03

[noise]
pixel = 0.3
velocity = 0.02
yaw_rate = 0.01
velocity_tau = 0.6
yaw_rate_tau = 0.5

[vehicle]
odom_scale = 1.015
odom_yaw_scale = 0.99
odom_yaw_bias = 0.002
time_offset = -0.012

[board]
threshold = 300000
max_features = 700

[lens.left]
model = "plumb_bob"
fx = 458.654
fy = 457.296
cx = 367.215
cy = 248.375
coefficients = [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]
rectification = [0.9999, -0.0087, 0.0112, 0.0088, 0.9999, -0.0048, -0.0112, 0.0049, 0.9999]

[lens.right]
model = "equidistant"
fx = 457.587
fy = 456.134
cx = 379.999
cy = 255.238
coefficients = [-0.01, 0.002, -0.0003, 0.00001]
rectification = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
"""


def full_rig(directory: pathlib.Path) -> pathlib.Path:
    """A rig file with every table and key, none at its default (the rectifications made
    orthonormal to the reader's tolerance)."""
    import tomllib

    tables = tomllib.loads(FULL_RIG)
    for side in ("left", "right"):
        r = np.array(tables["lens"][side]["rectification"]).reshape(3, 3)
        u, _, vt = np.linalg.svd(r)
        tables["lens"][side]["rectification"] = (u @ vt).ravel().tolist()
    path = directory / "full.rig.toml"
    path.write_text(RigConfig.from_tables(tables, "full").to_toml())
    return path


def test_the_rig_object_shows_every_table_and_key_the_reader_reads(tmp_path: pathlib.Path) -> None:
    import tomllib

    path = full_rig(tmp_path)
    text = tomllib.loads(path.read_text())
    rig = load_rig(path)
    keys = _native.rig_file_keys()
    assert {table for table, _ in keys} == set(SHOWN), "a rig-file table RigConfig does not show"
    for table, names in keys:
        if table == "prior":
            names = list(text["prior"])
        section = text
        for part in table.split("."):
            section = section[part]
        for key in names:
            shown = SHOWN[table](rig, key)
            value = section[key]
            if isinstance(value, list):
                np.testing.assert_array_equal(np.asarray(shown), np.asarray(value), err_msg=f"[{table}] {key}")
            else:
                assert shown == value, f"[{table}] {key}: RigConfig shows {shown!r}, the file has {value!r}"
    # The file every table of which differs from its default reads back whole.
    assert rig.tables == tomllib.loads(rig.to_toml())
    assert RigConfig.from_toml(rig.to_toml()) == rig == RigConfig.from_json(rig.to_json())
    assert RigConfig.from_tables(rig.tables) == rig
    assert rig.lens is not None and rig.lens.left.model == "plumb_bob" and rig.lens.right.model == "equidistant"
    assert rig.vehicle == stereonav.Vehicle(1.015, 0.99, 0.002, -0.012)
    assert rig.board == stereonav.Board(300000, 700)
    assert (rig.velocity_tau, rig.yaw_rate_tau) == (0.6, 0.5)


def test_replace_keeps_every_other_table_and_checks_again(tmp_path: pathlib.Path) -> None:
    import copy
    import pickle

    rig = load_rig(full_rig(tmp_path))
    noisier = rig.replace(pixel_noise=0.5)
    assert noisier.pixel_noise == 0.5 and noisier.lens == rig.lens and noisier.vehicle == rig.vehicle
    assert noisier.board == rig.board and noisier.velocity_tau == 0.6 and noisier != rig
    assert noisier.replace(pixel_noise=0.3) == rig
    no_lens = rig.replace(lens=None)
    assert no_lens.lens is None and "[lens" not in no_lens.to_toml()
    assert no_lens.replace(lens=rig.lens) == rig
    assert rig.replace(vehicle=stereonav.Vehicle()).tables.get("vehicle") is None
    assert rig.replace(board=stereonav.Board(1, 1)).board == stereonav.Board(1, 1)
    assert pickle.loads(pickle.dumps(rig)) == rig
    assert copy.deepcopy(rig) == rig
    with pytest.raises(stereonav.InputError, match=r"RigConfig: \[noise\] pixel: NaN is not a finite number"):
        rig.replace(pixel_noise=float("nan"))
    with pytest.raises(stereonav.InputError, match=r"RigConfig: \[board\] max_features: 2000 is outside"):
        rig.replace(board=stereonav.Board(0, 2000))
    with pytest.raises(stereonav.InputError, match=r"RigConfig: \[prior\] (baseline|f): missing key"):
        rig.replace(prior={})
    with pytest.raises(stereonav.InputTypeError, match="unknown field 'focus'"):
        rig.replace(focus=1.0)
    with pytest.raises(stereonav.InputError, match=r"camera.f: a rig file holds numbers"):
        RigConfig.from_tables({**rig.tables, "camera": {**rig.tables["camera"], "f": object()}})
    with pytest.raises(stereonav.InputTypeError, match="make a RigConfig with"):
        RigConfig()
    with pytest.raises(AttributeError):
        rig.width = 3  # type: ignore[misc]


# --- replay: every scenario, both writers ---------------------------------------------------------


@pytest.mark.parametrize("name", scenario_params())
def test_python_replays_every_scenario_as_the_command_line_does(
    cli: pathlib.Path, scratch: pathlib.Path, name: str
) -> None:
    log, rig = simulated(cli, scratch, name)
    config = load_rig(rig)
    for source in (log, rewritten(log)):
        expected = cli_summary(cli, "replay", source, "--rig", rig)
        assert_same_summary(stereonav.replay(source, rig).summary, expected)
        assert_same_summary(stereonav.replay(source, config).summary, expected)
    if config.lens is not None:
        assert expected["landmarks"], f"{name}: a lens log maps lamps"


def test_a_rig_with_every_table_replays_as_the_command_line_does(
    cli: pathlib.Path, scratch: pathlib.Path, tmp_path: pathlib.Path
) -> None:
    """The radtan scenario's rig with a vehicle off its defaults, the board's registers and the
    odometry's time constants added: the same summary from both front ends (the vehicle's
    nominal values are the first thing such a run's summary shows)."""
    log, rig = simulated(cli, scratch, "paper-experiment-radtan")
    tables = load_rig(rig).tables
    tables["vehicle"] = {"odom_scale": 1.004, "odom_yaw_scale": 1.0, "odom_yaw_bias": 0.0, "time_offset": 0.0}
    tables["board"] = {"threshold": 100000, "max_features": 900}
    tables["noise"]["velocity_tau"] = 0.3
    full = tmp_path / "everything.rig.toml"
    full.write_text(RigConfig.from_tables(tables).to_toml())
    expected = cli_summary(cli, "replay", log, "--rig", full)
    assert_same_summary(stereonav.replay(log, full).summary, expected)
    assert_same_summary(stereonav.replay(log, load_rig(full)).summary, expected)
    plain = cli_summary(cli, "replay", log, "--rig", rig)
    assert expected != plain, "the vehicle table changes the run"


# --- Navigator, calibrate_log, localize and the fleet on a real-lens log ------------------------------


@pytest.mark.parametrize("name", ["paper-experiment-radtan", "paper-experiment-fisheye", "paper-experiment-vehicle"])
def test_the_navigator_fed_by_hand_maps_as_the_command_line_does(
    cli: pathlib.Path, scratch: pathlib.Path, name: str
) -> None:
    log, rig = simulated(cli, scratch, name)
    expected = cli_summary(cli, "replay", log, "--rig", rig)
    data = stereonav.read_log(log)
    nav = stereonav.Navigator(rig)
    odometry = data.odometry
    start = 0
    for frame in sorted(data.frames, key=lambda f: f.t_us):
        # As the replay feeds a log's odometry: up to the look-ahead past the frame's stamp.
        end = int(np.searchsorted(odometry["t_us"], frame.t_us + stereonav.ODOMETRY_LOOKAHEAD_US, side="right"))
        nav.push_odometry_samples(odometry[start:end])
        start = end
        nav.push_frame(frame.t_us, frame.left, frame.right)
    nav.finish()
    landmarks = nav.landmarks
    assert len(landmarks) == len(expected["landmarks"]) > 0
    for row, want in zip(landmarks, expected["landmarks"]):
        assert [row["x"], row["y"], row["z"]] == [want["x"], want["y"], want["z"]]
    for name, estimate in nav.camera.items():
        assert estimate.value == expected["camera"][name]["value"], name
    for name, estimate in nav.vehicle.items():
        assert estimate.value == expected["vehicle"][name]["value"], name


def test_calibrate_log_gives_what_stereonav_calibrate_gives(cli: pathlib.Path, scratch: pathlib.Path) -> None:
    log, rig = simulated(cli, scratch, "paper-experiment-radtan")
    out = scratch / "radtan-calibration.json"
    run(cli, "calibrate", log, "--rig", rig, "--out", out)
    expected = json.loads(out.read_text())
    for given in (rig, load_rig(rig)):
        result = stereonav.calibrate_log(log, given)
        assert result.document == expected
        assert result.document["rig_source"] == "given"


def test_localize_gives_what_stereonav_localize_gives(cli: pathlib.Path, scratch: pathlib.Path) -> None:
    log, rig = simulated(cli, scratch, "paper-experiment-radtan")
    saved = scratch / "radtan.map"
    run(cli, "replay", log, "--rig", rig, "--save-map", saved)
    expected = cli_summary(cli, "localize", log, "--map", saved, "--rig", rig)
    for given in (rig, load_rig(rig)):
        assert_same_summary(stereonav.localize(log, saved, given).summary, expected)
    assert expected["localized_t_us"], "the lens log localises"


def test_the_fleet_gives_what_the_command_line_gives(cli: pathlib.Path, scratch: pathlib.Path) -> None:
    fleet = pytest.importorskip("stereonav.fleet")
    log, rig = simulated(cli, scratch, "paper-experiment-radtan")
    paths = [log, rewritten(log)]
    table = fleet.replay_logs(paths, rig, n_workers=1, progress=False)
    for log, (_, row) in zip(paths, table.iterrows()):
        expected = cli_summary(cli, "replay", log, "--rig", rig)
        assert row["error"] is None
        assert row["landmarks"] == len(expected["landmarks"])
        for group in ("camera", "vehicle"):
            for name, estimate in expected[group].items():
                assert row[name] == estimate["value"] and row[f"{name}_sigma"] == estimate["sigma"], name
    by_object = fleet.replay_logs(paths[:1], load_rig(rig), n_workers=1, progress=False)
    assert by_object.iloc[0]["landmarks"] == table.iloc[0]["landmarks"] > 0
