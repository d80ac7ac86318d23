"""Tree XML that must never crash, hang or pass silently (issue 14, XML side), and XML that BehaviorTree.CPP's
parser accepts although it is not well formed (issue 13).

Every bad input gives one located ``TreeXMLError``; the fuzz tests feed seeded mutations of real trees to the
loader and require that nothing but a ``BtMetaError`` comes out, within a time bound.
"""

from __future__ import annotations

import random
import re
import time

import behaviortreepy as btpy
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from py_trees.common import Status

from bt_meta.bt.nodes.ticking import tick_exactly_once, tick_once
from bt_meta.bt.registry import default_registry
from bt_meta.bt.xml.around_root import DOCTYPE_REFUSED
from bt_meta.bt.xml.document import MAX_NESTING, parse_file, parse_text
from bt_meta.bt.xml.reader import MAX_EXPANDED_NODES, load_tree_file, load_tree_text, resolve_document
from bt_meta.errors import BtMetaError, TreeXMLError

pytestmark = pytest.mark.usefixtures("clean_blackboard")


def tree(body: str, *more: str, main: str = "M") -> str:
    trees = "".join(more)
    head = f'<root BTCPP_format="4" main_tree_to_execute="{main}">'
    return f'{head}<BehaviorTree ID="M">{body}</BehaviorTree>{trees}</root>'


def error_of(text: str | bytes) -> TreeXMLError:
    with pytest.raises(TreeXMLError) as info:
        load_tree_text(text)
    return info.value


def test_two_thousand_nested_decorators_are_a_located_error_not_a_recursion_error() -> None:
    text = tree("<Inverter>" * 2000 + "<AlwaysSuccess/>" + "</Inverter>" * 2000)
    error = error_of(text)
    assert error.message == f"elements nested deeper than {MAX_NESTING} levels"
    assert error.line == 1 and error.column is not None


def test_an_unknown_encoding_is_a_located_error_not_a_lookup_error() -> None:
    text = ('<?xml version="1.0" encoding="klingon"?>' + tree("<AlwaysSuccess/>")).encode()
    error = error_of(text)
    assert error.message == "malformed XML: unsupported encoding (unknown encoding: klingon)"
    assert (error.line, error.column) == (1, 1)


def test_subtrees_that_expand_without_bound_are_refused_quickly() -> None:
    chain = "".join(
        f'<BehaviorTree ID="T{i}"><Sequence><SubTree ID="T{i + 1}"/><SubTree ID="T{i + 1}"/></Sequence></BehaviorTree>'
        for i in range(22)
    )
    text = f'<root BTCPP_format="4" main_tree_to_execute="T0">{chain}<BehaviorTree ID="T22"><AlwaysSuccess/>' + (
        "</BehaviorTree></root>"
    )
    assert len(text) < 3000
    started = time.perf_counter()
    error = error_of(text)
    assert time.perf_counter() - started < 2.0
    assert error.message == (
        f"tree 'T0' expands to 16,777,213 nodes through its SubTrees (at most {MAX_EXPANDED_NODES:,})"
    )
    assert error.line == 1


def test_subtrees_nested_too_deep_are_refused() -> None:
    chain = "".join(f'<BehaviorTree ID="T{i}"><SubTree ID="T{i + 1}"/></BehaviorTree>' for i in range(300))
    text = f'<root BTCPP_format="4" main_tree_to_execute="T0">{chain}<BehaviorTree ID="T300"><AlwaysSuccess/>' + (
        "</BehaviorTree></root>"
    )
    assert error_of(text).message == "tree 'T0' is 301 levels deep once its SubTrees are expanded (at most 256)"


@pytest.mark.parametrize(
    "loop",
    [
        '<Repeat num_cycles="1000000000"><AlwaysSuccess/></Repeat>',
        '<Repeat num_cycles="-1"><AlwaysSuccess/></Repeat>',
        '<RetryUntilSuccessful num_attempts="-1"><AlwaysFailure/></RetryUntilSuccessful>',
    ],
)
def test_loops_over_a_child_that_completes_at_once_yield_every_tick(loop: str) -> None:
    root = load_tree_text(tree(loop))
    started = time.perf_counter()
    assert [tick_exactly_once(root) for _ in range(50)] == [Status.RUNNING] * 50
    assert [tick_once(root) for _ in range(3)] == [Status.RUNNING] * 3  # BT.CPP would spin here forever
    assert time.perf_counter() - started < 10.0


