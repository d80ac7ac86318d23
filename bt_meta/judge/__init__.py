"""The judge: whether a run really did its task, read from the simulator's true state -- shared by demo and campaigns.

It imports neither the demo, the campaigns, the repair plugins nor the meta-reasoner, so what it decides does not
share the defendant's code (tests/test_import_rules.py checks this). Modules:

* :mod:`bt_meta.judge.noise` -- the seeded start-pose noise every demo run, demonstration and episode starts from
* :mod:`bt_meta.judge.checks` -- the geometric check kinds (held, lifted, attached, inserted, at, on a face)
* :mod:`bt_meta.judge.success` -- a task's success check: its goal mapped to checks, plus a family file's extras
"""
