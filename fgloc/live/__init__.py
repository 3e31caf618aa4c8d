"""Live localization on the robot: STM32 serial link, SICK CoLa-A laser, fusion loop.

* :mod:`fgloc.live.serial_protocol` - the STM32 frame format and incremental parser
* :mod:`fgloc.live.serial_link` - pyserial URL -> frames -> Odometry / CompassHeading
* :mod:`fgloc.live.sick` - CoLa-A framing, LMDscandata parsing, reconnecting TCP client
* :mod:`fgloc.live.clock` - device clock -> host clock (minimum-delay offset + drift)
* :mod:`fgloc.live.runner` / :mod:`fgloc.live.app` - the fusion loop and session wiring
* :mod:`fgloc.live.publish` - fused poses as UDP JSON lines

Hardware emulators and the replay harness (test support) live in :mod:`fgloc.testing`.

Protocols and schemas: ``docs/serial-protocol.md``.  Command line: ``fgloc live``.
"""
