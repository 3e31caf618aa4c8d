"""Where batch jobs run: in this process, in a local process pool, or on Ray.

Every engine runs ``fn(job, blobs)`` (normally :func:`fgloc.batch.jobs.execute`) for each job
and yields ``(index, JobResult)`` as jobs finish, in any order.  ``blobs`` is None when the
inputs go by path, and the input files' bytes when they are shipped (``ship=True``).

* :class:`InlineEngine`: one after the other in this process (the benchmark's baseline).
* :class:`LocalEngine` (``--engine local``, ``-j N``): N worker processes (spawned, so
  nothing of the driver's threads is inherited), each running one job at a time and reused
  for the next (imports and numba caches are paid once per worker).  A worker that dies
  (segfault, out of memory) fails only its own job and is replaced.  Workers ignore SIGINT:
  on Ctrl-C the driver terminates them and the interrupted jobs leave no completion marker.
* :class:`RayEngine` (``--engine ray``): one Ray task per job (1 CPU each).  Without an
  address (and no ``RAY_ADDRESS``) it starts a private local Ray instance with ``num_cpus``
  = ``-j`` or all cores (its workers at niceness 0, like the pool's; Ray's own default is 15)
  and shuts it down at the end (the start runs in the background while the driver prepares
  the jobs, see :meth:`RayEngine.start`).  The private instance is the driver's alone: every
  server of it (GCS, raylet, workers, the driver's own, the agents) listens on the loopback
  interface only, it asks a random token of every client (Ray's token authentication), it
  has no dashboard, and it dies with the driver however the driver ends (``kill -9``
  included: :mod:`fgloc.batch.raywatch`).  With ``--address HOST:PORT`` or
  ``RAY_ADDRESS`` it joins that cluster (fgloc must be installed on its nodes; inputs by
  path need shared storage, ``--ship-inputs`` does not).  At most twice the cluster's CPUs
  are in flight, so shipped inputs do not fill the object store.  A task whose worker
  crashes is retried once by Ray, then reported as that job's error.  A cluster with token
  authentication (what ``ray start`` sets up when a token exists) is joined as by any Ray
  client: ``RAY_AUTH_MODE=token`` and the token in ``RAY_AUTH_TOKEN`` or ``~/.ray/auth_token``.
"""

from __future__ import annotations

import importlib.util
import logging
import multiprocessing as mp
import os
import re
import secrets
import signal
import subprocess
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from pathlib import Path
from typing import Any

from fgloc.batch.jobs import Blob, Job, JobResult, read_blob
from fgloc.errors import ConfigError

JobFn = Callable[[Job, "dict[str, Blob] | None"], JobResult]

RAY_HINT = 'the ray engine needs Ray: pip install "fgloc[cluster]"'
RAYWATCH_ENV = "FGLOC_RAY_INSTANCE"  # every process of a private instance carries it (raywatch.py)
LOOPBACK = ("127.0.0.1", "::1", "localhost")


def shipped_inputs(job: Job) -> dict[str, Blob]:
    """Read a job's input files for shipping (driver side); OSError for a missing input."""
    return {role: read_blob(role, path) for role, path in job.inputs.items()}


def _ship_or_error(job: Job, ship: bool) -> tuple[dict[str, Blob] | None, JobResult | None]:
    if not ship:
        return None, None
    try:
        return shipped_inputs(job), None
    except OSError as e:
        path = e.filename or next(iter(job.inputs.values()), "")
        return None, JobResult(job.name, False, error=f"{path}: cannot read input to ship ({e.strerror or e})")


def crash_result(job: Job, exitcode: int | None) -> JobResult:
    """The result of a job whose worker process died under it."""
    if exitcode is not None and exitcode < 0:
        try:
            how = signal.Signals(-exitcode).name
        except ValueError:
            how = f"signal {-exitcode}"
        msg = f"worker process died ({how}) while running this log"
    else:
        msg = f"worker process exited (status {exitcode}) while running this log"
    return JobResult(job.name, False, error=msg)


class InlineEngine:
    """Jobs one after the other in this process (no isolation from crashes)."""

    name = "inline"

    def describe(self) -> str:
        return "inline (this process)"

    def run(self, fn: JobFn, jobs: list[Job], ship: bool = False) -> Iterator[tuple[int, JobResult]]:
        for i, job in enumerate(jobs):
            blobs, err = _ship_or_error(job, ship)
            yield i, err if err is not None else fn(job, blobs)


