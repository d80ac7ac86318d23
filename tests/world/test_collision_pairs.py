"""The collision pairs the checker hands to Pinocchio, against the rules written out pair by pair."""

from __future__ import annotations

import numpy as np

from bt_meta.world.kinematics.collision import CollisionChecker


def _expected_pairs(checker: CollisionChecker) -> list[tuple[int, int]]:
    """The rules of the module docstring, one pair at a time (the straightforward form of ``_rebuild_pairs``)."""
    objects = checker.geometry.geometryObjects
    n_robot = checker._robot_geometries
    link = checker._link_of
    out = []
    for i in range(checker.geometry.ngeoms):
        for j in range(i + 1, checker.geometry.ngeoms):
            a, b = objects[i], objects[j]
            if j < n_robot:
                keep = (a.parentJoint != b.parentJoint
                        and frozenset((link[i], link[j])) not in checker._disabled_links)
            elif i < n_robot:
                keep = (not (b.parentJoint != 0 and a.parentJoint == b.parentJoint)
                        and frozenset((link[i], b.name)) not in checker._allowed)
            else:
                keep = (not (a.parentJoint == 0 and b.parentJoint == 0) and a.parentJoint != b.parentJoint
                        and frozenset((a.name, b.name)) not in checker._allowed)
            if keep:
                out.append((i, j))
    return out


def _handed_over(checker: CollisionChecker) -> list[tuple[int, int]]:
    """The pairs Pinocchio checks in a full check: the model's pairs switched on in the geometry data."""
    data, _ = checker._activate((True, True, None))
    return [(pair.first, pair.second) for k, pair in enumerate(checker.geometry.collisionPairs)
            if data.activeCollisionPairs[k]]


def test_pairs_follow_the_rules_through_adds_allows_attaches_and_detaches(kin):
    checker = CollisionChecker(kin)
    q = kin.home
    steps = [
        lambda: checker.add_box("table", (0.6, 1.1, 0.04), (0.75, -0.1, -0.22)),
        lambda: checker.add_box("a", (0.05, 0.05, 0.05), (0.6, -0.2, -0.17)),
        lambda: checker.add_cylinder("b", 0.03, 0.05, (0.65, -0.3, -0.17)),
        lambda: checker.add_box("c", (0.05, 0.05, 0.05), (0.7, -0.2, -0.17)),
        lambda: checker.allow("a", ["table", "right_gripper_base_link"]),
        lambda: checker.attach("b", kin.end_effector("right"), q, allow=["r_gripper_l_finger", "a"]),
        lambda: checker.allow("b", ["b"]),
        lambda: checker.detach("b", q=q),
        lambda: checker.disallow("a"),
        lambda: checker.remove("c"),
        lambda: checker.attach("a", kin.end_effector("left"), q),
    ]
    for step in steps:
        step()
        expected = _expected_pairs(checker)
        assert _handed_over(checker) == expected
        assert checker.checked_pairs == expected
        assert checker.n_self_pairs + checker.n_scene_pairs == len(expected)


def test_arm_masks_keep_only_pairs_an_arm_moves(kin):
    checker = CollisionChecker(kin)
    checker.add_box("a", (0.05, 0.05, 0.05), (0.6, -0.2, -0.17))
    mask = checker._mask((True, True, "right"))
    objects = checker.geometry.geometryObjects
    moved = checker._joints_moved_by("right")
    expected = [objects[p.first].parentJoint in moved or objects[p.second].parentJoint in moved
                for p in checker.geometry.collisionPairs]
    assert mask.tolist() == expected
    assert 0 < int(np.count_nonzero(mask)) < len(expected)


def _fresh_like(kin, steps) -> CollisionChecker:
    checker = CollisionChecker(kin)
    for step in steps:
        step(checker)
    return checker


def test_one_geometry_data_serves_every_pair_set_of_the_same_objects(kin):
    """A grasp, a release or an allowed touch switches pairs on and off in the geometry data made once for the
    scene's objects (no new data); every check, with and without the broad phase, an arm mask or a clearance,
    answers as a checker built straight into the same state. Adding or removing an object makes new data."""
    import pinocchio as pin

    q = kin.home
    gripper = kin.end_effector_pose(q, "right")
    below = gripper * pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.1]))
    build = [lambda c: c.add_box("table", (1.0, 1.4, 0.1), (0.7, 0.0, -0.1)),
             lambda c: c.add_box("held", (0.04, 0.04, 0.04), below),
             lambda c: c.add_box("other", (0.04, 0.04, 0.04), (0.75, -0.3, -0.02))]
    grasp = [lambda c: c.attach("held", "right_gripper", q, allow=["r_gripper_l_finger"]),
             lambda c: c.allow("held", ["other"])]
    release = [lambda c: c.detach("held", below), lambda c: c.disallow("held")]
    checker = _fresh_like(kin, build)
    rng = np.random.default_rng(3)
    qs = [kin.q_from_dict({"right_s1": float(s1), "right_e1": float(e1)}, q)
          for s1, e1 in zip(rng.uniform(-0.8, 0.6, 12), rng.uniform(0.0, 2.0, 12), strict=True)]

    def answers(c: CollisionChecker) -> list:
        """What each check finds, to the last digit of a depth (coal warm-starts a pair's narrow phase from its
        last result: the data must start each pair set as a fresh one does)."""
        out = []
        for x in qs:
            for options in ({}, {"arm": "right"}, {"scene": False}, {"carried_clearance": 0.01},
                            {"carried_clearance": -0.002}):
                contact = c.check(x, **options)
                out.append(None if contact is None else (contact.pair, contact.penetration))
            out.append(sorted(contact.pair for contact in c.all_contacts(x)))
        if "other" in c.objects:
            out.append(c.distance(q, "other"))
        return out

    data = checker.geometry_data
    before = answers(checker)
    assert any(a is not None for a in before[:-1]) and any(a is None for a in before[:-1])
    for state in (grasp, release, grasp):
        for step in state:
            step(checker)
        assert checker.geometry_data is data
    assert answers(checker) == answers(_fresh_like(kin, build + grasp))
    for step in release:
        step(checker)
    assert checker.geometry_data is data
    assert answers(checker) == before == answers(_fresh_like(kin, build + grasp + release))
    for step in grasp:
        step(checker)
    checker.remove("other")
    assert checker.geometry_data is not data
    assert answers(checker) == answers(_fresh_like(kin, [build[0], build[1], grasp[0]]))
