"""Assessment report: markdown + self-contained HTML page, PNG figures and a JSON of all data.

Files written to ``out_dir`` (each written to a temporary name in the same folder and
renamed with :func:`os.replace`, so an interrupted run never leaves a file that looks
complete)::

    report.md            summary table, per-probe details, notes, figures (linked PNGs)
    report.html          the same page with the PNGs embedded (base64): one file to share
    report.json          the assessment results and the data of every figure (a long time
                         history as its min/max envelope, as drawn: ``ENVELOPE_BUCKETS``)
    figures/*.png        time histories, one-third-octave spectra vs VC curves, probe
                         peak map, contact force (optional)

Figures are drawn with matplotlib's Agg canvas on :class:`matplotlib.figure.Figure`
objects (no pyplot state, safe in batch jobs without a display). matplotlib is imported
only when a report is written, so the rest of :mod:`railvib_hpc.assess` needs only numpy
and scipy.
"""

from __future__ import annotations

import base64
import html
import json
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..io.atomic import atomic_file
from ..io.files import REPORT_HTML, REPORT_JSON, REPORT_MD
from .standards import (
    STANDARDS,
    THESIS_LIMIT,
    VC_CURVES,
    AssessInputError,
    format_table,
    vc_curve,
    vc_spectrum,
)

__all__ = ["write_report"]

_DIRS = ("x", "y", "z")
_COLOURS = {"x": "tab:blue", "y": "tab:orange", "z": "tab:green"}
_QUANTITIES = (("displacement", "m"), ("velocity", "m/s"), ("acceleration", "m/s²"))
#: Buckets of the min/max envelope that a time-history figure draws and ``report.json``
#: keeps for a long record. The figure is 8 in wide at 110 dpi, 880 pixel columns: two
#: points per column is all a line plot can show. A record of the coarse thesis run has
#: 22,771 samples; drawn and stored whole, its 14 probes made report.json 71 MB and
#: took 9 of the assessment's 20 s (measured).
ENVELOPE_BUCKETS = 1000


def _bad(name: str, value: Any, allowed: str) -> AssessInputError:
    return AssessInputError(f"{name} = {value!r}: {allowed}")


def _jsonable(x: Any) -> Any:
    """Arrays/numpy scalars to lists/floats, NaN/inf to None (strict JSON)."""
    if isinstance(x, Mapping):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        if x.dtype.kind == "f":
            obj = np.where(np.isfinite(x), x, np.nan).astype(object)
            obj[~np.isfinite(x)] = None
            return obj.tolist()
        return x.tolist()
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not np.isfinite(x):
        return None
    return x


def _slug(name: str, used: set[str]) -> str:
    base = re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("._") or "probe"
    slug, k = base, 2
    while slug in used:
        slug, k = f"{base}_{k}", k + 1
    used.add(slug)
    return slug


