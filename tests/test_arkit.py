"""ARKit-52 names: canonical spelling, groups, mirroring."""

from __future__ import annotations

import pytest

from workbench.arkit import ARKIT_52, canonical_arkit_name, mirror_name, shape_group


def test_table_is_the_52_apple_names() -> None:
    assert len(ARKIT_52) == 52
    assert len(set(ARKIT_52)) == 52
    # spot checks against Apple's ARFaceAnchor.BlendShapeLocation list
    for name in (
        "eyeBlinkLeft",
        "jawOpen",
        "mouthRollUpper",
        "cheekPuff",
        "tongueOut",
        "noseSneerRight",
    ):
        assert name in ARKIT_52


@pytest.mark.parametrize("name", ARKIT_52)
def test_canonical_names_map_to_themselves(name: str) -> None:
    assert canonical_arkit_name(name) == name


@pytest.mark.parametrize(
    ("variant", "expected"),
    [
        ("EyeBlinkLeft", "eyeBlinkLeft"),  # Live Link Face CSV column
        ("JawOpen", "jawOpen"),
        ("MouthClose", "mouthClose"),
        ("eyeBlink_L", "eyeBlinkLeft"),
        ("eyeBlink_R", "eyeBlinkRight"),
        ("eyeblinkleft", "eyeBlinkLeft"),
        ("EYE_BLINK_L", "eyeBlinkLeft"),
        ("eye_blink_left", "eyeBlinkLeft"),
        ("eye-blink-right", "eyeBlinkRight"),
        ("Blink_Left", "eyeBlinkLeft"),
        ("blink_R", "eyeBlinkRight"),
        ("browDown_R", "browDownRight"),
        ("browOuterUp_L", "browOuterUpLeft"),
        ("eyeLookIn_L", "eyeLookInLeft"),
        ("mouthSmile_L", "mouthSmileLeft"),
        ("Smile_Right", "mouthSmileRight"),
        ("L_eyeBlink", "eyeBlinkLeft"),
        ("LeftEyeBlink", "eyeBlinkLeft"),
        ("blendShape1.eyeBlink_L", "eyeBlinkLeft"),
        ("Face:jawOpen", "jawOpen"),
        ("  jawOpen ", "jawOpen"),
        ("jaw_L", "jawLeft"),
        ("mouth_right", "mouthRight"),
        ("cheekSquint_L", "cheekSquintLeft"),
        ("noseSneer_R", "noseSneerRight"),
        ("TongueOut", "tongueOut"),
    ],
)
def test_variants(variant: str, expected: str) -> None:
    assert canonical_arkit_name(variant) == expected


@pytest.mark.parametrize(
    "name",
    ["", "Left", "L", "HeadYaw", "eyeBlink_X", "smileBig", "browFurrow_L", "jawOpen2", "key 1"],
)
def test_non_arkit_names(name: str) -> None:
    assert canonical_arkit_name(name) is None


@pytest.mark.parametrize(
    ("name", "group"),
    [
        ("browInnerUp", "brows"),
        ("browDown_L", "brows"),
        ("eyeBlinkLeft", "eyes"),
        ("eyeLookUpRight", "eyes"),
        ("eyeSquint_L", "eyes"),
        ("eyeWideRight", "eyes"),
        ("cheekPuff", "cheeks"),
        ("cheekSquintRight", "cheeks"),
        ("noseSneerLeft", "nose"),
        ("mouthSmileLeft", "mouth"),
        ("mouthClose", "mouth"),
        ("MouthRollLower", "mouth"),
        ("jawOpen", "jaw"),
        ("jawForward", "jaw"),
        ("jawLeft", "jaw"),
        ("tongueOut", "tongue"),
        ("Blink_Left", "eyes"),
        ("browFurrow_custom", "brows"),
        ("L_lipBite", "mouth"),
        ("HeadYaw", "other"),
        ("", "other"),
    ],
)
def test_groups(name: str, group: str) -> None:
    assert shape_group(name) == group


def test_every_arkit_name_has_a_region() -> None:
    counts: dict[str, int] = {}
    for n in ARKIT_52:
        counts[shape_group(n)] = counts.get(shape_group(n), 0) + 1
    assert counts == {
        "brows": 5,
        "cheeks": 3,
        "eyes": 14,
        "jaw": 4,
        "mouth": 23,
        "nose": 2,
        "tongue": 1,
    }


@pytest.mark.parametrize(
    ("name", "mirrored"),
    [
        ("eyeBlinkLeft", "eyeBlinkRight"),
        ("EyeBlinkRight", "EyeBlinkLeft"),
        ("eyeBlink_L", "eyeBlink_R"),
        ("eye_blink_left", "eye_blink_right"),
        ("EYE_BLINK_LEFT", "EYE_BLINK_RIGHT"),
        ("L_browRaise", "R_browRaise"),
        ("jawLeft", "jawRight"),
        ("mouthRight", "mouthLeft"),
        ("blendShape1.eyeBlink_L", "blendShape1.eyeBlink_R"),
        ("myWrinkle_r", "myWrinkle_l"),
    ],
)
def test_mirror_keeps_style(name: str, mirrored: str) -> None:
    assert mirror_name(name) == mirrored
    assert mirror_name(mirrored) == name


@pytest.mark.parametrize(
    "name", ["jawOpen", "mouthClose", "cheekPuff", "tongueOut", "Left", "custom"]
)
def test_unsided_names_have_no_mirror(name: str) -> None:
    assert mirror_name(name) is None


def test_mirror_of_every_sided_arkit_name_is_arkit() -> None:
    sided = [n for n in ARKIT_52 if mirror_name(n) is not None]
    assert len(sided) == 40  # 52 minus 12 centre shapes
    for n in sided:
        m = mirror_name(n)
        assert m in ARKIT_52 and m != n
        assert shape_group(m) == shape_group(n)
