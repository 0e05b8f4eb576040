"""Which third-party modules a set of defgg_ros modules can import: the closure of their imports inside defgg_ros.

Read with the AST, so imports inside functions count too (a lazy import still fails at run time when missing),
and relative imports are resolved. Pure: imports nothing it scans.
"""
import ast
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
PACKAGE = "defgg_ros"


def _source(module: str) -> Path | None:
    path = REPO / Path(*module.split("."))
    if (path / "__init__.py").is_file():
        return path / "__init__.py"
    if path.with_suffix(".py").is_file():
        return path.with_suffix(".py")
    return None


def _imported_names(path: Path, module: str):
    """(module, attribute or None) for every import statement in the file."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, None
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                base = parts[:len(parts) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module
            for alias in node.names:
                yield target, alias.name


def third_party_imports(*roots: str) -> dict[str, set[str]]:
    """Top-level third-party module -> the defgg_ros modules (reachable from `roots`) that import it."""
    seen, found, todo = set(), {}, list(roots)
    while todo:
        module = todo.pop()
        path = _source(module)
        if module in seen or path is None:
            continue
        seen.add(module)
        parts = module.split(".")
        todo += [".".join(parts[:i]) for i in range(1, len(parts))]   # importing a.b.c runs a and a.b first
        for target, attribute in _imported_names(path, module):
            top = target.split(".")[0]
            if top == PACKAGE:
                todo.append(target)
                if attribute:
                    todo.append(f"{target}.{attribute}")   # `from pkg import submodule`
            elif top not in sys.stdlib_module_names:
                found.setdefault(top, set()).add(module)
    return found
