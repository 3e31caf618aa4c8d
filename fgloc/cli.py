"""The ``fgloc`` command line: one typer app, one module per subcommand group.

Each module in :mod:`fgloc.commands` exposes ``register(app)``; this file only
wires them together and turns :class:`fgloc.errors.FglocError` into a one-line
message with exit status 2 (never a traceback).
"""

from __future__ import annotations

import atexit
import gc
import importlib
import inspect
import logging
import re
import sys
import typing
from pathlib import Path
from typing import Any

import typer
import typer.core

from fgloc.app import mounts
from fgloc.errors import FglocError
from fgloc.io import stop

#: the top-level commands and the :mod:`fgloc.commands` modules whose ``register(app)`` adds them, in the
#: order ``fgloc --help`` lists them (typer's: the commands, then the groups).  A command line builds only the
#: command it runs (typer reads the annotations of every option of every command it builds: ~0.02 s of CPU
#: for all of them); ``fgloc --help`` lists their help texts without building any
COMMANDS: dict[str, tuple[str, ...]] = {
    "demo": ("bench",), "eval": ("eval",), "export": ("eval",), "import": ("io",), "info": ("io",),
    "live": ("live",), "map": ("map",), "map-check": ("map",), "map-info": ("maps",), "replay": ("replay",),
    "run": ("run",), "batch": ("batch",), "bench": ("bench",), "config": ("config", "porting"),
    "simulate": ("sim",), "view": ("view",),
}

#: the root app's settings, which every command built from it takes too
SETTINGS: dict[str, Any] = {"add_completion": False, "pretty_exceptions_enable": False,
                            # help texts are plain: "[/odom]" (a default shown in brackets) is not markup
                            "rich_markup_mode": None}


def registered(modules: tuple[str, ...] | list[str]) -> typer.Typer:
    """A Typer app with what the command modules ``modules`` of :mod:`fgloc.commands` register."""
    sub = typer.Typer(**SETTINGS)
    for name in modules:
        importlib.import_module(f"fgloc.commands.{name}").register(sub)
    return sub


#: a number as a command line writes one, which ``float()`` / ``int()`` read exactly as typer's coercion does
_FLOAT = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d{1,3})?")
_INT = re.compile(r"-?(?:0|[1-9]\d{0,17})")


class _Declined(ValueError):
    """A value :class:`PlainCoercion` leaves to typer's own coercion."""


class PlainCoercion:
    """A typer parameter's coercion of the plain values a command line gives (a string, a path, a number
    written as such, a tuple of them, a value through the option's ``parser``) without typer's pydantic
    TypeAdapters: importing pydantic and building an adapter per option cost every ``fgloc run`` ~0.1 s
    of CPU.  Anything else (a choice, a range, a bool given as text, a value that fails) goes to typer's
    own coercion, which gives the value or the error message; the values taken here are the ones it gives
    (tests/test_cli_coercion.py compares them)."""

    def __init__(self, descriptor: Any, build: Any) -> None:
        self.descriptor = descriptor
        self._build = build  # typer's coercion of this parameter, built when a value is declined
        self._typer: Any = None

    def coerce(self, value: Any, param: Any, ctx: Any) -> Any:
        multi = param.multiple or param.nargs == -1
        if value is None and not multi:
            return None
        if not multi:
            try:
                return self.plain(value, param, ctx)
            except Exception:  # noqa: BLE001  typer's coercion gives the value, or the error, its way
                pass
        if self._typer is None:
            self._typer = self._build(self.descriptor)
        return self._typer.coerce(value, param=param, ctx=ctx)

    def plain(self, value: Any, param: Any = None, ctx: Any = None) -> Any:
        """The value as typer's coercion gives it; :class:`_Declined` (or the parser's error) otherwise."""
        d = self.descriptor
        args = typing.get_args(d.annotation)
        if typing.get_origin(d.annotation) is tuple and args and Ellipsis not in args:
            if not isinstance(value, tuple) or len(value) != len(args):
                raise _Declined(value)
            return tuple(self._leaf(a, v, param, ctx) for a, v in zip(args, value, strict=True))
        return self._leaf(d.annotation, value, param, ctx)

    def _leaf(self, annotation: Any, value: Any, param: Any, ctx: Any) -> Any:
        info = self.descriptor.parameter_info
        if not isinstance(value, str):
            raise _Declined(value)
        if info.parser is not None:
            return info.parser(value)
        if annotation is str:
            return value
        ranged = info.min is not None or info.max is not None
        if annotation is float and not ranged and _FLOAT.fullmatch(value):
            return float(value)
        if annotation is int and not ranged and _INT.fullmatch(value):
            return int(value)
        if isinstance(annotation, type) and issubclass(annotation, Path) and info.path_type is None and value \
                and "\0" not in value:
            from typer._param_types import coerce_cli_path

            return coerce_cli_path(annotation(value), info, path_type=annotation, param=param, ctx=ctx)
        raise _Declined(value)


