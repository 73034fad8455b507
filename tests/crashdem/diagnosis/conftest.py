"""Make ``crashdem`` the installed package, not the ``tests/crashdem`` folder.

Under pytest's default "prepend" import mode ``tests/`` is on ``sys.path`` (root conftest), so
``import crashdem`` finds the test folder ``tests/crashdem`` as a namespace package before the
editable-install finder runs; ``crashdem.<module>`` still resolves through that finder, but
``crashdem.diagnosis`` resolves to this test folder. This conftest binds ``crashdem`` to the real
package (submodules already imported are kept, so class identities do not change).
A project-wide fix is ``pythonpath = ["."]`` in ``[tool.pytest.ini_options]``.
"""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

_PKG = Path(__file__).resolve().parents[3] / "crashdem"

_mod = sys.modules.get("crashdem")
if _mod is None or getattr(_mod, "__file__", None) is None:
    _spec = importlib.util.spec_from_file_location(
        "crashdem", _PKG / "__init__.py", submodule_search_locations=[str(_PKG)])
    _real = importlib.util.module_from_spec(_spec)
    sys.modules["crashdem"] = _real
    _spec.loader.exec_module(_real)
    for _name in [n for n in sys.modules if n == "crashdem.diagnosis" or n.startswith("crashdem.diagnosis.")]:
        if getattr(sys.modules[_name], "__file__", None) is None:
            del sys.modules[_name]
