"""The strict JSON reader: finite numbers only, no duplicate keys, bounded size, depth and count."""

from __future__ import annotations

import pytest

from vibsynth.errors import ClipError
from vibsynth.formats.jsonio import JsonFields, json_path, json_shape, load_json, parse_json


def parse(text: str, **caps):
    return parse_json(text, "x.json", error=ClipError, **caps)


def test_plain_json_parses():
    assert parse('{"a": [1, 2.5, "x", null, true]}') == {"a": [1, 2.5, "x", None, True]}


@pytest.mark.parametrize(
    "text, message",
    [
        ('{"t": NaN}', "x.json: NaN is not a number vibsynth accepts"),
        ('{"t": Infinity}', "x.json: Infinity is not a number"),
        ('{"t": -Infinity}', "x.json: -Infinity is not a number"),
        ('{"t": 1e999}', "x.json: 1e999 is too large"),
        ('{"t": 1' + "0" * 30 + "}", "is too large"),
        ('{"t": 1, "t": 2}', "x.json: key 't' appears twice in one object"),
        ('{"t": [1, 2', "x.json:1:12: not valid JSON"),
        ('{"t": [1, 2', "the file ends too early (truncated?)"),
        ('{"t": 1,, }', "x.json:1:9: not valid JSON (Expecting property name"),
        ("[" * 40 + "]" * 40, "x.json: nested more than 32 levels deep"),
        ("[" * 100_000 + "]" * 100_000, "x.json: nested more than 32 levels deep"),
    ],
)
def test_refused_documents_get_one_line_naming_the_file(text, message):
    with pytest.raises(ClipError) as info:
        parse(text)
    assert message in str(info.value) and "\n" not in str(info.value)


def test_truncation_is_not_claimed_for_an_error_in_the_middle():
    with pytest.raises(ClipError) as info:
        parse('{"a": 1 "b": 2}')
    assert "truncated" not in str(info.value)


def test_value_count_is_capped():
    with pytest.raises(ClipError, match=r"more than 100 values"):
        parse("[" + ",".join(["0"] * 200) + "]", max_values=100)


def test_file_size_is_checked_before_reading(tmp_path):
    big = tmp_path / "big.json"
    big.write_text("[" + "0," * 600 + "0]")
    with pytest.raises(ClipError, match=r"big.json: 1,203 bytes, over the 1 KiB limit for a test file; not read"):
        load_json(big, error=ClipError, what="a test file", max_bytes=1024)
    with pytest.raises(ClipError, match=r"no such file"):
        load_json(tmp_path / "none.json", error=ClipError, what="a test file", max_bytes=1024)


def test_paths_and_fields():
    assert json_path(("Pattern", 3, "Event", "Time")) == "Pattern[3].Event.Time"
    assert json_shape(("Pattern", 3, "Event", "Foo")) == "Pattern[].Event.Foo"
    fields = JsonFields("x.json", {(): {"a"}, ("a",): {"b"}}, ClipError)
    doc = fields.mapping({"a": [{"b": 1, "c": 2}], "z": 0}, ())
    fields.mapping(doc["a"][0], ("a", 0))
    assert fields.unknown == ["z", "a[].c"]
    with pytest.raises(ClipError, match=r"^x.json: a\[0\].b = true: must be a number$"):
        fields.number(True, ("a", 0, "b"))
    with pytest.raises(ClipError, match=r"^x.json: a\[0\].b = 7: outside the allowed range \[0, 1\]$"):
        fields.number(7, ("a", 0, "b"), 0, 1)
    with pytest.raises(ClipError, match=r"^x.json: a: must be an object, got a list$"):
        fields.mapping([], ("a",))
    with pytest.raises(ClipError, match=r"^x.json: a\[0\]: missing key 'q'$"):
        fields.require({}, "q", ("a", 0))
