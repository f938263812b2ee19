"""Direct (full-order) vs modal solution of one case, and the wave arrivals (issue 12, d, e).

Usage (heavy: run under the lock)::

    flock /tmp/railvib-heavy.lock .venv/bin/python bench/transient_vs_modal.py \\
        jobs/thesis_baseline.toml results/direct_vs_modal [--ranks 2] [--modes 100,300,600] \\
        [--set KEY=VALUE ...]

1. ``railvib transient`` (the direct solution, with the case's ``[damping]``: Rayleigh
   ``modal.damping_ratio`` at ``damping.f1``, ``f2`` by default) into ``OUT/direct``, with
   three extra probes on the track-side basement wall (near end, middle, far end);
2. ``railvib study modes`` with ``modal.damping = 'rayleigh'`` (the same damping, diagonal:
   exactly the direct solver's C in modal coordinates when no face absorbs; ``--modal-damping
   full`` for absorbing faces: the coupled modal equations with ``Phi^T C Phi``) for the mode
   counts, without and with the static correction, into ``OUT/modes``;
3. prints (markdown) the probe peaks of both and their differences, the same of both
   low-passed below the modal band (the in-band check of the whole modal chain), how much
   of the direct
   solution's building acceleration lies below each modal band, and the arrivals at the wall
   probes against ``r / c_P``, ``r / c_S`` and the thesis's 0.16 s / 0.20 s (its clock starts
   with the wheel at x = 0, which enters the flexible rail at 0.10 s). JSON in
   ``OUT/direct_vs_modal.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PY = str(ROOT / ".venv" / "bin" / "python")
BUILDING = ("footing", "basement_wall", "slab1", "slab2")
GROUND = ("ground_toe", "ground_mid", "ground_building", "ground_far")
#: Track-side basement wall, outer face (y = YS2 = -9.9 m), mid-height of the wall below
#: ground (z = 3.6 m): near end, middle and far end along the track.
WALL = {"wall_near": (12.9, -9.9, 3.6), "wall_mid": (16.2, -9.9, 3.6),
        "wall_far": (19.5, -9.9, 3.6)}


def _run(cmd: list[str], log: Path) -> tuple[float, float]:
    """Run a command; returns (wall seconds, peak RSS summed over processes in GB)."""
    t0 = time.perf_counter()
    with open(log, "w") as f:
        proc = subprocess.run(["/usr/bin/time", "-v", *cmd], stdout=f, stderr=subprocess.STDOUT,
                              env={**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1",
                                   "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"})
    wall = time.perf_counter() - t0
    text = log.read_text()
    if proc.returncode != 0:
        sys.exit(f"failed ({proc.returncode}): {' '.join(cmd)}; see {log}")
    rss = re.findall(r"Maximum resident set size \(kbytes\): (\d+)", text)
    return wall, sum(int(x) for x in rss) / 1e6


def _peaks(hist: dict) -> dict:
    out = {}
    for name, h in hist.items():
        a = h["acceleration"]
        out[name] = {"a_z": float(np.abs(a[:, 2]).max()),
                     "a_total": float(np.linalg.norm(a, axis=1).max()),
                     "v_total": float(np.linalg.norm(h["velocity"], axis=1).max())}
    return out


def band_fraction(t: np.ndarray, a: np.ndarray, f_hz: float) -> float:
    """Share of the acceleration energy (all components) below ``f_hz``."""
    dt = float(np.median(np.diff(t)))
    spec = np.abs(np.fft.rfft(a, axis=0)) ** 2
    f = np.fft.rfftfreq(len(t), dt)
    return float(spec[f <= f_hz].sum() / spec.sum())


#: Low-pass corner of the in-band comparison, as a share of the modal band: the Butterworth
#: filter (order 8) passes 99.6 % of the amplitude at 0.8 of its corner, so the band's top
#: modes (whose truncation neighbours are missing) stay out of the comparison.
IN_BAND = 0.8


def low_passed_peak(t: np.ndarray, a: np.ndarray, f_hz: float, t_grid: np.ndarray) -> float:
    """Largest vertical acceleration after a zero-phase low-pass at ``f_hz``, on ``t_grid``."""
    from scipy.signal import butter, sosfiltfilt

    az = np.interp(t_grid, t, a[:, 2])
    dt = float(t_grid[1] - t_grid[0])
    sos = butter(8, f_hz, fs=1.0 / dt, output="sos")
    return float(np.abs(sosfiltfilt(sos, az)).max())


def arrivals(case, hist: dict, names) -> dict:
    """Detected arrivals at probes from the direct solution (first exceedance of 2 % and
    10 % of the peak acceleration magnitude after the entry) and the analytic times."""
    from railvib_hpc.assess.stage import wave_arrival, wave_speeds
    from railvib_hpc.problem import Problem

    c_p, c_s = wave_speeds(Problem.from_case(case))
    x_entry = case["geometry.x1"]
    t_entry = (x_entry - case["vehicle.x_start"]) / case["vehicle.speed"]
    src = np.array([x_entry, -0.5 * case["track.gauge"], case["geometry.z4"]])
    out = {}
    for name in names:
        h = hist[name]
        r = float(np.linalg.norm(np.asarray(h["coords"]) - src))
        out[name] = {"r": r, "t_entry": t_entry, "r_over_cP": r / c_p, "r_over_cS": r / c_s,
                     "detected_2pct": wave_arrival(h["t"], h["acceleration"], t_entry, 0.02)
                     - t_entry,
                     "detected_10pct": wave_arrival(h["t"], h["acceleration"], t_entry, 0.10)
                     - t_entry,
                     "peak": float(h["t"][np.argmax(np.linalg.norm(h["acceleration"], axis=1))])
                     - t_entry}
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("case")
    p.add_argument("out", type=Path)
    p.add_argument("--ranks", type=int, default=2)
    p.add_argument("--modes", default="100,300,600")
    p.add_argument("--set", dest="overrides", action="append", default=[])
    p.add_argument("--modal-damping", default="rayleigh", choices=("rayleigh", "full"),
                   help="modal.damping of the modal runs: rayleigh (diagonal, exact without "
                        "absorbing faces) or full (Phi^T C Phi: absorbing faces)")
    args = p.parse_args()
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    sets = [x for s in args.overrides for x in ("--set", s)]
    probes = [c for xyz in WALL.values() for c in xyz]
    mpi = ["mpirun", "--oversubscribe", "-n", str(args.ranks), PY, "-m", "railvib_hpc"]
    direct_sets = [*sets, "--set", f"output.probes={json.dumps(probes)}"]
    wall_d, rss_d = _run([*mpi, "transient", args.case, "--out", str(out / "direct"),
                          *direct_sets], out / "direct.log")
    modes = [int(x) for x in args.modes.split(",")]
    wall_m, rss_m = _run([*mpi, "study", "modes", args.case, "--out", str(out), *sets,
                          "--set", f"modal.damping={args.modal_damping}", "--study-set",
                          f"n_modes={json.dumps(modes)}", "--study-set",
                          "static_correction=[false,true]"], out / "modes.log")

    sys.path.insert(0, str(ROOT))
    from railvib_hpc.assess.stage import read_probes
    from railvib_hpc.config import load_case

    case = load_case(args.case, args.overrides)
    hist = read_probes(out / "direct" / "probes.h5")
    for i, name in enumerate(WALL):                  # output.probes are named user_1, ...
        hist[name] = hist.pop(f"user_{i + 1}")
    direct = _peaks(hist)
    stats = json.loads(__import__("h5py").File(out / "direct" / "transient.h5", "r")
                       .attrs["stats"])
    rows = []
    for res_path in sorted((out / "modes").glob("n*/result.json")):
        res = json.loads(res_path.read_text())
        if not res.get("complete"):
            continue
        pk = res["probes"]
        dev = {f"{p} {k}": pk[p][{"a_z": "acc_vertical", "a_total": "acc_total"}[k]]
               / direct[p][k] - 1.0 for p in BUILDING + GROUND for k in ("a_z", "a_total")}
        mhist = read_probes(res_path.parent / "probes.h5")
        f_lp = IN_BAND * res["model"]["f_max_hz"]
        grid = hist[BUILDING[0]]["t"]
        in_band = {p: low_passed_peak(mhist[p]["t"], mhist[p]["acceleration"], f_lp, grid)
                   / low_passed_peak(hist[p]["t"], hist[p]["acceleration"], f_lp, grid) - 1.0
                   for p in BUILDING + GROUND}
        rows.append({"variant": res["variant"], "n_modes": res["parameter"]["n_modes"],
                     "in_band_hz": f_lp, "in_band_deviation": in_band,
                     "static_correction": res["parameter"]["static_correction"],
                     "band_hz": res["model"]["f_max_hz"], "deviation": dev,
                     "max_building": max(abs(v) for k, v in dev.items()
                                         if k.split()[0] in BUILDING),
                     "peak_contact_force": res["mbs"]["peak_contact_force"],
                     "fraction_below_band": {p: band_fraction(hist[p]["t"],
                                                              hist[p]["acceleration"],
                                                              res["model"]["f_max_hz"])
                                             for p in BUILDING}})
    rows.sort(key=lambda r: (r["n_modes"], r["static_correction"]))
    arr = arrivals(case, hist, [*WALL, "footing", "ground_building", "ground_mid",
                                "ground_far"])
    summary = {"direct": {"peaks": direct, "stats": {k: stats[k] for k in
                                                      ("dt", "n_steps", "n_dofs",
                                                       "time_integration", "steps_per_second",
                                                       "peak_contact_force",
                                                       "min_contact_force")},
                          "wall_s": wall_d, "peak_rss_gb": rss_d},
               "modal": rows, "modal_wall_s": wall_m, "modal_peak_rss_gb": rss_m,
               "arrivals": arr}
    (out / "direct_vs_modal.json").write_text(json.dumps(summary, indent=1))

    print(f"direct: {stats['n_dofs']:,} DOFs, dt {stats['dt']:.3e} s, {stats['n_steps']} steps, "
          f"wall {wall_d:.0f} s, peak {rss_d:.2f} GB; modal study: wall {wall_m:.0f} s, peak "
          f"{rss_m:.2f} GB")
    print("\n| probe | direct a_z [m/s²] | direct \\|a\\| [m/s²] | "
          + " | ".join(f"{r['variant']} ({r['band_hz']:.1f} Hz)" for r in rows) + " |")
    print("|---|---|---|" + "---|" * len(rows))
    for pname in BUILDING + GROUND:
        for k in ("a_z", "a_total"):
            label = f"{pname} {k}"
            print(f"| {label} | {direct[pname]['a_z']:.4g} | {direct[pname]['a_total']:.4g} | "
                  if k == "a_z" else f"| {label} | | | ", end="")
            print(" | ".join(f"{100 * r['deviation'][label]:+.1f} %" for r in rows) + " |")
    print("| max over building probes | | | "
          + " | ".join(f"{100 * r['max_building']:.1f} %" for r in rows) + " |")
    print("| peak contact force [kN] | "
          f"{max(stats['peak_contact_force']) / 1e3:.3f} | | "
          + " | ".join(f"{r['peak_contact_force'] / 1e3:.3f}" for r in rows) + " |")
    print(f"\nIn-band check (a_z of both low-passed at {IN_BAND} x the band, zero phase): the "
          "modal chain against the direct solution where the modes are complete")
    print("| probe | " + " | ".join(f"{r['variant']} (< {r['in_band_hz']:.1f} Hz)"
                                      for r in rows) + " |")
    print("|---|" + "---|" * len(rows))
    for pname in BUILDING + GROUND:
        print(f"| {pname} | " + " | ".join(f"{100 * r['in_band_deviation'][pname]:+.1f} %"
                                            for r in rows) + " |")
    print("| max over building probes | " + " | ".join(
        f"{100 * max(abs(r['in_band_deviation'][p]) for p in BUILDING):.1f} %" for r in rows)
        + " |")
    print("\nShare of the direct solution's acceleration energy below each modal band:")
    for r in rows:
        if r["static_correction"]:
            continue
        print(f"  {r['n_modes']} modes ({r['band_hz']:.1f} Hz): "
              + ", ".join(f"{p} {100 * v:.1f} %" for p, v in r["fraction_below_band"].items()))
    c = load_case(args.case, args.overrides)
    t0 = (c["geometry.x1"] - c["vehicle.x_start"]) / c["vehicle.speed"]
    print(f"\nArrivals (time after the wheel enters the flexible rail at {t0:.3f} s; "
          "thesis: P 0.06 s, S 0.10 s after entry = 0.16 / 0.20 s on its clock):")
    print("| probe | r [m] | r/c_P [s] | r/c_S [s] | detected, 2 % of peak [s] | "
          "detected, 10 % [s] | largest acceleration [s] |")
    print("|---|---|---|---|---|---|---|")
    for name, a in arr.items():
        print(f"| {name} | {a['r']:.2f} | {a['r_over_cP']:.4f} | {a['r_over_cS']:.4f} | "
              f"{a['detected_2pct']:.4f} | {a['detected_10pct']:.4f} | {a['peak']:.4f} |")


if __name__ == "__main__":
    main()
