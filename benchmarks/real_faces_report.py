"""The summary over clips and the Markdown tables of benchmarks/real_faces.py (pure numpy, no tracker)."""

from __future__ import annotations

import numpy as np
from real_faces_measures import jaw_at_consonants, pooled_best, response_curve, summarize_vowels

TARGETS = {"aperture_r": 0.65, "median_ratio": (0.7, 1.3), "closure_rate": 0.80}  # issue 23, GRID-like speech


def _closure_summary(cl: list[dict]) -> dict:
    """Closure durations over the p/b/m inside speech (not at its edges), timing over all closed ones."""
    inner = [c for c in cl if c["closed"] and not c["edge"]]
    every = [c for c in cl if c["closed"]]

    def med(rows, f):
        return float(np.median([f(c) for c in rows])) if rows else None

    return {
        "n": len(cl),
        "closed": len(every),
        "n_inner": len(inner),
        "duration_s_median": med(inner, lambda c: c["duration_s"]),
        "duration_s_iqr": np.percentile([c["duration_s"] for c in inner], [25, 75]).tolist()
        if inner
        else None,
        "acoustic_duration_s_median": med(inner, lambda c: c["end_s"] - c["start_s"]),
        "close_offset_s_median": med(inner, lambda c: c["close_offset_s"]),
        "release_offset_s_median": med(every, lambda c: c["release_offset_s"]),
    }


def summarize(clips: dict[str, dict]) -> dict:
    """Over all clips: mean per-clip r, best lags of the pooled lag curves, the ratios and rates pooled over
    frames and p/b/m, vowels, closures, leads, and how the tracker reads facegen's face."""
    rows = list(clips.values())

    def mean(key):
        vals = [r[key] for r in rows if r.get(key) is not None]
        return float(np.mean(vals)) if vals else None

    out = {
        k: mean(k)
        for k in ("aperture_r", "aperture_r_speech", "aperture_r_geometric", "facegen_tracked_vs_geometric_r")
    }
    for key, curve, rate in (
        ("aperture", "aperture", 25.0),
        ("aperture_speech", "aperture_speech", 25.0),
        ("envelope_real", "envelope_real", 100.0),
        ("envelope_facegen_geometric", "envelope_facegen_geometric", 100.0),
    ):
        r, lag = pooled_best([row["_curves"][curve] for row in rows])
        out[f"{key}_pooled_best_r"], out[f"{key}_pooled_best_lag_s"] = r, None if lag is None else lag / rate

    def pooled(who):
        return np.concatenate([np.asarray(r["tracks"][who[0]][who[1]])[r["_open"]] for r in rows])

    real_open = pooled(("real", "aperture"))
    for key, who in (("", ("facegen", "aperture")), ("_geometric", ("facegen", "geometric_aperture"))):
        fg_open = pooled(who)
        out[f"median_ratio{key}"] = (
            float(np.median(fg_open) / np.median(real_open)) if len(real_open) else None
        )
        out[f"median_open_facegen{key}_cm"] = float(np.median(fg_open)) if len(fg_open) else None
    out["median_open_real_cm"] = float(np.median(real_open)) if len(real_open) else None
    out["bilabials"] = int(sum(r["bilabials"] for r in rows))
    for who in ("real", "facegen", "facegen_geometric"):
        mids = sum(r["bilabials"] for r in rows)
        for key in ("closure_rate", "closure_rate_1frame"):
            vals = [(r[f"{key}_{who}"], r["bilabials"]) for r in rows if r[f"{key}_{who}"] is not None]
            out[f"{key}_{who}"] = sum(v * n for v, n in vals) / mids if mids else None
        out[f"aperture_range_{who}_cm"] = np.mean([r[f"aperture_range_{who}_cm"] for r in rows], 0).tolist()
    for who in ("real", "facegen_geometric"):
        out[f"closures_{who}"] = _closure_summary([c for r in rows for c in r[f"closures_{who}"]])
        onsets = [r[f"onset_lead_{who}_s"] for r in rows if r[f"onset_lead_{who}_s"] is not None]
        out[f"onset_lead_{who}_s"] = onsets
    for who in ("real", "facegen"):
        out[f"vowels_{who}"] = summarize_vowels([v for r in rows for v in r[f"vowels_{who}"]])
        out[f"width_range_{who}_cm"] = np.mean([r[f"width_range_{who}_cm"] for r in rows], 0).tolist()
        out[f"rest_width_{who}_cm"] = mean(f"rest_width_{who}_cm")
        out[f"jaw_p95_{who}_cm"] = mean(f"jaw_p95_{who}_cm")
    for who in ("real", "facegen"):
        out[f"jaw_at_consonants_{who}"] = jaw_at_consonants(
            [(np.asarray(r["tracks"][who]["jaw"]), r["phones"]) for r in rows], 25.0)
    out["tracker_on_facegen"] = response_curve(
        np.concatenate([r["tracks"]["facegen"]["aperture"] for r in rows]),
        np.concatenate([r["tracks"]["facegen"]["geometric_aperture"] for r in rows]),
    )
    ratio = out["median_ratio"]
    out["targets"] = {
        "aperture r >= 0.65": out["aperture_r"] is not None and out["aperture_r"] >= TARGETS["aperture_r"],
        "median ratio 0.7-1.3": ratio is not None
        and TARGETS["median_ratio"][0] <= ratio <= TARGETS["median_ratio"][1],
        "p/b/m closed >= 80 %": (out["closure_rate_facegen"] or 0) >= TARGETS["closure_rate"],
    }
    return out


