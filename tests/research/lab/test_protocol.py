"""Participant ids, seeds and parameters are checked at the edge (they name folders and seed plans)."""

from __future__ import annotations

import pytest

from vibsynth.errors import ParameterError
from vibsynth.research.lab.protocol import MAX_SEED, LabParameters, check_participant, check_protocol, check_seed


@pytest.mark.parametrize("good", ["p01", "P-7_b", "a", "9" * 64])
def test_plain_participant_ids_pass(good):
    assert check_participant(good) == good


@pytest.mark.parametrize(
    "bad",
    ["", ".", "..", "../x", "a/b", "a\\b", "/etc", "~root", "a b", "a:b", "x" * 65, "-x", "_x", "p\x00", "é", 7, None],
)
def test_participant_ids_with_path_characters_are_refused(bad):
    with pytest.raises(ParameterError, match="participant id .* is not allowed: use 1-64 letters"):
        check_participant(bad)


@pytest.mark.parametrize(
    "value, expected", [(0, 0), ("42", 42), (" 7 ", 7), (MAX_SEED, MAX_SEED), (str(MAX_SEED), MAX_SEED)]
)
def test_seeds_from_numbers_and_text(value, expected):
    assert check_seed(value) == expected


BAD_SEEDS = [-1, MAX_SEED + 1, 10**5000, "9" * 5000, "1e9", "0x10", "-3", "", True, 1.0, None, "٣"]


@pytest.mark.parametrize("bad", BAD_SEEDS, ids=[f"bad{k}" for k in range(len(BAD_SEEDS))])
def test_huge_negative_and_non_integer_seeds_are_refused_in_one_line(bad):
    with pytest.raises(ParameterError) as err:
        check_seed(bad)
    message = str(err.value)
    assert message.startswith(f"seed must be an integer 0..{MAX_SEED}")
    assert len(message) < 160  # a huge number is not printed back


def test_protocol_names():
    assert check_protocol("dissimilarity") == "dissimilarity"
    with pytest.raises(ParameterError, match="choose one of intensity, dissimilarity, resynthesis"):
        check_protocol("mushra")


def test_parameters_default_to_the_papers():
    p = LabParameters()
    assert (p.stimulus_s, p.gap_s, p.familiarisation_pairs, p.gain_min, p.gain_max) == (1.0, 0.5, 30, 0.2, 5.0)


def test_parameters_from_the_config_section_and_overrides():
    from vibsynth.settings.config import load_config

    lab = load_config(None).settings.lab
    p = LabParameters.from_settings(lab, familiarisation_pairs=0, gap_s=None)
    assert p == LabParameters(familiarisation_pairs=0)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"gain_min": 5.0, "gain_max": 0.2}, "gain_min .* must be below gain_max"),
        ({"stimulus_s": 0.1}, r"stimulus_s must be a number in \[0.5, 10\]"),
        ({"gap_s": float("nan")}, "gap_s must be a number"),
        ({"familiarisation_pairs": -1}, "familiarisation_pairs must be in"),
        ({"familiarisation_pairs": 2.5}, "familiarisation_pairs must be an integer"),
    ],
)
def test_bad_parameters_are_named(kwargs, message):
    with pytest.raises(ParameterError, match=message):
        LabParameters(**kwargs)
