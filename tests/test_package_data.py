"""docs/model.md ships with the package (issue 29): ``ddmr explain`` and the report cite it, so a wheel install
has it too, as ``ddmr_cli.docs`` read through importlib.resources."""

from __future__ import annotations

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from ddmr_cli.config import key_doc, compose_config, model_doc, model_section

ROOT = Path(__file__).resolve().parents[1]


def test_the_package_config_ships_docs_model_md():
    tomllib = pytest.importorskip("tomllib")
    setup = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert setup["package-dir"]["ddmr_cli.docs"] == "docs"
    assert "ddmr_cli.docs" in setup["packages"]
    assert "*.md" in setup["package-data"]["ddmr_cli.docs"]


def test_model_md_is_read_as_a_package_resource():
    assert model_doc().read_text(encoding="utf-8") == (ROOT / "docs" / "model.md").read_text(encoding="utf-8")
    assert model_section(6) == "6. Controllers and observers"
    assert model_section(99) == ""
    doc = key_doc(compose_config([]), "controller.switching_gain")
    assert doc.reference.startswith("docs/model.md §6 (Controllers and observers)")


@pytest.mark.slow
def test_the_wheel_holds_model_md_and_explain_reads_it_from_the_wheel(tmp_path):
    # from a clean copy of the tree: an egg-info left by an editable install lists every file, and setuptools
    # would ship what it lists whatever pyproject.toml says
    source = tmp_path / "src"
    shutil.copytree(ROOT, source, ignore=shutil.ignore_patterns(".*", "*.egg-info", "build", "dist", "outputs",
                                                                 "__pycache__", "multirun", "reports"))
    built = subprocess.run([sys.executable, "-m", "build", "--wheel", "-o", str(tmp_path), str(source)],
                           capture_output=True, text=True, timeout=600)
    assert built.returncode == 0, built.stdout[-2000:] + built.stderr[-2000:]
    wheel = next(tmp_path.glob("*.whl"))
    names = zipfile.ZipFile(wheel).namelist()
    assert "ddmr_cli/docs/model.md" in names and "ddmr_cli/conf/config.yaml" in names
    # the package imported from the wheel itself (a zip: no source tree beside it) reads model.md
    code = ("import sys; sys.path.insert(0, sys.argv[1]); import ddmr_cli.config as c; "
            "assert c.__file__.startswith(sys.argv[1]), c.__file__; print(c.model_section(10))")
    read = subprocess.run([sys.executable, "-c", code, str(wheel)], capture_output=True, text=True, timeout=120)
    assert read.returncode == 0, read.stderr
    assert read.stdout.strip() == "10. Sensors, actuator and control rate (the limits the paper names)"
