# %% [markdown]
# # Rail-pad stiffness: a parametric study with the Python API
#
# How much does the vertical stiffness of the rail pads change what a passing wheelset
# does to the building next to the track? This example runs the thesis baseline on a
# **coarse model** (mesh refinement 0.25, 8 modes: seconds per variant, numbers for
# illustration only) for three pad stiffnesses, from the thesis's Table I (2.65e8 N/m) to
# its APDL script (7e9 N/m), and tabulates the first natural frequency, the largest rail
# deflection under a wheel, the peak wheel-rail contact force and the peak vertical
# acceleration of both slabs. The softest variant is then assessed against the vibration
# standards.
#
# The same content is `examples/pad_stiffness.py` (run it with `python
# examples/pad_stiffness.py`, or under `mpirun -n 2`); `examples/pad_stiffness.ipynb` is
# generated from it by `python tools/notebook.py examples/pad_stiffness.py`. Results go to
# `$RAILVIB_EXAMPLE_OUT` (default `results/examples/pad_stiffness`), one folder per
# variant; a second run reuses every stage's files.

# %%
import os
from pathlib import Path

import railvib_hpc as rv

ROOT = Path(rv.__file__).resolve().parents[1]
OUT = Path(os.environ.get("RAILVIB_EXAMPLE_OUT", "results/examples/pad_stiffness"))

# %% [markdown]
# ## The coarse base case
#
# `Case.replace` returns a new, validated case: values are typed and checked like a case
# file's (a bad value raises `CaseError` naming the key, the value and what is allowed).
# Eight modes cannot represent the rail's flexibility on its pads; the static correction
# (`mbs.static_correction`) adds the static flexibility of the truncated modes at the
# wheels, which is where the pads' stiffness shows.

# %%
base = rv.Case.from_file(ROOT / "jobs" / "thesis_baseline.toml").replace({
    "mesh.refinement": 0.25,        # coarse mesh: ~5,000 nodes
    "modal.n_modes": 8,             # few modes: seconds, not minutes
    "modal.block_size": 8,
    "output.dt": 0.01,              # field output every 10 ms
    "output.stress_times": [],      # no element stresses
    "mbs.static_correction": True,  # the rail's (and pads') static flexibility at the wheels
})
stiffnesses = [2.65e8, 1.0e9, 7.0e9]    # pads.kz [N/m]: Table I, between, APDL script

# %% [markdown]
# ## The sweep
#
# One `Pipeline` per variant and output folder; each stage method returns a small frozen
# result (files, key numbers, `reused`, timings). The mesh does not depend on the pads,
# the modes and everything after them do.

# %%
rows = []
for kz in stiffnesses:
    case = base.replace({"pads.kz": kz})
    pipe = rv.Pipeline(case, OUT / f"kz_{kz:.3g}", quiet=True)
    pipe.mesh()
    modal = pipe.modal()
    mbs = pipe.mbs()
    probes = pipe.reconstruct().probes
    rows.append({"kz": kz, "f1": modal.frequencies_hz[0],
                 "deflection": mbs.max_rail_deflection,
                 "force": mbs.peak_contact_force.max(),
                 "slab1": probes["slab1"].acc_vertical,
                 "slab2": probes["slab2"].acc_vertical,
                 "reused": modal.reused, "pipeline": pipe})

print(f"{'pads.kz [N/m]':>13}  {'f1 [Hz]':>7}  {'rail [mm]':>9}  {'contact [kN]':>12}  "
      f"{'slab 1 a_z [m/s2]':>17}  {'slab 2 a_z [m/s2]':>17}")
for r in rows:
    print(f"{r['kz']:13.3g}  {r['f1']:7.3f}  {r['deflection'] * 1e3:9.4f}  "
          f"{r['force'] / 1e3:12.3f}  {r['slab1']:17.3e}  {r['slab2']:17.3e}")

# %% [markdown]
# ## The softest pads against the standards
#
# `assess()` evaluates every probe (ISO 2631-2, DIN 4150-2/-3, FTA, VC curves) and writes
# the report; `verdict` maps each probe to pass/fail.

# %%
softest = rows[0]["pipeline"].assess()
worst = max(softest.max_utilisation, key=lambda k: softest.max_utilisation[k] or 0.0)
print(f"pads.kz = {rows[0]['kz']:.3g} N/m: "
      + ("every probe passes" if softest.passed else
         f"limits exceeded at {', '.join(softest.exceeded)}")
      + f"; largest utilisation {softest.max_utilisation[worst]:.3f} at {worst}; "
      f"report: {softest.report_html}")

# %% [markdown]
# Every stage call is recorded in the folder's `run.json`: wall time, the timed parts,
# the peak memory of every rank, versions and the case digest.

# %%
record = rows[0]["pipeline"].run_record()
print({stage: round(entry["wall_s"], 2) for stage, entry in record["stages"].items()})
