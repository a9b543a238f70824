"""Synthetic data: the procedural face, its rig, the emotional lexicon and sentences, and the synthetic
corpus (speech from facegen.espeak)."""
