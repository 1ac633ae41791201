"""Fixtures shared by the test modules: the ``stereonav`` command line, for the tests that
compare the Python module with it (``test_rig_import``, ``test_localize``)."""

from __future__ import annotations

import os
import pathlib
import shutil
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[3]


@pytest.fixture(scope="session")
def cli() -> pathlib.Path:
    """The ``stereonav`` binary: ``$STEREONAV_BIN``, or built here (a no-op when it is fresh).

    ``scripts/test.sh`` sets ``$STEREONAV_BIN`` to the binary its test build made (profile
    ``ci``); run by hand, pytest builds the dev profile's (a release build of the binary, the
    viewer's window toolkit with it, would add minutes).
    """
    if "STEREONAV_BIN" in os.environ:
        return pathlib.Path(os.environ["STEREONAV_BIN"])
    cargo = shutil.which("cargo")
    if cargo is None:
        pytest.skip("no cargo to build the stereonav binary (set STEREONAV_BIN)")
    subprocess.run(
        [cargo, "build", "-p", "stereonav-cli", "--locked", "--quiet"],
        cwd=ROOT, check=True, timeout=3000,
    )
    target = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
    return target / "debug" / "stereonav"
