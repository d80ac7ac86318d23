"""What the reference engine and the generated fast path (:mod:`bt_meta.htn.codegen`) share.

Offers:

* :data:`IN_PROGRESS` -- the memo value of a derived atom whose top-down proof is under way (the reference
  prover :class:`~bt_meta.htn.axioms.AxiomSet` writes it, generated code reads it in the inherited memo)
* :class:`Unsupported` -- the generator does not handle a condition; the caller keeps the reference matcher

Why a module of its own: the axiom evaluator builds generated code, conditions ask for it and generated code reads
the axiom memo; with these two names here, :mod:`~bt_meta.htn.codegen` needs neither :mod:`~bt_meta.htn.axioms`
nor is needed by :mod:`~bt_meta.htn.conditions` at import time, so the three import no circle.
"""

from __future__ import annotations

IN_PROGRESS = object()


class Unsupported(Exception):
    """The generator does not handle this condition; the reference matcher is used instead."""
