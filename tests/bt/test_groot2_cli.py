"""``bt-meta tick/run --groot2 [PORT] --hold --btlog FILE`` end to end, against BehaviorTree.CPP where it can run.

The live tests start ``bt-meta tick`` as a process serving on 127.0.0.1, ask it what Groot2 asks and compare with
BehaviorTree.CPP's ``Groot2Publisher`` for the same tree after the same ticks; ``--hold`` must end cleanly (exit 0,
no traceback) on SIGTERM and on Ctrl-C. Every wait is bounded.
"""

from __future__ import annotations

import os
import signal
import socket
import struct
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import behaviortreepy as btpy
import pytest
import zmq

from bt_meta.bt.groot2.btlog import read_btlog
from bt_meta.cli import main
from bt_meta.testing import free_groot2_port

TREE = """<root BTCPP_format="4" main_tree_to_execute="MainTree">
  <BehaviorTree ID="MainTree">
    <Sequence name="top">
      <SetBlackboard output_key="n" value="2"/>
      <Repeat num_cycles="{n}"><AlwaysSuccess/></Repeat>
      <SubTree ID="Part" n="{n}"/>
      <Fallback><AlwaysFailure/><Inverter><AlwaysFailure name="no"/></Inverter></Fallback>
    </Sequence>
  </BehaviorTree>
  <BehaviorTree ID="Part">
    <ReactiveSequence><SetBlackboard output_key="mine" value="hello"/><AlwaysSuccess name="done"/></ReactiveSequence>
  </BehaviorTree>
</root>
"""
TIMEOUT_MS = 3000



def request(context: zmq.Context, port: int, letter: str, *extra: bytes, attempts: int = 40) -> list[bytes]:
    """One Groot2 request, retried with a fresh socket until the server is up (at most ``attempts`` x 0.25 s)."""
    for _ in range(attempts):
        sock = context.socket(zmq.REQ)
        sock.setsockopt(zmq.LINGER, 0)
        sock.setsockopt(zmq.RCVTIMEO, 250)
        sock.setsockopt(zmq.SNDTIMEO, TIMEOUT_MS)
        sock.connect(f"tcp://127.0.0.1:{port}")
        try:
            sock.send_multipart([struct.pack("<BBI", 2, ord(letter), 42), *extra])
            return sock.recv_multipart()
        except zmq.Again:
            continue
        finally:
            sock.close(linger=0)
    raise AssertionError(f"no reply on port {port}")


def canonical(element: ET.Element) -> tuple:
    return element.tag, tuple(sorted(element.attrib.items())), tuple(canonical(child) for child in element)


def trees_of(text: bytes) -> list[tuple]:
    return [canonical(tree) for tree in ET.fromstring(text).findall("BehaviorTree")]


# Runs a command with SIGINT at its default disposition: a background job started by a non-interactive shell
# inherits SIGINT ignored (exec keeps it so, and Python then installs no Ctrl-C handler), and the test asserts what
# Ctrl-C does. An exec wrapper, not ``preexec_fn``: nothing runs between fork and exec, safe with zmq's threads.
DEFAULT_SIGINT = [sys.executable, "-c", "import os, signal, sys; signal.signal(signal.SIGINT, signal.SIG_DFL); "
                  "os.execvp(sys.argv[1], sys.argv[1:])"]


def start_tick(tree: Path, port: int, *extra: str) -> subprocess.Popen:
    command = [*DEFAULT_SIGINT, sys.executable, "-m", "bt_meta.cli", "tick", str(tree), "--world", "fake",
               "--ticks", "1", "--groot2", str(port), "--groot2-host", "127.0.0.1", "--hold", *extra]
    return subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def stop(process: subprocess.Popen, signum: int) -> tuple[int, str, str]:
    process.send_signal(signum)
    try:
        out, err = process.communicate(timeout=20)
    except subprocess.TimeoutExpired:
        process.kill()
        out, err = process.communicate(timeout=10)
        raise AssertionError(f"bt-meta did not stop on signal {signum}: {err}") from None
    return process.returncode, out, err


@pytest.fixture
def context():
    ctx = zmq.Context()
    yield ctx
    ctx.term()


@pytest.fixture
def tree_file(tmp_path: Path) -> Path:
    path = tmp_path / "tree.xml"
    path.write_text(TREE, encoding="utf-8")
    return path


