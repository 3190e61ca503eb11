"""`torquebench cache info|clear`: the stage-result cache (torquebench.cache)."""

from __future__ import annotations

import sys
from pathlib import Path

HELP = "show or clear the stage-result cache"
EXAMPLES = """\
torquebench cache info
torquebench cache clear
"""


def add_arguments(parser) -> None:
    parser.add_argument("action", choices=("info", "clear"),
                        help="info: where the cache is and how big; clear: delete the cached stage results "
                             "(only the entries the cache wrote: other files in the directory stay)")
    parser.add_argument("--cache-dir", type=Path, default=None,
                        help="cache directory (default $TORQUEBENCH_CACHE or .torquebench-cache)")


def run(args) -> int:
    from torquebench.cache import Cache
    from torquebench.io import print_json
    from userio.outputs import room_problem

    cache = Cache(args.cache_dir)
    out = cache.info() if args.action == "info" else {"directory": str(cache.dir), "removed": cache.clear()}
    others = cache.info()["other_files"] if args.action == "clear" else out["other_files"]
    why = room_problem(cache.dir)            # a cache that cannot be written: runs recompute everything
    warnings = [f"{why}: stage results will not be cached there"] if why else []
    if args.json:
        print_json({**out, "other_files_kept": others, "warnings": warnings})
        return 0
    for w in warnings:
        print(f"warning: {w}", file=sys.stderr)
    if args.action == "info":
        print(f"{out['directory']}: {out['entries']} entries, {out['size_bytes'] / 1e6:.1f} MB"
              + (f" ({others} other .pkl files, not the cache's)" if others else ""))
    else:
        print(f"{out['directory']}: removed {out['removed']} entries"
              + (f"; kept {others} .pkl files the cache did not write" if others else ""))
    return 0
