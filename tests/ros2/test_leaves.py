"""ROS leaves in tree XML (BehaviorTree.ROS2's action, service, topic-subscriber and topic-publisher nodes): each
kind ticks against a real peer process (tests/ros2/servers/leaf_peer.py, in a loopback-only network namespace), a
halted action cancels its goal, an unreachable server fails after ``server_timeout`` naming it, a bad registration
is a located error (exit 2), and a tree goes through the XML writer with the same ports."""

from __future__ import annotations

import json
import os
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from .conftest import default_sigint, stop_process

ROOT = Path(__file__).resolve().parents[2]
PYTHON = sys.executable
BT_META = [PYTHON, "-m", "bt_meta.cli"]
PEER = ROOT / "tests" / "ros2" / "servers" / "leaf_peer.py"

LEAVES = """\
ros2_leaves:
  - ID: CloseGripper
    kind: action
    type: control_msgs/action/GripperCommand
    action_name: /gripper/gripper_cmd
    server_timeout: 20000
    inputs:
      position: command.position
      max_effort: {field: command.max_effort, default: 10.0}
    outputs:
      reached: reached_goal
      final_position: position
    success_if: reached
  - ID: ActivateCamera
    kind: service
    type: lifecycle_msgs/srv/ChangeState
    service_name: /camera/change_state
    server_timeout: 20000
    inputs:
      transition: {field: transition.id, default: 3}
    outputs:
      ok: success
    success_if: ok
  - ID: IsDoorOpen
    kind: topic_sub
    type: std_msgs/msg/Bool
    topic_name: /door_open
    outputs:
      open: data
    success_if: open
  - ID: SendBeacon
    kind: topic_pub
    type: std_msgs/msg/String
    topic_name: /beacon
    inputs:
      text: data
"""

EVERY_KIND = """\
<root BTCPP_format="4" main_tree_to_execute="Main">
  <BehaviorTree ID="Main">
    <Sequence>
      <ActivateCamera/>
      <Inverter><ActivateCamera transition="1"/></Inverter>
      <RetryUntilSuccessful num_attempts="500">
        <Sequence><Sleep msec="20"/><IsDoorOpen open="{door}"/></Sequence>
      </RetryUntilSuccessful>
      <ScriptCondition code="door == true"/>
      <CloseGripper position="0.02" reached="{reached}" final_position="{pos}"/>
      <ScriptCondition code="pos &gt; 0.019 &amp;&amp; pos &lt; 0.021"/>
      <Fallback><CloseGripper position="-1"/><AlwaysSuccess/></Fallback>
      <Repeat num_cycles="20"><Sequence><Sleep msec="50"/><SendBeacon text="hello"/></Sequence></Repeat>
      <ForceSuccess><Timeout msec="1500"><CloseGripper position="0.03" max_effort="6000"/></Timeout></ForceSuccess>
    </Sequence>
  </BehaviorTree>
</root>
"""


def _environment(domain: int) -> dict[str, str]:
    env = dict(os.environ)
    env.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", PYTHONUNBUFFERED="1",
               PYTHONPATH=os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH")) if p))
    env.pop("ROS_STATIC_PEERS", None)
    return env


