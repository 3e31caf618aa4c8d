"""Hardware emulators for testing the live stack without a robot (loopback only).

* :class:`Stm32Emulator` replays a run's ``/odom`` and ``/imu`` as serial frames
  (wheel counts by inverse kinematics, compass in 0.1 deg) to a pty or a TCP server
  (``socket://127.0.0.1:PORT`` for pyserial), with an MCU clock that has its own
  offset and drift, optional corruption / garbage injection and pauses.
* :class:`SickEmulator` is a CoLa-A TCP server on 127.0.0.1 streaming the run's
  ``/scan`` as ``sSN LMDscandata`` telegrams after ``sEN LMDscandata 1``; it can drop
  the connection (and refuse new ones for a while) and inject malformed telegrams.

Both can step their device clock mid-run (``clock_steps``: ``[(after_s, step_s), ...]``, the
device clock jumps by ``step_s`` once the replay is ``after_s`` seconds in): a microcontroller
reset or re-flash, a scanner re-synchronised, while the sequence and scan counters go on.

Replay timing: message stamp ``s`` is emitted at host time
``start_host + (s - s0) / speed`` (``s0`` the first stamp of the run), so a test knows
the exact host <-> run time mapping (:meth:`ReplayClock.to_host`).
``tools/emu_stm32.py`` and ``tools/emu_sick.py`` are the command-line wrappers.
"""

from __future__ import annotations

import logging
import math
import os
import random
import socket
import threading
import time
import tty
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from fgloc.geometry import wrap_angle
from fgloc.live.serial_link import RobotParams, kinematics_of
from fgloc.live.serial_protocol import FLAG_COUNTS, FLAG_GYRO, FLAG_HEADING, encode_sensor_frame
from fgloc.live.sick import COLA_B_HEADER, encode_lmdscandata, frame, frame_b, lmdscandata_to_binary
from fgloc.types import CompassHeading, Imu, LaserScan, Odometry

log = logging.getLogger(__name__)


@dataclass
class ReplayClock:
    """Maps run time to host time: ``host = start_host + (s - s0) / speed``."""

    s0: float
    start_host: float
    speed: float = 1.0

    def to_host(self, s: float | np.ndarray) -> float | np.ndarray:
        return self.start_host + (s - self.s0) / self.speed

    def to_run(self, h: float | np.ndarray) -> float | np.ndarray:
        return self.s0 + (h - self.start_host) * self.speed


def clock_step_us(steps: Iterable[tuple[float, float]], after_s: float) -> int:
    """The device clock's total step (us) ``after_s`` seconds into the replay: the sum of every
    ``step_s`` whose ``after_s`` has passed."""
    return int(round(sum(step for at, step in steps if after_s >= at) * 1e6))


def _wait_until(t_host: float, stop: threading.Event) -> bool:
    """Sleep until host time ``t_host``; False if stopped."""
    while True:
        dt = t_host - time.time()
        if dt <= 0:
            return not stop.is_set()
        if stop.wait(min(dt, 0.05)):
            return False


class _TcpSink:
    """A tiny TCP server on 127.0.0.1 that sends bytes to the one connected client."""

    def __init__(self, port: int = 0) -> None:
        self.srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.srv.bind(("127.0.0.1", port))
        self.srv.listen(1)
        self.srv.settimeout(0.1)
        self.port = self.srv.getsockname()[1]
        self.client: socket.socket | None = None

    def poll_accept(self) -> None:
        try:
            c, _ = self.srv.accept()
        except (TimeoutError, OSError):
            return
        if self.client is not None:
            self.client.close()
        c.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.client = c

    def write(self, data: bytes) -> None:
        client = self.client  # the emulator's thread; drop_connection may clear it meanwhile
        if client is None:
            return
        try:
            client.sendall(data)
        except OSError:
            client.close()
            if self.client is client:
                self.client = None

    def close(self) -> None:
        if self.client is not None:
            self.client.close()
        self.srv.close()


@dataclass
class InjectStats:
    frames: int = 0
    corrupted: int = 0
    garbage_bytes: int = 0
    paused_frames: int = 0
    malformed: int = 0
    dropped_connections: int = 0


