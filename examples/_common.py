"""What the figure scripts of ``examples/`` share: paths, the command line, saving a PNG,
3-sigma bands, and the simulator's lamp labels for the board's features.

Not an example itself (the leading underscore keeps it out of the test that runs them).
Importing it selects matplotlib's Agg backend, so that every script runs headless.
"""

from __future__ import annotations

import argparse
import io
import pathlib
from typing import Optional

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402  (after the backend is chosen)
import numpy as np  # noqa: E402
import numpy.typing as npt  # noqa: E402
import PIL.Image  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

import stereonav  # noqa: E402

#: The repository's root.
ROOT = pathlib.Path(__file__).resolve().parents[1]
#: The simulator's scenarios.
SCENARIOS = ROOT / "fixtures" / "scenarios"
#: The committed vehicle logs (each the simulation of its scenario at the scenario's seed).
LOGS = ROOT / "fixtures" / "logs"
#: Where the figures go by default (linked from docs/figures.md).
FIGURES = ROOT / "docs" / "figures"
#: Resolution of the PNGs: small enough to commit, sharp enough to read.
DPI = 100
#: How far a board feature may lie from a lamp's true projection to be that lamp, pixels (the
#: simulated pixel noise is 0.3 px, 1 sigma).
MATCH_PX = 2.0
#: One colour per lamp of the paper's five-lamp scenarios, by lamp id.
LAMP_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple")
#: A microsecond in seconds.
US = 1e-6

F64 = npt.NDArray[np.float64]


def output_dir(description: Optional[str]) -> pathlib.Path:
    """Parse ``[--out DIR]`` (default ``docs/figures/``) and return the directory, created."""
    summary = next(iter((description or "").strip().splitlines()), None)
    parser = argparse.ArgumentParser(description=summary)
    parser.add_argument(
        "--out",
        type=pathlib.Path,
        default=FIGURES,
        help=f"directory of the PNG (default: {FIGURES.relative_to(ROOT)})",
    )
    out: pathlib.Path = parser.parse_args().out
    out.mkdir(parents=True, exist_ok=True)
    return out


def save(figure: Figure, out: pathlib.Path, script: str) -> pathlib.Path:
    """Lay ``figure`` out tightly, write it as ``OUT/<script's name>.png``, print its path and
    close it.

    The PNG is reduced to a 256-colour palette without dithering (Pillow, which matplotlib
    depends on): a plot has few colours, and the file comes out about three times smaller
    than matplotlib's RGBA, small enough to commit.
    """
    path = out / (pathlib.Path(script).stem + ".png")
    rendered = io.BytesIO()
    figure.tight_layout()
    figure.savefig(rendered, format="png", dpi=DPI)
    plt.close(figure)
    with PIL.Image.open(rendered) as image:
        palette = image.convert("RGB").quantize(
            colors=256, method=PIL.Image.Quantize.MEDIANCUT, dither=PIL.Image.Dither.NONE
        )
    palette.save(path, optimize=True)
    print(path)
    return path


def band(
    ax: Axes,
    x: npt.ArrayLike,
    value: npt.ArrayLike,
    sigma: npt.ArrayLike,
    *,
    color: str,
    label: Optional[str] = None,
    shaded: bool = True,
) -> None:
    """Plot ``value`` over ``x`` with its 3-sigma band in one colour: shaded, or as two thin
    dashed lines (where several bands overlap)."""
    xs, v, s = np.asarray(x), np.asarray(value), np.asarray(sigma)
    if shaded:
        ax.fill_between(xs, v - 3 * s, v + 3 * s, color=color, alpha=0.2, linewidth=0)
    else:
        for edge in (v - 3 * s, v + 3 * s):
            ax.plot(xs, edge, color=color, linewidth=0.6, linestyle="--")
    ax.plot(xs, v, color=color, linewidth=1.2, label=label)


def error_axes(ax: Axes, ylabel: str, linthresh: float) -> None:
    """Axes of an error over time: a dashed zero line (the truth) and a symmetric log scale,
    linear within ``linthresh`` of zero, so that the start (far off) and the converged part
    (within the band) both show."""
    ax.axhline(0.0, color="black", linestyle="--", linewidth=1.0)
    ax.set_yscale("symlog", linthresh=linthresh)
    ax.set_xlabel("time (s)")
    ax.set_ylabel(f"{ylabel}, symlog")
    ax.grid(alpha=0.3)


def lamp_measurements(sim: stereonav.Simulation) -> npt.NDArray[np.void]:
    """The board's features of ``sim`` labelled with the lamp they show (MEASUREMENT_DTYPE).

    The stream is decoded as the vehicle receives it; a left and a right feature are lamp
    ``i`` when each is the nearest feature of its image, within :data:`MATCH_PX`, to lamp
    ``i``'s true projection. The estimators never need these labels (the navigator associates
    by itself); the figures use them to judge the filter apart from association, as the eval
    crate does. Clutter is left out this way.
    """
    decoder = stereonav.StreamDecoder()
    frames = decoder.push(sim.stream) + decoder.finish()
    poses = {int(row["t_us"]): (row["x"], row["y"], row["theta"]) for row in sim.trajectory}
    chunks = []
    for frame in frames:
        if frame.t_us not in poses or not len(frame.left) or not len(frame.right):
            continue
        z = stereonav.project(sim.landmarks, pose=poses[frame.t_us], camera=sim.camera).z
        lamps = np.flatnonzero(np.isfinite(z[:, 0]))
        nearest = []
        for features, columns in ((frame.left, (0, 1)), (frame.right, (2, 3))):
            uv = np.column_stack([features["x_q4"], features["y_q4"]]) / 16.0
            distance = np.hypot(
                uv[None, :, 0] - z[lamps, None, columns[0]],
                uv[None, :, 1] - z[lamps, None, columns[1]],
            )
            best = distance.argmin(axis=1)
            nearest.append((uv[best], distance[np.arange(len(lamps)), best] <= MATCH_PX))
        (left, left_ok), (right, right_ok) = nearest
        keep = left_ok & right_ok
        chunk = np.zeros(int(keep.sum()), dtype=stereonav.MEASUREMENT_DTYPE)
        chunk["t_us"], chunk["id"] = frame.t_us, lamps[keep]
        chunk["uL"], chunk["vL"] = left[keep, 0], left[keep, 1]
        chunk["uR"], chunk["vR"] = right[keep, 0], right[keep, 1]
        chunks.append(chunk)
    return np.concatenate(chunks)


def pixels(rows: npt.NDArray[np.void]) -> F64:
    """The ``(M, 4)`` pixels ``uL, vL, uR, vR`` of MEASUREMENT_DTYPE rows."""
    return np.column_stack([rows[name] for name in ("uL", "vL", "uR", "vR")]).astype(np.float64)
