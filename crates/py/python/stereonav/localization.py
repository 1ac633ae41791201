"""Runs on a saved map, and the map files themselves (``docs/maps.md``).

A map is what a replay built -- the ceiling lamps with their covariance, the calibrated camera
and vehicle parameters, the rig -- saved by ``stereonav replay --save-map`` or
``stereonav.replay(..., save_map=path)``. On it, the vehicle need not map again: it may start
anywhere in the map, unknown to the stack, and be moved while the stack is blind.

- :func:`localize` runs a vehicle log on a saved map, as ``stereonav localize`` does, and
  returns a :class:`Localization`: the summary (``SUMMARY.json``), the trajectory in the
  map's frame with whether the stack stood behind each pose, when it (re)gained its position,
  the map's lamps it missed and the lamps it saw that the map lacks.
- :func:`read_map` reads a map file into a dict (the file's JSON body), after every check
  ``stereonav localize`` makes (what the file is, its version, its length and CRC-32, every
  key and type); :func:`write_map` writes such a dict back as a map file, checked the same
  way. Both go through the Rust crate ``map-file``; floats read back bit for bit, so a map
  read and written again is the same file.
- :func:`import_map` makes a map from a hall's lighting plan or survey (a CSV file of the
  lamps' positions), as ``stereonav map import`` does: no mapping drive; :func:`localize`
  runs on it in the hall's frame, with the vehicle's rig.

Everything runs in Rust with the GIL released; arrays come back as copies.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from collections.abc import Mapping
from typing import Any, Final, Optional, Union, final

import numpy as np
import numpy.typing as npt

from . import _native
from ._arrays import LOCALIZED_TRAJECTORY_DTYPE, NEW_LAMP_DTYPE
from ._arrays import readonly as _readonly
from ._errors import InputError, InputTypeError
from .calibration import RigLike, _describe
from .navigation import _path, _rig, _topic

__all__ = [
    "LOCALIZED_TRAJECTORY_DTYPE",
    "MAP_VERSION",
    "NEW_LAMP_DTYPE",
    "DEFAULT_LAMP_SIGMA_M",
    "Localization",
    "import_map",
    "localize",
    "read_map",
    "write_map",
]

#: The newest map format version this build reads (``docs/maps.md``). A map is written as the
#: oldest version that holds it: 2 for a map without a rig (imported from a lighting plan
#: without one), else 1.
MAP_VERSION: Final[int] = _native.MAP_VERSION
#: The 1-sigma position uncertainty, in metres, of a lamp whose row of a lighting plan gives
#: none (:func:`import_map`'s ``sigma``, ``stereonav map import --sigma``'s default).
DEFAULT_LAMP_SIGMA_M: Final[float] = _native.DEFAULT_LAMP_SIGMA_M

_F64 = npt.NDArray[np.float64]
_PathLike = Union[str, "os.PathLike[str]"]
#: How a map given as a dict is named in messages (as the native module names it).
_GIVEN_MAP = "map"


def _new_lamps(raw: tuple[_F64, _F64, npt.NDArray[np.uint64]]) -> npt.NDArray[np.void]:
    positions, covariances, observations = raw
    out = np.zeros(len(observations), dtype=NEW_LAMP_DTYPE)
    if len(observations):
        out["x"], out["y"], out["z"] = positions.T
        sigma = np.sqrt(np.clip(np.diagonal(covariances, axis1=1, axis2=2), 0.0, None))
        out["sx"], out["sy"], out["sz"] = sigma.T
        out["covariance"] = covariances
    out["observations"] = observations
    return _readonly(out)


@final
@dataclasses.dataclass(frozen=True, eq=False, repr=False)
class Localization:
    """A vehicle log run on a saved map (:func:`localize`).

    Every array is read-only; :attr:`summary` and :attr:`truth` are new dicts at each access.
    Poses are in the map's frame (the first frame of the run that made the map).

    Attributes
    ----------
    summary : dict
        ``SUMMARY.json`` of ``stereonav localize`` (``vehicle-interfaces.md`` section 5): the
        replay's keys -- ``frames``, ``corrupt``, ``lost`` (int), ``phase_switch_t_us``
        (always None: there are no phases on a map), ``pose`` (``{t_us, x, y, theta,
        localized}`` at the last frame, or None), ``camera`` and ``vehicle`` (``{name: {value,
        sigma}}``: the map's C, V refined by this run), ``landmarks`` (the map's, ``[{id, x,
        y, z, sigma, observations}]`` with the times each was associated in this run as
        ``observations``) -- plus ``localized_t_us``, ``lamps_missing``, ``new_lamps``
        (``[{x, y, z, sigma, observations}]``), ``frames_processed``, ``localized_frames``,
        ``lost_by_reason`` (``gap``, ``no_odometry``, ``innovations``, ``uncertain``),
        ``hypotheses``, ``warnings`` and ``truth`` (as :attr:`truth`). Numbers that are not
        finite are None.
    trajectory : numpy.ndarray of LOCALIZED_TRAJECTORY_DTYPE, shape (F,)
        A row per stereo frame, in time order (the rows of ``TRAJ.csv``): ``t_us``
        (``<u8``), ``x``, ``y`` (``<f8``, metres), ``theta`` (``<f8``, radians), NaN where the
        localiser has no guess, and ``localized`` (``bool``): True while the stack stands
        behind the pose, False while it does not know where the vehicle is (the pose is then
        its best guess, or NaN).
    pose_sigma : numpy.ndarray of float64, shape (F, 3)
        The 1-sigma of each pose in ``x``, ``y`` (metres) and ``theta`` (radians); NaN without
        a pose.
    matched : numpy.ndarray of uint32, shape (F,)
        Map lamps associated at each frame.
    hypotheses : numpy.ndarray of uint32, shape (F,)
        Relocalisation hypotheses alive at each frame.
    localized_t_us : tuple of int
        Each time the stack (re)gained its position, microseconds.
    lamps_missing : tuple of int
        Ids of map landmarks it should have seen often and did not (ids as in the
        ``SUMMARY.json`` of the replay that saved the map).
    new_lamps : numpy.ndarray of NEW_LAMP_DTYPE, shape (K,)
        The lamps it saw that are not in the map.
    counts : dict of str to int
        What was read and decoded: ``frames`` (good packets), ``corrupt``, ``lost``,
        ``bytes_skipped``, ``odometry``, ... and what a damaged log lost (as
        :attr:`Replay.counts <stereonav.Replay>`).
    warnings : tuple of str
        What limits the result without stopping it (a log cut short, no odometry, never
        localised, inputs the localiser refused), one line each.
    truth : dict or None
        When the log carries the simulator's truth (taken to be in the map's frame: the
        mapping run started at the truth's origin), the errors against it: ``frames``,
        ``localized_frames``, ``ate_rms_m``, ``ate_max_m``, ``heading_rms_rad`` (over the
        localised frames), ``wrong_frames`` (localised more than ``wrong_fix_m`` off).
    """

    trajectory: npt.NDArray[np.void]
    pose_sigma: _F64
    matched: npt.NDArray[np.uint32]
    hypotheses: npt.NDArray[np.uint32]
    localized_t_us: tuple[int, ...]
    lamps_missing: tuple[int, ...]
    new_lamps: npt.NDArray[np.void]
    counts: dict[str, int]
    warnings: tuple[str, ...]
    _summary_json: str
    _result: _native.LocalizeResult

    @classmethod
    def _from_native(cls, native: _native.LocalizeResult) -> Localization:
        """The typed result of a native run, every array copied out once."""
        columns = native.frames
        t_us, poses = columns.t_us, columns.pose
        trajectory = np.zeros(len(t_us), dtype=LOCALIZED_TRAJECTORY_DTYPE)
        trajectory["t_us"] = t_us
        if len(t_us):
            trajectory["x"], trajectory["y"], trajectory["theta"] = poses.T
        trajectory["localized"] = columns.localized
        return cls(
            trajectory=_readonly(trajectory),
            pose_sigma=_readonly(columns.sigma),
            matched=_readonly(columns.matched),
            hypotheses=_readonly(columns.hypotheses),
            localized_t_us=tuple(native.localized_t_us),
            lamps_missing=tuple(native.lamps_missing),
            new_lamps=_new_lamps(native.new_lamps),
            counts=dict(native.counts),
            warnings=tuple(native.warnings),
            _summary_json=native.summary_json(),
            _result=native,
        )

    @property
    def summary(self) -> dict[str, Any]:
        """``SUMMARY.json`` as a dict (a new one at each access); see the class docs."""
        summary: dict[str, Any] = json.loads(self._summary_json)
        return summary

    @property
    def truth(self) -> Optional[dict[str, Any]]:
        """The errors against the simulator's truth, or None; see the class docs."""
        truth: Optional[dict[str, Any]] = self.summary["truth"]
        return truth

    def write_summary(self, path: _PathLike) -> None:
        """Write ``SUMMARY.json``: :attr:`summary`, pretty-printed, as ``stereonav localize
        --summary`` does. The GIL is released.

        Raises
        ------
        InputTypeError
            ``path`` is not a path.
        InputError
            The file cannot be created or written (the message names it; the ``OSError`` is
            the ``__cause__``).
        """
        self._result.write_summary(_path("path", path))

    def write_trajectory(self, path: _PathLike) -> None:
        """Write ``TRAJ.csv`` as ``stereonav localize --trajectory`` does: a header
        ``t_us,x,y,theta,localized`` and a row per stereo frame (:attr:`trajectory`, the pose
        columns empty where there is no guess, ``localized`` 1 or 0). Raises as
        :meth:`write_summary`."""
        self._result.write_trajectory(_path("path", path))

    def write_trajectory_tum(self, path: _PathLike) -> None:
        """Write the localised frames' poses in the TUM format, as ``stereonav localize
        --trajectory-tum`` (``t x y z qx qy qz qw``, ``z = 0``, the heading as a quaternion;
        lost frames have no line), for evo and other SLAM tools. Raises as
        :meth:`write_summary`."""
        self._result.write_trajectory_tum(_path("path", path))

    def __repr__(self) -> str:
        localized = int(np.count_nonzero(self.trajectory["localized"]))
        return (
            f"<stereonav.Localization: {len(self.trajectory)} frames, {localized} localised, "
            f"{len(self.localized_t_us)} fixes, {len(self.lamps_missing)} lamps missing, "
            f"{len(self.new_lamps)} new lamps>"
        )