# ---------------------------------------------------------------------------- local pool
def _worker_main(conn: Connection, fn: JobFn) -> None:
    """A pool worker: run jobs from ``conn`` until told to stop (None) or the pipe closes.

    Ctrl-C is the driver's to handle; SIGTERM (the driver stopping a busy worker, or the driver's
    death: the parent-death signal) ends the job where its outputs can be discarded whole
    (:mod:`fgloc.io.stop`), then the worker."""
    from fgloc.io import stop

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the driver decides what Ctrl-C stops
    parent = os.getppid()
    _die_with_parent()
    if os.getppid() != parent:  # the driver died before the parent-death signal was set
        return
    with stop.handling():
        while True:
            try:
                msg = conn.recv()
            except (EOFError, OSError, KeyboardInterrupt):
                return
            if msg is None:
                return
            i, job, blobs = msg
            try:
                res = fn(job, blobs)
            except KeyboardInterrupt:
                return
            conn.send((i, res))


def _die_with_parent() -> None:
    """SIGTERM this process when its parent dies (Linux ``PR_SET_PDEATHSIG``; elsewhere nothing)."""
    import ctypes
    import ctypes.util

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        libc.prctl(1, int(signal.SIGTERM), 0, 0, 0)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


@dataclass
class _Slot:
    proc: Any
    conn: Connection
    current: tuple[int, Job] | None = None


class LocalEngine:
    """A pool of ``jobs`` worker processes on this machine."""

    name = "local"

    def __init__(self, jobs: int | None = None) -> None:
        self.jobs = max(1, int(jobs or os.cpu_count() or 1))

    def describe(self) -> str:
        return f"local process pool, {self.jobs} worker(s)"

    def _start(self, ctx: Any, fn: JobFn) -> _Slot:
        parent, child = ctx.Pipe()
        p = ctx.Process(target=_worker_main, args=(child, fn), daemon=True, name="fgloc-batch-worker")
        p.start()
        child.close()
        return _Slot(p, parent)

    def run(self, fn: JobFn, jobs: list[Job], ship: bool = False) -> Iterator[tuple[int, JobResult]]:
        if not jobs:
            return
        ctx = mp.get_context("spawn")
        queue: deque[tuple[int, Job]] = deque(enumerate(jobs))
        slots: list[_Slot] = []
        from fgloc.io import stop

        def kill_all() -> None:  # a second Ctrl-C exits at once: no worker goes on as an orphan
            for s in slots:
                s.proc.kill()

        unhook = stop.at_hard_exit(kill_all)
        try:
            slots += [self._start(ctx, fn) for _ in range(min(self.jobs, len(jobs)))]
            while queue or any(s.current is not None for s in slots):
                for s in slots:
                    while s.current is None and queue:
                        i, job = queue.popleft()
                        blobs, err = _ship_or_error(job, ship)
                        if err is not None:
                            yield i, err
                            continue
                        try:
                            s.conn.send((i, job, blobs))
                            s.current = (i, job)
                        except (BrokenPipeError, OSError):  # died while idle: retry the job on a new one
                            queue.appendleft((i, job))
                            self._replace(ctx, fn, slots, s)
                            break
                busy = [s for s in slots if s.current is not None]
                if not busy:
                    continue
                ready = wait([s.conn for s in busy] + [s.proc.sentinel for s in busy])
                for s in busy:
                    if s.conn not in ready and s.proc.sentinel not in ready:
                        continue
                    assert s.current is not None
                    got, eof = None, False
                    try:
                        if s.conn.poll():
                            got = s.conn.recv()
                    except (EOFError, OSError):
                        eof = True
                    if got is not None:
                        s.current = None
                        yield got
                        continue
                    if not eof and s.proc.sentinel not in ready:
                        continue
                    s.proc.join(timeout=5)  # the pipe closed or the process ended: it died
                    i, job = s.current
                    s.current = None
                    yield i, crash_result(job, s.proc.exitcode)
                    self._replace(ctx, fn, slots, s)
        finally:
            unhook()
            self._stop(slots)

    def _replace(self, ctx: Any, fn: JobFn, slots: list[_Slot], dead: _Slot) -> None:
        dead.conn.close()
        if dead.proc.is_alive():
            dead.proc.kill()
        dead.proc.join(timeout=5)
        k = slots.index(dead)
        slots[k] = self._start(ctx, fn)

    @staticmethod
    def _stop(slots: list[_Slot]) -> None:
        """Idle workers are told to stop; busy ones (Ctrl-C, an error in the driver) are terminated."""
        for s in slots:
            try:
                if s.current is None and s.proc.is_alive():
                    s.conn.send(None)
                else:
                    s.proc.terminate()
            except (BrokenPipeError, OSError):
                pass
        for s in slots:
            s.proc.join(timeout=5)
            if s.proc.is_alive():
                s.proc.kill()
                s.proc.join(timeout=5)
            s.conn.close()


