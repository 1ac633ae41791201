"""stereonav's EKF update against the same update written densely in NumPy, in one process.

Run from the repository root, after ``maturin develop --release -m crates/py/Cargo.toml``::

    .venv/bin/python bench/ekf_vs_numpy.py [--repeat N] [--seed S]

NumPy is pinned to one thread: ``OPENBLAS_NUM_THREADS``, ``OMP_NUM_THREADS``,
``MKL_NUM_THREADS`` and friends are set to 1 below, before NumPy is imported, since the Rust
filter runs on one thread.

The map: 500 ceiling lamps on a 25 x 20 grid, 0.6 m apart, 3.3 to 3.6 m up, mapped by a
:class:`stereonav.Filter` (camera 0.8 m up, tilted 0.2 rad forward so that f is observable)
that drives a lawnmower path under them (ten 17 m passes, 1.2 m apart, U-turns between them,
0.1 m per frame, then back to the middle of the last pass): noisy odometry into ``predict``,
and at every
frame the lamps in view, projected with the true camera (f and baseline off the rig's
nominal values) plus 0.3 px noise, into ``observe``, which confirms each lamp after three
frames and updates with the mapped ones. Passes see the lamps of the previous pass again, so
the covariance ends dense and strongly correlated, as a real map's: the pose, 500 lamps, f
and the baseline, n = 1505 states.

One frame's update is then timed with 5 and with 10 lamps in view (measured from the true
pose with fresh noise), on both sides with the same inputs:

- Rust: ``Filter.update`` on a copy of the filter (copied outside the timed region): the
  linearisation, the per-landmark gate, the update of state and covariance in the form the
  filter picks at this size (``"auto"``: factored, ``P+ = P - W W^T`` with ``W = P H^T L^-T``,
  ``S = L L^T``, since n > 400; see the ``vslam-ekf`` crate docs), and the Python wrapper's
  argument checks;
- NumPy: the textbook dense EKF update at the same size: ``stereonav.project`` for h(x) and
  its Jacobians, a dense ``H`` (4m x n), ``A = P H^T``, ``S = H A + R``, the same per-landmark
  chi-square gate, the Cholesky factor of ``S`` and the same factored covariance update
  (``numpy.linalg``; no SciPy). "NumPy linear algebra" is its time without the linearisation.

Before timing, the NumPy result must equal the Rust one: state to 1e-9 of ``max |x|`` (and the
correction ``dx`` to 1e-9 of ``max |dx|``), covariance to 1e-9 of ``max |P|``. The same is
done for the Joseph form (``covariance_update="joseph"`` against ``P - K A^T - A K^T +
K S K^T`` in NumPy), for reference. Times are medians over ``--repeat`` calls, Rust and NumPy
interleaved. Targets: Rust at least 2x faster than NumPy, and at most 5 ms.
"""

from __future__ import annotations

import os

# One thread for NumPy's BLAS and LAPACK, set before NumPy is imported (the Rust side is
# single-threaded).
for _variable in (
    "OPENBLAS_NUM_THREADS",
    "OMP_NUM_THREADS",
    "MKL_NUM_THREADS",
    "BLIS_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "NUMEXPR_NUM_THREADS",
):
    os.environ[_variable] = "1"

import argparse  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from typing import Callable, Dict, List, NamedTuple, Tuple  # noqa: E402

import numpy as np  # noqa: E402
import numpy.typing as npt  # noqa: E402

try:
    import stereonav
except ImportError as err:  # pragma: no cover - a message instead of a traceback
    sys.exit(
        f"cannot import stereonav ({err}); build it first: "
        ".venv/bin/maturin develop --release -m crates/py/Cargo.toml"
    )

F64 = npt.NDArray[np.float64]

#: Lamp grid: columns along x, rows along y, spacing (m), heights (m).
GRID_X, GRID_Y, SPACING = 25, 20, 0.6
LAMP_Z = (3.3, 3.6)
#: Lawnmower path: passes along x, this far apart in y (m), this far past the grid (m).
PASS_SPACING, OVERRUN = 1.2, 1.5
#: Distance driven per frame (m) and frame period (s).
STEP_M, FRAME_S = 0.1, 0.1
PIXEL_NOISE = 0.3
#: The truth differs from the rig's nominal camera by this much.
TRUE_F, TRUE_BASELINE = 703.0, 0.1164
ESTIMATED = ("f", "baseline")
#: The head's forward tilt, rad (an upward camera on planar motion cannot give f).
MOUNT_PITCH = 0.2
TOLERANCE = 1e-9
TARGET_RATIO, TARGET_MS = 2.0, 5.0


