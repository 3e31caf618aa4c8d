"""The package's layout rules, checked on the source: no private name (``_x``) is used across
modules - neither ``from fgloc.a import _x`` nor ``import fgloc.a`` (or ``from fgloc import a``)
followed by ``a._x``, nor ``obj._x`` on another module's object (a private method or attribute
defined only in another fgloc module) - and the old ``fgloc.pipeline`` / ``fgloc.io.log`` import
paths are gone."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "fgloc"


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def _is_private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _absolute(module: str | None, level: int, here: str, is_package: bool) -> str:
    """The absolute module a ``from ... import`` names (relative imports resolved)."""
    if level == 0:
        return module or ""
    base = here.split(".")
    if not is_package:
        base = base[:-1]
    base = base[: len(base) - (level - 1)]
    return ".".join(base + ([module] if module else []))


def private_uses(source: str, here: str, is_package: bool, modules: set[str]) -> list[str]:
    """Each private name of another fgloc module that ``source`` (module ``here``) uses, as
    ``line: what``."""
    tree = ast.parse(source)
    found: list[str] = []
    aliases: dict[str, str] = {}  # local name -> the fgloc module it is bound to

    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if not a.name.startswith("fgloc"):
                    continue
                if any(_is_private(p) for p in a.name.split(".")[1:]):
                    found.append(f"{node.lineno}: import {a.name}")
                if a.asname:
                    aliases[a.asname] = a.name
                else:
                    aliases["fgloc"] = "fgloc"
        elif isinstance(node, ast.ImportFrom):
            mod = _absolute(node.module, node.level, here, is_package)
            if mod != "fgloc" and not mod.startswith("fgloc."):
                continue
            if mod != here and any(_is_private(p) for p in mod.split(".")[1:]):
                found.append(f"{node.lineno}: from {mod} import ...")
            for a in node.names:
                if mod != here and _is_private(a.name):
                    found.append(f"{node.lineno}: from {mod} import {a.name}")
                if f"{mod}.{a.name}" in modules:
                    aliases[a.asname or a.name] = f"{mod}.{a.name}"

    for node in ast.walk(tree):
        if not isinstance(node, ast.Attribute):
            continue
        chain = [node.attr]
        value = node.value
        while isinstance(value, ast.Attribute):
            chain.append(value.attr)
            value = value.value
        if not isinstance(value, ast.Name) or value.id not in aliases:
            continue
        chain.reverse()
        # walk the dotted path while it names modules; the next part is a name in that module
        mod = aliases[value.id]
        for part in chain:
            if f"{mod}.{part}" in modules:
                mod = f"{mod}.{part}"
                continue
            if mod != here and _is_private(part):
                found.append(f"{node.lineno}: {value.id}.{'.'.join(chain[:chain.index(part) + 1])}")
            break
    return sorted(set(found), key=lambda s: int(s.split(":")[0]))


def _private_definitions(tree: ast.AST) -> set[str]:
    """Private names a module defines: functions, methods, classes, ``self._x = ...``, class and
    module level ``_x = ...``."""
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            names.add(node.attr)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            names.add(node.id)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
    return {n for n in names if _is_private(n)}


# private names of the standard library's public protocols (namedtuple, os)
STDLIB_PROTOCOL = {"_replace", "_asdict", "_fields", "_field_defaults", "_make", "_exit"}


def private_attribute_uses(trees: dict[str, ast.AST]) -> dict[str, list[str]]:
    """``obj._x`` where ``obj`` is not ``self``/``cls``/``super()`` and ``_x`` is defined only in
    other fgloc modules: module -> ``line: expression``."""
    defined = {name: _private_definitions(t) for name, t in trees.items()}
    out: dict[str, list[str]] = {}
    for name, tree in trees.items():
        for node in ast.walk(tree):
            if not isinstance(node, ast.Attribute) or not _is_private(node.attr) or node.attr in STDLIB_PROTOCOL:
                continue
            v = node.value
            if isinstance(v, ast.Name) and v.id in ("self", "cls"):
                continue
            if isinstance(v, ast.Call) and isinstance(v.func, ast.Name) and v.func.id == "super":
                continue
            if node.attr in defined[name]:
                continue
            if any(node.attr in d for other, d in defined.items() if other != name):
                out.setdefault(name, []).append(f"{node.lineno}: {ast.unparse(node)}")
    return out


MODULES = _modules()


@pytest.mark.parametrize("name", sorted(MODULES))
def test_no_private_name_is_used_across_modules(name):
    path = MODULES[name]
    uses = private_uses(path.read_text(encoding="utf-8"), name, path.name == "__init__.py", set(MODULES))
    assert not uses, f"{path.relative_to(PACKAGE.parent)} uses private names of other modules: {uses}"


def test_no_private_attribute_of_another_module_is_used():
    trees = {name: ast.parse(p.read_text(encoding="utf-8")) for name, p in MODULES.items()}
    found = {name: sorted({u.split(": ", 1)[1] for u in uses}) for name, uses in private_attribute_uses(trees).items()}
    assert not found, f"private attributes of other modules used: {found}"


def test_the_attribute_checker_catches_a_foreign_private_method():
    trees = {"fgloc.a": ast.parse("class A:\n    def _hidden(self):\n        return self._x\n"),
             "fgloc.b": ast.parse("def f(a, t):\n    t._replace(x=1)\n    super()._hidden()\n    return a._hidden()\n")}
    assert private_attribute_uses(trees) == {"fgloc.b": ["4: a._hidden"]}


@pytest.mark.parametrize("source, bad", [
    ("from fgloc.io.ros import _mirror\n", ["1: from fgloc.io.ros import _mirror"]),
    ("from .ros import _mirror\n", ["1: from fgloc.io.ros import _mirror"]),
    ("import fgloc.io.ros\nfgloc.io.ros._mirror(1)\n", ["2: fgloc.io.ros._mirror"]),
    ("import fgloc.io.ros as r\nr._mirror(1)\n", ["2: r._mirror"]),
    ("from fgloc.io import ros\nros._mirror(1)\n", ["2: ros._mirror"]),
    ("from fgloc.io import ros\nros.mirror(1)\nx = ros.__name__\n", []),
    ("from fgloc.io.ros import mirror as _mirror\n", []),
    ("from fgloc.io.tum import _private_here\n", []),   # the module itself
    ("def f(self):\n    return self._x\n", []),
])
def test_the_checker_catches_each_form(source, bad):
    assert private_uses(source, "fgloc.io.tum", False, set(MODULES)) == bad


def _imports(tree: ast.AST, old: str) -> bool:
    """Whether ``tree`` imports module ``old`` (``import old``, ``from old import x``, ``from
    parent import last``); code in a string (run against another source tree) is not an import."""
    parent, _, last = old.rpartition(".")
    for node in ast.walk(tree):
        if isinstance(node, ast.Import) and any(a.name == old or a.name.startswith(old + ".") for a in node.names):
            return True
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module is not None:
            if node.module == old or node.module.startswith(old + "."):
                return True
            if node.module == parent and any(a.name == last for a in node.names):
                return True
    return False


def _importers(old: str) -> list[str]:
    return [name for name, p in MODULES.items() if _imports(ast.parse(p.read_text(encoding="utf-8")), old)]


@pytest.mark.parametrize("source, imports", [
    ("from fgloc.io.log import LogReader\n", True),
    ("import fgloc.io.log\n", True),
    ("from fgloc.io import log\n", True),
    ("def f():\n    from fgloc.io.log import LogWriter\n", True),
    ("from fgloc.io import logs, open_log\n", False),
    ("CODE = 'from fgloc.io.log import LogReader'\n", False),
])
def test_the_importer_check_reads_imports_not_text(source, imports):
    assert _imports(ast.parse(source), "fgloc.io.log") is imports


def test_the_pipeline_shim_is_gone():
    assert "fgloc.pipeline" not in MODULES
    assert not _importers("fgloc.pipeline")


def test_the_io_log_shim_is_gone():
    assert "fgloc.io.log" not in MODULES
    assert not _importers("fgloc.io.log")


REPO = PACKAGE.parent
SCRIPTS = sorted([*REPO.joinpath("tests").rglob("*.py"), *REPO.joinpath("tools").glob("*.py")])


@pytest.mark.parametrize("path", SCRIPTS, ids=lambda p: str(p.relative_to(REPO)))
def test_tests_and_tools_use_no_private_fgloc_name(path):
    uses = private_uses(path.read_text(encoding="utf-8"), "tests", False, set(MODULES))
    assert not uses, f"{path.relative_to(REPO)} uses private names of fgloc modules: {uses}"


# ------------------------------------------------------------------ back-end / front-end dispatch
#: objects named as a back-end or a front-end (``backend``, ``be``, ``self.loc.frontend`` ...)
ENGINE_NAMES = {"backend", "be", "frontend", "fe"}
#: attribute names too common to say what they are asked of (a message's ``name``, a config's ``cfg``)
GENERIC_NAMES = {"name", "stats", "sources", "cfg", "reset", "finish", "current", "initialize", "match", "map"}
#: getattr / hasattr dispatch the sources router still does, by module prefix (empty it as it switches
#: to the contract: fgloc.backends.contract's methods and capabilities)
DISPATCH_ALLOWED: dict[str, set[str]] = {}


def _contract_names() -> set[str]:
    """The public members of the back-end and front-end contracts, the capabilities' names, and
    back-end internals that were once reached from outside."""
    from fgloc.backends.contract import Backend, Capability
    from fgloc.frontends.base import FrontendBase, ScanMatcher

    names = {n for c in (Backend, FrontendBase, ScanMatcher) for n in dir(c) if not n.startswith("_")}
    names |= {c.value for c in Capability} | set(ENGINE_NAMES) | {"particles"}
    names |= {"arb", "latency_est", "gbias", "encoder_sigmas"}
    return names - GENERIC_NAMES


def _engine_like(node: ast.AST) -> bool:
    return (isinstance(node, ast.Name) and node.id in ENGINE_NAMES) or \
        (isinstance(node, ast.Attribute) and node.attr in ENGINE_NAMES)


def engine_dispatch(source: str, contract: set[str]) -> list[tuple[int, str]]:
    """``getattr(obj, "x", ...)`` / ``hasattr(obj, "x")`` where ``obj`` is named as a back-end or
    front-end, or ``x`` is a member of their contracts: ``(line, x)`` for each."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
                and node.func.id in ("getattr", "hasattr") and len(node.args) >= 2):
            continue
        obj, attr = node.args[0], node.args[1]
        name = attr.value if isinstance(attr, ast.Constant) and isinstance(attr.value, str) else None
        if _engine_like(obj) or (name is not None and name in contract):
            found.append((node.lineno, name if name is not None else ast.unparse(attr)))
    return found


