"""The API reference (``docs/api``: Sphinx, autodoc and numpydoc over the public modules' docstrings)
builds with warnings as errors: a docstring that docutils cannot read, a malformed table or
section, a module that does not import, fails the build. Built into a temporary folder; nothing
is generated into ``docs/api``."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

API = Path(__file__).resolve().parents[1] / "docs" / "api"


def test_the_api_reference_builds_without_a_warning(tmp_path):
    before = sorted(p.name for p in API.iterdir())
    r = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html", str(API),
                        str(tmp_path / "html"), "-d", str(tmp_path / "doctrees")], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in API.iterdir()) == before  # no page generated into the sources
    modules = re.findall(r"^   (musclemetab[\w.]*)$", (API / "index.rst").read_text(), flags=re.M)
    assert "musclemetab.redundancy.solution" in modules and "musclemetab.io.matlab" in modules
    index = (tmp_path / "html" / "index.html").read_text()
    for module in modules:  # every module of the index has its page, linked from the index
        assert (tmp_path / "html" / f"{module}.html").is_file() and f'href="{module}.html' in index, module
    page = (tmp_path / "html" / "musclemetab.redundancy.solution.html").read_text()
    assert 'id="musclemetab.redundancy.solution.Solution.to_mat"' in page  # a method's docstring, from the code
