"""The README's Python example runs as written from the clone's root: every ```python block of
`README.md` is executed in a scratch folder laid out like the clone (`fixtures/` linked), so it
reads only what the repository holds and writes nothing into it."""

import os
import pathlib
import re

import numpy as np

from conftest import REPO


def python_blocks(page: pathlib.Path) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", page.read_text(), flags=re.S | re.M)


def test_readme_python_example_runs(tmp_path, monkeypatch):
    blocks = python_blocks(REPO / "README.md")
    assert blocks, "README.md has no ```python block"
    (tmp_path / "fixtures").symlink_to(REPO / "fixtures")
    monkeypatch.chdir(tmp_path)
    for code in blocks:
        scope: dict = {}
        exec(compile(code, "README.md", "exec"), scope)  # noqa: S102 (the page's own example)
    # What the comment in the example promises.
    image = scope["I"]
    assert image.dtype == np.float32 and image.shape == (16, 16, 20)
    assert np.isfinite(image).all() and image.max() > 0
    assert sorted(os.listdir(tmp_path)) == ["fixtures"], "the example wrote files"