@pytest.mark.slow
@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_tick_serves_what_btcpp_serves_and_holds_until_a_signal(
    signum: int, context: zmq.Context, tree_file: Path, tmp_path: Path
) -> None:
    port = free_groot2_port()
    log = tmp_path / "run.btlog"
    process = start_tick(tree_file, port, "--btlog", str(log))
    try:
        ours = {letter: request(context, port, letter, *extra)
                for letter, extra in (("T", ()), ("S", ()), ("B", (b"MainTree;Part::5",)))}
    finally:
        code, out, err = stop(process, signum)
    assert code == 0, err
    assert "Traceback" not in err and "serving the finished tree on port" in err
    assert "SUCCESS after 1 ticks" in out

    tree = btpy.BehaviorTreeFactory().create_tree_from_text(TREE)
    btcpp_port = free_groot2_port()
    publisher = btpy.Groot2Publisher(tree, btcpp_port)
    logger_path = tmp_path / "btcpp.btlog"
    logger = btpy.FileLogger(tree, str(logger_path))
    time.sleep(0.02)  # let BT.CPP 4.8.2's log writer thread start (it drops what comes before)
    assert tree.tick_once().name == "SUCCESS"  # bt-meta's tick is BT.CPP's tickOnce (re-ticks on wake-up)
    theirs = {letter: request(context, btcpp_port, letter, *extra)
              for letter, extra in (("T", ()), ("S", ()), ("B", (b"MainTree;Part::5",)))}
    time.sleep(0.1)
    theirs_log = read_btlog(logger_path)
    del logger, publisher

    for letter in "TSB":
        assert ours[letter][0][:6] == theirs[letter][0][:6]
    assert trees_of(ours["T"][1]) == trees_of(theirs["T"][1])
    assert ours["S"][1] == theirs["S"][1]  # uid + status of every node, IDLE_FROM_* included
    assert ours["B"][1] == theirs["B"][1]  # {"MainTree": {"n": 2}, "Part::5": {"mine": "hello"}} as MessagePack
    ours_log = read_btlog(log)
    assert [(t.uid, t.status) for t in ours_log.transitions] == [(t.uid, t.status) for t in theirs_log.transitions]
    assert trees_of(ours_log.tree_xml.encode()) == trees_of(theirs["T"][1])


def test_btlog_written_by_tick_without_a_server(tree_file: Path, tmp_path: Path, capsys) -> None:
    log = tmp_path / "only.btlog"
    assert main(["tick", str(tree_file), "--world", "fake", "--ticks", "2", "--btlog", str(log)]) == 0
    written = read_btlog(log)
    assert ET.fromstring(written.tree_xml).find("BehaviorTree").get("_fullpath") == ""
    assert written.transitions[0].uid == 1 and written.transitions[-1].uid == 1  # root RUNNING ... root IDLE
    assert len(written.transitions) > 10


@pytest.mark.parametrize("busy_offset", [0, 1])
def test_port_in_use_is_a_clear_error_naming_it_before_any_work(busy_offset: int, tree_file: Path, capsys) -> None:
    port = free_groot2_port()
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", port + busy_offset))
        busy.listen()
        code = main(["tick", str(tree_file), "--world", "fake", "--ticks", "1", "--groot2", str(port),
                     "--groot2-host", "127.0.0.1"])
    captured = capsys.readouterr()
    assert code == 2
    assert f"--groot2: Groot2 port {port + busy_offset} cannot be opened: already in use" in captured.err
    assert "Traceback" not in captured.err and captured.out == ""  # nothing ticked


def test_server_bind_failure_names_the_port(tree_file: Path) -> None:
    """Taken between the early probe and the bind: the server itself reports it the same way."""
    from bt_meta.bt.groot2.observer import StatusObserver
    from bt_meta.bt.groot2.published_tree import PublishedTree
    from bt_meta.bt.groot2.server import Groot2PortError, Groot2Server
    from bt_meta.bt.xml.reader import load_tree_text

    port = free_groot2_port()
    tree = PublishedTree.build(load_tree_text(TREE))
    with socket.socket() as busy, StatusObserver(tree) as observer:
        busy.bind(("127.0.0.1", port))
        busy.listen()
        with pytest.raises(Groot2PortError, match=f"Groot2 port {port} cannot be opened: already in use"):
            Groot2Server(tree, observer, port, host="127.0.0.1")


@pytest.mark.parametrize("port", ["0", "65535", "70000", "-3"])
def test_invalid_port_is_a_clear_error(port: str, tree_file: Path, capsys) -> None:
    code = main(["tick", str(tree_file), "--world", "fake", "--groot2", port])
    err = capsys.readouterr()
    assert code == 2
    assert f"Groot2 port {port} is invalid: expected 1..65534" in err.err
    assert "tick" not in err.out  # refused before any work


def test_port_that_is_not_a_number_is_refused_by_the_parser(tree_file: Path, capsys) -> None:
    with pytest.raises(SystemExit) as stopped:
        main(["tick", str(tree_file), "--groot2", "ninety"])
    assert stopped.value.code == 2
    assert "--groot2: invalid int value: 'ninety'" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("name", "message"),
    [
        ("missing/run.btlog", "cannot write the log: folder"),
        ("run.log", "a Groot2 log file must end in .btlog"),
        (".", "a Groot2 log file must end in .btlog"),
    ],
)
def test_unusable_btlog_path_is_refused_before_any_work(
    name: str, message: str, tree_file: Path, tmp_path: Path, capsys
) -> None:
    target = tmp_path / name
    code = main(["tick", str(tree_file), "--world", "fake", "--btlog", str(target)])
    captured = capsys.readouterr()
    assert code == 2
    assert message in captured.err and str(target) in captured.err
    assert captured.out == ""  # nothing ticked
    assert not target.is_file()


