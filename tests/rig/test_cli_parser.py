"""Building the `hopkinson` parser (every call, `--help` too) loads no heavy library."""

from __future__ import annotations

import json
import subprocess
import sys

HEAVY = ("numpy", "scipy", "pymodbus", "pyvisa", "serial", "h5py", "matplotlib", "PySide6", "pyqtgraph")


def test_building_the_parser_imports_no_heavy_library() -> None:
    # A fresh interpreter: this test process has loaded everything already.
    code = (
        "import json, sys\n"
        "from hopkinson.rig.cli.main import build_parser\n"
        "build_parser()\n"
        "print(json.dumps(sorted(sys.modules)))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True)
    modules = set(json.loads(done.stdout))
    assert "hopkinson.rig.cli.shot" in modules  # the probe did import the commands
    loaded = {m.split(".")[0] for m in modules}
    assert loaded.isdisjoint(HEAVY), sorted(loaded & set(HEAVY))
