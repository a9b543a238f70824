"""Which espeak-ng → CMU table is right: facegen.phonetics.ESPEAK_TO_CMU (until issue 21 in facegen/espeak.py)
or the espeak → viseme table that facegen/synth/curves.py kept until then (frozen below as it was at 0dc2807).

Every word of the project's English text (the synthetic lexicon, the hand-written and generated sentences, the
example transcript) that pocketsphinx's own en-us dictionary (cmudict-en-us.dict, shipped with the
`pocketsphinx` package) knows is phonemized with libespeak-ng (`--voice`, default en-us). Each table turns the
espeak phonemes into visemes (ESPEAK_TO_CMU through CMU_VISEMES; the old curves table directly), and so does
the dictionary's pronunciation (CMU_VISEMES); the two are aligned (edit distance; of a word's dictionary
variants the closest one for each table) and every espeak phoneme counts as agreeing when all its visemes meet
equal visemes of the dictionary. The comparison is on visemes because the curves table only names visemes;
visemes of vowels are CMU vowels, so "a" → AE against "a" → AA is a phone comparison. For ESPEAK_TO_CMU the
same count is also made on CMU phones. Printed: per espeak phoneme where the tables disagree (and "a", "y"),
how often it occurs and the agreement of each table; then the totals.

    python benchmarks/espeak_table.py [--voice en-us] [--all]
"""

from __future__ import annotations

import argparse
import re
import sys
from collections import Counter
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

# facegen/synth/curves.py at 0dc2807: espeak-ng mnemonics -> visemes, its stress marks and its look-up
_OLD = {
    **{p: ("PBM",) for p in ("p", "b", "m", "m-")}, **{p: ("FV",) for p in ("f", "v")},
    **{p: ("TH",) for p in ("T", "D")}, **{p: ("SZ",) for p in ("s", "z", "z#")},
    **{p: ("SH",) for p in ("S", "Z", "tS", "dZ", "S;", "Z;")},
    **{p: ("TDN",) for p in ("t", "d", "n", "t#", "d#", "n-", "t2", "d2", "?", "*", "t^")},
    **{p: ("L",) for p in ("l", "l/", "L", "@L", "l-", "l#")},
    **{p: ("R",) for p in ("r", "r-", "r/", "R", "3", "@r", "r#")},
    **{p: ("KG",) for p in ("k", "g", "N", "x", "C", "k#", "g#")}, **{p: ("H",) for p in ("h", "h#")},
    **{p: ("W",) for p in ("w", "hw", "W")}, **{p: ("Y",) for p in ("j", "j#")},
    **{p: ("AA",) for p in ("a", "A:", "A", "aa", "a#", "A#", "a2", "0", "V", "A@")},
    **{p: ("AE",) for p in ("&", "a1")}, **{p: ("AH",) for p in ("@", "@2", "@5", "@1", "@-", "@#", "V#")},
    **{p: ("ER",) for p in ("3:", "3:r", "@r")}, **{p: ("EH",) for p in ("E", "e", "E2", "E#")},
    **{p: ("IY",) for p in ("i:", "i", "i#")}, **{p: ("IH",) for p in ("I", "I#", "I2", "I2#", "y", "Y")},
    **{p: ("AO",) for p in ("O:", "O", "O2", "O#", "0#", "Q")}, **{p: ("OW",) for p in ("o", "o:")},
    **{p: ("UH",) for p in ("U", "U#")}, **{p: ("UW",) for p in ("u:", "u", "U:", "u#")},
    "aI": ("AA", "IH"), "aU": ("AA", "UH"), "eI": ("EH", "IH"), "oU": ("OW", "UW"), "OI": ("AO", "IH"),
    "aI@": ("AA", "IH", "AH"), "aU@": ("AA", "UH", "AH"), "aI3": ("AA", "IH", "ER"),
    "aU3": ("AA", "UH", "ER"),
    "i@": ("IY", "AH"), "i@3": ("IY", "ER"), "e@": ("EH", "AH"), "U@": ("UH", "AH"), "A@r": ("AA", "ER"),
    "O@": ("AO", "AH"), "o@": ("OW", "AH"), "e@r": ("EH", "ER"), "0u": ("OW", "UW"), "@U": ("AH", "UW"),
    "eI#": ("EH", "IH"), "IR": ("IH", "ER"), "VR": ("AH", "ER"),
}
_OLD_STRESS = str.maketrans("", "", "'\",%=!")


