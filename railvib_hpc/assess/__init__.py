"""Vibration assessment against the standards (pure numpy/scipy; matplotlib for the report).

* :mod:`.weighting`: W_m (ISO 2631-2/ISO 8041) and KB (DIN 4150-2) weightings from their
  analog transfer functions, applied in the frequency domain; one-third-octave bands.
* :mod:`.metrics`: RMS, running RMS (exponential), MTVV, VDV, peak, PPV with dominant
  frequency, FTA velocity level, KB_Fmax.
* :mod:`.standards`: limits (ISO 10137/BS 6472, DIN 4150-2/-3, FTA, VC curves, the thesis
  criterion), :func:`assess_probe` and :func:`format_table`.
* :mod:`.report`: :func:`write_report` (markdown, HTML, PNG figures, JSON).

The criteria (weighting, metrics, standards) sit low in the layer order (the case schema
reads the standards registry); the report and the stage sit high. So that importing the
criteria does not import the report (and its file layer), ``write_report`` is loaded on
first use.
"""

from .metrics import (
    fta_vdb,
    kb_f,
    kb_fmax,
    kb_ftm,
    linear_running_rms,
    mtvv,
    peak,
    ppv,
    rms,
    running_rms,
    vdv,
    velocity_level,
)
from .standards import (
    STANDARDS,
    AssessInputError,
    Standard,
    assess_probe,
    din4150_2_guide_values,
    din4150_3_limit,
    format_table,
    fta_limit,
    iso_limit,
    vc_curve,
    vc_spectrum,
)
from .weighting import (
    BandSpectrum,
    ThirdOctaveBands,
    apply_response,
    band_limit_response,
    kb_response,
    third_octave_bands,
    third_octave_rms,
    weight_kb,
    weight_wm,
    wm_response,
)

__all__ = [
    "STANDARDS",
    "AssessInputError",
    "BandSpectrum",
    "Standard",
    "ThirdOctaveBands",
    "apply_response",
    "assess_probe",
    "band_limit_response",
    "din4150_2_guide_values",
    "din4150_3_limit",
    "format_table",
    "fta_limit",
    "fta_vdb",
    "iso_limit",
    "kb_f",
    "kb_fmax",
    "kb_ftm",
    "kb_response",
    "linear_running_rms",
    "mtvv",
    "peak",
    "ppv",
    "rms",
    "running_rms",
    "third_octave_bands",
    "third_octave_rms",
    "vc_curve",
    "vc_spectrum",
    "vdv",
    "velocity_level",
    "weight_kb",
    "weight_wm",
    "wm_response",
    "write_report",
]


def __getattr__(name: str):
    """``write_report`` on first use (see the module notes)."""
    if name == "write_report":
        from .report import write_report

        return write_report
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