@pytest.mark.skipif(os.geteuid() == 0, reason="root can write anywhere")
def test_read_only_folder_is_refused(tree_file: Path, tmp_path: Path, capsys) -> None:
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o500)
    try:
        code = main(["tick", str(tree_file), "--world", "fake", "--btlog", str(folder / "x.btlog")])
    finally:
        folder.chmod(0o700)
    assert code == 2
    assert "permission denied" in capsys.readouterr().err


def test_hold_needs_a_server(tree_file: Path, capsys) -> None:
    assert main(["tick", str(tree_file), "--world", "fake", "--hold"]) == 2
    assert "--hold: --hold keeps the Groot2 server up: it needs --groot2" in capsys.readouterr().err


def test_run_refuses_a_btlog_with_repair(tmp_path: Path, capsys) -> None:
    code = main(["run", str(tmp_path / "tasks.yaml"), "--repair", "--btlog", str(tmp_path / "r.btlog")])
    assert code == 2
    assert "--repair: a .btlog file holds one tree; --repair replaces it as it repairs" in capsys.readouterr().err


def test_a_session_follows_a_run_that_replaces_its_tree(context: zmq.Context, tmp_path: Path) -> None:
    from bt_meta.bt.groot2.session import Groot2Session
    from bt_meta.bt.nodes.sequences import Sequence
    from bt_meta.bt.nodes.ticking import tick_once
    from bt_meta.bt.xml.reader import load_tree_text
    from bt_meta.errors import UserInputError

    first = load_tree_text(TREE)
    second = load_tree_text(TREE.replace('<AlwaysSuccess name="done"/>', '<AlwaysFailure name="done"/>'))
    port = free_groot2_port()
    session = Groot2Session.start(first, port=port, host="127.0.0.1")
    try:
        session.after_tick(tick_once(first))
        before = request(context, port, "T")
        session.follow(first)  # the same tree: nothing changes
        assert request(context, port, "T")[0] == before[0]
        session.follow(second)
        session.after_tick(tick_once(second))
        after = request(context, port, "T")
        assert after[0][:6] == before[0][:6] and after[0][6:] != before[0][6:]  # a new tree id: Groot2 refetches
        assert b'AlwaysFailure name="done"' in after[1] and b'AlwaysFailure name="done"' not in before[1]
        status = request(context, port, "S")[1]
        assert status[:3] == bytes([1, 0, 13])  # the new root: failed, then reset
        assert type(first) is Sequence and type(second) is not Sequence  # the first tree's classes are given back
    finally:
        session.close()
    logged = Groot2Session.start(first, btlog=tmp_path / "one.btlog")
    try:
        with pytest.raises(UserInputError, match=r"a \.btlog file holds one tree"):
            logged.follow(second)
    finally:
        logged.close()


@pytest.mark.slow
def test_run_with_repair_serves_the_segment_being_run(context: zmq.Context, tmp_path: Path) -> None:
    tasks = Path(__file__).resolve().parents[2] / "trees" / "letters.yaml"
    port = free_groot2_port()
    command = [sys.executable, "-m", "bt_meta.cli", "run", str(tasks), "--problem", "A", "--repair",
               "--memory", str(tmp_path / "m.sqlite"), "--groot2", str(port), "--groot2-host", "127.0.0.1", "--hold"]
    errors = tmp_path / "stderr.txt"
    with errors.open("w") as err_file:
        process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=err_file, text=True)
        try:
            full = request(context, port, "T", attempts=240)  # served while it runs (the simulator loads first)
            deadline = time.monotonic() + 120
            while "serving the finished tree" not in errors.read_text() and time.monotonic() < deadline:
                time.sleep(0.1)
            final = request(context, port, "S")
        finally:
            code, _out, _err = stop(process, signal.SIGTERM)
    assert code == 0, errors.read_text()
    root = ET.fromstring(full[1]).find("BehaviorTree")[0]
    assert root.get("name") == "plan A segment 1" and root.get("_uid") == "1"
    assert final[1][:3] == bytes([1, 0, 12])  # the segment's root succeeded and was reset


@pytest.mark.slow
def test_run_in_the_simulator_writes_a_btlog(tmp_path: Path, capsys) -> None:
    log = tmp_path / "A.btlog"
    tasks = Path(__file__).resolve().parents[2] / "trees" / "letters.yaml"
    assert main(["run", str(tasks), "--problem", "A", "--btlog", str(log)]) == 0
    written = read_btlog(log)
    places = [e for e in ET.fromstring(written.tree_xml).iter() if e.tag == "place"]
    assert len(places) == 6 and all(e.get("_uid") for e in places)  # blocks b0..b5
    place_uids = {int(e.get("_uid")) for e in places}
    succeeded = {t.uid for t in written.transitions if t.status == 2}
    assert place_uids <= succeeded  # every placement ran to SUCCESS
    assert (written.transitions[-1].uid, written.transitions[-1].status) == (1, 0)  # the root, reset after success
