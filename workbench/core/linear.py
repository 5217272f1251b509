"""What a layer says about itself: linear in the timeline's keys or not, and its linear terms.

Exporters write a linear layer as morph targets and the viewport's GPU path
evaluates it in the browser; anything else is baked per frame (exporters) or
carried in the residual (GPU). They learn which is which by asking the layers,
never by naming families. A layer that is linear (``linear = True``) describes
its displacement ``d`` on the mesh ``below`` it (``neutral`` = the rest mesh)
as::

    below + d = neutral + gain ⊙ (below − neutral) + constant + apply(u(t))

* ``gain(view)`` — (n,) the share of the motion below it that each vertex keeps
  (painted expressions keep ``1 − Σ W``; the region blend keeps its background);
  ``None`` for 1 everywhere. A layer whose ``gain`` holds only for the blend (it
  reads the weights, not the mesh below: the region blend) sets the class
  attribute ``gain_scales = "blend"``; it is then linear only while no layer
  below it adds anything;
* ``constant`` — (n, 3) a displacement that does not change while the keyed
  quantities play;
* :class:`Controls` — the layer's own keyed parameters ``u`` (handle offsets),
  with ``apply`` linear in them and the timeline track that keys them
  (``controls(view, timeline)``; a layer with controls may also give the GPU
  path a basis: ``control_basis(view) -> (B (n, P) float32, columns (m,) int)``,
  ``apply(u) = B @ (mean of u over each column)``).

:func:`decompose` composes the description of every layer of a pipeline, in
order, into what the consumers need: the per-vertex factor of the shape deltas,
one constant, the factor of each controls layer, and which layers must be baked
(with the factor the linear layers above them apply to them). Written here
because no library describes a deformation stack this way; the algebra is the
usual one for affine maps applied in sequence.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from workbench.core.pipeline import Layer, StateView

__all__ = ["Controls", "Decomposition", "LinearLayer", "LinearTerms", "decompose", "is_linear"]


@dataclass(frozen=True)
class Controls:
    """A layer's keyed linear parameters ``u`` (m, 3): its displacement is ``apply(u)``.

    Parameters
    ----------
    values : (m, 3) float64
        ``u`` now (used when the timeline does not key them).
    track : Track or None
        The timeline track keying ``u`` (values (K, 3m)), None when not keyed.
    apply : callable
        ``apply(u (m, 3) float64) -> (n, 3) float64``, linear.
    label : str
        What they are, for reports (``"3 handle offsets"``).
    prefix : str
        Exporters name their morph targets ``"<prefix>:basis<i>"``.
    """

    values: NDArray[np.float64]
    track: Any
    apply: Callable[[NDArray[np.float64]], NDArray[np.float64]]
    label: str = "controls"
    prefix: str = "controls"


@dataclass(frozen=True)
class LinearTerms:
    """One linear layer's terms for one state and timeline (see the module docstring).

    ``baked`` non-empty: under this timeline the layer is not linear in the keys
    (e.g. region weights are keyed) and is baked per frame, for that reason.
    ``detail`` says what the terms are, for the export report.
    """

    gain: NDArray[np.float64] | None = None
    constant: NDArray[np.float64] | None = None
    controls: Controls | None = None
    detail: str = ""
    baked: str = ""

    @property
    def empty(self) -> bool:
        """True when the layer adds nothing (no gain, constant or controls)."""
        return self.gain is None and self.constant is None and self.controls is None


@runtime_checkable
class LinearLayer(Protocol):
    """A :class:`~workbench.core.pipeline.Layer` with ``linear = True`` that describes its terms."""

    name: str
    linear: bool

    def gain(self, view: StateView) -> NDArray[np.float64] | None:
        """(n,) float64 share of the motion below kept at each vertex (None: 1 everywhere). Cheap."""
        ...

    def linear_terms(self, view: StateView, timeline: Any) -> LinearTerms:
        """Gain, constant and controls for ``view`` played under ``timeline``."""
        ...

    def controls(self, view: StateView, timeline: Any) -> Controls | None:
        """The layer's keyed linear parameters (None: it has none). Cheap."""
        ...


