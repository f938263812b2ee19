"""Studies under faults: a corrupt shared model or result is recomputed, not reused; a
variant folder in use is refused while another variant runs concurrently."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
from faults import ENV, serial_only

from railvib_hpc.cli import run

ROOT = Path(__file__).resolve().parents[2]
TINY = ["--set", "mesh.refinement=0.25", "--set", "modal.n_modes=8",
        "--set", "modal.block_size=8"]


@pytest.mark.slow
@serial_only
def test_corrupt_shared_model_and_result_are_recomputed_and_busy_variants_refused(
        tmp_path, capsys, tally):
    base = ["study", "speed", str(ROOT / "jobs" / "thesis_baseline.toml"), *TINY, "--out",
            str(tmp_path), "--study-set", "speeds=[20, 60]"]
    root = tmp_path / "speed"
    assert run([*base, "--variant", "0"]) == 0
    first = json.loads((root / "v20" / "result.json").read_text())
    capsys.readouterr()
    # NaN in the shared modes: the model is recomputed, the variant's result with it
    with h5py.File(root / "model" / "modes.h5", "r+") as f:
        f["modes/translation"][2, 100, 2] = np.nan
    assert run([*base, "--variant", "0"]) == 0
    out = capsys.readouterr().out
    ok = (f"recomputing {root / 'model' / 'modes.h5'}: it is corrupt" in out
          and "[speed/v20] running" in out)
    again = json.loads((root / "v20" / "result.json").read_text())
    same = again["probes"] == first["probes"] and again["mbs"] == first["mbs"]
    tally.add("study: NaN in the shared modes", "recomputed" if ok and same else
              "silent wrong")
    assert ok and same, out
    # an edited result.json is not taken as finished
    doc = json.loads((root / "v20" / "result.json").read_text())
    doc["mbs"]["peak_contact_force"] *= 2
    (root / "v20" / "result.json").write_text(json.dumps(doc))
    assert run([*base, "--variant", "0"]) == 0
    out = capsys.readouterr().out
    ok = "[speed/v20] running" in out and "finished earlier" not in out
    tally.add("study: edited result.json", "recomputed" if ok else "silent wrong")
    assert ok, out
    # v20 busy in another process: refused at once; v60 runs meanwhile
    holder = subprocess.Popen([sys.executable, "-c", (
        "import time; from pathlib import Path; from railvib_hpc.io import locks\n"
        f"locks.acquire_lock(Path({str(root / 'v20')!r}), 'railvib study speed --variant 0')\n"
        "print('held', flush=True); time.sleep(60)")], stdout=subprocess.PIPE, text=True,
        env=ENV)
    try:
        assert holder.stdout.readline().strip() == "held"
        code = run([*base, "--variant", "0"])
        err = capsys.readouterr().err
        lines = [ln for ln in err.splitlines() if ln.strip()]
        clear = code == 2 and len(lines) == 1 and "is in use by pid" in lines[0]
        tally.add("study: variant folder in use", "clear error" if clear else "unclear", err)
        assert clear, err
        assert run([*base, "--variant", "1"]) == 0
        assert (root / "v60" / "result.json").exists()
    finally:
        holder.kill()
        holder.wait()
