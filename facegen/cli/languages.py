"""`facegen languages`: the transcript languages facegen reads, and what was measured of each."""

from __future__ import annotations

import json

import click

from facegen.cli.command import Command


@click.command(cls=Command)
@click.option("--json", "as_json", is_flag=True, help="Print them as JSON.")
def languages(as_json):
    """List the languages of --language: code, family, script and, where measured, how well the words align
    (word-onset error) and how the mismatch check does (benchmarks/bench_languages.py)."""
    from facegen.languages import CAVEATS, figures
    from facegen.languages import languages as table

    measured = figures()
    rows = [{"code": lang.code, "family": lang.family_name, "script": "/".join(lang.scripts).title(),
             **({"held_out": True} if measured.get(lang.code, {}).get("held_out") else {}),
             "measured": measured.get(lang.code),
             **({"caveat": CAVEATS[lang.code]} if lang.code in CAVEATS else {})} for lang in table().values()]
    rows.sort(key=lambda r: (r["measured"] is None, r["code"]))
    if as_json:
        click.echo(json.dumps(rows, indent=1, ensure_ascii=False))
        return
    click.echo(f"{'code':<16} {'family':<22} {'script':<20} measured on synthetic speech (espeak-ng voices)")
    for r in rows:
        m = r["measured"]
        said = "not measured" if m is None else "; ".join(_figures(m))
        said += f" (caveat: {r['caveat']})" if "caveat" in r else ""
        click.echo(f"{r['code']:<16} {r['family']:<22} {r['script']:<20} {said}")


def _figures(m: dict) -> list[str]:
    out = []
    if "onset_median_ms" in m:
        out.append(f"onsets {m['onset_median_ms']:.0f} ms off (median), {m['within_100ms']:.0%} within "
                   f"100 ms, matching lines {m['accepted']:.0%} accepted, swapped {m['refused']:.0%} refused")
    if "lips" in m:
        lips = m["lips"]
        out.append(f"lips vs the rig: aperture r {lips['aperture_r']:.2f}, ratio {lips['median_ratio']:.2f}, "
                   f"p/b/m closed {lips['pbm_closed']:.0%}")
    if m.get("held_out"):
        out.append("held out")
    return out
