"""Emotional words whose meaning moves the upper face of the synthetic speakers.

Each word has an expression class (see facegen.face.rig.EXPRESSIONS: surprise raises the brows, anger
and sadness frown, fear and awe widen the eyes, joy raises the cheeks), an intensity in (0, 1] and a role
for sentence templates (ROLES: an experiencer adjective says how a person feels, a stimulus adjective what
something is like; other words are for hand-written sentences).

TRAIN_LEXICON may appear in training sentences. HELD_OUT_LEXICON must never appear in training
sentences: it tests whether a model generalises from what words mean to emotional words it never saw.
LEXICON (both) is what the ground-truth rig responds to.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

ROLES = ("experiencer", "stimulus", "other")


@dataclass(frozen=True)
class Emotion:
    cls: str  # a key of facegen.face.rig.EXPRESSIONS
    intensity: float
    role: str = "other"  # one of ROLES


def _entries(cls: str, role: str, words: str) -> dict[str, Emotion]:
    """Parse "word:intensity word:intensity ..." into lexicon entries of one class and role."""
    out = {}
    for item in words.split():
        word, value = item.split(":")
        out[word] = Emotion(cls, float(value), role)
    return out


# experiencer: an adjective for how a person feels ("my brother was furious");
# stimulus: an adjective for what something is like ("the film was terrifying");
# other: nouns, verbs, adverbs, interjections and adjectives that fit no template (for hand-written
# sentences).
TRAIN_LEXICON: dict[str, Emotion] = {
    # ------------------------------------------------------------------------------------------ surprise
    **_entries("surprise", "experiencer", """
        surprised:0.9 amazed:0.9 astonished:1.0 shocked:1.0 startled:0.8 stunned:0.9 speechless:0.8
        baffled:0.6 puzzled:0.4 gobsmacked:1.0 floored:0.8 confounded:0.6 agog:0.7 jolted:0.6 dazed:0.6"""),
    **_entries("surprise", "stimulus", """
        surprising:0.8 amazing:0.9 astonishing:1.0 unexpected:0.7 sudden:0.6 incredible:0.9 unbelievable:0.9
        shocking:1.0 stunning:0.8 remarkable:0.6 extraordinary:0.7 startling:0.8 baffling:0.6 puzzling:0.4
        phenomenal:0.8 sensational:0.8 surreal:0.6 bizarre:0.6 strange:0.4 weird:0.4 unusual:0.4 uncanny:0.6
        improbable:0.5 implausible:0.5"""),
    **_entries("surprise", "other", """
        surprise:0.9 suddenly:0.6 wow:1.0 whoa:1.0 amazement:0.9 astonishment:0.9 shock:0.9 gasp:0.8
        gasped:0.8 blimey:0.8 gosh:0.7 amaze:0.8 stun:0.8 baffle:0.6 revelation:0.7 bombshell:0.9 abruptly:0.5
        unexpectedly:0.7 astonishingly:0.9 surprisingly:0.7 amazingly:0.8"""),
    # --------------------------------------------------------------------------------------------- anger
    **_entries("anger", "experiencer", """
        angry:0.9 furious:1.0 annoyed:0.5 irritated:0.6 mad:0.7 hostile:0.7 bitter:0.6 livid:1.0 enraged:1.0
        outraged:0.9 incensed:0.9 fuming:0.9 resentful:0.6 exasperated:0.7 frustrated:0.6 infuriated:1.0
        vexed:0.5 peeved:0.4 irked:0.4 grumpy:0.4 cranky:0.4 testy:0.4 disgusted:0.8 appalled:0.8 offended:0.6
        insulted:0.6 belligerent:0.8 spiteful:0.7"""),
    **_entries("anger", "stimulus", """
        annoying:0.5 outrageous:0.8 disgusting:0.8 infuriating:0.9 maddening:0.8 exasperating:0.7
        frustrating:0.6 irritating:0.6 aggravating:0.6 insulting:0.7 offensive:0.7 revolting:0.8 repulsive:0.8
        appalling:0.8 scandalous:0.7 despicable:0.9 vile:0.8 hateful:0.9 unbearable:0.7 intolerable:0.7
        unforgivable:0.8 obnoxious:0.6"""),
    **_entries("anger", "other", """
        anger:0.8 fury:1.0 rage:1.0 hate:0.9 hated:0.9 resent:0.6 disgust:0.8 angrily:0.9 outrage:0.9
        hatred:0.9 resentment:0.6 frustration:0.6 irritation:0.5 annoyance:0.5 grudge:0.6 scold:0.6
        scolded:0.6 yelled:0.7 growled:0.7 fumed:0.8 despise:0.9 temper:0.6 tantrum:0.7 grumbled:0.4
        furiously:1.0 resented:0.6 infuriate:0.9"""),
    # ------------------------------------------------------------------------------------------- sadness
    **_entries("sadness", "experiencer", """
        sad:0.8 grieving:1.0 miserable:0.9 lonely:0.7 heartbroken:1.0 unhappy:0.7 depressed:0.8 sorry:0.5
        downcast:0.6 dejected:0.7 despondent:0.8 glum:0.5 sorrowful:0.8 tearful:0.7 upset:0.6 devastated:1.0
        disheartened:0.6 discouraged:0.5 disappointed:0.5 homesick:0.6 wistful:0.4 distraught:0.9
        inconsolable:1.0 lonesome:0.6 heartsick:0.8 brokenhearted:1.0 crestfallen:0.7 mournful:0.8 weepy:0.6
        bereft:0.9"""),
    **_entries("sadness", "stimulus", """
        tragic:0.9 gloomy:0.6 heartbreaking:1.0 depressing:0.8 saddening:0.7 bleak:0.6 dismal:0.6 poignant:0.6
        pitiful:0.6 grim:0.6 dreary:0.5 disappointing:0.5 regrettable:0.5 painful:0.6 cheerless:0.5
        joyless:0.6 hopeless:0.8 bittersweet:0.5 somber:0.6"""),
    **_entries("sadness", "other", """
        sadly:0.7 sorrow:0.9 grief:1.0 tragedy:0.9 mourn:0.9 mourning:0.9 despair:1.0 crying:0.8 tears:0.7
        regret:0.6 sadness:0.8 sob:0.9 sobbed:0.9 sobbing:0.9 wept:0.9 weep:0.9 weeping:0.9 cried:0.8
        heartache:0.9 misery:0.9 anguish:1.0 loneliness:0.7 mourned:0.9 grieve:0.9 grieved:0.9 sigh:0.4
        sighed:0.4 alas:0.6 unhappiness:0.7 gloom:0.6"""),
    # ---------------------------------------------------------------------------------------------- fear
    **_entries("fear", "experiencer", """
        afraid:0.8 scared:0.9 frightened:0.9 terrified:1.0 nervous:0.5 anxious:0.6 worried:0.5 fearful:0.8
        panicked:0.9 alarmed:0.7 uneasy:0.5 tense:0.5 jumpy:0.5 timid:0.4 apprehensive:0.6 spooked:0.7
        shaken:0.7 horrified:0.9 panicky:0.8 edgy:0.5 fretful:0.5 paranoid:0.7 intimidated:0.6 distressed:0.7
        frantic:0.8 shaky:0.6 wary:0.4"""),
    **_entries("fear", "stimulus", """
        horrible:0.8 dreadful:0.8 alarming:0.7 creepy:0.6 scary:0.8 frightening:0.9 terrifying:1.0
        horrifying:1.0 chilling:0.8 spooky:0.6 eerie:0.7 sinister:0.7 menacing:0.8 ominous:0.7 nightmarish:0.9
        harrowing:0.9 disturbing:0.7 threatening:0.7 worrying:0.5 perilous:0.7 treacherous:0.7 frightful:0.8
        gruesome:0.9 hideous:0.8 monstrous:0.8 daunting:0.5 intimidating:0.6 distressing:0.7 haunted:0.7"""),
    **_entries("fear", "other", """
        fear:0.8 terror:1.0 horror:1.0 dread:0.8 panic:0.9 danger:0.7 dangerous:0.7 threat:0.6 fright:0.8
        scream:0.9 screamed:0.9 screaming:0.9 shudder:0.7 shuddered:0.7 nightmare:0.9 nightmares:0.9
        anxiety:0.6 worry:0.5 phobia:0.7 ghost:0.6 ghosts:0.6 monster:0.7 panicking:0.9 cowered:0.8 yikes:0.8
        hazardous:0.6"""),
    # ----------------------------------------------------------------------------------------------- awe
    **_entries("awe", "experiencer", """
        awed:0.8 awestruck:1.0 mesmerized:0.8 enthralled:0.8 captivated:0.7 entranced:0.8 dazzled:0.8
        enchanted:0.7 wonderstruck:1.0 hypnotized:0.7 inspired:0.5 impressed:0.5"""),
    **_entries("awe", "stimulus", """
        awesome:0.8 magnificent:0.9 majestic:0.8 breathtaking:1.0 wonderful:0.7 marvelous:0.8 spectacular:0.9
        glorious:0.8 splendid:0.7 sublime:0.8 grand:0.5 gorgeous:0.7 dazzling:0.8 mesmerizing:0.8
        impressive:0.6 stately:0.5 towering:0.6 mighty:0.6 heavenly:0.7 divine:0.7 radiant:0.7 exquisite:0.7
        superb:0.6 enchanting:0.7 captivating:0.7 miraculous:0.9 epic:0.7 legendary:0.6 luminous:0.6
        beautiful:0.6 inspiring:0.6 mystical:0.6 otherworldly:0.8 sacred:0.6"""),
    **_entries("awe", "other", """
        enormous:0.6 vast:0.5 immense:0.6 miracle:0.9 wonder:0.7 awe:0.9 marvel:0.8 marveled:0.8 splendor:0.7
        majesty:0.8 grandeur:0.7 wonders:0.7 glory:0.7 gigantic:0.6 colossal:0.7 behold:0.6 beheld:0.6
        admire:0.5 admired:0.5 admiration:0.6 boundless:0.6 vastness:0.6 miracles:0.9 infinite:0.5"""),
    # ----------------------------------------------------------------------------------------------- joy
    **_entries("joy", "experiencer", """
        happy:0.8 joyful:0.9 delighted:0.9 glad:0.6 cheerful:0.7 pleased:0.6 excited:0.8 thrilled:0.9
        grateful:0.6 contented:0.5 blissful:0.9 gleeful:0.8 merry:0.7 jolly:0.7 upbeat:0.6 chirpy:0.6
        bubbly:0.6 euphoric:1.0 exhilarated:0.9 joyous:0.9 proud:0.6 relieved:0.5 giddy:0.7 carefree:0.6
        lighthearted:0.6 beaming:0.8 cheery:0.6 chuffed:0.7 amused:0.5"""),
    **_entries("joy", "stimulus", """
        lovely:0.6 delightful:0.8 hilarious:0.9 funny:0.6 uplifting:0.7 heartwarming:0.8 charming:0.6
        pleasant:0.5 enjoyable:0.6 amusing:0.6 fantastic:0.8 terrific:0.8 brilliant:0.7 fabulous:0.8
        exciting:0.7 thrilling:0.8 exhilarating:0.9 entertaining:0.5 festive:0.6 gratifying:0.6"""),
    **_entries("joy", "other", """
        happiness:0.8 joy:0.9 delight:0.8 love:0.7 laugh:0.8 laughing:0.9 smile:0.7 smiling:0.8 fun:0.6
        celebrate:0.7 laughed:0.8 smiled:0.7 loved:0.7 hooray:1.0 yay:0.9 hurray:1.0 bliss:0.9 glee:0.8
        giggle:0.7 giggled:0.7 giggling:0.8 grin:0.7 grinned:0.7 laughter:0.9 celebrated:0.7 celebration:0.7
        rejoice:0.9 rejoiced:0.9 enjoy:0.5 enjoyed:0.5 adore:0.7 adored:0.7 hugged:0.6 yippee:1.0 laughs:0.8
        smiles:0.7 euphoria:1.0"""),
}

HELD_OUT_LEXICON: dict[str, Emotion] = {
    **_entries("surprise", "experiencer", """
        flabbergasted:1.0 dumbfounded:0.9 bewildered:0.7 thunderstruck:1.0 nonplussed:0.5 incredulous:0.7
        mystified:0.5 staggered:0.8 perplexed:0.5 astounded:0.9"""),
    **_entries("surprise", "stimulus", "staggering:0.8 stupefying:0.9 unforeseen:0.6 perplexing:0.5 "
               "astounding:0.9 peculiar:0.4 bewildering:0.7"),
    **_entries("anger", "experiencer", """
        seething:1.0 wrathful:0.9 irate:0.9 indignant:0.7 apoplectic:1.0 miffed:0.4 disgruntled:0.5
        vindictive:0.8"""),
    **_entries("anger", "other", "loathe:0.9"),
    **_entries("anger", "stimulus", "odious:0.8 loathsome:0.9 detestable:0.8 abhorrent:0.9 vexing:0.5 "
                                    "galling:0.6"),
    **_entries("sadness", "experiencer", """
        forlorn:0.8 melancholy:0.7 woebegone:0.8 disconsolate:0.9 doleful:0.6 rueful:0.4 dispirited:0.6
        morose:0.7"""),
    **_entries("sadness", "stimulus", """
        woeful:0.8 desolate:0.9 funereal:0.7 wretched:0.8 dispiriting:0.6 lamentable:0.6 heartrending:0.9"""),
    **_entries("fear", "experiencer", """
        petrified:1.0 aghast:0.9 trembling:0.7 skittish:0.5 quaking:0.8 unnerved:0.6 jittery:0.5
        hysterical:0.9"""),
    **_entries("fear", "stimulus", """
        ghastly:0.8 bloodcurdling:1.0 grisly:0.9 foreboding:0.6 unnerving:0.7 macabre:0.8 fearsome:0.8"""),
    **_entries("awe", "experiencer", """
        transfixed:0.9 overawed:0.9 enraptured:0.9 humbled:0.6 rapt:0.7 starstruck:0.7 reverent:0.6
        spellbound:0.9"""),
    **_entries("awe", "stimulus", """
        resplendent:0.9 stupendous:0.9 monumental:0.7 transcendent:0.8 celestial:0.7 imposing:0.6
        spellbinding:0.9"""),
    **_entries("joy", "experiencer", """
        jubilant:1.0 elated:0.9 ecstatic:1.0 overjoyed:1.0 buoyant:0.6 chipper:0.5 exultant:0.9 exuberant:0.9
        jovial:0.7"""),
    **_entries("joy", "stimulus", """
        rapturous:0.9 heartening:0.6 uproarious:0.9 gladdening:0.6 convivial:0.5 idyllic:0.6 comical:0.6"""),
}

LEXICON: dict[str, Emotion] = {**TRAIN_LEXICON, **HELD_OUT_LEXICON}
CLASSES = tuple(dict.fromkeys(e.cls for e in LEXICON.values()))  # the expression classes, in table order

_EDGES = re.compile(r"^[^\w']+|[^\w']+$")


def normalise_word(text: str) -> str:
    """Lower-case, edge punctuation and possessive 's removed ("Wow!" -> "wow", "fear's" -> "fear")."""
    word = _EDGES.sub("", text.strip().lower()).strip("'")
    return word.removesuffix("'s")


def lookup(text: str, lexicon: dict[str, Emotion] | None = None) -> Emotion | None:
    """The emotion of one word (as written in a transcript), or None when it carries none."""
    return (LEXICON if lexicon is None else lexicon).get(normalise_word(text))


def emotional_words(text: str, lexicon: dict[str, Emotion] | None = None) -> list[str]:
    """The words of `text` found in `lexicon` (all of LEXICON by default), normalised, in order."""
    table = LEXICON if lexicon is None else lexicon
    return [w for w in (normalise_word(t) for t in text.split()) if w in table]
