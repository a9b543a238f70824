"""The sentences of the synthetic corpus: e01–e40 like BIWI's 40, plus e41–e48 with unseen emotional words.

Every speaker says the same sentences (as in BIWI). Everyday sentences of 12–15 words (about 4.7 s when
spoken, BIWI's mean). Most carry one or two words of TRAIN_LEXICON (all six expression classes), a few
none — the upper face must stay at rest for them.

* e01–e32 (train), e33–e36 (validation), e37–e40 (test): TRAIN_LEXICON words only; e33–e40 are new
  sentences, so test and validation use known emotional words in new contexts.
* e41–e48 ("test-unseen"): one or two HELD_OUT_LEXICON words each and no TRAIN_LEXICON word, to test
  whether a model generalises from what words mean to emotional words it never saw in training.

`check_sentences()` asserts these rules (run at import time: an edit that breaks them fails at once).

e49 on are generated from slot templates (generated_sentences(); check_generated() asserts their rules):
train/val/test of sentences with training words (or none), and test-unseen ones with one held-out word each,
whose `neutral_twin()` swaps that word for a neutral one of the same role.
"""

from __future__ import annotations

import functools
import random

from facegen.synth.lexicon import CLASSES, HELD_OUT_LEXICON, TRAIN_LEXICON, Emotion, emotional_words

SENTENCES: dict[int, str] = {
    # ------------------------------------------------------------------- train (e01-e32)
    1: "We were amazed to find the old bakery still open on a quiet Sunday morning.",
    2: "My brother was furious when the train left ten minutes before the timetable said.",
    3: "She felt lonely in the big apartment after her roommate moved away to another city.",
    4: "The children were scared of the dark and narrow hallway that led down to the basement.",
    5: "From the top of the hill, the view over the green valley and the lake was breathtaking.",
    6: "Grandma was delighted with the yellow flowers we brought her for her eightieth birthday.",
    7: "Please put the blue folder on my desk before you leave for the meeting this afternoon.",
    8: "It was shocking to see how much the price of coffee and bread went up this year.",
    9: "He gets annoyed when people talk loudly on their phones in the reading room of the library.",
    10: "The news of the accident was tragic, and the whole town was in mourning.",
    11: "Driving on that narrow mountain road late at night without a torch is really dangerous.",
    12: "The old cathedral has a magnificent ceiling painted in gold and deep blue.",
    13: "We laughed all evening at the stories our uncle told about his school days.",
    14: "The bus to the airport leaves every twenty minutes from the main square.",
    15: "Suddenly the lights went out, and an unexpected silence filled the room.",
    16: "I hate waiting in line at the post office when only one window is open.",
    17: "He was sorry that he missed his sister's wedding in Spain last summer because of work.",
    18: "I was worried at first, but the view from the old bridge was wonderful.",
    19: "The ocean looked vast and glorious under the golden evening sky at the end of the day.",
    20: "The kids were thrilled when the snow started falling just before the holidays.",
    21: "Could you remind me to call the dentist tomorrow morning after breakfast?",
    22: "What an incredible goal, the whole stadium jumped up at the same moment.",
    23: "The neighbours were angry about the noise from the building site next door every morning.",
    24: "After the match, the players sat in the changing room, miserable and silent.",
    25: "A horrible storm broke the windows of the little shop on the corner of our street.",
    26: "The fireworks over the harbour were spectacular, and the children were laughing.",
    27: "It was a lovely afternoon, and everyone seemed happy to be outside.",
    28: "We need more flour, two onions and a bottle of milk for the recipe.",
    29: "She was astonished by how quickly her little garden had grown this spring.",
    30: "The long delay at the border made all the drivers bitter and tired by the evening.",
    31: "He wiped away his tears and said goodbye to his old dog at the gate.",
    32: "I was terrified when the small plane started shaking above the clouds.",
    # -------------------------------------------------------------- validation (e33-e36)
    33: "My friend was surprised to find a letter from her old teacher in the mailbox.",
    34: "The manager was livid when the shipment arrived broken for the second time.",
    35: "The garden looks gloomy in the winter rain, without any flowers or birds.",
    36: "The hikers were frightened by the sudden thunder on the open ridge above the forest.",
    # -------------------------------------------------------------------- test (e37-e40)
    37: "The singer gave a marvelous concert, and the crowd cheered for an hour.",
    38: "Our cat looks so cheerful when the sun warms the kitchen floor in the morning.",
    39: "The driver was irritated by the traffic, and the children in the back were anxious.",
    40: "Please close the window in the kitchen before the evening gets cold and windy.",
    # ------------------------------------------------- unseen emotional words (e41-e48)
    41: "The audience was flabbergasted when the magician vanished from the stage.",
    42: "My uncle was seething after the referee ignored the obvious foul in the final minute.",
    43: "The empty village looked forlorn in the grey light of the early morning after the rain.",
    44: "The campers were petrified when something moved behind their tent at midnight.",
    45: "From the balcony, the old palace looked resplendent in the setting sun.",
    46: "The team was jubilant after scoring the winning goal in the very last minute of the game.",
    47: "The tourists stood bewildered and indignant in front of the closed museum.",
    48: "She was elated to hear that the stupendous old theatre would open again.",
}

