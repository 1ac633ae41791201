#!/usr/bin/env python3
"""Measure the memory (time constant) of a vehicle's odometry errors from a recorded drive.

Compares the odometry of a drive with its ground truth and reports the numbers of the rig
file's ``[noise]`` table (vehicle-interfaces.md v3, sections 2 and 3): ``velocity``,
``yaw_rate`` (stationary 1-sigma per odometry sample) and ``velocity_tau``, ``yaw_rate_tau``
(time constant of a first-order Gauss-Markov error process; 0 = white). See
docs/odometry-memory.md.

    python3 scripts/odometry_memory.py --odometry ODOM.csv --truth TRUTH.csv [--step 0.1]
        [--fit-scale] [--fit-cross] [--per-drive] [--no-sweep]
    python3 scripts/odometry_memory.py --selftest

(numpy is the only package it needs; in this repository ``.venv/bin/python`` has it.)

``ODOM.csv`` has a header row and the columns ``t,vx,vy,vtheta`` (s, m/s, m/s, rad/s; robot
frame, each sample held from its timestamp until the next). ``TRUTH.csv`` has a header row
and ``t,x,y,theta`` (s, m, m, rad): the robot's pose in any fixed frame, on the same clock.
Other columns are ignored. ``--odometry``/``--truth`` may be repeated, in pairs, to pool
several drives of the same vehicle.

Method
------
1. A regular grid ``t_k = t_0 + k * step`` covers the time both files cover.
2. For each step ``[t_k, t_k + step]`` the held odometry samples are integrated exactly
   (constant velocities on each piece, composed on SE(2)) into a displacement
   ``(dx, dy, dtheta)`` in the robot frame at ``t_k``. The truth (interpolated linearly in
   x, y and unwrapped theta at the grid times) gives its displacement over the same step,
   expressed in its own robot frame at ``t_k``. (odometry - truth) / step is one velocity error
   sample for each of vx, vy, vtheta.
3. Each axis's mean (a bias) is removed; with ``--fit-scale`` a least-squares fit
   ``error = a + b * v`` is removed instead, ``v`` being the axis's true velocity over the
   step (``b`` = scale error, ``odom_scale - 1``). Noise in ``v`` biases ``b`` (a robot that
   never moves sideways has a truth vy that is all noise, and b = -1), so an axis is a
   regressor only when its odometry velocity varies and its errors are at most 5 % of its
   velocity's variance; otherwise only its mean is removed and the report says why.
   With ``--fit-cross`` the fit also takes the other two axes' true velocities, which
   absorbs systematic errors such as unequal wheel diameters (a yaw-rate error while
   driving straight) or a truth reference point that is not the odometry's (a vx or vy
   error while turning). Without it, the report says when the residual still follows
   another axis's true velocity. With several drives the fit is on all their steps
   together, or with ``--per-drive`` on each drive alone (for drives whose calibration
   differs: what stays constant through a drive is then not counted as memory).
4. On the residual of each axis: the stationary sigma, the autocorrelation r(L) at lags of
   1, 2, 5 and 10 steps, ``rho = r(1)`` and ``tau = -step / ln(rho)`` (when 0 < rho < 1).
5. An error sample is the *mean* of the odometry's held errors over a step. When the odometry
   is sampled faster than the step (n samples a step), that mean of a first-order process
   is no longer first-order on the grid: its lag-1 correlation is higher than
   ``exp(-step/tau)`` (for tau = 0.6 s, 100 Hz odometry and 0.1 s steps: 0.90 instead of
   0.85) and its sigma a little lower. The script therefore also fits tau to r(1) with the
   exact correlation of n-sample means of a first-order process whose per-sample
   correlation is ``exp(-period/tau)``, and converts the sigma per step to the sigma per
   odometry sample with that model. With n = 1 (odometry period = step) both are the plain
   values. These corrected values are the ones for the rig file.
6. The measured r(2), r(5), r(10) are compared with rho^L and with the model's prediction, and
   the tau implied by each lag is printed: a first-order process gives the same tau at every
   lag. The fit is called good when every lag is within max(2 standard errors (Bartlett's
   formula), 0.05) of the model.
7. The whole analysis is repeated at 2, 5, 10, 20 and 50 times the step (while there are at
   least 50 samples) and summarised in one table: for first-order errors tau and
   sigma/sample come out about the same at every step. Noise of the truth's positions (or
   jitter of the timestamps) falls as 1/step and shows as a negative rho(1) at short
   steps; a memory longer than the steps shows as tau growing with the step.

Assumptions: the truth is much more precise over one step than the odometry; the truth's
pose is of the same point and heading as the odometry (see --fit-cross); both are on
one clock; the truth is sampled at least as often as the grid (a coarser truth, linearly
interpolated, makes neighbouring errors look correlated); the errors are stationary.

Bad input (unreadable file, missing column, a value that is not a finite number, time that
does not increase, too few samples) gives a one-line error on stderr and exit code 2.
"""

from __future__ import annotations

import argparse
import csv
import io
import math
import sys
from dataclasses import dataclass, field
from typing import Iterable, NoReturn, Sequence

try:
    import numpy as np
except ImportError:  # pragma: no cover - depends on the machine
    sys.stderr.write(
        "odometry_memory.py: error: needs numpy (pip install numpy, or run with .venv/bin/python)\n"
    )
    sys.exit(1)