class Stm32Emulator:
    """Replays ``/odom`` + ``/imu`` as STM32 serial frames.  ``mode`` is ``"pty"`` or ``"tcp"``."""

    def __init__(
        self,
        messages: Iterable[tuple[str, object]],
        robot: RobotParams,
        mode: str = "pty",
        port: int = 0,
        speed: float = 1.0,
        start_host: float | None = None,
        t_start: float | None = None,
        duration: float | None = None,
        drift_ppm: float = 40.0,
        mcu_t0_us: int = (1 << 32) - 20_000_000,  # MCU clock wraps 20 s into the replay
        count0: int = (1 << 31) - 3000,  # encoder counters wrap almost at once
        corrupt_prob: float = 0.0,
        garbage_prob: float = 0.0,
        seed: int = 0,
        odom_topic: str = "/odom",
        imu_topic: str = "/imu",
        clock: ReplayClock | None = None,
        inject: dict[int, bytes] | None = None,
        clock_steps: Iterable[tuple[float, float]] = (),
    ) -> None:
        msgs: list[tuple[str, Odometry | CompassHeading]] = [
            (t, m.heading() if isinstance(m, Imu) else m) for t, m in messages  # a log's Imu: its yaw and yaw rate
            if t in (odom_topic, imu_topic) and isinstance(m, Odometry | CompassHeading | Imu)
        ]
        msgs.sort(key=lambda tm: tm[1].stamp)
        if t_start is not None:
            msgs = [tm for tm in msgs if tm[1].stamp >= t_start]
        if duration is not None and msgs:
            s_first = msgs[0][1].stamp
            msgs = [tm for tm in msgs if tm[1].stamp <= s_first + duration]
        if not msgs:
            raise ValueError("no /odom or /imu messages to replay")
        self.msgs = msgs
        self.robot = robot
        self.speed = speed
        self.s0 = float(msgs[0][1].stamp)
        self.clock = clock or ReplayClock(self.s0, start_host if start_host is not None else time.time() + 0.2, speed)
        self.drift = drift_ppm * 1e-6
        self.mcu_t0_us = mcu_t0_us
        self.count0 = count0
        self.corrupt_prob = corrupt_prob
        self.garbage_prob = garbage_prob
        self.rng = random.Random(seed)
        self.stats = InjectStats()
        self.inject = dict(inject or {})  # frame index -> raw bytes written just before that frame
        self.clock_steps = [(float(a), float(d)) for a, d in clock_steps]  # (s into the replay, MCU clock step s)
        self.sent: list[tuple[str, int]] = []  # ("odom" | "imu", index in self.msgs) of every intact frame written
        self.done = threading.Event()
        self._stop = threading.Event()
        self._pause_until = 0.0
        self._thread: threading.Thread | None = None
        self.mode = mode
        self._tcp: _TcpSink | None = None
        self._master: int | None = None
        self._slave: int | None = None
        if mode == "pty":
            self._master, self._slave = os.openpty()
            tty.setraw(self._slave)
            self.url = os.ttyname(self._slave)
        elif mode == "tcp":
            self._tcp = _TcpSink(port)
            self.url = f"socket://127.0.0.1:{self._tcp.port}"
        else:
            raise ValueError(f"mode must be 'pty' or 'tcp', got {mode!r}")

    @property
    def end_run_time(self) -> float:
        return float(self.msgs[-1][1].stamp)

    def pause(self, seconds: float) -> None:
        """Go silent (frames generated meanwhile are lost, the sequence counter keeps going)."""
        self._pause_until = time.time() + seconds

    def drop_connection(self) -> None:
        """TCP mode: close the client's connection (it may connect again)."""
        client = self._tcp.client if self._tcp is not None else None
        if self._tcp is not None and client is not None:
            # the emulator's thread may see the shutdown first and clear the sink's client: close this one
            try:
                client.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            client.close()
            if self._tcp.client is client:
                self._tcp.client = None
            self.stats.dropped_connections += 1

    def start(self) -> None:
        self._thread = threading.Thread(target=self.run, name="emu-stm32", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)
        self.close()

    def close(self) -> None:
        if self._tcp is not None:
            self._tcp.close()
        for fd in (self._master, self._slave):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = None

    def _write(self, data: bytes) -> None:
        if self._master is not None:
            try:
                os.write(self._master, data)
            except OSError:
                pass
        elif self._tcp is not None:
            self._tcp.write(data)

    def frames(self) -> Iterable[tuple[float, bytes]]:
        """``(host_send_time, frame bytes)`` for the whole replay (no corruption)."""
        for h, f, _ in self.frames_with_source():
            yield h, f

    def frames_with_source(self) -> Iterable[tuple[float, bytes, int]]:
        """``(host_send_time, frame bytes, index in self.msgs)`` for the whole replay."""
        n = self.robot.n_wheels
        kin = kinematics_of(self.robot)
        phi = np.zeros(n)  # wheel angles, rad
        last_s: float | None = None
        seq = 0
        for i, (_topic, m) in enumerate(self.msgs):
            s = float(m.stamp)
            h = float(self.clock.to_host(s))
            t_mcu = int(round(self.mcu_t0_us + (h - self.clock.start_host) * (1.0 + self.drift) * 1e6))
            t_mcu += clock_step_us(self.clock_steps, s - self.clock.s0)
            if isinstance(m, Odometry):
                if last_s is not None and s > last_s:
                    phi += np.asarray(kin.inverse(np.asarray(m.twist, dtype=float))) * (s - last_s)
                last_s = s
                # round, not floor: a source whose twists came from integer counts is reproduced exactly
                counts = [self.count0 + int(round(p * self.robot.counts_per_rev / (2 * math.pi))) for p in phi]
                f = encode_sensor_frame(seq, t_mcu, counts, None, None, FLAG_COUNTS)
            else:
                assert isinstance(m, CompassHeading)
                if m.yaw_rad is None:
                    continue
                hd = int(round(math.degrees(float(wrap_angle(m.yaw_rad))) * 10.0))
                hd = ((hd + 1800) % 3600) - 1800
                # the MCU's clock runs in host time: at speed k the encoders turn k times as fast per
                # MCU second, and so must the gyro (it read a k-th of the turn before)
                rate = None if m.yaw_rate_radps is None else m.yaw_rate_radps * self.speed
                g = None if rate is None else int(round(math.degrees(rate) * 100.0))
                flags = FLAG_HEADING | (FLAG_GYRO if g is not None else 0)
                counts = [0] * n
                f = encode_sensor_frame(seq, t_mcu, counts, hd, g, flags)
            seq += 1
            yield h, f, i

    def run(self) -> None:
        try:
            for k, (h, f, i) in enumerate(self.frames_with_source()):
                if not _wait_until(h, self._stop):
                    return
                if self._tcp is not None and self._tcp.client is None:
                    self._tcp.poll_accept()
                self.stats.frames += 1
                if time.time() < self._pause_until:
                    self.stats.paused_frames += 1
                    continue
                data = f
                intact = True
                if self.corrupt_prob and self.rng.random() < self.corrupt_prob:
                    b = bytearray(f)
                    b[self.rng.randint(4, len(b) - 1)] ^= self.rng.randint(1, 255)
                    data = bytes(b)
                    self.stats.corrupted += 1
                    intact = False
                if self.garbage_prob and self.rng.random() < self.garbage_prob:
                    g = bytes(self.rng.getrandbits(8) for _ in range(self.rng.randint(1, 32)))
                    self.stats.garbage_bytes += len(g)
                    data = g + data
                if k in self.inject:
                    self.stats.garbage_bytes += len(self.inject[k])
                    data = self.inject[k] + data
                self._write(data)
                if intact:
                    self.sent.append(("odom" if isinstance(self.msgs[i][1], Odometry) else "imu", i))
        finally:
            self.done.set()