UNSEEN_SENTENCES = tuple(range(41, 49))  # e41-e48: held-out emotional words only ("test-unseen")


def check_sentences(sentences: dict[int, str] | None = None) -> None:
    """Assert the corpus rules: no held-out word in e01–e40; e41–e48 only held-out emotional words."""
    table = SENTENCES if sentences is None else sentences
    for number, text in table.items():
        held = emotional_words(text, HELD_OUT_LEXICON)
        train = emotional_words(text, TRAIN_LEXICON)
        if number in UNSEEN_SENTENCES:
            assert 1 <= len(held) <= 2 and not train, \
                f"e{number:02d} must hold 1-2 held-out words only: {text}"
        else:
            assert not held, f"e{number:02d} holds the held-out words {held}: {text}"
            assert len(train) <= 2, f"e{number:02d} holds more than two emotional words: {text}"


check_sentences()


# ------------------------------------------------------------------------- generated sentences (e49 on)
FIRST_GENERATED = 49
GENERATED = 2400  # how many generated_sentences() makes by default

# Slot vocabularies. Items are ";"-separated; "|" adds the expression classes an event or sight suits
# (s surprise, a anger, d sadness, f fear, w awe, j joy). No item may hold a LEXICON word.
_PEOPLE = """my brother/he; my sister/she; my mother/she; my father/he; our neighbour/she; the old farmer/he;
    Paul/he; Maria/she; the bus driver/he; my best friend/she; the young waiter/he; our new boss/she;
    Uncle Bob/he; Aunt Vera/she; the postman/he; the twins/they; my parents/they; the students/they;
    the passengers/they; the visitors/they; our grandparents/they; Mia/she; Oliver/he; Fiona/she;
    Victor/he; Mum/she; Dad/he; the museum guide/she; the pub owner/he; our music teacher/she;
    the football coach/he; my flatmate/she; the pilot/he; Professor Moore/she; my cousin Pablo/he;
    the boys/they; the fans/they; the volunteers/they; my colleagues/they; the farmers/they; our guests/they;
    Bella/she; Mr Webb/he; Mrs Bowman/she; the plumber/he; Grandpa Wilfred/he; the new nurse/she"""
_EVENTS = """the bus broke down on the motorway|safd; the power went off during dinner|saf;
    the results of the exam came out|sdfj; the band played their old songs|sdjw; the puppy ran into the
    living room|sj; the doctor called back with the results|sfdj; the waiter brought the wrong bill|sa;
    the landlord put up the rent again|sad; the museum opened its new wing|sjw; the old mill by the river
    burned down|sdf; the flight to Boston was cancelled|sad; the football club moved to another town|sad;
    the parcel from Vienna finally arrived|sj; the team won the cup after fifty years|sjw; the school bus
    was two hours late|saf; the neighbours played music until four in the morning|sa; the lights in the
    building went out|sf; the dog escaped through the garden fence|sfa; the baby took her first steps|sjw;
    the orchestra played the final movement|wjd; the pub on the corner closed for good|sd; the bakery
    stopped making the apple pie|sda; the plumber flooded the bathroom floor|sa; the ferry rocked in the
    heavy wind|f; the wolves howled near the cabin|fw; the volcano on the island began to smoke|fws;
    a stranger followed us to the bus stop|fa; the vet said the old pony would be fine|j; the mayor opened
    the new swimming pool|sj; the price of the bus pass went up|sa; someone parked in front of the garage
    again|a; the cafe by the beach reopened in May|sj; the factory announced two hundred job cuts|sadf;
    the whale swam right under the boat|swf; the northern lights appeared above the farm|wsj; the choir
    sang in the old abbey|wjd; the pilot announced an emergency landing|sf; the police knocked on the door
    at night|sf; the cat brought a mouse into the kitchen|sa; the new puppy chewed up the sofa|sa; the old
    cinema showed its final film|sd; the hospital phoned about the operation|sfd; the printer jammed for
    the fifth time|a; the first snow of winter began to fall|jw; the sun came up over the mountains|wj;
    the ship sailed past the frozen cliffs|wf; the brass band marched through the village|js; the bridge
    was closed without any warning|sa; the museum sold its famous painting|sda; the rain flooded the whole
    basement|safd; the money for the trip was stolen|sadf; the goalkeeper saved the penalty|sjw; the
    builders knocked down the old library|sad; the lift got stuck between two floors|saf; the wedding
    photos finally came back from the printer|j; the big oak tree in the park fell over|sdf; the video
    of the moon landing started to play|wj; the storm blew the roof off the barn|sfw"""
