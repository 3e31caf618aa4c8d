"""Port robot_localization, fuse and nav2 parameter files to an fgloc config.

:func:`from_robot_localization`, :func:`from_fuse` and :func:`from_nav2` take the parsed YAML of a ROS 1 or ROS 2
parameter file and return ``(config, notes)``: a mapping of fgloc config sections (checked
by :func:`fgloc.config.parse_config`) and one line per parameter that could not be carried
over, saying why.  ``fgloc config from-robot-localization`` / ``from-fuse`` / ``from-nav2``
(:mod:`fgloc.commands.porting`) write it as YAML.
"""

from fgloc.porting.fuse import from_fuse
from fgloc.porting.nav2 import from_nav2
from fgloc.porting.robot_localization import from_robot_localization

__all__ = ["from_fuse", "from_nav2", "from_robot_localization"]
