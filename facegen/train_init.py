"""Fine-tuning: a training run that starts from a trained bundle's weights (`facegen train --init BUNDLE`)
instead of a random initialisation, e.g. to teach the default model new languages or a recalibrated rig in a
few epochs instead of a full run.

The bundle must describe the same network as the run (model sizes, modalities, fusion, speakers, phone
stream, text width and mesh) and its audio features must be the run's. Its mel normalisation is kept (the
weights were learnt on it). With the PCA output layer (facegen.train_pca) the run's basis B, mean m is fitted
on the new data as usual, and the bundle's plain output layer (weight W, bias b: facegen.model `folded`) is
projected into it: Bᵀ W, Bᵀ (b − m) — exact where the bundle's motion lies in the new basis's span.
"""

from __future__ import annotations

import torch

from facegen.errors import FacegenError


def warm_start(model, path: str, features) -> None:
    """Load the bundle at `path` into `model` (a FaceModel about to be trained on data with `features`)."""
    from facegen.bundle import load_bundle

    bundle = load_bundle(path)
    mine = {**model.cfg.to_dict(), "output_basis": 0}
    theirs = bundle.model.cfg.to_dict()
    differs = sorted(k for k in mine if mine[k] != theirs.get(k))
    if differs:
        shown = ", ".join(f"{k} {theirs.get(k)} vs {mine[k]}" for k in differs[:3])
        raise FacegenError(f"--init {path} is another network than this run's ({shown}): train with that "
                           "bundle's settings, or without --init", param="init")
    if bundle.features.to_dict() != features.to_dict():
        raise FacegenError(f"--init {path} was trained on other audio features than this data's: train "
                           "without --init", param="init")
    state = bundle.model.state_dict()
    with torch.no_grad():
        if model.cfg.output_basis:
            weight, bias = state.pop("fc_out.weight"), state.pop("fc_out.bias")
            state["fc_out.weight"] = model.basis.T @ weight
            state["fc_out.bias"] = model.basis.T @ (bias - model.basis_mean)
            state["basis"], state["basis_mean"] = model.basis.clone(), model.basis_mean.clone()
        missing, unexpected = model.load_state_dict(state, strict=False)
    if missing or unexpected:
        raise FacegenError(f"--init {path} does not fit this network (missing {missing[:3]}, unexpected "
                           f"{unexpected[:3]}): train without --init", param="init")
