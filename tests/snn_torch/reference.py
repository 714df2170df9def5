"""An independent float64 reference for the Izhikevich model, written for the tests.

Classic RK4 at 0.01 ms in NumPy (no torch, no code shared with snn_torch), vectorised over
many (parameter, current) pairs; the threshold crossing inside a step is located by linear
interpolation, the neuron is reset there and the rest of the step is integrated by Euler.
"""

from __future__ import annotations

import numpy as np


def simulate_reference(a, b, c, d, v_peak, current, *, t_ms, dt_ms=0.01, v0_mv=-65.0):
    """Spike times (ms) of independent neurons under constant currents.

    All arguments but ``t_ms``/``dt_ms``/``v0_mv`` are 1-D arrays of equal length K.
    Returns a list of K arrays of spike times.
    """
    a, b, c, d, vp, i = (np.asarray(x, dtype=np.float64) for x in (a, b, c, d, v_peak, current))
    v = np.full_like(i, v0_mv)
    u = b * v

    def f(v, u):
        return 0.04 * v * v + 5.0 * v + 140.0 - u + i, a * (b * v - u)

    spikes = [[] for _ in range(len(i))]
    n = int(round(t_ms / dt_ms))
    h = dt_ms
    for k in range(n):
        k1v, k1u = f(v, u)
        k2v, k2u = f(v + 0.5 * h * k1v, u + 0.5 * h * k1u)
        k3v, k3u = f(v + 0.5 * h * k2v, u + 0.5 * h * k2u)
        k4v, k4u = f(v + h * k3v, u + h * k3u)
        v1 = v + h / 6.0 * (k1v + 2 * k2v + 2 * k3v + k4v)
        u1 = u + h / 6.0 * (k1u + 2 * k2u + 2 * k3u + k4u)
        fired = ~(v1 < vp)
        if fired.any():
            idx = np.nonzero(fired)[0]
            frac = np.clip((vp[idx] - v[idx]) / (v1[idx] - v[idx]), 0.0, 1.0)
            for j, fr in zip(idx, frac, strict=True):
                spikes[j].append((k + fr) * h)
            u_cross = u[idx] + frac * (u1[idx] - u[idx]) + d[idx]
            rest = (1.0 - frac) * h
            v_c = c[idx]
            dv = 0.04 * v_c * v_c + 5.0 * v_c + 140.0 - u_cross + i[idx]
            du = a[idx] * (b[idx] * v_c - u_cross)
            v1[idx] = v_c + rest * dv
            u1[idx] = u_cross + rest * du
        v, u = v1, u1
    return [np.asarray(s) for s in spikes]
