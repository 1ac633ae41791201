"""The paper's Fig. 4: phase 1 (self-calibration) converging on the calibration drive.

Phase 1 runs on the committed log ``fixtures/logs/paper-calibration.mcap`` (five LEDs, slow
motion with turns, head tilted 22 degrees; the rig's nominal f and baseline 3 % off) through
:func:`stereonav.calibrate_log`, which associates the board's features and builds the frame
pairs by itself. Plotted, with the truth as a dashed line:

- left column, against time: the incremental calibration re-solved after every frame pair
  (2 s of driving each): the focal length f, the stereo separation (baseline) and the height
  of the central lamp triangulated with the current camera parameters, each with its 3-sigma
  band; the dotted line is when the vehicle hands over to phase 2 (the replay's settings);
- right column, against Levenberg-Marquardt iterations: the batch solve over every pair of
  the drive, from the nominal values, with the final 3-sigma band.

The central lamp is measured in the drive's first 2 s, while the robot stands at the origin
(its features averaged over those frames and labelled with the simulator's truth); its
sigma combines the pixel noise with the sigmas of f and the baseline (their correlation at
the solution is about -0.02, so they are propagated as independent).

    python examples/fig4_phase1_convergence.py [--out DIR]
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes

import stereonav
from _common import F64, LOGS, SCENARIOS, US, band, lamp_measurements, output_dir, pixels, save

LOG = LOGS / "paper-calibration.mcap"
SCENARIO = SCENARIOS / "paper-calibration.toml"
#: The central lamp of the five (the centre of the 0.6 m square the robot drives).
CENTRAL = 0
#: More frame pairs than the drive has: with a solve after every pair and this as the stable
#: rule's minimum, the calibrator never hands over, and the estimate can be followed over the
#: whole drive.
NEVER_STABLE_PAIRS = 1_000_000
F = stereonav.CAMERA_PARAMETERS.index("f")
B = stereonav.CAMERA_PARAMETERS.index("baseline")
#: Steps of the numerical derivatives of the lamp's height: 0.01 px of f, 1 um of baseline.
STEP = {F: 0.01, B: 1e-6}


def truth_line(ax: Axes, value: float) -> None:
    """The true value as a dashed black horizontal line."""
    ax.axhline(value, color="black", linestyle="--", linewidth=1.0, label="truth")


def central_lamp(sim: stereonav.Simulation) -> tuple[F64, float]:
    """The central lamp's pixels averaged over the frames at the start pose, and their sigma."""
    rows = lamp_measurements(sim)
    trajectory = sim.trajectory
    standing = trajectory["t_us"][(trajectory["x"] == 0) & (trajectory["y"] == 0) & (trajectory["theta"] == 0)]
    mine = rows[(rows["id"] == CENTRAL) & np.isin(rows["t_us"], standing)]
    pixel_noise = stereonav.load_rig(LOGS / "paper-calibration.rig.toml").pixel_noise
    return pixels(mine).mean(axis=0), pixel_noise / np.sqrt(len(mine))


def lamp_height(z: F64, sigma_px: float, cameras: F64, sigmas: F64) -> tuple[F64, F64]:
    """The lamp's world height triangulated from ``z`` at the origin with each camera row of
    ``cameras`` (K, 10), and its 1-sigma from the pixels and the camera sigmas (K, 10)."""
    heights, variances = [], []
    for camera, sigma in zip(cameras, sigmas):
        point = stereonav.triangulate(z, camera=camera, sigma_px=sigma_px)
        variance = point.cov_in_world[0, 2, 2]
        for k, step in STEP.items():
            up, down = camera.copy(), camera.copy()
            up[k] += step
            down[k] -= step
            slope = (
                stereonav.triangulate(z, camera=up).p_in_world[0, 2]
                - stereonav.triangulate(z, camera=down).p_in_world[0, 2]
            ) / (2 * step)
            variance += (slope * sigma[k]) ** 2
        heights.append(point.p_in_world[0, 2])
        variances.append(variance)
    return np.array(heights), np.sqrt(variances)