def rig() -> stereonav.RigConfig:
    nominal = stereonav.Camera(
        f=700.0, cx=376.0, cy=240.0, baseline=0.12, mount_z=0.8, mount_pitch=MOUNT_PITCH
    )
    return stereonav.RigConfig(
        width=752,
        height=480,
        nominal=nominal,
        estimate=ESTIMATED,
        prior={"f": 20.0, "baseline": 0.006},
        pixel_noise=PIXEL_NOISE,
        velocity_noise=0.02,
        yaw_rate_noise=0.01,
    )


def lamps(rng: np.random.Generator) -> F64:
    """The 500 lamps, row ``i`` lamp id ``i``."""
    i, j = np.meshgrid(np.arange(GRID_X), np.arange(GRID_Y), indexing="ij")
    z = rng.uniform(*LAMP_Z, size=i.size)
    return np.column_stack([SPACING * i.ravel(), SPACING * j.ravel(), z])


def velocities() -> List[Tuple[float, float]]:
    """``(v, w)`` per frame of the lawnmower path: straight passes along +x and -x joined by
    half-circle U-turns (radius half the pass spacing); at the end a turn on the spot and half
    the last pass again, so that the last pose is over the middle of the map."""
    length = SPACING * (GRID_X - 1) + 2 * OVERRUN
    passes = int(math.ceil(SPACING * (GRID_Y - 1) / PASS_SPACING))
    speed = STEP_M / FRAME_S
    radius = PASS_SPACING / 2
    out: List[Tuple[float, float]] = []
    for k in range(passes):
        out += [(speed, 0.0)] * int(round(length / STEP_M))
        if k + 1 < passes:
            turn = math.pi * radius
            steps = int(round(turn / STEP_M))
            w = math.pi / (steps * FRAME_S) * (1 if k % 2 == 0 else -1)
            out += [(turn / (steps * FRAME_S), w)] * steps
    steps = 20
    out += [(0.0, math.pi / (steps * FRAME_S))] * steps
    out += [(speed, 0.0)] * int(round(length / 2 / STEP_M))
    return out


def arc(pose: F64, v: float, w: float, dt: float) -> F64:
    """The pose after moving at ``(v, 0, w)`` for ``dt`` along the exact arc."""
    x, y, theta = pose
    if abs(w) < 1e-12:
        return np.array([x + v * dt * math.cos(theta), y + v * dt * math.sin(theta), theta])
    t1 = theta + w * dt
    return np.array(
        [x + v / w * (math.sin(t1) - math.sin(theta)), y + v / w * (math.cos(theta) - math.cos(t1)), t1]
    )


def visible(z: F64, config: stereonav.RigConfig) -> npt.NDArray[np.bool_]:
    """Rows of ``z`` inside both images."""
    inside = np.asarray(np.isfinite(z).all(axis=1), dtype=np.bool_)
    for column, size in ((0, config.width), (1, config.height), (2, config.width), (3, config.height)):
        inside &= (z[:, column] >= 1.0) & (z[:, column] < size - 1.0)
    return inside


class Map(NamedTuple):
    filter: stereonav.Filter
    truth_pose: F64
    lamps: F64
    camera: stereonav.Camera
    frames: int


def build_map(rng: np.random.Generator) -> Map:
    """Drives the lawnmower path with a Filter; returns it at the end."""
    config = rig()
    truth = stereonav.Camera(
        f=TRUE_F, cx=376.0, cy=240.0, baseline=TRUE_BASELINE, mount_z=0.8, mount_pitch=MOUNT_PITCH
    )
    points = lamps(rng)
    f = stereonav.Filter(config)
    # The world frame is the robot at the first frame: start at the grid's corner, outside.
    start = np.array([-OVERRUN, 0.0, 0.0])
    pose = np.zeros(3)
    world = points - [start[0], start[1], 0.0]
    path = velocities()
    for frame, (v, w) in enumerate([(0.0, 0.0)] + path):
        if frame > 0:
            pose = arc(pose, v, w, FRAME_S)
            f.predict(
                v + rng.normal(0.0, config.velocity_noise),
                rng.normal(0.0, config.velocity_noise),
                w + rng.normal(0.0, config.yaw_rate_noise),
                FRAME_S,
            )
        z = stereonav.project(world, pose=pose, camera=truth).z
        seen = np.flatnonzero(visible(z, config))
        noisy = z[seen] + rng.normal(0.0, PIXEL_NOISE, size=(len(seen), 4))
        f.observe(seen.astype(np.uint64), noisy)
    return Map(f, pose, world, truth, len(path) + 1)


# --- The dense NumPy EKF update ------------------------------------------------------------


