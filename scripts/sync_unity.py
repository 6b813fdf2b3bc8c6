"""Keep the Unity package (clients/unity/) in step with its one source, clients/csharp/.

    python scripts/sync_unity.py            # write the generated files and the .meta files
    python scripts/sync_unity.py --check    # exit 1, naming each file that differs (the tests run this)

The C# client is written once, in clients/csharp/ (compiled by the tests under mono). Unity cannot
follow a symbolic link out of a package reliably (Windows clones), so the package carries copies,
each with a header saying where to edit; this script writes them and ``--check`` fails when one
drifts. It also writes a ``.meta`` file beside every file and folder of the package (outside the
``~`` folders Unity does not import): a package installed from a Git URL is immutable, so Unity
cannot make them itself. Each guid is the MD5 of the path in the package, so it is the same on every
machine and at every run, and unique within the package.
"""

from __future__ import annotations

import argparse
import hashlib
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "clients" / "unity"

#: generated copy (in the package) -> its source (in the repository)
COPIES = {
    "Runtime/Client/VibsynthClient.cs": "clients/csharp/VibsynthClient.cs",
    "Runtime/VibsynthContactSource.cs": "clients/csharp/Unity/VibsynthContactSource.cs",
}
HEADER = "// Generated from {source} by scripts/sync_unity.py: edit there, then run the script.\n\n"

_COMMON_TAIL = "  userData: \n  assetBundleName: \n  assetBundleVariant: \n"
_IMPORTERS = {
    ".cs": "MonoImporter:\n  externalObjects: {}\n  serializedVersion: 2\n  defaultReferences: []\n"
    "  executionOrder: 0\n  icon: {instanceID: 0}\n" + _COMMON_TAIL,
    ".asmdef": "AssemblyDefinitionImporter:\n  externalObjects: {}\n" + _COMMON_TAIL,
    ".md": "TextScriptImporter:\n  externalObjects: {}\n" + _COMMON_TAIL,
    ".json": "TextScriptImporter:\n  externalObjects: {}\n" + _COMMON_TAIL,
}
_PACKAGE_MANIFEST = "PackageManifestImporter:\n  externalObjects: {}\n" + _COMMON_TAIL
_FOLDER = "folderAsset: yes\nDefaultImporter:\n  externalObjects: {}\n" + _COMMON_TAIL
_DEFAULT = "DefaultImporter:\n  externalObjects: {}\n" + _COMMON_TAIL


def guid(relative: str) -> str:
    """The stable guid of a package path (POSIX form, relative to the package root)."""
    return hashlib.md5(f"com.vibsynth.client/{relative}".encode()).hexdigest()


def generated_copy(source: str) -> str:
    """The package's copy of a source file: the header, then the source as it is."""
    return HEADER.format(source=source) + (ROOT / source).read_text(encoding="utf-8")


def imported(package: Path | None = None, extra: tuple[str, ...] = ()) -> list[str]:
    """Every file and folder Unity imports (not ``.meta``, nothing in or under a ``~``/hidden folder).

    ``extra`` names paths that will exist once the copies are written.
    """
    package = package or PACKAGE
    found: set[str] = set(extra)
    for path in package.rglob("*"):
        relative = path.relative_to(package)
        if path.suffix == ".meta" or any(part.endswith("~") or part.startswith(".") for part in relative.parts):
            continue
        found.add(relative.as_posix())
    for name in list(found):  # the folders of the copies
        parts = name.split("/")
        found.update("/".join(parts[:i]) for i in range(1, len(parts)))
    return sorted(found)


def meta(relative: str, package: Path | None = None) -> str:
    """The ``.meta`` text of a package path."""
    path = (package or PACKAGE) / relative
    if path.is_dir() or (not path.exists() and "." not in relative.rsplit("/", 1)[-1]):
        body = _FOLDER
    elif relative == "package.json":
        body = _PACKAGE_MANIFEST
    else:
        body = _IMPORTERS.get(path.suffix, _DEFAULT)
    return f"fileFormatVersion: 2\nguid: {guid(relative)}\n{body}"


def expected(package: Path | None = None) -> dict[Path, str]:
    """Every generated file (copies and .meta files) with the text it must have."""
    package = package or PACKAGE
    files = {package / target: generated_copy(source) for target, source in COPIES.items()}
    for relative in imported(package, tuple(COPIES)):
        files[package / f"{relative}.meta"] = meta(relative, package)
    return files


def stale_metas(package: Path | None = None) -> list[Path]:
    """``.meta`` files whose asset is gone."""
    package = package or PACKAGE
    wanted = set(expected(package))
    return sorted(p for p in package.rglob("*.meta") if p not in wanted and "~" not in p.as_posix())


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n", 1)[0])
    parser.add_argument("--check", action="store_true", help="only report what differs (exit 1)")
    args = parser.parse_args(argv)
    files = expected()
    differ = [path for path, text in files.items() if not path.is_file() or path.read_text("utf-8") != text]
    stale = stale_metas()
    if args.check:
        for path in differ:
            print(f"sync_unity: {_shown(path)} differs from its source: run python scripts/sync_unity.py")
        for path in stale:
            print(f"sync_unity: {_shown(path)} has no asset beside it")
        return 1 if differ or stale else 0
    for path in differ:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(files[path], encoding="utf-8", newline="\n")
        print(f"sync_unity: wrote {_shown(path)}")
    for path in stale:
        path.unlink()
        print(f"sync_unity: removed {_shown(path)}")
    return 0


def _shown(path: Path) -> str:
    try:
        return path.relative_to(ROOT).as_posix()
    except ValueError:
        return str(path)


if __name__ == "__main__":
    sys.exit(main())
