"""Dataset splits: which subjects and sentences make train, val, test-a and test-b, and sequence names.

Default splits are the community's (and the paper's): subjects F2 F3 F4 M3 M4 M5 with sentences
e01–e32 for training, e33–e36 for validation and e37–e40 for test A; e37–e40 of the other eight
subjects (F1 F5 F6 F7 F8 M1 M2 M6) are test B. A sequence is named {subject}_e{NN} (`sequence_name`).
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass

from facegen.errors import FacegenError

TRAIN_SUBJECTS = ("F2", "F3", "F4", "M3", "M4", "M5")
TEST_B_SUBJECTS = ("F1", "F5", "F6", "F7", "F8", "M1", "M2", "M6")
SPLITS = ("train", "val", "test-a", "test-b")


def parse_numbers(spec: str | Iterable[int]) -> tuple[int, ...]:
    """Sentence numbers from "1-32", "1,3,5-7" or "e33-e36" (or an iterable of ints), sorted, unique."""
    if not isinstance(spec, str):
        return tuple(sorted({int(n) for n in spec}))
    out: set[int] = set()
    for part in re.split(r"[,\s]+", spec.strip()):
        if not part:
            continue
        m = re.fullmatch(r"e?(\d+)(?:-e?(\d+))?", part, re.IGNORECASE)
        if not m:
            raise FacegenError(f"cannot read sentence numbers {spec!r}: write them like 1-32 or 1,3,5-7")
        lo, hi = int(m.group(1)), int(m.group(2) or m.group(1))
        if hi < lo:
            raise FacegenError(f"sentence range {part!r} is backwards: write it low-high, e.g. 33-36")
        out.update(range(lo, hi + 1))
    return tuple(sorted(out))


def parse_subjects(spec: str | Iterable[str]) -> tuple[str, ...]:
    """Subject names from "F2 F3 M3" or "F2,F3" (or an iterable), order kept, duplicates removed."""
    items = re.split(r"[,\s]+", spec.strip()) if isinstance(spec, str) else [str(s) for s in spec]
    return tuple(dict.fromkeys(s for s in items if s))


def sequence_name(subject: str, sentence: int) -> str:
    """F2, 1 → "F2_e01": the name of a sequence's files in the community layout."""
    return f"{subject}_e{sentence:02d}"


@dataclass(frozen=True)
class Splits:
    """Which subjects and sentences make the train, val, test-a and test-b splits.

    The training subjects are the model's speakers (in this order). test-a: the test sentences of the
    training subjects; test-b: the test sentences of the other subjects.
    """

    train_subjects: tuple[str, ...] = TRAIN_SUBJECTS
    test_subjects: tuple[str, ...] = TEST_B_SUBJECTS
    train_sentences: tuple[int, ...] = tuple(range(1, 33))
    val_sentences: tuple[int, ...] = tuple(range(33, 37))
    test_sentences: tuple[int, ...] = tuple(range(37, 41))

    def __post_init__(self) -> None:
        for name in ("train_subjects", "test_subjects"):
            object.__setattr__(self, name, parse_subjects(getattr(self, name)))
        for name in ("train_sentences", "val_sentences", "test_sentences"):
            object.__setattr__(self, name, parse_numbers(getattr(self, name)))
        if not self.train_subjects:
            raise FacegenError("no training subjects: give at least one, e.g. 'F2 F3'",
                               param="train_subjects")
        both = set(self.train_subjects) & set(self.test_subjects)
        if both:
            raise FacegenError(f"subjects {' '.join(sorted(both))} are both training and test-b subjects: "
                               "a subject belongs to one side only")
        sets = {"train": self.train_sentences, "val": self.val_sentences, "test": self.test_sentences}
        for a, b in (("train", "val"), ("train", "test"), ("val", "test")):
            common = set(sets[a]) & set(sets[b])
            if common:
                raise FacegenError(f"sentences {_ranges(common)} are in both the {a} and {b} sentences: "
                                   "the splits must not overlap")

    @classmethod
    def from_options(cls, train_subjects: str | None = None, test_subjects: str | None = None,
                     train_sentences: str | None = None, val_sentences: str | None = None,
                     test_sentences: str | None = None) -> Splits:
        """Defaults for every option left as None (what the CLI passes)."""
        options = {"train_subjects": train_subjects, "test_subjects": test_subjects,
                   "train_sentences": train_sentences, "val_sentences": val_sentences,
                   "test_sentences": test_sentences}
        given = {k: v for k, v in options.items() if v is not None}
        return cls(**given)

    def subjects(self, split: str) -> tuple[str, ...]:
        check_split(split)
        return self.test_subjects if split == "test-b" else self.train_subjects

    def sentences(self, split: str) -> tuple[int, ...]:
        check_split(split)
        return {"train": self.train_sentences, "val": self.val_sentences}.get(split, self.test_sentences)

    def names(self, split: str) -> list[str]:
        """Sequence names of a split, subject by subject: F2_e01, F2_e02, …"""
        return [sequence_name(s, n) for s in self.subjects(split) for n in self.sentences(split)]

    def to_dict(self) -> dict:
        return {"train_subjects": list(self.train_subjects), "test_subjects": list(self.test_subjects),
                "train_sentences": _ranges(self.train_sentences),
                "val_sentences": _ranges(self.val_sentences),
                "test_sentences": _ranges(self.test_sentences)}

    @classmethod
    def from_dict(cls, d: dict) -> Splits:
        return cls(**d)


def check_split(split: str) -> None:
    if split not in SPLITS:
        raise FacegenError(f"unknown split {split!r}: choose one of {', '.join(SPLITS)}")


def _ranges(numbers: Iterable[int]) -> str:
    """1,2,3,5 → "1-3,5"."""
    nums = sorted(set(numbers))
    parts: list[str] = []
    i = 0
    while i < len(nums):
        j = i
        while j + 1 < len(nums) and nums[j + 1] == nums[j] + 1:
            j += 1
        parts.append(str(nums[i]) if i == j else f"{nums[i]}-{nums[j]}")
        i = j + 1
    return ",".join(parts)
