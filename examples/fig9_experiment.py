"""The paper's Fig. 9: the experiment, phase 2 with the separation in the state.

The data of ``fixtures/logs/paper-experiment.mcap`` (five LEDs, the robot driven 2.5 m along X
and back, twice; only the baseline estimated: the paper's 19-element state), regenerated
byte for byte by the simulator at the log's seed, run through phase 2 from the rig's priors
(phase 1 skipped, as in the paper). The filter (:class:`stereonav.Filter`) is stepped frame by
frame here, because the figure needs what the replay does not keep: every innovation vector
and its covariance. The board's features are labelled with the lamp they show from the
simulator's truth, so that the figure judges the filter apart from association (the replay of
the log, which associates by itself, ends with the same baseline within 0.01 mm and a map
within 1.5 mm of this one, mostly a slight rotation). Plotted, each with its 3-sigma band:

- the landmarks' height errors (the dominant axis), the robot's motion along X against the
  truth, and its position error;
- the separation (baseline) error;
- the innovations in pixel space (``uL`` and ``vL`` of every accepted observation against
  ``3 sqrt(S)`` of its innovation covariance ``S = H P H^T + R``);
- the innovations in 3-D: the landmark triangulated from the measurement at the predicted
  pose and camera, minus the landmark's estimate, against ``3 sqrt`` of ``G S G^T`` (``G``
  the triangulation's Jacobian, by central differences).

    python examples/fig9_experiment.py [--out DIR]
"""

from __future__ import annotations

import dataclasses

import matplotlib.pyplot as plt
import numpy as np
import numpy.typing as npt
from matplotlib.axes import Axes

import stereonav
from _common import (
    F64,
    LAMP_COLORS,
    LOGS,
    SCENARIOS,
    US,
    band,
    error_axes,
    lamp_measurements,
    output_dir,
    pixels,
    save,
)

RIG = LOGS / "paper-experiment.rig.toml"
SCENARIO = SCENARIOS / "paper-experiment.toml"
B = stereonav.CAMERA_PARAMETERS.index("baseline")
#: Step of the numerical triangulation Jacobian, pixels.
STEP_PX = 1e-3


@dataclasses.dataclass
class Record:
    """What the filter did at every frame (F frames) and every accepted observation (K)."""

    t: F64  # (F,) s since the first frame
    pose: F64  # (F, 3)
    pose_sigma: F64  # (F, 3)
    baseline: F64  # (F,)
    baseline_sigma: F64  # (F,)
    #: lamp -> (times (s), position (x, y, z), height sigma) while it is in the map
    landmarks: dict[int, tuple[list[float], list[F64], list[float]]]
    obs_t: F64  # (K,)
    obs_lamp: npt.NDArray[np.int64]  # (K,)
    innovation: F64  # (K, 4) pixels
    innovation_sigma: F64  # (K, 4)
    innovation_3d: F64  # (K, 3) metres
    innovation_3d_sigma: F64  # (K, 3)
    nis: F64  # (K,)


def triangulation_jacobian(z: F64, camera: stereonav.Camera, pose: F64) -> F64:
    """``(M, 3, 4)``: d world point / d (uL, vL, uR, vR) of each measurement row of ``z``."""
    jacobian = np.zeros((len(z), 3, 4))
    for k in range(4):
        up, down = z.copy(), z.copy()
        up[:, k] += STEP_PX
        down[:, k] -= STEP_PX
        jacobian[:, :, k] = (
            stereonav.triangulate(up, camera=camera, pose=pose).p_in_world
            - stereonav.triangulate(down, camera=camera, pose=pose).p_in_world
        ) / (2 * STEP_PX)
    return jacobian


