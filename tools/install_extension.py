#!/usr/bin/env python3
"""Install the SymRay extension zip into Blender's user folder and enable it.

Usage: BLENDER_USER_RESOURCES=/some/folder python tools/install_extension.py dist/symray-X.zip

Uses the bpy module of this Python (the bpy wheel): ``bpy.ops.extensions.
package_install_files`` into the 'user_default' repository of the user folder named by
BLENDER_USER_RESOURCES (set it to keep your own Blender setup untouched), enables the
add-on and saves the preferences so later runs find it enabled.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

MODULE = "bl_ext.user_default.symray"


def install(zip_path: Path) -> str:
    """Install and enable the extension; returns its module name."""
    import importlib

    import bpy

    addon_utils = importlib.import_module("addon_utils")  # importable once bpy is

    result = bpy.ops.extensions.package_install_files(
        filepath=str(zip_path), repo="user_default", enable_on_install=True
    )
    if result != {"FINISHED"}:
        sys.exit(f"install_extension: installing {zip_path} failed: {result}")
    if not addon_utils.check(MODULE)[1]:
        bpy.ops.preferences.addon_enable(module=MODULE)
    if not addon_utils.check(MODULE)[1]:
        sys.exit(f"install_extension: {MODULE} is installed but could not be enabled")
    bpy.ops.wm.save_userpref()
    return MODULE


def main() -> None:
    """Command line entry point."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("zip", type=Path)
    args = parser.parse_args()
    if "BLENDER_USER_RESOURCES" not in os.environ:
        print(
            "install_extension: BLENDER_USER_RESOURCES is not set; installing into your "
            "own Blender user folder",
            file=sys.stderr,
        )
    module = install(args.zip.resolve())
    print(f"installed and enabled {module} in {os.environ.get('BLENDER_USER_RESOURCES', '~')}")


if __name__ == "__main__":
    main()
