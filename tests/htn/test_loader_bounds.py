"""The task-file loader's bounds and YAML safety: each refusal is one located TaskFileError, found fast."""

from __future__ import annotations

from pathlib import Path

import pytest

from bt_meta.errors import TaskFileError
from bt_meta.htn import load_task_file, load_task_text
from bt_meta.htn.conditions import dnf_size, parse_condition

DOMAIN = "domain:\n  predicates: {p: [], q: []}\n  primitives:\n    a: {}\n"
PROBLEM = "domain_file: {name}\nproblems:\n  x: {{tasks: [a()]}}\n"


def error_of(text: str, path: str = "t.yaml") -> TaskFileError:
    with pytest.raises(TaskFileError) as caught:
        load_task_text(text, path=path)
    return caught.value


# -- domain_file: what a task file may read ----------------------------------------------------------------------

def test_domain_file_under_the_task_folder_loads(tmp_path: Path):
    (tmp_path / "domains").mkdir()
    (tmp_path / "domains" / "d.yaml").write_text(DOMAIN)
    (tmp_path / "p.yaml").write_text(PROBLEM.format(name="domains/d.yaml"))
    loaded = load_task_file(tmp_path / "p.yaml")
    assert loaded.domain_path == str(tmp_path / "domains" / "d.yaml")
    assert list(loaded.problems) == ["x"]


@pytest.mark.parametrize("name", ["/etc/passwd", "../../../../../../etc/passwd", "/etc/shadow"])
def test_domain_file_outside_the_folder_is_refused_without_echoing_it(tmp_path: Path, name: str):
    (tmp_path / "p.yaml").write_text(PROBLEM.format(name=name))
    with pytest.raises(TaskFileError) as caught:
        load_task_file(tmp_path / "p.yaml")
    message = caught.value.location_message()
    assert message.startswith(f"{tmp_path / 'p.yaml'}:1:14: domain file {name!r} is outside the task file's folder")
    assert "BT_META_DOMAIN_ROOTS" in message
    assert "root:" not in message and "/bin/" not in message


def test_a_symlink_out_of_the_folder_is_refused(tmp_path: Path):
    (tmp_path / "link.yaml").symlink_to("/etc/passwd")
    (tmp_path / "p.yaml").write_text(PROBLEM.format(name="link.yaml"))
    with pytest.raises(TaskFileError, match="is outside the task file's folder"):
        load_task_file(tmp_path / "p.yaml")


