"""Install test: the wheel ships our four top-level packages, and after a clean install they
import as *ours* — `soil` and `coupling` are also names of unrelated PyPI packages, so a stray
install of those must never shadow them."""
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("crashdem", "soil", "bodies", "coupling")


@pytest.fixture(scope="module")
def wheel(tmp_path_factory):
    out = tmp_path_factory.mktemp("wheel")
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
         "-w", str(out), str(ROOT)],
        check=True, capture_output=True, text=True,
    )
    wheels = list(out.glob("crashdem-*.whl"))
    assert len(wheels) == 1
    return wheels[0]


def test_wheel_contents(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    tops = {n.split("/")[0] for n in names if not n.startswith("crashdem-")}
    assert tops == set(PACKAGES), f"unexpected top-level entries in the wheel: {tops}"
    for pkg in PACKAGES:
        assert f"{pkg}/__init__.py" in names
    assert not any(n.startswith("tests/") for n in names)
    meta = next(n for n in names if n.endswith("entry_points.txt"))
    assert "crashdem = crashdem.cli:main" in zipfile.ZipFile(wheel).read(meta).decode()
    # the licence as an SPDX expression (PEP 639; the table form is deprecated by setuptools)
    # and its text shipped with the metadata
    metadata = zipfile.ZipFile(wheel).read(next(n for n in names if n.endswith("/METADATA")))
    assert "License-Expression: MIT" in metadata.decode()
    assert any(n.endswith("/licenses/LICENSE") for n in names)


def test_clean_install_imports_our_packages(wheel, tmp_path):
    target = tmp_path / "site"
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(target), str(wheel)],
        check=True, capture_output=True, text=True,
    )
    code = (
        "import importlib, sys\n"
        f"for name in {PACKAGES!r}:\n"
        "    m = importlib.import_module(name)\n"
        "    print(name, m.__file__)\n"
    )
    env = {**os.environ, "PYTHONPATH": str(target)}
    env.pop("PYTHONSAFEPATH", None)
    res = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env,
                         capture_output=True, text=True, check=True)
    for line in res.stdout.splitlines():
        name, path = line.split(" ", 1)
        assert Path(path).resolve().is_relative_to(target.resolve()), (
            f"{name} imported from {path}, not from the clean install")