def old_visemes(mnemonic: str) -> tuple[str, ...]:
    """The visemes the curves table of 0dc2807 gave an espeak mnemonic."""
    name = mnemonic.translate(_OLD_STRESS).strip()
    if name.startswith("_") or not name:
        return ("rest",)
    for key in (name, name.rstrip("0123456789#-;"), name[:2], name[:1]):
        if key in _OLD:
            return _OLD[key]
    return ("rest",)


def words_of_project() -> list[str]:
    """The distinct lower-case words of the synthetic lexicon, the sentences and the example transcript."""
    from facegen.synth.lexicon import LEXICON
    from facegen.synth.sentences import SENTENCES, generated_sentences

    texts = [*LEXICON, *SENTENCES.values(), *generated_sentences().values(),
             (REPO / "examples" / "excellent_room.txt").read_text()]
    return sorted({w for t in texts for w in re.findall(r"[a-z]+(?:'[a-z]+)?", t.lower())})


def cmudict() -> dict[str, list[list[str]]]:
    """pocketsphinx's en-us dictionary: word -> its pronunciations (CMU phones, no stress)."""
    import pocketsphinx

    path = Path(pocketsphinx.get_model_path()) / "en-us" / "cmudict-en-us.dict"
    out: dict[str, list[list[str]]] = {}
    for line in path.read_text().splitlines():
        word, *phones = line.split()
        out.setdefault(re.sub(r"\(\d+\)$", "", word), []).append(phones)
    return out


def align(hyp: list[str], ref: list[str]) -> tuple[int, list[bool]]:
    """Edit distance of hyp against ref and, per hyp item, whether it meets an equal ref item."""
    n, m = len(hyp), len(ref)
    d = [[i + j if i * j == 0 else 0 for j in range(m + 1)] for i in range(n + 1)]
    for i in range(1, n + 1):
        for j in range(1, m + 1):
            d[i][j] = min(d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + (hyp[i - 1] != ref[j - 1]))
    ok = [False] * n
    i, j = n, m
    while i > 0 and j > 0:
        if d[i][j] == d[i - 1][j - 1] + (hyp[i - 1] != ref[j - 1]):
            ok[i - 1] = hyp[i - 1] == ref[j - 1]
            i, j = i - 1, j - 1
        elif d[i][j] == d[i - 1][j] + 1:
            i -= 1
        else:
            j -= 1
    return d[n][m], ok


