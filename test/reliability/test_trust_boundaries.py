"""No code path turns data into code: a syntax-tree scan of the project's own sources.

Files (models, datasets, scene YAML, bags) and requests come from outside
the process. The rules checked on every module of defgg_ros/, bench/ and the
console scripts:
- no pickle-family module is imported (pickle, cPickle, dill, shelve, marshal, joblib);
- no call of eval/exec/compile on anything;
- every torch.load passes weights_only=True, every np.load allow_pickle=False;
- YAML is only read with yaml.safe_load;
- no subprocess with shell=True.
Loading a real pickled object through the project's loaders is refused:
test/model/test_model_checkpoint.py::test_pickled_objects_are_refused and
test_segmentation_faults.py::test_a_pickled_background_file_is_refused.
"""
import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SOURCES = sorted(p for folder in ("defgg_ros", "bench") for p in (ROOT / folder).rglob("*.py"))
PICKLE_FAMILY = {"pickle", "cPickle", "_pickle", "dill", "shelve", "marshal", "joblib", "cloudpickle"}
CODE_FROM_DATA = {"eval", "exec", "compile"}


def _keyword(call: ast.Call, name: str):
    for kw in call.keywords:
        if kw.arg == name:
            return kw.value
    return None


def _is_constant(node, value) -> bool:
    return isinstance(node, ast.Constant) and node.value is value


def _dotted(func) -> str:
    parts = []
    while isinstance(func, ast.Attribute):
        parts.append(func.attr)
        func = func.value
    parts.append(func.id if isinstance(func, ast.Name) else "<expression>")  # x().eval() is not eval()
    return ".".join(reversed(parts))


def problems_in(source: str, filename: str) -> list[str]:
    found = []
    tree = ast.parse(source, filename)
    for node in ast.walk(tree):
        where = f"{filename}:{getattr(node, 'lineno', '?')}"
        if isinstance(node, ast.Import):
            found += [f"{where}: imports {a.name}" for a in node.names if a.name.split(".")[0] in PICKLE_FAMILY]
        elif isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] in PICKLE_FAMILY:
            found.append(f"{where}: imports from {node.module}")
        elif isinstance(node, ast.Call):
            name = _dotted(node.func)
            if name in CODE_FROM_DATA:
                found.append(f"{where}: calls {name}()")
            elif name == "torch.load" and not _is_constant(_keyword(node, "weights_only"), True):
                found.append(f"{where}: torch.load without weights_only=True")
            elif name in ("np.load", "numpy.load") and not _is_constant(_keyword(node, "allow_pickle"), False):
                found.append(f"{where}: np.load without allow_pickle=False")
            elif name in ("yaml.load", "yaml.unsafe_load", "yaml.full_load", "yaml.load_all"):
                found.append(f"{where}: {name} (use yaml.safe_load)")
            elif name.startswith("subprocess.") and _is_constant(_keyword(node, "shell"), True):
                found.append(f"{where}: {name} with shell=True")
    return found


def test_the_scan_finds_each_kind_of_problem():
    bad = "\n".join([
        "import pickle", "from joblib import load", "eval(text)", "exec(text)",
        "torch.load(path)", "torch.load(path, weights_only=False)", "np.load(path)",
        "np.load(path, allow_pickle=True)", "yaml.load(text)", "subprocess.run(cmd, shell=True)",
    ])
    assert len(problems_in(bad, "bad.py")) == 10
    good = "\n".join(["torch.load(p, weights_only=True)", "np.load(p, allow_pickle=False)", "yaml.safe_load(t)",
                      "model.eval()", "Net().eval()"])
    assert problems_in(good, "good.py") == []


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_source_file_turns_data_into_code(path):
    assert problems_in(path.read_text(encoding="utf-8"), str(path.relative_to(ROOT))) == []
