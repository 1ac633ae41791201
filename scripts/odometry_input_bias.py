"""Why the odometry's errors as filter states bias the odometry scale (docs/vehicle.md,
"The errors as states"): a one-dimensional Kalman filter, linear and with the process
exactly as it assumes, of a position p, the odometry's inverse scale k and its error E (a
first-order Gauss-Markov process of 0.6 s), predicting p += (k R - E) dt from an input R
and fixing p every frame. With R a known command (exogenous), the estimate of k is unbiased;
with R the reported odometry v / k + e (E = k e: the input carries the very error the state
estimates), it is not. The truth's k is drawn from the filter's prior, so an exact filter's
normalised error is N(0, 1). The third line writes the odometry as a measurement instead, of
the displacement between a cloned previous position and the current one (stochastic cloning,
the position predicted wide around where the odometry puts it): an EKF gives the same bias.
The fourth holds the true velocity as a state (driven by a white acceleration of 0.3 m/s^2)
and the reported odometry `r = s v + e` as a measurement of it every 10 ms sample: honest.

    .venv/bin/python scripts/odometry_input_bias.py [SEEDS]

prints the mean and spread of (k_hat - k) / sigma_k (of s for the fourth) over the seeds
(200: about a minute).
"""

import sys

import numpy as np


def run(seed, exogenous, seconds=40.0, fix_sigma=0.003, sigma=0.02, tau=0.6):
    rng = np.random.default_rng(seed)
    dt = 0.05  # a frame, the error held over it
    phi = np.exp(-dt / tau)
    k_true = 1.0 + 0.02 * rng.standard_normal()
    x = np.array([0.0, 1.0, 0.0])  # p, k, E
    cov = np.diag([1e-12, 0.02**2, sigma**2])
    error = sigma * rng.standard_normal()
    p = 0.0
    for frame in range(int(seconds / dt)):
        if exogenous:
            r = 0.5 + 0.1 * np.sin(0.3 * frame * dt)
            p += (k_true * r - error) * dt
        else:
            r = 0.5 / k_true + error / k_true
            p += 0.5 * dt
        f = np.eye(3)
        f[0, 1], f[0, 2], f[2, 2] = r * dt, -dt, phi
        q = np.zeros((3, 3))
        q[2, 2] = (1.0 - phi**2) * sigma**2
        x = np.array([x[0] + (x[1] * r - x[2]) * dt, x[1], phi * x[2]])
        cov = f @ cov @ f.T + q
        error = phi * error + np.sqrt(1.0 - phi**2) * sigma * rng.standard_normal()
        z = p + fix_sigma * rng.standard_normal()
        h = np.array([1.0, 0.0, 0.0])
        gain = cov @ h / (h @ cov @ h + fix_sigma**2)
        x = x + gain * (z - x[0])
        cov = cov - np.outer(gain, h @ cov)
    return (x[1] - k_true) / np.sqrt(cov[1, 1])


def run_cloned(seed, seconds=40.0, fix_sigma=0.003, sigma=0.02, tau=0.6, wide=1.0):
    rng = np.random.default_rng(seed)
    dt = 0.05
    phi = np.exp(-dt / tau)
    k_true = 1.0 + 0.02 * rng.standard_normal()
    x = np.array([0.0, 0.0, 1.0, 0.0])  # p, p_prev, k, E
    cov = np.diag([1e-12, 1e-12, 0.02**2, sigma**2])
    error = sigma * rng.standard_normal()
    p = 0.0
    for _ in range(int(seconds / dt)):
        r = 0.5 / k_true + error / k_true
        p += 0.5 * dt
        f = np.array([[1, 0, 0, 0], [1, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, phi]], float)
        x = f @ x
        cov = f @ cov @ f.T + np.diag([wide**2, 0.0, 0.0, (1.0 - phi**2) * sigma**2])
        x[0] = x[1] + dt * (x[2] * r - x[3])  # linearised where the odometry puts it
        d = (x[0] - x[1]) / dt + x[3]
        h = np.array([1 / (x[2] * dt), -1 / (x[2] * dt), -d / x[2] ** 2, 1 / x[2]])
        for z, hz, noise, predicted in (
            (r, h, 1e-8, d / x[2]),
            (None, np.array([1.0, 0.0, 0.0, 0.0]), fix_sigma**2, None),
        ):
            if z is None:
                z, predicted = p + fix_sigma * rng.standard_normal(), x[0]
            gain = cov @ hz / (hz @ cov @ hz + noise)
            x = x + gain * (z - predicted)
            joseph = np.eye(4) - np.outer(gain, hz)
            cov = joseph @ cov @ joseph.T + noise * np.outer(gain, gain)
        error = phi * error + np.sqrt(1.0 - phi**2) * sigma * rng.standard_normal()
    return (x[2] - k_true) / np.sqrt(cov[2, 2])


