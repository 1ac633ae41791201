"""Maps from lighting plans in Python: ``stereonav.import_map`` makes the map that ``stereonav
map import`` makes (the same body, read by the same Rust code), ``stereonav.localize`` runs a
simulated hall's drive on the map of its lighting plan with the vehicle's rig (and refuses it,
in one line, without), and every kind of bad plan raises ``stereonav.InputError`` with the
command line's one-line message naming the line."""

from __future__ import annotations

import pathlib
import re
import subprocess
from typing import Any

import numpy as np
import pytest

import stereonav
from stereonav import (
    DEFAULT_LAMP_SIGMA_M,
    MAP_VERSION,
    InputError,
    InputTypeError,
    import_map,
    localize,
    read_map,
    write_map,
)

ROOT = pathlib.Path(__file__).resolve().parents[3]
SCENARIOS = ROOT / "fixtures" / "scenarios"
#: The lamps of hall-localize's hall when its plan was drawn (ids 70..72 were fitted later).
PLANNED = 70


@pytest.fixture(scope="module")
def hall(tmp_path_factory: pytest.TempPathFactory) -> tuple[pathlib.Path, pathlib.Path]:
    """The hall-localize drive's log, and its hall's lighting plan: the true lamps (the dark
    ones too) with a survey's 1 cm of noise, in the hall's frame (the truth's)."""
    directory = tmp_path_factory.mktemp("plan")
    sim = stereonav.simulate(SCENARIOS / "hall-localize.toml")
    log = directory / "hall.mcap"
    sim.write_log(log)
    rng = np.random.default_rng(37)
    lamps = sim.landmarks[:PLANNED] + rng.normal(0.0, 0.01, (PLANNED, 3))
    rows = "".join(f"{float(x)!r}, {float(y)!r}, {float(z)!r}, {i}\n" for i, (x, y, z) in enumerate(lamps))
    plan = directory / "hall.csv"
    plan.write_text("# hall-localize's hall, surveyed\nX, Y, Z, id\n" + rows)
    return log, plan


def test_import_map_makes_the_map_the_command_line_makes(
    hall: tuple[pathlib.Path, pathlib.Path], cli: pathlib.Path, tmp_path: pathlib.Path
) -> None:
    _, plan = hall
    ours, theirs = tmp_path / "py.map", tmp_path / "cli.map"
    body = import_map(plan, ours, sigma=0.01)
    done = subprocess.run(
        [cli, "map", "import", plan, "--out", theirs, "--sigma", "0.01"],
        capture_output=True, text=True, check=False,
    )
    assert done.returncode == 0 and done.stderr == "", done.stderr
    assert done.stdout.startswith(f"{theirs}: {PLANNED} lamps from the lighting plan {plan}")
    assert body == read_map(ours)
    cli_body = read_map(theirs)
    assert {**body, "created_unix_s": 0} == {**cli_body, "created_unix_s": 0}
    assert body["version"] == MAP_VERSION == 2 and ours.read_bytes().startswith(b"stereonav-map 2 ")
    assert body["source_plan"] == str(plan) and body["source_log"] == ""
    assert "rig" not in body and body["parameters"] == []
    assert [l["id"] for l in body["landmarks"]] == list(range(PLANNED))
    assert all(l["covariance"] == [[1e-4, 0.0, 0.0], [0.0, 1e-4, 0.0], [0.0, 0.0, 1e-4]] for l in body["landmarks"])
    # A map without a rig reads and writes back byte for byte, as every map does.
    copy = tmp_path / "copy.map"
    write_map(body, copy)
    assert copy.read_bytes() == ours.read_bytes()
    # Without out_path nothing is written; the default sigma is 2 cm.
    assert DEFAULT_LAMP_SIGMA_M == 0.02
    body = import_map(str(plan))
    assert body["landmarks"][0]["covariance"][1][1] == 0.02**2