# ---------------------------------------------------------------------------- Ray
def import_ray() -> Any:
    """``ray`` or a one-line :class:`ConfigError` with the install hint."""
    try:
        import ray
    except ImportError:
        raise ConfigError(RAY_HINT) from None
    return ray


_TOKEN: list[str] = []


def _private_token() -> str:
    """The token of this process's private instances: one per process (Ray's client keeps the first
    token it loads for the life of the process), the user's own when ``RAY_AUTH_TOKEN`` is set."""
    if not _TOKEN:
        _TOKEN.append(os.environ.get("RAY_AUTH_TOKEN") or secrets.token_hex(32))
    return _TOKEN[0]


def _reload_ray_auth() -> None:
    """Have Ray's client read ``RAY_AUTH_MODE`` / ``RAY_AUTH_TOKEN`` again (its configuration first,
    then the token cache, as Ray's own ``ray get-auth-token`` and test utilities do)."""
    try:
        raylet: Any = importlib.import_module("ray._raylet")
    except ImportError:
        return
    raylet.Config.initialize("")
    raylet.AuthenticationTokenLoader.instance().reset_cache()


def _ray_task(fn: JobFn, job: Job, roles: list[str], *blobs: Blob) -> JobResult:
    """The Ray task: shipped inputs arrive as top-level arguments (Ray resolves them from the
    object store before the call)."""
    return fn(job, dict(zip(roles, blobs, strict=True)) if roles or blobs else None)


