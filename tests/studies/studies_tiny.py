"""Shared settings of the tiny CI studies (refinement <= 0.5, 8 modes, short runs)."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
BASELINE = ROOT / "jobs" / "thesis_baseline.toml"
#: A tiny model: coarse mesh, few modes, block size 8 (the modal solve takes ~2 s).
TINY = ["--set", "mesh.refinement=0.25", "--set", "modal.n_modes=8",
        "--set", "modal.block_size=8"]