def test_loops_built_without_a_wake_up_signal_still_end_the_tick() -> None:
    root = load_tree_text(tree('<Repeat num_cycles="-1"><AlwaysSuccess/></Repeat>'), wake_up=False)
    root.tick_once()
    assert root.status == Status.RUNNING


def test_loops_that_finish_still_tick_like_behaviortree_cpp() -> None:
    text = tree('<Sequence><Repeat num_cycles="3"><AlwaysSuccess/></Repeat><AlwaysFailure/></Sequence>')
    theirs = btpy.BehaviorTreeFactory().create_tree_from_text(text)
    ours = load_tree_text(text)
    assert [tick_exactly_once(ours).name for _ in range(8)] == [theirs.tick_exactly_once().name for _ in range(8)]


def test_a_duplicate_port_in_a_model_names_the_file_and_line() -> None:
    text = tree(
        "<Foo/>",
        '<TreeNodesModel>\n<Action ID="Foo">\n<input_port name="a"/>\n<input_port name="a"/></Action></TreeNodesModel>',
    )
    with pytest.raises(TreeXMLError) as info:
        parse_text(text, "nav.xml")
    assert str(info.value) == "nav.xml:4:1: port 'a' of 'Foo' is declared twice (first on line 3)"


def test_a_malformed_check_condition_is_caught_at_load() -> None:
    from bt_meta.bt.domain_nodes import domain_registry
    from bt_meta.htn.loader import load_task_file

    task_file = load_task_file("trees/housing_insertion.yaml")
    registry = domain_registry(task_file.domain)
    text = tree('<CheckCondition condition="upright(?part" bindings="part=housing"/>')
    with pytest.raises(TreeXMLError) as info:
        load_tree_text(text, registry, path="g.xml")
    assert str(info.value).startswith("g.xml:1:")
    assert "cannot build node 'CheckCondition': condition 'upright(?part'" in str(info.value)


# --- what BehaviorTree.CPP's tinyxml2 accepts -----------------------------------------------------------------


def test_unescaped_ampersands_and_less_than_in_attributes_load_with_a_warning_like_behaviortree_cpp() -> None:
    text = tree(
        '<Sequence><Script code="a := 1; b := 2"/>'
        '<ScriptCondition code="a < b && b > 1"/>'
        '<ScriptCondition code="a == 1 && b == 3" _onFailure="c := a < b"/></Sequence>'
    )
    theirs = btpy.BehaviorTreeFactory().create_tree_from_text(text)
    document = parse_text(text, "lenient.xml")
    assert len(document.warnings) == 6
    assert document.warnings[0].startswith("lenient.xml:1:")
    assert "unescaped '<' in an attribute value" in document.warnings[0]
    ours = load_tree_text(text)
    assert tick_once(ours).name == theirs.tick_once().name == "FAILURE"


def test_xml_that_stays_malformed_keeps_the_strict_error() -> None:
    error = error_of(tree('<AlwaysSuccess name="a && b"></Sequence>'))
    assert error.message == "malformed XML: not well-formed (invalid token)"  # the strict error, not the repaired one


def test_xxe_and_entity_expansion_stay_refused() -> None:
    bomb = '<?xml version="1.0"?><!DOCTYPE r [<!ENTITY a "aaaa"><!ENTITY b "&a;&a;&a;">]>' + tree("<AlwaysSuccess/>")
    assert "DOCTYPE" in error_of(bomb).message


