"""Make ``import bodies`` / ``import coupling`` / ``import soil`` resolve to the repository
packages, not to the same-named test folders.

With pytest's default ``prepend`` import mode, ``tests/`` (holding the top conftest) goes to
the front of ``sys.path``, and ``tests/bodies`` (no ``__init__``) then shadows the editable
install of ``bodies`` as a namespace package. Putting the repository root first fixes it.
(A ``pythonpath = ["."]`` entry in pyproject's pytest options would make this unnecessary.)
"""

import pathlib
import sys

_ROOT = str(pathlib.Path(__file__).resolve().parents[2])
if sys.path[:1] != [_ROOT]:
    sys.path.insert(0, _ROOT)
for _name in ("bodies", "coupling", "soil"):
    _mod = sys.modules.get(_name)
    if _mod is not None and getattr(_mod, "__file__", None) is None:
        del sys.modules[_name]
