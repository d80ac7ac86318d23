"""Campaigns: generated populations of scene variants run under plugin configurations and seeds, with intervals.

A campaign directory holds the generated variant scene files, a manifest (``campaign.json``: version, family,
seed, spec, every variant with its expected outcome), the demonstration memory recorded once for the campaign and
the campaign database (``campaign.sqlite``: one row per finished episode, written only by the driver).

Modules (one concept each):

* :mod:`bt_meta.campaign.families` -- family files: task file, problem, scene, demonstrations, perturbations, checks
* :mod:`bt_meta.campaign.spec` -- the declarative perturbation spec and its loader (located errors)
* :mod:`bt_meta.campaign.generator` -- draws variants from a spec with a seed, writes scene files + manifest
* :mod:`bt_meta.campaign.labeller` -- the expected outcome of a variant, decided from ground truth
* :mod:`bt_meta.campaign.manifest` -- reading / writing / checking a campaign directory
* :mod:`bt_meta.campaign.database` -- the campaign SQLite database (resume, no episode counted twice)
* :mod:`bt_meta.campaign.episode` -- one episode (variant x configuration x seed) in a fresh world
* :mod:`bt_meta.campaign.runner` -- the driver: local process pool or Ray, progress bar, resume
* :mod:`bt_meta.campaign.stats` -- Wilson intervals and the per-outcome x configuration tables
* :mod:`bt_meta.campaign.report` -- ``campaign report``: JSON and HTML with matplotlib plots (:mod:`bt_meta.plotting`)
* :mod:`bt_meta.campaign.ablation` -- the paper's ablation as campaigns (``experiment ablation --generated``)
"""

CAMPAIGN_VERSION = 2
"""Bumped whenever the layout of a campaign directory or the meaning of its rows changes: a directory of another
version is refused, never mixed."""

__all__ = ["CAMPAIGN_VERSION"]
