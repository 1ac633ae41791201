"""The README's Python sessions run as written (from the repository root, headless)."""

from __future__ import annotations

import os
import pathlib
import re
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[3]
BLOCKS = re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), flags=re.S)


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_readme_python_block_runs(index: int, tmp_path: pathlib.Path) -> None:
    code = BLOCKS[index]
    # Paths in the README are relative to the repository root; outputs go to tmp_path.
    code = code.replace('"fixtures/', f'"{ROOT}/fixtures/').replace('"replay.png"', f'"{tmp_path}/replay.png"')
    env = dict(os.environ, MPLBACKEND="Agg")
    done = subprocess.run(
        [sys.executable, "-c", "import stereonav\n" + code],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, f"README block {index}:\n{code}\n{done.stderr}"