def score(units: list[tuple[str, ...]], refs: list[list[str]]) -> tuple[list[bool], int, int]:
    """Per espeak phoneme (its output units), whether all its units agree with the closest reference; the
    edit distance to that reference and its length."""
    flat = [u for unit in units for u in unit]
    owner = [k for k, unit in enumerate(units) for _ in unit]
    (dist, ok), ref = min(((align(flat, ref), ref) for ref in refs), key=lambda r: r[0][0])
    agree = [bool(unit) for unit in units]
    for k, good in zip(owner, ok, strict=True):
        agree[k] = agree[k] and good
    return agree, dist, len(ref)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--voice", default="en-us", help="espeak-ng voice that phonemizes the words")
    parser.add_argument("--all", action="store_true", help="every espeak phoneme, not only disputed ones")
    args = parser.parse_args(argv)

    from facegen.espeak import phonemize
    from facegen.phonetics import (
        CMU_VISEMES,
        ESPEAK_TO_CMU,
        STRESS_MARKS,
        espeak_to_cmu,
        is_silence,
        phone_visemes,
    )

    known = cmudict()
    words = [w for w in words_of_project() if w in known]
    n, agree_new, agree_old, agree_phone = Counter(), Counter(), Counter(), Counter()
    exact_new = exact_old = 0
    errors = Counter()  # edit distance, summed over the words, and the references' length
    for word in words:
        # phonemes, not pauses or markers (";"), as facegen.espeak reads them
        symbols = [s for s in phonemize(word, args.voice)
                   if not is_silence(s) and any(c.isalnum() or c == "@" for c in s)]
        keys = [s.translate(str.maketrans("", "", STRESS_MARKS)) for s in symbols]
        # each phoneme's CMU phones as espeak_to_cmu maps the word ("b b" -> B: the second gets none)
        cmu = [espeak_to_cmu(symbols[:k]) for k in range(len(symbols) + 1)]
        units = [tuple(cmu[k + 1][len(cmu[k]):]) for k in range(len(symbols))]
        refs_vis = [[v for p in ref for v in CMU_VISEMES[p]] for ref in known[word]]
        new_units = [tuple(v for p in unit for v in CMU_VISEMES[p]) for unit in units]
        old_units = [() if old_visemes(s) == ("rest",) else old_visemes(s) for s in symbols]
        new, dist_new, size = score(new_units, refs_vis)
        old, dist_old, _ = score(old_units, refs_vis)
        phones, _, _ = score(units, known[word])
        errors.update(new=dist_new, old=dist_old, size=size)
        exact_new += all(new)
        exact_old += all(old)
        for key, a, b, c in zip(keys, new, old, phones, strict=True):
            n[key] += 1
            agree_new[key] += a
            agree_old[key] += b
            agree_phone[key] += c

    def differ(key: str) -> bool:
        return phone_visemes(key) != old_visemes(key)

    print(f"{len(words)} words (voice {args.voice}) in cmudict-en-us.dict, {sum(n.values())} espeak phonemes")
    print("| espeak | n | ESPEAK_TO_CMU -> | visemes agree | phones agree | old curves -> | visemes agree |")
    print("|---|---:|---|---:|---:|---|---:|")
    shown = sorted((k for k in set(n) | set(ESPEAK_TO_CMU) | set(_OLD) if args.all or differ(k) or k in "ay"),
                   key=lambda k: (-n[k], k))
    for key in shown:
        c = n[key]

        def pct(x: int, c: int = c) -> str:
            return f"{100 * x / c:.0f} %" if c else "–"
        print(f"| `{key}` | {c} | {ESPEAK_TO_CMU.get(key, '(longest match)')} | {pct(agree_new[key])} | "
              f"{pct(agree_phone[key])} | {' '.join(old_visemes(key))} | {pct(agree_old[key])} |")
    total = sum(n.values())
    disputed = [k for k in n if differ(k)]
    dn = sum(n[k] for k in disputed)
    print(f"\nall phonemes: ESPEAK_TO_CMU {100 * sum(agree_new.values()) / total:.1f} % of visemes agree "
          f"({100 * sum(agree_phone.values()) / total:.1f} % of phones), old curves table "
          f"{100 * sum(agree_old.values()) / total:.1f} %")
    if dn:
        print(f"the {dn} phonemes where the tables disagree ({len(disputed)} symbols): ESPEAK_TO_CMU "
              f"{100 * sum(agree_new[k] for k in disputed) / dn:.1f} %, old curves table "
              f"{100 * sum(agree_old[k] for k in disputed) / dn:.1f} %")
    print(f"viseme edit distance to the dictionary, per 100 visemes of it: ESPEAK_TO_CMU "
          f"{100 * errors['new'] / errors['size']:.1f}, "
          f"old curves table {100 * errors['old'] / errors['size']:.1f}")
    print(f"words whose every phoneme agrees: ESPEAK_TO_CMU {exact_new} "
          f"({100 * exact_new / len(words):.1f} %), "
          f"old curves table {exact_old} ({100 * exact_old / len(words):.1f} %)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