class Peer:
    """leaf_peer.py in a fresh loopback-only namespace; ``tick(...)`` runs ``bt-meta tick`` in the same one."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.env = _environment(30 + os.getpid() % 60)  # its own namespace: any valid domain is private
        self.log = folder / "peer.log"
        script = f"ip link set lo up && exec {shlex.quote(PYTHON)} {shlex.quote(str(PEER))}"
        self.process = subprocess.Popen(["unshare", "-n", "sh", "-c", script], cwd=ROOT, env=self.env,
                                        stdout=open(self.log, "w"), stderr=subprocess.STDOUT)  # noqa: SIM115
        deadline = time.monotonic() + 240  # the first start generates control_msgs (about a minute)
        while "ready" not in self.log.read_text():
            if self.process.poll() is not None or time.monotonic() > deadline:
                self.stop()
                raise AssertionError(f"the peer did not start: {self.log.read_text()[-2000:]}")
            time.sleep(0.1)
        (folder / "leaves.yaml").write_text(LEAVES)

    def run(self, *command: str, timeout: float = 120) -> subprocess.CompletedProcess:
        return subprocess.run(["nsenter", f"--net=/proc/{self.process.pid}/ns/net", *command], cwd=ROOT,
                              env=self.env, capture_output=True, text=True, timeout=timeout, check=False)

    def tick(self, tree: str, *args: str) -> subprocess.CompletedProcess:
        path = self.folder / f"tree{len(list(self.folder.glob('tree*.xml')))}.xml"
        path.write_text(tree)
        return self.run(*BT_META, "tick", str(path), "--ros2-leaves", str(self.folder / "leaves.yaml"),
                        "--ticks", "3000", "--json", *args)

    def start(self, tree: str) -> subprocess.Popen:
        path = self.folder / f"tree{len(list(self.folder.glob('tree*.xml')))}.xml"
        path.write_text(tree)
        return subprocess.Popen(["nsenter", f"--net=/proc/{self.process.pid}/ns/net", *BT_META, "tick", str(path),
                                 "--ros2-leaves", str(self.folder / "leaves.yaml"), "--ticks", "100000"], cwd=ROOT,
                                env=self.env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                preexec_fn=default_sigint)

    def wait_for(self, text: str, timeout: float = 20.0, count: int = 1) -> bool:
        deadline = time.monotonic() + timeout
        while self.log.read_text().splitlines().count(text) < count:
            if time.monotonic() > deadline:
                return False
            time.sleep(0.1)
        return True

    def stop(self) -> None:
        stop_process(self.process)


@pytest.fixture(scope="module")
def peer(tmp_path_factory):
    started = Peer(tmp_path_factory.mktemp("leaf_peer"))
    yield started
    started.stop()


def _failures(done: subprocess.CompletedProcess) -> list[dict]:
    return json.loads(done.stdout)["failures"]


# every test that starts ROS processes also names loopback_only: conftest skips it, with the reason, without the
# [ros2] extra or the right to make a network namespace


@pytest.fixture(scope="module")
def every_kind(peer):
    """One run of EVERY_KIND (``bt-meta tick --json``), shared by the tests that read it."""
    started = time.monotonic()
    done = peer.tick(EVERY_KIND)
    return done, time.monotonic() - started


@pytest.mark.slow
def test_every_kind_ticks_against_a_real_peer(peer, every_kind, loopback_only):
    done, _elapsed = every_kind
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(done.stdout)
    assert result["status"] == "SUCCESS"
    log = peer.log.read_text().splitlines()
    assert "change_state 3" in log and "change_state 1" in log  # the default and the XML's request
    assert "goal 0.02 10.0" in log and "succeeded" in log and "aborted" in log
    assert "beacon hello" in log
    # the service's response refused by success_if, and the aborted goal, are failures saying so
    errors = {failure["action"]: failure["evidence"]["error"] for failure in result["failures"]}
    assert errors == {"ActivateCamera": "RESULT_REFUSED", "CloseGripper": "ACTION_ABORTED"}
    shown = {name for tick in result["ticks"] for name in tick["nodes"]}
    assert {"ActivateCamera", "IsDoorOpen", "CloseGripper", "SendBeacon"} <= shown


@pytest.mark.slow
def test_a_halted_action_cancels_its_goal(peer, every_kind, loopback_only):
    done, elapsed = every_kind  # its last goal would run 60 s: the Timeout halts it after 1.5 s
    assert done.returncode == 0 and elapsed < 40, done.stderr[-3000:]
    assert peer.wait_for("goal 0.03 6000.0") and peer.wait_for("canceled"), peer.log.read_text()[-2000:]
    # Ctrl-C while a goal runs: the goal is cancelled as the process ends (exit 130)
    run = peer.start(STILL_RUNNING)
    try:
        assert peer.wait_for("goal 0.04 6000.0", timeout=60), peer.log.read_text()[-2000:]
        run.send_signal(signal.SIGINT)
        _out, err = run.communicate(timeout=30)
    finally:
        run.kill()
    assert run.returncode == 130, err[-3000:]
    assert peer.wait_for("canceled", count=2), peer.log.read_text()[-2000:]


STILL_RUNNING = """\
<root BTCPP_format="4" main_tree_to_execute="Main">
  <BehaviorTree ID="Main">
    <Sequence><CloseGripper position="0.01"/><CloseGripper position="0.04" max_effort="6000"/></Sequence>
  </BehaviorTree>
</root>
"""


UNREACHABLE = """\
<root BTCPP_format="4" main_tree_to_execute="Main">
  <BehaviorTree ID="Main">
    <Sequence>
      <ForceSuccess><ActivateCamera service_name="/nobody/change_state" server_timeout="1500"/></ForceSuccess>
      <CloseGripper action_name="/nobody/gripper_cmd" position="0.0" server_timeout="1500"/>
    </Sequence>
  </BehaviorTree>