def localize(
    log_path: _PathLike,
    map_path: _PathLike,
    rig_path: Optional[RigLike] = None,
    *,
    save_map: Optional[_PathLike] = None,
    left: Optional[str] = None,
    right: Optional[str] = None,
    odom: Optional[str] = None,
) -> Localization:
    """Run a vehicle log on a saved map, as ``stereonav localize`` does.

    In Rust with the GIL released: the map is read (and checked: :func:`read_map`), the log
    read and decoded as for :func:`stereonav.replay`, and every stereo frame goes through the
    localiser built from the map's lamps and calibration. It finds where the vehicle is from
    the constellation of lamps in view (the vehicle may start anywhere in the map), keeps the
    pose on the map, and finds it again after the vehicle was moved while blind.

    Parameters
    ----------
    log_path : str or os.PathLike
        The vehicle log (MCAP, ``vehicle-interfaces.md`` section 4). Its ``/rig`` is not
        needed.
    map_path : str or os.PathLike
        The saved map (``docs/maps.md``).
    rig_path : path or RigConfig, optional
        The rig file (or :func:`stereonav.load_rig`'s result) for its lens, image size and
        noise; default: the rig the map was made with. The camera's calibration comes from the
        map; a map imported from a lighting plan (:func:`import_map`) has none, and its runs
        take this rig's nominal camera and vehicle with their priors. Required for such a map
        without a rig of its own.
    save_map : str or os.PathLike, keyword-only
        Write a new version of the map, with the lamps this run found that are not in it and
        the vehicle parameters it refined, as ``stereonav localize --save-map`` does. Written
        after the run.
    left, right, odom : str, keyword-only
        A ROS 2 bag's camera and odometry topics, all three or none, as for
        :func:`stereonav.replay` (``stereonav localize --left --right --odom``).

    Returns
    -------
    Localization

    Raises
    ------
    InputTypeError
        (a ``TypeError``) an argument has the wrong type.
    InputError
        (a ``ValueError``) the map cannot be read (missing or unreadable: the ``OSError`` is
        the ``__cause__``), is not a stereonav map, is of a newer format version, is cut or
        damaged, or has a missing key or a wrong type; it has no rig and none is given; it
        cannot localise (no lamps); the log
        cannot be read or is not a vehicle log; the rig is not valid; ``save_map`` cannot be
        written; the bag's topics are named badly (one or two of three), are not in the bag or
        are of another type. Each message is one line naming the file and the problem. A log cut short is
        not an error: it is run as far as it goes, and :attr:`Localization.warnings` says so.

    Examples
    --------
    >>> stereonav.replay("paper-experiment.mcap", skip_phase1=True,
    ...                  save_map="experiment.map")                # doctest: +SKIP
    >>> run = stereonav.localize("paper-experiment.mcap", "experiment.map")  # doctest: +SKIP
    >>> run.localized_t_us, run.trajectory["localized"].mean()    # doctest: +SKIP
    ((5850000,), 0.899...)
    """
    native = _native.localize(
        _path("log_path", log_path),
        _path("map_path", map_path),
        None if rig_path is None else _rig("rig_path", rig_path),
        None if save_map is None else _path("save_map", save_map),
        _topic("left", left),
        _topic("right", right),
        _topic("odom", odom),
    )
    return Localization._from_native(native)