def run_filter(sim: stereonav.Simulation, rows: npt.NDArray[np.void]) -> Record:
    """Step a filter from the rig's priors through ``sim`` with the labelled ``rows`` (lamp ids
    as track ids), recording the state and, before each update, the innovations."""
    f = stereonav.Filter(RIG)
    times = sim.trajectory["t_us"]
    poses, pose_sigmas, baselines, baseline_sigmas = [], [], [], []
    tracks: dict[int, tuple[list[float], list[F64], list[float]]] = {}
    obs: dict[str, list[F64]] = {k: [] for k in ("t", "lamp", "nu", "s", "nu3", "s3", "nis")}
    for k, t_us in enumerate(times):
        t = float(t_us - times[0]) * US
        if k:
            f.predict_odometry(sim.odometry, int(times[k - 1]), int(t_us))
        frame = rows[rows["t_us"] == t_us]
        z = pixels(frame)
        bound = dict(zip(f.bindings["track"].tolist(), f.bindings["landmark"].tolist()))
        known = np.array([int(lamp) in bound for lamp in frame["id"]], dtype=bool)
        if known.any():
            landmarks = f.landmarks
            index = {int(i): n for n, i in enumerate(landmarks["id"])}
            ids = [bound[int(lamp)] for lamp in frame["id"][known]]
            predicted = [f.predict_measurement(i) for i in ids]
            nu = z[known] - np.array([p.z for p in predicted])
            s = np.array([p.covariance for p in predicted])
            camera, pose = f.camera, f.pose
            g = triangulation_jacobian(z[known], camera, pose)
            estimate = np.array([[landmarks[index[i]][c] for c in ("x", "y", "z")] for i in ids])
            nu3 = stereonav.triangulate(z[known], camera=camera, pose=pose).p_in_world - estimate
            s3 = np.einsum("mij,mjk,mlk->mil", g, s, g)
        report = f.observe(frame["id"], z)
        if known.any():
            accepted = np.isin(ids, report.update.accepted["id"])
            obs["t"].append(np.full(int(accepted.sum()), t))
            obs["lamp"].append(frame["id"][known][accepted].astype(np.int64))
            obs["nu"].append(nu[accepted])
            obs["s"].append(np.sqrt(np.diagonal(s[accepted], axis1=1, axis2=2)))
            obs["nu3"].append(nu3[accepted])
            obs["s3"].append(np.sqrt(np.diagonal(s3[accepted], axis1=1, axis2=2)))
            obs["nis"].append(np.einsum("mi,mij,mj->m", nu, np.linalg.inv(s), nu)[accepted])
        poses.append(f.pose)
        pose_sigmas.append(np.sqrt(np.diag(f.pose_covariance)))
        baselines.append(f.camera.baseline)
        baseline_sigmas.append(np.sqrt(f.camera_covariance[B, B]))
        lamp_of = dict(zip(f.bindings["landmark"].tolist(), f.bindings["track"].tolist()))
        for row in f.landmarks:
            seen, positions, sigmas = tracks.setdefault(lamp_of[int(row["id"])], ([], [], []))
            seen.append(t)
            positions.append(np.array([row["x"], row["y"], row["z"]]))
            sigmas.append(float(np.sqrt(row["covariance"][2, 2])))
    return Record(
        t=(times - times[0]).astype(np.float64) * US,
        pose=np.array(poses),
        pose_sigma=np.array(pose_sigmas),
        baseline=np.array(baselines),
        baseline_sigma=np.array(baseline_sigmas),
        landmarks=tracks,
        obs_t=np.concatenate(obs["t"]),
        obs_lamp=np.concatenate(obs["lamp"]),
        innovation=np.concatenate(obs["nu"]),
        innovation_sigma=np.concatenate(obs["s"]),
        innovation_3d=np.concatenate(obs["nu3"]),
        innovation_3d_sigma=np.concatenate(obs["s3"]),
        nis=np.concatenate(obs["nis"]),
    )


def innovation_panel(ax: Axes, record: Record, values: F64, sigmas: F64, ylabel: str) -> None:
    """Innovations of every accepted observation (dots) and each lamp's 3-sigma envelope."""
    for lamp, color in enumerate(LAMP_COLORS):
        mine = record.obs_lamp == lamp
        ax.plot(record.obs_t[mine], values[mine], ".", color=color, markersize=1.5)
        for sign in (-3, 3):
            ax.plot(record.obs_t[mine], sign * sigmas[mine], color=color, linewidth=0.6,
                    label=f"lamp {lamp}" if sign > 0 else None)
    inside = float(np.mean(np.abs(values) <= 3 * sigmas))
    ax.set_title(f"{ylabel}: {100 * inside:.1f} % inside 3 sigma", fontsize=10)
    ax.set_xlabel("time (s)")
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)


