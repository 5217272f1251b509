"""Track names and the error of this package: what a track animates is in its name.

* ``"weights/<shape>"`` — scalar tracks, one per keyed blendshape weight;
* ``"head_pose"`` — a rigid head transform, value ``(7,)`` =
  translation ``(tx, ty, tz)`` in model units + unit quaternion ``(qx, qy, qz, qw)``
  (glTF order). The transform maps a model point ``p`` to ``R(q) p + t``;
  :func:`head_rotation_from_euler` / :func:`head_euler_from_rotation` convert
  yaw/pitch/roll about the model's axes;
* any other name — a method family's own track (``"mouth_gain"``,
  ``"my_family/<level>/<part>"``): a name, or a name under the family's
  prefix; the family registers its value shape and its checks
  (:class:`workbench.core.families.TrackSpec`), the timeline knows only the two
  above.
"""

from __future__ import annotations

from workbench.core.shapes import ModelError

WEIGHTS_PREFIX = "weights/"
HEAD_POSE = "head_pose"


class TrackError(ModelError):
    """A key, track or timeline that cannot be built or edited as asked (or does not fit the model)."""


def weight_track_name(shape: str) -> str:
    """``"weights/<shape>"``: the track name of a blendshape weight."""
    return WEIGHTS_PREFIX + shape
