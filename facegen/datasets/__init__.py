"""Datasets in the BIWI community layout (FaceFormer, CodeTalker), one module per concern:

- `splits`: which subjects and sentences make train, val, test-a and test-b; sequence names.
- `templates`: the community's templates.pkl, read with a restricted unpickler (no code runs).
- `cache`: the dataset's cache folder and its feature cache (mel, word timings, text features).
- `biwi`: the layout itself: `Dataset` reads it (sequences, templates, regions, features), `DatasetWriter`
  writes it.
- `raw`: import of the raw BIWI release (.vl frames, OBJ templates, the videos' audio) into the layout.
"""