def plain_coercion(cmd: Any, ctx: Any = None) -> Any:
    """``cmd`` (and its subcommands) with :class:`PlainCoercion` on each parameter typer coerces through
    pydantic (typer 0.29's lazy per-parameter coercion; an older typer has none: ``cmd`` as it is); with
    ``ctx``, its help option too."""
    try:
        from typer._coercion import build_runtime_param
    except ImportError:
        return cmd
    for p in cmd.params if ctx is None else cmd.get_params(ctx):
        desc = vars(p).get("type_descriptor")
        if desc is not None and "_runtime_param" in vars(p) and p._runtime_param is None and \
                desc.file_annotation is None and not desc.is_choice:
            p._runtime_param = PlainCoercion(desc, build_runtime_param)
    for sub in (vars(cmd).get("commands") or {}).values():
        plain_coercion(sub, ctx)
    return cmd


class LazyCommands(typer.core.TyperGroup):
    """The root command: each of :data:`COMMANDS` is built when it is asked for (run, or its own help)."""

    def list_commands(self, ctx: Any) -> list[str]:
        return [*self.commands, *(n for n in COMMANDS if n not in self.commands)]

    def get_command(self, ctx: Any, cmd_name: str) -> Any:
        if cmd_name not in self.commands and cmd_name in COMMANDS:
            for name, cmd in typer.main.get_group(registered(COMMANDS[cmd_name])).commands.items():
                self.commands.setdefault(name, plain_coercion(cmd, ctx))
        return self.commands.get(cmd_name)

    def parse_args(self, ctx: Any, args: list[str]) -> list[str]:
        plain_coercion(self, ctx)  # the root's own options (--version, --help)
        return super().parse_args(ctx, args)

    def resolve_command(self, ctx: Any, args: list[str]) -> Any:
        if args and args[0] not in self.commands and args[0] not in COMMANDS:
            for name in COMMANDS:  # no such command: typer's suggestions are drawn from them all
                self.get_command(ctx, name)
        return super().resolve_command(ctx, args)

    def format_commands(self, ctx: Any, formatter: Any) -> None:
        """The list of commands, each one's help text as typer would give it, none built."""
        listed = registered(sorted({m for mods in COMMANDS.values() for m in mods}))
        stubs: dict[str, Any] = {}
        for ci in listed.registered_commands:
            assert ci.callback is not None
            doc = inspect.getdoc(ci.callback) if ci.help is None else inspect.cleandoc(ci.help)
            stubs[ci.name or typer.main.get_command_name(ci.callback.__name__)] = typer.core.TyperCommand(
                ci.name, help=doc, short_help=ci.short_help, hidden=ci.hidden, deprecated=ci.deprecated)
        for gi in listed.registered_groups:
            si = typer.main.solve_typer_info_defaults(gi)
            stubs[si.name or ""] = typer.core.TyperCommand(si.name, help=si.help, short_help=si.short_help,
                                                           hidden=si.hidden, deprecated=si.deprecated)
        stubs.update(self.commands)
        saved, self.commands = self.commands, {n: stubs[n] for n in self.list_commands(ctx) if n in stubs}
        try:
            super().format_commands(ctx, formatter)
        finally:
            self.commands = saved


app = typer.Typer(
    name="fgloc",
    help="Indoor robot localization without ROS: EKF, GTSAM smoothers, AMCL/KISS-ICP/native scan matching.",
    no_args_is_help=True,
    cls=LazyCommands,
    **SETTINGS,
)


