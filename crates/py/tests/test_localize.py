"""Saved maps and runs on them from Python: ``stereonav.replay(..., save_map=)`` saves the map
of the paper's experiment, ``stereonav.localize`` runs the same log on it (it localises, the
poses agree with the log's truth, the summary has the keys of vehicle-interfaces.md section 5
and equals the command line's ``SUMMARY.json``), ``read_map``/``write_map`` round-trip the file
byte for byte, and bad maps, logs and arguments are refused with one line naming them."""

from __future__ import annotations

import copy
import json
import pathlib
import re
import subprocess
import threading
import time
import zlib
from typing import Any

import numpy as np
import pytest

import stereonav
from stereonav import (
    CAMERA_PARAMETERS,
    LOCALIZED_TRAJECTORY_DTYPE,
    MAP_VERSION,
    NEW_LAMP_DTYPE,
    InputError,
    InputTypeError,
    Localization,
    localize,
    read_map,
    replay,
    write_map,
)

ROOT = pathlib.Path(__file__).resolve().parents[3]
LOGS = ROOT / "fixtures" / "logs"
EXPERIMENT_LOG = LOGS / "paper-experiment.mcap"
EXPERIMENT_RIG = LOGS / "paper-experiment.rig.toml"
#: The lamps of the paper's scenarios.
LAMPS = 5
#: The keys of a localisation SUMMARY.json fixed by vehicle-interfaces.md section 5.
SECTION_5_KEYS = {
    "frames", "corrupt", "lost", "phase_switch_t_us", "pose", "camera", "vehicle", "landmarks",
    "localized_t_us", "lamps_missing",
}
MAP_KEYS = {"common_error", "format", "version", "created_unix_s", "source_log", "rig", "parameters", "landmarks"}


