"""Monte Carlo consistency of phase 2: NEES and NIS against their chi-square bands.

:func:`stereonav.monte_carlo` runs phase 2 (EKF SLAM with the baseline in the state, from the
rig's priors) on ``RUNS`` seeded simulations of ``fixtures/scenarios/paper-experiment.toml``,
the paper's experiment, with the simulator's lamp ids as track ids (perfect association, so
that the filter is what is judged). For a consistent filter (Bar-Shalom, Li and Kirubarajan,
section 5.4), with ``R`` runs:

- the pose NEES averaged over the runs at a frame is chi-square with ``3 R`` dof over ``R``:
  plotted at every frame with its two-sided 95 % band;
- the full-state NEES (pose, mapped lamps, baseline) summed over the runs at a frame is
  chi-square with the summed dof: plotted per degree of freedom with its 95 % band (which
  narrows as the lamps enter the map);
- each run's mean NIS over its accepted observations (4 dof each) with its 95 % band, and the
  mean over every run with the summary's band;
- each run's final baseline error in units of its sigma, against +-3.

The bands whose dof change (state NEES per frame, NIS per run) use the Wilson-Hilferty
approximation of the chi-square quantiles, exact to about 1e-3 at these dof; the others are
the summary's own.

    python examples/mc_consistency.py [--out DIR]
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import numpy.typing as npt
from matplotlib.axes import Axes

import stereonav
from _common import F64, SCENARIOS, US, output_dir, save

SCENARIO = SCENARIOS / "paper-experiment.toml"
#: Seeded runs (seeds 0 to RUNS - 1): about a second of computing.
RUNS = 50
#: The standard normal's 97.5 % quantile: the two-sided 95 % band.
Z_975 = 1.959963984540054


def chi2_band(dof: npt.ArrayLike) -> tuple[F64, F64]:
    """The 2.5 % and 97.5 % quantiles of chi-square with ``dof`` degrees of freedom
    (Wilson-Hilferty: ``(chi2 / k) ** (1/3)`` is nearly normal)."""
    k = np.asarray(dof, dtype=np.float64)
    centre, spread = 1.0 - 2.0 / (9.0 * k), Z_975 * np.sqrt(2.0 / (9.0 * k))
    return k * (centre - spread) ** 3, k * (centre + spread) ** 3


def nees_panel(
    ax: Axes,
    t: F64,
    value: F64,
    limits: tuple[npt.ArrayLike, npt.ArrayLike],
    expectation: float,
    name: str,
    overall: stereonav.Banded,
    inside: float,
    label: str,
) -> None:
    """A NEES statistic at every frame with its 95 % band (``limits``: low and high, each a
    number or one per frame), its expectation, and the summary over all frames in the title."""
    ax.fill_between(t, limits[0], limits[1], color="tab:green", alpha=0.2, linewidth=0, label="95 % band")
    ax.plot(t, value, color="tab:blue", linewidth=0.8, label=label)
    ax.axhline(expectation, color="black", linestyle="--", linewidth=1.0, label=f"{expectation:g} (its expectation)")
    ax.set_title(
        f"{name} over all frames (band {overall.low:.3g}-{overall.high:.3g}),\n"
        f"{100 * inside:.0f} % of frames inside",
        fontsize=10,
    )
    ax.set_xlabel("time (s)")
    ax.set_ylabel(name.split(":")[0])
    ax.legend(fontsize=8, loc="upper right")


def main() -> None:
    out = output_dir(__doc__)
    mc = stereonav.monte_carlo(SCENARIO, RUNS)
    runs = mc.runs
    frames = runs.pose_nees.shape[1]
    # Every seed drives the same path at the same instants: the times of seed 0's frames.
    t_us = stereonav.simulate(SCENARIO, seed=0).trajectory["t_us"].astype(np.float64)
    t = (t_us[1 : frames + 1] - t_us[0]) * US

    figure, axes = plt.subplots(2, 2, figsize=(11, 8.5))
    pose, state = axes[0]
    nis, baseline = axes[1]

    nees_panel(
        pose, t, np.nanmean(runs.pose_nees, axis=0), (mc.pose_nees.low, mc.pose_nees.high), 3.0,
        f"pose NEES (3 dof): {mc.pose_nees.value:.2f}", mc.pose_nees, mc.pose_nees_frames_inside,
        f"average over {RUNS} runs",
    )
    dof = runs.state_nees_dof.astype(np.float64).sum(axis=0)
    low, high = chi2_band(dof)
    nees_panel(
        state, t, np.nansum(runs.state_nees, axis=0) / dof, (low / dof, high / dof), 1.0,
        f"full-state NEES per dof: {mc.state_nees_per_dof.value:.3f}", mc.state_nees_per_dof,
        mc.state_nees_frames_inside, f"sum over {RUNS} runs / its dof",
    )

    seeds = runs.seed.astype(np.float64)
    low, high = chi2_band(4.0 * runs.accepted)
    accepted = runs.accepted.astype(np.float64)
    nis.fill_between(seeds, low / accepted, high / accepted, step="mid", color="tab:green", alpha=0.2,
                     linewidth=0, label="95 % band of a run")
    nis.plot(seeds, runs.mean_nis, "o", color="tab:blue", markersize=4, label="mean NIS of a run")
    nis.axhspan(mc.nis.low, mc.nis.high, color="tab:orange", alpha=0.3, label="95 % band of all runs")
    nis.axhline(mc.nis.value, color="tab:orange", linewidth=1.2, label=f"all runs: {mc.nis.value:.3f}")
    nis.axhline(4.0, color="black", linestyle="--", linewidth=1.0)
    nis.set_title(
        f"NIS (4 dof) of the accepted observations ({int(accepted.mean())} per run):\n"
        f"all runs {mc.nis.value:.3f} (band {mc.nis.low:.3f}-{mc.nis.high:.3f})",
        fontsize=10,
    )
    nis.set_xlabel("run (seed)")
    nis.set_ylabel("mean NIS")
    nis.legend(fontsize=8, loc="upper right", ncol=2)

    b = runs.camera_parameters.index("baseline")
    normalised = runs.camera_error[:, b] / runs.camera_sigma[:, b]
    baseline.plot(seeds, normalised, "o", color="tab:blue", markersize=4, label="baseline error / sigma")
    for bound in (-3.0, 3.0):
        baseline.axhline(bound, color="tab:red", linestyle="--", linewidth=1.0)
    baseline.axhline(0.0, color="black", linewidth=0.8)
    baseline.set_title(
        f"final baseline error in sigmas (RMS {np.sqrt(np.mean(normalised**2)):.2f});\n"
        f"{mc.within_3_sigma} of {RUNS} runs with the baseline and every lamp inside 3 sigma",
        fontsize=10,
    )
    baseline.set_xlabel("run (seed)")
    baseline.set_ylabel("error / sigma")
    baseline.legend(fontsize=8, loc="upper right")
    for ax in axes.flat:
        ax.grid(alpha=0.3)
    figure.suptitle(f"Monte Carlo consistency of phase 2, paper-experiment, {RUNS} seeded runs", fontsize=11)
    save(figure, out, __file__)


if __name__ == "__main__":
    main()
