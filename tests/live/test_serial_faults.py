"""The STM32 serial link on real ports: a USB-serial unplugged and plugged back under its stable
path (a pty behind a symlink, as udev's /dev/serial/by-id gives), a board reset in the middle of
a frame, wrong-baud noise.  The reader keeps going and counts what it lost, each under its cause.
No timing: the tests wait (generously) for content and assert on counts."""

from __future__ import annotations

import math
import os
import random
import socket
import time
import tty

import pytest

from fgloc.live.serial_link import FrameConverter, RobotParams, SerialLink
from fgloc.live.serial_protocol import encode_sensor_frame

CPR = RobotParams.from_dict({"drive": "diff"}).counts_per_rev


def _frames(seq0: int, t0_us: int, n: int, count0: int = 0, per_frame: int = 5) -> list[bytes]:
    """``n`` frames 10 ms apart, both wheels ``per_frame`` counts further each frame, compass 10 deg."""
    return [encode_sensor_frame(seq0 + k, t0_us + 10_000 * k, [count0 + per_frame * k] * 2, 100, None)
            for k in range(n)]


def _wait(cond, timeout_s: float = 60.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not cond() and time.monotonic() < deadline:
        time.sleep(0.01)
    assert cond()


def _pty() -> tuple[int, int, str]:
    master, slave = os.openpty()
    tty.setraw(slave)
    return master, slave, os.ttyname(slave)


def _link(url: str):
    msgs: list[tuple[str, object]] = []
    events: list[str] = []
    conv = FrameConverter(RobotParams.from_dict({"drive": "diff"}), align_clock=False)
    link = SerialLink(url, conv, lambda kind, m, arrival: msgs.append((kind, m)), on_event=events.append)
    return link, msgs, events


def test_usb_serial_unplugged_mid_frame_and_replugged_under_its_path(tmp_path):
    """Before: the half frame left in the parser when the port died was joined to the new port's
    first frame and counted as a CRC error (line corruption); now it is a truncated frame."""
    path = tmp_path / "ttyROBOT"
    m1, s1, dev1 = _pty()
    path.symlink_to(dev1)
    link, msgs, events = _link(str(path))
    link.start()
    m2 = s2 = None
    try:
        _wait(lambda: link.connected)
        os.write(m1, b"".join(_frames(0, 0, 50)))
        _wait(lambda: link.parser.stats.frames_ok == 50)
        cut = _frames(50, 500_000, 1)[0]
        os.write(m1, cut[: len(cut) // 2])
        _wait(lambda: link.parser.pending > 0)  # the reader holds half a frame ...
        os.close(m1)  # ... when the adapter is unplugged
        os.close(s1)
        m2, s2, dev2 = _pty()  # plugged back: a new device node behind the same path
        path.unlink()
        path.symlink_to(dev2)
        _wait(lambda: link.opens == 2 and link.connected)
        os.write(m2, b"".join(_frames(51, 510_000, 50, count0=255)))
        _wait(lambda: link.parser.stats.frames_ok == 100)
    finally:
        link.stop()
        for fd in (m2, s2):
            if fd is not None:
                os.close(fd)
    st = link.parser.stats
    assert (st.crc_errors, st.truncated, st.dropped, link.disconnects) == (0, 1, 1, 1)
    assert link.failure is None and sum("lost" in e for e in events) == 1
    odom = [m for k, m in msgs if k == "odom"]
    assert len(odom) == 99  # every frame but the first; the gap over the lost frame spans 20 ms
    v = 5 * 2 * math.pi / CPR * RobotParams.from_dict({"drive": "diff"}).wheel_radius_m / 0.01
    assert all(m.twist[0] == pytest.approx(v) for m in odom)  # type: ignore[attr-defined]


def test_board_reset_mid_frame_then_wrong_baud_noise_over_socket_url():
    """socket:// (pyserial over a real TCP socket): the MCU restarts half-way through a frame
    (sequence, clock and counts from 0), then the line carries noise (a baud mismatch) before good
    frames again.  Every good frame is decoded, the restart is a reset (not 64k dropped frames,
    not an implausible twist), the noise is garbage."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    link, msgs, _ = _link(f"socket://127.0.0.1:{srv.getsockname()[1]}")
    link.start()
    try:
        conn, _ = srv.accept()
        with conn:
            _wait(lambda: link.connected)  # pyserial's socket:// drops what arrives while it opens
            conn.sendall(b"".join(_frames(1000, 5_000_000, 100, count0=40_000)))
            conn.sendall(_frames(1100, 6_000_000, 1, count0=40_500)[0][:11])  # reset mid-frame
            conn.sendall(b"".join(_frames(0, 0, 100)))
            noise = bytes(random.Random(7).getrandbits(8) for _ in range(3000))
            conn.sendall(noise)
            conn.sendall(b"".join(_frames(100, 1_000_000, 100, count0=500)))
            _wait(lambda: link.parser.stats.frames_ok == 300)
    finally:
        link.stop()
        srv.close()
    st = link.parser.stats
    assert st.seq_resets == 1 and st.dropped == 0 and st.garbage_bytes >= 3000
    assert link.converter.implausible_twist == 0 and link.converter.bad_dt == 0
    odom = [m for k, m in msgs if k == "odom"]
    assert len(odom) == 298  # the first frame after start and after the reset give no twist
    v = 5 * 2 * math.pi / CPR * RobotParams.from_dict({"drive": "diff"}).wheel_radius_m / 0.01
    assert all(m.twist[0] == pytest.approx(v) for m in odom)  # type: ignore[attr-defined]