class RayEngine:
    """One Ray task per job, on a private local Ray instance or an existing cluster.

    :meth:`start` begins joining (or starting) Ray in a background thread and returns at once, so
    the driver reads its inputs, fingerprints and completion markers meanwhile (the batch API
    calls it before that preparation); :meth:`connect` (and :meth:`run`) wait for it.  The thread
    lives as long as the connection: Ray ties its daemons to the thread that started them (Linux's
    parent-death signal), so a thread that ended would take a private instance down with it.
    ``timings`` records the start (``import ray`` and ``ray.init``), how long the driver waited for
    it, and the stop, in seconds.
    """

    name = "ray"

    def __init__(self, jobs: int | None = None, address: str | None = None) -> None:
        self.jobs = jobs
        self.address = address or os.environ.get("RAY_ADDRESS") or None
        if importlib.util.find_spec("ray") is None:  # the hint now; the import itself in start()
            raise ConfigError(RAY_HINT)
        self._started = False          # this engine started the Ray connection (it stops it)
        self._owned_by_run = False     # started by start(): run() stops it at the end
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._hold_until = threading.Event()
        self._error: BaseException | None = None
        self.timings: dict[str, float] = {"start_s": 0.0, "wait_s": 0.0, "stop_s": 0.0}
        self._watchdog: subprocess.Popen[bytes] | None = None  # a private instance's (raywatch.py)
        self._saved_env: dict[str, str | None] = {}
        self._cluster_flag: Any = None  # Ray's constants module, its cluster flag turned off for a private instance

    @property
    def ray(self) -> Any:
        return import_ray()

    def describe(self) -> str:
        if self.address:
            return f"Ray cluster at {self.address}"
        return f"local Ray instance, {self.jobs or os.cpu_count()} CPU(s)"

    def start(self) -> None:
        """Begin connecting in a background thread (no-op when Ray is already initialized in this
        process or a start is under way); :meth:`run` then stops Ray at its end."""
        if self._thread is not None or ("ray" in sys.modules and self.ray.is_initialized()):
            return
        self._owned_by_run = True
        self._ready.clear()
        self._hold_until.clear()
        self._error = None
        self._thread = threading.Thread(target=self._hold, name="fgloc-ray-start", daemon=True)
        self._thread.start()

    def _hold(self) -> None:
        """The start thread: connect, then stay alive until :meth:`shutdown` (see the class doc)."""
        try:
            self._connect_now()
        except BaseException as e:  # noqa: BLE001 - handed to the driver thread by connect()
            self._error = e
        finally:
            self._ready.set()
        self._hold_until.wait()

    def connect(self) -> None:
        """Join the cluster, or start a private local instance (address 'local': never attaches
        to another Ray instance running on this machine); waits for a :meth:`start` under way."""
        if self._thread is None:
            self._connect_now()
            return
        t0 = time.perf_counter()
        self._ready.wait()
        self.timings["wait_s"] += time.perf_counter() - t0
        if self._error is not None:
            err, self._error = self._error, None
            self._hold_until.set()
            self._thread = None
            raise err

    def _connect_now(self) -> None:
        t0 = time.perf_counter()
        private = not self.address
        imported = "ray" in sys.modules
        if private and not (imported and self.ray.is_initialized()):
            self._private_env()  # before `import ray`: Ray reads some of it when imported
        ray = import_ray()
        if ray.is_initialized():
            return
        if private and imported:
            _reload_ray_auth()  # Ray imported before: its client read the authentication settings then
        kw: dict[str, Any] = {"logging_level": logging.ERROR, "log_to_driver": False,
                              "configure_logging": True}
        try:
            if self.address:
                ray.init(address=self.address, **kw)
            else:
                # loopback only (Ray listens on every interface unless its node address is loopback,
                # and resolves a loopback --node-ip-address to the LAN address unless clusters are off)
                constants: Any = sys.modules.get("ray._private.ray_constants")
                if constants is not None and getattr(constants, "ENABLE_RAY_CLUSTER", False):
                    constants.ENABLE_RAY_CLUSTER = False  # (imported before the environment was set)
                    self._cluster_flag = constants
                # workers at normal priority, as the local pool's and `fgloc run`: Ray's default
                # (niceness 15) makes a batch yield to every other process of a shared machine
                ray.init(address="local", num_cpus=int(self.jobs or os.cpu_count() or 1),
                         include_dashboard=False, _system_config={"worker_niceness": 0}, **kw)
            self._started = True
            if private:
                node = str(ray.util.get_node_ip_address())
                if node not in LOOPBACK:
                    self.shutdown()
                    raise ConfigError(f"Ray: the private instance would listen on {node}, not on the loopback "
                                      f"interface; use --engine local, or a cluster you set up with --address")
        except (ConnectionError, RuntimeError, ValueError) as e:
            if self._saved_env or self._watchdog is not None:
                self._restore_env()
            where = self.address or "a local instance"
            hint = ""
            if self.address and os.environ.get("RAY_AUTH_MODE", "").lower() != "token":
                hint = ("; a cluster with token authentication needs RAY_AUTH_MODE=token and its token "
                        "(RAY_AUTH_TOKEN or ~/.ray/auth_token)")
            raise ConfigError(f"Ray: cannot connect to {where} ({str(e).strip().splitlines()[0]}){hint}") from None
        finally:
            self.timings["start_s"] += time.perf_counter() - t0

    def _private_env(self) -> None:
        """The environment a private instance starts in (restored by :meth:`shutdown`): loopback only,
        a random token asked of every client, every process tagged for the watchdog, which starts
        here (:mod:`fgloc.batch.raywatch`)."""
        tag = secrets.token_hex(8)
        if os.path.isdir("/proc"):
            self._watchdog = subprocess.Popen(
                [sys.executable, "-I", str(Path(__file__).with_name("raywatch.py")), str(os.getpid()), tag],
                stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                start_new_session=True)
        env = {"RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0", "RAY_AUTH_MODE": "token",
               "RAY_AUTH_TOKEN": _private_token(), RAYWATCH_ENV: tag}
        self._saved_env = {k: os.environ.get(k) for k in (*env, "RAY_AUTH_TOKEN_PATH")}
        os.environ.pop("RAY_AUTH_TOKEN_PATH", None)
        os.environ.update(env)

    def _restore_env(self) -> None:
        for k, v in self._saved_env.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        self._saved_env = {}
        if "ray" in sys.modules:
            _reload_ray_auth()  # the process's own settings again (a cluster joined later)
        if self._cluster_flag is not None:
            self._cluster_flag.ENABLE_RAY_CLUSTER = True
            self._cluster_flag = None
        w, self._watchdog = self._watchdog, None
        if w is not None:
            # the pipe closes: the watchdog kills whatever of the instance is left, then exits
            if w.stdin is not None:
                w.stdin.close()
            try:
                w.wait(timeout=15)
            except subprocess.TimeoutExpired:
                w.kill()
                w.wait()

    def shutdown(self) -> None:
        """Disconnect (a private instance stops, and none of its processes outlives this); waits for a
        start under way first."""
        t0 = time.perf_counter()
        if self._thread is not None:
            self._ready.wait()
        if "ray" in sys.modules and self.ray.is_initialized():
            self.ray.shutdown()
        if self._saved_env or self._watchdog is not None:
            self._restore_env()
        if self._thread is not None:
            self._hold_until.set()
            self._thread.join(timeout=10)
            self._thread = None
        self._started = self._owned_by_run = False
        self.timings["stop_s"] += time.perf_counter() - t0

    def run(self, fn: JobFn, jobs: list[Job], ship: bool = False) -> Iterator[tuple[int, JobResult]]:
        if not jobs:
            if self._owned_by_run:  # started for this run, which has nothing to do
                self.shutdown()
            return
        if self._thread is None and not self.ray.is_initialized():
            self.start()  # not started before: this run starts Ray and stops it at its end
        owns = self._owned_by_run
        ray: Any = None
        queue: deque[tuple[int, Job]] = deque(enumerate(jobs))
        pending: dict[Any, tuple[int, Job]] = {}
        refs: dict[tuple[str, str], Any] = {}     # shipped input -> object ref (a shared map is put once)
        users: dict[tuple[str, str], int] = {}    # jobs still needing that input
        if ship:
            for _, job in queue:
                for key in job.inputs.items():
                    users[key] = users.get(key, 0) + 1
        try:
            self.connect()  # the wait for a start under way is timed in self.timings
            ray = self.ray
            task = ray.remote(num_cpus=1, max_retries=1)(_ray_task)
            cpus = int(ray.cluster_resources().get("CPU", 1)) or 1
            cap = 2 * cpus
            while queue or pending:
                while queue and len(pending) < cap:
                    i, job = queue.popleft()
                    roles, args = [], []
                    if ship:
                        try:
                            for role, path in job.inputs.items():
                                if (role, path) not in refs:
                                    refs[(role, path)] = ray.put(read_blob(role, path))
                                roles.append(role)
                                args.append(refs[(role, path)])
                        except OSError as e:
                            self._release(job, refs, users)
                            yield i, JobResult(job.name, False, error=f"{e.filename}: cannot read input to ship "
                                                                     f"({e.strerror or e})")
                            continue
                    pending[task.remote(fn, job, roles, *args)] = (i, job)
                done, _ = ray.wait(list(pending), num_returns=1)
                for ref in done:
                    i, job = pending.pop(ref)
                    if ship:
                        self._release(job, refs, users)
                    try:
                        res = ray.get(ref)
                    except ray.exceptions.RayError as e:
                        res = JobResult(job.name, False, error=ray_error_line(e))
                    yield i, res
        finally:
            for ref in pending:  # (pending: ray was imported)
                try:
                    ray.cancel(ref, force=True)
                except Exception:  # noqa: BLE001 - best effort on the way out
                    pass
            refs.clear()
            if owns:
                self.shutdown()

    @staticmethod
    def _release(job: Job, refs: dict, users: dict) -> None:
        for key in job.inputs.items():
            users[key] = users.get(key, 1) - 1
            if users[key] <= 0:
                refs.pop(key, None)