# --- Map files -----------------------------------------------------------------------------


def read_map(path: _PathLike) -> dict[str, Any]:
    """Read a saved map file (``docs/maps.md``) into a dict: the file's JSON body.

    The file is checked as ``stereonav localize`` checks it, by the same Rust code: its
    header line (a stereonav map, of a version this build reads), the body's length and
    CRC-32, then every key and type of the body. Floats are the file's, bit for bit.

    Parameters
    ----------
    path : str or os.PathLike
        The map file.

    Returns
    -------
    dict
        ``format`` (``"stereonav-map"``), ``version`` (int: 1, or 2 for a map without a rig),
        ``created_unix_s`` (int), ``source_log`` (str), ``rig`` (dict: the rig in the rig
        file's JSON form, ``vehicle-interfaces.md`` section 3; absent in a map imported from a
        lighting plan without one), ``parameters`` (list of ``{name, value, sigma}``, every
        parameter of C and V; empty in a map imported from a lighting plan) and ``landmarks``
        (list of ``{id, position: [x, y, z], covariance: [[3], [3], [3]], observations}``,
        metres and square metres in the map's frame); ``common_error`` when the map has it,
        ``source_plan`` (str, the plan's file) when it was imported from a lighting plan.

    Raises
    ------
    InputTypeError
        ``path`` is not a path.
    InputError
        The file cannot be read (the ``OSError`` is the ``__cause__``), is not a stereonav
        map, is of a newer format version, is cut or damaged, or has a missing key or a wrong
        type (the key is named). One line naming the file and the problem.
    """
    body: dict[str, Any] = json.loads(_native.read_map(_path("path", path)))
    return body