def _check(results, histories, contact) -> tuple[dict, dict, tuple | None]:
    if not isinstance(results, Mapping) or not results:
        raise _bad("results", type(results).__name__,
                   "must be a non-empty mapping probe name -> assess_probe() result")
    for name, r in results.items():
        if not isinstance(r, Mapping) or "standards" not in r:
            raise _bad(f"results[{name!r}]", type(r).__name__,
                       "must be a result of assess_probe()")
    if not isinstance(histories, Mapping):
        raise _bad("histories", type(histories).__name__,
                   "must be a mapping probe name -> {'t', 'displacement', 'velocity', "
                   "'acceleration', 'coords'}")
    missing = [n for n in results if n not in histories]
    if missing:
        raise _bad("histories", sorted(histories),
                   f"has no entry for the probes {missing} of results")
    hist = {}
    for name in results:
        h = histories[name]
        if not isinstance(h, Mapping):
            raise _bad(f"histories[{name!r}]", type(h).__name__, "must be a mapping")
        keys = ("t", "displacement", "velocity", "acceleration", "coords")
        absent = [k for k in keys if k not in h]
        if absent:
            raise _bad(f"histories[{name!r}]", sorted(h), f"misses the keys {absent}")
        t = np.asarray(h["t"], dtype=float)
        if t.ndim != 1 or t.size < 4:
            raise _bad(f"histories[{name!r}]['t']", f"array of shape {t.shape}",
                       "must be 1-D with at least 4 samples")
        entry = {"t": t}
        for k, _ in _QUANTITIES:
            arr = np.asarray(h[k], dtype=float)
            if arr.shape != (t.size, 3):
                raise _bad(f"histories[{name!r}][{k!r}]", f"array of shape {arr.shape}",
                           f"must have shape ({t.size}, 3)")
            entry[k] = arr
        coords = np.asarray(h["coords"], dtype=float)
        if coords.shape != (3,):
            raise _bad(f"histories[{name!r}]['coords']", f"array of shape {coords.shape}",
                       "must have shape (3,): x, y, z [m]")
        entry["coords"] = coords
        hist[name] = entry
    if contact is not None:
        try:
            cx, cf = contact
        except (TypeError, ValueError) as exc:
            raise _bad("contact", type(contact).__name__,
                       "must be None or a pair (x, force)") from exc
        cx, cf = np.asarray(cx, dtype=float), np.asarray(cf, dtype=float)
        if cx.ndim not in (1, 2) or cf.shape[:1] != cx.shape[:1] or cf.ndim not in (1, 2):
            raise _bad("contact", f"arrays of shapes {cx.shape}, {cf.shape}",
                       "x and force must be (n,) or (n, wheels) with the same n")
        contact = (cx, cf)
    return dict(results), hist, contact


# --------------------------------------------------------------------------------------
# figures


#: Fixed margins (figure fractions) of the per-probe figures, in place of matplotlib's
#: constrained layout, which measured every tick label of every figure again: it took 9 of
#: the 17 s the 30 figures of the coarse thesis run took to draw (profiled).
_TIME_MARGINS = {"left": 0.11, "right": 0.98, "bottom": 0.07, "top": 0.93, "hspace": 0.12}
_SPECTRUM_MARGINS = {"left": 0.1, "right": 0.87, "bottom": 0.1, "top": 0.88}
#: Minor ticks and grid lines of the spectrum's velocity axis at 2 and 5 per decade (the
#: axis spans up to nine decades; all eight per decade took half of its drawing time).
_SPECTRUM_MINOR_SUBS = (2.0, 5.0)


def _figure(margins: Mapping[str, float] | None = None, **kwargs: Any) -> Any:
    """A new matplotlib Figure on an Agg canvas: fixed ``margins`` (``subplots_adjust``
    keywords) or, without them, the constrained layout."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(layout=None if margins else "constrained", **kwargs)
    if margins:
        fig.subplots_adjust(**margins)
    FigureCanvasAgg(fig)
    return fig


def _subplots(fig: Any, *args: Any, **kwargs: Any) -> Any:
    """``fig.subplots`` with the axes titles at a fixed height (``axes.titley = 1``):
    matplotlib otherwise measures every tick label of every axes at each draw to move the
    title clear of them, a third of a time-history figure's drawing time (profiled)."""
    import matplotlib

    with matplotlib.rc_context({"axes.titley": 1.0}):
        return fig.subplots(*args, **kwargs)


def _save(fig: Any, path: Path) -> None:
    with atomic_file(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)