_TIMES = """last Friday; on Monday morning; yesterday afternoon; this morning; last week; over the weekend;
    on Sunday evening; two days ago; in the middle of May; at lunchtime; after work; before breakfast;
    during the holidays; on Thursday night; last month; in the spring; early on Saturday; on Tuesday;
    last November"""
_PLACES = """the post office; the museum; the office; the pub; the bakery; the cinema; the police station;
    the library; the bank; the town hall; the opera house; the bus station; the farm shop; the swimming pool;
    the football club; the animal clinic; the school; the hospital; the market; the gym; the bookshop;
    the music shop; the bowling club; the village hall; the boat club; the barber shop; the pharmacy"""
_SHOWS = """the film; the final episode of the show; the ending of the book; the play at the village hall;
    the match on Saturday; the concert in the park; the documentary about whales; the speech at the wedding;
    the last chapter of the novel; the opera in Vienna; the puppet show; the news from home; the story in
    the paper; the whole evening; the film about the volcano; the boat trip around the bay; the magic show
    at the fair; the museum tour; the final round of the quiz; the visit to the old farm; the report on the
    radio; the podcast about the moon landing; the ballet at the opera house; the movie on Friday; the bus
    journey over the mountains; the new musical in town; the football final; the interview with the mayor;
    the photo exhibition; the school play"""
_SIGHTS = """the view from the top of the tower|wjfs; the storm over the bay|fws; the waves at the harbour|fw;
    the sky above the valley|wjdfs; the mountains behind the village|wf; the empty beach in winter|dw;
    the old palace by the river|wjd; the abandoned factory near the motorway|fd; the forest at midnight|fw;
    the frozen lake below the farm|wfd; the fireworks above the bridge|wjs; the old mill in the fog|fdw;
    the flower market in the square|jw; the city lights below the plane|wj; the waterfall in the park|wj;
    the ruins on the hill|wdf; the flooded fields by the motorway|fds; the garden in full bloom|jw;
    the moon over the harbour|wjf; the old graveyard behind the church|fd; the lighthouse in the storm|fw;
    the harbour full of boats|jw; the burnt woods above the town|df; the rubbish dumped by the river|ad;
    the litter all over the beach|ad; the graffiti on the old church|ads"""
_VANTAGES = ("the bus window; the bridge; our hotel room; the top floor; the ferry; the back of the boat; "
             "the plane;\n    the footpath; the upper deck; the hilltop")
_DURATIONS = "for days; for weeks; all evening; for the whole weekend; all the way home; for a month"
_PARTS = "day; evening; week; morning; afternoon; weekend; journey"
_ERRANDS = """buy bread and milk; post a parcel to Vienna; return two books; pick up the photos; book a table
    for four; pay the phone bill; pump up the bike tyres; collect the spare keys; buy a map of the park;
    order a new umbrella; move the boxes to the van; feed the ponies; buy plums and apples; pay the window
    cleaner; buy a birthday present for Bob; fetch the big blue umbrella; pick up some envelopes; borrow a
    power drill; wash the van; water the tomato plants; book the ferry tickets; buy a new pump for the pool;
    fix the broken bike lamp; renew the bus pass; move the piano upstairs"""
_DEADLINES = ("Friday; the end of the month; lunch; the meeting; we leave for Madrid; the shops close; "
              "the weekend")
