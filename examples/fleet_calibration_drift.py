"""A small fleet's calibration over the days, from its logs replayed on Dask.

Three forklifts of the same type work a shift a day for five days; each shift's log is a
simulation of ``fixtures/scenarios/paper-square-realistic.toml`` (the paper's 2 m square,
realistic odometry, f and baseline self-calibrated from the rig's priors) with its own noise.
Forklift ``FL-03``'s camera head drifts: its baseline shrinks by 0.4 mm a day and its focal
length grows by 1.5 px a day (a mount working loose in a warm hall), while the rig file every
log carries stays the nominal one. :func:`stereonav.fleet.replay_logs` replays the fifteen logs
on a two-worker local cluster and returns a table, a row per log; the figure plots each
forklift's estimated baseline and f over the days with their 3-sigma bands, and the truth of
the drifting one.

Needs the ``fleet`` extra (``pip install "./crates/py[fleet]"``).

    python examples/fleet_calibration_drift.py [--out DIR]
"""

from __future__ import annotations

import pathlib
import re
import tempfile

import matplotlib.pyplot as plt
import numpy as np

import stereonav
from _common import SCENARIOS, output_dir, save
from stereonav import fleet

SCENARIO = SCENARIOS / "paper-square-realistic.toml"
VEHICLES = ("FL-01", "FL-02", "FL-03")
DAYS = 5
#: The drifting forklift and its drift a day: baseline (m) and f (px).
DRIFTING = "FL-03"
BASELINE_PER_DAY = -0.0004
F_PER_DAY = 1.5


def true_camera(vehicle: str, day: int, f0: float, b0: float) -> tuple[float, float]:
    """The forklift's true f (px) and baseline (m) on ``day``."""
    if vehicle != DRIFTING:
        return f0, b0
    return f0 + F_PER_DAY * day, b0 + BASELINE_PER_DAY * day


def write_logs(directory: pathlib.Path) -> tuple[list[pathlib.Path], dict[str, tuple[str, int, float, float]]]:
    """Simulate every shift into ``directory``: the logs, and per log (vehicle, day, true f,
    true baseline)."""
    text = SCENARIO.read_text()
    f0 = float(re.search(r"^f_px = ([0-9.]+)", text, re.M).group(1))  # type: ignore[union-attr]
    b0 = float(re.search(r"^baseline_m = ([0-9.]+)", text, re.M).group(1))  # type: ignore[union-attr]
    rig = SCENARIO.with_name("paper-square-realistic.rig.toml")
    logs, truth = [], {}
    for v, vehicle in enumerate(VEHICLES):
        for day in range(DAYS):
            f, b = true_camera(vehicle, day, f0, b0)
            scenario = re.sub(r"^f_px = [0-9.]+", f"f_px = {f}", text, flags=re.M)
            scenario = re.sub(r"^baseline_m = [0-9.]+", f"baseline_m = {b}", scenario, flags=re.M)
            scenario = re.sub(r'^rig = ".*"', f"rig = {str(rig)!r}".replace("'", '"'), scenario, flags=re.M)
            path = directory / f"{vehicle}-day{day}.toml"
            path.write_text(scenario)
            log = directory / f"{vehicle}-day{day}.mcap"
            stereonav.simulate(path, seed=1000 * v + day).write_log(log)
            logs.append(log)
            truth[str(log)] = (vehicle, day, f, b)
    return logs, truth


def main() -> None:
    out = output_dir(__doc__)
    with tempfile.TemporaryDirectory() as tmp:
        logs, truth = write_logs(pathlib.Path(tmp))
        table = fleet.replay_logs(logs, n_workers=2, progress=False)
    failed = table[table["error"].notna()]
    if len(failed):
        raise SystemExit(f"{len(failed)} logs failed: {failed['error'].iloc[0]}")
    table["vehicle"] = [truth[log][0] for log in table["log"]]
    table["day"] = [truth[log][1] for log in table["log"]]

    figure, axes = plt.subplots(2, 1, figsize=(8.0, 7.0), sharex=True)
    colours = dict(zip(VEHICLES, ("tab:blue", "tab:green", "tab:red")))
    offsets = dict(zip(VEHICLES, (-0.08, 0.0, 0.08)))
    panels = (
        (axes[0], "baseline", 1e3, "baseline (mm)", 3),
        (axes[1], "f", 1.0, "f (px)", 2),
    )
    for ax, name, scale, label, truth_index in panels:
        for vehicle in VEHICLES:
            rows = table[table["vehicle"] == vehicle].sort_values("day")
            day = rows["day"].to_numpy(float) + offsets[vehicle]
            value = rows[name].to_numpy(float) * scale
            sigma = rows[f"{name}_sigma"].to_numpy(float) * scale
            c = colours[vehicle]
            ax.fill_between(day, value - 3 * sigma, value + 3 * sigma, color=c, alpha=0.2, lw=0)
            ax.errorbar(day, value, yerr=3 * sigma, fmt="o-", color=c, capsize=3, label=f"{vehicle} (3 sigma)")
        drifting = sorted((v[1], v[truth_index]) for v in truth.values() if v[0] == DRIFTING)
        days, true = np.array(drifting).T
        ax.plot(days, true * scale, "k--", lw=1, label=f"{DRIFTING}'s truth")
        nominal = [v[truth_index] for v in truth.values() if v[0] != DRIFTING][0]
        ax.axhline(nominal * scale, color="0.5", lw=0.8, ls=":", label="the others' truth")
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8, loc="best")
    axes[0].set_title("Self-calibrated camera of each forklift, a log a day (stereonav.fleet on Dask)")
    axes[1].set_xlabel("day")
    axes[1].set_xticks(range(DAYS))
    save(figure, out, __file__)


if __name__ == "__main__":
    main()