class Dense(NamedTuple):
    x: F64
    p: F64
    nis: F64


def linearise(
    x: F64, lamp_index: npt.NDArray[np.intp], fixed: Tuple[int, ...], base: F64
) -> Tuple[F64, F64]:
    """h(x) (4m,) and the dense H (4m x n): ``stereonav.project`` with its Jacobians."""
    n = len(x)
    camera = base.copy()
    camera[list(fixed)] = x[-len(fixed) :]
    points = np.column_stack([x[lamp_index], x[lamp_index + 1], x[lamp_index + 2]])
    projection = stereonav.project(points, pose=x[:3], camera=camera)
    m = len(lamp_index)
    h = np.zeros((4 * m, n))
    for k, i in enumerate(lamp_index):
        rows = slice(4 * k, 4 * k + 4)
        h[rows, 0:3] = projection.d_pose[k]
        h[rows, i : i + 3] = projection.d_landmark[k]
        h[rows, n - len(fixed) :] = projection.d_camera[k][:, list(fixed)]
    return projection.z.ravel(), h


def dense_update(x: F64, p: F64, predicted: F64, h: F64, z: F64, gate: float, joseph: bool) -> Dense:
    """The EKF update (eq. 6-7, with H of eq. 8), dense, with the filter's per-landmark gate."""
    nu = z - predicted
    a = p @ h.T  # n x 4m
    s = h @ a + PIXEL_NOISE**2 * np.eye(len(nu))
    s = 0.5 * (s + s.T)
    m = len(nu) // 4
    nis = np.empty(m)
    for j in range(m):
        block = slice(4 * j, 4 * j + 4)
        nis[j] = nu[block] @ np.linalg.solve(s[block, block], nu[block])
    keep = np.repeat(nis <= gate, 4)
    if not keep.any():
        return Dense(x.copy(), p.copy(), nis)
    a, s, nu = a[:, keep], s[np.ix_(keep, keep)], nu[keep]
    lower = np.linalg.cholesky(s)
    w = np.linalg.solve(lower, a.T).T  # A L^-T
    dx = w @ np.linalg.solve(lower, nu)
    if joseph:
        k = np.linalg.solve(lower.T, w.T).T  # W L^-1 = A S^-1
        p_new = p - k @ a.T - a @ k.T + k @ s @ k.T
    else:
        p_new = p - w @ w.T
    p_new = 0.5 * (p_new + p_new.T)
    x_new = x + dx
    x_new[2] = math.remainder(x_new[2], 2 * math.pi)
    return Dense(x_new, p_new, nis)