def test_allowed_roots_by_environment_and_argument(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    shared = tmp_path / "shared"
    shared.mkdir()
    (shared / "d.yaml").write_text(DOMAIN)
    project = tmp_path / "project"
    project.mkdir()
    (project / "p.yaml").write_text(PROBLEM.format(name="../shared/d.yaml"))
    with pytest.raises(TaskFileError, match="outside"):
        load_task_file(project / "p.yaml")
    assert load_task_file(project / "p.yaml", allowed_roots=[shared]).domain.primitives
    monkeypatch.setenv("BT_META_DOMAIN_ROOTS", f"/nonexistent-root:{shared}")
    assert load_task_file(project / "p.yaml").domain.primitives


def test_an_allowed_file_that_is_not_a_task_file_is_not_quoted(tmp_path: Path):
    (tmp_path / "secret.txt").write_text("root:x:0:0:root:/root:/bin/bash\ndaemon:x:1:1::/usr/sbin\n")
    (tmp_path / "p.yaml").write_text(PROBLEM.format(name="secret.txt"))
    with pytest.raises(TaskFileError) as caught:
        load_task_file(tmp_path / "p.yaml")
    message = caught.value.location_message()
    assert message == (f"{tmp_path / 'secret.txt'}:1:1: a task file must be a mapping with 'domain:' and/or "
                       "'problems:', found a single value")
    assert "root:x" not in message


def test_self_reference_and_cycles_and_chains(tmp_path: Path):
    (tmp_path / "self.yaml").write_text("domain_file: self.yaml\n")
    with pytest.raises(TaskFileError) as caught:
        load_task_file(tmp_path / "self.yaml")
    assert caught.value.message == ("domain file 'self.yaml' names a file that is already being loaded (a cycle: "
                                    "self.yaml -> self.yaml)")
    (tmp_path / "a.yaml").write_text("domain_file: b.yaml\n")
    (tmp_path / "b.yaml").write_text("domain_file: a.yaml\n")
    with pytest.raises(TaskFileError, match=r"a cycle: a\.yaml -> b\.yaml -> a\.yaml"):
        load_task_file(tmp_path / "a.yaml")
    for index in range(12):
        (tmp_path / f"c{index}.yaml").write_text(f"domain_file: c{index + 1}.yaml\n")
    (tmp_path / "c12.yaml").write_text(DOMAIN)
    with pytest.raises(TaskFileError, match=r"more than 8 domain files chained"):
        load_task_file(tmp_path / "c0.yaml")
    assert load_task_file(tmp_path / "c6.yaml").domain.primitives


def test_domain_file_paths_that_cannot_be_a_path(tmp_path: Path):
    (tmp_path / "p.yaml").write_text('domain_file: "a\\0b.yaml"\n')
    with pytest.raises(TaskFileError, match=r"p\.yaml:1:14: the domain file path holds a NUL byte"):
        load_task_file(tmp_path / "p.yaml")
    (tmp_path / "q.yaml").write_text(f"domain_file: {'x' * 5000}.yaml\n")
    with pytest.raises(TaskFileError, match=r"q\.yaml:1:14: the domain file path is too long"):
        load_task_file(tmp_path / "q.yaml")
    (tmp_path / "l1").symlink_to(tmp_path / "l2")
    (tmp_path / "l2").symlink_to(tmp_path / "l1")
    (tmp_path / "r.yaml").write_text("domain_file: l1\n")
    with pytest.raises(TaskFileError, match=r"r\.yaml:1:14: domain file 'l1': symlink loop"):
        load_task_file(tmp_path / "r.yaml")


# -- YAML bounds --------------------------------------------------------------------------------------------------

@pytest.mark.timeout(10)
def test_deeply_nested_flow_brackets_are_refused_fast():
    text = "domain:\n  name: x\nproblems: " + "[" * 20000 + "]" * 20000 + "\n"
    assert len(text) > 40_000
    assert error_of(text).location_message() == "t.yaml:3:74: YAML error: nested deeper than 64 levels"


@pytest.mark.timeout(10)
def test_deep_block_nesting_is_refused():
    text = "domain:\n  primitives:\n" + "".join("  " * (i + 2) + f"k{i}:\n" for i in range(100))
    assert "nested deeper than 64 levels" in error_of(text).message


@pytest.mark.timeout(10)
def test_many_aliases_are_refused_fast():
    aliases = ", ".join(["*a"] * 20000)
    text = DOMAIN.replace("a: {}", f"a:\n      expectations:\n        a: &a [1]\n        b: [{aliases}]")
    error = error_of(text)
    assert error.message == "YAML error: more than 1000 aliases (*name) in one file"
    assert error.line == 7


@pytest.mark.timeout(10)
def test_alias_expansion_and_recursion_are_refused():
    lines = ["l0: &l0 [x, x, x, x, x, x, x, x, x, x]"]
    for level in range(1, 8):
        lines.append(f"l{level}: &l{level} [" + ", ".join([f"*l{level - 1}"] * 10) + "]")
    text = DOMAIN.replace("a: {}", "a:\n      expectations:\n" + "".join(f"        {line}\n" for line in lines))
    assert "the aliases expand to more than 200000 values" in error_of(text).message
    text = DOMAIN.replace("a: {}", "a:\n      expectations:\n        x: &a {y: *a}")
    assert error_of(text).message == ("YAML error: an alias refers to a collection that contains it (a recursive "
                                      "structure)")


@pytest.mark.parametrize(("value", "message"), [
    ("!!python/object:os.system {}",
     "6:12: YAML tag error: the tag !!python/object:os.system is not allowed here (only plain values, lists and "
     "mappings)"),
    ("!!python/name:os.system ''", "6:12: YAML tag error: the tag !!python/name:os.system is not allowed here"),
    ("!!int xyz", "6:12: YAML tag error: cannot read the !!int value 'xyz': ValueError"),
    ("!!float abc", "6:12: YAML tag error: cannot read the !!float value 'abc': ValueError"),
    ("!!set {a: 1}", "6:12: YAML tag error: the tag !!set is not allowed here"),
    ("{<<: 5}", "6:17: YAML tag error: expected a mapping or list of mappings for merging, but found scalar"),
    ("{<<: [1]}", "6:18: YAML tag error: expected a mapping for merging, but found scalar"),
    ("!custom 1", "6:12: YAML tag error: the tag !custom is not allowed here"),
])
def test_tags_in_expectations_are_located(value: str, message: str):
    text = DOMAIN.replace("a: {}", f"a:\n      expectations:\n        x: {value}\n")
    assert error_of(text).location_message().startswith(f"t.yaml:{message}")


def test_plain_expectations_and_merge_keys_still_load():
    text = DOMAIN.replace("a: {}", "a:\n      expectations:\n        base: &b {k: 1}\n        x: {<<: *b, j: 2}\n"
                                   "        when: 2020-01-02\n")
    expectations = load_task_text(text).domain.primitives["a"].expectations
    assert expectations == {"base": {"k": 1}, "x": {"k": 1, "j": 2}, "when": "2020-01-02"}


def test_control_characters_give_one_located_line():
    error = error_of("domain:\n  name: a\x01b\n")
    assert error.location_message() == "t.yaml:2:10: control character #x0001 is not allowed in YAML"
    assert "\n" not in str(error)


# -- condition bounds ---------------------------------------------------------------------------------------------

def condition_file(condition: str) -> str:
    return DOMAIN.replace("a: {}", f"a:\n      precondition: '{condition}'")


@pytest.mark.timeout(10)
def test_nested_parentheses_and_nots_are_located():
    error = error_of(condition_file("(" * 1000 + "p()" + ")" * 1000))
    assert error.location_message() == "t.yaml:5:122: condition nested deeper than 100 levels of '(' and 'not'"
    assert "nested deeper than 100" in error_of(condition_file("not " * 2000 + "p()")).message
    assert load_task_text(condition_file("(" * 50 + "p()" + ")" * 50))


@pytest.mark.timeout(10)
def test_condition_size_is_computed_before_distributing():
    factor = "(" + " or ".join(["p()"] * 64) + ")"
    huge = " and ".join([factor] * 6)  # 64**6 alternatives: never built
    assert dnf_size(parse_condition(huge)) == (4097, 100_001)
    assert error_of(condition_file(huge)).message == ("condition too large once distributed (more than 4096 "
                                                      "alternatives)")
    long_clauses = " and ".join(["(p() or q())"] * 12 + ["p()"] * 30)  # 4096 alternatives of 42 atoms each
    assert dnf_size(parse_condition(long_clauses)) == (4096, 100_001)  # capped past the bound
    assert "more than 100000 atoms" in error_of(condition_file(long_clauses)).message
    assert dnf_size(parse_condition("not (p() and q()) or false")) == (2, 2)
    assert dnf_size(parse_condition("(p() or q()) and false")) == (0, 0)


def test_an_empty_block_scalar_condition_is_located():
    text = DOMAIN.rstrip("\n").replace("a: {}", "a:\n      precondition: |")  # at the very end of the file
    assert error_of(text).location_message() == "t.yaml:5:21: empty condition (write 'true' for no condition)"
    text = DOMAIN.replace("a: {}", "a:\n      precondition: |\n    b: {}")
    assert error_of(text).message == "empty condition (write 'true' for no condition)"
