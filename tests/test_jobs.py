"""Every job file in ``jobs/`` is a valid case, and each study's case plans its variants."""

from __future__ import annotations

from pathlib import Path

import pytest

from railvib_hpc.config import load_case

JOBS = Path(__file__).resolve().parents[1] / "jobs"
CASE_FILES = sorted(JOBS.glob("*.toml"))
#: The study each study case file is written for (jobs/README.md).
STUDY_OF = {"mesh_convergence.toml": "convergence", "modal_truncation.toml": "modes",
            "boundary_reflection.toml": "reflection", "speed_sweep.toml": "speed",
            "mitigation_study.toml": "mitigation", "uncertainty_study.toml": "uncertainty"}


def test_the_job_files_are_all_found():
    names = {p.name for p in CASE_FILES}
    assert {"thesis_baseline.toml", *STUDY_OF} <= names, names


@pytest.mark.parametrize("path", CASE_FILES, ids=lambda p: p.name)
def test_job_file_validates(path):
    case = load_case(path)          # raises CaseError naming key, value, allowed
    assert case.path == path.resolve()
    assert not case.notes or all(isinstance(n, str) for n in case.notes)


@pytest.mark.parametrize("name", sorted(STUDY_OF))
def test_study_job_file_plans_its_variants(name):
    from railvib_hpc.studies import study_settings
    from railvib_hpc.studies.runner import make_plan

    kind = STUDY_OF[name]
    case = load_case(JOBS / name)
    plan = make_plan(kind, case, study_settings(kind, case=case))     # the file's own table
    assert plan.kind == kind and len(plan.variants) >= 2


def test_every_job_names_its_own_results_folder():
    """Two job files with the same case.name would write into the same results/<name>."""
    names = {p.name: load_case(p)["case.name"] for p in CASE_FILES}
    assert len(set(names.values())) == len(names), names
