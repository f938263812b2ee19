"""Benchmark (not collected by pytest): the multibody stage on the real thesis modes.

Needs ``results/thesis_baseline/modes.h5`` and ``static.h5`` (``make run`` or
``mpirun -n 2 railvib modal jobs/thesis_baseline.toml --set mbs.static_correction=true``).
Prints: passage time and steps/s (target <= 30 s), dt convergence of the peak
contact force (target < 1 % for dt/2), rail deflection and peak force against
the number of modes with and without the static correction, and the 4-car
train passage (target <= 5 min).

Run: ``.venv/bin/python bench/mbs_thesis_bench.py [results/thesis_baseline]``
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

from railvib_hpc.config import load_case
from railvib_hpc.io.stage_protocol import StageRunner
from railvib_hpc.log import Reporter
from railvib_hpc.mbs.stage import STAGE, simulate_case

ROOT = Path(__file__).resolve().parents[1]


class _Quiet(Reporter):
    def info(self, msg: str) -> None:
        pass

    def progress(self, *args) -> None:
        pass


def passage(src: Path, *overrides: str) -> dict:
    """Run the mbs stage with overrides in a scratch folder linked to the modes."""
    case = load_case(ROOT / "jobs" / "thesis_baseline.toml", list(overrides))
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        for name in ("modes.h5", "static.h5"):
            if (src / name).exists():
                (out / name).symlink_to((src / name).resolve())
        t0 = time.perf_counter()
        from mpi4py import MPI

        # the stage's work in a context of the scratch folder (its links are no run's files)
        ctx = StageRunner(out, MPI.COMM_SELF, _Quiet(0), command="mbs").context(case, STAGE)
        stats = simulate_case(ctx)
        stats["wall"] = time.perf_counter() - t0
    return stats


def main() -> None:
    """Print the benchmark tables."""
    src = Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "results" / "thesis_baseline"
    if not (src / "modes.h5").exists():
        raise SystemExit(f"{src}/modes.h5 missing: run the modal stage first")
    s = passage(src)
    print(f"thesis passage (wheelset, {s['n_modes']} modes, 30 m/s, x = 0 -> 27.6 m): "
          f"dt = {s['dt']:.2e} s, {s['n_steps']} steps, integration {s['time_integration']:.2f}"
          f" s ({s['steps_per_second']:.0f} steps/s), stage wall {s['wall']:.2f} s")
    print(f"  contact force per wheel: static {s['static_wheel_load'][0]:.1f} N, mean on the "
          f"flexible rail {s['mean_contact_force'][0]:.1f} / {s['mean_contact_force'][1]:.1f} N,"
          f" peak {s['peak_contact_force'][0]:.1f} / {s['peak_contact_force'][1]:.1f} N, "
          f"min {s['min_contact_force'][0]:.1f} N, loss of contact {s['loss_of_contact_steps']}")
    have_static = (src / "static.h5").exists()
    for sc in ("false", "true") if have_static else ("false",):
        a = passage(src, f"mbs.static_correction={sc}")
        b = passage(src, f"mbs.static_correction={sc}", f"mbs.dt={a['dt'] / 2}")
        ch = abs(b["peak_contact_force"][0] / a["peak_contact_force"][0] - 1)
        print(f"dt convergence (static correction {sc}): peak force "
              f"{a['peak_contact_force'][0]:.1f}"
              f" N at dt = {a['dt']:.2e}, {b['peak_contact_force'][0]:.1f} N at dt/2: "
              f"change {100 * ch:.2f} %")
    print("modes | static corr. | max rail deflection [mm] | peak force [N] | min force [N]")
    for m in (50, 100, 200, 300):
        for sc in ("false", "true") if have_static else ("false",):
            r = passage(src, f"mbs.n_modes={m}", f"mbs.static_correction={sc}")
            print(f"{m:5d} | {sc:12s} | {r['max_rail_deflection'] * 1e3:24.5f} | "
                  f"{r['peak_contact_force'][0]:14.1f} | {r['min_contact_force'][0]:13.1f}")
    t = passage(src, "vehicle.type=vehicle", "vehicle.n_cars=4")
    print(f"4-car train (32 wheels, 68 DOFs): {t['n_steps']} steps, integration "
          f"{t['time_integration']:.1f} s ({t['steps_per_second']:.0f} steps/s), stage wall "
          f"{t['wall']:.1f} s; static wheel load {t['static_wheel_load'][0]:.0f} N, peak "
          f"{max(t['peak_contact_force']):.0f} N, min {min(t['min_contact_force']):.0f} N")


if __name__ == "__main__":
    main()