_LATER = "tomorrow morning; on Monday; next week; after lunch; before the weekend; on the way home; tonight"
_CITIES = ("Munich; Vienna; Boston; Oporto; Paris; Mumbai; Melbourne; Warsaw; Bologna; Moscow; Toulouse; "
           "Bilbao")
_PERIODS = "two months; a summer; five years; most of the winter; a week; a few days; half a year"
# neutral words of each role: the fillers of neutral sentences and of the held-out sentences' twins
_NEUTRAL = {"experiencer": ["calm", "busy", "hungry", "sleepy", "polite", "patient", "awake", "serious"],
            "stimulus": ["ordinary", "quiet", "normal", "familiar", "plain", "typical", "simple"]}
# the stimulus adjectives that say how a place looks (the others fit only shows: "a hilarious film")
_SCENIC_WORDS = """
    stunning remarkable extraordinary strange weird unusual uncanny surreal bizarre amazing incredible
    astonishing unbelievable peculiar staggering astounding disgusting revolting repulsive appalling vile
    loathsome odious gloomy bleak dismal dreary grim cheerless joyless somber depressing desolate funereal
    wretched woeful creepy scary frightening terrifying horrifying spooky eerie sinister menacing ominous
    nightmarish threatening perilous treacherous haunted hideous monstrous daunting intimidating dreadful
    horrible ghastly foreboding macabre unnerving fearsome awesome magnificent majestic breathtaking wonderful
    marvelous spectacular glorious splendid sublime grand gorgeous dazzling mesmerizing impressive stately
    towering mighty heavenly divine radiant exquisite superb enchanting captivating miraculous luminous
    beautiful mystical otherworldly sacred resplendent stupendous monumental transcendent celestial imposing
    spellbinding lovely delightful charming pleasant fantastic terrific fabulous festive brilliant idyllic
    """
_SCENIC = frozenset(_SCENIC_WORDS.split())

# Templates by the emotional words they hold: E experiencer, S stimulus (sights or shows), N none.
_TEMPLATES = {
    "E": ("{P} {be} {E} when {event} {time}.", "{P} {be} {E} to hear that {event}.",
          "{Time}, {p} looked {E} as {pron} walked out of {place}.",
          "When {event}, {p} {be} {E} for the rest of the {part}.",
          "{P} said that {pron} felt {E} when {event}.", "I could see that {p} {be} {E} the moment {event}.",
          "{P} {be} too {E} to speak when {event}.",
          "{P} {be} {E} after {show} and talked about it {duration}."),
    "S": ("From {vantage}, {sight} looked {S} {time}.", "We stopped the car because {sight} looked so {S}.",
          "{P} took a photo because {sight} looked so {S}.", "{Sight} looked {S} when we walked past {time}.",
          "{Show} was {S}, and {p} talked about it {duration}.",
          "Everyone at {place} agreed that {show} was {S}.",
          "{P} told us that {show} was really {S}.", "I did not expect {show} to be so {S}, but it was.",
          "To be honest, {show} was {S} from start to finish."),
    "EE": ("{P} {be} {E} when {event}, but {p2} {be2} {E2}.", "{P} {be} {E} and {E2} when {event}."),
    "SE": ("{Show} was {S}, and {p2} {be2} {E2} afterwards.",
           "{Sight} looked {S}, and {p2} {be2} {E2} at first."),
    "N": ("{P} went to {place} {time} to {errand}.", "Could you ask {p} to {errand} before {deadline}?",
          "We met {p} at {place} {time} and walked home together.",
          "{P} forgot to {errand} and had to go back to {place}.", "Please remind {p} to {errand} {later}.",
          "{P} spent {period} in {city} before moving back to the coast.",
          "{P} took the early bus to {city} {time} to {errand}."),
}
_CODES = dict(zip("sadfwj", ("surprise", "anger", "sadness", "fear", "awe", "joy")))


def _items(text: str) -> list[str]:
    return [" ".join(item.split()) for item in text.split(";") if item.strip()]


def _tagged(text: str) -> list[tuple[str, set[str]]]:
    out = []
    for item in _items(text):
        phrase, codes = item.split("|")
        out.append((phrase, {_CODES[c] for c in codes}))
    return out


def _cap(text: str) -> str:
    return text[0].upper() + text[1:]


