"""trimesh, imported so that a Ctrl-C during its import is not lost (every sim module takes it from here).

trimesh wraps each optional dependency's import in `except BaseException` and keeps the exception for
later (trimesh.exceptions.ExceptionWrapper), so a SIGINT that lands while trimesh imports is swallowed:
the process goes on as if nothing happened. Measured with the fake driver (the bringup's stop sends
SIGINT): a SIGINT 0.4-0.6 s after its start (inside `import networkx` under trimesh) left it running, so
the launcher had to escalate to SIGTERM 10 s later. After the import this re-raises such an interrupt.
"""
import sys


def swallowed_interrupt(modules=None) -> bool:
    """Whether a trimesh module keeps a KeyboardInterrupt in place of an optional dependency."""
    # looked up, not imported: importing any part of trimesh runs its package's optional imports
    wrapper = getattr(sys.modules.get("trimesh.exceptions"), "ExceptionWrapper", None)
    if wrapper is None:
        return False
    if modules is None:
        modules = [m for name, m in list(sys.modules.items()) if name.split(".")[0] == "trimesh"]
    for module in modules:
        for value in list(vars(module).values()):
            if type(value) is wrapper:  # isinstance would ask the wrapper, which raises
                exc_type, _ = object.__getattribute__(value, "exception")
                if issubclass(exc_type, KeyboardInterrupt):
                    return True
    return False


try:
    import trimesh
    import trimesh.creation  # noqa: F401  (imports more optional dependencies the same way)
except Exception as exc:  # a kept interrupt can also break the rest of trimesh's import (seen: TypeError)
    if swallowed_interrupt():
        raise KeyboardInterrupt("SIGINT while trimesh was being imported") from exc
    raise
if swallowed_interrupt():
    raise KeyboardInterrupt("SIGINT while trimesh was being imported")

__all__ = ["trimesh"]
