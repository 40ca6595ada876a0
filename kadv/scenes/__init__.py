"""Scene data and loaders: Mitsuba XML, PLY (scans' vertex colours), trimesh formats, scan layouts,
generated box rooms and furnished rooms."""

from __future__ import annotations

from kadv.scenes.box_rooms import box_room
from kadv.scenes.emitters import Emitters
from kadv.scenes.load import SUPPORTED_SUFFIXES, load_scene
from kadv.scenes.ply import PlyError, PlyMesh, read_ply
from kadv.scenes.procedural import procedural_room
from kadv.scenes.scans import ScanLayout, recognise_scan
from kadv.scenes.scene import Material, MeshPart, Scene, assemble_scene

__all__ = [
    "SUPPORTED_SUFFIXES",
    "Emitters",
    "Material",
    "MeshPart",
    "PlyError",
    "PlyMesh",
    "ScanLayout",
    "Scene",
    "assemble_scene",
    "box_room",
    "load_scene",
    "procedural_room",
    "read_ply",
    "recognise_scan",
]
