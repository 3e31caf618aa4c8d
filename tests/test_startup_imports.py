"""Start-up cost: the CLI must not import the heavy libraries before a command needs them.

`import fgloc.cli` took 0.76 s of CPU when one top-level import in a command module pulled in
numba and scipy (fixed in 27da586; 0.13-0.17 s without them). Every fgloc command, --help
included, pays that import, so it is checked here in a fresh interpreter.
"""

from __future__ import annotations

import json
import subprocess
import sys

HEAVY = ("numba", "scipy", "gtsam", "open3d", "kiss_icp", "ray", "matplotlib", "foxglove", "mcap_ros2")


def test_cli_import_pulls_in_no_heavy_library() -> None:
    code = (
        "import json, sys\n"
        "import fgloc.cli  # noqa: F401\n"
        f"print(json.dumps([m for m in {HEAVY!r} if m in sys.modules]))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    loaded = json.loads(out.stdout.strip().splitlines()[-1])
    assert loaded == [], f"import fgloc.cli imported {loaded}: import them inside the command that needs them"
