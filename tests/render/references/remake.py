"""Remake ``direct_lighting.npz`` from kadv 0.1's renders.

    git worktree add /tmp/kadv-0.1 3787428
    .venv/bin/python tests/render/references/remake.py /tmp/kadv-0.1 [scenes folder]

The first argument is the checkout whose ``kadv`` renders the references (it goes first on
``sys.path``); the scenes folder defaults to ``../shared/scenes``.
"""

from __future__ import annotations

import sys
from pathlib import Path

if __name__ == "__main__":
    source = Path(sys.argv[1]).resolve()
    here = Path(__file__).resolve()
    scenes = Path(sys.argv[2]) if len(sys.argv) > 2 else here.parents[4] / "shared" / "scenes"
    sys.path[:0] = [str(source), str(here.parent)]
    import numpy as np
    from direct_views import REFERENCE, render_direct_views

    import kadv

    if Path(kadv.__file__).resolve().parents[1] != source:
        sys.exit(f"kadv was imported from {kadv.__file__}, not from {source}")
    np.savez_compressed(REFERENCE, **render_direct_views(scenes))
    print(f"wrote {REFERENCE} with the renders of {source}")
