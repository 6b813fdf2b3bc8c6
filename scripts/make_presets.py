#!/usr/bin/env python3
"""Regenerate the shipped presets (``vibsynth/data/presets/*.yaml``) from the HaTT spectra.

For each chosen texture of ``shared/datasets/hatt-psd/psd.csv.gz``:

* every model's PSD -> 30 band powers -> dB -> t1 on the shipped basis;
* balance = the shipped basis' knob units of the **median t1 over that texture's models**;
* intensity = the texture's median 80-200 Hz band level *relative to the loudest texture
  of the whole set*, kept in dB under the default knob mapping: the loudest texture maps to
  :data:`TOP_INTENSITY` and each dB quieter is ``1 / range_db`` of knob (range_db = 40 dB by
  default). HaTT PSDs are of an AR model in (m/s^2)^2/Hz measured through a stylus: their
  absolute level is not an output level, only the differences between textures carry over;
* a texture whose low bands (10-100 Hz) sit within :data:`FLOOR_MARGIN_DB` of the dataset's
  quietest spectra (2nd percentile per band) is flagged: its "brightness" comes from the
  *absence* of low-frequency energy above the sensor's floor, not from felt high-frequency
  roughness, and its description says so.

Textures were picked by hand to span the balance range (darkest to brightest) with
names a designer recognises; the numbers all come from the data.

Usage::

    python scripts/make_presets.py [--psd ../shared/datasets/hatt-psd/psd.csv.gz] [--check]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from vibsynth.dsp.basis import band_powers_from_psd, to_db  # noqa: E402
from vibsynth.dsp.intensity import DEFAULT_RANGE_DB, intensity_response  # noqa: E402
from vibsynth.formats.basis_file import default_basis  # noqa: E402
from vibsynth.formats.psd import read_psd_table  # noqa: E402
from vibsynth.research.basis_fit import HATT_CITATION, HATT_TERMS  # noqa: E402
from vibsynth.settings.presets import Preset, parse_preset, preset_to_yaml  # noqa: E402

DEFAULT_PSD = ROOT.parent / "shared" / "datasets" / "hatt-psd" / "psd.csv.gz"
OUT_DIR = ROOT / "vibsynth" / "data" / "presets"
TOP_INTENSITY = 0.9
FLOOR_MARGIN_DB = 5.0
LOW_BANDS = slice(0, 15)  # 10 Hz .. ~100 Hz of the 30-band bank
GLIDE_MS = 50.0
DATASET = "hatt-psd (spectra of the Penn Haptic Texture Toolkit AR texture models)"

#: (preset name, HaTT texture, what it feels like / why it is here, tags)
CHOICES: list[tuple[str, str, str, list[str]]] = [
    (
        "metal-shelving",
        "Metal Shelving",
        "Perforated metal shelving: the darkest texture of the set, a low, rumbling buzz.",
        ["metal", "hard", "dark"],
    ),
    ("brick", "Brick 2", "Rough brick: coarse, strong low-frequency bumps.", ["stone", "hard", "rough"]),
    ("sandpaper-220", "Sandpaper 220", "Medium sandpaper (220 grit): grainy with a dark body.", ["abrasive", "rough"]),
    ("stone-tile", "Stone Tile 1", "Unglazed stone tile: dense and gritty.", ["stone", "hard"]),
    (
        "sandpaper-100",
        "Sandpaper 100",
        "Coarse sandpaper (100 grit): rough grit, a little brighter than the "
        "finer papers because its grains ring at higher frequencies.",
        ["abrasive", "rough"],
    ),
    ("wood", "Wood", "Planed wood: smooth grain, darker than the middle of the range.", ["wood", "hard"]),
    ("book", "Book", "A book cover: smooth, slightly dark, with a soft body.", ["paper", "smooth"]),
    ("folder", "Folder", "A plastic folder: smooth and neutral-dark.", ["plastic", "smooth"]),
    (
        "abs-plastic",
        "ABS Plastic",
        "ABS plastic: close to the average spectrum of the whole set.",
        ["plastic", "neutral"],
    ),
    ("velvet", "Velvet", "Velvet: the set's average balance (0), a soft, even texture.", ["fabric", "neutral"]),
    ("plastic-mesh", "Plastic Mesh 1", "Plastic mesh: regular ridges, slightly bright.", ["plastic", "mesh"]),
    ("cardboard", "Cardboard", "Corrugated cardboard: dry and slightly bright.", ["paper"]),
    ("denim", "Denim", "Denim: a fine woven fabric, moderately bright.", ["fabric", "woven"]),
    ("canvas", "Canvas 1", "Canvas: coarse weave, bright and grainy.", ["fabric", "woven"]),
    ("cork", "Cork", "Cork board: bright, crumbly fine grain.", ["soft", "bright"]),
    ("carpet", "Carpet 2", "Carpet: bright fibre texture.", ["fabric", "bright"]),
    (
        "artificial-grass",
        "Artificial Grass",
        "Artificial grass: stiff plastic blades flicking under the tool.",
        ["plastic", "bright"],
    ),
    ("towel", "Towel", "Terry towel: the brightest texture of the set.", ["fabric", "bright"]),
]

CAVEAT = (
    "Caution: {texture} comes out bright because its low bands (10-100 Hz) are only {margin:.1f} dB above "
    "the quietest spectra of the dataset: the stylus barely excites the low end on this soft material and "
    "what remains is largely the sensor's noise floor. Rendered, it feels like a fine, airy hiss, not like "
    "the softness of {texture_lower}."
)


def analyse_textures(psd_path: Path) -> dict[str, dict[str, float]]:
    """Per texture: number of models, median t1, median balance, median 80-200 Hz level, low-band margin."""
    basis = default_basis()
    table = read_psd_table(psd_path)
    band_db = to_db(band_powers_from_psd(table.freqs_hz, table.psd, centres=basis.centres_hz, order=basis.filter_order))
    t1 = basis.scores(band_db)[:, 0]
    response = intensity_response(table.freqs_hz)
    level_db = 10.0 * np.log10(np.trapezoid(table.psd * response, table.freqs_hz, axis=1))
    floor_db = np.percentile(band_db, 2.0, axis=0)
    labels = np.asarray(table.labels)
    out: dict[str, dict[str, float]] = {}
    for texture in sorted(set(table.labels)):
        rows = labels == texture
        median_band = np.median(band_db[rows], axis=0)
        median_t1 = float(np.median(t1[rows]))
        balances = basis.balance_from_t1(t1[rows])
        out[texture] = {
            "n_models": int(rows.sum()),
            "t1": median_t1,
            "balance": float(basis.balance_from_t1(median_t1)),
            "balance_q25": float(np.percentile(balances, 25)),
            "balance_q75": float(np.percentile(balances, 75)),
            "level_db": float(np.median(level_db[rows])),
            "low_margin_db": float(np.median((median_band - floor_db)[LOW_BANDS])),
        }
    return out


def build_presets(psd_path: Path) -> dict[str, str]:
    """Preset file name -> YAML text, deterministically from the PSD table."""
    stats = analyse_textures(psd_path)
    basis = default_basis()
    loudest = max(stats.values(), key=lambda s: s["level_db"])
    loudest_name = next(k for k, v in stats.items() if v is loudest)
    missing = [texture for _, texture, _, _ in CHOICES if texture not in stats]
    if missing:
        raise SystemExit(f"{psd_path}: textures not found: {', '.join(missing)}")
    ordered = sorted(CHOICES, key=lambda c: stats[c[1]]["balance"])
    files: dict[str, str] = {}
    for program, (name, texture, blurb, tags) in enumerate(ordered):
        s = stats[texture]
        intensity = TOP_INTENSITY + (s["level_db"] - loudest["level_db"]) / DEFAULT_RANGE_DB
        intensity = round(min(1.0, max(0.05, intensity)), 3)
        balance = round(s["balance"], 3)
        flagged = s["low_margin_db"] < FLOOR_MARGIN_DB
        description = f"{blurb} HaTT texture '{texture}', median of {s['n_models']} models."
        if flagged:
            description += " " + CAVEAT.format(
                texture=texture, margin=s["low_margin_db"], texture_lower=texture.lower()
            )
        provenance = {
            "dataset": DATASET,
            "file": "shared/datasets/hatt-psd/psd.csv.gz",
            "texture": texture,
            "n_models": s["n_models"],
            "median_t1": round(s["t1"], 3),
            "median_balance": round(s["balance"], 4),
            "balance_iqr": [round(s["balance_q25"], 3), round(s["balance_q75"], 3)],
            "level_db_80_200hz": round(s["level_db"], 2),
            "level_unit": "dB re 1 (m/s^2)^2 of the AR-model PSD (stylus accelerometer); relative use only",
            "intensity_rule": (
                f"{TOP_INTENSITY} + (level_db - ({loudest['level_db']:.2f})) / {DEFAULT_RANGE_DB:g}: the set's loudest "
                f"texture ({loudest_name}) = {TOP_INTENSITY}, 1/{DEFAULT_RANGE_DB:g} knob per dB quieter "
                "(default range_db), clipped to [0.05, 1]"
            ),
            "low_band_margin_db": round(s["low_margin_db"], 2),
            "noise_floor_caveat": bool(flagged),
            "basis_id": basis.id,
            "method": "median t1 over the texture's models (shipped basis, 30 Butterworth bands 10-1000 Hz)",
            "generated_by": "scripts/make_presets.py",
            "citation": HATT_CITATION,
            "terms": HATT_TERMS,
        }
        preset = Preset(
            name=name,
            intensity=intensity,
            balance=balance,
            description=description,
            glide_ms=GLIDE_MS,
            program=program,
            tags=tuple(tags),
            provenance=provenance,
        )
        header = (
            "# Shipped vibsynth preset, generated by scripts/make_presets.py from the HaTT spectra.\n"
            "# Do not edit here: copy it to your user preset folder (see docs/presets.md) and edit the copy.\n"
        )
        text = preset_to_yaml(preset, header=header)
        parse_preset(text, f"{name}.yaml", name=name)  # must validate
        files[f"{name}.yaml"] = text
    return files


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--psd", type=Path, default=DEFAULT_PSD, help=f"PSD table (default {DEFAULT_PSD})")
    parser.add_argument("--out", type=Path, default=OUT_DIR, help=f"output folder (default {OUT_DIR})")
    parser.add_argument(
        "--check", action="store_true", help="only compare with the files in --out; exit 1 if different"
    )
    args = parser.parse_args(argv)
    if not args.psd.exists():
        print(
            f"make_presets: {args.psd}: no such file (clone the shared data beside the repo or pass --psd)",
            file=sys.stderr,
        )
        return 2
    files = build_presets(args.psd)
    if args.check:
        current = {p.name: p.read_text(encoding="utf-8") for p in args.out.glob("*.yaml")}
        if current != files:
            print("make_presets: shipped presets differ from a fresh build", file=sys.stderr)
            return 1
        print(f"make_presets: {len(files)} presets up to date")
        return 0
    from vibsynth.formats.files import atomic_write_text

    args.out.mkdir(parents=True, exist_ok=True)
    for old in args.out.glob("*.yaml"):
        if old.name not in files:
            old.unlink()
    for name, text in files.items():
        atomic_write_text(args.out / name, text)
    keep = args.out / ".keep"
    if keep.exists():
        keep.unlink()
    for name, text in files.items():
        p = parse_preset(text, name, name=name[:-5])
        flag = "  (noise-floor caveat)" if p.provenance["noise_floor_caveat"] else ""
        print(
            f"{p.program:3d} {p.name:<18} balance {p.balance:+.3f} intensity {p.intensity:.3f} "
            f"{p.provenance['texture']}{flag}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
