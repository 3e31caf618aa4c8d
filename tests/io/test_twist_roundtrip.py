"""``geometry_msgs/TwistWithCovarianceStamped``: written by fgloc's MCAP writer, read back by the
readers as a :class:`~fgloc.types.Twist` (a ROS 2 MCAP with its ros2msg schema, decoded by
mcap_ros2 as any log's would be)."""

from __future__ import annotations

import numpy as np

from fgloc.io import open_log
from fgloc.io.mcap_writer import LogWriter
from fgloc.io.msgdefs import full_text
from fgloc.types import Twist


def test_a_twist_round_trips_through_an_mcap(tmp_path):
    rng = np.random.default_rng(0)
    sent = []
    for k in range(50):
        A = rng.normal(size=(3, 3))
        sent.append(Twist(10.0 + 0.02 * k, rng.normal(size=3), A @ A.T * 1e-3, "flow_link"))
    sent.append(Twist(11.5, np.array([0.4, 0.0, -0.1]), None, "base_link"))  # covariance unknown: all zeros
    with LogWriter(tmp_path / "t.mcap") as w:
        for m in sent:
            w.write("/twist", m)
    src = open_log(tmp_path / "t.mcap")
    assert src.summary()["topics"]["/twist"] == {"type": "geometry_msgs/msg/TwistWithCovarianceStamped",
                                                 "count": len(sent)}
    got = [m for _, m in src.messages(["/twist"])]
    assert all(isinstance(m, Twist) for m in got) and [m.frame_id for m in got] == [m.frame_id for m in sent]
    assert np.allclose([m.stamp for m in got], [m.stamp for m in sent], rtol=0, atol=1e-9)  # stamps in ns
    assert np.array_equal([m.twist for m in got], [m.twist for m in sent])
    assert all(np.array_equal(a.twist_cov, b.twist_cov) for a, b in zip(got[:-1], sent[:-1], strict=True))
    assert got[-1].twist_cov is None


def test_the_definition_is_the_ros2_one():
    assert full_text("geometry_msgs/TwistWithCovarianceStamped").startswith(
        "std_msgs/Header header\nTwistWithCovariance twist\n")
