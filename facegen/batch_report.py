"""A batch run's reports: OUT/report.json (every item with its line, status, error, files and validation) and
OUT/report.xml (JUnit XML: one testcase per item, a failed validation as <failure>, an item that could not be
written as <error>, an unchanged item as <skipped>), both written atomically, and the one-line summary.
"""

from __future__ import annotations

import json
import os
import re
import socket
import time
import xml.etree.ElementTree as ET
from collections import Counter
from pathlib import Path

from facegen.atomic import atomic_path
from facegen.batch import JobResult

STATUSES = ("passed", "failed", "error", "skipped")
_XML_BAD = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\ufffe\uffff]")  # characters XML 1.0 cannot hold


def counts(results: list[JobResult]) -> dict[str, int]:
    """Items per status, and those written with a transcript that may not match ("flagged")."""
    found = Counter(r.status for r in results)
    return {**{s: found.get(s, 0) for s in STATUSES}, "flagged": sum(r.flagged for r in results)}


def summary_line(results: list[JobResult], seconds: float, out_dir: str | os.PathLike) -> str:
    """e.g. "20 items in 6.1 s: 18 passed, 1 failed, 1 error, 0 skipped (16.2x real time); reports in
    out/"."""
    c = counts(results)
    audio = sum(r.audio_seconds for r in results if r.status != "skipped")
    speed = f" ({audio / seconds:.1f}x real time)" if audio and seconds > 0 else ""
    flagged = f" ({c['flagged']} flagged: transcript may not match)" if c["flagged"] else ""
    return (f"{len(results)} items in {seconds:.1f} s: {c['passed']} passed{flagged}, {c['failed']} failed, "
            f"{c['error']} error{'s' if c['error'] != 1 else ''}, {c['skipped']} skipped{speed}; reports in "
            f"{Path(out_dir) / 'report.json'} and report.xml")


def item_name(result: JobResult, out_dir: str | os.PathLike) -> str:
    return os.path.relpath(result.job.output, out_dir)


def item_dict(result: JobResult, out_dir: str | os.PathLike) -> dict:
    job = result.job
    return {"line": job.line, "output": item_name(result, out_dir), "audio": str(job.audio),
            "outputs": [os.path.relpath(t, out_dir) for t in job.targets], "status": result.status,
            "error": result.error, "files": [os.path.relpath(f, out_dir) for f in result.files],
            "frames": result.frames, "audio_seconds": round(result.audio_seconds, 3),
            "seconds": round(result.seconds, 3), "cpu_seconds": round(result.cpu_seconds, 3),
            "validation": result.validation, "notes": result.notes, "match": result.match,
            "flagged": result.flagged}


def write_reports(results: list[JobResult], out_dir: str | os.PathLike, run: dict) -> tuple[Path, Path]:
    """Write OUT/report.json and OUT/report.xml for `results` (manifest order); `run` describes the run
    (manifest, engine, workers, seconds, ...). Returns both paths."""
    out = Path(out_dir)
    payload = {"run": run, "summary": counts(results), "items": [item_dict(r, out) for r in results]}
    json_path, xml_path = out / "report.json", out / "report.xml"
    with atomic_path(json_path) as tmp:
        tmp.write_text(json.dumps(payload, indent=1) + "\n", encoding="utf-8")
    with atomic_path(xml_path) as tmp:
        junit(results, out, run).write(tmp, encoding="utf-8", xml_declaration=True)
    return json_path, xml_path


def junit(results: list[JobResult], out_dir: Path, run: dict) -> ET.ElementTree:
    """The JUnit XML tree: one <testsuite> named after the manifest, one <testcase> per item."""
    c = counts(results)
    attrs = {"tests": len(results), "failures": c["failed"], "errors": c["error"], "skipped": c["skipped"],
             "time": f"{run.get('seconds', 0.0):.3f}"}
    suites = ET.Element("testsuites", {"name": "facegen batch", **{k: str(v) for k, v in attrs.items()}})
    suite = ET.SubElement(suites, "testsuite", {
        "name": Path(run.get("manifest", "manifest")).name, **{k: str(v) for k, v in attrs.items()},
        "timestamp": time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(run.get("started", time.time()))),
        "hostname": socket.gethostname()})
    for r in results:
        case = ET.SubElement(suite, "testcase", {
            "classname": "facegen.batch", "name": _text(f"line {r.job.line}: {item_name(r, out_dir)}"),
            "file": _text(str(run.get("manifest", ""))), "line": str(r.job.line), "time": f"{r.seconds:.3f}"})
        if r.match is not None:  # CI tools show a testcase's properties: sort lines by how sure facegen is
            properties = ET.SubElement(case, "properties")
            found = {"match_score": f"{r.match['score']:.3f}", "match_problem": r.match.get("problem")}
            for name, value in found.items():
                if value is not None:
                    ET.SubElement(properties, "property", {"name": name, "value": _text(value)})
        if r.status == "error":
            ET.SubElement(case, "error", {"message": _text(r.error), "type": "error"}).text = _text(
                f"{r.job.audio}: {r.error}")
        elif r.status == "failed":
            bad = [v for v in r.validation if not v["ok"]]
            message = "; ".join(f"{Path(v['file']).name}: {', '.join(v['failures'])}" for v in bad)
            ET.SubElement(case, "failure", {"message": _text(message), "type": "validation"}).text = _text(
                "\n".join(f"{v['file']}: FAIL {f}" for v in bad for f in v["failures"]))
        elif r.status == "skipped":
            ET.SubElement(case, "skipped", {"message": "unchanged since the last run (validated then)"})
        lines = [f"{v['file']}: {'ok' if v['ok'] else 'FAILED'}" + "".join(f"\n  WARN {w}"
                                                                           for w in v["warnings"])
                 for v in r.validation] + [f"note: {n}" for n in r.notes]
        if lines:
            ET.SubElement(case, "system-out").text = _text("\n".join(lines))
    ET.indent(suites)
    return ET.ElementTree(suites)


def _text(value: str | None) -> str:
    return _XML_BAD.sub("?", value or "")