# Text around the root element, as BehaviorTree.CPP 4.8's tinyxml2 reads it: (name, text, accepted, warning lines).
R = tree("<AlwaysSuccess/>")
AROUND_ROOT = [
    ("a C++ comment line first", "// clang-format off\n" + R, True, [1]),
    ("blank lines, then indented text", "\n\n  // note\n" + R, True, [3]),
    ("text between the declaration and the root", '<?xml version="1.0"?>\n// c\n' + R, True, [2]),
    ("text, a comment, text; after the root text, then a comment", "// a\n<!-- b -->\n// c\n" + R
     + "\n// d\n<!-- e -->", True, [1, 3, 5]),
    ("text with & and > and ]]>", "a && b &foo; > ]]>\n" + R, True, [1]),
    ("a CDATA section before and after", "<![CDATA[ x ]]>\n" + R + "\n<![CDATA[ y ]]>", True, [1, 3]),
    ("an element after the root", R + '\n<extra a="x && y"><b/></extra>', True, [2]),
    ("a second root", R + "\n" + tree("<AlwaysFailure/>"), True, [2]),
    ("an end tag after the root ends the reading", R + "\n</junk a='1'> anything <<< &&&", True, [2]),
    ("whitespace before the XML declaration", '\n  <?xml version="1.0"?>\n' + R, True, [2]),
    ("text that ends the file", R + "\n// end\n", False, []),
    ("text before an XML declaration", '// c\n<?xml version="1.0"?>\n' + R, False, []),
    ("a comment before an XML declaration", '<!-- c --><?xml version="1.0"?>' + R, False, []),
    ("text before a processing instruction", "// c\n<?pi x?>\n" + R, False, []),
    ("a processing instruction after the root", R + "<?pi x?>", False, []),
    ("a processing instruction inside the root", R.replace("<AlwaysSuccess/>", "<?pi x?><AlwaysSuccess/>"), False,
     []),
    ("a '<' in the text before the root", "if (a < b)\n" + R, False, []),
    ("a malformed element after the root", R + "\n<extra>\n", False, []),
    ("text, then an end tag after the root", R + "\nfoo </x> bar", False, []),
    ("an end tag without a name", R + "</>", False, []),
    ("an unterminated comment after the root", R + "<!-- x", False, []),
    ("an end tag before the root", "</x>" + R, False, []),
    ("only text", "just text", False, []),
]


@pytest.mark.parametrize(("text", "accepted", "lines"), [case[1:] for case in AROUND_ROOT],
                         ids=[case[0] for case in AROUND_ROOT])
def test_text_around_the_root_is_read_as_behaviortree_cpp_reads_it(text: str, accepted: bool, lines: list[int],
                                                                    tmp_path) -> None:
    try:
        btpy.BehaviorTreeFactory().register_behavior_tree_from_text(text)
    except RuntimeError:
        theirs = False
    else:
        theirs = True
    assert theirs == accepted  # the table says what BehaviorTree.CPP does; bt-meta must do the same
    path = tmp_path / "around.xml"
    path.write_text(text)
    if not accepted:
        with pytest.raises(TreeXMLError) as info:
            parse_file(path)
        assert info.value.line is not None
        return
    document = parse_file(path)
    assert list(document.trees) == ["M"]
    assert [int(w.split(":")[1]) for w in document.warnings] == lines
    assert all(w.startswith(f"{path}:") and ": warning: " in w for w in document.warnings)


def test_a_file_starting_with_a_comment_line_ticks_like_behaviortree_cpp(tmp_path) -> None:
    text = "// clang-format off\n" + tree(
        '<Sequence><Script code="n := 1"/><Repeat num_cycles="3"><Script code="n += n"/></Repeat>'
        '<ScriptCondition code="n == 8"/></Sequence>')
    path = tmp_path / "commented.xml"
    path.write_text(text)
    theirs = btpy.BehaviorTreeFactory().create_tree_from_file(str(path))
    ours = load_tree_file(path)
    assert tick_once(ours).name == theirs.tick_once().name == "SUCCESS"
    assert parse_file(path).warnings == [
        f"{path}:1:1: warning: text before the root element (BehaviorTree.CPP ignores it)"]


def test_the_misplaced_xml_declaration_and_the_error_inside_the_root_are_named() -> None:
    error = error_of('// c\n<?xml version="1.0"?>\n' + R)
    assert (error.line, error.column) == (2, 1)
    assert error.message.startswith("the XML declaration must come first in the file")
    # Once the text before the root is set aside, the error is the one inside the root, where it is.
    error = error_of("// c\n" + tree("<Sequence><AlwaysSuccess/></Fallback>"))
    assert (error.line, error.message) == (2, "malformed XML: mismatched tag")
    error = error_of(R + "<?pi x?>")
    assert error.message.startswith("processing instruction <?pi ...?> after a comment or an element")
    # A DOCTYPE stays refused (BehaviorTree.CPP skips it; bt-meta reads no DTD), text before it or not.
    error = error_of("// c\n<!DOCTYPE root>\n" + R)
    assert (error.line, error.message) == (2, DOCTYPE_REFUSED)


