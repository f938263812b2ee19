"""Benchmark (not collected by pytest): thesis-sized wheelset passage with random modal data.

300 modes (9.56-57.87 Hz, 3 % damping), two rails with independent smooth random
modal rows on 27.6 m of flexible track (nodes every 0.15 m), suspended wheelset
of the thesis at 30 m/s from 1 m before to 1 m after the flexible part.

Run: ``.venv/bin/python bench/mbs_passage_bench.py``
"""

from __future__ import annotations

import time

import numpy as np

from railvib_hpc.mbs import RailCoupling, SuspendedWheelset, simulate_wheelset

N_MODES, LENGTH, SPEED = 300, 27.6, 30.0


def random_rails(rng: np.random.Generator) -> tuple[np.ndarray, tuple[RailCoupling, ...]]:
    """Frequencies and two rails of smooth random mass-normalised-like modal rows."""
    omega = 2 * np.pi * np.linspace(9.56, 57.87, N_MODES)
    xn = np.linspace(0.0, LENGTH, int(round(LENGTH / 0.15)) + 1)
    rails = []
    for _ in range(2):
        amp = rng.uniform(1e-3, 6e-3, N_MODES)[:, None]  # ~1 mm static deflection under 7.7 kN
        k = rng.uniform(0.1, 1.5, N_MODES)[:, None]
        ph = rng.uniform(0.0, 2 * np.pi, N_MODES)[:, None]
        taper = np.sin(np.pi * xn / LENGTH)  # zero at the rigid/flexible joints
        dtaper = np.pi / LENGTH * np.cos(np.pi * xn / LENGTH)
        w = amp * np.sin(k * xn + ph)
        dw = amp * k * np.cos(k * xn + ph)
        rails.append(RailCoupling(xn, w * taper, -(dw * taper + w * dtaper)))
    return omega, tuple(rails)


def main() -> None:
    """Time the passage and print steps per second."""
    omega, rails = random_rails(np.random.default_rng(0))
    veh = SuspendedWheelset()
    t0 = time.perf_counter()
    res = simulate_wheelset(omega, 0.03, rails, veh, -1.0, SPEED, (LENGTH + 2.0) / SPEED)
    wall = time.perf_counter() - t0
    print(f"dt = {res.dt:.3e} s, steps = {res.n_steps}, wall = {wall:.2f} s, "
          f"{res.n_steps / wall:.0f} steps/s")
    print(f"peak contact force {res.contact_force.max():.0f} N, min {res.contact_force.min():.0f}"
          f" N, loss of contact steps {res.n_loss_of_contact}, "
          f"max rail deflection {-res.rail_displacement.min() * 1e3:.3f} mm")
    t0 = time.perf_counter()
    res = simulate_wheelset(omega, 0.03, rails, veh, -1.0, SPEED, (LENGTH + 2.0) / SPEED,
                            dt=1e-5, store_every=100)
    wall = time.perf_counter() - t0
    print(f"dt = 1e-5 s (store every 100): steps = {res.n_steps}, "
          f"{res.n_steps / wall:.0f} steps/s, peak contact force "
          f"{res.contact_force.max():.0f} N (stored steps only)")


if __name__ == "__main__":
    main()