def is_linear(layer: Layer) -> bool:
    """True when ``layer`` says it is linear and describes its terms (:class:`LinearLayer`)."""
    return bool(getattr(layer, "linear", False)) and isinstance(layer, LinearLayer)


@dataclass
class Decomposition:
    """Every layer of a pipeline as linear terms and baked layers, composed (see :func:`decompose`).

    The mesh before the head pose is exactly::

        neutral + shape_gain ⊙ Σ_k g_k Δ_k + constant
                + Σ_c gain_c ⊙ apply_c(u_c(t)) + Σ_b gain_b ⊙ d_b(t)

    over the controls layers ``c`` and the baked layers ``b`` (their own
    displacement ``d_b``, evaluated per frame).
    """

    shape_gain: NDArray[np.float64]
    constant: NDArray[np.float64]
    #: (layer name, controls, gain): in pipeline order
    controls: list[tuple[str, Controls, NDArray[np.float64]]] = field(default_factory=list)
    #: (layer name, gain, reason): in pipeline order
    baked: list[tuple[str, NDArray[np.float64], str]] = field(default_factory=list)
    #: name -> LinearTerms of every linear layer
    terms: dict[str, LinearTerms] = field(default_factory=dict)
    has_constant: bool = False


def decompose(layers: Sequence[Layer], view: StateView, timeline: Any, *, n: int,
              constants: bool = True, skip: Callable[[Layer], bool] | None = None) -> Decomposition:
    """Compose the layers' descriptions, in pipeline order, into one :class:`Decomposition`.

    Parameters
    ----------
    layers : sequence of Layer
        The pipeline's layers, in order.
    view : StateView
    timeline : Timeline or None
        What plays (``None``: nothing keyed; the GPU path asks per state).
    n : int
        Number of vertices.
    constants : bool
        False: only gains and controls (the GPU path, whose residual carries the
        constants); then layers are asked only for ``gain`` and, for controls,
        ``linear_terms``.
    skip : callable, optional
        ``skip(layer) -> True`` leaves a layer out entirely (it adds nothing here).

    A linear layer scales everything below it by its gain: the shape factor,
    the constant, the controls and baked layers below it. A layer with
    ``gain_scales = "blend"`` above another contributing layer cannot say that;
    it is baked instead.
    """
    shape_gain = np.ones(n, np.float64)
    constant = np.zeros((n, 3), np.float64)
    out = Decomposition(shape_gain, constant)
    below_blend = False  # a layer below contributes (a "blend"-only gain would not scale it)
    for layer in layers:
        if skip is not None and skip(layer):
            continue
        if not is_linear(layer):
            out.baked.append((layer.name, np.ones(n, np.float64), "not linear in the keyed weights/offsets"))
            below_blend = True
            continue
        lin: Any = layer
        if constants:
            terms = lin.linear_terms(view, timeline)
        else:
            terms = LinearTerms(gain=lin.gain(view), controls=lin.controls(view, timeline))
        blend_only = getattr(layer, "gain_scales", "below") == "blend"
        if blend_only and below_blend and not terms.empty:
            terms = LinearTerms(baked=f"its gain holds for the blend only, and layers below it "
                                      f"({[nm for nm, *_ in out.controls + out.baked]}) add to the mesh")
        out.terms[layer.name] = terms
        if terms.baked:
            out.baked.append((layer.name, np.ones(n, np.float64), terms.baked))
            below_blend = True
            continue
        if terms.gain is not None:
            g = np.asarray(terms.gain, np.float64).reshape(n)
            out.shape_gain = out.shape_gain * g
            out.constant = out.constant * g[:, None]
            for i, (nm, c, cg) in enumerate(out.controls):
                out.controls[i] = (nm, c, cg * g)
            for i, (nm, bg, why) in enumerate(out.baked):
                out.baked[i] = (nm, bg * g, why)
        if terms.constant is not None:
            out.constant = out.constant + np.asarray(terms.constant, np.float64).reshape(n, 3)
            out.has_constant = True
        if terms.controls is not None:
            out.controls.append((layer.name, terms.controls, np.ones(n, np.float64)))
        below_blend = below_blend or not terms.empty
    return out