# -------------------------------------------------------------------------------------------- report
def _f(x, fmt="{:.2f}"):
    return "-" if x is None else fmt.format(x)


def _range(x) -> str:
    return f"{_f(x[0])}-{_f(x[1])}"


def _row(name: str, text: str, c: dict, best_r, lag) -> str:
    """One line of the clip table from a clip's (or the summary's) numbers."""
    ms = None if lag is None else lag * 1000
    return (
        f"| {name} | {text} | {_f(c['aperture_r'])} | {_f(best_r)} ({_f(ms, '{:+.0f}')}) | "
        f"{_f(c['aperture_r_speech'])} | {_f(c['aperture_r_geometric'])} | {_f(c['median_ratio'])} "
        f"({_f(c['median_ratio_geometric'])}) | {_f(c['closure_rate_real'], '{:.0%}')} / "
        f"{_f(c['closure_rate_facegen'], '{:.0%}')} ({c['bilabials']}) | "
        f"{_range(c['aperture_range_real_cm'])} / {_range(c['aperture_range_facegen_cm'])} |"
    )


def table(result: dict) -> str:
    """The per-clip table, the vowels and the targets, as Markdown."""
    lines = [
        (
            "| clip | transcript | r lag 0 | best r (lag ms) | r speech | r geometric | median ratio "
            "(geometric) | p/b/m closed real / facegen (n) | aperture p5-p95 real / facegen (cm) |"
        ),
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, c in result["clips"].items():
        lines.append(_row(name, c["transcript"], c, c["aperture_best_r"], c["aperture_best_lag_s"]))
    s = result["summary"]
    lines.append(
        _row(
            "**all**",
            f"{len(result['clips'])} clips",
            s,
            s["aperture_pooled_best_r"],
            s["aperture_pooled_best_lag_s"],
        )
    )
    lines += [
        "",
        (
            "| vowel | n | aperture real / facegen tracked / facegen geometric (cm) | relative opening "
            "real / facegen geometric | jaw real / facegen (cm) | width change real / facegen tracked / "
            "facegen geometric (cm) |"
        ),
        "|---|---|---|---|---|---|",
    ]
    vr, vf = s["vowels_real"], s["vowels_facegen"]
    for key in vr:
        a, b = vr[key], vf.get(key, {})
        lines.append(
            f"| {key} | {a['n']} | {_f(a['aperture'])} / {_f(b.get('aperture'))} / "
            f"{_f(b.get('geometric'))} | {_f(a['aperture_rel'])} / {_f(b.get('aperture_rel'))} | "
            f"{_f(a['jaw'])} / {_f(b.get('jaw'))} | "
            f"{_f(a['width_change'], '{:+.2f}')} / {_f(b.get('width_change'), '{:+.2f}')} / "
            f"{_f(b.get('geometric_width_change'), '{:+.2f}')} |"
        )
    cr, cf = s.get("jaw_at_consonants_real"), s.get("jaw_at_consonants_facegen")
    if cr and cf:
        classes = [c for c in cr if c != "vowels"]
        lines += ["", "| jaw at the consonant ÷ at vowels, real / facegen (tracked) | "
                  + " | ".join(f"{c} ({cr[c]['n']})" for c in classes) + " |",
                  "|---|" + "---|" * len(classes),
                  "| | " + " | ".join(f"{_f(cr[c]['ratio'])} / {_f(cf[c]['ratio'])}" for c in classes) + " |"]
    lines.append("")
    lines.append(
        "targets: " + ", ".join(f"{k}: {'met' if v else 'NOT met'}" for k, v in s["targets"].items())
    )
    return "\n".join(lines)
