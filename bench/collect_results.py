"""Gather every JSON result under a folder into one file (the device machine returns at most 8
files): ``python3 bench/collect_results.py DIR OUT.json`` writes {relative path: content}."""

import json
import sys
from pathlib import Path


def main(argv=None) -> int:
    root, out = (Path(a) for a in (sys.argv[1:] if argv is None else argv))
    found = {}
    for p in sorted(root.rglob("*.json")):
        try:
            found[str(p.relative_to(root))] = json.loads(p.read_text())
        except (OSError, ValueError) as e:
            found[str(p.relative_to(root))] = {"unreadable": str(e)}
    out.write_text(json.dumps(found, indent=1))
    print(f"{len(found)} results -> {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
