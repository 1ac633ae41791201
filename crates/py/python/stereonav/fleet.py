"""A fleet's vehicle logs replayed on Dask (``vehicle-interfaces.md`` section 6).

:func:`replay_logs` replays every log as one Dask task (each a :func:`stereonav.replay`, in
Rust with the GIL released) and gathers one row per log into a pandas ``DataFrame``. A log
that cannot be replayed gives its one-line error in its row and stops nothing.

The dependencies come with the package's ``fleet`` extra::

    pip install "stereonav[fleet]"          # or, from a checkout: pip install "./crates/py[fleet]"

From a shell, ``python -m stereonav.fleet LOG... [--rig RIG] [--scheduler ADDR] --out TABLE``
writes the same table as CSV or Parquet (by the extension); see :func:`main`.

Why this module writes its own task function and row instead of ``dask.bag`` or
``dask.dataframe``: a row is a flat dict built from one replay's summary, a task per log is
all the parallelism there is, and the futures interface (``Client.map`` and
``as_completed``) gives each log's failure to its own row and the progress as logs finish.
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import sys
import uuid
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any, Optional, Union

# distributed's public functions carry no annotations: the calls into it are marked
# `type: ignore[no-untyped-call]` for mypy --strict (pandas is typed by pandas-stubs).
try:
    import distributed
    import pandas as pd
except ImportError as _missing:  # pragma: no cover - exercised in a subprocess by the tests
    raise ImportError(
        "stereonav.fleet needs Dask's distributed scheduler and pandas "
        f"({_missing.name or 'one of them'} is not installed): pip install 'stereonav[fleet]' "
        "(from a checkout: pip install './crates/py[fleet]')"
    ) from _missing

from ._errors import InputError, InputTypeError
from .navigation import replay
from .rig import CAMERA_PARAMETERS, VEHICLE_PARAMETERS, RigConfig

__all__ = ["COLUMNS", "FIXED_COLUMNS", "main", "replay_logs", "summary_row"]

#: The columns every table starts with (``vehicle-interfaces.md`` section 6).
FIXED_COLUMNS: tuple[str, ...] = (
    "log",
    "frames",
    "corrupt",
    "lost",
    "landmarks",
    "phase_switch_t_us",
    "error",
)

#: The errors against the simulator's truth that a row carries (``truth_<key>``), when the
#: log has truth (``SUMMARY.json``'s ``truth``); NaN otherwise.
_TRUTH_FLOATS: tuple[str, ...] = (
    "landmark_rms_m",
    "landmark_rms_aligned_m",
    "ate_rms_m",
    "ate_max_m",
    "heading_rms_rad",
)
_TRUTH_INTS: tuple[str, ...] = (
    "landmarks_matched",
    "landmarks_unmatched",
    "landmarks_duplicate",
    "lamps_missed",
)
#: ``SUMMARY.json``'s ``counts`` (the reader's, the decoder's and the association's counters).
_COUNTS: tuple[str, ...] = (
    "frames_processed",
    "bytes_skipped",
    "frames_out_of_order",
    "odometry",
    "stereo_matches",
    "tracks",
    "confirmed_tracks",
    "tracker_resets",
    "phase1_solves",
    "log_spans_lost",
    "log_bytes_lost",
    "log_chunks_lost",
    "log_time_lost_ms",
    "landmarks_merged",
    "features_outside_field",
    "loops_closed",
    "loops_refused",
    "lamps_held_mapped",
    "images_left",
    "images_right",
    "images_unpaired",
    "images_wrong_size",
    "images_unsupported",
    "images_undecodable",
    "image_frames_dropped",
)

_PARAMETERS: tuple[str, ...] = CAMERA_PARAMETERS + VEHICLE_PARAMETERS

#: Every column, in order, with its pandas dtype. Integers are nullable (``Int64``) so that a
#: failed log's row keeps the others' integers integral; ``error`` is None or a string.
_DTYPES: dict[str, str] = {
    "log": "object",
    "frames": "Int64",
    "corrupt": "Int64",
    "lost": "Int64",
    "landmarks": "Int64",
    "phase_switch_t_us": "Int64",
    "error": "object",
    **{c: d for p in _PARAMETERS for c, d in ((p, "float64"), (f"{p}_sigma", "float64"))},
    "phase1_skipped": "boolean",
    "pose_t_us": "Int64",
    "pose_x": "float64",
    "pose_y": "float64",
    "pose_theta": "float64",
    "warnings": "Int64",
    "warnings_text": "object",
    "damage": "object",
    **{f"counts_{c}": "Int64" for c in _COUNTS},
    **{f"truth_{k}": "float64" for k in _TRUTH_FLOATS},
    **{f"truth_{k}": "Int64" for k in _TRUTH_INTS},
    **{f"truth_{p}_error": "float64" for p in _PARAMETERS},
    "truth_pose_nees": "float64",
}

#: Every column of :func:`replay_logs`'s table, in order.
COLUMNS: tuple[str, ...] = tuple(_DTYPES)

PathLike = Union[str, "os.PathLike[str]"]
#: ``progress``: True (a line on stderr), False, or called as ``progress(done, total, row)``.
Progress = Union[bool, Callable[[int, int, Mapping[str, Any]], None]]


def summary_row(log: str, summary: Mapping[str, Any]) -> dict[str, Any]:
    """One table row from a replay's ``SUMMARY.json`` dict (:attr:`stereonav.Replay.summary`).

    The fixed columns, ``<parameter>`` and ``<parameter>_sigma`` for every parameter of ``C``
    and ``V``, the last pose, the warnings, the counters and, for a log with simulator truth,
    the errors against it. ``error`` is None for a log read whole; for a damaged log that was
    replayed as far as it goes (the summary's ``log_damage``) it is the damage in one line,
    the other columns filled.
    """
    row: dict[str, Any] = dict.fromkeys(COLUMNS)
    row.update(
        log=log,
        frames=summary["frames"],
        corrupt=summary["corrupt"],
        lost=summary["lost"],
        landmarks=len(summary["landmarks"]),
        phase_switch_t_us=summary["phase_switch_t_us"],
        phase1_skipped=summary.get("phase1_skipped"),
    )
    for group in ("camera", "vehicle"):
        for name, estimate in (summary.get(group) or {}).items():
            if name in _PARAMETERS:
                row[name] = estimate.get("value")
                row[f"{name}_sigma"] = estimate.get("sigma")
    pose = summary.get("pose")
    if pose is not None:
        row.update(pose_t_us=pose["t_us"], pose_x=pose["x"], pose_y=pose["y"])
        row["pose_theta"] = pose["theta"]
    warnings = list(summary.get("warnings") or [])
    row["warnings"] = len(warnings)
    row["warnings_text"] = "\n".join(warnings) if warnings else None
    row["damage"] = _damage(summary.get("log_damage"))
    if row["damage"] is not None:
        row["error"] = f"damaged log, replayed as far as it goes: {row['damage']}"
    counts = summary.get("counts") or {}
    for name in _COUNTS:
        row[f"counts_{name}"] = counts.get(name)
    truth = summary.get("truth")
    if truth is not None:
        for key in _TRUTH_FLOATS + _TRUTH_INTS:
            row[f"truth_{key}"] = truth.get(key)
        for group in ("camera", "vehicle"):
            for name, error in (truth.get(group) or {}).items():
                if name in _PARAMETERS:
                    row[f"truth_{name}_error"] = error
        consistency = truth.get("consistency") or {}
        row["truth_pose_nees"] = consistency.get("pose_nees")
    return row


def _damage(damage: Optional[Mapping[str, Any]]) -> Optional[str]:
    """``SUMMARY.json``'s ``log_damage`` in one line, or None for a log read whole.

    A damaged log that could be replayed (:func:`stereonav.replay` raises nothing for it) is
    replayed as far as it goes: this says what the reader could not read."""
    if damage is None:
        return None
    parts = [f"{damage.get('spans_total', 0)} stretches ({damage.get('bytes_lost', 0)} bytes) lost"]
    lost = damage.get("messages_lost") or {}
    if lost:
        parts.append(
            "messages lost: " + ", ".join(f"{topic} {n}" for topic, n in sorted(lost.items()))
        )
    for flag, text in (
        ("header_damaged", "header damaged"),
        ("tail_damaged", "tail damaged"),
        ("cut", "cut short"),
    ):
        if damage.get(flag):
            parts.append(text)
    if damage.get("summary") not in (None, "intact"):
        parts.append(f"summary {damage['summary']}")
    return "; ".join(parts)


def _one_line(error: BaseException) -> str:
    """An exception as the one line a row carries: its message's first line, or its type."""
    text = str(error).strip()
    line = text.splitlines()[0] if text else ""
    return line or type(error).__name__


def _error_row(log: str, message: str) -> dict[str, Any]:
    row: dict[str, Any] = dict.fromkeys(COLUMNS)
    row.update(log=log, error=message)
    return row


def _replay_row(
    log: str, path: str, rig: Union[None, str, RigConfig], options: Mapping[str, Any]
) -> dict[str, Any]:
    """The Dask task: one log replayed, as its row; a failure is the row's error."""
    try:
        result = replay(path, rig, **options)
    except Exception as error:  # every failure of this log belongs in its row
        return _error_row(log, _one_line(error))
    except BaseException as error:  # pyo3's PanicException derives from BaseException
        if isinstance(error, (KeyboardInterrupt, SystemExit, GeneratorExit)):
            raise
        return _error_row(log, f"internal error replaying the log: {_one_line(error)}")
    return summary_row(log, result.summary)


def _table(rows: Sequence[Mapping[str, Any]]) -> pd.DataFrame:
    """The rows as a ``DataFrame`` with :data:`COLUMNS` and their dtypes."""
    frame = pd.DataFrame.from_records(list(rows), columns=list(COLUMNS))
    frame = frame.astype({c: d for c, d in _DTYPES.items() if d != "object"})
    # Missing strings stay None (not NaN): a good row's ``error`` is None.
    for column in ("log", "error", "warnings_text", "damage"):
        frame[column] = pd.Series(
            [row[column] for row in rows], index=frame.index, dtype="object"
        )
    return frame


def _log_paths(log_paths: object) -> list[str]:
    if isinstance(log_paths, (str, bytes, os.PathLike)):
        raise InputTypeError(
            "log_paths must be a list of log paths, got one path: wrap it in a list"
        )
    if not isinstance(log_paths, Iterable):
        raise InputTypeError(
            f"log_paths must be a list of log paths, got {type(log_paths).__qualname__}"
        )
    paths = []
    for i, path in enumerate(log_paths):
        if not isinstance(path, (str, os.PathLike)):
            raise InputTypeError(
                f"log_paths[{i}] must be a str or os.PathLike, got {type(path).__qualname__}"
            )
        text = os.fspath(path)
        if not isinstance(text, str):
            raise InputTypeError(f"log_paths[{i}] must be a str path, got bytes")
        paths.append(text)
    return paths


class _Reporter:
    """``progress=True``: how many logs are done, on stderr (in place on a terminal)."""

    def __init__(self, total: int) -> None:
        self.total = total
        self.failed = 0
        self.tty = sys.stderr.isatty()
        self.step = max(1, math.ceil(total / 10))

    def __call__(self, done: int, total: int, row: Mapping[str, Any]) -> None:
        self.failed += row.get("frames") is None  # a damaged log replayed is no failure
        if not self.tty and done % self.step and done != total:
            return
        line = f"fleet: {done}/{total} logs replayed, {self.failed} failed"
        end = "\n" if not self.tty or done == total else ""
        print(("\r" if self.tty else "") + line, end=end, file=sys.stderr, flush=True)


def replay_logs(
    log_paths: Iterable[PathLike],
    rig_path: Union[None, PathLike, RigConfig] = None,
    *,
    scheduler: Union[None, str, distributed.Client] = None,
    n_workers: Optional[int] = None,
    skip_phase1: bool = False,
    phase1_frames: Optional[int] = None,
    consider_camera: bool = False,
    left: Optional[str] = None,
    right: Optional[str] = None,
    odom: Optional[str] = None,
    progress: Progress = True,
) -> pd.DataFrame:
    """Replay many vehicle logs in parallel on Dask, one row per log.

    Each log is one task running :func:`stereonav.replay` (in Rust, the GIL released) on a
    Dask worker; the task sends back only its row. The row of a log equals what a one-by-one
    ``stereonav.replay(log, rig_path)`` gives (:func:`summary_row` of its summary).

    Parameters
    ----------
    log_paths : iterable of str or os.PathLike
        The logs. Relative paths are taken from this process's working directory; the workers
        must see the same files (the same machine, or a shared file system).
    rig_path : str, os.PathLike or RigConfig, optional
        The rig file for every log (read by each worker with the command line's reader: every
        table, the lenses and ``[vehicle]`` included), or a :class:`stereonav.RigConfig` (sent
        to the workers as its TOML text); default: each log's ``/rig`` message.
    scheduler : None, str or distributed.Client, keyword-only
        None: a local cluster on this machine (``n_workers`` processes of one thread each),
        closed at the end. A string: the address of an existing Dask scheduler
        (``"tcp://127.0.0.1:8786"``), whose workers must have ``stereonav[fleet]`` installed.
        A ``distributed.Client``: used as it is and left open.
    n_workers : int, keyword-only
        The local cluster's worker processes; default: the CPU cores. Only with
        ``scheduler=None``.
    skip_phase1, phase1_frames, consider_camera : keyword-only
        As for :func:`stereonav.replay`, for every log.
    left, right, odom : str, keyword-only
        The topics of ROS 2 bags with camera images (``vehicle-interfaces.md`` 4.1), all
        three or none, as for :func:`stereonav.replay`: every log is then such a bag with
        these topics (a fleet records under the same names), and the rig is needed
        (``rig_path``). Checked here, before any task starts.
    progress : bool or callable, keyword-only
        True (default): how many logs are done, on stderr. False: silent. A callable: called
        as ``progress(done, total, row)`` in this process as each log finishes.

    Returns
    -------
    pandas.DataFrame
        One row per log, in the order of ``log_paths``, with :data:`COLUMNS`: ``log`` (the
        path as given), ``frames``, ``corrupt``, ``lost``, ``landmarks`` (the map's size),
        ``phase_switch_t_us``, ``error`` (None for a log read whole and replayed; else one
        line: why the log failed, its other columns then missing, or, for a damaged log
        replayed as far as it goes, what was lost, its other columns filled), ``<parameter>`` and
        ``<parameter>_sigma`` for every parameter of :data:`stereonav.CAMERA_PARAMETERS` and
        :data:`stereonav.VEHICLE_PARAMETERS`, ``phase1_skipped``, the last pose
        (``pose_t_us``, ``pose_x``, ``pose_y``, ``pose_theta``), ``warnings`` (how many) and
        ``warnings_text`` (one per line), ``damage`` (None, or what the reader of a damaged
        log could not read, in one line: such a log is replayed as far as it goes), the
        summary's ``counts_<name>`` and, for a log
        with simulator truth, ``truth_<error>`` (NaN without). Integer columns are pandas'
        nullable ``Int64``.

    Raises
    ------
    InputTypeError
        (a ``TypeError``) ``log_paths`` is one path or holds something other than paths; an
        option has the wrong type.
    InputError
        (a ``ValueError``) ``n_workers`` is given with a scheduler, or is below 1; one or two
        of ``left``, ``right``, ``odom`` are named (the message names the missing ones).
    OSError
        The scheduler cannot be reached (Dask's own error).

    Examples
    --------
    >>> from stereonav import fleet                                # doctest: +SKIP
    >>> table = fleet.replay_logs(["monday.mcap", "tuesday.mcap"])  # doctest: +SKIP
    >>> table[["log", "frames", "baseline", "baseline_sigma", "error"]]  # doctest: +SKIP
    """
    logs = _log_paths(log_paths)
    rig: Union[None, str, RigConfig] = None
    if isinstance(rig_path, RigConfig):
        rig = rig_path
    elif rig_path is not None:
        if not isinstance(rig_path, (str, os.PathLike)):
            raise InputTypeError(
                "rig_path must be the path of a rig file (the workers read it) or a "
                f"stereonav.RigConfig, got {type(rig_path).__qualname__}"
            )
        rig = os.path.abspath(os.fspath(rig_path))
    named = {"left": left, "right": right, "odom": odom}
    for name, topic in named.items():
        if not (topic is None or isinstance(topic, str)):
            raise InputTypeError(
                f"{name} must be a topic name (str) or None, got {type(topic).__qualname__}"
            )
    missing = [name for name, topic in named.items() if topic is None]
    if 0 < len(missing) < len(named):
        given = ", ".join(f"{name}={topic!r}" for name, topic in named.items() if topic is not None)
        raise InputError(
            "a ROS 2 bag is read with all three topics named (left, right and odom) or none: "
            f"{' and '.join(missing)} missing (given {given})"
        )
    options: dict[str, Any] = {
        "skip_phase1": skip_phase1,
        "phase1_frames": phase1_frames,
        "consider_camera": consider_camera,
        **({} if missing else named),
    }
    if not (isinstance(progress, bool) or callable(progress)):
        raise InputTypeError(
            f"progress must be a bool or a callable, got {type(progress).__qualname__}"
        )
    if n_workers is not None:
        if scheduler is not None:
            raise InputError("n_workers is for the local cluster only (scheduler=None)")
        if isinstance(n_workers, bool) or not isinstance(n_workers, int):
            raise InputTypeError(f"n_workers must be an int, got {type(n_workers).__qualname__}")
        if n_workers < 1:
            raise InputError(f"n_workers {n_workers} must be at least 1")
    if not (scheduler is None or isinstance(scheduler, (str, distributed.Client))):
        raise InputTypeError(
            "scheduler must be None, a scheduler address or a distributed.Client, "
            f"got {type(scheduler).__qualname__}"
        )
    if not logs:
        return _table([])
    report: Optional[Callable[[int, int, Mapping[str, Any]], None]]
    report = _Reporter(len(logs)) if progress is True else (progress or None)

    cluster = None
    if isinstance(scheduler, distributed.Client):
        client, own_client = scheduler, False
    else:
        if scheduler is None:
            cluster = distributed.LocalCluster(  # type: ignore[no-untyped-call]
                n_workers=n_workers or os.cpu_count() or 1,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                # The scheduler serves HTTP (health, metrics) even without the dashboard,
                # on port 8787 unless told otherwise: any free port, so that a second
                # cluster or scheduler on the machine neither clashes nor warns.
                scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
                silence_logs=logging.ERROR,
            )
            client = distributed.Client(cluster)  # type: ignore[no-untyped-call]
        else:
            client = distributed.Client(scheduler)  # type: ignore[no-untyped-call]
        own_client = True
    # Unique task keys: a scheduler shared by several callers must never mix their tasks.
    batch = uuid.uuid4().hex
    try:
        futures = [
            client.submit(
                _replay_row,
                log,
                os.path.abspath(log),
                rig,
                options,
                key=f"stereonav-replay-{batch}-{i}",
                pure=False,
            )
            for i, log in enumerate(logs)
        ]
        index = {future.key: i for i, future in enumerate(futures)}
        rows: list[Optional[dict[str, Any]]] = [None] * len(logs)
        for done, future in enumerate(distributed.as_completed(futures), start=1):  # type: ignore[no-untyped-call]
            i = index[future.key]
            try:
                row = future.result()
            except Exception as error:  # the task itself failed: a worker died on it
                row = _error_row(
                    logs[i], f"the Dask task replaying the log failed: {_one_line(error)}"
                )
            rows[i] = row
            if report is not None:
                report(done, len(logs), row)
        return _table([row for row in rows if row is not None])
    finally:
        if own_client:
            client.close()  # type: ignore[no-untyped-call]
        if cluster is not None:
            cluster.close()


def main(argv: Optional[Sequence[str]] = None) -> int:
    """``python -m stereonav.fleet LOG... [--rig RIG] [--scheduler ADDR] [--workers N] --out TABLE``.

    With ``--skip-phase1``, ``--phase1-frames N``, ``--consider-camera`` and a ROS 2 bag's
    ``--left TOPIC --right TOPIC --odom TOPIC`` as for ``stereonav replay``.

    Replays the logs with :func:`replay_logs` and writes the table to ``TABLE``: CSV
    (``.csv``) or Parquet (``.parquet``, ``.pq``; needs pyarrow, which the ``fleet`` extra
    brings). Prints how many logs failed; exit status 0 when the table is written (the
    failures are in its ``error`` column), 2 for bad arguments or a table that cannot be
    written.
    """
    parser = argparse.ArgumentParser(
        prog="python -m stereonav.fleet",
        description="Replay many vehicle logs on Dask into one table, a row per log.",
    )
    parser.add_argument("logs", nargs="+", metavar="LOG", help="vehicle logs (MCAP)")
    parser.add_argument("--rig", help="rig file for every log (default: each log's /rig)")
    parser.add_argument(
        "--scheduler", help="address of an existing Dask scheduler (default: a local cluster)"
    )
    parser.add_argument("--workers", type=int, help="local cluster's workers (default: cores)")
    parser.add_argument("--out", required=True, help="the table: .csv or .parquet")
    parser.add_argument(
        "--skip-phase1", action="store_true", help="as stereonav replay --skip-phase1"
    )
    parser.add_argument(
        "--phase1-frames", type=int, metavar="N", help="as stereonav replay --phase1-frames"
    )
    parser.add_argument(
        "--consider-camera", action="store_true", help="as stereonav replay --consider-camera"
    )
    for option, what in (
        ("--left", "left camera"),
        ("--right", "right camera"),
        ("--odom", "odometry"),
    ):
        parser.add_argument(
            option,
            metavar="TOPIC",
            help=f"every log is a ROS 2 bag: its {what} topic (all three of --left --right "
            "--odom, as stereonav replay)",
        )
    parser.add_argument("--no-progress", action="store_true", help="no progress on stderr")
    args = parser.parse_args(argv)
    topics = {"--left": args.left, "--right": args.right, "--odom": args.odom}
    missing = [option for option, topic in topics.items() if topic is None]
    if 0 < len(missing) < len(topics):
        parser.error(f"--left, --right and --odom go together: {' and '.join(missing)} missing")
    extension = os.path.splitext(args.out)[1].lower()
    if extension not in (".csv", ".parquet", ".pq"):
        parser.error(f"--out {args.out}: the table must be .csv or .parquet")
    if args.workers is not None and args.scheduler is not None:
        parser.error("--workers is for the local cluster only (without --scheduler)")
    try:
        table = replay_logs(
            args.logs,
            args.rig,
            scheduler=args.scheduler,
            n_workers=args.workers,
            skip_phase1=args.skip_phase1,
            phase1_frames=args.phase1_frames,
            consider_camera=args.consider_camera,
            left=args.left,
            right=args.right,
            odom=args.odom,
            progress=not args.no_progress,
        )
    except (InputError, InputTypeError, OSError) as error:
        print(f"stereonav fleet: error: {_one_line(error)}", file=sys.stderr)
        return 2
    try:
        if extension == ".csv":
            table.to_csv(args.out, index=False)
        else:
            table.to_parquet(args.out, index=False)
    except (OSError, ImportError, ValueError) as error:
        print(f"stereonav fleet: error: {args.out}: {_one_line(error)}", file=sys.stderr)
        return 2
    failed = int((table["error"].notna() & table["frames"].isna()).sum())
    damaged = int(table["damage"].notna().sum())
    print(
        f"{args.out}: {len(table)} logs, {failed} failed, "
        f"{damaged} damaged (replayed as far as they go)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
