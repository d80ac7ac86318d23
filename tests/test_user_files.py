"""Reading user files: regular files only, bounded, never blocking, every refusal one located error."""

from __future__ import annotations

import os
import threading
from pathlib import Path

import pytest

from bt_meta.errors import TaskFileError, UserInputError
from bt_meta.htn import load_task_file
from bt_meta.user_files import (
    check_output_file,
    check_path_text,
    make_output_folder,
    read_user_bytes,
    read_user_text,
)


def test_reads_a_regular_file(tmp_path: Path):
    path = tmp_path / "a.txt"
    path.write_text("héllo\n", encoding="utf-8")
    assert read_user_text(path) == "héllo\n"
    assert read_user_bytes(path) == "héllo\n".encode()


def test_missing_file_and_folder(tmp_path: Path):
    with pytest.raises(UserInputError) as caught:
        read_user_text(tmp_path / "nope.yaml", what="task file")
    assert caught.value.location_message() == f"{tmp_path / 'nope.yaml'}: no such task file"
    with pytest.raises(UserInputError, match=r"the task file is a folder, not a regular file"):
        read_user_text(tmp_path, what="task file")


def test_nul_byte_and_too_long_paths():
    with pytest.raises(UserInputError) as caught:
        read_user_text("a\x00b.yaml", what="task file")
    assert caught.value.message == "the task file path holds a NUL byte"
    assert "\x00" not in caught.value.location_message()
    with pytest.raises(UserInputError, match=r"the task file path is too long \(5000 characters\)"):
        read_user_text("x" * 5000, what="task file")
    with pytest.raises(UserInputError, match="too long"):
        check_path_text("d/" + "y" * 300)


def test_symlink_loop(tmp_path: Path):
    (tmp_path / "a").symlink_to(tmp_path / "b")
    (tmp_path / "b").symlink_to(tmp_path / "a")
    with pytest.raises(UserInputError, match=r"cannot read the task file: symlink loop"):
        read_user_text(tmp_path / "a", what="task file")


@pytest.mark.timeout(20)
def test_named_pipe_is_refused_without_waiting(tmp_path: Path):
    fifo = tmp_path / "pipe.yaml"
    os.mkfifo(fifo)
    with pytest.raises(UserInputError, match=r"the task file is a named pipe, not a regular file"):
        read_user_text(fifo, what="task file")


def test_devices_are_refused():
    with pytest.raises(UserInputError, match=r"is a character device, not a regular file"):
        read_user_bytes("/dev/zero", what="tree XML file")


def test_size_bound(tmp_path: Path):
    path = tmp_path / "big.yaml"
    path.write_bytes(b"#" * 101)
    assert len(read_user_bytes(path, max_bytes=101)) == 101
    with pytest.raises(UserInputError, match=r"the file is larger than 100 bytes"):
        read_user_bytes(path, max_bytes=100)


def test_bad_utf8_is_located(tmp_path: Path):
    path = tmp_path / "t.yaml"
    path.write_bytes(b"domain:\n  name: \xff\n")
    with pytest.raises(TaskFileError) as caught:
        load_task_file(path)
    assert caught.value.location_message() == f"{path}:2:9: the task file is not UTF-8 text (byte 0xff)"


def test_unreadable_file(tmp_path: Path):
    if os.geteuid() == 0:
        pytest.skip("root reads every file")
    path = tmp_path / "secret.yaml"
    path.write_text("x: 1\n")
    path.chmod(0)
    with pytest.raises(UserInputError, match="permission denied"):
        read_user_text(path)


def test_task_file_loaders_use_the_checks(tmp_path: Path):
    with pytest.raises(TaskFileError, match=r"is a character device"):
        load_task_file("/dev/zero")
    fifo = tmp_path / "p.yaml"
    os.mkfifo(fifo)
    done = threading.Event()

    def load() -> None:
        with pytest.raises(TaskFileError, match="named pipe"):
            load_task_file(fifo)
        done.set()

    worker = threading.Thread(target=load, daemon=True)
    worker.start()
    worker.join(10)
    assert done.is_set(), "loading a named pipe blocked"


def test_output_locations(tmp_path: Path):
    assert check_output_file(tmp_path / "A.xml") == tmp_path / "A.xml"
    with pytest.raises(UserInputError) as caught:
        check_output_file(tmp_path / "missing" / "dir" / "A.xml", "output file")
    assert caught.value.message == f"the folder of the output file does not exist ({tmp_path / 'missing' / 'dir'})"
    with pytest.raises(UserInputError, match="the output file is a folder"):
        check_output_file(tmp_path)
    assert make_output_folder(tmp_path / "new" / "out").is_dir()
    (tmp_path / "file").write_text("")
    with pytest.raises(UserInputError, match=r"cannot make the output folder: a part of the path is not a folder"):
        make_output_folder(tmp_path / "file" / "out")
    with pytest.raises(UserInputError, match="the output folder exists and is not a folder"):
        make_output_folder(tmp_path / "file")
