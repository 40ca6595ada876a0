"""Generated materials: textures from scikit-image's bundled images and procedural patterns."""

from __future__ import annotations

from functools import cache

import numpy as np
import skimage.data

from kadv.scenes.scene import Material

__all__ = ["textured_materials"]

_GREY_IMAGES = ("brick", "grass", "gravel", "camera", "moon")
_COLOUR_IMAGES = ("coffee", "chelsea", "astronaut", "immunohistochemistry", "rocket")


def _downsample(image: np.ndarray, size: int = 256) -> np.ndarray:
    step = max(1, min(image.shape[:2]) // size)
    return image[::step, ::step]


@cache
def _image(name: str) -> np.ndarray:
    image = _downsample(getattr(skimage.data, name)())
    image.setflags(write=False)
    return image


def _photo(rng: np.random.Generator) -> np.ndarray:
    return _image(_COLOUR_IMAGES[rng.integers(len(_COLOUR_IMAGES))])[..., :3] / 255.0


def _grey_photo(rng: np.random.Generator, tint: np.ndarray, contrast: float) -> np.ndarray:
    grey = _image(_GREY_IMAGES[rng.integers(len(_GREY_IMAGES))]) / 255.0
    return (1.0 - contrast + contrast * grey[:, :, None]) * tint


def _checker(rng: np.random.Generator, tint: np.ndarray) -> np.ndarray:
    cells = int(rng.integers(2, 9))
    board = (np.indices((64, 64)).sum(axis=0) // (64 // cells)) % 2
    return np.where(board[:, :, None] == 0, tint, rng.uniform(0.1, 0.9, size=3))


def _stripes(rng: np.random.Generator, tint: np.ndarray) -> np.ndarray:
    phase = np.linspace(0, 2 * np.pi * int(rng.integers(2, 8)), 64)
    stripes = 0.5 + 0.5 * np.sin(phase)[None, :, None]
    return np.broadcast_to(stripes * tint + (1 - stripes) * tint[::-1] * 0.5, (64, 64, 3))


def _wood(rng: np.random.Generator, tint: np.ndarray) -> np.ndarray:
    """Planks' grain: wavy rings across u."""
    v, u = np.mgrid[0:1:128j, 0:1:128j]
    wobble = 0.03 * np.sin(2 * np.pi * (rng.uniform(1, 4) * v + rng.uniform()))
    grain = 0.5 + 0.5 * np.sin(2 * np.pi * rng.uniform(6, 20) * (u + wobble))
    return tint * (0.72 + 0.28 * grain[:, :, None])


def _backdrop(rng: np.random.Generator) -> np.ndarray:
    """A bright outdoor view mapped once over a quad: sky above a wavy line of trees or buildings."""
    v, u = np.mgrid[0:1:128j, 0:1:256j]  # row 0 is the top (v = 1)
    horizon = rng.uniform(0.35, 0.65) + 0.08 * np.sin(2 * np.pi * (rng.uniform(1, 6) * u + rng.uniform()))
    sky = np.array([0.62, 0.76, 0.96]) + (np.array([0.95, 0.97, 1.0]) - np.array([0.62, 0.76, 0.96])) * v[:, :, None]
    land = _grey_photo(rng, rng.uniform([0.45, 0.55, 0.35], [0.8, 0.9, 0.7]), contrast=0.5)[:128, :256]
    return np.where((v > horizon)[:, :, None], land, sky)


def textured_materials(rng: np.random.Generator, role: str, count: int) -> list[Material]:
    """Random materials for a surface role, as interiors tend to have them.

    Roles: "paint" (walls, ceiling: a tint with a low-contrast grain), "wall" (paint in the near-
    neutral tints real rooms have), "floor" (planks, tiles, carpet-like grain), "furniture"
    (anything, including photographs and bold patterns), "wood" (grain in brown tints), "fabric"
    (woven grain, checks, stripes), "picture" (a photograph, mapped once), "plain" (one flat
    colour), "ground" (bright grass or gravel outdoors), "backdrop" (a bright outdoor view,
    mapped once) and "foliage" (leaves' dark greens).
    """
    materials = []
    for index in range(count):
        tint = rng.uniform(0.35, 1.0, size=3)
        if role == "paint":
            texture = _grey_photo(rng, tint, contrast=rng.uniform(0.05, 0.25))
        elif role == "floor":
            kind = rng.integers(3)
            texture = (
                _stripes(rng, tint)
                if kind == 0
                else _checker(rng, tint)
                if kind == 1
                else _grey_photo(rng, tint, contrast=rng.uniform(0.3, 0.8))
            )
        elif role == "furniture":
            kind = rng.integers(4)
            texture = (_grey_photo(rng, tint, 1.0), _photo(rng), _checker(rng, tint), _stripes(rng, tint))[kind]
        elif role == "wall":
            grey = rng.uniform(0.5, 0.97)
            wall_tint = np.clip(grey * (1.0 + rng.uniform(-0.12, 0.12, size=3)), 0.0, 1.0)
            texture = _grey_photo(rng, wall_tint, contrast=rng.uniform(0.03, 0.15))
        elif role == "wood":
            texture = _wood(rng, rng.uniform([0.35, 0.2, 0.1], [0.9, 0.65, 0.45]))
        elif role == "fabric":
            kind = rng.integers(3)
            texture = (_grey_photo(rng, tint, rng.uniform(0.2, 0.6)), _checker(rng, tint), _stripes(rng, tint))[kind]
        elif role == "picture":
            texture = _photo(rng)
        elif role == "plain":
            texture = np.broadcast_to(rng.uniform(0.05, 0.95, size=3), (4, 4, 3))
        elif role == "ground":
            texture = _grey_photo(rng, rng.uniform([0.55, 0.6, 0.45], [0.9, 0.95, 0.8]), contrast=0.5)
        elif role == "backdrop":
            texture = _backdrop(rng)
        elif role == "foliage":
            texture = _grey_photo(rng, rng.uniform([0.1, 0.25, 0.05], [0.35, 0.6, 0.25]), contrast=0.8)
        else:
            raise ValueError(f"unknown material role {role!r}")
        materials.append(Material(f"{role}{index}", base_color=np.ones(3), texture=np.clip(texture, 0, 1)))
    return materials
