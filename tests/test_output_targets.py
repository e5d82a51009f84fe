"""Outputs through symbolic links and onto files that are not regular ones (issue 24).

Every output file is written by one function (``planner.export.files``): at the end of a symbolic link (or a chain of
them), which stays a link while its target gets the new contents, with the target's permissions; a dangling link
creates its target in the folder it names. A directory, a FIFO, a device (/dev/null), a socket, a loop of links, a
dangling link into a folder that does not exist are refused with one line naming the path and what it is, and
left as they were; an input is never replaced, by its name, through a link, or as a hard link of it. Checked
through every writer (CSV, JSON, URScript, saved job, plot, raw bytes, a simulator recording) and through
``planner plan -o`` / ``--plot`` on the command line, in-process and in a subprocess.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import socket
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from planner import PlannerError, PlanSettings, plan
from planner.export import (
    check_output,
    job_program,
    output_target,
    write_bytes_atomic,
    write_csv,
    write_json,
    write_script,
)
from planner.frontends.cli.main import main
from planner.io import read_toolpath
from tests.cam_excerpts import NX_HEAD

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "nx_first_pass.csv"
NX_PART = (0.4, 0.9965, -0.1, 0.0, 0.0, 0.0)
OLD = b"the link's target before the write\n"


@pytest.fixture(scope="module")
def job():
    tp = read_toolpath(io.StringIO(NX_HEAD), format="apt")
    return plan(tp, PlanSettings(path="cam", robot="ur5e", part_frame=NX_PART, rate=125.0))


def _umask_mode() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return 0o666 & ~mask


def _writers(job):
    """name -> (suffix, write(target)): every writer of output files."""
    from planner.plot import plot_job
    from sim.recording import Recorder

    def recording(target):
        Recorder(target).save()  # no samples: the header alone

    return {
        "csv": (".csv", lambda t: write_csv(job.trajectory(), t)),
        "json": (".json", lambda t: write_json(job.trajectory(), t)),
        "script": (".script", lambda t: write_script(job_program(job), t)),
        "job": (".job", job.save),
        "plot": (".png", lambda t: plot_job(job, t)),
        "bytes": (".bin", lambda t: write_bytes_atomic(t, b"\x00\x01 raw bytes\n")),
        "recording": (".npz", recording),
    }


def _snapshot(folder: Path) -> dict:
    """Every name in ``folder`` (recursively) with its type and, for a link, where it points."""
    out = {}
    for p in sorted(folder.rglob("*")):
        st = os.lstat(p)
        out[str(p.relative_to(folder))] = (stat.S_IFMT(st.st_mode), os.readlink(p) if p.is_symlink() else None)
    return out


def _device(folder: Path, suffix: str = ".csv") -> tuple[Path, str]:
    """A character device named null.csv (or another ``suffix``) in ``folder``: a null device made by mknod where
    permitted, else a link to /dev/null; and the words the refusal names it by."""
    node = folder / f"null{suffix}"
    try:
        os.mknod(node, 0o666 | stat.S_IFCHR, os.makedev(1, 3))
        return node, "is a character device"
    except OSError:
        os.symlink("/dev/null", node)
        return node, "a symbolic link to /dev/null, which is a character device"


# -- the Python writers ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("writer", ["csv", "json", "script", "job", "plot", "bytes", "recording"])
def test_every_writer_writes_through_a_link_and_keeps_it(job, writer, tmp_path):
    suffix, write = _writers(job)[writer]
    write(tmp_path / f"plain{suffix}")
    expected = (tmp_path / f"plain{suffix}").read_bytes()
    folder = tmp_path / "elsewhere"
    folder.mkdir()
    real = folder / f"real{suffix}"
    real.write_bytes(OLD)
    os.chmod(real, 0o640)
    link = tmp_path / f"out{suffix}"
    os.symlink(os.path.relpath(real, tmp_path), link)  # a relative link, resolved from the link's folder
    write(link)
    assert link.is_symlink() and os.readlink(link) == os.path.relpath(real, tmp_path)
    data = real.read_bytes()
    assert data != OLD and len(data) > 0
    if writer == "plot":  # (a picture's, a zip's bytes may differ run to run: metadata, times)
        assert data[:8] == b"\x89PNG\r\n\x1a\n"
    elif writer == "recording":
        from sim.recording import load

        assert data[:2] == b"PK" and load(real).t.size == load(tmp_path / f"plain{suffix}").t.size == 0
    else:
        assert data == expected
    assert stat.S_IMODE(real.stat().st_mode) == 0o640  # the target's permissions kept
    assert sorted(p.name for p in folder.iterdir()) == [real.name]  # no temporary file left
    assert sorted(p.name for p in tmp_path.iterdir()) == ["elsewhere", link.name, f"plain{suffix}"]


@pytest.mark.parametrize("writer", ["csv", "json", "script", "job", "plot", "bytes", "recording"])
def test_every_writer_refuses_a_fifo_and_a_device(job, writer, tmp_path):
    suffix, write = _writers(job)[writer]
    fifo = tmp_path / f"pipe{suffix}"
    os.mkfifo(fifo)
    dev, words = _device(tmp_path, suffix)
    to_dev = tmp_path / f"dev{suffix}"
    os.symlink(dev.name, to_dev)
    before = _snapshot(tmp_path)
    named = "(--plot )?" if writer == "plot" else ""  # (the plot's checks name the command line's option)
    refusals = {fifo: r"is a FIFO \(named pipe\), not a regular file; refusing to write to it",
                to_dev: r"a symbolic link to .*, which is a character device, not a regular file",
                dev: f"{words}, not a regular file"}
    for target, words in refusals.items():
        with pytest.raises(PlannerError, match=f"^{named}{re.escape(str(target))}: {words}"):
            write(target)
    assert _snapshot(tmp_path) == before  # the FIFO and the device are still there, nothing else is
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)


def _targets(tmp: Path) -> dict:
    """kind -> (the name written to, the file that must then hold the output, or None when it is refused)."""
    (tmp / "real.csv").write_bytes(OLD)
    (tmp / "sub").mkdir()
    (tmp / "real_in_sub.csv").symlink_to("sub/real.csv")
    (tmp / "sub" / "real.csv").write_bytes(OLD)
    t = {}
    os.symlink("real.csv", tmp / "link.csv")
    t["link"] = (tmp / "link.csv", tmp / "real.csv")
    os.symlink(tmp / "real.csv", tmp / "absolute.csv")
    t["absolute link"] = (tmp / "absolute.csv", tmp / "real.csv")
    os.symlink("link.csv", tmp / "chain2.csv")
    os.symlink("chain2.csv", tmp / "chain3.csv")
    t["chain of links"] = (tmp / "chain3.csv", tmp / "real.csv")
    t["link into a folder"] = (tmp / "real_in_sub.csv", tmp / "sub" / "real.csv")
    os.symlink("sub/new.csv", tmp / "dangling.csv")
    t["dangling link"] = (tmp / "dangling.csv", tmp / "sub" / "new.csv")
    os.symlink("dangling.csv", tmp / "dangling_chain.csv")
    t["chain to a dangling link"] = (tmp / "dangling_chain.csv", tmp / "sub" / "new.csv")
    os.symlink("sub", tmp / "subdir")
    t["through a linked folder"] = (tmp / "subdir" / "real.csv", tmp / "sub" / "real.csv")
    t["new file in new folders"] = (tmp / "made" / "deeper" / "new.csv", tmp / "made" / "deeper" / "new.csv")
    return t


def _refused(tmp: Path) -> dict:
    """kind -> (the name written to, words the one-line refusal must hold)."""
    t = {}
    os.symlink("missing/new.csv", tmp / "dangling_dir.csv")
    t["dangling link into a missing folder"] = (tmp / "dangling_dir.csv", "whose folder .*missing does not exist")
    os.symlink("loop_b.csv", tmp / "loop_a.csv")
    os.symlink("loop_a.csv", tmp / "loop_b.csv")
    t["loop of links"] = (tmp / "loop_a.csv", "a loop of symbolic links; refusing")
    os.symlink("self.csv", tmp / "self.csv")
    t["link to itself"] = (tmp / "self.csv", "a loop of symbolic links; refusing")
    os.mkfifo(tmp / "fifo.csv")
    t["fifo"] = (tmp / "fifo.csv", r"is a FIFO \(named pipe\), not a regular file")
    os.symlink("fifo.csv", tmp / "to_fifo.csv")
    t["link to a fifo"] = (tmp / "to_fifo.csv", r"a symbolic link to .*fifo.csv, which is a FIFO \(named pipe\)")
    dev, words = _device(tmp)
    t["device"] = (dev, words)
    os.symlink("/dev/null", tmp / "dev_null.csv")
    t["link to /dev/null"] = (tmp / "dev_null.csv", "a symbolic link to /dev/null, which is a character device")
    t["/dev/null"] = (Path("/dev/null"), "is a character device, not a regular file")
    (tmp / "dir.csv").mkdir()
    t["directory"] = (tmp / "dir.csv", "is a directory, not a regular file")
    os.symlink("dir.csv", tmp / "to_dir.csv")
    t["link to a directory"] = (tmp / "to_dir.csv", "a symbolic link to .*dir.csv, which is a directory")
    s = socket.socket(socket.AF_UNIX)
    with contextlib.closing(s):
        s.bind(str(tmp / "sock.csv"))
    t["socket"] = (tmp / "sock.csv", "is a socket, not a regular file")
    (tmp / "plain.txt").write_bytes(OLD)
    t["through a file"] = (tmp / "plain.txt" / "x.csv", "a part of the path before the file name is a file")
    os.symlink("nowhere", tmp / "deadfolder")
    t["in a dangling linked folder"] = (tmp / "deadfolder" / "x.csv",
                                        "its folder .*deadfolder is a symbolic link to .*nowhere, which does not exist")
    return t


TARGET_KINDS = ["link", "absolute link", "chain of links", "link into a folder", "dangling link",
                "chain to a dangling link", "through a linked folder", "new file in new folders"]
REFUSED_KINDS = ["dangling link into a missing folder", "loop of links", "link to itself", "fifo", "link to a fifo",
                 "device", "link to /dev/null", "/dev/null", "directory", "link to a directory", "socket",
                 "through a file", "in a dangling linked folder"]


@pytest.mark.parametrize("kind", TARGET_KINDS)
def test_the_output_lands_at_the_end_of_the_links(job, kind, tmp_path):
    write_csv(job.trajectory(), tmp_path / "plain.csv")
    expected = (tmp_path / "plain.csv").read_bytes()
    name, file = _targets(tmp_path)[kind]
    links = {p: os.readlink(p) for p in tmp_path.rglob("*") if p.is_symlink()}
    existed = file.exists()
    assert output_target(name).file == file.resolve()
    write_csv(job.trajectory(), name)
    assert file.read_bytes() == expected and not file.is_symlink()
    assert {p: os.readlink(p) for p in tmp_path.rglob("*") if p.is_symlink()} == links  # every link kept as it was
    assert stat.S_IMODE(file.stat().st_mode) == _umask_mode()  # an existing file's (0644 here) or a new one's
    assert not [p for p in tmp_path.rglob(".*.part")]  # no temporary file left
    assert existed or kind in ("dangling link", "chain to a dangling link", "new file in new folders")


@pytest.mark.parametrize("kind", REFUSED_KINDS)
def test_non_regular_targets_are_refused_by_name(job, kind, tmp_path):
    name, words = _refused(tmp_path)[kind]
    before = _snapshot(tmp_path)
    for attempt in (lambda: write_csv(job.trajectory(), name), lambda: output_target(name),
                    lambda: check_output(name, EXAMPLE)):
        with pytest.raises(PlannerError) as err:
            attempt()
        message = str(err.value)
        assert message.startswith(f"{name}: ") and "\n" not in message, message
        assert re.search(words, message), message
    assert _snapshot(tmp_path) == before  # left as it was: no file made, replaced, or left behind


def test_a_failed_write_through_a_link_leaves_its_target_and_no_temporary_file(job, tmp_path):
    (tmp_path / "store").mkdir()
    real = tmp_path / "store" / "real.json"
    real.write_bytes(OLD)
    link = tmp_path / "out.json"
    link.symlink_to(real)

    def fail(stage, done, total):
        if done > 10:
            raise RuntimeError("disk full")

    with pytest.raises(RuntimeError, match="disk full"):
        write_json(job.trajectory(), link, progress=fail)
    assert link.is_symlink() and real.read_bytes() == OLD
    assert [p.name for p in (tmp_path / "store").iterdir()] == ["real.json"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json", "store"]


def test_an_input_is_never_the_output_by_name_link_or_hard_link(tmp_path):
    src = tmp_path / "in.csv"
    src.write_bytes(EXAMPLE.read_bytes())
    (tmp_path / "other").mkdir()
    os.symlink("../in.csv", tmp_path / "other" / "up.csv")
    os.symlink(src, tmp_path / "abs.csv")
    os.symlink("abs.csv", tmp_path / "chain.csv")
    os.link(src, tmp_path / "other" / "hard.csv")
    os.symlink("other/hard.csv", tmp_path / "to_hard.csv")
    copy = tmp_path / "copy.csv"
    copy.write_bytes(src.read_bytes())  # the same bytes, another file: not an input
    cases = {
        src: "is the input file; refusing to overwrite it",
        tmp_path / "other" / ".." / "in.csv": "is the input file; refusing to overwrite it",
        tmp_path / "other" / "up.csv": r"is the input file; refusing to overwrite it \(a symbolic link to .*in.csv\)",
        tmp_path / "chain.csv": r"is the input file; refusing to overwrite it \(a symbolic link to .*in.csv\)",
        tmp_path / "other" / "hard.csv": r"is the input file; refusing to overwrite it \(a hard link of .*in.csv\)",
        tmp_path / "to_hard.csv": r"\(a symbolic link to .*hard.csv, a hard link of .*in.csv\)",
    }
    for target, words in cases.items():
        with pytest.raises(PlannerError, match=words):
            check_output(target, src)
        with pytest.raises(PlannerError, match=words):  # the input named through a link is the same input
            check_output(target, tmp_path / "abs.csv")
    assert check_output(copy, src) == copy
    assert check_output(tmp_path / "new.csv", src) == tmp_path / "new.csv"


# -- the command line ------------------------------------------------------------------------------------------


def _cli(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(argv)
    return rc, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def cli_plain(tmp_path_factory) -> bytes:
    """What ``planner plan in.csv -o plain.csv`` writes (the input's name is in the header: the same here)."""
    tmp = tmp_path_factory.mktemp("plain")
    (tmp / "in.csv").write_bytes(EXAMPLE.read_bytes())
    assert _cli(["plan", str(tmp / "in.csv"), "-o", str(tmp / "plain.csv")])[0] == 0
    return (tmp / "plain.csv").read_bytes()


@pytest.mark.parametrize("kind", ["link", "chain of links", "dangling link", "through a linked folder"])
def test_planner_plan_writes_through_links(cli_plain, kind, tmp_path):
    (tmp_path / "in.csv").write_bytes(EXAMPLE.read_bytes())
    name, file = _targets(tmp_path)[kind]
    links = {p: os.readlink(p) for p in tmp_path.rglob("*") if p.is_symlink()}
    rc, out, err = _cli(["plan", str(tmp_path / "in.csv"), "-o", str(name)])
    assert rc == 0 and err == "", err
    assert f"wrote     {name} (" in out
    assert file.read_bytes() == cli_plain
    assert {p: os.readlink(p) for p in tmp_path.rglob("*") if p.is_symlink()} == links


@pytest.mark.parametrize("kind", REFUSED_KINDS)
def test_planner_plan_refuses_non_regular_outputs_in_one_line_before_planning(kind, tmp_path):
    (tmp_path / "in.csv").write_bytes(EXAMPLE.read_bytes())
    name, words = _refused(tmp_path)[kind]
    before = _snapshot(tmp_path)
    rc, out, err = _cli(["plan", str(tmp_path / "in.csv"), "-o", str(name)])
    assert rc == 2 and out == "", out  # refused before reading or planning anything
    assert err.startswith(f"planner: error: -o {name}: ") and err.count("\n") == 1, err
    assert re.search(words, err), err
    assert _snapshot(tmp_path) == before


@pytest.mark.parametrize("how", ["name", "link", "hard link", "link to a hard link"])
@pytest.mark.parametrize("option", ["-o", "--plot"])
def test_planner_plan_never_writes_its_input(how, option, tmp_path):
    suffix = ".csv" if option == "-o" else ".png"
    src = tmp_path / f"in{suffix}"  # (a .png input for --plot: the reader refuses it, after the check)
    src.write_bytes(EXAMPLE.read_bytes())
    target = {"name": src, "link": tmp_path / f"l{suffix}", "hard link": tmp_path / f"h{suffix}",
              "link to a hard link": tmp_path / f"lh{suffix}"}[how]
    if how == "link":
        target.symlink_to(src.name)
    elif how in ("hard link", "link to a hard link"):
        os.link(src, tmp_path / f"h{suffix}")
        if how == "link to a hard link":
            target.symlink_to(f"h{suffix}")
    rc, out, err = _cli(["plan", str(src), option, str(target)])
    assert rc == 2 and out == "" and err.count("\n") == 1, err
    assert err.startswith(f"planner: error: {option} {target}: is the input file; refusing to overwrite it"), err
    assert src.read_bytes() == EXAMPLE.read_bytes()


def test_planner_plan_plot_refuses_a_fifo_and_writes_through_a_link(tmp_path):
    (tmp_path / "in.csv").write_bytes(EXAMPLE.read_bytes())
    os.mkfifo(tmp_path / "pipe.png")
    rc, out, err = _cli(["plan", str(tmp_path / "in.csv"), "--plot", str(tmp_path / "pipe.png")])
    assert rc == 2 and out == "" and err.count("\n") == 1, err
    assert err.startswith(f"planner: error: --plot {tmp_path / 'pipe.png'}: is a FIFO (named pipe)"), err
    (tmp_path / "pics").mkdir()
    (tmp_path / "pic.png").symlink_to("pics/job.png")
    rc, out, err = _cli(["plan", str(tmp_path / "in.csv"), "--plot", str(tmp_path / "pic.png")])
    assert rc == 0 and err == "", err
    assert (tmp_path / "pic.png").is_symlink() and (tmp_path / "pics" / "job.png").read_bytes()[:4] == b"\x89PNG"
    assert stat.S_ISFIFO(os.lstat(tmp_path / "pipe.png").st_mode)


@pytest.mark.parametrize("kind", ["fifo", "link to /dev/null", "loop of links"])
def test_through_a_subprocess_the_refusal_is_one_line_and_exit_2(kind, tmp_path):
    (tmp_path / "in.csv").write_bytes(EXAMPLE.read_bytes())
    name, words = _refused(tmp_path)[kind]
    p = subprocess.run([sys.executable, "-m", "planner.frontends.cli", "plan", "in.csv", "-o", name.name], cwd=tmp_path,
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 2 and p.stdout == "", p.stdout + p.stderr
    assert p.stderr.startswith(f"planner: error: -o {name.name}: ") and p.stderr.count("\n") == 1, p.stderr
    assert "Traceback" not in p.stderr and re.search(words, p.stderr)