def run_velocity(seed, seconds=40.0, fix_sigma=0.003, sigma=0.02, tau=0.6, accel=0.3, rn=0.001):
    rng = np.random.default_rng(seed)
    dt = 0.01  # an odometry sample; a position fix every fifth
    phi = np.exp(-dt / tau)
    s_true = 1.0 + 0.02 * rng.standard_normal()
    x = np.array([0.0, 0.5, 1.0, 0.0])  # p, v, s, e
    cov = np.diag([1e-12, 0.05**2, 0.02**2, sigma**2])
    error = sigma * rng.standard_normal()
    p = 0.0

    def update(x, cov, z, predicted, h, noise):
        gain = cov @ h / (h @ cov @ h + noise)
        joseph = np.eye(4) - np.outer(gain, h)
        return x + gain * (z - predicted), joseph @ cov @ joseph.T + noise * np.outer(gain, gain)

    for k in range(int(seconds / dt)):
        v = 0.5 + 0.1 * np.sin(0.3 * k * dt)
        r = s_true * v + error + rn * rng.standard_normal()
        h = np.array([0.0, x[2], x[1], 1.0])
        x, cov = update(x, cov, r, x[2] * x[1] + x[3], h, rn**2)
        f = np.eye(4)
        f[0, 1], f[3, 3] = dt, phi
        q = np.zeros((4, 4))
        q[0, 0], q[0, 1], q[1, 1] = accel**2 * dt**4 / 4, accel**2 * dt**3 / 2, (accel * dt) ** 2
        q[1, 0], q[3, 3] = q[0, 1], (1.0 - phi**2) * sigma**2
        x, cov = f @ x, f @ cov @ f.T + q
        p += v * dt
        error = phi * error + np.sqrt(1.0 - phi**2) * sigma * rng.standard_normal()
        if (k + 1) % 5 == 0:
            z = p + fix_sigma * rng.standard_normal()
            x, cov = update(x, cov, z, x[0], np.array([1.0, 0.0, 0.0, 0.0]), fix_sigma**2)
    return (x[2] - s_true) / np.sqrt(cov[2, 2])


def main():
    seeds = int(sys.argv[1]) if len(sys.argv) > 1 else 200
    for exogenous in (True, False):
        errors = np.array([run(s, exogenous) for s in range(seeds)])
        what = "a known command" if exogenous else "the reported odometry"
        print(
            f"input {what}: normalised error of k, mean {errors.mean():+.2f}, "
            f"spread {errors.std():.2f} over {seeds} seeds"
        )
    errors = np.array([run_cloned(s) for s in range(seeds)])
    print(
        "odometry as a measurement between cloned positions: normalised error of k, "
        f"mean {errors.mean():+.2f}, spread {errors.std():.2f} over {seeds} seeds"
    )
    errors = np.array([run_velocity(s) for s in range(seeds)])
    print(
        "the velocity a state, the odometry its measurement: normalised error of s, "
        f"mean {errors.mean():+.2f}, spread {errors.std():.2f} over {seeds} seeds"
    )


if __name__ == "__main__":
    main()
