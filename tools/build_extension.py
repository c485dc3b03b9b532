#!/usr/bin/env python3
"""Build and validate the SymRay extension zip with Blender's own extension tool.

Usage: python tools/build_extension.py [--output-dir dist]

Runs ``blender_ext.py build`` (from the installed bpy wheel, under this Python) on the
repository root, then ``blender_ext.py validate`` on the zip, then checks that the zip
holds only the extension's files. Prints the zip's path.
"""

from __future__ import annotations

import argparse
import importlib.util
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
ALLOWED_TOP = {
    "__init__.py",
    "blender_manifest.toml",
    "core",
    "symray_addon",
    "README.md",
    "LICENSE",
    "LICENSE.txt",
}


def blender_ext_script() -> Path:
    """Path of blender_ext.py inside the installed bpy package (bpy is not imported)."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        sys.exit("build_extension: the bpy module is not installed (run 'make venv')")
    for location in spec.submodule_search_locations:
        found = sorted(Path(location).glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
        if found:
            return found[-1]
    sys.exit("build_extension: blender_ext.py not found in the bpy package")


def zip_name() -> str:
    """dist file name from the manifest: <id>-<version>.zip."""
    manifest = tomllib.loads((REPO / "blender_manifest.toml").read_text(encoding="utf-8"))
    return f"{manifest['id']}-{manifest['version']}.zip"


def check_contents(path: Path) -> list[str]:
    """Names in the zip; exits if anything outside the extension's files slipped in."""
    with zipfile.ZipFile(path) as archive:
        names = archive.namelist()
    stray = sorted({n.split("/")[0] for n in names} - ALLOWED_TOP)
    if stray:
        sys.exit(
            f"build_extension: unexpected entries in {path.name}: {stray} "
            "(extend [build] paths_exclude_pattern in blender_manifest.toml)"
        )
    for required in (
        "__init__.py",
        "blender_manifest.toml",
        "core/__init__.py",
        "symray_addon/__init__.py",
    ):
        if required not in names:
            sys.exit(f"build_extension: {path.name} lacks {required}")
    return names


def build(output_dir: Path) -> Path:
    """Build, validate and check the zip in ``output_dir``; returns its path."""
    output_dir.mkdir(parents=True, exist_ok=True)
    tool = blender_ext_script()
    target = output_dir / zip_name()
    subprocess.run(
        [
            sys.executable,
            str(tool),
            "build",
            "--source-dir",
            str(REPO),
            "--output-filepath",
            str(target),
        ],
        check=True,
        stdout=subprocess.DEVNULL,
    )
    subprocess.run(
        [sys.executable, str(tool), "validate", str(target)], check=True, stdout=subprocess.DEVNULL
    )
    check_contents(target)
    return target


def main() -> None:
    """Command line entry point."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--output-dir", type=Path, default=REPO / "dist")
    args = parser.parse_args()
    print(build(args.output_dir.resolve()))


if __name__ == "__main__":
    main()
