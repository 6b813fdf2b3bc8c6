"""The Unity example (clients/csharp/Unity/VibsynthContactSource.cs), compiled with mcs against a
minimal UnityEngine shim (tests/clients/csharp/UnityEngineShim.cs: only the types it uses, with
Unity's names and signatures) so that a typo cannot ship, and driven as Unity would call it
(OnEnable, collision messages, OnDisable) with its datagrams captured on a local UDP socket.
Against a real server: tests/e2e/test_csharp_client.py.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.clients.mono import UNITY_EXAMPLE, UNITY_SHIM, build_unity_check, run_mono


@pytest.fixture(scope="module")
def unity_check(tmp_path_factory) -> Path:
    return build_unity_check(tmp_path_factory.mktemp("unity"))


def _message(text: str) -> tuple[str, str, list[object]]:
    """``/a fff 1 2 3`` (the C# OscMessage.ToString form) -> (address, tags, values)."""
    address, tags, *values = text.split(" ")
    parsed: list[object] = []
    for tag, value in zip(tags, values):
        parsed.append(float(value) if tag == "f" else int(value) if tag == "i" else value.strip('"'))
    return address, tags, parsed


def test_the_example_compiles_against_the_unity_shim_and_the_shim_is_minimal(unity_check):
    """(The fixture compiled it, warnings as errors.) The shim declares only what the example uses,
    so passing here says nothing about Unity APIs the example does not call."""
    shim = UNITY_SHIM.read_text(encoding="utf-8")
    example = UNITY_EXAMPLE.read_text(encoding="utf-8")
    declared = set(re.findall(r"public (?:sealed |static |abstract |partial )*(?:class|struct) (\w+)", shim))
    # base classes of what the example names, and the type GetContact returns
    implied = {"Object", "Component", "Behaviour", "PropertyAttribute", "ContactPoint"}
    assert implied <= declared
    for name in sorted(declared - implied):
        assert re.search(rf"\b{name.removesuffix('Attribute')}\b", example), f"the shim declares {name}, unused"


def test_a_contact_becomes_a_source_that_follows_it_and_turns_off(unity_check):
    seen = run_mono(unity_check, "listen")
    packets = [seen[f"packet{i}"] for i in range(int(seen["packets"]))]
    # the first contact: the mean of its two points, in the layout's frame (origin at (1, 0, 2)),
    # with the inspector's knobs, radius and law, turned on, as one bundle
    first = [_message(m) for m in packets[0].split(" | ")]
    assert first[0] == ("/vibsynth/source/3/speed", "i", [0])  # intensityFromSpeed off in this scene
    first = first[1:]
    assert [(a, t) for a, t, _ in first] == [
        ("/vibsynth/source/3/pos", "fff"),
        ("/vibsynth/source/3/texture", "ff"),
        ("/vibsynth/source/3/radius", "f"),
        ("/vibsynth/source/3/rolloff", "s"),
        ("/vibsynth/source/3/on", "i"),
    ]
    assert first[0][2] == pytest.approx([0.010, 0.0, 0.020], abs=1e-6)
    assert first[1][2] == pytest.approx([0.7, -1.0])
    assert first[2][2] == pytest.approx([0.04])
    assert first[3][2] == ["phantom"] and first[4][2] == [1]
    # sliding: 10 physics steps at 200 Hz, positions sent at most 100 Hz (every other step)
    slides = [_message(p) for p in packets[1:6]]
    assert [a for a, _, _ in slides] == ["/vibsynth/source/3/pos"] * 5
    assert [v[0] for _, _, v in slides] == pytest.approx([0.013, 0.016, 0.019, 0.022, 0.025], abs=1e-6)
    assert float(seen["speed_mps"]) == pytest.approx(0.3, rel=1e-3)  # 1.5 mm per 5 ms
    assert [float(v) for v in seen["position"].split(",")] == pytest.approx([0.025, 0.0, 0.02], abs=1e-6)
    # a second collider moves the source to it; the source stays on until the last contact ends
    assert _message(packets[6]) == ("/vibsynth/source/3/pos", "fff", pytest.approx([0.05, 0.0, 0.05], abs=1e-6))
    assert seen["touching.after_one_exit"] == "true"
    assert packets[7] == "/vibsynth/source/3/on i 0"
    assert seen["touching.after_both"] == "false" and float(seen["speed_after"]) == 0.0
    assert len(packets) == 8  # nothing else: no message per physics step beyond the rate
    assert seen["client_after_disable"] == "null"
    assert seen["warnings"] == "0"
