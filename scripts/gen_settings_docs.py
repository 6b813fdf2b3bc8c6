#!/usr/bin/env python3
"""Regenerate what is made from the settings models: the key tables of the docs and the JSON Schemas.

* ``docs/config.md``: between ``<!-- generated: config-reference -->`` / ``actuator-reference`` / ``layout-reference``
  and ``<!-- end generated -->``;
* ``docs/presets.md``: between ``<!-- generated: preset-reference -->`` and ``<!-- end generated -->``;
* ``docs/clips.md``: ``clip-reference``, ``clip-keyframe-reference``, ``clip-transient-reference``,
  ``clip-loop-reference``;
* ``vibsynth/data/schema/{config,preset,actuator,clip,layout}.schema.json``.

Usage::

    python scripts/gen_settings_docs.py           # rewrite the files
    python scripts/gen_settings_docs.py --check   # exit 1 if a file differs (tests/settings/test_generated.py)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from vibsynth.settings.reference import REFERENCES, reference_markdown, replace_generated  # noqa: E402
from vibsynth.settings.schema import SCHEMAS, schema_text  # noqa: E402

#: Document -> the generated blocks it holds.
DOCS = {
    Path("docs/config.md"): ("config-reference", "actuator-reference", "layout-reference"),
    Path("docs/presets.md"): ("preset-reference",),
    Path("docs/clips.md"): (
        "clip-reference",
        "clip-keyframe-reference",
        "clip-transient-reference",
        "clip-loop-reference",
    ),
}


def expected(root: Path = ROOT) -> dict[Path, str]:
    """Every generated file (relative path) and the text it must have."""
    out: dict[Path, str] = {}
    for doc, blocks in DOCS.items():
        text = (root / doc).read_text(encoding="utf-8")
        for name in blocks:
            text = replace_generated(text, name, reference_markdown(REFERENCES[name]))
        out[doc] = text
    for name in SCHEMAS:
        out[Path(f"vibsynth/data/schema/{name}.schema.json")] = schema_text(name)
    return out


def stale(root: Path = ROOT) -> list[Path]:
    """Generated files that differ from what the models give."""
    return [
        path
        for path, text in expected(root).items()
        if not (root / path).is_file() or (root / path).read_text(encoding="utf-8") != text
    ]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="only compare; exit 1 when a file is out of date")
    args = parser.parse_args(argv)
    if args.check:
        drifted = stale()
        for path in drifted:
            print(f"{path}: out of date; run: python scripts/gen_settings_docs.py", file=sys.stderr)
        return 1 if drifted else 0
    for path, text in expected().items():
        target = ROOT / path
        if not target.is_file() or target.read_text(encoding="utf-8") != text:
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(text, encoding="utf-8")
            print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
