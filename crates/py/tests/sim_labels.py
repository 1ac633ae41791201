"""Lamp labels for simulated board features, shared by the phase-1 and phase-2 tests.

The board's stream carries no lamp ids (and the estimators must not need them), but judging an
estimator apart from association does: the simulator's truth supplies them here.
"""

from __future__ import annotations

import numpy as np

import stereonav
from stereonav import MEASUREMENT_DTYPE

#: How far a board feature may lie from a lamp's true projection to be that lamp, pixels (the
#: simulated pixel noise is 0.3 px, 1 sigma).
MATCH_PX = 2.0


def lamp_measurements(sim: stereonav.Simulation) -> np.ndarray:
    """Board features labelled with the lamp they show, as MEASUREMENT_DTYPE rows.

    A feature is lamp ``i`` when it is the nearest one, within ``MATCH_PX``, to lamp ``i``'s
    true projection, in both images; clutter is left out that way.
    """
    decoder = stereonav.StreamDecoder()
    frames = decoder.push(sim.stream) + decoder.finish()
    poses = {int(row["t_us"]): (row["x"], row["y"], row["theta"]) for row in sim.trajectory}
    rows = []
    for frame in frames:
        z = stereonav.project(sim.landmarks, pose=poses[frame.t_us], camera=sim.camera).z
        left = np.column_stack([frame.left["x_q4"], frame.left["y_q4"]]) / 16.0
        right = np.column_stack([frame.right["x_q4"], frame.right["y_q4"]]) / 16.0
        if len(left) == 0 or len(right) == 0:
            continue
        for lamp, (ul, vl, ur, vr) in enumerate(z):
            if not np.isfinite(ul):
                continue
            dl = np.hypot(left[:, 0] - ul, left[:, 1] - vl)
            dr = np.hypot(right[:, 0] - ur, right[:, 1] - vr)
            if dl.min() <= MATCH_PX and dr.min() <= MATCH_PX:
                (ul_, vl_), (ur_, vr_) = left[dl.argmin()], right[dr.argmin()]
                rows.append((frame.t_us, lamp, ul_, vl_, ur_, vr_))
    return np.array(rows, dtype=MEASUREMENT_DTYPE)
