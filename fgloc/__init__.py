"""fgloc: indoor mobile-robot localization without ROS.

The paper's EKF, GTSAM fixed-lag and batch smoothers, AMCL / KISS-ICP / native
scan-to-map front-ends, ROS 2 MCAP logs, map_server maps and TUM trajectories.
"""

__version__ = "0.1.0"


def _early_signals() -> None:
    """The ``fgloc`` console script only: a Ctrl-C during the start-up is recorded, not raised in
    the middle of an import (fgloc.io.stop acts on it once the command runs)."""
    import os
    import sys

    main = sys.modules.get("__main__")
    if os.path.basename(getattr(main, "__file__", None) or "") == "fgloc":
        from fgloc.io.stop import install_early

        install_early()


_early_signals()
