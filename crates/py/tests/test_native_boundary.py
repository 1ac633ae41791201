"""The native boundary: results cross it as frozen, documented objects with named fields, not
positional tuples; keyword defaults come from Rust; rigs cross it as a native object."""

from __future__ import annotations

import ast
import inspect
import pathlib

import numpy as np
import pytest

import stereonav
from stereonav import _native

PACKAGE_DIR = pathlib.Path(stereonav.__file__).parent
ROOT = pathlib.Path(__file__).resolve().parents[3]
RIG = ROOT / "fixtures" / "scenarios" / "paper-experiment.rig.toml"


def _tuple_sizes(node: ast.AST) -> list[int]:
    """The element counts of every ``tuple[...]`` annotation under ``node``."""
    sizes = []
    for sub in ast.walk(node):
        if isinstance(sub, ast.Subscript) and isinstance(sub.value, ast.Name) and sub.value.id == "tuple":
            elements = sub.slice.elts if isinstance(sub.slice, ast.Tuple) else [sub.slice]
            sizes.append(len(elements))
    return sizes


def test_no_result_tuple_of_six_or_more_fields_crosses_into_python() -> None:
    stub = ast.parse((PACKAGE_DIR / "_native.pyi").read_text(encoding="utf-8"))
    assert max(_tuple_sizes(stub)) < 6


def test_native_classes_are_documented_and_frozen() -> None:
    classes = [c for _, c in inspect.getmembers(_native, inspect.isclass)]
    assert len(classes) >= 20
    for cls in classes:
        assert cls.__module__ == "stereonav._native", cls
        assert cls.__doc__, cls
        for name, member in vars(cls).items():
            if not name.startswith("_") and hasattr(member, "__get__") and not callable(member):
                assert member.__doc__, f"{cls.__name__}.{name}"


def test_settings_defaults_come_from_rust() -> None:
    solver = _native.SolverSettings()
    assert inspect.signature(stereonav.calibrate).parameters["huber"].default == solver.huber
    rule = _native.StableRule()
    calibrator = inspect.signature(stereonav.SelfCalibrator).parameters
    assert calibrator["solve_every"].default == rule.solve_every
    assert calibrator["consecutive"].default == rule.consecutive
    pairs = inspect.signature(stereonav.calibrate_log).parameters
    assert pairs["stride"].default == _native.PairSettings().stride
    assert pairs["pairing"].default == _native.PairSettings().pairing
    filter_settings = _native.FilterSettings()
    assert inspect.signature(stereonav.Filter).parameters["nis_window"].default == filter_settings.nis_window
    with pytest.raises(AttributeError):
        solver.huber = 1.0  # type: ignore[misc]
    with pytest.raises(stereonav.InputError, match="huber is -1"):
        _native.SolverSettings(huber=-1.0)


def test_the_rig_crosses_as_a_native_object() -> None:
    native = _native.Rig.load(str(RIG))
    config = stereonav.load_rig(RIG)
    assert native.estimate == list(config.estimate)
    assert native.prior == config.prior
    np.testing.assert_array_equal(native.nominal, config.nominal.to_array())
    with pytest.raises(AttributeError):
        native.width = 3  # type: ignore[misc]
    tables = native.tables()
    tables["estimate"]["parameters"] = ["f"]
    tables["prior"] = {}
    with pytest.raises(stereonav.InputError, match=r"values: \[prior\] f: missing key"):
        _native.Rig.from_tables(tables, "values")
    assert _native.Rig.from_tables(native.tables(), "values") == native


def test_decoded_frames_are_frozen_native_objects() -> None:
    left = np.array([(160, 320, 1 << 20)], dtype=stereonav.FEATURE_DTYPE)
    packet = stereonav.encode_packet(left, left[:0], frame=7, t_us=1000, right_overflow=True)
    (frame,) = stereonav.StreamDecoder().push(packet)
    assert isinstance(frame, _native.Frame) and frame.left.dtype == stereonav.FEATURE_DTYPE
    assert (frame.frame, frame.t_us, frame.left_overflow, frame.right_overflow) == (7, 1000, False, True)
    with pytest.raises(AttributeError):
        frame.t_us = 0  # type: ignore[misc]


def test_localisation_results_are_frozen_native_objects(tmp_path: pathlib.Path) -> None:
    log = ROOT / "fixtures" / "logs" / "paper-experiment.mcap"
    saved = tmp_path / "experiment.map"
    stereonav.replay(log, skip_phase1=True, save_map=saved)
    native = _native.localize(str(log), str(saved), None, None)
    assert isinstance(native, _native.LocalizeResult)
    frames = native.frames
    assert isinstance(frames, _native.LocalizedFrames) and frames.localized.dtype == np.bool_
    assert frames.pose.shape == frames.sigma.shape == (len(frames.t_us), 3)
    with pytest.raises(AttributeError):
        frames.t_us = frames.t_us  # type: ignore[misc]
    with pytest.raises(AttributeError):
        native.warnings = []  # type: ignore[misc]
    assert isinstance(_native.read_map(str(saved)), str) and _native.MAP_VERSION == 2
