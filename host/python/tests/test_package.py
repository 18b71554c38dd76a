"""The package's layout: `README.md`'s table of files against `vltm/`, every file at most 800
lines, and the keywords the probes share documented once (`vltm._options`) and shown in the
help of every function that takes them."""

import inspect
import re

import pytest

import vltm
from conftest import REPO
from vltm import _options

PKG = REPO / "host" / "python" / "vltm"
WRAPPERS = [vltm.direct, vltm.column, vltm.indirect, vltm.relight, vltm.row, vltm.matrix,
            vltm.info, vltm.Capture.transient]


def package_files() -> list:
    return sorted(p.name for p in PKG.iterdir()
                  if p.is_file() and (p.suffix in (".py", ".pyi") or p.name == "py.typed"))


def test_readme_table_names_every_file_once():
    text = (REPO / "host" / "python" / "README.md").read_text()
    section = text.split("## The package's files", 1)[1].split("\n## ", 1)[0]
    rows = re.findall(r"^\| `([^`]+)` \|", section, flags=re.M)
    assert sorted(rows) == package_files()


def test_every_file_is_at_most_800_lines():
    for name in package_files():
        n = len((PKG / name).read_text().splitlines())
        assert n <= 800, f"vltm/{name}: {n} lines, at most 800"


@pytest.mark.parametrize("fn", WRAPPERS, ids=lambda f: f.__qualname__)
def test_shared_keywords_are_in_each_wrappers_help(fn):
    doc = inspect.getdoc(fn)
    shared = [k for k in inspect.signature(fn).parameters if k in _options.DOCS]
    assert shared, fn.__qualname__
    head, common = doc.split("Common keywords", 1)
    assert head.strip(), f"{fn.__qualname__}: no description of its own"
    for k in shared:
        if fn is vltm.Capture.transient and k in _options.OUTPUT:
            continue  # its report and xarray are its own, in its own text
        assert f"- ``{k}``: " in common, f"{fn.__qualname__}: `{k}` not in Common keywords"


def test_every_shared_keyword_has_a_check_or_is_a_result_option():
    assert set(_options.DOCS) == set(_options.WAVE + _options.INPUT + _options.OUTPUT)
    assert set(_options._CHECKS) == set(_options.WAVE + _options.INPUT)


def test_every_public_name_has_a_docstring():
    for name in vltm.__all__:
        assert inspect.getdoc(getattr(vltm, name)), name