# --- fuzzing ----------------------------------------------------------------------------------------------------

SEEDS = [
    tree('<Sequence><Script code="x := 1"/><Repeat num_cycles="2"><AlwaysSuccess _skipIf="x > 2"/></Repeat>'
         "</Sequence>"),
    tree(
        '<Fallback><SubTree ID="S" v="{x}"/><IfThenElse><AlwaysFailure/><AlwaysSuccess/></IfThenElse></Fallback>',
        '<BehaviorTree ID="S"><Switch2 variable="{v}" case_1="1" case_2="2"><AlwaysSuccess/><AlwaysFailure/>'
        "<Sleep msec=\"0\"/></Switch2></BehaviorTree>",
    ),
    tree(
        '<Parallel success_count="-1"><LoopInt queue="1;2" value="{i}"><ScriptCondition code="i &lt; 3"/>'
        '</LoopInt><Precondition if="true" else="SKIPPED"><WasEntryUpdated entry="i"/></Precondition></Parallel>',
        '<TreeNodesModel><Action ID="Nav"><input_port name="goal" default="0"/></Action></TreeNodesModel>',
    ),
]
PIECES = ["<", ">", "/>", "</", '"', "&", "&amp;", "{", "}", "@", ":=", "_skipIf=", "<SubTree ID=\"S\"/>",
          "<Inverter>", "</Inverter>", "-1", "1e999", "\x00", "é", "<!--", "<![CDATA[", "]]>", "\n"]  # fmt: skip


CONTROLS = ["Sequence", "Fallback", "ReactiveSequence", "ReactiveFallback", "SequenceWithMemory", "Parallel",
            "ParallelAll", "AsyncSequence", "AsyncFallback", "IfThenElse", "WhileDoElse"]  # fmt: skip
NUMBERS = ["-1", "0", "1", "3", "1000000000", "-1000000000", "2.5", "x", "{x}", "{@x}", ""]
SCRIPTS = ["x := x + 1", "x = 'a'", "x := 1 ? 2 : 3", "y := x .. 'b'", "x &gt; 1 &amp;&amp; x &lt; 9", "((((", "@x"]


def mutate_meaning(text: str, rng: random.Random) -> str:
    """Well-formed mutations: other controls, extreme numbers, other scripts and conditions."""
    pick = rng.random()
    if pick < 0.35:
        old, new = rng.choice(CONTROLS), rng.choice(CONTROLS)
        return text.replace(f"<{old}>", f"<{new}>").replace(f"</{old}>", f"</{new}>")
    if pick < 0.7:
        return re.sub(r'="(-?[0-9.]+)"', lambda m: f'="{rng.choice(NUMBERS)}"' if rng.random() < 0.5 else m.group(0),
                      text)
    script = rng.choice(SCRIPTS)
    attribute = rng.choice(["code", "_skipIf", "_while", "_post", "_onHalted", "_successIf", "if"])
    return re.sub(r"<(Script|ScriptCondition|AlwaysSuccess|AlwaysFailure)\b", f'<\\1 {attribute}="{script}"', text,
                  count=1)


def mutate(seed_text: str, rng: random.Random) -> str:
    if rng.random() < 0.5:
        text = seed_text
        for _ in range(rng.randint(1, 3)):
            text = mutate_meaning(text, rng)
        return text
    text = seed_text
    for _ in range(rng.randint(1, 4)):
        position = rng.randrange(len(text) + 1)
        action = rng.random()
        if action < 0.4:
            text = text[:position] + rng.choice(PIECES) + text[position:]
        elif action < 0.7:
            end = min(len(text), position + rng.randint(1, 12))
            text = text[:position] + text[end:]
        else:
            end = min(len(text), position + rng.randint(1, 30))
            text = text[:position] + text[position:end] * rng.randint(2, 4) + text[end:]
    return text


