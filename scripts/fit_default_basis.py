#!/usr/bin/env python3
"""Regenerate the shipped default basis from shared/datasets/hatt-psd/psd.csv.gz.

    python scripts/fit_default_basis.py [--psd PATH] [-o vibsynth/data/default_basis.yaml]

tests/dsp/test_default_basis.py checks that the shipped file is what this produces.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from vibsynth.cli.basis import summary  # noqa: E402
from vibsynth.formats.basis_file import save_basis  # noqa: E402
from vibsynth.research.basis_fit import fit_default_basis  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--psd", type=Path, default=ROOT.parent / "shared" / "datasets" / "hatt-psd" / "psd.csv.gz")
    parser.add_argument("-o", "--output", type=Path, default=ROOT / "vibsynth" / "data" / "default_basis.yaml")
    args = parser.parse_args()
    basis = fit_default_basis(args.psd)
    save_basis(basis, args.output)
    print(summary(basis))
    return 0


if __name__ == "__main__":
    sys.exit(main())
