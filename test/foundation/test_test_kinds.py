"""Every test module states its kind: a module-level `pytestmark` with a kind, an entry in test/conftest.py's kind
table, or a kind marker on each of its test functions. Read from the source (no collection), so a module added
without a kind fails here even under `-m unit`, which would otherwise deselect its tests silently.
"""
import ast
from pathlib import Path

import conftest
import pytest

pytestmark = pytest.mark.unit

TEST_ROOT = Path(__file__).resolve().parents[1]


def _kind_markers(expression) -> set:
    """Kind names in a decorator or a `pytestmark` value: pytest.mark.unit, [pytest.mark.e2e, ...]."""
    return {node.attr for node in ast.walk(expression)
            if isinstance(node, ast.Attribute) and node.attr in conftest.KINDS}


def module_kind_sources(path: Path) -> list:
    """Where the module's tests get their kind from: 'pytestmark', 'table', 'each test'; empty: nowhere."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    sources = []
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "pytestmark" for t in node.targets):
            if _kind_markers(node.value):
                sources.append("pytestmark")
    if path.relative_to(TEST_ROOT).as_posix() in conftest.MODULE_KINDS:
        sources.append("table")
    tests = [node for node in tree.body
             if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.name.startswith("test")]
    if tests and all(any(_kind_markers(d) for d in t.decorator_list) for t in tests):
        sources.append("each test")
    return sources


TEST_MODULES = sorted(p for p in TEST_ROOT.rglob("test_*.py") if "support" not in p.relative_to(TEST_ROOT).parts)


def test_the_walk_sees_the_test_modules():
    assert len(TEST_MODULES) > 100
    assert module_kind_sources(Path(__file__)) == ["pytestmark"]


def test_every_test_module_has_an_explicit_kind():
    missing = [p.relative_to(TEST_ROOT).as_posix() for p in TEST_MODULES if not module_kind_sources(p)]
    assert not missing, ("no test kind (set `pytestmark = pytest.mark.<kind>` or list the module in "
                         f"test/conftest.py's UNIT_MODULES ... E2E_MODULES): {missing}")


def test_a_module_gets_its_kind_in_one_place():
    twice = [p.relative_to(TEST_ROOT).as_posix() for p in TEST_MODULES
             if {"pytestmark", "table"} <= set(module_kind_sources(p))]
    assert not twice, f"both a pytestmark and a table entry: {twice}"


def test_every_table_entry_is_a_test_module():
    stale = sorted(m for m in conftest.MODULE_KINDS if not (TEST_ROOT / m).is_file())
    assert not stale, f"test/conftest.py's kind table lists modules that do not exist: {stale}"


class _Item:
    def __init__(self, path, name, marker=None):
        self.path, self.name, self._marker = Path(path), name, marker

    def get_closest_marker(self, name):
        return name if name == self._marker else None


def test_files_with_a_cell_go_first_then_slow_files_each_keeping_its_tests_order():
    """The workers take files in collection order (make test: --no-loadscope-reorder): a one-test cell collected last
    ran alone at the end of the suite."""
    items = [_Item("a.py", "a1"), _Item("b.py", "b1", "slow"), _Item("a.py", "a2"), _Item("c.py", "c1"),
             _Item("c.py", "c2", "e2e"), _Item("b.py", "b2"), _Item("d.py", "d1", "e2e")]
    assert [i.name for i in conftest.heaviest_files_first(items)] == ["c1", "c2", "d1", "b1", "b2", "a1", "a2"]


def test_make_test_and_check_keep_that_order():
    makefile = (TEST_ROOT.parent / "Makefile").read_text()
    runs = [line for line in makefile.splitlines() if "-m pytest" in line and "-n $(TEST_WORKERS)" in line]
    assert len(runs) == 2 and all("--dist loadfile --no-loadscope-reorder" in line for line in runs), runs