def check_one(text: str) -> tuple[str, float]:
    """Load, resolve and tick a few times: only BtMetaError may come out, and quickly. Returns the outcome and the
    seconds it took."""
    started = time.perf_counter()
    outcome = "loaded and ticked"
    try:
        document = parse_text(text, "fuzz.xml")
        resolve_document(document, default_registry())
        root = load_tree_text(text, default_registry())
        for _ in range(3):
            tick_once(root)
    except BtMetaError:
        outcome = "refused (BtMetaError)"
    elapsed = time.perf_counter() - started
    assert elapsed < 5.0, text
    return outcome, elapsed


@settings(
    max_examples=300,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
)
@given(st.integers(min_value=0, max_value=2**32 - 1), st.sampled_from(range(len(SEEDS))))
def test_fuzzed_trees_raise_only_bt_meta_errors(seed: int, which: int) -> None:
    check_one(mutate(SEEDS[which], random.Random(seed)))


@given(st.lists(st.sampled_from([*PIECES, "a", "Sequence", " ", "="]), max_size=20))
@settings(max_examples=200, deadline=None, derandomize=True)
def test_fuzzed_text_raises_only_bt_meta_errors(pieces: list[str]) -> None:
    check_one(f'<root BTCPP_format="4"><BehaviorTree ID="M">{"".join(pieces)}</BehaviorTree></root>')


@pytest.mark.fuzz
@pytest.mark.slow
def test_fuzz_campaign_ten_thousand_trees(capsys: pytest.CaptureFixture[str]) -> None:
    """``pytest -m fuzz -n 0 -s tests/bt/test_xml_robustness.py`` prints the counts quoted in docs/benchmarks.md."""
    import collections
    import logging

    logging.getLogger("bt_meta.xml").setLevel(logging.ERROR)  # the leniency warnings, 1 per repaired mutant
    rng = random.Random(20261201)
    counts: collections.Counter[str] = collections.Counter()
    worst = 0.0
    for index in range(10_000):
        outcome, elapsed = check_one(mutate(SEEDS[index % len(SEEDS)], rng))
        counts[outcome] += 1
        worst = max(worst, elapsed)
    logging.getLogger("bt_meta.xml").setLevel(logging.NOTSET)
    with capsys.disabled():
        print(f"\nXML fuzz campaign: {dict(counts)}, slowest input {worst * 1000:.0f} ms")
    assert sum(counts.values()) == 10_000 and counts["loaded and ticked"] > 1000


@pytest.mark.parametrize(
    "loop",
    [
        '<Repeat num_cycles="-1"><AlwaysSuccess/></Repeat>',
        '<RetryUntilSuccessful num_attempts="-1"><AlwaysFailure/></RetryUntilSuccessful>',
    ],
)
def test_the_tick_command_bounds_an_endless_loop_by_ticks(loop: str, tmp_path, capsys) -> None:
    from bt_meta.cli import main

    path = tmp_path / "loop.xml"
    path.write_text(tree(loop))
    started = time.perf_counter()
    assert main(["tick", str(path), "--ticks", "3"]) == 0
    assert time.perf_counter() - started < 20.0
    assert capsys.readouterr().out.splitlines()[-1].startswith("RUNNING after 3 ticks")


@pytest.mark.parametrize(("name", "message"), [
    ("/dev/zero", "the tree XML file is a character device, not a regular file"),
    ("/etc", "the tree XML file is a folder, not a regular file"),
    ("missing.xml", "no such tree XML file"),
])
def test_only_regular_files_are_read(name: str, message: str) -> None:
    from bt_meta.bt.xml.document import parse_file

    with pytest.raises(TreeXMLError) as info:
        parse_file(name)
    assert info.value.message == message


def test_an_include_of_a_device_is_refused(tmp_path) -> None:
    from bt_meta.bt.xml.document import parse_file

    path = tmp_path / "main.xml"
    path.write_text(tree("<AlwaysSuccess/>").replace("<BehaviorTree", '<include path="/dev/zero"/><BehaviorTree', 1))
    with pytest.raises(TreeXMLError) as info:
        parse_file(path)
    assert info.value.message.startswith("<include path='/dev/zero'>: no such file")