@pytest.mark.parametrize("source, found", [
    ("getattr(self.loc.backend, 'add_gyro', None)\n", [(1, "add_gyro")]),
    ("hasattr(be, 'odom_scales')\n", [(1, "odom_scales")]),
    ("getattr(backend, 'stats', {})\n", [(1, "stats")]),
    ("getattr(self.loc, 'frontend', None)\n", [(1, "frontend")]),
    ("getattr(fe, 'particles', None)\n", [(1, "particles")]),
    ("getattr(thing, 'measures_velocity', False)\n", [(1, "measures_velocity")]),
    ("getattr(be, key)\n", [(1, "key")]),
    ("getattr(msg, 'stamp', None)\nhasattr(writer, 'close')\ngetattr(topics, 'scan', '/scan')\n", []),
    ("getattr(config, 'name', None)\ngetattr(self.session, 'sources', None)\n", []),
])
def test_the_dispatch_check_tells_engines_from_other_objects(source, found):
    assert engine_dispatch(source, _contract_names()) == found


def test_no_getattr_or_hasattr_dispatch_on_backends_or_frontends():
    """Back-ends and front-ends are called through their contracts (fgloc.backends.contract,
    fgloc.frontends.base): what only some do is a declared capability, not a ``hasattr``."""
    contract = _contract_names()
    found: dict[str, list[str]] = {}
    for path in MODULES.values():
        rel = str(path.relative_to(REPO))
        allowed = next((a for prefix, a in DISPATCH_ALLOWED.items() if rel.startswith(prefix)), set())
        bad = [f"{line}: {x}" for line, x in engine_dispatch(path.read_text(encoding="utf-8"), contract)
               if x not in allowed]
        if bad:
            found[rel] = bad
    assert not found, f"getattr / hasattr on a back-end or front-end (use the contract): {found}"


