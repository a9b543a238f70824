"""Synthetic data: procedural face, rig and synthetic speech (libespeak-ng)."""