class _Generator:
    """Fills templates from the slot vocabularies with one random.Random (deterministic for a seed)."""

    def __init__(self, seed: int):
        self.rng = random.Random(seed)
        self.people = [tuple(item.split("/")) for item in _items(_PEOPLE)]
        self.events, self.sights = _tagged(_EVENTS), _tagged(_SIGHTS)
        self.lists = {name: _items(text) for name, text in (
            ("time", _TIMES), ("place", _PLACES), ("show", _SHOWS), ("vantage", _VANTAGES),
            ("duration", _DURATIONS), ("part", _PARTS), ("errand", _ERRANDS), ("deadline", _DEADLINES),
            ("later", _LATER), ("city", _CITIES), ("period", _PERIODS))}

    def pick(self, items: list):
        return items[self.rng.randrange(len(items))]

    def slots(self, cls: str | None) -> dict[str, str]:
        """Every slot's filling; events and sights suit `cls` (any when None)."""
        (p, pron), (p2, pron2) = self.rng.sample(self.people, 2)
        fill = {name: self.pick(items) for name, items in self.lists.items()}
        fill["event"] = self.pick([e for e, classes in self.events if cls is None or cls in classes])
        fill["sight"] = self.pick([s for s, classes in self.sights if cls is None or cls in classes])
        fill.update(P=_cap(p), p=p, pron=pron, be="were" if pron == "they" else "was", p2=p2,
                    be2="were" if pron2 == "they" else "was", Time=_cap(fill["time"]),
                    Show=_cap(fill["show"]),
                    Sight=_cap(fill["sight"]))
        return fill

    def sentence(self, kind: str, cls: str | None, words: dict[str, str]) -> tuple[str, dict[str, str]]:
        """A sentence of template `kind` with `words` ({"E": ..., "S": ..., "E2": ...}) of class `cls`
        (the first word's), 10-16 words long; also its slot filling (to make a twin)."""
        templates = _TEMPLATES[kind]
        if "S" in words and words["S"] not in _SCENIC and words["S"] not in _NEUTRAL["stimulus"]:
            templates = tuple(t for t in templates if "{sight}" not in t.lower())
        # neutral or held-out (then its twin): "calm to hear"
        if "E" in words and words["E"] not in TRAIN_LEXICON:
            templates = tuple(t for t in templates if "to hear" not in t)
        while True:
            template = self.pick(templates)
            fill = {**self.slots(cls), **words}
            text = template.format(**fill)
            if 10 <= len(text.split()) <= 16:
                return text, {"template": template, **fill}


def _pools(lexicon: dict[str, Emotion]) -> dict[tuple[str, str], list[str]]:
    pools: dict[tuple[str, str], list[str]] = {}
    for word, emotion in sorted(lexicon.items()):
        pools.setdefault((emotion.cls, emotion.role), []).append(word)
    return pools


def _counts(size: int, rng: random.Random) -> list[int]:
    """How many training words each of `size` sentences holds: 25% none, 60% one, 15% two, shuffled."""
    none, two = round(size * 0.25), round(size * 0.15)
    counts = [0] * none + [2] * two + [1] * (size - none - two)
    rng.shuffle(counts)
    return counts


def generated_splits(n: int = GENERATED) -> dict[str, range]:
    """The split of the `n` generated sentences: train/val/test (80/10/10 of those with training words or
    none) and test-unseen (the last tenth: one held-out word each), as ranges of sentence numbers."""
    unseen = n // 10
    known = n - unseen
    train, val = known * 8 // 10, known // 10
    edges = [FIRST_GENERATED, FIRST_GENERATED + train, FIRST_GENERATED + train + val,
             FIRST_GENERATED + known, FIRST_GENERATED + n]
    return {name: range(a, b) for name, a, b in zip(("train", "val", "test", "test-unseen"), edges,
                                                    edges[1:])}


def _choice(rng: random.Random, count: int, cls: str, pools) -> tuple[str, str | None, dict[str, str]]:
    """(template kind, class, words) of a sentence with `count` (0-2) training words, the first of `cls`."""
    roles = {"E": "experiencer", "S": "stimulus"}
    kind = rng.choice("ES")
    if count == 0:
        return ("N", None, {}) if rng.random() < 0.5 else (kind, None,
                                                           {kind: rng.choice(_NEUTRAL[roles[kind]])})
    if count == 1:
        return kind, cls, {kind: rng.choice(pools[cls, roles[kind]])}
    kind = rng.choice(("EE", "SE"))
    first = rng.choice(pools[cls, roles[kind[0]]])
    second = rng.choice([w for w in pools[rng.choice(CLASSES), "experiencer"] if w != first])
    return kind, cls, {kind[0]: first, "E2": second}