</root>
"""


@pytest.mark.slow
def test_an_unreachable_server_fails_after_server_timeout_naming_it(peer, loopback_only):
    started = time.monotonic()
    done = peer.tick(UNREACHABLE)
    assert done.returncode == 1, done.stderr[-3000:]
    assert time.monotonic() - started >= 3.0  # two leaves, 1.5 s each
    messages = [failure["message"] for failure in _failures(done)]
    assert messages == [
        "ActivateCamera: no service /nobody/change_state (lifecycle_msgs/srv/ChangeState) within server_timeout "
        "1500 ms",
        "CloseGripper: no action server /nobody/gripper_cmd (control_msgs/action/GripperCommand) within "
        "server_timeout 1500 ms"]


ROUND_TRIP = """
import sys
from bt_meta.bt.domain_nodes import domain_registry
from bt_meta.bt.xml import load_tree_text, tree_to_xml
from bt_meta.bt.xml.document import parse_text
from bt_meta.bt.xml.reader import resolve_document
from bt_meta.ros2.leaves import load_leaves_file
from bt_meta.ros2.leaves.runtime import close_runtime

registry = domain_registry(None)
for node_type in load_leaves_file(sys.argv[1]):
    registry.register(node_type)
written = tree_to_xml(load_tree_text(open(sys.argv[2]).read(), registry, path=sys.argv[2]), registry=registry)
close_runtime()
print(written)
"""


@pytest.mark.slow
def test_a_tree_with_ros_leaves_goes_through_the_xml_writer_with_the_same_ports(peer, loopback_only, tmp_path,
                                                                               capsys):
    from bt_meta.cli import main

    tree = tmp_path / "tree.xml"
    tree.write_text(EVERY_KIND)
    leaves = str(peer.folder / "leaves.yaml")
    done = peer.run(PYTHON, "-c", ROUND_TRIP, leaves, str(tree))  # building the leaves opens a ROS node
    assert done.returncode == 0, done.stderr[-3000:]
    written = tmp_path / "written.xml"
    written.write_text(done.stdout)
    assert '<CloseGripper position="0.02" reached="{reached}" final_position="{pos}" />' in done.stdout
    assert '<ActivateCamera transition="1" />' in done.stdout
    # the model declares BT.ROS2's ports with the registered defaults: the file shows without the registration
    assert '<input_port name="action_name" type="std::string" default="/gripper/gripper_cmd">' in done.stdout
    assert '<input_port name="server_timeout" type="unsigned" default="20000">' in done.stdout
    assert '<output_port name="final_position" type="double">position</output_port>' in done.stdout
    assert main(["show", str(written)]) == 0
    shown = capsys.readouterr().out
    assert main(["show", str(tree), "--ros2-leaves", leaves]) == 0
    original = capsys.readouterr().out
    assert shown.splitlines()[1:] == original.splitlines()[1:]  # the same nodes with the same ports


BAD = [
    ("kind: action\n    type: std_msgs/msg/Bool\n", "4:11", "a action leaf needs a action type"),
    ("kind: topic_sub\n    type: std_msgs/msg/Boolean\n", "4:11", "std_msgs/msg has: Bool, Byte"),
    ("kind: topic_sub\n    type: no_such_msgs/msg/Bool\n", "4:11", "no installed package 'no_such_msgs'"),
    ("kind: topic_pub\n    type: std_msgs/msg/Bool\n    inputs: {value: datum}\n", "5:21",
     "Bool has no field 'datum' (in 'datum'); fields of std_msgs/Bool: data"),
    ("kind: service\n    type: lifecycle_msgs/srv/ChangeState\n    inputs: {t: transition}\n", "5:17",
     "field transition is a whole message (lifecycle_msgs/Transition); map one of its fields: transition.id"),
    ("kind: service\n    type: lifecycle_msgs/srv/ChangeState\n    inputs:\n      t: {field: transition.id, "
     "default: seven}\n", "6:42", "default of input 't': 'seven' is no unsigned (transition.id is a uint8)"),
    ("kind: topic_sub\n    type: std_msgs/msg/Bool\n    outputs: {open: data}\n    success_if: closed\n",
     "6:17", "success_if reads 'closed', which is no output port (outputs: open)"),
    ("kind: topic_sub\n    type: std_msgs/msg/Bool\n    inputs: {value: data}\n", "5:13",
     "a topic_sub leaf has no input fields"),
    ("kind: topic\n    type: std_msgs/msg/Bool\n", "3:11", "kind 'topic' is not one of action, service"),
    ("kind: topic_sub\n    type: std_msgs/msg/Bool\n    server_timeout: 5\n", "5:21",
     "server_timeout applies to action and service leaves"),
    ("kind: topic_sub\n    type: std_msgs/msg/Bool\n    topic: /x\n", "5:5", "unknown key 'topic'"),
]


@pytest.mark.parametrize(("body", "where", "message"), BAD)
def test_a_bad_registration_is_an_error_at_path_line_column(tmp_path, body, where, message):
    pytest.importorskip("std_msgs.msg", reason="needs the [ros2] extra: pip install 'bt-meta[ros2]'")
    from bt_meta.errors import ConfigError
    from bt_meta.ros2.leaves.registration import leaves_from_text

    path = tmp_path / "leaves.yaml"
    with pytest.raises(ConfigError) as caught:
        leaves_from_text(f"ros2_leaves:\n  - ID: Leaf\n    {body}", path)
    assert caught.value.location_message().startswith(f"{path}:{where}: "), caught.value.location_message()
    assert message in str(caught.value)


def test_an_id_of_a_built_in_node_or_a_stray_key_is_refused(tmp_path):
    pytest.importorskip("std_msgs.msg", reason="needs the [ros2] extra: pip install 'bt-meta[ros2]'")
    from bt_meta.errors import ConfigError
    from bt_meta.ros2.leaves.registration import leaves_from_text

    path = tmp_path / "leaves.yaml"
    with pytest.raises(ConfigError, match=r"ID 'Sequence' is a BehaviorTree\.CPP built-in node") as caught:
        leaves_from_text("ros2_leaves:\n  - ID: Sequence\n    kind: topic_sub\n    type: std_msgs/msg/Bool\n",
                         path)
    assert caught.value.location_message().startswith(f"{path}:2:9: ")
    with pytest.raises(ConfigError, match="unknown key 'ros2_leafs'"):
        leaves_from_text("ros2_leafs: []\n", path)


def test_a_bad_registration_exits_2_naming_the_line(tmp_path, capsys):
    pytest.importorskip("std_msgs.msg", reason="needs the [ros2] extra: pip install 'bt-meta[ros2]'")
    from bt_meta.cli import main

    leaves = tmp_path / "leaves.yaml"
    leaves.write_text("ros2_leaves:\n  - ID: IsDoorOpen\n    kind: topic_sub\n    type: std_msgs/msg/Bool\n"
                      "    outputs: {open: data.value}\n")
    tree = tmp_path / "tree.xml"
    tree.write_text('<root BTCPP_format="4"><BehaviorTree ID="M"><IsDoorOpen/></BehaviorTree></root>')
    for command in (["show", str(tree)], ["tick", str(tree)]):
        assert main([*command, "--ros2-leaves", str(leaves)]) == 2
        assert f"{leaves}:5:21: IsDoorOpen: field data is a boolean, it has no field 'value'" in \
            capsys.readouterr().err


def test_a_name_that_is_no_ros_name_in_the_xml_is_located_before_ticking(tmp_path, capsys):
    pytest.importorskip("std_msgs.msg", reason="needs the [ros2] extra: pip install 'bt-meta[ros2]'")
    from bt_meta.bt import python_nodes
    from bt_meta.cli import main

    leaves = tmp_path / "leaves.yaml"
    leaves.write_text("ros2_leaves:\n  - ID: IsDoorOpen\n    kind: topic_sub\n    type: std_msgs/msg/Bool\n")
    tree = tmp_path / "tree.xml"
    tree.write_text('<root BTCPP_format="4">\n<BehaviorTree ID="M">\n  <IsDoorOpen topic_name="door open"/>\n'
                    '</BehaviorTree></root>')
    try:
        assert main(["tick", str(tree), "--ros2-leaves", str(leaves)]) == 2
    finally:
        python_nodes._REGISTERED.pop("IsDoorOpen", None)
    assert f"{tree}:3:3: cannot build node 'IsDoorOpen': topic_name 'door open' is not a valid ROS 2 name" in \
        capsys.readouterr().err


def test_python_registration_declares_the_same_leaf(monkeypatch):
    pytest.importorskip("std_msgs.msg", reason="needs the [ros2] extra: pip install 'bt-meta[ros2]'")
    from bt_meta.bt import python_nodes
    from bt_meta.bt.domain_nodes import domain_registry
    from bt_meta.errors import ConfigError
    from bt_meta.ros2.leaves import ros_leaf

    monkeypatch.setattr(python_nodes, "_REGISTERED", {})
    made = ros_leaf("SetLabels", "topic_pub", "sensor_msgs/msg/JointState", name="/labels",
                    inputs={"names": "name", "positions": {"field": "position", "default": [0.5, 1]}})
    assert made.category == "Condition"  # BT.ROS2's RosTopicPubNode is a condition
    ports = {port.name: (port.direction, port.type_name, port.default) for port in made.ports}
    assert ports == {"topic_name": ("input", "std::string", "/labels"),
                     "names": ("input", "std::vector<std::string>", None),
                     "positions": ("input", "std::vector<double>", "0.5;1")}
    assert "SetLabels" in domain_registry(None)
    with pytest.raises(ConfigError, match="JointState has no field 'names'"):
        ros_leaf("Bad", "topic_pub", "sensor_msgs/msg/JointState", inputs={"names": "names"})
