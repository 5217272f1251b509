"""Performance enhancement (Bermano et al. 2014): data-driven retiming of key pairs (§6).

* :func:`retime` / :class:`RetimeResult` — sequence projection (eq. 5–6) and
  temporally driven interpolation (§6.2) (:mod:`.retime`);
* ``model.enhance.retime(t0, t1, takes)`` — *Retime from performance* on the
  timeline, one undo step (:mod:`.facet`, registered by :mod:`.family`).
"""

from workbench.enhance.retime import RetimeResult, retime

__all__ = ["RetimeResult", "retime"]