@functools.lru_cache(maxsize=4)
def _generate(n: int, seed: int) -> tuple[dict[int, str], dict[int, str]]:
    gen = _Generator(seed)
    rng = gen.rng
    pools = _pools(TRAIN_LEXICON)
    seen = set(SENTENCES.values())
    sentences, twins = {}, {}

    def add(number: int, kind: str, cls: str | None, words: dict[str, str]) -> dict[str, str]:
        """sentences[number] = a sentence not made before; its slot filling."""
        while True:
            text, fill = gen.sentence(kind, cls, words)
            if text not in seen:
                seen.add(text)
                sentences[number] = text
                return fill

    splits = generated_splits(n)
    for name in ("train", "val", "test"):
        classes: list[str] = []  # a shuffled deck of the classes, refilled when empty: balanced classes
        for number, count in zip(splits[name], _counts(len(splits[name]), rng)):
            if not classes:
                classes = rng.sample(CLASSES, len(CLASSES))
            add(number, *_choice(rng, count, classes.pop(), pools))
    held = [w for w in sorted(HELD_OUT_LEXICON) if HELD_OUT_LEXICON[w].role in ("experiencer", "stimulus")]
    order: list[str] = []  # every held-out adjective in turn, reshuffled each round
    for number in splits["test-unseen"]:
        if not order:
            order = rng.sample(held, len(held))
        word = order.pop()
        emotion = HELD_OUT_LEXICON[word]
        kind = "E" if emotion.role == "experiencer" else "S"
        fill = add(number, kind, emotion.cls, {kind: word})
        twins[number] = fill["template"].format(**{**fill, kind: rng.choice(_NEUTRAL[emotion.role])})
    return sentences, twins


def generated_sentences(n: int = GENERATED, seed: int = 0) -> dict[int, str]:
    """`n` distinct everyday sentences of 10-16 words numbered from e49 on, made from slot templates; see
    generated_splits() for which are train/val/test (~25% without emotional words, ~60% with one training
    word, ~15% with two) and test-unseen (one held-out word each, no training word)."""
    return dict(_generate(n, seed)[0])


def neutral_twin(number: int, n: int = GENERATED, seed: int = 0) -> str:
    """The test-unseen sentence `number` with its held-out word replaced by a neutral word of the same role
    (no lexicon word at all): the upper-face response test compares the two on the same audio."""
    twins = _generate(n, seed)[1]
    if number not in twins:
        raise KeyError(f"e{number:02d} is not a test-unseen sentence of generated_sentences({n})")
    return twins[number]


def check_generated(n: int = GENERATED, seed: int = 0) -> None:
    """Assert the generated sentences' rules: numbered e49 on, distinct from each other and e01–e48, 10-16
    words; train/val/test hold at most two training words and no held-out word; test-unseen exactly one
    held-out word and no training word, and its twin no lexicon word and one word changed."""
    sentences, twins = _generate(n, seed)
    assert list(sentences) == list(range(FIRST_GENERATED, FIRST_GENERATED + n))
    assert len(set(sentences.values()) | set(SENTENCES.values())) == n + len(SENTENCES), "repeated sentences"
    unseen = generated_splits(n)["test-unseen"]
    for number, text in sentences.items():
        assert 10 <= len(text.split()) <= 16, f"e{number:02d} is not 10-16 words long: {text}"
        held, train = emotional_words(text, HELD_OUT_LEXICON), emotional_words(text, TRAIN_LEXICON)
        if number not in unseen:
            assert not held and len(train) <= 2, f"e{number:02d} holds {held + train}: {text}"
            continue
        assert len(held) == 1 and not train, f"e{number:02d} must hold one held-out word only: {text}"
        twin = twins[number].split()
        changed = [i for i, (a, b) in enumerate(zip(text.split(), twin)) if a != b]
        assert len(twin) == len(text.split()) and len(changed) == 1, f"twin of e{number:02d}: {twin}"
        assert not emotional_words(twins[number]), f"twin of e{number:02d} holds lexicon words: {twin}"
