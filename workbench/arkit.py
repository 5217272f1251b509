"""ARKit-52 blendshape names: canonical spelling, grouping and left/right mirroring.

Face rigs name the same 52 expressions in many styles: Apple's ``eyeBlinkLeft``,
Live Link Face CSV columns ``EyeBlinkLeft``, Maya/Blender rigs ``eyeBlink_L``,
``eye_blink_left``, ``EYE_BLINK_L``, namespaced ``blendShape1.eyeBlink_L`` and
short forms such as ``Blink_Left``. This module maps all of them onto Apple's
spelling so presets, retargeting and mirroring can match shapes by meaning.

Left and right always mean the *subject's* left and right (the MakeHuman sample
puts the subject's left at +x), as in Apple's ARKit documentation.

Hand-written because no kept dependency knows these names; the table is the
public ARKit list and the parser is a small tokenizer.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence

__all__ = ["ARKIT_52", "canonical_arkit_name", "mirror_name", "shape_group"]

ARKIT_52: tuple[str, ...] = (
    "browDownLeft",
    "browDownRight",
    "browInnerUp",
    "browOuterUpLeft",
    "browOuterUpRight",
    "cheekPuff",
    "cheekSquintLeft",
    "cheekSquintRight",
    "eyeBlinkLeft",
    "eyeBlinkRight",
    "eyeLookDownLeft",
    "eyeLookDownRight",
    "eyeLookInLeft",
    "eyeLookInRight",
    "eyeLookOutLeft",
    "eyeLookOutRight",
    "eyeLookUpLeft",
    "eyeLookUpRight",
    "eyeSquintLeft",
    "eyeSquintRight",
    "eyeWideLeft",
    "eyeWideRight",
    "jawForward",
    "jawLeft",
    "jawOpen",
    "jawRight",
    "mouthClose",
    "mouthDimpleLeft",
    "mouthDimpleRight",
    "mouthFrownLeft",
    "mouthFrownRight",
    "mouthFunnel",
    "mouthLeft",
    "mouthLowerDownLeft",
    "mouthLowerDownRight",
    "mouthPressLeft",
    "mouthPressRight",
    "mouthPucker",
    "mouthRight",
    "mouthRollLower",
    "mouthRollUpper",
    "mouthShrugLower",
    "mouthShrugUpper",
    "mouthSmileLeft",
    "mouthSmileRight",
    "mouthStretchLeft",
    "mouthStretchRight",
    "mouthUpperUpLeft",
    "mouthUpperUpRight",
    "noseSneerLeft",
    "noseSneerRight",
    "tongueOut",
)

# lower-case, separator-free key -> canonical name ("eyeblinkleft" -> "eyeBlinkLeft")
_BY_KEY: dict[str, str] = {n.lower(): n for n in ARKIT_52}

# Short stems used by hand-made rigs, mapped to the ARKit stem (side added separately).
# Only unambiguous ones: "squint" alone is taken as the eye squint (cheekSquint is
# always spelled out), "smile"/"frown" as the mouth corners.
_ALIASES: dict[str, str] = {
    "blink": "eyeblink",
    "eyeclosed": "eyeblink",
    "eyeclose": "eyeblink",
    "squint": "eyesquint",
    "smile": "mouthsmile",
    "frown": "mouthfrown",
    "dimple": "mouthdimple",
    "sneer": "nosesneer",
    "pucker": "mouthpucker",
    "funnel": "mouthfunnel",
    "puff": "cheekpuff",
    "mouthopen": "jawopen",
    "tongue": "tongueout",
}

_GROUP_OF_PREFIX: tuple[tuple[str, str], ...] = (
    ("brow", "brows"),
    ("eye", "eyes"),
    ("cheek", "cheeks"),
    ("nose", "nose"),
    ("mouth", "mouth"),
    ("lip", "mouth"),
    ("jaw", "jaw"),
    ("tongue", "tongue"),
)

# Tokens: upper-case runs not followed by lower case ("EYE", the "L" in "BlinkL"),
# capitalised or lower-case words, digit runs. Anything else separates tokens.
_TOKEN = re.compile(r"[A-Z]+(?![a-z])|[A-Z]?[a-z]+|\d+")
_LEFT = {"l", "left", "lf", "lft"}
_RIGHT = {"r", "right", "rt", "rgt"}


def _strip_namespace(name: str) -> str:
    # "blendShape1.eyeBlink_L", "Face:eyeBlink_L", "Geo|eyeBlink_L" -> last part
    return re.split(r"[.:|/]", name.strip())[-1]


def _tokens(name: str) -> list[re.Match[str]]:
    return list(_TOKEN.finditer(_strip_namespace(name)))


def _side_token(tokens: list[re.Match[str]]) -> tuple[int, str] | None:
    """Index and side ("left"/"right") of the token naming a side, if any.

    The side is the last token ("eyeBlink_L", "EyeBlinkLeft") or, failing that,
    the first one ("L_eyeBlink", "LeftEyeBlink"); a name that is nothing but a
    side ("Left") has no side.
    """
    if len(tokens) < 2:
        return None
    for i in (len(tokens) - 1, 0):
        t = tokens[i].group().lower()
        if t in _LEFT:
            return i, "left"
        if t in _RIGHT:
            return i, "right"
    return None


def canonical_arkit_name(name: str) -> str | None:
    """Apple's spelling of an ARKit-52 shape name, or None if ``name`` is not one.

    Parameters
    ----------
    name : str
        Any common spelling: "eyeBlinkLeft", "EyeBlinkLeft", "eyeBlink_L",
        "eye_blink_left", "EYE_BLINK_L", "Blink_Left", "blendShape1.jawOpen".

    Returns
    -------
    str or None
        e.g. "eyeBlinkLeft"; None for names outside the ARKit set.
    """
    if not isinstance(name, str):
        return None
    tokens = _tokens(name)
    if not tokens:
        return None
    side = _side_token(tokens)
    words = [t.group().lower() for k, t in enumerate(tokens) if side is None or k != side[0]]
    stem = "".join(words)
    stem = _ALIASES.get(stem, stem)
    key = stem + (side[1] if side else "")
    return _BY_KEY.get(key)


def shape_group(name: str) -> str:
    """Face region a shape belongs to, for grouping sliders.

    Returns one of "brows", "eyes", "cheeks", "nose", "mouth", "jaw", "tongue",
    "other". ARKit names are grouped by their prefix; other names by their first
    word when it names a region ("browFurrow_custom" -> "brows").
    """
    canon = canonical_arkit_name(name)
    if canon is not None:
        first = _TOKEN.match(canon)
        word = first.group().lower() if first else ""
    else:
        tokens = _tokens(name)
        side = _side_token(tokens)
        words = [t.group().lower() for k, t in enumerate(tokens) if side is None or k != side[0]]
        word = words[0] if words else ""
    for prefix, group in _GROUP_OF_PREFIX:
        if word.startswith(prefix):
            return group
    return "other"


def _swap_case_like(token: str, replacement: str) -> str:
    if token.isupper():
        return replacement.upper()
    if token[0].isupper():
        return replacement[0].upper() + replacement[1:]
    return replacement


_SWAP = {
    "l": "r",
    "r": "l",
    "left": "right",
    "right": "left",
    "lf": "rt",
    "rt": "lf",
    "lft": "rgt",
    "rgt": "lft",
}


def mirror_name(name: str) -> str | None:
    """Left/right counterpart of a shape name, in the same naming style.

    Works for any name with a side token, ARKit or not:
    "eyeBlink_L" -> "eyeBlink_R", "EyeBlinkLeft" -> "EyeBlinkRight",
    "eye_blink_left" -> "eye_blink_right", "L_browRaise" -> "R_browRaise",
    "jawLeft" -> "jawRight". Names without a side ("jawOpen") give None.
    """
    if not isinstance(name, str):
        return None
    tokens = _tokens(name)
    side = _side_token(tokens)
    if side is None:
        return None
    m = tokens[side[0]]
    # token positions are relative to the namespace-stripped tail of the name
    offset = len(name) - len(name.lstrip()) + len(name.strip()) - len(_strip_namespace(name))
    start, end = m.start() + offset, m.end() + offset
    tok = m.group()
    return name[:start] + _swap_case_like(tok, _SWAP[tok.lower()]) + name[end:]


def split_half_of(name: str) -> tuple[str, str] | None:
    """``(ARKit name, side)`` when ``name`` is one side of a split symmetric ARKit shape.

    Rigs often split the unsided ARKit shapes into halves: "browInnerUp_L" /
    "browInnerUp_R", "CheekPuffLeft", "jawOpen.R". Returns e.g.
    ``("browInnerUp", "left")``; None for whole shapes and for sided ARKit
    shapes ("eyeBlink_L" is eyeBlinkLeft itself, not a half).
    """
    if not isinstance(name, str) or canonical_arkit_name(name) is not None:
        return None
    tokens = _tokens(name)
    side = _side_token(tokens)
    if side is None:
        return None
    stem = "".join(t.group().lower() for k, t in enumerate(tokens) if k != side[0])
    whole = _BY_KEY.get(_ALIASES.get(stem, stem))
    if whole is None or whole.endswith(("Left", "Right")):
        return None
    return whole, side[1]


def rig_weights(
    arkit_weights: Mapping[str, float], shape_names: Sequence[str]
) -> tuple[dict[str, float], list[str]]:
    """ARKit-named weights expressed on a rig's own shapes.

    Parameters
    ----------
    arkit_weights : mapping
        Weights by ARKit name (or any spelling :func:`canonical_arkit_name` reads).
    shape_names : sequence of str
        The rig's shapes.

    Returns
    -------
    weights : dict
        On the rig's names: a shape spelled otherwise ("mouthSmile_L") gets its
        ARKit weight; the halves of a split shape ("browInnerUp_L" and "_R")
        both get the whole shape's weight, since split halves sum to the whole;
        a rig's unsplit shape ("mouthSmile") standing for an ARKit left/right
        pair gets the mean of the pair.
    missing : list of str
        ARKit names with a non-zero weight that the rig has no counterpart for
        (a rig without a tongue has no ``tongueOut``).
    """
    by_canon: dict[str, list[str]] = {}
    halves: dict[str, list[str]] = {}
    unsided: dict[str, list[str]] = {}
    for n in shape_names:
        c = canonical_arkit_name(n)
        if c is not None:
            by_canon.setdefault(c, []).append(n)
            continue
        h = split_half_of(n)
        if h is not None:
            halves.setdefault(h[0], []).append(n)
            continue
        key = "".join(t.group().lower() for t in _tokens(n))
        key = _ALIASES.get(key, key)
        if _BY_KEY.get(key + "left") is not None:  # "mouthSmile": both ARKit sides in one shape
            unsided.setdefault(_BY_KEY[key + "left"][: -len("Left")], []).append(n)
    out: dict[str, float] = {}
    missing: list[str] = []
    pairs: dict[str, list[float]] = {}
    for name, w in arkit_weights.items():
        c = canonical_arkit_name(name) or name
        if c in by_canon:
            for n in by_canon[c]:
                out[n] = float(w)
        elif c in halves:
            for n in halves[c]:
                out[n] = float(w)
        elif c.endswith(("Left", "Right")) and c.removesuffix("Left").removesuffix("Right") in unsided:
            pairs.setdefault(c.removesuffix("Left").removesuffix("Right"), []).append(float(w))
        elif w:
            missing.append(c)
    for stem, ws in pairs.items():
        for n in unsided[stem]:
            out[n] = sum(ws) / 2.0
    return out, missing