def test_a_drive_localises_on_its_halls_lighting_plan(
    hall: tuple[pathlib.Path, pathlib.Path], tmp_path: pathlib.Path
) -> None:
    log, plan = hall
    map_path = tmp_path / "hall.map"
    import_map(plan, map_path, 0.01)
    with pytest.raises(InputError, match=re.escape("the map has no rig (it was imported from the lighting plan")) as info:
        localize(log, map_path)
    assert "--rig RIG.toml" in str(info.value) and "\n" not in str(info.value)
    rig = SCENARIOS / "hall-map.rig.toml"
    run = localize(log, map_path, rig)
    truth = run.truth
    assert truth is not None and truth["wrong_frames"] == 0, truth
    assert truth["ate_max_m"] <= 0.25, truth
    assert run.localized_t_us and (run.localized_t_us[0] - run.trajectory["t_us"][0]) <= 3_000_000
    # The plan's dark lamps (on this drive) are reported missing by their plan ids.
    assert set(run.lamps_missing) <= {13, 24, 25, 37, 43, 46, 56} and len(run.lamps_missing) >= 5
    # With the rig carried in the map (version 1), no rig is needed.
    carried = tmp_path / "carried.map"
    body = import_map(plan, carried, 0.01, rig_path=rig)
    assert body["version"] == 1 and "rig" in body
    assert localize(log, carried).summary == run.summary


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("x,y\n1,2\n", "plan.csv:1: the header has no 'z' column (it needs x, y, z; optional: id, sigma)"),
        ("x,y,z,lux\n1,2,3,400\n", "plan.csv:1: unknown column 'lux'"),
        ("x,y,z\n1,2,3\n1,2,three\n", "plan.csv:3: z 'three' is not a number"),
        ("x,y,z\n1,nan,3\n", "plan.csv:2: y is nan, not a finite number"),
        ("x,y,z\n1,2,-inf\n", "plan.csv:2: z is -inf, not a finite number"),
        ("x,y,z,sigma\n1,2,3,0\n", "plan.csv:2: sigma 0 is not positive"),
        ("x,y,z,sigma\n# c\n1,2,3,-0.1\n", "plan.csv:3: sigma -0.1 is not positive"),
        ("id,x,y,z\n4,1,2,3\n4,5,2,3\n", "plan.csv:3: id 4 is given twice (first on line 2)"),
        ("id,x,y,z\n-4,1,2,3\n", "plan.csv:2: id '-4' is not a non-negative integer"),
        ("", "plan.csv:1: no header line"),
        ("x,y,z\n", "plan.csv:1: no lamps: no row follows the header"),
        ("x,y,z\n1,2,3\n1,2,3,4\n", "plan.csv:3: 4 fields, the header names 3 columns"),
    ],
)
def test_bad_plans_raise_one_line_naming_the_line(tmp_path: pathlib.Path, text: str, message: str) -> None:
    plan = tmp_path / "plan.csv"
    plan.write_text(text)
    out = tmp_path / "never.map"
    with pytest.raises(InputError, match=re.escape(message)) as info:
        import_map(plan, out)
    assert isinstance(info.value, ValueError) and "\n" not in str(info.value)
    assert str(info.value).startswith(str(plan))
    assert not out.exists()


def test_import_map_checks_its_arguments(tmp_path: pathlib.Path) -> None:
    plan = tmp_path / "plan.csv"
    plan.write_text("x,y,z\n1,2,3\n")
    cases: list[tuple[Any, type[Exception], str]] = [
        (lambda: import_map(plan, sigma=0.0), InputError, "the default lamp sigma 0 m is not a positive, finite number"),
        (lambda: import_map(plan, sigma=float("nan")), InputError, "the default lamp sigma NaN m"),
        (lambda: import_map(plan, sigma="0.1"), InputTypeError, "sigma must be a float (metres), got str"),
        (lambda: import_map(plan, sigma=True), InputTypeError, "sigma must be a float"),
        (lambda: import_map(3), InputTypeError, "csv_path must be a str or os.PathLike"),
        (lambda: import_map(plan, rig_path=3), InputTypeError, "rig_path must be a stereonav.RigConfig"),
    ]
    for call, kind, message in cases:
        with pytest.raises(kind, match=re.escape(message)):
            call()
    assert import_map(plan, sigma=np.float32(0.5))["landmarks"][0]["covariance"][0][0] == 0.25
    missing = tmp_path / "no-such.csv"
    with pytest.raises(InputError, match=re.escape(str(missing))) as info:
        import_map(missing)
    assert isinstance(info.value.__cause__, FileNotFoundError)
    unwritable = tmp_path / "no-such-dir" / "x.map"
    with pytest.raises(InputError, match=re.escape(str(unwritable))) as info:
        import_map(plan, unwritable)
    assert isinstance(info.value.__cause__, FileNotFoundError)
