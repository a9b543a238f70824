"""Copy the assets a `facegen batch` run made (its OUT/report.json) to a publish folder, with their audio
sidecars and the reports; refuse (exit 1) when any line failed or could not be made.

    python publish_assets.py OUT DEST
"""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path


def publish(out: Path, dest: Path) -> int:
    report = json.loads((out / "report.json").read_text(encoding="utf-8"))
    bad = [i for i in report["items"] if i["status"] not in ("passed", "skipped")]  # skipped: passed before
    if bad:
        for item in bad:
            print(f"line {item['line']}: {item['output']}: {item['status']}: {item['error'] or 'validation failed'}",
                  file=sys.stderr)
        print(f"not publishing: {len(bad)} of {len(report['items'])} lines failed (see {out / 'report.xml'})",
              file=sys.stderr)
        return 1
    names = {"report.json", "report.xml"}
    for item in report["items"]:
        for output in item["outputs"]:
            names |= {output, str(Path(output).with_suffix(".wav"))}
    for name in sorted(names):
        target = dest / name
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(out / name, target)
    print(f"published {len(report['items'])} lines ({len(names)} files) to {dest}")
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__.strip().splitlines()[-1].strip())
    sys.exit(publish(Path(sys.argv[1]), Path(sys.argv[2])))
