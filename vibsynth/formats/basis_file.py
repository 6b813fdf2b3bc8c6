"""Basis files: the spectral basis (M, V1..V8) as YAML, and the basis shipped with the package."""

from __future__ import annotations

import os
from importlib import resources
from typing import TYPE_CHECKING, Any

from vibsynth.errors import InputError, ParameterError
from vibsynth.formats.files import MAX_BASIS_BYTES, atomic_write
from vibsynth.formats.yamlio import dump_yaml, load_yaml

if TYPE_CHECKING:  # the DSP layer and scipy load lazily: config reads YAML through here
    from vibsynth.dsp.basis import Basis

DEFAULT_BASIS_RESOURCE = "default_basis.yaml"


_BASIS_HEADER = """\
# vibsynth spectral basis: mean spectrum M and principal components V1..V8
# of level-normalised 30-band dB spectra (see docs/science.md).
# Written by `vibsynth basis fit`; numbers rounded to 8 decimals.
"""


def save_basis(basis: Basis, path: str | os.PathLike[str]) -> None:
    """Write a basis as YAML, atomically.

    Raises
    ------
    InputError
        The file cannot be written (the message names it).
    """
    text = _BASIS_HEADER + dump_yaml(basis.to_dict(), sort_keys=False, width=120, default_flow_style=None)
    try:
        atomic_write(path, text)
    except OSError as exc:
        raise InputError(f"{path}: {exc.strerror}") from None


def load_basis(path: str | os.PathLike[str]) -> Basis:
    """Read a basis YAML file (at most :data:`MAX_BASIS_BYTES`; see :func:`load_yaml`).

    Raises
    ------
    InputError
        Missing or oversized file, YAML syntax error, alias, or invalid basis (the message names the file).
    """
    loaded = load_yaml(path, error=InputError, what="a basis file", max_bytes=MAX_BASIS_BYTES)
    return _basis_from_data(loaded.data, loaded.origin)


def _basis_from_data(data: Any, name: str) -> Basis:
    from vibsynth.dsp.basis import Basis

    if not isinstance(data, dict):
        raise InputError(f"{name}: expected a mapping of basis fields")
    try:
        return Basis.from_dict(data)
    except ParameterError as exc:
        raise InputError(f"{name}: {exc}") from None


_DEFAULT_BASIS: Basis | None = None


def default_basis() -> Basis:
    """The basis shipped with the package (fitted from the HaTT spectra; cached)."""
    global _DEFAULT_BASIS
    if _DEFAULT_BASIS is None:
        text = resources.files("vibsynth.data").joinpath(DEFAULT_BASIS_RESOURCE).read_text(encoding="utf-8")
        name = f"vibsynth/data/{DEFAULT_BASIS_RESOURCE}"
        loaded = load_yaml(text=text, origin=name, what="a basis file", max_bytes=MAX_BASIS_BYTES)
        _DEFAULT_BASIS = _basis_from_data(loaded.data, name)
    return _DEFAULT_BASIS