@pytest.fixture(scope="module")
def saved_map(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    """The map of the paper's experiment (phase 1 skipped, as in the paper), saved by the
    Python replay once per module."""
    path = tmp_path_factory.mktemp("maps") / "experiment.map"
    replay(EXPERIMENT_LOG, EXPERIMENT_RIG, skip_phase1=True, save_map=path)
    return path


@pytest.fixture(scope="module")
def run(saved_map: pathlib.Path) -> Localization:
    """The same log localised on it."""
    return localize(EXPERIMENT_LOG, saved_map)


def map_file(body: dict[str, Any], version: int = MAP_VERSION) -> bytes:
    """A map file made by hand (docs/maps.md): the header line, then the body."""
    data = json.dumps(body).encode()
    return b"stereonav-map %d len=%d crc32=%08x\n" % (version, len(data), zlib.crc32(data)) + data


# --- Saving a map ----------------------------------------------------------------------------


def test_the_replay_saves_its_map(saved_map: pathlib.Path) -> None:
    r = replay(EXPERIMENT_LOG, EXPERIMENT_RIG, skip_phase1=True)
    m = read_map(saved_map)
    assert set(m) == MAP_KEYS
    # Version 1, which every build reads: only a map without a rig is written as 2.
    assert m["format"] == "stereonav-map" and m["version"] == 1 and MAP_VERSION == 2
    assert m["source_log"] == str(EXPERIMENT_LOG)
    assert isinstance(m["created_unix_s"], int) and abs(m["created_unix_s"] - time.time()) < 3600
    assert m["rig"] == json.loads(json.dumps(m["rig"])) and "camera" in m["rig"]
    # The replay's final map, with the covariance, bit for bit.
    assert [l["id"] for l in m["landmarks"]] == r.landmarks["id"].tolist() == list(range(LAMPS))
    for entry, row in zip(m["landmarks"], r.landmarks):
        assert set(entry) == {"id", "position", "covariance", "observations"}
        assert entry["position"] == [row["x"], row["y"], row["z"]]
        assert entry["covariance"] == row["covariance"].tolist()
        assert entry["observations"] == int(row["observations"])
    # Every parameter of C (as the replay estimated it) and V.
    parameters = {p["name"]: p for p in m["parameters"]}
    assert set(CAMERA_PARAMETERS) < set(parameters)
    for name, estimate in r.camera.items():
        assert (parameters[name]["value"], parameters[name]["sigma"]) == estimate


def test_an_unwritable_map_names_the_path(tmp_path: pathlib.Path) -> None:
    missing = tmp_path / "no-such-dir" / "x.map"
    with pytest.raises(InputError, match=re.escape(str(missing))) as info:
        replay(EXPERIMENT_LOG, skip_phase1=True, save_map=missing)
    assert isinstance(info.value.__cause__, FileNotFoundError)
    assert "\n" not in str(info.value)
    with pytest.raises(InputTypeError, match="save_map must be a str or os.PathLike"):
        replay(EXPERIMENT_LOG, save_map=3)  # type: ignore[arg-type]


# --- Localising ------------------------------------------------------------------------------


def test_the_log_localises_on_its_map(run: Localization) -> None:
    summary = run.summary
    assert run.localized_t_us and summary["localized_t_us"] == list(run.localized_t_us)
    trajectory = run.trajectory
    assert len(trajectory) == summary["frames"] == summary["frames_processed"] == 961
    localized = trajectory["localized"]
    assert int(np.count_nonzero(localized)) == summary["localized_frames"]
    assert np.count_nonzero(localized) > 0.8 * len(trajectory)
    # Localised from the first fix on, here (nothing moved the vehicle while blind).
    first_fix = run.localized_t_us[0]
    np.testing.assert_array_equal(localized, trajectory["t_us"] >= first_fix)
    assert run.lamps_missing == () and summary["lamps_missing"] == []
    assert len(run.new_lamps) == 0 and run.warnings == () and summary["warnings"] == []
    # The summary's errors against the log's truth: millimetres.
    truth = run.truth
    assert truth is not None and truth == summary["truth"]
    assert truth["localized_frames"] == summary["localized_frames"] and truth["wrong_frames"] == 0
    assert truth["ate_rms_m"] < 0.005 and truth["heading_rms_rad"] < 0.005
    # And the trajectory against the truth poses of the log itself.
    log_truth = stereonav.read_log(EXPERIMENT_LOG).truth
    assert log_truth is not None
    true_poses = {int(p["t_us"]): p for p in log_truth.trajectory}
    errors = [
        float(np.hypot(row["x"] - true_poses[int(row["t_us"])]["x"], row["y"] - true_poses[int(row["t_us"])]["y"]))
        for row in trajectory[localized]
    ]
    assert max(errors) < 0.01, max(errors)
    assert max(errors) == pytest.approx(truth["ate_max_m"], rel=1e-9)
    assert "961 frames" in repr(run) and "1 fixes" in repr(run)


def test_the_trajectory_and_columns(run: Localization) -> None:
    trajectory = run.trajectory
    assert trajectory.dtype == LOCALIZED_TRAJECTORY_DTYPE
    assert trajectory.dtype == np.dtype(
        [("t_us", "<u8"), ("x", "<f8"), ("y", "<f8"), ("theta", "<f8"), ("localized", "?")]
    )
    assert np.all(np.diff(trajectory["t_us"].astype(np.int64)) > 0)
    # A pose wherever the localiser stands behind it; NaN (x, y, theta and the sigmas
    # together) only where it has no guess.
    localized = trajectory["localized"]
    poses = np.column_stack([trajectory["x"], trajectory["y"], trajectory["theta"]])
    assert np.all(np.isfinite(poses[localized]))
    no_guess = np.isnan(poses[:, 0])
    np.testing.assert_array_equal(np.isnan(poses), np.repeat(no_guess[:, None], 3, axis=1))
    np.testing.assert_array_equal(np.isnan(run.pose_sigma).all(axis=1), no_guess)
    assert run.pose_sigma.shape == (len(trajectory), 3) and run.pose_sigma.dtype == np.float64
    assert np.all(run.pose_sigma[localized] > 0) and np.all(run.pose_sigma[localized] < 0.05)
    assert run.matched.dtype == run.hypotheses.dtype == np.uint32
    assert run.matched.shape == run.hypotheses.shape == (len(trajectory),)
    # Lamps associated at every localised frame but the fix itself (found by the
    # relocalisation, not yet by the filter's association).
    assert np.count_nonzero(run.matched[localized] == 0) <= len(run.localized_t_us)
    assert run.matched.max() <= LAMPS
    assert run.new_lamps.dtype == NEW_LAMP_DTYPE
    # The last row is the summary's pose.
    last = trajectory[-1]
    assert run.summary["pose"] == {
        "t_us": int(last["t_us"]), "x": last["x"], "y": last["y"], "theta": last["theta"],
        "localized": bool(last["localized"]),
    }
    # Read-only results.
    with pytest.raises(ValueError):
        trajectory["x"][0] = 1.0
    with pytest.raises(ValueError):
        run.pose_sigma[0, 0] = 1.0


def test_the_summary_has_the_keys_of_section_5(run: Localization, saved_map: pathlib.Path) -> None:
    summary = run.summary
    assert SECTION_5_KEYS <= set(summary)
    for key in ("frames", "corrupt", "lost"):
        assert type(summary[key]) is int, key
    assert summary["corrupt"] == summary["lost"] == 0 and summary["phase_switch_t_us"] is None
    assert all(type(t) is int for t in summary["localized_t_us"])
    assert set(summary["pose"]) == {"t_us", "x", "y", "theta", "localized"}
    m = read_map(saved_map)
    values = {p["name"]: p for p in m["parameters"]}
    assert set(summary["camera"]) == set(CAMERA_PARAMETERS)
    assert set(summary["camera"]) | set(summary["vehicle"]) == set(values)
    for name, estimate in summary["camera"].items():
        # C is the map's.
        assert estimate == {"value": values[name]["value"], "sigma": values[name]["sigma"]}
    for estimate in summary["vehicle"].values():
        assert set(estimate) == {"value", "sigma"}
    # The map's landmarks, with the associations of this run as observations.
    assert [l["id"] for l in summary["landmarks"]] == [l["id"] for l in m["landmarks"]]
    for row, entry in zip(summary["landmarks"], m["landmarks"]):
        assert set(row) == {"id", "x", "y", "z", "sigma", "observations"}
        assert [row["x"], row["y"], row["z"]] == entry["position"]
        assert row["sigma"] == [float(np.sqrt(entry["covariance"][i][i])) for i in range(3)]
        assert type(row["observations"]) is int and row["observations"] > 0
    # A new dict at each access.
    summary["frames"] = -1
    assert run.summary["frames"] == 961


def test_the_python_summary_and_trajectory_equal_the_command_lines(
    cli: pathlib.Path, run: Localization, saved_map: pathlib.Path, tmp_path: pathlib.Path
) -> None:
    summary, trajectory = tmp_path / "SUMMARY.json", tmp_path / "TRAJ.csv"
    done = subprocess.run(
        [str(cli), "localize", str(EXPERIMENT_LOG), "--map", str(saved_map),
         "--summary", str(summary), "--trajectory", str(trajectory)],
        capture_output=True, text=True, timeout=120, check=False,
    )
    assert done.returncode == 0, done.stderr
    # No key of the summary depends on the machine or the time: all are equal.
    assert json.loads(summary.read_text()) == run.summary
    run.write_summary(tmp_path / "py-SUMMARY.json")
    run.write_trajectory(str(tmp_path / "py-TRAJ.csv"))
    assert (tmp_path / "py-SUMMARY.json").read_bytes() == summary.read_bytes()
    assert (tmp_path / "py-TRAJ.csv").read_bytes() == trajectory.read_bytes()
    rows = trajectory.read_text().splitlines()
    assert rows[0] == "t_us,x,y,theta,localized" and len(rows) == 1 + len(run.trajectory)


def test_the_rig_given_or_the_maps_give_the_same_run(run: Localization, saved_map: pathlib.Path) -> None:
    given = localize(EXPERIMENT_LOG, saved_map, EXPERIMENT_RIG)
    assert given.summary == run.summary
    assert given.trajectory.tobytes() == run.trajectory.tobytes()  # NaN rows too
    config = localize(EXPERIMENT_LOG, saved_map, stereonav.load_rig(EXPERIMENT_RIG))
    assert config.summary == run.summary


def test_a_lamp_the_map_has_and_the_hall_does_not_is_missing(
    saved_map: pathlib.Path, tmp_path: pathlib.Path
) -> None:
    """A lamp added by hand to the map, 0.5 m from the most seen one: in view as often, never
    seen, so missing; the run localises as before on the real five."""
    m = read_map(saved_map)
    fake = copy.deepcopy(max(m["landmarks"], key=lambda l: l["observations"]))
    fake["id"] = 99
    fake["position"][0] += 0.4
    fake["position"][1] += 0.3
    m["landmarks"].append(fake)
    edited = tmp_path / "edited.map"
    write_map(m, edited)
    r = localize(EXPERIMENT_LOG, edited)
    assert r.lamps_missing == (99,) and r.summary["lamps_missing"] == [99]
    assert len(r.localized_t_us) == 1 and r.truth is not None and r.truth["wrong_frames"] == 0


def test_save_map_writes_the_map_with_the_runs_new_lamps(
    run: Localization, saved_map: pathlib.Path, tmp_path: pathlib.Path
) -> None:
    new = tmp_path / "new.map"
    again = localize(EXPERIMENT_LOG, saved_map, save_map=new)
    assert again.summary == run.summary
    old, updated = read_map(saved_map), read_map(new)
    # No new lamp on this drive: the same landmarks, made from this log.
    assert updated["landmarks"] == old["landmarks"] and updated["rig"] == old["rig"]
    assert updated["source_log"] == str(EXPERIMENT_LOG)
    camera = {p["name"]: p for p in old["parameters"] if p["name"] in CAMERA_PARAMETERS}
    assert {p["name"]: p for p in updated["parameters"] if p["name"] in CAMERA_PARAMETERS} == camera


def test_localize_releases_the_gil(saved_map: pathlib.Path) -> None:
    """While a thread is inside ``localize``, this one keeps running Python. With the GIL held
    through the run, this thread would stop for the whole run: one gap between its timestamps
    as long as the call (measured: 0.8 to 0.9 of it for a builtin that holds the GIL); with
    the GIL released, only the wrapper's own Python and the interpreter's 5 ms switch
    interval stop it (measured: 0.2 of a localize call)."""
    spans: list[tuple[float, float]] = []

    def worker() -> None:
        for _ in range(5):
            start = time.perf_counter()
            localize(EXPERIMENT_LOG, saved_map)
            spans.append((start, time.perf_counter()))

    thread = threading.Thread(target=worker)
    ticks = []
    thread.start()
    while thread.is_alive():
        ticks.append(time.perf_counter())
    thread.join()
    assert len(spans) == 5
    longest_stops = []
    for a, b in spans:
        inside = [a] + [t for t in ticks if a < t < b] + [b]
        longest_stops.append(max(y - x for x, y in zip(inside, inside[1:])) / (b - a))
    assert sorted(longest_stops)[2] < 0.5, longest_stops


# --- Map files in Python ---------------------------------------------------------------------


def test_a_map_reads_and_writes_back_byte_for_byte(saved_map: pathlib.Path, tmp_path: pathlib.Path) -> None:
    m = read_map(saved_map)
    copy_path = tmp_path / "copy.map"
    write_map(m, copy_path)
    assert copy_path.read_bytes() == saved_map.read_bytes()
    assert read_map(str(copy_path)) == m
    # Floats bit for bit: not one ULP lost on the way.
    positions = np.array([l["position"] for l in m["landmarks"]])
    np.testing.assert_array_equal(
        np.array([l["position"] for l in read_map(copy_path)["landmarks"]]).view(np.uint64),
        positions.view(np.uint64),
    )
    # NumPy arrays and scalars, tuples: the same file.
    arrays = copy.deepcopy(m)
    for landmark in arrays["landmarks"]:
        landmark["position"] = np.array(landmark["position"])
        landmark["covariance"] = np.array(landmark["covariance"])
        landmark["id"] = np.uint64(landmark["id"])
    arrays["parameters"] = tuple(
        {**p, "value": np.float64(p["value"])} for p in arrays["parameters"]
    )
    write_map(arrays, tmp_path / "arrays.map")
    assert (tmp_path / "arrays.map").read_bytes() == saved_map.read_bytes()
    # An edited map is written with a new header (length, CRC) and reads back as edited.
    m["landmarks"][1]["position"][2] = 1.0 / 3.0
    write_map(m, tmp_path / "edited.map")
    assert read_map(tmp_path / "edited.map") == m


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda m: m.pop("landmarks"), "map: missing key 'landmarks'"),
        (lambda m: m["landmarks"][0].pop("covariance"), "map: landmarks[0]: missing key 'covariance'"),
        (lambda m: m["landmarks"][2].update(id="two"), "map: landmarks[2]: 'id' is not a non-negative integer"),
        (lambda m: m["landmarks"][1].update(id=-1), "map: landmarks[1]: 'id' is not a non-negative integer"),
        (lambda m: m.update(landmarks={}), "map: 'landmarks' is not an array"),
        (lambda m: m["landmarks"][0].update(position=[1.0, 2.0]), "landmarks[0]: 'position' must hold 3 numbers"),
        (lambda m: m["landmarks"][0]["position"].__setitem__(1, "x"), "map: landmarks[0]: 'position' is not a finite number"),
        (lambda m: m["landmarks"][0]["position"].__setitem__(1, float("nan")), "map: landmarks[0].position[1] is nan, not a finite number"),
        (lambda m: m["parameters"][0].update(name="focal"), "map: parameters[0]: unknown parameter \"focal\""),
        (lambda m: m.update(source_log=3), "map: 'source_log' is not a string"),
        (lambda m: m.update(format="other"), "map: 'format' is not \"stereonav-map\""),
        (lambda m: m.pop("version"), "map: missing key 'version'"),
        (lambda m: m.update(version=2), "map: 'version' is 2, this stereonav writes a map with a rig as map format version 1"),
        (lambda m: m.pop("rig"), "map: missing key 'rig'"),
        (lambda m: m.update(notes="x"), "map: unknown key 'notes': the map format has no such key"),
        (lambda m: m["landmarks"][3].update(colour="red"), "map: landmarks[3]: unknown key 'colour'"),
        (lambda m: m["rig"].pop("camera"), "map: the map's rig: map rig: "),
        (lambda m: m["landmarks"][0].update(id={1, 2}), "map: landmarks[0].id is of type set, not a JSON value"),
        (lambda m: m.update({3: "x"}), "map: the map has a key 3 that is not a str"),
    ],
)
def test_write_map_refuses_a_bad_dict_naming_the_key(
    saved_map: pathlib.Path, tmp_path: pathlib.Path, edit: Any, message: str
) -> None:
    m = read_map(saved_map)
    edit(m)
    out = tmp_path / "bad.map"
    with pytest.raises(InputError, match=re.escape(message)) as info:
        write_map(m, out)
    assert isinstance(info.value, ValueError) and "\n" not in str(info.value)
    assert not out.exists()


