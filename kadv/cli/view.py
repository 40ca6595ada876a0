"""``kadv-view``: a run or a sweep in a local 3-D viewer (viser), served until Ctrl-C."""

from __future__ import annotations

# before anything loads torch: the wait policy is read when torch starts its thread pool
from kadv.runtime import configure_runtime

configure_runtime()

import argparse
import sys
import time
from pathlib import Path

from kadv.cli.common import USER_ERRORS
from kadv.report.viewer import MAX_TRIANGLES, view

DESCRIPTION = f"""kadv-view: walk through a scene among the cameras where a depth model failed.
Serves RUN_OR_SWEEP (a kadv-attack run directory, or a sweep directory of runs) in a local viser
viewer and prints its URL: the scene with its colours (decimated above {MAX_TRIANGLES:,} triangles),
every evaluated camera centre coloured by L_depth, the init and kept adversarial views as frusta
showing their images (coloured by delta1, red 0 to green 1) and each search's path. The panel lists
the views (select one, or click its frustum, for its four-panel image and metrics, and fly there),
steps through a search's trajectory and, for a sweep, chooses the run. Ctrl-C ends it."""


_ALL_INTERFACES = ("0.0.0.0", "::", "")


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="kadv-view", description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("path", type=Path, metavar="RUN_OR_SWEEP", help="a run directory or a sweep directory")
    parser.add_argument("--host", default="127.0.0.1", help="address to listen on (default: this machine only)")
    parser.add_argument("--port", type=int, default=8080, help="port (default 8080)")
    parser.add_argument("--scene", type=Path, help="the scene file, when it has moved since the run")
    return parser


def main(argv: list[str] | None = None) -> None:
    """Serve the viewer until Ctrl-C."""
    args = _parser().parse_args(argv)
    if args.host in _ALL_INTERFACES:
        print(
            f"kadv-view: warning: --host {args.host} serves the viewer to every machine that can reach this one "
            "(the run's pictures and scene included); --host 127.0.0.1 keeps it to this machine",
            file=sys.stderr,
        )
    try:
        viewer = view(args.path, args.host, args.port, args.scene)
    except USER_ERRORS as error:
        print(f"kadv-view: error: {' '.join(str(error).split())}", file=sys.stderr)
        sys.exit(2)
    print(f"kadv-view: {viewer.url}  (Ctrl-C ends it)", flush=True)
    try:
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        viewer.stop()


if __name__ == "__main__":
    main()