PROG = "odometry_memory.py"
DEFAULT_STEP_S = 0.1
#: Lags (in steps) whose autocorrelation is compared with the first-order model.
REPORT_LAGS = (2, 5, 10)
#: Multiples of the step at which the analysis is repeated for the report's sweep table.
SWEEP_FACTORS = (1, 2, 5, 10, 20, 50)
#: Fewest error samples (steps, pooled over drives) the statistics are computed from.
MIN_STEPS = 50
#: Most grid steps one drive may have (guards against times in microseconds).
MAX_STEPS = 20_000_000
#: A lag fits the first-order model when within max(2 standard errors, this).
FIT_TOLERANCE_FLOOR = 0.05
#: A velocity is a regressor of the scale fits only while the errors of its axis have at
#: most this share of its variance (errors in the regressor bias the fit by about as much).
REGRESSOR_NOISE_SHARE = 0.05
#: A sampling interval this much longer than expected counts as coarse or as a gap.
COARSE_FACTOR = 1.05
GAP_FACTOR = 5.0
ODOM_COLUMNS = ("t", "vx", "vy", "vtheta")
TRUTH_COLUMNS = ("t", "x", "y", "theta")
AXES = ("vx", "vy", "vtheta")
UNITS = {"vx": "m/s", "vy": "m/s", "vtheta": "rad/s"}


class InputError(Exception):
    """Bad input: reported as one line on stderr with exit code 2."""


# ---------------------------------------------------------------------------------------------
# Reading


def read_table(lines: Iterable[str], columns: Sequence[str], label: str) -> dict[str, np.ndarray]:
    """Parse CSV text with a header row into one float array per wanted column.

    Every value must be a finite number and ``t`` (the first wanted column) must increase.
    """
    header: list[str] | None = None
    col_index: list[int] = []
    rows: list[list[float]] = []
    line_numbers: list[int] = []
    try:
        reader = csv.reader(lines)
        for row in reader:
            line_no = reader.line_num
            if not row or all(not cell.strip() for cell in row):
                continue
            if header is None:
                header = [cell.strip().lstrip("\ufeff").strip() for cell in row]
                missing = [c for c in columns if c not in header]
                if missing:
                    raise InputError(
                        f"{label}: missing column(s) {', '.join(missing)} "
                        f"(header: {','.join(header)}; need {','.join(columns)})"
                    )
                col_index = [header.index(c) for c in columns]
                continue
            values = []
            for name, i in zip(columns, col_index):
                if i >= len(row) or not row[i].strip():
                    raise InputError(f"{label} line {line_no}: no value in column {name}")
                text = row[i].strip()
                try:
                    value = float(text)
                except ValueError:
                    raise InputError(
                        f"{label} line {line_no}: column {name}: {text!r} is not a number"
                    ) from None
                if not math.isfinite(value):
                    raise InputError(
                        f"{label} line {line_no}: column {name} is {text} (not a finite number)"
                    )
                values.append(value)
            rows.append(values)
            line_numbers.append(line_no)
    except csv.Error as err:
        raise InputError(f"{label}: not readable as CSV ({err})") from None
    except UnicodeDecodeError:
        raise InputError(f"{label}: not a text file (UTF-8)") from None
    if header is None:
        raise InputError(f"{label}: empty (no header row)")
    if len(rows) < 2:
        raise InputError(f"{label}: {len(rows)} data row(s), need at least 2")
    table = np.asarray(rows, dtype=float)
    t = table[:, 0]
    bad = np.flatnonzero(np.diff(t) <= 0.0)
    if bad.size:
        k = int(bad[0])
        raise InputError(
            f"{label} line {line_numbers[k + 1]}: time does not increase "
            f"(t = {float(t[k + 1])!r} after t = {float(t[k])!r})"
        )
    return {name: table[:, j].copy() for j, name in enumerate(columns)}


def read_csv_file(path: str, columns: Sequence[str], label: str) -> dict[str, np.ndarray]:
    """Read one input file (see :func:`read_table`); any OS error is an :class:`InputError`."""
    try:
        with open(path, encoding="utf-8-sig", newline="") as handle:
            return read_table(handle, columns, f"{label} {path}")
    except OSError as err:
        raise InputError(f"{label} {path}: {err.strerror or err}") from None


# ---------------------------------------------------------------------------------------------
# Kinematics