def write_map(map_dict: Mapping[str, Any], path: _PathLike) -> None:
    """Write a map given as a dict (the form :func:`read_map` returns) to a map file.

    The dict is checked as a map file's body is, by the same Rust code that
    ``stereonav localize`` reads maps with, and written with its header line (version, body
    length, CRC-32) as ``stereonav replay --save-map`` writes one. Lists may be tuples or
    NumPy arrays and numbers NumPy scalars; floats are written so that they read back bit for
    bit, so ``write_map(read_map(a), b)`` makes ``b`` the same file as ``a``. The GIL is
    released while the file is written.

    Parameters
    ----------
    map_dict : dict
        ``format``, ``version`` (1, or 2 for a map without a rig), ``created_unix_s``,
        ``source_log``, ``rig``, ``parameters``, ``landmarks`` as :func:`read_map` returns them.
    path : str or os.PathLike
        The file to write (replaced if it exists).

    Raises
    ------
    InputTypeError
        ``map_dict`` is not a dict, or ``path`` is not a path.
    InputError
        A key is missing, has a value of the wrong type or one that is not finite, or is not
        part of the map format (it would be lost); ``version`` is not the one the map is
        written as; the
        rig is not valid. The message is one line naming the key
        (``map: landmarks[2]: 'id' is not a non-negative integer``). Or the file cannot be
        written (the message names it; the ``OSError`` is the ``__cause__``). Nothing is
        written when the map is refused.
    """
    if not isinstance(map_dict, Mapping):
        raise InputTypeError(
            f"map_dict must be a dict (as read_map returns), got {_describe(map_dict)}"
        )
    body = json.dumps(_json_value(map_dict, ""), allow_nan=False)
    _native.write_map(body, _path("path", path))


