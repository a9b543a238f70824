"""The sentences of the synthetic corpus: e01–e40 like BIWI's 40, plus e41–e48 with unseen emotional words.

Every speaker says the same sentences (as in BIWI). Everyday sentences of 12–15 words (about 4.7 s when
spoken, BIWI's mean). Most carry one or two words of TRAIN_LEXICON (all six expression classes), a few
none — the upper face must stay at rest for them.

* e01–e32 (train), e33–e36 (validation), e37–e40 (test): TRAIN_LEXICON words only; e33–e40 are new
  sentences, so test and validation use known emotional words in new contexts.
* e41–e48 ("test-unseen"): one or two HELD_OUT_LEXICON words each and no TRAIN_LEXICON word, to test
  whether a model generalises from what words mean to emotional words it never saw in training.

`check_sentences()` asserts these rules (run at import time: an edit that breaks them fails at once).
"""

from __future__ import annotations

from facegen.synth.lexicon import HELD_OUT_LEXICON, TRAIN_LEXICON, emotional_words

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
