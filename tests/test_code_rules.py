"""Rules of the code base that ``make lint`` and ``make docs`` keep: function length, the
README's module table."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from railvib_hpc.docs import LAYOUT_BEGIN, LAYOUT_END, README, layout_markdown, module_summary

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))
import code_rules  # noqa: E402


def test_no_function_over_the_limit_unless_allowed():
    assert code_rules.violations() == []


def test_the_rule_counts_from_def_to_the_end(tmp_path):
    pkg = tmp_path / "railvib_hpc"
    pkg.mkdir()
    lines = [f"x{i} = {i}" for i in range(code_rules.MAX_FUNCTION_LINES - 2)]
    method, function = ("\n".join(indent + s for s in lines) for indent in (" " * 8, " " * 4))
    (pkg / "m.py").write_text(
        f'class A:\n    @staticmethod\n    def short():\n        """Doc."""\n{method}\n'
        f'\n\ndef long():\n    """Doc."""\n{function}\n    return 1\n')
    lengths = dict(code_rules.function_lengths(tmp_path))
    assert lengths == {"railvib_hpc/m.py::A.short": code_rules.MAX_FUNCTION_LINES,
                       "railvib_hpc/m.py::long": code_rules.MAX_FUNCTION_LINES + 1}
    assert [v.split(": ")[0] for v in code_rules.violations(tmp_path)] == [
        "railvib_hpc/m.py::long"]


def test_every_module_says_what_it_does():
    for path in sorted((ROOT / "railvib_hpc").rglob("*.py")):
        assert module_summary(path), path


def test_readme_layout_lists_every_module_and_is_up_to_date():
    text = (ROOT / README).read_text()
    current = text.split(LAYOUT_BEGIN, 1)[1].split(LAYOUT_END, 1)[0]
    assert current == "\n" + layout_markdown(ROOT / "railvib_hpc"), "run `make docs`"
    modules = [p for p in (ROOT / "railvib_hpc").rglob("*.py") if p.name != "__init__.py"]
    for path in modules:
        assert f"| `{path.relative_to(ROOT / 'railvib_hpc').as_posix()}` |" in current, path


def test_a_module_without_docstring_is_refused(tmp_path):
    (tmp_path / "m.py").write_text("x = 1\n")
    with pytest.raises(ValueError, match="no module docstring"):
        module_summary(tmp_path / "m.py")


def test_no_kernel_module_takes_the_case():
    assert code_rules.case_violations() == []


def test_the_case_rule_finds_a_case_parameter_and_a_case_import(tmp_path):
    modal, fem = tmp_path / "railvib_hpc" / "modal", tmp_path / "railvib_hpc" / "fem"
    modal.mkdir(parents=True)
    fem.mkdir()
    (modal / "kernel.py").write_text("def assemble(mesh, case, dofmap):\n    return 1\n")
    (modal / "stage.py").write_text("def compute(case):\n    return 1\n")   # a translator
    (modal / "fine.py").write_text("def assemble(mesh, problem, dofmap):\n    return 1\n")
    (fem / "typed.py").write_text("from typing import TYPE_CHECKING\n\nif TYPE_CHECKING:\n"
                                  "    from ..config import Case\n")
    (fem / "old.py").write_text("x = 1\n")
    found = code_rules.case_violations(tmp_path, {"modal/stage.py": "a stage"},
                                       {"fem/old.py": "to go", "fem/gone.py": "to go"})
    assert [v.split(": ")[:2] for v in found] == [
        ["railvib_hpc/fem/old.py", "listed in tools/code_rules.py PENDING but it no longer "
                                   "takes the case"],
        ["railvib_hpc/fem/typed.py", "line 4"],
        ["railvib_hpc/modal/kernel.py", "line 1"],
        ["railvib_hpc/fem/gone.py", "listed in tools/code_rules.py TRANSLATORS or PENDING but "
                                    "no such module"]]
    assert "imports Case from the case module" in found[1]
    assert "assemble() takes a parameter named case" in found[2]


def test_file_names_come_from_one_place():
    assert code_rules.file_name_violations() == []


def test_a_file_name_spelled_outside_its_home_is_found(tmp_path):
    pkg = tmp_path / "railvib_hpc"
    (pkg / "io").mkdir(parents=True)
    (pkg / "io" / "files.py").write_text('"""Names."""\nMODES_H5 = "modes.h5"\nRECORD_DIR = ".x"\n')
    (pkg / "stage.py").write_text('"""Writes ``modes.h5``."""\n\n\ndef f(out):\n'
                                  '    """Reads modes.h5."""\n    return out / "modes.h5"\n')
    assert code_rules.file_names(tmp_path) == {"modes.h5"}
    assert code_rules.file_name_violations(tmp_path) == [
        "railvib_hpc/stage.py: line 6: the file name 'modes.h5' (use its constant from "
        "railvib_hpc/io/files.py)"]


def test_no_module_over_the_limit_unless_listed():
    assert code_rules.module_length_violations() == []


def test_the_module_rule_finds_a_long_module_and_a_stale_entry(tmp_path):
    pkg = tmp_path / "railvib_hpc"
    pkg.mkdir()
    limit = code_rules.MAX_MODULE_LINES
    (pkg / "long.py").write_text("x = 1\n" * (limit + 1))
    (pkg / "fits.py").write_text("x = 1\n" * limit)
    found = code_rules.module_length_violations(tmp_path, {"fits.py": "was long",
                                                           "gone.py": "was long"})
    assert [v.split(": ")[0] for v in found] == ["railvib_hpc/fits.py", "railvib_hpc/long.py",
                                                 "railvib_hpc/gone.py"]
    assert f"{limit + 1} lines" in found[1]


def test_the_docs_cite_sources_not_tickets():
    assert code_rules.ticket_violations() == []


def test_the_ticket_rule_finds_a_ticket_number(tmp_path):
    (tmp_path / "railvib_hpc").mkdir()
    (tmp_path / "docs").mkdir()
    (tmp_path / "railvib_hpc" / "m.py").write_text('"""Why (Issue 28, item 2)."""\n')
    (tmp_path / "docs" / "a.md").write_text("fine: Lamb (1904)\nissues #12 and 13\n")
    (tmp_path / "README.md").write_text("see https://github.com/owner/repo/issues/7\n")
    assert [v.split(": ")[:2] for v in code_rules.ticket_violations(tmp_path)] == [
        ["railvib_hpc/m.py", "line 1"], ["docs/a.md", "line 2"]]


def test_the_schema_imports_nothing_from_the_assessment():
    assert code_rules.schema_import_violations() == []


def test_the_schema_rule_finds_an_import_of_the_assessment(tmp_path):
    schema = tmp_path / "railvib_hpc" / "schema"
    schema.mkdir(parents=True)
    (schema / "__init__.py").write_text('"""S."""\nfrom .a import X\n')
    (schema / "a.py").write_text('"""A."""\n\n\ndef f():\n    from ..assess import standards\n'
                                 '    return standards\n')
    (schema / "b.py").write_text('"""B."""\nfrom railvib_hpc.assess.standards import STANDARDS\n')
    (tmp_path / "railvib_hpc" / "standards_registry.py").write_text('"""R."""\nimport math\n')
    found = code_rules.schema_import_violations(tmp_path)
    assert [v.split(": ")[:2] for v in found] == [["railvib_hpc/schema/a.py", "line 5"],
                                                  ["railvib_hpc/schema/b.py", "line 2"]]
