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
        "from rig.cli import build_parser\n"
        "build_parser()\n"
        "print(json.dumps(sorted({m.split('.')[0] for m in sys.modules})))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True)
    loaded = set(json.loads(done.stdout))
    assert "rig" in loaded  # the probe did import the commands
    assert loaded.isdisjoint(HEAVY), sorted(loaded & set(HEAVY))
