"""The camera through ROS 2: the served simulator's top view (rgb8 + 32FC1 depth + CameraInfo) is what the ROS 2
world's perception looks through -- decoded equal to the in-process render of the same scene, recorded in the MCAP
file when used, and a clear error naming the topic when no frame comes."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from bt_meta.ros2.camera_subscriber import decode_image

ROOT = Path(__file__).resolve().parents[2]
LETTERS = "trees/letters.yaml"
START = ("--joint", "left_s0=0.8")  # the letters grounding's robot_pose for the Baxter

# In the served simulator's namespace: the ROS 2 world's frame and the in-process render of its model (the same
# scene, synced to the state the robot reported, before any motion).
_COMPARE = """
import json, sys
import numpy as np
from bt_meta.htn import load_task_file
from bt_meta.resources import trees_dir
from bt_meta.ros2.world import bt_meta_make_world
from bt_meta.world.simulation.camera import TopViewCamera

task = load_task_file(trees_dir() / "letters.yaml")
world = bt_meta_make_world("ros2", task.domain, task.problem("A"), {"task_file": str(trees_dir() / "letters.yaml")})
try:
    ros = world.top_camera.capture(depth=True, segmentation=False)
    local = TopViewCamera(world.sim).capture(depth=True, segmentation=False)
    rgb = np.abs(ros.rgb.astype(int) - local.rgb.astype(int))
    print(json.dumps({"shape": list(ros.rgb.shape), "rgb_max": int(rgb.max()),
                      "rgb_differing": float((rgb.max(axis=2) > 0).mean()),
                      "depth_max": float(np.nanmax(np.abs(ros.depth - local.depth))),
                      "k": ros.intrinsics.matrix().tolist(), "k_local": local.intrinsics.matrix().tolist(),
                      "pose": bool(np.allclose(ros.pose, local.pose))}))
finally:
    world.close()
"""


def _message(encoding: str, array: np.ndarray, pad: int = 0, bigendian: bool = False) -> SimpleNamespace:
    height, width = array.shape[:2]
    raw = array.astype(array.dtype.newbyteorder(">" if bigendian else "<")).reshape(height, -1).view(np.uint8)
    rows = np.concatenate([raw, np.zeros((height, pad), np.uint8)], axis=1)
    return SimpleNamespace(height=height, width=width, step=rows.shape[1], encoding=encoding,
                           is_bigendian=int(bigendian), data=rows.tobytes())


def test_images_decode_by_encoding_step_and_byte_order():
    rgb = np.random.default_rng(0).integers(0, 256, (4, 5, 3), dtype=np.uint8)
    assert np.array_equal(decode_image(_message("rgb8", rgb, pad=3)), rgb)  # rows padded past width * 3
    assert np.array_equal(decode_image(_message("bgr8", rgb[:, :, ::-1].copy())), rgb)
    rgba = np.concatenate([rgb, np.full((4, 5, 1), 255, np.uint8)], axis=2)
    assert np.array_equal(decode_image(_message("rgba8", rgba)), rgb)
    depth = np.linspace(0.5, 1.5, 20, dtype=np.float32).reshape(4, 5)
    assert np.array_equal(decode_image(_message("32FC1", depth, pad=4, bigendian=True)), depth)
    millimetres = np.array([[0, 1000], [1500, 2]], dtype=np.uint16)
    decoded = decode_image(_message("16UC1", millimetres))
    assert np.isnan(decoded[0, 0]) and np.allclose(decoded.ravel()[1:], [1.0, 1.5, 0.002])
    with pytest.raises(ValueError, match="unsupported image encoding 'yuv422'"):
        decode_image(_message("yuv422", rgb))
    with pytest.raises(ValueError, match="carries 60 bytes"):
        decode_image(SimpleNamespace(height=5, width=5, step=15, encoding="rgb8", is_bigendian=0, data=bytes(60)))


@pytest.mark.slow
def test_a_served_frame_decodes_as_the_in_process_render(serve):
    served = serve("--scene", "letters_A", *START)
    done = subprocess.run(["nsenter", f"--net=/proc/{served.process.pid}/ns/net", sys.executable, "-c", _COMPARE],
                          cwd=ROOT, env=served.env, capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert result["shape"] == [240, 320, 3]
    assert result["k"] == result["k_local"] and result["pose"]
    assert result["rgb_max"] == 0 and result["depth_max"] < 1e-6  # rgb8 and 32FC1 carry the render exactly


@pytest.mark.slow
def test_a_run_perceives_through_the_ros2_camera_and_records_its_frames(serve, tmp_path):
    """The camera perception plugin looks through the topics (its frames are in the MCAP file), and the run ends as
    the in-process one."""
    pytest.importorskip("mcap_ros2", reason="needs mcap-ros2-support (the [ros2] extra)")
    from mcap_ros2.reader import read_ros2_messages

    path = tmp_path / "run.mcap"
    served = serve("--scene", "letters_A", *START)
    done = served.run("run", LETTERS, "--problem", "A", "--world", "ros2", "--record-mcap", str(path), "--json")
    assert done.returncode == 0, done.stderr[-2000:]
    ros = json.loads(done.stdout)
    local = json.loads(subprocess.run([sys.executable, "-m", "bt_meta.cli", "run", LETTERS, "--problem", "A",
                                       "--json"], cwd=ROOT, capture_output=True, text=True, check=True).stdout)
    assert ros["status"] == local["status"] == "SUCCESS" and ros["plan"] == local["plan"]
    assert [f["kind"] for f in ros["failures"]] == [f["kind"] for f in local["failures"]]
    frames: dict[str, list] = {"/bt_meta/camera/image_raw": [], "/bt_meta/camera/depth/image_raw": [],
                               "/bt_meta/camera/camera_info": []}
    for message in read_ros2_messages(str(path)):
        if message.channel.topic in frames:
            frames[message.channel.topic].append(message.ros_msg)
    images = frames["/bt_meta/camera/image_raw"]
    assert len(images) == len(frames["/bt_meta/camera/depth/image_raw"]) == len(frames["/bt_meta/camera/camera_info"])
    assert len(images) >= len(ros["plan"])  # one frame after every successful primitive at least
    stamps = [(m.header.stamp.sec, m.header.stamp.nanosec) for m in images]
    assert stamps == sorted(set(stamps))  # each frame once, each newer than the last
    assert decode_image(images[-1]).shape == (240, 320, 3)


@pytest.mark.slow
def test_no_camera_frame_is_an_error_naming_the_topic(serve, tmp_path):
    config = tmp_path / "ros2.yaml"
    config.write_text("timeouts:\n  camera: 1.0\n")
    served = serve("--scene", "letters_A", *START, "--camera-rate", "0")
    done = served.run("run", LETTERS, "--problem", "A", "--world", "ros2", "--ros2", str(config), "--json",
                      timeout=300)
    output = done.stdout + done.stderr
    assert done.returncode == 1  # the run failed (the start observation and the first step's)
    assert ("no camera frame taken after the last motion within the 1 s camera timeout: "
            "/bt_meta/camera/image_raw (nothing received)") in output, output[-3000:]
