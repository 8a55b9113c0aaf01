"""The README's Python example runs as written (from the repository root)."""

import pathlib
import re
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parents[2]


def test_the_readme_python_example_runs_as_written():
    text = (ROOT / "README.md").read_text()
    section = text.split("## Using skinpatch from Python", 1)[1]
    blocks = re.findall(r"```python\n(.*?)```", section.split("\n## ", 1)[0], re.S)
    assert len(blocks) == 1, "one Python example in the section"
    code = blocks[0]
    assert len(code.strip().splitlines()) == 5
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    # 61 frames (t = 0 … 1 s at 60 Hz), then the shapes.
    assert len(lines) == 62 and lines[0] == "0 0.0", lines[:3]
    peak = max(float(line.split()[1]) for line in lines[:61])
    assert peak > 0.01, "the skin pushes back on the probe"
    assert re.fullmatch(r"\(\d+, 2\) \(\d+, 3, 3\)", lines[61]), lines[61]