def _print_version(value: bool) -> None:
    if value:
        from fgloc import __version__

        print(f"fgloc {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(False, "--version", "-V", is_eager=True, callback=_print_version,
                                 help="print the fgloc version and exit"),
) -> None:
    """Indoor robot localization without ROS."""


@app.command("version")
def version() -> None:
    """Print the fgloc version."""
    from fgloc import __version__

    print(__version__)



#: options whose usage errors get a message that names the values and their units
OPTION_HINTS = {
    "--initial-pose": "--initial-pose needs three values X Y YAW (m, m, rad or with its unit: 90deg; base_link in "
                      "the map frame), e.g. --initial-pose 2.5 3.0 0.0",
    "--laser-mount": "--laser-mount needs three values X Y YAW (m, m, rad or with its unit: 180deg; base_link -> "
                     "laser)",
    **mounts.HINTS,  # --static-transform-xyzw before --static-transform: the first name found in the message wins
}


def _option_hint(e: Exception) -> str | None:
    fmt = getattr(e, "format_message", None)
    text = fmt() if callable(fmt) else str(e)
    for opt, hint in OPTION_HINTS.items():
        if opt in text:
            return f"{hint} ({text.strip().rstrip('.')})"
    return None


def main(argv: list[str] | None = None) -> int:
    """Entry point: run the app, map user errors to one line on stderr and exit 2.

    Without ``argv`` (the ``fgloc`` console script, ``python -m fgloc.cli``) the process ends here
    once the command is done, without the interpreter's teardown (:func:`fgloc.app.startup.exit_process`);
    with ``argv`` (a caller in the same process) it returns the exit code."""
    code = _main(argv)
    if argv is None:
        from fgloc.app.startup import exit_process

        exit_process(code)
    return code


def _main(argv: list[str] | None) -> int:
    logging.basicConfig(level=logging.WARNING, format="fgloc: %(levelname)s: %(message)s")
    # at exit, skip the interpreter's last cycle collection over everything loaded (numba, scipy,
    # gtsam: 0.15-0.3 s of every command); the OS frees the memory
    atexit.register(gc.freeze)
    # SIGINT / SIGTERM: stop cleanly at the first, at once at the second (fgloc.io.stop); the
    # console script exits next, so its handlers stay (a late Ctrl-C is no traceback in the exit)
    with stop.handling(restore=argv is not None):
        code = _invoke(argv)
        if code == stop.EXIT_INTERRUPTED and stop.requested() is not None:
            print(stop.interrupted_line(), file=sys.stderr)
    return code


def _invoke(argv: list[str] | None) -> int:
    try:
        rv = app(args=argv, standalone_mode=False)
    except FglocError as e:
        print(f"fgloc: error: {e}", file=sys.stderr)
        return 2
    except (typer.Exit, SystemExit) as e:
        code = getattr(e, "exit_code", getattr(e, "code", 0))
        return int(code or 0)
    except typer.Abort:
        print("fgloc: aborted", file=sys.stderr)
        return stop.EXIT_INTERRUPTED
    except KeyboardInterrupt:
        if stop.requested() is None:
            print("fgloc: interrupted", file=sys.stderr)
        return stop.EXIT_INTERRUPTED
    except OSError as e:
        from fgloc.io.outputs import is_disk_error, problem

        if is_disk_error(e):  # a write no output layer saw (the layer names the file it was writing)
            print(f"fgloc: error: {e.filename or 'disk'}: {problem(e)}", file=sys.stderr)
            return 2
        raise
    except Exception as e:  # click usage errors (typer vendors click, so match by shape)
        if stop.requested() is not None:  # what a stop left behind (an import cut short): interrupted
            return stop.EXIT_INTERRUPTED
        if hasattr(e, "show") and hasattr(e, "exit_code"):
            hint = _option_hint(e)
            if hint is not None:
                print(f"fgloc: error: {hint}", file=sys.stderr)
                return 2
            e.show()
            return int(e.exit_code)
        raise
    # click returns the code of a typer.Exit(code) in non-standalone mode
    return rv if isinstance(rv, int) and not isinstance(rv, bool) else 0


if __name__ == "__main__":
    sys.exit(main())
