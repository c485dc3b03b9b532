"""Material colours for the intersector (unbaked path): a colour, an image texture, emission.

Reading happens on the main thread (``material_sampler``); the returned
``MaterialSampler`` is plain numpy and is safe to use from the render worker thread.

Understood, on the shader feeding the active Material Output: a Principled BSDF's Base
Color (its value, or an Image Texture node linked straight into it, sampled at the mesh's
active UV map) plus its Emission Color x Emission Strength; a Diffuse BSDF's Color (same
rules); an Emission shader's Color x Strength. The surface shows colour + emission (unlit:
as if under unit white light, so a glowing object glows without lights). Any other node
on the way (a Checker, a Mapping node, a Mix Shader, ...) cannot be evaluated here:
``unsupported_nodes`` names it, and the render reports it once as a warning (baking
evaluates every node: see bake.py). Images are converted to linear RGB as Blender does
for sRGB byte images.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import bpy
import numpy as np

from ..core.mipmap import MipMap, bilinear, point_or_filtered, wrap_index

DEFAULT_COLOR = (0.8, 0.8, 0.8, 1.0)
"""Colour of faces without a material (Blender's default surface)."""
MISSING_TEXTURE_COLOR = (1.0, 0.0, 1.0, 1.0)
"""Colour of a texture whose image has no pixels (Blender's magenta)."""


EXTENSION_WRAP = {"REPEAT": "repeat", "EXTEND": "extend", "CLIP": "extend", "MIRROR": "mirror"}
"""An Image Texture's extension as core.mipmap's wrap mode (CLIP: zero outside, after)."""


@dataclass
class MaterialSampler:
    """Colour of one material at given UVs: ``base`` times an optional texture, a linear
    (not Closest) texture averaged over each pixel's footprint where given (core.mipmap)."""

    base: np.ndarray
    image: np.ndarray | None = None
    """(h, w, 4) float32 linear RGBA, row 0 at the bottom (Blender's order), or None."""
    closest: bool = False
    extension: str = "REPEAT"
    emission: np.ndarray | None = None
    """Emitted radiance (3,) added to the colour (linear RGB), or None."""
    _pyramid: MipMap | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def filters(self) -> bool:
        """Whether a footprint changes its colour (a linear image texture)."""
        return self.image is not None and not self.closest

    def sample(self, uv: np.ndarray, footprint: np.ndarray | None = None) -> np.ndarray:
        """RGBA (M, 4) float64 at texture coordinates ``uv`` (M, 2), averaged over
        ``footprint`` (M, 2, 2: ∂(u, v)/∂(image x, y)) where given."""
        m = uv.shape[0]
        out = np.broadcast_to(self.base, (m, 4)).astype(np.float64)
        if self.image is not None and m:
            if footprint is not None and self.filters:
                texture = self._filtered(uv, footprint)
            else:
                texture = sample_image(self.image, uv, self.closest, self.extension)
            out = out * texture
        if self.emission is not None:
            out[:, :3] += self.emission
        return out

    def _filtered(self, uv: np.ndarray, footprint: np.ndarray) -> np.ndarray:
        """The texture averaged over footprints (core.mipmap.MipMap on the image turned
        top row first, as it takes them; a footprint of at most a texel: the plain bilinear
        lookup itself); zero outside [0, 1]² for CLIP."""
        if self._pyramid is None:
            wrap = EXTENSION_WRAP.get(self.extension, "repeat")
            assert self.image is not None
            self._pyramid = MipMap(self.image[::-1].astype(np.float64), (wrap, wrap))
        image, pyramid = self.image, self._pyramid
        texels = pyramid.texels(footprint)
        out = point_or_filtered(
            texels,
            lambda rows: sample_image(image, uv[rows], False, self.extension),
            lambda rows: pyramid.lookup(uv[rows], texels[rows]),
            image.shape[2],
        )
        if self.extension == "CLIP":
            out[_outside(uv)] = 0.0
        return out


def _outside(uv: np.ndarray) -> np.ndarray:
    """(M,) whether each uv lies outside [0, 1]²."""
    return (uv[:, 0] < 0) | (uv[:, 0] > 1) | (uv[:, 1] < 0) | (uv[:, 1] > 1)


def sample_image(
    image: np.ndarray, uv: np.ndarray, closest: bool = False, extension: str = "REPEAT"
) -> np.ndarray:
    """Sample an (h, w, 4) bottom-up image at ``uv`` (M, 2), bilinear or closest, as float64."""
    h, w = image.shape[:2]
    x = uv[:, 0] * w - 0.5
    y = uv[:, 1] * h - 0.5
    mode = EXTENSION_WRAP.get(extension, "repeat")
    if closest:
        xi = wrap_index(np.floor(x + 0.5).astype(np.int64), w, mode)
        yi = wrap_index(np.floor(y + 0.5).astype(np.int64), h, mode)
        out = image[yi, xi].astype(np.float64)
    else:
        out = bilinear(image, x, y, (mode, mode)).astype(np.float64)
    if extension == "CLIP":
        out[_outside(uv)] = 0.0
    return out


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """The sRGB transfer function, inverted (colour channels only)."""
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def image_pixels(image: bpy.types.Image) -> np.ndarray | None:
    """A linear float32 (h, w, 4) copy of an image's pixels (bottom row first), or None."""
    try:
        w, h = image.size
        channels = image.channels
    except (RuntimeError, ReferenceError):
        return None
    if w == 0 or h == 0 or channels not in (1, 3, 4):
        return None
    flat = np.empty(w * h * channels, dtype=np.float32)
    image.pixels.foreach_get(flat)
    pix = flat.reshape(h, w, channels)
    if channels != 4:
        rgb = np.repeat(pix[:, :, :1], 3, axis=2) if channels == 1 else pix
        pix = np.concatenate([rgb, np.ones((h, w, 1), np.float32)], axis=2)
    colorspace = image.colorspace_settings.name
    if not image.is_float and colorspace in ("sRGB", "sRGB 2.2"):
        pix = pix.copy()
        pix[:, :, :3] = srgb_to_linear(pix[:, :, :3])
    return np.ascontiguousarray(pix, dtype=np.float32)


def node_tree_of(datablock: bpy.types.ID) -> bpy.types.NodeTree | None:
    """The shader node tree a material or world renders with, or None (no nodes)."""
    if bpy.app.version >= (5, 0, 0):  # always node-based; use_nodes is deprecated
        return datablock.node_tree
    return datablock.node_tree if datablock.use_nodes else None


SHADERS = ("BSDF_PRINCIPLED", "BSDF_DIFFUSE", "EMISSION")
"""Shader nodes the unbaked reader understands (feeding the Material Output)."""
COLOR_INPUT = {"BSDF_PRINCIPLED": "Base Color", "BSDF_DIFFUSE": "Color", "EMISSION": "Color"}


def _output_shader(tree: bpy.types.NodeTree) -> bpy.types.Node | None:
    """The node linked into the active Material Output's Surface, else None."""
    outputs = [n for n in tree.nodes if n.type == "OUTPUT_MATERIAL"]
    active = next((n for n in outputs if n.is_active_output), outputs[0] if outputs else None)
    if active is None:
        return None
    surface = active.inputs.get("Surface")
    if surface is None or not surface.is_linked:
        return None
    return surface.links[0].from_node


def _shader(tree: bpy.types.NodeTree) -> bpy.types.Node | None:
    """The understood shader feeding the active output, else the first Principled BSDF."""
    node = _output_shader(tree)
    if node is not None and node.type in SHADERS:
        return node
    return next((n for n in tree.nodes if n.type == "BSDF_PRINCIPLED"), None)


def _value(node: bpy.types.Node, name: str, default: float) -> float:
    """A float input's value (``default`` if the node has no such input)."""
    socket = node.inputs.get(name)
    return float(socket.default_value) if socket is not None else default


def _emission(node: bpy.types.Node) -> np.ndarray | None:
    """Emitted radiance (3,) of a Principled BSDF's emission, None if it emits none."""
    if node.type != "BSDF_PRINCIPLED" or "Emission Color" not in node.inputs:
        return None
    color, strength = node.inputs["Emission Color"], _value(node, "Emission Strength", 0.0)
    if color.is_linked:
        return None  # reported by unsupported_nodes
    radiance = np.array(color.default_value[:3], dtype=np.float64) * strength
    return radiance if np.any(radiance != 0.0) else None


def unsupported_nodes(material: bpy.types.Material | None) -> list[str]:
    """Names of the nodes feeding ``material``'s surface that the unbaked reader ignores."""
    tree = node_tree_of(material) if material is not None else None
    if tree is None:
        return []
    shader = _output_shader(tree)
    if shader is None:
        return []
    if shader.type not in SHADERS:
        return [shader.name]
    found: list[str] = []
    for socket in shader.inputs:
        for link in socket.links:
            source = link.from_node
            if socket.name == COLOR_INPUT[shader.type] and source.type == "TEX_IMAGE":
                found += _upstream_names(source, skip_self=True)
            else:
                found += _upstream_names(source)
    return sorted(set(found))


def _upstream_names(node: bpy.types.Node, skip_self: bool = False) -> list[str]:
    """``node`` and every node linked into it (an image texture's Vector input included)."""
    names = [] if skip_self else [node.name]
    seen = {node.name}
    stack = [node]
    while stack:
        for socket in stack.pop().inputs:
            for link in socket.links:
                if link.from_node.name not in seen:
                    seen.add(link.from_node.name)
                    names.append(link.from_node.name)
                    stack.append(link.from_node)
    return names


def material_sampler(material: bpy.types.Material | None) -> MaterialSampler:
    """Read a material's colour (and image texture, emission) into a MaterialSampler."""
    if material is None:
        return MaterialSampler(np.array(DEFAULT_COLOR))
    base = np.array(material.diffuse_color, dtype=np.float64)
    tree = node_tree_of(material)
    node = _shader(tree) if tree is not None else None
    if node is None:
        return MaterialSampler(base)
    sampler = _color_sampler(node, base)
    if node.type == "EMISSION":  # an Emission shader's colour is radiance: Color x Strength
        sampler.base = sampler.base * [*([_value(node, "Strength", 1.0)] * 3), 1.0]
    else:
        sampler.emission = _emission(node)
    return sampler


def _color_sampler(node: bpy.types.Node, base: np.ndarray) -> MaterialSampler:
    """The colour input of shader ``node``: a constant or an image texture linked into it."""
    alpha = _value(node, "Alpha", 1.0)
    socket = node.inputs[COLOR_INPUT[node.type]]
    if not socket.is_linked:
        return MaterialSampler(np.array([*socket.default_value[:3], alpha], dtype=np.float64))
    source = socket.links[0].from_node
    if source.type != "TEX_IMAGE" or source.image is None:
        return MaterialSampler(np.array([*base[:3], alpha]))
    pixels = image_pixels(source.image)
    if pixels is None:
        return MaterialSampler(np.array(MISSING_TEXTURE_COLOR))
    return MaterialSampler(
        np.array([1.0, 1.0, 1.0, alpha]),
        pixels,
        closest=source.interpolation == "Closest",
        extension=source.extension,
    )
