"""Image level: cameras, lights, skin reflectance, the numba z-buffer rasterizer, textures,
the eye/mouth dressing of the face, overlays, and image/video writers."""

from myoface.render.camera import Camera
from myoface.render.io import VideoWriter, progress, write_image
from myoface.render.overlay import overlay_segments, overlay_wireframe
from myoface.render.renderer import (
    Light,
    Renderer,
    SkinMaterial,
    default_lights,
    load_texture,
    render_mesh,
    to_srgb8,
)

__all__ = [
    "Camera",
    "Light",
    "Renderer",
    "SkinMaterial",
    "VideoWriter",
    "default_lights",
    "load_texture",
    "overlay_segments",
    "overlay_wireframe",
    "progress",
    "render_mesh",
    "to_srgb8",
    "write_image",
]
