"""Test support, not product: what the tests, the benchmarks and the demo tools use to run
fgloc without hardware.  No module of the product imports this package.

* :mod:`fgloc.testing.emulators` - STM32 serial (pty / socket) and SICK CoLa-A (TCP)
  emulators replaying a run on a shared clock, with fault injection
* :mod:`fgloc.testing.harness` - :func:`~fgloc.testing.harness.replay_live`: a run replayed
  through the emulators into a live session, poses mapped back to run time
* :mod:`fgloc.testing.rosmsgs` - ROS odometry and laser-scan messages built with ``rosbags``, as
  the tests write them into rosbag2 folders

It ships in the wheel (so ``tools/emu_*.py`` and ``tools/bench_latency.py`` work from an
installed fgloc) but depends only on the standard library, fgloc and fgloc's own dependencies.
"""
