"""The paper's Fig. 8: the landmarks in the robot frame and in the world frame.

The committed log ``fixtures/logs/paper-experiment.mcap`` (five LEDs, the robot driven
2.5 m along X and back, twice) replayed with phase 1 skipped (:func:`stereonav.replay`). Every
stereo measurement of a lamp is triangulated with the replay's final camera parameters:

- left, in the robot frame (x ahead, y to the left, z up from the floor under the robot):
  as the robot drives, the lamps stream past it along x; the large markers are the instant
  at ``INSTANT_S`` (the robot halfway along its first leg), with the map and the true lamps
  as seen from the robot's estimated and true pose then;
- right, in the world frame (the robot at the first frame): the same measurements carried by
  the estimated pose of their frame fall onto the mapped landmarks; with the estimated and
  the true path, and the true lamps.

Top row: seen from above; bottom row: from the side. The lamp labels of the measurements
come from the simulator's truth (the replay associates by itself); the truth is the log's own
simulation (:func:`stereonav.simulate` of the scenario at the seed that made the log).

    python examples/fig8_landmarks_frames.py [--out DIR]
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np

import stereonav
from _common import F64, LAMP_COLORS, LOGS, SCENARIOS, US, lamp_measurements, output_dir, pixels, save

LOG = LOGS / "paper-experiment.mcap"
RIG = LOGS / "paper-experiment.rig.toml"
SCENARIO = SCENARIOS / "paper-experiment.toml"
#: The instant shown in the robot frame, seconds after the first frame.
INSTANT_S = 5.0


def robot_from_world(points: F64, pose: F64) -> F64:
    """World points ``(N, 3)`` in the frame of the robot at ``pose = (x, y, theta)``."""
    x, y, theta = pose
    c, s = np.cos(theta), np.sin(theta)
    dx, dy = points[:, 0] - x, points[:, 1] - y
    return np.column_stack([c * dx + s * dy, -s * dx + c * dy, points[:, 2]])


def world_from_robot(points: F64, poses: F64) -> F64:
    """Robot-frame points ``(N, 3)``, each at its own pose ``(N, 3)``, in the world frame."""
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    x = poses[:, 0] + c * points[:, 0] - s * points[:, 1]
    y = poses[:, 1] + s * points[:, 0] + c * points[:, 1]
    return np.column_stack([x, y, points[:, 2]])


def main() -> None:
    out = output_dir(__doc__)
    sim = stereonav.simulate(SCENARIO)
    run = stereonav.replay(LOG, RIG, skip_phase1=True)
    camera = stereonav.Camera(**{name: estimate.value for name, estimate in run.camera.items()})
    rows = lamp_measurements(sim)
    trajectory = run.trajectory
    frame = np.searchsorted(trajectory["t_us"], rows["t_us"])
    estimated = np.column_stack([trajectory[k] for k in ("x", "y", "theta")])
    true_poses = np.column_stack([sim.trajectory[k] for k in ("x", "y", "theta")])
    in_robot = stereonav.triangulate(pixels(rows), camera=camera).p_in_robot
    in_world = world_from_robot(in_robot, estimated[frame])
    mapped = np.column_stack([run.landmarks[k] for k in ("x", "y", "z")])
    lamps = sim.landmarks

    instant = int(np.searchsorted(trajectory["t_us"], trajectory["t_us"][0] + INSTANT_S / US))
    now = frame == instant
    figure, axes = plt.subplots(2, 2, figsize=(11, 8.5), gridspec_kw={"height_ratios": [3, 2]})
    views = ((0, 1, "y (m)"), (0, 2, "z (m)"))
    for row, (a, b, label) in enumerate(views):
        robot, world = axes[row]
        for lamp in range(len(lamps)):
            mine = rows["id"] == lamp
            color = LAMP_COLORS[lamp]
            robot.plot(in_robot[mine, a], in_robot[mine, b], ".", color=color, markersize=2, alpha=0.3)
            robot.plot(in_robot[mine & now, a], in_robot[mine & now, b], "o", color=color, markersize=9,
                       label=f"lamp {lamp}")
            world.plot(in_world[mine, a], in_world[mine, b], ".", color=color, markersize=2, alpha=0.3)
        seen_map = robot_from_world(mapped, estimated[instant])
        seen_truth = robot_from_world(lamps, true_poses[instant])
        robot.plot(seen_map[:, a], seen_map[:, b], "s", color="black", markerfacecolor="none", markersize=12,
                   label="map, from the estimated pose")
        robot.plot(seen_truth[:, a], seen_truth[:, b], "kx", markersize=8, label="true lamps, from the true pose")
        world.plot(mapped[:, a], mapped[:, b], "s", color="black", markerfacecolor="none", markersize=12,
                   label="mapped landmarks")
        world.plot(lamps[:, a], lamps[:, b], "kx", markersize=8, label="true lamps")
        if b == 1:
            robot.plot(0.0, 0.0, ">", color="black", markersize=12, label="the robot")
            world.plot(sim.trajectory["x"], sim.trajectory["y"], color="black", linestyle="--", linewidth=1,
                       label="true path")
            world.plot(trajectory["x"], trajectory["y"], color="tab:gray", linewidth=1, label="estimated path")
            x, y, theta = estimated[instant]
            world.plot(x, y, marker=(3, 0, np.degrees(theta) - 90), color="black", markersize=12,
                       linestyle="none", label=f"the robot at {INSTANT_S:.0f} s")
        for ax, frame_name in ((robot, "robot"), (world, "world")):
            ax.set_xlabel(f"x in the {frame_name} frame (m)")
            ax.set_ylabel(f"{label[0]} in the {frame_name} frame (m)")
            ax.grid(alpha=0.3)
        if b == 1:
            for ax in (robot, world):
                ax.set_aspect("equal", adjustable="datalim")
    axes[0, 0].set_title(f"robot frame: every measurement, and the instant at {INSTANT_S:.0f} s (large)",
                         fontsize=10)
    truth = run.truth or {}
    axes[0, 1].set_title(
        f"world frame: landmark RMS {truth.get('landmark_rms_m', float('nan')) * 1e3:.2f} mm, "
        f"trajectory RMS {truth.get('ate_rms_m', float('nan')) * 1e3:.2f} mm",
        fontsize=10,
    )
    axes[0, 0].legend(fontsize=7, loc="upper left", ncol=2)
    axes[0, 1].legend(fontsize=7, loc="upper left", ncol=2)
    figure.suptitle(
        "Landmarks in the robot and world frames, paper-experiment.mcap replayed (Fig. 8)", fontsize=11
    )
    save(figure, out, __file__)


if __name__ == "__main__":
    main()
