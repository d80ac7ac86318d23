"""The generator is deterministic, always changes something, and writes ordinary scene files."""

from __future__ import annotations

from bt_meta.campaign.families import default_spec_path
from bt_meta.campaign.generator import VARIANT_NAME, draw_variant, placed_objects, scene_text
from bt_meta.campaign.spec import load_spec
from bt_meta.world.simulation.scenes import load_scene


def _setup(name="letters_A", family="letters_A"):
    scene = load_scene(name)
    spec = load_spec(default_spec_path(family), [o.name for o in scene.objects])
    return scene, spec, placed_objects(scene)


def test_same_seed_same_variant_and_index_independent():
    _, spec, nominal = _setup()
    a = [draw_variant(nominal, spec, 3, k) for k in range(8)]
    b = [draw_variant(nominal, spec, 3, k) for k in range(8)]
    assert a == b
    assert draw_variant(nominal, spec, 3, 5) == a[5]
    assert len({str(objects) for objects, _ in a}) == 8
    assert all(changes for _, changes in a)
    assert draw_variant(nominal, spec, 4, 0) != a[0]


def test_variant_scene_file_loads_and_gives_the_drawn_objects(tmp_path):
    scene, spec, nominal = _setup()
    for k in range(10):
        objects, changes = draw_variant(nominal, spec, 1, k)
        path = tmp_path / f"v{k}.yaml"
        path.write_text(scene_text(scene, f"v{k}", objects, changes, "repairable", "a reason"), encoding="utf-8")
        loaded = load_scene(path)
        assert [o.name for o in loaded.objects] == [o.name for o in nominal]
        got = {o.name: (o.type, o.colour) for o in loaded.objects_for(VARIANT_NAME)}
        assert got == {o.name: (o.type, o.colour) for o in objects}
        assert loaded.anchors.keys() == scene.anchors.keys()


def test_perturbations_do_what_they_say():
    scene, _, nominal = _setup()
    kinds = set()
    spec = load_spec(default_spec_path("letters_A"), [o.name for o in scene.objects])
    for k in range(60):
        objects, changes = draw_variant(nominal, spec, 0, k)
        names = {o.name for o in objects}
        for change in changes:
            kinds.add(change["kind"])
            if change["kind"] == "remove" and change["spare"] is None:
                assert change["object"] not in names or any(c["kind"] == "replace_shape" for c in changes)
            if change["kind"] == "out_of_reach":
                moved = next((o for o in objects if o.name == change["object"]), None)
                assert moved is None or moved.x >= 0.85 or any(
                    c.get("object") == change["object"] for c in changes if c is not change)
    assert kinds == {"shift", "turn", "rotate", "colour", "replace_shape", "remove", "distractor", "out_of_reach"}



def test_a_shape_replacement_with_no_room_changes_nothing():
    """A 1x1 and a partner become one 1x2 only where the 1x2 fits: with no room, the partner stays on the table (it
    was taken away anyway, and a letter with a spare ended one block short of what its label said)."""
    import numpy as np

    from bt_meta.campaign.generator import _Draw, _replace_shape

    _, spec, nominal = _setup()
    replace_shape = next(p for p in spec.perturbations if p.kind == "replace_shape")
    no_room = ((0.0, 0.01), (0.0, 0.01))  # a table nothing fits on
    draw = _Draw(nominal, [], np.random.default_rng(0), no_room)
    b0 = next(o for o in draw.objects if o.name == "b0")
    assert _replace_shape(draw, replace_shape, b0) is None
    assert draw.objects == list(nominal)