def _json_value(value: object, at: str) -> Any:
    """``value`` (found at ``at`` in the map) as plain JSON data: dicts with ``str`` keys,
    lists, ``str``, ``int``, finite ``float``, ``bool``, None; NumPy arrays and scalars become
    lists and Python numbers. Anything else raises :class:`InputError` naming where it is."""
    where = at or "the map"
    if isinstance(value, Mapping):
        out = {}
        for key, item in value.items():
            if not isinstance(key, str):
                raise InputError(f"{_GIVEN_MAP}: {where} has a key {key!r} that is not a str")
            out[key] = _json_value(item, f"{at}.{key}" if at else key)
        return out
    if isinstance(value, np.ndarray):
        return _json_value(value.tolist(), at)
    if isinstance(value, (list, tuple)):
        return [_json_value(item, f"{at}[{i}]") for i, item in enumerate(value)]
    if value is None or isinstance(value, str):
        return value
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        number = float(value)
        if not math.isfinite(number):
            raise InputError(f"{_GIVEN_MAP}: {where} is {number}, not a finite number")
        return number
    raise InputError(
        f"{_GIVEN_MAP}: {where} is of type {type(value).__qualname__}, not a JSON value "
        "(dict, list, str, int, float, bool or None)"
    )


def import_map(
    csv_path: _PathLike,
    out_path: Optional[_PathLike] = None,
    sigma: float = DEFAULT_LAMP_SIGMA_M,
    *,
    rig_path: Optional[RigLike] = None,
) -> dict[str, Any]:
    """Make a map from a hall's lighting plan or survey, as ``stereonav map import`` does.

    The plan is a CSV file (``docs/maps.md``, "A map from a lighting plan"): a header naming
    the columns ``x``, ``y``, ``z`` (metres, the hall's frame, z up) and optionally ``id`` (a
    non-negative integer; default: the row's index from 0) and ``sigma`` (the lamp's 1-sigma
    position uncertainty in metres, covariance ``sigma**2 I``; default: ``sigma``), in any
    order, then a row per lamp; blank lines and lines starting with ``#`` are skipped. It is
    read by the same Rust code as the command line, with the GIL released.

    The map has the lamps only: no calibration, no log (``source_log`` empty), the plan's file
    as ``source_plan``, and the rig only when ``rig_path`` is given (then the map is format
    version 1; without, version 2 and :func:`localize` needs a rig).

    Parameters
    ----------
    csv_path : str or os.PathLike
        The lighting plan (CSV).
    out_path : str or os.PathLike, optional
        Write the map there (replaced if it exists), the same file as ``stereonav map import
        --out`` writes (but for its ``created_unix_s``).
    sigma : float
        The 1-sigma position uncertainty of a lamp whose row gives none, metres (> 0).
        Default :data:`DEFAULT_LAMP_SIGMA_M` (0.02).
    rig_path : path or RigConfig, keyword-only, optional
        A rig to carry in the map, so that :func:`localize` needs none.

    Returns
    -------
    dict
        The map's body, as :func:`read_map` returns it.

    Raises
    ------
    InputTypeError
        (a ``TypeError``) an argument has the wrong type.
    InputError
        (a ``ValueError``) the plan cannot make a map: one line naming the file, the line and
        the problem (``hall.csv:1: the header has no 'z' column ...``, ``hall.csv:7: id 3 is
        given twice (first on line 4)``); ``sigma`` is not positive; the rig is not valid; a
        file cannot be read or written (the ``OSError`` is the ``__cause__``).

    Examples
    --------
    >>> m = stereonav.import_map("hall.csv", "hall.map", sigma=0.01)   # doctest: +SKIP
    >>> run = stereonav.localize("drive.mcap", "hall.map", "forklift.rig.toml")  # doctest: +SKIP
    """
    if isinstance(sigma, (bool, np.bool_)) or not isinstance(sigma, (int, float, np.integer, np.floating)):
        raise InputTypeError(f"sigma must be a float (metres), got {_describe(sigma)} {sigma!r}")
    body: dict[str, Any] = json.loads(
        _native.import_map(
            _path("csv_path", csv_path),
            None if out_path is None else _path("out_path", out_path),
            float(sigma),
            None if rig_path is None else _rig("rig_path", rig_path),
        )
    )
    return body
