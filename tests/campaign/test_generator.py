"""The generator is deterministic, always changes something, and writes ordinary scene files."""

from __future__ import annotations

from bt_meta.campaign.families import family, family_spec
from bt_meta.campaign.generator import VARIANT_NAME, draw_variant, placed_objects, scene_text
from bt_meta.campaign.spec import load_spec
from bt_meta.world.simulation.scenes import load_scene


def _setup(name="letters_A", family_name="letters_A"):
    scene = load_scene(name)
    spec = family_spec(family(family_name), scene)
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
    spec = family_spec(family("letters_A"), scene)
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
    assert kinds == {"shift", "turn", "rotate", "colour", "replace_shape", "remove", "distractor", "out_of_reach",
                     "obstacles"}



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


def _obstacle_spec(tmp_path, on_work):
    scene = load_scene("letters_A")
    path = tmp_path / "spec.yaml"
    path.write_text("perturbations:\n  - obstacles: {probability: 1, count: [1, 2], on_work_probability: "
                    f"{on_work}}}\n", encoding="utf-8")
    return scene, load_spec(path, [o.name for o in scene.objects]), placed_objects(scene)


def test_obstacles_stand_off_every_object_and_load_as_the_variants_obstacles(tmp_path):
    """Obstacles never overlap an object (the physics would throw it); clear ones keep off the task's places;
    over-the-work ones come near them; the scene file gives the simulator the same obstacles."""
    from bt_meta.campaign.generator import TARGET_CLEARANCE, Obstacle, _radius

    targets = [(0.55, 0.10), (0.61, 0.06)]
    for on_work in (0.0, 1.0):
        scene, spec, nominal = _obstacle_spec(tmp_path, on_work)
        near = 0
        for k in range(12):
            objects, changes = draw_variant(nominal, spec, 2, k, targets=targets)
            (change,) = changes
            assert change["kind"] == "obstacles" and objects == list(nominal)
            near += change["near"] is not None
            for entry in change["obstacles"]:
                dims = {key: entry[key] for key in ("size", "radius", "height", "thickness") if key in entry}
                obstacle = Obstacle(entry["name"], entry["shape"], dims, entry["pose"][0], entry["pose"][1],
                                    entry["pose"][5])
                assert all(obstacle.distance(o.x, o.y) >= _radius(o.type) for o in objects)
                if on_work == 0.0:
                    assert all(obstacle.distance(tx, ty) >= TARGET_CLEARANCE for tx, ty in targets)
            path = tmp_path / f"v{k}.yaml"
            path.write_text(scene_text(scene, f"v{k}", objects, changes), encoding="utf-8")
            loaded = load_scene(path)
            assert [o.name for o in loaded.obstacles_for(VARIANT_NAME)] == [o["name"] for o in change["obstacles"]]
            assert loaded.obstacles_for(None) == scene.obstacles
        assert (near == 0) if on_work == 0.0 else near >= 9  # a first obstacle that fits nowhere near is dropped


def test_a_distractor_blocking_a_target_on_a_part_rests_on_the_part(tmp_path):
    """A target on a part (the reference's magnet): the blocking distractor is put on the part, not inside it,
    and the settled scene keeps the part upright (inside it, the simulator threw the reference over)."""
    import math

    from bt_meta.campaign.labeller import Labeller

    scene = load_scene("magnetic_attach")
    spec_path = tmp_path / "spec.yaml"
    spec_path.write_text("family: magnetic\nperturbations:\n  - distractor: {probability: 1.0, count: [1, 1], "
                         "types: [megablok_1x2], colours: [green], on_target_probability: 1.0}\n", encoding="utf-8")
    spec = load_spec(spec_path, [o.name for o in scene.objects], family="magnetic")
    reference = next(o for o in placed_objects(scene) if o.name == "reference")
    objects, changes = draw_variant(placed_objects(scene), spec, 0, 0, targets=[(reference.x, reference.y)])
    distractor = next(o for o in objects if o.name.startswith("distractor"))
    assert changes[0]["blocking"] == [reference.x, reference.y]
    assert distractor.z is not None and distractor.z > -0.20  # above the table top: on the reference
    path = tmp_path / "v.yaml"
    path.write_text(scene_text(scene, "v", objects, changes), encoding="utf-8")
    with Labeller(family("magnetic"), scene) as labeller:
        label = labeller.label(path, VARIANT_NAME, changes)
        world = labeller._world(path, VARIANT_NAME)
        try:
            up = world.sim.object_transform("reference")[:3, 2]
        finally:
            world.close()
    assert math.degrees(math.acos(min(1.0, float(up[2])))) < 5.0
    assert label.expected == "limit:collision" and "distractor" in label.reason
