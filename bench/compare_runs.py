"""Compare the key results of two run folders: frequencies, contact force, probe peaks.

Usage::

    python bench/compare_runs.py results/before results/after

Prints the largest relative difference of the natural frequencies (``modes.h5``), the first,
mean, largest and smallest contact force per wheel (``mbs.h5``) and, per probe, the peak
vertical and total acceleration, velocity and displacement (``probes.h5``) of both runs and
their relative difference. Used to show that a refactoring leaves the results unchanged.
"""

from __future__ import annotations

import sys
from pathlib import Path

import h5py
import numpy as np


def key_numbers(out: Path) -> dict:
    """Frequencies, contact-force summary and probe peaks of one run folder."""
    r: dict = {}
    with h5py.File(out / "modes.h5", "r") as f:
        r["frequency_hz"] = f["modes/frequency_hz"][()]
    with h5py.File(out / "mbs.h5", "r") as f:
        force = f["wheels/contact_force"][()]
    r["contact force first"] = force[0]
    r["contact force mean"] = force.mean(axis=0)
    r["contact force max"] = force.max(axis=0)
    r["contact force min"] = force.min(axis=0)
    r["probes"] = {}
    with h5py.File(out / "probes.h5", "r") as f:
        for raw in f["names"][()]:
            name = raw.decode() if isinstance(raw, bytes) else str(raw)
            g = f[f"probes/{name}"]
            a, v, u = g["acceleration"][()], g["velocity"][()], g["displacement"][()]
            r["probes"][name] = {"a_z": np.abs(a[:, 2]).max(),
                                 "|a|": np.linalg.norm(a, axis=1).max(),
                                 "|v|": np.linalg.norm(v, axis=1).max(),
                                 "|u|": np.linalg.norm(u, axis=1).max()}
    return r


def main(a: str, b: str) -> None:
    ra, rb = key_numbers(Path(a)), key_numbers(Path(b))
    fa, fb = ra["frequency_hz"], rb["frequency_hz"]
    n = min(len(fa), len(fb))
    print(f"frequencies: {len(fa)} / {len(fb)} modes, {fa[0]:.6f} - {fa[-1]:.6f} Hz; "
          f"max |relative difference| {np.max(np.abs(fb[:n] / fa[:n] - 1)):.2e}")
    print("  first five:", " ".join(f"{x:.6f}" for x in fa[:5]), "|",
          " ".join(f"{x:.6f}" for x in fb[:5]))
    for key in ("contact force first", "contact force mean", "contact force max",
                "contact force min"):
        va, vb = ra[key], rb[key]
        print(f"{key:20s} [N] " + ", ".join(f"{x:.2f} -> {y:.2f} ({y / x - 1:+.3e})"
                                            for x, y in zip(va, vb)))
    print(f"{'probe':16s}" + "".join(f" {q:>26s}" for q in ("a_z [m/s2]", "|a| [m/s2]",
                                                           "|v| [m/s]", "|u| [m]")))
    for name, pa in ra["probes"].items():
        pb = rb["probes"].get(name)
        if pb is None:
            print(f"{name:16s} only in {a}")
            continue
        print(f"{name:16s}" + "".join(f" {pa[q]:.4e} ({pb[q] / pa[q] - 1:+.2e})"
                                      for q in ("a_z", "|a|", "|v|", "|u|")))


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