def main() -> None:
    out = output_dir(__doc__)
    sim = stereonav.simulate(SCENARIO)  # the log's own simulation (same seed, same bytes)
    record = run_filter(sim, lamp_measurements(sim))
    truth = np.column_stack([sim.trajectory[k] for k in ("x", "y", "theta")])
    lamps = sim.landmarks

    figure, axes = plt.subplots(4, 2, figsize=(12, 13))
    landmark_ax, motion_ax = axes[0]
    pose_ax, baseline_ax = axes[1]
    for lamp, (times, positions, sigmas) in sorted(record.landmarks.items()):
        errors = (np.array(positions)[:, 2] - lamps[lamp, 2]) * 1e3
        band(landmark_ax, times, errors, np.array(sigmas) * 1e3, color=LAMP_COLORS[lamp],
             label=f"lamp {lamp}", shaded=False)
    error_axes(landmark_ax, "landmark height error (mm)", 1.0)
    final = np.array([positions[-1] - lamps[lamp] for lamp, (_, positions, _) in record.landmarks.items()])
    landmark_ax.set_title(
        f"landmarks: height error (final 3-D RMS {np.sqrt(np.mean(np.sum(final**2, axis=1))) * 1e3:.2f} mm)",
        fontsize=10,
    )
    landmark_ax.legend(fontsize=8, ncol=5, loc="upper right")

    motion_ax.plot(record.t, truth[:, 0], color="black", linestyle="--", linewidth=1, label="true x")
    motion_ax.plot(record.t, record.pose[:, 0], color="tab:blue", linewidth=1, label="estimated x")
    motion_ax.set_xlabel("time (s)")
    motion_ax.set_ylabel("robot x (m)")
    motion_ax.set_title("robot motion: straight along X and back, twice", fontsize=10)
    motion_ax.legend(fontsize=8, loc="upper right")
    motion_ax.grid(alpha=0.3)

    for k, (name, color) in enumerate((("x", "tab:blue"), ("y", "tab:orange"))):
        band(pose_ax, record.t, (record.pose[:, k] - truth[:, k]) * 1e3, record.pose_sigma[:, k] * 1e3,
             color=color, label=f"{name} error")
    pose_ax.axhline(0.0, color="black", linestyle="--", linewidth=1.0)
    position_rms = np.sqrt(np.mean(np.sum((record.pose[:, :2] - truth[:, :2]) ** 2, axis=1)))
    pose_ax.set_title(f"robot position error, RMS {position_rms * 1e3:.2f} mm", fontsize=10)
    pose_ax.set_xlabel("time (s)")
    pose_ax.set_ylabel("position error (mm)")
    pose_ax.legend(fontsize=8, loc="upper left")
    pose_ax.grid(alpha=0.3)

    band(baseline_ax, record.t, (record.baseline - sim.camera.baseline) * 1e3, record.baseline_sigma * 1e3,
         color="tab:blue", label="estimate - truth, 3-sigma band")
    error_axes(baseline_ax, "separation (baseline) error (mm)", 0.1)
    baseline_ax.set_title(
        f"separation {record.baseline[-1] * 1e3:.3f} +- {record.baseline_sigma[-1] * 1e3:.3f} mm "
        f"(truth {sim.camera.baseline * 1e3:.3f}, nominal {record.baseline[0] * 1e3:.1f})",
        fontsize=10,
    )
    baseline_ax.legend(fontsize=8, loc="upper right")

    innovation_panel(axes[2, 0], record, record.innovation[:, 0], record.innovation_sigma[:, 0],
                     "innovation uL (px)")
    innovation_panel(axes[2, 1], record, record.innovation[:, 1], record.innovation_sigma[:, 1],
                     "innovation vL (px)")
    innovation_panel(axes[3, 0], record, record.innovation_3d[:, 0] * 1e3,
                     record.innovation_3d_sigma[:, 0] * 1e3, "3-D innovation x (mm)")
    innovation_panel(axes[3, 1], record, record.innovation_3d[:, 2] * 1e3,
                     record.innovation_3d_sigma[:, 2] * 1e3, "3-D innovation z (mm)")
    axes[2, 0].legend(fontsize=8, ncol=5, loc="upper right")
    figure.suptitle(
        "The experiment (Fig. 9): phase 2 on paper-experiment's data from the rig's priors, "
        f"mean NIS {record.nis.mean():.2f} (4 dof)",
        fontsize=11,
    )
    save(figure, out, __file__)


if __name__ == "__main__":
    main()