def test_write_map_refuses_what_is_not_a_map(saved_map: pathlib.Path, tmp_path: pathlib.Path) -> None:
    with pytest.raises(InputTypeError, match="map_dict must be a dict"):
        write_map([1, 2], tmp_path / "x.map")  # type: ignore[arg-type]
    with pytest.raises(InputTypeError, match="path must be a str or os.PathLike"):
        write_map(read_map(saved_map), 3)  # type: ignore[arg-type]
    with pytest.raises(InputError, match=re.escape(str(tmp_path / "no-such-dir"))) as info:
        write_map(read_map(saved_map), tmp_path / "no-such-dir" / "x.map")
    assert isinstance(info.value.__cause__, FileNotFoundError)


# --- Bad maps, logs and arguments ------------------------------------------------------------


def bad_maps(saved_map: pathlib.Path, directory: pathlib.Path) -> list[tuple[pathlib.Path, str]]:
    """Map files that must be refused, each with the start of its reason."""
    data = saved_map.read_bytes()
    header, body = data.split(b"\n", 1)
    damaged = bytearray(data)
    damaged[len(header) + 1 + len(body) // 2] ^= 0x01
    m = json.loads(body)
    del m["landmarks"]
    no_lamps = json.loads(body)
    no_lamps["landmarks"] = []
    files = {
        "damaged.map": (bytes(damaged), "the map is damaged (CRC-32"),
        "cut.map": (data[: len(data) // 2], "the file is cut or damaged"),
        "foreign.map": (EXPERIMENT_LOG.read_bytes(), "not a stereonav map (no 'stereonav-map' header line)"),
        "empty.map": (b"", "not a stereonav map"),
        "newer.map": (b"stereonav-map 3" + data[len(b"stereonav-map 1"):], "map format version 3 is newer than this stereonav reads (up to 2)"),
        "no-landmarks.map": (map_file(m), "missing key 'landmarks'"),
        "no-lamps.map": (map_file(no_lamps), "localiser: "),
    }
    out = []
    for name, (content, reason) in files.items():
        path = directory / name
        path.write_bytes(content)
        out.append((path, reason))
    return out


def test_bad_maps_are_refused_with_one_line(saved_map: pathlib.Path, tmp_path: pathlib.Path) -> None:
    for path, reason in bad_maps(saved_map, tmp_path):
        with pytest.raises(InputError, match=re.escape(reason)) as info:
            localize(EXPERIMENT_LOG, path)
        message = str(info.value)
        assert "\n" not in message and isinstance(info.value, ValueError), message
        if path.name == "no-lamps.map":  # a good file, a map that cannot localise
            assert read_map(path)["landmarks"] == []
            continue
        assert path.name in message, message
        with pytest.raises(InputError, match=re.escape(reason)):
            read_map(path)


def test_missing_files_name_the_path(saved_map: pathlib.Path, tmp_path: pathlib.Path) -> None:
    missing = tmp_path / "no-such.map"
    for call in (lambda: localize(EXPERIMENT_LOG, missing), lambda: read_map(missing)):
        with pytest.raises(InputError, match=re.escape(str(missing))) as info:
            call()
        assert isinstance(info.value.__cause__, FileNotFoundError)
    log = tmp_path / "no-such.mcap"
    with pytest.raises(InputError, match=re.escape(str(log))) as info:
        localize(log, saved_map)
    assert isinstance(info.value.__cause__, FileNotFoundError)


def test_bad_logs_and_rigs_are_named(saved_map: pathlib.Path, tmp_path: pathlib.Path) -> None:
    with pytest.raises(InputError, match=re.escape(f"{EXPERIMENT_RIG} is not an MCAP file")):
        localize(EXPERIMENT_RIG, saved_map)
    with pytest.raises(InputError, match="no-such.rig.toml"):
        localize(EXPERIMENT_LOG, saved_map, tmp_path / "no-such.rig.toml")
    # A log cut short is run as far as it goes, with a warning.
    data = EXPERIMENT_LOG.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    r = localize(cut, saved_map)
    assert any("ends early" in w for w in r.warnings), r.warnings
    assert 0 < len(r.trajectory) < 961 and r.summary["warnings"] == list(r.warnings)


def test_bad_arguments_are_type_errors(saved_map: pathlib.Path) -> None:
    with pytest.raises(InputTypeError, match="log_path must be"):
        localize(42, saved_map)  # type: ignore[arg-type]
    with pytest.raises(InputTypeError, match="map_path must be"):
        localize(EXPERIMENT_LOG, None)  # type: ignore[arg-type]
    with pytest.raises(InputTypeError, match="rig_path must be a stereonav.RigConfig"):
        localize(EXPERIMENT_LOG, saved_map, 3.0)  # type: ignore[arg-type]
    with pytest.raises(InputTypeError, match="save_map must be"):
        localize(EXPERIMENT_LOG, saved_map, save_map=b"x.map")  # type: ignore[arg-type]
    with pytest.raises(InputTypeError, match="path must be"):
        read_map(3)  # type: ignore[arg-type]
    with pytest.raises(TypeError):
        localize(EXPERIMENT_LOG, saved_map, None, "x.map")  # type: ignore[call-arg]
    for exception in (InputError, InputTypeError):
        assert issubclass(exception, stereonav.Error)
