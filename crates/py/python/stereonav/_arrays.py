"""The package's NumPy structured dtypes and the conversions of native columns into them.

The native module (:mod:`stereonav._native`) hands back plain columns (1-D and 2-D arrays
named by the fields of a result object); the structured arrays of the public API are made
here, in one place. ``_native`` itself imports :data:`FEATURE_DTYPE` from this module to view
the board's packed records.
"""

from __future__ import annotations

from typing import Any, Final

import numpy as np
import numpy.typing as npt

#: One feature as the board sends it (``board-icd.md`` section 2, step 7): column ``x_q4`` and
#: row ``y_q4`` in Q12.4 pixels (``u = x_q4 / 16``, ``v = y_q4 / 16``) and the Harris response
#: ``r`` at the integer pixel. Little-endian and packed, 8 bytes, as in the board's stream.
FEATURE_DTYPE: Final[np.dtype[np.void]] = np.dtype(
    [("x_q4", "<u2"), ("y_q4", "<u2"), ("r", "<i4")]
)

#: One landmark observation's gate outcome: ``id`` (``<u8``, the landmark) and ``nis``
#: (``<f8``, its normalised innovation squared, 4 dof; ``inf`` when the landmark could not
#: be projected at the current estimate).
GATE_DTYPE = np.dtype([("id", "<u8"), ("nis", "<f8")])
#: A track bound to a landmark: ``track`` (``<u8``, the caller's track id) and ``landmark``
#: (``<u8``, the filter's landmark id).
BINDING_DTYPE = np.dtype([("track", "<u8"), ("landmark", "<u8")])

#: One stereo frame of a run on a saved map (:func:`stereonav.localize`; the rows of its
#: ``TRAJ.csv``): ``t_us`` (``<u8``), the pose ``x``, ``y`` (``<f8``, metres) and ``theta``
#: (``<f8``, radians) in the map's frame, NaN when the localiser has no guess, and
#: ``localized`` (``?``): whether the localiser stands behind the pose.
LOCALIZED_TRAJECTORY_DTYPE: Final[np.dtype[np.void]] = np.dtype(
    [("t_us", "<u8"), ("x", "<f8"), ("y", "<f8"), ("theta", "<f8"), ("localized", "?")]
)
#: A lamp a run on a saved map saw that is not in the map: its position ``x, y, z`` (``<f8``,
#: metres, the map's frame), per-axis 1-sigma ``sx, sy, sz`` (``<f8``, metres), its position
#: ``covariance`` (``<f8``, shape (3, 3), m**2) and ``observations`` (``<u8``, fused). The
#: rows of the localisation ``SUMMARY.json``'s ``new_lamps``, with the covariance.
NEW_LAMP_DTYPE: Final[np.dtype[np.void]] = np.dtype(
    [
        ("x", "<f8"),
        ("y", "<f8"),
        ("z", "<f8"),
        ("sx", "<f8"),
        ("sy", "<f8"),
        ("sz", "<f8"),
        ("covariance", "<f8", (3, 3)),
        ("observations", "<u8"),
    ]
)

_F64 = npt.NDArray[np.float64]
_U64 = npt.NDArray[np.uint64]


def readonly(array: npt.NDArray[Any]) -> npt.NDArray[Any]:
    """``array``, made read-only (results are not to be written to)."""
    array.setflags(write=False)
    return array


def gated(ids: _U64, nis: _F64) -> npt.NDArray[np.void]:
    """Ids and their NIS as a read-only :data:`GATE_DTYPE` array."""
    out = np.zeros(len(ids), dtype=GATE_DTYPE)
    out["id"], out["nis"] = ids, nis
    return readonly(out)


def bindings(pairs: npt.NDArray[np.uint64]) -> npt.NDArray[np.void]:
    """``(K, 2)`` ``(track, landmark)`` pairs as a :data:`BINDING_DTYPE` array."""
    out = np.zeros(len(pairs), dtype=BINDING_DTYPE)
    if len(pairs):
        out["track"], out["landmark"] = pairs[:, 0], pairs[:, 1]
    return out
