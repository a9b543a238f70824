"""A transcript that does not match its speech: refused (the default) or animated with a warning
(`on_mismatch="warn"`, `--on-mismatch warn`); its match score in the metadata, in batch's report.json and in
the JUnit report either way, so that a CI can sort lines by how sure facegen is."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from facegen.errors import FacegenError
from facegen.transcript_match import MAX_UNEXPLAINED, PART_UNEXPLAINED, PART_WORD_GAP, Match

REPO = Path(__file__).resolve().parents[1]
WAV = REPO / "examples" / "excellent_room.wav"
TEXT = (REPO / "examples" / "excellent_room.txt").read_text().strip()
HALF = "What an excellent room you have, sir."  # the first half of TEXT: the end of the speech unexplained


def test_the_score_is_one_half_at_every_bound_and_orders_lines():
    bound = 16.0
    assert Match(0.0, 0.0, bound).score == 1.0
    assert Match(MAX_UNEXPLAINED, 0.0, bound).score == 0.5
    assert Match(0.0, bound, bound).score == 0.5
    assert Match(PART_UNEXPLAINED, PART_WORD_GAP, bound).score == 0.5  # both signs halfway
    assert Match(PART_UNEXPLAINED, 0.0, bound).score == 1.0 - PART_UNEXPLAINED / MAX_UNEXPLAINED / 2
    assert Match(0.9, 60.0, bound).score == 0.0
    assert Match(0.01, float("nan"), bound).score > 0.9  # no scored word: the share alone
    ordered = [Match(u, g, bound).score for u, g in ((0.02, -3.0), (0.1, 5.0), (0.2, 12.0), (0.4, 30.0))]
    assert ordered == sorted(ordered, reverse=True)
    found = Match(0.4, float("nan"), bound, "40% of the speech lies outside its words").as_dict()
    assert found["word_gap"] is None and found["problem"].startswith("40%") and found["score"] < 0.5
    json.dumps(found)


@pytest.fixture(scope="module")
def animations():
    """The example line animated with its whole transcript and (warn) with half of it."""
    import facegen

    notes: list[str] = []
    whole = facegen.animate(WAV, text=TEXT)
    half = facegen.animate(WAV, text=HALF, on_mismatch="warn", reporter=facegen.Reporter(note=notes.append))
    return whole, half, notes


def test_a_matching_transcript_has_a_high_score_in_the_metadata(animations):
    whole, _, _ = animations
    match = whole.metadata["transcript_match"]
    assert match["problem"] is None and match["score"] > 0.8
    assert 0 <= match["unexplained"] < 0.1


def test_warn_animates_the_mismatch_with_a_note_and_its_low_score(animations):
    whole, half, notes = animations
    match = half.metadata["transcript_match"]
    assert match["problem"].endswith("at the end") and match["score"] < 0.5
    assert match["unexplained"] > MAX_UNEXPLAINED
    assert [w["word"] for w in half.metadata["words"]] == HALF.rstrip(".").replace(",", "").split()
    assert half.num_frames == whole.num_frames
    assert any("may not match the speech" in n and f"{match['score']:.2f}" in n for n in notes)


def test_error_refuses_it_with_its_match_in_the_details():
    import facegen

    with pytest.raises(FacegenError, match="does not match the speech .* at the end") as refused:
        facegen.animate(WAV, text=HALF)
    assert refused.value.details["transcript_match"]["score"] < 0.5
    with pytest.raises(FacegenError, match="unknown mismatch choice 'ignore'"):
        facegen.animate(WAV, text=TEXT, on_mismatch="ignore")


def test_the_cli_refuses_or_warns(tmp_path):
    def run(*extra):
        return subprocess.run([sys.executable, "-m", "facegen", "animate", str(WAV), "--text", HALF, "-o",
                               str(tmp_path / "out.npy"), *extra], capture_output=True, text=True,
                              timeout=600, check=False)

    refused = run()
    assert refused.returncode == 2 and "Traceback" not in refused.stderr
    assert not (tmp_path / "out.npy").exists()
    warned = run("--on-mismatch", "warn")
    assert warned.returncode == 0, warned.stderr
    assert "may not match the speech" in warned.stderr and (tmp_path / "out.npy").is_file()


@pytest.mark.parametrize("choice", ["error", "warn"])
def test_batch_reports_every_lines_score_and_flags_the_mismatches_it_wrote(tmp_path, choice):
    from facegen.batch_run import run_manifest

    (tmp_path / "whole.txt").write_text(TEXT)
    (tmp_path / "half.txt").write_text(HALF)
    manifest = tmp_path / "lines.csv"
    manifest.write_text(f"audio,text_file,output\n{WAV},whole.txt,whole.json\n{WAV},half.txt,half.json\n")
    outcome = run_manifest(manifest, tmp_path / "out", jobs=1, on_mismatch=choice)
    report = json.loads(outcome.report_json.read_text())
    whole, half = report["items"]
    assert whole["status"] == "passed" and not whole["flagged"] and whole["match"]["score"] > 0.8
    assert half["match"]["score"] < 0.5 and half["match"]["problem"].endswith("at the end")
    if choice == "error":
        assert half["status"] == "error" and "does not match the speech" in half["error"]
        assert not half["flagged"] and report["summary"]["flagged"] == 0
        assert not (tmp_path / "out" / "half.json").exists()
    else:
        assert half["status"] == "passed" and half["flagged"] and report["summary"]["flagged"] == 1
        assert (tmp_path / "out" / "half.json").is_file() and "1 flagged" in outcome.summary
    cases = ET.parse(outcome.report_xml).getroot().iter("testcase")
    scores = [float(p.get("value")) for case in cases for p in case.iter("property")
              if p.get("name") == "match_score"]
    assert scores == [whole["match"]["score"], half["match"]["score"]]
    assert all(not math.isnan(s) for s in scores)


def test_a_transcript_that_cannot_be_aligned_is_refused_or_animated_from_the_recognised_words():
    """Another line's script whose words cannot be placed at all: refused with score 0, or (warn) animated
    from the words recognised in the audio, flagged with score 0."""
    import facegen

    wrong = "Seven purple elephants were dancing slowly across the frozen river."
    with pytest.raises(FacegenError, match="no alignment of its words") as refused:
        facegen.animate(WAV, text=wrong)
    assert refused.value.details["transcript_match"]["score"] == 0.0
    notes: list[str] = []
    anim = facegen.animate(WAV, text=wrong, on_mismatch="warn", reporter=facegen.Reporter(note=notes.append))
    match = anim.metadata["transcript_match"]
    assert match["score"] == 0.0 and match["problem"] == "no alignment of its words to the audio exists"
    assert anim.metadata["word_timing"] == "speech recognition" and anim.metadata["words"]
    assert all("confidence" in w for w in anim.metadata["words"])
    assert any("animated from the words recognised" in n for n in notes)
