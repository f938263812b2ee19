"""Regenerate docs/verification/transient.md: the full-order solver against analytic answers.

Usage (serial, a few minutes; run under the lock)::

    flock /tmp/railvib-heavy.lock .venv/bin/python bench/transient_verification.py \\
        [--thesis results/direct_vs_modal/direct_vs_modal.json] [--coarse ...json]

Cases (the same models as tests/transient/test_verification.py, at more resolutions):

(a) 1-D P and S pulses through a 40 m soil column with an absorbing base: waveform error at a
    receiver against the travelling pulse (h and dt halved together, and dt alone), and the
    energy left in the column after the pulse has reached the base;
(b) Lamb's problem (Pekeris, nu = 1/4): peak of the Rayleigh pulse and the arrival lags at
    5 and 8 m, with 1 m and 0.5 m elements;
(c) energy: a closed undamped box, and the balance with dashpots and Rayleigh damping;
(d), (e) direct vs modal on the thesis model and the wave arrivals, from the JSON written by
    bench/transient_vs_modal.py (thesis size and/or coarse), when given.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "tests" / "transient"), str(ROOT / "tests" / "fem"), str(ROOT)]

from mpi4py import MPI  # noqa: E402
from wave_cases import C_P, C_S, RHO, Model, box_mesh, column_pulse, soil_case  # noqa: E402

from railvib_hpc.problem import Problem  # noqa: E402

COMM = MPI.COMM_SELF


def section_a() -> list[str]:
    out = ["## (a) 1-D pulses through a soil column with an absorbing base", "",
           "Column of 1 m x 1 m subgrade hexahedra (E 200 MPa, nu 0.2, rho 1850: c_P = "
           f"{C_P:.2f} m/s, c_S = {C_S:.2f} m/s), 40 m high, only u_z (P) or u_x (S) free, "
           "Lysmer-Kuhlemeyer base; a sin^4 force pulse of 0.04 s on the top. Receiver 15 m "
           "down against the exact travelling pulse v = F(t - d/c) / (rho c A) until it has "
           "passed (relative L2 error over time); Newmark average acceleration.", ""]
    hs = [1.0, 0.5, 0.25, 0.125]
    out += ["| h [m] | dt P [s] | error P | dt S [s] | error S |", "|---|---|---|---|---|"]
    errs = {"P": [], "S": []}
    dts = {"P": [], "S": []}
    for h in hs:
        for kind in ("P", "S"):
            r = column_pulse(kind, h, 0.5, COMM)
            errs[kind].append(np.linalg.norm(r["v"] - r["v_exact"]) / np.linalg.norm(r["v_exact"]))
            dts[kind].append(r["dt"])
        out.append(f"| {h} | {dts['P'][-1]:.3e} | {errs['P'][-1]:.3e} | {dts['S'][-1]:.3e} | "
                   f"{errs['S'][-1]:.3e} |")
    rates = {k: np.polyfit(np.log(hs), np.log(v), 1)[0] for k, v in errs.items()}
    out += [f"| rate (polyfit) | | {rates['P']:.3f} | | {rates['S']:.3f} |", "",
            "Courant number c dt / h = 0.5 throughout. Time step alone (h = 0.25 m, P wave; RMS "
            "difference between successive time steps):", ""]
    runs = {cr: column_pulse("P", 0.25, cr, COMM) for cr in (2.0, 1.0, 0.5, 0.25)}
    keys = sorted(runs, reverse=True)
    out += ["| Courant | dt [s] | RMS difference to dt/2 [m/s] | ratio |", "|---|---|---|---|"]
    prev = None
    for a, b in zip(keys[:-1], keys[1:]):
        fine = runs[b]["v"][::2]
        n = min(len(runs[a]["v"]), len(fine))
        d = float(np.sqrt(np.mean((runs[a]["v"][:n] - fine[:n]) ** 2)))
        out.append(f"| {a} | {runs[a]['dt']:.3e} | {d:.3e} | "
                   f"{'' if prev is None else f'{prev / d:.2f}'} |")
        prev = d
    out += ["", "Energy left in the column after the pulse has passed the base "
            "(E after / E of the pulse):", "", "| h [m] | P | S |", "|---|---|---|"]
    for h in (0.5, 0.25, 0.125):
        row = []
        for kind, c in (("P", C_P), ("S", C_S)):
            r = column_pulse(kind, h, 0.5, COMM, t_end=40.0 / c + 0.04 + 5.0 / c, energy=True)
            e_in = r["energy"][np.searchsorted(r["t"], 0.04 + 1.0 / c)]
            row.append(r["energy"][-1] / e_in)
        out.append(f"| {h} | {row[0]:.2e} | {row[1]:.2e} |")
    out += ["", "Criterion: reflected energy < 1 % at normal incidence; the error "
            "falls at the scheme's order (2).", "",
            "Second method, a graded Caughey absorbing layer (CALM: Rayleigh damping at 10 "
            "and 50 Hz whose ratio grows quadratically to zeta_max at the fixed bottom) in "
            "extra column below the 40 m, against the dashpots; h = 0.25 m, P wave, a zero-mean "
            "pulse (sin^3 cos, 0.04 s, 20-50 Hz, lambda_P ~ 14 m) and the sin^4 pulse (net "
            "impulse: a quasi-static part):", "",
            "| base | extra mesh [m] | reflected, zero-mean pulse | reflected, sin^4 pulse |",
            "|---|---|---|---|"]
    from wave_cases import smooth_pulse, zero_mean_pulse

    def reflected(height, base, shape):
        r = column_pulse("P", 0.25, 0.5, COMM, height=height, base=base, energy=True,
                         shape=shape, t_end=(2 * height - 40.0) / C_P + 0.04)
        return r["energy"][-1] / r["energy"][np.searchsorted(r["t"], 0.04 + 1.0 / C_P)]

    cases = [("Lysmer-Kuhlemeyer dashpots", 0.0, ("boundary.base=absorbing",))]
    for thickness in (10.0, 20.0, 40.0):
        for zeta in (0.5, 0.9):
            cases.append((f"Caughey layer, zeta_max {zeta}", thickness,
                          ("boundary.base=caughey", f"boundary.layer_thickness={thickness}",
                           f"boundary.layer_damping={zeta}", "damping.f1=10",
                           "damping.f2=50")))
    for label, extra, base in cases:
        a, b = (reflected(40.0 + extra, base, s) for s in (zero_mean_pulse, smooth_pulse))
        out.append(f"| {label} | {extra:g} | {a:.2e} | {b:.2e} |")
    out += ["", "The layer needs more than a wavelength of extra mesh for < 1 % and cannot "
            "absorb the quasi-static part of a load with a net impulse (a train's static "
            "load moving along): the dashpots are the method of choice here.", ""]
    return out


def lamb_run(h: float, extent=(16.0, 16.0, 12.0), radii=(5.0, 8.0)) -> dict:
    from lamb import GAMMA, lamb_displacement, pulse

    from railvib_hpc.model.boundary import constraint_rules, face_node_sets

    n = tuple(int(round(e / h)) for e in extent)
    mesh = box_mesh(n, extent, origin=(0, 0, -extent[2]))
    case = soil_case("materials.subgrade.nu=0.25", "damping.model=none",
                     "boundary.x_min=roller", "boundary.y_min=roller",
                     "boundary.x_max=absorbing", "boundary.y_max=absorbing",
                     "boundary.base=absorbing")
    mu = case["materials.subgrade.E"] / 2.5
    c_s = math.sqrt(mu / RHO)
    duration = 14.0 / c_s            # 14 m / c_S: the same pulse for every mesh
    dt = duration / 40 * h
    t0 = time.perf_counter()
    model = Model(mesh, case, constraint_rules(Problem.from_case(case)), COMM, dt,
                  node_sets=face_node_sets(mesh))
    setup = time.perf_counter() - t0
    src = np.flatnonzero(np.all(np.isclose(mesh.points, 0.0), axis=1))
    sdof = model.dofs(src, 2)
    rec = [np.flatnonzero(np.isclose(mesh.points[:, 0], r) & np.isclose(mesh.points[:, 1], 0)
                          & np.isclose(mesh.points[:, 2], 0))[0] for r in radii]
    rdof = model.dofs(rec, 2)
    solver = model.solver(lambda k: (sdof, np.array([-0.25e5 * float(pulse(k * dt, duration))])))
    st = model.state()
    nt = int(math.ceil((max(radii) * GAMMA / c_s + 1.2 * duration) / dt))
    u = [np.zeros(len(radii))]
    t0 = time.perf_counter()
    for _ in range(nt):
        solver.step(st)
        u.append(-model.values(st.u, rdof))
    run = time.perf_counter() - t0
    n_dofs = model.dofmap.n_dofs
    solver.destroy()
    model.destroy()
    t = np.arange(nt + 1) * dt
    u = np.array(u)
    exact = np.array([lamb_displacement(r, t, 1e5, mu, c_s, duration) for r in radii]).T
    return {"t": t, "u": u, "exact": exact, "dt": dt, "c_s": c_s, "duration": duration,
            "radii": radii, "n_dofs": n_dofs, "setup_s": setup, "run_s": run, "steps": nt}


def section_b() -> list[str]:
    from lamb import GAMMA
    from test_verification import _lag

    out = ["## (b) Lamb's problem: vertical point load on a half-space", "",
           "Quarter model 16 x 16 x 12 m (symmetry planes x = 0, y = 0 on rollers, absorbing "
           "far faces and base), nu = 1/4 (c_S = 200 m/s, c_P = sqrt(3) c_S, c_R = 0.9194 "
           "c_S), a sin^4 pulse of 100 kN and 70 ms (14 m / c_S) on the corner node; the "
           "surface displacement in the load direction at 5 and 8 m against Pekeris's closed "
           "form (nu = 1/4) convolved with the pulse (lamb.py: the antiderivative of the "
           "step response is closed form, so the Rayleigh singularity integrates exactly). "
           "Lags: cross-correlation shift in the window of the early phases (P, S and the "
           "upward motion before the Rayleigh wave) and of the Rayleigh pulse, in time steps "
           "(dt = pulse / 40 for h = 1 m, / 80 for 0.5 m).", "",
           "| h [m] | DOFs | r [m] | r/h | peak FE [m] | peak Pekeris [m] | error | lag early "
           "[steps] | lag Rayleigh [steps] | peak time FE - Pekeris [steps] | max before r/c_P |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]
    for h in (1.0, 0.5):
        res = lamb_run(h)
        t, dt = res["t"], res["dt"]
        for j, r in enumerate(res["radii"]):
            u, ex = res["u"][:, j], res["exact"][:, j]
            t_p, t_r = r / (math.sqrt(3) * res["c_s"]), r * GAMMA / res["c_s"]
            early = (t >= t_p) & (t < t_r + 0.25 * res["duration"])
            ray = (t >= t_r + 0.25 * res["duration"]) & (t < t_r + 1.2 * res["duration"])
            pk, pe = np.abs(u).max(), np.abs(ex).max()
            out.append(f"| {h} | {res['n_dofs']:,} | {r:g} | {r / h:g} | {pk:.4e} | {pe:.4e} | "
                       f"{100 * (pk / pe - 1):+.2f} % | {_lag(u, ex, early, 12):+.2f} | "
                       f"{_lag(u, ex, ray, 12):+.2f} | "
                       f"{(t[np.argmax(u)] - t[np.argmax(ex)]) / dt:+.0f} | "
                       f"{np.abs(u[t < t_p]).max() / pe:.1e} |")
        out.append(f"|  | setup {res['setup_s']:.1f} s, {res['steps']} steps in "
                   f"{res['run_s']:.1f} s | | | | | | | | | |")
    out += ["", "The analytic onset is at the P front (zero before it); the FE solution is "
            "causal (its largest value before r/c_P is in the last column, relative to the "
            "peak). Criterion: arrivals within a few time steps, amplitude within "
            "5 % at distances >= 5 elements.", ""]
    return out


def section_c() -> list[str]:
    from test_verification import _box

    closed = {"bottom": ("ux", "uy", "uz"), "x_faces": ("ux", "uy", "uz"),
              "y_faces": ("ux", "uy", "uz")}
    e, _ = _box([], closed, steps=1000)
    e8, _ = _box([], closed, rho_inf=0.8, steps=1000)
    faces = [f"boundary.{f}=absorbing" for f in ("x_min", "x_max", "y_min", "y_max", "base")]
    ed, dd = _box(faces, {}, steps=1000)
    er, dr = _box([*faces, "damping.model=rayleigh", "modal.damping_ratio=0.05"], {}, steps=1000)
    return ["## (c) Energy", "",
            "Box of 4 x 4 x 4 subgrade hexahedra (1 m), a smooth initial velocity field, "
            "1000 steps of 2 ms:", "",
            "| case | quantity | value |", "|---|---|---|",
            f"| closed (all faces fixed), undamped, trapezoidal rule | max \\|E_n - E_0\\| / E_0 "
            f"| {np.abs(e - e[0]).max() / e[0]:.2e} |",
            f"| closed, undamped, generalized-alpha rho_inf = 0.8 | E_1000 / E_0 (max E_n / E_0)"
            f" | {e8[-1] / e8[0]:.4f} ({e8.max() / e8[0]:.6f}) |",
            f"| all faces absorbing | E_1000 / E_0; max \\|E_0 - E_n - dashpot work\\| / E_0 | "
            f"{ed[-1] / ed[0]:.2e}; {np.abs(ed[0] - ed - dd).max() / ed[0]:.2e} |",
            f"| absorbing + Rayleigh 5 % | E_1000 / E_0; max \\|E_0 - E_n - damping work\\| / E_0 "
            f"| {er[-1] / er[0]:.2e}; {np.abs(er[0] - er - dr).max() / er[0]:.2e} |", "",
            "The dashpot work is sum dt vbar^T C vbar with vbar = (v_n + v_{n+1}) / 2, which "
            "the trapezoidal rule balances exactly.", ""]


def section_de(path: Path, label: str) -> list[str]:
    data = json.loads(path.read_text())
    d = data["direct"]
    s = d["stats"]
    out = [f"## (d) Direct vs modal ({label})", "",
           f"`railvib transient`: {s['n_dofs']:,} DOFs, dt {s['dt']:.3e} s, {s['n_steps']} "
           f"steps, {s['time_integration']:.0f} s of time integration"
           + (" (the bench reused that result)" if d["wall_s"] < s["time_integration"] else
              f" ({d['wall_s']:.0f} s wall, {d['peak_rss_gb']:.2f} GB)")
           + "; modal: `railvib "
           "study modes` with the direct solution's damping in modal coordinates "
           f"({data['modal_wall_s']:.0f} s wall). Peak accelerations of the "
           "direct solution and the modal runs' differences from them:", ""]
    rows = data["modal"]
    probes = list(d["peaks"])
    head = ("| probe | direct a_z | direct \\|a\\| | "
            + " | ".join(f"{r['n_modes']}{' + corr.' if r['static_correction'] else ''} "
                         f"({r['band_hz']:.1f} Hz) a_z / \\|a\\|" for r in rows) + " |")
    out += [head, "|---|---|---|" + "---|" * len(rows)]
    for p in probes:
        if f"{p} a_z" not in rows[0]["deviation"]:
            continue
        out.append(f"| {p} | {d['peaks'][p]['a_z']:.4g} | {d['peaks'][p]['a_total']:.4g} | "
                   + " | ".join(f"{100 * r['deviation'][f'{p} a_z']:+.1f} / "
                                f"{100 * r['deviation'][f'{p} a_total']:+.1f} %" for r in rows)
                   + " |")
    out.append("| max over the building probes | | | "
               + " | ".join(f"{100 * r['max_building']:.1f} %" for r in rows) + " |")
    if all("in_band_deviation" in r for r in rows):
        out += ["", "In-band check, the whole modal chain against the direct solution where the "
                "modes are complete: a_z of both low-passed (zero phase, Butterworth order 8) at "
                "0.8 x the modal band:", "",
                "| probe | " + " | ".join(f"{r['n_modes']}"
                                          f"{' + corr.' if r['static_correction'] else ''} "
                                          f"(< {r['in_band_hz']:.1f} Hz)" for r in rows) + " |",
                "|---|" + "---|" * len(rows)]
        for p in rows[0]["in_band_deviation"]:
            out.append(f"| {p} | " + " | ".join(f"{100 * r['in_band_deviation'][p]:+.1f} %"
                                                 for r in rows) + " |")
    out += ["", "Share of the direct solution's building acceleration energy below each modal "
            "band:", ""]
    for r in rows:
        if not r["static_correction"]:
            out.append(f"- {r['n_modes']} modes ({r['band_hz']:.1f} Hz): "
                       + ", ".join(f"{p} {100 * v:.1f} %"
                                   for p, v in r["fraction_below_band"].items()))
    out += ["", f"## (e) Wave arrivals ({label})", "",
            "Time after the first wheel enters the flexible rail (x = 3 m); distance from that "
            "point of the rail. The thesis reads 0.16 s (P) and 0.20 s (S) on a clock that "
            "starts with the wheel at x = 0, i.e. 0.06 s and 0.10 s after the entry, for 20.2 m "
            "(the far end of the track-side basement wall).", "",
            "| probe | r [m] | r/c_P [s] | r/c_S [s] | detected, 2 % of the peak [s] | "
            "detected, 10 % [s] | largest acceleration [s] |", "|---|---|---|---|---|---|---|"]
    for name, a in data["arrivals"].items():
        out.append(f"| {name} | {a['r']:.2f} | {a['r_over_cP']:.4f} | {a['r_over_cS']:.4f} | "
                   f"{a['detected_2pct']:.4f} | {a['detected_10pct']:.4f} | "
                   f"{a.get('peak', float('nan')):.4f} |")
    out.append("")
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--thesis", type=Path, help="direct_vs_modal.json at thesis size")
    p.add_argument("--coarse", type=Path, help="direct_vs_modal.json of the coarse model")
    p.add_argument("--absorbing", type=Path, help="direct_vs_modal.json of the coarse model "
                   "with absorbing faces (modal.damping = 'full')")
    p.add_argument("--out", type=Path, default=ROOT / "docs" / "verification" / "transient.md")
    args = p.parse_args()
    from railvib_hpc.petsc_env import init_petsc

    init_petsc([])
    t0 = time.perf_counter()
    lines = ["# Verification of the full-order solver (`railvib transient`)", "",
             "Regenerate with `flock /tmp/railvib-heavy.lock .venv/bin/python "
             "bench/transient_verification.py --thesis ... --coarse ...` (cases a-c: a few "
             "minutes, serial; d, e from `bench/transient_vs_modal.py`). The CI versions of "
             "(a)-(c) are `tests/transient/test_verification.py` (serial and 2 ranks).", ""]
    lines += section_a() + section_b() + section_c()
    for path, label in ((args.thesis, "thesis model, refinement 1"),
                        (args.coarse, "coarse model, refinement 0.5"),
                        (args.absorbing, "coarse model, absorbing faces")):
        if path is not None and path.exists():
            lines += section_de(path, label)
    lines.append(f"_Generated in {time.perf_counter() - t0:.0f} s by "
                 "bench/transient_verification.py._")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
