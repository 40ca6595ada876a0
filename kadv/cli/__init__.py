"""Hydra entry points; the only place kadv imports Hydra."""

from __future__ import annotations

__all__: list[str] = []
