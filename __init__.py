"""SymRay Blender extension entry point: registers the add-on in ``symray_addon``.

The import is deferred to register() so that importing this package outside
Blender (pytest collects the repository root as a package) needs no bpy.
"""


def register() -> None:
    """Register SymRay's properties, panel, operator and render engine."""
    from .symray_addon import register as register_addon

    register_addon()


def unregister() -> None:
    """Unregister everything register() added."""
    from .symray_addon import unregister as unregister_addon

    unregister_addon()
