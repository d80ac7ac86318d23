"""docs/campaigns.md's commands for a user's own task, run as the page writes them (on the tutorial's task, with a
smaller ``--n``), so the page and the code cannot drift apart."""

from __future__ import annotations

import json
import re
import shlex
import sys
from pathlib import Path

import pytest

from bt_meta.cli import main

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_tutorial import tutorial_steps  # the tutorial's files, as its own test extracts them

CAMPAIGNS = Path(__file__).resolve().parents[1] / "docs" / "campaigns.md"
BLOCK = re.compile(r"^```sh\n(?P<body>.*?)^```$", re.M | re.S)


def own_task_commands() -> list[list[str]]:
    """The commands of the page's code block that generates a campaign with ``--task``, one word list each
    (comments dropped, ``&&`` chains split)."""
    blocks = [m["body"] for m in BLOCK.finditer(CAMPAIGNS.read_text(encoding="utf-8")) if "--task" in m["body"]]
    assert len(blocks) == 1, "docs/campaigns.md should show one block of commands for a user's own task"
    commands = []
    for line in blocks[0].splitlines():
        for part in line.split("#", 1)[0].split("&&"):
            if part.strip():
                commands.append(shlex.split(part))
    return commands


def test_the_page_shows_generate_run_and_report_for_ones_own_task():
    commands = own_task_commands()
    assert [c[:3] for c in commands] == [["bt-meta", "campaign", "generate"], ["bt-meta", "campaign", "run"],
                                         ["bt-meta", "campaign", "report"]]
    assert "--task" in commands[0] and "--n" in commands[0] and "-o" in commands[0]


@pytest.mark.slow
def test_the_pages_commands_run_on_the_tutorials_task(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("BT_META_MEMORY", raising=False)
    for kind, text in tutorial_steps():
        if kind == "file":
            name, body = text.split("\n", 1)
            Path(name).parent.mkdir(parents=True, exist_ok=True)
            Path(name).write_text(body, encoding="utf-8")
    commands = own_task_commands()
    folder = Path(commands[0][commands[0].index("-o") + 1])
    for words in commands:
        if "--n" in words:  # the page's population, cut to one variant to keep the test short
            words[words.index("--n") + 1] = "1"
        code = main(words[1:])
        captured = capsys.readouterr()
        assert code == 0, f"{' '.join(words)}: exit {code}\n{captured.out[-2000:]}\n{captured.err[-2000:]}"
    manifest = json.loads((folder / "campaign.json").read_text(encoding="utf-8"))
    assert manifest["family"] == "peg" and len(manifest["variants"]) == 1
    episodes = sorted((folder / "episodes").glob("*.json"))
    assert episodes, "campaign run wrote no episode"
    for path in episodes:
        row = json.loads(path.read_text(encoding="utf-8"))
        assert row["achieved"] in (True, False) and row["truth"]  # judged on the simulator's true state
    page = (folder / "report.html").read_text(encoding="utf-8")
    assert "peg" in page and "Wilson" in page