def _envelope(t: np.ndarray, series: np.ndarray,
              buckets: int = ENVELOPE_BUCKETS) -> tuple[np.ndarray, np.ndarray, int]:
    """The min/max envelope of columns sampled at ``t``, for drawing a long record.

    Parameters
    ----------
    t : (n,) ndarray
        Sample times.
    series : (n, m) ndarray
        Columns sampled at ``t``.
    buckets : int
        Up to this many buckets of consecutive samples.

    Returns
    -------
    t2 : (2 b,) ndarray
        Each bucket's first and last sample time.
    s2 : (2 b, m) ndarray
        Each column's minimum and maximum in the bucket, in the order they occur there
        (so every extreme and every sign change of the record is kept; its time is exact
        to one bucket).
    per_bucket : int
        Samples per bucket; 1 (and the record itself) when ``n <= 2 buckets``.

    Examples
    --------
    >>> t = np.arange(10_000) * 1e-3
    >>> t2, s2, k = _envelope(t, np.sin(40 * t)[:, None], buckets=100)
    >>> t2.shape, k, float(s2.max()) == float(np.sin(40 * t).max())
    ((200,), 100, True)
    """
    n = t.size
    if n <= 2 * buckets:
        return t, series, 1
    k = -(-n // buckets)
    nb = -(-n // k)
    pad = np.concatenate([series, np.repeat(series[-1:], nb * k - n, axis=0)])
    blocks = pad.reshape(nb, k, -1)
    i_lo, i_hi = blocks.argmin(axis=1), blocks.argmax(axis=1)
    lo = np.take_along_axis(blocks, i_lo[:, None, :], axis=1)[:, 0]
    hi = np.take_along_axis(blocks, i_hi[:, None, :], axis=1)[:, 0]
    first = np.where(i_lo <= i_hi, lo, hi)
    second = np.where(i_lo <= i_hi, hi, lo)
    starts = np.arange(nb) * k
    t2 = np.column_stack([t[starts], t[np.minimum(starts + k, n) - 1]]).ravel()
    return t2, np.stack([first, second], axis=1).reshape(2 * nb, -1), k


def _fig_time(name: str, h: dict, path: Path) -> dict:
    columns = np.concatenate([h[q] for q, _ in _QUANTITIES], axis=1)
    t, env, per_bucket = _envelope(h["t"], columns)
    fig = _figure(_TIME_MARGINS, figsize=(8.0, 7.0))
    axes = _subplots(fig, 3, 1, sharex=True)
    for j, (ax, (q, unit)) in enumerate(zip(axes, _QUANTITIES)):
        for i, d in enumerate(_DIRS):
            ax.plot(t, env[:, 3 * j + i], lw=0.8, color=_COLOURS[d], label=d)
        ax.set_ylabel(f"{q} [{unit}]")
        ax.ticklabel_format(axis="y", style="sci", scilimits=(-3, 4))
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", ncols=3, fontsize="small")
    axes[-1].set_xlabel("t [s]")
    fig.suptitle(f"probe {name}: time histories")
    _save(fig, path)
    data = {"t": t, **{q: {d: env[:, 3 * j + i] for i, d in enumerate(_DIRS)}
                       for j, (q, _) in enumerate(_QUANTITIES)}}
    if per_bucket > 1:
        data["envelope"] = {"samples_per_bucket": per_bucket, "samples": int(h["t"].size),
                            "note": "per bucket each series' minimum and maximum in the "
                                    "order they occur, at the bucket's first and last "
                                    "sample time; the whole record is in the probe files"}
    return data


def _fig_spectrum(name: str, h: dict, result: Mapping, path: Path) -> dict:
    fs = 1.0 / float(np.mean(np.diff(h["t"])))
    spec = vc_spectrum(h["velocity"], fs)
    nominal = spec.bands.nominal
    settings = result.get("settings", {})
    chosen = settings.get("vc_class")
    low = settings.get("vc_low_frequency", "constant_acceleration")
    curves = {c: vc_curve(nominal, c, low) for c in VC_CURVES}
    fig = _figure(_SPECTRUM_MARGINS, figsize=(8.0, 5.0))
    ax = _subplots(fig)
    for c, lim in curves.items():
        bold = c == chosen
        ax.plot(nominal, lim * 1e6, color="k" if bold else "0.65", lw=1.8 if bold else 0.7,
                ls="-" if bold else "--", zorder=1)
        ax.annotate(c, (nominal[-1], lim[-1] * 1e6), fontsize=7, va="center",
                    xytext=(3, 0), textcoords="offset points",
                    color="k" if bold else "0.45")
    ok = spec.n_bins > 0
    for i, d in enumerate(_DIRS):
        vals = np.where(ok, spec.rms[:, i], np.nan) * 1e6
        ax.plot(nominal, vals, marker="o", ms=3.5, lw=1.2, color=_COLOURS[d], label=d,
                zorder=3)
    ax.set_xscale("log")
    ax.set_yscale("log", subs=_SPECTRUM_MINOR_SUBS)
    top = max(float(np.max(spec.rms[ok], initial=0.0)) * 1e6,
              max(float(c.max()) for c in curves.values()) * 1e6)
    floor = min(0.1 * min(VC_CURVES.values()) * 1e6, 1e-3 * top)
    ax.set_ylim(floor, 2.0 * top)
    ax.set_xlabel("one-third-octave band centre [Hz]")
    ax.set_ylabel("RMS velocity [µm/s]")
    ax.grid(which="both", alpha=0.3)
    ax.legend(loc="lower left", fontsize="small")
    ax.set_title(f"probe {name}: 1/3-octave RMS velocity vs VC curves\n"
                 f"(bold: {chosen}; below 8 Hz: {low.replace('_', ' ')})", fontsize="medium")
    _save(fig, path)
    return {"nominal_hz": nominal, "n_bins": spec.n_bins,
            "rms_m_per_s": {d: np.where(ok, spec.rms[:, i], np.nan)
                            for i, d in enumerate(_DIRS)},
            "vc_curves_m_per_s": curves, "vc_class": chosen, "vc_low_frequency": low}


def _fig_probes(hist: dict, path: Path) -> dict:
    names = list(hist)
    peaks = np.array([np.max(np.abs(hist[n]["acceleration"]), axis=0) for n in names])
    total = np.array([np.max(np.linalg.norm(hist[n]["acceleration"], axis=1)) for n in names])
    coords = np.array([hist[n]["coords"] for n in names])
    fig = _figure(figsize=(11.0, 4.8))
    ax_bar, ax_map = fig.subplots(1, 2, width_ratios=(1.2, 1.0))
    pos = np.arange(len(names))
    width = 0.8 / 3
    for i, d in enumerate(_DIRS):
        ax_bar.bar(pos + (i - 1) * width, peaks[:, i], width, color=_COLOURS[d], label=d)
    ax_bar.axhline(THESIS_LIMIT, color="r", ls="--", lw=1.0,
                   label=f"thesis 0.005 g = {THESIS_LIMIT:.3f} m/s²")
    ax_bar.set_xticks(pos, names, rotation=30, ha="right", fontsize="small")
    ax_bar.set_ylabel("peak acceleration [m/s²]")
    ax_bar.set_title("peak acceleration per probe and direction")
    ax_bar.legend(fontsize="small")
    ax_bar.grid(axis="y", alpha=0.3)
    sc = ax_map.scatter(coords[:, 0], coords[:, 1], c=total, s=80, cmap="viridis",
                        edgecolors="k")
    for n, (x, y, z) in zip(names, coords):
        ax_map.annotate(f"{n}\nz={z:.1f} m", (x, y), fontsize=7, xytext=(5, 5),
                        textcoords="offset points")
    fig.colorbar(sc, ax=ax_map, label="peak |a| (vector) [m/s²]")
    ax_map.set_xlabel("x [m]")
    ax_map.set_ylabel("y [m]")
    ax_map.set_title("probe map (plan view)")
    ax_map.set_aspect("equal", adjustable="datalim")
    ax_map.grid(alpha=0.3)
    _save(fig, path)
    return {"probes": names, "coords_m": coords,
            "peak_acceleration": {d: peaks[:, i] for i, d in enumerate(_DIRS)},
            "peak_total_acceleration": total, "thesis_limit": THESIS_LIMIT}


def _fig_contact(contact: tuple, path: Path) -> dict:
    cx, cf = contact
    cx2 = cx.reshape(cx.shape[0], -1)
    cf2 = cf.reshape(cf.shape[0], -1)
    fig = _figure(figsize=(8.0, 4.0))
    ax = fig.subplots()
    for j in range(cf2.shape[1]):
        xj = cx2[:, min(j, cx2.shape[1] - 1)]
        ax.plot(xj, cf2[:, j] * 1e-3, lw=0.9, label=f"wheel {j + 1}")
    ax.set_xlabel("position along the track x [m]")
    ax.set_ylabel("contact force [kN]")
    ax.set_title("wheel–rail contact force")
    ax.grid(alpha=0.3)
    if cf2.shape[1] > 1:
        ax.legend(fontsize="small")
    _save(fig, path)
    return {"x_m": cx, "force_n": cf}


# --------------------------------------------------------------------------------------
# page


def _fmt(x: Any) -> str:
    if x is None:
        return "–"
    if isinstance(x, bool):
        return "pass" if x else "FAIL"
    if isinstance(x, float):
        return f"{x:.4g}"
    return str(x)


def _verdict(p: Any, comparison: bool = False) -> str:
    if comparison:
        return "ok (cmp.)" if p else ("over (cmp.)" if p is False else "? (cmp.)")
    return "PASS" if p else ("FAIL" if p is False else "UNDETERMINED")


def _detail_rows(result: Mapping) -> list[list[str]]:
    rows = []
    for s in STANDARDS:
        b = result["standards"].get(s)
        if b is None:
            continue
        for d, e in b["directions"].items():
            rows.append([b["title"], d, _fmt(e["value"]), _fmt(e["limit"]), b["unit"],
                         _fmt(e["utilisation"]),
                         _verdict(e["passed"], b["comparison_only"])])
    return rows


_DETAIL_HEAD = ["standard", "dir", "value", "limit", "unit", "value/limit", "verdict"]

_METHODS = [
    "Weightings (Wm of ISO 2631-2/ISO 8041 on acceleration, KB of DIN 4150-2 on velocity "
    "with 1–80 Hz Butterworth band limits) are applied in the frequency domain with the "
    "exact analog transfer functions (zero-padded FFT), exact below Nyquist at any "
    "sample rate.",
    "Running RMS: exponential (ISO 2631-1), τ = 1 s for MTVV and the FTA 1 s RMS, "
    "τ = 0.125 s for KB_F; VDV = (∫ a_w⁴ dt)^¼.",
    "PPV dominant frequency: zero crossings around the peak (half period).",
    "One-third-octave bands: base 10, band RMS over the whole record from the power "
    "spectrum (Parseval-consistent).",
    "VC curves: flat 8–80 Hz; below 8 Hz constant acceleration unless 'flat' was chosen.",
    "The thesis criterion 0.005 g (peak) is reported for comparison only.",
]


def _md_table(head: list[str], rows: list[list[str]]) -> str:
    def esc(c: str) -> str:
        return c.replace("|", "\\|")

    lines = ["| " + " | ".join(esc(h) for h in head) + " |",
             "|" + "|".join("---" for _ in head) + "|"]
    lines += ["| " + " | ".join(esc(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def _summary(results: Mapping) -> tuple[list[str], list[list[str]]]:
    names = [s for s in STANDARDS if any(s in r["standards"] for r in results.values())]
    rows = []
    for probe, r in results.items():
        row = [str(probe)]
        for s in names:
            b = r["standards"].get(s)
            if b is None:
                row.append("–")
                continue
            u = b["utilisation"]
            row.append(_verdict(b["passed"], b["comparison_only"])
                       + (f" ({u:.2f})" if u is not None else ""))
        row.append(_verdict(r.get("passed")))
        rows.append(row)
    return ["probe", *names, "overall"], rows


def _html_table(head: list[str], rows: list[list[str]]) -> str:
    def cls(c: str) -> str:
        if c.startswith("FAIL") or c.startswith("over"):
            return ' class="fail"'
        if c.startswith("PASS") or c.startswith("ok"):
            return ' class="pass"'
        if c.startswith("UNDET") or c.startswith("?"):
            return ' class="undet"'
        return ""

    out = ["<table>", "<tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in head) + "</tr>"]
    out += ["<tr>" + "".join(f"<td{cls(c)}>{html.escape(c)}</td>" for c in row) + "</tr>"
            for row in rows]
    out.append("</table>")
    return "\n".join(out)


_CSS = """body{font-family:sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222}
table{border-collapse:collapse;margin:0.8em 0}th,td{border:1px solid #bbb;padding:3px 8px;
text-align:left;font-size:0.92em}th{background:#eee}td.pass{color:#176b1a}
td.fail{color:#b00020;font-weight:bold}td.undet{color:#a06000}img{max-width:100%}
pre{background:#f6f6f6;padding:0.6em;overflow-x:auto}"""


def write_report(out_dir: str | os.PathLike, results: Mapping[str, Mapping[str, Any]],
                 histories: Mapping[str, Mapping[str, Any]],
                 contact: tuple[Any, Any] | None = None,
                 extra_figures: Sequence[Mapping[str, Any]] = (),
                 extra_text: Sequence[tuple[str, str]] = (),
                 extra_data: Mapping[str, Any] | None = None) -> dict[str, Path]:
    """Write the assessment report (markdown, HTML, PNG figures, JSON).

    Parameters
    ----------
    out_dir
        Output folder (created if needed).
    results
        Probe name → :func:`~railvib_hpc.assess.standards.assess_probe` result.
    histories
        Probe name → ``{"t": (nt,), "displacement": (nt, 3), "velocity": (nt, 3),
        "acceleration": (nt, 3), "coords": (3,)}`` in SI units; must hold every probe
        of ``results``.
    contact
        Optional ``(x, force)``: wheel positions [m] and contact forces [N], (n,) or
        (n, wheels), for a contact-force figure.
    extra_figures
        Figures already written under ``out_dir``: mappings with ``id``, ``file``
        (relative path), ``title`` and ``data`` (JSON-serialisable).
    extra_text
        ``(title, preformatted text)`` sections added after the summary.
    extra_data
        Further JSON-serialisable entries of ``report.json`` (e.g. ``free_field``).

    Returns
    -------
    dict
        ``{"markdown", "html", "json", <figure id>...}`` → written paths.

    Raises
    ------
    AssessInputError
        (a ``ValueError``) for malformed inputs, naming the argument.
    """
    results, hist, contact = _check(results, histories, contact)
    out = Path(out_dir)
    fig_dir = out / "figures"
    fig_dir.mkdir(parents=True, exist_ok=True)

    figures: dict[str, dict[str, Any]] = {}
    used: set[str] = set()
    for name in results:
        slug = _slug(str(name), used)
        fid = f"time_{slug}"
        data = _fig_time(str(name), hist[name], fig_dir / f"{fid}.png")
        figures[fid] = {"file": f"figures/{fid}.png", "probe": str(name),
                        "title": f"Time histories, probe {name}", "data": data}
        fid = f"spectrum_{slug}"
        data = _fig_spectrum(str(name), hist[name], results[name], fig_dir / f"{fid}.png")
        figures[fid] = {"file": f"figures/{fid}.png", "probe": str(name),
                        "title": f"One-third-octave velocity vs VC curves, probe {name}",
                        "data": data}
    figures["probes"] = {"file": "figures/probes.png", "title": "Peak acceleration of the probes",
                         "data": _fig_probes(hist, fig_dir / "probes.png")}
    if contact is not None:
        figures["contact"] = {"file": "figures/contact.png", "title": "Contact force",
                              "data": _fig_contact(contact, fig_dir / "contact.png")}

    for f in extra_figures:
        figures[str(f["id"])] = {k: f[k] for k in ("file", "title", "data")}

    head, rows = _summary(results)
    table_txt = format_table(results)

    # ---- markdown
    md = ["# Vibration assessment", "", "## Summary", "",
          "Verdict per probe and standard; in brackets the utilisation (largest "
          "value/limit over the directions, ≤ 1 passes).", "", _md_table(head, rows), ""]
    for title, text in extra_text:
        md += [f"## {title}", "", "```", text, "```", ""]
    for name, r in results.items():
        md += [f"## Probe {name}", ""]
        rec = r.get("record", {})
        if rec:
            md += [f"{rec.get('n_samples')} samples at {_fmt(rec.get('sample_rate_hz'))} Hz "
                   f"({_fmt(rec.get('duration_s'))} s).", ""]
        md += [_md_table(_DETAIL_HEAD, _detail_rows(r)), ""]
        notes = [f"- **{s}**: {n}" for s, b in r["standards"].items() for n in b["notes"]]
        if notes:
            md += ["Notes:", "", *notes, ""]
    md += ["## Figures", ""]
    md += [f"### {f['title']}\n\n![{f['title']}]({f['file']})\n" for f in figures.values()]
    md += ["## Methods", "", *(f"- {m}" for m in _METHODS), "",
           "Data of every figure: `report.json`.", ""]

    # ---- html (figures embedded)
    parts = ["<!DOCTYPE html>", "<html><head><meta charset='utf-8'>",
             "<title>Vibration assessment</title>", f"<style>{_CSS}</style></head><body>",
             "<h1>Vibration assessment</h1>", "<h2>Summary</h2>",
             "<p>Verdict per probe and standard; in brackets the utilisation (largest "
             "value/limit over the directions, ≤ 1 passes).</p>", _html_table(head, rows)]
    for title, text in extra_text:
        parts.append(f"<h2>{html.escape(title)}</h2><pre>{html.escape(text)}</pre>")
    for name, r in results.items():
        parts.append(f"<h2>Probe {html.escape(str(name))}</h2>")
        parts.append(_html_table(_DETAIL_HEAD, _detail_rows(r)))
        notes = [f"<li><b>{html.escape(s)}</b>: {html.escape(n)}</li>"
                 for s, b in r["standards"].items() for n in b["notes"]]
        if notes:
            parts.append("<ul>" + "".join(notes) + "</ul>")
    parts.append("<h2>Figures</h2>")
    for f in figures.values():
        b64 = base64.b64encode((out / f["file"]).read_bytes()).decode("ascii")
        parts.append(f"<h3>{html.escape(f['title'])}</h3>"
                     f"<img alt='{html.escape(f['title'])}' src='data:image/png;base64,{b64}'>")
    parts += ["<h2>Methods</h2>", "<ul>" + "".join(f"<li>{html.escape(m)}</li>"
                                                   for m in _METHODS) + "</ul>",
              "<h2>Table (text)</h2>", f"<pre>{html.escape(table_txt)}</pre>",
              "</body></html>"]

    # ---- json
    payload = {"schema": "railvib_hpc.assess.report/1", "results": results,
               "table": table_txt, "figures": figures, **dict(extra_data or {})}
    text_json = json.dumps(_jsonable(payload), allow_nan=False, indent=1)

    paths = {"markdown": out / REPORT_MD, "html": out / REPORT_HTML,
             "json": out / REPORT_JSON}
    for key, text in (("json", text_json), ("markdown", "\n".join(md)),
                      ("html", "\n".join(parts))):
        with atomic_file(paths[key]) as tmp:
            tmp.write_text(text, encoding="utf-8")
    paths.update({fid: out / f["file"] for fid, f in figures.items()})
    return paths
