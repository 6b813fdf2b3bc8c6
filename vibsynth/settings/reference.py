"""The key tables of docs/config.md and docs/presets.md, made from the models.

The docs hold them between marker comments::

    <!-- generated: config-reference -->
    ...
    <!-- end generated -->

``python scripts/gen_settings_docs.py`` rewrites them (``--check`` only compares); a test
fails when they drift from the models.
"""

from __future__ import annotations

import re
from typing import Any

from pydantic import BaseModel

from vibsynth.formats.yamlio import dump_yaml
from vibsynth.settings.fields import JsonSchema, describe, resolve
from vibsynth.settings.layouts import LayoutFileModel
from vibsynth.settings.models_clip import ClipModel, KeyframeModel, LoopModel, TransientModel
from vibsynth.settings.models_config import VibsynthConfig
from vibsynth.settings.models_preset import ActuatorProfileModel, PresetModel
from vibsynth.settings.validation import ModelSpec, model_spec

__all__ = ["REFERENCES", "reference_markdown", "replace_generated", "generated_blocks"]

#: Marker name -> the model whose table goes there.
REFERENCES: dict[str, type[BaseModel]] = {
    "config-reference": VibsynthConfig,
    "preset-reference": PresetModel,
    "actuator-reference": ActuatorProfileModel,
    "clip-reference": ClipModel,
    "clip-keyframe-reference": KeyframeModel,
    "clip-transient-reference": TransientModel,
    "clip-loop-reference": LoopModel,
    "layout-reference": LayoutFileModel,
}
_END = "<!-- end generated -->"


def _type(schema: JsonSchema, defs: JsonSchema) -> str:
    schema = resolve(schema, defs)
    names: list[str] = []
    for option in schema.get("anyOf", [schema]):
        option = resolve(option, defs)
        kind = option.get("type")
        kinds = kind if isinstance(kind, list) else [kind]
        for k in kinds:
            word = {"array": "list", "object": "mapping", "null": "null"}.get(str(k), str(k))
            if "enum" in option and k == "string":
                word = "choice"
            if k is not None and word not in names:
                names.append(word)
    return " or ".join(names) or "any"


def _default(value: Any) -> str:
    text = dump_yaml(value, default_flow_style=True, width=10_000).strip()
    return text.removesuffix("...").strip()


def _default_cell(value: Any) -> str:
    return "**required**" if value is Ellipsis else f"`{_cell(_default(value))}`"


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _table(spec: ModelSpec, keys: list[str]) -> list[str]:
    rows = ["| key | type | default | allowed | meaning |", "|---|---|---|---|---|"]
    for key in keys:
        leaf = spec.leaves[key]
        rows.append(
            f"| `{key}` | {_type(leaf.schema, spec.defs)} | {_default_cell(leaf.default)} | "
            f"{_cell(describe(leaf.schema, spec.defs))} | {_cell(leaf.help)} |"
        )
    return rows


def reference_markdown(model: type[BaseModel]) -> str:
    """Markdown tables of every key of ``model``: key, type, default, allowed values, meaning.

    A model with sections (the config) gets one ``###`` heading and table per section.
    """
    spec = model_spec(model)
    if not spec.nested:
        return "\n".join(_table(spec, list(spec.leaves))) + "\n"
    out: list[str] = []
    for name in spec.sections[""]:
        keys = [name] if name in spec.leaves else [k for k in spec.leaves if k.startswith(name + ".")]
        out += [f"### `{name}`", ""]
        doc = model.model_fields[name].description
        if doc and name not in spec.leaves:
            out += [doc[0].upper() + doc[1:] + ".", ""]
        out += [*_table(spec, keys), ""]
    return "\n".join(out).rstrip("\n") + "\n"


def _pattern(name: str) -> re.Pattern[str]:
    return re.compile(rf"(<!-- generated: {re.escape(name)} -->\n)(.*?)({re.escape(_END)})", re.S)


def replace_generated(text: str, name: str, body: str) -> str:
    """``text`` with the block between ``<!-- generated: NAME -->`` and ``<!-- end generated -->`` replaced.

    Raises
    ------
    KeyError
        The markers are missing.
    """
    pattern = _pattern(name)
    if not pattern.search(text):
        raise KeyError(f"no '<!-- generated: {name} -->' ... '{_END}' block")
    return pattern.sub(lambda m: m.group(1) + body + m.group(3), text, count=1)


def generated_blocks(text: str) -> list[str]:
    """Names of the generated blocks in a document."""
    return re.findall(r"<!-- generated: ([\w-]+) -->", text)