def _fgloc_imports(tree: ast.AST, here: str) -> set[str]:
    """Every fgloc module a module imports, at the top or inside a function."""
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name.startswith("fgloc")}
        elif isinstance(node, ast.ImportFrom):
            mod = _absolute(node.module, node.level, here, False)
            if mod.startswith("fgloc"):
                out |= {f"{mod}.{a.name}" if f"{mod}.{a.name}" in MODULES else mod for a in node.names}
    return out


def test_the_front_ends_import_no_config_but_its_schema():
    """config.loader composes the front-ends' sections (frontends.factory.FrontendsConfig): a front-end
    module importing fgloc.config (its loader) would close an import cycle."""
    found = {}
    for name, path in MODULES.items():
        if not name.startswith("fgloc.frontends"):
            continue
        bad = sorted(m for m in _fgloc_imports(ast.parse(path.read_text(encoding="utf-8")), name)
                     if (m == "fgloc.config" or m.startswith("fgloc.config.")) and m != "fgloc.config.schema")
        if bad:
            found[name] = bad
    assert not found, found


#: The back-end contract's size rule: no module of the fusion's two rooms outgrows what a newcomer
#: can read in one sitting.
MAX_MODULE_LINES = 600


@pytest.mark.parametrize("room", ["backends", "localization"])
def test_no_module_in_the_fusion_rooms_is_over_600_lines(room):
    sizes = {
        str(p.relative_to(PACKAGE.parent)): len(p.read_text().splitlines())
        for p in sorted((PACKAGE / room).rglob("*.py"))
    }
    assert len(sizes) > 10, sizes
    too_long = {name: n for name, n in sizes.items() if n > MAX_MODULE_LINES}
    assert not too_long, f"split by responsibility: {too_long}"
