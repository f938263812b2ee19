"""write_report: files are written atomically, the JSON parses and holds the figure data."""

from __future__ import annotations

import json

import numpy as np
import pytest

from railvib_hpc.assess.report import write_report
from railvib_hpc.assess.standards import STANDARDS, assess_probe

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _history(scale, coords, fs=256.0, duration=4.0):
    t = np.arange(int(fs * duration)) / fs
    env = np.exp(-(((t - 2.0) / 0.5) ** 2))
    f = np.array([12.0, 20.0, 9.0])
    w = 2 * np.pi * f
    disp = scale * env[:, None] * np.sin(w * t[:, None]) / w**2
    vel = np.gradient(disp, t, axis=0)
    acc = np.gradient(vel, t, axis=0)
    return {"t": t, "displacement": disp, "velocity": vel, "acceleration": acc,
            "coords": np.asarray(coords, float)}


@pytest.fixture
def probes():
    hist = {"slab 1": _history(0.03, [10.0, 4.0, 3.0]),
            "slab/2": _history(0.08, [12.0, 6.0, 6.0])}
    results = {n: assess_probe(h["t"], h["acceleration"], h["velocity"], STANDARDS)
               for n, h in hist.items()}
    return results, hist


def _strict_json(path):
    def reject(c):
        raise ValueError(f"non-standard JSON constant {c}")

    return json.loads(path.read_text(encoding="utf-8"), parse_constant=reject)


def test_report_files_and_json(tmp_path, probes):
    results, hist = probes
    x = np.linspace(0.0, 60.0, 300)
    force = np.c_[75e3 + 2e3 * np.sin(x), 75e3 - 2e3 * np.sin(x)]
    paths = write_report(tmp_path / "out", results, hist, contact=(x, force))
    out = tmp_path / "out"
    for key in ("markdown", "html", "json"):
        assert paths[key].is_file() and paths[key].stat().st_size > 0
    # no temporary files left behind
    assert not [p for p in out.rglob("*") if ".part-" in p.name]
    data = _strict_json(out / "report.json")
    figs = data["figures"]
    # two figures per probe (the '/' in a name is made file-safe), the map and the contact plot
    assert set(figs) == {"time_slab_1", "spectrum_slab_1", "time_slab_2", "spectrum_slab_2",
                         "probes", "contact"}
    for fid, f in figs.items():
        png = out / f["file"]
        assert paths[fid] == png
        assert png.read_bytes()[:8] == PNG_MAGIC
    # figure data round-trips
    h = hist["slab/2"]
    np.testing.assert_allclose(figs["time_slab_2"]["data"]["t"], h["t"])
    np.testing.assert_allclose(figs["time_slab_2"]["data"]["acceleration"]["z"],
                               h["acceleration"][:, 2])
    np.testing.assert_allclose(figs["probes"]["data"]["peak_acceleration"]["z"],
                               [np.max(np.abs(hist[n]["acceleration"][:, 2])) for n in hist])
    np.testing.assert_allclose(figs["contact"]["data"]["force_n"], force)
    spec = figs["spectrum_slab_1"]["data"]
    assert spec["nominal_hz"][0] == 1.0 and spec["nominal_hz"][-1] == 80.0
    assert spec["vc_class"] == "residential"
    # the spectrum drawn is the one assessed
    np.testing.assert_allclose(spec["rms_m_per_s"]["z"],
                               results["slab 1"]["standards"]["vc"]["bands"]["z"],
                               rtol=1e-12)
    assert data["results"]["slab/2"]["standards"]["iso2631"]["directions"]["z"]["value"] == \
        pytest.approx(results["slab/2"]["standards"]["iso2631"]["directions"]["z"]["value"])
    # pages
    md = (out / "report.md").read_text(encoding="utf-8")
    html = (out / "report.html").read_text(encoding="utf-8")
    assert "| slab 1 |" in md and "figures/probes.png" in md
    for f in figs.values():
        assert f"]({f['file']})" in md
    assert html.count("data:image/png;base64,") == len(figs)
    assert "slab/2" in html and "<table>" in html


def test_report_without_contact_and_rewrite(tmp_path, probes):
    results, hist = probes
    first = write_report(tmp_path, results, hist)
    assert "contact" not in first
    second = write_report(tmp_path, results, hist)  # overwrite in place
    assert second["json"].is_file()
    assert "contact" not in _strict_json(second["json"])["figures"]


def test_report_input_checks(tmp_path, probes):
    results, hist = probes
    with pytest.raises(ValueError, match="histories"):
        write_report(tmp_path, results, {"slab 1": hist["slab 1"]})
    bad = dict(hist)
    bad["slab 1"] = dict(hist["slab 1"], coords=[1.0, 2.0])
    with pytest.raises(ValueError, match=r"coords.*\(3,\)"):
        write_report(tmp_path, results, bad)
    with pytest.raises(ValueError, match="results"):
        write_report(tmp_path, {}, hist)
    with pytest.raises(ValueError, match="contact"):
        write_report(tmp_path, results, hist, contact=(np.zeros(3), np.zeros(4)))


def test_a_long_record_is_drawn_and_kept_as_its_envelope(tmp_path, probes):
    """A record longer than two samples per bucket: report.json keeps each series' min/max
    per bucket in time order (every extreme kept exactly), at most 2 x ENVELOPE_BUCKETS
    points; a short one is kept whole (test above)."""
    from railvib_hpc.assess.report import ENVELOPE_BUCKETS

    results, _ = probes
    long = {"slab 1": _history(0.03, [10.0, 4.0, 3.0], fs=2048.0, duration=12.0),
            "slab/2": _history(0.08, [12.0, 6.0, 6.0], fs=2048.0, duration=12.0)}
    write_report(tmp_path, results, long)
    data = _strict_json(tmp_path / "report.json")["figures"]["time_slab_1"]["data"]
    h = long["slab 1"]
    n = h["t"].size
    assert data["envelope"]["samples"] == n
    k = data["envelope"]["samples_per_bucket"]
    assert len(data["t"]) == 2 * -(-n // k) <= 2 * ENVELOPE_BUCKETS
    assert np.all(np.diff(data["t"]) >= 0)
    for q in ("displacement", "velocity", "acceleration"):
        for i, d in enumerate("xyz"):
            got, full = np.asarray(data[q][d]), h[q][:, i]
            assert got.max() == full.max() and got.min() == full.min()
            # bucket j's pair is its own min and max, in the order they occur
            j = int(np.argmax(np.abs(full))) // k
            block = full[j * k:(j + 1) * k]
            pair = got[2 * j:2 * j + 2]
            assert sorted(pair) == [block.min(), block.max()]
            assert (pair[0] == block.min()) == (block.argmin() <= block.argmax())