def _arc_terms(phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``sin(phi)/phi`` and ``(1 - cos(phi))/phi``, with their series near 0."""
    small = np.abs(phi) < 1e-4
    safe = np.where(small, 1.0, phi)
    a = np.where(small, 1.0 - phi * phi / 6.0, np.sin(safe) / safe)
    b = np.where(small, phi / 2.0 - phi**3 / 24.0, (1.0 - np.cos(safe)) / safe)
    return a, b


def integrate_held(
    t_samples: np.ndarray, velocities: Sequence[np.ndarray], times: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pose ``(x, y, theta)`` at each of ``times``, starting from 0 at ``times[0]``.

    Robot-frame velocities ``(vx, vy, vtheta)`` are held from each sample's time until the
    next; every constant piece is an exact arc on SE(2). ``times`` must increase and start at
    or after ``t_samples[0]``.
    """
    vx_s, vy_s, w_s = (np.asarray(v, dtype=float) for v in velocities)
    inside = t_samples[(t_samples > times[0]) & (t_samples < times[-1])]
    breaks = np.union1d(times, inside)
    h = np.diff(breaks)
    held = np.searchsorted(t_samples, breaks[:-1], side="right") - 1
    vx, vy, w = vx_s[held], vy_s[held], w_s[held]
    phi = w * h
    a, b = _arc_terms(phi)
    local_x = h * (vx * a - vy * b)
    local_y = h * (vx * b + vy * a)
    theta = np.concatenate(([0.0], np.cumsum(phi)))
    c, s = np.cos(theta[:-1]), np.sin(theta[:-1])
    x = np.concatenate(([0.0], np.cumsum(c * local_x - s * local_y)))
    y = np.concatenate(([0.0], np.cumsum(s * local_x + c * local_y)))
    at = np.searchsorted(breaks, times)
    return x[at], y[at], theta[at]


def robot_frame_steps(
    x: np.ndarray, y: np.ndarray, theta: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Displacement between consecutive poses, in the robot frame of the first of each pair."""
    dx_w, dy_w = np.diff(x), np.diff(y)
    c, s = np.cos(theta[:-1]), np.sin(theta[:-1])
    return c * dx_w + s * dy_w, -s * dx_w + c * dy_w, np.diff(theta)


# ---------------------------------------------------------------------------------------------
# Error samples of one drive


@dataclass
class DriveErrors:
    """Velocity error samples of one drive on the grid."""

    label: str
    errors: np.ndarray  # (K, 3): odometry - truth, per axis, m/s and rad/s
    truth_velocity: np.ndarray  # (K, 3): truth displacement / step (the fits' regressors)
    odom_velocity: np.ndarray  # (K, 3): odometry displacement / step
    odom_intervals: np.ndarray  # odometry sample intervals inside the compared time
    truth_intervals: np.ndarray
    start_s: float
    notes: list[str] = field(default_factory=list)


def drive_errors(
    odom: dict[str, np.ndarray], truth: dict[str, np.ndarray], step: float, label: str
) -> DriveErrors:
    """Velocity errors of one drive on a regular grid of ``step`` seconds (method steps 1-2)."""
    t_odom, t_truth = odom["t"], truth["t"]
    start = max(t_odom[0], t_truth[0])
    end = min(t_odom[-1], t_truth[-1])
    if end <= start:
        raise InputError(
            f"{label}: odometry ({t_odom[0]:g}..{t_odom[-1]:g} s) and truth "
            f"({t_truth[0]:g}..{t_truth[-1]:g} s) do not overlap in time"
        )
    count = math.floor((end - start) / step + 1e-9)
    if count > MAX_STEPS:
        raise InputError(
            f"{label}: {count} steps of {step:g} s; are the times in seconds?"
        )
    if count < 2:
        raise InputError(
            f"{label}: odometry and truth overlap for {end - start:g} s, "
            f"fewer than 2 steps of {step:g} s"
        )
    grid = start + step * np.arange(count + 1)
    grid[-1] = min(grid[-1], end)

    ox, oy, oth = integrate_held(t_odom, (odom["vx"], odom["vy"], odom["vtheta"]), grid)
    odom_steps = np.column_stack(robot_frame_steps(ox, oy, oth))
    theta_truth = np.unwrap(truth["theta"])
    tx = np.interp(grid, t_truth, truth["x"])
    ty = np.interp(grid, t_truth, truth["y"])
    tth = np.interp(grid, t_truth, theta_truth)
    truth_steps = np.column_stack(robot_frame_steps(tx, ty, tth))
    widths = np.diff(grid)[:, None]
    errors = (odom_steps - truth_steps) / widths
    truth_velocity = truth_steps / widths
    odom_velocity = odom_steps / widths

    def intervals(t: np.ndarray) -> np.ndarray:
        lo = max(np.searchsorted(t, grid[0], side="right") - 1, 0)
        hi = np.searchsorted(t, grid[-1], side="left") + 1
        return np.diff(t[lo:hi])

    drive = DriveErrors(
        label,
        errors,
        truth_velocity,
        odom_velocity,
        intervals(t_odom),
        intervals(t_truth),
        float(start),
    )
    for what, dt in (("odometry", drive.odom_intervals), ("truth", drive.truth_intervals)):
        if dt.size == 0:
            continue
        median = float(np.median(dt))
        gaps = int(np.count_nonzero(dt > GAP_FACTOR * median))
        if gaps:
            drive.notes.append(
                f"{label}: {what} has {gaps} gap(s) longer than {GAP_FACTOR:g} x its median "
                f"interval of {median:.4g} s (longest {float(dt.max()):.4g} s); the gaps are "
                f"bridged ({'samples held' if what == 'odometry' else 'interpolated'})"
            )
    return drive


# ---------------------------------------------------------------------------------------------
# First-order (Gauss-Markov) model of step means


def window_acf(lag: int, tau: float, period: float, n: int) -> float:
    """Correlation, ``lag`` steps apart, of step means of a first-order process.

    Each step is the mean of ``n`` held odometry samples ``period`` apart whose errors are a
    first-order Gauss-Markov process of time constant ``tau`` (per-sample correlation
    ``r = exp(-period / tau)``): var = (n + 2 sum_j (n - j) r^j) / n^2 and, for lag >= 1,
    cov = r^((lag - 1) n + 1) (sum_j r^j)^2 / n^2.
    """
    if lag == 0:
        return 1.0
    if tau <= 0.0:
        return 0.0
    r = math.exp(-period / tau)
    j = np.arange(1, n)
    var = n + 2.0 * float(np.sum((n - j) * r**j))
    s = float(np.sum(r ** np.arange(n)))
    return r ** ((lag - 1) * n + 1) * s * s / var


def variance_factor(tau: float, period: float, n: int) -> float:
    """Variance of a step mean of ``n`` samples over the per-sample variance (<= 1)."""
    if n <= 1:
        return 1.0
    if tau <= 0.0:
        return 1.0 / n
    r = math.exp(-period / tau)
    j = np.arange(1, n)
    return (n + 2.0 * float(np.sum((n - j) * r**j))) / (n * n)


def tau_for_correlation(target: float, lag: int, period: float, n: int) -> float | None:
    """The tau whose :func:`window_acf` at ``lag`` equals ``target``; None outside (0, 1)."""
    if not 0.0 < target < 1.0:
        return None
    lo, hi = 1e-6 * period, 1e7 * period * max(n, 1)
    if window_acf(lag, hi, period, n) <= target:
        return None
    for _ in range(200):
        mid = math.sqrt(lo * hi)
        if window_acf(lag, mid, period, n) < target:
            lo = mid
        else:
            hi = mid
        if hi / lo < 1.0 + 1e-10:
            break
    return math.sqrt(lo * hi)


def bartlett_se(lag: int, acf: np.ndarray, samples: int, max_lag: int) -> float:
    """Standard error of a measured autocorrelation at ``lag`` (Bartlett's formula).

    ``acf[k]`` is the model's autocorrelation at lag k, for k up to ``max_lag + lag``; the
    sum runs over lags -max_lag..max_lag.
    """
    k = np.arange(-max_lag, max_lag + 1)

    def at(offsets: np.ndarray) -> np.ndarray:
        return np.asarray(np.take(acf, np.abs(offsets)), dtype=float)

    rl = float(acf[lag])
    terms = (
        at(k) ** 2
        + at(k + lag) * at(k - lag)
        - 4.0 * rl * at(k) * at(k - lag)
        + 2.0 * at(k) ** 2 * rl**2
    )
    return math.sqrt(max(float(np.sum(terms)), 0.0) / samples)


# ---------------------------------------------------------------------------------------------
# Statistics per axis


@dataclass
class LagResult:
    lag: int
    measured: float | None
    rho_power: float | None
    model: float | None
    tolerance: float | None
    tau_implied: float | None


@dataclass
class AxisResult:
    axis: str
    bias: float
    scale: float | None  # fitted b (error per unit of own true velocity), when estimable
    scale_note: str | None  # why there is no scale
    scale_removed: bool
    cross: dict[str, float]  # error per unit of another axis's true velocity
    cross_removed: bool
    cross_share: float  # fraction of the kept residual's variance the cross terms explain
    sigma_step: float
    rho: float | None
    tau_plain: float | None
    tau: float | None  # corrected for averaging over the step (the rig-file value)
    sigma_sample: float
    lags: list[LagResult]
    fits: bool | None


@dataclass
class Analysis:
    step: float
    drives: list[DriveErrors]
    samples: int
    period: float
    per_step: int
    truth_period: float
    axes: dict[str, AxisResult]
    notes: list[str]
    per_drive: bool = False


def _lag_sums(series: list[np.ndarray], lag: int) -> tuple[float, int]:
    total, pairs = 0.0, 0
    for e in series:
        if e.size > lag:
            total += float(np.dot(e[:-lag] if lag else e, e[lag:]))
            pairs += e.size - lag
    return total, pairs


def autocorrelation(series: list[np.ndarray], lag: int) -> float | None:
    """Pooled autocorrelation at ``lag`` of zero-mean series (mean product / mean square)."""
    c0, n0 = _lag_sums(series, 0)
    cl, nl = _lag_sums(series, lag)
    if nl == 0 or c0 <= 0.0:
        return None
    return (cl / nl) / (c0 / n0)


def analyse_axis(
    axis: str,
    drives: list[DriveErrors],
    step: float,
    period: float,
    per_step: int,
    fit_scale: bool,
    fit_cross: bool,
    per_drive: bool,
) -> AxisResult:
    j = AXES.index(axis)
    error = np.concatenate([d.errors[:, j] for d in drives])
    truth = np.concatenate([d.truth_velocity for d in drives])
    odom_velocity = np.concatenate([d.odom_velocity for d in drives])
    all_errors = np.concatenate([d.errors for d in drives])
    samples = error.size
    ones = np.ones(samples)

    def why_not_regressor(k: int) -> str | None:
        """None when the true velocity of axis k can be a regressor, else the reason."""
        varies = float(np.std(odom_velocity[:, k]))
        if varies <= 1e-12 * max(1.0, float(np.max(np.abs(odom_velocity[:, k])))):
            return "its odometry velocity does not vary"
        truth_var = float(np.var(truth[:, k]))
        if truth_var <= 1e-24 * max(1.0, float(np.max(np.abs(truth[:, k]))) ** 2):
            return "its true velocity does not vary"
        share = float(np.var(all_errors[:, k])) / truth_var
        if share > REGRESSOR_NOISE_SHARE:
            size = f"{100 * share:.0f} % of" if share < 10.0 else "more than 10 times"
            return f"its errors are {size} its velocity's variance, a fit would be biased"
        return None

    own_reason = why_not_regressor(j)
    others = [a for k, a in enumerate(AXES) if k != j and why_not_regressor(k) is None]

    starts = np.cumsum([0] + [d.errors.shape[0] for d in drives])
    pieces = (
        [slice(int(starts[i]), int(starts[i + 1])) for i in range(len(drives))]
        if per_drive
        else [slice(0, samples)]
    )

    def fit(names: list[str]) -> tuple[dict[str, float], np.ndarray]:
        """Least squares on all steps, or on each drive (coefficients: mean over steps)."""
        columns = [ones] + [truth[:, AXES.index(n)] for n in names]
        design = np.column_stack(columns)
        residual = np.empty_like(error)
        total = np.zeros(design.shape[1])
        for piece in pieces:
            coef, *_ = np.linalg.lstsq(design[piece], error[piece], rcond=None)
            residual[piece] = error[piece] - design[piece] @ coef
            total += coef * (piece.stop - piece.start)
        return dict(zip(["a", *names], (float(c) for c in total / samples))), residual

    used: list[str] = []
    if (fit_scale or fit_cross) and own_reason is None:
        used.append(axis)
    if fit_cross:
        used.extend(others)
    fitted, residual = fit(used)
    dof = max(samples - len(fitted) * len(pieces), 1)
    sigma_step = math.sqrt(float(np.dot(residual, residual)) / dof)
    if sigma_step <= 1e-12 * (1.0 + float(np.sqrt(np.mean(truth[:, j] ** 2)))):
        residual[:] = 0.0  # rounding only: no error on this axis
        sigma_step = 0.0
    # Reported even when kept: the scale, and how much the other axes would explain.
    scale = fitted.get(axis)
    if scale is None and own_reason is None:
        scale = fit([axis])[0][axis]
    cross = {n: fitted[n] for n in others if n in fitted}
    cross_share = 0.0
    kept = float(np.dot(residual, residual))
    if not fit_cross and others and kept > 0.0:
        wider, wider_residual = fit(used + others)
        cross = {n: wider[n] for n in others}
        cross_share = max(0.0, 1.0 - float(np.dot(wider_residual, wider_residual)) / kept)

    series = [residual[starts[i] : starts[i + 1]] for i in range(len(drives))]
    rho = autocorrelation(series, 1)  # None when there is no error at all
    tau_plain = -step / math.log(rho) if rho is not None and 0.0 < rho < 1.0 else None
    tau = tau_for_correlation(rho, 1, period, per_step) if rho is not None else None
    model_tau = tau if tau is not None else 0.0
    sigma_sample = sigma_step / math.sqrt(variance_factor(model_tau, period, per_step))

    def model(lag: int) -> float:
        return window_acf(lag, model_tau, period, per_step)

    # Enough lags for Bartlett's sum: until the model has decayed to 1e-4.
    decay_steps = 0 if model_tau <= 0 else int(math.ceil(model_tau / step * math.log(1e4)))
    max_lag = min(max(max(REPORT_LAGS) + 2, decay_steps + max(REPORT_LAGS) + 2), 20000)
    model_cache = np.array([model(k) for k in range(max_lag + max(REPORT_LAGS) + 1)])

    lags: list[LagResult] = []
    fits: bool | None = True
    for lag in (1, *REPORT_LAGS):
        measured = autocorrelation(series, lag)
        predicted = float(model_cache[lag])
        tolerance = max(2.0 * bartlett_se(lag, model_cache, samples, max_lag), FIT_TOLERANCE_FLOOR)
        implied = tau_for_correlation(measured, lag, period, per_step) if measured is not None else None
        rho_power = rho**lag if rho is not None else None
        lags.append(LagResult(lag, measured, rho_power, predicted, tolerance, implied))
        if lag == 1:
            continue
        if measured is None:
            fits = None if fits or rho is None else fits
        elif abs(measured - predicted) > tolerance:
            fits = False
    return AxisResult(
        axis=axis,
        bias=fitted["a"],
        scale=scale,
        scale_note=own_reason,
        scale_removed=axis in fitted,
        cross=cross,
        cross_removed=fit_cross and bool(cross),
        cross_share=cross_share,
        sigma_step=sigma_step,
        rho=rho,
        tau_plain=tau_plain,
        tau=tau,
        sigma_sample=sigma_sample,
        lags=lags,
        fits=fits,
    )


def analyse(
    pairs: list[tuple[dict[str, np.ndarray], dict[str, np.ndarray], str]],
    step: float,
    fit_scale: bool = False,
    fit_cross: bool = False,
    per_drive: bool = False,
) -> Analysis:
    """Errors of every drive, pooled statistics per axis (method steps 3-6).

    With several drives, one too short for two steps is left out (and said so); with one,
    that is an error.
    """
    drives: list[DriveErrors] = []
    skipped: list[str] = []
    for odom, truth, label in pairs:
        try:
            drives.append(drive_errors(odom, truth, step, label))
        except InputError as err:
            if len(pairs) == 1 or "fewer than 2 steps" not in str(err):
                raise
            skipped.append(label)
    if not drives:
        raise InputError(f"every drive is shorter than 2 steps of {step:g} s")
    samples = sum(d.errors.shape[0] for d in drives)
    if samples < MIN_STEPS:
        raise InputError(
            f"too few samples: {samples} steps of {step:g} s where odometry and truth overlap, "
            f"need at least {MIN_STEPS}"
        )
    odom_dt = np.concatenate([d.odom_intervals for d in drives])
    truth_dt = np.concatenate([d.truth_intervals for d in drives])
    period = float(np.median(odom_dt)) if odom_dt.size else step
    truth_period = float(np.median(truth_dt)) if truth_dt.size else step
    notes = [note for d in drives for note in d.notes]
    if skipped:
        notes.append(
            f"{len(skipped)} drive(s) shorter than 2 steps of {step:g} s left out: "
            + ", ".join(skipped[:5])
            + (", ..." if len(skipped) > 5 else "")
        )
    ratio = step / period
    per_step = max(1, int(round(ratio)))
    if period > COARSE_FACTOR * step:
        notes.append(
            f"odometry is sampled every {period:.4g} s, more than the step of {step:g} s: one "
            f"held sample spans several steps, which makes neighbouring errors look correlated; "
            f"use --step {period:.3g} or more"
        )
    elif abs(ratio - per_step) > 0.1 * per_step:
        notes.append(
            f"the step ({step:g} s) is not a whole number of odometry periods ({period:.4g} s); "
            f"the averaging correction takes {per_step} samples a step"
        )
    if truth_period > COARSE_FACTOR * step:
        notes.append(
            f"the truth is sampled every {truth_period:.4g} s, more than the step of {step:g} s: "
            f"interpolating it makes neighbouring errors look correlated (rho and tau too high); "
            f"use --step {truth_period:.3g} or more"
        )
    axes = {
        axis: analyse_axis(axis, drives, step, period, per_step, fit_scale, fit_cross, per_drive)
        for axis in AXES
    }
    for axis, r in axes.items():
        if r.cross_share > 0.1:
            terms = ", ".join(
                f"{c:+.3g} {UNITS[axis]} per {UNITS[n]} of true {n}" for n, c in r.cross.items()
            )
            notes.append(
                f"the {axis} error follows the other axes' true velocities ({terms}; "
                f"{100 * r.cross_share:.0f} % of its variance): a systematic error (unequal wheels, "
                f"a truth point or heading that is not the odometry's), not noise; "
                f"--fit-cross removes it"
            )
    return Analysis(step, drives, samples, period, per_step, truth_period, axes, notes, per_drive)


# ---------------------------------------------------------------------------------------------
# Report


def _num(value: float | None, fmt: str = ".3g", unit: str = "") -> str:
    if value is None:
        return "n/a"
    return f"{value:{fmt}}{(' ' + unit) if unit else ''}"


def sweep(
    pairs: list[tuple[dict[str, np.ndarray], dict[str, np.ndarray], str]],
    step: float,
    fit_scale: bool,
    fit_cross: bool,
    per_drive: bool,
) -> list[Analysis]:
    """The analysis at multiples of ``step`` while there are enough samples."""
    results = []
    for factor in SWEEP_FACTORS[1:]:
        try:
            results.append(analyse(pairs, factor * step, fit_scale, fit_cross, per_drive))
        except InputError:
            break
    return results


def format_sweep(results: list[Analysis]) -> str:
    out = io.StringIO()
    out.write(
        "the same at longer steps (first-order errors give about the same tau and sigma/sample\n"
        "at every step; sigma/step then falls only once the step nears tau):\n"
    )
    out.write(f"{'axis':<7} {'step':>6} {'samples':>8} {'sigma/step':>11} {'rho(1)':>7} {'tau':>8} {'sigma/sample':>13}\n")
    for axis in AXES:
        for result in results:
            r = result.axes[axis]
            out.write(
                f"{axis:<7} {result.step:>6.3g} {result.samples:>8} {_num(r.sigma_step, '.4g'):>11} "
                f"{_num(r.rho, '.3f'):>7} {_num(r.tau, '.3g', 's'):>8} {_num(r.sigma_sample, '.4g'):>13}\n"
            )
    return out.getvalue()


def format_report(result: Analysis, longer: Sequence[Analysis] = ()) -> str:
    step, n = result.step, result.per_step
    out = io.StringIO()
    w = out.write
    drives = len(result.drives)
    seconds = result.samples * step
    w(
        f"odometry_memory: {drives} drive{'s' if drives != 1 else ''}, {result.samples} error "
        f"samples of {step:g} s ({seconds:.1f} s)\n"
    )
    w(
        f"odometry every {result.period:.4g} s ({n} sample{'s' if n != 1 else ''} a step), "
        f"truth every {result.truth_period:.4g} s\n\n"
    )
    w(
        "removed from the errors (least squares "
        + ("on each drive; mean coefficients" if result.per_drive else "on all steps")
        + "):\n"
    )
    for axis, r in result.axes.items():
        unit = UNITS[axis]
        scale = (
            f"scale b = {_num(r.scale, '+.4f')} ({'removed' if r.scale_removed else 'kept; --fit-scale removes it'})"
            if r.scale is not None
            else f"scale b: n/a ({r.scale_note})"
        )
        line = f"  {axis:<7} bias a = {r.bias:+.4g} {unit}, {scale}"
        if r.cross_removed:
            line += ", cross terms " + ", ".join(
                f"{c:+.4g} per {UNITS[n]} of {n}" for n, c in r.cross.items()
            ) + " (removed)"
        w(line + "\n")
    w("\n")
    w(f"{'axis':<7} {'sigma/step':>12} {'rho(1)':>7} {'-step/ln(rho)':>14} {'tau':>8} {'sigma/sample':>13}\n")
    for axis, r in result.axes.items():
        unit = UNITS[axis]
        w(
            f"{axis:<7} {_num(r.sigma_step, '.4g'):>12} {_num(r.rho, '.3f'):>7} "
            f"{_num(r.tau_plain, '.3g', 's'):>14} {_num(r.tau, '.3g', 's'):>8} "
            f"{_num(r.sigma_sample, '.4g'):>13}  {unit}\n"
        )
    w(
        f"  tau: fitted to rho(1) as {n} held sample{'s' if n != 1 else ''} of a first-order "
        f"process averaged over each step"
        + (" (equal to -step/ln(rho) here)" if n == 1 else "")
        + ".\n"
    )
    w(
        "  sigma/sample: the per-sample sigma of that first-order process; assumes the errors\n"
        "  are first-order (equal to sigma/step when the odometry period is the step, nearly\n"
        "  equal when tau >> step).\n\n"
    )
    w("autocorrelation r(L) against a first-order process (model: with the fitted tau):\n")
    w(f"{'axis':<7} {'L':>3} {'r(L)':>7} {'rho^L':>7} {'model':>7} {'+-tol':>6} {'tau from r(L)':>14}\n")
    for axis, r in result.axes.items():
        for lag in r.lags:
            w(
                f"{axis:<7} {lag.lag:>3} {_num(lag.measured, '.3f'):>7} {_num(lag.rho_power, '.3f'):>7} "
                f"{_num(lag.model, '.3f'):>7} {_num(lag.tolerance, '.3f'):>6} "
                f"{_num(lag.tau_implied, '.3g', 's'):>14}\n"
            )
    w("first-order fit (r(2), r(5), r(10) within tol of the model):\n")
    for axis, r in result.axes.items():
        if r.rho is None:
            verdict = "no error on this axis"
        elif r.fits is None:
            verdict = "not tested (too few samples for the lags)"
        elif r.fits:
            verdict = "fits"
        else:
            tails = [
                lag.measured - lag.model
                for lag in r.lags[1:]
                if lag.measured is not None and lag.model is not None
            ]
            slower = sum(tails) > 0
            verdict = (
                "does not fit: the correlation decays more slowly than first-order at longer "
                "lags (a longer memory on top, or a white part: tau depends on the lag)"
                if slower
                else "does not fit: the correlation decays faster than first-order at longer lags"
            )
        w(f"  {axis:<7} {verdict}\n")
    if longer:
        w("\n" + format_sweep([result, *longer]))
    if result.notes:
        w("\nnotes:\n")
        for note in result.notes:
            w(f"  - {note}\n")
    w("\n")
    w(rig_snippet(result))
    return out.getvalue()


def rig_snippet(result: Analysis) -> str:
    """The ``[noise]`` lines of the rig file (vehicle-interfaces.md section 3)."""
    vx, vy, yaw = result.axes["vx"], result.axes["vy"], result.axes["vtheta"]

    def tau_value(r: AxisResult) -> tuple[str, str]:
        if r.tau is not None:
            return f"{r.tau:.3g}", ""
        if r.rho is None:
            return "0.0", " (no error on this axis)"
        if r.rho <= 0.0:
            return "0.0", " (rho <= 0: no memory measured, white)"
        return "0.0", " (tau could not be measured)"

    vx_tau, vx_note = tau_value(vx)
    vy_tau, _ = tau_value(vy)
    yaw_tau, yaw_note = tau_value(yaw)
    return (
        f"# rig file (vehicle-interfaces.md section 3), measured over steps of {result.step:g} s;\n"
        f"# sigmas per odometry sample, assuming first-order errors\n"
        f"[noise]\n"
        f"velocity = {vx.sigma_sample:.3g}      # m/s, from vx (vy: {vy.sigma_sample:.3g})\n"
        f"yaw_rate = {yaw.sigma_sample:.3g}      # rad/s\n"
        f"velocity_tau = {vx_tau}   # s, from vx{vx_note} (vy: {vy_tau})\n"
        f"yaw_rate_tau = {yaw_tau}   # s{yaw_note}\n"
    )


# ---------------------------------------------------------------------------------------------
# Self-test


def _gauss_markov(rng: np.random.Generator, count: int, sigma: float, tau: float, period: float) -> np.ndarray:
    r = math.exp(-period / tau)
    innovations = sigma * math.sqrt(1.0 - r * r) * rng.standard_normal(count)
    e = np.empty(count)
    e[0] = sigma * rng.standard_normal()
    for k in range(1, count):
        e[k] = r * e[k - 1] + innovations[k]
    return e


def _csv_text(columns: Sequence[str], data: Sequence[np.ndarray]) -> io.StringIO:
    text = io.StringIO()
    text.write(",".join(columns) + "\n")
    for row in zip(*data):
        text.write(",".join(repr(float(v)) for v in row) + "\n")
    text.seek(0)
    return text


def _simulate(
    rng: np.random.Generator,
    period: float,
    duration: float,
    truth_period: float,
    sigma_v: float,
    tau_v: float,
    sigma_w: float,
    tau_w: float,
) -> tuple[io.StringIO, io.StringIO]:
    """A curvy drive: odometry CSV (true + bias + scale + Gauss-Markov errors) and truth CSV."""
    count = int(round(duration / period))
    t = np.arange(count + 1) * period
    ts = t[:-1]
    vx = 0.6 + 0.3 * np.sin(0.21 * ts)
    vy = 0.05 * np.sin(0.37 * ts + 1.0)
    w = 0.5 * np.sin(0.13 * ts) + 0.25 * np.sin(0.51 * ts + 0.3)
    truth_times = np.arange(int(round(duration / truth_period)) + 1) * truth_period
    x, y, theta = integrate_held(ts, (vx, vy, w), truth_times)
    # The truth in another world frame, heading wrapped to (-pi, pi].
    yaw0, x0, y0 = 2.5, 3.0, -2.0
    world_x = x0 + math.cos(yaw0) * x - math.sin(yaw0) * y
    world_y = y0 + math.sin(yaw0) * x + math.cos(yaw0) * y
    world_theta = np.angle(np.exp(1j * (theta + yaw0)))
    reported_vx = 1.03 * vx + 0.01 + _gauss_markov(rng, count, sigma_v, tau_v, period)
    reported_vy = vy + _gauss_markov(rng, count, sigma_v, tau_v, period)
    reported_w = 0.98 * w - 0.004 + _gauss_markov(rng, count, sigma_w, tau_w, period)
    t0 = 1000.0  # any clock
    odom = _csv_text(ODOM_COLUMNS, (ts + t0, reported_vx, reported_vy, reported_w))
    truth = _csv_text(TRUTH_COLUMNS, (truth_times + t0, world_x, world_y, world_theta))
    return odom, truth


def selftest() -> int:
    """Simulate known Gauss-Markov errors, run the estimator, check what it recovers."""
    rng = np.random.default_rng(20240611)
    failures: list[str] = []

    def check(what: str, got: float | None, want: float, rel: float) -> None:
        ok = got is not None and abs(got / want - 1.0) <= rel
        print(f"  {what:<28} {_num(got, '.4g'):>8}  (true {want:g}, within {100 * rel:.0f} %: {'ok' if ok else 'FAIL'})")
        if not ok:
            failures.append(what)

    cases = [
        # odometry period, duration, truth period, step, sigma_v, tau_v, sigma_w, tau_w
        ("100 Hz odometry, 0.1 s steps", 0.01, 600.0, 0.01, 0.1, 0.02, 0.6, 0.01, 0.3),
        ("10 Hz odometry, 0.1 s steps", 0.1, 1200.0, 0.05, 0.1, 0.02, 0.6, 0.01, 0.3),
    ]
    for name, period, duration, truth_period, step, sigma_v, tau_v, sigma_w, tau_w in cases:
        odom_text, truth_text = _simulate(rng, period, duration, truth_period, sigma_v, tau_v, sigma_w, tau_w)
        odom = read_table(odom_text, ODOM_COLUMNS, "simulated odometry")
        truth = read_table(truth_text, TRUTH_COLUMNS, "simulated truth")
        result = analyse([(odom, truth, "simulated")], step, fit_scale=True)
        print(f"selftest: {name}, {duration:g} s, first-order errors, bias and scale added")
        vx, vy, yaw = result.axes["vx"], result.axes["vy"], result.axes["vtheta"]
        print(
            f"  (vx: rho(1) = {vx.rho:.3f}, -step/ln(rho) = {_num(vx.tau_plain, '.3g')} s before the "
            f"averaging correction)"
        )
        check("vx tau [s]", vx.tau, tau_v, 0.20)
        check("vy tau [s]", vy.tau, tau_v, 0.20)
        check("vtheta tau [s]", yaw.tau, tau_w, 0.20)
        check("vx sigma [m/s]", vx.sigma_sample, sigma_v, 0.15)
        check("vy sigma [m/s]", vy.sigma_sample, sigma_v, 0.15)
        check("vtheta sigma [rad/s]", yaw.sigma_sample, sigma_w, 0.15)
        check("vx scale b", vx.scale, 0.03, 0.20)
        check("vtheta scale b", yaw.scale, -0.02, 0.20)
        check("vx bias a [m/s]", vx.bias, 0.01, 0.25)
        # Printed, not asserted: each lag is tested at 2 standard errors, so a true first-order
        # process is called "does not fit" now and then.
        print(f"  first-order fit: {', '.join(f'{a} {r.fits}' for a, r in result.axes.items())}")

    # Bad input is an InputError (one line, exit code 2), never a traceback.
    bad_inputs = {
        "missing column": "t,vx,vy\n0,1,2\n1,1,2\n",
        "NaN": "t,vx,vy,vtheta\n0,1,0,0\n0.1,nan,0,0\n0.2,1,0,0\n",
        "not a number": "t,vx,vy,vtheta\n0,1,0,0\n0.1,x,0,0\n",
        "time not increasing": "t,vx,vy,vtheta\n0,1,0,0\n0.1,1,0,0\n0.1,1,0,0\n",
        "one row": "t,vx,vy,vtheta\n0,1,0,0\n",
        "empty": "",
    }
    for what, text in bad_inputs.items():
        try:
            read_table(io.StringIO(text), ODOM_COLUMNS, "odometry")
        except InputError as err:
            print(f"  bad input ({what}): {err}")
        else:
            failures.append(f"bad input not refused: {what}")
    short = read_table(io.StringIO("t,vx,vy,vtheta\n0,1,0,0\n1,1,0,0\n"), ODOM_COLUMNS, "odometry")
    short_truth = read_table(io.StringIO("t,x,y,theta\n0,0,0,0\n1,1,0,0\n"), TRUTH_COLUMNS, "truth")
    try:
        analyse([(short, short_truth, "short")], 0.1)
    except InputError as err:
        print(f"  bad input (too few samples): {err}")
    else:
        failures.append("bad input not refused: too few samples")

    if failures:
        print(f"selftest: FAILED: {'; '.join(failures)}")
        return 1
    print("selftest: passed")
    return 0


# ---------------------------------------------------------------------------------------------
# Command line


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:  # one line, exit code 2
        sys.stderr.write(f"{PROG}: error: {message}\n")
        sys.exit(2)


def _positive_seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value) or value <= 0.0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a positive number of seconds")
    return value


def main(argv: Sequence[str] | None = None) -> int:
    parser = _Parser(
        prog=PROG,
        description="Measure the odometry's error sigma and time constant (rig file [noise]) "
        "from a recorded drive and its ground truth.",
    )
    parser.add_argument(
        "--odometry", action="append", metavar="ODOM.csv", help="columns t,vx,vy,vtheta (s, m/s, rad/s)"
    )
    parser.add_argument(
        "--truth", action="append", metavar="TRUTH.csv", help="columns t,x,y,theta (s, m, rad)"
    )
    parser.add_argument(
        "--step", type=_positive_seconds, default=DEFAULT_STEP_S, help="grid step in s (default 0.1)"
    )
    parser.add_argument(
        "--fit-scale", action="store_true", help="remove a + b * true velocity instead of the mean"
    )
    parser.add_argument(
        "--fit-cross",
        action="store_true",
        help="remove a + the errors' linear dependence on all three true velocities "
        "(implies --fit-scale)",
    )
    parser.add_argument(
        "--per-drive",
        action="store_true",
        help="with several drives: fit the bias (and scale) of each drive on its own",
    )
    parser.add_argument(
        "--no-sweep",
        action="store_true",
        help="leave out the table of the same analysis at 2, 5, 10, 20 and 50 steps",
    )
    parser.add_argument(
        "--selftest", action="store_true", help="simulate known errors and check the estimator"
    )
    args = parser.parse_args(argv)
    if args.selftest:
        return selftest()
    odometry, truth = args.odometry or [], args.truth or []
    if not odometry or not truth:
        parser.error("--odometry and --truth are required (or --selftest)")
    if len(odometry) != len(truth):
        parser.error(f"{len(odometry)} --odometry but {len(truth)} --truth: give them in pairs")
    try:
        pairs = [
            (
                read_csv_file(odom_path, ODOM_COLUMNS, "odometry"),
                read_csv_file(truth_path, TRUTH_COLUMNS, "truth"),
                f"drive {i + 1}" if len(odometry) > 1 else "drive",
            )
            for i, (odom_path, truth_path) in enumerate(zip(odometry, truth))
        ]
        result = analyse(pairs, args.step, args.fit_scale, args.fit_cross, args.per_drive)
    except InputError as err:
        sys.stderr.write(f"{PROG}: error: {err}\n")
        return 2
    longer = (
        []
        if args.no_sweep
        else sweep(pairs, args.step, args.fit_scale, args.fit_cross, args.per_drive)
    )
    sys.stdout.write(format_report(result, longer))
    return 0


if __name__ == "__main__":
    sys.exit(main())
