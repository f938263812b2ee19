"""A wave-impeding block (``[wib]``) on the coarse slice with absorbing boundaries (issue 15,
item 4: a reference case for the measure): it is invisible to waves much longer than it,
and screens short waves when it lies within their reach.

The model is ``test_fem_trench_trend``'s plane-strain slice (c_S = 200 m/s, 0.5 m elements,
Lysmer-Kuhlemeyer dashpots on both ends and the base, 5 % hysteretic damping), the load at
8 m and the receivers 20-26 m on the surface. The block is the project's default
``materials.wib`` (stabilised soil, E = 2 GPa, rho = 2100, ~11 x the soil's modulus): 6 m
wide centred under the load (the embankment base's width), 1 m thick, its top ``d`` below
the ground. The insertion loss compares the same mesh with and without the block's
material, rms over the receivers and 5 frequencies per band.

The physics the test checks:

* **Long waves pass.** At 8-12 Hz the Rayleigh wavelength (lambda_R ~ 0.93 c_S / f, 18.6 m
  at 10 Hz) is three times the block's width: the soil's stiffness averaged over a
  wavelength hardly changes, and neither does the response (|IL| < 1 dB).
* **Short waves are screened near the surface.** At 50-70 Hz (lambda_R ~ 3.1 m at 60 Hz)
  the Rayleigh wave carries its energy within about lambda_R / 2 of the surface. A block
  0.5 m down sits in it and stiffens the ground under the load: the surface response falls
  by several dB. A block 2 m down lies below most of it and changes little.

The literature's numbers are of this size: Thompson, Jiang, Toward, Hussein, Dijckmans,
Coulier, Degrande and Lombaert (Soil Dyn. Earthq. Eng. 79 (2015) 89-103) report 4-10 dB
between 16 and 50 Hz for a 6 m x 1 m concrete block directly under the track on ground
with a 3 m soft upper layer. This slice is homogeneous and not their model: it checks the
mechanism, not their values.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_fem_trench_trend import (
    DEPTH,
    HIGH,
    LOW,
    RHO,
    Y_SOURCE,
    E,
    insertion_loss,
    slice_model,
    slice_response,
)

#: materials.wib's defaults (railvib_hpc.schema): stabilised soil.
E_WIB, RHO_WIB = 2.0e9, 2100.0
WIB_WIDTH, WIB_THICKNESS = 6.0, 1.0


@pytest.mark.slow
def test_block_is_invisible_to_long_waves_and_screens_short_ones_near_the_surface():
    points, hexes, faces, blocks = slice_model()
    centre = points[hexes].mean(axis=1)
    il = {}
    for band, freqs in (("low", LOW), ("high", HIGH)):
        ref = slice_response(points, hexes, faces, blocks, freqs)
        for d in (0.5, 2.0):
            z = DEPTH - centre[:, 2]                                  # depth below the ground
            block = (np.abs(centre[:, 1] - Y_SOURCE) < WIB_WIDTH / 2) & (z > d) & \
                (z < d + WIB_THICKNESS)
            assert block.sum() == int(WIB_WIDTH / 0.5) * int(WIB_THICKNESS / 0.5)
            out = slice_response(points, hexes, faces, blocks, freqs,
                                 E_el=np.where(block, E_WIB, E),
                                 rho_el=np.where(block, RHO_WIB, RHO))
            il[band, d] = insertion_loss(ref, out)
    print({f"{b} {d} m": round(v, 2) for (b, d), v in il.items()})
    assert abs(il["low", 0.5]) < 1.0 and abs(il["low", 2.0]) < 1.0
    assert il["high", 0.5] >= 5.0
    assert il["high", 0.5] > il["high", 2.0] + 5.0
