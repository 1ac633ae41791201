"""The paper's Fig. 5: phase 2 along the 2 m square, the separation and the landmarks converging.

The committed log ``fixtures/logs/paper-square.mcap`` (a 2 m square driven twice, five
landmarks, f and baseline estimated with them, the rig's nominal values 2.5 % off) replayed
through the whole stack with phase 1 skipped (:func:`stereonav.replay`: association, map
matching, EKF SLAM with the camera parameters in the state). Plotted:

- the path: the estimated trajectory and map against the truth (top view);
- the separation (baseline) and the focal length f after every frame, with 3-sigma bands;
- each landmark's height error (estimate minus the true lamp), with its 3-sigma band, from
  the map snapshots the replay keeps about once a second.

The truth is the log's own simulation (:func:`stereonav.simulate` of the scenario, whose seed
made the log).

    python examples/fig5_square_path.py [--out DIR]
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np

import stereonav
from _common import F64, LAMP_COLORS, LOGS, SCENARIOS, US, band, error_axes, output_dir, save

LOG = LOGS / "paper-square.mcap"
RIG = LOGS / "paper-square.rig.toml"
SCENARIO = SCENARIOS / "paper-square.toml"
#: A landmark is a lamp when it lies within this distance of it (the replay's own rule).
MATCH_M = 0.1
F = stereonav.CAMERA_PARAMETERS.index("f")
B = stereonav.CAMERA_PARAMETERS.index("baseline")


def lamp_of_landmark(landmarks: np.ndarray, lamps: F64) -> dict[int, int]:
    """Each landmark id of the final map matched to the nearest lamp within :data:`MATCH_M`."""
    matched = {}
    for row in landmarks:
        distance = np.linalg.norm(lamps - np.array([row["x"], row["y"], row["z"]]), axis=1)
        if distance.min() <= MATCH_M:
            matched[int(row["id"])] = int(distance.argmin())
    return matched


def main() -> None:
    out = output_dir(__doc__)
    sim = stereonav.simulate(SCENARIO)
    run = stereonav.replay(LOG, RIG, skip_phase1=True)
    t0 = float(run.trajectory["t_us"][0])
    t = (run.trajectory["t_us"] - t0) * US
    lamps = sim.landmarks
    matched = lamp_of_landmark(run.landmarks, lamps)
    against_truth = run.truth or {}  # the replay's own errors against the log's truth

    figure, axes = plt.subplots(2, 2, figsize=(11, 8.5))
    path, height = axes[0, 0], axes[1, 1]
    path.plot(sim.trajectory["x"], sim.trajectory["y"], color="black", linestyle="--", linewidth=1, label="true path")
    path.plot(run.trajectory["x"], run.trajectory["y"], color="tab:blue", linewidth=1, label="estimated path")
    path.plot(lamps[:, 0], lamps[:, 1], "kx", markersize=9, label="true lamps")
    path.plot(run.landmarks["x"], run.landmarks["y"], "o", color="tab:red", markerfacecolor="none",
              markersize=9, label="mapped landmarks")
    for lamp, (x, y, z) in enumerate(lamps):
        path.annotate(f"{lamp}: {z - sim.camera.mount_z:.2f} m up", (x, y), textcoords="offset points",
                      xytext=(6, 6), fontsize=8)
    path.set_aspect("equal")
    path.set_xlabel("x (m)")
    path.set_ylabel("y (m)")
    path.set_title(
        f"path and map, top view (trajectory error RMS {against_truth.get('ate_rms_m', float('nan')) * 1e3:.2f} mm)",
        fontsize=10,
    )
    path.legend(fontsize=8, loc="lower left", bbox_to_anchor=(0.08, 0.06))
    path.grid(alpha=0.3)

    history = run.camera_history
    for ax, k, truth, scale, unit, linear in (
        (axes[0, 1], B, sim.camera.baseline, 1e3, "mm", 0.1),
        (axes[1, 0], F, sim.camera.f, 1.0, "px", 1.0),
    ):
        name = stereonav.CAMERA_PARAMETERS[k]
        band(ax, t, (history.values[:, k] - truth) * scale, history.sigmas[:, k] * scale,
             color="tab:blue", label="estimate - truth, 3-sigma band")
        error_axes(ax, f"{'separation (baseline)' if k == B else 'focal length f'} error ({unit})", linear)
        ax.set_title(
            f"{name} {history.values[-1, k] * scale:.3f} +- {history.sigmas[-1, k] * scale:.3f} {unit} "
            f"(truth {truth * scale:.3f}, nominal {history.values[0, k] * scale:.1f})",
            fontsize=10,
        )
        ax.legend(fontsize=8, loc="upper right")

    # The landmarks over time: the height error of each, from the map snapshots.
    for landmark, lamp in sorted(matched.items(), key=lambda item: item[1]):
        times, errors, sigmas = [], [], []
        for snapshot in run.maps:
            rows = snapshot.landmarks[snapshot.landmarks["id"] == landmark]
            if len(rows):
                times.append((snapshot.t_us - t0) * US)
                errors.append((rows["z"][0] - lamps[lamp, 2]) * 1e3)
                sigmas.append(rows["sz"][0] * 1e3)
        band(height, times, errors, sigmas, color=LAMP_COLORS[lamp], label=f"lamp {lamp}", shaded=False)
    error_axes(height, "landmark height error (mm)", 1.0)
    height.set_title(
        "landmarks: height error with 3-sigma band "
        f"(final 3-D RMS {against_truth.get('landmark_rms_m', float('nan')) * 1e3:.2f} mm)",
        fontsize=10,
    )
    height.legend(fontsize=8, ncol=5, loc="upper right")
    figure.suptitle("Phase 2 along the 2 m square, paper-square.mcap replayed with phase 1 skipped (Fig. 5)", fontsize=11)
    save(figure, out, __file__)


if __name__ == "__main__":
    main()
