"""Every figure script of ``examples/`` runs headless and writes a PNG that is not blank.

Each script (``examples/*.py`` not starting with ``_``) runs in its own interpreter, as a user
would run it, with ``--out`` a temporary directory; it must exit 0, print the path of the PNG
it wrote, ``<script name>.png``, and that PNG must be a real picture: a valid PNG of a
sensible size whose pixels vary (many distinct colours, a clear spread of values).
"""

from __future__ import annotations

import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

#: The scripts need matplotlib (requirements-dev.txt); without it there is nothing to run.
matplotlib_image = pytest.importorskip("matplotlib.image")

ROOT = pathlib.Path(__file__).resolve().parents[3]
EXAMPLES = ROOT / "examples"
SCRIPTS = sorted(p for p in EXAMPLES.glob("*.py") if not p.name.startswith("_"))
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: Each script must finish within the issue's minute (they take a few seconds): a run that
#: takes longer fails with ``subprocess.TimeoutExpired``.
TIMEOUT_S = 60.0
#: A figure of several panels at 100 dpi: at least this wide and high, pixels.
MIN_SIDE_PX = 400
#: Committable: each PNG below this size.
MAX_BYTES = 300_000
#: A plot with axes, text, lines and bands has many colours; a blank or one-colour image not.
MIN_COLOURS = 16
#: Standard deviation of the grey levels (0 to 1): a white page with a few marks is below.
MIN_STD = 0.05


def test_there_are_figure_scripts() -> None:
    names = {p.stem for p in SCRIPTS}
    assert {
        "fig4_phase1_convergence",
        "fig5_square_path",
        "fig8_landmarks_frames",
        "fig9_experiment",
        "mc_consistency",
    } <= names, names


@pytest.mark.parametrize("script", SCRIPTS, ids=[p.stem for p in SCRIPTS])
def test_the_script_writes_a_png_that_is_not_blank(script: pathlib.Path, tmp_path: pathlib.Path) -> None:
    environment = dict(os.environ, MPLBACKEND="Agg")
    result = subprocess.run(
        [sys.executable, "-W", "error", str(script), "--out", str(tmp_path)],
        cwd=tmp_path,  # the scripts find the fixtures from their own location
        env=environment,
        capture_output=True,
        text=True,
        timeout=TIMEOUT_S,
        check=False,
    )
    assert result.returncode == 0, f"{script.name} failed:\n{result.stderr}"
    png = tmp_path / f"{script.stem}.png"
    assert str(png) in result.stdout.splitlines(), result.stdout
    assert png.is_file()
    data = png.read_bytes()
    assert data.startswith(PNG_SIGNATURE)
    assert 10_000 < len(data) < MAX_BYTES, len(data)
    pixels = matplotlib_image.imread(png)
    assert pixels.ndim == 3 and pixels.shape[2] in (3, 4), pixels.shape
    height, width = pixels.shape[:2]
    assert min(height, width) >= MIN_SIDE_PX, pixels.shape
    rgb = pixels[:, :, :3]
    assert float(rgb.mean(axis=2).std()) > MIN_STD
    # Each colour as one integer, 0xRRGGBB, to count them.
    levels = np.round(rgb * 255).astype(np.uint32)
    codes = (levels[:, :, 0] << 16) | (levels[:, :, 1] << 8) | levels[:, :, 2]
    _, counts = np.unique(codes, return_counts=True)
    assert len(counts) >= MIN_COLOURS, len(counts)
    # Not one colour over most of the picture: the most common one covers less than 95 %.
    assert counts.max() < 0.95 * height * width