class SickEmulator:
    """CoLa-A TCP server on 127.0.0.1 streaming LMDscandata telegrams of a run's scans."""

    def __init__(
        self,
        messages: Iterable[tuple[str, object]],
        port: int = 0,
        speed: float = 1.0,
        start_host: float | None = None,
        t_start: float | None = None,
        duration: float | None = None,
        angle_offset_deg: float = -90.0,
        drift_ppm: float = -25.0,
        dev_t0_us: int = 123_456_789,
        malformed_prob: float = 0.0,
        seed: int = 0,
        scan_topic: str = "/scan",
        clock: ReplayClock | None = None,
        inject: dict[int, bytes] | None = None,
        device_ident: str = "10 LMS10x_FieldEval 10 V1.36-21.10.2010",
        telegram: dict | None = None,
        dialect: str = "A",
        measuring: bool = True,
        clock_steps: Iterable[tuple[float, float]] = (),
    ) -> None:
        """``device_ident``: the ``sRA DeviceIdent`` answer's fields (default: the example answer SICK's
        telegram listing gives, as ansarid/pysicktim and zh3305/LMS5xxConnector quote it);
        ``telegram``: :func:`encode_lmdscandata` keywords giving a real device's telegram shape
        (e.g. a TiM571's ``{"rssi_bits": 16, "name": "..."}``, an LMS5xx's ``{"scale": 2.0}``);
        ``dialect="B"``: a device set to CoLa-B (binary): every answer and telegram in CoLa-B, to
        commands in either dialect; ``measuring=False``: a device left in standby (it acknowledges
        sEN LMDscandata but sends nothing until logged in (sMN SetAccessMode 03 F4724744), told
        sMN LMCstartmeas and sMN Run); ``clock_steps``: ``[(after_s, step_s)]``, the device's clock
        (time since start-up and of transmission) steps by ``step_s`` ``after_s`` seconds into the replay."""
        if dialect not in ("A", "B"):
            raise ValueError(f"dialect must be 'A' or 'B', got {dialect!r}")
        self.device_ident = device_ident
        self.telegram_kw = dict(telegram or {})
        self.dialect = dialect
        self.measuring = measuring
        self._logged_in = False
        self._start_requested = False
        scans = [m for t, m in messages if t == scan_topic and isinstance(m, LaserScan)]
        scans.sort(key=lambda m: m.stamp)
        if t_start is not None:
            scans = [m for m in scans if m.stamp >= t_start]
        if duration is not None and scans:
            scans = [m for m in scans if m.stamp <= scans[0].stamp + duration]
        if not scans:
            raise ValueError("no /scan messages to replay")
        self.scans = scans
        self.speed = speed
        self.clock = clock or ReplayClock(
            float(scans[0].stamp), start_host if start_host is not None else time.time() + 0.2, speed
        )
        self.angle_offset_deg = angle_offset_deg
        self.drift = drift_ppm * 1e-6
        self.dev_t0_us = dev_t0_us
        self.malformed_prob = malformed_prob
        self.rng = random.Random(seed)
        self.stats = InjectStats()
        self.inject = dict(inject or {})  # scan index -> raw bytes sent just before that scan's telegram
        self.clock_steps = [(float(a), float(d)) for a, d in clock_steps]
        self.sent_scans = 0
        self.sent: list[int] = []  # indices (in self.scans) of the scans whose telegrams were sent
        self.done = threading.Event()
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._client: socket.socket | None = None
        self._streaming = False
        self._refuse_until = 0.0
        self._threads: list[threading.Thread] = []
        self._srv: socket.socket | None = None
        self.port = port
        self._listen()

    def _listen(self) -> None:
        srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        srv.bind(("127.0.0.1", self.port))
        srv.listen(1)
        srv.settimeout(0.1)
        self.port = srv.getsockname()[1]
        self._srv = srv

    @property
    def address(self) -> str:
        return f"127.0.0.1:{self.port}"

    def drop_connection(self, refuse_s: float = 0.0) -> None:
        """Close the client connection; refuse connections for ``refuse_s`` seconds."""
        with self._lock:
            self.stats.dropped_connections += 1
            self._refuse_until = time.time() + refuse_s
            if refuse_s > 0 and self._srv is not None:
                # listener first, so a quick reconnect is refused rather than reset
                self._srv.close()
                self._srv = None
            if self._client is not None:
                try:
                    self._client.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass
                self._client.close()
                self._client = None
                self._streaming = False

    def start(self) -> None:
        for target, name in ((self._serve, "emu-sick-serve"), (self._stream, "emu-sick-stream")):
            t = threading.Thread(target=target, name=name, daemon=True)
            t.start()
            self._threads.append(t)

    def stop(self) -> None:
        self._stop.set()
        for t in self._threads:
            t.join(2.0)
        with self._lock:
            if self._client is not None:
                self._client.close()
            if self._srv is not None:
                self._srv.close()

    def _dev_us(self, h: float) -> int:
        step = clock_step_us(self.clock_steps, (h - self.clock.start_host) * self.clock.speed)
        return int(round(self.dev_t0_us + (h - self.clock.start_host) * (1.0 + self.drift) * 1e6 + step)) & 0xFFFFFFFF

    def _serve(self) -> None:
        """Accept one client at a time and answer its commands."""
        buf = b""
        while not self._stop.is_set():
            with self._lock:
                if self._srv is None and time.time() >= self._refuse_until:
                    try:
                        self._listen()
                    except OSError:
                        pass
                srv, client = self._srv, self._client
            if client is None:
                if srv is None:
                    time.sleep(0.02)
                    continue
                try:
                    c, _ = srv.accept()
                except (TimeoutError, OSError):
                    continue
                c.settimeout(0.1)
                c.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                with self._lock:
                    self._client = c
                    self._streaming = False
                    self._logged_in = False
                buf = b""
                continue
            try:
                data = client.recv(4096)
            except TimeoutError:
                continue
            except OSError:
                data = b""
            if not data:
                with self._lock:
                    if self._client is client:
                        client.close()
                        self._client = None
                        self._streaming = False
                continue
            buf += data
            while True:
                if buf.startswith(COLA_B_HEADER):
                    if len(buf) < 8 or len(buf) < 9 + int.from_bytes(buf[4:8], "big"):
                        break
                    n = int.from_bytes(buf[4:8], "big")
                    cmd, buf = buf[8 : 8 + n], buf[9 + n :]
                    # the binary argument of sEN as its CoLa-A digit
                    cmd = cmd[:-1] + b"%d" % cmd[-1] if cmd.startswith(b"sEN ") and cmd[-1] < 2 else cmd
                    self._answer(client, cmd.strip())
                elif b"\x03" in buf and not buf.startswith(b"\x02\x02"):
                    cmd, _, buf = buf.partition(b"\x03")
                    cmd = cmd[cmd.rfind(b"\x02") + 1 :].strip()
                    self._answer(client, cmd)
                else:
                    break

    def _frame(self, payload: bytes) -> bytes:
        """A telegram in the emulated device's dialect (a CoLa-A payload turned binary for CoLa-B)."""
        if self.dialect == "A":
            return frame(payload)
        if payload.startswith((b"sSN LMDscandata", b"sRA LMDscandata")):
            return frame_b(lmdscandata_to_binary(payload))
        if payload.startswith(b"sRA DeviceIdent "):
            parts = payload[16:].split(b" ")
            name, version = parts[1] if len(parts) > 1 else b"", parts[3] if len(parts) > 3 else b""
            return frame_b(b"sRA DeviceIdent " + len(name).to_bytes(2, "big") + name
                           + len(version).to_bytes(2, "big") + version)
        if payload.startswith(b"sEA LMDscandata "):
            return frame_b(b"sEA LMDscandata " + bytes([int(payload[16:])]))
        if payload.startswith(b"sFA "):
            return frame_b(b"sFA" + int(payload[4:], 16).to_bytes(2, "big"))
        if payload.startswith(b"sAN "):
            head, _, val = payload.rpartition(b" ")
            return frame_b(head + b" " + bytes([int(val)]))
        return frame_b(payload)

    def _answer(self, client: socket.socket, cmd: bytes) -> None:
        reply: bytes
        if cmd == b"sEN LMDscandata 1":
            reply, on = self._frame(b"sEA LMDscandata 1"), True
        elif cmd == b"sEN LMDscandata 0":
            reply, on = self._frame(b"sEA LMDscandata 0"), False
        elif cmd == b"sRN LMDscandata":
            k = max(0, min(self.sent_scans, len(self.scans) - 1))
            h = time.time()
            reply = self._frame(encode_lmdscandata(self.scans[k], k, k, self._dev_us(h), self._dev_us(h),
                                             self.angle_offset_deg, command="sRA", **self.telegram_kw))
            on = self._streaming
        elif cmd == b"sRN DeviceIdent":
            reply, on = self._frame(b"sRA DeviceIdent " + self.device_ident.encode()), self._streaming
        elif cmd.startswith(b"sMN SetAccessMode"):
            ok = cmd[18:] in (b"03 F4724744", b"\x03\xf4\x72\x47\x44")  # authorized client, its default password
            self._logged_in = ok
            reply, on = self._frame(b"sAN SetAccessMode %d" % ok), self._streaming
        elif cmd == b"sMN LMCstartmeas":
            self._start_requested = self._start_requested or self._logged_in
            reply = self._frame(b"sAN LMCstartmeas 0" if self._logged_in else b"sFA 1")
            on = self._streaming
        elif cmd == b"sMN Run":
            self.measuring = self.measuring or self._start_requested
            reply, on = self._frame(b"sAN Run 1"), self._streaming
        else:
            reply, on = self._frame(b"sFA 1"), self._streaming
        with self._lock:
            if self._client is client:
                self._streaming = on
                try:
                    client.sendall(reply)
                except OSError:
                    pass

    def _stream(self) -> None:
        try:
            for k, sc in enumerate(self.scans):
                period = sc.scan_time if sc.scan_time > 0 else 0.04
                h_start = float(self.clock.to_host(sc.stamp))
                h_send = h_start + period / self.speed
                scaled = LaserScan(
                    stamp=sc.stamp, angle_min=sc.angle_min, angle_increment=sc.angle_increment,
                    range_min=sc.range_min, range_max=sc.range_max, ranges=sc.ranges,
                    time_increment=sc.time_increment / self.speed, scan_time=period / self.speed,
                )
                payload = encode_lmdscandata(scaled, k, k, self._dev_us(h_start), self._dev_us(h_send),
                                             self.angle_offset_deg, **self.telegram_kw)
                out = self._frame(payload)
                bad = self.malformed_prob > 0 and self.rng.random() < self.malformed_prob
                if bad:
                    cut = payload[: self.rng.randint(20, max(21, len(payload) - 5))]
                    out = frame(cut) + out
                out = self.inject.get(k, b"") + out
                # encoded ahead, sent on time: "time of transmission" is when the bytes leave
                if not _wait_until(h_send, self._stop):
                    return
                with self._lock:
                    c, on = self._client, self._streaming and self.measuring
                    if c is not None and on:
                        try:
                            c.sendall(out)
                            self.sent_scans += 1
                            self.sent.append(k)
                            self.stats.malformed += int(bad)
                        except OSError:
                            pass
                self.stats.frames += 1
        finally:
            self.done.set()