def median_ms(samples: List[float]) -> float:
    return 1e3 * statistics.median(samples)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=50, help="timed calls per case (default 50)")
    parser.add_argument("--seed", type=int, default=1, help="seed of the map and the noise")
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)

    started = time.perf_counter()
    built = build_map(rng)
    f = built.filter
    n = len(f.state)
    mapped = len(f.landmarks)
    build_s = time.perf_counter() - started
    print(
        f"map: {mapped} lamps mapped over {built.frames} frames of a lawnmower path "
        f"({build_s:.1f} s to build), n = {n} states (pose, {mapped} lamps, {', '.join(ESTIMATED)})"
    )
    if mapped != GRID_X * GRID_Y:
        print(f"error: expected {GRID_X * GRID_Y} lamps in the map", file=sys.stderr)
        return 1
    p = f.covariance
    d = np.sqrt(np.diag(p))
    corr = np.abs(p / np.outer(d, d))
    print(
        f"covariance: dense ({np.count_nonzero(p) / p.size:.1%} non-zero), median |correlation| "
        f"{np.median(corr):.2f}; camera f {f.camera.f:.2f} px (truth {TRUE_F}), baseline "
        f"{1e3 * f.camera.baseline:.2f} mm (truth {1e3 * TRUE_BASELINE})"
    )
    print(
        f"threads: OPENBLAS_NUM_THREADS={os.environ['OPENBLAS_NUM_THREADS']} "
        f"OMP_NUM_THREADS={os.environ['OMP_NUM_THREADS']} (set before importing NumPy); "
        "the Rust filter is single-threaded"
    )
    try:  # NumPy >= 1.25
        blas = np.show_config(mode="dicts")["Build Dependencies"]["blas"]
        blas_name = f"{blas.get('name')} {blas.get('version')}"
    except (TypeError, KeyError):
        blas_name = "BLAS unknown"
    print(
        f"stereonav {stereonav.__version__}, NumPy {np.__version__} ({blas_name}), "
        f"Python {platform.python_version()}, {platform.machine()}, {os.cpu_count()} CPUs"
    )

    # The lamps in view from the true pose, measured with fresh noise: one frame's input.
    z_all = stereonav.project(built.lamps, pose=built.truth_pose, camera=built.camera).z
    in_view = np.flatnonzero(visible(z_all, rig()))
    print(f"lamps in view at the last pose: {len(in_view)}")
    if len(in_view) < 10:
        print("error: fewer than 10 lamps in view", file=sys.stderr)
        return 1
    landmark_of = {int(track): int(landmark) for track, landmark in f.bindings}
    x0, p0 = f.state, f.covariance
    base = f.camera.to_array()
    fixed = tuple(stereonav.CAMERA_PARAMETERS.index(name) for name in f.estimated_parameters)
    gate = f.gate_bound

    print()
    header = (
        f"{'form':<15} {'lamps':>5} {'Rust ms':>9} {'NumPy ms':>9} {'NumPy linalg ms':>16} "
        f"{'NumPy/Rust':>11} {'max rel. diff x, dx, P':>28}"
    )
    print(header)
    print("-" * len(header))
    ok = True
    for form in ("auto", "joseph"):
        filt = f.copy()
        filt.covariance_update = form
        for seen in (5, 10):
            lamps_seen = in_view[np.linspace(0, len(in_view) - 1, seen).round().astype(int)]
            ids = np.array([landmark_of[int(t)] for t in lamps_seen], dtype=np.uint64)
            z = z_all[lamps_seen] + rng.normal(0.0, PIXEL_NOISE, size=(seen, 4))
            index = np.array([filt.landmark_state_index(int(i)) for i in ids], dtype=np.intp)
            joseph = form == "joseph" or (form == "auto" and n <= 400)

            def numpy_update() -> Dense:
                predicted, h = linearise(x0, index, fixed, base)
                return dense_update(x0, p0, predicted, h, z.ravel(), gate, joseph)

            predicted, h = linearise(x0, index, fixed, base)

            def numpy_linalg() -> Dense:
                return dense_update(x0, p0, predicted, h, z.ravel(), gate, joseph)

            # Equality first.
            rust = filt.copy()
            report = rust.update(ids, z)
            reference = numpy_update()
            if len(report.accepted) != seen or not np.all(reference.nis <= gate):
                print(f"error: the gate rejected lamps ({report.rejected})", file=sys.stderr)
                return 1
            np.testing.assert_allclose(report.accepted["nis"], reference.nis, rtol=1e-8)
            x1, p1 = rust.state, rust.covariance
            diff_x = np.abs(x1 - reference.x).max() / np.abs(x0).max()
            diff_dx = np.abs((x1 - x0) - (reference.x - x0)).max() / np.abs(reference.x - x0).max()
            diff_p = np.abs(p1 - reference.p).max() / np.abs(p0).max()
            equal = max(diff_x, diff_dx, diff_p) <= TOLERANCE
            ok &= equal

            times: Dict[str, List[float]] = {"rust": [], "numpy": [], "linalg": []}
            cases: Dict[str, Callable[[], object]] = {"numpy": numpy_update, "linalg": numpy_linalg}
            for _ in range(args.repeat):
                copy = filt.copy()
                start = time.perf_counter()
                copy.update(ids, z)
                times["rust"].append(time.perf_counter() - start)
                for name, call in cases.items():
                    start = time.perf_counter()
                    call()
                    times[name].append(time.perf_counter() - start)
            rust_ms, numpy_ms = median_ms(times["rust"]), median_ms(times["numpy"])
            linalg_ms = median_ms(times["linalg"])
            label = form + (" (factored)" if form == "auto" and not joseph else "")
            print(
                f"{label:<15} {seen:>5} {rust_ms:>9.3f} {numpy_ms:>9.3f} {linalg_ms:>16.3f} "
                f"{numpy_ms / rust_ms:>10.2f}x "
                f"{diff_x:>9.1e} {diff_dx:>8.1e} {diff_p:>8.1e}{'' if equal else '  MISMATCH'}"
            )
            if form == "auto":
                ok &= numpy_ms / rust_ms >= TARGET_RATIO and rust_ms <= TARGET_MS
    print()
    print(
        f"ms: median of {args.repeat} calls. Rust = Filter.update on a fresh copy (wrapper checks "
        "included); NumPy = linearisation through stereonav.project + dense update; NumPy linalg "
        "= the dense update alone. NumPy/Rust > 1 means Rust is faster."
    )
    print(
        f"targets (auto form): Rust at least {TARGET_RATIO:.0f}x faster than NumPy and at most "
        f"{TARGET_MS:.0f} ms; results equal to {TOLERANCE:g} relative: {'met' if ok else 'NOT met'}"
    )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
