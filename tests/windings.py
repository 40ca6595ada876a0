"""Scenes wound another way: shared by the bake's tests and the view-validity tests."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from kadv.scenes import Scene


def rewound(scene: Scene, flip: np.ndarray, name: str) -> Scene:
    """``scene`` with the triangles ``flip`` (F,) bool wound the other way."""
    faces, uvs, normals = scene.faces.copy(), scene.uvs.copy(), scene.normals.copy()
    for array in (faces, uvs, normals):
        array[flip] = array[flip][:, [0, 2, 1]]
    return replace(scene, faces=faces, uvs=uvs, normals=normals, name=name)