def main() -> None:
    out = output_dir(__doc__)
    sim = stereonav.simulate(SCENARIO)  # the log's own simulation: its truth
    run = stereonav.calibrate_log(LOG, solve_every=1, min_pairs=NEVER_STABLE_PAIRS)
    handover = stereonav.calibrate_log(LOG).handover
    history, batch = run.history, run.calibration
    t = (history.t_us.astype(np.float64) - float(sim.trajectory["t_us"][0])) * US
    z, sigma_px = central_lamp(sim)
    height, height_sigma = lamp_height(z, sigma_px, history.values, history.sigmas)
    batch_sigmas = np.tile(batch.covariance.diagonal() ** 0.5, (len(batch.history), 1))
    batch_height, batch_height_sigma = lamp_height(z, sigma_px, batch.history, batch_sigmas)
    iterations = np.arange(len(batch.history))

    # Before a parameter is observable it is held at its nominal value (sigma 0): no band.
    # The lamp's height needs both.
    estimated = history.sigmas > 0
    rows = [
        ("focal length f (px)", history.values[:, F], history.sigmas[:, F], estimated[:, F],
         batch.history[:, F], batch.sigmas["f"], sim.camera.f, 1.0),
        ("separation (baseline, mm)", history.values[:, B], history.sigmas[:, B], estimated[:, B],
         batch.history[:, B], batch.sigmas["baseline"], sim.camera.baseline, 1e3),
        ("central lamp height (m)", height, height_sigma, estimated[:, F] & estimated[:, B],
         batch_height, batch_height_sigma[-1], sim.landmarks[CENTRAL, 2], 1.0),
    ]
    figure, axes = plt.subplots(3, 2, figsize=(11, 8.5), sharey="row", gridspec_kw={"width_ratios": [3, 1]})
    for (name, value, sigma, known, lm, lm_sigma, truth, scale), (left, right) in zip(rows, axes):
        left.plot(t[~known], value[~known] * scale, ".", color="tab:gray", label="held at nominal")
        band(left, t[known], value[known] * scale, sigma[known] * scale, color="tab:blue", label="estimate, 3-sigma band")
        truth_line(left, truth * scale)
        if handover is not None:
            left.axvline((handover.t_us - float(sim.trajectory["t_us"][0])) * US, color="tab:green",
                         linestyle=":", label="hand-over to phase 2")
        left.set_ylabel(name)
        left.grid(alpha=0.3)
        right.fill_between(iterations, (lm[-1] - 3 * lm_sigma) * scale, (lm[-1] + 3 * lm_sigma) * scale,
                           color="tab:orange", alpha=0.2, linewidth=0)
        right.plot(iterations, lm * scale, "o-", color="tab:orange", label="batch solve")
        truth_line(right, truth * scale)
        right.set_xticks(iterations)
        right.grid(alpha=0.3)
    axes[0, 0].legend(loc="lower right", fontsize=8)
    axes[0, 1].legend(loc="lower right", fontsize=8)
    axes[-1, 0].set_xlabel("time (s): incremental solve after each frame pair")
    axes[-1, 1].set_xlabel("Levenberg-Marquardt iteration")
    # Zoom on the converged part; the start (nominal, 3 % off) stays in view on the right.
    for row, (_, _, sigma, _, lm, _, truth, scale) in zip(axes, rows):
        spread = 8 * max(float(sigma[-1]), 1e-12) * scale
        low = min(truth * scale - spread, float(lm.min()) * scale)
        high = max(truth * scale + spread, float(lm.max()) * scale)
        margin = 0.05 * (high - low)
        row[0].set_ylim(low - margin, high + margin)
    figure.suptitle(
        "Phase 1 self-calibration on paper-calibration.mcap (Fig. 4): "
        f"f {batch.camera.f:.1f} +- {batch.sigmas['f']:.1f} px (truth {sim.camera.f:.1f}), "
        f"baseline {batch.camera.baseline * 1e3:.2f} +- {batch.sigmas['baseline'] * 1e3:.2f} mm "
        f"(truth {sim.camera.baseline * 1e3:.2f})",
        fontsize=10,
    )
    save(figure, out, __file__)


if __name__ == "__main__":
    main()
