"""Bridge between the recognition textures (:mod:`plugins.processing.textures`) and pybullet.

An object listed in the RGB recognition's model file (the sim channel's Param ``textures``) is painted with
exactly the texture that model learnt (same pattern, colours and seed); another textured object
gets one drawn from its environment ``<Texture>`` and a seed derived from the texture's name.
Images are written as PNG files at run time into a cache directory (never committed), named by
a hash of their spec so concurrent worlds and processes share them safely.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
import zlib
from pathlib import Path

import cv2

from ckmconf.model import Environment
from plugins.processing.textures import WORDS, ModelSpec, TextureSpec, render_texture

CACHE_ENV = "CKM_SIM_TEXTURES"
"""Environment variable naming the texture cache directory (default: a folder in the temp dir)."""


def cache_dir() -> Path:
    """The directory texture PNGs are written to (created on demand)."""
    path = Path(os.environ.get(CACHE_ENV) or Path(tempfile.gettempdir()) / "ckm-sim-textures")
    path.mkdir(parents=True, exist_ok=True)
    return path


def texture_spec(environment: Environment, object_name: str, catalog: ModelSpec | None) -> TextureSpec | None:
    """The texture an environment object is painted with, or None for a plain-coloured one.

    Args:
        environment: the ``<Environment>`` holding the object and its ``<Texture>`` records.
        object_name: the ``<Object>`` name.
        catalog: the RGB recognition's model file, whose entries win (same texture as learnt).
    """
    if catalog is not None:
        for spec in catalog.objects:
            if spec.name == object_name:
                return spec
    obj = next((o for o in environment.objects if o.name == object_name), None)
    if obj is None or obj.texture is None:
        return None
    texture = next((t for t in environment.textures if t.name == obj.texture), None)
    if texture is None or texture.pattern in ("plain", "image"):
        return None
    return TextureSpec(
        name=texture.name,
        pattern=texture.pattern,
        color=texture.color,
        secondary=texture.secondary or "#FFFFFF",
        seed=zlib.crc32(texture.name.encode()),
        words=WORDS if catalog is None else catalog.words,  # the catalogue's print, as its own objects'
    )


def texture_file(spec: TextureSpec) -> Path:
    """A PNG of ``spec``'s texture in the cache directory (written once, atomically)."""
    digest = hashlib.sha1(repr(spec).encode()).hexdigest()[:16]
    path = cache_dir() / f"{spec.name}-{digest}.png"
    if not path.exists():
        image = render_texture(spec)
        fd, tmp = tempfile.mkstemp(suffix=".png", dir=path.parent)
        os.close(fd)
        cv2.imwrite(tmp, cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
        os.replace(tmp, path)
    return path
