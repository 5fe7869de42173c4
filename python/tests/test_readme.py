"""README.md's Python blocks (```python), run as written from the checkout, so the notebook
example cannot drift from the package."""

import re

from conftest import ROOT


def test_readme_python_blocks_run(monkeypatch, capsys):
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"^```python\n(.*?)^```", text, flags=re.S | re.M)
    assert blocks, "README.md has no ```python block"
    monkeypatch.chdir(ROOT)
    for code in blocks:
        exec(compile(code, "README.md", "exec"), {})
    assert "['asymmetry']" in capsys.readouterr().out
