"""The API reference builds from the docstrings in mkdocs' strict mode (what `make docs` runs).

A broken cross-reference, a link to a missing page, a module that moved without its page or a
docstring griffe cannot parse fails here. Skipped where the `docs` extra is not installed.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def test_every_public_module_has_a_page():
  import jaxfilters  # noqa: PLC0415

  pages = {p.stem for p in (ROOT / "docs" / "api").glob("*.md")}
  config = (ROOT / "mkdocs.yml").read_text()
  modules = {name for name in jaxfilters.__all__ if not name.startswith("_")
             and type(getattr(jaxfilters, name)).__name__ == "module"}
  for name in {"jaxfilters", *(f"jaxfilters.{m}" for m in modules)}:
    assert name in pages, f"docs/api/{name}.md missing"
  for page in pages:
    assert f"api/{page}.md" in config, f"docs/api/{page}.md is not in mkdocs.yml's nav"
    assert re.search(rf"^::: {re.escape(page)}$", (ROOT / "docs" / "api" / f"{page}.md").read_text(), re.M)


@pytest.mark.slow
def test_the_api_reference_builds_in_strict_mode(tmp_path):
  pytest.importorskip("mkdocs", reason="the docs extra is not installed (pip install -e '.[docs]')")
  pytest.importorskip("mkdocstrings_handlers.python", reason="mkdocstrings-python is not installed")
  proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
                        cwd=ROOT, capture_output=True, text=True, timeout=600)
  warnings = [line for line in proc.stderr.splitlines() if not line.startswith("INFO")]
  assert proc.returncode == 0, "\n".join(warnings[-40:])
  assert (tmp_path / "site" / "api" / "jaxfilters.keepout.html").is_file()
