"""The scene's world -> the core's ``background=`` (procedural sky, colour or environment).

Understood: a Background node feeding the World Output, with either a constant Color or an
Environment Texture (equirectangular image, optionally rotated by a Mapping node) linked
into it, times its Strength. Without nodes, ``world.color``. Images are handed to the core
with row 0 at the top, in Blender's equirectangular orientation (see core/sky.py).
"""

from __future__ import annotations

from typing import Any

import bpy
import numpy as np
from mathutils import Euler

from ..core.mipmap import flip_rows
from ..core.sky import Background
from ..core.stars import FLUX_ZERO, StarField
from .materials import MISSING_TEXTURE_COLOR, image_pixels, node_tree_of


def _background_node(world: bpy.types.World) -> bpy.types.Node | None:
    """The Background node feeding the active world output, if any."""
    tree = node_tree_of(world)
    if tree is None:
        return None
    outputs = [n for n in tree.nodes if n.type == "OUTPUT_WORLD"]
    active = next((n for n in outputs if n.is_active_output), outputs[0] if outputs else None)
    if active is None:
        return None
    surface = active.inputs.get("Surface")
    if surface is None or not surface.is_linked:
        return None
    node = surface.links[0].from_node
    return node if node.type == "BACKGROUND" else None


def _mapping_matrix(texture: bpy.types.Node) -> np.ndarray | None:
    """The core Background matrix of a Mapping node rotating an environment texture."""
    vector = texture.inputs.get("Vector")
    if vector is None or not vector.is_linked:
        return None
    mapping = vector.links[0].from_node
    if mapping.type != "MAPPING":
        return None
    rotation = mapping.inputs.get("Rotation")
    if rotation is None or rotation.is_linked:
        return None
    r = np.array(Euler(rotation.default_value).to_matrix(), dtype=np.float64)
    # POINT/VECTOR look the world direction d up at R d (matrix.T @ d): the matrix is R^T.
    # TEXTURE is the inverse transform: the lookup is at R^T d.
    return r if mapping.vector_type == "TEXTURE" else r.T


def _environment(node: bpy.types.Node, strength: float, warnings: list[str] | None) -> Any:
    """The background of an Environment Texture node: a Background of its image's colour
    (its alpha is not the render's: Cycles' sky is opaque), Blender's magenta (× Strength,
    with a warning naming the image) where the image has no pixels (a missing file), or
    None when the node is not one SymRay reads."""
    if node.type != "TEX_ENVIRONMENT" or node.image is None:
        return None
    pixels = image_pixels(node.image)
    if pixels is None:
        warning = missing_image_warning(node.image)
        if warnings is not None and warning not in warnings:
            warnings.append(warning)
        return (*(c * strength for c in MISSING_TEXTURE_COLOR[:3]), 1.0)
    projection = getattr(node, "projection", "EQUIRECTANGULAR")
    if projection != "EQUIRECTANGULAR":
        raise ValueError(
            f"The world's Environment Texture ('{node.image.name}') uses the "
            f"{projection.replace('_', ' ').title()} projection: SymRay reads Equirectangular "
            "environment images only; set the node's projection to Equirectangular"
        )
    # rows flipped in place (a big sky is held once: issue 45.7); RGB: the sky is opaque
    top_first = flip_rows(pixels)[:, :, :3]
    interpolation = "closest" if node.interpolation == "Closest" else "linear"
    return Background(
        top_first, strength=strength, matrix=_mapping_matrix(node), interpolation=interpolation
    )


def missing_image_warning(image: bpy.types.Image) -> str:
    """The warning for a world image that has no pixels: it renders magenta."""
    where = f" (file '{image.filepath}' not found)" if image.filepath else ""
    return (
        f"The world's Environment Texture image '{image.name}' has no pixels{where}: the "
        "sky renders magenta, as in Cycles"
    )


def point_stars(settings: Any) -> StarField:
    """The StarField of ``scene.symray``'s star settings: its catalogue (a CSV; ValueError
    naming the file and line when it cannot be read) or the seeded random field."""
    options = {"flux_zero": FLUX_ZERO * float(settings.star_brightness)}
    path = settings.star_catalog.strip()
    if not path:
        return StarField.random(int(settings.star_count), int(settings.star_seed), **options)
    try:
        return StarField.from_csv(bpy.path.abspath(path), **options)
    except OSError as error:
        raise ValueError(f"cannot read the star catalogue {path!r}: {error.strerror}") from None


def world_background(
    scene: bpy.types.Scene, mode: str = "AUTO", warnings: list[str] | None = None
) -> Any:
    """The ``background=`` for core.Scene: "procedural", an rgba tuple or a Background.

    ``mode``: 'PROCEDURAL', 'STARS' (point stars: point_stars), 'WORLD' (texture or colour
    of the world, black without one) or
    'AUTO' (the world's environment texture or plain colour; the procedural sky when the
    scene has no world, or a world whose nodes SymRay cannot read). An environment image
    without pixels is magenta, as in Cycles, with a warning appended to ``warnings``.
    """
    if mode == "PROCEDURAL":
        return "procedural"
    if mode == "STARS":
        return point_stars(scene.symray)
    world = scene.world
    if world is None:
        return "procedural" if mode == "AUTO" else (0.0, 0.0, 0.0, 1.0)
    node = _background_node(world)
    if node is None:
        if mode == "AUTO" and node_tree_of(world) is not None:
            return "procedural"  # nodes, but no Background node SymRay reads
        return (*(float(c) for c in world.color[:3]), 1.0)
    strength_socket = node.inputs.get("Strength")
    strength = 1.0
    if strength_socket is not None and not strength_socket.is_linked:
        strength = float(strength_socket.default_value)
    color = node.inputs["Color"]
    if color.is_linked:
        environment = _environment(color.links[0].from_node, strength, warnings)
        if environment is not None:
            return environment
        return "procedural" if mode == "AUTO" else (0.0, 0.0, 0.0, 1.0)
    rgb = np.array(color.default_value[:3], dtype=np.float64) * strength
    return (*rgb.tolist(), 1.0)


def plain_colour(scene: bpy.types.Scene) -> bool:
    """True when Background › Auto shows the world as one plain colour (the factory grey
    world: no environment texture), which shows nothing of a black hole's lensing."""
    world = scene.world
    if world is None:
        return False
    node = _background_node(world)
    if node is None:
        return node_tree_of(world) is None
    return not node.inputs["Color"].is_linked
