"""The output-writing layer itself (fgloc.io.outputs), in-process: confinement, ownership,
staging and whole publication, links, inputs, the record of what fgloc wrote."""

from __future__ import annotations

import errno
import os
import socket
from pathlib import Path

import pytest

from fgloc.io import outputs as O
from fgloc.io.outputs import GuardedFile, OutputError, OutputFile, Outputs, confined, safe_name


def _tree(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (links as their target text), by relative path."""
    out = {}
    for p in sorted(folder.rglob("*")):
        rel = p.relative_to(folder).as_posix()
        if p.is_symlink():
            out[rel] = b"-> " + os.readlink(p).encode()
        elif p.is_file():
            out[rel] = p.read_bytes()
    return out


@pytest.mark.parametrize("text, want", [("...", "___"), ("..", "__"), (".", "_"), ("", "output"),
                                        ("../x", "___x"), ("/etc/passwd", "_etc_passwd"), (".hidden", "_hidden"),
                                        ("run 1", "run 1"), ("a.b", "a.b"), ("a\0b", "a_b")])
def test_safe_name_is_one_harmless_component(text, want):
    assert safe_name(text) == want
    assert "/" not in safe_name(text) and safe_name(text) not in (".", "..")


def test_confined_refuses_every_way_out(tmp_path):
    root = tmp_path / "out"
    root.mkdir()
    (tmp_path / "elsewhere").mkdir()
    (root / "link").symlink_to(tmp_path / "elsewhere")
    (root / "afile").write_text("x")
    for bad in ("..", "../x", "/abs/x", "", ".", "a/../../x", "a/./b", "link/x", "afile/x"):
        with pytest.raises(OutputError):
            confined(root, bad)
    with pytest.raises(OutputError):
        confined(root, "link", folder=True)
    assert confined(root, "a/b.tum") == root / "a" / "b.tum"
    assert confined(root, "link") == root / "link"  # a link as the file itself: replaced, never followed


def test_publish_whole_and_stale_files_go(tmp_path):
    out = tmp_path / "out"
    names = ("a.txt", "b.txt", "sub/c.txt")
    with Outputs(out, names, command="t") as o:
        for n in names:
            o.path(n).write_text(f"one {n}")
        assert not (out / "a.txt").exists()  # nothing in place before the end
    assert _tree(out).keys() == {".fgloc-outputs.json", "a.txt", "b.txt", "sub/c.txt"}
    with Outputs(out, names, command="t") as o:  # ours: replaced without force; b.txt not produced this time
        o.path("a.txt").write_text("two")
        o.path("sub/c.txt").write_text("two c")
    assert (out / "a.txt").read_text() == "two" and not (out / "b.txt").exists()
    assert (out / "sub" / "c.txt").read_text() == "two c"
    assert sorted(O.read_manifest(out)) == ["a.txt", "sub/c.txt"]
    assert not list(out.glob(".fgloc-staging-*"))


@pytest.mark.parametrize("exc", [RuntimeError("boom"), KeyboardInterrupt(), OSError(errno.ENOSPC, "No space left")])
def test_an_error_leaves_the_folder_as_it_was(tmp_path, exc):
    out = tmp_path / "out"
    with Outputs(out, ("a.txt", "b.txt"), command="t") as o:
        o.path("a.txt").write_text("old a")
        o.path("b.txt").write_text("old b")
    before = _tree(out)
    with pytest.raises((RuntimeError, KeyboardInterrupt, OutputError)) as info:
        with Outputs(out, ("a.txt", "b.txt"), command="t") as o:
            o.path("a.txt").write_text("new a")
            raise exc
    assert _tree(out) == before
    if isinstance(exc, OSError):
        assert str(info.value) == (f"{out}/a.txt: no space left; nothing was written to {out} "
                                   f"(what it held is unchanged)")
    fresh = tmp_path / "new" / "deeper"
    with pytest.raises((RuntimeError, KeyboardInterrupt, OutputError)):
        with Outputs(fresh, ("a.txt",), command="t") as o:
            o.path("a.txt").write_text("x")
            raise exc
    assert not (tmp_path / "new").exists()  # the folders it made for nothing are gone again


def test_foreign_files_need_force_and_inputs_never_go(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "a.txt").write_text("the user's")
    with pytest.raises(OutputError, match=r"holds a.txt, not written by fgloc t; pass --force"):
        Outputs(out, ("a.txt",), command="t").check()
    assert (out / "a.txt").read_text() == "the user's"
    with Outputs(out, ("a.txt",), command="t", force=True) as o:
        o.path("a.txt").write_text("ours")
    assert (out / "a.txt").read_text() == "ours"
    # an input under an output name: never, even with force (the same path, a hard link, a symlink)
    (out / "b.txt").write_text("input")
    os.link(out / "b.txt", tmp_path / "hard.txt")
    for given in (out / "b.txt", tmp_path / "hard.txt"):
        with pytest.raises(OutputError, match="is an input of this command"):
            Outputs(out, ("b.txt",), command="t", inputs=[given], force=True).check()
    assert (out / "b.txt").read_text() == "input"


def test_another_commands_files_are_not_ours(tmp_path):
    """`fgloc map sim/log.mcap -o sim` must not replace the map `fgloc simulate` wrote."""
    with Outputs(tmp_path, ("map.yaml",), command="simulate") as o:
        o.path("map.yaml").write_text("simulated")
    with pytest.raises(OutputError, match="holds map.yaml, not written by fgloc map"):
        Outputs(tmp_path, ("map.yaml",), command="map").check()
    Outputs(tmp_path, ("map.yaml",), command="map", shares=("simulate",)).check()
    (tmp_path / "map.yaml").write_text("edited by the user")  # ours no more once changed
    with pytest.raises(OutputError):
        Outputs(tmp_path, ("map.yaml",), command="simulate").check()


def test_a_link_at_an_output_name_is_replaced_never_written_through(tmp_path):
    target = tmp_path / "precious.txt"
    target.write_text("keep me")
    out = tmp_path / "out"
    out.mkdir()
    (out / "a.txt").symlink_to(target)
    with pytest.raises(OutputError, match=r"a.txt \(a symbolic link\)"):
        Outputs(out, ("a.txt",), command="t").check()
    with Outputs(out, ("a.txt",), command="t", force=True) as o:
        o.path("a.txt").write_text("new")
    assert target.read_text() == "keep me"
    assert not (out / "a.txt").is_symlink() and (out / "a.txt").read_text() == "new"
    # a linked folder inside the output folder is refused, even with force
    (tmp_path / "ext").mkdir()
    (out / "sub").symlink_to(tmp_path / "ext")
    with pytest.raises(OutputError, match="symbolic link"), Outputs(out, ("sub/x.txt",), command="t", force=True):
        pass
    assert not list((tmp_path / "ext").iterdir())


def test_staging_left_by_a_killed_process_is_removed(tmp_path):
    host = O.host_tag()
    dead = tmp_path / f"{O.STAGING}{host}.{2**22 + 12345}.ab"  # no such pid (above pid_max's default)
    alive = tmp_path / f"{O.STAGING}{host}.{os.getppid()}.cd"
    other = tmp_path / f"{O.STAGING}another-host.1.ef"
    for d in (dead, alive, other):
        d.mkdir()
        (d / "x").write_text("partial")
    with Outputs(tmp_path, ("a.txt",), command="t") as o:
        o.path("a.txt").write_text("x")
    assert not dead.exists() and alive.exists() and other.exists()
    assert socket.gethostname()


def test_a_cut_publish_keeps_the_files_ours(tmp_path, monkeypatch):
    """A publish that fails half-way (here: the second rename, EIO) says so in one line, and the
    next run replaces the mixed files without --force (the record knows old and new contents)."""
    names = ("a.txt", "b.txt")
    with Outputs(tmp_path, names, command="t") as o:
        for n in names:
            o.path(n).write_text(f"old {n}")
    real = os.replace
    calls = []

    def flaky(src, dst):
        calls.append(dst)
        if len(calls) == 3:  # the record, a.txt, then b.txt fails
            raise OSError(errno.EIO, "Input/output error")
        return real(src, dst)

    monkeypatch.setattr(O.os, "replace", flaky)
    with pytest.raises(OutputError, match=r"b.txt: input/output error"):
        with Outputs(tmp_path, names, command="t") as o:
            for n in names:
                o.path(n).write_text(f"new {n}")
    monkeypatch.setattr(O.os, "replace", real)
    assert (tmp_path / "a.txt").read_text() == "new a.txt" and (tmp_path / "b.txt").read_text() == "old b.txt"
    Outputs(tmp_path, names, command="t").check()  # both still ours
    assert not list(tmp_path.glob(".fgloc-staging-*"))


def test_output_file_partial_and_ownership(tmp_path):
    f = tmp_path / "rec.mcap"
    with OutputFile(f, command="x") as o:
        assert o.path == tmp_path / "rec.mcap.partial"
        o.path.write_bytes(b"1")
        assert not f.exists()
    assert f.read_bytes() == b"1" and not o.path.exists()
    with pytest.raises(OutputError, match="exists; pass --force"):
        OutputFile(f, command="x").check()
    with OutputFile(f, command="x", ours=lambda p: p.read_bytes() == b"1") as o:
        o.path.write_bytes(b"2")
    assert f.read_bytes() == b"2"
    with pytest.raises(OutputError, match="is the input"):
        OutputFile(f, command="x", inputs=[f], force=True).check()
    # a recording: what a failed session wrote stays as .partial, and is refused (not erased) next time
    g = tmp_path / "live.mcap"
    with pytest.raises(OutputError), OutputFile(g, command="live", precious=True) as o:
        o.path.write_bytes(b"m" * 10_000)
        raise OSError(errno.ENOSPC, "No space left on device")
    assert (tmp_path / "live.mcap.partial").stat().st_size == 10_000 and not g.exists()
    with pytest.raises(OutputError, match="live.mcap.partial: what an earlier fgloc live left"):
        OutputFile(g, command="live", precious=True).check()
    OutputFile(g, command="live", precious=True, force=True).check()
    (tmp_path / "live.mcap.partial").write_bytes(b"hdr")  # a header only: nothing to keep
    OutputFile(g, command="live", precious=True).check()


def test_guarded_file_on_a_real_full_device(tmp_path):
    """/dev/full answers every write with ENOSPC: the first error is reported once, later writes
    are dropped (the file stays a readable prefix), nothing raises."""
    if not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full on this system (Linux has it)")
    seen: list[OSError] = []
    with open("/dev/full", "wb", buffering=0) as raw:
        g = GuardedFile(raw, on_error=seen.append)
        assert g.write(b"x" * 100) == 100
        assert g.write(b"y") == 1
        g.flush()
        g.close()
    assert len(seen) == 1 and seen[0].errno == errno.ENOSPC and g.error is seen[0]


def test_write_text_output(tmp_path):
    p = tmp_path / "c.yaml"
    O.write_text_output(p, "a: 1\n", what="config", command="config")
    with pytest.raises(OutputError, match="exists; pass --force"):
        O.write_text_output(p, "a: 2\n", what="config", command="config")
    O.write_text_output(p, "a: 2\n", force=True, what="config", command="config")
    assert p.read_text() == "a: 2\n" and not (tmp_path / "c.yaml.partial").exists()
