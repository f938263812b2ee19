"""What the twist round a turned building costs in accuracy (``building.rotation``,
``building.twist_shear``): a homogeneous soil box (16 x 16 x 6 m, c_S = 150 m/s class
soil, fixed base) meshed straight and twisted about its centre between r_in = 3 m and
r_out = 7.5 m. The continuum is the same, so any change of its 30 lowest eigenfrequencies
is discretisation error the twist adds; it is printed against the straight mesh's own
error (h = 1 m against h = 0.5 m), for the log profile the code uses (the same shear all
across the ring) and the C1 smoothstep it replaced, at shears 0.5-2.5.

Usage::

    python bench/twist_accuracy.py [bbar|full|incompatible]     # ~4 min on one core

Printed per line: profile, shear, the turn it gives here, the largest relative change of
the 30 eigenfrequencies against the straight mesh and against the h/2 mesh.
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np
import scipy.sparse.linalg as spla

from railvib_hpc.fem import assemble_matrix, element_dofs, hex8_mass, hex8_stiffness
from railvib_hpc.fem.reference import ElementGeometryError

E, NU, RHO = 2 * 1900 * 150.0 ** 2 * 1.3, 0.3, 1900.0
L, D = 16.0, 6.0
R_IN, R_OUT = 3.0, 7.5
N = 30


def box3(n, nz, h):
    g = np.arange(n + 1) * h
    gz = np.arange(nz + 1) * h
    X, Y, Z = np.meshgrid(g, g, gz, indexing="ij")
    pts = np.c_[X.ravel(), Y.ravel(), Z.ravel()]
    idx = np.arange(len(pts)).reshape(n + 1, n + 1, nz + 1)
    a, b = idx[:-1, :-1, :-1].ravel(), idx[1:, :-1, :-1].ravel()
    c, d = idx[1:, 1:, :-1].ravel(), idx[:-1, 1:, :-1].ravel()
    return pts, np.stack([a, b, c, d, a + 1, b + 1, c + 1, d + 1], axis=1)


def w_smooth(r):
    s = np.clip((r - R_IN) / (R_OUT - R_IN), 0, 1)
    return 1 - s * s * (3 - 2 * s)


def w_log(r):
    return np.clip(np.log(R_OUT / np.maximum(r, 1e-30)) / math.log(R_OUT / R_IN), 0, 1)


SHEAR_PER_RAD = {"smooth": None, "log": 1 / math.log(R_OUT / R_IN)}
rr = np.linspace(R_IN, R_OUT, 200001)
SHEAR_PER_RAD["smooth"] = float(np.max(rr * np.abs(np.gradient(w_smooth(rr), rr))))


def twist(pts, ang, w):
    c0 = L / 2
    dx, dy = pts[:, 0] - c0, pts[:, 1] - c0
    phi = ang * w(np.hypot(dx, dy))
    out = pts.copy()
    out[:, 0] = c0 + np.cos(phi) * dx - np.sin(phi) * dy
    out[:, 1] = c0 + np.sin(phi) * dx + np.cos(phi) * dy
    return out


def freqs(h, ang=0.0, w=None, form=None):
    n, nz = int(round(L / h)), int(round(D / h))
    pts, hexes = box3(n, nz, h)
    if ang:
        pts = twist(pts, ang, w)
    x = pts[hexes]
    dofs = element_dofs(hexes, 3)
    K = assemble_matrix(dofs, hex8_stiffness(x, E, NU, formulation=form), 3 * len(pts)).tocsc()
    M = assemble_matrix(dofs, hex8_mass(x, RHO), 3 * len(pts)).tocsc()
    free = np.flatnonzero(np.repeat(pts[:, 2] > 1e-9, 3))
    K, M = K[free][:, free], M[free][:, free]
    lam = spla.eigsh(K, N, M, sigma=0.0, return_eigenvectors=False)
    return np.sqrt(np.sort(lam)) / (2 * np.pi)


form = sys.argv[1] if len(sys.argv) > 1 else None
t = time.time()
f0 = freqs(1.0, form=form)
f_fine = freqs(0.5, form=form)
print(f"formulation {form}: straight h=1 {f0[0]:.3f}..{f0[-1]:.3f} Hz; h vs h/2 max rel "
      f"{np.max(np.abs(f0 / f_fine - 1)):.2e}  ({time.time() - t:.0f} s)", flush=True)
for prof, w in (("smooth", w_smooth), ("log", w_log)):
    for gamma in (0.5, 1.0, 1.5, 2.0, 2.5):
        ang = gamma / SHEAR_PER_RAD[prof]
        try:
            f = freqs(1.0, ang, w, form=form)
        except ElementGeometryError as err:           # coarse elements across the ring fold
            print(f"{prof:6s} shear {gamma:.1f}: {math.degrees(ang):5.1f} deg; {err}")
            continue
        own, fine = np.max(np.abs(f / f0 - 1)), np.max(np.abs(f / f_fine - 1))
        print(f"{prof:6s} shear {gamma:.1f}: {math.degrees(ang):5.1f} deg; twisted vs straight "
              f"max rel {own:.2e}, vs h/2 {fine:.2e}", flush=True)