@dataclass
class EmulatorPair:
    """Both emulators on a shared replay clock (so serial and laser stay in sync)."""

    stm32: Stm32Emulator
    sick: SickEmulator
    clock: ReplayClock
    extra: dict = field(default_factory=dict)

    @staticmethod
    def create(
        messages: list[tuple[str, object]],
        robot: RobotParams,
        mode: str = "pty",
        speed: float = 1.0,
        t_start: float | None = None,
        duration: float | None = None,
        lead_s: float = 0.5,
        stm32_kw: dict | None = None,
        sick_kw: dict | None = None,
    ) -> EmulatorPair:
        """Replay ``messages[t_start : t_start + duration]`` starting ``lead_s`` from now."""
        stamps = [float(m.stamp) for t, m in messages if hasattr(m, "stamp")]  # type: ignore[attr-defined]
        s0 = min(stamps) if t_start is None else max(min(stamps), t_start)
        clock = ReplayClock(s0, time.time() + lead_s, speed)
        stm = Stm32Emulator(messages, robot, mode=mode, speed=speed, t_start=s0,
                            duration=duration, clock=clock, **(stm32_kw or {}))
        sick = SickEmulator(messages, speed=speed, t_start=s0, duration=duration, clock=clock, **(sick_kw or {}))
        return EmulatorPair(stm, sick, clock)

    def start(self) -> None:
        self.sick.start()
        self.stm32.start()

    def stop(self) -> None:
        self.stm32.stop()
        self.sick.stop()
