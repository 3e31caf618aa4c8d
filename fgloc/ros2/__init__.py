"""fgloc as a ROS 2 peer over DDS, without a ROS installation.

* :mod:`~fgloc.ros2.names` - topic and type names as ROS 2's rmw layers put them on the wire;
* :mod:`~fgloc.ros2.qos` - the QoS profiles of ROS 2, tf2 and nav2, and their DDS form;
* :mod:`~fgloc.ros2.msgtypes` - DDS types of the ROS 2 messages (from :mod:`fgloc.io.msgdefs`);
* :mod:`~fgloc.ros2.codec` - CDR bytes <-> fgloc objects (fgloc's own codecs);
* :mod:`~fgloc.ros2.typehash` - the RIHS01 type hashes ROS 2 Iron and later put in USER_DATA;
* :mod:`~fgloc.ros2.graph` - ``ros_discovery_info``: fgloc as a node of the ROS 2 graph;
* :mod:`~fgloc.ros2.transport` - the transport interface and its Cyclone DDS implementation;
* :mod:`~fgloc.ros2.node` - ``fgloc live --ros2``: the localizer as a drop-in for nav2's AMCL;
* :mod:`~fgloc.ros2.replay` - ``fgloc replay --ros2``: a log published as a ROS 2 robot would;
* :mod:`~fgloc.ros2.config` - the ``ros2:`` config section.

Only :mod:`~fgloc.ros2.config` is imported when the config is composed; the rest import Cyclone
DDS (``pip install "fgloc[ros2]"``) when used.
"""