_ANSI = re.compile(r"\x1b\[[0-9;]*m")
_EXC_LINE = re.compile(r"^(?:[\w.]+\.)?(\w+(?:Error|Exception|Interrupt)): (.+)$")


def ray_error_line(e: BaseException) -> str:
    """A Ray failure as one line: a dead worker as such, else the innermost ``Type: message`` of
    Ray's text (colour codes and Ray's task header removed), with a hint when a worker cannot
    import what the job needs (fgloc not installed on a node)."""
    name = e.__class__.__name__
    text = [t.strip() for t in _ANSI.sub("", str(e)).splitlines() if t.strip()]
    first = text[0] if text else ""
    if "WorkerCrashed" in name or "worker died" in first.lower():
        return f"Ray worker died while running this log ({name})"
    inner = [m for m in (_EXC_LINE.match(t) for t in text) if m]
    if inner:
        kind, msg = inner[-1].group(1), inner[-1].group(2)
        line = f"{kind}: {msg}"
        if kind == "ModuleNotFoundError":
            line += " (on the Ray worker: is fgloc installed on every node?)"
    else:
        line = f"{name}: {first}" if first else name
    return line[:300]


def make_engine(engine: str, jobs: int | None = None, address: str | None = None):
    """``local`` / ``ray`` / ``inline`` by name (``address`` only for Ray)."""
    if engine == "local":
        if address:
            raise ConfigError("--address is for --engine ray")
        return LocalEngine(jobs)
    if engine == "ray":
        return RayEngine(jobs, address)
    if engine == "inline":
        return InlineEngine()
    raise ConfigError(f"unknown engine '{engine}' (choose local or ray)")
